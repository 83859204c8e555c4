"""Progress on stderr for the commands whose library calls report ``progress(stage, done, total)``."""

from __future__ import annotations

import sys


class StageBars:
    """One tqdm bar per stage, on stderr: a callable ``(stage, done, total)``.

    ``delay``: seconds a stage must last before its bar appears (tqdm's ``delay``), so
    that quick runs print nothing. ``quiet``: no bars at all.
    """

    def __init__(self, quiet: bool = False, delay: float = 0.0):
        self.quiet, self.delay, self.stage, self.bar = quiet, delay, None, None

    def __call__(self, stage: str, done: int, total: int) -> None:
        if self.quiet:
            return
        from tqdm import tqdm

        if stage != self.stage:
            self.close()
            self.stage = stage
            self.bar = tqdm(total=max(total, 1), desc=stage, file=sys.stderr, leave=False, delay=self.delay)
        self.bar.total = max(total, 1)
        self.bar.update(min(done, self.bar.total) - self.bar.n)  # drawn at most every 0.1 s, after the delay

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
            self.bar = None
        self.stage = None

"""Running the command line in-process from tests."""

from __future__ import annotations

from nurbskit.cli import main


def run(argv) -> int:
    """``main``'s exit code, whether argparse (SystemExit) or the command refused the input."""
    try:
        return main(argv)
    except SystemExit as exc:
        return exc.code


def one_line(err: str) -> bool:
    """What stderr must be for a user's mistake: one line, no traceback."""
    return "Traceback" not in err and len(err.strip().splitlines()) == 1

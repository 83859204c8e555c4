"""Running the command line in-process from tests."""

from __future__ import annotations

from pathlib import Path

import numpy as np

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


def refused(capsys, argv, *needles) -> str:
    """Run ``argv``; assert exit 2 and one line on stderr (no "unexpected" error) holding
    every needle; return the line."""
    rc = run([str(a) for a in argv])
    err = capsys.readouterr().err
    assert rc == 2 and one_line(err) and "unexpected" not in err, err
    for needle in needles:
        assert needle in err, err
    return err.strip()


def run_shape_cli(root: Path, clouds: dict) -> dict:
    """``nurbskit shape --kind KIND --iters 0`` (no refinement, no figures) on each cloud of
    ``{kind: cloud}`` (``cloud.points (N, 3)``), saved as ``root/KIND.npy``: ``{kind:
    the output folder root/KIND}``."""
    out = {}
    for kind, cloud in clouds.items():
        src = root / f"{kind}.npy"
        np.save(src, cloud.points.numpy())
        assert main(["shape", str(src), "--kind", kind, "--iters", "0", "--no-figures", "--out", str(root / kind)]) == 0
        out[kind] = root / kind
    return out

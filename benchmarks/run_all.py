"""Run every benchmark (``make bench``): each ``bench_*.py`` in its own process.

Usage: python benchmarks/run_all.py [--quick] [--only NAME ...] [--device cuda]
Results land in benchmarks/results/ (GPU runs in benchmarks/results/gpu/).
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent


def main() -> int:
    parser = argparse.ArgumentParser(description="Run all benchmarks")
    parser.add_argument("--quick", action="store_true", help="pass --quick to each benchmark")
    parser.add_argument("--only", nargs="*", default=None, help="names like core_eval, io, volume")
    parser.add_argument("--device", default=None, help="pass --device to benchmarks that take it")
    args = parser.parse_args()
    scripts = sorted(HERE.glob("bench_*.py"))
    if args.only:
        scripts = [s for s in scripts if s.stem.removeprefix("bench_") in args.only]
    failed = []
    for script in scripts:
        cmd = [sys.executable, str(script)] + (["--quick"] if args.quick else [])
        if args.device:
            cmd += ["--device", args.device]
        print(f"== {script.name}", flush=True)
        start = time.perf_counter()
        rc = subprocess.call(cmd, cwd=HERE.parent)
        print(f"== {script.name}: exit {rc} after {time.perf_counter() - start:.1f} s", flush=True)
        if rc:
            failed.append(script.name)
    if failed:
        print("failed: " + ", ".join(failed), file=sys.stderr)
    return 1 if failed else 0


if __name__ == "__main__":
    raise SystemExit(main())

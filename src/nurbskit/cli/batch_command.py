"""``nurbskit batch``: run one command over many inputs on a Dask cluster.

Examples::

    nurbskit batch fit clouds/ --out fits/ -- --iters 300 --no-figures
    nurbskit batch fit 'scans/**/*.ply' --out fits/ --workers 4 --memory-limit 6GB --timeout 600
    nurbskit batch fit clouds/ --out fits/ --resume                   # after Ctrl-C: only what is left
    nurbskit batch fit clouds/ --out fits/ --scheduler tcp://10.0.0.5:8786
    nurbskit batch volume drawings.csv --out volumes/ -- --iters 50

Everything after ``--`` goes to the command itself and means what it means there
(``nurbskit fit --help``). See docs/batch.md.
"""

from __future__ import annotations

import argparse
import json
import signal
import sys
import threading
from pathlib import Path

from .._fs import file_id
from ..errors import OptionError
from ._options import resume_hint


def _int(low: int):
    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected an integer >= {low}, got {text!r}") from None
        if value < low:
            raise argparse.ArgumentTypeError(f"expected an integer >= {low}, got {value}")
        return value

    return parse


def _seconds(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number of seconds, got {text!r}") from None
    if not value > 0 or value == float("inf"):
        raise argparse.ArgumentTypeError(f"expected a positive number of seconds, got {text!r}")
    return value


def _add_options(p, suppress: bool) -> None:
    """The batch's own options (``suppress``: no defaults, for the second parsing pass)."""
    d = (lambda value: argparse.SUPPRESS) if suppress else (lambda value: value)
    p.add_argument("--out", metavar="DIR", default=d(None), help="output folder: DIR/<input name>/ per input, and the summary")
    p.add_argument("--workers", type=_int(1), metavar="N", default=d(None),
                   help="local worker processes (default: cores / --threads-per-worker)")
    p.add_argument("--threads-per-worker", type=_int(1), metavar="T", default=d(1),
                   help="torch threads of each item; a local worker runs one item at a time (default 1)")
    p.add_argument("--memory-limit", metavar="SIZE", default=d("4GB"),
                   help="memory of each local worker, at least 512MiB; a worker past 95%% of it is restarted and "
                        "its item recorded as failed (default 4GB; 'auto': the machine's memory / workers)")
    p.add_argument("--scheduler", metavar="ADDRESS", default=d(None),
                   help="use the Dask cluster at this scheduler (tcp://HOST:PORT) instead of a local one; "
                        "one that does not answer within 20 s fails the run before anything is written")
    p.add_argument("--retries", type=_int(0), metavar="N", default=d(1),
                   help="times an item whose worker died is tried again on the local cluster (default 1)")
    p.add_argument("--timeout", type=_seconds, metavar="S", default=d(None), help="seconds allowed per item; an item past it is recorded as failed (default: none)")
    p.add_argument("--resume", action="store_true", default=d(False),
                   help="skip inputs whose output is complete (their folders are not touched); run the rest")
    p.add_argument("--overwrite", action="store_true", default=d(False), help="run every input again, replacing its folder")
    p.add_argument("--no-figure", action="store_true", default=d(False), help="skip summary.png")
    p.add_argument("--quiet", action="store_true", default=d(False), help="no progress bar")


def register(subparsers) -> None:
    from ..batch.commands import COMMANDS

    names = ", ".join(sorted(COMMANDS))
    p = subparsers.add_parser(
        "batch", help="run a command over many inputs on a Dask cluster (resumable)",
        usage="nurbskit batch COMMAND INPUTS... --out DIR [options] [-- COMMAND OPTIONS]",
        description=(
            "Run COMMAND (" + names + ") on every input, one Dask task per input, each writing DIR/<input name>/ "
            "exactly as the single command does, and DIR/summary.csv, summary.json and summary.png. INPUTS are "
            "files, folders (searched by the command's extensions) and glob patterns. Options after '--' go to "
            "COMMAND. A failed input is recorded and does not stop the others. Needs the [dist] extra."
        ),
    )
    # dest is not "command": the top-level parser's error prefix reads args.command ("nurbskit batch: ...")
    p.add_argument("batch_command", metavar="COMMAND", help=f"one of: {names}")
    p.add_argument("rest", nargs=argparse.REMAINDER, metavar="INPUTS...", help="inputs, batch options, then -- and the command's options")
    _add_options(p, suppress=False)
    p.set_defaults(run=run, batch_parser=p)


class _SecondPass(argparse.ArgumentParser):
    """Parses what followed COMMAND; a mistake is an OptionError (one line, exit 2)."""

    def error(self, message: str):  # noqa: D401 - argparse API
        raise OptionError(message)


def _split(args) -> tuple[argparse.Namespace, list[str]]:
    """The second parsing pass: INPUTS and batch options before ``--``, the command's after."""
    rest = list(args.rest)
    if "--" in rest:
        cut = rest.index("--")
        mine, command_options = rest[:cut], rest[cut + 1:]
    else:
        mine, command_options = rest, []
    second = _SecondPass(prog=f"nurbskit batch {args.batch_command}", add_help=False)
    second.add_argument("inputs", nargs="*")
    _add_options(second, suppress=True)
    second.parse_args(mine, namespace=args)
    if not args.inputs:
        raise OptionError("INPUTS: expected files, folders or glob patterns after COMMAND")
    if args.out is None:
        raise OptionError("--out DIR is required")
    return args, command_options


class _Bar:
    """A tqdm bar over items: done, failed and running in its postfix; failures as lines."""

    def __init__(self, quiet: bool):
        self.quiet = quiet
        self.bar = None

    def __call__(self, event: dict) -> None:
        kind = event["event"]
        if kind == "started":
            where = event.get("dashboard") or "none (the scheduler has no dashboard; install bokeh for one)"
            workers = f", {event['workers']} local workers" if "workers" in event else ""
            sys.stderr.write(f"nurbskit batch: scheduler {event['scheduler']}{workers}; dashboard: {where}\n")
            if event.get("resumed"):
                sys.stderr.write(f"nurbskit batch: --resume: {event['resumed']} of {event['total']} inputs are finished already\n")
            if not self.quiet:
                from tqdm import tqdm

                self.bar = tqdm(total=event["total"], initial=event.get("resumed", 0), desc="batch", unit="input",
                                file=sys.stderr, dynamic_ncols=True)
        elif kind == "result":
            record = event["record"]
            if record["status"] != "ok":
                line = f"nurbskit batch: {record['input']}: failed: {record['error']}\n"
                if self.bar is not None:
                    self.bar.write(line.rstrip("\n"), file=sys.stderr)
                else:
                    sys.stderr.write(line)
            if self.bar is not None:
                self.bar.update(1)
        elif kind == "update" and self.bar is not None:
            self.bar.set_postfix_str(f"failed={event['failed']} running={event['running']}", refresh=True)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()


def _sigterm_as_interrupt(signum, frame):
    from . import Terminated

    raise Terminated


def _left_behind(out: Path, existed: bool, before) -> str:
    """One truthful clause on what an interrupted batch left in ``out``: the items that
    finished (each folder complete) and the summary the runner writes on its way out."""
    if file_id(out / "summary.json") not in (None, before):
        try:
            rows = json.loads((out / "summary.json").read_text(encoding="utf-8"))["rows"]
            ok = sum(r.get("status") == "ok" for r in rows)
            done = f"{ok} of {len(rows)} inputs finished"
        except (OSError, ValueError, KeyError, TypeError, AttributeError):
            done = "the inputs that finished"
        return (f"kept {done} and the summary in {out}/ (summary.csv, summary.json; the others are "
                f"listed as 'interrupted before it finished'); {resume_hint('batch')}")
    if before is not None:
        return f"{out}/ holds its files as they were; nothing new was summarised"
    if existed:
        return f"{out}/ holds what it held before; nothing was written"
    return "no output was left behind"


def run(args) -> int:
    from ..batch import run as run_batch
    from ..batch.commands import get_command

    rest_before = args.rest[: args.rest.index("--")] if "--" in args.rest else args.rest
    if "-h" in rest_before or "--help" in rest_before:
        args.batch_parser.print_help()
        return 0
    get_command(args.batch_command)
    args, command_options = _split(args)
    bar = _Bar(args.quiet)
    main_thread = threading.current_thread() is threading.main_thread()
    # `kill` (SIGTERM) cleans up like Ctrl-C; signal handlers can only be set from the main thread.
    previous = signal.signal(signal.SIGTERM, _sigterm_as_interrupt) if main_thread else None
    out = Path(args.out)
    existed, before = out.exists(), file_id(out / "summary.json")
    try:
        records = run_batch(
            args.batch_command, args.inputs, args.out, options=command_options, workers=args.workers,
            threads_per_worker=args.threads_per_worker, memory_limit=args.memory_limit, scheduler=args.scheduler,
            retries=args.retries, timeout=args.timeout, resume=args.resume, overwrite=args.overwrite,
            figure=not args.no_figure, progress=bar,
        )
    except KeyboardInterrupt as exc:  # SIGTERM too: say what --out now holds
        bar.close()
        from . import EXIT_INTERRUPTED, EXIT_TERMINATED, Terminated

        terminated = isinstance(exc, Terminated)
        what = "terminated" if terminated else "interrupted"
        sys.stderr.write(f"nurbskit batch: {what}; {_left_behind(out, existed, before)}\n")
        raise SystemExit(EXIT_TERMINATED if terminated else EXIT_INTERRUPTED) from None
    finally:
        bar.close()
        if main_thread:
            signal.signal(signal.SIGTERM, previous)
    ok = sum(r["status"] == "ok" for r in records)
    resumed = sum(bool(r.get("resumed")) for r in records)
    failed = len(records) - ok
    print(f"{ok} ok ({resumed} finished before), {failed} failed of {len(records)} inputs; "
          f"summary in {args.out}/summary.csv")
    return 0 if failed == 0 else 1

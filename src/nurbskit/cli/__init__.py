"""The ``nurbskit`` command line.

Each command lives in its own module with a ``register(subparsers)`` function that
adds its parser and sets ``run=callable(args) -> int``. ``main`` turns every
:class:`~nurbskit.errors.NurbskitError` (and argparse's usage errors) into one line on
stderr and a non-zero exit, and any other exception into one line too (exit 1; the
traceback with ``--debug``); Ctrl-C exits with 130 and SIGTERM with 143, at any
moment, and leave no half-written output (see :mod:`nurbskit._fs`).
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import os
import signal
import sys
import threading
import traceback

from .. import _fs
from ..errors import NurbskitError

# Command modules, imported lazily by name so that `nurbskit info` does not load the fitter.
COMMAND_MODULES = (
    "nurbskit.cli.io_commands",
    "nurbskit.cli.fit_command",
    "nurbskit.cli.volume_command",
    "nurbskit.cli.studio_command",
    "nurbskit.cli.export_command",
    "nurbskit.cli.patches_command",
    "nurbskit.cli.batch_command",
    "nurbskit.cli.shape_command",
    "nurbskit.cli.curves_command",
    "nurbskit.cli.train_command",
    "nurbskit.cli.revolve_image_command",
)

EXIT_BUG = 1
EXIT_USER_ERROR = 2
EXIT_INTERRUPTED = 130
EXIT_TERMINATED = 143


_ARGV: list[str] = []  # the arguments being parsed, for the messages of _Parser.error


class _Parser(argparse.ArgumentParser):
    """argparse with one-line errors (no usage dump): `nurbskit fit: error: ...`."""

    def error(self, message: str):  # noqa: D401 - argparse API
        if message.endswith(("expected one argument", "expected at least one argument")):
            # argparse takes the value of "--ctrl -3x5" for an option: say how to give it
            names = message.split(":", 1)[0].removeprefix("argument ").split("/")
            for given, value in zip(_ARGV, _ARGV[1:]):
                if given in names and value.startswith("-") and len(value) > 1:
                    long = next((n for n in names if n.startswith("--")), None)
                    message += f" (a value that starts with '-' is written {f'{long}={value}' if long else given + value})"
                    break
        sys.stderr.write(f"{self.prog}: error: {message}\n")
        raise SystemExit(EXIT_USER_ERROR)


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The parser of every command, or only of ``command`` when its module is
    ``nurbskit.cli.<command>_command`` (so that ``nurbskit studio`` does not import the
    fitter, and torch, through the other commands' modules before it starts)."""
    from .. import __version__

    parser = _Parser(prog="nurbskit", description="NURBS geometry from point clouds, meshes and silhouettes.")
    parser.add_argument("--version", action="version", version=f"nurbskit {__version__}")
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    own = f"nurbskit.cli.{command.replace('-', '_')}_command" if command else None
    for name in (own,) if own in COMMAND_MODULES else COMMAND_MODULES:
        importlib.import_module(name).register(subparsers)
    return parser


def _command_of(argv: list[str] | None) -> str | None:
    """The command a command line names (its first word that is not an option), if any."""
    words = sys.argv[1:] if argv is None else argv
    for word in words:
        if not word.startswith("-"):
            return word
    return None


def _add_debug(parser: argparse.ArgumentParser) -> None:
    """``--debug`` on the top-level parser and on every command (``nurbskit fit ... --debug``)."""
    parser.add_argument("--debug", action="store_true", help="show the traceback of an unexpected error")
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for sub in action.choices.values():
                sub.add_argument("--debug", action="store_true", default=argparse.SUPPRESS,
                                 help="show the traceback of an unexpected error")


def _input_of(args) -> str | None:
    """The file a command was working on, for the last-resort message."""
    for name in ("input", "file", "mesh", "front"):
        value = getattr(args, name, None)
        if isinstance(value, (str, bytes)) or hasattr(value, "__fspath__"):
            return str(value)
    return None


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised like Ctrl-C so that the same clean-up removes partial outputs."""


_RECEIVED: list[int] = []  # signals that arrived during main(): a library may wrap what they raise


def _on_signal(signum, frame):  # noqa: ARG001 - signal handler signature
    _RECEIVED.append(signum)
    raise Terminated if signum == signal.SIGTERM else KeyboardInterrupt


def main(argv: list[str] | None = None) -> int:
    """Run one command; returns the exit status.

    Exit status: 0 success; 2 a user's mistake (one line on stderr, from a
    :class:`~nurbskit.errors.NurbskitError`, an OS error or argparse); 1 an unexpected
    error (one line naming the command, the file and the exception, the traceback with
    ``--debug`` or ``NURBSKIT_DEBUG=1``); 130 Ctrl-C and 143 SIGTERM, at any moment,
    with no partial output and no traceback.
    """
    previous = {}
    if threading.current_thread() is threading.main_thread():
        for signum in (signal.SIGINT, signal.SIGTERM):
            with contextlib.suppress(ValueError, OSError):
                previous[signum] = signal.signal(signum, _on_signal)
    _RECEIVED.clear()
    try:
        return _main(argv)
    finally:
        for signum, handler in previous.items():
            with contextlib.suppress(ValueError, OSError, TypeError):
                signal.signal(signum, handler)


def _main(argv: list[str] | None) -> int:
    command = "nurbskit"
    args = None
    debug = os.environ.get("NURBSKIT_DEBUG", "") not in ("", "0")
    try:
        parser = build_parser(_command_of(argv))
        _add_debug(parser)
        _ARGV[:] = list(sys.argv[1:] if argv is None else argv)
        args = parser.parse_args(argv)
        debug = debug or bool(getattr(args, "debug", False))
        if getattr(args, "run", None) is None:
            parser.print_help(sys.stderr)
            return EXIT_USER_ERROR
        command = f"nurbskit {args.command}"
        _fs.COMMAND = command  # recorded in the output folders' manifests (for this call only)
        try:
            return int(args.run(args) or 0)
        finally:
            _fs.COMMAND = None
    except NurbskitError as exc:
        if _RECEIVED:
            return _signalled(command)
        _say(f"{command}: error: {_one_line(exc)}")
        return EXIT_USER_ERROR
    except OSError as exc:  # disk full, permission denied: the OS's own words, one line
        if _RECEIVED:
            return _signalled(command)
        if debug:
            traceback.print_exc()
        where = f"{exc.filename}: " if exc.filename else ""
        _say(f"{command}: error: {where}{exc.strerror or _one_line(exc)}")
        return EXIT_USER_ERROR
    except MemoryError:
        where = _input_of(args) if args is not None else None
        _say(f"{command}: error: {where + ': ' if where else ''}out of memory; the input or the options ask for more "
             "than this machine has")
        return EXIT_USER_ERROR
    except Terminated:
        _say(f"{command}: terminated; no partial output was left behind")
        return EXIT_TERMINATED
    except KeyboardInterrupt:
        _say(f"{command}: interrupted; no partial output was left behind")
        return EXIT_INTERRUPTED
    except SystemExit:
        raise
    except BaseException as exc:  # the last line of defence: a bug, said in one line
        # A signal that a library turned into something else (numpy makes Ctrl-C during its
        # import an ImportError without the KeyboardInterrupt in the chain).
        if _RECEIVED or _caused_by_interrupt(exc):
            return _signalled(command)
        if debug:
            traceback.print_exc()
        where = _input_of(args) if args is not None else None
        _say(f"{command}: error: {where + ': ' if where else ''}unexpected {type(exc).__name__}: {_one_line(exc)}"
             + ("" if debug else "; run with --debug for the details"))
        return EXIT_BUG


def _signalled(command: str) -> int:
    if signal.SIGTERM in _RECEIVED:
        _say(f"{command}: terminated; no partial output was left behind")
        return EXIT_TERMINATED
    _say(f"{command}: interrupted; no partial output was left behind")
    return EXIT_INTERRUPTED


def _caused_by_interrupt(exc: BaseException) -> bool:
    """Whether a KeyboardInterrupt is somewhere in the exception's chain of causes."""
    seen = set()
    while exc is not None and id(exc) not in seen:
        if isinstance(exc, KeyboardInterrupt):
            return True
        seen.add(id(exc))
        exc = exc.__cause__ or exc.__context__
    return False


def _one_line(exc: BaseException) -> str:
    text = " ".join(str(exc).split())
    return text if len(text) <= 500 else text[:497] + "..."


def _say(line: str) -> None:
    with contextlib.suppress(OSError, ValueError):  # a closed stderr must not turn into a traceback
        sys.stderr.write(line + "\n")
        sys.stderr.flush()


def entry() -> None:  # pragma: no cover - console script shim
    """The ``nurbskit`` console script: ``main`` with Ctrl-C covered from the first instruction."""
    try:
        status = main()
    except KeyboardInterrupt:  # between main's own handlers (e.g. while it returns)
        _say("nurbskit: interrupted")
        status = EXIT_INTERRUPTED
    if status in (EXIT_INTERRUPTED, EXIT_TERMINATED):
        # Interrupted work may leave torch's worker threads mid-operation; tearing the
        # interpreter down under them crashed (SIGSEGV) in about 1 run in 10. The outputs
        # are already cleaned up and the message said: end the process here.
        for stream in (sys.stdout, sys.stderr):
            with contextlib.suppress(Exception):
                stream.flush()
        os._exit(status)
    raise SystemExit(status)

"""The ``nurbskit`` command line.

Each command lives in its own module with a ``register(subparsers)`` function that
adds its parser and sets ``run=callable(args) -> int``. ``main`` turns every
:class:`~nurbskit.errors.NurbskitError` (and argparse's usage errors) into one line on
stderr and a non-zero exit; Ctrl-C exits with 130 and leaves no half-written output
(see :mod:`nurbskit._fs`).
"""

from __future__ import annotations

import argparse
import importlib
import sys

from ..errors import NurbskitError

# Command modules, imported lazily by name so that `nurbskit info` does not load the fitter.
COMMAND_MODULES = (
    "nurbskit.cli.io_commands",
    "nurbskit.cli.fit_command",
    "nurbskit.cli.volume_command",
    "nurbskit.cli.shape_command",
)

EXIT_USER_ERROR = 2
EXIT_INTERRUPTED = 130


class _Parser(argparse.ArgumentParser):
    """argparse with one-line errors (no usage dump): `nurbskit fit: error: ...`."""

    def error(self, message: str):  # noqa: D401 - argparse API
        sys.stderr.write(f"{self.prog}: error: {message}\n")
        raise SystemExit(EXIT_USER_ERROR)


def build_parser() -> argparse.ArgumentParser:
    from .. import __version__

    parser = _Parser(prog="nurbskit", description="NURBS geometry from point clouds, meshes and silhouettes.")
    parser.add_argument("--version", action="version", version=f"nurbskit {__version__}")
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    for name in COMMAND_MODULES:
        try:
            module = importlib.import_module(name)
        except ModuleNotFoundError as exc:
            if exc.name == name:  # a command module not written yet
                continue
            raise
        module.register(subparsers)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if getattr(args, "run", None) is None:
        parser.print_help(sys.stderr)
        return EXIT_USER_ERROR
    try:
        return int(args.run(args) or 0)
    except NurbskitError as exc:
        sys.stderr.write(f"nurbskit {args.command}: error: {exc}\n")
        return EXIT_USER_ERROR
    except OSError as exc:  # disk full, permission denied: the OS's own words, one line
        where = f"{exc.filename}: " if exc.filename else ""
        sys.stderr.write(f"nurbskit {args.command}: error: {where}{exc.strerror or exc}\n")
        return EXIT_USER_ERROR
    except MemoryError:
        sys.stderr.write(f"nurbskit {args.command}: error: out of memory; the input is too large for this machine\n")
        return EXIT_USER_ERROR
    except KeyboardInterrupt:
        sys.stderr.write(f"nurbskit {args.command}: interrupted; no partial output was left behind\n")
        return EXIT_INTERRUPTED


def entry() -> None:  # pragma: no cover - console script shim
    raise SystemExit(main())

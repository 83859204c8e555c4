"""Options shared by the commands: device and dtype, ranges, sizes, and options generated from a config.

* :func:`add_device_options` / :func:`device_and_dtype`: the one ``--device`` / ``--dtype``
  parser. Convention: these options only move the inputs; the library then runs on the
  inputs' own device and dtype.
* :func:`int_in`, :func:`number_in`: argparse types that check a range and say it.
* :func:`add_config_options` / :func:`config_from_args`: one option per field of a
  configuration dataclass whose ``metadata`` holds ``help`` and optionally ``low``,
  ``high``, ``low_open``, ``choices`` and ``flag`` (see
  :class:`nurbskit.volume.config.VolumeFitConfig`); every option defaults to None,
  meaning "the preset's value".
* :func:`resume_hint`: how to continue an interrupted ``train`` or ``batch``.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import shlex
import sys

from ..errors import OptionError

DTYPES = ("float32", "float64")


def parse_device(text: str):
    """``"cpu"``, ``"cuda"``, ``"cuda:1"`` -> a ``torch.device`` that exists here; an OptionError otherwise."""
    import torch

    try:
        device = torch.device(text)
    except (RuntimeError, TypeError, ValueError):
        raise OptionError(f"--device: expected cpu or cuda[:N], got {text!r}") from None
    if device.type == "cuda":
        if not torch.cuda.is_available():
            raise OptionError(f"--device {text}: torch sees no CUDA device on this machine")
        if device.index is not None and device.index >= torch.cuda.device_count():
            raise OptionError(
                f"--device {text}: this machine has {torch.cuda.device_count()} CUDA device(s), cuda:0 to "
                f"cuda:{torch.cuda.device_count() - 1}"
            )
    elif device.type != "cpu":
        raise OptionError(f"--device: expected cpu or cuda[:N], got {text!r}")
    return device


def add_device_options(parser: argparse.ArgumentParser, *, dtype_default: str) -> None:
    """``--device`` (default cpu) and ``--dtype`` (``dtype_default``): where the inputs are moved."""
    parser.add_argument("--device", default="cpu", metavar="DEVICE",
                        help="torch device the inputs are moved to, and the work runs on: cpu or cuda[:N] (default cpu)")
    parser.add_argument("--dtype", choices=DTYPES, default=dtype_default,
                        help=f"floating-point type the inputs are converted to (default {dtype_default})")


def device_and_dtype(args) -> tuple:
    """``(torch.device, torch.dtype)`` of :func:`add_device_options`'s options, checked."""
    import torch

    return parse_device(args.device), {"float32": torch.float32, "float64": torch.float64}[args.dtype]


def _range_text(low, high, low_open=False) -> str:
    def fmt(x):
        return str(x) if isinstance(x, int) else f"{x:g}"

    if high is None:
        return f"> {fmt(low)}" if low_open else f">= {fmt(low)}"
    return f"in {'(' if low_open else '['}{fmt(low)}, {fmt(high)}]"


def int_in(low: int, high: int | None = None):
    """An argparse type: an integer in ``[low, high]``, the range in the message otherwise."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected an integer {_range_text(low, high)}, got {text!r}") from None
        if value < low or (high is not None and value > high):
            raise argparse.ArgumentTypeError(f"expected an integer {_range_text(low, high)}, got {value}")
        return value

    return parse


def number_in(low: float | None = None, high: float | None = None, *, low_open: bool = False):
    """An argparse type: a finite number in the range (``(low, high]`` when ``low_open``)."""

    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
        if not math.isfinite(value):
            raise argparse.ArgumentTypeError(f"expected a finite number, got {text!r}")
        if low is not None and (value < low or (low_open and value == low)) or high is not None and value > high:
            raise argparse.ArgumentTypeError(f"expected a number {_range_text(low, high, low_open)}, got {text}")
        return value

    return parse


def sizes_in(low: int, high: int, count: int = 3):
    """An argparse type: one integer or ``count`` of them (``64``, ``64x48x32``), each in ``[low, high]``."""

    def parse(text: str) -> tuple[int, ...]:
        parts = str(text).lower().replace(",", "x").split("x")
        try:
            values = tuple(int(p) for p in parts)
        except ValueError:
            raise argparse.ArgumentTypeError(
                f"expected one integer or {count} like {'x'.join(['32'] * count)}, got {text!r}"
            ) from None
        if len(values) == 1:
            values = values * count
        if len(values) != count or min(values) < low or max(values) > high:
            raise argparse.ArgumentTypeError(
                f"expected one integer or {count}, each in [{low}, {high}], got {text!r}"
            )
        return values

    return parse


def add_config_options(parser: argparse.ArgumentParser, cls, defaults, skip: tuple[str, ...] = ()) -> None:
    """One option per field of the dataclass ``cls`` (help, range, choices from its metadata).

    ``defaults`` (an instance, the default preset) supplies the defaults shown in the help;
    the options themselves default to None so that a preset's value stays unless given.
    """
    for f in dataclasses.fields(cls):
        if f.name in skip:
            continue
        meta = f.metadata
        flag = "--" + (meta.get("flag") or f.name).replace("_", "-")
        default = getattr(defaults, f.name)
        shown = "x".join(map(str, default)) if isinstance(default, tuple) else default
        help_text = meta.get("help", "") + ("" if default is None else f" (default {shown})")
        kw: dict = {"default": None, "dest": f.name}
        if meta.get("choices"):
            kw["choices"] = meta["choices"]
        elif isinstance(default, tuple) or f.name.endswith(("size", "grid", "resolution")) and not isinstance(default, int):
            kw["type"] = sizes_in(meta["low"], meta["high"])
            kw["metavar"] = "N|NxNxN"
        elif isinstance(f.default, bool):
            kw["action"] = argparse.BooleanOptionalAction
        elif isinstance(f.default, int):
            kw["type"] = int_in(meta["low"], meta["high"])
            kw["metavar"] = "N"
        else:
            kw["type"] = number_in(meta.get("low"), meta.get("high"), low_open=bool(meta.get("low_open")))
            kw["metavar"] = "X"
        parser.add_argument(flag, help=help_text, **kw)


def config_from_args(args, base, skip: tuple[str, ...] = ()):
    """``base`` (a preset instance) with every option of :func:`add_config_options` that was given."""
    changes = {
        f.name: getattr(args, f.name)
        for f in dataclasses.fields(base)
        if f.name not in skip and getattr(args, f.name, None) is not None
    }
    return dataclasses.replace(base, **changes).validate()


def resume_hint(command: str) -> str:
    """How to continue an interrupted ``command`` (``"train"``, ``"batch"``): the command
    line as typed, without ``--overwrite`` and with ``--resume`` (before a ``--`` that
    starts another command's options)."""
    argv = sys.argv[1:]
    if argv[:1] != [command]:  # called in-process (tests, scripts): sys.argv is not this command
        return "run the same command with --resume (without --overwrite) to continue"
    end = argv.index("--") if "--" in argv else len(argv)
    own = [a for a in argv[:end] if a != "--overwrite"]
    argv = own + ([] if "--resume" in own else ["--resume"]) + argv[end:]
    return "continue with: nurbskit " + " ".join(shlex.quote(a) for a in argv)

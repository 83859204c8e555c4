"""JSON with bounded nesting: a file nested 100,000 levels deep is an error, not a RecursionError.

Python's ``json`` module recurses once per level and raises ``RecursionError`` (or
exhausts the C stack) on deep input. The depth is measured first, without recursion:
strings are blanked out (they may hold brackets), then the running count of open
brackets is a cumulative sum over the bytes.
"""

from __future__ import annotations

import json
import sys
import re
from pathlib import Path

import numpy as np

from ..errors import InputError
from ._base import read_bytes

MAX_DEPTH = 64  # NURBS files nest 4 or 5 levels; 64 leaves room for any sane producer
_STRING = re.compile(rb'"(?:[^"\\]|\\.)*"', re.DOTALL)


def nesting_depth(text: bytes) -> int:
    """The deepest nesting of ``[`` and ``{`` in JSON text (brackets inside strings ignored).

    Example:
        >>> nesting_depth(b'{"a": [1, [2, "]]]"]]}')
        3
    """
    bare = np.frombuffer(_STRING.sub(b'""', text), np.uint8)
    step = np.zeros(bare.shape, np.int64)
    step[(bare == ord("[")) | (bare == ord("{"))] = 1
    step[(bare == ord("]")) | (bare == ord("}"))] = -1
    return int(np.cumsum(step).max(initial=0))


def loads(path: Path, text: bytes, max_depth: int = MAX_DEPTH):
    """Parse JSON ``text`` read from ``path``; InputError (one line) for anything malformed."""
    depth = nesting_depth(text)
    if depth > max_depth:
        raise InputError(f"{path}: JSON is nested {depth:,} levels deep; at most {max_depth} are allowed")
    try:
        return json.loads(text)
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        where = f" at line {exc.lineno}" if isinstance(exc, json.JSONDecodeError) else ""
        raise InputError(f"{path}: not valid JSON{where} ({getattr(exc, 'msg', exc)})") from None
    except (RecursionError, ValueError) as exc:  # a 5,000-digit integer; depth already bounded
        if "digits" in str(exc):
            raise InputError(f"{path}: JSON holds an integer of more than {sys.get_int_max_str_digits():,} digits; "
                             f"no field of a nurbskit file needs one") from None
        raise InputError(f"{path}: JSON cannot be read ({exc})") from None


def load_json(path: str | Path, max_depth: int = MAX_DEPTH):
    """The JSON value of the file at ``path``, with nesting bounded by ``max_depth``.

    Example:
        >>> load_json("duck.json")["format"]  # doctest: +SKIP
        'nurbskit'
    """
    path = Path(path)
    return loads(path, read_bytes(path), max_depth)

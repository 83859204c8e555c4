"""Optional extras in tests: skip with a reason when missing, FAIL when CI requires them.

CI sets ``NURBSKIT_REQUIRE_EXTRAS=1``: there a test that needs ``[cad]`` (rhino3dm) or
``[pcd]`` (python-lzf) cannot pass by skipping.

Example:
    >>> lzf = require_extra("lzf", "pcd")  # doctest: +SKIP
"""

from __future__ import annotations

import importlib
import os

import pytest


def extras_required() -> bool:
    return os.environ.get("NURBSKIT_REQUIRE_EXTRAS", "") not in ("", "0")


def require_extra(module: str, extra: str, *, module_level: bool = False):
    """Import ``module``; without it, fail under NURBSKIT_REQUIRE_EXTRAS=1, skip otherwise
    (the whole test module with ``module_level=True``)."""
    try:
        return importlib.import_module(module)
    except ImportError:
        missing(f"needs the optional package {module!r} (pip install 'nurbskit[{extra}]')", module_level)


def missing(message: str, module_level: bool = False):
    """Fail under NURBSKIT_REQUIRE_EXTRAS=1, skip (with ``message``) otherwise."""
    if extras_required():
        pytest.fail(f"NURBSKIT_REQUIRE_EXTRAS is set but {message}")
    pytest.skip(message, allow_module_level=module_level)

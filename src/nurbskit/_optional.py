"""Lazy loading of optional dependencies with a message that names the extra."""

import importlib
from types import ModuleType

from .errors import NurbskitError


def require(module: str, extra: str, purpose: str = "") -> ModuleType:
    """Import ``module`` or raise a NurbskitError that says which extra installs it.

    Example:
        >>> rhino3dm = require("rhino3dm", "cad", "reading .3dm files")  # doctest: +SKIP
    """
    try:
        return importlib.import_module(module)
    except ImportError as exc:  # pragma: no cover - depends on the environment
        what = f" for {purpose}" if purpose else ""
        raise NurbskitError(
            f"the optional package '{module}' is needed{what}; "
            f"install it with: pip install 'nurbskit[{extra}]'"
        ) from exc

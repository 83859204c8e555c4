"""``nurbskit studio``: the thesis's visual tool (section 5.2), in the browser.

A viser server (the ``[studio]`` extra) with one tab per capability of the library:
Unsupervised and Supervised fitting, the NURBS Generator, Patches (multi-patch fitting),
Revolve / Extrude, Volume from drawings, and more tabs as capabilities land (see
:mod:`.registry`). The studio holds no reconstruction logic: every tab calls nurbskit's
public API.

Example:
    >>> from nurbskit.studio import StudioOptions, Studio   # doctest: +SKIP
    >>> studio = Studio(StudioOptions(port=0, workdir="data")).start()  # doctest: +SKIP
    >>> studio.url  # doctest: +SKIP
    'http://127.0.0.1:8080/'
"""

from .registry import TABS, TabSpec, available_tabs
from .workdir import Workdir

__all__ = ["Studio", "StudioOptions", "TABS", "TabSpec", "available_tabs", "Workdir", "launch"]


def __getattr__(name: str):
    # app imports viser lazily, but keep even its import off `import nurbskit.studio`
    if name in ("Studio", "StudioOptions"):
        from . import app

        return getattr(app, name)
    raise AttributeError(f"module 'nurbskit.studio' has no attribute {name!r}")


def launch(**options):
    """Start a studio (keyword arguments of :class:`StudioOptions`) and return it."""
    from .app import Studio, StudioOptions

    return Studio(StudioOptions(**options)).start()

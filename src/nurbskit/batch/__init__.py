"""``nurbskit batch``: one command over many inputs on Dask, resumable, nothing lost.

Example:
    >>> from nurbskit import batch
    >>> records = batch.run("fit", ["clouds/"], "fits/", options=["--iters", "200"])  # doctest: +SKIP
    >>> [(r["name"], r["status"], r["metrics"].get("to_surface_p95")) for r in records]  # doctest: +SKIP

``import nurbskit.batch`` does not import Dask: :func:`run` loads it (the ``[dist]``
extra) when there is work to do. See ``docs/batch.md``.
"""

from .commands import COMMANDS, BatchCommand, Item, get_command, register
from .inputs import find_items
from .runner import run
from .task import MARKER, run_item

__all__ = ["run", "register", "get_command", "find_items", "run_item", "BatchCommand", "Item", "COMMANDS", "MARKER"]

"""What the tabs offer, read from the library's source without running it.

Issue 13 wants the page interactive within 3 s of ``nurbskit studio``; importing the
capabilities (torch and the fitting code) alone takes longer than that on a small CPU.
So the tabs' widgets are built from plain data: whether a capability exists, the names
of the pipelines, the kinds of shapes, the CAD formats. This module reads that data
from the modules that declare it with Python's :mod:`ast` (nothing is executed, nothing
is imported), and the capabilities themselves are imported in the background and on
first use (see :mod:`.app`).

The library stays the one source of truth: nothing here is a copy of its tables. A
reading that fails (the declaration changed shape, the source is not a ``.py`` file)
falls back to importing the module, which is slower and never wrong; the unit tests
assert that every reading equals the live value, so such a change is caught in CI.

Convention: ``module`` is a dotted name inside ``nurbskit``; "declares ``name``" means
a top-level binding of the module (``def``, ``class``, an assignment, an import),
including those under a top-level ``if`` or ``try``.
"""

from __future__ import annotations

import ast
import functools
import importlib
import importlib.util
from pathlib import Path


@functools.lru_cache(maxsize=None)
def source_tree(module: str) -> ast.Module | None:
    """The parsed source of ``module`` (a ``nurbskit`` module), found without importing it.

    Importing ``nurbskit.fit.pipelines`` would run ``nurbskit/fit/__init__.py``, which
    imports torch; the file is found from the ``nurbskit`` package's folder instead.
    None when there is no such source file.
    """
    import nurbskit

    parts = module.split(".")
    if parts[0] != "nurbskit":
        return None
    base = Path(nurbskit.__file__).parent.joinpath(*parts[1:])
    for path in (base.parent / f"{base.name}.py", base / "__init__.py"):
        if path.is_file():
            return ast.parse(path.read_text(encoding="utf-8"), str(path))
    return None


def _statements(body):
    """Top-level statements, looking into ``if`` / ``try`` blocks (their bindings are top-level)."""
    for node in body:
        yield node
        if isinstance(node, ast.If):
            yield from _statements(node.body)
            yield from _statements(node.orelse)
        elif isinstance(node, ast.Try):
            for block in (node.body, node.orelse, node.finalbody, *(h.body for h in node.handlers)):
                yield from _statements(block)


def _targets(node) -> list[str]:
    if isinstance(node, ast.Name):
        return [node.id]
    if isinstance(node, (ast.Tuple, ast.List)):
        return [n for elt in node.elts for n in _targets(elt)]
    return []


def top_level_names(tree: ast.Module) -> set[str]:
    """Every name a module binds at its top level."""
    names: set[str] = set()
    for node in _statements(tree.body):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            names.add(node.name)
        elif isinstance(node, ast.Assign):
            for target in node.targets:
                names.update(_targets(target))
        elif isinstance(node, (ast.AnnAssign, ast.AugAssign)):
            names.update(_targets(node.target))
        elif isinstance(node, ast.Import):
            names.update(a.asname or a.name.split(".")[0] for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            names.update(a.asname or a.name for a in node.names if a.name != "*")
    return names


def exists(module: str) -> bool:
    """True when ``module`` has a source file (static; the import itself may still fail)."""
    if source_tree(module) is not None:
        return True
    try:  # not a nurbskit module, or not a .py file: ask the import system
        return importlib.util.find_spec(module) is not None
    except (ImportError, ValueError):
        return False


def declares(module: str, name: str) -> bool:
    """True when ``module`` binds ``name`` at its top level; imports it only when its source cannot be read."""
    tree = source_tree(module)
    if tree is not None:
        return name in top_level_names(tree)
    try:
        return hasattr(importlib.import_module(module), name)
    except ImportError:
        return False


def constant(module: str, name: str):
    """The literal value ``module`` assigns to ``name`` (e.g. a tuple of names), else imported."""
    tree = source_tree(module)
    for node in _statements(tree.body if tree is not None else []):
        if isinstance(node, ast.Assign) and any(name in _targets(t) for t in node.targets):
            try:
                return ast.literal_eval(node.value)
            except ValueError:
                break
        if isinstance(node, ast.AnnAssign) and name in _targets(node.target) and node.value is not None:
            try:
                return ast.literal_eval(node.value)
            except ValueError:
                break
    return getattr(importlib.import_module(module), name)


def decorator_calls(module: str, decorator: str) -> list[tuple[tuple, dict]] | None:
    """``(args, kwargs)`` of every ``@decorator(...)`` on a top-level function, in source order.

    None when a call has an argument that is not a literal (it cannot be read statically).
    """
    tree = source_tree(module)
    if tree is None:
        return None
    out = []
    for node in _statements(tree.body):
        if not isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            continue
        for dec in node.decorator_list:
            if isinstance(dec, ast.Call) and isinstance(dec.func, ast.Name) and dec.func.id == decorator:
                try:
                    args = tuple(ast.literal_eval(a) for a in dec.args)
                    kwargs = {k.arg: ast.literal_eval(k.value) for k in dec.keywords}
                except ValueError:
                    return None
                if None in kwargs:  # **mapping
                    return None
                out.append((args, kwargs))
    return out


# ---- what the tabs offer ------------------------------------------------------------------

PIPELINES_MODULE = "nurbskit.fit.pipelines"


def pipelines(supervised: bool) -> tuple[str, ...]:
    """The names of the registered fitting pipelines that do (not) need a supervised target.

    Read from the ``@register(name, supervised, summary)`` lines of
    :mod:`nurbskit.fit.pipelines`, in registration order (the order of ``PIPELINES``).
    """
    calls = decorator_calls(PIPELINES_MODULE, "register")
    names = []
    try:
        for args, kwargs in calls or ():
            bound = dict(zip(("name", "supervised", "summary"), args), **kwargs)
            if bool(bound["supervised"]) == supervised:
                names.append(str(bound["name"]))
    except KeyError:
        calls = None
    if not calls:
        from ..fit.pipelines import PIPELINES  # imports torch: the slow, always-right way

        return tuple(k for k, p in PIPELINES.items() if p.supervised == supervised)
    return tuple(names)


def shape_kinds() -> tuple[str, ...]:
    """The kinds ``nurbskit.shapes.fit_shape`` accepts (``KINDS`` of :mod:`nurbskit.shapes.fit`)."""
    return tuple(constant("nurbskit.shapes.fit", "KINDS"))


def volume_losses() -> tuple[str, ...]:
    """The costs ``nurbskit.fit_silhouettes`` offers (``LOSSES`` of :mod:`nurbskit.volume.config`)."""
    return tuple(constant("nurbskit.volume.config", "LOSSES"))


def warm() -> None:
    """Read everything the tabs ask for now, so that the first page is built from the cache."""
    for supervised in (False, True):
        pipelines(supervised)
    shape_kinds()
    volume_losses()

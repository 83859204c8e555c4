"""The tabs of the studio, and the capability each one needs.

A tab is listed with the module (and, optionally, the attribute) its capability lives
in; it appears on the page only when that module exists and declares the attribute. So
a capability that another part of nurbskit adds later (multi-patch fitting in
``nurbskit.patches``, CAD exchange in ``nurbskit.io.cad``) shows up in the studio with
no change here beyond its line in :data:`TABS` and its builder.

Whether a capability exists is read from its source (:mod:`.choices`), not by importing
it: the capabilities import torch, which takes longer than the page may (issue 13: the
page is interactive within 3 s). They are imported in the background once the page is
up (:meth:`TabSpec.load`); one that then fails to import says so in its tab.

Convention: a builder is ``build(session, ui) -> Tab`` where ``ui`` is the client's GUI
API inside the tab's context and ``Tab`` has ``scene_root`` (the scene-tree node under
which the tab draws) and ``shown()`` (the objects an export writes).
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass

from . import choices


@dataclass(frozen=True)
class TabSpec:
    """One tab: its label, the module/attribute it needs, and where its builder lives."""

    label: str
    requires: str
    attribute: str | None
    builder: str  # "module:function" inside nurbskit.studio

    def available(self) -> bool:
        """True when the capability's module exists (and declares ``attribute``): read, not imported."""
        if not choices.exists(self.requires):
            return False
        return self.attribute is None or choices.declares(self.requires, self.attribute)

    def load(self) -> None:
        """Import the capability (torch and all); raises ImportError naming what is missing."""
        module = importlib.import_module(self.requires)
        if self.attribute is not None and not hasattr(module, self.attribute):
            raise ImportError(f"{self.requires} has no {self.attribute}")

    def load_builder(self):
        module, _, name = self.builder.partition(":")
        mod = importlib.import_module(module)
        return getattr(mod, name, None)


TABS: tuple[TabSpec, ...] = (
    TabSpec("Unsupervised", "nurbskit.fit", "fit_surface", "nurbskit.studio.tabs:build_unsupervised"),
    TabSpec("Supervised", "nurbskit.fit", "fit_surface", "nurbskit.studio.tabs:build_supervised"),
    TabSpec("NURBS Generator", "nurbskit.core.ops", "split", "nurbskit.studio.generator:build_generator"),
    # Multi-patch fitting (nurbskit.fit_patches -> PatchSet): the tab appears once the
    # module exists; its builder lives beside the others (see docs/studio.md).
    TabSpec("Patches", "nurbskit.patches", "fit_patches", "nurbskit.studio.tabs:build_patches"),
    TabSpec("Revolve / Extrude", "nurbskit.shapes", "fit_shape", "nurbskit.studio.tabs:build_shape"),
    TabSpec("Curves from images", "nurbskit.curves", None, "nurbskit.studio.tabs:build_curves"),
    TabSpec("Volume from drawings", "nurbskit.volume", "fit_silhouettes", "nurbskit.studio.tabs:build_volume"),
)


def available_tabs() -> list[TabSpec]:
    """The tabs whose capability exists and whose builder exists, in display order (imports no capability)."""
    out = []
    for spec in TABS:
        if spec.available() and spec.load_builder() is not None:
            out.append(spec)
    return out


# Export formats beyond nurbskit's own: (label, extension, module, writer attribute).
CAD_WRITERS = (
    ("STEP", ".step", "nurbskit.io.cad", "write_cad"),
    ("IGES", ".iges", "nurbskit.io.cad", "write_cad"),
    ("BREP", ".brep", "nurbskit.io.cad", "write_cad"),
)


def _deferred(module: str, attr: str):
    """``module.attr(...)``, imported on the first call (the CAD code imports torch)."""

    def writer(*args, **kwargs):
        return getattr(importlib.import_module(module), attr)(*args, **kwargs)

    writer.__qualname__ = f"{module}.{attr}"
    return writer


def cad_writers() -> dict[str, tuple[str, object]]:
    """``{label: (extension, writer)}`` for the CAD writers that exist now (imported on first use)."""
    return {label: (ext, _deferred(module, attr)) for label, ext, module, attr in CAD_WRITERS
            if choices.declares(module, attr)}

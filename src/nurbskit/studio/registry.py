"""The tabs of the studio, and the capability each one needs.

A tab is listed with the module (and, optionally, the attribute) its capability lives
in; it appears on the page only when that module imports and has the attribute. So a
capability that another part of nurbskit adds later (multi-patch fitting in
``nurbskit.patches``, CAD exchange in ``nurbskit.io.cad``) shows up in the studio with
no change here beyond its line in :data:`TABS` and its builder.

Convention: a builder is ``build(session, ui) -> Tab`` where ``ui`` is the client's GUI
API inside the tab's context and ``Tab`` has ``scene_root`` (the scene-tree node under
which the tab draws) and ``shown()`` (the objects an export writes).
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass


@dataclass(frozen=True)
class TabSpec:
    """One tab: its label, the module/attribute it needs, and where its builder lives."""

    label: str
    requires: str
    attribute: str | None
    builder: str  # "module:function" inside nurbskit.studio

    def available(self) -> bool:
        """True when the capability imports (and has ``attribute``)."""
        try:
            module = importlib.import_module(self.requires)
        except ImportError:
            return False
        return self.attribute is None or hasattr(module, self.attribute)

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
    """The tabs whose capability imports and whose builder exists, in display order."""
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


def cad_writers() -> dict[str, tuple[str, object]]:
    """``{label: (extension, writer)}`` for the CAD writers that exist now."""
    out = {}
    for label, ext, module, attr in CAD_WRITERS:
        try:
            writer = getattr(importlib.import_module(module), attr, None)
        except ImportError:
            writer = None
        if callable(writer):
            out[label] = (ext, writer)
    return out

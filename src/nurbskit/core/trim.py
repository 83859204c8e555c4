"""Trimmed surfaces: a NURBS surface and closed loops in its (u, v) domain.

The one representation that multi-patch fitting writes, CAD exchange turns into faces
with wires, and the studio draws.

Convention:
    A loop is a closed polyline in parameter space, ``uv (L, 2)`` with ``L >= 3``, the
    first point not repeated at the end. The outer loop runs counter-clockwise in the
    (u, v) plane (positive signed area), holes clockwise, so that the kept region is on
    the left of every loop, as in STEP and OpenCASCADE. A trimmed surface has exactly one
    outer loop (or none, meaning the whole parameter domain) and any number of holes.

nurbskit JSON: a surface object (``core/serialize.py``) with one more key::

    "trim": [{"kind": "outer" | "hole", "uv": [[u, v], ...]}, ...]

>>> import torch
>>> from nurbskit import NURBSSurface
>>> square = TrimLoop.from_uv([[0.1, 0.1], [0.9, 0.1], [0.9, 0.9], [0.1, 0.9]])
>>> round(square.area, 6), square.kind
(0.64, 'outer')
>>> t = TrimmedSurface(NURBSSurface(torch.rand(4, 4, 3), (3, 3)), [square])
>>> TrimmedSurface.from_dict(t.to_dict()).loops[0].kind
'outer'
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..errors import InputError


def signed_area(uv: np.ndarray) -> float:
    """Shoelace area of a closed polyline ``(L, 2)``: positive when counter-clockwise."""
    u, v = uv[:, 0], uv[:, 1]
    return 0.5 * float(np.dot(u, np.roll(v, -1)) - np.dot(np.roll(u, -1), v))


@dataclass
class TrimLoop:
    """One closed loop in (u, v): ``uv (L, 2)`` float64 and ``kind`` 'outer' or 'hole'."""

    uv: np.ndarray
    kind: str

    def __post_init__(self):
        self.uv = np.asarray(self.uv, dtype=np.float64)
        if self.uv.ndim != 2 or self.uv.shape[1] != 2 or self.uv.shape[0] < 3:
            raise InputError(f"a trimming loop needs (L >= 3, 2) points in (u, v), got shape {self.uv.shape}")
        if not np.isfinite(self.uv).all():
            raise InputError("a trimming loop has NaN or infinite (u, v) values")
        if self.kind not in ("outer", "hole"):
            raise InputError(f"a trimming loop's kind must be 'outer' or 'hole', got {self.kind!r}")
        # Orientation is part of the convention: outer counter-clockwise, holes clockwise.
        if (signed_area(self.uv) > 0) != (self.kind == "outer"):
            self.uv = self.uv[::-1].copy()

    @classmethod
    def from_uv(cls, uv, kind: str | None = None) -> "TrimLoop":
        """A loop from points; ``kind`` defaults to 'outer' for counter-clockwise input."""
        uv = np.asarray(uv, dtype=np.float64)
        if kind is None:
            kind = "outer" if signed_area(uv) > 0 else "hole"
        return cls(uv, kind)

    @property
    def area(self) -> float:
        """Unsigned area enclosed in parameter space."""
        return abs(signed_area(self.uv))


@dataclass
class TrimmedSurface:
    """A surface with trimming loops (outer first, then holes); no loops: untrimmed."""

    surface: object  # NURBSSurface
    loops: list[TrimLoop] = field(default_factory=list)

    def __post_init__(self):
        outer = [lp for lp in self.loops if lp.kind == "outer"]
        if len(outer) > 1:
            raise InputError(f"a trimmed surface has at most one outer loop, got {len(outer)}")
        self.loops = outer + [lp for lp in self.loops if lp.kind == "hole"]

    @property
    def outer(self) -> TrimLoop | None:
        return self.loops[0] if self.loops and self.loops[0].kind == "outer" else None

    @property
    def holes(self) -> list[TrimLoop]:
        return [lp for lp in self.loops if lp.kind == "hole"]

    def to_dict(self) -> dict:
        """nurbskit JSON: the surface's object plus a ``trim`` list."""
        from .serialize import to_dict

        data = to_dict(self.surface)
        data["trim"] = [{"kind": lp.kind, "uv": lp.uv.tolist()} for lp in self.loops]
        return data

    @classmethod
    def from_dict(cls, data: dict, *, source: str = "data", **kwargs) -> "TrimmedSurface":
        """Read a surface object with an optional ``trim`` list (kwargs go to ``from_dict``)."""
        from .serialize import from_dict

        surface = from_dict(data, source=source, **kwargs)
        if surface.kind != "surface":
            raise InputError(f"{source}: a trimmed object must be a surface, got a {surface.kind}")
        loops = []
        for i, item in enumerate(data.get("trim", []) or []):
            if not isinstance(item, dict) or "uv" not in item:
                raise InputError(f"{source}: trim[{i}] must be an object with 'kind' and 'uv'")
            try:
                loops.append(TrimLoop(np.asarray(item["uv"], dtype=np.float64), item.get("kind", "outer")))
            except (TypeError, ValueError) as exc:
                raise InputError(f"{source}: trim[{i}].uv must be a list of [u, v] numbers ({exc})") from None
        return cls(surface, loops)

"""The NURBS Generator tab: build a curve, surface or volume and edit it by hand.

Sizes, degrees, knot vectors (clamped, uniform, periodic) and weights are set in the
panel; a control point is picked by its indices and moved either with the 3-D
transform handle or with the coordinate widget: both go through :meth:`GeneratorTab.
set_point`, which changes the one point and redraws the object in place (the scene
nodes keep their identity, only arrays travel; see :class:`.scene.SplineView`).
Knot insertion, degree elevation and splitting call ``nurbskit.insert_knot``,
``nurbskit.elevate_degree`` and ``nurbskit.split``.

Convention: "periodic" closes the object along u: the first ``p`` control points are
repeated at the end (``sizes[0]`` counts the free ones) over a uniform unclamped knot
vector, so the curve or surface is ``C^{p-1}`` across the seam; moving a repeated
point moves its copy. Knot operations turn the object into an ordinary (unclamped)
one: it stays closed but the copies are no longer tied.
"""

from __future__ import annotations

import threading

import numpy as np

from ..errors import OptionError
from .app import TabBase
from .scene import SURFACE_COLOR, SplineView, diagonal

KINDS = ("surface", "curve", "volume")
KNOTS = ("clamped", "uniform", "periodic")
AXES = ("u", "v", "w")


def make_object(kind: str, sizes, degrees, knots: str):
    """A fresh object to edit: a gentle wave (curve, surface), a box (volume), or closed.

    Args:
        kind: 'curve', 'surface' or 'volume'.
        sizes, degrees: per parametric direction (extra entries ignored).
        knots: 'clamped', 'uniform' (unclamped, evenly spaced) or 'periodic' (closed in u).

    Returns:
        ``(object, periodic_free)``: the float64 object and, when periodic, the number of
        free control points along u (else None).
    """
    import torch

    from .. import NURBSCurve, NURBSSurface, NURBSVolume

    k = {"curve": 1, "surface": 2, "volume": 3}[kind]
    sizes = [int(s) for s in sizes[:k]]
    degrees = [int(p) for p in degrees[:k]]
    periodic = knots == "periodic"
    for a, (n, p) in enumerate(zip(sizes, degrees)):
        if p < 1:
            raise OptionError(f"degree along {AXES[a]} must be >= 1, got {p}")
        need = p + 1 if not (periodic and a == 0) else max(3, p)
        if n < need:
            raise OptionError(f"{kind}: {n} control points along {AXES[a]} cannot carry degree {p}"
                              f"{' closed' if periodic and a == 0 else ''}; need at least {need}")
    if periodic:
        nfree = sizes[0]
        t = np.arange(nfree) / nfree * 2 * np.pi
        ring = np.stack([np.cos(t), np.sin(t)], -1)  # (nfree, 2)
        ring = np.concatenate([ring, ring[: degrees[0]]], 0)
        if k == 1:
            cp = np.concatenate([ring, np.zeros((ring.shape[0], 1))], -1)
        elif k == 2:
            h = np.linspace(0, 2, sizes[1])
            cp = np.concatenate([np.repeat(ring[:, None], sizes[1], 1), np.broadcast_to(h[None, :, None],
                                 (ring.shape[0], sizes[1], 1))], -1)
        else:
            h = np.linspace(0, 2, sizes[1])
            r = np.linspace(0.5, 1.0, sizes[2])
            cp = np.zeros((ring.shape[0], sizes[1], sizes[2], 3))
            cp[..., :2] = ring[:, None, None, :] * r[None, None, :, None]
            cp[..., 2] = h[None, :, None]
        sizes[0] = nfree + degrees[0]
    else:
        axes = [np.linspace(0, 1, n) for n in sizes]
        if k == 1:
            x = axes[0]
            cp = np.stack([x, 0.3 * np.sin(2 * np.pi * x), np.zeros_like(x)], -1)
        elif k == 2:
            x, y = np.meshgrid(axes[0], axes[1], indexing="ij")
            cp = np.stack([x, y, 0.2 * np.sin(np.pi * x) * np.cos(np.pi * y)], -1)
        else:
            x, y, z = np.meshgrid(*axes, indexing="ij")
            cp = np.stack([x, y, z], -1)
        nfree = None
    kvs = None
    if knots in ("uniform", "periodic"):
        kvs = []
        for a, (n, p) in enumerate(zip(sizes, degrees)):
            if a == 0 or knots == "uniform":
                kvs.append(torch.linspace(0, 1, n + p + 1, dtype=torch.float64))
            else:
                kvs.append(None)
    cls = {1: NURBSCurve, 2: NURBSSurface, 3: NURBSVolume}[k]
    cpt = torch.as_tensor(np.ascontiguousarray(cp), dtype=torch.float64)
    if k == 1:
        obj = cls(cpt, degrees[0], None if kvs is None else kvs[0])
    else:
        obj = cls(cpt, tuple(degrees), kvs)
    return obj, (nfree if periodic else None)


class GeneratorTab(TabBase):
    """Create and edit a curve, surface or volume."""

    label = "NURBS Generator"
    scene = "generator"
    stem = "generated"

    def __init__(self, session, ui):
        super().__init__(session, ui)
        scene = session.client.scene
        self.lock = threading.RLock()
        self.obj = None
        self.other = None  # the second piece of a split
        self.periodic_free: int | None = None
        self._syncing = False
        self.updates = 0
        self.kind = ui.add_dropdown("Object", KINDS, initial_value="surface")
        self.sizes = ui.add_vector3("Sizes (u, v, w)", (6, 5, 4), min=(2, 2, 2), max=(64, 64, 32), step=1)
        self.degrees = ui.add_vector3("Degrees (u, v, w)", (3, 3, 2), min=(1, 1, 1), max=(7, 7, 7), step=1)
        self.knots = ui.add_dropdown("Knots", KNOTS, initial_value="clamped")
        self.create = ui.add_button("Create")
        self.index = ui.add_vector3("Control point (i, j, k)", (2, 2, 0), min=(0, 0, 0), max=(255, 255, 255), step=1)
        self.position = ui.add_vector3("Point position", (0.0, 0.0, 0.0), step=0.01)
        self.weight = ui.add_number("Point weight", 1.0, min=0.01, max=100.0, step=0.01)
        self.axis = ui.add_dropdown("Axis", AXES, initial_value="u")
        self.at = ui.add_slider("Parameter (fraction of the domain)", min=0.01, max=0.99, step=0.01, initial_value=0.5)
        self.insert = ui.add_button("Insert knot")
        self.elevate = ui.add_button("Elevate degree")
        self.split_button = ui.add_button("Split")
        self.display = ui.add_dropdown("Show", ("shaded", "curvature", "normals"), initial_value="shaded")
        self.info = ui.add_markdown("")
        self.add_export()
        self.view = SplineView(scene, "/generator/object", SURFACE_COLOR)
        self.other_view = SplineView(scene, "/generator/other", (160, 160, 160))
        self.handle = scene.add_transform_controls("/generator/handle", scale=0.25, disable_rotations=True,
                                                   depth_test=False)

        self.create.on_click(lambda e: self.guard(self.rebuild))
        self.index.on_update(lambda e: self.guard(self._select))
        self.position.on_update(lambda e: self.guard(self._from_widget))
        self.weight.on_update(lambda e: self.guard(self._weight))
        self.insert.on_click(lambda e: self.guard(lambda: self._op("insert")))
        self.elevate.on_click(lambda e: self.guard(lambda: self._op("elevate")))
        self.split_button.on_click(lambda e: self.guard(lambda: self._op("split")))
        self.display.on_update(lambda e: self.guard(self._redisplay))
        self.handle.on_update(lambda e: self.guard(self._from_handle))
        # the first object is built once the fitting code has loaded (activate), or when
        # the page asks for it before that (_need)

    def activate(self) -> None:
        """Build the first object. It is drawn hidden unless this tab is the one shown: the
        page opens on another tab, and its first paint need not wait for the surface's
        shaders (software WebGL: seconds)."""
        super().activate()
        with self.lock:
            if self.obj is None:
                self.rebuild(show=self.session.focused == self.label)

    def _need(self):
        """The object being edited (built now if the page is used before :meth:`activate`)."""
        with self.lock:
            if self.obj is None:
                self.rebuild(show=False)
            return self.obj

    # ---- building ------------------------------------------------------------------------
    def rebuild(self, show: bool = True) -> None:
        with self.lock:
            obj, free = make_object(self.kind.value, self.sizes.value, self.degrees.value, self.knots.value)
            self.set_object(obj, free, show=show)
            self.status.info(f"created a {obj.kind} with {tuple(obj.sizes)} control points")

    def set_object(self, obj, periodic_free=None, other=None, frame: bool = True, show: bool = True) -> None:
        """Edit ``obj`` from now on; ``show``: bring this tab to the 3-D view (else it stays as it is)."""
        import torch

        with self.lock:
            self.obj = obj.to(torch.float64).clone()
            self.periodic_free = periodic_free
            self.other = other
            if show:
                self.session.focus(self.label)
            self.view.mode = self.display.value
            self.view.clear()
            self.view.draw(self.obj)
            self.other_view.clear()
            if other is not None:
                self.other_view.draw(other.to(torch.float64))
            self._describe()
            self._select()
            if frame and show:
                self.session.frame(self.obj.control_points.numpy()[..., :3])

    def _describe(self) -> None:
        o = self.obj
        knots = "\n".join(
            f"- {AXES[a]}: degree {p}, {n} points, knots "
            + ", ".join(f"{x:.3g}" for x in kv.tolist()[:24]) + (" ..." if kv.numel() > 24 else "")
            for a, (p, n, kv) in enumerate(zip(o.degrees, o.sizes, o.knot_vectors))
        )
        self.info.content = f"**{o.kind}** {tuple(o.sizes)}\n\n{knots}"

    def _redisplay(self) -> None:
        with self.lock:
            if self.obj is None:
                return  # the first object takes the display mode when it is built
            self.view.mode = self.display.value
            self.view.clear()
            self.view.draw(self.obj)

    # ---- picking and moving a point ------------------------------------------------------
    def _index(self) -> tuple[int, ...]:
        k = self._need().para_dim
        idx = tuple(int(i) for i in self.index.value[:k])
        for a, (i, n) in enumerate(zip(idx, self.obj.sizes)):
            if not 0 <= i < n:
                raise OptionError(f"control point index along {AXES[a]} must be in 0..{n - 1}, got {i}")
        return idx

    def _select(self) -> None:
        with self.lock:
            idx = self._index()
            p = self.obj.control_points[idx][:3].tolist()
            p = p + [0.0] * (3 - len(p))
            self._syncing = True
            try:
                self.position.value = tuple(float(x) for x in p)
                self.weight.value = float(self.obj.weights[idx])
                self.handle.position = np.asarray(p, dtype=np.float64)
                self.handle.scale = 0.15 * diagonal(self.obj.control_points.numpy()[..., :3])
            finally:
                self._syncing = False

    def _from_widget(self) -> None:
        if not self._syncing:
            self.set_point(self._index(), self.position.value, source="widget")

    def _from_handle(self) -> None:
        if not self._syncing:
            self.set_point(self._index(), tuple(self.handle.position), source="handle")

    def _copies(self, idx: tuple[int, ...]) -> list[tuple[int, ...]]:
        """``idx`` and, on a periodic object, the tied copy across the seam."""
        out = [idx]
        free = self.periodic_free
        if free is not None:
            p = self.obj.degrees[0]
            if idx[0] < p:
                out.append((idx[0] + free,) + idx[1:])
            elif idx[0] >= free:
                out.append((idx[0] - free,) + idx[1:])
        return out

    def set_point(self, idx: tuple[int, ...], xyz, source: str = "api") -> None:
        """Move control point ``idx`` to ``xyz`` and redraw (the drag update path)."""
        import torch

        with self.lock:
            cp = self.obj.control_points
            value = torch.as_tensor(np.asarray(xyz, dtype=np.float64)[: cp.shape[-1]], dtype=cp.dtype)
            if not torch.isfinite(value).all():
                raise OptionError(f"control point coordinates must be finite, got {tuple(xyz)}")
            for i in self._copies(idx):
                cp[i] = value
            self.view.draw(self.obj)
            self.updates += 1
            self._syncing = True
            try:
                if source != "widget":
                    self.position.value = tuple(float(x) for x in np.asarray(xyz)[:3])
                if source != "handle":
                    self.handle.position = np.asarray(xyz, dtype=np.float64)[:3]
            finally:
                self._syncing = False

    def _weight(self) -> None:
        if self._syncing:
            return
        with self.lock:
            w = float(self.weight.value)
            if not w > 0:
                raise OptionError(f"weights must be positive, got {w}")
            idx = self._index()
            for i in self._copies(idx):
                self.obj.weights[i] = w
            self.view.draw(self.obj)

    # ---- knot operations -----------------------------------------------------------------
    def _op(self, what: str) -> None:
        import nurbskit

        with self.lock:
            axis = AXES.index(self.axis.value)
            if axis >= self._need().para_dim:
                raise OptionError(f"a {self.obj.kind} has no {self.axis.value} direction")
            a, b = self.obj.domain[axis]
            value = a + float(self.at.value) * (b - a)
            if what == "insert":
                obj, other = nurbskit.insert_knot(self.obj, value, times=1, axis=axis), None
                note = f"inserted a knot at {value:.4g} along {self.axis.value}"
            elif what == "elevate":
                obj, other = nurbskit.elevate_degree(self.obj, times=1, axis=axis), None
                note = f"raised the degree along {self.axis.value} to {obj.degrees[axis]}"
            else:
                obj, other = nurbskit.split(self.obj, value, axis=axis)
                note = (f"split at {value:.4g} along {self.axis.value}: the first piece is edited, "
                        "the second is shown in grey")
            self.set_object(obj, None, other, frame=False)
            self.status.info(note)

    def shown(self):
        return self.obj, None, f"generated-{self.obj.kind}" if self.obj is not None else "generated"


def build_generator(session, ui):
    return GeneratorTab(session, ui)

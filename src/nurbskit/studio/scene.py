"""Drawing nurbskit objects into a viser scene: surfaces, nets, clouds, curves, volumes.

Every function takes a viser ``SceneApi`` (a client's own scene, so that browser tabs
do not see each other's objects) and a scene-tree name. :class:`SplineView` keeps its
handles and updates their arrays in place, which is what makes dragging a control
point redraw at interactive rates (no node is re-created per update).

Convention: colours are RGB ``uint8``; point sizes are a fraction of the drawn
object's bounding-box diagonal so that clouds in millimetres and in metres look alike.
"""

from __future__ import annotations

import numpy as np

# torch and nurbskit.core are imported where they are used: this module is imported while
# the page's widgets are built, before the fitting code has loaded (see .choices)

SURFACE_COLOR = (90, 160, 230)
RESULT_COLOR = (240, 150, 60)
NET_COLOR = (200, 40, 40)
WIRE_COLOR = (30, 30, 30)
CLOUD_COLOR = (40, 40, 40)


def diagonal(points: np.ndarray) -> float:
    """Bounding-box diagonal of ``(N, 3)`` points (1.0 when degenerate)."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if pts.size == 0:
        return 1.0
    d = float(np.linalg.norm(pts.max(0) - pts.min(0)))
    return d if d > 0 else 1.0


def colormap(values: np.ndarray, lo: float | None = None, hi: float | None = None) -> np.ndarray:
    """Viridis colours ``(N, 3)`` uint8 of ``values (N,)`` scaled to ``[lo, hi]``."""
    import matplotlib

    v = np.asarray(values, dtype=np.float64).ravel()
    lo = float(np.nanmin(v)) if lo is None and v.size else (lo or 0.0)
    hi = float(np.nanmax(v)) if hi is None and v.size else (hi or 1.0)
    t = np.clip((v - lo) / (hi - lo if hi > lo else 1.0), 0, 1)
    return (matplotlib.colormaps["viridis"](t)[:, :3] * 255).astype(np.uint8)


def _np(x) -> np.ndarray:
    return x.detach().cpu().numpy() if hasattr(x, "detach") else np.asarray(x)


def net_segments(cp: np.ndarray) -> np.ndarray:
    """Line segments ``(K, 2, 3)`` joining neighbours of a control grid ``(*sizes, 3)``."""
    segs = []
    for axis in range(cp.ndim - 1):
        a = np.moveaxis(cp, axis, 0)
        if a.shape[0] > 1:
            segs.append(np.stack([a[:-1], a[1:]], axis=-2).reshape(-1, 2, 3))
    return np.concatenate(segs, 0) if segs else np.zeros((0, 2, 3))


def grid_lines(grid: np.ndarray, every: int) -> np.ndarray:
    """Iso-parameter lines of a sampled surface ``(R, S, 3)``: every ``every``-th row and column."""
    R, S = grid.shape[:2]
    rows = list(range(0, R, every)) + ([R - 1] if (R - 1) % every else [])
    cols = list(range(0, S, every)) + ([S - 1] if (S - 1) % every else [])
    u = grid[rows]
    v = grid[:, cols].transpose(1, 0, 2)
    segs = [np.stack([u[:, :-1], u[:, 1:]], -2).reshape(-1, 2, 3), np.stack([v[:, :-1], v[:, 1:]], -2).reshape(-1, 2, 3)]
    return np.concatenate(segs, 0)


def gaussian_curvature(surface, resolution: tuple[int, int]) -> np.ndarray:
    """Gaussian curvature ``K = (LN - M^2) / (EG - F^2)`` on the sampling grid, ``(R*S,)``.

    From the first and second fundamental forms (do Carmo, *Differential Geometry of
    Curves and Surfaces*, 3.3), with derivatives from the surface itself.
    """
    import torch

    u, v = surface.grid_axes(resolution)
    with torch.no_grad():
        d = surface.evaluate_grid(u, v, order=2)  # (R, S, 3, 3, dim)
    su, sv = d[..., 1, 0, :], d[..., 0, 1, :]
    suu, suv, svv = d[..., 2, 0, :], d[..., 1, 1, :], d[..., 0, 2, :]
    n = torch.cross(su, sv, dim=-1)
    n = n / n.norm(dim=-1, keepdim=True).clamp_min(1e-300)
    E, F, G = (su * su).sum(-1), (su * sv).sum(-1), (sv * sv).sum(-1)
    L, M, N = (suu * n).sum(-1), (suv * n).sum(-1), (svv * n).sum(-1)
    K = (L * N - M * M) / (E * G - F * F).clamp_min(1e-300)
    return _np(K).reshape(-1)


class SplineView:
    """A curve, surface or volume drawn under ``name``: body, iso-lines and control net.

    ``update(obj)`` changes the arrays of the existing nodes when the sizes did not
    change (a control point moved) and re-creates them otherwise.
    """

    def __init__(self, scene, name: str, color=SURFACE_COLOR, resolution: int = 64, lines: int = 8,
                 show_net: bool = True, show_wire: bool = True, offset=(0.0, 0.0, 0.0)):
        self.scene, self.name, self.color = scene, name, color
        self.resolution, self.lines = resolution, lines
        self.show_net, self.show_wire = show_net, show_wire
        self.offset = np.asarray(offset, dtype=np.float64)
        self.handles: dict[str, object] = {}
        self.shape_key = None
        self.mode = "shaded"  # shaded | curvature | normals
        self.last_vertices: np.ndarray | None = None
        self.last_faces: np.ndarray | None = None

    # ---- geometry ---------------------------------------------------------------------
    def _body(self, obj):
        """``(vertices (V, 3), faces (F, 3), lines (K, 2, 3), grid)`` of the object's body."""
        import torch

        from ..core.tessellate import grid_faces

        res = self.resolution
        with torch.no_grad():
            if obj.para_dim == 1:
                pts = _np(obj.sample(max(2 * res, 64)))[..., :3]
                return None, None, np.stack([pts[:-1], pts[1:]], 1), None
            if obj.para_dim == 2:
                grid = _np(obj.sample((res, res)))
                faces = grid_faces(res, res).numpy()
                every = max(1, (res - 1) // self.lines)
                return grid.reshape(-1, 3), faces, grid_lines(grid, every), grid
            # a volume: its six boundary faces
            r = max(8, res // 2)
            axes = obj.grid_axes((r, r, r))
            verts, faces, lines = [], [], []
            base = 0
            for a in range(3):
                for end in (0, -1):
                    ax = list(axes)
                    ax[a] = axes[a][end:][:1]
                    g = _np(obj.evaluate_grid(*ax)).squeeze(a)[..., :3]
                    verts.append(g.reshape(-1, 3))
                    f = grid_faces(r, r).numpy() + base
                    faces.append(f[:, ::-1] if end == 0 else f)
                    lines.append(grid_lines(g, max(1, (r - 1) // 4)))
                    base += r * r
            return np.concatenate(verts), np.concatenate(faces), np.concatenate(lines), None

    def draw(self, obj) -> None:
        """Draw ``obj`` (re-using the nodes when only coordinates changed)."""
        vertices, faces, lines, grid = self._body(obj)
        cp = _np(obj.control_points)[..., :3] + self.offset
        key = (obj.para_dim, tuple(obj.sizes), self.mode, None if faces is None else faces.shape,
               lines.shape, self.show_net, self.show_wire)
        if vertices is not None:
            vertices = vertices + self.offset
        lines = lines + self.offset
        self.last_vertices, self.last_faces = vertices, faces
        size = diagonal(cp if vertices is None else vertices)
        if key == self.shape_key and self.mode == "shaded":
            h = self.handles
            if "mesh" in h:
                h["mesh"].vertices = vertices.astype(np.float32)
            if "curve" in h:
                h["curve"].points = lines.astype(np.float32)
            if "wire" in h:
                h["wire"].points = lines.astype(np.float32)
            if "net" in h:
                h["net"].points = net_segments(cp).astype(np.float32)
                h["cp"].points = cp.reshape(-1, 3).astype(np.float32)
            return
        self.clear()
        self.shape_key = key
        s = self.scene
        if faces is None:  # a curve
            self.handles["curve"] = s.add_line_segments(f"{self.name}/curve", lines, self.color, thickness=3.0,
                                                        thickness_units="screen")
        elif self.mode == "curvature" and obj.para_dim == 2:
            import trimesh

            K = gaussian_curvature(obj, (self.resolution, self.resolution))
            lim = float(np.nanpercentile(np.abs(K), 95)) or 1.0
            mesh = trimesh.Trimesh(vertices, faces, process=False, vertex_colors=colormap(K, -lim, lim))
            self.handles["mesh"] = s.add_mesh_trimesh(f"{self.name}/surface", mesh)
        else:
            self.handles["mesh"] = s.add_mesh_simple(f"{self.name}/surface", vertices, faces, color=self.color,
                                                     side="double")
        if self.mode == "normals" and obj.para_dim == 2:
            import torch

            g = self.resolution
            u, v = obj.grid_axes((g, g))
            with torch.no_grad():
                n = _np(obj.normals_grid(u[:: max(1, g // 16)], v[:: max(1, g // 16)])).reshape(-1, 3)
                p = _np(obj.evaluate_grid(u[:: max(1, g // 16)], v[:: max(1, g // 16)])).reshape(-1, 3) + self.offset
            segs = np.stack([p, p + 0.05 * size * n], 1)
            self.handles["normals"] = s.add_line_segments(f"{self.name}/normals", segs, (20, 140, 60),
                                                          thickness=1.5, thickness_units="screen")
        if self.show_wire and faces is not None:
            self.handles["wire"] = s.add_line_segments(f"{self.name}/wire", lines, WIRE_COLOR, thickness=1.0,
                                                       thickness_units="screen")
        if self.show_net:
            self.handles["net"] = s.add_line_segments(f"{self.name}/net", net_segments(cp), NET_COLOR,
                                                      thickness=1.0, thickness_units="screen")
            self.handles["cp"] = s.add_point_cloud(f"{self.name}/cp", cp.reshape(-1, 3), NET_COLOR,
                                                   point_size=0.008 * size, point_shape="circle")

    def clear(self) -> None:
        for h in self.handles.values():
            h.remove()
        self.handles = {}
        self.shape_key = None


def draw_points(scene, name: str, points: np.ndarray, colors=None, size: float | None = None):
    """A point cloud ``(N, 3)``; ``colors`` one RGB or ``(N, 3)`` uint8."""
    pts = np.asarray(points, dtype=np.float32).reshape(-1, 3)
    return scene.add_point_cloud(name, pts, CLOUD_COLOR if colors is None else colors,
                                 point_size=size or 0.004 * diagonal(pts), point_shape="circle")


def draw_mesh(scene, name: str, vertices: np.ndarray, faces: np.ndarray, color=RESULT_COLOR):
    return scene.add_mesh_simple(name, np.asarray(vertices, np.float32), np.asarray(faces, np.uint32),
                                 color=color, side="double")

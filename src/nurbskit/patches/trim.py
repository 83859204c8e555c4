"""Trimming in (u, v): the region of a patch where its inliers are, and its trimmed mesh.

NURBSFit (section 3.2, "Finalization") projects each patch's inliers into its parameter
domain, takes their alpha shape (Edelsbrunner, Kirkpatrick and Seidel 1983) and keeps the
triangles of the patch's grid mesh inside it. Here the alpha shape is the union of the
Delaunay triangles of the inliers whose circumradius is below ``r`` (scipy's Delaunay and
shapely's coverage union), computed in a *metric* (u, v) frame, each direction scaled by
the patch's mean speed ``|S_u|``, ``|S_v|``, so ``r`` is a length on the surface; points
near the seam of a closed patch are repeated across it.

The trimmed mesh: the cells of a (u, v) grid are cut by the trimming region
(``shapely.intersection``) and each piece is triangulated with a constrained Delaunay
triangulation, so the mesh border follows the trimming curve exactly; the triangles are
lifted to 3D by evaluating the surface.

Convention: loops follow :mod:`nurbskit.core.trim` (outer counter-clockwise, holes
clockwise, in the surface's knot domain).
"""

from __future__ import annotations

import numpy as np
import shapely
import torch
from scipy.spatial import Delaunay, cKDTree
from shapely.geometry import Polygon, box

from ..core import NURBSSurface
from ..core.trim import TrimLoop, TrimmedSurface


def metric_scales(surface: NURBSSurface, resolution: int = 12) -> tuple[float, float]:
    """Mean ``|S_u|`` and ``|S_v|`` over a grid: lengths on the surface per unit of u and v."""
    with torch.no_grad():
        axes = surface.grid_axes(resolution)
        d = surface.evaluate_grid(*axes, order=1)  # (R, S, 2, 2, 3)
    su = float(d[..., 1, 0, :].norm(dim=-1).mean())
    sv = float(d[..., 0, 1, :].norm(dim=-1).mean())
    return max(su, 1e-12), max(sv, 1e-12)


def alpha_shape(xy: np.ndarray, alpha: float):
    """The alpha shape of ``xy (M, 2)``: the union of the Delaunay triangles whose circumradius is below ``alpha``.

    Edelsbrunner, Kirkpatrick and Seidel (1983). The kept triangles tile without overlap,
    so their union is a coverage union (``shapely.coverage_union_all``), fast and exact.
    """
    if len(xy) < 3:
        return Polygon()
    try:
        tri = Delaunay(xy)
    except Exception:  # all points on a line: no area
        return Polygon()
    p = xy[tri.simplices]
    a = np.linalg.norm(p[:, 1] - p[:, 2], axis=1)
    b = np.linalg.norm(p[:, 0] - p[:, 2], axis=1)
    c = np.linalg.norm(p[:, 0] - p[:, 1], axis=1)
    area2 = np.abs((p[:, 1, 0] - p[:, 0, 0]) * (p[:, 2, 1] - p[:, 0, 1]) - (p[:, 1, 1] - p[:, 0, 1]) * (p[:, 2, 0] - p[:, 0, 0]))
    keep = (a * b * c < 2 * alpha * area2) & (area2 > 0)  # circumradius abc / (4 area) < alpha
    if not keep.any():
        return Polygon()
    return shapely.coverage_union_all(shapely.polygons(p[keep]))


def trim_region(
    uv: np.ndarray, surface: NURBSSurface, closed_v: bool = False, alpha: float = 4.0, keep: float = 0.05
) -> list[Polygon]:
    """Trimming regions in the metric (u, v) frame from the inliers' parameters ``uv (M, 2)``.

    The alpha radius is ``alpha`` times the inliers' median nearest-neighbour distance on
    the surface; the alpha shape is then grown by 0.75 of that distance, because its
    border runs through the outermost samples, about that far inside the sampled
    surface's true border (measured on a uniformly sampled disc with a hole: the area
    comes within 1 % of the true one). Returns the connected regions (shapely polygons in
    *metric* coordinates), largest first, keeping those of at least ``keep`` times the
    largest's area; holes smaller than an alpha disc are filled.
    """
    (u0, u1), (v0, v1) = surface.domain
    su, sv = metric_scales(surface)
    xy = np.c_[(uv[:, 0] - u0) * su, (uv[:, 1] - v0) * sv]
    if len(xy) < 3:
        return []
    width, height = (u1 - u0) * su, (v1 - v0) * sv
    dnn = cKDTree(xy).query(xy, k=2)[0][:, 1]
    spacing = float(np.median(dnn[dnn > 0])) if (dnn > 0).any() else 0.0
    if spacing <= 0:
        return []
    radius = alpha * spacing
    if closed_v:  # the seam is no border: repeat the points near it on the other side
        near0 = xy[:, 1] < 2 * radius
        near1 = xy[:, 1] > height - 2 * radius
        xy = np.vstack([xy, xy[near0] + [0, height], xy[near1] - [0, height]])
    shape = alpha_shape(xy, radius).buffer(0.75 * spacing, quad_segs=4)
    region = shape.intersection(box(0.0, 0.0, width, height)).simplify(spacing / 4)
    parts = [g for g in shapely.get_parts(region) if isinstance(g, Polygon) and not g.is_empty]
    if not parts:
        return []
    parts.sort(key=lambda g: -g.area)
    parts = [g for g in parts if g.area >= keep * parts[0].area]
    small = np.pi * radius * radius
    return [Polygon(g.exterior, [h for h in g.interiors if Polygon(h).area > small]) for g in parts]


def polygon_loops(polygon: Polygon, surface: NURBSSurface) -> list[TrimLoop]:
    """A metric-frame polygon as trimming loops in the surface's (u, v) domain."""
    (u0, _), (v0, _) = surface.domain
    su, sv = metric_scales(surface)

    def to_uv(ring) -> np.ndarray:
        xy = np.asarray(ring.coords)[:-1]
        return np.c_[xy[:, 0] / su + u0, xy[:, 1] / sv + v0]

    loops = [TrimLoop(to_uv(polygon.exterior), "outer")]
    loops += [TrimLoop(to_uv(ring), "hole") for ring in polygon.interiors if len(ring.coords) >= 4]
    return loops


def trim_patch(uv: np.ndarray, surface: NURBSSurface, closed_v: bool = False, alpha: float = 4.0) -> list[TrimmedSurface]:
    """Trimmed faces of one patch: one :class:`TrimmedSurface` per connected region."""
    return [TrimmedSurface(surface, polygon_loops(p, surface)) for p in trim_region(uv, surface, closed_v, alpha)]


def trimmed_mesh(face: TrimmedSurface, cells: int = 40) -> tuple[np.ndarray, np.ndarray]:
    """Triangle mesh of a trimmed face: ``vertices (V, 3)``, ``faces (F, 3)``.

    The parameter domain is cut into ``cells x cells`` cells (in the metric frame, so cells
    are about square on the surface); every cell is intersected with the trimming region and
    the pieces triangulated (constrained Delaunay), so the border follows the trimming loops.
    """
    surface = face.surface
    (u0, u1), (v0, v1) = surface.domain
    if face.outer is None:
        region = box(u0, v0, u1, v1)
    else:
        region = Polygon(face.outer.uv, [h.uv for h in face.holes])
    region = shapely.make_valid(region)
    su, sv = metric_scales(surface)
    # cells about square on the surface: split the longer side in `cells`
    longer = max((u1 - u0) * su, (v1 - v0) * sv)
    nu = max(2, int(np.ceil(cells * (u1 - u0) * su / longer)))
    nv = max(2, int(np.ceil(cells * (v1 - v0) * sv / longer)))
    us, vs = np.linspace(u0, u1, nu + 1), np.linspace(v0, v1, nv + 1)
    a, b = np.meshgrid(np.arange(nu), np.arange(nv), indexing="ij")
    grid = shapely.box(us[a.ravel()], vs[b.ravel()], us[a.ravel() + 1], vs[b.ravel() + 1])
    # Whole cells: two triangles each; cut cells: constrained Delaunay of the piece.
    shapely.prepare(region)
    inside = shapely.contains_properly(region, grid)
    tri = []
    ia, ib = a.ravel()[inside], b.ravel()[inside]
    p00 = np.stack([us[ia], vs[ib]], -1)
    p10 = np.stack([us[ia + 1], vs[ib]], -1)
    p11 = np.stack([us[ia + 1], vs[ib + 1]], -1)
    p01 = np.stack([us[ia], vs[ib + 1]], -1)
    tri.append(np.stack([p00, p10, p11], 1))
    tri.append(np.stack([p00, p11, p01], 1))
    cut = ~inside & shapely.intersects(region, grid)
    if cut.any():
        pieces = shapely.intersection(grid[cut], region)
        triangles = shapely.get_parts(shapely.constrained_delaunay_triangles(pieces))
        triangles = triangles[shapely.get_type_id(triangles) == 3]
        if len(triangles):
            coords = shapely.get_coordinates(shapely.get_exterior_ring(triangles)).reshape(-1, 4, 2)[:, :3]
            tri.append(coords)
    uv_tri = np.concatenate(tri, 0) if tri else np.zeros((0, 3, 2))
    if len(uv_tri) == 0:
        return np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64)
    # Counter-clockwise in (u, v): the normal follows S_u x S_v.
    e1, e2 = uv_tri[:, 1] - uv_tri[:, 0], uv_tri[:, 2] - uv_tri[:, 0]
    flip = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0] < 0
    uv_tri[flip] = uv_tri[flip][:, ::-1]
    uv_vert, faces = np.unique(np.round(uv_tri.reshape(-1, 2), 12), axis=0, return_inverse=True)
    faces = faces.reshape(-1, 3)
    with torch.no_grad():
        xyz = surface.evaluate(torch.as_tensor(uv_vert, dtype=surface.dtype, device=surface.device))
    return xyz.cpu().double().numpy(), faces.astype(np.int64)

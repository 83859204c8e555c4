"""The planar start: region growing on normals and point-to-plane distance, then refinement.

Our stand-in for GoCoPP (Yu and Lafarge, "Finding good configurations of planar
primitives in unorganized point clouds", CVPR 2022), which NURBSFit runs as a separate
C++ program. Region growing after Rabbani, van den Heuvel and Vosselman ("Segmentation
of point clouds using smoothness constraint", 2006), with the plane refitted as the
region grows:

1. seeds in order of increasing surface variation (flattest first);
2. a region takes a kNN neighbour when the neighbour's normal is within
   ``normal_angle`` of the plane's and its distance to the plane is below ``tol``
   (grown wave by wave; the plane is refitted by PCA each time the region grew by half);
3. refinement: coplanar neighbouring regions merge, strips along sharp edges (a
   spacing or two wide, made of points whose normals blend two faces) are dropped,
   boundary points move to the
   neighbouring plane that is closer, unassigned points join a neighbouring plane they fit,
   and regions smaller than ``min_region`` are dropped (their points become unassigned).

Also :func:`read_vg`: a GoCoPP / PolyFit vertex-group file, for people who already have one.

Convention: ``labels (N,)`` int64, ``-1`` for unassigned points, regions numbered
``0 .. R-1`` in order of decreasing size.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import InputError


@dataclass
class PlanarStart:
    """The planar start and its GoCoPP-style report."""

    labels: np.ndarray
    """``(N,)`` region per point, -1 unassigned."""
    centers: np.ndarray
    """``(R, 3)`` a point on each plane (the centroid of its points)."""
    plane_normals: np.ndarray
    """``(R, 3)`` unit normal of each plane."""

    @property
    def count(self) -> int:
        return len(self.centers)

    def report(self, points: np.ndarray, diag: float) -> dict:
        """Number of planes, coverage (fraction of points in a plane), mean point-to-plane error."""
        inside = self.labels >= 0
        d = plane_distances(points[inside], self.centers[self.labels[inside]], self.plane_normals[self.labels[inside]])
        return {
            "planes": int(self.count),
            "coverage": float(inside.mean()) if len(inside) else 0.0,
            "mean_error": float(d.mean() / diag) if len(d) else 0.0,
        }


def plane_distances(points: np.ndarray, centers: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """``|(p - c) . n|`` row by row: ``(N, 3)`` x3 -> ``(N,)``."""
    return np.abs(np.einsum("ij,ij->i", points - centers, normals))


def fit_plane(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Centroid ``(3,)`` and unit normal ``(3,)`` of the least-squares plane (PCA)."""
    c = points.mean(axis=0)
    _, _, vt = np.linalg.svd(points - c, full_matrices=False)
    return c, vt[-1]


def planes_of(points: np.ndarray, labels: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares plane of every region ``0 .. max(labels)``: ``(R, 3)``, ``(R, 3)``."""
    r = int(labels.max()) + 1 if (labels >= 0).any() else 0
    centers, normals = np.zeros((r, 3)), np.zeros((r, 3))
    order = np.argsort(labels, kind="stable")
    bounds = np.searchsorted(labels[order], np.arange(r + 1))
    for i in range(r):
        idx = order[bounds[i] : bounds[i + 1]]
        centers[i], normals[i] = fit_plane(points[idx]) if len(idx) >= 3 else (points[idx].mean(0), np.array([0, 0, 1.0]))
    return centers, normals


def relabel_by_size(labels: np.ndarray, min_size: int = 1) -> np.ndarray:
    """Renumber regions 0.. by decreasing size; regions below ``min_size`` become -1."""
    out = np.full_like(labels, -1)
    keep = labels >= 0
    if not keep.any():
        return out
    ids, counts = np.unique(labels[keep], return_counts=True)
    order = np.argsort(-counts, kind="stable")
    new = np.full(int(ids.max()) + 1, -1)
    rank = 0
    for j in order:
        if counts[j] >= min_size:
            new[ids[j]] = rank
            rank += 1
    out[keep] = new[labels[keep]]
    return out


def grow_regions(
    points: np.ndarray,
    normals: np.ndarray,
    neighbours: np.ndarray,
    variation: np.ndarray,
    tol: float,
    normal_angle: float,
    min_region: int,
) -> np.ndarray:
    """Region growing (steps 1-2 of the module docstring): ``labels (N,)``.

    Shapes: ``points (N, 3)``, ``normals (N, 3)``, ``neighbours (N, k)``, ``variation (N,)``.
    """
    n = len(points)
    labels = np.full(n, -1, dtype=np.int64)
    tried = np.zeros(n, dtype=bool)
    cos_t = np.cos(np.radians(normal_angle))
    region = 0
    for seed in np.argsort(variation, kind="stable"):
        if labels[seed] >= 0 or tried[seed]:
            continue
        tried[seed] = True
        c, nrm = points[seed], normals[seed]
        members = [np.array([seed])]
        labels[seed] = region
        size, fitted_at = 1, 1
        frontier = np.array([seed])
        while len(frontier):
            cand = np.unique(neighbours[frontier].reshape(-1))
            cand = cand[labels[cand] == -1]
            if len(cand) == 0:
                break
            ok = (np.abs(normals[cand] @ nrm) > cos_t) & (np.abs((points[cand] - c) @ nrm) < tol)
            frontier = cand[ok]
            labels[frontier] = region
            members.append(frontier)
            size += len(frontier)
            if size >= 1.5 * fitted_at and size >= 3:
                c, nrm = fit_plane(points[np.concatenate(members)])
                fitted_at = size
        if size < min_region:
            idx = np.concatenate(members)
            labels[idx] = -1
            tried[idx] = True  # not a seed again, but other regions may take these points
        else:
            region += 1
    return labels


def _region_links(labels: np.ndarray, neighbours: np.ndarray) -> dict[tuple[int, int], int]:
    a = np.repeat(labels, neighbours.shape[1])
    b = labels[neighbours.reshape(-1)]
    ok = (a >= 0) & (b >= 0) & (a != b)
    lo, hi = np.minimum(a[ok], b[ok]), np.maximum(a[ok], b[ok])
    if not len(lo):
        return {}
    pairs, counts = np.unique(np.stack([lo, hi], 1), axis=0, return_counts=True)
    return {(int(p), int(q)): int(c) for (p, q), c in zip(pairs, counts)}


def drop_strips(points: np.ndarray, labels: np.ndarray, neighbours: np.ndarray, width: float = 1.5) -> np.ndarray:
    """Unassign regions narrower than ``width`` point spacings (the std of their second principal direction).

    Along a sharp edge the PCA normals blend the two faces, and the points of the edge can
    grow into a strip of their own, one or two spacings wide: no surface, an artefact.
    """
    labels = labels.copy()
    spacing = float(np.median(np.linalg.norm(points[neighbours[:, 0]] - points, axis=1)))
    for r in range(int(labels.max()) + 1 if (labels >= 0).any() else 0):
        idx = np.flatnonzero(labels == r)
        if len(idx) < 3:
            continue
        w = np.linalg.eigvalsh(np.cov(points[idx].T))
        if np.sqrt(max(w[1], 0.0)) < width * spacing:
            labels[idx] = -1
    return relabel_by_size(labels)


def merge_coplanar(points: np.ndarray, labels: np.ndarray, neighbours: np.ndarray, tol: float, normal_angle: float) -> np.ndarray:
    """Merge neighbouring regions whose union is still a plane (RMS below ``tol / 2``, normals within the angle)."""
    labels = labels.copy()
    cos_t = np.cos(np.radians(normal_angle))
    for _ in range(10):
        centers, nrm = planes_of(points, labels)
        r = len(centers)
        # Moments for the union's plane: counts, sums and second moments per region.
        cnt = np.bincount(labels[labels >= 0], minlength=r).astype(float)
        s1 = np.zeros((r, 3))
        s2 = np.zeros((r, 3, 3))
        np.add.at(s1, labels[labels >= 0], points[labels >= 0])
        np.add.at(s2, labels[labels >= 0], np.einsum("ni,nj->nij", points[labels >= 0], points[labels >= 0]))
        parent = np.arange(r)
        changed = False
        links = sorted(_region_links(labels, neighbours).items(), key=lambda kv: -abs(nrm[kv[0][0]] @ nrm[kv[0][1]]))
        for (p, q), _ in links:
            if parent[p] != p or parent[q] != q or abs(nrm[p] @ nrm[q]) < cos_t:
                continue
            m = cnt[p] + cnt[q]
            mean = (s1[p] + s1[q]) / m
            cov = (s2[p] + s2[q]) / m - np.outer(mean, mean)
            w = np.linalg.eigvalsh(cov)
            if np.sqrt(max(w[0], 0.0)) < tol / 2:
                parent[q] = p
                cnt[p], s1[p], s2[p] = m, s1[p] + s1[q], s2[p] + s2[q]
                changed = True
        if not changed:
            break
        keep = labels >= 0
        labels[keep] = parent[labels[keep]]
        labels = relabel_by_size(labels)
    return labels


def reassign(points: np.ndarray, normals: np.ndarray, labels: np.ndarray, neighbours: np.ndarray, tol: float, normal_angle: float) -> np.ndarray:
    """Boundary points to the closest neighbouring plane; unassigned points to a plane they fit."""
    labels = labels.copy()
    cos_t = np.cos(np.radians(normal_angle))
    for _ in range(3):
        centers, nrm = planes_of(points, labels)
        if not len(centers):
            return labels
        cand = labels[neighbours]  # (N, k) labels of the neighbours
        best = labels.copy()
        own = np.where(labels >= 0, plane_distances(points, centers[np.maximum(labels, 0)], nrm[np.maximum(labels, 0)]), np.inf)
        best_d = own.copy()
        for j in range(cand.shape[1]):
            c = cand[:, j]
            ok = c >= 0
            d = np.full(len(points), np.inf)
            d[ok] = plane_distances(points[ok], centers[c[ok]], nrm[c[ok]])
            fits = ok & (d < tol) & (np.abs(np.einsum("ij,ij->i", normals, nrm[np.maximum(c, 0)])) > cos_t)
            better = fits & (d < best_d)
            best[better], best_d[better] = c[better], d[better]
        if np.array_equal(best, labels):
            break
        labels = best
    return labels


def planar_start(
    points: np.ndarray,
    normals: np.ndarray,
    neighbours: np.ndarray,
    variation: np.ndarray,
    tol: float,
    normal_angle: float = 25.0,
    min_region: int = 10,
) -> PlanarStart:
    """Region growing and refinement (module docstring): the planar start of a cloud.

    Shapes: ``points (N, 3)``, ``normals (N, 3)``, ``neighbours (N, k)`` kNN indices,
    ``variation (N,)``; ``tol`` in the points' units.
    """
    labels = grow_regions(points, normals, neighbours, variation, tol, normal_angle, min_region)
    labels = relabel_by_size(labels)
    labels = merge_coplanar(points, labels, neighbours, tol, normal_angle)
    labels = drop_strips(points, labels, neighbours)
    labels = reassign(points, normals, labels, neighbours, tol, normal_angle)
    labels = relabel_by_size(labels, min_region)
    centers, nrm = planes_of(points, labels)
    return PlanarStart(labels, centers, nrm)


def read_vg(path: str | Path, n_points: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Read a GoCoPP / PolyFit vertex-group file: ``points (N, 3)`` and ``labels (N,)``.

    The format (PolyFit, Nan and Wonka 2017): ``num_points: N`` then N lines ``x y z``;
    ``num_colors: C`` and C colours; ``num_normals: M`` and M normals; ``num_groups: G``
    then per group ``group_type``, ``num_group_parameters``, ``group_parameters``,
    ``group_label``, ``group_color``, ``group_num_point: K`` and K point indices, and
    ``num_children`` (children groups are read the same way and flattened). Points in no
    group get label -1. With ``n_points`` the file must hold exactly that many points.
    """
    path = Path(path)
    try:
        tokens = path.read_text(errors="strict").split()
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"{path}: cannot read the vertex-group file ({exc})") from None
    pos = 0

    def expect(key: str) -> int:
        nonlocal pos
        if pos >= len(tokens) or tokens[pos] != key:
            found = tokens[pos] if pos < len(tokens) else "the end of the file"
            raise InputError(f"{path}: expected '{key}' in the vertex-group file, found {found!r}")
        pos += 1
        return take_int()

    def take_int() -> int:
        nonlocal pos
        try:
            value = int(tokens[pos])
        except (IndexError, ValueError):
            raise InputError(f"{path}: expected an integer after '{tokens[pos - 1]}'") from None
        pos += 1
        return value

    def take_floats(count: int, what: str) -> np.ndarray:
        nonlocal pos
        try:
            values = np.asarray(tokens[pos : pos + count], dtype=np.float64)
        except ValueError:
            raise InputError(f"{path}: {what} must be numbers") from None
        if len(values) != count:
            raise InputError(f"{path}: the file ends inside the {what}")
        pos += count
        return values

    n = expect("num_points:")
    points = take_floats(3 * n, "point coordinates").reshape(n, 3)
    if n_points is not None and n != n_points:
        raise InputError(f"{path}: the vertex-group file has {n} points, the input cloud has {n_points}")
    c = expect("num_colors:")
    take_floats(3 * c, "colours")
    m = expect("num_normals:")
    take_floats(3 * m, "normals")
    labels = np.full(n, -1, dtype=np.int64)
    group = 0

    def read_group():
        nonlocal pos, group
        expect("group_type:")
        k = expect("num_group_parameters:")
        if pos >= len(tokens) or tokens[pos] != "group_parameters:":
            raise InputError(f"{path}: expected 'group_parameters:' in group {group}")
        pos += 1
        take_floats(k, "group parameters")
        if pos < len(tokens) and tokens[pos] == "group_label:":
            pos += 2
        if pos < len(tokens) and tokens[pos] == "group_color:":
            pos += 4
        count = expect("group_num_point:")
        idx = take_floats(count, "group point indices").astype(np.int64)
        if count and (idx.min() < 0 or idx.max() >= n):
            raise InputError(f"{path}: group {group} refers to point {int(idx.max())} but the file has {n} points")
        labels[idx] = group
        group += 1
        children = expect("num_children:") if pos < len(tokens) and tokens[pos] == "num_children:" else 0
        for _ in range(children):
            read_group()

    g = expect("num_groups:")
    for _ in range(g):
        read_group()
    return points, labels

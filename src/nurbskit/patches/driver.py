"""``fit_patches``: a point cloud as a few trimmed NURBS patches (NURBSFit, Algorithm 1).

Flow (one function per step, each in its own module):

1. **normals** (:mod:`.normals`): kept when given, else PCA on the kNN graph, oriented by
   propagation;
2. **planar start** (:mod:`.planar`): region growing + refinement, or labels from a
   GoCoPP / PolyFit ``.vg`` file;
3. **adjacency** (:mod:`.adjacency`) and **priority** (:mod:`.quadric`, :mod:`.queue`):
   every pair of adjacent regions enters a heap keyed by the Taubin quadric error of
   their union (sums of 10 x 10 moment matrices);
4. **merge and refit** (:mod:`.refit`, :mod:`.energy`): the cheapest pair is fitted with
   one NURBS patch (the project's fitting), its inliers found by true projection, and the
   merge kept only when the energy U decreases and the patch does not round a sharp crease
   (its parts meet at a steep seam, or it bends tighter than ``min_radius`` where it turns
   away from its parts' own normals: a fillet cut into planar strips still merges); a
   crease refusal is inherited, without a fit, by every later pair holding both its sides
   (:func:`contains_refused`); a leftover of at most ``leftover`` of the points is exempt
   from both tests (the energy alone decides); a rejected pair is tried again (with its
   cached fit) when a neighbour of it changes;
5. **finalise**: untouched planar regions become flat patches, outliers join a
   neighbouring patch they lie within ``eps`` of; a cloud larger than ``max_points`` ran
   steps 1-5 on a seeded subset, and now every input point is projected onto the patches
   of its nearest merged points (5b);
6. **trim** (:mod:`.trim`): alpha shapes of the inliers in (u, v), trimmed meshes;
7. **metrics** (:mod:`.metrics`).

Convention: ``points (N, 3)`` in any units; ``eps`` and the other lengths of
:class:`~nurbskit.patches.config.PatchConfig` are fractions of the bounding-box diagonal.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Callable

import numpy as np
import torch

from ..core import NURBSSurface
from ..core.trim import TrimmedSurface
from ..errors import InputError
from .adjacency import adjacency
from .config import MIN_POINTS, PatchConfig
from .energy import Contribution, energy
from .metrics import patch_metrics
from .normals import knn_graph, orient_normals, pca_normals
from .planar import planar_start, planes_of, relabel_by_size, plane_distances
from .quadric import moments, taubin_error
from .queue import MergeQueue
from .refit import crease_stats, fit_patch, plane_patch, point_distances, refine_patch, surface_normals
from .trim import trim_patch, trimmed_mesh

Progress = Callable[[str, int, int], None]


@dataclass
class Patch:
    """One output patch: its surface, trimmed faces, inliers and trimmed mesh."""

    surface: NURBSSurface
    closed: bool
    faces: list[TrimmedSurface]
    inliers: np.ndarray
    """``(M,)`` indices of the input points that are inliers of this patch."""
    distance: np.ndarray
    """``(M,)`` their true distances to the surface (input units)."""
    params: np.ndarray
    """``(M, 2)`` their foot-point parameters."""
    regions: list[int]
    """The planar-start regions merged into this patch."""
    mesh: tuple[np.ndarray, np.ndarray]
    """Trimmed triangle mesh of all faces: ``vertices (V, 3)``, ``faces (F, 3)``."""

    def summary(self) -> dict:
        return {
            "ctrl": list(self.surface.sizes),
            "degrees": list(self.surface.degrees),
            "closed_v": bool(self.closed),
            "inliers": int(len(self.inliers)),
            "mean_distance": float(self.distance.mean()) if len(self.distance) else 0.0,
            "planar_regions": [int(r) for r in self.regions],
            "faces": len(self.faces),
            "holes": sum(len(f.holes) for f in self.faces),
            "triangles": int(len(self.mesh[1])),
        }


@dataclass
class PatchSet:
    """The result of :func:`fit_patches`."""

    patches: list[Patch]
    labels: np.ndarray
    """``(N,)`` patch per input point, -1 for outliers."""
    points: np.ndarray
    normals: np.ndarray
    planar_labels: np.ndarray
    config: PatchConfig
    eps: float
    """The inlier tolerance in input units."""
    history: list[dict] = field(default_factory=list)
    """One record per merge tried: regions, priority, energy before/after, accepted."""
    energy: list[float] = field(default_factory=list)
    """The energy U after the start and after every accepted merge."""
    metrics: dict = field(default_factory=dict)
    planar: dict = field(default_factory=dict)
    timings: dict = field(default_factory=dict)
    counts: dict = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.patches)

    @property
    def faces(self) -> list[TrimmedSurface]:
        """Every trimmed face of every patch, in patch order (what CAD exchange writes)."""
        return [face for patch in self.patches for face in patch.faces]


@dataclass
class _Region:
    members: np.ndarray
    distance: np.ndarray
    params: np.ndarray | None
    surface: NURBSSurface | None
    closed: bool
    moments: tuple[np.ndarray, np.ndarray]
    origin: list[int]
    topology: object = None
    normals: np.ndarray | None = None
    """``(M,)`` x 3: each member's normal in this region's model (plane or patch)."""

    def contribution(self, eps: float) -> Contribution:
        ok = self.distance < eps
        return Contribution(int(ok.sum()), float(self.distance[ok].sum() / eps))


def _add(a: Contribution, b: Contribution, sign: int = 1) -> Contribution:
    return Contribution(a.inliers + sign * b.inliers, a.distance + sign * b.distance)


def _check_points(points) -> np.ndarray:
    if isinstance(points, torch.Tensor):
        points = points.detach().cpu().numpy()
    x = np.asarray(points, dtype=np.float64)
    if x.ndim != 2 or x.shape[1] != 3:
        raise InputError(f"points must have shape (N, 3), got {x.shape}")
    if len(x) < MIN_POINTS:
        raise InputError(f"multi-patch fitting needs at least {MIN_POINTS} points, got {len(x)}")
    if not np.isfinite(x).all():
        raise InputError("points contain NaN or infinite values")
    from ..fit.api import bounding_diagonal, check_spread  # the surface fit's own tests, one message each

    lo, hi = torch.from_numpy(x.min(0)), torch.from_numpy(x.max(0))
    diagonal = bounding_diagonal(lo, hi)
    if not diagonal > 0:
        raise InputError(f"all {len(x)} input points coincide; there is no surface to fit")
    check_spread((torch.from_numpy(x) - (lo + hi) / 2) / diagonal)
    return x


def fit_patches(
    points,
    normals=None,
    config: PatchConfig | None = None,
    *,
    init_labels: np.ndarray | None = None,
    truth: np.ndarray | None = None,
    progress: Progress | None = None,
) -> PatchSet:
    """Fit a few trimmed NURBS patches to a point cloud (module docstring).

    Args:
        points: ``(N, 3)`` array or tensor.
        normals: ``(N, 3)`` normals, or None to estimate them.
        config: a :class:`PatchConfig` (None: the defaults).
        init_labels: ``(N,)`` planar-start regions (-1: none), e.g. from :func:`read_vg`;
            None: our region growing.
        truth: ``(N,)`` true segment labels, for the IoU metric.
        progress: called as ``progress(stage, done, total)``.

    Returns:
        a :class:`PatchSet`.

    Example:
        >>> rng = np.random.default_rng(0)
        >>> xy = rng.random((400, 2))
        >>> result = fit_patches(np.c_[xy, 0.05 * xy[:, 0] ** 2])
        >>> len(result), result.metrics["completeness"] > 99
        (1, True)
    """
    cfg = (config or PatchConfig()).validate()
    full = _check_points(points)
    check_patch_memory(len(full))
    report = progress or (lambda stage, done, total: None)
    timings: dict[str, float] = {}
    lo, hi = full.min(0), full.max(0)
    diag = float(np.linalg.norm(hi - lo))
    eps = cfg.eps * diag
    rng = np.random.default_rng(cfg.seed)
    # Large clouds: the planar start and the merges run on a seeded subset of max_points
    # (a surface is determined long before 10^5 points); every input point is assigned
    # by projection onto the final patches at the end (step 5b). Points repeated in the
    # input (scans merged, files concatenated) enter the subset once: copies would fill
    # each other's neighbourhoods and leave the normals undefined.
    distinct = distinct_rows(full)
    subset = None if distinct is None else distinct
    base = len(full) if distinct is None else len(distinct)
    if cfg.max_points and base > cfg.max_points:
        pick = np.sort(rng.choice(base, cfg.max_points, replace=False))
        subset = pick if distinct is None else distinct[pick]
    x = full if subset is None else full[subset]
    n = len(x)
    xn = (x - (lo + hi) / 2) / diag  # for the quadric moments: unit diagonal

    # 1. normals
    t = time.perf_counter()
    report("normals", 0, 1)
    _, nb = knn_graph(x, cfg.neighbours)
    pca, variation = pca_normals(x, nb)
    if normals is None:
        nrm = orient_normals(x, pca, nb)
    else:
        nrm = np.asarray(normals.detach().cpu().numpy() if isinstance(normals, torch.Tensor) else normals, dtype=np.float64)
        if nrm.shape != full.shape:
            raise InputError(f"normals must have the points' shape {full.shape}, got {nrm.shape}")
        nrm = nrm if subset is None else nrm[subset]
        nrm = nrm / np.maximum(np.linalg.norm(nrm, axis=1, keepdims=True), 1e-300)
    report("normals", 1, 1)
    timings["normals"] = time.perf_counter() - t

    # 2. planar start
    t = time.perf_counter()
    report("planar", 0, 1)
    min_region = cfg.min_region or max(10, int(0.002 * n))
    if init_labels is None:
        start = planar_start(x, nrm, nb, variation, cfg.planar_eps * eps, cfg.normal_angle, min_region)
        labels0 = start.labels
    else:
        labels0 = np.asarray(init_labels, dtype=np.int64)
        if labels0.shape != (len(full),):
            raise InputError(f"the planar start has {labels0.shape[0]} labels for {len(full)} points")
        labels0 = labels0 if subset is None else labels0[subset]
        labels0 = relabel_by_size(labels0, 3)
    centers, plane_normals = planes_of(x, labels0)
    inside = labels0 >= 0
    pd = plane_distances(x[inside], centers[labels0[inside]], plane_normals[labels0[inside]])
    planar = {
        "planes": int(len(centers)),
        "coverage": float(100.0 * inside.mean()),
        "mean_error": float(pd.mean() / diag) if len(pd) else 0.0,
        "source": "region growing" if init_labels is None else "vertex groups",
    }
    if len(centers) == 0:
        raise InputError("the planar start found no region: the cloud is too sparse or too noisy for this eps")
    report("planar", 1, 1)
    timings["planar"] = time.perf_counter() - t

    # 3. regions, adjacency and priorities
    t = time.perf_counter()
    regions: dict[int, _Region] = {}
    order = np.argsort(labels0, kind="stable")
    bounds = np.searchsorted(labels0[order], np.arange(len(centers) + 1))
    for r in range(len(centers)):
        idx = order[bounds[r] : bounds[r + 1]]
        d = plane_distances(x[idx], np.broadcast_to(centers[r], (len(idx), 3)), np.broadcast_to(plane_normals[r], (len(idx), 3)))
        regions[r] = _Region(idx, d, None, None, False, moments(xn[idx]), [r],
                             normals=np.broadcast_to(plane_normals[r], (len(idx), 3)))
    graph = adjacency(labels0, nb, cfg.min_links)
    # per point: its current region and its normal in that region's model (the crease test)
    current = labels0.copy()
    model_normal = np.zeros((n, 3))
    for r, reg in regions.items():
        model_normal[reg.members] = reg.normals

    def seam_angle(a: int, b: int) -> float:
        """Median angle (degrees) between a's and b's model normals across the kNN links joining them."""
        ia = regions[a].members
        hit = current[nb[ia]] == b
        if not hit.any():
            return 0.0
        i = np.repeat(ia, hit.sum(1))
        j = nb[ia][hit]
        cos = np.abs((model_normal[i] * model_normal[j]).sum(1))
        return float(np.degrees(np.arccos(np.clip(np.median(cos), 0.0, 1.0))))
    queue = MergeQueue()
    priority: dict[tuple[int, int], float] = {}

    def pair_error(a: int, b: int) -> float:
        (ma, na), (mb, nb_) = regions[a].moments, regions[b].moments
        return taubin_error(ma + mb, na + nb_) / cfg.eps**2  # in eps^2

    for a in graph:
        for b in graph[a]:
            if a < b:
                priority[(a, b)] = pair_error(a, b)
                queue.push(priority[(a, b)], a, b)
    timings["priority"] = time.perf_counter() - t

    # 4. merge and refit
    t = time.perf_counter()
    s0 = len(regions)
    total = Contribution(0, 0.0)
    for reg in regions.values():
        total = _add(total, reg.contribution(eps))
    alive = s0
    u, parts = energy(total, alive, s0, n, cfg.weights)
    energies = [u]
    history: list[dict] = []
    cache: dict[tuple[int, int], _Region | None] = {}
    rejected: set[tuple[int, int]] = set()
    crease_log: dict[tuple[int, int], tuple[float, float, float]] = {}
    counts = {"fits": 0, "candidates": 0, "accepted": 0, "seams": 0, "creases": 0, "skipped_quadric": 0, "retries": 0,
              "inherited": 0}
    # planar-start regions of the two sides of every union refused for rounding a crease
    creased: list[tuple[frozenset, frozenset]] = []
    seam_diag: dict = {}

    def holds_crease(a: int, b: int) -> bool:
        return contains_refused(regions[a].origin, regions[b].origin, creased)
    next_id = s0
    while True:
        item = queue.pop()
        if item is None:
            break
        e, a, b = item
        if cfg.max_quadric_error and e > cfg.max_quadric_error:
            counts["skipped_quadric"] += 1
            continue
        key = (a, b)
        if key in cache:
            cand = cache[key]
            counts["retries"] += 1
        else:
            # parts meeting at a steep seam cannot be one smooth patch, however a fit would
            # round it: decided from the parts' own normals, before any fit
            seam = seam_angle(a, b)
            # a leftover (a strip or a cap at an edge, at most `leftover` of the points) is
            # exempt from the seam and crease tests: the energy alone decides its merge
            small = min(len(regions[a].members), len(regions[b].members)) <= cfg.leftover * n
            if seam > cfg.crease_seam and not small:
                cand = None
                counts["seams"] += 1
                crease_log[key] = (float("nan"), float("nan"), seam)
                cache[key] = cand
                record = {"a": a, "b": b, "priority": e, "energy_before": u, "seam_angle": seam,
                          "accepted": False, "reason": "seam"}
                history.append(record)
                report("merge", counts["accepted"], s0 - 1)
                continue
            if cfg.crease_inherit and holds_crease(a, b):
                # the crease a refused union rounded lies between a and b too: no smooth patch
                # over a superset of that union can avoid rounding it
                cache[key] = None
                counts["inherited"] += 1
                crease_log[key] = (float("nan"), float("nan"), seam)
                history.append({"a": a, "b": b, "priority": e, "energy_before": u, "seam_angle": seam,
                                "accepted": False, "reason": "crease (inherited)"})
                report("merge", counts["accepted"], s0 - 1)
                continue
            members = np.concatenate([regions[a].members, regions[b].members])
            grids = [regions[r].surface.sizes for r in (a, b) if regions[r].surface is not None]
            start_ctrl = tuple(np.max(grids, axis=0)) if grids else None
            pf = fit_patch(x[members], eps, cfg, rng=rng, start_ctrl=start_ctrl)
            counts["fits"] += pf.fits
            counts["candidates"] += 1
            ok = pf.distance < eps
            part_normals = np.concatenate([regions[a].normals, regions[b].normals])
            tight, turned = crease_stats(pf.surface, pf.params[ok], cfg.min_radius * eps,
                                         model_normals=part_normals[ok], max_angle=cfg.crease_angle)
            crease_log[key] = (tight, turned, seam)
            # recorded in the history (not a test): how the union treats the points along the
            # seam (points of one part with a kNN link into the other), for reading its decisions
            at = np.r_[(current[nb[regions[a].members]] == b).any(1), (current[nb[regions[b].members]] == a).any(1)]
            # the union's normal at every member: the seam record reads it here, and an
            # accepted union keeps it as its members' model normals (one evaluation, not two)
            union_normals = surface_normals(pf.surface, pf.params)
            un = union_normals[at]
            ang = np.degrees(np.arccos(np.clip(np.abs((un * part_normals[at]).sum(1)), 0, 1)))
            seam_diag[key] = dict(
                fits=pf.fits, seam_pts=int(at.sum()),
                seam_turn_med=float(np.median(ang)) if len(ang) else 0.0,
                seam_turn_p90=float(np.percentile(ang, 90)) if len(ang) else 0.0,
                seam_dist=float(pf.distance[at].mean() / eps) if at.any() else 0.0,
                rest_dist=float(pf.distance[~at].mean() / eps) if (~at).any() else 0.0)
            if tight > cfg.crease_fraction and turned > cfg.crease_turned and not small:
                cand = None
                counts["creases"] += 1
                creased.append((frozenset(regions[a].origin), frozenset(regions[b].origin)))
            else:
                (ma, na), (mb, nb_) = regions[a].moments, regions[b].moments
                cand = _Region(members, pf.distance, pf.params, pf.surface, pf.closed, (ma + mb, na + nb_),
                               regions[a].origin + regions[b].origin, pf.topology, union_normals)
            cache[key] = cand
        record = {"a": a, "b": b, "priority": e, "energy_before": u}
        if key in crease_log:
            record["tight"], record["turned"], record["seam_angle"] = crease_log[key]
        record.update(seam_diag.get(key, {}))
        if cand is None:
            record.update(accepted=False, reason="crease")
            history.append(record)
            report("merge", counts["accepted"], s0 - 1)
            continue
        new_total = _add(_add(total, regions[a].contribution(eps), -1), regions[b].contribution(eps), -1)
        new_total = _add(new_total, cand.contribution(eps))
        u_new, parts_new = energy(new_total, alive - 1, s0, n, cfg.weights)
        record.update(energy_after=u_new, ctrl=list(cand.surface.sizes), closed_v=cand.closed)
        ca, cb, cu = regions[a].contribution(eps), regions[b].contribution(eps), cand.contribution(eps)
        record.update(parts_in=ca.inliers + cb.inliers, union_in=cu.inliers, parts_dist=ca.distance + cb.distance,
                      union_dist=cu.distance, size_a=len(regions[a].members), size_b=len(regions[b].members),
                      origin_a=list(regions[a].origin), origin_b=list(regions[b].origin))
        if u_new < u:
            new = next_id
            next_id += 1
            regions[new] = cand
            current[cand.members] = new
            model_normal[cand.members] = cand.normals
            queue.retire(a)
            queue.retire(b)
            links: dict[int, int] = {}
            for old in (a, b):
                for c, k in graph.pop(old).items():
                    if c not in (a, b):
                        links[c] = links.get(c, 0) + k
                        graph[c].pop(old, None)
            graph[new] = links
            for c, k in links.items():
                graph[c][new] = k
                pk = (min(c, new), max(c, new))
                priority[pk] = pair_error(c, new)
                queue.push(priority[pk], c, new)
            # A neighbour changed: try its rejected merges again (their fits are cached).
            for pair in sorted(rejected):
                if not (queue.alive(pair[0]) and queue.alive(pair[1])):
                    rejected.discard(pair)
                elif pair[0] in links or pair[1] in links:
                    rejected.discard(pair)
                    queue.push(priority[pair], *pair)
            del regions[a], regions[b]
            total, u, alive = new_total, u_new, alive - 1
            energies.append(u)
            counts["accepted"] += 1
            record.update(accepted=True, new=new)
        else:
            rejected.add(key)
            record.update(accepted=False, reason="energy")
        history.append(record)
        report("merge", counts["accepted"], s0 - 1)
    timings["merge"] = time.perf_counter() - t

    # 5. finalise: planar regions become flat patches; outliers join a patch they fit
    t = time.perf_counter()
    final = sorted(regions, key=lambda r: -len(regions[r].members))
    for i, r in enumerate(final):
        reg = regions[r]
        if reg.surface is None:
            reg.surface = plane_patch(x[reg.members], cfg.min_ctrl, cfg.degree)
            reg.params, reg.distance = point_distances(reg.surface, x[reg.members])
        elif cfg.final_iters:
            # the winners get the default refinement (candidates were least-squares fits)
            ok = reg.distance < eps
            surface = refine_patch(reg.surface, reg.topology, x[reg.members[ok]], cfg, rng=rng)
            p, d = point_distances(surface, x[reg.members], reg.closed)
            counts["refined"] = counts.get("refined", 0) + 1
            before = reg.contribution(eps)
            after = Contribution(int((d < eps).sum()), float(d[d < eps].sum() / eps))
            u_after, _ = energy(_add(_add(total, before, -1), after), alive, s0, n, cfg.weights)
            if u_after < u:  # kept, like a merge, only when the energy falls
                reg.surface, reg.params, reg.distance = surface, p, d
                total, u = _add(_add(total, before, -1), after), u_after
                counts["refinements_kept"] = counts.get("refinements_kept", 0) + 1
        report("finalise", i + 1, len(final))
    # 5a. absorption: a small patch whose points its neighbours already fit (their surfaces
    # extended to its points, true projection: at least absorb_held of them within eps) is
    # dissolved into them when the energy falls:
    # a leftover strip at a sharp edge or a fillet's end costs a patch (simplicity) for
    # points the neighbours hold within eps anyway (fidelity, completeness); points no
    # neighbour holds become outliers (the outlier pass below may still place them).
    if cfg.absorb:
        for r in sorted(regions, key=lambda r: len(regions[r].members)):
            reg = regions[r]
            if len(reg.members) > cfg.absorb * n:
                break
            nbrs = [c for c in graph.get(r, {}) if c in regions and c != r]
            if not nbrs:
                continue
            pts = x[reg.members]
            best_d, best_c, best_p = np.full(len(pts), np.inf), np.full(len(pts), -1), np.zeros((len(pts), 2))
            for c in nbrs:
                p, d = point_distances(regions[c].surface, pts, regions[c].closed)
                better = d < best_d
                best_d[better], best_c[better], best_p[better] = d[better], c, p[better]
            take = best_d < eps
            gained = Contribution(int(take.sum()), float(best_d[take].sum() / eps))
            new_total = _add(_add(total, reg.contribution(eps), -1), gained)
            u_new, _ = energy(new_total, alive - 1, s0, n, cfg.weights)
            record = {"a": r, "b": -1, "absorbed_into": [int(c) for c in nbrs], "points": int(len(pts)),
                      "held": int(take.sum()), "energy_before": u, "energy_after": u_new}
            # the neighbours must fit the patch (hold at least absorb_held of its points
            # within eps), not merely make it cheaper to drop than to keep
            if take.mean() >= cfg.absorb_held and u_new < u:
                for c in nbrs:
                    sel = take & (best_c == c)
                    if sel.any():
                        nc = regions[c]
                        nc.members = np.concatenate([nc.members, reg.members[sel]])
                        nc.distance = np.concatenate([nc.distance, best_d[sel]])
                        nc.params = np.concatenate([nc.params, best_p[sel]])
                        if nc.normals is not None:
                            nc.normals = np.concatenate([nc.normals, surface_normals(nc.surface, best_p[sel])])
                for c, k in graph.pop(r).items():  # the absorbed patch's neighbours now touch each other
                    graph.get(c, {}).pop(r, None)
                del regions[r]
                total, u, alive = new_total, u_new, alive - 1
                energies.append(u)
                counts["absorbed"] = counts.get("absorbed", 0) + 1
                record.update(accepted=True, reason="absorb")
            else:
                record.update(accepted=False, reason="absorb")
            history.append(record)
        final = sorted(regions, key=lambda r: -len(regions[r].members))
    owner = np.full(n, -1, dtype=np.int64)
    dist = np.full(n, np.inf)
    params = np.zeros((n, 2))
    for i, r in enumerate(final):
        reg = regions[r]
        owner[reg.members], dist[reg.members], params[reg.members] = i, reg.distance, reg.params
    # a (point, patch) pair projected once is not projected again in a later round: the
    # patch has not moved, so its distance has not either (and did not place the point)
    tried = np.zeros((n, len(final)), dtype=bool)
    for _ in range(10):  # outliers next to newly assigned points get their turn in the next round
        out = np.flatnonzero(~(dist < eps))
        if not len(out):
            break
        cand_labels = owner[nb[out]]  # patches of the outliers' neighbours
        moved = 0
        for i, r in enumerate(final):
            pts = out[(cand_labels == i).any(axis=1) & (owner[out] != i) & ~tried[out, i]]
            tried[pts, i] = True
            if not len(pts):
                continue
            p, d = point_distances(regions[r].surface, x[pts], regions[r].closed)
            better = (d < eps) & (d < dist[pts])
            owner[pts[better]], dist[pts[better]], params[pts[better]] = i, d[better], p[better]
            moved += int(better.sum())
        if not moved:
            break
    labels = np.where(dist < eps, owner, -1)
    timings["finalise"] = time.perf_counter() - t

    # 5b. a subsampled cloud: every input point goes to the patch it lies closest to among
    # the patches of its nearest subset points (true projection), as an inlier within eps
    nearest = None
    if subset is not None:
        t = time.perf_counter()
        from scipy.spatial import cKDTree

        _, near = cKDTree(x).query(full, k=4)
        nearest = near[:, 0]
        f_owner, f_dist, f_params = assign_by_projection(full, labels[near], [regions[r] for r in final], report)
        f_owner = np.where(f_dist < eps, f_owner, -1)
        timings["assign"] = time.perf_counter() - t

    # 6. trim
    t = time.perf_counter()
    patches: list[Patch] = []
    renumber = np.full(len(final) + 1, -1, dtype=np.int64)  # final index -> patch index (last: -1)
    for i, r in enumerate(final):
        idx = np.flatnonzero(labels == i)
        reg = regions[r]
        # trimmed on the merged points' feet (the subset of a large cloud: its outline is the same)
        faces = trim_patch(params[idx], reg.surface, reg.closed) if len(idx) >= 3 else []
        if not faces:
            labels[idx] = -1
            continue
        vs, fs, offset = [], [], 0
        for face in faces:
            v, f = trimmed_mesh(face)
            vs.append(v)
            fs.append(f + offset)
            offset += len(v)
        mesh = (np.concatenate(vs), np.concatenate(fs))
        labels[idx] = len(patches)
        renumber[i] = len(patches)
        if subset is not None:
            idx = np.flatnonzero(f_owner == i)
            patches.append(Patch(reg.surface, reg.closed, faces, idx, f_dist[idx], f_params[idx], reg.origin, mesh))
        else:
            patches.append(Patch(reg.surface, reg.closed, faces, idx, dist[idx], params[idx], reg.origin, mesh))
        report("trim", i + 1, len(final))
    timings["trim"] = time.perf_counter() - t
    if subset is not None:
        # the input's own labels, distances, normals and planar start (of the nearest subset point)
        labels, dist = renumber[f_owner], f_dist
        nrm = nrm[nearest] if normals is None else np.asarray(
            normals.detach().cpu().numpy() if isinstance(normals, torch.Tensor) else normals, dtype=np.float64)
        labels0 = labels0[nearest]
        n = len(full)

    # 7. metrics
    t = time.perf_counter()
    report("metrics", 0, 1)
    m = patch_metrics(full, labels, np.where(labels >= 0, dist, 0.0), [p.mesh for p in patches], eps, truth=truth, seed=cfg.seed)
    final_total = Contribution(int((labels >= 0).sum()), float(dist[labels >= 0].sum() / eps))
    m["energy"], parts = energy(final_total, len(patches), s0, n, cfg.weights)
    m["energy_parts"] = parts
    report("metrics", 1, 1)
    timings["metrics"] = time.perf_counter() - t
    counts["stale_pops"] = queue.stale_pops
    counts["pushes"] = queue.pushes
    counts["merged_points"] = int(len(x))
    counts["repeated_points"] = int(len(full) - base)
    return PatchSet(patches, labels, full, nrm, labels0, cfg, eps, history, energies, m, planar, timings, counts)


def distinct_rows(points: np.ndarray) -> np.ndarray | None:
    """Indices of the first occurrence of every distinct row, in input order; None when no
    row repeats.

    Example:
        >>> distinct_rows(np.array([[0.0, 1], [2, 3], [0, 1]])), distinct_rows(np.eye(2))
        (array([0, 1]), None)
    """
    _, first = np.unique(points, axis=0, return_index=True)
    return None if len(first) == len(points) else np.sort(first)


def contains_refused(a: list[int], b: list[int], refused: list[tuple[frozenset, frozenset]]) -> bool:
    """Whether parts made of planar regions ``a`` and ``b`` hold both sides of a refused union.

    ``refused`` lists ``(side, side)`` pairs of planar-region sets whose union was refused
    for rounding a crease. When one side lies in ``a`` and the other in ``b``, the crease
    runs between ``a`` and ``b`` too, and no smooth patch over ``a`` and ``b`` (a superset
    of the refused union) can avoid rounding it: the pair is refused without a fit.

    Example:
        >>> refused = [(frozenset({1}), frozenset({2}))]
        >>> contains_refused([1, 5], [2], refused), contains_refused([1, 2], [5], refused)
        (True, False)
    """
    oa, ob = set(a), set(b)
    return any((sa <= oa and sb <= ob) or (sa <= ob and sb <= oa) for sa, sb in refused)


#: Bytes per input point of a run beyond the merge subset: the points, normals, labels,
#: distances and foot parameters, the 4-neighbour query, the metrics' kNN queries and the
#: projection chunks' temporaries (measured peak over input size, rounded up).
BYTES_PER_POINT = 600
#: Bytes of the rest: torch, the fits of the merge subset (max_points), the trimmed meshes
#: and the output samples of the metrics.
BASE_BYTES = 1.5 * 2**30
CHUNK = 65_536


def patch_memory(n_points: int) -> float:
    """An upper estimate of the bytes :func:`fit_patches` needs for ``n_points`` input points."""
    return BASE_BYTES + BYTES_PER_POINT * float(n_points)


def check_patch_memory(n_points: int, what: str = "the input", *, budget: float | None = None) -> None:
    """Refuse, before any work, a cloud whose run would not fit in memory (one-line OptionError)."""
    from .._budget import require_memory

    require_memory(patch_memory(n_points), f"multi-patch fitting of {what} ({n_points:,} points)",
                   "subsample the cloud (e.g. --sample) to fewer points", budget=budget)


def assign_by_projection(points: np.ndarray, candidates: np.ndarray, regions: list[_Region],
                         report: Progress) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Owner ``(N,)`` (-1: outlier), distance ``(N,)`` and foot parameters ``(N, 2)`` of every point.

    ``candidates (N, k)`` holds, per point, the indices of the patches (-1: none) of its
    nearest merged points; a point is projected (the core's projection, in chunks of
    ``CHUNK`` points) onto each of its candidate patches and kept by the closest within
    the inlier tolerance by the caller.
    """
    n = len(points)
    owner = np.full(n, -1, dtype=np.int64)
    dist = np.full(n, np.inf)
    params = np.zeros((n, 2))
    for i, reg in enumerate(regions):
        pts = np.flatnonzero((candidates == i).any(axis=1))
        for start in range(0, len(pts), CHUNK):
            chunk = pts[start : start + CHUNK]
            p, d = point_distances(reg.surface, points[chunk], reg.closed)
            better = d < dist[chunk]
            owner[chunk[better]], dist[chunk[better]], params[chunk[better]] = i, d[better], p[better]
        report("assign", i + 1, len(regions))
    return owner, dist, params

"""Classical curve extraction from a drawing, no network: ink, skeleton, strokes, B-splines.

Steps (each a library call where one exists):

1. Ink: the image in grey; Otsu's threshold (``skimage.filters.threshold_otsu``) splits it
   in two classes, and the smaller class is the ink, so dark on light and light on dark
   both work (drawings are mostly background).
2. Skeleton: ``skimage.morphology.skeletonize`` (Zhang-Suen) of the ink mask, its thin
   holes (slivers between strokes running side by side) filled first.
3. Strokes: the skeleton as an 8-connected pixel graph; endpoints (one neighbour) and
   junctions (three or more; adjacent junction pixels are one junction) are its nodes,
   the pixel chains between them its edges. Spurs shorter than the stroke width are
   pruned, and junctions joined by an edge shorter than the stroke width merged (a thick
   "X" skeletonises into two "Y"s). At each junction the branches are rejoined by good
   continuation (see ``_pair_ends``): an "X" gives two strokes, a "T" its bar and its
   stem, a curve crossing itself one stroke, a hairpin (a curve turning back on itself)
   one stroke, two curves touching near-tangentially two strokes sharing the stretch.
   Then each junction's pairing is re-chosen for the fewest control points and curves
   that describe the whole strokes (``_fewest_curves``, minimum description length),
   and short edges between nodes of odd degree are tried as shared by two curves (walked
   twice), kept where the description is shorter. A vote on the number of curves (the
   MV network's, ``count_prior``; the ``hybrid`` method of :mod:`nurbskit.curves.api`)
   adds ``-2 log P(count)`` to the description.
4. Fit: a cubic B-spline per stroke by least squares on chord-length parameters
   (``nurbskit.core.basis.basis_matrix``), then parameter correction, each parameter
   replaced by its foot point's (``nurbskit.core.project.project_points_curve``),
   Hoschek's "intrinsic parametrisation" (The NURBS Book, section 9.4.1). The number of
   control points grows until the largest distance from the stroke's pixels to the curve
   is within the tolerance.
5. Optional refinement: the control points by L-BFGS on the Chamfer distance between the
   curves' samples and the ink pixels (``nurbskit.losses.chamfer_distance``).

Convention: pixel coordinates, x to the right, y down, the origin at the top-left corner
of the top-left pixel; the centre of pixel ``[row, col]`` is ``(col + 0.5, row + 0.5)``.
"""

from __future__ import annotations

import dataclasses
import functools

import numpy as np
from scipy.spatial import cKDTree

from ..errors import InputError, OptionError
from ..io.image import to_grey

# Weight of the control polygon's second differences in the least squares (see fit_stroke).
_SMOOTH = 1e-2
# Gaussian smoothing (pixels, along the stroke) of the skeleton's staircase before fitting.
_STROKE_SIGMA = 1.0
# Junctions joined by an edge shorter than this many stroke widths are one junction.
_MERGE = 5.0
# ... as long as the merged cluster spans at most this many times that distance.
_SPAN = 1.0
# Stroke widths above this (pixels) count as this for merging junctions and dropping short
# strokes: thick strokes (a digit upsampled) would merge every junction of the drawing.
_THICK = 4.0
# Branch directions at a junction are read over this many stroke widths of skeleton.
_REACH = 2.0

# The 8 neighbours of a pixel, as (drow, dcol).
_NEIGHBOURS = [(-1, -1), (-1, 0), (-1, 1), (0, -1), (0, 1), (1, -1), (1, 0), (1, 1)]


@dataclasses.dataclass
class Strokes:
    """Strokes traced from a skeleton.

    Attributes:
        strokes: one ``(n_i, 2)`` array of pixel centres (x, y) per stroke, in order.
        ink: ``(H, W)`` bool, the ink mask.
        width: estimated stroke width in pixels.
        inverted: True when the ink was light on a dark background.
    """

    strokes: list[np.ndarray]
    ink: np.ndarray
    width: float
    inverted: bool


# Lighting that varies by more than this (grey levels in [0, 1], across the image) is
# evened out before thresholding (see even_background).
_UNEVEN = 0.1


def even_background(grey: np.ndarray, n_ctrl: int | None = None) -> np.ndarray:
    """``grey (H, W)`` in [0, 1] with uneven lighting divided out -> ``(H, W)`` in [0, 1].

    A drawing photographed under a lamp is lighter on one side than the other, and one
    global threshold (Otsu) then takes a whole side for ink. The paper's (or board's)
    brightness is fitted as a bicubic B-spline height field of ``n_ctrl x n_ctrl`` control
    points over the image (``nurbskit.core.basis.basis_matrix``; default one span per 64 px
    of the shorter side, at most 3 spans: smooth at the scale of a lamp's falloff or a
    vignette, too stiff to follow a stroke; an image under 64 px across is returned as
    it is, its lighting not told apart from its strokes), by least squares on
    the image averaged down to at most 64 px across, four times, each time without the
    pixels more than 3 robust standard deviations (1.4826 x the median absolute residual)
    from the last fit, starting from a flat background at the median grey: the strokes,
    dark or light, are such outliers. Where the background so found varies by at most
    ``_UNEVEN``, covers less than half the image, or is not one smooth sheet (its pixels
    spread by over ``_UNEVEN`` about the fit: thick strokes filling a small frame, as
    a digit), the image is returned unchanged (scans and clean drawings: the same
    threshold as before). Otherwise light paper is divided by it (light times
    reflectance: the ink keeps its contrast on both sides) and a dark board has it
    subtracted, each rescaled to [0, 1].
    """
    import torch
    from skimage.measure import block_reduce

    from ..core.basis import basis_matrix
    from ..core.knots import clamped_uniform

    h, w = grey.shape
    if n_ctrl is None:
        if min(h, w) < 64:
            return grey
        n_ctrl = 3 + min(3, min(h, w) // 64)
    step = max(1, int(np.ceil(max(h, w) / 64)))
    small = block_reduce(grey, (step, step), np.mean)
    knots = clamped_uniform(n_ctrl, 3, dtype=torch.float64)

    def basis(centres, extent):  # (N, n_ctrl) at pixel centres of an axis of `extent` px
        return basis_matrix(knots, 3, n_ctrl, torch.as_tensor(np.clip(centres / extent, 0.0, 1.0)))

    # The products run in torch, on its threads: numpy's BLAS would start threads of its own
    # (which spin on a second core after each call).
    Br = basis(np.minimum((np.arange(small.shape[0]) + 0.5) * step, h), h)
    Bc = basis(np.minimum((np.arange(small.shape[1]) + 0.5) * step, w), w)
    A = torch.einsum("ri,cj->rcij", Br, Bc).reshape(-1, n_ctrl * n_ctrl)
    v = small.reshape(-1)
    r = v - np.median(v)  # the start: a flat background at the median grey
    keep = np.abs(r) <= 3 * 1.4826 * np.median(np.abs(r)) + 1e-9
    sigma = 0.0
    for _ in range(4):
        if keep.mean() < 0.5:  # no background covers most of the image
            return grey
        Ak = A[torch.as_tensor(keep)]  # normal equations (36 x 36): the B-spline basis keeps them well posed
        rhs = Ak.T @ torch.as_tensor(v[keep])
        coef = torch.linalg.solve(Ak.T @ Ak + 1e-9 * torch.eye(A.shape[1], dtype=A.dtype), rhs)
        r = v - (A @ coef).numpy()
        sigma = 1.4826 * np.median(np.abs(r[keep]))
        keep = np.abs(r) <= 3 * sigma + 1e-9
    background = (basis(np.arange(h) + 0.5, h) @ coef.reshape(n_ctrl, n_ctrl)
                  @ basis(np.arange(w) + 0.5, w).T).numpy()
    if keep.mean() < 0.5 or sigma > _UNEVEN or float(background.max() - background.min()) <= _UNEVEN:
        return grey
    if float(np.median(background)) >= 0.5:  # light paper: divide by the light
        out = grey / np.maximum(background, 1e-3)
    else:  # a dark board: take the glow away
        out = grey - background
        out = out - np.percentile(out, 0.1)
    return np.clip(out / max(float(np.percentile(out, 99.9)), 1e-6), 0.0, 1.0)


def ink_mask(grey: np.ndarray, source: str = "image") -> tuple[np.ndarray, bool]:
    """Otsu's threshold, kept clear of the background's noise; the smaller class is the ink
    -> ``(mask (H, W) bool, inverted)``.

    Raises InputError for a blank image (no contrast: nothing to trace).
    """
    from skimage.filters import threshold_otsu

    from ..io.image import check_contrast

    check_contrast(grey, source, "dark strokes on a light background or light on dark")
    t = threshold_otsu(grey)
    dark = grey <= t
    inverted = dark.sum() > dark.size / 2  # most pixels dark: light ink on a dark background
    # On a noisy background with little ink Otsu may split the background's own noise:
    # the threshold then stays 4 noise standard deviations beyond the median grey (the
    # background's level). The noise is read from neighbouring pixels' differences
    # (1.4826 x their median absolute value / sqrt 2), and only where it describes a
    # background: nine pixels in ten within it of the median. A clean drawing reads no
    # noise; a small image of thick shaded strokes (a digit) has no such background; both
    # keep Otsu's threshold.
    median = float(np.median(grey))
    spread = 4 * 1.4826 * float(np.median(np.abs(np.diff(grey, axis=1)))) / np.sqrt(2)
    if np.mean(np.abs(grey - median) <= spread) < 0.9:
        spread = 0.0
    mask = grey > max(t, median + spread) if inverted else grey <= min(t, median - spread)
    if not mask.any():
        raise InputError(f"{source}: no strokes found: {100 * dark.mean():.0f} % of the pixels are dark and none "
                         "stands out from the background as ink does (noise, or a picture without strokes?); "
                         "expected dark strokes on a light background or light on dark")
    return mask, bool(inverted)


def _neighbours(skel: np.ndarray, r: int, c: int):
    h, w = skel.shape
    for dr, dc in _NEIGHBOURS:
        rr, cc = r + dr, c + dc
        if 0 <= rr < h and 0 <= cc < w and skel[rr, cc]:
            yield rr, cc


def _graph(skel: np.ndarray):
    """Nodes and edges of a skeleton.

    Returns ``node_of`` (dict pixel -> node id), ``nodes`` (list of pixel lists) and
    ``edges`` (list of ``(a, b, pixels)`` with ``pixels`` from node ``a`` to node ``b``,
    including one pixel of each node; ``a == b == -1`` for a closed loop with no node).
    """
    from scipy import ndimage

    pixels = [tuple(p) for p in np.argwhere(skel)]
    # 8-neighbour counts of all pixels at once (a 3 x 3 box sum less the pixel itself).
    degree = ndimage.convolve(skel.astype(np.uint8), np.ones((3, 3), np.uint8), mode="constant") - 1
    special = skel & (degree != 2)
    labels, n = ndimage.label(special, structure=np.ones((3, 3)))
    node_of = {p: int(labels[p]) - 1 for p in pixels if labels[p] > 0}
    nodes = [[] for _ in range(n)]
    for p, k in node_of.items():
        nodes[k].append(p)
    edges, seen = [], set()
    # Walk from every node pixel into each non-node neighbour until the next node.
    for start, k in node_of.items():
        for nb in _neighbours(skel, *start):
            if nb in node_of or (start, nb) in seen:
                continue
            path, prev, cur = [start, nb], start, nb
            while cur not in node_of:
                nxt = [q for q in _neighbours(skel, *cur) if q != prev and q not in path[-3:]]
                if not nxt:
                    break
                # Prefer a 4-neighbour step, then any: keeps the chain one pixel wide.
                nxt.sort(key=lambda q: abs(q[0] - cur[0]) + abs(q[1] - cur[1]))
                prev, cur = cur, nxt[0]
                path.append(cur)
            end = node_of.get(cur, -1)
            seen.add((start, nb))
            if len(path) >= 2:
                seen.add((path[-1], path[-2]))
            edges.append((k, end, path))
    # Adjacent node pixels of different nodes do not happen (they are one label), but two
    # nodes can touch diagonally through no chain pixel: ndimage's 8-connectivity joins them.
    visited = set(node_of) | {p for _, _, e in edges for p in e}
    for p in pixels:  # closed loops without any node
        if p in visited:
            continue
        path, prev, cur = [p], None, p
        while True:
            visited.add(cur)
            nxt = [q for q in _neighbours(skel, *cur) if q != prev and q not in visited]
            if not nxt:
                break
            prev, cur = cur, nxt[0]
            path.append(cur)
        path.append(p)
        edges.append((-1, -1, path))
    return nodes, edges


def _direction(pixels: list, reach: int) -> np.ndarray:
    """Unit direction (x, y) of the chain ``pixels (row, col)`` leaving its first pixel.

    The principal axis (least-squares line, by SVD) of the first ``reach + 1`` pixels,
    oriented away from the first: less sensitive to the skeleton's one-pixel staircase
    than the chord to a single pixel.
    """
    p = np.asarray(pixels[: reach + 1], dtype=float)[:, ::-1]
    if len(p) < 2:
        return np.zeros(2)
    _, _, vt = np.linalg.svd(p - p.mean(axis=0), full_matrices=False)
    d = vt[0]
    return -d if d @ (p[-1] - p[0]) < 0 else d


# Holes in the ink at most this deep (pixels from their edge to their middle) are filled.
_SLIVER = 1.5


def _fill_slivers(ink: np.ndarray) -> np.ndarray:
    """The ink mask with its thin holes filled -> ``(H, W)`` bool.

    Where a curve turns back close to itself (a hairpin) or two strokes run side by side,
    the background between them is a sliver a pixel or two wide; its skeleton would be a
    thin cycle of two parallel branches. A hole no deeper than ``_SLIVER`` px (the
    largest distance from a hole pixel to the ink, ``scipy.ndimage.distance_transform_edt``)
    is ink; real loops of a curve enclose more.
    """
    from scipy import ndimage

    holes = ndimage.binary_fill_holes(ink) & ~ink
    if not holes.any():
        return ink
    labels, _ = ndimage.label(holes)
    out = ink.copy()
    for k, box in enumerate(ndimage.find_objects(labels), start=1):
        hole = np.pad(labels[box] == k, 1)  # the distance transform of each hole on its own box
        if ndimage.distance_transform_edt(hole).max() <= _SLIVER:
            out[box] |= hole[1:-1, 1:-1]
    return out


# Good continuation at a junction (cosines of the branches' directions, each pointing away
# from the junction). A hairpin or a near-tangent touch: two branches leaving a three-way
# junction within 90 degrees of each other (cosine >= 0), the third leaving on the other
# side (at more than about 100 degrees from each: cosine <= -0.2).
_PARALLEL = 0.0
_OPPOSITE = -0.2
# ... but no hairpin where a dead-end stem runs straight on into one branch (within
# _RUNS_ON degrees) and the other leaves it at more than _LEAVES degrees, the stem longer
# than _LONG_STEM times the branch-reading reach (skeleton pixels): one stroke with another
# ending on it at an acute angle (an "A", a "y"), not two sides merged (see _pair_ends).
# A hairpin's merged stem is short: the benchmark's drawn cusps that run on into one
# branch measured 11 to 17 px at 128 px (reach 4), the letters of the tests 53 px and more.
_RUNS_ON = 20.0
_LEAVES = 50.0
# ... nor where both branches turn away from such a stem by more than _SPREAD degrees (a
# "Y": a stroke ending where two others meet; a hairpin's two sides leave its merged stem
# nearly straight, one of them within a few degrees).
_SPREAD = 25.0
_LONG_STEM = 5.0
# ... and the ink along the stem one stroke wide: at most this many stroke widths (the
# two sides of a long hairpin merge into ink up to twice as wide, and the skeleton runs
# along the sliver filled between them).
_ONE_STROKE = 1.5


# Junctions with more branch ends than this are paired greedily (the exact matching
# enumerates (n - 1)!! pairings).
_EXACT_ENDS = 10


def _least_turning(ends: list, cos) -> list:
    """Pairs of ``ends`` meeting at one junction, the total turning through it least.

    Each curve through a junction enters along one branch and leaves along another, so
    the branches pair up: a minimum-weight perfect matching of the ends, the weight of a
    pair its turning angle ``arccos(-cos)`` (0 straight through, pi for a reversal;
    ``cos(e, f)`` the cosine between the two ends' directions, both pointing away from
    the junction). With an odd count one end stays alone: a curve ends there (a "T": a
    stroke ending on another curve). The two ends of one edge (a loop) are not paired
    with each other when other ends are there: a curve crossing itself continues through
    its crossing. Exhaustive over the (n - 1)!! matchings up to ``_EXACT_ENDS`` ends
    (945 for 10), most nearly straight pairs first beyond.
    """
    def turn(e, f):
        if e[0] == f[0] and len(ends) > 2:
            return 10.0  # a loop closed on itself at a crossing: last resort
        return float(np.arccos(np.clip(-cos(e, f), -1.0, 1.0)))

    if len(ends) > _EXACT_ENDS:
        out, used = [], set()
        for _, e, f in sorted((turn(e, f), e, f) for x, e in enumerate(ends) for f in ends[x + 1:]):
            if e not in used and f not in used:
                used.update((e, f))
                out.append((e, f))
        return out

    def best(rest):
        """(cost, pairs) of the best matching of ``rest`` (one end left alone when odd)."""
        if len(rest) < 2:
            return 0.0, []
        if len(rest) % 2:  # try each end as the one left alone
            return min((best(rest[:i] + rest[i + 1:]) for i in range(len(rest))), key=lambda t: t[0])
        e, options = rest[0], []
        for i in range(1, len(rest)):
            cost, pairs = best(rest[1:i] + rest[i + 1:])
            options.append((cost + turn(e, rest[i]), [(e, rest[i])] + pairs))
        return min(options, key=lambda t: t[0])

    return best(list(ends))[1]


def _pair_ends(edges: list, reach: int, stub: float = 0.0, one_stroke=None) -> tuple[dict, set, set]:
    """Which edge continues which through each node of the stroke graph (good continuation).

    ``edges`` is a list of ``(a, b, pixels)`` (node ids, ``-1`` for none; ``pixels`` from
    ``a`` to ``b`` as ``(row, col)``); an edge end is ``(edge index, side)``, side 0 at
    ``a`` and 1 at ``b``. Returns ``partner`` (end -> end: a stroke leaving through the
    first end comes back in through the second) and ``tips``, the ends joined at a
    hairpin's tip (no trimming there). Edges that two curves share are appended to
    ``edges`` as a second copy. Also returns ``done``, the nodes whose pairing the
    shared-edge rule settled (no other pairing is tried there).

    The rules, in order, at each node (the Gestalt rule of good continuation, as in
    vectorisation of line drawings, e.g. Noris et al., "Topology-driven vectorization of
    clean line drawings", ACM TOG 2013):

    - Shared edge: at a three-way junction where two branches leave within 90 degrees
      of each other and the third (the stem) on the other side, two strokes run
      along the stem. Either it ends there (a dead end: a hairpin, a curve turning back
      sharply, whose two sides merged into one skeleton line), and the two copies are
      joined at its tip, one curve; or its other end is a three-way junction of the same
      shape (two curves touching near-tangentially over a stretch), and the copies
      continue into the branches there, each into the one that turns least. No
      hairpin where the dead-end stem runs straight on into one branch (within
      ``_RUNS_ON`` degrees) while the other leaves at more than ``_LEAVES``, or both
      turn away from it by more than ``_SPREAD`` (a "Y"), and the stem is longer
      than ``_LONG_STEM * reach`` pixels and its ink one stroke wide
      (``one_stroke(path)``, when given, with ``_ONE_STROKE``): the medial line of two
      merged sides runs between them, and two sides stay merged only over a short
      stretch near the tip or make a wider stroke, so this is one stroke with another
      ending on it at an acute angle (the legs and the crossbar of an "A", the arms of
      a "y"). A short stem that runs on into one branch is a cusp (one side of a sharp
      turn runs on straight, the other turns back along it); two curves touching along
      a stretch may have one of them run straight through it, so the test is not made
      there. These directions are read further from the junction (from ``reach / 2``
      pixels out, over ``2 reach``), past the bend of the skeleton towards it.
    - Otherwise the branches are paired by least total turning (``_least_turning``):
      an "X" gives two strokes, a "T" its bar and its stem. A node with only two
      branches passes through, whatever the turn.
    - The two ends of a loop (an edge from a junction back to itself) always continue
      into other branches when any are left: a curve crossing itself stays one stroke.
    """
    at: dict[int, list] = {}
    for i, (a, b, _) in enumerate(edges):
        if a >= 0:
            at.setdefault(a, []).append((i, 0))
        if b >= 0:
            at.setdefault(b, []).append((i, 1))

    def direction(end, skip=0, span=reach):  # leaving the node, read over ``span`` pixels after ``skip``
        path = edges[end[0]][2]
        path = path if end[1] == 0 else path[::-1]
        return _direction(path[skip:] if len(path) > skip + 2 else path, span)

    def other(end):
        a, b, _ = edges[end[0]]
        return b if end[1] == 0 else a

    dirs = {end: direction(end) for ends in at.values() for end in ends}
    cos = lambda e, f: float(dirs[e] @ dirs[f])  # noqa: E731

    def distant(end):  # the direction past the skeleton's bend towards the junction
        return direction(end, reach // 2, 2 * reach)

    def runs_on(stem, f, g):
        """True where a long one-stroke dead-end ``stem`` is a stroke ending on ``f`` and ``g``: it runs
        straight on into one of them and the other leaves it (a "y"), or both turn away from it (a "Y")."""
        o, path = other(stem), edges[stem[0]][2]
        if o < 0 or len(at.get(o, [])) != 1 or len(path) <= _LONG_STEM * reach:
            return False
        turns = sorted(float(np.degrees(np.arccos(np.clip(-distant(stem) @ distant(e), -1.0, 1.0)))) for e in (f, g))
        ends_on = turns[0] < _RUNS_ON and turns[1] > _LEAVES or turns[0] > _SPREAD
        return ends_on and (one_stroke is None or one_stroke(path))

    def fork(k, stem):
        """The two other ends at three-way junction ``k`` if they fork away from ``stem``, else None."""
        ends = at.get(k, [])
        if len(ends) != 3 or stem not in ends:
            return None
        f, g = [e for e in ends if e != stem]
        if f[0] == g[0] or stem[0] in (f[0], g[0]):
            return None
        if (cos(f, g) >= _PARALLEL and cos(stem, f) <= _OPPOSITE and cos(stem, g) <= _OPPOSITE
                and not runs_on(stem, f, g)):
            return f, g
        return None

    def stubby(end):
        o = other(end)
        if o < 0 or len(at.get(o, [])) != 1:
            return False
        path = np.asarray(edges[end[0]][2], dtype=float)
        return float(np.linalg.norm(np.diff(path, axis=0), axis=1).sum()) < stub

    partner, tips, done = {}, set(), set()

    def link(e, f):
        partner[e], partner[f] = f, e

    # Shared edges first, the most nearly parallel forks first.
    candidates = []
    for k, ends in at.items():
        for stem in ends:
            pair = fork(k, stem)
            if pair is not None:
                candidates.append((-cos(*pair), k, stem, pair))
    candidates.sort(key=lambda t: t[0])
    for _, k, stem, (f, g) in candidates:
        if k in done:
            continue
        i, side = stem
        a, b, path = edges[i]
        if a == b:
            continue
        o = other(stem)
        far = (i, 1 - side)
        if o >= 0 and o not in done and len(at[o]) == 1:  # a hairpin: the copies meet at the tip
            j = len(edges)
            edges.append((a, b, path))
            link(f, (i, side))
            link(g, (j, side))
            link(far, (j, 1 - side))
            tips.update({far, (j, 1 - side)})
            done.update({k, o})
            continue
        pair2 = fork(o, far) if o >= 0 and o not in done else None
        if pair2 is not None:  # two curves touching along the stem
            j = len(edges)
            edges.append((a, b, path))
            f2, g2 = pair2
            if cos(f, f2) > cos(f, g2):  # f continues into the branch most nearly opposite to it
                f2, g2 = g2, f2
            link(f, (i, side))
            link(g, (j, side))
            link(f2, far)
            link(g2, (j, 1 - side))
            done.update({k, o})

    for k, ends in at.items():
        if k in done:
            continue
        if len(ends) == 2 and ends[0][0] != ends[1][0]:
            link(*ends)  # a pruned spur or a corner: the stroke passes through
            continue
        # Dead ends shorter than ``stub`` (the shortest stroke kept) stay out of the
        # pairing: a spur the pruning missed, or a curve's end overhanging a crossing by a
        # few pixels, would otherwise leave a real branch alone and split its curve.
        live = [e for e in ends if not stubby(e)]
        for e, f in _least_turning(live if len(live) >= 2 else ends, cos):
            link(e, f)
    return partner, tips, done


def _arc_length(points: np.ndarray) -> float:
    return float(np.linalg.norm(np.diff(points, axis=0), axis=1).sum())


def _min_length(width: float) -> float:
    """The shortest stroke kept (pixels): shorter pieces are left between junctions and
    loose ends; 3 stroke widths + 4 px, the width capped at 4 px for thick strokes."""
    return 2.0 * min(width, _THICK) + 4.0


def _cropped(ink: np.ndarray) -> tuple[np.ndarray, int, int]:
    """The ink's bounding box with a 2 px margin (drawings are mostly background), and its
    top-left corner ``(row, col)`` in the image."""
    rows, cols = np.nonzero(ink)
    r0, c0 = max(int(rows.min()) - 2, 0), max(int(cols.min()) - 2, 0)
    return ink[r0:int(rows.max()) + 3, c0:int(cols.max()) + 3], r0, c0


def _width(skel: np.ndarray, dt: np.ndarray) -> float:
    """Twice the median distance transform ``dt`` on the skeleton ``skel`` (1.0 if empty)."""
    return float(2 * np.median(dt[skel])) if skel.any() else 1.0


def stroke_width(ink: np.ndarray) -> float:
    """The strokes' width in pixels, as :func:`trace_strokes` estimates it: twice the median
    distance from the skeleton's pixels to the background (1.0 without ink)."""
    from scipy import ndimage
    from skimage.morphology import skeletonize

    if not ink.any():
        return 1.0
    ink, _, _ = _cropped(ink)
    return _width(skeletonize(_fill_slivers(ink)), ndimage.distance_transform_edt(ink))


def trace_strokes(ink: np.ndarray, width: float | None = None, simplify: bool = True,
                  tolerance: float | None = 1.0, count_prior=None,
                  search_extent: float | None = None) -> tuple[list[np.ndarray], float]:
    """Ink mask ``(H, W)`` bool -> strokes ``[(n_i, 2)]`` of pixel centres (x, y), and the stroke width.

    ``simplify=False`` keeps every junction and spur of the skeleton (no merging, no
    pruning): the fallback for blobs whose strokes are as wide as the drawing is long.
    ``tolerance`` (pixels, the fit's) drives the choice of pairings at junctions
    (:func:`_fewest_curves`); None keeps the good-continuation pairing alone.
    ``count_prior``, when given, is called with the skeleton ``(H, W)`` bool (the ink's
    frame), the stroke width (pixels) and ``ink`` itself, and returns the probabilities of
    1, 2, ... curves (a network's count vote,
    :func:`nurbskit.curves.nets.predict.count_probabilities`): evidence added to the
    description length of each candidate grouping (see :func:`_fewest_curves`), or None
    for no evidence. It is called only when the search runs: on drawings whose ink spans
    at most ``search_extent`` pixels (bounding-box diagonal; default ``_SEARCH_EXTENT``).
    """
    from scipy import ndimage
    from skimage.morphology import skeletonize

    if not ink.any():
        return [], 1.0 if width is None else width
    frame, full_ink = ink.shape, ink
    ink, r0, c0 = _cropped(ink)
    filled = _fill_slivers(ink)
    skel = skeletonize(filled)
    dt = ndimage.distance_transform_edt(ink)
    if width is None:
        width = _width(skel, dt)
    nodes, edges = _graph(skel)
    short = max(2.0, 1.5 * width)

    def length(path):
        return float(np.linalg.norm(np.diff(np.array(path, float), axis=0), axis=1).sum())

    # Merge junctions joined by a short edge; prune short spurs (edges to an endpoint).
    parent = list(range(len(nodes)))

    def find(k):
        while parent[k] != k:
            parent[k] = parent[parent[k]]
            k = parent[k]
        return k

    is_junction = [len(nodes[k]) > 1 or sum(1 for _ in _neighbours(skel, *nodes[k][0])) >= 3 for k in range(len(nodes))]
    # Shortest edges first, and a merge only while the whole cluster stays within the
    # merging distance: chained merges would make one "junction" of crossings far apart
    # and pair branches across it.
    limit = max(3.0, _MERGE * min(width, _THICK))
    centre = [np.mean(np.asarray(nd, dtype=float), axis=0) for nd in nodes]
    members = {k: [k] for k in range(len(nodes))}
    kept, merged = [], set()
    order = sorted(range(len(edges)), key=lambda x: length(edges[x][2]))
    for x in order:
        a, b, path = edges[x]
        if not (simplify and a >= 0 and b >= 0 and a != b and is_junction[a] and is_junction[b]
                and length(path) < limit):
            continue
        ra, rb = find(a), find(b)
        if ra == rb:
            merged.add(x)
            continue
        span = max(float(np.linalg.norm(centre[i] - centre[j])) for i in members[ra] for j in members[rb])
        if span <= _SPAN * limit:
            parent[ra] = rb
            members[rb] += members.pop(ra)
            merged.add(x)
    kept = [e for x, e in enumerate(edges) if x not in merged]
    degree = {}
    for a, b, _ in kept:
        for k in (a, b):
            if k >= 0:
                degree[find(k)] = degree.get(find(k), 0) + 1
    pruned = []
    for a, b, path in kept:
        ra, rb = (find(a) if a >= 0 else -1), (find(b) if b >= 0 else -1)
        spur = (ra >= 0 and rb >= 0 and ra != rb and min(degree[ra], degree[rb]) == 1
                and max(degree[ra], degree[rb]) >= 3 and length(path) < short)
        if spur:
            # A spur of skeletonisation barely reaches out of the junction's disc (the ink's
            # local radius there); a real branch of a thick stroke reaches well beyond.
            end, root = (path[0], path[-1]) if degree[ra] == 1 else (path[-1], path[0])
            # (Short branches of thin strokes, a few pixels, are spurs whatever their reach.)
            spur = length(path) < 6.0 or length(path) + dt[end] < 2.0 * dt[root] + 1.0
        if not spur or not simplify:
            pruned.append((ra, rb, path))
    edges = pruned

    filled_dt = []

    def one_stroke(path):
        """True where the ink along ``path`` (slivers filled) is one stroke wide, not two merged."""
        if not filled_dt:  # needed only at a long dead-end stem of a fork: rare
            filled_dt.append(ndimage.distance_transform_edt(filled))
        rows, cols = np.asarray(path).T
        return 2.0 * float(np.median(filled_dt[0][rows, cols])) <= _ONE_STROKE * width

    partner, tips, done = _pair_ends(edges, int(max(4, _REACH * width)), _min_length(width), one_stroke)
    # Near a junction the skeleton bends towards it (the medial axis of a crossing is not
    # the two centre lines): through a junction, the last pixels of each branch are left
    # out and the spline bridges the gap. Not at a hairpin's tip, which is the stroke's own end.
    trim = int(np.ceil(width))
    origin = (c0 + 0.5, r0 + 0.5)
    extent = float(np.hypot(*ink.shape))
    if simplify and tolerance is not None and extent <= (_SEARCH_EXTENT if search_extent is None else search_extent):
        prior = None
        if count_prior is not None:
            full = np.zeros(frame, bool)
            full[r0:r0 + skel.shape[0], c0:c0 + skel.shape[1]] = skel
            prior = count_prior(full, width, full_ink)
            prior = None if prior is None else np.asarray(prior, dtype=np.float64)
        partner, tips = _fewest_curves(edges, partner, tips, done, trim, origin, width, tolerance, extent, prior)
    out = [pts for pts, _ in _chains(edges, partner, tips, trim, origin)]
    out = _join_broken(out, width)
    return out, width


# The description length of a curve beyond its control points (see _fewest_curves): one
# more curve costs as much as this many control points.
_CURVE_COST = 4.0
# The search runs on drawings whose ink spans at most this many pixels (bounding-box
# diagonal): on the 512 px development drawings it changed no count for 3 times the
# time (benchmarks/results/curves.md).
_SEARCH_EXTENT = 256.0
# Junctions with more branch ends than this keep their good-continuation pairing.
_SEARCH_ENDS = 6
# Edges between two nodes of odd degree (junctions, or a junction and a dead end) up to
# this many stroke widths, plus as many pixels, are tried as shared by two curves (see
# _fewest_curves).
_SHARED = 10.0
# A network's count vote (see _fewest_curves): -log P(count) in nats times this is added
# to the description length (control points); probabilities below the floor count as it.
# Chosen on development drawings (128 px, 1-3 curves, seeds 300000 + i and 310000 + i,
# disjoint from the benchmark's): counts right with 2 / 3 / 4 / 6: 89.2 / 89.8 / 90.0 /
# 89.5 % of 600, 89.4 (2) and 90.2 % (4) of 900; the Chamfer to the true curves unchanged.
_PRIOR_WEIGHT = 4.0
_PRIOR_FLOOR = 1e-3
# ... only where good continuation alone reads at most this many curves.
_PRIOR_COUNTS = 4
# Points per stroke at most when scoring it.
_SCORE_POINTS = 96
# Strokes are scored at this many times the fit tolerance, or at this fraction of the
# drawing's extent (the diagonal of the ink's bounding box) where that is more.
_SCORE_TOL = 2.0
_SCORE_REL = 0.015


def _matchings(ends: list, partial: bool) -> list:
    """Every set of disjoint pairs of ``ends`` (all of them when ``partial``, else only the
    largest) -> list of lists of pairs."""
    if len(ends) < 2:
        return [[]]
    e, rest = ends[0], ends[1:]
    out = [[(e, f)] + m for x, f in enumerate(rest) for m in _matchings(rest[:x] + rest[x + 1:], partial)]
    if partial or len(ends) % 2:
        out += [m for m in _matchings(rest, partial)]
    if not partial:
        size = max(len(m) for m in out)
        out = [m for m in out if len(m) == size]
    return out


def _fewest_within(residual, least: int, cap: int, tolerance: float) -> tuple[int, dict]:
    """The smallest control-point count in ``[least, cap]`` whose ``residual(n)`` is within
    ``tolerance`` (``cap`` when none is) -> ``(count, {count probed: residual})``.

    Galloping, then bisection: most strokes need few control points, so the probes stay
    small (``least``, then doubling) until one fits; the residual is taken to fall as the
    count grows. The count search of :func:`_control_points_needed`.
    """
    bounds: dict[int, float] = {}

    def probe(n):
        if n not in bounds:
            bounds[n] = residual(n)
        return bounds[n]

    lo = hi = least
    while hi < cap and probe(hi) > tolerance:
        lo, hi = hi + 1, min(2 * hi, cap)
    while lo < hi:  # hi always fits or is the cap
        mid = (lo + hi) // 2
        if probe(mid) <= tolerance:
            hi = mid
        else:
            lo = mid + 1
    probe(hi)
    return hi, bounds


def _control_points_needed(points: np.ndarray, tolerance: float, degree: int = 3) -> tuple[int, float]:
    """The fewest control points of a clamped uniform B-spline within ``tolerance`` of
    ``points (N, 2)`` -> ``(count, largest residual)``.

    The least squares and one parameter correction of :func:`fit_stroke`, on uniform
    knots with the count searched (galloping then bisection, :func:`_fewest_within`;
    ``fit_stroke`` itself places its knots where the residual is), on scipy's B-splines
    (``scipy.interpolate.BSpline``, ``splev``) instead of the core's differentiable
    basis: a cost read many times while choosing junction pairings
    (:func:`_fewest_curves`), where no curve is kept and no gradient is needed. Dense:
    on the pieces the search reads, one scipy call beats the core's nonzero basis and the
    banded solve of :func:`_corrected_fits` (a tenth of a millisecond of torch calls per
    fit; the default method at 128 px took 21 against 43 ms per drawing, median, on 300
    development drawings with them).
    """
    from scipy.interpolate import BSpline, splev

    n_pts = len(points)
    seg = np.linalg.norm(np.diff(points, axis=0), axis=1)
    u0 = np.concatenate([[0.0], np.cumsum(seg)]) / max(seg.sum(), 1e-12)
    cap = max(degree + 1, min(n_pts // 3, int(seg.sum() / 3) + degree))

    def residual(n_ctrl):
        t = np.concatenate([np.zeros(degree), np.linspace(0, 1, n_ctrl - degree + 1), np.ones(degree)])
        eye = np.eye(n_ctrl)
        D = np.diff(eye, n=2, axis=0) * _SMOOTH
        # The basis as a spline with the identity for coefficients: the same numbers as
        # BSpline.design_matrix(...).toarray() (bitwise, checked on 500 random knot
        # vectors and parameters) in half its time, without the sparse matrix.
        basis = BSpline(t, eye, degree)
        u = u0
        for rounds in range(2):
            B = basis(np.clip(u, 0, 1))
            cp = np.linalg.solve(B.T @ B + D.T @ D, B.T @ points)
            r = points - B @ cp
            if rounds:
                break
            # Hoschek's correction: each parameter moved towards its foot point.
            dB = np.stack([splev(u, (t, cp[:, k], degree), der=1) for k in range(cp.shape[1])], axis=1)
            du = (r * dB).sum(1) / np.maximum((dB * dB).sum(1), 1e-12)
            u = np.maximum.accumulate(np.clip(u + du, 0, 1))
            u[0], u[-1] = 0.0, 1.0
        return float(np.sqrt((r * r).sum(1)).max())

    hi, bounds = _fewest_within(residual, degree + 1, cap, tolerance)
    return hi, bounds[hi]


def _fewest_curves(edges: list, partner: dict, tips: set, done: set, trim: int, origin: tuple,
                   width: float, tolerance: float, extent: float, prior: np.ndarray | None = None) -> dict:
    """The pairing at each junction re-chosen for the shortest description of the drawing.

    Good continuation reads each junction alone and from a few pixels of each branch; a
    curve ending on another, a curve crossing itself near a sharp turn, or two crossings
    close together fool it. Here each junction's pairing (which branch continues which,
    and which end there) is chosen by what the whole strokes cost to describe: the
    control points of a cubic B-spline that fits each stroke within ``tolerance``
    (``fit_stroke``, uniform knots, so a corner costs many) plus ``_CURVE_COST`` per
    stroke; strokes shorter than the shortest kept cost that share of a curve. This is
    the minimum description length principle (Rissanen 1978) applied to the stroke
    graph: a curve wrongly split costs an extra curve and more control points, two
    curves wrongly joined cost the control points of a corner. Coordinate descent: each
    junction (up to ``_SEARCH_ENDS`` ends, pairings the shared-edge rule settled left
    alone) tries every pairing of its ends with the others fixed, keeps the cheapest,
    until a pass changes nothing (at most 3 passes). Fits are cached by stroke.

    Shared edges: at a node of odd degree at least one curve ends, so a graph with many
    odd nodes is read as many curves. Two odd nodes joined by a short edge are often no
    curve's end: a shallow crossing whose skeleton runs along one segment between two
    three-way junctions, or a curve turning back sharply whose two sides merged into one
    line up to its tip, where the geometric rule of ``_pair_ends`` (a fork, then a stem)
    did not fire. After the descent, each edge joining two odd nodes (up to ``_SHARED``
    times (width + 1) px, nodes up to ``_SEARCH_ENDS - 1`` ends) is tried as walked twice:
    a copy of it is added, both nodes become even, every perfect pairing of their ends
    is scored (a dead end's two copies join at the tip, as a hairpin), and the copy is
    kept when the description is shorter; then the descent runs again. In the search's
    terms this is a move the per-junction descent cannot make, since it changes the graph
    itself (the Chinese-postman view of covering a graph by few walks that may repeat an
    edge; Edmonds and Johnson, "Matching, Euler tours and the Chinese postman", 1973).

    Count evidence: ``prior`` (the probabilities of 1, 2, ... curves, a network's vote),
    when given and when the starting pairing reads at most ``_PRIOR_COUNTS`` curves, adds
    ``-_PRIOR_WEIGHT * ln P(n)`` to every description (``P`` floored at ``_PRIOR_FLOOR``),
    ``n`` the strokes at least as long as the shortest kept: in the MDL reading, the
    code length of the count under the network's distribution, scaled to control points.

    Returns the new ``partner`` (a copy) and ``tips``; the copies kept are appended to
    ``edges``.
    """
    from scipy.ndimage import gaussian_filter1d

    at: dict[int, list] = {}
    for i, (a, b, _) in enumerate(edges):
        for side, k in ((0, a), (1, b)):
            if k >= 0:
                at.setdefault(k, []).append((i, side))
    fixed = {e for e in tips} | {e for k in done for e in at.get(k, [])}
    least = 3  # a node of two ends is a stroke passing through: never split there
    # The precision a stroke's shape is read at grows with the drawing: the same drawing
    # at 4 times the size costs the same (a scale-free description).
    tolerance = max(tolerance * _SCORE_TOL, _SCORE_REL * extent)
    nodes = [k for k, ends in at.items() if k not in done and least <= len(ends) <= _SEARCH_ENDS
             and not any(e in fixed for e in ends)]
    if not nodes:
        return partner, tips
    shortest = _min_length(width)
    cache: dict = {}

    def stroke_cost(pts, keys):
        rev = tuple((i, 1 - s) for i, s in reversed(keys))
        key = min(keys, rev)
        if key in cache:
            return cache[key]
        length = _arc_length(pts)
        if length < shortest:
            cost = _CURVE_COST * length / shortest
        else:
            closed = len(pts) > 3 and bool(np.all(pts[0] == pts[-1]))
            if len(pts) > 4:
                pts = gaussian_filter1d(pts, _STROKE_SIGMA, axis=0, mode="wrap" if closed else "nearest")
                if closed:
                    pts[-1] = pts[0]
                # Resampled by arc length, 2 px apart or _SCORE_POINTS in all: the cost
                # reads the shape, not the pixel count, and a long stroke stays cheap.
                arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(pts, axis=0), axis=1))])
                m = int(min(_SCORE_POINTS, max(8, arc[-1] / 2.0)))
                t = np.linspace(0.0, arc[-1], m)
                pts = np.stack([np.interp(t, arc, pts[:, k]) for k in range(2)], axis=1)
            if len(pts) < 4:
                t = np.linspace(0, 1, 4)
                pts = np.stack([np.interp(t, np.linspace(0, 1, len(pts)), pts[:, k]) for k in range(2)], axis=1)
            n_ctrl, bound = _control_points_needed(pts, tolerance)
            cost = n_ctrl + _CURVE_COST + max(0.0, bound - tolerance) / tolerance * 4.0
        cache[key] = cost
        return cost

    # Edges that two curves may share (see the docstring): copies appended after the
    # graph's edges, each used only once accepted. ``ext`` is the graph with every
    # candidate copy; ``active`` the edges of the current description.
    n_edges = len(edges)
    shared = [i for i, (a, b, path) in enumerate(edges)
              if a >= 0 and b >= 0 and a != b and a not in done and b not in done
              and not any(e in fixed for e in ((i, 0), (i, 1)))
              and len(at[a]) % 2 == 1 and len(at[b]) % 2 == 1 and max(len(at[a]), len(at[b])) >= 3
              and max(len(at[a]), len(at[b])) < _SEARCH_ENDS
              and _arc_length(np.asarray(path, dtype=float)) <= _SHARED * (min(width, _THICK) + 1)]
    ext = list(edges) + [edges[i] for i in shared]
    active = set(range(n_edges))
    tips = set(tips)

    evidence = None  # -log P(count) of the count vote, in nats, scaled to control points

    walked: dict = {}  # a walk's points, its ends and whether it counts, built once

    def strokes(p, act=None, tp=None):
        out = []
        for steps in _walks(ext, p, tips if tp is None else tp, active if act is None else act):
            if steps not in walked:
                pts = _walk_points(ext, steps, trim, origin)
                walked[steps] = None if pts is None else (pts, tuple((i, side) for i, side, _ in steps),
                                                          _arc_length(pts) >= shortest)
            if walked[steps] is not None:
                out.append(walked[steps])
        return out

    def total(p, act=None, tp=None):
        chains = strokes(p, act, tp)
        cost = sum(stroke_cost(pts, keys) for pts, keys, _ in chains)
        if evidence is not None:
            n = sum(1 for _, _, counts in chains if counts)
            cost += float(evidence[n - 1]) if 1 <= n <= len(evidence) else -_PRIOR_WEIGHT * np.log(_PRIOR_FLOOR)
        return cost

    partner = dict(partner)
    if prior is not None and len(prior):
        # The networks read 1 to 3 curves: on a drawing of many more strokes (a sketch) the
        # vote says nothing, and its floor would push every drawing towards 5 curves.
        counted = sum(1 for _, _, counts in strokes(partner) if counts)
        if counted <= _PRIOR_COUNTS:
            evidence = -_PRIOR_WEIGHT * np.log(np.maximum(np.asarray(prior, dtype=np.float64), _PRIOR_FLOOR))
    best = total(partner)

    def descend(passes):
        nonlocal partner, best
        for _ in range(passes):
            changed = False
            for k in nodes:
                ends = at[k]
                if len(ends) > _SEARCH_ENDS:
                    continue
                current = {e: partner[e] for e in ends if e in partner}
                base = {e: f for e, f in partner.items() if e not in current}
                for pairs in _matchings(ends, partial=len(ends) <= 4):
                    trial = dict(base)
                    for e, f in pairs:
                        trial[e], trial[f] = f, e
                    if all(trial.get(e) == current.get(e) for e in ends):
                        continue
                    cost = total(trial)
                    if cost < best - 1e-9:
                        best, partner, changed = cost, trial, True
                        current = {e: partner[e] for e in ends if e in partner}
                # (the base of later trials at this node: the best so far)
            if not changed:
                break

    descend(3)
    accepted = []
    for c, i in enumerate(shared):
        a, b, _ = edges[i]
        sa, sb = 0, 1
        if len(at[a]) == 1:  # the end node (a hairpin's tip) as b
            a, b, sa, sb = b, a, 1, 0
        if len(at[a]) % 2 == 0 or len(at[b]) % 2 == 0:
            continue  # a copy accepted next to it already evened a node
        j = n_edges + c
        act = active | {j}
        ends_a, ends_b = at[a] + [(j, sa)], at[b] + [(j, sb)]
        tip = len(at[b]) == 1
        base = {e: f for e, f in partner.items() if e not in ends_a and e not in ends_b}
        tp = tips | {(i, sb), (j, sb)} if tip else tips
        choice = None
        for side_a in _matchings(ends_a, partial=False):
            for side_b in ([[((i, sb), (j, sb))]] if tip else _matchings(ends_b, partial=False)):
                trial = dict(base)
                for e, f in side_a + side_b:
                    trial[e], trial[f] = f, e
                cost = total(trial, act, tp)
                if cost < best - 1e-9 and (choice is None or cost < choice[0]):
                    choice = (cost, trial)
        if choice is not None:
            best, partner = choice
            active, tips = act, tp
            at[a], at[b] = ends_a, ends_b
            accepted.append(j)
            for k in (a, b):
                if k not in nodes and 3 <= len(at[k]) <= _SEARCH_ENDS:
                    nodes.append(k)
    if accepted:
        descend(2)
    # The accepted copies become edges of the graph (appended, indices kept in order).
    renum = {j: n_edges + x for x, j in enumerate(accepted)}
    for j in accepted:
        edges.append(ext[j])
    fix = lambda e: (renum.get(e[0], e[0]), e[1])  # noqa: E731
    out_tips = {fix(e) for e in tips}
    return {fix(e): fix(f) for e, f in partner.items()}, out_tips


def _chains(edges: list, partner: dict, tips: set, trim: int, origin: tuple, active=None) -> list:
    """Edges chained into strokes through the ``partner`` links -> ``[(points (n, 2), ends)]``.

    ``points`` are pixel centres (x, y) (``origin`` added to (col, row)), consecutive
    duplicates dropped; ``ends`` is the tuple of ``(edge, side)`` walked, which names the
    stroke. Through a junction (a link not in ``tips``) ``trim`` pixels of each side are
    left out. The walks (:func:`_walks`) and their points (:func:`_walk_points`) apart,
    so that the pairing search builds the points of a walk once.
    """
    out = []
    for steps in _walks(edges, partner, tips, active):
        pts = _walk_points(edges, steps, trim, origin)
        if pts is not None:
            out.append((pts, tuple((i, side) for i, side, _ in steps)))
    return out


def _walks(edges: list, partner: dict, tips: set, active=None) -> list[tuple]:
    """The strokes of :func:`_chains` as walks: one tuple of ``(edge, side, cut)`` steps
    per stroke, ``cut`` True where the walk leaves the edge through a junction (its
    ``trim`` last pixels left out). Open strokes first (from their free ends), then
    closed ones; edges not in ``active`` (when given) are not walked."""
    used, out = set(), []

    def walk(i, side):
        steps = []
        while i not in used:
            used.add(i)
            nxt = partner.get((i, 1 - side))
            steps.append((i, side, nxt is not None and (i, 1 - side) not in tips))
            if nxt is None:
                break
            i, side = nxt
        return tuple(steps)

    if active is not None:  # edges left out of this description count as walked
        used.update(i for i in range(len(edges)) if i not in active)
    out = [walk(i, s) for i in range(len(edges)) for s in (0, 1) if (i, s) not in partner and i not in used]
    out += [walk(i, 0) for i in range(len(edges)) if i not in used]  # closed chains
    return [steps for steps in out if steps]


def _walk_points(edges: list, steps: tuple, trim: int, origin: tuple) -> np.ndarray | None:
    """The pixel centres ``(n, 2)`` of a walk of :func:`_walks` (None for fewer than two)."""
    chain, cut = [], False
    for i, side, leaves in steps:
        path = list(edges[i][2] if side == 0 else edges[i][2][::-1])
        if chain and cut:  # arriving through a junction
            path = path[min(trim, max(0, len(path) - 2)) + 1:]
        elif chain:
            path = path[1:]
        chain.extend(path)
        cut = leaves
        if cut and len(chain) > trim + 2:
            del chain[len(chain) - trim:]
    if not chain:
        return None
    pts = np.array(chain, dtype=float)[:, ::-1] + origin
    keep = np.ones(len(pts), bool)
    keep[1:] = np.any(np.diff(pts, axis=0) != 0, axis=1)
    pts = pts[keep]
    return pts if len(pts) >= 2 else None


# Two stroke ends this close (stroke widths, plus 2 px) that continue each other are joined.
_GAP = 2.0
# ... when the turn from one into the other is at most this (cosine of 45 degrees).
_CONTINUES = 0.7


def _end(stroke: np.ndarray, side: int, reach: float):
    """The end point of ``stroke (n, 2)`` at ``side`` (0: first, 1: last) and its outward unit direction."""
    s = stroke if side == 1 else stroke[::-1]
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(s[::-1], axis=0), axis=1))])
    back = s[::-1][min(int(np.searchsorted(arc, reach)), len(s) - 1)]
    d = s[-1] - back
    n = np.linalg.norm(d)
    return s[-1], (d / n if n > 0 else d)


def _join_broken(strokes: list, width: float) -> list:
    """Strokes joined end to end where one continues the other across a small gap.

    Pairing at a junction cluster can leave a curve's two sides apart (the branch it
    should have continued into was taken by another curve); their ends then face each
    other a stroke width or two apart. Two ends of different strokes within
    ``_GAP * width + 2`` px whose outward directions are nearly opposite, and whose gap
    runs along them, are joined, the most nearly straight joins first (good continuation).
    """
    strokes = [np.asarray(s) for s in strokes]
    if len(strokes) < 2:
        return strokes
    reach = max(4.0, 2.0 * width)
    gap_max = _GAP * width + 2.0
    ends = {}
    for i, st in enumerate(strokes):
        if len(st) > 3 and np.all(st[0] == st[-1]):
            continue  # closed
        for side in (0, 1):
            ends[(i, side)] = _end(st, side, reach)
    keys = list(ends)
    pts = np.array([ends[k][0] for k in keys])
    tree = cKDTree(pts)
    options = []
    for x, y in tree.query_pairs(gap_max):
        (i, si), (j, sj) = keys[x], keys[y]
        if i == j:
            continue
        (p, dp), (q, dq) = ends[keys[x]], ends[keys[y]]
        turn = -float(dp @ dq)
        g = q - p
        gn = float(np.linalg.norm(g))
        along = 1.0 if gn < 1.0 else min(float(dp @ g) / gn, -float(dq @ g) / gn)
        if turn >= _CONTINUES and along >= _CONTINUES:
            options.append((-(turn + along), keys[x], keys[y]))
    if not options:
        return strokes
    # Union of chains: each stroke end used once.
    options.sort(key=lambda t: t[0])
    link, used = {}, set()
    for _, e, f in options:
        if e in used or f in used:
            continue
        # Refuse a join that closes a chain on itself.
        a, seen = e[0], {e[0]}
        cur = (f[0], 1 - f[1])
        ok = True
        while cur in link:
            nxt = link[cur]
            if nxt[0] == a:
                ok = False
                break
            cur = (nxt[0], 1 - nxt[1])
        if not ok:
            continue
        link[e], link[f] = f, e
        used.update((e, f))
    out, done = [], set()
    for i in range(len(strokes)):
        if i in done:
            continue
        # Walk to one end of the chain, then along it.
        side, cur = 0, i
        seen = {i}
        while (cur, side) in link and link[(cur, side)][0] not in seen:
            cur, side = link[(cur, side)][0], 1 - link[(cur, side)][1]
            seen.add(cur)
        # cur's `side` end is free (or the chain loops): walk from it.
        parts, s_, c_ = [], side, cur
        while True:
            done.add(c_)
            st = strokes[c_]
            parts.append(st if s_ == 0 else st[::-1])
            nxt = link.get((c_, 1 - s_))
            if nxt is None or nxt[0] in done:
                break
            c_, s_ = nxt
        out.append(np.concatenate(parts))
    return out


def _local_basis(knots: np.ndarray, degree: int, u, order: int) -> tuple[np.ndarray, np.ndarray]:
    """The nonzero basis functions of the clamped B-spline space of ``knots (m,)`` at
    ``u (N,)`` (float64 tensor): ``values (N, order + 1, p + 1)`` (with derivatives,
    ``nurbskit.core.basis.basis_function_derivatives``) and the index of the first control
    point each row touches ``(N,)``: a basis matrix without its zeros."""
    import torch

    from ..core.basis import basis_function_derivatives, find_spans

    kv = torch.as_tensor(knots, dtype=u.dtype)
    n_ctrl = len(knots) - degree - 1
    spans = find_spans(kv, degree, n_ctrl, u)
    values = basis_function_derivatives(kv, degree, spans, u, order)
    return values.numpy(), (spans - degree).numpy()


def _apply_local(values: np.ndarray, first: np.ndarray, cp: np.ndarray) -> np.ndarray:
    """``B @ cp`` for the basis rows ``values (N, p + 1)`` starting at columns ``first (N,)``."""
    return np.einsum("nj,njd->nd", values, cp[first[:, None] + np.arange(values.shape[1])])


@functools.lru_cache(maxsize=None)
def _pairs(width: int) -> tuple[np.ndarray, np.ndarray]:
    """The index pairs ``a <= b`` of a ``width x width`` upper triangle (``np.triu_indices``)."""
    return np.triu_indices(width)


def _banded_least_squares(values: np.ndarray, first: np.ndarray, points: np.ndarray, n_ctrl: int,
                          smooth: float) -> np.ndarray:
    """Control points ``(n_ctrl, dim)`` minimising ``|B c - points|^2 + smooth^2 |D c|^2``,
    ``B`` given by its nonzero rows (:func:`_local_basis`) and ``D`` the control polygon's
    second differences.

    The normal matrix is banded (half-bandwidth ``max(p, 2)``): assembled from the
    ``(p + 1)^2`` products per row and solved by banded Cholesky
    (LAPACK ``dpbsv`` through scipy), ``O(N p^2 + n p^2)`` instead of the dense product's
    ``O(N n^2)``: on 2048 px drawings whose strokes take 600 to 700 control points the
    classical path went from 2.2 and 4.1 s to 0.35 and 0.21 s. ``smooth > 0`` keeps the
    matrix positive definite where spans hold no points.
    """
    from scipy.linalg.lapack import dpbsv

    n_pts, p1 = values.shape
    width = max(p1, 3)  # the second differences span 3 control points
    penalty = n_ctrl - 2 if smooth and n_ctrl > 2 else 0
    V = np.zeros((n_pts + penalty, width))
    V[:n_pts, :p1] = values
    V[n_pts:, :3] = (smooth, -2.0 * smooth, smooth)
    f = np.concatenate([first, np.arange(penalty)])
    a, b = _pairs(width)
    # Lower form, normal[k, j] = (B^T B + smooth^2 D^T D)[j + k, j]: every product of a
    # row's entries at once (a zero padding entry may land past the end: cut off).
    normal = np.bincount(((b - a) * n_ctrl + f[:, None] + a).ravel(), weights=(V[:, a] * V[:, b]).ravel(),
                         minlength=width * n_ctrl)[: width * n_ctrl].reshape(width, n_ctrl)
    columns = (first[:, None] + np.arange(p1)).ravel()
    rhs = np.stack([np.bincount(columns, weights=(values * points[:, d, None]).ravel(), minlength=n_ctrl)
                    for d in range(points.shape[1])], axis=1)
    factor, solution, info = dpbsv(normal, rhs, lower=1)  # LAPACK's banded Cholesky solve, one call
    if info:
        raise np.linalg.LinAlgError(f"the normal matrix is not positive definite (LAPACK dpbsv info {info})")
    return solution


def _corrected_fits(points: np.ndarray, u: np.ndarray, knots: np.ndarray, degree: int, closed: bool = False):
    """Least-squares fits of a clamped B-spline on ``knots (m,)`` to ``points (N, 2)``,
    first at the parameters ``u (N,)``, then after each round of Hoschek's parameter
    correction: yields ``(control points, u, residuals (N,))`` without end.

    The correction (The NURBS Book, section 9.4.1, "intrinsic parametrisation") moves
    each parameter by the first-order step ``du = (p - C(u)) . C'(u) / |C'(u)|^2``
    towards its foot point, from the nonzero basis functions and their derivatives
    (:func:`_local_basis`), no per-point search; parameters stay in order (one behind
    its predecessor would fold the fit) and the ends stay at 0 and 1. A faint
    second-difference penalty on the control polygon (``_SMOOTH``) keeps spans with few
    or no points well posed (no wild control points) and changes nothing else. A closed
    stroke's first and last control points are made one.
    """
    import torch

    n_ctrl = len(knots) - degree - 1
    while True:
        values, first = _local_basis(knots, degree, torch.from_numpy(np.clip(u, 0.0, 1.0)), 1)
        cp = _banded_least_squares(values[:, 0], first, points, n_ctrl, _SMOOTH)
        if closed:
            cp[0] = cp[-1] = (cp[0] + cp[-1]) / 2
        at = _apply_local(values[:, 0], first, cp)
        yield cp, u, np.sqrt(((points - at) ** 2).sum(1))
        tangent = _apply_local(values[:, 1], first, cp)
        du = ((points - at) * tangent).sum(1) / np.maximum((tangent * tangent).sum(1), 1e-12)
        u = np.maximum.accumulate(np.clip(u + du, 0.0, 1.0))
        u[0], u[-1] = 0.0, 1.0


def fit_stroke(points: np.ndarray, tolerance: float = 1.0, degree: int = 3, max_ctrl: int | None = None,
               corrections: int = 3, measure: bool = True):
    """A clamped B-spline through ordered ``points (N, 2)`` within ``tolerance`` (max distance).

    Least squares on chord-length parameters, then up to ``corrections`` rounds of
    Hoschek's parameter correction while they lower the largest residual
    (:func:`_corrected_fits`). The knots are placed where the stroke needs them: from a
    single span (a Bezier curve), every span holding a point whose residual after one
    correction exceeds ``tolerance`` is split at its middle (the spans with the largest
    residuals first), until none does or the curve has ``max_ctrl`` control points
    (default about one per 3 px of stroke). A near-cusp then costs knots where it is,
    not everywhere along the stroke as with uniform knots (sixteenth session: on 2048 px
    drawings 83 % fewer control points, at 512 px 48 %, at 128 px 21 %, within the same
    tolerance). Returns ``(curve, max_distance)``: the distance by projection
    (``nurbskit.core.project.project_points_curve``) when ``measure``, else the residual
    bound (the residual at the corrected parameters bounds the distance from above).
    """
    import torch

    from ..core import NURBSCurve
    from ..core.project import project_points_curve

    pts_np = np.ascontiguousarray(points, dtype=np.float64)
    pts = torch.from_numpy(pts_np)
    n_pts = len(pts_np)
    closed = n_pts > 3 and bool(np.linalg.norm(pts_np[0] - pts_np[-1]) < 1e-9)
    seg = np.linalg.norm(np.diff(pts_np, axis=0), axis=1)
    u_chord = np.concatenate([[0.0], np.cumsum(seg)])
    u_chord = u_chord / u_chord[-1]
    length = float(seg.sum())
    if max_ctrl is None:  # at most one span per 3 px of stroke and 4 points per control point
        max_ctrl = min(n_pts // 4, int(length / 3) + degree)
    max_ctrl = max(degree + 1, min(max_ctrl, n_pts))

    def fit(knots, rounds):
        fits = _corrected_fits(pts_np, u_chord, knots, degree, closed)
        best = next(fits)
        for _ in range(rounds):
            cp, u, residuals = next(fits)
            if not residuals.max() < best[2].max():  # a correction that does not help ends the rounds
                break
            best = (cp, u, residuals)
        return best

    interior = np.zeros(0)
    while True:
        knots = np.concatenate([np.zeros(degree + 1), interior, np.ones(degree + 1)])
        _, u, residuals = fit(knots, 1)
        room = max_ctrl - (len(knots) - degree - 1)
        if residuals.max() <= tolerance or room <= 0:
            break
        bounds = np.concatenate([[0.0], interior, [1.0]])
        far = residuals > tolerance
        span = np.clip(np.searchsorted(bounds, u[far], side="right") - 1, 0, len(bounds) - 2)
        worst = np.zeros(len(bounds) - 1)
        np.maximum.at(worst, span, residuals[far])
        split = np.argsort(-worst)[: min(room, int((worst > 0).sum()))]
        interior = np.sort(np.concatenate([interior, (bounds[split] + bounds[split + 1]) / 2]))
    cp, u, residuals = fit(knots, corrections)
    bound = float(residuals.max())
    curve = NURBSCurve(torch.from_numpy(cp), degree=degree, knot_vector=torch.from_numpy(knots))
    if not measure:
        return curve, bound
    distance = float(project_points_curve(curve, pts, params=torch.from_numpy(u), iterations=8).distance.max())
    return curve, min(distance, bound)


def _ink_points(ink: np.ndarray) -> np.ndarray:
    rows, cols = np.nonzero(ink)
    return np.stack([cols + 0.5, rows + 0.5], axis=1).astype(np.float64)


def refine(curves: list, ink: np.ndarray, iterations: int = 20, spacing: float = 0.5, progress=None) -> list:
    """Control points of every curve moved by L-BFGS to lower the Chamfer distance to the ink.

    The loss is ``nurbskit.losses.chamfer_distance`` between all curves' samples (about
    ``spacing`` px apart) and the ink pixels' centres; knots and degree stay. The fitting
    loop's L-BFGS (:meth:`nurbskit.fit.optim.LBFGS.run`: ``torch.optim.LBFGS``'s
    iterations, strong Wolfe search, its defaults; not a ``torch.optim.Optimizer``, so no
    ``torch._dynamo`` import).

    The samples are linear in the control points of these polynomial curves: one sparse
    product ``S @ P`` for all curves per step (:func:`_sample_matrix`, built once), and
    the ink's KD-tree is built once too (``y_index``). Seventeenth session, one thread:
    20 iterations on 30 drawings of 1-3 curves 34 -> 24 ms at 128 px, 83 -> 63 ms at 512
    px, and on a 1024 px maze of 753 curves 16.7 -> 9.4 s, against a core evaluation per
    curve and a tree per step (the same Chamfer to the ink to 1e-4 px; L-BFGS's path
    differs by rounding). ``progress``: None, or called as ``progress("refining", loss
    evaluations, their most)``.
    """
    import torch

    from ..core import NURBSCurve
    from ..core.neighbors import NeighborIndex
    from ..errors import NurbskitError
    from ..fit.optim import LBFGS
    from ..losses import chamfer_distance

    if not curves:
        return curves
    if any(not bool((c.weights == 1).all()) for c in curves):
        raise NurbskitError("refine: the curves must be polynomial (all weights 1)")
    target = torch.as_tensor(_ink_points(ink))
    index = NeighborIndex(target)  # the ink's KD-tree, built once for all steps
    params = [c.control_points.detach().contiguous().clone().requires_grad_(True) for c in curves]
    basis = _sample_matrix(curves, spacing)
    opt = LBFGS(params, lr=1.0, history_size=100)
    report = progress or (lambda stage, done, total: None)
    most = iterations * 5 // 4  # L-BFGS's most evaluations (torch's default max_eval)
    evaluations = iter(range(1, most + 1))

    def closure():
        report("refining", next(evaluations, most), most)
        opt.zero_grad()
        loss = chamfer_distance(torch.sparse.mm(basis, torch.cat(params)), target, y_index=index)
        loss.backward()
        return loss

    opt.run(closure, max_iter=iterations)
    return [NURBSCurve(p.detach(), degree=c.degree, knot_vector=c.knot_vector) for p, c in zip(params, curves)]


def _sample_matrix(curves: list, spacing: float):
    """The sparse ``(samples, control points)`` matrix ``S`` of polynomial ``curves``: ``S @
    cat(control points)`` are their samples, about ``spacing`` px apart along each control
    polygon (16 to 4,096 per curve), at parameters uniform over each curve's domain, curve
    after curve; block-diagonal, ``degree + 1`` nonzero basis values per row
    (:func:`_local_basis`)."""
    import torch

    rows, cols, vals = [], [], []
    n_samples = n_ctrl = 0
    for c in curves:
        cp = c.control_points.detach().numpy()
        m = int(np.clip(np.linalg.norm(np.diff(cp, axis=0), axis=1).sum() / spacing, 16, 4096))
        lo, hi = c.domain[0]
        u = torch.linspace(lo, hi, m, dtype=torch.float64)
        values, first = _local_basis(c.knot_vector.detach().numpy(), c.degree, u, 0)
        rows.append(np.repeat(np.arange(n_samples, n_samples + m), c.degree + 1))
        cols.append((n_ctrl + first[:, None] + np.arange(c.degree + 1)).ravel())
        vals.append(values[:, 0].ravel())
        n_samples, n_ctrl = n_samples + m, n_ctrl + len(cp)
    at = torch.from_numpy(np.stack([np.concatenate(rows), np.concatenate(cols)]))
    return torch.sparse_coo_tensor(at, torch.from_numpy(np.concatenate(vals)), (n_samples, n_ctrl),
                                   check_invariants=True).coalesce()


def resampled(curve, n_ctrl: int, samples_per_point: int = 16):
    """``curve`` (a clamped cubic, or any degree) as the closest clamped-uniform curve of the
    same degree with ``n_ctrl`` control points: least squares through ``samples_per_point *
    max(n_ctrl, n)`` points of ``curve`` at their own parameters (uniform over the domain;
    ``nurbskit.core.basis.basis_matrix``), so no parameters are guessed. Float64; a curve
    the new spline space holds (a Bezier curve, or the curve itself) comes back exactly.
    """
    import torch

    from ..core import NURBSCurve
    from ..core.basis import basis_matrix
    from ..core.knots import clamped_uniform

    lo, hi = curve.domain[0]
    m = samples_per_point * max(n_ctrl, curve.control_points.shape[0])
    u = torch.linspace(0.0, 1.0, m, dtype=torch.float64)
    points = curve.evaluate(lo + (hi - lo) * u).detach().to(torch.float64)
    B = basis_matrix(clamped_uniform(n_ctrl, curve.degree, dtype=torch.float64), curve.degree, n_ctrl, u)
    # Normal equations by Cholesky (B^T B is well posed: 16 samples per control point), as
    # fit_stroke solves them; torch.linalg.lstsq's default driver (gelsy, MKL) is not
    # bitwise repeatable from call to call, and a count search must be.
    return NURBSCurve(torch.cholesky_solve(B.T @ points, torch.linalg.cholesky(B.T @ B)), degree=curve.degree)


def refine_counts(curves: list, ink: np.ndarray, iterations: int = 20, fewest: int = 4,
                  most: int = 8) -> list:
    """Curves refined by :func:`refine` (as it leaves them), with each curve's number of
    control points searched against the ink.

    Curve by curve, the count is stepped down by one (then, if that did not help, up by
    one) and kept stepping while it helps: the curve :func:`resampled` to the new count,
    all curves refined again, and the step kept when the symmetric Chamfer distance to the
    ink (:func:`chamfer_to_ink`) falls. Counts stay within ``fewest`` to ``most``.

    Why: refinement moves control points but cannot change how many there are, and a start
    with the wrong count (a network reads the count of a curve's control points right
    about half the time) ends a pixel from the truth where the right count ends a third
    of one: on 40 development drawings of one to three curves, the refined MV readings
    whose counts were all right lay 0.35 px from the true curves, the others 1.1 px
    (``docs/curves.md``, "The count search"). The search lowers that distance by about a
    third; it does not recover the true counts (it usually settles on more control
    points than the truth has, which lets a curve follow its stroke).
    """
    best = list(curves)
    if not best:
        return best
    score = chamfer_to_ink(best, ink)["symmetric"]
    for k in range(len(best)):
        for step in (-1, 1):
            moved = False
            while fewest <= best[k].control_points.shape[0] + step <= most:
                trial = list(best)
                trial[k] = resampled(best[k], best[k].control_points.shape[0] + step)
                trial = refine(trial, ink, iterations)
                trial_score = chamfer_to_ink(trial, ink)["symmetric"]
                if not trial_score < score:
                    break
                best, score, moved = trial, trial_score, True
            if moved:
                break
    return best


def regrouped(curves: list, guides: list, tolerance: float = 1.0) -> list | None:
    """``curves`` joined into one curve per guide curve -> a list as long as ``guides``, or
    None where some guide has no curve along it.

    Each curve goes to the guide it lies closest to (the mean distance from its points,
    1 px apart, to the guide's); the curves of one guide are put in order along it (by
    the guide points nearest their two ends), each turned to run the way the guide does,
    and their points fitted as one stroke (:func:`fit_stroke` within ``tolerance``, the
    canonical orientation kept: first point left of the last). A guide with one curve
    keeps that curve as it is.

    Why: the hybrid method's count vote can say that the classical path split one curve
    in two (at a sharp turn, or where the pairing at a crossing went wrong), and the
    network's curves for the vote's count say which pieces belong together; their own
    geometry is coarse (refined from the network's start they lie pixels from the strokes
    at 512 px), the pieces' is not. Where the network's curves do not match the pieces
    (a guide with none), this says so and the caller decides.
    """
    from .synthetic import dense_samples

    if not curves or not guides:
        return None
    trees = [cKDTree(dense_samples(g, 1.0)) for g in guides]
    pieces = [dense_samples(c, 1.0) for c in curves]
    members: list[list[int]] = [[] for _ in guides]
    for i, pts in enumerate(pieces):
        members[int(np.argmin([tree.query(pts)[0].mean() for tree in trees]))].append(i)
    if not all(members):
        return None
    out = []
    for tree, group in zip(trees, members):
        if len(group) == 1:
            out.append(curves[group[0]])
            continue
        parts = []
        for i in group:
            pts = pieces[i]
            first, last = tree.query(pts[[0, -1]])[1]
            if first > last:  # the piece runs against the guide
                pts, first, last = pts[::-1], last, first
            parts.append((first + last, i, pts))
        parts.sort(key=lambda part: part[:2])
        joined = np.concatenate([pts for _, _, pts in parts])
        if joined[0, 0] > joined[-1, 0]:
            joined = joined[::-1].copy()
        out.append(fit_stroke(joined, tolerance, measure=False)[0])
    return out


def chamfer_to_ink(curves: list, ink: np.ndarray, spacing: float = 0.25) -> dict:
    """Mean distances in pixels between the curves and the ink pixel centres, both ways.

    Returns ``{"curves_to_ink", "ink_to_curves", "symmetric"}`` (symmetric: their mean);
    not squared, unlike the training loss, so the numbers read in pixels.
    """
    from .synthetic import dense_samples

    samples = np.concatenate([dense_samples(c, spacing) for c in curves]) if curves else np.zeros((0, 2))
    return chamfer_points(samples, _ink_points(ink))


def chamfer_points(a: np.ndarray, b: np.ndarray) -> dict:
    """Mean nearest distances ``a -> b`` and ``b -> a`` (cKDTree) and their mean, in the points' units."""
    if len(a) == 0 or len(b) == 0:
        return {"curves_to_ink": float("inf"), "ink_to_curves": float("inf"), "symmetric": float("inf")}
    ab = float(cKDTree(b).query(a)[0].mean())
    ba = float(cKDTree(a).query(b)[0].mean())
    return {"curves_to_ink": ab, "ink_to_curves": ba, "symmetric": (ab + ba) / 2}


def fit_image(image, tolerance: float = 1.0, refine_iterations: int = 0, source: str = "image",
              min_length: float | None = None, count_prior=None, search_extent: float | None = None,
              progress=None):
    """Curves in a drawing by the classical path -> ``(curves, Strokes)``.

    Args:
        image: ``(H, W)`` grey or ``(H, W, 3|4)`` colour array.
        tolerance: largest distance in pixels from a stroke's skeleton pixels to its curve.
        refine_iterations: L-BFGS iterations of Chamfer refinement (0: none).
        min_length: strokes shorter than this (pixels) are dropped as noise (default:
            2 stroke widths + 4 px, the width taken at most 4 px).
        count_prior: None, or a callable: (skeleton ``(H, W)`` bool, stroke width, ink
            ``(H, W)`` bool) -> probabilities of 1, 2, ... curves (or None), used as
            evidence when choosing junction pairings (see :func:`trace_strokes`).
        search_extent: the pairing search runs on drawings whose ink spans at most this
            many pixels (default: 256, see :func:`trace_strokes`).
        progress: None, or called as ``progress(stage, done, total)`` ("tracing strokes",
            "fitting strokes", then :func:`refine`'s "refining").
    """
    if not tolerance > 0:
        raise OptionError(f"tolerance: expected a positive number of pixels, got {tolerance}")
    report = progress or (lambda stage, done, total: None)
    report("tracing strokes", 0, 1)
    grey = even_background(to_grey(image, source))
    ink, inverted = ink_mask(grey, source)
    strokes, width = trace_strokes(ink, tolerance=tolerance, count_prior=count_prior, search_extent=search_extent)
    if min_length is None:
        min_length = _min_length(width)
    if not any(_arc_length(st) >= min_length for st in strokes):
        # Strokes as wide as the drawing is long (a digit upsampled from 8 x 8): merging
        # junctions and pruning spurs left nothing long enough. The raw skeleton's longest
        # strokes are better than no curve.
        strokes, width = trace_strokes(ink, width, simplify=False, tolerance=None)
        longest = max((_arc_length(st) for st in strokes), default=0.0)
        if longest >= 2.0 * width + 4.0:  # still a stroke, not a dot
            min_length = min(min_length, 0.5 * longest)
    curves = []
    for i, s in enumerate(strokes):
        report("fitting strokes", i, len(strokes))
        if np.linalg.norm(np.diff(s, axis=0), axis=1).sum() < min_length:
            continue
        if len(s) < 4:  # too few points for a cubic: resample the short segment
            t = np.linspace(0, 1, 4)
            s = np.stack([np.interp(t, np.linspace(0, 1, len(s)), s[:, k]) for k in range(2)], axis=1)
        if len(s) > 4:  # the skeleton's pixel staircase is noise of +-0.5 px: smooth it along the stroke
            from scipy.ndimage import gaussian_filter1d

            closed = bool(np.all(s[0] == s[-1]))
            s = gaussian_filter1d(s, _STROKE_SIGMA, axis=0, mode="wrap" if closed else "nearest")
            if closed:
                s[-1] = s[0]
        if s[0, 0] > s[-1, 0]:  # canonical orientation (as the synthetic targets): first point left of the last
            s = s[::-1].copy()
        curve, _ = fit_stroke(s, tolerance, measure=False)
        curves.append(curve)
    if refine_iterations:
        curves = refine(curves, ink, refine_iterations, progress=progress)
    return curves, Strokes(strokes=strokes, ink=ink, width=width, inverted=inverted)

"""The shipped curve networks at work: image in, B-spline curves in pixel coordinates out.

Convention: the input image (any size, dark on light or light on dark: detected as the
classical path does, :func:`nurbskit.curves.classic.ink_mask`) is turned into ink in
[0, 1] (0 the background's median grey, 1 the darkest ink), resized to the network's
``S x S`` by area averaging when larger (as the training images are,
:func:`~.train.network_inputs`) and bilinearly when smaller, and the
predicted control points ``(u, v)`` in the unit square map back to pixels as
``(u * W, v * H)`` (x to the right, y down, the origin at the top-left corner of the
top-left pixel: the api's convention). Counts follow the stop probabilities: a curve or
point sequence ends at the first step whose STOP probability exceeds 1/2 (at most
:data:`~.models.MAX_CURVES` curves and :data:`~.models.MAX_POINTS` points; a curve keeps
at least 4 control points, the fewest a cubic has).
"""

from __future__ import annotations

import functools

import numpy as np
import torch

from ...errors import OptionError
from .models import MAX_CURVES, MAX_POINTS, MIN_POINTS, build
from .train import predicted_count

MODES = ("V", "M", "MV")
INPUTS = ("image", "redrawn")


@functools.lru_cache(maxsize=None)
def load_model(mode: str, input: str = "image"):
    """The shipped network of ``mode`` trained on ``input`` drawings, loaded once, in eval mode:
    ``nurbskit/learn/weights/curves_<mode>.pt`` for the drawings themselves,
    ``curves_<mode>_redrawn.pt`` for their skeletons redrawn (:func:`redrawn`, the hybrid
    method's reading).

    Returns ``(model, meta)``; raises InputError when the weights are not shipped.
    """
    from ...learn import load_weights

    if mode not in MODES:
        raise OptionError(f"mode: expected one of {', '.join(MODES)}, got {mode!r}")
    if input not in INPUTS:
        raise OptionError(f"input: expected one of {', '.join(INPUTS)}, got {input!r}")
    state, meta = load_weights(f"curves_{mode.lower()}" + ("_redrawn" if input == "redrawn" else ""))
    model = build(mode, meta.get("arch"))
    model.load_state_dict(state)
    model.eval()
    return model, meta


def network_ink(grey: np.ndarray, size: int, inverted: bool = False) -> torch.Tensor:
    """``(H, W)`` grey in [0, 1] -> ink ``(1, 1, size, size)`` float32 (see the module's convention)."""
    from torch.nn import functional as F

    ink = grey if inverted else 1.0 - grey
    ink = np.asarray(ink, dtype=np.float64)
    lo, hi = float(np.median(ink)), float(ink.max())
    ink = torch.as_tensor(np.clip((ink - lo) / max(hi - lo, 1e-6), 0.0, 1.0), dtype=torch.float32)[None, None]
    if ink.shape[-2:] != (size, size):
        shrink = min(ink.shape[-2:]) >= size
        ink = F.interpolate(ink, size=(size, size), mode="area" if shrink else "bilinear",
                            align_corners=None if shrink else False)
    return ink.clamp(0.0, 1.0)


#: The views of a drawing whose readings :func:`read_views` averages (``views=4``), as
#: (flip x, flip y): the drawing, flipped top to bottom, flipped left to right, turned
#: half a turn. Each keeps the canonical orientation (first control point left of the
#: last) once its points are mapped back, a flip in x reversing every point sequence.
VIEWS = ((False, False), (False, True), (True, False), (True, True))


def _raw(model, ink: torch.Tensor):
    """One reading in the common layout: points ``(B, K, T, 2)``, point-stop log-probabilities
    ``(B, K, T, 2)`` (None: a fixed count) and curve-stop log-probabilities ``(B, K, 2)``
    (None: one curve)."""
    if model.mode == "V":
        pts, stops = model(ink, MAX_POINTS)
        return pts[:, None], stops.log_softmax(-1)[:, None], None
    if model.mode == "M":
        pts, stops = model(ink, MAX_CURVES)
        return pts, None, stops.log_softmax(-1)
    tokens, codes, curve_stops = model.curve_codes(ink, MAX_CURVES)
    pts, point_stops = model.decode_points(tokens, codes, MAX_POINTS)
    return pts, point_stops.log_softmax(-1), curve_stops.log_softmax(-1)


def _point_counts(point_logp, shape) -> torch.Tensor:
    """Points per curve ``(B, K)``: from the point stops, or all ``T`` for a fixed count."""
    if point_logp is None:
        return torch.full(shape[:2], shape[2], dtype=torch.long)
    return predicted_count(point_logp, MIN_POINTS)


def _unview(points: torch.Tensor, counts: torch.Tensor, flip_x: bool, flip_y: bool) -> torch.Tensor:
    """Points ``(B, K, T, 2)`` read in a flipped view -> the drawing's own frame; a flip in x
    also reverses the first ``counts (B, K)`` points of each sequence."""
    p = points.clone()
    if flip_y:
        p[..., 1] = 1.0 - p[..., 1]
    if flip_x:
        p[..., 0] = 1.0 - p[..., 0]
        i = torch.arange(p.shape[-2])
        c = counts[..., None]
        order = torch.where(i < c, c - 1 - i, i)
        p = p.gather(-2, order[..., None].expand(p.shape))
    return p


def _match_cost(a: torch.Tensor, na: torch.Tensor, b: torch.Tensor, nb: torch.Tensor) -> torch.Tensor:
    """How far apart the curves of two readings are: ``(B, K, K)`` from points ``(B, K, T, 2)``
    and counts ``(B, K)``: squared distances of the first points, the last points and the
    centroids of the control polygons."""

    def summary(p, n):
        i = torch.arange(p.shape[-2])
        mask = (i < n[..., None]).to(p.dtype)[..., None]
        last = p.gather(-2, (n - 1)[..., None, None].expand(*n.shape, 1, 2))[..., 0, :]
        return torch.stack([p[..., 0, :], last, (p * mask).sum(-2) / mask.sum(-2)], -2)  # (B, K, 3, 2)

    sa, sb = summary(a, na), summary(b, nb)
    return ((sa[:, :, None] - sb[:, None]) ** 2).sum((-1, -2))


def _view_batch(model, ink: torch.Tensor, flips) -> tuple:
    """``_raw`` of ink ``(B, 1, S, S)`` seen in the views ``flips``, in one batch: points
    ``(V, B, K, T, 2)``, point-stop and curve-stop log-probabilities with the same leading
    ``(V, B)`` (None where ``_raw`` gives None), each in its view's frame."""
    b = ink.shape[0]
    stacked = torch.cat([ink.flip([d for d, f in ((-1, fx), (-2, fy)) if f]) if fx or fy else ink for fx, fy in flips])
    return tuple(None if z is None else z.view(len(flips), b, *z.shape[1:]) for z in _raw(model, stacked))


@torch.no_grad()
def each_view(model, ink: torch.Tensor) -> list[list[list[np.ndarray]]]:
    """Each of the four :data:`VIEWS` read on its own, in the drawing's frame: per view, per
    image of ink ``(B, 1, S, S)``, one ``(n, 2)`` unit-square array per curve (the view's
    own counts). The starts of :func:`refined_curves`."""
    pts, point_logp, curve_logp = _view_batch(model, ink, VIEWS)
    out = []
    for j, flips in enumerate(VIEWS):
        n = _point_counts(None if point_logp is None else point_logp[j], pts[j].shape)
        k = torch.ones(ink.shape[0], dtype=torch.long) if curve_logp is None else predicted_count(curve_logp[j])
        p = _unview(pts[j], n, *flips)
        out.append([[p[i, c, : int(n[i, c])].double().numpy() for c in range(int(k[i]))] for i in range(len(k))])
    return out


@torch.no_grad()
def read_views(model, ink: torch.Tensor, views: int = 1, counts: torch.Tensor | None = None):
    """A network's reading of ink ``(B, 1, S, S)``, from one view or averaged over four.

    Returns ``(points (B, K, T, 2), curves (B,), counts (B, K))``: control points in the
    unit square (the first ``counts[b, c]`` of curve ``c < curves[b]`` are the curve's).
    ``views`` 1 reads the drawing once. ``views`` 4 reads the four :data:`VIEWS` in one
    batch and averages them: the stop log-probabilities of the curves (their count), each
    view's curves matched to the first view's (Hungarian, on the first and last control
    points and the polygon's centroid), the matched curves' point-stop log-probabilities
    (each curve's count), and their control points mapped back for that count. A
    recurrent decoder's error grows along the sequence it emits; a view flipped in x emits
    it backwards, so the average gains most at the ends. ``counts (B, K)``, when given,
    decides how the sequences are reversed and read in place of the counts read (the
    benchmark's "decoded for the true number of points"); the counts returned are always
    the ones read.
    """
    from .train import hungarian

    if views not in (1, len(VIEWS)):
        raise OptionError(f"views: expected 1 or {len(VIEWS)}, got {views!r}")
    b = ink.shape[0]
    flips = VIEWS[:views]
    pts, point_logp, curve_logp = _view_batch(model, ink, flips)
    k = torch.ones(b, dtype=torch.long) if curve_logp is None else predicted_count(curve_logp.mean(0))
    own = [_point_counts(None if point_logp is None else point_logp[j], pts[j].shape) for j in range(views)]
    ref = _unview(pts[0], own[0], *flips[0])
    matched_pts, matched_logp = [pts[0]], [None if point_logp is None else point_logp[0]]
    for j in range(1, views):
        perm = hungarian(_match_cost(ref, own[0], _unview(pts[j], own[j], *flips[j]), own[j]), k)  # (B, K)
        matched_pts.append(pts[j].gather(1, perm[..., None, None].expand(pts[j].shape)))
        if point_logp is not None:
            matched_logp.append(point_logp[j].gather(1, perm[..., None, None].expand(point_logp[j].shape)))
    n = _point_counts(None if point_logp is None else torch.stack(matched_logp).mean(0), pts[0].shape)
    decode = n if counts is None else counts
    mean = torch.stack([_unview(p, decode, *f) for p, f in zip(matched_pts, flips)]).mean(0)
    return mean, k, n


#: Views read by default, per mode (measured on 500 held-out drawings, 128 px: averaging
#: four views lowers V's mean Chamfer to the true curve from 3.70 to 3.50 px and its
#: point-count errors from 19.0 to 17.2 %; for M and MV it moves the count by under one
#: point and raises the Chamfer by 2-3 %, so they read once).
DEFAULT_VIEWS = {"V": 4, "M": 1, "MV": 1}


def predict_unit(model, ink: torch.Tensor, views: int | None = None) -> list[list[np.ndarray]]:
    """Control points in the unit square: ink ``(B, 1, S, S)`` -> per image, one ``(n_i, 2)`` array per curve.

    ``views``: 1 or 4 (:func:`read_views`); default :data:`DEFAULT_VIEWS` of the model's mode.
    """
    points, k, n = read_views(model, ink, DEFAULT_VIEWS[model.mode] if views is None else views)
    return [[points[i, c, : int(n[i, c])].double().numpy() for c in range(int(k[i]))] for i in range(len(k))]


def to_curves(unit: list[np.ndarray], width: int, height: int) -> list:
    """Unit-square control points -> :class:`~nurbskit.NURBSCurve` (float64, cubic, clamped uniform) in pixels."""
    from ..synthetic import curve_of

    scale = np.array([width, height], dtype=np.float64)
    return [curve_of(p * scale) for p in unit]


def network_curves(grey: np.ndarray, mode: str = "MV", inverted: bool = False) -> list:
    """The curves the shipped ``mode`` network reads in ``grey (H, W)``, in pixel coordinates."""
    model, meta = load_model(mode)
    size = int(meta.get("size", 64))
    unit = predict_unit(model, network_ink(grey, size, inverted))[0]
    h, w = grey.shape
    return to_curves(unit, w, h)


def refined_curves(grey: np.ndarray, ink: np.ndarray, mode: str = "MV", inverted: bool = False,
                   iterations: int = 20, counts: bool | None = None) -> list:
    """The paper's network-initialised optimisation: the shipped ``mode`` network's
    readings of ``grey (H, W)`` in each of the four :data:`VIEWS` (:func:`each_view`),
    each refined by Chamfer against the ink pixels (``ink (H, W)`` bool;
    :func:`nurbskit.curves.classic.refine`, ``iterations`` L-BFGS iterations), the one
    whose symmetric Chamfer to the ink is smallest kept (the first on a tie), and, with
    ``counts``, each of its curves' number of control points searched against the ink
    (:func:`nurbskit.curves.classic.refine_counts`, within the networks' 4 to 8). By
    default (``counts=None``) the search runs where the strokes are as thin as the
    networks know (:func:`nurbskit.curves.api.thin_enough`): on thick strokes (upsampled
    digits) the Chamfer to the ink pixels rewards curves that fill the stroke, and more
    control points only let them scribble.

    Why four starts: refinement keeps the basin its start lies in, and where strokes
    cross, a reading a few pixels off locks onto the wrong stroke. The four readings
    differ (a recurrent decoder's errors depend on the direction it emits in), and one
    of them is often in the right basin: on 40 held-out drawings per mode the refined
    Chamfer to the true curves fell from 1.40 to 1.08 px (M), 1.25 to 0.98 px (MV) and
    0.53 to 0.39 px (V) against refining the reading :func:`network_curves` gives
    (twelfth session, before the count search; with it, 0.68 / 0.59 / 0.31 px, table 1
    of ``benchmarks/results/curves_nets.md``).
    """
    from ..classic import chamfer_to_ink, refine, refine_counts

    model, meta = load_model(mode)
    h, w = grey.shape
    readings = each_view(model, network_ink(grey, int(meta.get("size", 64)), inverted))
    best, best_score = [], float("inf")
    for unit in readings:
        curves = refine(to_curves(unit[0], w, h), ink, iterations)
        score = chamfer_to_ink(curves, ink)["symmetric"] if curves else float("inf")
        if score < best_score:
            best, best_score = curves, score
    if counts is None:  # see the docstring: on thick strokes the search would fill them
        from ..api import thin_enough
        from ..classic import stroke_width

        counts = thin_enough(stroke_width(ink), ink)
    if not counts:
        return best
    return refine_counts(best, ink, iterations, MIN_POINTS, MAX_POINTS)


# The training drawings' size and stroke width (synthetic.mode_config at 128 px).
TRAIN_SIZE = 128
TRAIN_WIDTH = 2.0


def redrawn(skeleton: np.ndarray) -> np.ndarray:
    """A skeleton ``(H, W)`` bool -> grey ``(TRAIN_SIZE, TRAIN_SIZE)`` float64: the drawing
    as the training drawings look, dark strokes of the training width on white.

    The curve networks saw 128 px drawings of one stroke width only (2 px); the counts
    they read from thinner or thicker strokes are much worse (on 1 and 3 px strokes M's
    curve count fell from 81 to 55 and 49 %, ``docs/curves.md``). The skeleton's pixel
    centres, scaled to the training frame, are drawn by the training renderer
    (:func:`nurbskit.curves.synthetic.render_batch`), so any drawing of any size has the
    training strokes. The MV weights that vote for the hybrid method are trained on these
    very images (``curves_mv_redrawn``, :func:`~.train.redrawn_batch_maker`).
    """
    return redrawn_points([skeleton_points(skeleton)])[0]


def skeleton_points(skeleton: np.ndarray) -> np.ndarray:
    """A skeleton ``(H, W)`` bool -> its pixel centres ``(N, 2)`` scaled to the training frame.

    Over ``TRAIN_SIZE`` px across, the points are rasterised in the training frame and
    thinned again (:func:`thinned`): the skeleton of a drawing of any size is drawn as the
    128 px one would be (the counts follow the amount of ink closely: the same skeleton
    drawn from dense points, a bolder line, reads as more curves).
    """
    h, w = skeleton.shape
    rows, cols = np.nonzero(skeleton)
    pts = np.stack([(cols + 0.5) * TRAIN_SIZE / w, (rows + 0.5) * TRAIN_SIZE / h], axis=1)
    return thinned(pts) if max(h, w) > TRAIN_SIZE else pts


def thinned(points: np.ndarray) -> np.ndarray:
    """Dense points ``(N, 2)`` in the training frame -> the pixel centres of their one-pixel
    skeleton there (skimage's ``skeletonize`` of the pixels they fall in)."""
    from skimage.morphology import skeletonize

    grid = np.zeros((TRAIN_SIZE, TRAIN_SIZE), bool)
    ij = np.clip(np.floor(points).astype(int), 0, TRAIN_SIZE - 1)
    grid[ij[:, 1], ij[:, 0]] = True
    rows, cols = np.nonzero(skeletonize(grid))
    return np.stack([cols + 0.5, rows + 0.5], axis=1)


def redrawn_points(points: list[np.ndarray]) -> np.ndarray:
    """Points in the training frame, one ``(N_i, 2)`` array per drawing -> grey
    ``(len, TRAIN_SIZE, TRAIN_SIZE)`` float64: strokes of the training width through them, on white."""
    from ..synthetic import render_batch

    pts = [torch.as_tensor(p, dtype=torch.float64).reshape(-1, 2) for p in points]
    owner = torch.repeat_interleave(torch.arange(len(pts)), torch.tensor([len(p) for p in pts], dtype=torch.long))
    ink = render_batch(torch.cat(pts), owner, len(pts), (TRAIN_SIZE, TRAIN_SIZE), TRAIN_WIDTH)
    return 1.0 - ink.numpy()


@torch.no_grad()
def count_probabilities(skeleton: np.ndarray, mode: str = "MV", input: str = "redrawn") -> np.ndarray:
    """P(1, 2, ..., MAX_CURVES curves) that a shipped ``mode`` network ("M" or "MV") reads
    in a drawing, from its skeleton ``(H, W)`` bool (redrawn at the training width,
    :func:`redrawn`) -> ``(MAX_CURVES,)`` float64 summing to 1.

    ``input``: which weights read it: ``"redrawn"`` (the default; trained on redrawn
    skeletons, ``nurbskit train curves --input redrawn``) or ``"image"``. The curve
    decoder's stop probabilities ``s_k`` (STOP after curve ``k``) give
    ``P(k) = s_k * prod_{j < k} (1 - s_j)``, the last step taken as STOP.
    """
    if mode not in ("M", "MV"):
        raise OptionError(f"mode: expected M or MV for a curve count, got {mode!r}")
    model, meta = load_model(mode, input)
    ink = network_ink(redrawn(skeleton), int(meta.get("size", 64)))
    stops = model(ink, MAX_CURVES)[1] if mode == "M" else model.curve_codes(ink, MAX_CURVES)[2]
    s = stops.softmax(-1)[0, :, 1].double()
    s[-1] = 1.0
    alive = torch.cumprod(torch.cat([s.new_ones(1), 1.0 - s[:-1]]), 0)
    return (alive * s).numpy()


@torch.no_grad()
def curves_of_count(grey: np.ndarray, count: int, shape: tuple[int, int] | None = None,
                    input: str = "redrawn") -> list:
    """The MV network's curves in ``grey (h, w)`` (dark on light) with the number of curves
    given (its own curve-stop ignored; each curve's point count from its point-stop), in
    the pixels of an image of ``shape (H, W)`` (default ``grey``'s); ``input`` as in
    :func:`count_probabilities` (the default reads a :func:`redrawn` drawing)."""
    model, meta = load_model("MV", input)
    ink = network_ink(grey, int(meta.get("size", 64)))
    tokens, codes, _ = model.curve_codes(ink, count)
    pts, point_stops = model.decode_points(tokens, codes, MAX_POINTS)
    n = predicted_count(point_stops, MIN_POINTS)[0]
    h, w = grey.shape if shape is None else shape
    return to_curves([pts[0, i, : int(n[i])].double().numpy() for i in range(count)], w, h)

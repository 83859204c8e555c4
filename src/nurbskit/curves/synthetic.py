"""Synthetic drawings of B-spline curves, deterministic by seed (DeepSpline, section 4).

The recipe of the DeepSpline paper (seed 002, section 4): cubic B-splines with a clamped
uniform knot vector and 4 to 6 control points drawn uniformly in the image, 1 to 3
curves per image, 128 x 128, each curve oriented so that its first control point lies
left of its last (the "canonical orientation" that removes the reversal ambiguity of a
curve's control polygon). Nothing is read from or written to disk.

Convention: pixel coordinates, x to the right, y down, the origin at the top-left corner
of the top-left pixel; the centre of pixel ``[row, col]`` is ``(col + 0.5, row + 0.5)``.
Images are ``(H, W)`` float64 in [0, 1], dark strokes (0) on a light background (1).

Example:
    >>> from nurbskit.curves.synthetic import SyntheticConfig, make_sample
    >>> s = make_sample(7, SyntheticConfig(size=(64, 64)))
    >>> s.image.shape, len(s.control_points) == s.n_curves
    ((64, 64), True)
"""

from __future__ import annotations

import dataclasses

import numpy as np
from scipy.spatial import cKDTree

from ..errors import OptionError


@dataclasses.dataclass(frozen=True)
class SyntheticConfig:
    """What a synthetic drawing holds.

    Attributes:
        size: image ``(H, W)`` in pixels.
        curves: inclusive range of the number of curves per image.
        ctrl: inclusive range of the number of control points per curve.
        degree: the curves' degree (cubic in the paper).
        width: stroke width in pixels (the full width of the anti-aliased line).
        margin: control points are drawn uniformly in the image shrunk by this many pixels.
    """

    size: tuple[int, int] = (128, 128)
    curves: tuple[int, int] = (1, 3)
    ctrl: tuple[int, int] = (4, 6)
    degree: int = 3
    width: float = 2.0
    margin: float = 4.0

    def __post_init__(self):
        h, w = self.size
        if min(h, w) < 8:
            raise OptionError(f"size: expected at least 8 x 8 pixels, got {h} x {w}")
        if not 1 <= self.curves[0] <= self.curves[1]:
            raise OptionError(f"curves: expected 1 <= low <= high, got {self.curves}")
        if not self.degree + 1 <= self.ctrl[0] <= self.ctrl[1]:
            raise OptionError(f"ctrl: expected {self.degree + 1} <= low <= high, got {self.ctrl}")
        if not 0 < self.width <= min(h, w) / 4:
            raise OptionError(f"width: expected a stroke width in (0, {min(h, w) / 4:g}] pixels, got {self.width}")
        if not 0 <= self.margin < min(h, w) / 2:
            raise OptionError(f"margin: expected [0, {min(h, w) / 2:g}) pixels, got {self.margin}")


@dataclasses.dataclass
class Sample:
    """One drawing and its targets.

    Attributes:
        image: ``(H, W)`` float64 in [0, 1], dark strokes on white.
        control_points: one ``(n_i, 2)`` array per curve, pixel coordinates (x, y).
        counts: ``(n_curves,)`` number of control points of each curve.
    """

    image: np.ndarray
    control_points: list[np.ndarray]
    counts: np.ndarray

    @property
    def n_curves(self) -> int:
        return len(self.control_points)

    def curves(self):
        """The targets as :class:`~nurbskit.NURBSCurve` objects (float64, clamped uniform)."""
        return [curve_of(p) for p in self.control_points]


def curve_of(control_points: np.ndarray, degree: int = 3):
    """A clamped-uniform B-spline of ``control_points (n, 2)`` (float64)."""
    import torch

    from ..core import NURBSCurve

    return NURBSCurve(torch.as_tensor(np.asarray(control_points, dtype=np.float64)), degree=degree)


def dense_samples(curve, spacing: float = 0.25) -> np.ndarray:
    """Points ``(M, 2)`` along ``curve`` at most about ``spacing`` pixels apart.

    The count comes from the control polygon's length, which bounds the curve's length
    (the variation-diminishing property of B-splines).
    """
    import torch

    cp = curve.control_points.detach().cpu().numpy()
    polygon = float(np.linalg.norm(np.diff(cp, axis=0), axis=1).sum())
    m = int(np.clip(np.ceil(polygon / spacing), 16, 1 << 20)) + 1
    u0, u1 = curve.domain[0]
    with torch.no_grad():
        pts = curve.evaluate(torch.linspace(float(u0), float(u1), m, dtype=curve.dtype))
    return pts.cpu().numpy().astype(np.float64)


def render(polylines: list[np.ndarray], size: tuple[int, int], width: float) -> np.ndarray:
    """Anti-aliased strokes of ``width`` pixels along dense ``polylines [(M_i, 2)]`` -> ``(H, W)`` ink in [0, 1].

    A distance-field render: a pixel's ink is ``clip(width / 2 + 1/2 - d, 0, 1)`` with ``d``
    the distance from its centre to the nearest curve sample, a one-pixel linear ramp
    across the stroke's edge (the box-filter coverage of a straight edge). The samples
    must be dense (:func:`dense_samples`), so that the nearest sample is the nearest point.
    """
    h, w = size
    ink = np.zeros((h, w))
    if not polylines:
        return ink
    tree = cKDTree(np.concatenate(polylines))
    reach = width / 2 + 1.0
    ys, xs = np.mgrid[0:h, 0:w]
    centres = np.stack([xs.ravel() + 0.5, ys.ravel() + 0.5], axis=1)
    d, _ = tree.query(centres, distance_upper_bound=reach)
    ink.ravel()[:] = np.clip(width / 2 + 0.5 - d, 0.0, 1.0)  # inf (beyond reach) -> 0
    return ink


#: How :func:`photograph` lights a drawing.
LIGHTS = ("lamp", "vignette", "board")


def photograph(image: np.ndarray, light: str = "lamp", noise: float = 0.02, seed: int = 0) -> np.ndarray:
    """A drawing ``(H, W)`` (dark strokes on 1) as a phone photographs it -> ``(H, W)`` in [0, 1].

    ``light``: ``"lamp"`` (paper lit from one corner: its brightness falls linearly from
    0.95 to 0.4 across the page; the ink reflects a quarter of the paper's light),
    ``"vignette"`` (the lens darkens the corners to 0.4 of the centre; ink a fifth),
    ``"board"`` (light strokes, 0.55 above a dark board, and a lamp's round glow of 0.35
    on the board off-centre). ``noise``: the standard deviation of Gaussian sensor noise
    added to every pixel (deterministic by ``seed``). For the tests and benchmarks of
    thresholding under uneven lighting (:func:`nurbskit.curves.classic.even_background`).
    """
    if light not in LIGHTS:
        raise OptionError(f"light: expected one of {', '.join(LIGHTS)}, got {light!r}")
    h, w = image.shape
    y, x = np.mgrid[0:h, 0:w]
    x, y = (x + 0.5) / w, (y + 0.5) / h
    if light == "lamp":
        out = (0.4 + 0.55 * (0.6 * x + 0.4 * y)) * (0.25 + 0.75 * image)
    elif light == "vignette":
        out = (1.0 - 1.2 * ((x - 0.5) ** 2 + (y - 0.5) ** 2)) * (0.2 + 0.8 * image)
    else:
        out = 0.05 + 0.35 * np.exp(-((x - 0.2) ** 2 + (y - 0.3) ** 2) / 0.1) + 0.55 * (1.0 - image)
    out = out + np.random.default_rng(seed).normal(0.0, noise, image.shape)
    return np.clip(out, 0.0, 1.0)


def make_sample(seed: int, config: SyntheticConfig = SyntheticConfig()) -> Sample:
    """The drawing number ``seed``: the same seed gives the same drawing on every machine.

    Uses its own ``numpy.random.Generator(PCG64(seed))``; the global RNGs are untouched.
    """
    rng = np.random.Generator(np.random.PCG64(seed))
    h, w = config.size
    n_curves = int(rng.integers(config.curves[0], config.curves[1] + 1))
    points, polylines = [], []
    for _ in range(n_curves):
        n = int(rng.integers(config.ctrl[0], config.ctrl[1] + 1))
        cp = np.stack([rng.uniform(config.margin, w - config.margin, n),
                       rng.uniform(config.margin, h - config.margin, n)], axis=1)
        if cp[0, 0] > cp[-1, 0]:  # canonical orientation: first point left of the last
            cp = cp[::-1].copy()
        points.append(cp)
        polylines.append(dense_samples(curve_of(cp, config.degree)))
    image = 1.0 - render(polylines, config.size, config.width)
    return Sample(image=image, control_points=points, counts=np.array([len(p) for p in points]))


def make_batch(seeds, config: SyntheticConfig = SyntheticConfig()) -> list[Sample]:
    """:func:`make_sample` for each seed."""
    return [make_sample(int(s), config) for s in seeds]


# --------------------------------------------------------------------------------------
# Batches for training (issue 10): the same recipe, drawn from a torch.Generator and
# rendered for a whole batch at once.

# The three problems of the paper (section 6): V one curve of 4 to 6 control points; M 1 to
# 3 curves of 5; MV 1 to 3 curves of 4 to 6.
MODES = {"V": {"curves": (1, 1), "ctrl": (4, 6)},
         "M": {"curves": (1, 3), "ctrl": (5, 5)},
         "MV": {"curves": (1, 3), "ctrl": (4, 6)}}


def mode_config(mode: str, size: int = 128, width: float | None = None) -> SyntheticConfig:
    """The :class:`SyntheticConfig` of a DeepSpline problem (``"V"``, ``"M"``, ``"MV"``) at ``size`` pixels.

    The stroke width and margin scale with the size (2 px and 4 px at 128, the recipe's).
    """
    if mode not in MODES:
        raise OptionError(f"mode: expected one of {', '.join(MODES)}, got {mode!r}")
    width = 2.0 * size / 128 if width is None else width
    return SyntheticConfig(size=(size, size), width=width, margin=4.0 * size / 128, **MODES[mode])


@dataclasses.dataclass
class Batch:
    """A batch of drawings with padded targets.

    Attributes:
        image: ``(B, H, W)`` float32 in [0, 1], dark strokes on white.
        points: ``(B, K, P, 2)`` float64 control points in pixels (x, y), zero where padded;
            ``K``, ``P`` the config's largest numbers of curves and control points.
        counts: ``(B, K)`` int64 control points of each curve, 0 for absent curves.
        n_curves: ``(B,)`` int64.
    """

    image: "torch.Tensor"  # noqa: F821 - torch is imported lazily
    points: "torch.Tensor"  # noqa: F821
    counts: "torch.Tensor"  # noqa: F821
    n_curves: "torch.Tensor"  # noqa: F821

    def samples(self) -> list[Sample]:
        """The batch as :class:`Sample` objects (numpy, float64 images)."""
        out = []
        for b in range(self.image.shape[0]):
            cps = [self.points[b, k, : int(self.counts[b, k])].numpy().astype(np.float64)
                   for k in range(int(self.n_curves[b]))]
            out.append(Sample(image=self.image[b].double().numpy(), control_points=cps,
                              counts=np.array([len(p) for p in cps])))
        return out


def make_torch_batch(generator, batch_size: int, config: SyntheticConfig = SyntheticConfig(),
                     spacing: float = 0.25) -> Batch:
    """``batch_size`` drawings of the recipe of ``config``, drawn from a ``torch.Generator``.

    The same generator state gives the same batch (the training loop's convention:
    :func:`nurbskit.learn.batch_generator`). Rendering is :func:`render`'s distance-field
    stroke, evaluated by scattering each curve sample's ink into the pixels within its
    reach (``scatter_reduce`` with ``amax``: the largest ink over samples is the ink of
    the nearest sample), with every curve sampled at most ``spacing`` px apart (its
    control polygon bounds its length).
    """
    import torch

    h, w = config.size
    k_max, p_max = config.curves[1], config.ctrl[1]
    f64 = torch.float64
    n_curves = torch.randint(config.curves[0], config.curves[1] + 1, (batch_size,), generator=generator)
    counts = torch.randint(config.ctrl[0], config.ctrl[1] + 1, (batch_size, k_max), generator=generator)
    u = torch.rand((batch_size, k_max, p_max, 2), generator=generator, dtype=f64)
    lo = torch.tensor([config.margin, config.margin], dtype=f64)
    hi = torch.tensor([w - config.margin, h - config.margin], dtype=f64)
    points = lo + u * (hi - lo)
    present = torch.arange(k_max) < n_curves[:, None]
    counts = torch.where(present, counts, torch.zeros_like(counts))
    j = torch.arange(p_max)
    valid = j < counts[..., None]  # (B, K, P)
    last = points.gather(2, (counts.clamp(min=1) - 1)[..., None, None].expand(-1, -1, 1, 2))[:, :, 0]
    reverse = points[:, :, 0, 0] > last[..., 0]  # canonical orientation: first point left of the last
    index = torch.where(reverse[..., None] & valid, counts[..., None] - 1 - j, j)
    points = points.gather(2, index[..., None].expand(-1, -1, -1, 2))
    points = torch.where(valid[..., None], points, torch.zeros_like(points))
    pts, owner = curve_samples(points, counts, config.degree, spacing)
    ink = render_batch(pts, owner // k_max, batch_size, config.size, config.width)
    return Batch(image=(1.0 - ink).float(), points=points, counts=counts, n_curves=n_curves)


def curve_samples(points, counts, degree: int = 3, spacing: float = 0.25):
    """Samples of padded curves, each at most about ``spacing`` px apart -> ``(pts (N, 2), owner (N,))``.

    ``points (B, K, P, 2)``, ``counts (B, K)`` (0: no curve); ``owner`` is the flat curve
    index ``b * K + k`` of each sample. A curve gets ``ceil(polygon / spacing) + 1``
    uniform parameters (its control polygon bounds its length), so no curve pays for the
    longest one.
    """
    import torch

    from ..core.basis import basis_matrix
    from ..core.knots import clamped_uniform

    k_max, p_max = points.shape[1], points.shape[2]
    flat_pts = points.reshape(-1, p_max, 2).double()
    flat_counts = counts.reshape(-1)
    valid = torch.arange(p_max) < flat_counts[:, None]
    polygon = ((flat_pts[:, 1:] - flat_pts[:, :-1]).norm(dim=-1) * valid[:, 1:]).sum(-1)
    out, owner = [], []
    for n in sorted({int(c) for c in flat_counts.tolist() if c > 0}):
        curves = (flat_counts == n).nonzero()[:, 0]
        m = (torch.ceil(polygon[curves] / spacing).long() + 1).clamp(min=16)
        who = torch.repeat_interleave(curves, m)
        start = torch.repeat_interleave(torch.cumsum(m, 0) - m, m)
        u = (torch.arange(int(m.sum())) - start).double() / torch.repeat_interleave(m - 1, m).double()
        basis = basis_matrix(clamped_uniform(n, degree, dtype=torch.float64), degree, n, u)  # (N, n)
        out.append(torch.einsum("sn,snd->sd", basis, flat_pts[who, :n]))
        owner.append(who)
    if not out:
        return torch.zeros(0, 2, dtype=torch.float64), torch.zeros(0, dtype=torch.long)
    return torch.cat(out), torch.cat(owner)


#: Samples :func:`render_batch` inks at a time.
RENDER_CHUNK = 4096


def render_batch(pts, image_index, batch_size: int, size: tuple[int, int], width: float):
    """:func:`render` for many images at once: ``pts (N, 2)`` dense samples, ``image_index (N,)`` -> ``(B, H, W)`` ink.

    Each sample scatters ``clip(width / 2 + 1/2 - d, 0, 1)`` into the pixels within its
    reach and each pixel keeps the largest (``scatter_reduce(amax)``), which is the ink of
    its nearest sample: the same image as :func:`render`, without a k-d tree per image.
    """
    import torch

    h, w = size
    if not len(pts):
        return torch.zeros(batch_size, h, w, dtype=torch.float64)
    r = int(np.ceil(width / 2 + 1.0))  # a sample's ink reaches under r px
    near = (pts[:, 0] > -r) & (pts[:, 0] < w + r) & (pts[:, 1] > -r) & (pts[:, 1] < h + r)
    if not bool(near.all()):  # samples that ink no pixel of their image
        pts, image_index = pts[near], image_index[near]
    # each image framed by 2r px, so that every pixel a near sample reaches has an index: no
    # boolean mask (its nonzero and gathers cost half the time), the frame cut off at the end
    f = 2 * r
    hh, ww = h + 2 * f, w + 2 * f
    off = torch.arange(-r, r + 1)
    canvas = torch.zeros(batch_size * hh * ww, dtype=torch.float64)
    # in chunks of samples: each chunk's buffers stay in the cache and are reused from the
    # heap (whole-batch buffers of 10-20 MB are paged in anew on every call, at 2-3x the time)
    for start in range(0, len(pts), RENDER_CHUNK):
        p, owner = pts[start : start + RENDER_CHUNK], image_index[start : start + RENDER_CHUNK]
        fx, fy = torch.floor(p[:, 0]), torch.floor(p[:, 1])
        cx = fx[:, None, None] + (off + 0.5)[None, None, :]  # pixel centres (n, 1, 2r+1), exact
        cy = fy[:, None, None] + (off + 0.5)[None, :, None]  # (n, 2r+1, 1)
        # full-size operands: a broadcast hypot takes another code path, apart by an ulp
        full = (len(p), 2 * r + 1, 2 * r + 1)
        d = torch.hypot(cx.expand(full) - p[:, 0, None, None], cy.expand(full) - p[:, 1, None, None])
        ink = (width / 2 + 0.5 - d).clamp_(0, 1)
        row = (owner * hh + fy.long() + f)[:, None, None] + off[None, :, None]
        flat = row * ww + ((fx.long() + f)[:, None, None] + off[None, None, :])
        canvas.scatter_reduce_(0, flat.reshape(-1), ink.reshape(-1), reduce="amax")
    return canvas.view(batch_size, hh, ww)[:, f : f + h, f : f + w].contiguous()

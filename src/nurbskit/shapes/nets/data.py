"""Synthetic training data and the fixed surface layer of the learned path (DeepSpline, section 5).

Convention (the canonical frame every network sees and predicts in):
    * A profile is a clamped uniform cubic B-spline with :data:`N_CTRL` control points.
    * Revolution: the axis is the z axis through the origin; the profile's control points
      are ``(r, z)`` (radius, height). Extrusion: the direction is z; the profile's control
      points are ``(x, y)`` in the plane, and the extent is ``(t0, t1)`` along z.
    * A cloud is normalised by :func:`normalise`: minus its centroid, divided by the largest
      distance from it, so it lies in the unit ball. Training clouds are generated already
      in the canonical orientation (axis or direction = z) and normalised the same way, so
      the network sees at training time what :func:`~nurbskit.shapes.nets.initial_guess`
      gives it after aligning a world cloud.
    * Silhouettes (the image variant, revolutions only) are ``(RES, RES)`` images of the
      normalised shape seen along y, orthographic: column ``j`` is ``x`` from -1 to 1, row
      ``i`` is ``z`` from 1 (top) to -1; a pixel is 1 inside the silhouette, 0 outside.

The generated surface is the paper's "linear layer with fixed weights" (eq. 19): with the
profile's knots and weights fixed, the points of the exact NURBS surface at fixed
parameters are a linear function of the profile's control points (and, for an extrusion,
of the extent). :class:`SurfaceLayer` holds that matrix; it is extracted once from the
core's exact constructors (:func:`nurbskit.core.construct.revolve` / ``extrude``) by
exact differences of the linear map, and the tests check it against them.
"""

from __future__ import annotations

import math

import torch
from torch import Tensor, nn

from ...core.basis import basis_matrix
from ...core.construct import extrude, revolve
from ...core.curve import NURBSCurve
from ...core.knots import clamped_uniform
from ...errors import NurbskitError

KINDS = ("revolution", "extrusion")
N_CTRL = 8  # profile control points predicted by every network
DEGREE = 3
RES = 64  # silhouette image size
GRID = {"revolution": (32, 24), "extrusion": (12, 48)}  # (n_u sweep, n_v profile) samples of the layer

__all__ = ["KINDS", "N_CTRL", "DEGREE", "RES", "SurfaceLayer", "profile_knots", "random_profiles",
           "sample_clouds", "normalise", "silhouettes", "make_batch", "n_outputs"]


def _check_kind(kind: str) -> None:
    if kind not in KINDS:
        raise NurbskitError(f"kind must be one of {', '.join(KINDS)}, got {kind!r}")


def n_outputs(kind: str) -> int:
    """Numbers a network predicts: ``2 * N_CTRL`` profile coordinates (+ ``t0, t1`` for an extrusion)."""
    _check_kind(kind)
    return 2 * N_CTRL + (2 if kind == "extrusion" else 0)


def profile_knots(dtype=torch.float64) -> Tensor:
    """The profile's knot vector ``(N_CTRL + DEGREE + 1,)``: clamped uniform on [0, 1]."""
    return clamped_uniform(N_CTRL, DEGREE, dtype=dtype)


def _params(kind: str, dtype) -> Tensor:
    """The layer's fixed parameters ``(n_u * n_v, 2)``: a uniform grid, the sweep open at u = 1."""
    n_u, n_v = GRID[kind]
    u = (torch.arange(n_u, dtype=dtype) + 0.5) / n_u if kind == "revolution" else torch.linspace(0, 1, n_u, dtype=dtype)
    v = torch.linspace(0, 1, n_v, dtype=dtype)
    return torch.stack(torch.meshgrid(u, v, indexing="ij"), -1).reshape(-1, 2)


def exact_surface(kind: str, coords: Tensor):
    """The core's exact surface in the canonical frame from one prediction ``(n_outputs,)``.

    Revolution: the profile ``(r, z)`` placed in the xz plane, revolved about z (full turn).
    Extrusion: the profile ``(x, y)`` at height ``t0``, extruded along z by ``t1 - t0``.
    """
    _check_kind(kind)
    c = coords[: 2 * N_CTRL].reshape(N_CTRL, 2)
    zero = torch.zeros_like(c[:, :1])
    z_axis = torch.tensor([0.0, 0.0, 1.0], dtype=coords.dtype)
    if kind == "revolution":
        profile = NURBSCurve(torch.cat([c[:, :1], zero, c[:, 1:]], -1), degree=DEGREE, knot_vector=profile_knots(coords.dtype))
        return revolve(profile, torch.zeros(3, dtype=coords.dtype), z_axis)
    t0, t1 = coords[2 * N_CTRL], coords[2 * N_CTRL + 1]
    profile = NURBSCurve(torch.cat([c, zero + t0], -1), degree=DEGREE, knot_vector=profile_knots(coords.dtype))
    return extrude(profile, z_axis, t1 - t0)


class SurfaceLayer(nn.Module):
    """The fixed linear layer: predicted coordinates ``(*, n_outputs)`` -> surface points ``(*, S, 3)``.

    ``S = n_u * n_v`` points of the exact surface at the fixed parameters of :data:`GRID`.
    The matrix is the Jacobian of ``coords -> exact_surface(kind, coords).evaluate(params)``,
    found by exact differences (the map is linear; :func:`exact_surface` builds it with the
    core's constructors); a buffer, never trained.
    """

    def __init__(self, kind: str):
        super().__init__()
        _check_kind(kind)
        self.kind = kind
        dt = torch.float64
        params = _params(kind, dt)
        base = self._base(dt)

        def f(c):
            return exact_surface(kind, c).evaluate(params).reshape(-1)

        f0 = f(base)
        cols = [f(base + torch.nn.functional.one_hot(torch.tensor(k), base.numel()).to(dt)) - f0
                for k in range(base.numel())]
        matrix = torch.stack(cols, -1)  # (3 S, n_outputs)
        # the map is homogeneous (axis through the origin): f(base) = matrix @ base exactly
        if float((matrix @ base - f0).abs().max()) > 1e-10:
            raise NurbskitError("internal: the surface is not linear in the profile (constructor changed?)")
        self.register_buffer("matrix", matrix, persistent=False)  # float64; cast per call
        self.register_buffer("params", params, persistent=False)

    def _base(self, dt) -> Tensor:
        # a generic point of the domain where the map is linear: every radius > 1 (so that
        # base + e_k keeps it positive) and a non-zero extent
        k = torch.arange(N_CTRL, dtype=dt)
        prof = torch.stack([2.0 + 0.1 * k, 0.3 * k - 1.0], -1).reshape(-1)
        return prof if self.kind == "revolution" else torch.cat([prof, torch.tensor([-1.0, 1.5], dtype=dt)])

    def forward(self, coords: Tensor) -> Tensor:
        m = self.matrix.to(coords.dtype)
        return (coords @ m.T).reshape(*coords.shape[:-1], -1, 3)


# ---- random profiles and clouds -----------------------------------------------------------

def _smooth_walk(g: torch.Generator, b: int, n: int, dtype) -> Tensor:
    """``(b, n)`` smooth random sequences in [0, 1]: a random walk, then rescaled."""
    steps = torch.randn(b, n, generator=g, dtype=dtype)
    walk = torch.cumsum(steps, -1)
    walk = walk + 0.6 * torch.randn(b, n, generator=g, dtype=dtype)  # some local wiggle
    lo, hi = walk.amin(-1, keepdim=True), walk.amax(-1, keepdim=True)
    return (walk - lo) / (hi - lo).clamp_min(1e-9)


def random_profiles(g: torch.Generator, batch: int, kind: str, dtype=torch.float64) -> Tensor:
    """Random profiles in the canonical frame, ``(batch, n_outputs(kind))``.

    Both kinds are monotone in one coordinate (strictly increasing control coordinate, so
    the cubic curve is monotone too, by variation diminishing) and therefore never
    self-intersect. Revolution: heights ``z`` increasing over a total height in [0.5, 2.5],
    radii in [0.1, 1.2] (the smaller end at least 0.1: a shape, not a needle), positive.
    Extrusion: ``x`` increasing over a width in [0.8, 2], ``y`` a smooth wave of amplitude
    up to 0.8, the profile turned by a random angle in its plane, extent ``t1 - t0`` in
    [0.4, 2.5] centred on 0.
    """
    _check_kind(kind)
    u = lambda *s: torch.rand(*s, generator=g, dtype=dtype)  # noqa: E731
    gaps = 0.3 + u(batch, N_CTRL - 1)
    along = torch.cat([torch.zeros(batch, 1, dtype=dtype), torch.cumsum(gaps, -1)], -1)
    along = along / along[:, -1:]
    wave = _smooth_walk(g, batch, N_CTRL, dtype)
    if kind == "revolution":
        height = 0.5 + 2.0 * u(batch, 1)
        r_min = 0.1 + 0.4 * u(batch, 1)
        r_max = r_min + 0.1 + (1.2 - r_min - 0.1) * u(batch, 1)
        r = r_min + (r_max - r_min) * wave
        z = (along - 0.5) * height
        return torch.stack([r, z], -1).reshape(batch, -1)
    width = 0.8 + 1.2 * u(batch, 1)
    amp = 0.05 + 0.75 * u(batch, 1)
    x = (along - 0.5) * width
    y = (wave - 0.5) * amp
    phi = 2 * math.pi * u(batch, 1)
    c, s = torch.cos(phi), torch.sin(phi)
    xy = torch.stack([c * x - s * y, s * x + c * y], -1).reshape(batch, -1)
    half = 0.2 + 1.05 * u(batch, 1)
    return torch.cat([xy, -half, half], -1)


def sample_clouds(g: torch.Generator, coords: Tensor, kind: str, n: int, noise: float | Tensor = 0.0) -> Tensor:
    """Points of the surfaces ``coords (B, n_outputs)`` -> ``(B, n, 3)``, with Gaussian noise.

    Parameters are uniform (the sweep angle, or extent, and the profile parameter); the
    noise has a standard deviation of ``noise`` (a float or ``(B,)``) times each cloud's
    bounding-box diagonal, per coordinate.
    """
    _check_kind(kind)
    b, dt = coords.shape[0], coords.dtype
    prof = coords[:, : 2 * N_CTRL].reshape(b, N_CTRL, 2)
    v = torch.rand(b, n, generator=g, dtype=dt)
    basis = basis_matrix(profile_knots(dt), DEGREE, N_CTRL, v.reshape(-1)).reshape(b, n, N_CTRL)
    q = basis @ prof  # (B, n, 2) profile points
    t = torch.rand(b, n, generator=g, dtype=dt)
    if kind == "revolution":
        phi = 2 * math.pi * t
        pts = torch.stack([q[..., 0] * torch.cos(phi), q[..., 0] * torch.sin(phi), q[..., 1]], -1)
    else:
        t0, t1 = coords[:, -2:-1], coords[:, -1:]
        pts = torch.cat([q, (t0 + (t1 - t0) * t)[..., None]], -1)
    diag = (pts.amax(1) - pts.amin(1)).norm(dim=-1)  # (B,)
    sigma = (torch.as_tensor(noise, dtype=dt) * diag).reshape(b, 1, 1)
    return pts + sigma * torch.randn(pts.shape, generator=g, dtype=dt)


def normalise(points: Tensor) -> tuple[Tensor, Tensor, Tensor]:
    """``points (*, N, 3)`` -> ``(normalised, centre (*, 3), scale (*,))``: centred, in the unit ball."""
    centre = points.mean(-2)
    rel = points - centre[..., None, :]
    scale = rel.norm(dim=-1).amax(-1).clamp_min(torch.finfo(points.dtype).tiny)
    return rel / scale[..., None, None], centre, scale


def silhouettes(coords: Tensor, centre: Tensor, scale: Tensor, res: int = RES) -> Tensor:
    """Silhouettes ``(B, 1, res, res)`` of revolutions ``coords (B, 2 N_CTRL)`` after :func:`normalise`.

    ``centre (B, 3)``, ``scale (B,)`` the normalisation of each cloud. A pixel at height z
    is inside when its distance from the (shifted) axis is at most the profile's radius at
    that height, found by interpolating a dense sample of the profile (monotone in z).
    """
    b, dt = coords.shape[0], coords.dtype
    prof = coords.reshape(b, N_CTRL, 2)
    v = torch.linspace(0, 1, 256, dtype=dt)
    dense = basis_matrix(profile_knots(dt), DEGREE, N_CTRL, v) @ prof  # (B, 256, 2)
    r = dense[..., 0] / scale[:, None]
    z = ((dense[..., 1] - centre[:, 2:3]) / scale[:, None]).contiguous()
    rows = torch.linspace(1, -1, res, dtype=dt)
    cols = torch.linspace(-1, 1, res, dtype=dt)
    idx = torch.searchsorted(z, rows.expand(b, res).contiguous()).clamp(1, z.shape[1] - 1)
    z0, z1 = torch.gather(z, 1, idx - 1), torch.gather(z, 1, idx)
    r0, r1 = torch.gather(r, 1, idx - 1), torch.gather(r, 1, idx)
    w = ((rows - z0) / (z1 - z0).clamp_min(1e-12)).clamp(0, 1)
    radius = r0 + w * (r1 - r0)  # (B, res)
    inside_z = (rows >= z[:, :1]) & (rows <= z[:, -1:])
    x_axis = -centre[:, 0:1] / scale[:, None]
    dist = (cols[None, None, :] - x_axis[:, :, None]).abs()  # (B, 1, res)
    img = (dist <= radius[:, :, None]) & inside_z[:, :, None]
    return img.to(dt)[:, None]


def make_batch(g: torch.Generator, batch: int, kind: str, n_points: int = 512, *, images: bool = False,
               max_noise: float = 0.01, dtype=torch.float32) -> dict:
    """One training batch: ``{"points": (B, n, 3)}`` normalised clouds (+ ``"images"`` ``(B, 1, RES, RES)``).

    Noise per cloud uniform in ``[0, max_noise]`` of the diagonal. ``"truth"`` holds the
    generating coordinates (never used by the loss: the training is unsupervised).
    """
    coords = random_profiles(g, batch, kind)
    noise = max_noise * torch.rand(batch, generator=g, dtype=torch.float64)
    pts = sample_clouds(g, coords, kind, n_points, noise)
    pts, centre, scale = normalise(pts)
    out = {"points": pts.to(dtype), "truth": coords.to(dtype)}
    if images:
        if kind != "revolution":
            raise NurbskitError("silhouette images are made for revolutions only")
        out["images"] = silhouettes(coords, centre, scale).to(dtype)
    return out

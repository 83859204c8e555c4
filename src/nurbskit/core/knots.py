"""Knot vectors: defaults, validation, span search and an ordered parametrisation.

Convention: a knot vector for ``n`` control points of degree ``p`` has ``n + p + 1``
non-decreasing entries; the parameter domain is ``[knots[p], knots[n]]``. Span ``k``
is the half-open interval ``[knots[k], knots[k+1])`` with ``p <= k <= n - 1``; the last
span also owns ``u = knots[n]``, so the domain end evaluates exactly to the last
control point of a clamped curve (The NURBS Book, A2.1). A batch of splines shares one
knot vector ``(m,)`` or has one per element, ``(*B, m)``.

Knots closer than :func:`knot_tolerance` are one knot (as in OpenCASCADE): insertion,
refinement and construction raise the multiplicity of the existing knot instead of
creating a span too short to divide by.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np
import torch

from ..errors import NurbskitError

Tensor = torch.Tensor


def clamped_uniform(
    n_ctrl: int,
    degree: int,
    domain: tuple[float, float] = (0.0, 1.0),
    *,
    dtype: torch.dtype | None = None,
    device: torch.device | str | None = None,
) -> Tensor:
    """Clamped uniform knot vector of length ``n_ctrl + degree + 1`` on ``domain``.

    Example:
        >>> clamped_uniform(5, 2, dtype=torch.float64).tolist()
        [0.0, 0.0, 0.0, 0.3333333333333333, 0.6666666666666667, 1.0, 1.0, 1.0]
    """
    if n_ctrl < degree + 1:
        raise NurbskitError(f"degree {degree} needs at least {degree + 1} control points, got {n_ctrl}")
    a, b = domain
    inner = torch.linspace(a, b, n_ctrl - degree + 1, dtype=dtype or torch.get_default_dtype(), device=device)
    return torch.cat([inner[:1].repeat(degree), inner, inner[-1:].repeat(degree)])


def knot_tolerance(knots, dtype: torch.dtype | None = None) -> float:
    """Distance below which two knots are one knot: ``16 eps max(|a|, |b|, b - a)``.

    ``a, b`` are the first and last knots (of every row of a batch) and ``eps`` the
    machine epsilon of ``dtype`` (default: the knots' own dtype, float64 for arrays).
    Two knots closer than this differ by a few units in the last place of their
    magnitude: the span between them carries no information, and dividing by its length
    (The NURBS Book A2.2) overflows once it is subnormal.

    Example:
        >>> knot_tolerance(torch.tensor([0.0, 0.0, 1.0, 1.0], dtype=torch.float64))
        3.552713678800501e-15
    """
    if isinstance(knots, Tensor):
        dtype = dtype or knots.dtype
        k = knots.detach().reshape(-1, knots.shape[-1]).cpu().double().numpy()
    else:
        k = np.atleast_2d(np.asarray(knots, dtype=np.float64))
    eps = torch.finfo(dtype or torch.float64).eps
    a, b = k[:, 0], k[:, -1]
    return float(16 * eps * np.max(np.maximum(np.maximum(np.abs(a), np.abs(b)), b - a)))


def merge_close_knots(knots: Tensor, tol: float | None = None) -> Tensor:
    """``knots`` with every knot within ``tol`` of its predecessor snapped onto it.

    Shapes: ``(*, m)`` -> ``(*, m)``; ``tol`` defaults to :func:`knot_tolerance`. A run of
    nearly equal knots becomes one knot of higher multiplicity (the run's first value),
    so no span is shorter than ``tol`` unless it is empty. Returns ``knots`` itself when
    nothing moves. Reads the knots on the host: construction-time only. Differentiable:
    a snapped knot takes its predecessor's value and gradient.

    Example:
        >>> merge_close_knots(torch.tensor([0.0, 0.0, 5e-324, 1.0, 1.0], dtype=torch.float64)).tolist()
        [0.0, 0.0, 0.0, 1.0, 1.0]
    """
    tol = knot_tolerance(knots) if tol is None else tol
    m = knots.shape[-1]
    k = knots.detach().cpu().double().reshape(-1, m).numpy()
    close = (np.diff(k, axis=-1) > 0) & (np.diff(k, axis=-1) <= tol)
    if not close.any():
        return knots
    source = np.tile(np.arange(m), (k.shape[0], 1))
    for i in range(1, m):  # the run's first index propagates forward
        source[:, i] = np.where(close[:, i - 1], source[:, i - 1], source[:, i])
    index = torch.as_tensor(source.reshape(knots.shape), device=knots.device)
    return torch.gather(knots, -1, index)


def validate_knot_vector(knots: Tensor, degree: int, n_ctrl: int, axis: str = "", batch_shape: tuple = (),
                         *, multiplicity: bool = True) -> None:
    """Raise a NurbskitError that names the axis when ``knots`` cannot serve.

    ``knots`` is ``(m,)`` (shared) or ``(*batch_shape, m)`` (one per batch element).
    Checks count against degree and control points, monotonicity, finiteness, a
    non-empty domain (longer than :func:`knot_tolerance`) and multiplicities of at most
    ``degree + 1`` (knots given equal; ``multiplicity=False`` skips that test, for knots
    that :func:`merge_close_knots` made equal), naming the first bad element.
    """
    where = f"knot vector for {axis}" if axis else "knot vector"
    if knots.ndim != 1 and tuple(knots.shape[:-1]) != tuple(batch_shape):
        expected = "(m,)" if not batch_shape else f"(m,) or {tuple(batch_shape) + ('m',)}"
        raise NurbskitError(f"{where} must have shape {expected}, got {tuple(knots.shape)}")
    need = n_ctrl + degree + 1
    if knots.shape[-1] != need:
        raise NurbskitError(
            f"{where} has {knots.shape[-1]} knots; degree {degree} with {n_ctrl} control points needs {need}"
        )
    rows = knots.detach().cpu().double().reshape(-1, need).numpy()
    for r, k in enumerate(rows):
        at = "" if knots.ndim == 1 else f" (batch element {tuple(int(i) for i in np.unravel_index(r, batch_shape))})"
        if not np.all(np.isfinite(k)):
            raise NurbskitError(f"{where}{at} contains NaN or infinite values")
        drops = np.nonzero(np.diff(k) < 0)[0]
        if drops.size:
            i = int(drops[0])
            raise NurbskitError(f"{where}{at} decreases at index {i + 1}: {float(k[i])!r} > {float(k[i + 1])!r}")
        if not k[n_ctrl] - k[degree] > knot_tolerance(k, knots.dtype):
            raise NurbskitError(f"{where}{at} has an empty domain [{float(k[degree])!r}, {float(k[n_ctrl])!r}]")
        starts = np.flatnonzero(np.r_[True, k[1:] != k[:-1]])
        runs = np.diff(np.r_[starts, k.size])
        if multiplicity and runs.max() > degree + 1:
            i = int(starts[np.argmax(runs)])
            raise NurbskitError(
                f"{where}{at} repeats the knot {float(k[i])!r} {int(runs.max())} times from index {i}; "
                f"degree {degree} allows at most {degree + 1} (beyond that a control point has no effect)"
            )


def span_bounds(knots: Tensor, degree: int, n_ctrl: int) -> tuple[Tensor, Tensor]:
    """The first and last non-empty spans of the domain, ``(1,)`` int64 each (``(*B, 1)``
    for one knot vector per batch element): usually ``p`` and ``n - 1``, but an unclamped
    vector may repeat its end knots (``knots[n - 1] == knots[n]``), and then span
    ``n - 1`` is empty. Found by search on detached knots, so nothing is read back."""
    return _span_bounds(knots.detach(), degree, n_ctrl)


def _span_bounds(k: Tensor, p: int, n: int) -> tuple[Tensor, Tensor]:
    if k.ndim == 1:
        return (torch.searchsorted(k, k[p : p + 1], right=True) - 1,
                torch.searchsorted(k, k[n : n + 1], right=False) - 1)
    first = torch.searchsorted(k, k[..., p : p + 1].contiguous(), right=True) - 1
    last = torch.searchsorted(k, k[..., n : n + 1].contiguous(), right=False) - 1
    return first, last


def find_spans(knots: Tensor, degree: int, n_ctrl: int, u: Tensor,
               bounds: tuple[Tensor, Tensor] | None = None) -> Tensor:
    """Span index ``k`` with ``knots[k] <= u < knots[k+1]`` for every entry of ``u``.

    Shapes: ``knots (n_ctrl + degree + 1,)``, ``u (...)`` -> ``(...)`` int64; with one knot
    vector per batch element, ``knots (*B, m)`` and ``u (*B, ...)`` -> ``(*B, ...)``.
    Values outside the domain take the first or last non-empty span (polynomial
    extrapolation); the domain end ``knots[n]`` belongs to the last non-empty span.
    The search runs on detached knots (the span is piecewise constant in the knots) and
    reads nothing back to the host. ``bounds`` are :func:`span_bounds` of these knots,
    when the caller keeps them (they depend on the knots alone).
    """
    k = knots.detach()
    first, last = _span_bounds(k, degree, n_ctrl) if bounds is None else bounds
    if k.ndim == 1:
        spans = torch.searchsorted(k, u.detach().contiguous(), right=True) - 1
        return torch.maximum(torch.minimum(spans, last), first)
    lead = k.shape[:-1]
    flat_u = u.detach().reshape(lead + (-1,)).contiguous()
    spans = torch.searchsorted(k, flat_u, right=True) - 1
    return torch.maximum(torch.minimum(spans, last), first).reshape(u.shape)


def multiplicity(knots: Sequence[float] | Tensor, value: float, tol: float = 0.0) -> int:
    """How many times ``value`` occurs in ``knots`` (within ``tol``)."""
    k = torch.as_tensor(knots).detach().cpu().double()
    return int((k - value).abs().le(tol).sum())


# Smallest gap of a trained knot vector, as a fraction of the domain: trained knots stay
# strictly ordered with spans the basis can divide by (never subnormal, however far the
# logits go), yet far below any spacing a fit would choose.
_GAP_FLOOR = 1e-7


def knots_to_logits(knots: Tensor, degree: int, n_ctrl: int) -> Tensor:
    """Unconstrained parameters for the interior knots of a clamped knot vector.

    The ``n_ctrl - degree`` gaps between consecutive distinct domain knots are kept
    positive and summing to the domain length through a floored softmax (see
    :func:`logits_to_knots`), which this inverts. Repeated interior knots become knots
    a hair apart (a gap of ``1e-6`` of the domain), so trained knots stay strictly ordered.
    """
    inner = knots[degree : n_ctrl + 1]
    gaps = (inner[1:] - inner[:-1]).clamp_min(1e-6 * float((inner[-1] - inner[0]).detach()))
    share = gaps / gaps.sum()
    return torch.log((share - _GAP_FLOOR) / (1 - share.shape[-1] * _GAP_FLOOR))


def logits_to_knots(logits: Tensor, degree: int, domain: tuple[float, float]) -> Tensor:
    """Clamped, strictly ordered knot vector from ``logits`` (see :func:`knots_to_logits`).

    Shapes: ``logits (*, n_ctrl - degree)`` -> ``(*, n_ctrl + degree + 1)``; differentiable.
    Each of the ``G`` gaps is ``(b - a) (f + (1 - G f) softmax(logits))`` with the floor
    ``f = 1e-7``: however extreme the logits, no span is shorter than ``f (b - a)``, so
    trained knots never create a span that the basis cannot divide by.
    """
    a, b = domain
    count = logits.shape[-1]
    gaps = (_GAP_FLOOR + (1 - count * _GAP_FLOOR) * torch.softmax(logits, dim=-1)) * (b - a)
    inner = a + torch.cumsum(gaps, dim=-1)[..., :-1]
    start = logits.new_full(logits.shape[:-1] + (degree + 1,), a)
    end = logits.new_full(logits.shape[:-1] + (degree + 1,), b)
    return torch.cat([start, inner, end], dim=-1)

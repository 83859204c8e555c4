"""Knot vectors: defaults, validation, span search and an ordered parametrisation.

Convention: a knot vector for ``n`` control points of degree ``p`` has ``n + p + 1``
non-decreasing entries; the parameter domain is ``[knots[p], knots[n]]``. Span ``k``
is the half-open interval ``[knots[k], knots[k+1])`` with ``p <= k <= n - 1``; the last
span also owns ``u = knots[n]``, so the domain end evaluates exactly to the last
control point of a clamped curve (The NURBS Book, A2.1).
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
        >>> clamped_uniform(5, 2).tolist()
        [0.0, 0.0, 0.0, 0.3333333432674408, 0.6666666865348206, 1.0, 1.0, 1.0]
    """
    if n_ctrl < degree + 1:
        raise NurbskitError(f"degree {degree} needs at least {degree + 1} control points, got {n_ctrl}")
    a, b = domain
    inner = torch.linspace(a, b, n_ctrl - degree + 1, dtype=dtype or torch.get_default_dtype(), device=device)
    return torch.cat([inner[:1].repeat(degree), inner, inner[-1:].repeat(degree)])


def validate_knot_vector(knots: Tensor, degree: int, n_ctrl: int, axis: str = "") -> None:
    """Raise a NurbskitError that names the axis when ``knots`` cannot serve.

    Checks count against degree and control points, monotonicity, finiteness and a
    non-empty domain.
    """
    where = f"knot vector for {axis}" if axis else "knot vector"
    if knots.ndim != 1:
        raise NurbskitError(f"{where} must be one-dimensional, got shape {tuple(knots.shape)}")
    need = n_ctrl + degree + 1
    if knots.numel() != need:
        raise NurbskitError(
            f"{where} has {knots.numel()} knots; degree {degree} with {n_ctrl} control points needs {need}"
        )
    k = knots.detach().cpu().double().numpy()
    if not np.all(np.isfinite(k)):
        raise NurbskitError(f"{where} contains NaN or infinite values")
    drops = np.nonzero(np.diff(k) < 0)[0]
    if drops.size:
        i = int(drops[0])
        raise NurbskitError(f"{where} decreases at index {i + 1}: {k[i]!r} > {k[i + 1]!r}")
    if not k[degree] < k[n_ctrl]:
        raise NurbskitError(f"{where} has an empty domain [{k[degree]!r}, {k[n_ctrl]!r}]")


def find_spans(knots: Tensor, degree: int, n_ctrl: int, u: Tensor) -> Tensor:
    """Span index ``k`` with ``knots[k] <= u < knots[k+1]`` for every entry of ``u``.

    Shapes: ``knots (n_ctrl + degree + 1,)``, ``u (...)`` -> ``(...)`` int64.
    Values outside the domain take the first or last non-empty span (polynomial
    extrapolation); the domain end ``knots[n]`` belongs to the last non-empty span.
    The search runs on detached knots: the span is piecewise constant in the knots.
    """
    k = knots.detach()
    spans = torch.searchsorted(k, u.detach().contiguous(), right=True) - 1
    # The first and last non-empty spans of the domain: usually p and n - 1, but an
    # unclamped vector may repeat its end knots (knots[n - 1] == knots[n]), and then
    # span n - 1 is empty. Found by search, so no value is read back to the host.
    first = torch.searchsorted(k, k[degree : degree + 1], right=True) - 1
    last = torch.searchsorted(k, k[n_ctrl : n_ctrl + 1], right=False) - 1
    return torch.maximum(torch.minimum(spans, last), first)


def multiplicity(knots: Sequence[float] | Tensor, value: float, tol: float = 0.0) -> int:
    """How many times ``value`` occurs in ``knots`` (within ``tol``)."""
    k = torch.as_tensor(knots).detach().cpu().double()
    return int((k - value).abs().le(tol).sum())


def knots_to_logits(knots: Tensor, degree: int, n_ctrl: int) -> Tensor:
    """Unconstrained parameters for the interior knots of a clamped knot vector.

    The ``n_ctrl - degree`` gaps between consecutive distinct domain knots are kept
    positive and summing to the domain length through a softmax; ``logits_to_knots``
    inverts this map. Repeated interior knots become knots a hair apart (the gap
    ``floor``), so trained knots stay strictly ordered.
    """
    inner = knots[degree : n_ctrl + 1]
    gaps = (inner[1:] - inner[:-1]).clamp_min(1e-6 * float((inner[-1] - inner[0]).detach()))
    return torch.log(gaps / gaps.sum())


def logits_to_knots(logits: Tensor, degree: int, domain: tuple[float, float]) -> Tensor:
    """Clamped, strictly ordered knot vector from ``logits`` (see :func:`knots_to_logits`).

    Shapes: ``logits (n_ctrl - degree,)`` -> ``(n_ctrl + degree + 1,)``; differentiable.
    """
    a, b = domain
    gaps = torch.softmax(logits, dim=-1) * (b - a)
    inner = a + torch.cumsum(gaps, dim=-1)[:-1]
    start = logits.new_full((degree + 1,), a)
    end = logits.new_full((degree + 1,), b)
    return torch.cat([start, inner, end])

"""The shared body of NURBSCurve, NURBSSurface and NURBSVolume.

A spline object holds tensors and nothing else: ``control_points (n_1..n_k, dim)``,
``weights (n_1..n_k)``, ``knot_vectors`` (one 1-D tensor per direction) and
``degrees``. Any of the tensors may require gradients; every method is built from
differentiable tensor operations, so gradients reach control points, weights and
knots (exactly: the knot gradient is the derivative of the piecewise-rational basis).
dtype and device follow the control points.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np
import torch

from ..errors import NurbskitError
from . import tensor as _tp
from .knots import clamped_uniform, validate_knot_vector

Tensor = torch.Tensor
_AXES = ("u", "v", "w")


def _as_tensor(x, dtype=None, device=None) -> Tensor:
    if isinstance(x, Tensor):
        if dtype is not None and x.dtype != dtype or device is not None and x.device != torch.device(device):
            return x.to(dtype=dtype, device=device)
        return x
    return torch.as_tensor(np.asarray(x, dtype=np.float64), dtype=dtype, device=device)


class TensorSpline:
    """A rational tensor-product B-spline with ``para_dim`` parametric directions."""

    para_dim: int = 0
    kind: str = ""

    def __init__(
        self,
        control_points,
        degrees: Sequence[int],
        knot_vectors: Sequence | None = None,
        weights=None,
        *,
        validate: bool = True,
    ):
        k = self.para_dim
        cp = _as_tensor(control_points)
        if not cp.is_floating_point():
            cp = cp.to(torch.get_default_dtype())
        if validate and cp.ndim != k + 1:
            shape = ", ".join(f"n_{a}" for a in _AXES[:k])
            raise NurbskitError(
                f"{self.kind} control points must have shape ({shape}, dim), got {tuple(cp.shape)}"
            )
        dtype, device = cp.dtype, cp.device
        sizes = tuple(cp.shape[:k])
        degrees = tuple(int(d) for d in degrees)
        if validate:
            if len(degrees) != k:
                raise NurbskitError(f"{self.kind} needs {k} degree(s), got {len(degrees)}")
            for a, (p, n) in enumerate(zip(degrees, sizes)):
                if p < 1:
                    raise NurbskitError(f"degree in {_AXES[a]} must be >= 1, got {p}")
                if n < p + 1:
                    raise NurbskitError(
                        f"degree {p} in {_AXES[a]} needs at least {p + 1} control points, got {n}"
                    )
            if not torch.isfinite(cp.detach()).all():
                raise NurbskitError(f"{self.kind} control points contain NaN or infinite values")
        if knot_vectors is None:
            knot_vectors = [None] * k
        if validate and len(knot_vectors) != k:
            raise NurbskitError(f"{self.kind} needs {k} knot vector(s), got {len(knot_vectors)}")
        kvs = []
        for a, (kv, p, n) in enumerate(zip(knot_vectors, degrees, sizes)):
            kv = clamped_uniform(n, p, dtype=dtype, device=device) if kv is None else _as_tensor(kv, dtype, device)
            if validate:
                validate_knot_vector(kv, p, n, _AXES[a] if k > 1 else "")
            kvs.append(kv)
        if weights is None:
            w = torch.ones(sizes, dtype=dtype, device=device)
        else:
            w = _as_tensor(weights, dtype, device)
            if validate:
                if tuple(w.shape) != sizes:
                    raise NurbskitError(f"weights must have shape {sizes} to match the control points, got {tuple(w.shape)}")
                wd = w.detach()
                if not torch.isfinite(wd).all() or not (wd > 0).all():
                    bad = wd[~(wd > 0) | ~torch.isfinite(wd)].flatten()[0].item()
                    raise NurbskitError(f"weights must be positive and finite, found {bad!r}")
        self.control_points = cp
        self.weights = w
        self.knot_vectors = kvs
        self.degrees = degrees

    # ---- description -------------------------------------------------------------
    @property
    def dim(self) -> int:
        """Dimension of the control points (1 for scalar fields, 2 or 3 for geometry)."""
        return int(self.control_points.shape[-1])

    @property
    def sizes(self) -> tuple[int, ...]:
        """Number of control points along each parametric direction."""
        return tuple(self.control_points.shape[: self.para_dim])

    @property
    def dtype(self) -> torch.dtype:
        return self.control_points.dtype

    @property
    def device(self) -> torch.device:
        return self.control_points.device

    @property
    def domain(self) -> list[tuple[float, float]]:
        """``[(knots[p], knots[n]), ...]`` per direction, as Python floats."""
        return [
            (float(kv[p].detach()), float(kv[n].detach()))
            for kv, p, n in zip(self.knot_vectors, self.degrees, self.sizes)
        ]

    @property
    def is_rational(self) -> bool:
        w = self.weights.detach()
        return bool((w != w.flatten()[0]).any())

    def __repr__(self) -> str:
        return (
            f"{type(self).__name__}(sizes={self.sizes}, degrees={self.degrees}, dim={self.dim}, "
            f"rational={self.is_rational}, dtype={self.dtype}, device={self.device})"
        )

    # ---- construction helpers ------------------------------------------------------
    def _replace(self, **changes) -> "TensorSpline":
        """A new object of the same kind with some tensors replaced (no validation)."""
        args = dict(
            control_points=self.control_points,
            weights=self.weights,
            knot_vectors=list(self.knot_vectors),
            degrees=self.degrees,
        )
        args.update(changes)
        obj = type(self).__new__(type(self))
        TensorSpline.__init__(
            obj, args["control_points"], args["degrees"], args["knot_vectors"], args["weights"], validate=False
        )
        return obj

    def to(self, *args, **kwargs) -> "TensorSpline":
        """Move or cast every tensor, like ``Tensor.to`` (knot vectors and weights follow)."""
        return self._replace(
            control_points=self.control_points.to(*args, **kwargs),
            weights=self.weights.to(*args, **kwargs),
            knot_vectors=[kv.to(*args, **kwargs) for kv in self.knot_vectors],
        )

    def detach(self) -> "TensorSpline":
        return self._replace(
            control_points=self.control_points.detach(),
            weights=self.weights.detach(),
            knot_vectors=[kv.detach() for kv in self.knot_vectors],
        )

    def clone(self) -> "TensorSpline":
        return self._replace(
            control_points=self.control_points.clone(),
            weights=self.weights.clone(),
            knot_vectors=[kv.clone() for kv in self.knot_vectors],
        )

    # ---- evaluation ----------------------------------------------------------------
    def _params(self, params) -> Tensor:
        t = _as_tensor(params, self.dtype, self.device)
        if self.para_dim == 1:
            return t.unsqueeze(-1)
        if t.ndim < 2 or t.shape[-1] != self.para_dim:
            raise NurbskitError(
                f"{self.kind} parameters must have shape (..., M, {self.para_dim}), got {tuple(t.shape)}"
            )
        return t

    def evaluate(self, params) -> Tensor:
        """Points at parameters in the knot domain: ``(..., M[, k])`` -> ``(..., M, dim)``."""
        return _tp.evaluate(self.control_points, self.weights, self.knot_vectors, self.degrees, self._params(params))

    __call__ = evaluate

    def derivatives(self, params, order: int = 1) -> Tensor:
        """Partial derivatives up to ``order`` per direction (see the class docstring for shapes)."""
        if order < 0:
            raise NurbskitError(f"derivative order must be >= 0, got {order}")
        return _tp.derivatives(
            self.control_points, self.weights, self.knot_vectors, self.degrees, self._params(params), order
        )

    def grid_axes(self, resolution: int | Sequence[int]) -> list[Tensor]:
        """Uniformly spaced parameters over the domain, ends included, per direction."""
        if isinstance(resolution, int):
            resolution = (resolution,) * self.para_dim
        if len(resolution) != self.para_dim or min(resolution) < 1:
            raise NurbskitError(f"resolution must be {self.para_dim} positive integer(s), got {tuple(resolution)}")
        return [
            torch.linspace(a, b, int(r), dtype=self.dtype, device=self.device)
            for (a, b), r in zip(self.domain, resolution)
        ]

    def evaluate_grid(self, *axes, order: int = 0) -> Tensor:
        """Points on the tensor grid of the given 1-D parameter arrays, through basis matrices.

        ``evaluate_grid(u, v)`` -> ``(R, S, dim)``; with ``order > 0`` the derivative axes
        follow the grid axes, as in :meth:`derivatives`.
        """
        if len(axes) != self.para_dim:
            raise NurbskitError(f"{self.kind} evaluate_grid takes {self.para_dim} parameter arrays, got {len(axes)}")
        axes = [_as_tensor(a, self.dtype, self.device).reshape(-1) for a in axes]
        return _tp.evaluate_grid(self.control_points, self.weights, self.knot_vectors, self.degrees, axes, order)

    def sample(self, resolution: int | Sequence[int]) -> Tensor:
        """The object on a uniform parametric grid (the thesis's "parametric sampling")."""
        return self.evaluate_grid(*self.grid_axes(resolution))

    # ---- conversion ----------------------------------------------------------------
    def to_dict(self) -> dict:
        """The nurbskit JSON structure (see :mod:`nurbskit.core.serialize`)."""
        from .serialize import to_dict

        return to_dict(self)

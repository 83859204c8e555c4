"""The shared body of NURBSCurve, NURBSSurface and NURBSVolume.

A spline object holds tensors and nothing else: ``control_points (*B, n_1..n_k, dim)``,
``weights (*B, n_1..n_k)``, ``knot_vectors`` (one per direction, each ``(m_a,)`` shared
by the batch or ``(*B, m_a)`` per element) and ``degrees`` (one per direction, for the
whole batch). ``*B`` are batch axes: none for a single spline. Any of the tensors may
require gradients; every method is built from differentiable tensor operations, so
gradients reach control points, weights and knots (exactly: the knot gradient is the
derivative of the piecewise-rational basis), each batch element's from its own outputs.
dtype and device follow the control points.

Validation happens once, at construction (``validate=True``, the default): shapes,
finiteness, positive weights, knot vectors (knots closer than
:func:`~nurbskit.core.knots.knot_tolerance` merged into one). A validated object also
checks, in :meth:`TensorSpline.evaluate`, :meth:`~TensorSpline.derivatives` and
:meth:`~TensorSpline.evaluate_grid`, that parameters lie in the knot domain, and raises
an error naming the parameter, its value and the domain unless ``extrapolate=True``.
That check reads one boolean back to the host per call (one for all the axes of
:meth:`~TensorSpline.evaluate_grid`), which on a GPU waits for the device. Objects built
with ``validate=False`` (as a fitting loop builds them; what an object derives, a batch
element or a knot operation's result, keeps its setting) skip it, and then evaluation,
derivatives and sampling read nothing back to the host at all. :meth:`~TensorSpline.sample`
never checks: its grid lies in the domain by construction.
"""

from __future__ import annotations

import math
import operator
from typing import Sequence

import numpy as np
import torch

from ..errors import NurbskitError
from . import tensor as _tp
from .knots import clamped_uniform, merge_close_knots, validate_knot_vector

Tensor = torch.Tensor
_AXES = ("u", "v", "w")
#: Grids above this size are checked against the available memory before they are made
#: (one read of /proc/meminfo; smaller ones, a fit's and a network's, are never checked).
_CHECKED_GRID_BYTES = 1 << 28


def _order(order) -> int:
    """A derivative order: an integer >= 0."""
    if isinstance(order, bool) or not isinstance(order, (int, np.integer)) or order < 0:
        raise NurbskitError(f"derivative order must be an integer >= 0, got {order!r}")
    return int(order)


def _degrees(degrees, k: int, kind: str) -> tuple[int, ...]:
    """One integer degree per direction; a single integer serves every direction."""
    if not hasattr(degrees, "__iter__"):
        degrees = (degrees,) * k
    try:
        out = tuple(operator.index(d) for d in degrees)
    except TypeError:
        out = None
    if out is None or any(isinstance(d, bool) for d in degrees):
        if k == 1 and len(degrees) == 1:
            raise NurbskitError(f"{kind} degree must be an integer, got {degrees[0]!r}")
        raise NurbskitError(f"{kind} degrees must be {k} integers, got {degrees!r}")
    return out


def _as_tensor(x, dtype=None, device=None) -> Tensor:
    if isinstance(x, Tensor):
        if dtype is not None and x.dtype != dtype or device is not None and x.device != torch.device(device):
            return x.to(dtype=dtype, device=device)
        return x
    return torch.as_tensor(np.asarray(x, dtype=np.float64), dtype=dtype, device=device)


class TensorSpline:
    """A rational tensor-product B-spline with ``para_dim`` parametric directions, or a batch of them."""

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
        if validate and cp.ndim < k + 1:
            shape = ", ".join(f"n_{a}" for a in _AXES[:k])
            raise NurbskitError(
                f"{self.kind} control points must have shape ({shape}, dim) or (*batch, {shape}, dim), "
                f"got {tuple(cp.shape)}"
            )
        dtype, device = cp.dtype, cp.device
        batch = tuple(cp.shape[: cp.ndim - k - 1])
        sizes = tuple(cp.shape[cp.ndim - k - 1 : -1])
        degrees = _degrees(degrees, k, self.kind)
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
                axis = _AXES[a] if k > 1 else ""
                validate_knot_vector(kv, p, n, axis, batch)  # shapes first, then merge, then the domain
                kv = merge_close_knots(kv)
                validate_knot_vector(kv, p, n, axis, batch, multiplicity=False)
            kvs.append(kv)
        if weights is None:
            w = torch.ones(batch + sizes, dtype=dtype, device=device)
        else:
            w = _as_tensor(weights, dtype, device)
            if tuple(w.shape) == sizes and batch:  # shared by the batch: a view, validated or not
                w = w.expand(batch + sizes)
            if validate:
                if tuple(w.shape) != batch + sizes:
                    raise NurbskitError(
                        f"weights must have shape {batch + sizes} to match the control points, got {tuple(w.shape)}"
                    )
                wd = w.detach()
                if not torch.isfinite(wd).all() or not (wd > 0).all():
                    bad = wd[~(wd > 0) | ~torch.isfinite(wd)].flatten()[0].item()
                    raise NurbskitError(f"weights must be positive and finite, found {bad!r}")
        self.control_points = cp
        self.weights = w
        self.knot_vectors = kvs
        self.degrees = degrees
        self.validate = bool(validate)

    # ---- description -------------------------------------------------------------
    @property
    def batch_shape(self) -> tuple[int, ...]:
        """The batch axes ``*B`` (``()`` for a single spline)."""
        return tuple(self.control_points.shape[: self.control_points.ndim - self.para_dim - 1])

    @property
    def dim(self) -> int:
        """Dimension of the control points (1 for scalar fields, 2 or 3 for geometry)."""
        return int(self.control_points.shape[-1])

    @property
    def sizes(self) -> tuple[int, ...]:
        """Number of control points along each parametric direction."""
        nb = len(self.batch_shape)
        return tuple(self.control_points.shape[nb : nb + self.para_dim])

    @property
    def dtype(self) -> torch.dtype:
        return self.control_points.dtype

    @property
    def device(self) -> torch.device:
        return self.control_points.device

    @property
    def domain(self) -> list[tuple]:
        """``[(knots[p], knots[n]), ...]`` per direction: Python floats for a shared knot
        vector, tensors ``(*B,)`` for per-element knot vectors (reads the host)."""
        out = []
        for kv, p, n in zip(self.knot_vectors, self.degrees, self.sizes):
            k = kv.detach()
            out.append((float(k[p]), float(k[n])) if k.ndim == 1 else (k[..., p], k[..., n]))
        return out

    @property
    def is_rational(self) -> bool:
        w = self.weights.detach()
        return bool((w != w.flatten()[0]).any())

    def __repr__(self) -> str:
        batch = f"batch_shape={self.batch_shape}, " if self.batch_shape else ""
        return (
            f"{type(self).__name__}({batch}sizes={self.sizes}, degrees={self.degrees}, dim={self.dim}, "
            f"rational={self.is_rational}, dtype={self.dtype}, device={self.device})"
        )

    def __len__(self) -> int:
        if not self.batch_shape:
            raise TypeError(f"a single {self.kind} has no len(); only a batch does")
        return self.batch_shape[0]

    def __getitem__(self, index) -> "TensorSpline":
        """Batch elements: ``batch[i]`` is one spline (or a smaller batch), sharing storage."""
        if not self.batch_shape:
            raise NurbskitError(f"indexing selects batch elements, but this {self.kind} is not a batch")
        index = index if isinstance(index, tuple) else (index,)
        nb = len(self.batch_shape)
        if len(index) > nb or any(i is Ellipsis or i is None for i in index):
            raise NurbskitError(f"index {index!r} must select among the batch axes {self.batch_shape}")
        cp = self.control_points[index]
        return self._replace(
            control_points=cp,
            weights=self.weights[index],
            knot_vectors=[kv if kv.ndim == 1 else kv[index] for kv in self.knot_vectors],
        )

    def require_single(self, op: str) -> None:
        """Raise a one-line NurbskitError when this is a batch (for operations on one spline)."""
        if self.batch_shape:
            raise NurbskitError(
                f"{op} works on one {self.kind}, got a batch of shape {self.batch_shape}: "
                f"select an element first (batch[i])"
            )

    # ---- construction helpers ------------------------------------------------------
    def _replace(self, **changes) -> "TensorSpline":
        """A new object of the same kind with some tensors replaced, not validated again.

        It keeps this object's ``validate`` (the domain check on evaluation) unless
        ``validate`` is given: what a validated object derives (a batch element, the result
        of a knot operation) still refuses parameters outside its domain, and what a loop's
        unchecked object derives reads nothing back to the host."""
        validate = changes.pop("validate", self.validate)
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
        obj.validate = validate
        return obj

    def to(self, *args, **kwargs) -> "TensorSpline":
        """Move or cast every tensor, like ``Tensor.to`` (knot vectors and weights follow)."""
        return self._replace(
            control_points=self.control_points.to(*args, **kwargs),
            weights=self.weights.to(*args, **kwargs),
            knot_vectors=[kv.to(*args, **kwargs) for kv in self.knot_vectors],
            validate=self.validate,
        )

    def detach(self) -> "TensorSpline":
        return self._replace(
            control_points=self.control_points.detach(),
            weights=self.weights.detach(),
            knot_vectors=[kv.detach() for kv in self.knot_vectors],
            validate=self.validate,
        )

    def clone(self) -> "TensorSpline":
        return self._replace(
            control_points=self.control_points.clone(),
            weights=self.weights.clone(),
            knot_vectors=[kv.clone() for kv in self.knot_vectors],
            validate=self.validate,
        )

    # ---- evaluation ----------------------------------------------------------------
    def _params(self, params) -> Tensor:
        t = _as_tensor(params, self.dtype, self.device)
        if self.para_dim == 1:
            if t.ndim == 0:
                raise NurbskitError(f"curve parameters must have shape (..., M), got the single number {float(t)!r}: "
                                    f"pass [u]")
            t = t.unsqueeze(-1)
        elif t.ndim < 2 or t.shape[-1] != self.para_dim:
            raise NurbskitError(
                f"{self.kind} parameters must have shape (..., M, {self.para_dim}), got {tuple(t.shape)}"
            )
        try:
            np.broadcast_shapes(self.batch_shape, t.shape[:-2])
        except ValueError:
            raise NurbskitError(
                f"the parameters' batch shape {tuple(t.shape[:-2])} does not broadcast with the "
                f"{self.kind}'s {self.batch_shape}"
            ) from None
        return t

    def _check_domain(self, t: Tensor, extrapolate: bool, given=None) -> None:
        """Raise when a parameter ``t (..., M, k)`` lies outside the knot domain (one host
        read; see the module docstring)."""
        if extrapolate or not self.validate:
            return
        inside = self._inside(t, *self._bounds([given]))
        if not bool(inside.all()):
            self._raise_outside(t, inside)

    def _check_grid_domain(self, axes: Sequence[Tensor], extrapolate: bool, given: Sequence) -> None:
        """:meth:`_check_domain` of the axes ``(R,)`` or ``(*B, R)`` of a grid, with one host read for all."""
        if extrapolate or not self.validate:
            return
        lo, hi = self._bounds(given)
        inside = [self._inside(ax, lo, hi, a) for a, ax in enumerate(axes)]
        if bool(torch.stack([m.all() for m in inside]).all()):
            return
        for a, (ax, m) in enumerate(zip(axes, inside)):
            if not bool(m.all()):
                self._raise_outside(ax, m, a)

    def _bounds(self, given: Sequence) -> tuple[Tensor, Tensor]:
        """The domain's ends ``(k,)`` (or ``(*B, k)`` for per-element knots), widened by a
        slack of 8 units in the last place (in the coarser of the spline's dtype and that
        of the ``given`` parameters), which absorbs parameters computed or rounded in
        floating point."""
        kvs = [kv.detach() for kv in self.knot_vectors]
        lo = torch.stack(torch.broadcast_tensors(*[kv[..., p] for kv, p in zip(kvs, self.degrees)]), -1)
        hi = torch.stack(torch.broadcast_tensors(*[kv[..., n] for kv, n in zip(kvs, self.sizes)]), -1)
        eps = max([torch.finfo(lo.dtype).eps] + [torch.finfo(g.dtype).eps for g in given
                                                   if isinstance(g, Tensor) and g.is_floating_point()])
        slack = 8 * eps * torch.maximum(lo.abs(), hi.abs())
        return lo - slack, hi + slack

    def _inside(self, t: Tensor, lo: Tensor, hi: Tensor, grid_axis: int | None = None) -> Tensor:
        """Which parameters of ``t`` lie within the :meth:`_bounds` ``lo``, ``hi``, as a
        boolean tensor (nothing is read back to the host): ``t (..., M, k)``, or ``(..., R)``
        for one grid axis."""
        if grid_axis is not None:
            lo, hi = lo[..., grid_axis : grid_axis + 1], hi[..., grid_axis : grid_axis + 1]
        if lo.ndim > 1:  # per-element domains (*B, k): align with (*B, M, k)
            lo, hi = lo.unsqueeze(-2), hi.unsqueeze(-2)
        x = t.detach() if grid_axis is None else t.detach().unsqueeze(-1)
        return (x >= lo) & (x <= hi)

    def _raise_outside(self, t: Tensor, inside: Tensor, grid_axis: int | None = None) -> None:
        """The error for the first parameter of ``t`` outside the domain (``inside`` from :meth:`_inside`)."""
        axes = range(self.para_dim) if grid_axis is None else [grid_axis]
        x = t.detach() if grid_axis is None else t.detach().unsqueeze(-1)
        where = tuple(int(i) for i in (~inside).nonzero()[0])
        a = list(axes)[where[-1]]
        value = float(x.expand(inside.shape)[where])
        k = self.knot_vectors[a].detach()
        row = k if k.ndim == 1 else k[where[: k.ndim - 1]]
        dom = (float(row[self.degrees[a]]), float(row[self.sizes[a]]))
        name = f"parameter {_AXES[a]}" if self.para_dim > 1 else "parameter u"
        raise NurbskitError(
            f"{self.kind} {name} = {value!r} lies outside the domain [{dom[0]!r}, {dom[1]!r}] "
            f"(pass extrapolate=True to evaluate the polynomial continuation)"
        )

    def evaluate(self, params, *, extrapolate: bool = False) -> Tensor:
        """Points at parameters in the knot domain: ``(*P, M[, k])`` -> ``(*broadcast(B, P), M, dim)``.

        Outside the domain raises (on a validated object) unless ``extrapolate=True``, which
        evaluates the first or last span's polynomial.
        """
        t = self._params(params)
        self._check_domain(t, extrapolate, given=params)
        return _tp.evaluate(self.control_points, self.weights, self.knot_vectors, self.degrees, t)

    __call__ = evaluate

    def derivatives(self, params, order: int = 1, *, extrapolate: bool = False) -> Tensor:
        """Partial derivatives up to ``order`` per direction (see the class docstring for shapes)."""
        order = _order(order)
        t = self._params(params)
        self._check_domain(t, extrapolate, given=params)
        return _tp.derivatives(self.control_points, self.weights, self.knot_vectors, self.degrees, t, order)

    def _resolution(self, resolution, *, minimum: int = 1, op: str = "sample", values: int | None = None
                    ) -> tuple[int, ...]:
        """``R`` or ``(R_1, ..., R_k)`` as k integers ``>= minimum``; a grid whose ``values``
        numbers per point (default: the homogeneous point and the result) cannot fit in
        memory is refused before anything is allocated."""
        k = self.para_dim
        try:
            if isinstance(resolution, (Tensor, np.ndarray)) and resolution.ndim == 0 or not hasattr(resolution, "__iter__"):
                res = (operator.index(resolution),) * k
            else:
                res = tuple(operator.index(r) for r in resolution)
        except TypeError:
            res = ()
        if len(res) != k or min(res) < minimum:
            raise NurbskitError(f"{op}: resolution must be an int or {k} ints, each >= {minimum}, got {resolution!r}")
        points = math.prod(res) * math.prod(self.batch_shape)
        nbytes = points * (values or 2 * self.dim + 1) * self.control_points.element_size()
        if nbytes > _CHECKED_GRID_BYTES:
            from .._budget import require_memory

            require_memory(nbytes, f"{op} at resolution {res} ({points:,} points)", "choose a smaller resolution")
        return res

    def grid_axes(self, resolution: int | Sequence[int]) -> list[Tensor]:
        """Uniformly spaced parameters over the domain, ends included, per direction:
        ``(R_a,)``, or ``(*B, R_a)`` for a per-element knot vector. No host reads. The
        parameters are data (detached from trainable knots); :meth:`sample`'s grid follows
        the end knots, gradient included."""
        res = self._resolution(resolution)
        return [
            _tp.uniform_axis(kv.detach(), p, n, r)
            for kv, p, n, r in zip(self.knot_vectors, self.degrees, self.sizes, res)
        ]

    def evaluate_grid(self, *axes, order: int = 0, extrapolate: bool = False) -> Tensor:
        """Points on the tensor grid of the given parameter arrays, through basis matrices.

        ``evaluate_grid(u, v)`` -> ``(*B, R, S, dim)`` for axes ``(R,)``, ``(S,)`` (or per
        element ``(*B, R)``); with ``order > 0`` the derivative axes follow the grid axes,
        as in :meth:`derivatives`.
        """
        if len(axes) != self.para_dim:
            raise NurbskitError(f"{self.kind} evaluate_grid takes {self.para_dim} parameter arrays, got {len(axes)}")
        order = _order(order)
        given = axes
        axes = [_as_tensor(a, self.dtype, self.device) for a in axes]
        axes = [a.reshape(-1) if a.ndim <= 1 else a for a in axes]
        for a, ax in enumerate(axes):
            if ax.ndim > 1 and tuple(ax.shape[:-1]) != self.batch_shape:
                per = f" or, one row per batch element, {self.batch_shape + ('R',)}" if self.batch_shape else ""
                raise NurbskitError(f"{self.kind} evaluate_grid: the {_AXES[a]} axis must have shape (R,){per}, "
                                    f"got {tuple(ax.shape)}")
        self._check_grid_domain(axes, extrapolate, given)
        return _tp.evaluate_grid(self.control_points, self.weights, self.knot_vectors, self.degrees, axes, order)

    def sample(self, resolution: int | Sequence[int], order: int = 0) -> Tensor:
        """The object on a uniform parametric grid (the thesis's "parametric sampling").

        ``(*B, R_1, ..., R_k, dim)`` (with ``order > 0`` the derivative axes follow, as in
        :meth:`evaluate_grid`). The grid is :meth:`grid_axes`; with fixed knots the basis
        matrices are cached, so repeated calls (a fit) cost a few GEMMs and no host reads.
        """
        order = _order(order)
        values = (order + 1) ** self.para_dim * (self.dim + 1) + self.dim
        return _tp.sample(self.control_points, self.weights, self.knot_vectors, self.degrees,
                          self._resolution(resolution, values=values), order)

    # ---- conversion ----------------------------------------------------------------
    def to_dict(self) -> dict:
        """The nurbskit JSON structure (see :mod:`nurbskit.core.serialize`); one spline only."""
        from .serialize import to_dict

        self.require_single("to_dict")
        return to_dict(self)

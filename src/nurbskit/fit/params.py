"""The trainable parametrisation of a NURBS surface.

:class:`SurfaceParameters` holds what an optimiser updates and builds a
:class:`~nurbskit.core.NURBSSurface` from it on every call (cheap: built with
``validate=False``):

* control points as a free tensor; a surface *closed in v* stores only the
  ``n_v - q`` distinct columns and wraps the first ``q`` onto the end, with uniform
  unclamped knots along v, so the seam stays closed (and C^{q-1}) whatever the
  optimiser does;
* weights through their logarithm (always positive);
* interior knots through softmax gaps (always ordered, ends fixed), see
  :func:`nurbskit.core.knots.knots_to_logits`.

Convention: control points ``(n_u, n_v, dim)`` with u on the first axis, as in the core.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from ..core import NURBSSurface
from ..core.knots import clamped_uniform, knots_to_logits, logits_to_knots

Tensor = torch.Tensor


def periodic_knots(n_ctrl: int, degree: int, *, dtype=None, device=None) -> Tensor:
    """Uniform unclamped knots whose domain ``[knots[p], knots[n]]`` is ``[0, 1]``.

    With the last ``degree`` control points equal to the first ``degree`` the curve is
    closed with C^{degree-1} continuity at the seam. The ``degree`` knots beyond each end
    of the domain are the knots one period (1) away, computed as OpenCASCADE computes a
    periodic spline's (``t[i] = t[i + n - p] - 1``, ``t[n + 1 + j] = t[p + 1 + j] + 1``, in
    the knots' dtype): ``(i - p) / s`` can differ from them in the last place, and
    :mod:`nurbskit.io.cad` writes a spline as periodic (closed, with a seam edge) only when
    its knots are periodic.

    Example:
        >>> periodic_knots(6, 2).tolist()
        [-0.5, -0.25, 0.0, 0.25, 0.5, 0.75, 1.0, 1.25, 1.5]
    """
    p, n = degree, n_ctrl
    s = n - p  # spans in the domain, and the shift between a knot and its periodic copy
    inner = torch.arange(s + 1, dtype=dtype or torch.get_default_dtype(), device=device) / s
    t = [None] * p + list(inner.unbind()) + [None] * p
    for j in range(p):  # each wrapped knot from one already known (also when s < p)
        t[n + 1 + j] = t[p + 1 + j] + 1.0
    for i in reversed(range(p)):
        t[i] = t[i + s] - 1.0
    return torch.stack(t)


def wrap_columns(free: Tensor, degree: int) -> Tensor:
    """``(n_u, m, ...)`` distinct columns -> ``(n_u, m + degree, ...)`` with the seam closed."""
    return torch.cat([free, free[:, :degree]], dim=1)


@dataclass(frozen=True)
class Topology:
    """How the control net is tied together.

    ``closed_v``: the last ``q`` columns repeat the first ``q`` (periodic seam);
    ``pole_start`` / ``pole_end``: the first / last row is one point (a closed end, like
    the poles of a sphere or the duck's tail and beak).
    """

    closed_v: bool = False
    pole_start: bool = False
    pole_end: bool = False

    def index(self, n_u: int, n_v: int, q: int, device=None) -> tuple[Tensor, int]:
        """``(n_u * n_v,)`` index of each control point's free unknown, and the unknown count.

        Control point ``(i, j)`` (u-major) equals free unknown ``index[i * n_v + j]``.
        """
        m = n_v - q if self.closed_v else n_v
        canon = {}
        index = []
        for i in range(n_u):
            for j in range(n_v):
                jj = j % m
                if (i == 0 and self.pole_start) or (i == n_u - 1 and self.pole_end):
                    jj = 0
                key = (i, jj)
                if key not in canon:
                    canon[key] = len(canon)
                index.append(canon[key])
        return torch.tensor(index, dtype=torch.int64, device=device), len(canon)

    def as_dict(self) -> dict:
        return {"closed_v": self.closed_v, "pole_start": self.pole_start, "pole_end": self.pole_end}


def expand(free: Tensor, index: Tensor, n_u: int, n_v: int) -> Tensor:
    """Free unknowns ``(k, ...)`` -> the full net ``(n_u, n_v, ...)`` through ``index``."""
    return free[index].reshape((n_u, n_v) + tuple(free.shape[1:]))


def reduce(full: Tensor, index: Tensor, k: int) -> Tensor:
    """The full net ``(n_u, n_v, ...)`` -> free unknowns ``(k, ...)``, averaging tied entries."""
    flat = full.reshape((-1,) + tuple(full.shape[2:]))
    out = flat.new_zeros((k,) + tuple(flat.shape[1:])).index_add(0, index, flat)
    count = flat.new_zeros(k).index_add(0, index, flat.new_ones(flat.shape[0]))
    return out / count.reshape((k,) + (1,) * (flat.ndim - 1))


class SurfaceParameters(torch.nn.Module):
    """Trainable control points, log-weights and knot logits of one surface.

    Args:
        surface: the starting surface; its net must already respect ``topology``
            (periodic seam, collapsed pole rows).
        topology: how the net is tied (:class:`Topology`); a bool means ``closed_v``.
        train_control_points, train_weights, train_knots: which tensors require grad.

    Example:
        >>> import torch
        >>> from nurbskit.core import NURBSSurface
        >>> params = SurfaceParameters(NURBSSurface(torch.rand(5, 6, 3)), train_knots=True)
        >>> params().evaluate_grid(torch.linspace(0, 1, 4), torch.linspace(0, 1, 4)).shape
        torch.Size([4, 4, 3])
    """

    def __init__(
        self,
        surface: NURBSSurface,
        topology: "Topology | bool" = False,
        *,
        train_control_points: bool = True,
        train_weights: bool = False,
        train_knots: bool = False,
    ):
        super().__init__()
        if isinstance(topology, bool):
            topology = Topology(closed_v=topology)
        self.topology = topology
        p, q = surface.degrees
        self.degrees = (p, q)
        self.closed_v = topology.closed_v
        self.n_u, self.n_v = surface.sizes
        index, k = topology.index(self.n_u, self.n_v, q, device=surface.device)
        self.register_buffer("index", index)
        self.n_free = k
        cp = reduce(surface.control_points.detach(), index, k)
        w = reduce(surface.weights.detach(), index, k)
        self.control_points = torch.nn.Parameter(cp.clone(memory_format=torch.contiguous_format))
        self.log_weights = torch.nn.Parameter(torch.log(w).clone(memory_format=torch.contiguous_format))
        ku, kv = (kk.detach() for kk in surface.knot_vectors)
        self.domains = [surface.domain[0], surface.domain[1]]
        self.knot_logits_u = torch.nn.Parameter(knots_to_logits(ku, p, self.n_u).clone())
        self.register_buffer("fixed_knots_u", ku.clone())
        self.knot_logits_v = torch.nn.Parameter(knots_to_logits(kv, q, self.n_v).clone())
        self.register_buffer("fixed_knots_v", kv.clone())
        self.set_trainable(train_control_points, train_weights, train_knots)

    def set_trainable(self, control_points: bool, weights: bool, knots: bool) -> None:
        """Choose which tensors train; knots along a closed v stay uniform."""
        self.control_points.requires_grad_(control_points)
        self.log_weights.requires_grad_(weights)
        self.knot_logits_u.requires_grad_(knots)
        self.knot_logits_v.requires_grad_(knots and not self.closed_v)
        self.train_knots = knots

    def knot_vectors(self) -> list[Tensor]:
        p, q = self.degrees
        if self.knot_logits_u.requires_grad:
            ku = logits_to_knots(self.knot_logits_u, p, self.domains[0])
        else:
            ku = self.fixed_knots_u
        if self.knot_logits_v.requires_grad:
            kv = logits_to_knots(self.knot_logits_v, q, self.domains[1])
        else:
            kv = self.fixed_knots_v
        return [ku, kv]

    def freeze_knots(self) -> None:
        """Store the current trained knots as the fixed ones (call after a knot stage)."""
        with torch.no_grad():
            ku, kv = self.knot_vectors()
            self.fixed_knots_u.copy_(ku)
            self.fixed_knots_v.copy_(kv)

    def full_control_points(self) -> Tensor:
        return expand(self.control_points, self.index, self.n_u, self.n_v)

    def full_weights(self) -> Tensor:
        return expand(torch.exp(self.log_weights), self.index, self.n_u, self.n_v)

    def forward(self) -> NURBSSurface:
        """The current surface (differentiable in every trainable tensor)."""
        return NURBSSurface(
            self.full_control_points(), self.degrees, self.knot_vectors(), self.full_weights(), validate=False
        )

    def load_control_points(self, control_points: Tensor) -> None:
        """Replace the control points from a full ``(n_u, n_v, dim)`` net."""
        with torch.no_grad():
            self.control_points.copy_(reduce(control_points, self.index, self.n_free))

    def surface(self) -> NURBSSurface:
        """A detached, validated copy of the current surface."""
        s = self.forward()
        return NURBSSurface(
            s.control_points.detach().clone(),
            s.degrees,
            [k.detach().clone() for k in s.knot_vectors],
            s.weights.detach().clone(),
        )

    def trainable(self) -> list[Tensor]:
        return [t for t in self.parameters() if t.requires_grad]


def new_surface(control_points: Tensor, degrees, closed_v: bool, knot_vectors=None, weights=None) -> NURBSSurface:
    """A surface with clamped uniform knots in u and, closed in v, periodic knots in v."""
    n_u, n_v = control_points.shape[:2]
    p, q = degrees
    dt, dev = control_points.dtype, control_points.device
    if knot_vectors is None:
        ku = clamped_uniform(n_u, p, dtype=dt, device=dev)
        kv = periodic_knots(n_v, q, dtype=dt, device=dev) if closed_v else clamped_uniform(n_v, q, dtype=dt, device=dev)
        knot_vectors = [ku, kv]
    return NURBSSurface(control_points, (p, q), knot_vectors, weights)

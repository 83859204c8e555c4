"""Tensor-product rational B-splines of any parametric dimension: one mechanism for
curves (k = 1), surfaces (k = 2) and volumes (k = 3), for one spline or a batch.

Convention: control points ``(*B, n_1, ..., n_k, dim)`` with the first parametric
direction on the first grid axis after the batch axes ``*B`` (none for one spline);
weights ``(*B, n_1, ..., n_k)``; knot vectors one per direction, each shared ``(m_a,)``
or one per batch element ``(*B, m_a)``; one degree per direction for the whole batch.
Parameters ``(*P, M, k)`` broadcast against the batch: ``(M, k)`` is shared by every
element, ``(*B, M, k)`` is one set per element, and for a single spline any leading
axes are kept (``(..., M, k) -> (..., M, dim)``). Internally the evaluation works on
homogeneous points ``(w * P, w)`` and divides once at the end.

Two ways in:

* scattered parameters: spans by ``searchsorted``, the ``p + 1`` non-zero basis values
  per direction, a gather of the local control block and one contraction (cost
  ``M * prod(p_a + 1)``);
* grids: dense basis matrices ``B_a (R_a, n_a)`` and ``k`` matrix products, which is
  what BLAS and GPUs are built for. A surface (order 0, knots shared by the batch) is
  one autograd node, :class:`_SurfaceGrid`: the homogeneous net laid out in channel rows
  ``(n_u, D, n_v)``, two GEMMs, a division of whole rows in place, the result a
  channel-last view; its backward is two more GEMMs and two passes over the grid, plus
  two GEMMs for the basis matrices when knots or parameters train. Other grids apply
  the last direction as one product with ``B_k^T kron I_D`` on the channel-last net.

Basis cache: when neither the knots nor the parameters need gradients, the basis (the
matrices of a grid, the spans and values of scattered parameters) is kept in a small
LRU cache keyed on the identity, ``_version`` counter and storage of the knot and
parameter tensors (see :class:`BasisCache`); a fit with fixed knots then pays only for
the products. Any in-place change to a key tensor bumps its version, so a stale basis is
never served; a tensor that needs gradients is never cached.

Nothing on these paths reads a value back to the host (no ``.item()``, no Python ``if``
on a tensor, no boolean-mask indexing): on a GPU they never wait for the device.

Derivatives of the rational map use the generalised quotient rule
(The NURBS Book, eq. 4.8 / A4.4 for surfaces): for a multi-index ``alpha``,
``S^(alpha) = (A^(alpha) - sum_{0 != beta <= alpha} C(alpha, beta) w^(beta) S^(alpha - beta)) / w``.
The weight's derivatives ``w^(beta)`` come from one more channel, ``w - w_ref`` (``w_ref``
the first weight, detached: the same function of the weights, so the same gradient),
and ``w`` itself from the weight channel as :func:`evaluate` contracts it (the point of a
derivative table is the evaluated point, bit for bit). The basis derivatives sum to zero
only up to rounding: contracted with the weights as they are, a polynomial spline's
``w^(beta)`` were ``1e-11`` of ``|A^(beta)|`` instead of 0, and a degree-7 curve's 8th
derivative came out 0.07 instead of 0. Shifted, equal weights give ``w^(beta) = 0``
exactly and the quotient rule reduces to ``A^(alpha) / w``.
"""

from __future__ import annotations

import itertools
import math
import weakref
from collections import OrderedDict
from math import comb
from typing import Callable, Sequence

import numpy as np
import torch

from .basis import (basis_function_derivatives, basis_functions, basis_matrices, basis_matrix, knot_window,
                    window_basis_derivatives)
from .knots import find_spans, span_bounds

Tensor = torch.Tensor

# Channels up to which the last direction is applied through B^T kron I_D (one GEMM on
# the channel-last net); wider nets (scalar fields with many channels) use a batched product.
_KRON_MAX_CHANNELS = 8


# ---- the basis cache ----------------------------------------------------------------------

class BasisCache:
    """An LRU cache of basis tensors keyed on the tensors they were built from.

    A key tensor is identified by its ``id``, storage pointer, ``_version`` (bumped by
    every in-place change), shape, strides and offset, and checked through a weak
    reference on every hit, so a freed tensor whose ``id`` is reused never matches; the
    entry dies with its key tensor. Tensors that require gradients (or inference-mode
    tensors, which have no version counter) are never cached: the basis is then built
    afresh, differentiably. Bounded by ``max_entries`` and ``max_bytes``.

    Writes that bypass the version counter are not seen: through ``.data``
    (``knots.data[4] = 0.3``) or through a NumPy array sharing the tensor's memory
    (``knots.numpy()[4] = 0.3``). After such a write call :meth:`clear` (or write through
    the tensor itself, ``knots[4] = 0.3``, which bumps ``_version``).
    """

    def __init__(self, max_entries: int = 256, max_bytes: int = 512 << 20):
        self.max_entries = max_entries
        self.max_bytes = max_bytes
        self._entries: OrderedDict = OrderedDict()
        self._bytes = 0
        self.hits = 0
        self.misses = 0
        self.enabled = True

    @staticmethod
    def _identity(t: Tensor):
        if t.requires_grad or t.is_inference():
            return None
        base = t if t._base is None else t._base  # a view made per call keys on its base
        try:
            return base, (id(base), base.data_ptr(), base._version, tuple(t.shape), t.stride(), t.storage_offset())
        except (RuntimeError, NotImplementedError):  # functorch wrappers and other tensor subclasses
            return None

    def get(self, tensors: Sequence[Tensor], extra: tuple, build: Callable[[], object]):
        """``build()``, or its cached value for these ``tensors`` and ``extra`` key."""
        if not self.enabled:
            return build()
        ids, bases = [], []
        for t in tensors:
            found = self._identity(t)
            if found is None:
                return build()
            bases.append(found[0])
            ids.append(found[1])
        tensors = bases
        key = (tuple(ids), extra)
        entry = self._entries.get(key)
        if entry is not None and all(r() is t for r, t in zip(entry[0], tensors)):
            self._entries.move_to_end(key)
            self.hits += 1
            return entry[1]
        self.misses += 1
        with torch.no_grad():
            value = build()
        size = sum(v.numel() * v.element_size() for v in _tensors_in(value))
        if size > self.max_bytes:
            return value

        def forget(_, key=key):
            e = self._entries.get(key)
            if e is not None and e[0] is refs:
                self._pop(key)

        refs = tuple(weakref.ref(t, forget) for t in tensors)
        if key in self._entries:
            self._pop(key)
        self._entries[key] = (refs, value, size)
        self._bytes += size
        while len(self._entries) > self.max_entries or self._bytes > self.max_bytes:
            self._pop(next(iter(self._entries)))
        return value

    def _pop(self, key) -> None:
        entry = self._entries.pop(key, None)
        if entry is not None:
            self._bytes -= entry[2]

    def clear(self) -> None:
        self._entries.clear()
        self._bytes = 0
        self.hits = self.misses = 0

    def __len__(self) -> int:
        return len(self._entries)


def _tensors_in(value):
    """The tensors in ``value``: a tensor, or tuples, lists and dicts of them."""
    if isinstance(value, Tensor):
        yield value
    elif isinstance(value, (tuple, list)):
        for v in value:
            yield from _tensors_in(v)
    elif isinstance(value, dict):
        for v in value.values():
            yield from _tensors_in(v)


basis_cache = BasisCache()
"""The process-wide cache used by :func:`evaluate`, :func:`derivatives`, :func:`evaluate_grid` and :func:`sample`."""



# ---- homogeneous points and batch plumbing -------------------------------------------------

def homogeneous(control_points: Tensor, weights: Tensor, shift: Tensor | None = None) -> Tensor:
    """``(w * P, w)``: shapes ``(..., dim)``, ``(...)`` -> ``(..., dim + 1)``; with ``shift``
    (:func:`weight_shift`) ``(w * P, w, w - shift)``, ``(..., dim + 2)``, for derivatives
    (see the module's note on them)."""
    w = weights.unsqueeze(-1)
    return torch.cat([control_points * w, w] if shift is None else [control_points * w, w, w - shift], dim=-1)


def weight_shift(weights: Tensor) -> Tensor:
    """The first weight, detached, as a 0-d view (no host read, no copy of an expanded
    tensor): what :func:`homogeneous` subtracts from the weights in the channel it
    contracts as the channel of the weight's derivatives (see the module's note on derivatives)."""
    return weights.detach()[(0,) * weights.ndim]


def batch_shape(control_points: Tensor, k: int) -> tuple[int, ...]:
    """The batch axes ``*B`` of control points ``(*B, n_1..n_k, dim)``."""
    return tuple(control_points.shape[: control_points.ndim - k - 1])


def _per_element(knot_vectors: Sequence[Tensor]) -> bool:
    return any(kv.ndim > 1 for kv in knot_vectors)


# ---- scattered parameters --------------------------------------------------------------------

def _gather_blocks(Pw: Tensor, spans: Sequence[Tensor], degrees: Sequence[int], element: Tensor | None = None) -> Tensor:
    """Local control blocks ``(M, p_1 + 1, ..., p_k + 1, D)`` for each point.

    ``Pw (..., n_1..n_k, D)``; ``spans[a] (M,)``; ``element (M,)`` (optional) names each
    point's element of the flattened leading (batch) axes. Where there are at least as
    many points as blocks, every block of ``p_a + 1`` consecutive control points per
    direction is first laid out as one row of a table (``unfold``), and each point takes
    one row: on an H100 taking 16 rows of 4 values for each of 10^6 points (the gather
    of a bicubic block) took 9.8 ms, at 26 GB/s, and one row of 64 values is a plain
    copy; on a CPU it is 3 to 8 times faster too. Otherwise (few points on a large net,
    where the table would cost more than the gather) one ``index_select`` of the rows of
    the blocks (advanced indexing with k index tensors is far slower on CPU).
    """
    k = len(degrees)
    sizes = Pw.shape[-k - 1 : -1]
    D = Pw.shape[-1]
    M = spans[0].shape[0]
    lead = math.prod(Pw.shape[: -k - 1])
    counts = [n - p for n, p in zip(sizes, degrees)]  # blocks per direction
    if M >= lead * math.prod(counts):
        table = Pw.reshape((lead, *sizes, D))
        for a in range(k):  # (lead, c_1..c_k, D, p_1 + 1..p_k + 1)
            table = table.unfold(1 + a, degrees[a] + 1, 1)
        table = table.movedim(1 + k, -1).reshape(lead * math.prod(counts), -1)
        row, stride = None, 1
        for a in reversed(range(k)):
            term = (spans[a] - degrees[a]) * stride
            row = term if row is None else row + term
            stride *= counts[a]
        if element is not None:
            row = row + element * stride
        return table.index_select(0, row).reshape((M, *(p + 1 for p in degrees), D))
    flat = None
    stride = 1
    for a in reversed(range(k)):
        idx = spans[a].unsqueeze(-1) - degrees[a] + torch.arange(degrees[a] + 1, device=spans[a].device)
        shape = list(idx.shape[:-1]) + [1] * k
        shape[idx.ndim - 1 + a] = degrees[a] + 1
        term = idx.reshape(shape) * stride
        flat = term if flat is None else flat + term
        stride *= sizes[a]
    if element is not None:
        flat = flat + (element * stride).reshape(element.shape + (1,) * k)
    rows = Pw.reshape(-1, D).index_select(0, flat.reshape(-1))
    return rows.reshape(flat.shape + (D,))


def _contract(block: Tensor, bases: Sequence[Tensor]) -> Tensor:
    """Contract local blocks with per-direction basis values, one direction at a time.

    Shapes: ``block (M, s_1, ..., s_k, D)``, ``bases[a] (M, o + 1, s_a)`` ->
    ``(M, o + 1, ..., o + 1, D)``. On a CPU each step is one batched matrix product
    ``(M, 1, o + 1, s_a) @ (M, O, s_a, rest)``; on these tiny per-point blocks that beats
    both a many-operand ``einsum`` and broadcast multiply-and-sum. On a GPU a batched
    GEMM of 10^6 such products is slow (cuBLAS splits it into launches of 65,535 tiny
    matrices: a bicubic surface's second derivatives took 8.3 ms on an H100), and the
    same sums as ``s_a`` fused multiply-adds over the whole batch take 1.6 ms.
    """
    M = block.shape[0]
    orders = [B.shape[-2] for B in bases]
    X = block
    done = 1  # product of the order axes produced so far
    for a, B in enumerate(bases):
        s_a = B.shape[-1]
        rest = math.prod(block.shape[a + 2 :])  # explicit: M may be 0
        X = X.reshape(M, done, s_a, rest)
        if X.device.type == "cpu":
            X = torch.matmul(B.unsqueeze(1), X)  # (M, done, o + 1, rest)
        else:
            out = B[:, None, :, 0, None] * X[:, :, None, 0]
            for j in range(1, s_a):
                out = out.addcmul(B[:, None, :, j, None], X[:, :, None, j])
            X = out
        done *= B.shape[-2]
    return X.reshape((M, *orders, block.shape[-1]))


def _bounds(kv: Tensor, p: int, n: int) -> tuple[Tensor, Tensor]:
    """:func:`~nurbskit.core.knots.span_bounds`, cached with the knots (an iterative solver
    evaluates at new parameters every step, on the same knots)."""
    return basis_cache.get([kv], ("span bounds", p, n), lambda: span_bounds(kv, p, n))


def _span_basis(kv: Tensor, p: int, n: int, u: Tensor, order: int | None) -> tuple[Tensor, Tensor]:
    """Spans ``(...)`` and basis values ``(..., o + 1, p + 1)`` at ``u`` (``o = 0`` for ``order`` None)."""
    s = find_spans(kv, p, n, u, _bounds(kv, p, n))
    if order is None:
        return s, basis_functions(kv, p, s, u).unsqueeze(-2)
    return s, basis_function_derivatives(kv, p, s, u, order)


def _scattered_basis(knot_vectors: Sequence[Tensor], degrees: Sequence[int], sizes: Sequence[int], flat: Tensor,
                     order: int | None) -> list[tuple[Tensor, Tensor]]:
    """Spans ``(M,)`` and basis values ``(M, o + 1, p + 1)`` per direction at ``flat (M, k)``, shared knots."""
    k = len(degrees)
    if k == 1 or len(set(degrees)) > 1:
        return [_span_basis(knot_vectors[a], degrees[a], sizes[a], flat[:, a], order) for a in range(k)]
    # One degree: the directions' knot windows stacked, one pass of the recurrence.
    p = degrees[0]
    spans = [find_spans(knot_vectors[a], p, sizes[a], flat[:, a], _bounds(knot_vectors[a], p, sizes[a]))
             for a in range(k)]
    K = torch.stack([knot_window(knot_vectors[a], p, spans[a]) for a in range(k)])  # (k, M, 2p)
    bases = window_basis_derivatives(K, p, flat.t(), order or 0).unbind(0)
    return list(zip(spans, bases))


def _element_basis(kv: Tensor, p: int, n: int, u: Tensor, element: Tensor, order: int | None) -> tuple[Tensor, Tensor]:
    """:func:`_span_basis` of points ``u (M,)`` on the elements ``element (M,)`` of a batch
    whose knots are ``kv (Bt, m)`` (one vector per element): each point reads its own
    element's knots (span bounds cached with ``kv``)."""
    first, last = _bounds(kv, p, n)  # (Bt, 1) each
    kp = kv.index_select(0, element)  # (M, m)
    u = u.unsqueeze(-1)
    s = find_spans(kp, p, n, u, (first.index_select(0, element), last.index_select(0, element)))
    if order is None:
        b = basis_functions(kp, p, s, u)  # (M, 1, p + 1): the one value row
    else:
        b = basis_function_derivatives(kp, p, s, u, order)[:, 0]
    return s[:, 0], b


def _local(Pw: Tensor, knot_vectors: Sequence[Tensor], degrees: Sequence[int], params: Tensor, order: int | None,
           element: Tensor | None = None) -> Tensor:
    """Homogeneous values (``order`` None) or derivatives at ``params (*P, M, k)``.

    ``Pw (*B, n_1..n_k, D)`` -> ``(*broadcast(B, P), M, [o + 1, ... (k times),] D)``.
    With ``element (M,)``: ``Pw (Bt, n_1..n_k, D)`` is a flat batch, ``params (M, k)``
    and point ``i`` lies on element ``element[i]`` (knots shared ``(m,)`` or
    ``(Bt, m)``) -> ``(M, [o + 1, ...,] D)``: the points of many elements in one call,
    however they are spread over the batch (a projection's Newton iterations).
    """
    k = len(degrees)
    B = batch_shape(Pw, k)
    sizes = tuple(Pw.shape[len(B) : len(B) + k])
    D = Pw.shape[-1]
    P, M = tuple(params.shape[:-2]), params.shape[-2]
    per_element = _per_element(knot_vectors)
    extra = ("scattered", tuple(degrees), sizes, order, B)
    if element is not None:
        if per_element:
            found = [_element_basis(kv, degrees[a], sizes[a], params[:, a], element, order)
                     if kv.ndim > 1 else _span_basis(kv, degrees[a], sizes[a], params[:, a], order)
                     for a, kv in enumerate(knot_vectors)]
        else:
            found = _scattered_basis(knot_vectors, degrees, sizes, params, order)
        h = _contract(_gather_blocks(Pw, [s for s, _ in found], degrees, element), [b for _, b in found])
    elif not per_element and (not B or not P):
        # One set of parameters for every element: the basis is computed once, and the
        # batch rides along as extra channels of one contraction.
        flat = params.reshape(-1, k)
        found = basis_cache.get([params, *knot_vectors], extra,
                                lambda: _scattered_basis(knot_vectors, degrees, sizes, flat, order))
        spans = [s for s, _ in found]
        bases = [b for _, b in found]
        if B:
            Bt = math.prod(B)
            folded = Pw.reshape((Bt,) + sizes + (D,)).movedim(0, -2).reshape(sizes + (Bt * D,))
            h = _contract(_gather_blocks(folded, spans, degrees), bases)  # (M, o.., Bt * D)
            h = h.reshape(h.shape[:-1] + (Bt, D)).movedim(-2, 0)
            h = h.reshape(B + (M,) + h.shape[2:])
        else:
            h = _contract(_gather_blocks(Pw, spans, degrees), bases)
            h = h.reshape(P + (M,) + h.shape[1:])
    else:
        Bout = np.broadcast_shapes(B, P)  # torch's imports sympy on first use (0.3 s)
        Bt = math.prod(Bout)
        prm = params.expand(Bout + (M, k)).reshape(Bt, M, k)
        kvs = [kv if kv.ndim == 1 else kv.expand(Bout + kv.shape[-1:]).reshape(Bt, -1) for kv in knot_vectors]

        def build():
            out = []
            for a in range(k):
                u = prm[..., a]  # (Bt, M)
                s, b = _span_basis(kvs[a], degrees[a], sizes[a], u if kvs[a].ndim > 1 else u.reshape(-1), order)
                out.append((s.reshape(-1), b.reshape((Bt * M,) + b.shape[-2:])))
            return out

        found = basis_cache.get([params, *knot_vectors], extra + (Bout,), build)
        spans = [s for s, _ in found]
        bases = [b for _, b in found]
        element = torch.arange(math.prod(B), device=Pw.device).reshape(B).expand(Bout).reshape(Bt, 1)
        h = _contract(_gather_blocks(Pw, spans, degrees, element.expand(Bt, M).reshape(-1)), bases)
        h = h.reshape(Bout + (M,) + h.shape[1:])
    if order is None:
        h = h.reshape(h.shape[: -1 - k] + h.shape[-1:])
    return h


def homogeneous_derivatives_to_points(hders: Tensor, k: int, shifted: bool = False) -> Tensor:
    """Quotient rule on homogeneous derivatives.

    Shapes: ``hders (..., o + 1, ... (k times), D)`` holding derivatives of ``(w P, w)``
    -> ``(..., o + 1, ..., D - 1)`` derivatives of ``P``; ``shifted``: of ``(w P, w, w -
    shift)`` (:func:`homogeneous` with a shift) -> ``(..., D - 2)``, the weight's derivatives
    taken from the last channel and the weight itself from the one before.

    Each term ``C(alpha, beta) w^(beta) S^(alpha - beta)`` is one fused ``addcmul`` on
    views from one ``unbind``: a surface's first derivatives cost 16 operations, its
    second 43 (one ``select``, ``mul``, ``mul`` and ``sub`` per term before: 43 and 168).
    """
    order = hders.shape[-2] - 1
    D = hders.shape[-1]
    lead = hders.shape[: hders.ndim - k - 1]
    alphas = list(itertools.product(range(order + 1), repeat=k))  # the flat order of the output
    index = {alpha: i for i, alpha in enumerate(alphas)}
    flat = hders.reshape(lead + (len(alphas), D))
    A = flat[..., : D - 1 - shifted].unbind(-2)
    w = flat[..., -1:].unbind(-2)
    w0 = flat[..., 0, D - 1 - shifted : D - shifted]  # the weight, as evaluate() contracts it
    S: list[Tensor] = []
    for alpha in alphas:
        value = A[index[alpha]]
        for beta in itertools.product(*(range(a + 1) for a in alpha)):
            if any(beta):
                coef = math.prod(comb(a, b) for a, b in zip(alpha, beta))
                rest = tuple(a - b for a, b in zip(alpha, beta))
                value = torch.addcmul(value, w[index[beta]], S[index[rest]], value=-coef)
        S.append(value / w0)
    return torch.stack(S, dim=-2).reshape(lead + (order + 1,) * k + (D - 1 - shifted,))


def evaluate(
    control_points: Tensor,
    weights: Tensor,
    knot_vectors: Sequence[Tensor],
    degrees: Sequence[int],
    params: Tensor,
) -> Tensor:
    """Points of a rational tensor-product spline (or a batch) at scattered parameters.

    Shapes: ``control_points (*B, n_1, ..., n_k, dim)``, ``weights (*B, n_1, ..., n_k)``,
    knot vectors ``(m_a,)`` or ``(*B, m_a)``, ``params (*P, M, k)`` ->
    ``(*broadcast(B, P), M, dim)`` (see the module's Convention). No host reads.
    """
    h = _local(homogeneous(control_points, weights), knot_vectors, degrees, params, None)
    num, den = h.split([h.shape[-1] - 1, 1], dim=-1)
    return num / den


def derivatives(
    control_points: Tensor,
    weights: Tensor,
    knot_vectors: Sequence[Tensor],
    degrees: Sequence[int],
    params: Tensor,
    order: int,
) -> Tensor:
    """All mixed partial derivatives up to ``order`` in each direction.

    Shapes: ``params (*P, M, k)`` -> ``(*broadcast(B, P), M, order + 1, ... (k times), dim)``;
    entry ``[..., a, b, :]`` of a surface is the derivative ``a`` times in u and ``b``
    times in v; ``[..., 0, 0, :]`` is the point itself. No host reads.
    """
    shift = weight_shift(weights)
    return homogeneous_derivatives_to_points(
        _local(homogeneous(control_points, weights, shift), knot_vectors, degrees, params, order), len(degrees), True
    )


def derivatives_from_homogeneous(
    Pw: Tensor, knot_vectors: Sequence[Tensor], degrees: Sequence[int], params: Tensor, order: int,
    element: Tensor | None = None,
) -> Tensor:
    """:func:`derivatives` from homogeneous control points ``Pw (*B, n_1..n_k, dim + 1)``
    formed once by the caller (iterative solvers evaluate the same spline many times).

    With ``element (M,)``, point ``i`` of ``params (M, k)`` lies on element ``element[i]``
    of the flat batch ``Pw (Bt, n_1..n_k, dim + 1)`` -> ``(M, o + 1, ..., dim)`` (see
    :func:`_local`). ``Pw`` has no shifted weight channel (the module's note on
    derivatives): the projection, its one user, reads first and second derivatives, where
    that rounding is far below what it resolves."""
    return homogeneous_derivatives_to_points(_local(Pw, knot_vectors, degrees, params, order, element), len(degrees))


# ---- grids -------------------------------------------------------------------------------------

def uniform_axis(knots: Tensor, degree: int, n_ctrl: int, count: int) -> Tensor:
    """``count`` evenly spaced parameters over the domain ``[knots[p], knots[n]]``, ends exact.

    Shapes: ``knots (m,)`` -> ``(count,)``; ``knots (*B, m)`` -> ``(*B, count)``. Computed on
    the device from the end knots with ``torch.linspace``'s own formula (from the start
    for the first half, from the end for the second), so nothing is read back to the host
    and the last sample is the domain end exactly. The parameters follow the end knots,
    gradient included: a sample grid is uniform over the domain, so moving an end knot
    moves every sample (what a finite difference of the end knot measures).
    """
    k = knots
    a, b = k[..., degree : degree + 1], k[..., n_ctrl : n_ctrl + 1]
    if count == 1:
        return a
    i = torch.arange(count, dtype=k.dtype, device=k.device)
    step = (b - a) / (count - 1)
    return torch.where(i < count / 2, a + step * i, b - step * (count - 1 - i))


def span_axis(knots: Tensor, degree: int, n_ctrl: int, count: int) -> Tensor:
    """``count`` parameters spread evenly over the knot spans of the domain, ends exact.

    Uniform in a parameter ``s`` in which every non-empty span of ``[knots[p], knots[n]]``
    has length 1 (a repeated knot's empty spans get none): span ``j`` covers ``s`` from the
    number of non-empty spans before it, linearly (``torch.lerp``, exact at both ends of a
    span). Each span gets about ``count / spans`` samples, however short it is in the
    parameter (a span holds a piece of the control polygon whatever its length, so this
    follows the geometry where knots cluster); uniform knots give the uniform grid. The
    count of non-empty spans stays on the device (a ``searchsorted``), so nothing is read
    back to the host. Shapes as :func:`uniform_axis`.
    """
    k = knots[..., degree : n_ctrl + 1]  # the domain's knots, (..., S + 1)
    if count == 1:
        return k[..., :1]
    filled = (k[..., 1:] > k[..., :-1]).to(k.dtype)
    c = torch.cat([torch.zeros_like(k[..., :1]), filled.cumsum(-1)], -1)  # s at each knot
    s = torch.linspace(0, 1, count, dtype=k.dtype, device=k.device) * c[..., -1:]
    # the span of each s: the last knot at or below it (after a repeated knot's empty spans)
    j = (torch.searchsorted(c.contiguous(), s.contiguous(), right=True) - 1).clamp(0, k.shape[-1] - 2)
    lo, at = k.gather(-1, j), c.gather(-1, j)
    return torch.lerp(lo, k.gather(-1, j + 1), s - at)


def _kron_channels(matrix: Tensor, D: int) -> Tensor:
    """``B^T kron I_D``: ``(*, R, n)`` -> ``(*, n * D, R * D)``, so that a channel-last
    ``(rows, n * D)`` view times it contracts ``n`` and keeps the channels last."""
    eye = torch.eye(D, dtype=matrix.dtype, device=matrix.device)
    BT = matrix.transpose(-1, -2)  # (*, n, R)
    lead = BT.shape[:-2]
    n, R = BT.shape[-2:]
    return (BT[..., :, None, :, None] * eye[:, None, :]).reshape(lead + (n * D, R * D))


def _grid_matrix(kv: Tensor, p: int, n: int, axis: Tensor | int, order: int) -> Tensor:
    """Stacked basis matrix ``((o + 1) R, n)`` (or ``(*B, (o + 1) R, n)``) of one direction."""
    u = uniform_axis(kv, p, n, axis) if isinstance(axis, int) else axis
    m = basis_matrix(kv, p, n, u, order)
    if order:
        m = m.reshape(m.shape[:-3] + (-1, m.shape[-1]))
    return m


def _grid_operators(knot_vectors, degrees, sizes, axes, order: int, D: int, kron_last: bool = True) -> list[Tensor]:
    """The per-direction operators of a grid: basis matrices ``(R_a, n_a)``, the last one as
    ``B^T kron I_D`` when ``kron_last`` and ``D <= _KRON_MAX_CHANNELS``, else as ``B^T (n_k, R_k)``
    (a transposed view, kept in the cache so that a hit costs no operation).

    Cached on (knots, axis tensor) or (knots, sample count) when nothing needs gradients;
    built differentiably otherwise.
    """
    k = len(degrees)
    given = [ax for ax in axes if not isinstance(ax, int)]
    if (order == 0 and k > 1 and len(set(degrees)) == 1 and len(set(sizes)) == 1
            and all(kv.ndim == 1 for kv in knot_vectors) and all(ax.ndim == 1 for ax in given)
            and len({ax if isinstance(ax, int) else ax.shape[0] for ax in axes}) == 1
            and any(t.requires_grad for t in (*knot_vectors, *given))):
        # Trainable knots or parameters (nothing to cache): one recurrence for all directions.
        us = [uniform_axis(kv, p, n, ax) if isinstance(ax, int) else ax
              for kv, p, n, ax in zip(knot_vectors, degrees, sizes, axes)]
        mats = basis_matrices(list(knot_vectors), degrees[0], sizes[0], us).unbind(0)
        last = kron_last and D <= _KRON_MAX_CHANNELS
        tail = _kron_channels(mats[-1], D) if last else mats[-1] if kron_last else mats[-1].transpose(-1, -2)
        return list(mats[:-1]) + [tail]
    ops = []
    for a in range(k):
        last = kron_last and a == k - 1 and D <= _KRON_MAX_CHANNELS
        key_tensors = [knot_vectors[a]] + ([] if isinstance(axes[a], int) else [axes[a]])
        transposed = not kron_last and a == k - 1
        extra = ("grid", degrees[a], sizes[a], order, axes[a] if isinstance(axes[a], int) else -1,
                 D if last else 0, transposed)

        def build(a=a, last=last, transposed=transposed):
            m = _grid_matrix(knot_vectors[a], degrees[a], sizes[a], axes[a], order)
            return _kron_channels(m, D) if last else m.transpose(-1, -2) if transposed else m

        ops.append(basis_cache.get(key_tensors, extra, build))
    return ops


def _grid_products(Pw: Tensor, ops: Sequence[Tensor], k: int, kron: bool) -> Tensor:
    """``Pw (*B, n_1..n_k, D)`` through the direction operators -> ``(*B, R_1..R_k, D)``.

    ``ops[a]`` is ``(R_a, n_a)`` or per element ``(*B, R_a, n_a)``; with ``kron`` the last
    is ``B_k^T kron I_D``, ``(n_k D, R_k D)`` (or per element). Each direction is one GEMM
    (batched when it must be).
    """
    B = batch_shape(Pw, k)
    Bt = math.prod(B)
    sizes = Pw.shape[len(B) : len(B) + k]
    D = Pw.shape[-1]
    last = ops[-1]
    R = [0] * k
    if kron:
        if last.ndim == 2:
            X = Pw.reshape(-1, sizes[-1] * D).mm(last)
        else:
            X = torch.bmm(Pw.reshape(Bt, -1, sizes[-1] * D), last.reshape(Bt, sizes[-1] * D, -1))
        R[-1] = last.shape[-1] // D
    else:  # wide channels: (rows, n_k, D) -> (rows, R_k, D) by a broadcast product
        mat = last if last.ndim == 2 else last.reshape(Bt, 1, *last.shape[-2:])
        X = torch.matmul(mat, Pw.reshape(Bt, -1, sizes[-1], D))
        R[-1] = last.shape[-2]
    for a in range(k - 2, -1, -1):
        P = math.prod(sizes[:a])
        Q = math.prod(R[a + 1 :]) * D
        mat = ops[a]
        if mat.ndim == 2:
            if Bt * P == 1:
                X = mat.mm(X.reshape(sizes[a], Q))
            else:
                X = torch.matmul(mat, X.reshape(Bt * P, sizes[a], Q))
        elif P == 1:
            X = torch.bmm(mat.reshape(Bt, *mat.shape[-2:]), X.reshape(Bt, sizes[a], Q))
        else:
            X = torch.matmul(mat.reshape(Bt, 1, *mat.shape[-2:]), X.reshape(Bt, P, sizes[a], Q))
        R[a] = mat.shape[-2]
    return X.reshape(B + tuple(R) + (D,))


class _SurfaceGrid(torch.autograd.Function):
    """A rational surface on a grid through two basis matrices, with a hand-written backward.

    ``cp ([Bt,] n_u, n_v, dim)``, ``w ([Bt,] n_u, n_v)``, ``Bu (R, n_u)``, ``BvT (n_v, S)`` ->
    ``([Bt,] R, S, dim)``: one surface, or a batch of ``Bt`` sharing the basis.

    Forward: ``Pw = (w P, w)`` laid out ``([Bt,] n_u, D, n_v)`` (channel rows), then
    ``X = Pw B_v^T`` as one GEMM over all ``Bt * n_u * D`` rows, ``H = B_u X`` (one GEMM, or
    for a batch one ``bmm`` with ``B_u`` broadcast at stride 0: on a CPU twice as fast as a
    single ``(R, n_u) x (n_u, Bt * D * S)`` GEMM, whose output rows span the whole batch),
    and the division of whole channel rows of ``H`` by its weight row, in place (no new
    buffer the size of the grid); the result is a transposed view, channel last.

    Backward: one autograd node whose cost is the forward's again: with ``out = num / den``,
    ``dH = (G, -sum_c G_c out_c) / den`` written into one buffer (no concatenation, no
    temporary per channel), the two GEMMs transposed, and the product rule of
    ``(w P, w)`` on the (small) control net. When the basis matrices need gradients
    (trainable knots or parameters), ``dB_u = dH X^T`` and ``dB_v^T = Pw^T dX``: GEMMs of
    the same size, instead of autograd through a division broadcast over a channel-last
    grid (what made the knot path 1.3 to 2.2x slower than before issue 16).

    Second derivatives (``create_graph=True``, a Hessian-vector product) go through
    :meth:`_differentiable_backward`: the fast backward writes into buffers in place.

    Measured and not taken (tenth session): a channel-last layout, ``X = Pw (B_v^T kron I_D)``
    and ``H`` contiguous ``(R, S, D)``, so that the backward reads the loss's gradient
    without a transposed access: exact, but the 64-surface batch forward + backward on the
    CPU took 18.6 ms against this layout's 12.9 ms (16 x 16 at 128^2, float32, 2 threads).
    """

    @staticmethod
    def forward(ctx, cp, w, Bu, BvT):
        wT = w.unsqueeze(-2)
        Pw = torch.cat([cp.transpose(-1, -2) * wT, wT], dim=-2)  # ([Bt,] n_u, D, n_v)
        R, n_u, S = Bu.shape[0], Bu.shape[1], BvT.shape[1]
        D, lead = Pw.shape[-2], cp.shape[:-3]
        X = Pw.view(-1, Pw.shape[-1]).mm(BvT)  # ([Bt *] n_u * D, S): contracts v
        if lead:
            H = torch.bmm(Bu.expand(lead[0], R, n_u), X.view(lead[0], n_u, D * S))  # (Bt, R, D * S)
        else:
            H = Bu.mm(X.view(n_u, D * S))  # (R, D * S): contracts u
        num, den = H.view(lead + (R, D, S)).split([D - 1, 1], dim=-2)
        out = num.div_(den)  # ([Bt,] R, dim, S), a view of H: the rows do not overlap
        ctx.save_for_backward(cp, w, Bu, BvT, out, den,
                              X if ctx.needs_input_grad[2] else None,
                              Pw if ctx.needs_input_grad[3] else None)
        return out.transpose(-1, -2)

    @staticmethod
    def backward(ctx, G):
        if torch.is_grad_enabled():  # create_graph=True: second derivatives need a differentiable backward
            return _SurfaceGrid._differentiable_backward(ctx, G)
        cp, w, Bu, BvT, out, den, X, Pw = ctx.saved_tensors
        R, n_u, S, dim = Bu.shape[0], Bu.shape[1], BvT.shape[1], cp.shape[-1]
        lead = cp.shape[:-3]
        dH = G.new_empty(out.shape[:-2] + (dim + 1, S))
        gnum, gden = dH.split([dim, 1], dim=-2)
        torch.div(G.transpose(-1, -2), den, out=gnum)
        if dim <= 4:  # a running sum of products over the channel rows: no temporary
            torch.mul(gnum[..., :1, :], out[..., :1, :], out=gden)
            for c in range(1, dim):
                gden.addcmul_(gnum[..., c : c + 1, :], out[..., c : c + 1, :])
        else:
            torch.sum(gnum * out, dim=-2, keepdim=True, out=gden)
        gden.neg_()
        if lead:
            dH2 = dH.view(lead[0], R, -1)
            dX = torch.bmm(Bu.t().expand(lead[0], n_u, R), dH2)  # (Bt, n_u, D * S)
        else:
            dH2 = dH.view(R, -1)
            dX = Bu.t().mm(dH2)  # (n_u, D * S)
        dPw = dX.view(-1, S).mm(BvT.t()).view(cp.shape[:-2] + (dim + 1, cp.shape[-2]))
        gP, gw = dPw.split([dim, 1], dim=-2)  # ([Bt,] n_u, dim, n_v), ([Bt,] n_u, 1, n_v)
        dcp = (gP * w.unsqueeze(-2)).transpose(-1, -2) if ctx.needs_input_grad[0] else None
        dw = (gP * cp.transpose(-1, -2)).sum(-2) + gw.squeeze(-2) if ctx.needs_input_grad[1] else None
        dBu = dBvT = None
        if X is not None:
            if lead:
                dBu = torch.bmm(dH2, X.view(lead[0], n_u, -1).transpose(1, 2)).sum(0)
            else:
                dBu = dH2.mm(X.view(n_u, -1).t())
        if Pw is not None:
            dBvT = Pw.view(-1, Pw.shape[-1]).t().mm(dX.view(-1, S))
        return dcp, dw, dBu, dBvT

    @staticmethod
    def _differentiable_backward(ctx, G):
        """The backward as autograd of the plain forward (``H = B_u Pw B_v^T``, then the
        division), with ``create_graph``: the fast backward writes into buffers in place,
        which autograd cannot differentiate again. Only Hessian-vector products and the
        like (``create_graph=True``) come here."""
        cp, w, Bu, BvT = ctx.saved_tensors[:4]
        inputs = [t for t, need in zip((cp, w, Bu, BvT), ctx.needs_input_grad) if need]
        with torch.enable_grad():
            Pw = torch.cat([cp * w.unsqueeze(-1), w.unsqueeze(-1)], dim=-1)  # ([Bt,] n_u, n_v, D)
            H = torch.einsum("rn,...nmd,ms->...rsd", Bu, Pw, BvT)
            out = H[..., :-1] / H[..., -1:]
            found = iter(torch.autograd.grad(out, inputs, G, create_graph=True, allow_unused=True))
        return tuple(next(found) if need else None for need in ctx.needs_input_grad)


def _folded_products(Pw: Tensor, ops: Sequence[Tensor], sizes: Sequence[int], folded: bool) -> Tensor:
    """Shared operators on ``Pw (n_1, [Bt,] n_2..n_k, D)`` (the batch, if any, behind the first
    direction, so that every direction is one GEMM over the whole batch) ->
    ``(R_1, [Bt,] R_2..R_k, D)``; ``ops[-1]`` is ``B_k^T kron I_D``."""
    k = len(sizes)
    D = Pw.shape[-1]
    X = Pw.reshape(-1, sizes[-1] * D).mm(ops[-1])
    R = [0] * k
    R[-1] = ops[-1].shape[-1] // D
    lead = Pw.shape[: 2 if folded else 1]
    for a in range(k - 2, 0, -1):
        P = math.prod(lead) * math.prod(sizes[1:a])
        X = torch.matmul(ops[a], X.reshape(P, sizes[a], -1))
        R[a] = ops[a].shape[0]
    X = ops[0].mm(X.reshape(sizes[0], -1))
    R[0] = ops[0].shape[0]
    return X.reshape((R[0],) + tuple(lead[1:]) + tuple(R[1:]) + (D,))


def _grid(control_points, weights, knot_vectors, degrees, axes, order: int) -> Tensor:
    k = len(degrees)
    B = batch_shape(control_points, k)
    nb = len(B)
    sizes = tuple(control_points.shape[nb : nb + k])
    shift = weight_shift(weights) if order else None  # derivatives: one more channel (module note)
    D = control_points.shape[-1] + (2 if order else 1)
    kron = D <= _KRON_MAX_CHANNELS
    per_element = _per_element(knot_vectors) or any(isinstance(ax, Tensor) and ax.ndim > 1 for ax in axes)
    if k == 2 and order == 0 and not per_element:
        # The hot path of a fit and of a network: a surface through two shared basis
        # matrices (cached when fixed, rebuilt differentiably when the knots or the
        # parameters train), one autograd node.
        Bu, BvT = _grid_operators(knot_vectors, degrees, sizes, axes, order, D, kron_last=False)
        if len(B) > 1:
            control_points = control_points.reshape((-1,) + sizes + (D - 1,))
            weights = weights.reshape((-1,) + sizes)
        elif B and weights.ndim == k:  # weights shared by the batch
            weights = weights.expand(B + sizes)
        out = _SurfaceGrid.apply(control_points, weights, Bu, BvT)  # ([Bt,] R, S, dim)
        return out.reshape(B + out.shape[-3:]) if len(B) > 1 else out
    ops = _grid_operators(knot_vectors, degrees, sizes, axes, order, D)
    if kron and k >= 2 and all(op.ndim == 2 for op in ops):
        # Shared operators: the batch rides behind the first direction (a cheap permuted
        # copy of the control net), and every direction is one GEMM for the whole batch.
        Bt = math.prod(B)
        cp, w = control_points, weights
        if B:
            cp = cp.reshape((Bt,) + sizes + cp.shape[-1:]).movedim(0, 1)
            w = w.reshape((Bt,) + sizes).movedim(0, 1)
        h = _folded_products(homogeneous(cp, w, shift), ops, sizes, bool(B))
        if B:
            h = h.movedim(1, 0).reshape(B + h.shape[:1] + h.shape[2:])
    else:
        h = _grid_products(homogeneous(control_points, weights, shift), ops, k, kron)
    if order == 0:
        num, den = h.split([D - 1, 1], dim=-1)
        return num / den
    # (*B, (o+1) R_1, ..., (o+1) R_k, D) -> (*B, R_1..R_k, o..o, D)
    lengths = h.shape[nb : nb + k]
    h = h.reshape(B + sum(((order + 1, r // (order + 1)) for r in lengths), ()) + (D,))
    perm = list(range(nb)) + [nb + 2 * a + 1 for a in range(k)] + [nb + 2 * a for a in range(k)] + [nb + 2 * k]
    return homogeneous_derivatives_to_points(h.permute(perm), k, shift is not None)


def evaluate_grid(
    control_points: Tensor,
    weights: Tensor,
    knot_vectors: Sequence[Tensor],
    degrees: Sequence[int],
    axes: Sequence[Tensor],
    order: int = 0,
) -> Tensor:
    """Points (or derivatives) on the tensor grid ``axes[0] x axes[1] x ...``.

    Shapes: ``axes[a] (R_a,)`` (shared) or ``(*B, R_a)`` (per element, with per-element
    knots) -> ``(*B, R_1, ..., R_k, dim)``; with ``order > 0``,
    ``(*B, R_1, ..., R_k, order + 1, ... (k times), dim)`` laid out as :func:`derivatives`.
    No host reads; the basis matrices are cached while knots and axes stay unchanged.
    """
    return _grid(control_points, weights, knot_vectors, degrees, list(axes), order)


def sample(
    control_points: Tensor,
    weights: Tensor,
    knot_vectors: Sequence[Tensor],
    degrees: Sequence[int],
    resolution: Sequence[int],
    order: int = 0,
) -> Tensor:
    """:func:`evaluate_grid` on ``resolution[a]`` evenly spaced parameters per direction
    (:func:`uniform_axis`, domain ends included): ``(*B, R_1, ..., R_k, dim)``.

    The fast path of a fit: with fixed knots the basis operators come from the cache
    (keyed on the knot tensors and the resolution), and a surface costs two GEMMs and
    a division, about ten aten operations, whatever the control points.
    """
    return _grid(control_points, weights, knot_vectors, degrees, [int(r) for r in resolution], order)

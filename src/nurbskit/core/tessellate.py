"""Triangle meshes of NURBS surfaces from a parametric tensor grid.

:func:`tessellate` samples a uniform grid; :func:`tessellate_adaptive` a non-uniform one
refined until the chords are within a tolerance. Both share one layout.

Convention: vertex ``i * S + j`` is the surface at ``(u_i, v_j)`` of the grid (for
:func:`tessellate`, ``surface.grid_axes((R, S))``; u on the first axis, as everywhere in
nurbskit). Each grid
cell ``(i, j)`` gives two triangles, ``(i, j), (i+1, j), (i+1, j+1)`` and
``(i, j), (i+1, j+1), (i, j+1)``, in that order, so that a face's normal
``(b - a) x (c - a)`` points along ``S_u x S_v`` (for the first one it is
``du dv S_u x S_v`` to first order). Vertex normals are unit ``S_u x S_v``.

Where ``S_u x S_v`` vanishes (a collapsed edge, such as the pole of a sphere built as a
surface of revolution, where ``S_u = 0`` along the whole edge ``v = v_max``), the normal
is its limit from inside the domain: with ``S_u(u, v0) = 0``,
``S_u(u, v) = (v - v0) S_uv + O((v - v0)^2)``, so ``S_u x S_v`` points along
``sign(v - v0) S_uv x S_v`` (and symmetrically ``sign(u - u0) S_u x S_uv`` when
``S_v = 0``). Where that limit vanishes as well, the area-weighted mean of the normals of
the faces around the vertex is used, and where that vanishes too, the mean normal of the
neighbouring grid vertices. Zero-area triangles at a collapsed edge are kept, so
the face count is always ``2 (R - 1) (S - 1)``; seams of closed surfaces are not welded.

Everything is built from differentiable tensor operations: vertices and normals carry
gradients to the surface's control points, weights and knots.
"""

from __future__ import annotations

from typing import NamedTuple, Sequence

import torch

from ..errors import NurbskitError
from .surface import limit_normals

Tensor = torch.Tensor

__all__ = ["Tessellation", "tessellate", "tessellate_adaptive", "grid_faces"]


class Tessellation(NamedTuple):
    """Result of :func:`tessellate`; unpacks as ``vertices, faces, normals``."""

    vertices: Tensor
    """``(R * S, 3)`` surface points, vertex ``i * S + j`` at ``(u_i, v_j)``."""
    faces: Tensor
    """``(2 (R - 1) (S - 1), 3)`` int64 vertex indices, counter-clockwise about ``S_u x S_v``."""
    normals: Tensor
    """``(R * S, 3)`` unit vertex normals along ``S_u x S_v``."""


def grid_faces(rows: int, cols: int, device=None) -> Tensor:
    """Triangles of a ``rows x cols`` vertex grid (vertex ``i * cols + j``): ``(2 (rows-1) (cols-1), 3)`` int64.

    Example:
        >>> grid_faces(2, 2).tolist()
        [[0, 2, 3], [0, 3, 1]]
    """
    i = torch.arange(rows - 1, device=device)[:, None]
    j = torch.arange(cols - 1, device=device)[None, :]
    a = (i * cols + j).reshape(-1)
    b, c, d = a + cols, a + cols + 1, a + 1
    first = torch.stack([a, b, c], dim=-1)
    second = torch.stack([a, c, d], dim=-1)
    # interleave so that the two triangles of cell (i, j) are faces 2k and 2k + 1
    return torch.stack([first, second], dim=1).reshape(-1, 3)


def _unit(n: Tensor) -> Tensor:
    return n / n.norm(dim=-1, keepdim=True).clamp_min(torch.finfo(n.dtype).tiny)


def tessellate(surface, resolution: int | Sequence[int] = 32) -> Tessellation:
    """Vertices, triangles and vertex normals of a surface on a uniform parametric grid.

    Args:
        surface: a 3-D :class:`NURBSSurface`, or a batch of them.
        resolution: ``R`` or ``(R, S)`` samples per direction, each ``>= 2``, ends included.

    Returns:
        ``Tessellation(vertices (*B, R*S, 3), faces (2(R-1)(S-1), 3) int64, normals (*B, R*S, 3))``;
        a batch shares its faces. dtype and device follow the surface (see the module
        docstring for the conventions).

    Example:
        >>> import torch
        >>> from nurbskit import NURBSSurface
        >>> s = NURBSSurface(torch.rand(4, 4, 3), degrees=(3, 3))
        >>> vertices, faces, normals = tessellate(s, (8, 6))
        >>> vertices.shape, faces.shape, normals.shape
        (torch.Size([48, 3]), torch.Size([70, 3]), torch.Size([48, 3]))
    """
    _check_surface(surface, "tessellate")
    # per grid point: the first derivatives (4 homogeneous points), vertex and normal
    res = surface._resolution(resolution, minimum=2, op="tessellate", values=4 * 4 + 2 * 3)
    u, v = surface.grid_axes(res)
    return _tessellate_axes(surface, u, v)


def _check_surface(surface, name: str) -> None:
    if getattr(surface, "para_dim", None) != 2:
        raise NurbskitError(f"{name} takes a NURBSSurface, got {type(surface).__name__}")
    if surface.dim != 3:
        raise NurbskitError(f"{name} needs a surface in 3-D (normals), got control points of dimension {surface.dim}")


def _tessellate_axes(surface, u: Tensor, v: Tensor) -> Tessellation:
    """:func:`tessellate` on the tensor grid of increasing parameter arrays ``u (*, R)``, ``v (*, S)``."""
    R, S = u.shape[-1], v.shape[-1]
    B = surface.batch_shape
    D = surface.evaluate_grid(u, v, order=1, extrapolate=True)  # (*B, R, S, 2, 2, 3)
    vertices = D[..., 0, 0, :].reshape(B + (R * S, 3))
    at_u, at_v = surface._upper_edges(u.reshape(u.shape[:-1] + (-1, 1)), v.reshape(v.shape[:-1] + (1, -1)), 2)
    n = limit_normals(D[..., 1, 0, :], D[..., 0, 1, :], D[..., 1, 1, :], at_u, at_v).reshape(B + (R * S, 3))
    faces = grid_faces(R, S, device=vertices.device)
    with torch.no_grad():
        size = n.norm(dim=-1)
        scale = size.amax(dim=-1, keepdim=True)
        # sqrt(eps) relative: rows next to a pole still have |n| ~ 1/R of the largest.
        missing = size <= torch.finfo(n.dtype).eps ** 0.5 * scale
    if bool(missing.any()):  # one host read: only surfaces whose limit normal vanishes go on
        n = _repair_normals(n, missing, scale, vertices, faces, R, S)
    return Tessellation(vertices, faces, _unit(n))


def _repair_normals(n, missing, scale, vertices, faces, R: int, S: int) -> Tensor:
    """Where even the limit normal vanishes: the area-weighted mean of the surrounding face
    normals, then the grid neighbours' mean. ``n, vertices (*B, R S, 3)``, ``missing (*B, R S)``."""
    a, b, c = (vertices[..., faces[:, i], :] for i in range(3))
    fn = torch.linalg.cross(b - a, c - a, dim=-1)  # |(b - a) x (c - a)| is twice the area: a plain sum weights by area
    spread = fn.unsqueeze(-2).expand(fn.shape[:-1] + (3, 3)).reshape(fn.shape[:-2] + (-1, 3))
    around = torch.zeros_like(vertices).index_add(-2, faces.reshape(-1), spread)
    n = torch.where(missing.unsqueeze(-1), _unit(around) * scale.unsqueeze(-1), n)
    return _fill_from_neighbours(n.reshape(n.shape[:-2] + (R, S, 3)), scale).reshape(n.shape)


def _fill_from_neighbours(n: Tensor, scale: Tensor) -> Tensor:
    """Give vertices still without a normal the mean of their grid neighbours' normals.

    ``n (*B, R, S, 3)``, ``scale (*B, 1)``. Needed where every surrounding face has zero area
    too (a corner of the grid touches one triangle only, which a collapsed edge may
    flatten). Repeats until each such vertex has a neighbour with a normal (at most
    ``R + S`` rounds).
    """
    R, S = n.shape[-3], n.shape[-2]
    limit = torch.finfo(n.dtype).eps ** 0.5 * scale.unsqueeze(-1)
    for _ in range(R + S):
        with torch.no_grad():
            missing = n.norm(dim=-1) <= limit
        if not bool(missing.any()):
            break
        unit = torch.where(missing[..., None], torch.zeros_like(n), _unit(n))
        padded = torch.nn.functional.pad(unit.movedim(-1, -3), (1, 1, 1, 1)).movedim(-3, -1)
        around = sum(padded[..., 1 + di : 1 + di + R, 1 + dj : 1 + dj + S, :] for di in (-1, 0, 1) for dj in (-1, 0, 1))
        n = torch.where(missing[..., None], around, n)
    return n


def _breaks(knots: Tensor, degree: int, n_ctrl: int) -> Tensor:
    """Distinct knots inside the domain (span boundaries), ends included: ``(B,)``."""
    return torch.unique_consecutive(knots.detach()[degree : n_ctrl + 1])


def tessellate_adaptive(surface, tolerance: float, *, max_resolution: int = 1025) -> Tessellation:
    """A tessellation on a non-uniform tensor grid, refined until the chords are within ``tolerance``.

    Starts from the span boundaries (distinct knots) in each direction and bisects a
    parameter interval while some triangle edge over it deviates from the surface by
    more than ``tolerance``, measured at the edge's parameter midpoint:
    ``|S(midpoint) - (S(a) + S(b)) / 2|`` for the edges along u, along v and the cell
    diagonals. That bounds the distance from each edge midpoint to the surface; flat
    directions (a ruled or extruded surface) stay at their span boundaries. Refinement
    stops at ``max_resolution`` samples per direction even if the tolerance is not met.

    Shapes and conventions as :func:`tessellate`, with ``R, S`` chosen by the refinement.

    Example:
        >>> import torch
        >>> from nurbskit import NURBSSurface
        >>> cp = torch.zeros(3, 2, 3)
        >>> cp[:, :, 0] = torch.tensor([0., 0.5, 1.])[:, None]
        >>> cp[:, :, 1] = torch.tensor([0., 1.])
        >>> cp[1, :, 2] = 0.5  # a parabolic cylinder: curved in u, straight in v
        >>> mesh = tessellate_adaptive(NURBSSurface(cp, degrees=(2, 1)), 1e-3)
        >>> mesh.vertices.shape  # 17 x 2: sag h^2 / 4 <= 1e-3 needs h = 1/16 in u
        torch.Size([34, 3])
    """
    _check_surface(surface, "tessellate_adaptive")
    surface.require_single("tessellate_adaptive")
    if not tolerance > 0:
        raise NurbskitError(f"tessellate_adaptive: tolerance must be > 0, got {tolerance!r}")
    if max_resolution < 2:
        raise NurbskitError(f"tessellate_adaptive: max_resolution must be >= 2, got {max_resolution}")
    fixed = surface.detach()
    axes = [_breaks(kv, p, n) for kv, p, n in zip(fixed.knot_vectors, fixed.degrees, fixed.sizes)]
    with torch.no_grad():
        while True:
            u, v = axes
            mu, mv = (u[1:] + u[:-1]) / 2, (v[1:] + v[:-1]) / 2
            P = fixed.evaluate_grid(u, v, extrapolate=True)  # (R, S, 3)
            along_u = (fixed.evaluate_grid(mu, v, extrapolate=True) - (P[1:] + P[:-1]) / 2).norm(dim=-1)  # (R-1, S)
            along_v = (fixed.evaluate_grid(u, mv, extrapolate=True) - (P[:, 1:] + P[:, :-1]) / 2).norm(dim=-1)
            diagonal = (fixed.evaluate_grid(mu, mv, extrapolate=True) - (P[1:, 1:] + P[:-1, :-1]) / 2).norm(dim=-1)
            split_u = along_u.amax(dim=1) > tolerance
            split_v = along_v.amax(dim=0) > tolerance
            # A diagonal's deviation mixes both directions' sag and the twist; splitting
            # the directions already split usually cures it, so only cells where neither
            # is split get both.
            twisted = (diagonal > tolerance) & ~split_u[:, None] & ~split_v[None, :]
            split_u = split_u | twisted.any(dim=1)
            split_v = split_v | twisted.any(dim=0)
            grown = False
            for a, (split, mid) in enumerate(((split_u, mu), (split_v, mv))):
                if bool(split.any()) and len(axes[a]) + int(split.sum()) <= max_resolution:
                    axes[a] = torch.sort(torch.cat([axes[a], mid[split]])).values
                    grown = True
            if not grown:
                break
    return _tessellate_axes(surface, axes[0], axes[1])

"""Taubin's quadric fitting error from additive moment matrices (the merge priority).

G. Taubin, "Estimation of planar curves, surfaces, and nonplanar space curves defined by
implicit equations" (PAMI 1991). A quadric is ``f(x) = c . m(x)`` with the ten monomials
``m = (1, x, y, z, x^2, y^2, z^2, xy, xz, yz)``. Its fitting error over a point set is the
generalised Rayleigh quotient

    e = min_c (c^T M c) / (c^T N c),  M = sum m m^T,  N = sum J^T J,  J = d m / d x (3 x 10),

the smallest generalised eigenvalue of ``(M, N)``: to first order the mean squared
distance of the points to the best quadric. Both matrices are sums over points, so the
matrices of a union are the sums of its parts' (NURBSFit, section 3.2): a merge's priority
costs one 10 x 10 eigenproblem, not a refit.

Convention: coordinates should be normalised (centred, unit bounding-box diagonal) so
that the monomials are of similar size; errors are then in squared diagonals.
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import eigh


def monomials(points: np.ndarray) -> np.ndarray:
    """``(N, 3)`` -> ``(N, 10)``: ``1, x, y, z, x^2, y^2, z^2, xy, xz, yz``."""
    x, y, z = points[:, 0], points[:, 1], points[:, 2]
    one = np.ones_like(x)
    return np.stack([one, x, y, z, x * x, y * y, z * z, x * y, x * z, y * z], axis=1)


def monomial_gradients(points: np.ndarray) -> np.ndarray:
    """``(N, 3)`` -> ``(N, 3, 10)``: row ``d`` holds ``d m / d x_d``."""
    x, y, z = points[:, 0], points[:, 1], points[:, 2]
    zero, one = np.zeros_like(x), np.ones_like(x)
    gx = [zero, one, zero, zero, 2 * x, zero, zero, y, z, zero]
    gy = [zero, zero, one, zero, zero, 2 * y, zero, x, zero, z]
    gz = [zero, zero, zero, one, zero, zero, 2 * z, zero, x, y]
    return np.stack([np.stack(gx, 1), np.stack(gy, 1), np.stack(gz, 1)], axis=1)


def moments(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The moment matrices ``M (10, 10)`` and ``N (10, 10)`` of ``points (N, 3)``."""
    m = monomials(points)
    g = monomial_gradients(points)
    return m.T @ m, np.einsum("ndi,ndj->ij", g, g)


def taubin_error(M: np.ndarray, N: np.ndarray) -> float:
    """Smallest generalised eigenvalue of ``(M, N)``: the quadric fitting error.

    ``N`` is singular in the constant coefficient (its gradient is zero), so the constant
    is eliminated first: for fixed other coefficients ``c'`` the best constant is
    ``-M[0, 1:] c' / M[0, 0]``, leaving the Schur complement ``S = M' - m m^T / M[0, 0]``
    and the 9 x 9 problem ``S c' = e N' c'``. A tiny ridge keeps ``N'`` definite where a
    monomial's gradient vanishes on every point (``z^2`` on the plane ``z = 0``: the
    quotient is then 0/0 and the ridge makes it 0, which is right for points on a quadric).
    """
    if M[0, 0] <= 0:
        return 0.0
    S = M[1:, 1:] - np.outer(M[1:, 0], M[0, 1:]) / M[0, 0]
    Np = N[1:, 1:]
    ridge = 1e-12 * max(np.trace(Np), 1e-300)
    w = eigh(0.5 * (S + S.T), 0.5 * (Np + Np.T) + ridge * np.eye(9), eigvals_only=True, subset_by_index=[0, 0])
    return float(max(w[0], 0.0))


def quadric_error(points: np.ndarray) -> float:
    """Taubin error of one point set ``(N, 3)`` (the sum of the moments of its parts)."""
    return taubin_error(*moments(points))

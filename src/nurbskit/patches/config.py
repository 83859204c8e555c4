"""Typed configuration of ``nurbskit patches`` (multi-patch fitting after NURBSFit).

Each field's help text (``metadata["help"]``) is also its command-line help; the resolved
configuration is written as ``config.json`` next to every run's outputs
(:func:`config_to_dict`).

Convention: lengths are fractions of the input's bounding-box diagonal (``eps = 0.01``
is 1 % of it), so one configuration serves clouds of any size.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any

from ..errors import OptionError

#: Fewest points a multi-patch fit runs on: the input, and the subset of ``max_points``.
MIN_POINTS = 20
#: Largest ``seed`` (numpy's generators take any non-negative integer; torch's, as the fit's, below 2**63).
MAX_SEED = 2**63 - 1


def _f(default, help: str):
    return field(default=default, metadata={"help": help})


@dataclass
class PatchConfig:
    """Everything one multi-patch fit needs (defaults: the paper's, where it has one)."""

    eps: float = _f(0.01, "inlier tolerance as a fraction of the bounding-box diagonal (the paper: 1 %)")
    weights: tuple[float, float, float] = _f(
        (0.3, 0.4, 0.3), "energy weights lambda_fid, lambda_simp, lambda_cov (the paper's real-data defaults)"
    )
    max_ctrl: int = _f(12, "largest control grid per patch along u and v (the grid grows with the patch's complexity)")
    min_ctrl: int = _f(4, "starting control grid per patch along u and v (the paper's fixed 4 x 4)")
    degree: int = _f(3, "degree of every patch along u and v")
    init: str = _f("auto", "planar start: 'auto' (our region growing) or a GoCoPP / PolyFit .vg file")
    planar_eps: float = _f(1.0, "tolerance of the planar start as a multiple of eps (the paper: 1 on scans, 2 on CAD)")
    normal_angle: float = _f(25.0, "region growing: largest angle in degrees between a point's normal and its plane")
    min_region: int = _f(0, "regions smaller than this many points are dropped (0: 0.2 % of the points, at least 10)")
    neighbours: int = _f(12, "k of the k-nearest-neighbour graph (normals, region growing, adjacency)")
    min_links: int = _f(3, "two regions are adjacent when at least this many kNN links join them")
    min_radius: float = _f(
        3.0, "a merged patch may not bend tighter than this many eps on more than crease_fraction of its inliers"
    )
    crease_fraction: float = _f(0.01, "fraction of inliers allowed on a tighter bend than min_radius (a sharp crease)")
    crease_turned: float = _f(
        0.2, "a tight bend is a rounded crease when more than this fraction of it turns by more than crease_angle"
    )
    crease_seam: float = _f(
        75.0,
        "two parts never merge when they meet at more than this many degrees (median angle of their "
        "normals across the kNN links joining them), decided before any fit, unless one is a leftover (see leftover): "
        "sharp edges are kept; planar strips "
        "of a fillet meet at less (about 2 x normal_angle); 90: never refused on the angle alone, a sharp edge is "
        "judged by the energy and the crease test, as in the paper (fewer patches)",
    )
    crease_angle: float = _f(
        40.0,
        "a tight bend rounds a crease only where the patch's normal turns more than this many degrees away from the "
        "normal of the merged part the point came from (a fillet cut into planar strips stays within normal_angle)",
    )
    leftover: float = _f(
        0.05,
        "a part of at most this fraction of the points (a leftover at an edge, a small cap) may merge across a steep "
        "seam or a crease: the energy alone decides its merge (0: the seam and crease tests hold for every part)",
    )
    crease_inherit: bool = _f(
        True,
        "a pair whose parts contain both sides of a union already refused for rounding a crease is refused without "
        "a fit (the crease lies between them too)",
    )
    absorb: float = _f(
        0.05,
        "after the merges, a patch of at most this fraction of the points is dissolved into its neighbours (their "
        "surfaces hold its points within eps, true projection) when the energy falls; 0: never",
    )
    absorb_held: float = _f(
        0.5, "absorption needs the neighbours to hold at least this fraction of the small patch's points within eps"
    )
    fit_points: int = _f(800, "fit each candidate patch on at most this many of its points (seeded subset)")
    fit_rounds: int = _f(5, "alternating projection + least-squares rounds of each candidate fit (accepted patches are refined later)")
    fit_iters: int = _f(0, "refinement iterations (the fit's default stage) of each candidate fit; 0: least squares only")
    final_iters: int = _f(15, "refinement iterations (the fit's default stage) of each final patch; 0: none")
    final_points: int = _f(1500, "fit each final patch on at most this many of its inliers")
    max_quadric_error: float = _f(
        0.0,
        "skip merges whose Taubin quadric error (about the mean squared distance to the best quadric) exceeds "
        "this many eps^2 (0: never skip, the default: a freeform union no quadric fits can still be one NURBS patch, "
        "and the seam test keeps a cap off its tube); the paper's optional cut",
    )
    max_points: int = _f(
        20_000,
        "larger clouds: the planar start and the merges run on a seeded subset of this many points, and every input "
        "point is then assigned to a patch by projection (0: never subsample)",
    )
    seed: int = _f(0, "seed of every random subset")
    device: str = _f("cpu", "torch device of the fits: cpu or cuda")

    def validate(self) -> "PatchConfig":
        """Raise an OptionError naming the field when a value is out of range."""
        if not 0 < self.eps < 1:
            raise OptionError(f"eps: expected a fraction of the diagonal in (0, 1), got {self.eps!r}")
        w = tuple(self.weights)
        if len(w) != 3 or any(not x >= 0 for x in w) or sum(w) <= 0:
            raise OptionError(f"weights: expected three non-negative numbers with a positive sum, got {self.weights!r}")
        if self.degree < 1:
            raise OptionError(f"degree: expected an integer >= 1, got {self.degree!r}")
        if not self.degree + 1 <= self.min_ctrl <= self.max_ctrl:
            raise OptionError(
                f"max_ctrl: expected degree + 1 = {self.degree + 1} <= min_ctrl ({self.min_ctrl}) <= max_ctrl, got {self.max_ctrl}"
            )
        for name in ("planar_eps", "normal_angle", "min_radius", "crease_fraction", "crease_angle", "crease_seam"):
            if not getattr(self, name) > 0:
                raise OptionError(f"{name}: expected a positive number, got {getattr(self, name)!r}")
        for name in ("normal_angle", "crease_angle", "crease_seam"):
            if not getattr(self, name) <= 180:
                raise OptionError(f"{name}: expected an angle in degrees, at most 180, got {getattr(self, name)!r}")
        for name, low in (("neighbours", 3), ("min_links", 1), ("fit_points", 16), ("fit_iters", 0), ("fit_rounds", 0), ("final_iters", 0), ("final_points", 16), ("min_region", 0)):
            v = getattr(self, name)
            if int(v) != v or v < low:
                raise OptionError(f"{name}: expected an integer >= {low}, got {v!r}")
        if int(self.max_points) != self.max_points or not (self.max_points == 0 or self.max_points >= MIN_POINTS):
            raise OptionError(
                f"max_points: expected 0 (never subsample) or an integer >= {MIN_POINTS} (the fewest points a "
                f"multi-patch fit runs on), got {self.max_points!r}"
            )
        if isinstance(self.seed, bool) or int(self.seed) != self.seed or not 0 <= self.seed <= MAX_SEED:
            raise OptionError(f"seed: expected an integer in [0, {MAX_SEED}], got {self.seed!r}")
        if not 0 <= self.absorb_held <= 1:
            raise OptionError(f"absorb_held: expected a fraction in [0, 1], got {self.absorb_held!r}")
        if not 0 <= self.leftover <= 1:
            raise OptionError(f"leftover: expected a fraction of the points in [0, 1], got {self.leftover!r}")
        if not 0 <= self.absorb <= 1:
            raise OptionError(f"absorb: expected a fraction of the points in [0, 1], got {self.absorb!r}")
        if not 0 <= self.crease_turned < 1:
            raise OptionError(f"crease_turned: expected a fraction in [0, 1), got {self.crease_turned!r}")
        if self.max_quadric_error < 0:
            raise OptionError(f"max_quadric_error: expected >= 0, got {self.max_quadric_error!r}")
        return self


def config_to_dict(cfg: PatchConfig) -> dict:
    """The configuration as plain JSON data."""
    d = dataclasses.asdict(cfg)
    d["weights"] = list(d["weights"])
    return d


def config_from_dict(data: dict[str, Any]) -> PatchConfig:
    """Inverse of :func:`config_to_dict`; unknown keys raise an OptionError."""
    names = {f.name for f in dataclasses.fields(PatchConfig)}
    unknown = set(data) - names
    if unknown:
        raise OptionError(f"PatchConfig: unknown field(s) {', '.join(sorted(unknown))}")
    kw = dict(data)
    if "weights" in kw:
        kw["weights"] = tuple(kw["weights"])
    return PatchConfig(**kw).validate()

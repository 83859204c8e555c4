"""Typed configuration of one surface fit.

A fit is: an initial surface (:class:`InitConfig`), optionally a few rounds of
alternating projection and least squares (:class:`AlternationConfig`), then one or
more gradient *stages* of the generic loop (:class:`StageConfig`), each with its own
loss weights (:class:`LossWeights`), optimiser and trainable parameters. A named
pipeline (``SB``, ``UCDL``, ``default`` ...) is nothing but a :class:`FitConfig`
preset (see :mod:`nurbskit.fit.pipelines`).

Each field's docstring (``metadata["help"]``) is also its command-line help. The
resolved configuration is written as ``config.json`` next to every fit's outputs
(:func:`config_to_dict`).

Convention: all lengths inside the fit are in *normalised* units: the input is
centred on its bounding-box centre and scaled so that the box diagonal is 1. Loss
weights and learning rates are therefore independent of the input's size.

Convention: dtype and device are not configuration: a fit runs on the input's own
(:func:`nurbskit.fit.fit_surface`); ``nurbskit fit --device/--dtype`` moves the input.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any, Literal

from ..errors import OptionError

LaplacianOn = Literal["grid", "control"]
InitKind = Literal["auto", "random", "plane", "cylinder", "cage", "lstsq", "target"]
OptimizerKind = Literal["adam", "sgd", "lbfgs"]

INIT_KINDS = ("auto", "random", "plane", "cylinder", "cage", "lstsq", "target")
OPTIMIZERS = ("adam", "sgd", "lbfgs")
LAPLACIAN_ON = ("grid", "control")
CLOSED = ("auto", "open", "v")
#: Sane ranges, checked before any work (a learning rate beyond this makes every optimiser
#: here diverge in fit units, where the input's diagonal is 1).
LR_RANGE = (0.0, 10.0)
MAX_ITERS = 1_000_000
MAX_DEGREE = 15


def _f(default, help: str, **kw):
    """A dataclass field whose help text becomes the CLI help."""
    if isinstance(default, (list, dict, tuple)) and not isinstance(default, tuple):
        return field(default_factory=lambda: type(default)(default), metadata={"help": help}, **kw)
    return field(default=default, metadata={"help": help}, **kw)


@dataclass
class LossWeights:
    """Weights of the loss terms; a zero weight switches a term off.

    Terms (``X`` the input, ``Y`` the surface sampled on the stage's grid, ``P`` the
    control net): ``l2`` mean squared distance of ordered pairs (supervised, UB, UM
    after matching); ``chamfer`` and ``hausdorff`` between ``X`` and ``Y``;
    ``laplacian`` the squared Laplacian of the output grid or of the control net
    (``laplacian_on``), or, supervised, the Laplacian difference to the target's;
    ``point_to_surface`` mean squared distance of each input point to its foot point
    on the surface (true projection); ``coverage`` mean squared distance of surface
    samples to their nearest input point (penalises surface where there is no data);
    ``smoothness`` squared second differences of the control net.
    """

    l2: float = _f(0.0, "weight of the L2 loss between ordered point pairs")
    chamfer: float = _f(0.0, "weight of the Chamfer distance between input and surface samples")
    hausdorff: float = _f(0.0, "weight of the Hausdorff distance between input and surface samples")
    laplacian: float = _f(0.0, "weight of the Laplacian loss")
    laplacian_on: LaplacianOn = _f("grid", "apply the unsupervised Laplacian to the output 'grid' or the 'control' net")
    laplacian_boundary: Literal["edge", "zeros", "interior"] = _f(
        "edge", "Laplacian boundary rule: 'zeros' pads with zero vectors like the thesis's conv2d; 'edge' does not pull the border in"
    )
    point_to_surface: float = _f(0.0, "weight of the mean squared point-to-surface distance (projection)")
    coverage: float = _f(0.0, "weight of the surface-to-input one-sided Chamfer term")
    smoothness: float = _f(0.0, "weight of the control-net second-difference energy")

    def active(self) -> dict[str, float]:
        """The non-zero weighted terms, ``{name: weight}``."""
        return {
            k: v for k, v in dataclasses.asdict(self).items() if isinstance(v, float) and v != 0.0
        }


@dataclass
class StageConfig:
    """One run of the generic gradient loop."""

    name: str = _f("refine", "label of the stage in progress reports and the loss curve")
    iters: int = _f(100, "maximum number of iterations of this stage")
    optimizer: OptimizerKind = _f("adam", "optimiser: adam, sgd or lbfgs")
    lr: float = _f(1e-2, "learning rate (lbfgs: its step length)")
    train_control_points: bool = _f(True, "train the control points")
    train_weights: bool = _f(False, "train the weights (kept positive through their logarithm)")
    train_knots: bool = _f(False, "train the interior knots (kept ordered through softmax gaps)")
    loss: LossWeights = field(default_factory=LossWeights, metadata={"help": "loss weights"})
    resolution: tuple[int, int] | None = _f(
        None, "grid on which the surface is sampled for the losses; None: the fit's resolution"
    )
    same_size_as_input: bool = _f(
        False, "sample the surface on a grid with as many points as the input (thesis UB, UC, UM)"
    )
    rematch_every: int = _f(0, "UM: recompute the one-to-one matching every N iterations (0: never)")
    reproject_every: int = _f(1, "recompute foot points for point_to_surface every N iterations")
    loss_threshold: float = _f(0.0, "stop the stage once the loss falls below this value")
    plateau: float = _f(0.0, "stop once the loss fell by less than this fraction over the last 10 iterations (0: never)")
    relocate_knots: bool = _f(
        False,
        "supervised: before the stage, move the interior knots to equidistribute the target's "
        "(p+1)-th differences (de Boor's knot placement)",
    )
    eliminate_control_points: bool = _f(
        False,
        "supervised: solve the control points by (differentiable) least squares at every step and "
        "optimise the knots and weights only (variable projection)",
    )


@dataclass
class InitConfig:
    """The initial surface."""

    kind: InitKind = _f(
        "auto",
        "initial surface: random control points; plane (a sheet on the best-fitting plane); "
        "cylinder (a cage around the principal axis, closed in v); cage (cylinder when the input "
        "looks closed, else plane); lstsq (least squares from a plane or cylinder parametrisation; "
        "supervised: from the grid, at the target's knots and weights); target (supervised: the "
        "target's knots and weights, random control points); auto (lstsq)",
    )
    closed: Literal["auto", "open", "v"] = _f(
        "auto", "surface topology: 'open' sheet, closed in 'v' (periodic seam), or 'auto' detection"
    )
    smoothness: float = _f(1e-3, "relative smoothness weight of the least-squares solves")


@dataclass
class AlternationConfig:
    """Alternating projection (foot points) and linear least squares (control points)."""

    rounds: int = _f(0, "rounds of projection + least squares before the gradient stages")
    smoothness: float = _f(1e-3, "relative weight of the control-net smoothness in each solve")
    tolerance: float = _f(
        1e-7, "stop when a round lowers the mean squared distance by less than this fraction of the first round's"
    )


@dataclass
class FitConfig:
    """Everything one fit needs; a pipeline preset fills it in."""

    pipeline: str = _f("default", "name of the preset this configuration came from")
    supervised: bool = _f(False, "the input is an ordered target grid (supervised pipelines)")
    ctrl: tuple[int, int] | None = _f(
        None, "control points along u and v (closed: v counts the wrapped ones); None: 15 x 15, or a supervised NURBS target's own"
    )
    degree: tuple[int, int] | None = _f(None, "degrees along u and v; None: 3 x 3, or a supervised NURBS target's own")
    resolution: tuple[int, int] = _f((64, 64), "output grid (points.off, metrics) and default training grid")
    init: InitConfig = field(default_factory=InitConfig, metadata={"help": "initial surface"})
    alternation: AlternationConfig = field(default_factory=AlternationConfig, metadata={"help": "alternation"})
    stages: list[StageConfig] = field(default_factory=list, metadata={"help": "gradient stages"})
    normalize: bool = _f(True, "centre and scale the input to a unit bounding-box diagonal while fitting")
    max_points: int = _f(
        20000,
        "fit on at most this many input points, a random subset drawn with the seed (the report still "
        "measures every point); 0: all points",
    )
    seed: int = _f(0, "seed of the fit's own random generator (random initialisation)")

    @property
    def total_iters(self) -> int:
        return sum(s.iters for s in self.stages)

    @property
    def progress_steps(self) -> int:
        """How many progress reports a fit makes at most: the alternation rounds (point
        clouds only) and the iterations."""
        return self.total_iters + (0 if self.supervised else self.alternation.rounds)

    def validate(self) -> "FitConfig":
        """Raise an OptionError naming the field when a value is out of range."""
        for name, pair, low in (("ctrl", self.ctrl, 2), ("degree", self.degree, 1), ("resolution", self.resolution, 2)):
            if pair is None and name != "resolution":
                continue
            if pair is None or len(pair) != 2 or any(int(x) != x or x < low for x in pair):
                raise OptionError(f"{name}: expected two integers >= {low}, got {tuple(pair)}")
        if self.degree is not None and max(self.degree) > MAX_DEGREE:
            raise OptionError(f"degree: expected two integers in [1, {MAX_DEGREE}], got {tuple(self.degree)}")
        for a, (n, p) in enumerate(zip(self.ctrl or (15, 15), self.degree or (3, 3))):
            if n < p + 1:
                raise OptionError(f"ctrl: degree {p} along {'uv'[a]} needs at least {p + 1} control points, got {n}")
        if self.init.kind not in INIT_KINDS:
            raise OptionError(f"init: expected one of {', '.join(INIT_KINDS)}, got {self.init.kind!r}")
        if self.init.closed not in CLOSED:
            raise OptionError(f"closed: expected one of {', '.join(CLOSED)}, got {self.init.closed!r}")
        sheet, wrap = ("plane", "random"), ("cylinder",)
        if self.init.closed == "v" and self.init.kind in sheet or self.init.closed == "open" and self.init.kind in wrap:
            raise OptionError(
                f"closed: the {self.init.kind} start is {'an open sheet' if self.init.kind in sheet else 'closed in v'}, "
                f"not {self.init.closed!r}; use init auto, lstsq or cage, which follow closed"
            )
        if self.init.closed == "v" and (self.ctrl or (15, 15))[1] < 2 * (self.degree or (3, 3))[1] + 1:
            raise OptionError(
                "ctrl: a surface closed in v needs at least 2 * degree + 1 control points along v, "
                f"got {(self.ctrl or (15, 15))[1]}"
            )
        if int(self.max_points) != self.max_points or self.max_points < 0 or 0 < self.max_points < 4:
            raise OptionError(f"max_points: expected 0 (all points) or an integer >= 4, got {self.max_points!r}")
        if not 0 <= self.alternation.rounds <= MAX_ITERS:
            raise OptionError(f"alternation rounds must be in [0, {MAX_ITERS:,}], got {self.alternation.rounds}")
        for s in self.stages:
            if s.optimizer not in OPTIMIZERS:
                raise OptionError(f"stage {s.name}: optimizer must be one of {', '.join(OPTIMIZERS)}, got {s.optimizer!r}")
            if not 0 <= s.iters <= MAX_ITERS:
                raise OptionError(f"stage {s.name}: iters must be in [0, {MAX_ITERS:,}], got {s.iters}")
            if not LR_RANGE[0] < s.lr <= LR_RANGE[1]:
                raise OptionError(f"stage {s.name}: lr must be in ({LR_RANGE[0]:g}, {LR_RANGE[1]:g}], got {s.lr:g}")
            if s.loss.laplacian_on not in LAPLACIAN_ON:
                raise OptionError(f"stage {s.name}: laplacian_on must be grid or control, got {s.loss.laplacian_on!r}")
            if not (s.train_control_points or s.train_weights or s.train_knots):
                raise OptionError(f"stage {s.name}: nothing to train (control points, weights and knots all off)")
            if not s.loss.active():
                raise OptionError(f"stage {s.name}: every loss weight is zero")
            if s.resolution is not None and (len(s.resolution) != 2 or min(s.resolution) < 2):
                raise OptionError(f"stage {s.name}: resolution must be two integers >= 2, got {s.resolution}")
        return self

    def with_iters(self, iters: int) -> "FitConfig":
        """A copy whose stages share ``iters`` iterations in the preset's proportions."""
        if not 0 <= iters <= MAX_ITERS:
            raise OptionError(f"--iters must be in [0, {MAX_ITERS:,}], got {iters}")
        cfg = dataclasses.replace(self, stages=[dataclasses.replace(s) for s in self.stages])
        total = self.total_iters
        if not cfg.stages or total == 0:
            return cfg
        left = iters
        for i, s in enumerate(cfg.stages):
            share = left if i == len(cfg.stages) - 1 else round(iters * self.stages[i].iters / total)
            s.iters = max(0, min(share, left))
            left -= s.iters
        return cfg


def config_to_dict(cfg: Any) -> dict:
    """The configuration as plain JSON data (tuples become lists)."""
    return dataclasses.asdict(cfg)


def config_from_dict(data: dict) -> FitConfig:
    """Inverse of :func:`config_to_dict` (unknown keys raise an OptionError).

    The top-level ``device`` and ``dtype`` of older files are ignored: a fit runs on its
    input's device and dtype.
    """

    def build(cls, d):
        if not isinstance(d, dict):
            raise OptionError(f"{cls.__name__}: expected an object, got {type(d).__name__}")
        names = {f.name: f for f in dataclasses.fields(cls)}
        unknown = set(d) - set(names)
        if unknown:
            raise OptionError(f"{cls.__name__}: unknown field(s) {', '.join(sorted(unknown))}")
        kw = {}
        for k, v in d.items():
            if k == "loss":
                v = build(LossWeights, v)
            elif k == "init":
                v = build(InitConfig, v)
            elif k == "alternation":
                v = build(AlternationConfig, v)
            elif k == "stages":
                v = [build(StageConfig, s) for s in v]
            elif isinstance(v, list):
                v = tuple(v)
            kw[k] = v
        return cls(**kw)

    if isinstance(data, dict) and ("device" in data or "dtype" in data):
        # config.json files written before dtype and device followed the input.
        data = {k: v for k, v in data.items() if k not in ("device", "dtype")}
    return build(FitConfig, data)

"""Typed configuration of one volume fit (:func:`nurbskit.volume.fit_silhouettes`).

One dataclass, :class:`VolumeFitConfig`; each field's ``metadata`` holds its help text,
its allowed range and, where it differs from the field's name, its command-line flag:
``nurbskit volume`` generates its options from these fields
(:func:`nurbskit.cli.volume_command.register`), and :meth:`VolumeFitConfig.validate`
checks the same ranges. Named presets (:data:`PRESETS`): ``default``, the best that
runs in seconds (an 80^3 grid, the field started from the visual hull, 30 iterations:
IoU >= 0.95 in every view on consistent drawings), and ``paper``, the setting of W. Li,
"Multi-view NURBS Volume" (50^3 control values, 20^3 grid, weights 0.1 / 0.9, isovalue
0.5, 100 iterations, values 0 and weights 1 at the start).

Why 80^3: the fit follows the visual hull sampled on the grid, and that sampling bounds
the IoU. Measured on consistent drawings (a sphere joined to a box, 256 px), the hull's
own mesh reaches 0.78-0.81 at 20^3, 0.92-0.94 at 48^3, 0.94-0.95 at 64^3 and 0.96 at
96^3; the default fit reaches 0.97 in every view after 10 iterations.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .._budget import available_bytes, human_bytes, largest_fitting
from ..errors import OptionError

LOSSES = ("paper", "silhouette")
INITS = ("auto", "zeros", "hull")
SMOOTH_SAMPLES = ("auto", "grid")
#: The largest side of any grid or control net (beyond it the memory check speaks anyway).
MAX_SIDE = 4096


def _f(default, help: str, *, low=None, high=None, choices=None, flag=None, low_open=False):
    """A field whose metadata carries its help, range (``[low, high]``, ``(low, high]`` when
    ``low_open``), choices and command-line flag."""
    meta = {"help": help, "low": low, "high": high, "choices": choices, "flag": flag, "low_open": low_open}
    return field(default=default, metadata=meta)


@dataclass
class VolumeFitConfig:
    """Settings of :func:`~nurbskit.volume.fit_silhouettes` (saved in every report).

    Sizes take one integer (the same along x, y and z) or three.
    """

    control_size: tuple[int, int, int] = _f((50, 50, 50), "control values per axis (x, y, z); the paper uses 50",
                                            low=2, high=MAX_SIDE)
    grid: tuple[int, int, int] = _f((80, 80, 80), "grid points per axis where the costs are evaluated "
                                    "(the paper's 'cell size': 20)", low=2, high=MAX_SIDE)
    degree: int = _f(2, "B-spline degree in every direction (the paper's order 3 = degree 2)", low=1, high=7)
    iterations: int = _f(30, "maximum L-BFGS iterations; it stops earlier when the cost stops changing",
                         low=0, high=100_000, flag="iters")
    isovalue: float = _f(0.5, "the solid is {f >= isovalue}; the field is fitted to the solid's indicator (0 "
                         "outside, 1 inside), so 0 or below makes the whole cube solid and above 1 nothing",
                         low=0.0, high=1.0, low_open=True)
    shape_weight: float = _f(0.1, "weight of the shape cost", low=0.0, high=1e6, low_open=True)
    smooth_weight: float = _f(0.9, "weight of the smoothness cost", low=0.0, high=1e6)
    loss: str = _f("paper", "shape cost: 'paper' (the volume against the visual hull) or 'silhouette' "
                   "(projections against the drawings)", choices=LOSSES)
    init: str = _f("hull", "initial field: 'zeros' (the paper: values 0, weights 1), 'hull' (values from the "
                   "visual hull), or 'auto' (zeros for the paper loss, hull for the silhouette loss)", choices=INITS)
    sharpness: float = _f(20.0, "silhouette loss: slope of the soft projection sigmoid(sharpness (max f - isovalue))",
                          low=0.0, high=1e6, low_open=True)
    laplacian_unit: float = _f(0.01, "length unit of the smoothness cost's Laplacian (unit^2 lap f), as a fraction "
                               "of the cube", low=0.0, high=1.0, low_open=True)
    smooth_samples: str = _f("auto", "where the smoothness cost is sampled: 'grid' (the fitting grid, as the paper) "
                             "or 'auto' (the knot-span midpoints along an axis where the grid is finer than the "
                             "control net's knot spans)", choices=SMOOTH_SAMPLES)
    tolerance: float = _f(1e-9, "L-BFGS stops when the cost changes less than this between iterations (0: never)",
                          low=0.0, high=1.0)
    mesh_resolution: tuple[int, int, int] | None = _f(None, "grid for marching cubes (default: --grid)",
                                                      low=2, high=MAX_SIDE)
    iou_resolution: int = _f(256, "side of the square raster on which projections are compared with the drawings",
                             low=2, high=2048)

    @property
    def resolved_init(self) -> str:
        """``init`` with 'auto' resolved by the loss."""
        if self.init != "auto":
            return self.init
        return "hull" if self.loss == "silhouette" else "zeros"

    @property
    def resolved_mesh_resolution(self) -> tuple[int, int, int]:
        return tuple(self.grid if self.mesh_resolution is None else self.mesh_resolution)

    def validate(self) -> "VolumeFitConfig":
        """Normalise sizes to triples and raise an OptionError (naming the field and its range) otherwise."""
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            meta = f.metadata
            if f.name in ("control_size", "grid", "mesh_resolution"):
                if value is None and f.name == "mesh_resolution":
                    continue
                # One range per field, its metadata's (the option's too); the degree's own
                # requirement on the control size is a separate check, said as such below.
                setattr(self, f.name, _triple(f.name, value, meta["low"], meta["high"]))
            elif meta["choices"] is not None:
                if value not in meta["choices"]:
                    raise OptionError(f"{f.name} must be one of {list(meta['choices'])}, got {value!r}")
            elif isinstance(f.default, int):
                if not _is_int(value) or not meta["low"] <= value <= meta["high"]:
                    raise OptionError(f"{f.name} must be an integer in [{meta['low']}, {meta['high']:,}], got {value!r}")
                setattr(self, f.name, int(value))
            else:
                if isinstance(value, bool) or not isinstance(value, (int, float, np.floating)) or not math.isfinite(value):
                    raise OptionError(f"{f.name} must be a finite number, got {value!r}")
                low, high = meta["low"], meta["high"]
                ok = (value > low if meta["low_open"] else value >= low) and value <= high
                if not ok:
                    raise OptionError(
                        f"{f.name} must be in {'(' if meta['low_open'] else '['}{low:g}, {high:g}], got {value:g}"
                        + (" (without it nothing ties the solid to the drawings)" if f.name == "shape_weight" else "")
                    )
                setattr(self, f.name, float(value))
        if min(self.control_size) < self.degree + 1:
            high = next(f.metadata["high"] for f in dataclasses.fields(self) if f.name == "control_size")
            raise OptionError(
                f"control_size must be one or three integers in [{self.degree + 1}, {high}] with degree "
                f"{self.degree} (at least degree + 1 per axis), got {self.control_size!r}; raise control_size "
                "or lower degree"
            )
        return self

    def replace(self, **changes) -> "VolumeFitConfig":
        """A validated copy with ``changes``."""
        return dataclasses.replace(self, **changes).validate()


def _is_int(value) -> bool:
    return isinstance(value, (int, np.integer)) and not isinstance(value, bool)


def _triple(name: str, value, low: int, high: int) -> tuple[int, int, int]:
    if _is_int(value):
        value = (int(value),) * 3
    try:
        value = tuple(value)
    except TypeError:
        raise OptionError(f"{name} must be an integer or three integers, got {value!r}") from None
    if len(value) != 3 or not all(_is_int(v) for v in value):
        raise OptionError(f"{name} must be one or three integers in [{low}, {high}], got {value!r}")
    if min(value) < low or max(value) > high:
        raise OptionError(f"{name} must be one or three integers in [{low}, {high}], got {value!r}")
    return tuple(int(v) for v in value)


def default_config() -> VolumeFitConfig:
    """Ours: the best that runs in seconds (80^3 grid, hull start, 30 iterations)."""
    return VolumeFitConfig().validate()


def paper_config() -> VolumeFitConfig:
    """The paper's setting exactly: 50^3 control values, 20^3 grid, paper loss, zeros start."""
    return VolumeFitConfig(grid=(20, 20, 20), iterations=100, init="zeros", smooth_samples="grid").validate()


PRESETS = {"default": default_config, "paper": paper_config}


def get_preset(name: str) -> VolumeFitConfig:
    """A fresh configuration of the preset ``name``."""
    if name not in PRESETS:
        raise OptionError(f"unknown volume preset {name!r}; choose one of {', '.join(PRESETS)}")
    return PRESETS[name]()


def config_to_dict(cfg: VolumeFitConfig) -> dict[str, Any]:
    """JSON-ready (tuples become lists)."""
    return {k: list(v) if isinstance(v, tuple) else v for k, v in dataclasses.asdict(cfg).items()}


# ---- memory ----------------------------------------------------------------------------

def fit_bytes(cfg: VolumeFitConfig, item: int = 4) -> float:
    """An upper estimate of the bytes of the largest allocations of one volume fit.

    Terms: the control values and weights with their gradients and L-BFGS's history
    (10 pairs); the field on the grid with its derivatives, Laplacian and autograd
    intermediates, and the partial mode products (grid x control); marching cubes on
    the mesh grid (float64, padded); the IoU report's visual hull on an
    ``iou_resolution^3`` grid.
    """
    n = float(np.prod(cfg.control_size))
    g = float(np.prod(cfg.grid))
    (gx, gy, _), (_, ny, nz) = cfg.grid, cfg.control_size
    partial = gx * ny * nz + gx * gy * nz
    m = float(np.prod(cfg.resolved_mesh_resolution))
    r = float(cfg.iou_resolution) ** 3
    return item * (n * 52 + g * 40 + partial * 20) + 8 * m * 6 + 4 * r * 5


def check_fit_size(cfg: VolumeFitConfig, item: int = 4, *, budget: float | None = None) -> None:
    """Refuse, before any work, a configuration whose allocations would not fit in memory.

    The message names the sizes and the largest control size, grid and mesh resolution
    that fit with the others unchanged.
    """
    budget = available_bytes() if budget is None else budget
    need = fit_bytes(cfg, item)
    if need <= budget:
        return
    hints = []
    for name, flag in (("control_size", "--control-size"), ("grid", "--grid"), ("mesh_resolution", "--mesh-resolution")):
        current = max(getattr(cfg, name) or cfg.grid)
        low = cfg.degree + 1 if name == "control_size" else 2
        side = largest_fitting(lambda k: fit_bytes(dataclasses.replace(cfg, **{name: (k, k, k)}), item), budget, low, current)
        if side is not None and side < current:
            hints.append(f"{flag} {side}")
    sizes = (
        f"control size {'x'.join(map(str, cfg.control_size))}, grid {'x'.join(map(str, cfg.grid))}, "
        f"mesh resolution {'x'.join(map(str, cfg.resolved_mesh_resolution))}"
    )
    fits = (" or ".join(hints) + " fits") if hints else "reduce the sizes"
    raise OptionError(
        f"a volume fit with {sizes} needs about {human_bytes(need)} of memory but about "
        f"{human_bytes(budget)} is available; {fits}"
    )

"""The fitting tabs: Unsupervised, Supervised, Patches, Revolve / Extrude, Curves from
images, Volume from drawings.

Each tab is a thin layer over the library's public API: it reads with
``nurbskit.io``, samples meshes with ``nurbskit.sample_mesh``, fits with
``nurbskit.fit_surface`` / ``nurbskit.fit_patches`` / ``nurbskit.shapes.fit_shape`` /
``nurbskit.curves_from_image`` / ``nurbskit.fit_silhouettes``, reports with
``nurbskit.fit.fit_report``, and draws with :mod:`.scene`. Every tab is a
:class:`~.app.TabBase` (status, loader, parameters, run panel, export, in that order);
the three that fit a point cloud share :class:`CloudTab`.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from ..errors import InputError, OptionError
from . import choices
from .app import TabBase, iteration_progress, markdown_table, read_upload
from .scene import RESULT_COLOR, SURFACE_COLOR, SplineView, colormap, diagonal, draw_mesh, draw_points


def f64(obj):
    """A nurbskit object (or tensor) detached, in float64.

    torch is imported here and in the other methods that use it, not at the top: the tabs
    are built before the fitting code has loaded (see :mod:`.choices`).
    """
    import torch

    return obj.detach().to(torch.float64)


def _apply_iterations(cfg, iterations: int):
    """Scale the stages' iteration counts so that they add up to ``iterations`` (0: keep)."""
    total = cfg.total_iters
    if iterations <= 0 or total <= 0:
        return cfg
    stages = []
    left = iterations
    for i, s in enumerate(cfg.stages):
        n = left if i == len(cfg.stages) - 1 else max(1, round(iterations * s.iters / total))
        n = max(0, min(n, left))
        left -= n
        stages.append(dataclasses.replace(s, iters=n))
    return dataclasses.replace(cfg, stages=stages)


def _apply_loss_weights(cfg, text: str):
    """Set loss weights of every stage from ``"chamfer=1 laplacian=0.001"`` (blank: keep)."""
    from ..fit.config import LossWeights

    text = text.strip()
    if not text:
        return cfg
    names = {f.name for f in dataclasses.fields(LossWeights) if f.type in ("float", float)}
    changes = {}
    for item in text.replace(",", " ").split():
        key, sep, value = item.partition("=")
        if not sep or key not in names:
            raise OptionError(f"loss weights: expected name=value with names {', '.join(sorted(names))}; got {item!r}")
        try:
            changes[key] = float(value)
        except ValueError:
            raise OptionError(f"loss weights: {key} needs a number, got {value!r}") from None
        if not changes[key] >= 0:
            raise OptionError(f"loss weights: {key} must be >= 0, got {value}")
    stages = [dataclasses.replace(s, loss=dataclasses.replace(s.loss, **changes)) for s in cfg.stages]
    return dataclasses.replace(cfg, stages=stages)


def _metrics_markdown(report: dict) -> str:
    m, mn = report.get("metrics", {}), report.get("metrics_normalized", {})
    rows = [
        ("pipeline", report.get("pipeline")),
        ("iterations", report.get("iterations")),
        ("seconds", f"{report.get('seconds', 0.0):.2f}"),
        ("Chamfer", f"{m.get('chamfer', float('nan')):.4g} ({mn.get('chamfer', float('nan')):.3g} of diag.)"),
        ("Hausdorff", f"{m.get('hausdorff', float('nan')):.4g} ({mn.get('hausdorff', float('nan')):.3g} of diag.)"),
        ("Laplacian", f"{m.get('laplacian', float('nan')):.4g}"),
        ("combined (CD + HD + 0.1 LD)", f"{mn.get('combined', float('nan')):.4g}"),
    ]
    if "rms" in report:
        rows.append(("RMS to target", f"{report['rms']:.4g}"))
    return markdown_table("Metrics", rows)


def _read_cloud(path: Path, name: str, count: int):
    """``(points (N, 3) float64, what)`` from a point cloud, or ``count`` Poisson samples of a mesh."""
    import nurbskit

    try:
        mesh = nurbskit.io.read_mesh(path)
    except InputError as exc:
        if "no faces" not in str(exc) and "point cloud" not in str(exc):
            raise InputError(f"{name}: {exc}".replace(str(path), name)) from None
        mesh = None
    except Exception as exc:  # noqa: BLE001 - a reader's own words, with the client's name
        raise InputError(f"{name}: not a readable point cloud or mesh ({str(exc).replace(str(path), name)})") from None
    if mesh is not None:
        pts = nurbskit.sample_mesh(mesh.vertices, mesh.faces, count, method="poisson", seed=0)
        return np.asarray(pts, dtype=np.float64), f"mesh, {count:,} Poisson samples"
    cloud = nurbskit.io.read_points(path)
    return np.asarray(cloud.points, dtype=np.float64), "cloud"


class CloudTab(TabBase):
    """A tab that fits a point cloud, or a mesh Poisson-sampled to ``count`` points.

    A subclass sets ``samples`` (the default count), ``min_points`` and ``purpose`` (for
    the message when a cloud is too small), and implements :meth:`forget` (drop the
    last result and its drawing when a new cloud arrives).
    """

    stem = "cloud"
    samples = 2000
    min_points = 4
    purpose = "a surface fit"

    def __init__(self, session, ui):
        super().__init__(session, ui)
        self.points: np.ndarray | None = None
        self.cloud_handle = None
        self.count = ui.add_number("Poisson samples of a mesh", self.samples, min=max(10, self.min_points),
                                   max=200000, step=1)
        self.add_loader("Load cloud or mesh")

    def _read(self, path: Path, name: str):
        return _read_cloud(path, name, int(self.count.value))

    def forget(self) -> None:
        """Drop the last result and its drawing (a new cloud was loaded)."""

    def _loaded(self, data, name: str) -> None:
        points, what = data
        if points.shape[0] < self.min_points:
            raise InputError(f"{name}: {points.shape[0]} points; {self.purpose} needs at least {self.min_points}")
        self.points, self.name = points, Path(name).stem or self.stem
        self.session.focus(self.label)
        self.forget()
        self.cloud_handle = draw_points(self.session.client.scene, f"/{self.scene}/input", points)
        self.session.frame(points)
        self.status.info(f"loaded {name}: {points.shape[0]:,} points ({what})")

    def need_points(self) -> np.ndarray:
        if self.points is None:
            raise OptionError("load a point cloud or mesh first")
        return self.points


# ---- Unsupervised -----------------------------------------------------------------------

class UnsupervisedTab(CloudTab):
    """Load a cloud or mesh, choose a pipeline, fit, look at the result."""

    label = "Unsupervised"
    scene = "unsupervised"

    def __init__(self, session, ui):
        self.result = None
        super().__init__(session, ui)
        names = choices.pipelines(supervised=False)
        self.pipeline = ui.add_dropdown("Pipeline", names, initial_value="default" if "default" in names else names[0])
        self.ctrl = ui.add_vector2("Control grid", (15, 15), min=(2, 2), max=(64, 64), step=1)
        self.degree = ui.add_vector2("Degree", (3, 3), min=(1, 1), max=(7, 7), step=1)
        self.iters = ui.add_number("Iterations (0: the pipeline's)", 0, min=0, max=100000, step=1)
        self.weights = ui.add_text("Loss weights (e.g. chamfer=1 laplacian=0.001; blank: the pipeline's)", "")
        self.add_device()
        self.show_error = ui.add_checkbox("Colour points by error", True)
        self.add_runner("Fit")
        self.add_export()
        self.surface_view = SplineView(session.client.scene, "/unsupervised/surface", RESULT_COLOR)

    def forget(self) -> None:
        self.result = None
        self.surface_view.clear()

    # fitting
    def config(self):
        from ..fit.pipelines import get_pipeline

        cfg = get_pipeline(self.pipeline.value)
        cfg = dataclasses.replace(cfg, ctrl=tuple(int(x) for x in self.ctrl.value),
                                  degree=tuple(int(x) for x in self.degree.value))
        cfg = _apply_loss_weights(cfg, self.weights.value)
        return _apply_iterations(cfg, int(self.iters.value)).validate()

    def _fit(self, progress, stop):
        import nurbskit

        points = self.need_points()
        cfg = self.config()
        progress(0.0)
        # the fit runs where its inputs are: the device choice only moves the points
        import torch

        points = torch.as_tensor(points, dtype=torch.float64).to(self.device.value)
        result = nurbskit.fit_surface(points, cfg, callback=iteration_progress(progress, cfg.progress_steps))
        from ..fit import fit_report

        report = fit_report(result, distances=True)
        return result, report

    def _done(self, out) -> None:
        result, report = out
        self.result = result
        self.session.focus(self.label)
        self.surface_view.draw(f64(result.surface))
        if self.show_error.value:
            d = report["_distances"].detach().cpu().numpy()
            colors = colormap(d, 0.0, float(np.percentile(d, 99)) or 1.0)
            pts = result.points.detach().cpu().numpy()
            self.cloud_handle = draw_points(self.session.client.scene, "/unsupervised/input", pts, colors)
        self.runner.metrics.content = _metrics_markdown(report)
        self.status.info(f"fit finished: {report['iterations']} iterations in {report['seconds']:.2f} s")

    def shown(self):
        surface = None if self.result is None else f64(self.result.surface)
        return surface, None, f"{self.name}-{self.pipeline.value}"


def build_unsupervised(session, ui):
    return UnsupervisedTab(session, ui)


# ---- Supervised -------------------------------------------------------------------------

class SupervisedTab(TabBase):
    """Load a NURBS (nurbskit/geomdl JSON, .ctrlpts + .weights, .3dm), fit it, compare."""

    label = "Supervised"
    scene = "supervised"
    stem = "target"

    def __init__(self, session, ui):
        super().__init__(session, ui)
        self.target = None
        self.result = None
        ui.add_markdown("`.ctrlpts` files take sizes and degrees below (or a side `<file>.json`); "
                        "a `.weights` file beside one in the workdir is read with it.")
        self.sizes = ui.add_text("Sizes of a .ctrlpts grid", "")
        self.degrees = ui.add_text("Degrees of a .ctrlpts grid", "3 3")
        self.weights = None  # from an uploaded .weights file, for the next uploaded .ctrlpts
        self.weights_upload = ui.add_upload_button("Upload .weights (for an uploaded .ctrlpts)")
        self.weights_upload.on_upload(lambda event: self.guard(self._weights_uploaded))
        session.upload_status[self.weights_upload._impl.uuid] = self.status
        self.add_loader("Load NURBS")
        names = choices.pipelines(supervised=True)
        self.pipeline = ui.add_dropdown("Pipeline", names, initial_value="SC" if "SC" in names else names[0])
        self.resolution = ui.add_vector2("Target grid", (32, 32), min=(2, 2), max=(256, 256), step=1)
        self.iters = ui.add_number("Iterations (0: the pipeline's)", 0, min=0, max=100000, step=1)
        self.add_device()
        self.add_runner("Fit")
        self.add_export()
        scene = session.client.scene
        self.truth_view = SplineView(scene, "/supervised/truth", SURFACE_COLOR)
        self.result_view = SplineView(scene, "/supervised/result", RESULT_COLOR)

    def _weights_uploaded(self) -> None:
        import nurbskit

        def read(path: Path, name: str):
            try:
                return np.asarray(nurbskit.io.read_weights(path), dtype=np.float64)
            except Exception as exc:  # noqa: BLE001
                raise InputError(str(exc).replace(str(path), name)) from None

        self.weights, name = read_upload(self.session, self.weights_upload.value, read)
        self.status.info(f"{name}: {self.weights.size} weights, used by the next .ctrlpts upload")

    def _read(self, path: Path, name: str):
        import nurbskit

        options = {}
        if Path(name).suffix.lower() == ".ctrlpts" and self.weights is not None and ".studio" in path.parts:
            options["weights"] = self.weights  # an upload has no sibling .weights file
        if Path(name).suffix.lower() in (".ctrlpts", ".cptw"):
            if self.sizes.value.strip():
                options["sizes"] = [int(x) for x in self.sizes.value.replace(",", " ").split()]
            if self.degrees.value.strip():
                options["degrees"] = [int(x) for x in self.degrees.value.replace(",", " ").split()]
        try:
            # names come from the client: the file's companions must lie in the workdir too
            obj = nurbskit.io.read_nurbs(path, within=self.session.workdir.root, **options)
        except (InputError, OptionError) as exc:
            raise type(exc)(str(exc).replace(str(path), name)) from None
        except Exception as exc:  # noqa: BLE001
            raise InputError(f"{name}: not a readable NURBS file ({exc})") from None
        if obj.para_dim != 2 or obj.control_points.shape[-1] != 3:
            raise InputError(f"{name}: holds a {obj.kind} in {obj.control_points.shape[-1]}-D; "
                             "the supervised pipelines fit 3-D surfaces")
        return obj

    def _loaded(self, obj, name: str) -> None:
        self.target, self.result, self.name = f64(obj), None, Path(name).stem or "target"
        self.session.focus(self.label)
        self.result_view.clear()
        self.truth_view.draw(self.target)
        self.session.frame(self.target.control_points.numpy())
        self.status.info(f"loaded {name}: {obj.kind} {tuple(obj.sizes)} degrees {tuple(obj.degrees)}")

    def _fit(self, progress, stop):
        import nurbskit
        from ..fit import fit_report
        from ..fit.pipelines import get_pipeline

        if self.target is None:
            raise OptionError("load a NURBS surface first")
        cfg = dataclasses.replace(get_pipeline(self.pipeline.value),
                                  resolution=tuple(int(x) for x in self.resolution.value))
        cfg = _apply_iterations(cfg, int(self.iters.value)).validate()
        progress(0.0)
        result = nurbskit.fit_surface(config=cfg, target_surface=self.target.to(device=self.device.value),
                                      callback=iteration_progress(progress, cfg.progress_steps))
        return result, fit_report(result)

    def _done(self, out) -> None:
        result, report = out
        self.result = result
        self.session.focus(self.label)
        surface = f64(result.surface)
        # side by side: the result to the right of the ground truth
        shift = 1.2 * diagonal(self.target.control_points.numpy())
        self.result_view.offset = np.array([shift, 0.0, 0.0])
        self.result_view.shape_key = None
        self.result_view.draw(surface)
        self.session.frame(np.concatenate([self.target.control_points.numpy().reshape(-1, 3),
                                           surface.control_points.numpy().reshape(-1, 3) + [shift, 0.0, 0.0]]))
        self.runner.metrics.content = _metrics_markdown(report)
        self.status.info(f"fit finished: RMS {report.get('rms', float('nan')):.3g} to the target; "
                         "ground truth left (blue), result right (orange)")

    def shown(self):
        obj = f64(self.result.surface) if self.result is not None else self.target
        return obj, None, f"{self.name}-{self.pipeline.value}"


def build_supervised(session, ui):
    return SupervisedTab(session, ui)


# ---- Patches ------------------------------------------------------------------------------

# one colour per patch, cycled (tab10-like, readable on the white background)
PATCH_COLORS = (
    (31, 119, 180), (255, 127, 14), (44, 160, 44), (214, 39, 40), (148, 103, 189),
    (140, 86, 75), (227, 119, 194), (127, 127, 127), (188, 189, 34), (23, 190, 207),
)


def patch_color(i: int) -> tuple[int, int, int]:
    return PATCH_COLORS[i % len(PATCH_COLORS)]


def _patches_markdown(result) -> str:
    """The metrics of a :class:`~nurbskit.patches.PatchSet` (percentages; |N| a count)."""
    m = result.metrics
    rows = [
        (r"\|N\| (patches)",  # pipes escaped: they would split the table row
         f"{int(m.get('N', len(result)))}"),
        ("completeness", f"{m.get('completeness', float('nan')):.1f} %"),
        ("P_cov^i (input covered)", f"{m.get('P_cov_i', float('nan')):.1f} %"),
        ("P_cov^o (output covered)", f"{m.get('P_cov_o', float('nan')):.1f} %"),
        ("E_fid (mean inlier distance / eps)", f"{m.get('E_fid', float('nan')):.1f} %"),
        ("eps", f"{result.eps:.4g} ({m.get('eps', float('nan')):.3g} of diag.)"),
        ("trimmed faces", f"{len(result.faces)}"),
    ]
    if result.timings:
        rows.append(("seconds", f"{sum(float(v) for v in result.timings.values()):.2f}"))
    return markdown_table("Metrics", rows)


def combined_mesh(result) -> tuple[np.ndarray, np.ndarray]:
    """All patches' trimmed meshes as one ``vertices (V, 3)``, ``faces (F, 3)``."""
    verts, faces, base = [], [], 0
    for patch in result.patches:
        v, f = np.asarray(patch.mesh[0], np.float64).reshape(-1, 3), np.asarray(patch.mesh[1], np.int64).reshape(-1, 3)
        verts.append(v)
        faces.append(f + base)
        base += len(v)
    if not verts:
        return np.zeros((0, 3)), np.zeros((0, 3), np.int64)
    return np.concatenate(verts), np.concatenate(faces)


class PatchesTab(CloudTab):
    """Load a cloud or mesh, fit a few trimmed NURBS patches (``nurbskit.fit_patches``)."""

    label = "Patches"
    scene = "patches"
    samples = 3000
    min_points = 20
    purpose = "multi-patch fitting"

    def __init__(self, session, ui):
        self.result = None
        self.handles: list = []
        super().__init__(session, ui)
        self.eps = ui.add_number("eps (fraction of the diagonal)", 0.01, min=1e-4, max=0.5, step=1e-4)
        self.weights = ui.add_vector3("Weights (fidelity, simplicity, coverage)", (0.3, 0.4, 0.3),
                                      min=(0.0, 0.0, 0.0), max=(10.0, 10.0, 10.0), step=0.05)
        self.max_ctrl = ui.add_number("Max control grid per patch", 12, min=4, max=64, step=1)
        self.final_iters = ui.add_number("Refinement iterations per final patch", 15, min=0, max=1000, step=1)
        self.add_device()
        self.show_points = ui.add_checkbox("Show the input points", True)
        self.add_runner("Fit patches")
        self.add_export()

    def _clear(self) -> None:
        for h in self.handles:
            h.remove()
        self.handles = []

    def forget(self) -> None:
        self.result = None
        self._clear()

    def config(self):
        from ..patches import PatchConfig

        max_ctrl = int(self.max_ctrl.value)
        return PatchConfig(eps=float(self.eps.value), weights=tuple(float(w) for w in self.weights.value),
                           max_ctrl=max_ctrl, min_ctrl=min(PatchConfig.min_ctrl, max_ctrl),
                           final_iters=int(self.final_iters.value), device=self.device.value).validate()

    def _fit(self, progress, stop):
        import nurbskit

        points = self.need_points()
        cfg = self.config()
        progress(0.0)

        def report(stage, done, total):
            # the stages report their own counts; the bar shows the share of the current one
            progress(min(0.99, done / max(1, total)))

        return nurbskit.fit_patches(points, normals=None, config=cfg, progress=report)

    def _done(self, result) -> None:
        self.result = result
        self.session.focus(self.label)
        self._clear()
        scene = self.session.client.scene
        for i, patch in enumerate(result.patches):
            v, f = patch.mesh
            if len(f):
                self.handles.append(draw_mesh(scene, f"/patches/patch{i}", v, f, color=patch_color(i)))
        if self.show_points.value:
            colors = np.array([(60, 60, 60)] * len(result.points), dtype=np.uint8)
            inl = result.labels >= 0
            colors[inl] = np.array([patch_color(int(k)) for k in result.labels[inl]], dtype=np.uint8)
            self.handles.append(draw_points(scene, "/patches/input", result.points, colors))
        v, _ = combined_mesh(result)
        self.session.frame(v if len(v) else result.points)
        self.runner.metrics.content = _patches_markdown(result)
        self.status.info(f"fit finished: {len(result)} patches, {len(result.faces)} trimmed faces")

    def shown(self):
        if self.result is None:
            return None, None, f"{self.name}-patches"
        return self.result.faces, combined_mesh(self.result), f"{self.name}-patches"


def build_patches(session, ui):
    return PatchesTab(session, ui)


# ---- Revolve / Extrude ------------------------------------------------------------------------

AXIS_COLOR = (20, 150, 60)  # green: the control net is red


def axis_segment(fit, points: np.ndarray) -> np.ndarray | None:
    """The fitted axis (or extrusion direction) as one segment ``(1, 2, 3)`` spanning the points."""
    if fit.axis is None:
        return None
    p = np.asarray(fit.axis["point"], np.float64)
    d = np.asarray(fit.axis["direction"], np.float64)
    d = d / (np.linalg.norm(d) or 1.0)
    t = (np.asarray(points, np.float64).reshape(-1, 3) - p) @ d
    pad = 0.15 * (float(t.max() - t.min()) or 1.0)
    return np.stack([p + (t.min() - pad) * d, p + (t.max() + pad) * d])[None]


def _shape_markdown(fit) -> str:
    """The report of a :class:`~nurbskit.shapes.ShapeFit`."""
    rows = [("kind", fit.kind)]
    if fit.axis is not None:
        p, d = fit.axis["point"], fit.axis["direction"]
        rows.append(("axis point" if fit.kind == "revolution" else "point", ", ".join(f"{x:.4g}" for x in p)))
        rows.append(("axis direction" if fit.kind == "revolution" else "extrusion direction",
                     ", ".join(f"{x:.4g}" for x in d)))
    rows += [
        ("mean distance", f"{fit.distance_mean:.3g} of diag. ({fit.distance_mean * fit.diagonal:.4g})"),
        ("95th percentile distance", f"{fit.distance_p95:.3g} of diag."),
        ("control grid", " x ".join(str(n) for n in fit.surface.sizes)),
        ("seconds", f"{fit.seconds:.2f}"),
    ]
    for k, v in (fit.candidates or {}).items():
        if isinstance(v, (int, float)):
            rows.append((f"candidate {k}: mean distance", f"{v:.3g} of diag."))
    return markdown_table("Report", rows) + (f"\n\n{fit.reason}" if fit.reason else "")


class ShapeTab(CloudTab):
    """Load a cloud or mesh, fit an exact surface of revolution or extrusion (``fit_shape``)."""

    label = "Revolve / Extrude"
    scene = "shape"
    min_points = 30
    purpose = "a shape fit"

    def __init__(self, session, ui):
        self.fit = None
        self.axis_handle = None
        super().__init__(session, ui)
        kinds = ("auto",) + tuple(k for k in choices.shape_kinds() if k != "auto")
        self.kind = ui.add_dropdown("Kind", kinds, initial_value="auto")
        self.iters = ui.add_number("Refinement iterations", 30, min=0, max=1000, step=1)
        self.add_runner("Fit shape")
        self.add_export()
        self.surface_view = SplineView(session.client.scene, "/shape/surface", RESULT_COLOR)

    def _drop_axis(self) -> None:
        if self.axis_handle is not None:
            self.axis_handle.remove()
            self.axis_handle = None

    def forget(self) -> None:
        self.fit = None
        self.surface_view.clear()
        self._drop_axis()

    def _fit(self, progress, stop):
        from ..shapes import fit_shape

        points = self.need_points()
        progress(0.0)
        iters = int(self.iters.value)
        return fit_shape(points, self.kind.value, refine=iters > 0, iterations=max(iters, 1),
                         progress=lambda stage, done, total: progress(min(0.99, done / max(1, total))))

    def _done(self, fit) -> None:
        self.fit = fit
        self.session.focus(self.label)
        self.surface_view.shape_key = None
        self.surface_view.draw(f64(fit.surface))
        self._drop_axis()
        seg = axis_segment(fit, self.points)
        if seg is not None:
            self.axis_handle = self.session.client.scene.add_line_segments(
                "/shape/axis", seg.astype(np.float32), AXIS_COLOR, thickness=3.0, thickness_units="screen")
        self.session.frame(self.points)
        self.runner.metrics.content = _shape_markdown(fit)
        self.status.info(f"fit finished: {fit.kind}, mean distance {fit.distance_mean:.3g} of the diagonal")

    def shown(self):
        surface = None if self.fit is None else f64(self.fit.surface)
        return surface, None, f"{self.name}-{self.fit.kind if self.fit is not None else 'shape'}"


def build_shape(session, ui):
    return ShapeTab(session, ui)


# ---- Curves from images ------------------------------------------------------------------

CURVE_COLOR = (230, 25, 75)  # the red of `nurbskit curves`' overlay and SVG
CONTROL_COLOR = (0, 90, 200)


def image_to_world(xy: np.ndarray) -> np.ndarray:
    """Pixel coordinates ``(..., 2)`` (x right, y down) -> scene points ``(..., 3)`` in z = 0.

    Convention: y is negated so that the image reads upright from above in the studio's
    z-up scene; one scene unit is one pixel.
    """
    xy = np.asarray(xy, dtype=np.float64)
    return np.stack([xy[..., 0], -xy[..., 1], np.zeros(xy.shape[:-1])], -1)


def curve_segments(curves: list, spacing: float = 1.0) -> np.ndarray:
    """Every curve as a polyline of segments ``(K, 2, 3)`` in the z = 0 plane (scene coordinates)."""
    from ..curves.synthetic import dense_samples

    segs = []
    for c in curves:
        pts = image_to_world(dense_samples(c, spacing))
        segs.append(np.stack([pts[:-1], pts[1:]], 1))
    return np.concatenate(segs) if segs else np.zeros((0, 2, 3))


def method_options() -> dict[str, object]:
    """The keyword arguments of ``curves_from_image`` beyond the classic ones (e.g. ``mode``,
    which the network method takes), with their defaults: the tab offers what the API has."""
    import inspect

    from ..curves.api import curves_from_image

    known = {"image", "method", "tolerance", "refine", "refine_iterations"}
    out = {}
    for name, p in inspect.signature(curves_from_image).parameters.items():
        if name not in known and p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY):
            out[name] = None if p.default is p.empty else p.default
    return out


def _curves_markdown(report: dict) -> str:
    c = report["chamfer"]
    rows = [
        ("image", f"{report['size'][0]} x {report['size'][1]} px, {report['polarity']}"),
        ("method", report["method"]),
        ("curves", report["curves"]),
        ("control points", report["control_points"]),
        ("Chamfer curves -> ink", "-" if c is None else f"{c['curves_to_ink']:.3f} px"),
        ("Chamfer ink -> curves", "-" if c is None else f"{c['ink_to_curves']:.3f} px"),
        ("seconds", f"{report['seconds']:.2f}"),
    ]
    return markdown_table("Report", rows)


class CurvesTab(TabBase):
    """An image (a drawing) -> B-spline curves (``nurbskit.curves_from_image``), drawn over it."""

    label = "Curves from images"
    scene = "curves"
    stem = "image"

    def __init__(self, session, ui):
        from ..curves.api import METHODS

        super().__init__(session, ui)
        self.grey: np.ndarray | None = None
        self.curves: list | None = None
        self.report: dict | None = None
        self.handles: dict[str, object] = {}
        self.add_loader("Load image")
        self.method = ui.add_dropdown("Method", tuple(METHODS), initial_value=METHODS[0])
        # options the API grows (the network method's mode): offered as text, passed when set
        self.options = {name: ui.add_text(f"{name} (method option; blank: the default)",
                                          "" if default is None else str(default))
                        for name, default in method_options().items()}
        self.tolerance = ui.add_number("Tolerance (pixels)", 1.0, min=0.01, max=1000.0, step=0.01)
        self.refine = ui.add_checkbox("Refine (Chamfer against the ink, L-BFGS)", False)
        self.refine_iters = ui.add_number("Refinement iterations", 20, min=1, max=1000, step=1)
        self.add_runner("Find curves")
        self.add_export({
            "curves.json": ("-curves.json", self._write_json),
            "curves.svg": ("-curves.svg", self._write_svg),
        })

    # loading
    def _read(self, path: Path, name: str):
        from ..curves.api import read_image

        try:
            return read_image(path)  # PIL decides by the content; its size limit applies
        except InputError as exc:
            raise InputError(str(exc).replace(str(path), name)) from None

    def _loaded(self, grey, name: str) -> None:
        self.grey, self.name, self.curves, self.report = grey, Path(name).stem or self.stem, None, None
        self.session.focus(self.label)
        self._clear()
        h, w = grey.shape
        rgb = np.repeat(np.round(255 * np.clip(grey, 0, 1)).astype(np.uint8)[..., None], 3, -1)
        # the image plane's own frame is x right, y down (viser's image convention); turned
        # half a turn about x it lands on image_to_world's (x, -y)
        self.handles["image"] = self.session.client.scene.add_image(
            f"/{self.scene}/image", rgb, float(w), float(h), format="png", position=(w / 2, -h / 2, -0.01),
            wxyz=(0.0, 1.0, 0.0, 0.0), cast_shadow=False, receive_shadow=False)
        # the image's edge, so that a white drawing stands out from the white background
        corners = image_to_world(np.array([[0.0, 0.0], [w, 0.0], [w, h], [0.0, h], [0.0, 0.0]]))
        self.handles["border"] = self.session.client.scene.add_line_segments(
            f"/{self.scene}/border", np.stack([corners[:-1], corners[1:]], 1).astype(np.float32), (150, 150, 150),
            thickness=1.5, thickness_units="screen")
        self.frame()
        self.status.info(f"loaded {name}: {w} x {h} pixels")

    def _clear(self) -> None:
        for h in self.handles.values():
            h.remove()
        self.handles = {}

    def frame(self) -> None:
        h, w = self.grey.shape
        self.session.frame(image_to_world(np.array([[0.0, 0.0], [w, h]])), view=(0.0, -0.35, 1.0))

    # running
    def kwargs(self) -> dict:
        out = {"method": self.method.value, "tolerance": float(self.tolerance.value),
               "refine": bool(self.refine.value), "refine_iterations": int(self.refine_iters.value)}
        for name, box in self.options.items():
            if box.value.strip():
                out[name] = box.value.strip()
        return out

    def _fit(self, progress, stop):
        import time

        import nurbskit
        from ..curves.classic import chamfer_to_ink, even_background, ink_mask

        if self.grey is None:
            raise OptionError("load an image first")
        kwargs = self.kwargs()
        progress(0.0)
        t0 = time.perf_counter()
        curves = nurbskit.curves_from_image(
            self.grey, **kwargs, progress=lambda stage, done, total: progress(min(0.89, 0.9 * done / max(1, total))))
        seconds = time.perf_counter() - t0
        progress(0.9)  # raises Stopped when Stop was pressed meanwhile
        ink, inverted = ink_mask(even_background(self.grey), self.name)  # the ink the curves were read from
        h, w = self.grey.shape
        return curves, {
            "size": (w, h), "method": kwargs["method"], "curves": len(curves),
            "control_points": sum(int(c.control_points.shape[0]) for c in curves),
            "polarity": "light on dark" if inverted else "dark on light",
            "chamfer": chamfer_to_ink(curves, ink) if curves else None, "seconds": seconds,
        }

    def _done(self, out) -> None:
        curves, report = out
        self.curves, self.report = curves, report
        self.session.focus(self.label)
        scene = self.session.client.scene
        for key in ("curves", "control"):
            if key in self.handles:
                self.handles.pop(key).remove()
        if curves:
            self.handles["curves"] = scene.add_line_segments(
                f"/{self.scene}/curves", curve_segments(curves).astype(np.float32), CURVE_COLOR,
                thickness=3.0, thickness_units="screen")
            cp = image_to_world(np.concatenate([c.control_points.detach().cpu().numpy() for c in curves]))
            size = 0.012 * float(np.hypot(*self.grey.shape))
            self.handles["control"] = draw_points(scene, f"/{self.scene}/control", cp + [0.0, 0.0, size],
                                                  np.tile(np.array(CONTROL_COLOR, np.uint8), (len(cp), 1)), size)
        self.runner.metrics.content = _curves_markdown(report)
        self.status.info(f"found {len(curves)} curve(s)")

    # export
    def _need_curves(self) -> list:
        if self.curves is None:
            raise OptionError("nothing to export yet; load an image and find its curves first")
        return self.curves

    def _write_json(self, path: Path) -> None:
        from ..cli.curves_command import write_curves_json

        curves = self._need_curves()
        h, w = self.grey.shape
        write_curves_json(path, curves, (w, h))

    def _write_svg(self, path: Path) -> None:
        from ..cli.curves_command import write_svg

        write_svg(path, self.grey, self._need_curves())

    def shown(self):
        return None, None, self.name


def build_curves(session, ui):
    return CurvesTab(session, ui)


# ---- Volume from drawings ------------------------------------------------------------------

class VolumeTab(TabBase):
    """Three drawings (front, left, top) -> a NURBS volume and its isosurface."""

    label = "Volume from drawings"
    scene = "volume"
    stem = "volume"

    def __init__(self, session, ui):
        super().__init__(session, ui)
        self.drawings: dict[str, object] = {}  # view -> mask (H, W) tensor
        self.fit = None
        self.which = ui.add_dropdown("Drawing to load", ("front", "left", "top"), initial_value="front")
        self.add_loader("Load drawing")
        self.sample = ui.add_button("Use the paper's drawings")
        self.control = ui.add_number("Control values per axis", 20, min=4, max=80, step=1)
        self.grid = ui.add_number("Cost grid per axis", 20, min=4, max=128, step=1)
        self.iters = ui.add_number("Iterations", 60, min=0, max=2000, step=1)
        self.loss = ui.add_dropdown("Cost", choices.volume_losses(), initial_value="paper")
        self.add_runner("Fit volume")
        self.add_export()
        self.sample.on_click(lambda event: self.guard(self._paper))

    def _read(self, path: Path, name: str):
        from ..volume import load_drawing

        try:
            return load_drawing(str(path), name=self.which.value)
        except Exception as exc:  # noqa: BLE001
            raise InputError(str(exc).replace(str(path), name)) from None

    def _loaded(self, mask, name: str) -> None:
        self.drawings[self.which.value] = mask
        missing = [v for v in ("front", "left", "top") if v not in self.drawings]
        self.status.info(f"{self.which.value} drawing: {name} {tuple(mask.shape)}"
                         + (f"; still needed: {', '.join(missing)}" if missing else "; ready"))

    def _paper(self) -> None:
        from ..volume.shapes import paper_drawings

        self.drawings = dict(paper_drawings(96))
        self.status.info("the paper's drawings (front, left, top) are loaded")

    def _fit(self, progress, stop):
        import nurbskit

        missing = [v for v in ("front", "left", "top") if v not in self.drawings]
        if missing:
            raise OptionError(f"load the {', '.join(missing)} drawing(s) first")
        iters = int(self.iters.value)

        def callback(stage, done, total, cost):
            progress(0.99 * done / max(1, total) if stage == "fit" else 1.0, cost)

        from ..volume.config import get_preset

        control, grid = int(self.control.value), int(self.grid.value)
        cfg = dataclasses.replace(get_preset("default"), control_size=(control,) * 3, grid=(grid,) * 3,
                                  iterations=iters, loss=self.loss.value)
        cfg = cfg.validate()
        views = {v: self.drawings[v] for v in ("front", "left", "top")}
        return nurbskit.fit_silhouettes(views, cfg, callback=callback)

    def _done(self, fit) -> None:
        self.fit = fit
        self.session.focus(self.label)
        if fit.mesh.is_empty:
            self.status.error(fit.message or "the fitted volume has no isosurface")
            return
        draw_mesh(self.session.client.scene, "/volume/mesh", fit.mesh.vertices, fit.mesh.faces)
        self.session.frame(fit.mesh.vertices)
        self.runner.metrics.content = markdown_table(
            "Metrics", [("iterations", fit.iterations)] + [(f"IoU {k}", f"{v:.3f}") for k, v in fit.iou.items()])
        self.status.info(f"volume fitted: {len(fit.mesh.faces):,} triangles")

    def shown(self):
        if self.fit is None:
            return None, None, "volume"
        return self.fit.volume, (self.fit.mesh.vertices, self.fit.mesh.faces), "volume"


def build_volume(session, ui):
    return VolumeTab(session, ui)

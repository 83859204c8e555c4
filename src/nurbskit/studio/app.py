"""The studio server: one viser server, one :class:`Session` per browser tab.

Each connected client gets its own GUI (``client.gui``) and its own scene
(``client.scene``), built by the tab builders of :mod:`.registry`, and its own
:class:`Session` holding what it loaded and fitted: two browser tabs never share
state. Long work (fits) runs on a worker thread per tab, reports progress through the
library's callbacks and can be stopped; an exception is shown in the page and the
server carries on.

The widgets every tab shares (:class:`Loader`, :class:`RunPanel`, :class:`ExportPanel`,
:class:`Status`) live here; the tabs only wire them to the library's public API.
"""

from __future__ import annotations

import contextlib
import html
import io
import threading
import time
import traceback
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from .._optional import require
from ..errors import NurbskitError, OptionError
from . import choices
from .registry import available_tabs, cad_writers
from .workdir import Workdir, check_upload, too_large

DEFAULT_MAX_UPLOAD = 200 * 1024 * 1024
PROGRESS_INTERVAL = 0.1  # seconds between progress redraws (10 per second at most)
HEARTBEAT = 0.25  # seconds between "still running" lines while no iteration reports
IMPORT_WITHOUT_PAGE = 5.0  # seconds after start: the fitting code imports even if no page has come


class Stopped(Exception):
    """Raised inside a progress callback when the user pressed Stop."""


@dataclass
class StudioOptions:
    """What the command line sets."""

    host: str = "127.0.0.1"
    port: int = 8080
    workdir: Path = field(default_factory=Path.cwd)
    max_upload_bytes: int = DEFAULT_MAX_UPLOAD


# ---- widgets shared by every tab ---------------------------------------------------------

class Status:
    """One line of status per tab: information, or an error shown in red (and as a toast)."""

    def __init__(self, session: "Session", ui):
        self.session = session
        self.handle = ui.add_html("<div></div>")

    def info(self, text: str) -> None:
        self.handle.content = f"<div class='studio-status'>{html.escape(text)}</div>"

    def error(self, text: str) -> None:
        self.handle.content = (
            f"<div class='studio-error' style='color:#c92a2a'><b>Error:</b> {html.escape(text)}</div>"
        )
        try:
            self.session.client.add_notification("Error", text, color="red", auto_close_seconds=8.0)
        except Exception:  # a closed browser tab: nothing to show it in
            pass


def describe_error(exc: BaseException) -> str:
    """The message people see: a NurbskitError's own words, else type and message."""
    if isinstance(exc, NurbskitError):
        return str(exc)
    if isinstance(exc, OSError):
        return f"{exc.strerror or exc}"
    return f"{type(exc).__name__}: {exc}"


#: A file read for a client may take this many times the upload limit in memory, and at
#: least ``READ_MEMORY_FLOOR`` bytes (an image's reading takes about 128 bytes a pixel: a
#: few hundred KB of PNG can need tens of MB, rightly).
READ_MEMORY_FACTOR = 10
READ_MEMORY_FLOOR = 1 << 30


def read_upload(session: "Session", file, read: Callable[[Path, str], object]) -> tuple[object, str]:
    """``(read(scratch_path, name), name)`` of an uploaded ``file`` (viser's UploadedFile).

    Size-checked, written under the workdir's scratch folder with a made-up name (only a
    safe extension of the client's name is kept), read, and deleted whatever happens.
    """
    check_upload(file.name, file.content, session.options.max_upload_bytes)
    name = Path(str(file.name).replace("\\", "/")).name
    tmp = session.workdir.scratch(file.name)
    try:
        tmp.write_bytes(file.content)
        with read_memory(session), named_as(tmp, name):
            return read(tmp, name), name
    finally:
        tmp.unlink(missing_ok=True)


@contextlib.contextmanager
def named_as(path: Path, name: str):
    """A reader's error about ``path`` (a scratch file, an absolute path on the server)
    told with the ``name`` the page knows it by."""
    try:
        yield
    except NurbskitError as exc:
        text = str(exc)
        if str(path) not in text:
            raise
        raise type(exc)(text.replace(str(path), name)) from None


def read_memory(session: "Session"):
    """The memory a client's file may take once read: ``READ_MEMORY_FACTOR`` times the upload
    limit, at least ``READ_MEMORY_FLOOR`` (a compressed ``.npz`` of a few MB can declare
    gigabytes; the readers check what a file declares against this before allocating)."""
    from ..io._base import memory_cap

    return memory_cap(max(READ_MEMORY_FACTOR * session.options.max_upload_bytes, READ_MEMORY_FLOOR))


class Loader:
    """Upload a file, or pick one from the workdir; ``read(path)`` turns it into data.

    The upload is size-checked, written under the workdir's scratch folder with a
    made-up name, read by ``read`` (nurbskit's readers: the content decides), and the
    scratch file is deleted whatever happens.
    """

    def __init__(self, session: "Session", ui, status: Status, read: Callable[[Path, str], object],
                 on_loaded: Callable[[object, str], None], label: str = "Load"):
        self.session, self.status, self.read, self.on_loaded = session, status, read, on_loaded
        self.upload = ui.add_upload_button(f"{label}: upload a file", icon=None)
        self.choice = ui.add_dropdown("Workdir file", ("",) + session.initial_files(), initial_value="")
        self.path = ui.add_text("Path in workdir", "")
        self.load = ui.add_button(f"{label} from workdir")
        self.refresh = ui.add_button("Refresh file list")
        self.upload.on_upload(lambda event: self._guard(self._from_upload))
        session.upload_status[self.upload._impl.uuid] = status
        self.load.on_click(lambda event: self._guard(self._from_workdir))
        self.refresh.on_click(lambda event: self._refresh())
        self.choice.on_update(lambda event: self._choose())

    def _options(self) -> tuple[str, ...]:
        return ("",) + tuple(self.session.workdir.files())

    def _refresh(self) -> None:
        self.choice.options = self._options()

    def _choose(self) -> None:
        if self.choice.value:
            self.path.value = self.choice.value

    def _guard(self, fn) -> None:
        try:
            fn()
        except Exception as exc:  # shown in the page; the server carries on
            self.status.error(describe_error(exc))

    def _from_upload(self) -> None:
        data, name = read_upload(self.session, self.upload.value, self.read)
        self.on_loaded(data, name)

    def _from_workdir(self) -> None:
        name = self.path.value or self.choice.value
        path = self.session.workdir.resolve(name)
        with read_memory(self.session), named_as(path, name):
            data = self.read(path, name)
        self.on_loaded(data, name)


class RunPanel:
    """Run / Stop buttons, a progress bar, a loss curve and the metrics of the last run."""

    def __init__(self, session: "Session", ui, status: Status, start: Callable[[Callable, threading.Event], object],
                 done: Callable[[object], None], label: str = "Run"):
        from viser import uplot

        self.session, self.status, self.start, self.done = session, status, start, done
        self.run = ui.add_button(label)
        self.stop = ui.add_button("Stop", disabled=True)
        self.bar = ui.add_progress_bar(0.0)
        self.curve = ui.add_uplot(
            (np.zeros(1), np.zeros(1)),
            (uplot.Series(label="iteration"), uplot.Series(label="log10 loss", stroke="#1c7ed6", width=2)),
            # log10 on a linear axis: uPlot's log axis labels small losses "0"
            title="Loss (log10)", scales={"x": {"time": False}}, aspect=1.6,
            # shown from the first run on: an empty chart is nothing to look at, and the
            # page's first paint skips the chart library's set-up (issue 13: interactive within 3 s)
            visible=False,
        )
        self.clock = ui.add_markdown("")
        self.metrics = ui.add_markdown("")
        self.thread: threading.Thread | None = None
        self.heartbeats = 0
        self._fraction = 0.0
        self.stop_event = threading.Event()
        self.updates = 0
        self.losses: list[float] = []
        self.run.on_click(lambda event: self.launch())
        self.stop.on_click(lambda event: self.stop_event.set())

    @property
    def running(self) -> bool:
        return self.thread is not None and self.thread.is_alive()

    def launch(self) -> None:
        if self.running:
            self.status.error("a run is already in progress; stop it first")
            return
        self.stop_event = threading.Event()
        self.losses, self.updates = [], 0
        self.bar.value, self.bar.animated = 0.0, True
        self.curve.visible = True
        self.run.disabled, self.stop.disabled = True, False
        self.metrics.content = ""
        self.status.info("running ...")
        self.thread = threading.Thread(target=self._work, name="nurbskit-studio-run", daemon=True)
        self.thread.start()
        threading.Thread(target=self._beat, args=(self.thread,), name="nurbskit-studio-clock", daemon=True).start()

    def _beat(self, worker: threading.Thread) -> None:
        """Elapsed time and iteration count, a few times a second, for as long as the run lasts.

        Some phases report no iterations (the initial surface, the least-squares
        alternation, the final report); the page still shows that work goes on.
        """
        t0 = time.perf_counter()
        while worker.is_alive():
            worker.join(HEARTBEAT)
            if worker.is_alive():
                self.heartbeats += 1
                self.clock.content = (f"running for {time.perf_counter() - t0:.1f} s; "
                                      f"{len(self.losses)} iterations, {100 * self._fraction:.0f} %")
        self.clock.content = f"last run: {time.perf_counter() - t0:.1f} s, {len(self.losses)} iterations"

    def _work(self) -> None:
        last = [0.0]

        def progress(fraction: float, loss: float | None = None) -> None:
            if self.stop_event.is_set():
                raise Stopped()
            if loss is not None and np.isfinite(loss):
                self.losses.append(float(loss))
            now = time.perf_counter()
            if now - last[0] >= PROGRESS_INTERVAL or fraction >= 1.0:
                last[0] = now
                self._show_progress(fraction)

        try:
            result = self.start(progress, self.stop_event)
            if self.stop_event.is_set():  # Stop pressed after the run's last report: keep nothing
                raise Stopped()
            self._show_progress(1.0)
            self.done(result)
        except Stopped:
            self.status.info("stopped; nothing was kept from the interrupted run")
        except Exception as exc:  # the page says what failed; the server keeps serving
            self.status.error(describe_error(exc))
            self.session.log_exception(exc)
        finally:
            self.bar.animated = False
            self.run.disabled, self.stop.disabled = False, True

    def _show_progress(self, fraction: float) -> None:
        self.updates += 1
        self._fraction = fraction
        self.bar.value = float(min(100.0, max(0.0, 100.0 * fraction)))
        if self.losses:
            y = np.asarray(self.losses, dtype=np.float64)
            self.curve.data = (np.arange(1, y.size + 1, dtype=np.float64), np.log10(np.maximum(y, 1e-300)))


EXPORT_FORMATS = {
    "nurbskit JSON": ".json",
    "geomdl JSON": ".geomdl.json",
    "Rhino .3dm": ".3dm",
    "OBJ mesh": ".obj",
    "PLY mesh": ".ply",
}


class ExportPanel:
    """Download what the tab shows (NURBS files, meshes, CAD once available) or a screenshot.

    ``shown()`` returns ``(nurbs or None, (vertices, faces) or None, stem)``. A tab whose
    output is not one NURBS object passes ``formats``: ``{label: (extension, write(path))}``
    (the Curves tab: ``curves.json``, ``curves.svg``), which replace the NURBS and mesh
    formats.
    """

    def __init__(self, session: "Session", ui, status: Status, shown: Callable[[], tuple],
                 formats: dict[str, tuple[str, Callable[[Path], None]]] | None = None):
        self.session, self.status, self.shown = session, status, shown
        self.own = dict(formats or {})
        self.cad = {} if self.own else cad_writers()
        formats = tuple(self.own) if self.own else tuple(EXPORT_FORMATS) + tuple(self.cad)
        self.format = ui.add_dropdown("Export format", formats, initial_value=formats[0])
        self.download = ui.add_button("Download")
        self.save_name = ui.add_text("Save as (in workdir)", "")
        self.save = ui.add_button("Save to workdir")
        self.screenshot = ui.add_button("Screenshot")
        self.download.on_click(lambda event: self._guard(self._download))
        self.save.on_click(lambda event: self._guard(self._save))
        self.screenshot.on_click(lambda event: self._guard(self._screenshot))

    def _guard(self, fn) -> None:
        try:
            fn()
        except Exception as exc:
            self.status.error(describe_error(exc))

    def write(self, path: Path) -> None:
        """Write what is shown to ``path`` in the chosen format."""
        import nurbskit

        fmt = self.format.value
        if fmt in self.own:
            self.own[fmt][1](path)
            return
        obj, mesh, _ = self.shown()
        if fmt in ("OBJ mesh", "PLY mesh"):
            if mesh is None:
                if obj is None or obj.para_dim != 2:
                    raise OptionError("nothing to export as a mesh yet")
                t = nurbskit.tessellate(obj.detach().to(dtype=__import__("torch").float64), (64, 64))
                mesh = (t.vertices.numpy(), t.faces.numpy())
            nurbskit.io.write_mesh(path, mesh[0], mesh[1])
            return
        if obj is None:
            raise OptionError("nothing to export as NURBS yet; load, fit or create an object first")
        if isinstance(obj, (list, tuple)):
            # trimmed faces (a PatchSet's): only the CAD writers keep the trims
            if fmt not in self.cad:
                raise OptionError(f"{fmt}: the trimmed patches export as {', '.join(self.cad) or 'STEP (needs [cad])'}"
                                  " or as an OBJ/PLY mesh")
            self.cad[fmt][1](list(obj), path)
            return
        obj = obj.detach()
        if fmt in self.cad:
            self.cad[fmt][1](obj, path)  # write_cad: the format from the extension; read back and checked
        elif fmt == "geomdl JSON":
            nurbskit.io.write_nurbs(path, obj, format="geomdl")
        else:
            nurbskit.io.write_nurbs(path, obj)

    def extension(self) -> str:
        fmt = self.format.value
        if fmt in self.own:
            return self.own[fmt][0]
        return self.cad[fmt][0] if fmt in self.cad else EXPORT_FORMATS[fmt]

    def _download(self) -> None:
        _, _, stem = self.shown()
        ext = self.extension()
        tmp = self.session.workdir.scratch(f"export{ext}", kind="exports")
        try:
            try:
                self.write(tmp)
            except Exception as exc:  # name the download, not the scratch file
                raise type(exc)(str(exc).replace(str(tmp), f"{stem}{ext}")) from None
            content = tmp.read_bytes()
        finally:
            tmp.unlink(missing_ok=True)
        self.session.client.send_file_download(f"{stem}{ext}", content, save_immediately=True)
        self.status.info(f"downloaded {stem}{ext} ({len(content):,} bytes)")

    def _save(self) -> None:
        name = self.save_name.value.strip()
        path = self.session.workdir.output_name(name)
        self.write(path)
        self.status.info(f"saved {name}")

    def _screenshot(self) -> None:
        from PIL import Image

        image = self.session.client.get_render(720, 1280, transport_format="png", timeout=20.0)
        buffer = io.BytesIO()
        Image.fromarray(image).save(buffer, format="PNG")
        self.session.client.send_file_download("nurbskit-studio.png", buffer.getvalue(), save_immediately=True)
        self.status.info("screenshot downloaded")


# ---- the parts of a tab, in one order ----------------------------------------------------

def devices() -> tuple[str, ...]:
    """The devices a fit may run on here (imports torch)."""
    import torch

    return ("cpu", "cuda") if torch.cuda.is_available() else ("cpu",)


def markdown_table(title: str, rows) -> str:
    """A two-column report table ``rows [(name, value)]`` under a bold ``title``."""
    body = "\n".join(f"| {k} | {v} |" for k, v in rows)
    return f"**{title}**\n\n| | |\n|---|---|\n" + body


def iteration_progress(progress: Callable, total: int) -> Callable:
    """A fitting loop's ``callback(p)`` (``p.loss``) that moves the bar one iteration of ``total``."""
    done = [0]

    def callback(p) -> None:
        done[0] += 1
        progress(min(1.0, done[0] / max(1, total)), p.loss)

    return callback


class TabBase:
    """What every tab is made of: one status line, then the shared widgets, built in one
    order (issue 13: "each tab reuses one set of widgets for loading, parameters, progress
    and export").

    A tab sets ``label`` (its title), ``scene`` (its folder in the scene tree) and
    ``stem`` (the download name before a file is loaded), calls ``super().__init__`` and
    then, in page order, the builders it needs: :meth:`add_loader` (its ``_read(path,
    name)`` turns a file into data, ``_loaded(data, name)`` shows it), its own
    parameters, :meth:`add_device`, :meth:`add_runner` (``_fit(progress, stop)`` works
    on the run thread, ``_done(result)`` shows the result) and :meth:`add_export`
    (``shown()``).
    """

    label = ""
    scene = ""
    stem = "object"

    def __init__(self, session: "Session", ui):
        self.session, self.ui = session, ui
        self.root = session.client.scene.add_frame(f"/{self.scene}", show_axes=False)
        self.name = self.stem
        self.status = Status(session, ui)

    def add_loader(self, label: str) -> Loader:
        self.loader = Loader(self.session, self.ui, self.status, self._read, self._loaded, label=label)
        return self.loader

    def add_device(self):
        # "cuda" is offered once torch has loaded and says it is there (activate)
        self.device = self.ui.add_dropdown("Device", ("cpu",), initial_value="cpu")
        return self.device

    def add_runner(self, label: str) -> RunPanel:
        self.runner = RunPanel(self.session, self.ui, self.status, self._fit, self._done, label=label)
        return self.runner

    def add_export(self, formats=None) -> ExportPanel:
        self.export = ExportPanel(self.session, self.ui, self.status, self.shown, formats)
        return self.export

    def activate(self) -> None:
        """Called once the fitting code (torch, the capabilities) has loaded: what needs it.

        The widgets are built before (from plain data, see :mod:`.choices`), so that the
        page is interactive while torch still imports.
        """
        device = getattr(self, "device", None)
        if device is not None and tuple(device.options) != devices():
            device.options = devices()

    def guard(self, fn) -> None:
        """Run ``fn`` (a widget's handler); an exception is shown in the tab, the server carries on."""
        try:
            fn()
        except Exception as exc:  # noqa: BLE001
            self.status.error(describe_error(exc))

    def shown(self):
        return None, None, self.name


# ---- one browser tab ---------------------------------------------------------------------

class Session:
    """Everything one browser tab (viser client) has: its GUI, scene and data.

    The tabs' widgets are built at once, from plain data (no torch); :meth:`activate`
    runs once the fitting code has loaded and does what needs it (the generator's first
    object, the device list).
    """

    def __init__(self, studio: "Studio", client):
        self.studio, self.client = studio, client
        self.options, self.workdir = studio.options, studio.workdir
        self.tabs: dict[str, object] = {}
        self.errors: list[str] = []
        self.upload_status: dict[str, Status] = {}  # upload button uuid -> its tab's status
        self.focused: str | None = None  # the tab whose objects the 3-D view shows
        self.active = False
        self._files: tuple[str, ...] | None = None
        self._refuse_large_uploads()
        from .guard import check_client_updates

        check_client_updates(self.client.gui)  # a widget's value must be one it offers
        client.scene.set_up_direction("+z")
        with client.gui.add_folder("nurbskit studio", expand_by_default=True):
            self.loading = None if studio.ready.is_set() else client.gui.add_markdown(
                "*Loading the fitting code ...*")
            group = client.gui.add_tab_group()
            for spec in studio.tabs:
                with group.add_tab(spec.label):
                    # viser reports no tab switches: the 3-D view shows the tab last acted
                    # in, and this button brings a tab's objects back
                    show = client.gui.add_button("Show this tab in the 3-D view", color="gray")
                    show.on_click(lambda event, label=spec.label: self.show(label))
                    builder = spec.load_builder()
                    self.tabs[spec.label] = builder(self, client.gui)
        self.group = group
        if self.tabs:  # the page opens on the first tab: only its objects are shown
            self.focus(next(iter(self.tabs)))

    def initial_files(self) -> tuple[str, ...]:
        """The workdir's files when the page was built (listed once for every tab's loader)."""
        if self._files is None:
            self._files = tuple(self.workdir.files())
        return self._files

    def activate(self) -> None:
        """The fitting code has loaded: let every tab do what needs it (once)."""
        if self.active:
            return
        self.active = True
        for label, tab in self.tabs.items():
            problem = self.studio.tab_errors.get(label)
            if problem is not None:
                tab.status.error(f"this tab's code could not be loaded: {problem}")
                continue
            try:
                tab.activate()
            except Exception as exc:  # noqa: BLE001 - shown in the tab; the others carry on
                tab.status.error(describe_error(exc))
                self.log_exception(exc)
        if self.loading is not None:
            self.loading.remove()
            self.loading = None

    def focus(self, label: str) -> None:
        """Show the scene of tab ``label`` only."""
        self.focused = label
        for name, tab in self.tabs.items():
            root = getattr(tab, "root", None)
            if root is not None:
                root.visible = name == label

    def _refuse_large_uploads(self) -> None:
        """Drop an upload whose declared size is over the limit before its bytes arrive,
        and one whose parts add up to more than it declared.

        viser buffers an upload in memory until it is complete; these handlers run after
        viser's own handlers of the transfer's messages and forget the transfer, so the
        remaining parts are discarded as they come. (Uses viser's upload table; if
        that ever changes, the size check after the upload still refuses the file.)
        """
        from viser import _messages

        gui = self.client.gui
        limit = self.options.max_upload_bytes

        def check(client_id, message) -> None:
            if message.size_bytes <= limit:
                return
            states = getattr(gui, "_current_file_upload_states", None)
            if isinstance(states, dict):
                states.pop(message.transfer_uuid, None)
            # tell the page the transfer is over, so that its upload button comes back
            gui._websock_interface.queue_message(_messages.FileTransferPartAck(
                source_component_uuid=message.source_component_uuid, transfer_uuid=message.transfer_uuid,
                transferred_bytes=message.size_bytes, total_bytes=message.size_bytes))
            status = self.upload_status.get(message.source_component_uuid)
            if status is not None:
                status.error(too_large(message.filename, message.size_bytes, limit))

        gui._websock_interface.register_handler(_messages.FileTransferStartUpload, check)

        def count(client_id, message) -> None:
            # The declared size is the client's word: a transfer whose parts add up to more
            # than it declared, or than the limit, is forgotten (its bytes freed) at once.
            states = getattr(gui, "_current_file_upload_states", None)
            state = states.get(message.transfer_uuid) if isinstance(states, dict) else None
            if state is not None and state.get("transferred_bytes", 0) > min(limit, state.get("total_bytes", 0)):
                states.pop(message.transfer_uuid, None)

        gui._websock_interface.register_handler(_messages.FileTransferPart, count)  # after viser's own

    def show(self, label: str) -> None:
        """Show tab ``label``'s objects and point the camera at them."""
        self.focus(label)
        tab = self.tabs[label]
        try:
            obj, mesh, _ = tab.shown()
        except Exception:  # nothing to show yet
            obj, mesh = None, None
        if mesh is not None:
            self.frame(mesh[0])
        elif obj is not None:
            self.frame(obj.control_points.detach().cpu().numpy()[..., :3])
        elif getattr(tab, "points", None) is not None:
            self.frame(tab.points)
        elif getattr(tab, "grey", None) is not None:
            tab.frame()  # an image seen from above

    def frame(self, points, view=(0.9, -1.2, 0.9)) -> None:
        """Point the camera at ``points (N, 3)`` from ``view`` (a direction; default three-quarter)."""
        pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        if pts.size == 0 or not np.isfinite(pts).all():
            return
        lo, hi = pts.min(0), pts.max(0)
        center, size = (lo + hi) / 2, float(np.linalg.norm(hi - lo)) or 1.0
        camera = self.client.camera
        if camera._state.update_timestamp == 0.0:
            return  # the browser has not reported its camera yet (still connecting)
        view = np.asarray(view, dtype=np.float64)
        view = view * (1.75 / np.linalg.norm(view))  # the default's distance: 1.75 diagonals
        right = np.cross(-view, [0.0, 0.0, 1.0])
        right /= np.linalg.norm(right)
        # the panel covers the right of the page: aim right of the object so that it sits left
        target = center + 0.3 * size * right
        # position first, then look_at: viser keeps the look-at point fixed that way
        camera.position = target + size * view
        camera.look_at = target

    def log_exception(self, exc: BaseException) -> None:
        self.errors.append("".join(traceback.format_exception(exc)))


class Studio:
    """The server. ``Studio(options).start()``; ``url``; ``stop()``."""

    def __init__(self, options: StudioOptions):
        self.options = options
        self.workdir = Workdir(options.workdir)
        self._tabs: list | None = None
        self._tabs_lock = threading.Lock()
        self.ready = threading.Event()  # set once the tabs' capabilities are imported (_load)
        self.tab_errors: dict[str, str] = {}  # tab label -> why its capability did not import
        self.sessions: dict[int, Session] = {}
        self.server = None
        self._loader: threading.Thread | None = None
        self._timer: threading.Timer | None = None
        self._lock = threading.Lock()

    def start(self) -> "Studio":
        """Listen; the fitting code (torch, the capabilities) is imported once a page is up
        (or a few seconds after start, when no page has come).

        A client that connects gets its widgets at once: they are built from plain data
        read from the library's sources (:mod:`.choices`, read on a thread while the
        browser fetches the page's code, a few MB of JavaScript). Then the capabilities
        import on a thread (:meth:`_load`; the first page is drawn in the browser
        meanwhile, and the server's Python is free of the import while it builds the
        widgets) and the tabs are activated (:meth:`Session.activate`). A click that
        needs the code before then waits for it.
        """
        viser = require("viser", "studio", "nurbskit studio")
        from .guard import install

        install()  # requests from other web sites refused (viser checks no Origin)
        self.server = viser.ViserServer(host=self.options.host, port=self.options.port, verbose=False)
        self.server.gui.configure_theme(control_width="large", show_share_button=False)
        # No HDRI environment (a texture download the machine may not reach, and slow in
        # software WebGL) and no shadow maps: the default lights shade the surfaces.
        self.server.scene.configure_environment_map(None)
        self.server.scene.configure_default_lights(enabled=True, cast_shadow=False)
        self.server.on_client_connect(self._connect)
        self.server.on_client_disconnect(self._disconnect)
        threading.Thread(target=self._read_choices, name="nurbskit-studio-choices", daemon=True).start()
        # no page within a few seconds: import anyway, so that a page opened later finds it in
        self._timer = threading.Timer(IMPORT_WITHOUT_PAGE, self.load)
        self._timer.daemon = True
        self._timer.start()
        return self

    @property
    def tabs(self) -> list:
        """The tabs whose capability exists (:func:`.registry.available_tabs`; read, not imported)."""
        with self._tabs_lock:
            if self._tabs is None:
                self._tabs = available_tabs()
            return self._tabs

    def _read_choices(self) -> None:
        """Read what the widgets offer while the browser fetches the page's code."""
        self.tabs  # noqa: B018 - the property reads the capabilities' sources once, here
        choices.warm()

    def load(self) -> "Studio":
        """Start importing the tabs' capabilities on a thread (once; :meth:`wait_ready` waits for it)."""
        with self._lock:
            if self._loader is None:
                self._loader = threading.Thread(target=self._load, name="nurbskit-studio-import", daemon=True)
                self._loader.start()
        return self

    def _load(self) -> None:
        """Import every tab's capability (the slow part of start-up: torch)."""
        try:
            for spec in self.tabs:
                try:
                    spec.load()
                except Exception as exc:  # noqa: BLE001 - shown in that tab; the others work
                    self.tab_errors[spec.label] = describe_error(exc)
        finally:
            self.ready.set()

    def wait_ready(self, timeout: float | None = None) -> "Studio":
        """Import the tabs' code now if no page has asked for it yet, and wait for it."""
        self.load()
        if not self.ready.wait(timeout):
            raise TimeoutError(f"the studio's tabs were not ready after {timeout} s")
        return self

    @property
    def port(self) -> int:
        return int(self.server.get_port())

    @property
    def url(self) -> str:
        host = self.options.host
        shown = f"[{host}]" if ":" in host else host
        return f"http://{shown}:{self.port}/"

    def _connect(self, client) -> None:
        # viser runs this on a worker thread: waiting here for the imports holds no one else up
        session = Session(self, client)
        with self._lock:
            self.sessions[client.client_id] = session
        self.load()  # the first page's widgets are on their way: import the fitting code now
        self.ready.wait()
        session.activate()

    def _disconnect(self, client) -> None:
        with self._lock:
            session = self.sessions.pop(client.client_id, None)
        if session is not None:
            for tab in session.tabs.values():
                panel = getattr(tab, "runner", None)
                if panel is not None:
                    panel.stop_event.set()

    def stop(self) -> None:
        if self._timer is not None:
            self._timer.cancel()
        if self.server is not None:
            self.server.stop()
            self.server = None

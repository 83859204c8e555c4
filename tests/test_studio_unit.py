"""The studio's parts that need no browser: folder confinement, the tab registry, the
generator's objects, the command line's options."""

from __future__ import annotations

import os

import numpy as np
import pytest
import torch

from _assert import assert_close
from nurbskit.errors import InputError, OptionError
from nurbskit.studio.registry import TABS, TabSpec, available_tabs
from nurbskit.studio.workdir import Workdir, check_upload


@pytest.fixture
def folder(tmp_path):
    work, outside = tmp_path / "work", tmp_path / "outside"
    (work / "sub").mkdir(parents=True)
    outside.mkdir()
    (work / "a.ply").write_text("x")
    (work / "sub" / "b.json").write_text("{}")
    (outside / "secret.ply").write_text("s")
    os.symlink(outside / "secret.ply", work / "link.ply")
    os.symlink(outside, work / "linkdir")
    return Workdir(work), work, outside


def test_resolve_inside(folder):
    wd, work, _ = folder
    assert wd.resolve("a.ply") == (work / "a.ply").resolve()
    assert wd.resolve("sub/b.json") == (work / "sub" / "b.json").resolve()


@pytest.mark.parametrize("name, words", [
    ("../outside/secret.ply", "'..' is not allowed"),
    ("sub/../../outside/secret.ply", "'..' is not allowed"),
    ("/etc/passwd", "relative"),
    ("~/x.ply", "relative"),
    ("C:/x.ply", "relative"),
    ("sub\\b.json", "backslashes"),
    ("link.ply", "outside"),
    ("linkdir/secret.ply", "outside"),
    ("", "no file name"),
    ("missing.ply", "no such file"),
])
def test_resolve_refuses(folder, name, words):
    wd = folder[0]
    with pytest.raises(OptionError, match=None) as info:
        wd.resolve(name)
    assert words in str(info.value)


def test_files_lists_only_inside(folder):
    wd = folder[0]
    assert wd.files() == ["a.ply", "sub/b.json"]


def test_scratch_keeps_only_a_safe_extension(folder):
    wd, work, _ = folder
    for name, ext in (("../../evil.ply", ".ply"), ("x.json", ".json"), ("a.b/../c", ""), ("bad.p;y", "")):
        path = wd.scratch(name)
        assert path.parent == work / ".studio" / "uploads" and path.suffix == ext
        assert ".." not in path.name


def test_output_name_is_confined(folder):
    wd, work, _ = folder
    assert wd.output_name("new/out.json") == (work / "new" / "out.json").resolve()
    with pytest.raises(OptionError):
        wd.output_name("../out.json")
    with pytest.raises(OptionError, match="directory"):
        wd.output_name("sub")


def test_upload_limit():
    check_upload("a.ply", b"x" * 10, 10)
    with pytest.raises(InputError, match="at most 10"):
        check_upload("a.ply", b"x" * 11, 10)
    with pytest.raises(InputError, match="empty"):
        check_upload("a.ply", b"", 10)


def test_registry_shows_a_tab_only_when_its_capability_imports():
    labels = [t.label for t in available_tabs()]
    assert labels[:3] == ["Unsupervised", "Supervised", "NURBS Generator"]
    assert "Volume from drawings" in labels
    assert not TabSpec("X", "nurbskit.no_such_module", None, "nurbskit.studio.tabs:build_volume").available()
    missing = TabSpec("X", "nurbskit.fit", "no_such_function", "nurbskit.studio.tabs:build_volume")
    assert not missing.available()
    with pytest.raises(ImportError, match="no_such_function"):
        missing.load()
    for spec in TABS:  # a listed tab has a builder, an unlisted one lacks its capability or builder
        assert (spec in available_tabs()) == (spec.available() and spec.load_builder() is not None)


@pytest.mark.parametrize("kind, k", [("curve", 1), ("surface", 2), ("volume", 3)])
@pytest.mark.parametrize("knots", ["clamped", "uniform", "periodic"])
def test_generator_objects(kind, k, knots):
    from nurbskit.studio.generator import make_object

    obj, free = make_object(kind, (6, 5, 4), (3, 2, 2), knots)
    assert obj.para_dim == k and obj.control_points.dtype == torch.float64
    if knots == "periodic":
        assert free == 6 and obj.sizes[0] == 6 + 3
        # closed: the two ends of the u domain meet, with matching first derivatives
        a, b = obj.domain[0]
        rest = [[sum(d) / 2] for d in obj.domain[1:]]
        ends = [obj.evaluate_grid(*([torch.tensor([u], dtype=torch.float64)] + [torch.tensor(r, dtype=torch.float64) for r in rest]), order=1)
                for u in (a, b)]
        assert_close(ends[0], ends[1], atol=1e-10)
    elif knots == "uniform":
        kv = obj.knot_vectors[0]
        assert_close(kv[1:] - kv[:-1], torch.full_like(kv[1:], float(kv[1] - kv[0])), atol=1e-12)
    else:
        assert float(obj.knot_vectors[0][0]) == float(obj.knot_vectors[0][3]) == 0.0


def test_generator_refuses_bad_sizes():
    from nurbskit.studio.generator import make_object

    with pytest.raises(OptionError, match="need at least 4"):
        make_object("surface", (3, 5, 2), (3, 3, 2), "clamped")


def test_gaussian_curvature_of_a_sphere_patch():
    """A rational quadratic patch of the unit sphere (a quarter circle revolved): K = 1."""
    import nurbskit
    from nurbskit.studio.scene import gaussian_curvature

    s2 = np.sqrt(0.5)
    arc = np.array([[1, 0], [1, 1], [0, 1]], float)  # quarter circle in (r, z)
    w_arc = np.array([1, s2, 1])
    ring = np.array([[1, 0], [1, 1], [0, 1]], float)  # quarter circle in (x, y)
    w_ring = np.array([1, s2, 1])
    cp = np.zeros((3, 3, 3))
    for i in range(3):
        for j in range(3):
            cp[i, j] = [arc[i, 0] * ring[j, 0], arc[i, 0] * ring[j, 1], arc[i, 1]]
    w = w_arc[:, None] * w_ring[None, :]
    surface = nurbskit.NURBSSurface(torch.tensor(cp), (2, 2), weights=torch.tensor(w))
    K = gaussian_curvature(surface, (9, 9))
    interior = K.reshape(9, 9)[1:-1, :]  # the pole row (u = 1) is degenerate
    assert_close(interior, np.ones_like(interior), atol=1e-9)


def test_cli_refuses_bad_options(tmp_path, capsys):
    from nurbskit.cli import main

    assert main(["studio", "--port", "99999"]) == 2
    assert "--port" in capsys.readouterr().err
    assert main(["studio", "--workdir", str(tmp_path / "nope")]) == 2
    assert "--workdir" in capsys.readouterr().err
    assert main(["studio", "--max-upload-mb", "-1"]) == 2
    assert "--max-upload-mb" in capsys.readouterr().err


def test_missing_viser_names_the_extra(monkeypatch, capsys, tmp_path):
    import sys

    from nurbskit.cli import main

    monkeypatch.setitem(sys.modules, "viser", None)  # import viser -> ImportError
    assert main(["studio", "--workdir", str(tmp_path), "--port", "0"]) == 2
    err = capsys.readouterr().err
    assert "pip install 'nurbskit[studio]'" in err and "Traceback" not in err


def test_command_serves_the_page(tmp_path):
    """``nurbskit studio --port 0`` answers HTTP on loopback with viser's page; Ctrl-C stops it."""
    import re
    import signal
    import subprocess
    import sys
    import time
    import urllib.request

    from _extras import require_extra

    require_extra("viser", "studio")
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(sys.path))
    proc = subprocess.Popen([sys.executable, "-m", "nurbskit", "studio", "--port", "0", "--workdir", str(tmp_path)],
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, env=env)
    try:
        line = ""
        end = time.monotonic() + 60
        while "serving" not in line and time.monotonic() < end:
            line = proc.stderr.readline()
            assert line or proc.poll() is None, "the studio exited early"
        url = re.search(r"http://127\.0\.0\.1:\d+/", line).group(0)
        with urllib.request.urlopen(url, timeout=30) as response:
            assert response.status == 200 and b"<html" in response.read(2000).lower()
    finally:
        proc.send_signal(signal.SIGINT)
        try:
            rest = proc.communicate(timeout=30)[1]
        except subprocess.TimeoutExpired:
            proc.kill()
            raise
    assert proc.returncode == 130 and "Traceback" not in rest


def test_loss_weights_and_iterations_from_the_panel():
    from nurbskit.fit.pipelines import get_pipeline
    from nurbskit.studio.tabs import _apply_iterations, _apply_loss_weights

    cfg = _apply_loss_weights(get_pipeline("UCDL"), "chamfer=2, laplacian=0.5")
    assert all(s.loss.chamfer == 2.0 and s.loss.laplacian == 0.5 for s in cfg.stages)
    assert _apply_loss_weights(get_pipeline("UCDL"), "  ").stages == get_pipeline("UCDL").stages
    for bad, words in (("laplace=1", "expected name=value"), ("chamfer=x", "needs a number"),
                       ("chamfer=-1", ">= 0"), ("laplacian_on=1", "expected name=value")):
        with pytest.raises(OptionError, match=words):
            _apply_loss_weights(get_pipeline("UCDL"), bad)
    sb = get_pipeline("SB")
    scaled = _apply_iterations(sb, 40)
    assert sum(s.iters for s in scaled.stages) == 40 and len(scaled.stages) == len(sb.stages)
    assert _apply_iterations(sb, 0).stages == sb.stages


@pytest.mark.parametrize("host, loopback", [("127.0.0.1", True), ("127.0.0.2", True), ("localhost", True),
                                            ("::1", True), ("0.0.0.0", False), ("192.168.1.5", False),
                                            ("example.org", False), ("::", False)])
def test_only_loopback_hosts_go_without_a_warning(host, loopback):
    from nurbskit.studio.guard import is_loopback

    assert is_loopback(host) is loopback


def box_corner(n: int = 150, seed: int = 0) -> np.ndarray:
    """Three faces of the unit cube meeting at the origin, ``n`` points each ``(3n, 3)``."""
    rng = np.random.default_rng(seed)
    a, b, c = rng.random((n, 2)), rng.random((n, 2)), rng.random((n, 2))
    zero = np.zeros(n)
    return np.concatenate([np.c_[a, zero], np.c_[b[:, 0], zero, b[:, 1]], np.c_[zero, c]])


def small_cylinder(n: int = 300, seed: int = 0) -> np.ndarray:
    """Radius 0.3, height 1, axis the z axis through (0.5, 0.2, *): ``(n, 3)``."""
    rng = np.random.default_rng(seed)
    t, z = 2 * np.pi * rng.random(n), rng.random(n)
    return np.c_[0.5 + 0.3 * np.cos(t), 0.2 + 0.3 * np.sin(t), z]


def test_registry_lists_the_patches_and_shape_tabs():
    labels = [t.label for t in available_tabs()]
    assert "Patches" in labels and "Revolve / Extrude" in labels
    spec = {t.label: t for t in TABS}
    assert spec["Revolve / Extrude"].requires == "nurbskit.shapes" and spec["Revolve / Extrude"].attribute == "fit_shape"


def test_patches_tab_parts(tmp_path):
    """The tab's report, combined mesh and STEP export of a box corner's trimmed faces."""
    import nurbskit
    from nurbskit.patches import PatchConfig
    from nurbskit.studio.app import ExportPanel
    from nurbskit.studio.tabs import _patches_markdown, combined_mesh, patch_color
    from _extras import require_extra

    result = nurbskit.fit_patches(box_corner(), normals=None, config=PatchConfig(final_iters=0))
    assert result.metrics["N"] == len(result) >= 1 and len(result.faces) >= len(result)
    md = _patches_markdown(result)
    m = result.metrics
    for value in (f"| \\|N\\| (patches) | {m['N']} |", f"{m['completeness']:.1f} %", f"{m['P_cov_i']:.1f} %",
                  f"{m['P_cov_o']:.1f} %"):
        assert value in md
    v, f = combined_mesh(result)
    assert len(v) == sum(len(p.mesh[0]) for p in result.patches)
    assert len(f) == sum(len(p.mesh[1]) for p in result.patches)
    last = 0
    for p in result.patches:  # each patch's triangles index its own vertices in the combined mesh
        fp = f[last:last + len(p.mesh[1])]
        assert_close(v[fp], np.asarray(p.mesh[0])[np.asarray(p.mesh[1])], atol=0.0)
        last += len(p.mesh[1])
    assert len({patch_color(i) for i in range(len(result))}) == len(result)

    # the export panel writes the trimmed faces with write_cad; other NURBS formats refuse
    require_extra("OCP", "cad")
    from nurbskit.io.cad import read_cad
    from nurbskit.studio.registry import cad_writers

    panel = ExportPanel.__new__(ExportPanel)
    panel.shown = lambda: (result.faces, (v, f), "corner-patches")
    panel.cad, panel.own = cad_writers(), {}
    assert "STEP" in panel.cad
    panel.format = type("F", (), {"value": "STEP"})()
    panel.write(tmp_path / "corner.step")
    assert len(read_cad(tmp_path / "corner.step").faces) == len(result.faces)
    panel.format.value = "nurbskit JSON"
    with pytest.raises(OptionError, match="trimmed patches export as"):
        panel.write(tmp_path / "corner.json")
    assert not (tmp_path / "corner.json").exists()


def test_shape_tab_parts():
    """The report and the axis segment of a cylinder fitted as a surface of revolution."""
    from nurbskit.shapes import fit_shape
    from nurbskit.studio.tabs import _shape_markdown, axis_segment

    pts = small_cylinder()
    fit = fit_shape(pts, "revolution", iterations=5)
    seg = axis_segment(fit, pts)
    assert seg.shape == (1, 2, 3)
    d = seg[0, 1] - seg[0, 0]
    # along z, through (0.5, 0.2), spanning the points' heights with a margin
    assert_close(np.abs(d / np.linalg.norm(d)), np.array([0.0, 0.0, 1.0]), atol=3e-3)  # within 0.2 degrees
    assert_close(seg[0, :, :2], np.array([[0.5, 0.2], [0.5, 0.2]]), atol=5e-3)  # 0.5 % of the diagonal
    assert min(seg[0, :, 2]) < pts[:, 2].min() and max(seg[0, :, 2]) > pts[:, 2].max()
    md = _shape_markdown(fit)
    assert "| kind | revolution |" in md and f"{fit.distance_mean:.3g} of diag." in md
    assert "axis direction" in md


def test_page_is_built_before_the_fitting_code_imports(tmp_path):
    """Start-up order (issue 13: interactive within 3 s): ``nurbskit studio`` parses only its
    own options, the server listens and every tab's widgets are built (a session on the
    server's own GUI, as a page gets it) without importing torch; then the capabilities
    import and the tabs are activated (the generator's first object, the device list)."""
    import subprocess
    import sys

    from _extras import require_extra

    require_extra("viser", "studio")
    script = (
        "import sys, types\n"
        "from nurbskit.cli import build_parser\n"
        f"build_parser('studio').parse_args(['studio', '--workdir', {str(tmp_path)!r}])\n"
        "from nurbskit.studio import app\n"
        "from nurbskit.studio.app import Session, Studio, StudioOptions\n"
        "app.IMPORT_WITHOUT_PAGE = 1e6  # the import waits for the page however slow this machine is\n"
        "before = 'torch' in sys.modules\n"
        f"s = Studio(StudioOptions(port=0, workdir={str(tmp_path)!r}))\n"
        "s.start()\n"
        "listening = s.port > 0\n"
        "client = types.SimpleNamespace(scene=s.server.scene, gui=s.server.gui, client_id=0)\n"
        "page = Session(s, client)\n"
        "built = 'torch' in sys.modules or s.ready.is_set()\n"
        "gen = page.tabs['NURBS Generator']\n"
        "empty = gen.obj is None and page.loading is not None\n"
        "s.wait_ready(120)\n"
        "page.activate()\n"
        "print('RESULT', before, listening, built, empty, 'torch' in sys.modules, s.tab_errors, list(page.tabs),\n"
        "      gen.obj.kind, gen.root.visible, page.loading, page.tabs['Unsupervised'].device.options)\n"
        "s.stop()\n"
    )
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(sys.path))
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, env=env, timeout=180)
    assert out.returncode == 0, out.stderr[-2000:]
    [line] = [x for x in out.stdout.splitlines() if x.startswith("RESULT ")]
    tabs = [t.label for t in available_tabs()]
    devices = "('cpu', 'cuda')" if torch.cuda.is_available() else "('cpu',)"
    # the generator's object is drawn hidden: the page opens on the Unsupervised tab
    assert line == f"RESULT False True False True True {{}} {tabs} surface False None {devices}"


def test_static_choices_equal_the_library():
    """What the widgets offer, read from the sources without importing (``.choices``), is
    what the library has when imported: the one source of truth stays the library."""
    import nurbskit.io.cad
    import nurbskit.shapes
    import nurbskit.volume
    from nurbskit.fit.pipelines import PIPELINES
    from nurbskit.studio import choices
    from nurbskit.studio.registry import CAD_WRITERS, cad_writers

    for supervised in (False, True):
        live = tuple(k for k, p in PIPELINES.items() if p.supervised == supervised)
        assert choices.pipelines(supervised) == live and live
    assert choices.shape_kinds() == tuple(nurbskit.shapes.KINDS)
    assert choices.volume_losses() == tuple(nurbskit.volume.LOSSES)
    for spec in TABS:
        module = __import__(spec.requires, fromlist=["_"])
        assert choices.exists(spec.requires)
        if spec.attribute is not None:
            assert choices.declares(spec.requires, spec.attribute) == hasattr(module, spec.attribute)
        spec.load()  # imports, and finds the attribute
    assert set(cad_writers()) == {label for label, _, module, attr in CAD_WRITERS
                                  if hasattr(__import__(module, fromlist=["_"]), attr)}
    assert not choices.declares("nurbskit.fit", "no_such_function") and not choices.exists("nurbskit.no_such_module")
    # the readers on a module of their own: bindings under if/try, imports, literals, decorators
    tree = __import__("ast").parse(
        "import a.b\nfrom c import d as e\nX: int = 3\nif True:\n    Y = (1, 'two')\ntry:\n    Z = 1\n"
        "except ImportError:\n    W = 2\n@reg('n', True, 's')\ndef f(): pass\nclass C: pass\n")
    assert choices.top_level_names(tree) == {"a", "e", "X", "Y", "Z", "W", "f", "C"}


def test_curves_tab_parts(monkeypatch):
    """Pixels land upright in the z = 0 plane; curves become polylines through their ends; the
    tab offers exactly the options ``curves_from_image`` has beyond the classic ones."""
    import nurbskit.curves.api as api
    from nurbskit.curves.synthetic import curve_of
    from nurbskit.studio.tabs import curve_segments, image_to_world, method_options

    assert_close(image_to_world(np.array([[3.0, 4.0], [0.5, 0.0]])),
                 np.array([[3.0, -4.0, 0.0], [0.5, 0.0, 0.0]]), atol=0.0)
    curve = curve_of(np.array([[0.0, 0.0], [10.0, 0.0], [20.0, 0.0], [30.0, 0.0]]))
    segs = curve_segments([curve, curve])
    assert segs.shape[1:] == (2, 3) and segs.shape[0] >= 2 * 30  # at most 1 px apart
    assert_close(segs[0, 0], np.zeros(3), atol=1e-12)
    assert_close(segs[segs.shape[0] // 2 - 1, 1], np.array([30.0, 0.0, 0.0]), atol=1e-12)
    half = segs.shape[0] // 2
    assert_close(segs[1:half, 0], segs[:half - 1, 1], atol=0.0)  # one unbroken polyline per curve
    assert float(np.linalg.norm(segs[:, 1] - segs[:, 0], axis=1).max()) <= 1.0 + 1e-9

    def with_mode(image, method="classic", tolerance=1.0, refine=False, refine_iterations=20, mode="auto"):
        return []

    expected = {k: v.default for k, v in __import__("inspect").signature(api.curves_from_image).parameters.items()
                if k not in ("image", "method", "tolerance", "refine", "refine_iterations")}
    assert method_options() == expected
    monkeypatch.setattr(api, "curves_from_image", with_mode)
    assert method_options() == {"mode": "auto"}


def test_widget_defaults_are_the_librarys(tmp_path):
    """The tabs' widgets start at the library's own defaults where the studio does not
    choose otherwise (PatchConfig's, fit_shape's, curves_from_image's), and offer its
    choices: a page built on the server's own GUI, as a browser gets it."""
    import inspect
    import types

    from _extras import require_extra

    require_extra("viser", "studio")
    from nurbskit.curves.api import METHODS, curves_from_image
    from nurbskit.patches import PatchConfig
    from nurbskit.shapes import KINDS, fit_shape
    from nurbskit.studio.app import Session, Studio, StudioOptions

    s = Studio(StudioOptions(port=0, workdir=tmp_path)).start()
    try:
        page = Session(s, types.SimpleNamespace(scene=s.server.scene, gui=s.server.gui, client_id=0))
        patches, shape, curves = page.tabs["Patches"], page.tabs["Revolve / Extrude"], page.tabs["Curves from images"]
        cfg = PatchConfig()
        assert patches.eps.value == cfg.eps and tuple(patches.weights.value) == tuple(cfg.weights)
        assert patches.max_ctrl.value == cfg.max_ctrl and patches.final_iters.value == cfg.final_iters
        assert shape.iters.value == inspect.signature(fit_shape).parameters["iterations"].default
        assert set(shape.kind.options) == set(KINDS) and shape.kind.value == "auto"
        sig = inspect.signature(curves_from_image).parameters
        assert curves.tolerance.value == sig["tolerance"].default and curves.refine.value == sig["refine"].default
        assert curves.refine_iters.value == sig["refine_iterations"].default
        assert tuple(curves.method.options) == tuple(METHODS) and curves.method.value == sig["method"].default
        assert page.tabs["Unsupervised"].pipeline.value == "default"
    finally:
        s.stop()


def test_requests_from_other_sites_are_refused(tmp_path):
    # A page from another site may open ws://127.0.0.1:PORT in the user's browser; a name
    # pointed at 127.0.0.1 (DNS rebinding) arrives with its own Host. Both get 403; the
    # studio's own page (Origin = its Host) and clients that send no Origin connect.
    import asyncio
    import socket

    from _extras import require_extra

    require_extra("viser", "studio")
    from websockets.asyncio.client import connect
    from websockets.exceptions import InvalidStatus

    from nurbskit.studio.app import Studio, StudioOptions
    from nurbskit.studio.guard import refusal

    assert refusal({"Host": "127.0.0.1:8080", "Origin": "http://127.0.0.1:8080"}, True) is None
    assert refusal({"Host": "localhost:8080"}, True) is None
    assert "another site" in refusal({"Host": "127.0.0.1:8080", "Origin": "http://evil.example"}, True)
    assert "not a loopback name" in refusal({"Host": "evil.example:8080", "Origin": "http://evil.example:8080"}, True)
    assert refusal({"Host": "studio.lan:8080", "Origin": "http://studio.lan:8080"}, False) is None

    import viser

    s = Studio(StudioOptions(host="127.0.0.1", port=0, workdir=tmp_path)).start()
    try:
        port = s.server.get_port()

        async def status(**headers) -> int:
            try:
                async with connect(f"ws://127.0.0.1:{port}", subprotocols=[f"viser-v{viser.__version__}"], additional_headers=headers,
                                   open_timeout=20):
                    return 101
            except InvalidStatus as exc:
                return exc.response.status_code

        assert asyncio.run(status(Origin=f"http://127.0.0.1:{port}")) == 101
        assert asyncio.run(status()) == 101
        assert asyncio.run(status(Origin="http://evil.example")) == 403

        def raw(host: str, origin: str) -> str:  # a handshake whose Host a client chose (DNS rebinding)
            with socket.create_connection(("127.0.0.1", port), timeout=20) as sock:
                sock.sendall((f"GET / HTTP/1.1\r\nHost: {host}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
                              "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n"
                              f"Sec-WebSocket-Protocol: viser-v{viser.__version__}\r\nOrigin: {origin}\r\n\r\n").encode())
                return sock.recv(200).decode("latin-1").split("\r\n")[0]

        assert raw(f"evil.example:{port}", f"http://evil.example:{port}").startswith("HTTP/1.1 403")
        assert raw(f"localhost:{port}", f"http://localhost:{port}").startswith("HTTP/1.1 101")
    finally:
        s.stop()


def test_a_clients_widget_values_are_checked_on_the_server():
    # viser applies what a client sends; the studio first keeps only the value, and only
    # one the widget offers: numbers clamped into [min, max], choices among the options.
    import asyncio

    from _extras import require_extra

    require_extra("viser", "studio")
    import viser
    from viser import _messages

    from nurbskit.studio.guard import check_client_updates

    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    try:
        gui = server.gui
        number = gui.add_number("samples", 5, min=1, max=64, step=1)
        grid = gui.add_vector2("grid", (15, 15), min=(2, 2), max=(64, 64), step=1)
        device = gui.add_dropdown("device", ("cpu",), initial_value="cpu")
        assert check_client_updates(gui)

        def send(handle, **updates):
            message = _messages.GuiUpdateMessage(handle._impl.uuid, updates)
            asyncio.run(gui._websock_interface._handle_incoming_message("client", message))

        send(number, value=2000, max=10**9)
        assert number.value == 64 and number.max == 64
        send(number, value=float("nan"))
        assert number.value == 64
        send(grid, value=(2000, 1))
        assert grid.value == (64, 2)
        send(device, value="cuda:7", options=("cpu", "cuda:7"))
        assert device.value == "cpu" and tuple(device.options) == ("cpu",)
        send(number, value=12)
        assert number.value == 12
    finally:
        server.stop()


def test_hidden_names_and_link_loops_are_not_the_clients(tmp_path):
    from nurbskit.studio.workdir import Workdir

    (tmp_path / ".env").write_text("SECRET=1\n")
    (tmp_path / "loop.xyz").symlink_to(tmp_path / "loop.xyz")
    (tmp_path / "ok.xyz").write_text("0 0 0\n")
    wd = Workdir(tmp_path)
    assert wd.files() == ["ok.xyz"]  # the loop is not offered, and listing does not fail
    for name, says in ((".env", "hidden names"), ("a/.git/config.json", "hidden names"),
                       (".studio/uploads/x.xyz", "hidden names"), ("loop.xyz", "cannot be followed")):
        with pytest.raises(OptionError, match=says):
            wd.resolve(name, must_exist=False)
    with pytest.raises(OptionError, match="--workdir: expected a folder, got an empty name"):
        Workdir("")


def test_a_clients_file_may_take_ten_times_the_upload_limit_once_read(tmp_path, monkeypatch):
    # a compressed .npz of a few hundred KB declares 480 MB of points: refused by what the
    # studio gives one file, not by what the machine has, and named as the page knows it
    import types

    import nurbskit.studio.app as app
    from nurbskit.io import read_points
    from nurbskit.studio.app import READ_MEMORY_FACTOR, read_upload
    from nurbskit.studio.workdir import Workdir

    monkeypatch.setattr(app, "READ_MEMORY_FLOOR", 0)  # the floor (1 GiB) would take a bigger bomb than a test makes

    np.savez_compressed(tmp_path / "bomb.npz", points=np.zeros((20_000_000, 3)))
    session = types.SimpleNamespace(options=types.SimpleNamespace(max_upload_bytes=10 * 2**20),
                                    workdir=Workdir(tmp_path))
    upload = types.SimpleNamespace(name="bomb.npz", content=(tmp_path / "bomb.npz").read_bytes())
    with pytest.raises(InputError, match=rf"^bomb\.npz: reading the arrays needs about 457\.8 MB of memory but only "
                                         rf"{READ_MEMORY_FACTOR * 10:.1f} MB is available"):
        read_upload(session, upload, lambda path, name: read_points(path))
    assert list((tmp_path / ".studio" / "uploads").iterdir()) == []

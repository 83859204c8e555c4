"""``nurbskit batch`` on a real Dask LocalCluster (loopback, 2 worker processes).

The fits are tiny (150-point clouds, a 4 x 4 net, a few iterations) and most cluster
behaviour (worker killed, memory limit, timeout, an external scheduler) is exercised
with ``probe``, a test command defined in this module: it does what its input file
says (write a report, kill its own process, allocate memory, loop forever), so those
tests do not pay for fitting.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

import nurbskit
from nurbskit.batch import BatchCommand, find_items, get_command
from nurbskit.batch import commands as batch_commands
from nurbskit.batch import runner
from nurbskit.batch.inputs import assign_names
from nurbskit.batch.task import MARKER
from nurbskit.errors import InputError, NurbskitError, OptionError

from _assert import assert_close

SRC = Path(nurbskit.__file__).resolve().parents[1]
TESTS = Path(__file__).resolve().parent
PYTHON = sys.executable
FIT_OPTIONS = ["--iters", "3", "--ctrl", "4x4", "--resolution", "8x8", "--no-figures"]


def _require_dask():
    try:
        import distributed  # noqa: F401
    except ImportError:
        if os.environ.get("NURBSKIT_REQUIRE_EXTRAS", "") not in ("", "0"):
            pytest.fail("NURBSKIT_REQUIRE_EXTRAS is set but dask.distributed (the [dist] extra) is missing")
        pytest.skip("dask.distributed (the [dist] extra) is not installed")


@pytest.fixture(scope="module")
def client():
    """A local cluster made by the batch's own `connect`: 2 processes, no retries, 1.5 GB each."""
    _require_dask()
    import psutil

    before = {p.pid for p in _cluster_processes(os.getpid())}
    with runner.connect(workers=2, memory_limit="1.5GB", retries=0) as (dask_client, info):
        started = [p for p in _cluster_processes(os.getpid()) if p.pid not in before]
        assert len(started) >= 2
        yield dask_client
    gone, alive = psutil.wait_procs(started, timeout=30)
    assert alive == [], f"processes left after the cluster closed: {alive}"


def _cluster_processes(pid: int) -> list:
    """Descendants of ``pid`` except multiprocessing's resource tracker (one per Python
    process that ever spawned a child; it ends with that process, not with the cluster)."""
    import psutil

    out = []
    try:
        children = psutil.Process(pid).children(recursive=True)
    except psutil.NoSuchProcess:
        return []
    for p in children:
        try:
            if "resource_tracker" not in " ".join(p.cmdline()):
                out.append(p)
        except psutil.NoSuchProcess:
            pass
    return out


# --- the probe command (runs inside the workers: importable as this module) ------------------

def register(subparsers) -> None:
    p = subparsers.add_parser("probe")
    p.add_argument("input")
    p.add_argument("--out", required=True)
    p.add_argument("--overwrite", action="store_true")
    p.add_argument("--quiet", action="store_true")
    p.add_argument("--scale", type=float, default=1.0)
    p.set_defaults(run=run_probe)


def run_probe(args) -> int:
    import torch

    from nurbskit._fs import output_directory

    word = Path(args.input).read_text().strip()
    if word == "crash":
        os.kill(os.getpid(), signal.SIGKILL)
    if word == "hog":  # grows until the nanny restarts the worker (capped at 6 GB, never reached)
        hog = []
        for _ in range(60):
            hog.append(np.ones(100 * 2**20 // 8))
            time.sleep(0.05)
        raise RuntimeError("the memory limit never stopped this task")
    if word == "loop":
        while True:
            time.sleep(0.01)
    if word == "bad":
        raise InputError(f"{args.input}: not a probe")
    if word in ("swallow", "status"):  # a command that makes its own of the timeout
        try:
            while True:
                time.sleep(0.01)
        except BaseException:  # noqa: BLE001 - the point of this probe
            if word == "status":
                print("probe: stopped", file=sys.stderr)
                return 1
    with output_directory(args.out, args.overwrite) as tmp:
        report = {"value": len(word) * args.scale, "threads": torch.get_num_threads(), "pid": os.getpid()}
        (tmp / "report.json").write_text(json.dumps(report))
    return 0


def probe_metrics(report: dict) -> dict:
    return {"value": float(report["value"]), "threads": float(report["threads"]), "pid": float(report["pid"])}


PROBE = BatchCommand(name="probe", module=__name__, extensions=(".probe",), metrics=probe_metrics)


def _probes(folder: Path, words: dict[str, str]) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    for name, word in words.items():
        (folder / f"{name}.probe").write_text(word)
    return folder


@pytest.fixture
def clouds(tmp_path):
    folder = tmp_path / "clouds"
    folder.mkdir()
    for i in range(6):
        g = np.random.default_rng(i)
        uv = g.random((150, 2))
        np.savetxt(folder / f"cloud{i}.xyz", np.column_stack([uv, 0.2 * np.sin(3 * uv[:, 0] + i) * uv[:, 1]]))
    (folder / "garbage.ply").write_bytes(b"ply\nformat nonsense\n\x00\x01\x02")
    return folder


def _by_name(records):
    return {r["name"]: r for r in records}


# --- fit on a real cluster -----------------------------------------------------------------

def test_fit_folder_six_results_one_recorded_failure_then_resume_does_no_work(client, clouds, tmp_path, monkeypatch):
    out = tmp_path / "fits"
    records = nurbskit.batch.run("fit", [clouds], out, client=client, options=FIT_OPTIONS)
    by = _by_name(records)
    assert sorted(by) == [*(f"cloud{i}" for i in range(6)), "garbage"]
    assert [by[f"cloud{i}"]["status"] for i in range(6)] == ["ok"] * 6
    assert by["garbage"]["status"] == "failed"
    assert "garbage.ply" in by["garbage"]["error"] and "\n" not in by["garbage"]["error"]
    assert not (out / "garbage").exists()
    for i in range(6):
        folder = out / f"cloud{i}"
        assert {p.name for p in folder.iterdir()} == {"surface.json", "points.off", "control_points.off",
                                                    "report.json", "config.json", MARKER,
                                                    ".nurbskit-manifest.json"}
        report = json.loads((folder / "report.json").read_text())
        assert by[f"cloud{i}"]["metrics"] == {"to_surface_mean": report["metrics"]["to_surface_mean"],
                                              "to_surface_p95": report["metrics"]["to_surface_p95"]}
        assert 0 < report["metrics"]["to_surface_mean"] <= report["metrics"]["to_surface_p95"]
    # no temporary leftovers; the manifest lists the summary files the batch wrote
    assert [p.name for p in out.iterdir() if p.name.startswith(".")] == [".nurbskit-manifest.json"]

    # The outputs are those of the single command (same seed, same options).
    from nurbskit.cli import main

    single = tmp_path / "single"
    assert main(["fit", str(clouds / "cloud3.xyz"), "--out", str(single), "--quiet", *FIT_OPTIONS]) == 0
    ours = json.loads((out / "cloud3" / "surface.json").read_text())
    theirs = json.loads((single / "surface.json").read_text())
    assert_close(np.array(ours["control_points"]), np.array(theirs["control_points"]), atol=1e-12)

    # The summary: one row per input and the aggregate (mean of the ok rows).
    lines = (out / "summary.csv").read_text().strip().splitlines()
    assert lines[0].split(",")[:6] == ["input", "name", "status", "error", "seconds", "resumed"]
    assert len(lines) == 1 + 7 + 1 and lines[-1].startswith("ALL,")
    summary = json.loads((out / "summary.json").read_text())
    assert summary["aggregate"]["status"] == "6 ok, 1 failed"
    mean = np.mean([by[f"cloud{i}"]["metrics"]["to_surface_mean"] for i in range(6)])
    assert_close(summary["aggregate"]["to_surface_mean"], mean, atol=1e-15)
    assert (out / "summary.png").stat().st_size > 1000

    # --resume on the six clouds: nothing is submitted (no cluster is even asked for),
    # and the finished folders are not touched.
    stamps = {p: p.stat().st_mtime_ns for p in out.glob("cloud*/*")}

    def no_cluster(*args, **kwargs):
        raise AssertionError("--resume started a cluster although every input was finished")

    monkeypatch.setattr(runner, "connect", no_cluster)
    again = nurbskit.batch.run("fit", [str(clouds / "*.xyz")], out, options=FIT_OPTIONS, resume=True)
    assert [r["resumed"] for r in again] == [True] * 6
    assert [r["metrics"] for r in again] == [by[f"cloud{i}"]["metrics"] for i in range(6)]
    assert {p: p.stat().st_mtime_ns for p in out.glob("cloud*/*")} == stamps
    assert json.loads((out / "summary.json").read_text())["submitted"] == 0

    # Resuming with other options would mix two runs: refused before any work.
    with pytest.raises(OptionError, match="--overwrite"):
        nurbskit.batch.run("fit", [str(clouds / "*.xyz")], out, options=["--iters", "4"], resume=True)
    # And a non-empty --out needs --resume or --overwrite.
    with pytest.raises(OptionError, match="--resume"):
        nurbskit.batch.run("fit", [clouds], out, options=FIT_OPTIONS)


# --- worker loss, memory, timeout, resume of failures (the probe command) -----------------

def test_killed_worker_is_recorded_and_the_others_finish(client, tmp_path):
    inputs = _probes(tmp_path / "in", {"a": "aa", "b": "bbb", "crash": "crash", "c": "c", "d": "dddd", "bad": "bad"})
    out = tmp_path / "out"
    records = nurbskit.batch.run(PROBE, [inputs], out, client=client, options=["--scale", "2"], threads_per_worker=2)
    by = _by_name(records)
    assert {k: r["status"] for k, r in by.items()} == {"a": "ok", "b": "ok", "c": "ok", "d": "ok",
                                                       "crash": "failed", "bad": "failed"}
    assert "worker process died" in by["crash"]["error"]
    assert by["bad"]["error"].endswith("bad.probe: not a probe")
    assert [by[k]["metrics"]["value"] for k in "abcd"] == [4.0, 6.0, 2.0, 8.0]  # the option reached the command
    assert {by[k]["metrics"]["threads"] for k in "abcd"} == {2.0}  # torch threads per task
    assert not (out / "crash").exists() and not (out / "bad").exists()
    for k in "abcd":
        assert (out / k / MARKER).is_file()

    # --resume runs only what did not finish; the finished folders keep their files.
    (inputs / "crash.probe").write_text("fixed")
    stamps = {p: p.stat().st_mtime_ns for p in out.glob("[abcd]/*")}
    again = _by_name(nurbskit.batch.run(PROBE, [inputs], out, client=client, options=["--scale", "2"], resume=True))
    assert {k: r["resumed"] for k, r in again.items()} == {"a": True, "b": True, "c": True, "d": True,
                                                          "crash": False, "bad": False}
    assert again["crash"]["status"] == "ok" and again["crash"]["metrics"]["value"] == 10.0
    assert json.loads((out / "summary.json").read_text())["submitted"] == 2
    assert {p: p.stat().st_mtime_ns for p in out.glob("[abcd]/*")} == stamps


def test_local_workers_allocate_like_a_plain_process(client):
    # Dask's nanny sets MALLOC_TRIM_THRESHOLD_ (which pins glibc's mmap threshold and, for a
    # fit, doubles the CPU time in page faults); the batch's local cluster leaves it unset,
    # also in a worker its nanny restarted (found by running this after the killed-worker test).
    # A worker killed by an earlier test may still be coming back: count both before and after.
    client.wait_for_workers(2, timeout=120)
    client.restart_workers([next(iter(client.scheduler_info()["workers"]))])
    client.wait_for_workers(2, timeout=120)
    env = client.run(lambda: os.environ.get("MALLOC_TRIM_THRESHOLD_"))
    assert len(env) == 2 and set(env.values()) == {os.environ.get("MALLOC_TRIM_THRESHOLD_")}
    # and without the statistical profiler sampling the fits' stacks every 10 ms
    profiling = client.run(lambda dask_worker: "profile" in dask_worker.periodic_callbacks)
    assert set(profiling.values()) == {False}
    # and with Dask's diagnostic tick and system monitor slowed (the idle cluster's CPU), in the
    # workers and the scheduler, while the memory monitor that enforces --memory-limit keeps 100 ms
    def intervals(dask_worker=None, dask_scheduler=None):
        callbacks = (dask_worker or dask_scheduler).periodic_callbacks
        return {name: callbacks[name].callback_time for name in ("tick", "monitor", "memory_monitor")
                if name in callbacks}

    expected = {"tick": 200, "monitor": 2000}
    assert list(client.run(intervals).values()) == [{**expected, "memory_monitor": 100}] * 2
    assert client.run_on_scheduler(intervals) == expected


def test_dataframe_return_needs_pandas(client, tmp_path, monkeypatch):
    inputs = _probes(tmp_path / "in", {"a": "aa", "b": "bbb", "bad": "bad"})
    try:
        import pandas
    except ImportError:
        pandas = None
    if pandas is not None:
        df = nurbskit.batch.run(PROBE, [inputs], tmp_path / "out", client=client, dataframe=True)
        assert list(df["name"]) == ["a", "b", "bad"] and list(df["status"]) == ["ok", "ok", "failed"]
        assert list(df["value"])[:2] == [2.0, 3.0]
    monkeypatch.setitem(sys.modules, "pandas", None)  # import pandas -> ImportError
    with pytest.raises(OptionError, match="needs pandas"):
        nurbskit.batch.run(PROBE, [inputs], tmp_path / "out2", client=client, dataframe=True)
    assert not (tmp_path / "out2").exists()  # refused before any work


def test_memory_limit_kills_the_worker_and_the_input_is_recorded(client, tmp_path):
    inputs = _probes(tmp_path / "in", {"hog": "hog", "x": "xx"})
    records = _by_name(nurbskit.batch.run(PROBE, [inputs], tmp_path / "out", client=client, memory_limit="1.5GB"))
    assert records["x"]["status"] == "ok"
    assert records["hog"]["status"] == "failed"
    assert "killed for memory" in records["hog"]["error"], records["hog"]["error"]


def test_timeout_stops_the_task_and_records_it(client, tmp_path):
    inputs = _probes(tmp_path / "in", {"slow": "loop", "y": "y"})
    start = time.perf_counter()
    records = _by_name(nurbskit.batch.run(PROBE, [inputs], tmp_path / "out", client=client, timeout=1.5))
    assert records["slow"]["status"] == "failed"
    assert records["slow"]["error"] == "timed out after 1.5 s (--timeout)"
    assert records["y"]["status"] == "ok"
    assert time.perf_counter() - start < 60  # the endless loop was stopped (no assertion on speed)
    assert [p.name for p in (tmp_path / "out").iterdir() if p.name.startswith(".")] == [".nurbskit-manifest.json"]


# --- the command line: its own cluster, interrupts, an external scheduler ---------------------

def _env():
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(SRC), str(TESTS), env.get("PYTHONPATH", "")])
    env["OMP_NUM_THREADS"] = "1"
    return env


def test_local_cluster_processes_end_with_the_run(tmp_path):
    _require_dask()
    import psutil

    inputs = _probes(tmp_path / "in", {"a": "a", "b": "bb"})
    seen = []
    others = {p.pid for p in _cluster_processes(os.getpid())}  # e.g. the module's cluster

    def progress(event):
        if event["event"] == "started":
            seen.extend(p for p in _cluster_processes(os.getpid()) if p.pid not in others)
            assert event["workers"] == 2 and event["scheduler"].startswith("tcp://127.0.0.1:")
            dashboards.append(event["dashboard"])
            if event["dashboard"] is not None:  # with bokeh: the page answers, on loopback
                import urllib.request

                assert event["dashboard"].startswith("http://127.0.0.1:")
                with urllib.request.urlopen(event["dashboard"], timeout=30) as response:
                    assert response.status == 200

    dashboards = []

    records = nurbskit.batch.run(PROBE, [inputs], tmp_path / "out", workers=2, progress=progress)
    assert [r["status"] for r in records] == ["ok", "ok"]
    assert {r["metrics"]["pid"] for r in records} <= {p.pid for p in seen}  # the items ran in those processes
    import importlib.util

    from _extras import extras_required

    has_bokeh = importlib.util.find_spec("bokeh") is not None
    if not has_bokeh and extras_required():
        pytest.fail("NURBSKIT_REQUIRE_EXTRAS is set but bokeh (the [dist] extra's dashboard) is missing")
    assert (dashboards[0] is not None) == has_bokeh  # no address printed that would answer "install bokeh"
    assert len(seen) >= 2
    gone, alive = psutil.wait_procs(seen, timeout=30)
    assert alive == [], f"left running: {[(p.pid, _cmdline(p)) for p in alive]}"


def _cmdline(p) -> str:
    try:
        return " ".join(p.cmdline())[:200]
    except Exception:  # noqa: BLE001 - a diagnostic only
        return "?"


def test_ctrl_c_ends_every_process_and_leaves_no_half_written_output(clouds, tmp_path):
    _require_dask()
    import psutil

    out = tmp_path / "out"
    proc = subprocess.Popen(
        [PYTHON, "-m", "nurbskit", "batch", "fit", str(clouds), "--out", str(out), "--workers", "2", "--quiet",
         "--", "--iters", "100000", "--ctrl", "4x4", "--resolution", "8x8", "--no-figures"],
        env=_env(), stderr=subprocess.PIPE, stdout=subprocess.PIPE, text=True, start_new_session=True,
    )
    lines = []
    reader = threading.Thread(target=lambda: lines.extend(proc.stderr), daemon=True)
    reader.start()
    try:
        deadline = time.monotonic() + 120
        while not any("scheduler tcp://" in ln for ln in lines) and time.monotonic() < deadline and proc.poll() is None:
            time.sleep(0.2)
        assert any("scheduler tcp://" in ln for ln in lines), lines
        time.sleep(1.0)
        started = _cluster_processes(proc.pid)
        assert len(started) >= 2
        os.killpg(proc.pid, signal.SIGINT)  # what Ctrl-C in a terminal does: the whole group
        assert proc.wait(timeout=90) == 130
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    gone, alive = psutil.wait_procs(started, timeout=30)
    assert alive == [], f"left running after Ctrl-C: {alive}"
    reader.join(timeout=5)
    assert any("interrupted" in ln for ln in lines) and not any("Traceback" in ln for ln in lines), lines
    said = [ln for ln in lines if "nurbskit batch: interrupted" in ln]
    assert len(said) == 1 and "no partial output" not in said[0], lines
    assert "inputs finished and the summary in" in said[0] and "--resume" in said[0], said
    # Only complete folders: each one has its completion marker; the summary says what ran.
    for folder in out.iterdir():
        if folder.is_dir():
            assert not folder.name.startswith("."), folder
            assert (folder / MARKER).is_file(), folder
    summary = json.loads((out / "summary.json").read_text())
    assert summary["interrupted"] is True
    assert {r["status"] for r in summary["rows"]} <= {"ok", "failed"}


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_existing_scheduler_and_worker_through_the_cli(tmp_path, monkeypatch):
    _require_dask()
    import psutil

    bin_dir = Path(PYTHON).parent
    dask_cli = str(bin_dir / "dask") if (bin_dir / "dask").exists() else None
    if dask_cli is None:
        pytest.fail(f"the dask command line is missing from {bin_dir}")
    port = _free_port()
    address = f"tcp://127.0.0.1:{port}"
    procs = [subprocess.Popen([dask_cli, "scheduler", "--host", "127.0.0.1", "--port", str(port), "--no-dashboard"],
                              env=_env(), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)]
    try:
        procs.append(subprocess.Popen(
            [dask_cli, "worker", address, "--host", "127.0.0.1", "--nworkers", "1", "--nthreads", "1",
             "--no-dashboard", "--memory-limit", "1GB"],
            env=_env(), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True))
        from distributed import Client

        with Client(address, timeout="60s") as c:
            c.wait_for_workers(1, timeout=120)
        monkeypatch.setitem(batch_commands.COMMANDS, "probe", PROBE)
        inputs = _probes(tmp_path / "in", {"p": "ppp", "q": "q", "bad": "bad"})
        from nurbskit.cli import main

        code = main(["batch", "probe", str(inputs), "--out", str(tmp_path / "out"), "--scheduler", address,
                     "--quiet", "--", "--scale", "3"])
        assert code == 1  # one input failed
        summary = _by_name(json.loads((tmp_path / "out" / "summary.json").read_text())["rows"])
        assert {k: r["status"] for k, r in summary.items()} == {"p": "ok", "q": "ok", "bad": "failed"}
        assert summary["p"]["value"] == 9.0
        # The external cluster is left running: it is not ours to stop.
        assert all(p.poll() is None for p in procs)
    finally:
        everything = [psutil.Process(p.pid) for p in procs if p.poll() is None]
        for p in list(everything):
            everything += _cluster_processes(p.pid)
        for p in procs:
            if p.poll() is None:
                os.killpg(p.pid, signal.SIGTERM)
        gone, alive = psutil.wait_procs(everything, timeout=30)
        for p in alive:
            p.kill()


def test_volume_csv_rows_run_through_volume(client, tmp_path):
    from PIL import Image

    from nurbskit.volume.shapes import solid_drawings, sphere_and_box

    rows = ["front,left,top,name"]
    for k in range(2):
        for view, mask in solid_drawings(sphere_and_box, 24).items():
            Image.fromarray(((1 - mask.numpy()) * 255).astype(np.uint8)).save(tmp_path / f"{view}{k}.png")
        rows.append(f"front{k}.png,left{k}.png,top{k}.png,shape{k}")
    (tmp_path / "drawings.csv").write_text("\n".join(rows) + "\n")
    records = nurbskit.batch.run("volume", [tmp_path / "drawings.csv"], tmp_path / "out", client=client,
                                 options=["--iters", "3", "--control-size", "6", "--grid", "6"])
    assert [r["name"] for r in records] == ["shape0", "shape1"]
    assert [r["status"] for r in records] == ["ok", "ok"], records
    report = json.loads((tmp_path / "out" / "shape0" / "report.json").read_text())
    assert records[0]["metrics"]["mean_iou"] == report["mean_iou"]
    assert (tmp_path / "out" / "shape0" / "mesh.obj").is_file()


def test_curves_and_patches_run_through_the_registry(client, tmp_path):
    from PIL import Image

    for k in range(2):
        img = np.full((48, 48), 255, np.uint8)
        img[20 + k : 23 + k, 4:44] = 0  # one horizontal stroke
        Image.fromarray(img).save(tmp_path / f"stroke{k}.png")
    records = nurbskit.batch.run("curves", [tmp_path], tmp_path / "out", client=client)
    assert sorted(r["status"] for r in records) == ["ok", "ok"], records
    first = next(r for r in records if r["name"].startswith("stroke0"))
    report = json.loads((tmp_path / "out" / first["name"] / "report.json").read_text())
    assert first["metrics"] == {"curves": 1.0, "chamfer_px": report["chamfer_px"]["symmetric"]}
    assert set(nurbskit.batch.COMMANDS) >= {"fit", "volume", "patches", "shape", "curves"}


def test_shape_through_the_cli_on_the_cluster_kind_per_input(client, tmp_path, capsys):
    # `nurbskit batch shape ... -- --kind auto` (the issue's `fit --kind ...`): a vase of
    # revolution and an extruded wave; the summary names the kind fitted to each.
    g = np.random.default_rng(0)
    folder = tmp_path / "clouds"
    folder.mkdir()
    t, z = g.random(400) * 2 * np.pi, g.random(400) * 2
    r = 1 + 0.3 * np.sin(2 * z)
    np.savetxt(folder / "vase.xyz", np.column_stack([r * np.cos(t), r * np.sin(t), z]))
    x, h = g.random(400) * 3, g.random(400) * 2
    np.savetxt(folder / "wave.xyz", np.column_stack([x, 0.5 * np.sin(2 * x), h]))
    from nurbskit.cli import main

    out = tmp_path / "shapes"
    code = main(["batch", "shape", str(folder), "--out", str(out), "--scheduler", client.scheduler.address,
                 "--quiet", "--", "--kind", "auto", "--iters", "5", "--no-figures"])
    assert code == 0, capsys.readouterr().err
    summary = json.loads((out / "summary.json").read_text())
    rows = _by_name(summary["rows"])
    assert (rows["vase"]["kind"], rows["wave"]["kind"]) == ("revolution", "extrusion")
    for name in ("vase", "wave"):
        report = json.loads((out / name / "report.json").read_text())
        assert report["kind"] == rows[name]["kind"]
        assert rows[name]["to_surface_p95"] == report["metrics"]["to_surface_p95"] < 5e-3
    assert summary["aggregate"]["kind"] in ("revolution: 1, extrusion: 1", "extrusion: 1, revolution: 1")
    header, *lines = (out / "summary.csv").read_text().strip().splitlines()
    assert header.split(",")[6] == "kind" and lines[-1].startswith("ALL,")
    assert (out / "summary.png").stat().st_size > 1000


def test_export_json_surfaces_to_step_read_back_by_opencascade(client, tmp_path):
    import torch

    from _extras import require_extra

    require_extra("OCP", "cad")
    from nurbskit.io.cad import read_cad

    folder = tmp_path / "surfaces"
    folder.mkdir()
    surfaces = {}
    for i, sizes in enumerate([(4, 4), (5, 4), (4, 6)]):
        g = torch.Generator().manual_seed(i)
        surfaces[f"s{i}"] = nurbskit.NURBSSurface(torch.rand(*sizes, 3, dtype=torch.float64, generator=g), (3, 3))
        nurbskit.core.save(surfaces[f"s{i}"], folder / f"s{i}.json")
    (folder / "garbage.json").write_text("{not json")
    (folder / "report.json").write_text("{}")  # a result's side file: no input of a folder search
    out = tmp_path / "steps"
    records = _by_name(nurbskit.batch.run("export", [folder], out, client=client, options=["--format", "step"]))
    assert sorted(records) == ["garbage", "s0", "s1", "s2"]
    assert records["garbage"]["status"] == "failed" and "garbage.json" in records["garbage"]["error"]
    assert "\n" not in records["garbage"]["error"] and not (out / "garbage").exists()
    for name, surface in surfaces.items():
        assert records[name]["status"] == "ok", records[name]
        files = {p.name for p in (out / name).iterdir()}
        assert files == {f"{name}.step", "report.json", MARKER, ".nurbskit-manifest.json"}
        assert (records[name]["metrics"]["valid"], records[name]["metrics"]["faces"]) == (1.0, 1.0)
        model = read_cad(out / name / f"{name}.step")  # read back independently of the batch
        assert len(model.faces) == 1
        back = model.faces[0].surface
        assert back.sizes == surface.sizes
        assert_close(back.control_points, surface.control_points, atol=1e-12)
    summary = json.loads((out / "summary.json").read_text())
    assert summary["aggregate"]["status"] == "3 ok, 1 failed" and summary["aggregate"]["valid"] == 1.0


# --- no cluster needed -------------------------------------------------------------------------

def test_import_does_not_load_dask():
    code = "import sys, nurbskit.batch, nurbskit.cli.batch_command; print('distributed' in sys.modules, 'dask' in sys.modules)"
    out = subprocess.run([PYTHON, "-c", code], env=_env(), capture_output=True, text=True, check=True).stdout
    assert out.split() == ["False", "False"]


def test_missing_extra_names_it(tmp_path, monkeypatch):
    inputs = _probes(tmp_path / "in", {"a": "a"})
    monkeypatch.setitem(sys.modules, "distributed", None)  # import distributed -> ImportError
    with pytest.raises(NurbskitError, match=r"nurbskit\[dist\]"):
        nurbskit.batch.run(PROBE, [inputs], tmp_path / "out")


def test_options_are_checked_before_any_work(tmp_path, monkeypatch, clouds, capsys):
    def no_cluster(*args, **kwargs):
        raise AssertionError("a cluster was started for a bad option")

    monkeypatch.setattr(runner, "connect", no_cluster)
    from nurbskit.cli import main

    assert main(["batch", "fit", str(clouds), "--out", str(tmp_path / "o"), "--", "--no-such-option"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--no-such-option" in err
    with pytest.raises(OptionError, match="set by nurbskit batch"):
        nurbskit.batch.run("fit", [clouds], tmp_path / "o", options=["--out", "x"])
    assert main(["batch", "fit", str(tmp_path / "missing"), "--out", str(tmp_path / "o")]) == 2
    assert "missing: no such file or folder" in capsys.readouterr().err
    assert main(["batch", "fit", str(clouds), "--out", str(tmp_path / "o"), "--", "--kind", "revolution"]) == 2
    assert "nurbskit batch shape" in capsys.readouterr().err  # fit --kind: the exact shapes are `shape`
    assert main(["batch", "nope", str(clouds), "--out", str(tmp_path / "o")]) == 2
    assert "COMMAND: expected one of" in capsys.readouterr().err
    assert main(["batch", "fit", str(clouds), "--out", str(tmp_path / "o"), "--workers", "0"]) == 2
    assert main(["batch", "fit", str(clouds)]) == 2
    assert "--out DIR is required" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


def test_inputs_files_folders_globs_and_unique_names(tmp_path):
    a, b = tmp_path / "a", tmp_path / "b"
    for folder in (a, b, a / "deeper", a / ".hidden"):
        folder.mkdir(parents=True)
    for path in (a / "x.xyz", b / "x.xyz", a / "x.ply", a / "deeper" / "y.off", a / ".hidden" / "z.xyz",
                 a / "notes.md", b / "summary.json.xyz"):
        path.write_text("0 0 0\n")
    fit = get_command("fit")
    items = find_items([a, str(b / "*.xyz"), a / "x.xyz"], fit)
    names = {Path(i.paths[0]).relative_to(tmp_path).as_posix(): i.name for i in items}
    assert names == {"a/x.ply": "x.ply", "a/x.xyz": "a_x", "b/x.xyz": "b_x", "a/deeper/y.off": "y",
                     "b/summary.json.xyz": "summary.json_"}
    with pytest.raises(InputError, match="no file matches"):
        find_items([str(tmp_path / "*.nothing")], fit)
    (tmp_path / "empty").mkdir()
    with pytest.raises(InputError, match="holds no fit input"):
        find_items([tmp_path / "empty"], fit)
    # The output folder inside an input folder is not searched (its points.off are no inputs).
    (a / "fits" / "x").mkdir(parents=True)
    (a / "fits" / "x" / "points.off").write_text("OFF\n0 0 0\n")
    assert all("fits" not in i.paths[0] for i in find_items([a], fit, exclude=a / "fits"))
    # Same stems everywhere: numbered in the end, still unique and deterministic.
    clash = [batch_commands.Item(name="s", inputs=(("input", f"/{k}/s.xyz"),), source="") for k in "pq"] * 2
    named = [i.name for i in assign_names(clash)]
    assert len(set(named)) == 4 and named == [i.name for i in assign_names(clash)]


def test_volume_csv_parsing(tmp_path):
    (tmp_path / "t.csv").write_text("# drawings\nf.png,l.png,t.png\n/abs/f2.png, l2.png ,t2.png,named\n")
    items = batch_commands.volume_rows(tmp_path / "t.csv")
    assert [i.name for i in items] == ["f", "named"]
    assert dict(items[1].inputs) == {"front": "/abs/f2.png", "left": str(tmp_path / "l2.png"), "top": str(tmp_path / "t2.png")}
    assert batch_commands.volume_argv(items[0])[:2] == ["--front", str(tmp_path / "f.png")]
    (tmp_path / "bad.csv").write_text("front,left,top\na.png,,c.png\n")
    with pytest.raises(InputError, match="row 2: expected front, left and top drawings, missing left"):
        batch_commands.volume_rows(tmp_path / "bad.csv")


def test_parsers_reuse_the_single_command(tmp_path):
    from nurbskit.batch.task import command_args

    item = batch_commands.Item(name="c", inputs=(("input", "c.xyz"),), source="c.xyz")
    args = command_args(get_command("fit"), item, tmp_path / "c", ["--iters", "7", "--pipeline", "UB"])
    assert (args.input, args.iters, args.pipeline, args.out, args.overwrite, args.quiet) == \
        ("c.xyz", 7, "UB", str(tmp_path / "c"), True, True)
    with pytest.raises(OptionError, match="--iters"):
        command_args(get_command("fit"), item, tmp_path / "c", ["--iters", "many"])
    assert isinstance(args, argparse.Namespace)


def test_summary_rows_and_aggregate():
    from nurbskit.batch.summary import aggregate, flat_rows

    records = [
        {"input": "a", "name": "a", "status": "ok", "error": "", "seconds": 1.0, "metrics": {"m": 1.0, "k": 4.0}},
        {"input": "b", "name": "b", "status": "ok", "error": "", "seconds": 2.0, "metrics": {"m": 3.0}, "resumed": True},
        {"input": "c", "name": "c", "status": "failed", "error": "x", "seconds": 0.5, "metrics": {}},
    ]
    rows = flat_rows(records)
    assert [r["m"] for r in rows][:2] == [1.0, 3.0] and np.isnan(rows[2]["m"]) and np.isnan(rows[1]["k"])
    total = aggregate(records)
    assert (total["status"], total["seconds"], total["m"], total["k"], total["resumed"]) == ("2 ok, 1 failed", 3.5, 2.0, 4.0, 1)
    # A label metric (strings) is counted per value over the ok rows, most common first.
    labelled = [{**r, "metrics": {**r["metrics"], "kind": kind}} for r, kind in zip(records * 2, "abacba")]
    assert aggregate(labelled)["kind"] == "b: 2, a: 1, c: 1"  # the failed rows (a, a) are not counted


def test_deadline_interrupts_python_loops_and_leaves_no_stray_exception():
    from nurbskit.batch.task import Deadline, TaskTimeout

    with pytest.raises(TaskTimeout):
        with Deadline(0.2):
            while True:
                time.sleep(0.001)
    with Deadline(5.0):  # finishes in time: nothing is raised, then or later
        total = sum(range(1000))
    for _ in range(200):
        time.sleep(0.001)
    assert total == 499500


def test_run_item_in_process_records_and_marker(tmp_path):
    from nurbskit.batch.task import read_marker, run_item

    inputs = _probes(tmp_path / "in", {"good": "abc", "bad": "bad", "slow": "loop"})
    items = {i.name: i for i in find_items([inputs], PROBE)}
    out = tmp_path / "out"
    ok = run_item(items["good"], command=PROBE, out_root=str(out), options=["--scale", "0.5"], threads=1)
    assert (ok["status"], ok["error"], ok["metrics"]["value"]) == ("ok", "", 1.5)
    marker = read_marker(out / "good")
    assert marker["command"] == "probe" and marker["options"] == ["--scale", "0.5"] and marker["record"]["status"] == "ok"
    bad = run_item(items["bad"], command=PROBE, out_root=str(out), options=[], threads=1)
    assert bad["status"] == "failed" and bad["error"].endswith("bad.probe: not a probe")
    slow = run_item(items["slow"], command=PROBE, out_root=str(out), options=[], threads=1, timeout=0.3)
    assert slow["error"] == "timed out after 0.3 s (--timeout)"
    assert sorted(p.name for p in out.iterdir()) == ["good"]


def test_resume_trusts_only_a_matching_marker(tmp_path):
    from nurbskit.batch.task import run_item

    inputs = _probes(tmp_path / "in", {"good": "abc", "half": "xy"})
    items = {i.name: i for i in find_items([inputs], PROBE)}
    out = tmp_path / "out"
    run_item(items["good"], command=PROBE, out_root=str(out), options=["--scale", "2"])
    (out / "half").mkdir()  # an output without its marker: an earlier run stopped before the end
    (out / "half" / "report.json").write_text("{}")
    assert runner.completed(PROBE, items["half"], out, ["--scale", "2"]) is None
    record = runner.completed(PROBE, items["good"], out, ["--scale", "2"])
    assert record["resumed"] is True and record["metrics"]["value"] == 6.0
    with pytest.raises(OptionError, match="--overwrite"):
        runner.completed(PROBE, items["good"], out, ["--scale", "3"])
    path = Path(items["good"].paths[0])
    os.utime(path, ns=(path.stat().st_atime_ns, path.stat().st_mtime_ns + 10**9))  # the input changed
    assert runner.completed(PROBE, items["good"], out, ["--scale", "2"]) is None


def test_summary_figure_with_values_equal_up_to_rounding(tmp_path):
    # Two inputs whose metrics differ by one unit in the last place: numpy cannot make 5
    # bins of that range (found by CI on two identical drawings); one bar is drawn.
    from nurbskit.batch.summary import plot_summary

    v = 0.4900257753980464
    records = [{"name": n, "status": "ok", "seconds": 1.0, "metrics": {"chamfer_px": x, "curves": 1.0}}
               for n, x in (("a", v), ("b", float(np.nextafter(v, 1.0))))]
    path = plot_summary(records, tmp_path / "summary.png")
    assert path.is_file() and path.stat().st_size > 1000


# --- refused before any work: summary files, --scheduler, --memory-limit, --out ---------------

def test_summary_files_the_batch_did_not_write_are_never_replaced(client, tmp_path, monkeypatch, capsys):
    inputs = _probes(tmp_path / "in", {"a": "aa", "b": "bbb"})
    monkeypatch.setitem(batch_commands.COMMANDS, "probe", PROBE)
    from nurbskit.cli import main

    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "summary.csv").write_text("my,csv\n")
    (mine / "summary.png").write_bytes(b"my picture")
    for flag in ("--resume", "--overwrite"):
        assert main(["batch", "probe", str(inputs), "--out", str(mine), flag, "--scheduler",
                     client.scheduler.address, "--quiet"]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and "summary.csv (not in its .nurbskit-manifest.json)" in err
        assert "summary.png" in err and "Traceback" not in err
    assert sorted(p.name for p in mine.iterdir()) == ["summary.csv", "summary.png"]  # nothing run, nothing written
    assert (mine / "summary.csv").read_text() == "my,csv\n"

    # The batch's own summary files are listed in the folder's manifest, so that a later
    # --resume or --overwrite of its own run replaces them.
    out = tmp_path / "out"
    nurbskit.batch.run(PROBE, [inputs], out, client=client)
    manifest = json.loads((out / ".nurbskit-manifest.json").read_text())["files"]
    assert manifest == {n: (out / n).stat().st_size for n in ("summary.csv", "summary.json", "summary.png")}
    records = nurbskit.batch.run(PROBE, [inputs], out, client=client, overwrite=True, figure=False)
    assert [r["status"] for r in records] == ["ok", "ok"]
    assert not (out / "summary.png").exists()  # the earlier run's figure, which this run did not redo
    assert sorted(json.loads((out / ".nurbskit-manifest.json").read_text())["files"]) == ["summary.csv", "summary.json"]
    assert [r["resumed"] for r in nurbskit.batch.run(PROBE, [inputs], out, client=client, resume=True)] == [True, True]
    # A summary file the user changed since is theirs now.
    with open(out / "summary.json", "a") as handle:
        handle.write("my note\n")
    with pytest.raises(OptionError, match=r"summary.json \(changed since nurbskit batch wrote it\)"):
        nurbskit.batch.run(PROBE, [inputs], out, client=client, resume=True)
    assert (out / "summary.json").read_text().endswith("my note\n")


@pytest.mark.parametrize("address", ["garbage", "tcp://host", "tcp://host:port", "tcp://host:99999", "foo://host:1",
                                     "inproc://x"])
def test_a_bad_scheduler_address_is_refused_before_any_work(tmp_path, monkeypatch, capsys, address):
    _require_dask()
    from nurbskit.cli import main

    monkeypatch.setattr(runner, "connect", lambda *a, **k: pytest.fail("connected to a bad address"))
    monkeypatch.setitem(batch_commands.COMMANDS, "probe", PROBE)
    inputs = _probes(tmp_path / "in", {"a": "a"})
    assert main(["batch", "probe", str(inputs), "--out", str(tmp_path / "out"), "--scheduler", address]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--scheduler: expected tcp://HOST:PORT" in err and repr(address) in err
    assert not (tmp_path / "out").exists()
    assert runner.check_scheduler_address("tcp://10.0.0.5:8786") == "tcp://10.0.0.5:8786"
    assert runner.check_scheduler_address("localhost:8786") == "localhost:8786"


def test_an_unreachable_scheduler_fails_in_bounded_time_and_writes_nothing(tmp_path, monkeypatch):
    _require_dask()
    monkeypatch.setattr(runner, "CONNECT_TIMEOUT", 1.0)  # 20 s in use; the test needs only the behaviour
    inputs = _probes(tmp_path / "in", {"a": "a"})
    address = f"tcp://127.0.0.1:{_free_port()}"  # nothing listens there
    with pytest.raises(OptionError, match=f"--scheduler {address}: cannot connect"):
        nurbskit.batch.run(PROBE, [inputs], tmp_path / "out", scheduler=address)
    assert not (tmp_path / "out").exists()


def test_memory_limits_too_small_for_a_worker_are_refused(tmp_path, monkeypatch, capsys):
    _require_dask()
    from nurbskit.cli import main

    monkeypatch.setattr(runner, "connect", lambda *a, **k: pytest.fail("a cluster was started"))
    monkeypatch.setitem(batch_commands.COMMANDS, "probe", PROBE)
    inputs = _probes(tmp_path / "in", {"a": "a"})
    for size in ("1KB", "400MB"):
        assert main(["batch", "probe", str(inputs), "--out", str(tmp_path / "out"), "--memory-limit", size]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and "--memory-limit: expected at least 512 MiB" in err and size in err
    assert not (tmp_path / "out").exists()
    assert runner._memory_bytes("512MiB") == runner.MIN_WORKER_MEMORY
    import psutil

    too_many = psutil.virtual_memory().total // runner.MIN_WORKER_MEMORY + 1
    with pytest.raises(OptionError, match="--memory-limit auto: .* lower --workers"):
        runner._check_fits_in_memory(too_many, None)


def test_out_equal_to_the_input_folder_says_so(tmp_path, monkeypatch, capsys):
    from nurbskit.cli import main

    monkeypatch.setitem(batch_commands.COMMANDS, "probe", PROBE)
    inputs = _probes(tmp_path / "in", {"a": "a"})
    assert main(["batch", "probe", str(inputs), "--out", str(inputs), "--resume"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "found the input folder" in err and "holds no" not in err
    assert sorted(p.name for p in inputs.iterdir()) == ["a.probe"]


# --- timeouts: never ok past the deadline, never printed as a traceback -----------------------

def test_an_item_that_survives_its_timeout_is_still_timed_out(tmp_path):
    from nurbskit.batch.task import read_marker, run_item

    inputs = _probes(tmp_path / "in", {"swallow": "swallow", "status": "status"})
    items = {i.name: i for i in find_items([inputs], PROBE)}
    out = tmp_path / "out"
    for name in ("swallow", "status"):  # the command swallows the exception, or turns it into a status
        record = run_item(items[name], command=PROBE, out_root=str(out), timeout=0.3)
        assert (record["status"], record["error"]) == ("failed", "timed out after 0.3 s (--timeout)")
    assert read_marker(out / "swallow") is None  # its output is there but not complete: --resume redoes it


def test_a_timeout_python_could_not_raise_is_delivered_again_silently():
    # Dask's GC diagnosis runs Python code in every collection of a worker: a TaskTimeout
    # delivered there (or in a __del__) is "ignored", was printed with a traceback, and the
    # task ran on and was reported ok.
    import gc

    from nurbskit.batch.task import Deadline, TaskTimeout, _in_gc_callback

    class RaisesWhenCollected:
        def __del__(self):
            raise TaskTimeout  # what Python does with an exception delivered into a __del__

    printed = []
    previous_hook = sys.unraisablehook
    sys.unraisablehook = printed.append
    try:
        with pytest.raises(TaskTimeout):
            with Deadline(0.2) as clock:
                try:
                    while True:
                        time.sleep(0.001)
                except TaskTimeout:
                    pass  # the first delivery: lost here, as in a gc callback
                assert clock.expired and not gc.isenabled()  # no collection (no callback) until it lands
                RaisesWhenCollected()  # an unraisable TaskTimeout: not printed, delivered again
                end = time.perf_counter() + 5.0
                while time.perf_counter() < end:
                    time.sleep(0.001)
    finally:
        sys.unraisablehook = previous_hook
    assert printed == []
    assert gc.isenabled()

    seen = []
    callback = lambda phase, info: seen.append(_in_gc_callback(threading.get_ident()))  # noqa: E731
    gc.callbacks.append(callback)
    try:
        gc.collect(0)
    finally:
        gc.callbacks.remove(callback)
    assert seen == [True, True] and not _in_gc_callback(threading.get_ident())


def test_folder_search_skips_folders_nurbskit_wrote(tmp_path):
    # an earlier run's output inside an input folder holds overlays and figures: no drawings
    from nurbskit._fs import MANIFEST
    from nurbskit.batch.inputs import expand_inputs

    (tmp_path / "drawings").mkdir()
    for name in ("a.png", "b.png"):
        (tmp_path / "drawings" / name).write_bytes(b"png")
    old = tmp_path / "drawings" / "old_run" / "a.png"
    old.parent.mkdir()
    (old.parent / "overlay.png").write_bytes(b"png")
    (old.parent / MANIFEST).write_text("{}")
    found = expand_inputs([tmp_path / "drawings"], get_command("curves"))
    assert sorted(p.name for p in found) == ["a.png", "b.png"]


def test_resume_keeps_the_names_an_earlier_run_gave(tmp_path):
    # adding b/x.png beside a/x.png renames a's item ("x" -> "a_x"); on --resume the
    # finished folder's name is kept, so its result is reused, not recomputed beside it
    from nurbskit.batch.commands import Item
    from nurbskit.batch.task import fingerprint

    a, b = tmp_path / "a" / "x.png", tmp_path / "b" / "x.png"
    for p in (a, b):
        p.parent.mkdir()
        p.write_bytes(b"png")
    out = tmp_path / "out"
    (out / "x").mkdir(parents=True)
    first = Item(name="x", inputs=(("input", str(a)),), source=str(a))
    (out / "x" / MARKER).write_text(json.dumps({"version": 1, "command": "curves", "options": [],
                                                 "inputs": fingerprint(first), "record": {"status": "ok"}}))
    items = assign_names([Item(name="x", inputs=(("input", str(p)),), source=str(p)) for p in (a, b)])
    assert [i.name for i in items] == ["a_x", "b_x"]
    assert [i.name for i in runner.kept_names(items, out)] == ["x", "b_x"]
    assert [i.name for i in runner.kept_names(items, tmp_path / "empty")] == ["a_x", "b_x"]

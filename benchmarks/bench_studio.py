"""Benchmark: is the studio responsive? Start-up, drag redraws, fit progress, idle memory.

    python benchmarks/bench_studio.py [--quick] [--repeats 3]

Questions (issue 13's goals): the page is interactive within 3 s of ``nurbskit studio``;
dragging a control point of a 32 x 32 surface redraws at >= 20 updates per second;
progress reaches the page at least twice per second during a fit; an idle studio takes
less than 400 MB of memory.

Method:

* **Start-up**: Chromium (``/usr/bin/chromium``, headless, Playwright) is launched first
  and not counted. The clock starts when ``python -m nurbskit studio --port 0`` is
  spawned; "serving" is when it prints its URL (the server listens before it imports
  torch and the capabilities); "page loaded" is when the browser's load event fires for
  that URL (viser's JavaScript fetched and run); "interactive" is when the page shows
  the tab names and its Fit button is enabled (the GUI was built for this client: its
  widgets are built from plain data, without torch); "fitting code loaded" is when the
  page's "Loading the fitting code" line goes (the capabilities, torch among them,
  imported after the first page's widgets were built, and the tabs activated: the
  generator's first object drawn, the device list set). Median of ``--repeats`` cold
  starts. CPU times, which depend little on the load, are recorded too: the server's
  until it listens, until the page is interactive and until the fitting code is loaded,
  and the page's renderer process's (Chromium's ``Performance.getMetrics``
  ProcessTime) until interactive.
  Peer, in the same run and interleaved with it (same load): the previous start-up order
  (issue 13's earlier sessions) in this code, the capabilities imported from the moment
  the server listens and a page's widgets built only once they are in (``IMPORT_FIRST``
  patches ``Studio.start`` and ``Studio._connect`` in the spawned process); reported as a
  ratio.
* **Idle memory**: the resident set (``VmRSS`` of ``/proc/PID/status``) of that server
  process with one page connected, 2 s after the fitting code is loaded; the largest
  over the repeats.
* **Redraw rate**: an in-process studio with a connected page; the generator's surface
  is set to 32 x 32 control points (degree 3) and a control point is moved 200 times
  through ``GeneratorTab.set_point``, the path both the transform handle and the
  coordinate widget take: evaluation of the 64 x 64 display grid, the iso-lines and
  control net, the in-place array updates, and the flush of the websocket messages.
  Updates per second = 200 / wall time. Peer in the same process: the same updates when
  every node is re-created instead of updated in place (``SplineView`` with its node
  cache dropped), reported as a ratio.
* **Progress rate**: the Unsupervised tab fits a 2,000-point cloud with ``default``
  (up to 300 iterations) through its Run panel. Counted: redraws of the bar and loss
  curve (at most one per iteration, at most ten per second) and the elapsed-time lines
  (four per second while the run lasts, also in phases without iterations: the initial
  surface, the least-squares alternation, the report), divided by the run's wall time.

The machine may be shared (2 cores, 8 users): the load average is recorded; wall-clock
numbers taken under load are upper bounds. Load-independent evidence is recorded next
to them: the number of redraws per fit iteration, and the bytes moved per redraw.
"""

from __future__ import annotations

import argparse
import os
import re
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _harness import write_results  # noqa: E402

CHROMIUM = "/usr/bin/chromium"
ARGS = ["--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run", "--disable-background-networking",
        "--disable-component-update", "--disable-sync"]
VIEWPORT = {"width": 1000, "height": 700}
LOADING = "Loading the fitting code"  # the page's line until its tabs are activated


def cpu_seconds(pid: int) -> float:
    """User + system CPU time of a process (load-independent, unlike wall time)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def rss_mb(pid: int) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    return float("nan")


# The peer: the previous start-up order, in this version's code. The capabilities import
# from the moment the server listens, and a page's widgets are built only once they are in.
IMPORT_FIRST = """
import sys
from nurbskit.studio import app

start, connect = app.Studio.start, app.Studio._connect

def start_and_import(self):
    return start(self).load()

def connect_after_import(self, client):
    self.ready.wait()
    connect(self, client)

app.Studio.start, app.Studio._connect = start_and_import, connect_after_import
from nurbskit.cli import main
sys.exit(main(sys.argv[1:]))
"""


def cold_start(browser, workdir: Path, import_first: bool = False) -> dict:
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(sys.path))
    command = ["-c", IMPORT_FIRST] if import_first else ["-m", "nurbskit"]
    t0 = time.perf_counter()
    proc = subprocess.Popen([sys.executable, *command, "studio", "--port", "0", "--workdir", str(workdir)],
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, env=env)
    try:
        line = ""
        while "serving" not in line:
            line = proc.stderr.readline()
            if not line and proc.poll() is not None:
                raise RuntimeError("the studio exited")
        t_serving = time.perf_counter() - t0
        cpu_serving = cpu_seconds(proc.pid)
        url = re.search(r"http://\S+/", line).group(0)
        context = browser.new_context(viewport=VIEWPORT)
        page = context.new_page()
        cdp = context.new_cdp_session(page)
        cdp.send("Performance.enable")
        page.goto(url)
        t_loaded = time.perf_counter() - t0
        page.get_by_role("tab", name="NURBS Generator", exact=True).wait_for(timeout=60000)
        page.get_by_role("button", name="Fit", exact=True).wait_for(timeout=60000)
        t_interactive = time.perf_counter() - t0
        cpu_interactive = cpu_seconds(proc.pid)
        metrics = {m["name"]: m["value"] for m in cdp.send("Performance.getMetrics")["metrics"]}
        # the fitting code (torch, the capabilities) imports after the widgets are built;
        # the page's "Loading the fitting code" line goes when the tabs are activated
        page.get_by_text(LOADING).wait_for(state="detached", timeout=120000)
        t_activated = time.perf_counter() - t0
        cpu_activated = cpu_seconds(proc.pid)
        time.sleep(2.0)
        rss = rss_mb(proc.pid)
        context.close()
        return {"page_cpu_s": metrics.get("ProcessTime", float("nan")), "serving_s": t_serving, "loaded_s": t_loaded,
                "interactive_s": t_interactive, "idle_rss_mb": rss, "cpu_serving_s": cpu_serving,
                "cpu_interactive_s": cpu_interactive, "activated_s": t_activated, "cpu_activated_s": cpu_activated}
    finally:
        proc.send_signal(signal.SIGINT)
        try:
            proc.wait(timeout=30)
        except subprocess.TimeoutExpired:
            proc.kill()


def connect(browser, studio):
    before = set(studio.sessions)
    page = browser.new_page(viewport=VIEWPORT)
    page.goto(studio.url)
    page.get_by_role("tab", name="Unsupervised", exact=True).wait_for(timeout=60000)
    end = time.monotonic() + 60
    while not (set(studio.sessions) - before) and time.monotonic() < end:
        time.sleep(0.05)
    session = studio.sessions[max(set(studio.sessions) - before)]
    # the capabilities import after the page is built: measure once they are in (the
    # import would otherwise hold the interpreter during the first redraws)
    while not session.active and time.monotonic() < end:
        time.sleep(0.05)
    return page, session


def redraws(session, count: int, in_place: bool) -> dict:
    from nurbskit.studio.generator import make_object

    tab = session.tabs["NURBS Generator"]
    obj, _ = make_object("surface", (32, 32, 2), (3, 3, 1), "clamped")
    tab.set_object(obj)
    rng = np.random.default_rng(0)
    targets = rng.random((count, 3))
    t0 = time.perf_counter()
    for xyz in targets:
        if not in_place:
            tab.view.shape_key = None  # the peer: every node is re-created
        tab.set_point((16, 16), xyz, source="benchmark")
        session.client.flush()
    seconds = time.perf_counter() - t0
    return {"updates": count, "seconds": seconds, "updates_per_s": count / seconds}


def progress_rate(session, points: int, iters: int) -> dict:
    tab = session.tabs["Unsupervised"]
    rng = np.random.default_rng(1)
    uv = rng.random((points, 2))
    tab._loaded((np.stack([uv[:, 0], uv[:, 1], 0.2 * np.sin(3 * uv[:, 0]) * uv[:, 1]], -1), "benchmark"), "bench")
    tab.iters.value = iters
    runner = tab.runner
    runner.launch()
    t0 = time.perf_counter()
    runner.thread.join()
    seconds = time.perf_counter() - t0
    fit_seconds = tab.result.loop_seconds if tab.result is not None else float("nan")
    done = tab.result.iterations if tab.result is not None else 0
    return {"iterations": iters, "progress_updates": runner.updates, "heartbeats": runner.heartbeats,
            "fit_wall_s": seconds,
            "loop_s": fit_seconds, "updates_per_s": runner.updates / seconds, "iterations_run": done,
            "updates_per_iteration": runner.updates / max(1, done)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    torch.set_num_threads(1)
    from playwright.sync_api import sync_playwright

    from nurbskit.studio.app import Studio, StudioOptions

    load_before = os.getloadavg()
    rows = []
    with tempfile.TemporaryDirectory() as tmp, sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=CHROMIUM, args=ARGS)
        starts, peers = [], []
        for _ in range(1 if args.quick else args.repeats):  # interleaved: both see the same load
            starts.append(cold_start(browser, Path(tmp)))
            peers.append(cold_start(browser, Path(tmp), import_first=True))
        peer = statistics.median(s["interactive_s"] for s in peers)
        interactive = statistics.median(s["interactive_s"] for s in starts)
        serving = statistics.median(s["serving_s"] for s in starts)
        loaded = statistics.median(s["loaded_s"] for s in starts)
        activated = statistics.median(s["activated_s"] for s in starts)
        rss = max(s["idle_rss_mb"] for s in starts)
        rows.append({"what": "page interactive after `nurbskit studio`", "goal": "<= 3 s",
                     "measured": interactive, "unit": "s",
                     "detail": f"server listening after {serving:.2f} s, page loaded after {loaded:.2f} s; runs "
                               + ", ".join(
                         f"{s['interactive_s']:.2f}" for s in starts) + "; server CPU time until listening "
                         + ", ".join(f"{s['cpu_serving_s']:.2f}" for s in starts) + " s, until interactive "
                         + ", ".join(f"{s['cpu_interactive_s']:.2f}" for s in starts) + " s; the page's renderer "
                         "process CPU time until interactive " + ", ".join(f"{s['page_cpu_s']:.2f}" for s in starts)
                         + " s (WebGL runs in Chromium's GPU process, not counted); fitting code loaded "
                         f"after {activated:.2f} s (runs " + ", ".join(f"{s['activated_s']:.2f}" for s in starts)
                         + "; server CPU time until then " + ", ".join(f"{s['cpu_activated_s']:.2f}" for s in starts)
                         + f" s). Peer, interleaved: the previous order (capabilities imported from the start, "
                         f"widgets built after them) {peer:.2f} s (runs "
                         + ", ".join(f"{s['interactive_s']:.2f}" for s in peers) + "; server CPU until interactive "
                         + ", ".join(f"{s['cpu_interactive_s']:.2f}" for s in peers)
                         + f" s): this order takes {interactive / peer:.2f}x its time"})
        rows.append({"what": "idle studio memory (RSS, one page connected)", "goal": "< 400 MB",
                     "measured": rss, "unit": "MB", "detail": ", ".join(f"{s['idle_rss_mb']:.0f}" for s in starts)})

        studio = Studio(StudioOptions(port=0, workdir=Path(tmp))).start()
        try:
            page, session = connect(browser, studio)
            count = 50 if args.quick else 200
            redraws(session, 10, True)  # warm-up
            inplace = redraws(session, count, True)
            recreate = redraws(session, count, False)
            rows.append({"what": "control point drag, 32 x 32 surface (64 x 64 display grid)", "goal": ">= 20 /s",
                         "measured": inplace["updates_per_s"], "unit": "updates/s",
                         "detail": f"{count} updates in {inplace['seconds']:.2f} s; re-creating the nodes instead: "
                                   f"{recreate['updates_per_s']:.1f} /s (in place is "
                                   f"{inplace['updates_per_s'] / recreate['updates_per_s']:.1f}x)"})
            prog = progress_rate(session, 2000, 100 if args.quick else 300)
            total = prog["progress_updates"] + prog["heartbeats"]
            rows.append({"what": "progress updates during a fit (default, 2,000 points)", "goal": ">= 2 /s",
                         "measured": total / prog["fit_wall_s"], "unit": "updates/s",
                         "detail": f"{prog['progress_updates']} bar + loss-curve redraws over "
                                   f"{prog['loop_s']:.1f} s of iterations "
                                   f"({prog['progress_updates'] / prog['loop_s']:.1f} /s, "
                                   f"{prog['iterations_run']} iterations run (the stages stop on a plateau), "
                                   f"{prog['updates_per_iteration']:.2f} redraws per iteration) and {prog['heartbeats']} "
                                   f"elapsed-time lines over the whole {prog['fit_wall_s']:.1f} s run"})
            page.close()
        finally:
            studio.stop()
        browser.close()
    meta = {"load_before": load_before, "load_after": os.getloadavg(), "repeats": args.repeats, "quick": args.quick}
    notes = (f"Load average before {load_before[0]:.1f}, after {os.getloadavg()[0]:.1f} on "
             f"{os.cpu_count()} cores: wall-clock numbers under load are upper bounds. Method: "
             "benchmarks/bench_studio.py docstring.")
    path = write_results("studio", rows, [("what", "what"), ("goal", "goal"), ("measured", "measured"),
                                          ("unit", "unit"), ("detail", "detail")],
                         meta=meta, title="nurbskit studio: responsiveness", notes=notes)
    print(path.read_text())


if __name__ == "__main__":
    main()

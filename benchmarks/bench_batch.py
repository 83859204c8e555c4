"""``nurbskit batch``: throughput of 1 versus 2 workers, per-task overhead, scheduler memory.

Questions and method:

1. **Throughput, 1 vs 2 workers** (goal: 2 workers >= 1.7 x the throughput of 1 on the
   2-core machine). Inputs: the 6 ABC clouds (``../shared/data/abc/*.xyzc``) and the 20
   thesis inputs (``thesis_nurbsdiff/meshes/*.off``, 15 meshes and point samples, and
   ``pointclouds_rows/*.txt``, 5 row-structured clouds), 26 in all, through ``fit`` with
   the default pipeline and ``FIT_OPTIONS`` (fewer iterations and points than the
   default, so that the three runs fit in minutes; ``--iters N`` lowers them further).
   Each batch runs on a local cluster made by :func:`nurbskit.batch.runner.connect`;
   the cluster is started and every worker warmed (one fit each, which imports torch's
   optimizer machinery) before the clock starts; start-up is timed separately.
   Throughput = items / wall seconds. The ratio is measured in ``--rounds`` rounds (3 by
   default), each timing a 1-worker and a 2-worker batch back to back, in the order 1-2,
   2-1, 1-2, ...; the result is the median of the rounds' ratios. This machine's speed
   drifts by up to 20 % over minutes (the same items took 3.8 to 4.6 CPU s each in runs
   an hour apart, with nothing else running), which a single pair of runs cannot tell
   from a change in scaling; the rounds pair runs minutes apart and alternate their order.
2. **Per-task overhead** (goal <= 0.3 s), three ways:
   - against the API in a loop: (batch wall on 1 worker - the same items through the
     same per-item function, :func:`nurbskit.batch.task.run_item`, in a loop in this
     process, warmed the same way) / items. Under load the two runs see different
     contention, so this one is noisy;
   - within each batch run: (workers x wall - the sum of the items' own seconds) /
     items, the worker-seconds per item spent outside an item (dispatch, transfer,
     idle waiting), and each worker's idle fraction (1 - its items' seconds / wall);
   - in CPU time, which load hardly changes: (CPU seconds of the workers and of this
     process, which runs the client and the local scheduler - the loop's CPU seconds) /
     items (psutil; ``cpu_seconds`` of each record is its worker's CPU time during the
     item).
   The speedup is judged with efficiency = workers' CPU seconds / (wall x workers): 1
   when every worker had a core all the time; on a loaded machine it shows how much of
   the ratio the other processes took. Projected ratio on an idle machine: 2 x (CPU
   seconds per item on 1 worker + dispatch wall per item) / (the same on 2 workers).
3. **Scheduler memory, 10,000 queued inputs** (goal < 300 MB): a separate ``dask
   scheduler`` process with no worker; ``nurbskit.batch.run`` submits 10,000 synthetic
   inputs (empty files of a command defined here, never run); the scheduler's resident
   memory (psutil) is read over 5 progress updates, then the run is stopped (the
   progress callback raises). The batch keeps a window of items on the scheduler and
   the rest in the client; for reference the same 10,000 tasks are also submitted at
   once with ``client.map``. Reported: scheduler RSS before and with the queue.

Timings on the shared 2-core machine are contended (load is recorded with each run):
the ratio of 2 to 1 workers is the number to re-run on a quiet machine. Memory and
counts do not depend on load.

Run: ``PYTHONPATH=src python benchmarks/bench_batch.py`` (about 15 minutes on a quiet
2-core machine with 3 rounds; writes ``results/batch.json`` and ``batch.md``).
``--quick``: 6 inputs, few iterations (``batch_quick``); ``--iters N``: fewer fit
iterations (stated in the results); ``--rounds R``; ``--skip-memory``: no scheduler-memory part (it is
also run alone by ``--memory-only``, into ``batch_memory``).
"""

from __future__ import annotations

import json
import os
import pickle
import socket
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
DATA = HERE.parents[1] / "shared" / "data"
FIT_OPTIONS = ["--iters", "40", "--max-points", "3000", "--no-figures"]


def inputs() -> list[Path]:
    if not DATA.is_dir():
        raise SystemExit(f"bench_batch: needs {DATA} (the ABC clouds and thesis meshes)")
    abc = sorted((DATA / "abc").glob("*.xyzc"))
    thesis = sorted((DATA / "thesis_nurbsdiff" / "meshes").glob("*.off")) + \
        sorted((DATA / "thesis_nurbsdiff" / "pointclouds_rows").glob("*.txt"))
    assert len(abc) == 6 and len(thesis) == 20, (len(abc), len(thesis))
    return abc + thesis


def _warm(options):
    """Import and run everything a fit touches once in this process (one tiny fit)."""
    import numpy as np

    from nurbskit.batch import get_command
    from nurbskit.batch.commands import Item
    from nurbskit.batch.task import run_item

    with tempfile.TemporaryDirectory() as tmp:
        g = np.random.default_rng(0)
        uv = g.random((300, 2))
        path = Path(tmp) / "warm.xyz"
        np.savetxt(path, np.column_stack([uv, 0.1 * uv[:, 0] * uv[:, 1]]))
        item = Item(name="warm", inputs=(("input", str(path)),), source=str(path))
        record = run_item(item, command=get_command("fit"), out_root=tmp, options=options, threads=1)
        assert record["status"] == "ok", record
    return os.getpid()


def loop_seconds(files, out) -> tuple[float, float, list[dict]]:
    """The items through :func:`run_item` in a loop here: wall seconds, CPU seconds, records."""
    from nurbskit.batch import find_items, get_command
    from nurbskit.batch.task import run_item

    command = get_command("fit")
    items = find_items(files, command)
    _warm(FIT_OPTIONS)
    start, cpu = time.perf_counter(), time.process_time()
    records = [run_item(it, command=command, out_root=str(out), options=FIT_OPTIONS, threads=1) for it in items]
    return time.perf_counter() - start, time.process_time() - cpu, records


def _cpu(pid: int) -> float:
    import psutil

    t = psutil.Process(pid).cpu_times()
    return t.user + t.system


def batch_seconds(files, out, workers: int) -> dict:
    """One batch on a fresh local cluster of ``workers``: wall and CPU seconds of each part."""
    import nurbskit.batch
    from nurbskit.batch.runner import connect

    t0 = time.perf_counter()
    with connect(workers=workers, memory_limit="4GB", retries=1) as (client, info):
        client.wait_for_workers(workers)
        t1 = time.perf_counter()
        pids = client.run(_warm, FIT_OPTIONS)
        t2 = time.perf_counter()
        cpu_before = {pid: _cpu(pid) for pid in pids.values()}
        here_before = time.process_time()
        records = nurbskit.batch.run("fit", files, out, client=client, options=FIT_OPTIONS)
        t3 = time.perf_counter()
        here = time.process_time() - here_before
        worker_cpu = {pid: _cpu(pid) - before for pid, before in cpu_before.items()}
    t4 = time.perf_counter()
    wall = t3 - t2
    busy = {pid: sum(r["seconds"] for r in records if r["worker"].endswith(f":{pid}")) for pid in pids.values()}
    return {"workers": workers, "start_seconds": t1 - t0, "warm_seconds": t2 - t1, "wall_seconds": wall,
            "close_seconds": t4 - t3, "worker_pids": sorted(pids.values()), "records": records,
            "worker_cpu_seconds": [worker_cpu[p] for p in sorted(worker_cpu)],
            "worker_idle_fraction": [1 - busy[p] / wall for p in sorted(busy)],
            "client_scheduler_cpu_seconds": here,
            "efficiency": sum(worker_cpu.values()) / (wall * workers)}


# --- a synthetic command for the scheduler-memory measurement (never run: no worker) ----------

def register(subparsers) -> None:
    p = subparsers.add_parser("noop")
    p.add_argument("input")
    p.add_argument("--out", required=True)
    p.add_argument("--overwrite", action="store_true")
    p.set_defaults(run=lambda args: 0)


def _no_metrics(report: dict) -> dict:
    return {}


class _Stop(Exception):
    pass


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def scheduler_memory(n: int = 10_000, all_at_once: bool = False, packed: bool = True) -> dict:
    """Scheduler RSS with ``n`` inputs queued (no worker, so nothing runs).

    ``all_at_once``: submit the same ``n`` tasks with one ``client.map`` (the reference
    that :func:`nurbskit.batch.runner.window_size` avoids) instead of ``nurbskit.batch.run``;
    ``packed=False``: as plain ``run_item`` calls, which the scheduler unpickles into
    nurbskit objects (so it imports nurbskit and torch), instead of ``packed_task`` bytes.
    """
    import psutil
    from distributed import Client

    import nurbskit.batch
    from nurbskit.batch import BatchCommand, find_items
    from nurbskit.batch.task import packed_task, run_item

    command = BatchCommand(name="noop", module="bench_batch", extensions=(".in",), metrics=_no_metrics)
    port = _free_port()
    address = f"tcp://127.0.0.1:{port}"
    dask_cli = str(Path(sys.executable).parent / "dask")
    # The scheduler unpickles the tasks it receives: it must import nurbskit and this module.
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(HERE.parent / "src"), str(HERE), os.environ.get("PYTHONPATH", "")]))
    proc = subprocess.Popen([dask_cli, "scheduler", "--host", "127.0.0.1", "--port", str(port), "--no-dashboard"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env)
    try:
        with Client(address, timeout="60s") as watcher, tempfile.TemporaryDirectory() as tmp:
            folder = Path(tmp) / "in"
            folder.mkdir()
            for i in range(n):
                (folder / f"s{i:05d}.in").write_text("")
            scheduler = psutil.Process(proc.pid)
            time.sleep(1.0)
            before = scheduler.memory_info().rss
            seen = {"updates": 0, "rss": 0}

            def tasks_on_scheduler():
                return watcher.run_on_scheduler(lambda dask_scheduler: len(dask_scheduler.tasks))

            def progress(event):
                if event["event"] != "update":
                    return
                seen["updates"] += 1
                seen["rss"] = max(seen["rss"], scheduler.memory_info().rss)
                seen["tasks"] = tasks_on_scheduler()
                if seen["updates"] >= 5:
                    raise _Stop

            if all_at_once:
                items = find_items([folder], command)
                if packed:
                    payloads = [packed_task(it, command=command, out_root=str(Path(tmp) / "out")) for it in items]
                    futures = watcher.map(pickle.loads, payloads, pure=False)
                else:
                    futures = watcher.map(run_item, items, pure=False, command=command, out_root=str(Path(tmp) / "out"))
                deadline = time.monotonic() + 120
                while tasks_on_scheduler() < n and time.monotonic() < deadline:
                    time.sleep(0.5)
                time.sleep(2.0)
                seen.update(rss=scheduler.memory_info().rss, tasks=tasks_on_scheduler())
                watcher.cancel(futures)
                del futures
            else:
                try:
                    nurbskit.batch.run(command, [folder], Path(tmp) / "out", scheduler=address, progress=progress,
                                       figure=False)
                except _Stop:
                    pass
    finally:
        proc.terminate()
        proc.wait(timeout=30)
    how = "nurbskit.batch.run (window)" if not all_at_once else \
        f"client.map, all at once, {'packed bytes' if packed else 'run_item objects'}"
    return {"inputs": n, "how": how,
            "scheduler_rss_before_mb": before / 2**20, "scheduler_rss_queued_mb": seen["rss"] / 2**20,
            "per_input_kb": (seen["rss"] - before) / n / 1024, "tasks_on_scheduler": seen["tasks"]}


def _option(name: str, default=None):
    return sys.argv[sys.argv.index(name) + 1] if name in sys.argv else default


def main() -> None:
    from _harness import write_results

    files = inputs()
    if "--quick" in sys.argv:  # make bench --quick: 2 ABC clouds and 4 thesis inputs, few iterations
        files = files[:2] + files[6:10]
        FIT_OPTIONS[:] = ["--iters", "10", "--max-points", "1000", "--no-figures"]
    if _option("--iters"):
        FIT_OPTIONS[FIT_OPTIONS.index("--iters") + 1] = str(int(_option("--iters")))
    rounds = int(_option("--rounds", 3))
    load_before = os.getloadavg()
    ones, twos = [], []
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        loop_t, loop_cpu, loop_records = loop_seconds(files, tmp / "loop")
        for k in range(rounds):  # 1-2, 2-1, 1-2, ...: a drift of the machine's speed falls on both alike
            for workers in ((1, 2) if k % 2 == 0 else (2, 1)):
                run = batch_seconds(files, tmp / f"r{k}w{workers}", workers)
                (ones if workers == 1 else twos).append(run)
    load_after = os.getloadavg()
    n = len(files)
    result = {}
    if "--skip-memory" not in sys.argv:
        result["memory"] = scheduler_memory()
        result["memory_all_at_once"] = scheduler_memory(all_at_once=True)
        result["memory_all_at_once_unpacked"] = scheduler_memory(all_at_once=True, packed=False)

    def derived(run: dict) -> dict:
        w, wall = run["workers"], run["wall_seconds"]
        item_s = sum(r["seconds"] for r in run["records"])
        item_cpu = sum(r["cpu_seconds"] for r in run["records"])
        cpu = sum(run["worker_cpu_seconds"]) + run["client_scheduler_cpu_seconds"]
        return {"overhead_wall_s": (w * wall - item_s) / n, "idle_fraction": max(run["worker_idle_fraction"]),
                "worker_cpu_s": sum(run["worker_cpu_seconds"]), "cpu_per_item_s": item_cpu / n,
                "overhead_cpu_s": (cpu - loop_cpu) / n, "efficiency": run["efficiency"],
                "cpu_share": item_cpu / item_s, "dispatch_wall_s": (w * wall - item_s) / n}

    median = statistics.median
    ratios = [one["wall_seconds"] / two["wall_seconds"] for one, two in zip(ones, twos)]
    speedup = median(ratios)
    d1s, d2s = [derived(r) for r in ones], [derived(r) for r in twos]
    d1 = {key: median(d[key] for d in d1s) for key in d1s[0]}
    d2 = {key: median(d[key] for d in d2s) for key in d2s[0]}
    projected = 2 * (d1["cpu_per_item_s"] + d1["dispatch_wall_s"]) / (d2["cpu_per_item_s"] + d2["dispatch_wall_s"])
    one_wall = median(r["wall_seconds"] for r in ones)
    rows = [
        {"run": "API in a loop (this process)", "workers": 0, "items": n,
         "ok": sum(r["status"] == "ok" for r in loop_records), "wall_s": loop_t,
         "items_per_s": n / loop_t, "start_s": 0.0, "overhead_vs_loop_s": 0.0, "overhead_wall_s": 0.0,
         "idle_fraction": 0.0, "worker_cpu_s": loop_cpu, "cpu_per_item_s": loop_cpu / n, "overhead_cpu_s": 0.0,
         "efficiency": loop_cpu / loop_t},
    ]
    for k in range(rounds):
        for run, d in ((ones[k], d1s[k]), (twos[k], d2s[k])):
            w = run["workers"]
            rows.append({
                "run": f"round {k + 1}: batch, {w} worker{'s' if w > 1 else ''}", "workers": w, "items": n,
                "ok": sum(r["status"] == "ok" for r in run["records"]), "wall_s": run["wall_seconds"],
                "items_per_s": n / run["wall_seconds"], "start_s": run["start_seconds"] + run["warm_seconds"],
                "overhead_vs_loop_s": (w * run["wall_seconds"] - loop_t) / n, **d,
                "ratio_2_vs_1": ratios[k]})
    meta = {
        "fit_options": FIT_OPTIONS, "inputs": [str(f.relative_to(DATA)) for f in files], "rounds": rounds,
        "throughput_ratio_2_vs_1": speedup, "throughput_ratio_2_vs_1_per_round": ratios,
        "projected_ratio_idle_machine": projected, "goal_ratio": 1.7,
        "overhead_per_item_s_vs_loop": (one_wall - loop_t) / n,
        "overhead_per_item_s_within_1_worker": d1["overhead_wall_s"],
        "overhead_per_item_s_within_2_workers": d2["overhead_wall_s"],
        "overhead_per_item_cpu_s_1_worker": d1["overhead_cpu_s"], "goal_overhead_s": 0.3,
        "loop_cpu_seconds": loop_cpu,
        "runs": {"one": [{k: v for k, v in r.items() if k != "records"} for r in ones],
                 "two": [{k: v for k, v in r.items() if k != "records"} for r in twos]},
        "load_average_before": load_before, "load_average_after": load_after, "cpu_count": os.cpu_count(),
        "contended": max(load_before[0], load_after[0]) > (os.cpu_count() or 1),
        "item_seconds": {"loop": [r["seconds"] for r in loop_records],
                         "one": [[r["seconds"] for r in run["records"]] for run in ones],
                         "two": [[r["seconds"] for r in run["records"]] for run in twos]},
        "item_cpu_seconds": {"loop": [r["cpu_seconds"] for r in loop_records],
                             "one": [[r["cpu_seconds"] for r in run["records"]] for run in ones],
                             "two": [[r["cpu_seconds"] for r in run["records"]] for run in twos]},
        **{f"scheduler_{k}": v for k, v in result.items()},
    }
    memory_note = ""
    if result:
        mem = result["memory"]
        memory_note = (
            f"Scheduler with 10,000 queued inputs: **{mem['scheduler_rss_queued_mb']:.0f} MB** "
            f"({mem['scheduler_rss_before_mb']:.0f} MB empty; {mem['tasks_on_scheduler']} tasks on it at a time; "
            f"submitted all at once {result['memory_all_at_once']['scheduler_rss_queued_mb']:.0f} MB packed, "
            f"{result['memory_all_at_once_unpacked']['scheduler_rss_queued_mb']:.0f} MB as nurbskit objects; "
            f"goal < 300 MB). ")
    notes = (
        f"{n} inputs (6 ABC clouds, 20 thesis meshes/clouds) through `nurbskit batch fit` {' '.join(FIT_OPTIONS)}. "
        f"Throughput 2 vs 1 workers: **{speedup:.2f}x** (goal >= 1.7x; the median over {rounds} rounds, each "
        f"timing 1 and 2 workers back to back, in the order 1-2, 2-1, ...: "
        f"{', '.join(f'{r:.2f}x' for r in ratios)}); medians over the rounds follow: efficiency (workers' CPU s / (wall x "
        f"workers)) {d1['efficiency']:.2f} on 1 worker, {d2['efficiency']:.2f} on 2; projected on an idle machine "
        f"from CPU time per item and dispatch time: **{projected:.2f}x**. Per-item overhead: "
        f"**{d1['overhead_wall_s']:.3f} s** of wall time outside the items on 1 worker "
        f"({d2['overhead_wall_s']:.3f} worker-s on 2; largest worker idle fraction {d1['idle_fraction']:.3f} / "
        f"{d2['idle_fraction']:.3f}); in CPU time against the loop **{d1['overhead_cpu_s']:+.3f} s** (1 worker: "
        f"worker + client + scheduler CPU - the loop's CPU, per item); wall against the loop "
        f"{meta['overhead_per_item_s_vs_loop']:+.3f} s (noisy: the machine's speed drifts between runs) (goal <= 0.3 s). "
        f"CPU share of the items (their CPU s / their wall s): loop {loop_cpu / sum(r['seconds'] for r in loop_records):.2f}, "
        f"1 worker {d1['cpu_share']:.2f}, 2 workers {d2['cpu_share']:.2f}. " + memory_note
        + f"Load average before/after: {load_before[0]:.1f} / {load_after[0]:.1f} on {os.cpu_count()} cores"
        + (" -- CONTENDED: the machine was shared; re-run quiet for the scaling ratio." if meta["contended"] else ".")
    )
    columns = [("run", "run"), ("workers", "workers"), ("items", "items"), ("ok", "ok"), ("wall_s", "wall s"),
               ("items_per_s", "items/s"), ("start_s", "cluster start + warm-up s"),
               ("overhead_wall_s", "wall outside items per item s"), ("idle_fraction", "worker idle fraction (max)"),
               ("worker_cpu_s", "CPU s (workers)"), ("cpu_per_item_s", "CPU s per item"),
               ("overhead_cpu_s", "CPU overhead per item s"), ("efficiency", "efficiency"),
               ("overhead_vs_loop_s", "wall overhead vs loop per item s"), ("ratio_2_vs_1", "round's 2 vs 1")]
    name = "batch_quick" if "--quick" in sys.argv else "batch"  # a quick run never replaces the full one
    path = write_results(name, rows, columns, meta=meta, title="nurbskit batch: 1 vs 2 workers, overhead, memory",
                         notes=notes)
    print(path.read_text())


def memory_only() -> None:
    """``--memory-only``: the scheduler-memory variants alone (a minute; no fitting)."""
    from _harness import write_results

    rows = [scheduler_memory(), scheduler_memory(all_at_once=True), scheduler_memory(all_at_once=True, packed=False)]
    columns = [("how", "submitted as"), ("inputs", "inputs"), ("tasks_on_scheduler", "tasks on the scheduler"),
               ("scheduler_rss_before_mb", "scheduler MB empty"), ("scheduler_rss_queued_mb", "scheduler MB queued"),
               ("per_input_kb", "kB per input")]
    notes = ("Scheduler resident memory (psutil) with 10,000 inputs queued and no worker. Goal < 300 MB. "
             "Packed: tasks travel as bytes the scheduler never turns into nurbskit objects.")
    print(write_results("batch_memory", rows, columns, title="nurbskit batch: scheduler memory", notes=notes).read_text())


if __name__ == "__main__":
    if "--memory-only" in sys.argv:
        memory_only()
    else:
        main()

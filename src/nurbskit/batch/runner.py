"""The client side of ``nurbskit batch``: find the work, start or join a Dask cluster,
submit one task per item, follow them, write the summary.

Convention (cluster):
    Without ``client`` or ``scheduler``, a :class:`dask.distributed.LocalCluster` on
    127.0.0.1: ``workers`` processes (default: usable cores // ``threads_per_worker``),
    each running ONE item at a time with ``threads_per_worker`` torch threads (torch's
    thread count is per process, and the fitting loops hold the GIL between operations,
    so processes, not threads, are how items run side by side), each restarted by its
    nanny when it passes 95 % of ``memory_limit``. The scheduler retries an item whose
    worker died ``retries`` times (``distributed.scheduler.allowed-failures``) and sends
    no more items than there are worker threads (:func:`window_size`), so a dying worker
    takes down only the item it was running. The cluster and every process it
    started are closed when :func:`run` returns or raises (Ctrl-C included).

    With ``scheduler="tcp://host:port"`` (or a ``client``), the existing cluster is
    used as it is: its workers' threads, memory limits and ``allowed-failures`` apply,
    and it is left running. The address is checked before anything else
    (:func:`check_scheduler_address`); a scheduler that does not answer within
    :data:`CONNECT_TIMEOUT` seconds fails the run before ``out`` is created.
"""

from __future__ import annotations

import contextlib
import math
import os
import pickle
import time
import uuid
from collections import Counter
from pathlib import Path
from typing import Callable, Iterable, Sequence

from .._optional import require
from ..errors import OptionError
from .commands import COMMANDS, BatchCommand, Item, get_command
from .inputs import find_items
from .summary import check_summary_files, write_summary
from .task import MARKER, command_args, fingerprint, packed_task, read_marker

EXTRA = "dist"


def _distributed():
    require("dask", EXTRA, "nurbskit batch")
    return require("distributed", EXTRA, "nurbskit batch")


def usable_cores() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - macOS, Windows
        return os.cpu_count() or 1


def _check_positive(name: str, value, integer: bool = True, allow_zero: bool = False) -> None:
    if value is None:
        return
    ok = isinstance(value, int) if integer else isinstance(value, (int, float))
    low_ok = value >= 0 if allow_zero else value > 0
    if not ok or isinstance(value, bool) or not low_ok or (not integer and not math.isfinite(value)):
        kind = "an integer" if integer else "a number"
        bound = ">= 0" if allow_zero else "> 0"
        raise OptionError(f"--{name.replace('_', '-')}: expected {kind} {bound}, got {value!r}")


# The least --memory-limit a local worker can work in. Measured (one worker, a 40- and a
# 2000-point `shape`): 62 MiB idle, 244 MiB once torch and nurbskit are imported, 352 MiB
# after the first item. Dask pauses a worker at 80 % of its limit (no new item starts) and
# restarts it at 95 %: below about 440 MiB a worker stops after its first item or dies
# before it ends, and every input fails.
MIN_WORKER_MEMORY = 512 * 2**20


def _memory_bytes(memory_limit) -> int | None:
    """``"4GB"`` -> bytes; ``None``, ``"auto"`` or 0 -> None (Dask's share of the machine).

    Refuses a limit below :data:`MIN_WORKER_MEMORY`.
    """
    if memory_limit in (None, 0, "0", "auto"):
        return None
    if isinstance(memory_limit, (int, float)) and not isinstance(memory_limit, bool):
        value = int(memory_limit)
    else:
        from dask.utils import parse_bytes

        try:
            value = int(parse_bytes(str(memory_limit)))
        except (ValueError, TypeError):
            raise OptionError(f"--memory-limit: expected a size like 4GB or 500MiB, got {memory_limit!r}") from None
    if value <= 0:
        raise OptionError(f"--memory-limit: expected a positive size, got {memory_limit!r}")
    if value < MIN_WORKER_MEMORY:
        raise OptionError(f"--memory-limit: expected at least {MIN_WORKER_MEMORY // 2**20} MiB (a worker holds about "
                          f"350 MiB once it has run an item), got {memory_limit}")
    return value


def _check_fits_in_memory(workers: int, limit: int | None) -> None:
    """Refuse a local cluster whose memory limits add up to more than this machine has,
    or (``limit`` None: ``auto``) whose share of the machine is too small for a worker."""
    import psutil

    total = psutil.virtual_memory().total
    if limit is None:
        if total // workers < MIN_WORKER_MEMORY:
            raise OptionError(
                f"--memory-limit auto: this machine's {total / 2**30:.1f} GiB / {workers} workers = "
                f"{total / workers / 2**20:.0f} MiB each, expected at least {MIN_WORKER_MEMORY // 2**20} MiB; "
                "lower --workers"
            )
        return
    if workers * limit > total:
        raise OptionError(
            f"--memory-limit {limit / 2**30:.1f} GiB x {workers} workers = {workers * limit / 2**30:.1f} GiB, "
            f"more than this machine's {total / 2**30:.1f} GiB; lower --workers or --memory-limit"
        )


# How long a --scheduler has to answer before the batch gives up (nothing written by then).
CONNECT_TIMEOUT = 20.0


def check_scheduler_address(address: str) -> str:
    """``address`` if ``distributed`` can dial it: ``SCHEME://HOST:PORT`` with a scheme it
    knows (``tcp``, ``tls``, ``ws``, ``wss``, ``ucx``) or ``HOST:PORT`` (tcp); else OptionError.

    Checked before any work: Dask itself reports a bad address only once it tries to
    connect, as a ValueError followed by a 40 s wait while it closes the half-made client.
    """
    from distributed.comm.addressing import parse_address, parse_host_port
    from distributed.comm.registry import backends

    schemes = sorted(name for name in backends if name != "inproc")  # inproc: this process only
    expected = f"expected tcp://HOST:PORT, HOST:PORT or SCHEME://HOST:PORT with SCHEME one of {', '.join(schemes)}"
    text = str(address)
    try:
        scheme, location = parse_address(text, strict=False)
        host, port = parse_host_port(location) if scheme in schemes else (None, None)
    except ValueError:
        host = port = None
    if not host or port is None or not 0 < port < 65536:
        raise OptionError(f"--scheduler: {expected}, got {text!r}")
    return text


@contextlib.contextmanager
def connect(client=None, scheduler: str | None = None, *, workers: int | None = None, threads_per_worker: int = 1,
            memory_limit="4GB", retries: int = 1):
    """Yield ``(client, info)``: the given client, one connected to ``scheduler``, or a
    new local cluster (see the module's Convention). What this opened, it closes."""
    distributed = _distributed()
    if client is not None:
        yield client, {"cluster": "given", "scheduler": client.scheduler.address}
        return
    if scheduler is not None:
        try:
            own = distributed.Client(check_scheduler_address(scheduler), timeout=f"{CONNECT_TIMEOUT:g}s",
                                     set_as_default=False)
        except OSError as exc:  # refused, unknown host, or no answer within CONNECT_TIMEOUT
            raise OptionError(f"--scheduler {scheduler}: cannot connect ({exc})") from None
        with own:
            yield own, {"cluster": "existing", "scheduler": scheduler}
        return
    import logging

    import dask

    n = workers or max(1, usable_cores() // threads_per_worker)
    limit = _memory_bytes(memory_limit)
    _check_fits_in_memory(n, limit)
    config = {
        "distributed.scheduler.allowed-failures": retries,
        "distributed.scheduler.worker-saturation": 1.0,
        # the items are independent: nothing to steal or rebalance between workers
        "distributed.scheduler.work-stealing": False,
        # Dask's nanny sets MALLOC_TRIM_THRESHOLD_=65536 in its workers, which also fixes
        # glibc's mmap threshold at 128 kB: every tensor above it is mapped and unmapped
        # again, and a fit spends as much CPU time in page faults as in its own work (1.9x
        # the CPU time of the same fit in a plain process; benchmarks/results/batch.md).
        # Unset, the workers allocate as any Python process does (the API in a loop).
        "distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_": None,
        # The worker's statistical profiler walks every thread's stack each 10 ms; the
        # fitting loops' deep Python stacks made that 8-15 % of an item's CPU time
        # (measured, 3 ABC clouds, on and off twice). The dashboard's Profile page is the price.
        "distributed.worker.profile.enabled": False,
        # An idle local cluster of 2 workers took 124 ms of CPU per second (6 % of a 2-core
        # machine, taken from the items once every core computes), most of it Dask's 20 ms
        # event-loop health tick in this process and each worker, then the 500 ms system
        # monitor (dashboard statistics). Both are diagnostics; at 200 ms and 2 s the idle
        # cluster takes about 49 ms/s (docs/batch.md, "Cluster"). The memory monitor, which
        # enforces --memory-limit, keeps its 100 ms.
        "distributed.admin.tick.interval": "200ms",
        "distributed.admin.system-monitor.interval": "2s",
    }
    # Held for the cluster's whole life, not only its start: a nanny keeps a shallow copy of
    # the configuration, whose nested settings revert when the context ends, and a worker
    # it restarts (after a crash or the memory limit) would start with Dask's defaults.
    with dask.config.set(config):
        with _workers_ignore_ctrl_c():
            cluster = distributed.LocalCluster(
                n_workers=n, threads_per_worker=1, processes=True, host="127.0.0.1", scheduler_port=0,
                dashboard_address="127.0.0.1:0", memory_limit=limit if limit is not None else "auto",
                silence_logs=logging.CRITICAL,
            )
        try:
            with distributed.Client(cluster, set_as_default=False) as own:
                yield own, {"cluster": "local", "scheduler": cluster.scheduler_address, "workers": n}
        finally:
            cluster.close()


@contextlib.contextmanager
def _workers_ignore_ctrl_c():
    """Start worker processes with SIGINT ignored; this process keeps its own handler.

    Ctrl-C in a terminal reaches the whole process group. The workers must not each die
    with a KeyboardInterrupt traceback on the user's terminal: this process handles the
    interrupt and closes the cluster (and with it the workers). An ignored signal is the
    one disposition a spawned process inherits, and Python then installs no handler of
    its own. A Ctrl-C during the cluster's start-up takes effect once it has started.
    """
    import signal
    import threading

    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


def dashboard_link(client, local: bool) -> str | None:
    """The dashboard's address, or None when the scheduler serves none.

    A local scheduler serves the dashboard only with bokeh installed (without it the
    address answers with a page asking for bokeh); a remote one is taken at its word.
    """
    import importlib.util

    if local and importlib.util.find_spec("bokeh") is None:
        return None
    try:
        info = client.scheduler_info()
        if not info.get("services", {}).get("dashboard"):
            return None
        return client.dashboard_link
    except Exception:  # noqa: BLE001 - an address to print, never a reason to fail
        return None


def _failure_message(exc: BaseException, client, memory_limit, retries_hint: str) -> str:
    """One line for an item whose task erred on the scheduler's side (its worker died)."""
    distributed = _distributed()
    if isinstance(exc, distributed.KilledWorker):
        worker = getattr(getattr(exc, "last_worker", None), "address", None)
        with contextlib.suppress(Exception):
            for _, event in client.get_events("nurbskit-batch-timeout"):
                if event.get("key") == exc.task:
                    return f"timed out after {event.get('seconds'):g} s (--timeout) and its worker had to be restarted"
        with contextlib.suppress(Exception):
            for _, event in client.get_events("worker-restart-memory"):
                if worker is not None and event.get("worker") == worker:
                    return (f"worker killed for memory: it used {event.get('rss', 0) / 2**30:.2f} GiB, over 95% of "
                            f"{memory_limit} ({retries_hint})")
        return f"worker process died while running this input ({retries_hint})"
    from .task import describe_error

    return describe_error(exc)


def kept_names(items: list[Item], out: Path) -> list[Item]:
    """``items`` with the folder names an earlier run in ``out`` gave the same inputs.

    Names are unique among a run's items, so adding inputs can rename an item (``x.png``
    becomes ``a_x`` beside ``b/x.png``); on ``--resume`` an item whose inputs (paths)
    a finished folder's marker lists keeps that folder's name, when no other item has it.
    """
    earlier: dict[tuple, str] = {}
    with contextlib.suppress(OSError):
        for folder in sorted(p for p in out.iterdir() if p.is_dir()):
            marker = read_marker(folder)
            if marker is not None and isinstance(marker.get("inputs"), list):
                with contextlib.suppress(TypeError, KeyError, AttributeError):
                    earlier.setdefault(tuple((i["role"], i["path"]) for i in marker["inputs"]), folder.name)
    if not earlier:
        return items
    wanted = [earlier.get(tuple((role, os.path.abspath(path)) for role, path in item.inputs)) for item in items]
    taken = Counter(w for w in wanted if w is not None)
    names = [w if w is not None and taken[w] == 1 else item.name for w, item in zip(wanted, items)]
    if len(set(names)) != len(names):  # a kept name would clash with a new one: keep the run's own names
        return items
    return [Item(name=n, inputs=item.inputs, source=item.source) for n, item in zip(names, items)]


def completed(command: BatchCommand, item: Item, out: Path, options: Sequence[str]) -> dict | None:
    """The record of a finished item (``--resume``), or None when it has to run.

    Raises OptionError when ``out`` holds a finished item made by another command or
    with other options: resuming it would mix two different runs in one summary.
    """
    marker = read_marker(out / item.name)
    if marker is None:
        return None
    if marker.get("command") != command.name or list(marker.get("options", [])) != list(options):
        raise OptionError(
            f"--resume: {out / item.name} was made by 'nurbskit batch {marker.get('command')}' with options "
            f"{marker.get('options')}, not '{command.name}' with {list(options)}; use --overwrite to redo it"
        )
    if marker.get("inputs") != fingerprint(item):
        return None  # an input changed since: fit it again
    record = dict(marker.get("record", {}))
    if record.get("status") != "ok":
        return None
    record.update(input=item.source, name=item.name, resumed=True)
    return record


def run(command: str | BatchCommand, inputs: Iterable[str | os.PathLike] | str | os.PathLike, out: str | os.PathLike,
        client=None, *, options: Sequence[str] = (), workers: int | None = None, threads_per_worker: int = 1,
        memory_limit="4GB", scheduler: str | None = None, retries: int = 1, timeout: float | None = None,
        resume: bool = False, overwrite: bool = False, figure: bool = True,
        progress: Callable[[dict], None] | None = None, dataframe: bool = False):
    """Run ``command`` on every input on a Dask cluster; the summary records.

    Args:
        command: a registered command name (``"fit"``, ``"volume"``) or a :class:`BatchCommand`.
        inputs: files, folders (searched by the command's extensions) and glob patterns.
        out: the output folder; item ``x`` goes to ``out/x/`` as the single command writes it.
        client: a ``distributed.Client`` to use (left open); else ``scheduler`` or a local cluster.
        options: the single command's options, e.g. ``["--iters", "50"]``.
        workers, threads_per_worker, memory_limit, retries: the local cluster (module Convention).
        timeout: seconds allowed per item (None: no limit).
        resume: skip items whose output is complete (their folders are not touched).
        overwrite: run every item again, replacing its folder.
        figure: also write ``summary.png``.
        progress: called with dicts: ``{"event": "started", "dashboard", "scheduler", "total",
            "resumed"}``, ``{"event": "update", "done", "failed", "running", "total"}`` and
            ``{"event": "result", "record"}``.
        dataframe: return a pandas DataFrame (needs pandas) instead of a list of dicts.

    Returns:
        One record per item, in input order: ``input``, ``name``, ``status`` (``ok`` or
        ``failed``), ``error``, ``seconds``, ``cpu_seconds`` (on its worker; 0 when resumed from
        an older marker), ``metrics`` (a dict), ``resumed``, ``worker``.

    Raises NurbskitError before any work starts, and before ``out`` is created, for bad
    inputs or options, for summary files in ``out`` that no batch wrote, and for a
    ``scheduler`` that does not answer within :data:`CONNECT_TIMEOUT` seconds; a failure
    of one item is a record, never an exception. KeyboardInterrupt passes through after
    the cluster is closed and the summary of the finished items is written (nothing is
    written when it comes while the cluster starts).
    """
    command = get_command(command)
    if isinstance(inputs, (str, os.PathLike)):
        inputs = [inputs]
    options = [str(o) for o in options]
    _check_positive("workers", workers)
    _check_positive("threads_per_worker", threads_per_worker)
    _check_positive("retries", retries, allow_zero=True)
    _check_positive("timeout", timeout, integer=False)
    if resume and overwrite:
        raise OptionError("--resume and --overwrite: choose one (resume keeps finished outputs, overwrite redoes them)")
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise OptionError(f"--out {out}: expected a directory, found an existing file")
    if command.name == "fit" and any(o.split("=", 1)[0] == "--kind" for o in options) and "shape" in COMMANDS:
        raise OptionError("-- --kind: nurbskit fit fits free-form surfaces; for a surface of revolution or an "
                          "extrusion run 'nurbskit batch shape INPUTS... -- --kind revolution|extrusion|auto'")
    items = find_items(inputs, command, exclude=out)
    # Parse the options once here, so that a typo fails now and not once per item.
    command_args(command, items[0], out / items[0].name, options)
    if out.is_dir() and any(out.iterdir()) and not (resume or overwrite):
        raise OptionError(f"--out {out}: directory exists and is not empty; pass --resume to continue it "
                          f"or --overwrite to run every input again")
    check_summary_files(out)  # the user's own summary.csv is never replaced, whatever the flags
    _distributed()  # a missing extra fails before any work, whatever there is to do
    if client is None and scheduler is None:
        _memory_bytes(memory_limit)  # a bad size fails now, before --out is created
    elif client is None:
        check_scheduler_address(scheduler)
    if dataframe:
        try:
            import pandas
        except ImportError:
            raise OptionError("dataframe=True needs pandas (pip install pandas); "
                              "without it the summary is a list of dicts and summary.csv") from None
    notify = progress or (lambda event: None)

    records: dict[str, dict] = {}
    if resume:
        items = kept_names(items, out)
        for item in items:
            record = completed(command, item, out, options)
            if record is not None:
                records[item.name] = record
    todo = [item for item in items if item.name not in records]
    meta = {"command": command.name, "options": options, "out": str(out), "timeout": timeout,
            "retries": retries, "threads_per_worker": threads_per_worker, "submitted": len(todo),
            "resumed": len(records)}
    start = time.perf_counter()
    interrupted = begun = False
    try:
        with contextlib.ExitStack() as cluster:
            if todo:
                # Before --out is created: a scheduler that does not answer, or a local cluster
                # that cannot start, leaves nothing behind.
                dask_client, info = cluster.enter_context(connect(
                    client, scheduler, workers=workers, threads_per_worker=threads_per_worker,
                    memory_limit=memory_limit, retries=retries))
            out.mkdir(parents=True, exist_ok=True)
            begun = True
            if todo:
                meta.update({k: v for k, v in info.items() if k != "scheduler"})
                meta["dashboard"] = dashboard_link(dask_client, info["cluster"] == "local")
                notify({"event": "started", "dashboard": meta["dashboard"], "scheduler": info["scheduler"],
                        "total": len(items), "resumed": len(records), **{k: v for k, v in info.items() if k == "workers"}})
                limit = f"--memory-limit {memory_limit}" if info["cluster"] == "local" else "its memory limit"
                _follow(dask_client, command, todo, out, options, threads_per_worker, timeout, records,
                        notify, len(items), limit, retries if info["cluster"] == "local" else None)
    except KeyboardInterrupt:
        interrupted = True
        raise
    finally:
        if begun:
            if interrupted:  # items the workers finished while the cluster closed count as finished
                for item in items:
                    if item.name not in records:
                        with contextlib.suppress(OptionError, OSError, ValueError):
                            record = completed(command, item, out, options)
                            if record is not None:
                                records[item.name] = dict(record, resumed=False)
            _summarise(out, items, records, meta, start, interrupted, figure)
    ordered = [records[item.name] for item in items]
    if dataframe:
        from .summary import flat_rows

        return pandas.DataFrame(flat_rows(ordered))
    return ordered


def _summarise(out: Path, items: list[Item], records: dict, meta: dict, start: float, interrupted: bool,
               figure: bool) -> None:
    """Complete ``records`` (an item that did not run is a failed record) and write the summary."""
    meta["wall_seconds"] = time.perf_counter() - start
    meta["interrupted"] = interrupted
    for item in items:
        records.setdefault(item.name, {
            "input": item.source, "name": item.name, "status": "failed", "seconds": 0.0, "metrics": {},
            "error": "interrupted before it finished" if interrupted else "not run"})
        records[item.name].setdefault("resumed", False)
    write_summary(out, [records[item.name] for item in items], meta, figure=figure and not interrupted)


def window_size(client) -> int:
    """How many items may be on the scheduler at once: one per worker thread.

    The rest wait in this process, as :class:`Item` objects of a few hundred bytes, so the
    scheduler's memory stays flat however many inputs there are (68 MB with 10,000
    queued, as empty; ``benchmarks/bench_batch.py``). One per thread, not more: a task
    the scheduler has already handed to a worker dies with that worker, so a worker that
    crashes (memory limit, a fault) must hold nothing but the item that killed it. The
    price is one scheduler round trip between items, milliseconds against fits of
    seconds.
    """
    try:
        threads = sum(client.nthreads().values())
    except Exception:  # noqa: BLE001 - a window size, never a reason to fail
        threads = 0
    return max(1, threads)


def _input_bytes(item: Item) -> int:
    total = 0
    for path in item.paths:
        with contextlib.suppress(OSError):
            total += os.stat(path).st_size
    return total


def _follow(client, command, todo, out, options, threads, timeout, records, notify, total, memory_limit, retries):
    """Submit one task per item (a window at a time) and collect the records as they finish.

    The loop sleeps until a task finishes (each future's done-callback wakes it) or a
    second has passed (for the progress bar's running count), so the next item is
    submitted as soon as a worker thread is free: no polling interval between items.
    """
    import threading
    from collections import deque

    token = uuid.uuid4().hex[:8]
    # Largest inputs first (by size on disk, a proxy for their work): the last items to
    # start are the short ones, so the workers finish close together.
    queue = deque(sorted(enumerate(todo), key=lambda pair: -_input_bytes(pair[1])))
    in_flight: dict[str, tuple] = {}
    woken = threading.Event()
    failed = sum(r["status"] != "ok" for r in records.values())
    retries_hint = (f"{retries + 1} attempt{'s' if retries else ''}" if retries is not None
                    else "attempts as the scheduler's allowed-failures permits")
    window = window_size(client)

    def top_up():
        batch = [queue.popleft() for _ in range(min(len(queue), window - len(in_flight)))]
        if not batch:
            return
        keys = [f"nurbskit-{command.name}-{token}-{i}" for i, _ in batch]
        items = [item for _, item in batch]
        payloads = [packed_task(item, k, command=command, out_root=str(out), options=list(options), threads=threads,
                                timeout=timeout) for item, k in zip(items, keys)]
        futures = client.map(pickle.loads, payloads, key=keys, pure=False)
        for future, item in zip(futures, items):
            in_flight[future.key] = (future, item)
            future.add_done_callback(lambda _: woken.set())

    last_poll, running = time.monotonic(), 0
    try:
        top_up()
        while in_flight:
            woken.wait(timeout=max(0.0, 1.0 - (time.monotonic() - last_poll)))
            woken.clear()  # before looking: a task finishing from now on wakes the next wait
            batch = [(future, in_flight.pop(key)[1]) for key, (future, _) in list(in_flight.items()) if future.done()]
            if batch:
                top_up()  # the freed worker threads get their next items before the results travel here
            finished = [f for f, _ in batch if f.status == "finished"]
            results = client.gather(finished, errors="skip") if finished else []
            got = {f.key: r for f, r in zip(finished, results)} if len(results) == len(finished) else {}
            for future, item in batch:
                record = got.get(future.key)
                if record is None:
                    if future.status == "finished":
                        record = client.gather(future, errors="raise")
                    else:
                        exc = future.exception() if future.status == "error" else None
                        error = _failure_message(exc, client, memory_limit, retries_hint) if exc else f"task {future.status}"
                        record = {"input": item.source, "name": item.name, "status": "failed", "error": error,
                                  "seconds": 0.0, "metrics": {}}
                record["resumed"] = False
                records[item.name] = record
                failed += record["status"] != "ok"
                notify({"event": "result", "record": record})
            if batch:
                notify({"event": "update", "done": len(records), "failed": failed, "running": running, "total": total})
            now = time.monotonic()
            if now - last_poll >= 1.0:
                last_poll = now
                with contextlib.suppress(Exception):
                    running = sum(1 for keys_ in client.processing().values() for k in keys_ if k in in_flight)
                window = window_size(client)  # workers may have come or gone
                top_up()
                notify({"event": "update", "done": len(records), "failed": failed, "running": running, "total": total})
    finally:
        if in_flight:
            with contextlib.suppress(Exception):
                client.cancel([f for f, _ in in_flight.values()])


__all__ = ["run", "connect", "completed", "dashboard_link", "usable_cores", "MARKER"]

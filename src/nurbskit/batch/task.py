"""One item, run on a worker: the single command in process, a deadline, a completion marker.

:func:`run_item` is the task ``nurbskit batch`` submits once per item. It never raises
for a failure of the item itself (a bad file, a non-finite fit, a timeout): it returns
a record with ``status="failed"`` and a one-line ``error``, so one bad input cannot stop
the others. Only the loss of the worker process (killed for memory, crashed) is seen
by the scheduler, which retries the item on another worker (``--retries``).

Convention (the output folder ``DIR/<name>/`` of one item):
    The single command builds it under a temporary name and renames it into place when
    complete (:func:`nurbskit._fs.output_directory`). The batch then writes the
    completion marker ``DIR/<name>/.nurbskit-batch.json`` (atomically: temporary file,
    then rename), last. ``--resume`` skips an item only when its marker is there, names
    the same command and options, and the input files have not changed since; so an
    item interrupted at any point, even between the rename and the marker, runs again,
    and its folder is replaced as a whole.
"""

from __future__ import annotations

import argparse
import contextlib
import ctypes
import gc
import importlib
import io
import json
import os
import signal
import socket
import sys
import threading
import time
from functools import lru_cache
from pathlib import Path

from .._fs import atomic_open
from ..errors import NurbskitError, OptionError
from .commands import BatchCommand, Item

MARKER = ".nurbskit-batch.json"
MARKER_VERSION = 1
# Options the batch sets itself for every item; the user may not pass them after `--`.
RESERVED_OPTIONS = ("--out", "--overwrite")


class TaskTimeout(BaseException):
    """Raised inside a task that ran past ``--timeout``.

    A BaseException, like KeyboardInterrupt, so that no ``except Exception`` in the
    command swallows it and every ``finally`` (the temporary output folder's removal)
    still runs.
    """


class _RaisingParser(argparse.ArgumentParser):
    """The command's own parser, raising OptionError instead of exiting the worker."""

    def error(self, message: str):  # noqa: D401 - argparse API
        raise OptionError(f"{self.prog}: {message}")


@lru_cache(maxsize=None)
def command_parser(module: str, name: str) -> argparse.ArgumentParser:
    """The parser ``nurbskit <name>`` uses, built by the command's own ``register``."""
    root = _RaisingParser(prog="nurbskit")
    subparsers = root.add_subparsers(parser_class=_RaisingParser)
    importlib.import_module(module).register(subparsers)
    return subparsers.choices[name]


def command_args(command: BatchCommand, item: Item, out_dir: str | os.PathLike, options: list[str]) -> argparse.Namespace:
    """The single command's parsed arguments for ``item``, writing to ``out_dir``.

    ``options`` (what followed ``--``) are parsed by the command's own parser, after the
    item's inputs; the batch adds ``--out``, ``--overwrite`` (a folder without a
    completion marker is unfinished work) and ``--quiet`` where the command has it.
    """
    for option in options:
        if option.split("=", 1)[0] in RESERVED_OPTIONS:
            raise OptionError(f"-- {option}: set by nurbskit batch for each input (use batch's --out DIR)")
    parser = command_parser(command.module, command.name)
    extra = ["--out", os.fspath(out_dir), "--overwrite"]
    if "--quiet" in parser._option_string_actions:
        extra.append("--quiet")
    return parser.parse_args([*command.argv(item), *extra, *options])


def fingerprint(item: Item) -> list[dict]:
    """What ``--resume`` compares: each input file's path, size and modification time."""
    out = []
    for role, path in item.inputs:
        try:
            st = os.stat(path)
            out.append({"role": role, "path": os.path.abspath(path), "size": st.st_size, "mtime_ns": st.st_mtime_ns})
        except OSError:
            out.append({"role": role, "path": os.path.abspath(path), "size": None, "mtime_ns": None})
    return out


def read_marker(folder: str | os.PathLike) -> dict | None:
    """The completion marker of an item's folder, or None (absent or unreadable)."""
    try:
        with open(Path(folder) / MARKER, encoding="utf-8") as handle:
            marker = json.load(handle)
    except (OSError, ValueError):
        return None
    return marker if isinstance(marker, dict) and marker.get("version") == MARKER_VERSION else None


def one_line(text: str, limit: int = 400, last: bool = False) -> str:
    """An error message as one line, at most ``limit`` characters: the first non-empty line
    of several (an exception's summary), or the ``last`` (what a command printed last)."""
    lines = [ln.strip() for ln in str(text).splitlines() if ln.strip()]
    line = (lines[-1] if last else lines[0]) if lines else ""
    return line if len(line) <= limit else line[: limit - 3] + "..."


def describe_error(exc: BaseException) -> str:
    """One line for a failed item, in the words the single command would print."""
    if isinstance(exc, NurbskitError):
        return one_line(str(exc))
    if isinstance(exc, OSError):
        where = f"{exc.filename}: " if exc.filename else ""
        return one_line(f"{where}{exc.strerror or exc}")
    if isinstance(exc, MemoryError):
        return "out of memory; the input is too large for this worker"
    return one_line(f"{type(exc).__name__}: {exc}")


def _forget_marker(out_dir: Path) -> None:
    """Remove this item's completion marker before it runs again.

    The marker is batch's own file, not the command's: the command's ``--overwrite``
    replaces only the files its manifest lists (:mod:`nurbskit._fs`) and refuses a folder
    holding anything else, so the marker goes first; without it the folder is unfinished
    work until the new marker is written. Staging folders left by a killed attempt are
    removed by the command's own output-folder helper.
    """
    with contextlib.suppress(FileNotFoundError, NotADirectoryError):
        (out_dir / MARKER).unlink()


def _raise_in_thread(thread_id: int, exc_type) -> None:
    ctypes.pythonapi.PyThreadState_SetAsyncExc(ctypes.c_ulong(thread_id), ctypes.py_object(exc_type) if exc_type else None)


# The deadlines running now, by thread; the unraisable hook and the paused collector they share.
_running: dict[int, "Deadline"] = {}
_running_lock = threading.RLock()
_previous_hook = None
_gc_pauses = 0
_gc_was_enabled = True


def _on_unraisable(unraisable) -> None:
    """``sys.unraisablehook`` while a deadline runs: a TaskTimeout that Python could not
    raise (it landed in a garbage-collector callback, such as Dask's GC diagnosis in every
    worker, or in a ``__del__``) is delivered again, not printed; anything else is
    printed as before."""
    if isinstance(unraisable.exc_value, TaskTimeout):
        clock = _running.get(threading.get_ident())
        if clock is not None and clock.expired:
            clock._wake.set()  # its watchdog delivers it again (from here it would land in this hook)
        return
    (_previous_hook or sys.__unraisablehook__)(unraisable)


def _in_gc_callback(thread_id: int) -> bool:
    """Whether the thread is running one of ``gc.callbacks`` now."""
    codes = {getattr(getattr(cb, "__func__", cb), "__code__", None) for cb in gc.callbacks}
    frame = sys._current_frames().get(thread_id)
    while frame is not None:
        if frame.f_code in codes:
            return True
        frame = frame.f_back
    return False


def _pause_gc(pause: bool) -> None:
    """Pause automatic garbage collection while a TaskTimeout is on its way (one counter for
    every deadline of the process): its callbacks run Python code that would swallow it."""
    global _gc_pauses, _gc_was_enabled
    with _running_lock:
        if pause:
            if _gc_pauses == 0:
                _gc_was_enabled = gc.isenabled()
                gc.disable()
            _gc_pauses += 1
        else:
            _gc_pauses -= 1
            if _gc_pauses == 0 and _gc_was_enabled:
                gc.enable()


class Deadline:
    """Raise :class:`TaskTimeout` in the thread that enters it once ``seconds`` have passed.

    Convention (how a timeout reaches the task):
        The exception is delivered between two Python bytecodes of the running thread
        (``PyThreadState_SetAsyncExc``): the fitting loops return to Python at every
        iteration, so it lands within one iteration. Where Python cannot raise it (a
        garbage-collector callback, a ``__del__``: "Exception ignored in ...") it is
        delivered again and nothing is printed; the collector pauses until the task has
        stopped. Whether or not the exception arrived, :meth:`finish` raises it once the
        time has run out, so a task never ends ``ok`` after its deadline. If the thread is
        still busy ``max(10 s, seconds / 2)`` later (stuck inside one long native call, or
        the exception swallowed by an ``except BaseException``), the worker process ends
        itself, after logging a ``nurbskit-batch-timeout`` event that the batch reads to
        report the timeout; the nanny starts a fresh worker.

    ``seconds`` None or 0: no deadline. ``expired`` tells whether the time ran out.

    Example:
        >>> with Deadline(600) as clock:  # doctest: +SKIP
        ...     fit(...)
        ...     clock.finish()  # TaskTimeout if the 600 s have passed; from here on, never
    """

    def __init__(self, seconds: float | None, key: str = ""):
        self.seconds, self.key = seconds, key
        self.expired = False
        self._done = self._ended = self._gc_resumed = False
        self._lock = threading.Lock()  # between the task thread (close) and its watchdog (expiry, delivery)
        self._wake = threading.Event()  # set by close(), and by the hook when the exception was swallowed
        self._thread_id = threading.get_ident()

    def __enter__(self) -> "Deadline":
        global _previous_hook
        if self.seconds:
            self._thread_id = threading.get_ident()
            with _running_lock:
                if not _running and sys.unraisablehook is not _on_unraisable:
                    _previous_hook, sys.unraisablehook = sys.unraisablehook, _on_unraisable
                _running[self._thread_id] = self
            threading.Thread(target=self._watch, name="nurbskit-batch-deadline", daemon=True).start()
        return self

    def __exit__(self, *exc) -> bool:
        self.close()
        return False

    def finish(self) -> None:
        """Stop the clock: raise TaskTimeout when the time has run out, else never from now on."""
        self.close()
        if self.expired:
            raise TaskTimeout

    def close(self) -> None:
        """Stop the clock; idempotent, and safe against the TaskTimeout landing inside it."""
        global _previous_hook
        if not self.seconds or self._ended:
            return
        while True:
            try:
                with self._lock:
                    self._done = True  # the watchdog and the hook deliver nothing from now on
                    if self.expired and not self._gc_resumed:
                        _raise_in_thread(self._thread_id, None)  # clear one not delivered yet
                        _pause_gc(False)
                        self._gc_resumed = True
                break
            except TaskTimeout:  # the pending one arrived just here: nothing is pending now
                continue
        self._wake.set()
        with _running_lock:
            _running.pop(self._thread_id, None)
            if not _running and sys.unraisablehook is _on_unraisable:
                sys.unraisablehook, _previous_hook = _previous_hook, None
        self._ended = True

    def _watch(self) -> None:
        if self._wake.wait(self.seconds):
            return  # closed in time
        with self._lock:
            if self._done:
                return
            self.expired = True
            _pause_gc(True)
            self._wake.clear()
        kill_at = time.monotonic() + max(10.0, self.seconds / 2)
        self._deliver(kill_at)
        while self._wake.wait(max(0.0, kill_at - time.monotonic())):  # closed, or the exception swallowed
            self._wake.clear()
            if not self._deliver(kill_at):
                return

    def _deliver(self, until: float) -> bool:
        """Raise TaskTimeout in the task's thread, once it is out of any garbage-collector
        callback (polled each millisecond, up to ``until``); False when closed meanwhile."""
        while True:
            with self._lock:
                if self._done:
                    return False
                if time.monotonic() >= until or not _in_gc_callback(self._thread_id):
                    _raise_in_thread(self._thread_id, TaskTimeout)
                    return True
            time.sleep(0.001)
        with self._lock:
            if self._done:
                return
        with contextlib.suppress(Exception):
            from distributed import get_worker

            get_worker().log_event("nurbskit-batch-timeout", {"key": self.key, "seconds": self.seconds})
            time.sleep(1.0)  # let the event reach the scheduler
        os.kill(os.getpid(), signal.SIGKILL)


@contextlib.contextmanager
def _torch_threads(threads: int | None):
    if not threads:
        yield
        return
    import torch

    before = torch.get_num_threads()
    torch.set_num_threads(int(threads))
    try:
        yield
    finally:
        torch.set_num_threads(before)


def run_item(item: Item, task_key: str = "", *, command: BatchCommand, out_root: str, options: list[str] = (),
             threads: int | None = 1, timeout: float | None = None) -> dict:
    """Run ``command`` on ``item`` into ``out_root/<item.name>/``; a summary record.

    The record: ``name``, ``input`` (what the user named), ``status`` (``ok`` or
    ``failed``), ``error`` (one line, empty when ok), ``seconds`` (this item's wall
    time), ``cpu_seconds`` (the CPU time of the worker process meanwhile: with one item
    per process, the item's), ``metrics`` (the command's headline numbers), ``worker``
    (host:pid).
    ``task_key`` names the task in the timeout event (see :class:`Deadline`).
    """
    out_root_path = Path(out_root)
    out_dir = out_root_path / item.name
    start, cpu_start = time.perf_counter(), time.process_time()
    record = {"name": item.name, "input": item.source, "status": "failed", "error": "", "seconds": 0.0,
              "cpu_seconds": 0.0, "metrics": {}, "worker": f"{socket.gethostname()}:{os.getpid()}"}
    clock = Deadline(timeout, task_key)
    try:
        with clock:
            _forget_marker(out_dir)
            args = command_args(command, item, out_dir, options)
            stdout, stderr = io.StringIO(), io.StringIO()
            with _torch_threads(threads), contextlib.redirect_stdout(stdout), contextlib.redirect_stderr(stderr):
                code = int(args.run(args) or 0)
            if code != 0:
                raise _CommandFailed(one_line(stderr.getvalue(), last=True) or f"{command.name} exited with status {code}")
            with open(out_dir / command.report, encoding="utf-8") as handle:
                metrics = command.metrics(json.load(handle))
            clock.finish()  # past --timeout is a failure, even when the exception never arrived
        done = {**record, "status": "ok", "metrics": metrics, "seconds": time.perf_counter() - start,
                "cpu_seconds": time.process_time() - cpu_start}
        marker = {"version": MARKER_VERSION, "command": command.name, "options": list(options),
                  "inputs": fingerprint(item), "record": done}
        with atomic_open(out_dir / MARKER, encoding="utf-8") as handle:
            json.dump(marker, handle, indent=1)
        record = done  # ok only once the marker is written
    except TaskTimeout:
        pass  # said below
    except _CommandFailed as exc:
        record["error"] = str(exc)
    except SystemExit as exc:  # a command that calls sys.exit must not end the worker
        record["error"] = f"{command.name} exited with status {exc.code}"
    except Exception as exc:  # noqa: BLE001 - any failure of one item is recorded, never raised
        record["error"] = describe_error(exc)
    finally:
        clock.close()  # already closed, unless the TaskTimeout landed in the deadline's own exit
    if clock.expired:  # whatever the command made of the TaskTimeout (a status, another exception)
        record["error"] = f"timed out after {timeout:g} s (--timeout)"
    record["seconds"] = time.perf_counter() - start
    record["cpu_seconds"] = time.process_time() - cpu_start
    return record


def _run_item_now(args: tuple, kwargs: dict) -> dict:
    return run_item(*args, **kwargs)


class _RunOnLoad:
    """Pickles as "call :func:`run_item` with these arguments" (see :func:`packed_task`)."""

    def __init__(self, args: tuple, kwargs: dict):
        self.args, self.kwargs = args, kwargs

    def __reduce__(self):
        return _run_item_now, (self.args, self.kwargs)


def packed_task(*args, **kwargs) -> bytes:
    """``run_item(*args, **kwargs)`` as bytes that run it when unpickled.

    The batch submits ``pickle.loads(packed_task(...))``: the scheduler, which unpickles
    every task it receives, then sees only the standard library's ``pickle.loads`` and a
    bytes argument, and so never imports nurbskit (nor torch: 240 MB of scheduler memory,
    measured) and needs nothing but Dask installed; the worker's ``pickle.loads`` imports
    nurbskit and runs the item.
    """
    import pickle

    return pickle.dumps(_RunOnLoad(args, kwargs), protocol=pickle.HIGHEST_PROTOCOL)


class _CommandFailed(Exception):
    """The command returned a non-zero status (its last stderr line is the message)."""

"""Outputs that are complete or absent, and that never destroy data nurbskit did not write.

Every file is written to a temporary name in the destination folder and renamed into
place once complete (:func:`atomic_path`, :func:`atomic_open`). Every output *folder*
goes through :func:`output_directory`, which every command uses (and the studio and
batch runs after them).

Convention (the output-folder rules, as the README states them for users):

* A folder nurbskit writes is marked as nurbskit's by ``.nurbskit-manifest.json``,
  which lists the files the run wrote (with their sizes).
* A new folder, or an existing empty one, is written without ``--overwrite``.
* An existing non-empty folder is replaced only with ``overwrite=True``, and only when
  every file in it is one nurbskit wrote there (listed in its manifest, unchanged in
  size). Then exactly those files are removed and the new run's files put in their
  place. Anything else in the folder, a file nurbskit did not write, a file changed
  since, a folder without a manifest, refuses the run, whatever the flags; so does a
  folder another command wrote (the manifest records the command: ``train
  --overwrite`` does not replace the output of ``curves``).
* A folder that holds an input of the run (at any depth) is refused, whatever the flags.
* Nothing is left behind by a failed or interrupted run: the run's files are built in a
  hidden staging folder inside the output folder (``.nurbskit-partial-<pid>-*``, so
  that ``--out .`` works too) and moved into place only at the end; a folder the
  helper created is removed again on failure.
* Two runs on one folder never mix their files: the final move happens under a lock
  on the folder, the folder is checked again under that lock, and Ctrl-C is held back
  until the move is complete.
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import signal
import tempfile
import threading
from pathlib import Path, PurePosixPath
from typing import Iterable, Iterator

from .errors import OptionError

MANIFEST = ".nurbskit-manifest.json"
#: The running command (``"nurbskit fit"``), recorded in the manifests it writes; set by
#: the command line, None in library use (then nothing is recorded or compared).
COMMAND: str | None = None
_PARTIAL = ".nurbskit-partial-"
_SHOWN = 3  # foreign file names quoted in a refusal


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; rename it onto ``path`` on success.

    On any exception (KeyboardInterrupt included) the temporary file is removed and
    ``path`` keeps whatever it held before. Writing a file onto itself is therefore
    safe: the input is read in full before the rename replaces it.
    """
    with atomic_paths([path]) as (tmp_path,):
        yield tmp_path


@contextlib.contextmanager
def atomic_paths(paths) -> Iterator[list[Path]]:
    """:func:`atomic_path` for a set of files written together (a control-point file, its
    weights and its side JSON): a temporary path beside each, all renamed onto ``paths``
    once the block succeeds (Ctrl-C held for the renames), none on failure.

    An OSError of the writing that names no file (a full disk) or a temporary file (a
    read-only folder) is raised again naming the file the caller asked for.
    """
    paths = [Path(p) for p in paths]
    temps: list[Path] = []
    made: list[Path] = []  # folders this call made, deepest last: removed again on failure
    done = False
    try:
        for path in paths:
            missing = [f for f in (path.parent, *path.parent.parents) if not f.exists()]
            try:
                path.parent.mkdir(parents=True, exist_ok=True)
                made += [f for f in reversed(missing) if f not in made]
            except OSError as exc:
                why = "a file of that name is in the way" if isinstance(exc, FileExistsError) else exc.strerror
                raise OSError(exc.errno, f"its folder cannot be made ({why})", str(path)) from None
            try:
                fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
            except OSError as exc:
                raise OSError(exc.errno, exc.strerror, str(path)) from None
            os.close(fd)
            temps.append(Path(tmp))
        try:
            yield list(temps)
        except OSError as exc:
            ours = dict(zip(map(str, temps), paths))
            if exc.filename is not None and str(exc.filename) not in ours:
                raise  # another file's error (an input read while writing)
            raise OSError(exc.errno, exc.strerror, str(ours.get(str(exc.filename), paths[0]))) from None
        with interrupts_held():
            for tmp, path in zip(temps, paths):
                # mkstemp creates 0600 files; give the result the mode a plain open() would.
                os.chmod(tmp, 0o666 & ~_umask())
                os.replace(tmp, path)
        done = True
    finally:
        for tmp in temps:  # the renamed ones are gone already
            with contextlib.suppress(FileNotFoundError):
                tmp.unlink()
        for folder in reversed(made) if not done else ():
            with contextlib.suppress(OSError):  # only if still empty
                folder.rmdir()


@contextlib.contextmanager
def atomic_open(path: str | os.PathLike, mode: str = "w", **kwargs) -> Iterator:
    """``open`` for writing through :func:`atomic_path` (``mode`` 'w' or 'wb')."""
    if "w" not in mode:
        raise ValueError(f"atomic_open is for writing; got mode {mode!r}")
    with atomic_path(path) as tmp:
        with open(tmp, mode, **kwargs) as handle:
            yield handle


# ---- the output folder ----------------------------------------------------------------

def file_id(path: Path):
    """What tells a file apart from the one that replaces it (an atomic write makes a new
    inode) -> a tuple, or None when there is no file."""
    try:
        st = path.stat()
    except OSError:
        return None
    return (st.st_ino, st.st_mtime_ns, st.st_size)


def read_manifest(folder: Path) -> dict[str, int] | None:
    """``{relative posix path: size}`` from the folder's manifest, or None when absent or unreadable."""
    try:
        data = json.loads((folder / MANIFEST).read_text(encoding="utf-8"))
        files = data["files"]
        if data.get("format") != "nurbskit-output" or not isinstance(files, dict):
            return None
        for name in files:  # a manifest must not name anything outside its folder
            parts = PurePosixPath(name).parts
            if not parts or PurePosixPath(name).is_absolute() or ".." in parts or "\\" in name or name == MANIFEST:
                return None
        return {str(k): int(v) for k, v in files.items()}
    except (OSError, ValueError, KeyError, TypeError, RecursionError):
        return None


def manifest_command(folder: Path) -> str | None:
    """The command that wrote ``folder``'s manifest (``"nurbskit curves"``), or None when
    it is not recorded (library use, or a manifest older than the record)."""
    try:
        command = json.loads((folder / MANIFEST).read_text(encoding="utf-8")).get("command")
    except (OSError, ValueError, AttributeError, RecursionError):
        return None
    return command if isinstance(command, str) else None


def write_manifest(folder: Path, files: dict[str, int]) -> None:
    """Write ``folder``'s manifest (atomically): ``files`` maps each file this run wrote,
    as a path relative to ``folder`` (posix), to its size in bytes."""
    data = {"format": "nurbskit-output", "version": 1, "files": files}
    if COMMAND:
        data["command"] = COMMAND
    with atomic_open(folder / MANIFEST, "w", encoding="utf-8") as handle:
        json.dump(data, handle, indent=1)
        handle.write("\n")


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OSError):
        return True
    return True


def _is_partial(name: str) -> bool:
    return name.startswith(_PARTIAL)


def _stale_partials(folder: Path) -> list[Path]:
    """Staging folders left by runs that no longer exist (killed with SIGKILL, power loss)."""
    out = []
    with contextlib.suppress(OSError):
        for entry in folder.iterdir():
            if _is_partial(entry.name):
                try:
                    pid = int(entry.name[len(_PARTIAL):].split("-", 1)[0])
                except ValueError:
                    continue
                if pid != os.getpid() and not _pid_alive(pid):
                    out.append(entry)
    return out


def _foreign(folder: Path, manifest: dict[str, int] | None) -> list[str]:
    """Entries of ``folder`` nurbskit did not write (relative paths, sorted), staging folders aside."""
    listed = manifest or {}
    parents = {p for name in listed for p in Path(name).parents if str(p) != "."}
    found = []
    for root, dirs, files in os.walk(folder, followlinks=False):
        rel_root = Path(root).relative_to(folder)
        if rel_root == Path("."):
            dirs[:] = [d for d in dirs if not _is_partial(d)]
        for d in list(dirs):
            rel = (rel_root / d)
            full = folder / rel
            if full.is_symlink() or rel not in parents:
                found.append(rel.as_posix() + "/")
                dirs.remove(d)
        for f in files:
            rel = (rel_root / f).as_posix()
            if rel == MANIFEST and manifest is not None:
                continue
            size = listed.get(rel)
            full = folder / rel
            if size is None or full.is_symlink():
                found.append(rel)
            else:
                try:
                    if full.stat().st_size != size:
                        found.append(f"{rel} (changed since nurbskit wrote it)")
                except OSError:
                    found.append(rel)
    return sorted(found)


def _holds(folder: Path, path: Path) -> bool:
    try:
        Path(path).resolve().relative_to(folder)
        return True
    except ValueError:
        return False


def check_output_dir(path: str | os.PathLike, overwrite: bool = False, *,
                     inputs: Iterable[str | os.PathLike] = (), option: str = "--out") -> Path:
    """Check that ``path`` may receive this run's outputs, before any work starts.

    Refuses (:class:`~nurbskit.errors.OptionError`, one line naming ``option``): an
    existing file; a folder that holds one of ``inputs``; a non-empty folder without
    ``overwrite``; a non-empty folder holding anything nurbskit did not write (see the
    module docstring). Returns ``path`` as a Path. Creates nothing.
    """
    path = Path(path)
    where = f"{option} {path}"
    if path.exists() and not path.is_dir():
        raise OptionError(f"{where}: expected a folder, found an existing file")
    folder = path.resolve()
    for given in inputs:
        if given is not None and _holds(folder, Path(given)):
            raise OptionError(
                f"{where}: the folder holds the input {given}; nurbskit never writes over its inputs, "
                "choose another output folder"
            )
    for parent in (folder, *folder.parents):
        if parent.exists():
            if not parent.is_dir():
                raise OptionError(f"{where}: {parent} is a file, not a folder")
            break
    if not path.is_dir():
        return path
    manifest = read_manifest(folder)
    if not any(not _is_partial(e.name) for e in folder.iterdir()):  # staging folders aside
        return path
    foreign = _foreign(folder, manifest)
    if foreign:
        shown = ", ".join(foreign[:_SHOWN]) + (f" and {len(foreign) - _SHOWN} more" if len(foreign) > _SHOWN else "")
        why = ("it has no " + MANIFEST) if manifest is None else "they are not in its " + MANIFEST
        raise OptionError(
            f"{where}: the folder holds files nurbskit did not write ({shown}; {why}); "
            "nurbskit replaces only folders it wrote, even with --overwrite: choose a new or empty folder"
        )
    if not overwrite:
        raise OptionError(
            f"{where}: the folder holds the outputs of an earlier run; pass --overwrite to replace them"
        )
    theirs = manifest_command(folder)
    if theirs and COMMAND and theirs != COMMAND:
        raise OptionError(
            f"{where}: the folder holds the outputs of {theirs}; --overwrite replaces only an earlier "
            f"{COMMAND}'s: choose another folder"
        )
    return path


@contextlib.contextmanager
def _folder_lock(folder: Path) -> Iterator[None]:
    """An exclusive lock on ``folder`` itself (flock on its descriptor; none where unsupported)."""
    try:
        import fcntl
    except ImportError:  # pragma: no cover - Windows: no advisory locks on folders
        yield
        return
    fd = os.open(folder, os.O_RDONLY)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        yield
    finally:
        os.close(fd)  # closing releases the lock


@contextlib.contextmanager
def interrupts_held() -> Iterator[None]:
    """Hold Ctrl-C and SIGTERM back for the duration (main thread only); deliver them afterwards.

    The final move of a run's files takes milliseconds; a signal in the middle of it would
    leave the previous run's and this run's files mixed.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    caught: list[int] = []
    previous = {}
    for signum in (signal.SIGINT, signal.SIGTERM):
        with contextlib.suppress(ValueError, OSError):
            previous[signum] = signal.signal(signum, lambda n, _frame: caught.append(n))
    try:
        yield
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)
    for signum in dict.fromkeys(caught):
        handler = previous.get(signum)
        if callable(handler):
            handler(signum, None)  # Python's own SIGINT handler raises KeyboardInterrupt here
        elif handler == signal.SIG_DFL:
            signal.raise_signal(signum)


def _commit(staging: Path, folder: Path, overwrite: bool, inputs, option: str) -> list[str]:
    """Move the staged files into ``folder`` in place of the previous run's; write the manifest."""
    with _folder_lock(folder), interrupts_held():
        # Checked again under the lock: another run may have written here since the start.
        try:
            check_output_dir(folder, overwrite, inputs=inputs, option=option)
        except OptionError as exc:
            raise OptionError(f"{exc} (written by another run while this one worked)") from None
        old = read_manifest(folder) or {}
        new = {}
        for root, _, files in os.walk(staging):
            for f in files:
                rel = (Path(root) / f).relative_to(staging).as_posix()
                new[rel] = (Path(root) / f).stat().st_size
        for stale in _stale_partials(folder):
            shutil.rmtree(stale, ignore_errors=True)
        for rel in old:
            if rel not in new:
                with contextlib.suppress(FileNotFoundError):
                    (folder / rel).unlink()
        for rel in sorted(set(Path(r).parent for r in old if r not in new), key=lambda p: -len(p.parts)):
            if str(rel) != ".":
                with contextlib.suppress(OSError):
                    (folder / rel).rmdir()  # only when empty
        for rel in new:
            target = folder / rel
            target.parent.mkdir(parents=True, exist_ok=True)
            os.replace(staging / rel, target)
        write_manifest(folder, new)
    return sorted(new)


@contextlib.contextmanager
def output_directory(path: str | os.PathLike, overwrite: bool = False, *,
                     inputs: Iterable[str | os.PathLike] = (), option: str = "--out") -> Iterator[Path]:
    """Yield a staging folder to write a run's outputs into; move them into ``path`` at the end.

    Args:
        path: the output folder (created if missing, parents included; ``.`` works).
        overwrite: replace the outputs of an earlier nurbskit run in ``path``.
        inputs: the run's input files: a folder holding any of them is refused.
        option: the option name used in messages (``--out``).

    The rules (module docstring): checked by :func:`check_output_dir` before anything is
    created and again under a lock before the files move. On success ``path`` holds
    exactly this run's files and ``.nurbskit-manifest.json``; on failure or Ctrl-C the
    staging folder (and a ``path`` this call created) is removed and ``path`` holds
    what it held before.

    Example:
        >>> with output_directory("fit-out", overwrite=True, inputs=["scan.ply"]) as tmp:  # doctest: +SKIP
        ...     (tmp / "report.json").write_text("{}")
    """
    inputs = [Path(p) for p in inputs if p is not None]
    path = check_output_dir(path, overwrite, inputs=inputs, option=option)
    folder = path.resolve()
    created = []
    for parent in (folder, *folder.parents):
        if parent.exists():
            break
        created.append(parent)
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OptionError(f"{option} {path}: cannot create the folder ({exc.strerror or exc})") from None
    staging = None
    try:
        staging = Path(tempfile.mkdtemp(prefix=f"{_PARTIAL}{os.getpid()}-", dir=folder))
        os.chmod(staging, 0o777 & ~_umask())  # mkdtemp creates 0700 folders
        yield staging
        _commit(staging, folder, overwrite, inputs, option)
    except BaseException:
        if staging is not None:
            shutil.rmtree(staging, ignore_errors=True)
            staging = None
        for made in created:  # innermost first; only while still empty
            try:
                made.rmdir()
            except OSError:
                break
        raise
    finally:
        if staging is not None:  # after the move only empty subfolders remain
            shutil.rmtree(staging, ignore_errors=True)

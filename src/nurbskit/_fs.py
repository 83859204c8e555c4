"""Atomic outputs: nothing half-written is ever left behind.

Every file is written to a temporary name in the destination folder and renamed
into place once complete; every output directory is built under a temporary name
and renamed into place at the end. An input file is never opened for writing.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
from pathlib import Path
from typing import Iterator

from .errors import OptionError


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
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    os.close(fd)
    tmp_path = Path(tmp)
    try:
        yield tmp_path
        # mkstemp creates 0600 files; give the result the mode a plain open() would.
        os.chmod(tmp_path, 0o666 & ~_umask())
        os.replace(tmp_path, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            tmp_path.unlink()
        raise


@contextlib.contextmanager
def atomic_open(path: str | os.PathLike, mode: str = "w", **kwargs) -> Iterator:
    """``open`` for writing through :func:`atomic_path` (``mode`` 'w' or 'wb')."""
    if "w" not in mode:
        raise ValueError(f"atomic_open is for writing; got mode {mode!r}")
    with atomic_path(path) as tmp:
        with open(tmp, mode, **kwargs) as handle:
            yield handle


def check_output_dir(path: str | os.PathLike, overwrite: bool) -> Path:
    """Refuse an existing non-empty directory unless ``overwrite``; refuse a file."""
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise OptionError(f"--out {path}: expected a directory, found an existing file")
    if path.is_dir() and any(path.iterdir()) and not overwrite:
        raise OptionError(
            f"--out {path}: directory exists and is not empty; pass --overwrite to replace it"
        )
    return path


@contextlib.contextmanager
def output_directory(path: str | os.PathLike, overwrite: bool = False) -> Iterator[Path]:
    """Build an output directory under a temporary name; move it into place at the end.

    Yields the temporary directory to write into. On success the finished directory
    replaces ``path`` (the old one is removed only after the new one is complete);
    on failure or Ctrl-C the temporary directory is removed and ``path`` is untouched.
    """
    path = check_output_dir(path, overwrite)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent))
    try:
        yield tmp
        os.chmod(tmp, 0o777 & ~_umask())  # mkdtemp creates 0700 directories
        if path.exists():
            old = Path(tempfile.mkdtemp(prefix=f".{path.name}.", suffix=".old", dir=path.parent))
            os.replace(path, old / "previous")
            os.replace(tmp, path)
            shutil.rmtree(old, ignore_errors=True)
        else:
            os.replace(tmp, path)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise

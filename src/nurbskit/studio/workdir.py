"""The studio's one folder: every file it reads or writes lies inside it.

No path that arrives from a browser is trusted. A client names a file by a path
*relative* to the working directory; :meth:`Workdir.resolve` refuses absolute paths,
``..`` components, and anything that (through symbolic links) resolves outside the
folder. Uploads are written under ``.studio/uploads`` inside the folder with a name the
studio makes up (only the extension of the client's name is kept, because some readers
choose their parser by it), read back through nurbskit's own readers, and deleted.

Convention: a "relative name" is a POSIX-style path such as ``clouds/duck.ply``.
"""

from __future__ import annotations

import os
import re
import uuid
from pathlib import Path, PurePosixPath

from ..errors import InputError, OptionError

SCRATCH = ".studio"
_EXTENSION = re.compile(r"^\.[A-Za-z0-9]{1,8}$")
# What the file list offers: everything nurbskit reads (points, meshes, NURBS, drawings).
LISTED = {
    ".ply", ".off", ".noff", ".obj", ".stl", ".xyz", ".txt", ".pts", ".xyzc", ".pcd", ".npy", ".npz",
    ".json", ".ctrlpts", ".cptw", ".smesh", ".dat", ".3dm", ".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff",
}


class Workdir:
    """A folder the studio is confined to.

    Example:
        >>> import tempfile
        >>> wd = Workdir(tempfile.mkdtemp())
        >>> wd.resolve("../etc/passwd")  # doctest: +IGNORE_EXCEPTION_DETAIL
        Traceback (most recent call last):
        nurbskit.errors.OptionError: ...
    """

    def __init__(self, root: str | os.PathLike):
        if not str(root).strip():
            raise OptionError("--workdir: expected a folder, got an empty name")
        root = Path(root)
        if not root.is_dir():
            raise OptionError(f"--workdir: {root} is not a directory")
        self.root = root.resolve()

    # ---- names from the client --------------------------------------------------------
    def resolve(self, name: str, *, must_exist: bool = True) -> Path:
        """The absolute path of ``name`` (relative to the folder), or an OptionError.

        Refused: empty names, absolute paths (``/x``, ``C:\\x``, ``~``), any ``..`` part,
        hidden parts (``.x``: the studio's own ``.studio`` scratch, a user's dot-files),
        backslashes, NUL bytes, links that cannot be followed, and paths whose real
        location (after following symbolic links) is outside the folder.
        """
        text = str(name).strip()
        if not text:
            raise OptionError("no file name given")
        if "\x00" in text or "\\" in text:
            raise OptionError(f"{text!r}: file names may not contain backslashes or NUL bytes")
        pure = PurePosixPath(text)
        if pure.is_absolute() or text.startswith("~") or re.match(r"^[A-Za-z]:", text):
            raise OptionError(f"{text!r}: give a path relative to the studio's folder, not an absolute one")
        if any(part == ".." for part in pure.parts):
            raise OptionError(f"{text!r}: '..' is not allowed; the studio only reads and writes inside its folder")
        if any(part.startswith(".") for part in pure.parts):
            raise OptionError(f"{text!r}: hidden names (starting with '.') are not the studio's to read or write")
        path = self.root.joinpath(*pure.parts)
        try:
            real = path.resolve()
        except (OSError, RuntimeError):  # a loop of symbolic links, a folder that cannot be entered
            raise OptionError(f"{text!r}: cannot be followed to a file (a loop of symbolic links?)") from None
        if real != self.root and self.root not in real.parents:
            raise OptionError(f"{text!r}: resolves outside the studio's folder (a symbolic link?)")
        if must_exist and not real.is_file():
            raise OptionError(f"{text!r}: no such file in the studio's folder")
        return real

    def files(self, limit: int = 500) -> list[str]:
        """Relative names of readable files under the folder (scratch excluded), sorted."""
        out = []
        for dirpath, dirnames, filenames in os.walk(self.root, followlinks=False):
            dirnames[:] = sorted(d for d in dirnames if not d.startswith("."))
            for f in sorted(filenames):
                if f.startswith(".") or Path(f).suffix.lower() not in LISTED:
                    continue
                rel = Path(dirpath, f).relative_to(self.root).as_posix()
                try:
                    self.resolve(rel)
                except (OptionError, OSError):
                    continue  # a link out of the folder, or one that cannot be followed, is not offered
                out.append(rel)
                if len(out) >= limit:
                    return out
        return out

    # ---- scratch files -----------------------------------------------------------------
    def scratch(self, client_name: str = "", kind: str = "uploads") -> Path:
        """A fresh path under ``.studio/<kind>/`` keeping only a safe extension of ``client_name``."""
        ext = Path(PurePosixPath(str(client_name).replace("\\", "/")).name).suffix.lower()
        if not _EXTENSION.match(ext or ""):
            ext = ""
        # .ctrlpts.json and similar double extensions matter to the readers
        folder = self.root / SCRATCH / kind
        folder.mkdir(parents=True, exist_ok=True)
        return folder / f"{uuid.uuid4().hex}{ext}"

    def output_name(self, name: str) -> Path:
        """Where a client-named output may be written (validated like :meth:`resolve`)."""
        path = self.resolve(name, must_exist=False)
        if path.is_dir():
            raise OptionError(f"{name!r}: is a directory, expected a file name")
        return path


def too_large(name: str, size: int, limit: int) -> str:
    """The message for an upload of ``size`` bytes over ``limit``."""
    return (f"upload {Path(str(name).replace(chr(92), '/')).name!r} is {size:,} bytes; the studio accepts at most "
            f"{limit:,} (nurbskit studio --max-upload-mb)")


def check_upload(name: str, content: bytes, limit: int) -> None:
    """Refuse an upload larger than ``limit`` bytes, or an empty one (an InputError)."""
    if len(content) > limit:
        raise InputError(too_large(name, len(content), limit))
    if not content:
        raise InputError(f"upload {Path(str(name)).name!r} is empty")

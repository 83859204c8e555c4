"""Atomic outputs: complete or absent, never half-written; modes as a plain open() gives."""

from __future__ import annotations

import os
import stat

import pytest

from nurbskit._fs import atomic_open, atomic_path, output_directory
from nurbskit.errors import OptionError


def _mode(path) -> int:
    return stat.S_IMODE(os.stat(path).st_mode)


def test_atomic_file_is_renamed_into_place_with_umask_mode(tmp_path):
    target = tmp_path / "a.txt"
    with atomic_open(target) as handle:
        handle.write("done")
        assert not target.exists()  # nothing visible until complete
    assert target.read_text() == "done"
    plain = tmp_path / "plain.txt"
    plain.write_text("x")
    assert _mode(target) == _mode(plain)
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []


def test_failed_write_keeps_the_old_file(tmp_path):
    target = tmp_path / "keep.txt"
    target.write_text("old")
    with pytest.raises(KeyboardInterrupt):
        with atomic_path(target) as tmp:
            tmp.write_text("half")
            raise KeyboardInterrupt
    assert target.read_text() == "old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["keep.txt"]


def test_output_directory_needs_overwrite_and_survives_failure(tmp_path):
    out = tmp_path / "out"
    with output_directory(out) as d:
        (d / "result.json").write_text("{}")
    assert (out / "result.json").exists()
    assert _mode(out) == _mode(tmp_path / "out")  # and readable like any mkdir
    probe = tmp_path / "probe"
    probe.mkdir()
    assert _mode(out) == _mode(probe)
    with pytest.raises(OptionError, match="--overwrite"):
        with output_directory(out):
            pass
    with pytest.raises(RuntimeError):
        with output_directory(out, overwrite=True) as d:
            (d / "partial").write_text("x")
            raise RuntimeError("interrupted")
    assert sorted(p.name for p in out.iterdir()) == ["result.json"]  # the old run is intact
    with output_directory(out, overwrite=True) as d:
        (d / "new.json").write_text("{}")
    assert sorted(p.name for p in out.iterdir()) == ["new.json"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out", "probe"]  # no temporaries left

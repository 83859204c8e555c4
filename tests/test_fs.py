"""Outputs: complete or absent, never half-written, and never at the cost of data nurbskit did not write."""

from __future__ import annotations

import json
import os
import stat
import subprocess
import sys
import textwrap

import pytest

from nurbskit._fs import MANIFEST, atomic_open, atomic_path, check_output_dir, output_directory
from nurbskit.errors import OptionError


def _mode(path) -> int:
    return stat.S_IMODE(os.stat(path).st_mode)


def _names(folder) -> list[str]:
    return sorted(p.name for p in folder.iterdir())


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
    assert _names(tmp_path) == ["keep.txt"]


def test_output_directory_needs_overwrite_and_survives_failure(tmp_path):
    out = tmp_path / "out"
    with output_directory(out) as d:
        (d / "result.json").write_text("{}")
    assert _names(out) == [MANIFEST, "result.json"]
    probe = tmp_path / "probe"
    probe.mkdir()
    assert _mode(out) == _mode(probe)  # readable like any mkdir
    with pytest.raises(OptionError, match="--overwrite"):
        with output_directory(out):
            pass
    with pytest.raises(RuntimeError):
        with output_directory(out, overwrite=True) as d:
            (d / "partial").write_text("x")
            raise RuntimeError("interrupted")
    assert _names(out) == [MANIFEST, "result.json"]  # the old run is intact, no staging left
    with output_directory(out, overwrite=True) as d:
        (d / "new.json").write_text("{}")
        (d / "sub").mkdir()
        (d / "sub" / "deep.txt").write_text("deep")
    assert _names(out) == [MANIFEST, "new.json", "sub"]  # exactly this run's files
    manifest = json.loads((out / MANIFEST).read_text())
    assert manifest["files"] == {"new.json": 2, "sub/deep.txt": 4}
    with output_directory(out, overwrite=True) as d:  # a run without the subfolder removes it
        (d / "only.txt").write_text("1")
    assert _names(out) == [MANIFEST, "only.txt"]
    assert _names(tmp_path) == ["out", "probe"]  # no temporaries beside it


def test_overwrite_never_removes_an_input_or_a_foreign_file(tmp_path):
    """The issue's data loss: `fit data/scan.xyz --out data --overwrite` deleted data/."""
    data = tmp_path / "data"
    data.mkdir()
    scan = data / "scan.xyz"
    scan.write_text("0 0 0\n")
    (data / "notes.txt").write_text("mine")
    for inputs in ([scan], []):
        with pytest.raises(OptionError) as err:
            with output_directory(data, overwrite=True, inputs=inputs) as d:
                (d / "surface.json").write_text("{}")
        assert "\n" not in str(err.value)
    assert _names(data) == ["notes.txt", "scan.xyz"]
    assert scan.read_text() == "0 0 0\n"


def test_an_output_folder_holding_an_input_is_refused_even_when_nurbskit_wrote_it(tmp_path):
    out = tmp_path / "out"
    with output_directory(out) as d:
        (d / "points.off").write_text("OFF\n0 0 0\n")
    with pytest.raises(OptionError, match="holds the input"):
        check_output_dir(out, True, inputs=[out / "points.off"])
    with pytest.raises(OptionError, match="holds the input"):  # nested deeper, and the folder itself
        check_output_dir(tmp_path, True, inputs=[out / "points.off"])
    assert (out / "points.off").read_text() == "OFF\n0 0 0\n"


def test_a_changed_or_unlisted_file_makes_the_folder_foreign(tmp_path):
    out = tmp_path / "out"
    with output_directory(out) as d:
        (d / "report.json").write_text("{}")
    (out / "report.json").write_text('{"edited": true}')
    with pytest.raises(OptionError, match="changed since nurbskit wrote it"):
        check_output_dir(out, True)
    (out / "report.json").write_text("{}")
    check_output_dir(out, True)
    (out / "mine.txt").write_text("x")
    with pytest.raises(OptionError, match="mine.txt"):
        check_output_dir(out, True)
    (out / "mine.txt").unlink()
    (out / MANIFEST).unlink()  # without the mark, the folder is not nurbskit's
    with pytest.raises(OptionError, match="no .nurbskit-manifest.json"):
        check_output_dir(out, True)


def test_out_dot_works_in_an_empty_folder_and_is_refused_beside_other_files(tmp_path):
    """`--out . --overwrite` used to fail with EBUSY and leave a `..XXXXXXXX.old` folder."""
    script = textwrap.dedent("""
        import sys
        from pathlib import Path
        from nurbskit._fs import output_directory
        from nurbskit.errors import OptionError
        for overwrite in (False, True):
            with output_directory(".", overwrite) as d:
                (d / "a.txt").write_text(str(overwrite))
        Path("mine.txt").write_text("x")
        try:
            with output_directory(".", True) as d:
                (d / "b.txt").write_text("x")
        except OptionError as exc:
            print(exc)
    """)
    work = tmp_path / "work"
    work.mkdir()
    run = subprocess.run([sys.executable, "-c", script], cwd=work, capture_output=True, text=True,
                         env={**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)}, timeout=60)
    assert run.returncode == 0, run.stderr
    assert "did not write (mine.txt" in run.stdout
    assert _names(work) == [MANIFEST, "a.txt", "mine.txt"]
    assert (work / "a.txt").read_text() == "True"
    assert _names(tmp_path) == ["work"]


def test_a_failed_run_removes_the_folders_it_created(tmp_path):
    target = tmp_path / "a" / "b" / "out"
    with pytest.raises(KeyboardInterrupt):
        with output_directory(target) as d:
            (d / "x").write_text("x")
            raise KeyboardInterrupt
    assert _names(tmp_path) == []


def test_an_existing_file_or_a_path_below_a_file_is_refused(tmp_path):
    f = tmp_path / "file.txt"
    f.write_text("x")
    with pytest.raises(OptionError, match="found an existing file"):
        check_output_dir(f, True)
    with pytest.raises(OptionError, match="is a file, not a folder"):
        with output_directory(f / "sub"):
            pass
    assert _names(tmp_path) == ["file.txt"]


def test_two_runs_on_one_folder_never_mix_their_files(tmp_path):
    """Both start on an empty folder; the one that finishes second finds the first one's outputs."""
    out = tmp_path / "out"
    first = output_directory(out)
    second = output_directory(out)
    d1 = first.__enter__()
    d2 = second.__enter__()
    (d1 / "one.txt").write_text("1")
    (d2 / "two.txt").write_text("2")
    first.__exit__(None, None, None)
    with pytest.raises(OptionError, match="another run"):
        second.__exit__(None, None, None)
    assert _names(out) == [MANIFEST, "one.txt"]
    # with overwrite the later run replaces the earlier one's files completely
    a, b = output_directory(out, True), output_directory(out, True)
    da, db = a.__enter__(), b.__enter__()
    (da / "a.txt").write_text("a")
    (db / "b.txt").write_text("b")
    a.__exit__(None, None, None)
    b.__exit__(None, None, None)
    assert _names(out) == [MANIFEST, "b.txt"]


def test_a_staging_folder_left_by_a_killed_run_is_cleaned_up(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True,
                          text=True, timeout=60)
    stale = out / f".nurbskit-partial-{int(dead.stdout)}-abc"
    stale.mkdir()
    (stale / "half.json").write_text("{")
    with output_directory(out) as d:  # an empty folder apart from the stale staging
        (d / "r.txt").write_text("r")
    assert _names(out) == [MANIFEST, "r.txt"]


@pytest.mark.parametrize("name", ["../victim.txt", "/etc/passwd", "a/../../victim.txt"])
def test_a_manifest_naming_files_outside_its_folder_is_not_trusted(tmp_path, name):
    victim = tmp_path / "victim.txt"
    victim.write_text("precious")
    out = tmp_path / "out"
    with output_directory(out) as d:
        (d / "r.txt").write_text("r")
    manifest = json.loads((out / MANIFEST).read_text())
    manifest["files"][name] = 8
    (out / MANIFEST).write_text(json.dumps(manifest))
    with pytest.raises(OptionError, match="did not write"):
        with output_directory(out, overwrite=True) as d:
            (d / "s.txt").write_text("s")
    assert victim.read_text() == "precious"


def test_atomic_paths_writes_a_set_whole_and_leaves_no_folder_it_made(tmp_path):
    from nurbskit._fs import atomic_paths

    target = [tmp_path / "new" / "deep" / "a.txt", tmp_path / "new" / "deep" / "a.json"]
    with pytest.raises(RuntimeError):
        with atomic_paths(target) as temps:
            temps[0].write_text("half")
            raise RuntimeError("the second file failed")
    assert list(tmp_path.iterdir()) == []  # neither file, nor the folders made for them
    (tmp_path / "kept").mkdir()
    with pytest.raises(RuntimeError):
        with atomic_paths([tmp_path / "kept" / "x.txt"]):
            raise RuntimeError
    assert (tmp_path / "kept").is_dir() and list((tmp_path / "kept").iterdir()) == []
    with atomic_paths(target) as temps:
        for t, text in zip(temps, ("a", "b")):
            t.write_text(text)
    assert [p.read_text() for p in target] == ["a", "b"] and len(list(target[0].parent.iterdir())) == 2


def test_overwrite_replaces_only_the_same_commands_output(tmp_path, monkeypatch):
    import nurbskit._fs as fs

    out = tmp_path / "o"
    monkeypatch.setattr(fs, "COMMAND", "nurbskit curves")
    with output_directory(out) as tmp:
        (tmp / "curves.json").write_text("{}")
    assert json.loads((out / MANIFEST).read_text())["command"] == "nurbskit curves"
    monkeypatch.setattr(fs, "COMMAND", "nurbskit train")
    with pytest.raises(OptionError, match="holds the outputs of nurbskit curves; --overwrite replaces only an earlier "
                                          "nurbskit train's"):
        check_output_dir(out, overwrite=True)
    monkeypatch.setattr(fs, "COMMAND", "nurbskit curves")
    assert check_output_dir(out, overwrite=True) == out
    monkeypatch.setattr(fs, "COMMAND", None)  # library use: nothing recorded, nothing compared
    assert check_output_dir(out, overwrite=True) == out

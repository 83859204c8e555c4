"""Never a traceback, nothing lost: the command line's last line of defence, Ctrl-C and SIGTERM at
any moment, output folders that cannot destroy data, and writers that keep the data."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from nurbskit._fs import MANIFEST
from nurbskit.cli import main
from nurbskit.io import read_points, write_points

from _assert import assert_close
from conftest import REPO_ROOT

ENV = {**os.environ, "PYTHONPATH": str(REPO_ROOT / "src"), "OMP_NUM_THREADS": "1"}


def run(capsys, *argv):
    rc = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return rc, out, err


# ---- the last line of defence -------------------------------------------------------------

@pytest.fixture
def broken_describe(monkeypatch):
    """A bug inside a command: describe() raising an exception nobody planned for."""
    import nurbskit.cli.io_commands as commands

    def boom(*args, **kwargs):
        raise ZeroDivisionError("a bug deep inside")

    monkeypatch.setattr(commands, "describe", boom)


def test_an_unexpected_exception_is_one_line_with_exit_1(tmp_path, capsys, broken_describe):
    path = tmp_path / "a.xyz"
    path.write_text("0 0 0\n1 1 1\n")
    rc, out, err = run(capsys, "info", path)
    assert rc == 1 and out == ""
    assert err.count("\n") == 1 and "Traceback" not in err
    assert err.startswith("nurbskit info: error: ") and str(path) in err
    assert "ZeroDivisionError: a bug deep inside" in err and "run with --debug for the details" in err


@pytest.mark.parametrize("where", ["after", "before"])
def test_debug_shows_the_traceback(tmp_path, capsys, broken_describe, where):
    path = tmp_path / "a.xyz"
    path.write_text("0 0 0\n1 1 1\n")
    argv = ["info", path, "--debug"] if where == "after" else ["--debug", "info", path]
    rc, _, err = run(capsys, *argv)
    assert rc == 1
    assert "Traceback" in err and "ZeroDivisionError" in err and "--debug for the details" not in err


# ---- files with no points (the cases), through the command line ------------------------

EMPTY = {
    "empty.ply": b"ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\nproperty float y\n"
                 b"property float z\nend_header\n",
    "empty.off": b"OFF\n0 0 0\n",
    "empty.pcd": b"VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 0\nHEIGHT 1\n"
                 b"POINTS 0\nDATA ascii\n",
}


@pytest.mark.parametrize("name", sorted(EMPTY))
def test_files_with_no_points_on_info_and_convert(tmp_path, capsys, name):
    path = tmp_path / name
    path.write_bytes(EMPTY[name])
    rc, out, err = run(capsys, "info", path)
    assert rc == 0 and "points      0" in out and err == ""
    rc, out, err = run(capsys, "convert", path, tmp_path / "out.ply")
    assert rc == 2 and err.count("\n") == 1 and "no points" in err
    assert not (tmp_path / "out.ply").exists()


def test_empty_npy_on_info(tmp_path, capsys):
    path = tmp_path / "empty.npy"
    np.save(path, np.zeros((0, 3)))
    rc, out, err = run(capsys, "info", path, "--json")
    assert rc == 0 and '"num_points": 0' in out


# ---- writers that keep the data -----------------------------------------------------------------

def test_float64_beyond_float32_converted_to_pcd_stays_finite(tmp_path, capsys):
    """The issue's silent corruption: a float64 PLY beyond float32's range became inf in PCD."""
    points = np.array([[1e39, 0.0, -2.5e300], [1.0, 2.0, 3.0]])
    src = tmp_path / "big.ply"
    write_points(src, points)
    for mode in ("binary", "ascii", "binary_compressed"):
        dst = tmp_path / f"big_{mode}.pcd"
        rc, _, err = run(capsys, "convert", src, dst, "--pcd-data", mode)
        assert rc == 0, err
        back = read_points(dst)
        assert np.isfinite(back.points).all()
        assert_close(back.points, points, atol=0)
        assert b"SIZE 8 8 8" in dst.read_bytes()[:400]


def test_pcd_keeps_float32_when_the_values_fit(tmp_path):
    path = tmp_path / "small.pcd"
    write_points(path, np.array([[1.0, 2.0, 3.0]]))
    assert b"SIZE 4 4 4" in path.read_bytes()[:400]
    with pytest.raises(Exception, match="beyond float32's range") as err:
        write_points(path, np.array([[1e39, 0.0, 0.0]]), coordinate_dtype=np.float32)
    assert "\n" not in str(err.value)


def test_labels_beyond_32_bits(tmp_path):
    points = np.zeros((2, 3))
    labels = np.array([2**40, -(2**35)])
    write_points(tmp_path / "l.pcd", points, labels=labels)
    assert read_points(tmp_path / "l.pcd").labels.tolist() == labels.tolist()
    from nurbskit.errors import OptionError

    with pytest.raises(OptionError, match="32-bit"):
        write_points(tmp_path / "l.ply", points, labels=labels)
    assert not (tmp_path / "l.ply").exists()


def test_stl_refuses_coordinates_beyond_float32(tmp_path):
    from nurbskit.errors import OptionError
    from nurbskit.io import write_mesh

    with pytest.raises(OptionError, match="float32"):
        write_mesh(tmp_path / "m.stl", np.array([[0, 0, 0], [1e39, 0, 0], [0, 1, 0]], float), [[0, 1, 2]])
    assert list(tmp_path.iterdir()) == []


# ---- output folders -------------------------------------------------------------------------------

def test_train_refuses_a_foreign_folder_before_it_starts(tmp_path, capsys):
    """`train curves --out` on a folder of the user's: one line, no progress bar, the file kept."""
    out = tmp_path / "mine"
    out.mkdir()
    (out / "keep.txt").write_text("mine")
    rc, _, err = run(capsys, "train", "curves", "--mode", "V", "--steps", "2", "--out", out, "--overwrite")
    assert rc == 2 and err.count("\n") == 1 and "did not write (keep.txt" in err
    assert "step" not in err  # refused before the training (and its progress bar) started
    assert [p.name for p in out.iterdir()] == ["keep.txt"] and (out / "keep.txt").read_text() == "mine"


def test_fit_with_out_on_the_input_folder_and_overwrite_deletes_nothing(tmp_path, capsys):
    """The issue's data loss: `fit data/scan.xyz --out data --overwrite` deleted the whole folder."""
    data = tmp_path / "data"
    data.mkdir()
    scan = data / "scan.xyz"
    np.savetxt(scan, np.random.default_rng(0).random((50, 3)))
    (data / "notes.txt").write_text("mine")
    before = {p.name: p.read_bytes() for p in data.iterdir()}
    rc, _, err = run(capsys, "fit", scan, "--out", data, "--overwrite", "--iters", "1", "--quiet")
    assert rc == 2 and err.count("\n") == 1
    assert "did not write" in err or "holds the input" in err
    assert {p.name: p.read_bytes() for p in data.iterdir()} == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["data"]


# ---- Ctrl-C and SIGTERM ---------------------------------------------------------------------------

def _start(args, cwd):
    return subprocess.Popen([sys.executable, "-m", "nurbskit", *map(str, args)], cwd=cwd, env=ENV,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


_INTERRUPT_AT_IMPORT = """
import builtins, runpy, sys
real_import = builtins.__import__
target = sys.argv[1]
def interrupting_import(name, *args, **kwargs):
    level = kwargs.get("level", args[3] if len(args) > 3 else 0)
    if name.split(".")[0] == target and (level > 0) == (target == "cli"):  # "cli": __main__'s own import
        builtins.__import__ = real_import
        raise KeyboardInterrupt
    return real_import(name, *args, **kwargs)
builtins.__import__ = interrupting_import
sys.argv = ["nurbskit", *sys.argv[2:]]
runpy.run_module("nurbskit", run_name="__main__", alter_sys=True)
"""


@pytest.mark.parametrize("module", ["cli", "numpy", "torch"])
def test_ctrl_c_during_start_up_imports_is_one_line(tmp_path, module):
    """Ctrl-C while the command is still importing (made deterministic: the import of ``module``
    raises KeyboardInterrupt, as a SIGINT arriving then does): 'interrupted', exit 130."""
    cloud = tmp_path / "c.xyz"
    cloud.write_text("0 0 0\n1 0 0\n0 1 0\n")
    args = ["fit", cloud, "--out", tmp_path / "out"] if module == "torch" else ["convert", cloud, tmp_path / "c.ply"]
    proc = subprocess.run([sys.executable, "-c", _INTERRUPT_AT_IMPORT, module, *map(str, args)], cwd=tmp_path,
                          env=ENV, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 130, proc.stderr
    assert "Traceback" not in proc.stderr and proc.stderr.count("\n") == 1 and "interrupted" in proc.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["c.xyz"]


def _wait_for_library(proc, marker: str, timeout: float = 60.0) -> None:
    """Wait until ``proc`` has mapped a shared library whose path holds ``marker`` (Linux)."""
    maps = f"/proc/{proc.pid}/maps"
    if not os.path.exists(maps):
        pytest.skip("needs /proc/PID/maps to know when the command has started")
    end = time.monotonic() + timeout
    while time.monotonic() < end and proc.poll() is None:
        try:
            with open(maps) as handle:
                if marker in handle.read():
                    return
        except OSError:
            return
        time.sleep(0.005)


@pytest.mark.parametrize("command, library", [("convert", "_multiarray_umath"), ("fit", "libtorch_cpu")])
def test_ctrl_c_with_a_real_signal_during_start_up(tmp_path, command, library):
    """A real SIGINT as soon as numpy's (or torch's) C core is mapped: nurbskit is importing.

    (Earlier, while Python itself starts, is the interpreter's business, not nurbskit's.)
    """
    cloud = tmp_path / "c.xyz"
    cloud.write_text("0 0 0\n1 0 0\n0 1 0\n0 0 1\n1 1 0\n")
    args = ["convert", cloud, tmp_path / "c.ply"] if command == "convert" else \
        ["fit", cloud, "--out", tmp_path / "out", "--quiet", "--no-figures"]
    proc = _start(args, tmp_path)
    _wait_for_library(proc, library)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    if proc.returncode == 0:
        pytest.skip("the command finished before the signal arrived")
    assert proc.returncode == 130, err
    assert "Traceback" not in err and err.count("\n") == 1
    assert sorted(p.name for p in tmp_path.iterdir()) == ["c.xyz"]


def test_sigterm_during_a_fit_leaves_nothing_behind(tmp_path):
    cloud = tmp_path / "c.xyz"
    rng = np.random.default_rng(0)
    uv = rng.random((400, 2))
    np.savetxt(cloud, np.column_stack([uv, np.sin(3 * uv[:, 0]) * uv[:, 1]]))
    # UCD has no plateau stop, so 100,000 iterations run until the signal (the default
    # pipeline stops on a plateau: this fit took 6.1 s, about when the signal came).
    proc = _start(["fit", cloud, "--out", tmp_path / "out", "--pipeline", "UCD", "--iters", "100000", "--quiet",
                   "--no-figures"], tmp_path)
    time.sleep(6.0)
    proc.send_signal(signal.SIGTERM)
    out, err = proc.communicate(timeout=120)
    assert proc.returncode == 143, err
    assert "Traceback" not in err and "terminated" in err and err.count("\n") == 1
    assert sorted(p.name for p in tmp_path.iterdir()) == ["c.xyz"]


def test_out_dot_with_overwrite_in_a_folder_nurbskit_wrote(tmp_path, capsys):
    """`--out . --overwrite` used to fail with 'Device or resource busy' and leave `..XXXXXXXX.old`."""
    work = tmp_path / "work"
    work.mkdir()
    cwd = os.getcwd()
    os.chdir(work)
    try:
        from nurbskit._fs import output_directory

        with output_directory(".", overwrite=True) as tmp:
            (tmp / "a.txt").write_text("1")
        with output_directory(".", overwrite=True) as tmp:
            (tmp / "b.txt").write_text("2")
    finally:
        os.chdir(cwd)
    assert sorted(p.name for p in work.iterdir()) == [MANIFEST, "b.txt"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["work"]


def test_sample_refuses_too_many_points_and_its_own_input(tmp_path, capsys):
    mesh = tmp_path / "t.off"
    mesh.write_text("OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n")
    before = mesh.read_bytes()
    rc, _, err = run(capsys, "sample", mesh, "-n", 10**13, "-o", tmp_path / "s.ply")
    assert rc == 2 and "samples fit" in err and err.count("\n") == 1
    rc, _, err = run(capsys, "sample", mesh, "-n", 10, "-o", mesh)
    assert rc == 2 and "is the input file" in err
    assert mesh.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["t.off"]

"""Clouds a user may have that no fit can serve as given (coordinates whose squares leave
float64, values beyond float32, points that coincide or lie on a line, points repeated)
and options that contradict each other: one line naming the file or the option, exit 2,
nothing written; and repeated points do not change a multi-patch fit."""

from __future__ import annotations

import json

import numpy as np
import pytest

from _cli import refused, run


def _sheet(n: int = 400, seed: int = 0) -> np.ndarray:
    uv = np.random.default_rng(seed).random((n, 2))
    return np.c_[uv, 0.2 * np.sin(3 * uv[:, 0]) * np.cos(2 * uv[:, 1])]


@pytest.mark.parametrize("factor, word", [(1e200, "overflow"), (1e-300, "underflow")])
def test_fit_refuses_coordinates_whose_squares_leave_float64(tmp_path, capsys, factor, word):
    src = tmp_path / "scaled.xyz"
    np.savetxt(src, _sheet() * factor)
    refused(capsys, ["fit", src, "--out", tmp_path / "o", "--iters", "1", "--quiet"],
            "scaled.xyz: the input points span", f"in float64, would {word}; rescale the coordinates")
    assert not (tmp_path / "o").exists()


def test_fit_in_float32_names_values_beyond_float32_and_fits_tiny_ones(tmp_path, capsys):
    big, tiny = tmp_path / "big.xyz", tmp_path / "tiny.xyz"
    np.savetxt(big, _sheet() * 1e39)
    np.savetxt(tiny, _sheet() * 1e-30)  # representable in float32, but its squares are not
    refused(capsys, ["fit", big, "--out", tmp_path / "o", "--dtype", "float32", "--quiet"],
            "big.xyz: coordinates up to 1e+39 exceed float32; use --dtype float64")
    assert run(["fit", str(tiny), "--out", str(tmp_path / "t"), "--dtype", "float32", "--iters", "2",
                "--no-figures", "--quiet"]) == 0
    report = json.loads((tmp_path / "t" / "report.json").read_text())
    assert report["metrics_normalized"]["to_surface_mean"] < 1e-2


@pytest.mark.parametrize("command", ["fit", "shape", "patches"])
def test_coinciding_and_collinear_points_are_named_as_such(tmp_path, capsys, command):
    same, line = tmp_path / "same.xyz", tmp_path / "line.xyz"
    np.savetxt(same, np.ones((200, 3)))
    t = np.linspace(0, 1, 200)
    np.savetxt(line, np.c_[t, 2 * t, 3 * t])
    quiet = ["--quiet"] if command != "shape" else []  # (a progress bar is not a message)
    refused(capsys, [command, same, "--out", tmp_path / "a", *quiet], "same.xyz: all 200 input points coincide")
    refused(capsys, [command, line, "--out", tmp_path / "b", *quiet], "line.xyz: the 200 input points lie on a line")


def test_fit_names_the_file_when_there_are_too_few_points(tmp_path, capsys):
    src = tmp_path / "one.xyz"
    np.savetxt(src, _sheet(1))
    refused(capsys, ["fit", src, "--out", tmp_path / "o", "--quiet"], "one.xyz: a surface fit needs at least 4 points, got 1")


@pytest.mark.parametrize("init, closed, says", [("plane", "v", "the plane start is an open sheet, not 'v'"),
                                                ("random", "v", "the random start is an open sheet"),
                                                ("cylinder", "open", "the cylinder start is closed in v, not 'open'")])
def test_fit_refuses_a_start_that_contradicts_closed(tmp_path, capsys, init, closed, says):
    src = tmp_path / "s.xyz"
    np.savetxt(src, _sheet())
    refused(capsys, ["fit", src, "--out", tmp_path / "o", "--init", init, "--closed", closed], says)


def test_patches_angles_are_at_most_180_degrees(tmp_path, capsys):
    src = tmp_path / "s.xyz"
    np.savetxt(src, _sheet())
    refused(capsys, ["patches", src, "--out", tmp_path / "o", "--crease-seam", "400"],
            "--crease-seam: expected an angle in degrees, at most 180, got 400.0")


def test_repeated_points_do_not_change_a_multi_patch_fit(tmp_path):
    # Each point listed twice (two scans of one part merged, a file concatenated with
    # itself): the copies once emptied every point's neighbourhood, and the run wrote no
    # patch with exit 0. Now the fit runs on the distinct points and labels every input point.
    from nurbskit.patches import PatchConfig, fit_patches

    x = _sheet(300)
    cfg = PatchConfig(final_iters=0)
    once, twice = fit_patches(x, config=cfg), fit_patches(np.vstack([x, x]), config=cfg)
    assert len(once.patches) == len(twice.patches) >= 1
    assert twice.counts["repeated_points"] == 300 and once.counts["repeated_points"] == 0
    np.testing.assert_array_equal(twice.labels[:300], once.labels)
    np.testing.assert_array_equal(twice.labels[300:], once.labels)
    assert twice.metrics["completeness"] == once.metrics["completeness"]

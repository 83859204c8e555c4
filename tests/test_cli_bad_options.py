"""Bad options of fit, patches, shape, volume and revolve-image: one line naming the option, exit 2,
before any work (an input that does not exist shows the check came first); and the suggestions
those lines make are themselves accepted."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest
from PIL import Image

from _cli import one_line, refused, run
from nurbskit.errors import OptionError


@pytest.fixture
def cloud(tmp_path):
    """``(N, 3)`` random points saved as ``.xyz``: ``cloud(n, planar=False) -> path``."""

    def make(n: int, planar: bool = False, name: str | None = None):
        p = np.random.default_rng(n).random((n, 3))
        if planar:
            p[:, 2] = 0.0
        path = tmp_path / (name or f"r{n}.xyz")
        np.savetxt(path, p)
        return path

    return make


# ---- --mesh-tolerance: checked before anything is read, with or without --format ------------

MISSING = "no-such-input.xyz"


@pytest.mark.parametrize("value, expected", [("-1", "expected a number > 0, got -1"), ("0", "> 0"),
                                             ("nan", "expected a finite number"), ("inf", "finite")])
@pytest.mark.parametrize("command", ["fit", "patches"])
def test_mesh_tolerance_is_checked_before_the_input_is_read(tmp_path, capsys, command, value, expected):
    err = refused(capsys, [command, tmp_path / MISSING, "--out", tmp_path / "o", "--mesh-tolerance", value],
                  "--mesh-tolerance", expected)
    assert "--tolerance" not in err.replace("--mesh-tolerance", "")
    assert MISSING not in err and not (tmp_path / "o").exists()


@pytest.mark.parametrize("command", ["fit", "patches", "volume"])
def test_a_tolerance_too_fine_to_mesh_is_refused_before_the_input_is_read(tmp_path, capsys, command):
    # in range for argparse; refused by the commands' own check of the export options, before any work
    inputs = ([tmp_path / MISSING] if command != "volume" else
              ["--front", tmp_path / "f.png", "--left", tmp_path / "l.png", "--top", tmp_path / "t.png"])
    err = refused(capsys, [command, *inputs, "--out", tmp_path / "o", "--mesh-tolerance", "1e-300"],
                  "--mesh-tolerance")
    assert MISSING not in err and "f.png" not in err and not (tmp_path / "o").exists()


@pytest.mark.parametrize("extra", [[], ["--format", "obj"]])
def test_volume_mesh_tolerance_is_refused_with_or_without_format(tmp_path, capsys, extra):
    missing = [str(tmp_path / f"{v}.png") for v in ("front", "left", "top")]
    err = refused(capsys, ["volume", "--front", missing[0], "--left", missing[1], "--top", missing[2],
                           "--out", tmp_path / "o", "--mesh-tolerance", "-1", *extra],
                  "--mesh-tolerance", "expected a number > 0, got -1")
    assert "front.png" not in err and not (tmp_path / "o").exists()


# ---- patches: --max-points and --seed ------------------------------------------------------

@pytest.mark.parametrize("value", ["1", "2", "19", "-1"])
def test_patches_max_points_below_what_a_fit_needs_is_refused(cloud, tmp_path, capsys, value):
    refused(capsys, ["patches", cloud(60, planar=True), "--out", tmp_path / "o", "--max-points", value, "--quiet"],
            "--max-points: expected 0 (never subsample) or an integer >= 20", f"got {value}")
    assert not (tmp_path / "o").exists()


def test_patch_config_takes_the_bound_the_driver_needs():
    from nurbskit.patches.config import MIN_POINTS, PatchConfig

    for ok in (0, MIN_POINTS, 20_000):
        PatchConfig(max_points=ok).validate()
    with pytest.raises(OptionError, match=f"max_points: expected 0 .* >= {MIN_POINTS}"):
        PatchConfig(max_points=MIN_POINTS - 1).validate()
    with pytest.raises(OptionError, match="seed: expected an integer in"):
        PatchConfig(seed=-1).validate()


def test_patches_subset_of_the_smallest_size_runs(cloud, tmp_path, capsys):
    rc = run(["patches", str(cloud(60, planar=True)), "--out", str(tmp_path / "o"), "--max-points", "20",
              "--no-figures", "--quiet"])
    err = capsys.readouterr().err
    # 20 points either fit or are refused in one line for their content, never an internal error
    assert rc in (0, 2) and "unexpected" not in err and "--max-points" not in err, err


@pytest.mark.parametrize("value", ["-1", "1.5", str(2**63)])
def test_patches_seed_is_checked_as_an_option(cloud, tmp_path, capsys, value):
    path = cloud(60, planar=True)
    err = refused(capsys, ["patches", path, "--out", tmp_path / "o", "--seed", value], "--seed")
    assert path.name not in err


# ---- fit: the suggested --ctrl respects the degree ------------------------------------------

def _suggestion(err: str) -> list[str]:
    found = re.search(r"e\.g\. ((?:--\w+ \S+ ?)+)$", err)
    assert found, err
    return found.group(1).split()


@pytest.mark.parametrize("n, degree_lowered", [(4, True), (10, True), (40, False)])
def test_fit_suggests_a_net_the_degree_allows(cloud, tmp_path, capsys, n, degree_lowered):
    path = cloud(n)
    err = refused(capsys, ["fit", path, "--out", tmp_path / "o", "--quiet"], f"determined by {n} fitted points")
    hint = _suggestion(err)
    assert ("--degree" in hint) == degree_lowered
    # what it suggests passes every check (config and size), here run with no iterations
    rc = run(["fit", str(path), "--out", str(tmp_path / "o"), "--quiet", "--no-figures", "--iters", "0", *hint])
    assert rc == 0, capsys.readouterr().err


def test_fewer_controls_hint():
    from nurbskit.fit.checks import determined_net, fewer_controls_hint

    assert determined_net(40, (3, 3)) == (6, 6) and determined_net(15, (3, 3)) is None
    assert determined_net(20, (4, 1)) == (5, 4)  # as square as the degree allows
    assert fewer_controls_hint(10, (3, 3)).endswith("e.g. --degree 2 --ctrl 3x3")
    assert determined_net(10, (1, 1), closed_v=True) == (3, 3)
    assert "too few for a surface" in fewer_controls_hint(3, (3, 3))


# ---- shape ----------------------------------------------------------------------------------

def test_shape_small_cloud_names_the_file_and_what_shape_can_do(cloud, tmp_path, capsys):
    path = cloud(40)
    err = refused(capsys, ["shape", path, "--out", tmp_path / "o", "--iters", "0", "--no-figures", "--quiet"],
                  f"{path}: ", "--kind revolution or --kind extrusion", "nurbskit fit INPUT --ctrl 6x6")
    assert not (tmp_path / "o").exists()


def test_shape_planar_small_cloud_suggests_only_a_freeform_fit(cloud, tmp_path, capsys):
    path = cloud(50, planar=True)
    err = refused(capsys, ["shape", path, "--out", tmp_path / "o", "--no-figures"], f"{path}: ", "--ctrl 7x7")
    assert "--kind" not in err


@pytest.mark.parametrize("value", ["99999999999999999999", "100001", "-1"])
def test_shape_iters_is_bounded(tmp_path, capsys, value):
    refused(capsys, ["shape", tmp_path / MISSING, "--out", tmp_path / "o", "--iters", value],
            "--iters: expected an integer in [0, 100000]")


def test_fit_shape_bounds_iterations():
    from nurbskit.shapes import fit_shape

    with pytest.raises(OptionError, match=r"iterations must be an integer in \[0, 100,000\]"):
        fit_shape(np.random.default_rng(0).random((40, 3)), "revolution", iterations=10**20)


# ---- volume: --control-size and --isovalue --------------------------------------------------

def volume_args(tmp_path, *extra):
    missing = [str(tmp_path / f"{v}.png") for v in ("front", "left", "top")]
    return ["volume", "--front", missing[0], "--left", missing[1], "--top", missing[2], "--out", tmp_path / "o",
            *extra]


def test_volume_control_size_range_and_degree_agree(tmp_path, capsys):
    from nurbskit.volume.config import VolumeFitConfig

    # the option's range is the field's; the degree's own need is said as such, not as a second range
    low = next(f.metadata["low"] for f in __import__("dataclasses").fields(VolumeFitConfig) if f.name == "control_size")
    refused(capsys, volume_args(tmp_path, "--control-size", str(low - 1)), f"[{low}, 4096]")
    refused(capsys, volume_args(tmp_path, "--control-size", "2"),
            "control_size must be one or three integers in [3, 4096] with degree 2 (at least degree + 1 per axis)")
    refused(capsys, volume_args(tmp_path, "--control-size", "3", "--degree", "3"), "in [4, 4096] with degree 3")
    assert VolumeFitConfig(control_size=2, degree=1).validate().control_size == (2, 2, 2)


@pytest.mark.parametrize("value", ["5", "-5", "0", "1.0001"])
def test_volume_isovalue_outside_the_indicator_range_is_refused(tmp_path, capsys, value):
    err = refused(capsys, volume_args(tmp_path, "--isovalue", value), "--isovalue", "(0, 1]")
    assert "front.png" not in err


# ---- revolve-image: --pixel-size and ignored objects -----------------------------------------

def _image(path, boxes, size=(80, 100)):
    img = np.full(size, 255, np.uint8)
    for r0, r1, c0, c1 in boxes:
        img[r0:r1, c0:c1] = 0
    Image.fromarray(img).save(path)
    return path


@pytest.mark.parametrize("value", ["1e308", "1e-320", "0", "-1", "nan", "inf"])
def test_revolve_image_pixel_size_bounds(tmp_path, capsys, value):
    refused(capsys, ["revolve-image", tmp_path / "missing.png", "--out", tmp_path / "o", "--pixel-size", value],
            "--pixel-size")


@pytest.mark.parametrize("value", ["1e50", "1e-50"])
def test_revolve_image_pixel_size_extremes_give_finite_surfaces(tmp_path, capsys, value):
    from nurbskit import load

    src = _image(tmp_path / "one.png", [(10, 70, 20, 40)])
    nets = {}
    for size in ("1", value):
        out = tmp_path / f"o{size}"
        assert run(["revolve-image", str(src), "--out", str(out), "--pixel-size", size, "--no-figures"]) == 0
        nets[size] = load(out / "surface.json").control_points.numpy()
    assert np.isfinite(nets[value]).all()
    # the pixel-unit surface scaled, not collapsed or overflowed
    np.testing.assert_allclose(nets[value] / float(value), nets["1"], rtol=1e-9, atol=1e-9)


def test_revolve_image_says_other_objects_were_ignored(tmp_path, capsys):
    src = _image(tmp_path / "two.png", [(10, 70, 20, 40), (30, 50, 60, 72), (2, 4, 90, 92)])  # + a 4-pixel speck
    assert run(["revolve-image", str(src), "--out", str(tmp_path / "o"), "--no-figures"]) == 0
    err = capsys.readouterr().err
    assert one_line(err) and "note:" in err and "1 other object (240 pixels) ignored" in err, err
    assert json.loads((tmp_path / "o" / "report.json").read_text())["ignored_objects_px"] == [240]


def test_revolve_image_one_object_with_a_hole_has_no_note(tmp_path, capsys):
    src = _image(tmp_path / "one.png", [(10, 70, 20, 40)])
    img = np.array(Image.open(src))
    img[30:34, 25:35] = 255  # a hole: filled, part of the object
    Image.fromarray(img).save(src)
    assert run(["revolve-image", str(src), "--out", str(tmp_path / "o"), "--no-figures"]) == 0
    assert "note" not in capsys.readouterr().err
    assert json.loads((tmp_path / "o" / "report.json").read_text())["ignored_objects_px"] == []


@pytest.mark.parametrize("argv, says", [
    (["fit", "in.xyz", "--out", "o", "--ctrl", "-3x5"], "argument --ctrl: expected one argument (a value that starts "
                                                         "with '-' is written --ctrl=-3x5)"),
    (["sample", "in.xyz", "-n", "10", "-o", "-x.ply"], "(a value that starts with '-' is written --output=-x.ply)"),
])
def test_a_value_that_starts_with_a_dash_is_explained(capsys, argv, says):
    refused(capsys, argv, says)


def test_a_missing_value_is_not_explained_as_a_dash(capsys):
    err = refused(capsys, ["fit", "in.xyz", "--out"], "argument --out: expected one argument")
    assert "starts with '-'" not in err

"""``nurbskit curves`` end to end, and its one-line errors."""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET

import numpy as np
import pytest
from PIL import Image

from nurbskit.cli import main
from nurbskit.errors import InputError
from nurbskit.core.serialize import from_dict
from nurbskit.curves.classic import chamfer_points
from nurbskit.curves.synthetic import curve_of, dense_samples, render

KNOWN = np.array([[14.0, 100.0], [40.0, 20.0], [80.0, 30.0], [112.0, 96.0]])


def _write(path, grey):
    Image.fromarray(np.round(255 * grey).astype(np.uint8), mode="L").save(path)
    return path


def test_curves_end_to_end(tmp_path, capsys):
    ink = render([dense_samples(curve_of(KNOWN))], (128, 160), 2.0)
    src = _write(tmp_path / "drawing.png", 1.0 - ink)
    out = tmp_path / "out"
    assert main(["curves", str(src), "--out", str(out)]) == 0
    assert "1 curve(s)" in capsys.readouterr().out
    data = json.loads((out / "curves.json").read_text())
    assert "top-left" in data["coordinates"] and data["size"] == [160, 128]
    [curve] = [from_dict(d) for d in data["curves"]]
    got = chamfer_points(dense_samples(curve), dense_samples(curve_of(KNOWN)))
    assert got["symmetric"] < 1.0
    report = json.loads((out / "report.json").read_text())
    assert report["curves"] == 1 and report["polarity"] == "dark on light"
    assert 0 < report["chamfer_px"]["curves_to_ink"] < 1.0 and 0 < report["chamfer_px"]["ink_to_curves"] < 1.5
    svg = ET.parse(out / "curves.svg").getroot()
    paths = [e for e in svg.iter() if e.tag.endswith("path")]
    assert len(paths) == 1 and paths[0].get("d").startswith("M ")
    start = [float(v) for v in paths[0].get("d").split()[1:3]]
    assert np.linalg.norm(np.array(start) - curve.control_points[0].numpy()) < 1e-3
    with Image.open(out / "overlay.png") as im:
        assert im.size == (640, 512)  # scaled up 4x to at least 512 px
    # An existing output is kept without --overwrite, replaced with it.
    assert main(["curves", str(src), "--out", str(out)]) == 2
    assert "--overwrite" in capsys.readouterr().err
    assert main(["curves", str(src), "--out", str(out), "--overwrite", "--refine", "--refine-iters", "5"]) == 0
    assert json.loads((out / "report.json").read_text())["refined"] is True


def test_curves_light_on_dark(tmp_path, capsys):
    ink = render([dense_samples(curve_of(KNOWN))], (128, 128), 3.0)
    src = _write(tmp_path / "chalk.png", ink)
    assert main(["curves", str(src), "--out", str(tmp_path / "o")]) == 0
    report = json.loads((tmp_path / "o" / "report.json").read_text())
    assert report["polarity"] == "light on dark" and report["curves"] == 1


@pytest.mark.parametrize("kind, expected", [
    ("missing", "no such file"),
    ("empty", "the file is empty"),
    ("text", "not a readable image"),
    ("blank", "blank"),
])
def test_curves_bad_images_are_one_line_errors(tmp_path, capsys, kind, expected):
    path = tmp_path / "in.png"
    if kind == "empty":
        path.write_bytes(b"")
    elif kind == "text":
        path.write_text("not an image\n")
    elif kind == "blank":
        _write(path, np.ones((32, 32)))
    assert main(["curves", str(path), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip()
    assert expected in err and "\n" not in err and "Traceback" not in err
    assert not (tmp_path / "o").exists()


def test_curves_unknown_method_or_mode_is_a_usage_error(tmp_path, capsys):
    src = _write(tmp_path / "d.png", 1.0 - render([dense_samples(curve_of(KNOWN))], (128, 128), 2.0))
    for bad in (["--method", "nope"], ["--mode", "X"]):
        with pytest.raises(SystemExit) as info:
            main(["curves", str(src), "--out", str(tmp_path / "o"), *bad])
        assert info.value.code == 2
        assert bad[0] in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("method, mode", [("classic", "MV"), ("hybrid", "V"), ("auto", "M")])
def test_curves_mode_a_method_does_not_use_is_refused(tmp_path, capsys, method, mode):
    src = _write(tmp_path / "d.png", 1.0 - render([dense_samples(curve_of(KNOWN))], (128, 128), 2.0))
    assert main(["curves", str(src), "--out", str(tmp_path / "o"), "--method", method, "--mode", mode]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and f"--mode {mode}: --method {method} reads" in err
    assert not (tmp_path / "o").exists()


def test_curves_decompression_bomb_is_refused(tmp_path, capsys, monkeypatch):
    from PIL import Image as PILImage

    src = _write(tmp_path / "big.png", np.ones((64, 64)))
    monkeypatch.setattr(PILImage, "MAX_IMAGE_PIXELS", 1000)  # 4096 pixels > 2 x 1000: a bomb
    assert main(["curves", str(src), "--out", str(tmp_path / "o")]) == 2
    assert "too large" in capsys.readouterr().err


def test_curves_an_image_that_would_not_fit_in_memory_is_refused(tmp_path, capsys, monkeypatch):
    import nurbskit.io._base as base

    src = _write(tmp_path / "big.png", np.ones((64, 64)))
    monkeypatch.setattr(base, "available_memory", lambda: 100_000)  # 64 x 64 x 128 bytes = 524,288
    assert main(["curves", str(src), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip()
    assert err == (f"nurbskit curves: error: {src}: reading curves from a 64 x 64 image needs about 512.0 KB "
                   "of memory but only 97.7 KB is available")
    assert not (tmp_path / "o").exists()
    with pytest.raises(InputError, match="64 x 64 image needs about 512.0 KB"):  # the API, an array
        import nurbskit

        nurbskit.curves_from_image(np.ones((64, 64)))


def test_curves_a_dot_gives_no_curve_and_valid_json(tmp_path, capsys):
    grey = np.ones((64, 64))
    grey[30:33, 30:33] = 0.0
    src = _write(tmp_path / "dot.png", grey)
    assert main(["curves", str(src), "--out", str(tmp_path / "o")]) == 0
    assert "0 curves" in capsys.readouterr().out
    report = json.loads((tmp_path / "o" / "report.json").read_text())  # strict JSON: no Infinity
    assert report["curves"] == 0 and report["chamfer_px"]["symmetric"] is None
    assert json.loads((tmp_path / "o" / "curves.json").read_text())["curves"] == []


def test_curves_report_their_stages_as_progress():
    from nurbskit.curves.api import extract

    a = KNOWN
    b = np.array([[10.0, 20.0], [60.0, 60.0], [100.0, 40.0], [150.0, 110.0]])
    ink = render([dense_samples(curve_of(a)), dense_samples(curve_of(b))], (128, 160), 2.0)
    seen = []
    curves, _ = extract(1.0 - ink, method="classic", refine=True, refine_iterations=8,
                        progress=lambda stage, done, total: seen.append((stage, done, total)))
    stages = [s for i, (s, _, _) in enumerate(seen) if i == 0 or seen[i - 1][0] != s]
    assert stages == ["tracing strokes", "fitting strokes", "refining"]
    fitting = [(d, t) for s, d, t in seen if s == "fitting strokes"]
    assert [d for d, _ in fitting] == list(range(len(fitting))) and all(t == len(fitting) for _, t in fitting)
    refining = [(d, t) for s, d, t in seen if s == "refining"]
    assert [d for d, _ in refining] == list(range(1, len(refining) + 1)) and all(t == 10 for _, t in refining)
    assert len(curves) == 2


def test_stage_bars_draw_each_stage_on_stderr_unless_quiet(capsys):
    from nurbskit.cli._progress import StageBars

    for quiet in (False, True):
        bars = StageBars(quiet)
        for stage in ("tracing strokes", "fitting strokes"):
            for done in range(3):
                bars(stage, done, 2)
        bars.close()
        err = capsys.readouterr().err
        assert ("tracing strokes" in err and "fitting strokes" in err) is not quiet
        assert quiet is (err == "")


def test_train_curves_sketch_is_an_option_of_mv_only(tmp_path, capsys):
    out = tmp_path / "run"
    code = main(["train", "curves", "--mode", "V", "--sketch", "5", "--steps", "1", "--out", str(out)])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1
    assert "--sketch" in err and "MV" in err and "Traceback" not in err
    assert not out.exists()


@pytest.mark.parametrize("width, noted", [(2.0, False), (14.0, True)])
def test_the_network_method_notes_strokes_thicker_than_it_knows(width, noted, tmp_path, capsys):
    """The networks learnt strokes up to about 5 % of a drawing (1-3 px at 128 px); the
    hybrid method reads thicker ones classically, --method network says what it was given."""
    ink = render([dense_samples(curve_of(KNOWN))], (128, 128), width)
    src = _write(tmp_path / "pen.png", 1.0 - ink)
    assert main(["curves", str(src), "--out", str(tmp_path / "o"), "--method", "network"]) == 0
    err = capsys.readouterr().err
    report = json.loads((tmp_path / "o" / "report.json").read_text())
    assert report["stroke_width"] == pytest.approx(width, abs=2.0)
    if noted:
        assert err.count("\n") == 1 and err.startswith(f"nurbskit curves: note: {src}: the strokes are ")
        assert "(hybrid) reads such drawings classically" in err
        assert report["notes"] == [err.split(f"{src}: ", 1)[1].rstrip("\n")]
    else:
        assert "note" not in err and "notes" not in report

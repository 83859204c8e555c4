"""Units of CAD files: ``units`` names the unit of nurbskit's coordinates. STEP, IGES and
``.3dm`` files declare it with the numbers written unchanged; reading STEP and IGES converts
from the unit a file declares into ``units`` (default millimetres, as before).

Oracles: the files' own text (STEP's ``SI_UNIT`` / ``CONVERSION_BASED_UNIT`` of length,
IGES's global section unit flag and name), rhino3dm's reading of a ``.3dm`` file's model
unit system, and the exact factors between units (1000 mm per m, 25.4 mm per inch).
"""

from __future__ import annotations

import argparse
import re

import numpy as np
import pytest

from _assert import assert_close
from _cad import diagonal, random_surface, require_extra
from _cli import refused
from conftest import shared_file

import nurbskit
from nurbskit.cli import main
from nurbskit.errors import OptionError

OCP = require_extra("OCP")

from nurbskit.io import cad  # noqa: E402


def _surface(seed: int = 3, rational: bool = True):
    return random_surface(np.random.default_rng(seed), (3, 2), rational=rational)


def _same_numbers(a, b, scale: float = 1.0, rtol: float = 0.0, atol: float = 0.0):
    """``a`` is ``b`` with its coordinates times ``scale``: knots and weights exactly."""
    assert a.degrees == b.degrees and a.sizes == b.sizes
    for x, y in zip(a.knot_vectors, b.knot_vectors):
        assert_close(x, y, atol=0)
    assert_close(a.weights, b.weights, atol=0)
    assert_close(a.control_points, b.control_points * scale, rtol=rtol, atol=atol)


def _step_length_unit(text: str) -> str:
    """The length unit a STEP file's geometry declares: the entity, among those of its
    (one) GLOBAL_UNIT_ASSIGNED_CONTEXT, that is a LENGTH_UNIT, on one line."""
    data = text.split("DATA;", 1)[1]
    entities = {int(k): " ".join(v.split()) for k, v in re.findall(r"#(\d+)\s*=\s*(.*?);\s*(?=#\d+\s*=|ENDSEC)",
                                                                  data, flags=re.S)}
    contexts = [re.search(r"GLOBAL_UNIT_ASSIGNED_CONTEXT\s*\(\s*\(([^)]*)\)", e) for e in entities.values()]
    contexts = [c for c in contexts if c]
    assert len(contexts) == 1
    length = [entities[int(i.strip().lstrip("#"))] for i in contexts[0].group(1).split(",")]
    length = [e for e in length if "LENGTH_UNIT()" in e]
    assert len(length) == 1
    return length[0]


def _declares_metres(path) -> bool:
    unit = _step_length_unit(path.read_text())
    return "SI_UNIT($,.METRE.)" in unit and ".MILLI." not in unit


def _iges_global(path) -> list[str]:
    """The parameters of an IGES file's global section (parameter n at index n - 1; the
    delimiters left at their defaults, ',' and ';')."""
    lines = [line for line in path.read_text().splitlines() if len(line) >= 73 and line[72] == "G"]
    text = "".join(line[:72] for line in lines).rstrip()
    assert text.startswith(",,") and text.endswith(";")
    return text[:-1].split(",")


# ---- STEP -------------------------------------------------------------------------------------

def test_step_in_metres_declares_metres_and_keeps_the_numbers(tmp_path):
    s = _surface()
    path = tmp_path / "m.step"
    report = cad.write_cad(s, path, units="m")
    assert report["valid"] and report["faces"] == 1
    assert _declares_metres(path)
    # read in metres: bit for bit; read in millimetres (the default): 1000 times larger
    _same_numbers(cad.read_cad(path, units="m").faces[0].surface, s)
    _same_numbers(cad.read_cad(path).faces[0].surface, s, 1000.0, rtol=1e-12)
    assert cad.cad_info(path)["units"].upper() == "METRE"


def test_step_in_inches_declares_inches(tmp_path):
    s = _surface(4)
    path = tmp_path / "in.step"
    assert cad.write_cad(s, path, units="in")["valid"]
    assert "CONVERSION_BASED_UNIT('INCH'" in _step_length_unit(path.read_text())
    _same_numbers(cad.read_cad(path, units="in").faces[0].surface, s)
    _same_numbers(cad.read_cad(path, units="mm").faces[0].surface, s, 25.4, rtol=1e-12)
    # and from inches into metres
    _same_numbers(cad.read_cad(path, units="m").faces[0].surface, s, 0.0254, rtol=1e-12)


def test_default_units_are_millimetres(tmp_path):
    s = _surface(5)
    cad.write_cad(s, tmp_path / "d.step")
    assert "SI_UNIT(.MILLI.,.METRE.)" in _step_length_unit((tmp_path / "d.step").read_text())
    cad.write_cad(s, tmp_path / "d.igs")
    params = _iges_global(tmp_path / "d.igs")
    assert params[13] == "2" and params[14] == "2HMM"  # unit flag 2: millimetres
    for ext in ("step", "igs"):
        _same_numbers(cad.read_cad(tmp_path / f"d.{ext}").faces[0].surface, s)


# ---- IGES -------------------------------------------------------------------------------------

def test_iges_in_metres_declares_metres_and_keeps_the_numbers(tmp_path):
    s = _surface(6)
    path = tmp_path / "m.igs"
    assert cad.write_cad(s, path, units="m")["valid"]
    params = _iges_global(path)
    assert params[13] == "6" and params[14] == "1HM"  # unit flag 6: metres
    assert params[12] == "1."  # model space scale: the numbers are not scaled
    d = diagonal(s)
    _same_numbers(cad.read_cad(path, units="m").faces[0].surface, s, atol=1e-12 * d)
    _same_numbers(cad.read_cad(path).faces[0].surface, s, 1000.0, rtol=1e-12, atol=1e-12 * d)
    assert cad.cad_info(path)["units"] == "M"


def test_units_pass_through_write_shape_and_read_shape(tmp_path):
    from nurbskit.io.cad.shapes import shape_to_model

    s = _surface(7)
    cad.write_cad(s, tmp_path / "a.brep")
    shape = cad.read_shape(tmp_path / "a.brep", units="m")  # BREP holds no unit: read as it is
    _same_numbers(shape_to_model(shape).faces[0].surface, s)
    assert cad.write_shape(shape, tmp_path / "a.igs", units="ft")["valid"]
    assert _iges_global(tmp_path / "a.igs")[14] == "2HFT"
    d = diagonal(s)
    _same_numbers(shape_to_model(cad.read_shape(tmp_path / "a.igs", units="ft")).faces[0].surface, s, atol=1e-12 * d)
    _same_numbers(shape_to_model(cad.read_shape(tmp_path / "a.igs")).faces[0].surface, s, 304.8, rtol=1e-12,
                  atol=1e-12 * d)


# ---- .3dm -------------------------------------------------------------------------------------

def test_3dm_declares_its_units(tmp_path):
    rhino3dm = require_extra("rhino3dm")
    s = _surface(8, rational=False)  # (a rational one reads back to 1 ulp: x*w / w)
    cad.write_result(s, tmp_path / "m.3dm", units="m")
    cad.write_result(s, tmp_path / "d.3dm")
    cad.write_3dm(tmp_path / "one.3dm", s, units="in")
    assert rhino3dm.File3dm.Read(str(tmp_path / "m.3dm")).Settings.ModelUnitSystem == rhino3dm.UnitSystem.Meters
    assert rhino3dm.File3dm.Read(str(tmp_path / "d.3dm")).Settings.ModelUnitSystem \
        == rhino3dm.UnitSystem.Millimeters
    assert rhino3dm.File3dm.Read(str(tmp_path / "one.3dm")).Settings.ModelUnitSystem == rhino3dm.UnitSystem.Inches
    _same_numbers(cad.read_3dm(tmp_path / "m.3dm"), s)  # the numbers as written


# ---- bad units ------------------------------------------------------------------------------------

@pytest.mark.parametrize("call", [
    lambda s, p: cad.write_cad(s, p / "x.step", units="parsec"),
    lambda s, p: cad.write_result(s, p / "x.3dm", units="parsec"),
    lambda s, p: cad.write_result(s, p / "x.json", units="M"),
    lambda s, p: cad.read_cad(p / "x.step", units="km"),
])
def test_a_bad_unit_is_an_option_error_naming_the_units(tmp_path, call):
    with pytest.raises(OptionError, match=r"units must be one of mm, cm, m, in, ft, um"):
        call(_surface(), tmp_path)
    assert not list(tmp_path.iterdir())


# ---- the command line -----------------------------------------------------------------------------

def test_export_units_on_the_command_line(tmp_path, capsys):
    s = _surface(9)
    nurbskit.save(s, tmp_path / "s.json")
    assert main(["export", str(tmp_path / "s.json"), str(tmp_path / "s.step"), "--units", "m"]) == 0
    assert "OpenCASCADE check passed" in capsys.readouterr().err
    assert _declares_metres(tmp_path / "s.step")
    _same_numbers(cad.read_cad(tmp_path / "s.step", units="m").faces[0].surface, s)
    # STEP in: converted into --units (metres: the numbers as they were; default: millimetres)
    assert main(["export", str(tmp_path / "s.step"), str(tmp_path / "back.json"), "--units", "m"]) == 0
    _same_numbers(nurbskit.load(tmp_path / "back.json"), s)
    assert main(["export", str(tmp_path / "s.step"), str(tmp_path / "mm.json")]) == 0
    _same_numbers(nurbskit.load(tmp_path / "mm.json"), s, 1000.0, rtol=1e-12)
    # `info` says what the file declares
    assert main(["info", str(tmp_path / "s.step")]) == 0
    assert "units       the file declares" in capsys.readouterr().out
    err = refused(capsys, ["export", tmp_path / "s.json", tmp_path / "p.step", "--units", "parsec"], "--units")
    assert "parsec" in err
    assert not (tmp_path / "p.step").exists()


def test_a_result_commands_units_option(tmp_path):
    from nurbskit.cli.export_command import add_format_option, write_requested_format

    parser = argparse.ArgumentParser()
    add_format_option(parser)
    args = parser.parse_args(["--format", "step", "--units", "m"])
    assert args.export_units == "m"
    assert parser.parse_args(["--format", "step"]).export_units == "mm"
    with pytest.raises(SystemExit):
        parser.parse_args(["--units", "parsec"])
    args.command = "fit"
    s = _surface(10)
    write_requested_format(args, s, tmp_path, "surface")
    assert _declares_metres(tmp_path / "surface.step")
    _same_numbers(cad.read_cad(tmp_path / "surface.step", units="m").faces[0].surface, s)


def test_fit_format_step_units_m(tmp_path):
    """`nurbskit fit --format step --units m`: the fitted surface in a file that declares metres."""
    rng = np.random.default_rng(0)
    uv = rng.random((400, 2))
    np.savetxt(tmp_path / "c.xyz", np.c_[uv, 0.1 * np.sin(3 * uv[:, 0]) * uv[:, 1]])
    out = tmp_path / "fit"
    assert main(["fit", str(tmp_path / "c.xyz"), "--ctrl", "6x6", "--iters", "3", "--resolution", "16x16",
                 "--no-figures", "--quiet", "--out", str(out), "--format", "step", "--units", "m"]) == 0
    assert _declares_metres(out / "surface.step")
    _same_numbers(cad.read_cad(out / "surface.step", units="m").faces[0].surface, nurbskit.load(out / "surface.json"))


# ---- a STEP file from elsewhere ---------------------------------------------------------------------

def test_abc_step_in_metres_reads_in_metres(shared_data):
    step = shared_file(shared_data, "abc/00000050_80d90bfdd2e74e709956122a_step_000.step")
    assert cad.cad_info(step)["units"] == "METRE"
    mm, m = cad.read_cad(step), cad.read_cad(step, units="m")
    assert len(mm.faces) == len(m.faces) == 43
    for a, b in zip(m.faces, mm.faces):
        assert_close(a.surface.control_points, b.surface.control_points / 1000.0, rtol=1e-12,
                     atol=1e-12 * diagonal(b.surface) / 1000.0)


def test_the_command_lines_units_are_the_libraries():
    from nurbskit.cli.export_command import UNIT_CHOICES
    from nurbskit.io.cad.exchange import UNITS

    assert UNIT_CHOICES == tuple(UNITS)


def test_a_batch_export_items_units(tmp_path):
    # what each item of `nurbskit batch export ... -- --units m` runs (the batch's own parser)
    from nurbskit.batch import export as batch_export

    s = _surface(5)
    nurbskit.core.save(s, tmp_path / "s.json")
    parser = argparse.ArgumentParser()
    batch_export.register(parser.add_subparsers())
    args = parser.parse_args(["export", str(tmp_path / "s.json"), "--out", str(tmp_path / "out"), "--units", "m"])
    assert args.run(args) == 0
    assert _declares_metres(tmp_path / "out" / "s.step")
    _same_numbers(cad.read_cad(tmp_path / "out" / "s.step", units="m").faces[0].surface, s)


def test_a_3dm_input_is_converted_from_its_declared_unit_on_export(tmp_path, capsys):
    # a Rhino model in metres exported to STEP was declared millimetres with its numbers
    # unchanged: 1000 times too small in CAD software
    require_extra("rhino3dm")
    from nurbskit.io.cad.rhino import read_3dm_all

    s = _surface(9, rational=False)
    cad.write_result(s, tmp_path / "m.3dm", units="m")
    _same_numbers(read_3dm_all(tmp_path / "m.3dm")[0], s)  # no units: the numbers as they are
    _same_numbers(read_3dm_all(tmp_path / "m.3dm", units="m")[0], s)
    _same_numbers(read_3dm_all(tmp_path / "m.3dm", units="mm")[0], s, scale=1000.0, rtol=1e-15)
    assert main(["export", str(tmp_path / "m.3dm"), str(tmp_path / "mm.step")]) == 0
    assert not _declares_metres(tmp_path / "mm.step")
    _same_numbers(cad.read_cad(tmp_path / "mm.step").faces[0].surface, s, scale=1000.0, rtol=1e-15)
    assert main(["export", str(tmp_path / "m.3dm"), str(tmp_path / "m.step"), "--units", "m"]) == 0
    assert _declares_metres(tmp_path / "m.step")
    _same_numbers(cad.read_cad(tmp_path / "m.step", units="m").faces[0].surface, s)

"""NURBS parameter files: nurbskit JSON, geomdl JSON, .ctrlpts/.weights/.cptw, smesh, .3dm;
geomdl's own readers and writers as the oracle, round trips exact."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch

import nurbskit
from _splines import small_curve as _curve, small_surface as _surface, small_volume as _volume
from nurbskit.errors import InputError, OptionError
from nurbskit.io import read_nurbs, read_weights, write_nurbs

from _assert import assert_close


def assert_same(a, b):
    assert a.kind == b.kind and a.sizes == b.sizes and a.degrees == b.degrees
    torch.testing.assert_close(a.control_points, b.control_points, rtol=0, atol=1e-14)
    torch.testing.assert_close(a.weights, b.weights, rtol=0, atol=1e-15)
    for x, y in zip(a.knot_vectors, b.knot_vectors):
        torch.testing.assert_close(x, y, rtol=0, atol=0)


@pytest.mark.parametrize("make", [_curve, _surface, _volume])
@pytest.mark.parametrize("ext", [".json", ".ctrlpts"])
def test_round_trip_json_and_ctrlpts(tmp_path, make, ext):
    obj = make()
    written = write_nurbs(tmp_path / f"obj{ext}", obj)
    assert all(p.exists() for p in written)
    assert_same(read_nurbs(tmp_path / f"obj{ext}"), obj)


@pytest.mark.parametrize("make", [_curve, _surface])
def test_round_trip_cptw(tmp_path, make):
    obj = make()
    write_nurbs(tmp_path / "o.cptw", obj)
    assert_same(read_nurbs(tmp_path / "o.cptw"), obj)


def test_round_trip_smesh_and_geomdl_reads_it(tmp_path):
    from geomdl import exchange

    obj = _surface()
    write_nurbs(tmp_path / "s.smesh", obj)
    assert_same(read_nurbs(tmp_path / "s.smesh"), obj)
    ref = nurbskit.from_geomdl(exchange.import_smesh(str(tmp_path / "s.smesh"))[0])
    torch.testing.assert_close(ref.control_points, obj.control_points, rtol=0, atol=1e-14)


@pytest.mark.parametrize("make", [_curve, _surface, _volume])
def test_geomdl_json_both_ways(tmp_path, make):
    from geomdl import exchange

    obj = make()
    write_nurbs(tmp_path / "g.json", obj, format="geomdl")
    ref = nurbskit.from_geomdl(exchange.import_json(str(tmp_path / "g.json"))[0])
    torch.testing.assert_close(ref.control_points, obj.control_points, rtol=0, atol=1e-14)
    torch.testing.assert_close(ref.weights, obj.weights, rtol=0, atol=1e-15)
    exchange.export_json(nurbskit.to_geomdl(obj), str(tmp_path / "h.json"))
    back = read_nurbs(tmp_path / "h.json")
    torch.testing.assert_close(back.control_points, obj.control_points, rtol=0, atol=1e-14)
    torch.testing.assert_close(back.weights, obj.weights, rtol=0, atol=1e-15)


def test_cptw_as_in_the_thesis(tmp_path):
    """Listing 2.6: rows are u, ';' separates v, each point is x*w, y*w, z*w, w."""
    path = tmp_path / "t.cptw"
    path.write_text("1.0,0.0,0.0,1.0;0.7071,0.7071,0.0,0.7071;0.0,1.0,0.0,1.0\n"
                    "1.0,0.0,1.0,1.0;0.7071,0.7071,0.7071,0.7071;0.0,1.0,1.0,1.0\n")
    s = read_nurbs(path, degrees=(1, 2))
    assert s.sizes == (2, 3)
    assert_close(s.control_points[0, 1], torch.tensor([1.0, 1.0, 0.0], dtype=torch.float64), atol=0.0)
    # a quarter circle: the middle of the first row is at distance 1 from the axis
    mid = s.evaluate(torch.tensor([[0.0, 0.5]], dtype=torch.float64))[0]
    assert abs(float(mid[:2].norm()) - 1.0) < 1e-4


def test_ctrlpts_options_side_json_and_weights(tmp_path):
    obj = _surface()
    cp = obj.control_points.reshape(-1, 3).numpy()
    (tmp_path / "d.ctrlpts").write_text("\n".join(" ".join(repr(float(c)) for c in p) for p in cp) + "\n")
    with pytest.raises(OptionError, match="give sizes"):
        read_nurbs(tmp_path / "d.ctrlpts")
    # a weights file beside it is found; knots from the options
    (tmp_path / "d.weights").write_text(",".join(repr(float(w)) for w in obj.weights.flatten()) + ",")
    kv = [k.tolist() for k in obj.knot_vectors]
    s = read_nurbs(tmp_path / "d.ctrlpts", knot_vectors=kv)  # sizes and degrees follow from clamped knots
    assert_same(s, obj)
    assert not read_nurbs(tmp_path / "d.ctrlpts", knot_vectors=kv, weights=None).is_rational
    # the same through a side JSON
    (tmp_path / "meta.json").write_text(json.dumps({"knot_vectors": kv, "weights": "d.weights"}))
    assert_same(read_nurbs(tmp_path / "d.ctrlpts", meta=tmp_path / "meta.json"), obj)
    with pytest.raises(InputError, match="holds 20 control points but sizes \\[4, 4\\] need 16"):
        read_nurbs(tmp_path / "d.ctrlpts", sizes=(4, 4), degrees=(2, 2))
    with pytest.raises(OptionError, match="degrees are needed"):
        read_nurbs(tmp_path / "d.ctrlpts", sizes=(5, 4))


def test_weights_file(tmp_path):
    path = tmp_path / "w.weights"
    path.write_text("1,1,1,1,\n0.5,1,1,1,\n1,1,0.5,1")
    np.testing.assert_array_equal(read_weights(path), [1, 1, 1, 1, 0.5, 1, 1, 1, 1, 1, 0.5, 1])
    path.write_text("1,0,1")
    with pytest.raises(InputError, match="positive"):
        read_weights(path)
    path.write_text("1,x,1")
    with pytest.raises(InputError, match="found b'x'"):
        read_weights(path)
    with pytest.raises(InputError, match="holds only weights"):
        read_nurbs(path)


@pytest.mark.parametrize("text, message", [
    ('{"format": "nurbskit", "version": 9}', "version 9 is not supported"),
    ('{"shape": {"type": "surface", "data": [{"degree_u": 2}]}}', "lacks the field"),
    ('{"hello": 1}', "neither nurbskit"),
    ('{"format": "nurbskit", ', "not valid JSON"),
])
def test_bad_json(tmp_path, text, message):
    path = tmp_path / "bad.json"
    path.write_text(text)
    with pytest.raises(InputError, match=message):
        read_nurbs(path)


def test_inconsistent_knots_named(tmp_path):
    path = tmp_path / "bad.ctrlpts"
    path.write_text("0 0 0\n1 0 0\n2 0 0\n3 0 0\n")
    with pytest.raises(InputError, match=r"bad\.ctrlpts: .*knot"):
        read_nurbs(path, sizes=(4,), degrees=(2,), knot_vectors=[[0, 0, 0, 1, 1, 1]])


def test_write_nurbs_rejects(tmp_path):
    with pytest.raises(OptionError, match="smesh holds surfaces"):
        write_nurbs(tmp_path / "c.smesh", _curve())
    with pytest.raises(OptionError, match="cannot write NURBS as '.ply'"):
        write_nurbs(tmp_path / "c.ply", _curve())


# .3dm tests: tests/test_io_cad_outputs.py (they must fail, not skip, without rhino3dm in CI)

"""STEP and IGES files read by a second, independent reader: the file's text parsed here
(the STEP exchange structure of ISO 10303-21, IGES 5.3's fixed columns), its B-spline
surface rebuilt from the parsed numbers alone and evaluated by geomdl, against nurbskit's
evaluation of the surface that was written. Nothing of OpenCASCADE or of nurbskit's
readers is used on the way back, so a writer that put wrong numbers, a wrong ordering of
the control net or wrong knots into the file would be caught here even if OCC read its own
mistake back consistently.
"""

from __future__ import annotations

import re

import numpy as np
import pytest
import torch

from _cad import require_extra

import nurbskit
from nurbskit.core.trim import TrimLoop, TrimmedSurface

OCP = require_extra("OCP")
geomdl = pytest.importorskip("geomdl")

from nurbskit.io import cad  # noqa: E402


def _surface(seed: int = 0, rational: bool = True) -> nurbskit.NURBSSurface:
    """Clamped on [0, 1] (geomdl's domain), an interior double knot, weights far from one."""
    rng = np.random.default_rng(seed)
    ku = np.array([0, 0, 0, 0, 0.3, 0.55, 0.55, 1, 1, 1, 1.0])  # degree 3, 7 control points
    kv = np.array([0, 0, 0, 0.4, 1, 1, 1.0])  # degree 2, 4 control points
    cp = np.concatenate([np.stack(np.meshgrid(np.linspace(0, 60, 7), np.linspace(0, 30, 4), indexing="ij"), -1),
                         rng.normal(0, 5, (7, 4, 1))], -1) + 120.0  # mid-range and large coordinates
    w = rng.uniform(0.5, 2.0, (7, 4)) if rational else np.ones((7, 4))
    return nurbskit.NURBSSurface(torch.tensor(cp), (3, 2), [torch.tensor(ku), torch.tensor(kv)], torch.tensor(w))


# ---- a small reader of STEP's exchange structure ---------------------------------------------

_TOKEN = re.compile(r"\s*(?:(?P<ref>#\d+)|(?P<str>'(?:[^']|'')*')|(?P<enum>\.[A-Z_][A-Z0-9_]*\.)|"
                    r"(?P<num>[-+]?(?:\d+\.?\d*|\.\d+)(?:[EeDd][-+]?\d+)?)|(?P<name>[A-Z_][A-Z0-9_]*)|"
                    r"(?P<punct>[(),$*]))")


def _parse_params(text: str):
    """STEP parameters to Python: lists, floats, ints, '#n' references, strings, enums, and
    typed values / partial entities as (NAME, [args])."""
    tokens = [(m.lastgroup, m.group(m.lastgroup)) for m in _TOKEN.finditer(text)]
    pos = 0

    def value():
        nonlocal pos
        kind, tok = tokens[pos]
        pos += 1
        if tok == "(":
            items = []
            while tokens[pos][1] != ")":
                items.append(value())
                if tokens[pos][1] == ",":
                    pos += 1
            pos += 1
            return items
        if kind == "name":  # NAME(args): a typed value or a partial entity of a complex one
            return (tok, value())
        if kind == "num":
            return float(tok.replace("D", "E")) if any(c in tok for c in ".EeDd") else int(tok)
        return tok

    out = []
    while pos < len(tokens):
        out.append(value())
    return out


def step_entities(text: str) -> dict[int, dict[str, list]]:
    """``{id: {entity name: args}}`` (a complex entity has several names)."""
    data = text.split("DATA;", 1)[1].split("ENDSEC;", 1)[0]
    out = {}
    for record in re.split(r";\s*(?=#\d+\s*=|$)", data.strip()):
        m = re.match(r"#(\d+)\s*=\s*(.*)", record.strip(), re.S)
        if not m:
            continue
        parsed = _parse_params(m.group(2))
        parts = parsed[0] if isinstance(parsed[0], list) else parsed  # complex: ( A(..) B(..) )
        out[int(m.group(1))] = {name: args for name, args in parts}
    return out


def _expand(knots, mults):
    return np.repeat(np.asarray(knots, dtype=float), np.asarray(mults, dtype=int))


def step_surfaces(text: str) -> list[dict]:
    ents = step_entities(text)
    point = lambda ref: ents[int(ref[1:])]["CARTESIAN_POINT"][1]  # noqa: E731
    found = []
    for e in ents.values():
        if "B_SPLINE_SURFACE_WITH_KNOTS" not in e:
            continue
        if "B_SPLINE_SURFACE" in e:  # complex (rational) form
            deg_u, deg_v, net = e["B_SPLINE_SURFACE"][:3]
            mu, mv, ku, kv = e["B_SPLINE_SURFACE_WITH_KNOTS"][:4]
            weights = np.array(e["RATIONAL_B_SPLINE_SURFACE"][0], dtype=float)
        else:
            _, deg_u, deg_v, net, *_rest = e["B_SPLINE_SURFACE_WITH_KNOTS"]
            mu, mv, ku, kv = e["B_SPLINE_SURFACE_WITH_KNOTS"][8:12]
            weights = None
        cp = np.array([[point(r) for r in row] for row in net], dtype=float)
        found.append({"degrees": (deg_u, deg_v), "control_points": cp, "knots": (_expand(ku, mu), _expand(kv, mv)),
                      "weights": np.ones(cp.shape[:2]) if weights is None else weights})
    return found


# ---- a small reader of IGES's fixed columns ---------------------------------------------------

def iges_entities(text: str, entity_type: int) -> list[list]:
    """The parameter lists of every entity of ``entity_type`` (parameter section: data in
    columns 1-64, the directory entry's pointer in 66-72; ',' and ';' delimiters)."""
    records: dict[int, str] = {}
    for line in text.splitlines():
        if len(line) >= 73 and line[72] == "P":
            de = int(line[64:72])
            records[de] = records.get(de, "") + line[:64]
    out = []
    for data in records.values():
        fields = data.split(";")[0].split(",")
        if int(fields[0]) == entity_type:
            out.append([float(f.replace("D", "E")) if f.strip() else 0.0 for f in fields])
    return out


def iges_surfaces(text: str) -> list[dict]:
    found = []
    for f in iges_entities(text, 128):
        k1, k2, m1, m2 = (int(x) for x in f[1:5])
        n1, n2 = k1 + 1, k2 + 1
        i = 10
        ku = np.array(f[i:i + n1 + m1 + 1]); i += n1 + m1 + 1
        kv = np.array(f[i:i + n2 + m2 + 1]); i += n2 + m2 + 1
        w = np.array(f[i:i + n1 * n2]).reshape(n2, n1).T; i += n1 * n2  # the first index runs fastest
        cp = np.array(f[i:i + 3 * n1 * n2]).reshape(n2, n1, 3).transpose(1, 0, 2)
        found.append({"degrees": (m1, m2), "control_points": cp, "knots": (ku, kv), "weights": w})
    return found


def geomdl_evaluate(parsed: dict, uv: np.ndarray) -> np.ndarray:
    """Evaluate the parsed surface with geomdl (its own NURBS evaluator)."""
    from geomdl import NURBS

    s = NURBS.Surface(normalize_kv=False)
    s.degree_u, s.degree_v = parsed["degrees"]
    nu, nv = parsed["control_points"].shape[:2]
    s.ctrlpts_size_u, s.ctrlpts_size_v = nu, nv
    s.ctrlpts = parsed["control_points"].reshape(-1, 3).tolist()  # u-major, v fastest
    s.weights = parsed["weights"].reshape(-1).tolist()
    s.knotvector_u, s.knotvector_v = (k.tolist() for k in parsed["knots"])
    return np.array(s.evaluate_list(uv.tolist()))


def _check_same(surface, parsed: list[dict], rel: float):
    assert len(parsed) == 1
    p = parsed[0]
    assert p["degrees"] == surface.degrees and p["control_points"].shape[:2] == surface.sizes
    uv = np.random.default_rng(5).uniform(0, 1, (60, 2))
    uv[:4] = [[0, 0], [1, 1], [0.55, 0.4], [0.3, 1]]  # corners, the double knot
    expected = surface.evaluate(torch.tensor(uv)).numpy()
    cp = surface.control_points.reshape(-1, 3).numpy()
    diag = float(np.linalg.norm(cp.max(0) - cp.min(0)))
    assert np.abs(geomdl_evaluate(p, uv) - expected).max() <= rel * diag


@pytest.mark.parametrize("rational", [True, False])
def test_step_file_read_by_a_second_reader_shows_the_same_surface(tmp_path, rational):
    s = _surface(1, rational)
    cad.write_cad(s, tmp_path / "s.step")
    text = (tmp_path / "s.step").read_text()
    assert text.count("ADVANCED_FACE") == 1 and ("RATIONAL_B_SPLINE_SURFACE" in text) == rational
    _check_same(s, step_surfaces(text), 1e-13)


@pytest.mark.parametrize("rational", [True, False])
def test_iges_file_read_by_a_second_reader_shows_the_same_surface(tmp_path, rational):
    s = _surface(2, rational)
    cad.write_cad(s, tmp_path / "s.iges")
    _check_same(s, iges_surfaces((tmp_path / "s.iges").read_text()), 1e-13)


def test_trimmed_patch_in_step_and_iges_keeps_its_surface_for_a_second_reader(tmp_path):
    s = _surface(3)
    th = np.linspace(0, 2 * np.pi, 40, endpoint=False)
    hole = TrimLoop(np.stack([0.5 + 0.2 * np.cos(th), 0.5 + 0.2 * np.sin(th)], 1), "hole")
    patch = TrimmedSurface(s, [hole])
    cad.write_cad(patch, tmp_path / "p.step")
    cad.write_cad(patch, tmp_path / "p.iges")
    _check_same(s, step_surfaces((tmp_path / "p.step").read_text()), 1e-13)
    iges = (tmp_path / "p.iges").read_text()
    _check_same(s, iges_surfaces(iges), 1e-13)
    assert len(iges_entities(iges, 144)) == 1  # one trimmed surface (IGES 144) over the 128

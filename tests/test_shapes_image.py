"""``revolve_image`` / ``nurbskit revolve-image``: profiles from rendered silhouettes.

Oracle: silhouettes rendered here from known radius functions ``r(y)`` by exact area
coverage (8 x 8 supersampling per pixel, so the edges are anti-aliased as a renderer's),
on a light or a dark background, upright or tilted; the recovered radius profile must
match ``r`` within 1 pixel (it does within a few hundredths).
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import torch

import nurbskit
from nurbskit.cli import main
from nurbskit.errors import InputError, OptionError
from nurbskit.shapes.image import revolve_image

H, W, CX, Y0, Y1 = 200, 160, 80.3, 20.0, 180.0


def render(radius, *, dark_background=False, tilt=0.0, cx=CX, ss=8) -> np.ndarray:
    """Grey image (H, W) in [0, 1]: the solid ``|x - cx| <= radius(y)``, ``Y0 <= y <= Y1``,
    turned by ``tilt`` degrees about (cx, 100); dark object on white unless ``dark_background``."""
    ys = (np.arange(H * ss) + 0.5) / ss
    xs = (np.arange(W * ss) + 0.5) / ss
    X, Y = np.meshgrid(xs, ys)
    if tilt:
        a = math.radians(tilt)
        dx, dy = X - cx, Y - 100.0
        X, Y = cx + math.cos(a) * dx + math.sin(a) * dy, 100.0 - math.sin(a) * dx + math.cos(a) * dy
    inside = (Y >= Y0) & (Y <= Y1) & (np.abs(X - cx) <= radius(Y))
    coverage = inside.reshape(H, ss, W, ss).mean((1, 3))
    return coverage if dark_background else 1.0 - coverage


def cylinder(y):
    return np.full_like(y, 25.0)


def vase(y):
    return 30.0 + 12.0 * np.sin((y - Y0) / 35.0)


def radius_error(res, radius) -> float:
    """Largest |r_fit(z) - r(z)| over heights inside the object (pixels)."""
    cur = res.profile.evaluate(torch.linspace(0, 1, 4000, dtype=torch.float64)).numpy()
    order = np.argsort(cur[:, 1])
    z = np.linspace(2.0, (Y1 - Y0) - 2.0, 80)
    r_fit = np.interp(z, cur[order, 1], cur[order, 0])
    return float(np.abs(r_fit - radius(Y1 - z)).max())


@pytest.mark.parametrize("radius", [cylinder, vase], ids=["cylinder", "vase"])
@pytest.mark.parametrize("dark_background", [False, True], ids=["light", "dark"])
def test_radius_profile_within_one_pixel(radius, dark_background):
    res = revolve_image(render(radius, dark_background=dark_background))
    assert res.background == ("dark" if dark_background else "light")
    assert radius_error(res, radius) < 1.0
    assert abs(res.axis["point"][0] - CX) < 0.1 and res.axis["direction"] == [0.0, -1.0]
    assert abs(res.axis["point"][1] - Y1) < 0.5  # the axis point is the object's bottom
    assert res.symmetry_residual < 0.2
    # the surface is the profile revolved: a sample's distance to the z axis is r(z)
    p = res.surface.evaluate(torch.rand(200, 2, dtype=torch.float64, generator=torch.Generator().manual_seed(0)))
    prof = res.profile.evaluate(torch.linspace(0, 1, 4000, dtype=torch.float64)).numpy()
    order = np.argsort(prof[:, 1])
    expect = np.interp(p[:, 2].numpy(), prof[order, 1], prof[order, 0])
    assert np.abs(p[:, :2].norm(dim=-1).numpy() - expect).max() < 1e-3


def test_tilted_object_with_principal_axis():
    img = render(vase, tilt=10.0)
    with pytest.raises(InputError, match="not mirror-symmetric.*principal"):
        revolve_image(img)  # a vertical mirror does not fit a tilted object
    res = revolve_image(img, axis="principal")
    assert abs(res.rotation - 10.0) < 0.2
    d = np.array(res.axis["direction"])
    assert math.degrees(math.acos(abs(d @ [math.sin(math.radians(10)), -math.cos(math.radians(10))]))) < 0.2
    # the axis passes through the centre of the turn, (CX, 100)
    rel = np.array([CX, 100.0]) - np.array(res.axis["point"])
    assert abs(rel[0] * d[1] - rel[1] * d[0]) < 0.5
    assert radius_error(res, vase) < 1.0


def test_pixel_size_scales_the_surface():
    img = render(cylinder)
    a, b = revolve_image(img), revolve_image(img, pixel_size=0.5)
    assert torch.equal(b.surface.control_points, a.surface.control_points * 0.5)


def test_blank_and_asymmetric_images_are_refused():
    with pytest.raises(InputError, match="blank"):
        revolve_image(np.full((50, 40), 0.7))
    # a right triangle: its row midpoints drift with the height
    yy, xx = np.mgrid[0:120, 0:100]
    tri = np.where((xx >= 20) & (xx <= 20 + (yy - 10) * 0.6) & (yy >= 10) & (yy < 110), 0.0, 1.0)
    with pytest.raises(InputError, match="not mirror-symmetric"):
        revolve_image(tri)
    with pytest.raises(OptionError, match="axis"):
        revolve_image(render(cylinder), axis="diagonal")


def test_python_api_is_exported():
    assert nurbskit.revolve_image is revolve_image


def test_cli_end_to_end(tmp_path, capsys):
    from PIL import Image

    src = tmp_path / "vase.png"
    Image.fromarray((render(vase) * 255).round().astype(np.uint8)).save(src)
    out = tmp_path / "out"
    assert main(["revolve-image", str(src), "--out", str(out)]) == 0
    assert sorted(p.name for p in out.iterdir()) == [".nurbskit-manifest.json", "report.json", "silhouette.png",
                                                      "surface.json", "surface.png"]
    rep = json.loads((out / "report.json").read_text())
    assert abs(rep["axis"]["point"][0] - CX) < 0.1 and rep["symmetry_residual_px"] < 0.2
    assert rep["background"] == "light" and rep["profile"]["coordinates"] == ["r", "z"]
    assert abs(rep["max_radius_px"] - 42.0) < 1.0
    surface = nurbskit.load(out / "surface.json")
    assert surface.degrees[0] == 2 and surface.sizes[0] == 9
    # an existing output is not overwritten; a blank image is a one-line error
    capsys.readouterr()
    blank = tmp_path / "blank.png"
    Image.fromarray(np.full((40, 40), 200, np.uint8)).save(blank)
    assert main(["revolve-image", str(blank), "--out", str(tmp_path / "o2")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "blank" in err and "blank.png" in err
    assert not (tmp_path / "o2").exists()
    assert main(["revolve-image", str(src), "--out", str(out)]) == 2


def test_a_line_and_a_faint_picture_are_named_as_such(tmp_path):
    line = np.full((200, 160), 255, np.uint8)
    line[20:180, 80] = 0
    with pytest.raises(InputError, match=r"the silhouette is [0-9.]+ px wide on average; at least 3 px"):
        revolve_image(line)
    faint = np.full((120, 100), 1200, np.uint16)
    faint[20:100, 30:70] = 1000
    with pytest.raises(InputError, match=r"the image has too little contrast \(grey values span 0\.0153\.\.0\.0183"):
        revolve_image(faint)

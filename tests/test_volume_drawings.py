"""Drawings: polarity detection, resampling, and clear errors for unusable images."""

import numpy as np
import pytest
import torch
from PIL import Image

from nurbskit.errors import InputError
from nurbskit.volume.drawings import load_drawing, mask_on_plane, resample
from nurbskit.volume.shapes import disc_drawing
from nurbskit.volume.views import FRONT, TOP


def save(tmp_path, name, array, mode="L"):
    path = tmp_path / name
    Image.fromarray(array, mode=mode).save(path)
    return path


def test_dark_on_light_and_light_on_dark_give_the_same_mask(tmp_path):
    mask = disc_drawing(40).numpy()
    ink = save(tmp_path, "ink.png", ((1 - mask) * 255).astype(np.uint8))
    chalk = save(tmp_path, "chalk.png", (mask * 200 + 20).astype(np.uint8))
    a, b = load_drawing(ink), load_drawing(chalk)
    assert torch.equal(a, torch.from_numpy(mask))
    assert torch.equal(b, torch.from_numpy(mask))


def test_jpeg_and_rgba_are_read(tmp_path):
    mask = disc_drawing(64).numpy()
    rgb = np.repeat(((1 - mask) * 255).astype(np.uint8)[..., None], 3, axis=2)
    jpg = tmp_path / "d.jpg"
    Image.fromarray(rgb).save(jpg, quality=90)
    got = load_drawing(jpg).numpy()
    assert (got != mask).mean() < 0.01  # JPEG ringing moves a few edge pixels at most
    # a shape painted opaque on a transparent layer: transparency is white paper
    rgba = np.zeros((64, 64, 4), np.uint8)
    rgba[..., 3] = (mask * 255).astype(np.uint8)
    png = save(tmp_path, "layer.png", rgba, mode="RGBA")
    assert torch.equal(load_drawing(png), torch.from_numpy(mask))


def test_arrays_are_masks_as_given():
    m = np.zeros((5, 7))
    m[1:3, 2:5] = 1
    out = load_drawing(m)
    assert out.dtype == torch.float32 and torch.equal(out, torch.from_numpy(m).float())


@pytest.mark.parametrize(
    "array, message",
    [
        (np.full((20, 20), 255, np.uint8), "empty"),
        (np.zeros((20, 20), np.uint8), "all filled"),
    ],
)
def test_blank_and_filled_images_are_rejected(tmp_path, array, message):
    path = save(tmp_path, "x.png", array)
    with pytest.raises(InputError, match=message) as info:
        load_drawing(path, name="front")
    assert "front drawing" in str(info.value) and str(path) in str(info.value)


def test_unreadable_and_missing_files_are_rejected(tmp_path):
    bad = tmp_path / "notes.png"
    bad.write_text("not an image")
    with pytest.raises(InputError, match="cannot be read as an image"):
        load_drawing(bad, name="left")
    with pytest.raises(InputError, match="no such file"):
        load_drawing(tmp_path / "missing.png")
    with pytest.raises(InputError, match="found a directory"):
        load_drawing(tmp_path)


def test_bad_arrays_are_rejected():
    with pytest.raises(InputError, match=r"expected a mask array \(H, W\)"):
        load_drawing(np.zeros((3, 4, 3)))
    with pytest.raises(InputError, match=r"lie in \[0, 1\]"):
        load_drawing(np.full((4, 4), 2.0))
    with pytest.raises(InputError, match="mask is empty"):
        load_drawing(np.zeros((4, 4)))
    with pytest.raises(InputError, match="all filled"):
        load_drawing(np.ones((4, 4)))


def test_resample_keeps_corner_pixels_on_the_cube_edges():
    image = torch.zeros(9, 9)
    image[0, 8] = 1.0  # top-right pixel: front view x = 1, y = 1
    out = resample(image, 5, 5)
    assert out[0, 4] > 0 and out[4, 0] == 0
    plane = mask_on_plane(image, FRONT, (5, 5, 5))
    assert plane[4, 4] == out[0, 4]  # plane[i_x, i_y]


def test_downsampling_agrees_with_drawing_at_the_small_size():
    # the same disc rendered directly on the 40 x 40 pixel centres is the oracle
    small = resample(disc_drawing(400), 40, 40)
    direct = disc_drawing(40)
    assert abs(float(small.mean()) - float(direct.mean())) < 0.005
    assert float(((small >= 0.5).float() - direct).abs().mean()) < 0.02
    # and a non-square drawing is stretched onto the unit square
    wide = torch.zeros(10, 30)
    wide[:, 15:] = 1  # right half: x >= 0.5
    plane = mask_on_plane(wide, TOP, (11, 11, 11))  # plane[i_x, i_z]
    assert plane[:4].max() == 0 and plane[7:].min() > 0.999

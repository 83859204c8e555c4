"""Grey levels of drawings (``nurbskit.io.image``): what a pixel value means, for every reader."""

import numpy as np
import pytest
from PIL import Image

from nurbskit.curves.api import read_image
from nurbskit.errors import InputError
from nurbskit.io.image import pil_grey, to_grey
from nurbskit.volume.drawings import load_drawing
from nurbskit.volume.shapes import disc_drawing


def _scan(paper: int, ink: int, dtype) -> np.ndarray:
    """A 12-bit scan's values: paper and one dark stroke, in an array of ``dtype``."""
    a = np.full((64, 64), paper, dtype)
    a[30:33, 5:60] = ink
    return a


@pytest.mark.parametrize("dtype, name", [(np.uint16, "scan.png"), (np.int32, "scan.tif")])
def test_deep_images_keep_their_depth(tmp_path, dtype, name):
    # Pillow's convert("L") clips 500 and 3,500 to 255 alike: the drawing would be blank.
    values = _scan(3500, 500, dtype)
    path = tmp_path / name
    Image.fromarray(values).save(path)
    with Image.open(path) as im:
        assert im.mode == ("I;16" if dtype == np.uint16 else "I")
    np.testing.assert_allclose(read_image(path), values / 65535.0, rtol=0, atol=1e-15)


def test_float_images_are_read_as_they_are(tmp_path):
    values = _scan(1, 0, np.float32) * np.float32(0.8) + np.float32(0.1)
    path = tmp_path / "scan.tif"
    Image.fromarray(values).save(path)
    np.testing.assert_allclose(read_image(path), values.astype(np.float64), rtol=0, atol=0)
    stretched = tmp_path / "hdr.tif"  # outside [0, 1]: stretched from its minimum to its maximum
    Image.fromarray(values * np.float32(1000)).save(stretched)
    np.testing.assert_allclose(read_image(stretched), _scan(1, 0, np.float64), rtol=0, atol=1e-6)


def test_eight_bit_and_transparent_images_read_as_before(tmp_path):
    grey = _scan(230, 20, np.uint8)
    Image.fromarray(grey).save(tmp_path / "g.png")
    np.testing.assert_array_equal(read_image(tmp_path / "g.png"), grey / 255.0)
    rgba = np.zeros((64, 64, 4), np.uint8)
    rgba[30:33, 5:60, 3] = 255  # black ink on a transparent layer: the layer is paper
    Image.fromarray(rgba).save(tmp_path / "layer.png")
    np.testing.assert_array_equal(read_image(tmp_path / "layer.png"), 1.0 - rgba[..., 3] / 255.0)


@pytest.mark.parametrize("values, white", [
    (np.array([[0, 1], [1, 0]], np.int64), 1.0),  # a mask
    (np.array([[0, 255], [17, 0]], np.int64), 255.0),  # 8-bit values in a wide type
    (np.array([[0, 4095], [17, 0]], np.int32), 65535.0),
    (np.array([[0, 300], [17, 0]], np.uint16), 65535.0),  # the type's own range
])
def test_integer_arrays_are_full_scale_for_the_range_they_fit(values, white):
    np.testing.assert_array_equal(to_grey(values), values / white)


def test_integer_arrays_outside_sixteen_bits_are_stretched():
    values = np.array([[-5, 95], [45, -5]], np.int64)
    np.testing.assert_allclose(to_grey(values), (values + 5) / 100.0, rtol=0, atol=1e-15)


def test_big_endian_sixteen_bit_images_are_read_in_native_order():
    values = _scan(3500, 500, np.uint16)
    im = Image.frombytes("I;16B", values.shape[::-1], values.astype(">u2").tobytes())
    np.testing.assert_array_equal(pil_grey(im), values / 65535.0)


def test_a_sixteen_bit_drawing_gives_the_eight_bit_drawings_mask(tmp_path):
    mask = disc_drawing(40).numpy()
    eight = tmp_path / "d8.png"
    Image.fromarray(((1 - mask) * 200 + 20).astype(np.uint8)).save(eight)
    sixteen = tmp_path / "d16.png"  # the same drawing from a 16-bit scanner, paper above 255
    Image.fromarray(((1 - mask) * 52000 + 5000).astype(np.uint16)).save(sixteen)
    np.testing.assert_array_equal(load_drawing(sixteen).numpy(), load_drawing(eight).numpy())
    np.testing.assert_array_equal(load_drawing(sixteen).numpy(), mask)


def test_non_finite_float_images_are_refused(tmp_path):
    values = _scan(1, 0, np.float32)
    values[0, 0] = np.nan
    Image.fromarray(values).save(tmp_path / "nan.tif")
    with pytest.raises(InputError, match="nan.tif: the image holds non-finite values"):
        read_image(tmp_path / "nan.tif")


@pytest.mark.parametrize("orientation, turn", [(1, 0), (3, 2), (6, -1), (8, 1)])
def test_photographs_are_read_upright(tmp_path, orientation, turn):
    stored = np.zeros((20, 30), np.uint8)
    stored[2:5, 3:12] = 255  # a mark near the stored image's top-left corner
    exif = Image.Exif()
    exif[0x0112] = orientation  # EXIF Orientation: how a viewer turns the stored pixels
    path = tmp_path / "photo.png"
    Image.fromarray(stored).save(path, exif=exif)
    np.testing.assert_array_equal(read_image(path), np.rot90(stored, turn) / 255.0)


def test_a_light_shape_on_a_transparent_ground_is_read_from_its_alpha(tmp_path):
    # white paint on a transparent sheet: composited on white it vanishes; its alpha is the drawing
    rgba = np.zeros((40, 50, 4), np.uint8)
    rgba[..., :3] = 255
    rgba[10:30, 15:35, 3] = 255
    Image.fromarray(rgba, "RGBA").save(tmp_path / "white.png")
    with Image.open(tmp_path / "white.png") as image:
        grey = pil_grey(image)
    expected = np.ones((40, 50))
    expected[10:30, 15:35] = 0.0
    np.testing.assert_array_equal(grey, expected)
    # a dark shape on a transparent ground still composites as before
    rgba[..., :3] = 0
    np.testing.assert_array_equal(to_grey(rgba), expected)

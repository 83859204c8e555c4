"""Drawings in: files or arrays -> shape masks, and masks resampled onto the grid.

A *mask* is a float tensor ``(H, W)`` with 1 inside the drawn shape and 0 outside
(values between 0 and 1 are allowed: anti-aliased edges). Files (PNG, JPEG, anything
Pillow reads) may be a dark shape on a light background or the reverse: the
background is the side of the threshold (Otsu's) that most border pixels fall on.
Arrays and tensors are taken as masks as given.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import TYPE_CHECKING, Union

import numpy as np
import torch
import torch.nn.functional as F

from ..errors import InputError
from .views import View, image_to_plane

Tensor = torch.Tensor
if TYPE_CHECKING:
    from PIL.Image import Image as PILImage

DrawingLike = Union[str, os.PathLike, np.ndarray, Tensor, "PILImage"]

#: Gray-level spread (0..1) below which an image counts as having no shape at all.
MIN_CONTRAST = 0.05
#: Largest side a drawing keeps when loaded; larger ones are area-averaged down first.
MAX_SIDE = 1024


def max_pixels() -> int:
    """The largest drawing, in pixels: Pillow's decompression-bomb limit (``Image.MAX_IMAGE_PIXELS``)."""
    from PIL import Image

    return int(Image.MAX_IMAGE_PIXELS or 89_478_485)


def check_pixels(size: tuple[int, int], label: str) -> None:
    """Refuse an image of ``size (width, height)`` beyond :func:`max_pixels`, before it is decoded.

    A small file can declare a huge image (a decompression bomb); decoding it would take
    gigabytes. The check also covers the memory the decoded image needs.
    """
    from .._budget import require_memory

    width, height = size
    pixels = int(width) * int(height)
    if pixels > max_pixels():
        raise InputError(
            f"{label}: the image declares {width} x {height} = {pixels:,} pixels, more than the "
            f"{max_pixels():,} allowed (Pillow's decompression-bomb limit); scale it down"
        )
    # RGBA decoding, the gray levels (float64) and the mask (float32).
    require_memory(pixels * 16, f"{label} ({width} x {height} pixels)", "scale the image down")


def _gray_from_pil(image, source: str) -> np.ndarray:
    """Gray levels in [0, 1] of a Pillow image (:func:`nurbskit.io.image.pil_grey`:
    transparent pixels are white paper, 16-bit scans keep their depth)."""
    from ..io.image import pil_grey

    gray = pil_grey(image, source)
    if gray.ndim != 2 or min(gray.shape) < 2:
        raise InputError(f"{source}: expected a 2-D image at least 2 x 2 pixels, got shape {gray.shape}")
    return gray


def mask_from_gray(gray: np.ndarray, source: str = "drawing") -> np.ndarray:
    """Binary shape mask ``(H, W)`` (float 0/1) of a gray image in [0, 1], polarity detected.

    Raises InputError for a blank image (no shape) and for one whose shape fills every
    pixel, naming ``source``.
    """
    lo, hi = float(gray.min()), float(gray.max())
    if hi - lo < MIN_CONTRAST:
        if lo > 0.5:
            raise InputError(f"{source}: the drawing is empty (a uniform light image, no shape found)")
        raise InputError(f"{source}: the drawing is all filled (a uniform dark image, no background found)")
    from skimage.filters import threshold_otsu

    dark = gray <= threshold_otsu(gray)  # as the curves and shapes readers threshold
    border = np.concatenate([dark[0], dark[-1], dark[1:-1, 0], dark[1:-1, -1]])
    # The background is what most of the border shows; the shape is the other side.
    shape = ~dark if border.mean() > 0.5 else dark
    filled = float(shape.mean())
    if filled == 0.0:
        raise InputError(f"{source}: the drawing is empty (no shape pixels after thresholding)")
    if filled == 1.0:
        raise InputError(f"{source}: the drawing is all filled (no background pixels after thresholding)")
    return shape.astype(np.float32)


def _shrink(mask: np.ndarray) -> np.ndarray:
    """Area-average a large mask down so that its longer side is at most MAX_SIDE."""
    h, w = mask.shape
    factor = int(np.ceil(max(h, w) / MAX_SIDE))
    if factor <= 1:
        return mask
    t = torch.from_numpy(np.ascontiguousarray(mask, dtype=np.float32))[None, None]
    return F.avg_pool2d(t, factor, ceil_mode=True)[0, 0].numpy()


def load_drawing(source: DrawingLike, *, name: str = "drawing") -> Tensor:
    """A drawing as a float mask ``(H, W)`` (1 = shape), from a file, image or array.

    Files and Pillow images are thresholded (Otsu) with the polarity detected from the
    border; arrays/tensors ``(H, W)`` are masks already (bool or values in [0, 1]).
    Images larger than :data:`MAX_SIDE` are area-averaged down.

    Example:
        >>> import numpy as np
        >>> m = np.zeros((5, 5)); m[1:4, 1:4] = 1
        >>> load_drawing(m).shape
        torch.Size([5, 5])
    """
    if isinstance(source, (str, os.PathLike)):
        from PIL import Image, UnidentifiedImageError

        path = Path(source)
        label = f"{name} drawing {path}"
        if not path.exists():
            raise InputError(f"{label}: no such file")
        if path.is_dir():
            raise InputError(f"{label}: expected an image file, found a directory")
        try:
            with Image.open(path) as image:  # reads the header only
                check_pixels(image.size, label)
                image.load()
                gray = _gray_from_pil(image, label)
        except Image.DecompressionBombError:
            raise InputError(f"{label}: the image declares more than {2 * max_pixels():,} pixels (Pillow's limit)") from None
        except (UnidentifiedImageError, OSError, SyntaxError) as exc:
            raise InputError(f"{label}: cannot be read as an image (PNG or JPEG expected): {exc}") from None
        return torch.from_numpy(_shrink(mask_from_gray(gray, label)))
    if hasattr(source, "mode") and hasattr(source, "convert"):  # a Pillow image
        label = f"{name} drawing"
        return torch.from_numpy(_shrink(mask_from_gray(_gray_from_pil(source, label), label)))
    label = f"{name} drawing"
    if isinstance(source, Tensor):
        arr = source.detach().cpu().numpy()
    else:
        arr = np.asarray(source)
    if arr.ndim != 2 or min(arr.shape) < 2:
        raise InputError(f"{label}: expected a mask array (H, W) with H, W >= 2, got shape {arr.shape}")
    arr = arr.astype(np.float32)
    if not np.isfinite(arr).all() or arr.min() < 0 or arr.max() > 1:
        raise InputError(f"{label}: mask values must lie in [0, 1] (1 = shape), got [{arr.min()}, {arr.max()}]")
    if arr.max() < 0.5:
        raise InputError(f"{label}: the mask is empty (no value reaches 0.5)")
    if arr.min() >= 0.5:
        raise InputError(f"{label}: the mask is all filled (no value below 0.5)")
    return torch.from_numpy(_shrink(arr))


def resample(mask: Tensor, height: int, width: int) -> Tensor:
    """Resample a mask ``(H, W)`` to ``(height, width)`` keeping the pixel-centre convention.

    Corner pixels stay on the cube's edges (``align_corners=True``); shrinking is
    anti-aliased so a 1000-pixel drawing on a 20-point grid keeps its area.
    """
    if tuple(mask.shape) == (height, width):
        return mask
    t = mask[None, None].float()
    shrinking = height < mask.shape[0] or width < mask.shape[1]
    out = F.interpolate(t, size=(height, width), mode="bilinear", align_corners=True, antialias=shrinking)
    return out[0, 0].clamp(0, 1).to(mask.dtype)


def mask_on_plane(mask: Tensor, view: View, sizes: tuple[int, int, int]) -> Tensor:
    """A drawing resampled onto the grid plane of its view, ``(N_a, N_b)`` over ``view.plane_axes``.

    ``sizes`` is the grid ``(N_x, N_y, N_z)``; the image is resampled to
    ``(N_row_axis, N_column_axis)`` and re-indexed by :func:`views.image_to_plane`.
    """
    image = resample(mask, sizes[view.row_axis], sizes[view.column_axis])
    return image_to_plane(image, view)

"""Grey levels of drawings: arrays and Pillow images -> ``(H, W)`` float64 in [0, 1].

The one place that decides what a pixel value means, for every pipeline that reads a
drawing (``nurbskit curves``, ``nurbskit shapes`` from a silhouette, ``nurbskit volume``
from three drawings); each pipeline opens its files itself, with its own memory check.

- 8-bit images (Pillow's ``L``, ``RGB``, ``P``, ``1``, ``CMYK``, ...) and ``uint8`` /
  ``uint16`` arrays are full scale: 0 black, the type's maximum white.
- Deeper images keep their depth. Pillow's ``convert("L")`` clips a 16-bit scan's values
  to 0..255 (a drawing whose paper is at 3,500 of 65,535 becomes all white), so 16-bit
  (``I;16*``) images are read as ``uint16``; 32-bit integer (``I``) and other integer
  arrays are full scale for the smallest of 0..1, 0..255 and 0..65,535 that holds their
  values, and stretched from their minimum to their maximum otherwise; float images (``F``) and arrays are taken
  as they are when they lie in [0, 1] and stretched otherwise.
- Photographs are turned upright by their EXIF orientation, as every viewer shows them,
  so that pixel coordinates are those of the image the user sees.
- Transparent pixels are paper: colour is composited onto white by its alpha, then
  weighted to luma (ITU-R 601: 0.299 R + 0.587 G + 0.114 B, Pillow's ``L``). When that
  leaves no contrast but the alpha does (a white shape on a transparent ground), the
  alpha is the drawing: opaque is ink.
"""

from __future__ import annotations

import numpy as np

from ..errors import InputError

_LUMA = np.array([0.299, 0.587, 0.114])


def to_grey(image, source: str = "image") -> np.ndarray:
    """``(H, W)`` or ``(H, W, 3|4)`` array (any numeric dtype) -> ``(H, W)`` float64 in [0, 1].

    Raises InputError (naming ``source``) for a non-numeric, empty, non-finite or
    wrongly shaped array.
    """
    a = np.asarray(image)
    if a.dtype == bool:
        a = a.astype(np.float64)
    if not np.issubdtype(a.dtype, np.number):
        raise InputError(f"{source}: expected a numeric image array, got dtype {a.dtype}")
    white = _full_scale(a)  # None: a float array, or integers stretched below
    if a.ndim == 3 and a.shape[-1] in (3, 4):
        rgb = a[..., :3].astype(np.float64)
        if a.shape[-1] == 4:  # composite onto white: transparent means background
            alpha = a[..., 3].astype(np.float64)
            alpha = alpha / (alpha.max() if alpha.max() > 1 else 1.0)
            grey = (rgb * alpha[..., None] + (white or 1.0) * (1 - alpha[..., None])) @ _LUMA
            if np.ptp(grey) < MIN_CONTRAST * (white or 1.0) and np.ptp(alpha) >= 0.5:
                # a light shape on a transparent ground vanishes on white: its alpha is the drawing
                grey = (1 - alpha) * (white or 1.0)
            a = grey
        else:
            a = rgb @ _LUMA
    if a.ndim != 2:
        raise InputError(f"{source}: expected an (H, W) grey or (H, W, 3|4) colour image, got shape {a.shape}")
    if a.size == 0:
        raise InputError(f"{source}: the image is empty (shape {a.shape})")
    a = a.astype(np.float64)
    if not np.isfinite(a).all():
        raise InputError(f"{source}: the image holds non-finite values")
    if white:
        return a / white
    if a.max() > 1.0 or a.min() < 0.0:
        lo, hi = a.min(), a.max()
        a = (a - lo) / (hi - lo) if hi > lo else np.zeros_like(a)
    return a


#: The least grey-level range (of full scale) an image needs to hold a drawing.
MIN_CONTRAST = 1.0 / 64


def check_contrast(grey: np.ndarray, source: str, expected: str) -> None:
    """An InputError naming ``source`` when ``grey`` (in [0, 1]) spans less than
    :data:`MIN_CONTRAST`: blank when it holds one value, of too little contrast otherwise;
    ``expected`` says what the pipeline looks for."""
    lo, hi = float(grey.min()), float(grey.max())
    if hi - lo >= MIN_CONTRAST:
        return
    what = "is blank" if hi == lo else "has too little contrast"
    raise InputError(f"{source}: the image {what} (grey values span {lo:.3g}..{hi:.3g} of 0..1, "
                     f"at least {MIN_CONTRAST:.3g} needed), expected {expected}")


def _full_scale(a: np.ndarray) -> float | None:
    """The value of white for an integer array: the type's maximum for ``uint8`` and
    ``uint16``; for other integer types the smallest of 1 (a mask), 255 and 65,535 that
    holds the values. None for floats and for integers outside 0..65,535 (stretched from
    their minimum to their maximum)."""
    if not np.issubdtype(a.dtype, np.integer) or a.size == 0:
        return None
    if a.dtype in (np.uint8, np.uint16):
        return float(np.iinfo(a.dtype).max)
    if int(a.min()) < 0:
        return None
    hi = int(a.max())
    return next((float(top) for top in (1, 255, 65535) if hi <= top), None)


def pil_grey(image, source: str = "image") -> np.ndarray:
    """A loaded Pillow image -> ``(H, W)`` float64 grey in [0, 1] (see the module's rules),
    turned upright as its EXIF orientation says (a phone's photograph of a drawing is
    stored as the sensor saw it; viewers, and so the user, see it turned)."""
    from PIL import ImageOps

    if image.getexif().get(0x0112, 1) != 1:  # EXIF Orientation; no copy of an upright image
        image = ImageOps.exif_transpose(image)
    if image.mode in ("RGBA", "LA", "PA") or (image.mode == "P" and "transparency" in image.info):
        array = np.asarray(image.convert("RGBA"))
    elif image.mode.startswith(("I", "F")):  # 16- and 32-bit integers, 32-bit floats
        array = np.asarray(image)
        array = array.astype(array.dtype.newbyteorder("="))  # native order, whatever the file's
    else:
        array = np.asarray(image.convert("L"))
    return to_grey(array, source)

"""``nurbskit.curves_from_image``: B-spline curves from a drawing, and reading images.

Convention: pixel coordinates, x to the right, y down, the origin at the top-left corner
of the top-left pixel (the centre of pixel ``[row, col]`` is ``(col + 0.5, row + 0.5)``).
"""

from __future__ import annotations

import os
import warnings
from pathlib import Path

import numpy as np

from ..errors import InputError, OptionError

METHODS = ("classic", "network")
COORDINATES = ("pixels: x to the right, y down, origin at the top-left corner of the top-left pixel; "
               "the centre of pixel [row, col] is (col + 0.5, row + 0.5)")


def read_image(path: str | os.PathLike) -> np.ndarray:
    """An image file -> ``(H, W)`` float64 grey in [0, 1] (PIL; its decompression-bomb limit applies).

    Raises InputError (one line naming the file) for a missing, unreadable, empty or
    oversized image.
    """
    from PIL import Image, UnidentifiedImageError

    from .classic import to_grey

    path = Path(path)
    if not path.exists():
        raise InputError(f"{path}: no such file")
    if path.is_dir():
        raise InputError(f"{path}: is a directory, expected an image file (PNG, JPEG, ...)")
    if path.stat().st_size == 0:
        raise InputError(f"{path}: the file is empty, expected an image (PNG, JPEG, ...)")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error", Image.DecompressionBombWarning)
            with Image.open(path) as im:
                im.load()
                if im.width == 0 or im.height == 0:
                    raise InputError(f"{path}: the image is empty ({im.width} x {im.height} pixels)")
                if im.mode in ("RGBA", "LA", "PA") or (im.mode == "P" and "transparency" in im.info):
                    array = np.asarray(im.convert("RGBA"))
                else:
                    array = np.asarray(im.convert("L"))
    except (Image.DecompressionBombError, Image.DecompressionBombWarning) as exc:
        raise InputError(f"{path}: the image is too large to read safely ({exc})") from None
    except UnidentifiedImageError:
        raise InputError(f"{path}: not a readable image (expected PNG, JPEG, BMP, TIFF, ...)") from None
    except (OSError, ValueError, SyntaxError) as exc:
        raise InputError(f"{path}: not a readable image ({exc})") from None
    return to_grey(array, str(path))


def curves_from_image(image, method: str = "classic", tolerance: float = 1.0, refine: bool = False,
                      refine_iterations: int = 20) -> list:
    """B-spline curves drawn in ``image``, in pixel coordinates (see the module's convention).

    Args:
        image: a path to an image file, or an ``(H, W)`` grey / ``(H, W, 3|4)`` colour array.
            Dark on light and light on dark are both detected.
        method: ``"classic"`` (skeleton, strokes, least squares; see
            :mod:`nurbskit.curves.classic`). ``"network"`` is not shipped yet.
        tolerance: largest distance in pixels from a stroke's skeleton to its curve.
        refine: refine the control points by Chamfer against the ink pixels (L-BFGS).

    Returns:
        A list of :class:`~nurbskit.NURBSCurve` (float64, 2D), one per stroke.

    Example:
        >>> import numpy as np, nurbskit
        >>> img = np.ones((40, 60)); img[19:22, 5:55] = 0       # a horizontal line, centre y = 20.5
        >>> [c] = nurbskit.curves_from_image(img)
        >>> c.control_points[:, 1].sub(20.5).abs().max().item() < 1, c.control_points[0, 0].item() < 10
        (True, True)
    """
    from .classic import fit_image

    if method not in METHODS:
        raise OptionError(f"method: expected one of {', '.join(METHODS)}, got {method!r}")
    if method == "network":
        raise OptionError("method 'network': the trained curve models are not shipped yet; use method='classic'")
    source = "image"
    if isinstance(image, (str, os.PathLike)):
        source = str(image)
        image = read_image(image)
    curves, _ = fit_image(image, tolerance=tolerance, refine_iterations=refine_iterations if refine else 0,
                          source=source)
    return curves

"""A surface of revolution from the silhouette of a turned object in an image.

DeepSpline (section 5) reads the profile of a turned object off a photograph with a CNN;
the geometric path here reads it off the silhouette directly:

1. **Silhouette**: the image in grey (:func:`nurbskit.curves.api.read_image`), Otsu's
   threshold (scikit-image); the background is the class that holds most of the image's
   border (so a dark object on a light background and a light one on a dark background
   both work), the object the largest connected component of the other class, its holes
   filled (scipy.ndimage).
2. **Edges, sub-pixel**: on each pixel row the object spans, the leftmost and rightmost
   edges placed by area: an anti-aliased edge pixel's grey mixes the object's and the
   background's (median) greys in proportion to its coverage, so the sum of background
   fractions over a few pixels across the edge is its distance from the window's end.
3. **Axis**: ``axis="vertical"``: the vertical line that best mirrors the silhouette,
   ``x = c`` minimising ``sum_rows (x_left + x_right - 2 c)^2``, i.e. the mean of the
   row midpoints; ``axis="principal"``: the image is first turned (scikit-image
   ``rotate``, bilinear) so that the mask's principal axis (second moments) is vertical.
   The **symmetry residual** is the RMS distance of the row midpoints from the axis
   (pixels); above ``symmetry_tolerance`` (pixels, or that fraction of the mean width when
   below 1) the image is refused as not mirror-symmetric.
4. **Profile**: the half-widths ``r = (x_right - x_left) / 2`` against the height ``z``
   (pixels, upwards from the lowest row), fitted by the shapes' least-squares B-spline
   (:func:`nurbskit.shapes.profile.fit_profile`: ordering, quantile knots, parameter
   correction, the number of control points by the information criterion).
5. **Surface**: :func:`nurbskit.core.construct.revolve` of the profile placed in the
   ``(x, z)`` plane, about the ``z`` axis, in pixel units times ``pixel_size``.

Convention: image coordinates are pixels, x to the right, y down, the origin at the
top-left corner of the top-left pixel (pixel ``[row, col]`` has its centre at
``(col + 0.5, row + 0.5)``), as :mod:`nurbskit.curves`. The 3-D surface: axis ``+z``
through the origin, ``z = 0`` at the bottom of the silhouette, ``x`` the image's right.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import torch

from ..core.construct import revolve
from ..core.curve import NURBSCurve
from ..core.surface import NURBSSurface
from ..errors import InputError, OptionError

__all__ = ["ImageRevolution", "revolve_image", "silhouette", "PIXEL_SIZE_RANGE"]

AXES = ("vertical", "principal")
MIN_ROWS = 8
#: The least mean width (pixels) of a silhouette to read a profile from.
MIN_WIDTH = 3
PIXEL_SIZE_RANGE = (1e-50, 1e50)
"""Accepted ``pixel_size``: any image Pillow opens is under 1e9 pixels a side, so every length of
the result (sub-pixel edges to the diagonal) and its fourth power (a surface normal's squared
norm, in shading and export) stay finite, normal float64 numbers: no overflow, no subnormal
collapse of the profile."""


@dataclass
class ImageRevolution:
    """The result of :func:`revolve_image`.

    ``surface``: the exact NURBS; ``profile``: the (r, z) curve in pixels, ``(n, 2)``
    control points; ``axis``: in image coordinates ``{"point": [x, y], "direction": [dx,
    dy]}`` (unit, pointing up the object: ``dy < 0``); ``rows``: ``(R, 3)`` per row
    ``(y, x_left, x_right)`` of the (turned, for ``principal``) image; ``points``:
    ``(R, 2)`` the (r, z) pairs fitted; ``symmetry_residual``: RMS of the midpoints'
    distance to the axis (pixels), ``symmetry_max`` the largest; ``profile_residual``:
    mean distance of the (r, z) pairs to the profile (pixels); ``background``: 'light'
    or 'dark'; ``rotation``: degrees the image was turned (``principal``); ``mask``: the
    silhouette ``(H, W)`` bool of the (turned) image; ``grey``: that image; ``levels``:
    the object's and the background's grey; ``ignored_objects``: the sizes in pixels of the
    other objects in the image (each large enough to read a profile from), largest first: only
    the largest object is revolved.
    """

    surface: NURBSSurface
    profile: NURBSCurve
    axis: dict
    rows: np.ndarray
    points: np.ndarray
    symmetry_residual: float
    symmetry_max: float
    profile_residual: float
    background: str
    levels: tuple
    rotation: float
    pixel_size: float
    mask: np.ndarray
    grey: np.ndarray
    axis_x: float
    z_origin: float
    ignored_objects: list = field(default_factory=list)


def silhouette(grey: np.ndarray, source: str = "image") -> tuple[np.ndarray, float, str]:
    """``(mask (H, W) bool, (object grey, background grey), background)`` of a grey image
    in [0, 1] (step 1); the greys are the two classes' medians."""
    return _silhouette(grey, source)[:3]


def _silhouette(grey: np.ndarray, source: str) -> tuple[np.ndarray, tuple, str, list[int]]:
    """:func:`silhouette` and the sizes (pixels, largest first) of the other objects it left
    out: components large enough to read a profile from (``4 * MIN_ROWS`` pixels), not specks."""
    from scipy import ndimage
    from skimage.filters import threshold_otsu
    from skimage.measure import label

    from ..io.image import check_contrast

    check_contrast(grey, source, "the silhouette of an object on a light or dark background")
    t = float(threshold_otsu(grey))
    dark = grey <= t
    border = np.concatenate([dark[0], dark[-1], dark[:, 0], dark[:, -1]])
    background = "dark" if border.mean() > 0.5 else "light"
    fg = ~dark if background == "dark" else dark
    labels = label(fg, connectivity=2)
    if labels.max() == 0:
        raise InputError(f"{source}: no object found after thresholding (the whole image is background)")
    counts = np.bincount(labels.reshape(-1))
    counts[0] = 0
    largest = int(counts.argmax())
    mask = ndimage.binary_fill_holes(labels == largest)
    if mask.sum() < 4 * MIN_ROWS:
        raise InputError(f"{source}: the object is too small ({int(mask.sum())} pixels) to read a profile from")
    # other objects (not inside the filled silhouette, as a hole's contents are)
    inside = np.unique(labels[mask])
    others = counts.copy()
    others[inside] = 0
    ignored = sorted((int(c) for c in others if c >= 4 * MIN_ROWS), reverse=True)
    # the two greys an anti-aliased edge pixel mixes in proportion to its coverage
    levels = (float(np.median(grey[mask])), float(np.median(grey[~fg])))
    return mask, levels, background, ignored


def _edges(grey: np.ndarray, mask: np.ndarray, levels: tuple[float, float], window: int = 2) -> np.ndarray:
    """Per row of the mask: ``(y_centre, x_left, x_right)``, sub-pixel (step 2).

    ``levels``: the object's and the background's grey. Each edge is placed by area:
    over ``window`` pixels on each side of the first (last) object pixel, the sum of the
    pixels' background fractions ``(g - g_object) / (g_background - g_object)`` (clipped to
    [0, 1]) is the distance from the window's outer end to the edge; exact for an edge
    anti-aliased by area coverage, and the centre of the blur for a soft edge.
    """
    g_obj, g_bg = levels
    frac = np.clip((grey - g_obj) / (g_bg - g_obj), 0.0, 1.0)
    H, W = grey.shape
    rows = []
    for i in np.flatnonzero(mask.any(1)):
        cols = np.flatnonzero(mask[i])
        a, b = int(cols[0]), int(cols[-1])
        lo, hi = max(a - window, 0), min(a + window, W)  # pixels lo .. hi - 1
        left = lo + float(frac[i, lo:hi].sum())
        lo, hi = max(b - window + 1, 0), min(b + window + 1, W)
        right = hi - float(frac[i, lo:hi].sum())
        rows.append((i + 0.5, left, right))
    return np.asarray(rows, dtype=np.float64).reshape(-1, 3)


def _principal_angle(mask: np.ndarray) -> float:
    """Degrees to turn the image (counter-clockwise, scikit-image's ``rotate``) so that the
    mask's principal axis becomes vertical."""
    y, x = np.nonzero(mask)
    x = x - x.mean()
    y = y - y.mean()
    cov = np.cov(np.stack([x, y]))
    vals, vecs = np.linalg.eigh(cov)
    vx, vy = vecs[:, 1]  # the long axis
    # angle of the long axis from the image's vertical, in the image's (x right, y down) frame
    ang = math.degrees(math.atan2(vx, vy))
    if ang > 90:
        ang -= 180
    if ang < -90:
        ang += 180
    return -ang


def revolve_image(image, *, axis: str = "vertical", symmetry_tolerance: float = 0.02, pixel_size: float = 1.0,
                  degree: int = 3, source: str | None = None) -> ImageRevolution:
    """Revolve the profile of the turned object whose silhouette ``image`` shows (module docstring).

    Args:
        image: a path, or an ``(H, W)`` / ``(H, W, 3|4)`` array (grey or colour; alpha
            composited on white).
        axis: 'vertical' (the best mirror line among vertical lines) or 'principal'
            (turn the image so the silhouette's principal axis is vertical first).
        symmetry_tolerance: the largest accepted RMS symmetry residual: pixels when
            >= 1, else that fraction of the silhouette's mean width.
        pixel_size: the length of one pixel in the surface's units.
        degree: the profile's degree.

    Returns:
        :class:`ImageRevolution`.

    Example:
        >>> import numpy as np
        >>> img = np.ones((60, 50)); img[10:50, 15:35] = 0.0      # a dark 20 px wide cylinder
        >>> res = revolve_image(img)
        >>> round(res.axis["point"][0], 6), round(float(res.points[:, 0].mean()), 6)
        (25.0, 10.0)
    """
    from ..curves.api import read_image
    from ..io.image import to_grey
    from .profile import fit_profile

    if axis not in AXES:
        raise OptionError(f"axis must be one of {', '.join(AXES)}, got {axis!r}")
    if not (symmetry_tolerance > 0 and math.isfinite(symmetry_tolerance)):
        raise OptionError(f"symmetry tolerance must be positive, got {symmetry_tolerance}")
    low, high = PIXEL_SIZE_RANGE
    if not (low <= pixel_size <= high):
        raise OptionError(f"pixel size must be in [{low:g}, {high:g}] (finite, non-degenerate lengths), got {pixel_size}")
    if isinstance(image, (str, bytes)) or hasattr(image, "__fspath__"):
        source = source or str(image)
        grey = read_image(image)
    else:
        source = source or "image"
        grey = to_grey(image, source)
    H, W = grey.shape
    mask, levels, background, ignored = _silhouette(grey, source)
    rotation = 0.0
    if axis == "principal":
        from skimage.transform import rotate

        rotation = _principal_angle(mask)
        if abs(rotation) > 1e-9:
            fill = 1.0 if background == "light" else 0.0
            grey = rotate(grey, rotation, resize=True, center=None, order=1, mode="constant", cval=fill)
            mask, levels, background, ignored = _silhouette(grey, source)
    rows = _edges(grey, mask, levels)
    if rows.shape[0] < MIN_ROWS:
        raise InputError(f"{source}: the silhouette spans {rows.shape[0]} rows; at least {MIN_ROWS} are needed")
    mid = 0.5 * (rows[:, 1] + rows[:, 2])
    width = rows[:, 2] - rows[:, 1]
    if float(width.mean()) < MIN_WIDTH:
        raise InputError(f"{source}: the silhouette is {max(float(width.mean()), 0.0):.1f} px wide on average; "
                         f"at least {MIN_WIDTH} px are needed (a line has no profile to turn)")
    c = float(mid.mean())
    dev = mid - c
    sym_rms = float(np.sqrt((dev ** 2).mean()))
    sym_max = float(np.abs(dev).max())
    tol = symmetry_tolerance if symmetry_tolerance >= 1 else symmetry_tolerance * float(width.mean())
    if sym_rms > tol:
        raise InputError(
            f"{source}: the silhouette is not mirror-symmetric about a {'vertical' if axis == 'vertical' else 'principal'} "
            f"axis (row midpoints {sym_rms:.2f} px RMS from the best axis x = {c:.1f}, tolerance {tol:.2f} px); "
            "expected a turned object seen from the side" + ("; try --axis principal" if axis == "vertical" else "")
        )
    z0 = float(rows[:, 0].max()) + 0.5  # the bottom edge of the lowest row
    r = 0.5 * width
    z = z0 - rows[:, 0]
    rz = np.stack([r, z], -1)
    prof = fit_profile(rz, degree=degree)
    curve = prof.curve
    ctrl2 = curve.control_points
    P = torch.stack([ctrl2[:, 0], torch.zeros_like(ctrl2[:, 0]), ctrl2[:, 1]], -1) * pixel_size
    prof3 = NURBSCurve(P, degree=curve.degree, knot_vector=curve.knot_vector, weights=curve.weights)
    surface = revolve(prof3, [0.0, 0.0, 0.0], [0.0, 0.0, 1.0])
    # the axis in the input image's coordinates (undo the turn about the image centre)
    point = np.array([c, z0])
    direction = np.array([0.0, -1.0])
    if rotation:
        point, direction = _unrotate(point, direction, rotation, grey.shape, (H, W))
    return ImageRevolution(
        surface=surface, profile=curve, axis={"point": point.tolist(), "direction": direction.tolist()},
        rows=rows, points=rz, symmetry_residual=sym_rms, symmetry_max=sym_max,
        profile_residual=prof.residual_mean, background=background, levels=levels, rotation=rotation,
        pixel_size=pixel_size, mask=mask, grey=grey, axis_x=c, z_origin=z0, ignored_objects=ignored,
    )


def _unrotate(point, direction, angle_deg, shape_rot, shape_in):
    """Map a point and a direction of the turned image (``rotate(..., resize=True)``) back
    to the input image: scikit-image turns counter-clockwise about the centre."""
    a = math.radians(angle_deg)
    # in (x, y-down) coordinates a counter-clockwise turn on screen is R(-a) in math terms
    ca, sa = math.cos(a), math.sin(a)
    Hr, Wr = shape_rot
    H, W = shape_in
    p = np.asarray(point) - np.array([Wr / 2, Hr / 2])
    # inverse of the turn: rotate by +a on screen back, i.e. (x, y) -> (x cos a - y sin a, x sin a + y cos a)
    back = np.array([ca * p[0] - sa * p[1], sa * p[0] + ca * p[1]])
    d = np.asarray(direction)
    dback = np.array([ca * d[0] - sa * d[1], sa * d[0] + ca * d[1]])
    return back + np.array([W / 2, H / 2]), dback / np.linalg.norm(dback)

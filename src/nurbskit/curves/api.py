"""``nurbskit.curves_from_image``: B-spline curves from a drawing, and reading images.

Convention: pixel coordinates, x to the right, y down, the origin at the top-left corner
of the top-left pixel (the centre of pixel ``[row, col]`` is ``(col + 0.5, row + 0.5)``).
"""

from __future__ import annotations

import os
import warnings

import numpy as np

from ..errors import InputError, OptionError

METHODS = ("hybrid", "classic", "network", "auto")
DEFAULT_METHOD = "hybrid"
MODES = ("V", "M", "MV")
COORDINATES = ("pixels: x to the right, y down, origin at the top-left corner of the top-left pixel; "
               "the centre of pixel [row, col] is (col + 0.5, row + 0.5)")


#: Peak memory of reading one drawing, per pixel: an upper bound of what was measured
#: (seventeenth session, peak resident size less the interpreter's and torch's: 45 bytes
#: at 2048 x 2048, 110 with ``--refine`` on a 4096 x 4096 maze of 3,656 curves).
BYTES_PER_PIXEL = 128


def check_fits(source, height: int, width: int) -> None:
    """Refuse (InputError naming ``source``) an image whose reading would not fit in memory."""
    from ..io._base import check_fits as fits

    fits(source, BYTES_PER_PIXEL * height * width, f"curves from a {width} x {height} image")


def read_image(path: str | os.PathLike) -> np.ndarray:
    """An image file -> ``(H, W)`` float64 grey in [0, 1] (PIL; its decompression-bomb limit applies).

    Raises InputError (one line naming the file) for a missing, unreadable, empty or
    oversized image.
    """
    from PIL import Image, UnidentifiedImageError

    from ..io._base import check_readable
    from ..io.image import pil_grey

    path = check_readable(path)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error", Image.DecompressionBombWarning)
            with Image.open(path) as im:
                check_fits(path, im.height, im.width)  # before the pixels are decoded
                im.load()
                if im.width == 0 or im.height == 0:
                    raise InputError(f"{path}: the image is empty ({im.width} x {im.height} pixels)")
                return pil_grey(im, str(path))
    except InputError:  # ours (the memory check, an empty image): already one line naming the file
        raise
    except (Image.DecompressionBombError, Image.DecompressionBombWarning) as exc:
        raise InputError(f"{path}: the image is too large to read safely ({exc})") from None
    except UnidentifiedImageError:
        raise InputError(f"{path}: not a readable image (expected PNG, JPEG, BMP, TIFF, ...)") from None
    except (OSError, ValueError, SyntaxError) as exc:
        raise InputError(f"{path}: not a readable image ({exc})") from None


def extract(grey: np.ndarray, method: str = DEFAULT_METHOD, mode: str = "MV", tolerance: float = 1.0,
            refine: bool = False, refine_iterations: int = 20, source: str = "image", progress=None):
    """Curves in a grey image ``(H, W)`` and what was found on the way -> ``(curves, Extraction)``.

    The one place that dispatches on ``method`` (:func:`curves_from_image` and
    ``nurbskit curves`` both call it). ``progress``: None, or called as ``progress(stage,
    done, total)`` by the classical path's stages (``fit_image``, ``refine``). An image
    whose reading would not fit in memory (``BYTES_PER_PIXEL``) is refused first.
    Methods:

    * ``"hybrid"`` (the default): the classical path with the MV network's vote on the
      number of curves as evidence. The vote: :func:`nurbskit.curves.nets.predict.count_probabilities`
      on the drawing's skeleton redrawn as the training drawings are (any stroke width,
      any size), by the MV weights trained on such redrawn drawings
      (``curves_mv_redrawn``). It enters the junction-pairing search as
      ``-2 log P(count)`` added to the description length (:func:`nurbskit.curves.classic.trace_strokes`,
      ``count_prior``); where the classical count stays less likely than the vote's
      (1-3 curves) by more than ``HYBRID_SWITCH`` nats, the MV network's curves for the
      vote's count, refined by Chamfer against the ink, regroup the classical curves
      (:func:`nurbskit.curves.classic.regrouped`: each classical curve joins the network
      curve it lies along, and those of one network curve are fitted as one), refined
      by Chamfer in turn (``chosen == "regrouped"``); where a network curve has no
      classical curve along it, the network's curves themselves, their control-point
      counts searched (:func:`nurbskit.curves.classic.refine_counts`; ``"network"``). On
      drawings over 256 px across, where the search does not run by default, the vote
      is read first and the search run with it only where it is surer of another count
      by more than ``HYBRID_LARGE`` nats, then the same test, regrouping included (but
      not the network's own curves). Drawings the classical path reads as more
      than 4 curves (sketches) keep the classical curves: the networks know 1-3; so do
      drawings whose strokes are thicker than ``HYBRID_MAX_WIDTH`` of the ink's extent
      (upsampled digits): the networks know thin strokes.
    * ``"classic"``: :func:`nurbskit.curves.classic.fit_image` (skeleton, strokes, least
      squares), refined by Chamfer against the ink when ``refine``; no network.
    * ``"network"``: the shipped ``mode`` network (:mod:`nurbskit.curves.nets.predict`);
      with ``refine`` its readings start the classical Chamfer refinement
      (:func:`nurbskit.curves.classic.refine`), the paper's "network-initialised
      optimisation": one reading per view of the drawing (four), each refined, the one
      closest to the ink kept, then each curve's number of control points searched
      against the ink where the strokes are as thin as the networks know
      (:func:`thin_enough`; :func:`nurbskit.curves.nets.predict.refined_curves`).
    * ``"auto"``: both candidates, the classical curves (refined when ``refine``) and the
      MV network's curves refined by Chamfer as ``"network"`` refines them (always:
      unrefined network curves are rarely better), and keeps the one with the smaller
      symmetric Chamfer distance to the ink pixels, the measure ``report.json`` gives; a
      tie goes to the classical curves. Why: the classical path wins on drawings unlike the training set (any stroke
      count, open and closed strokes), the refined network where strokes cross and the
      skeleton's junction pairing guesses wrong (see ``benchmarks/results/curves_nets.md``).
    """
    from functools import partial

    from .classic import Strokes, chamfer_to_ink, even_background, fit_image, ink_mask

    if method not in METHODS:
        raise OptionError(f"method: expected one of {', '.join(METHODS)}, got {method!r}")
    if mode not in MODES:
        raise OptionError(f"mode: expected one of {', '.join(MODES)}, got {mode!r}")
    if not tolerance > 0:
        raise OptionError(f"tolerance: expected a positive number of pixels, got {tolerance}")
    if isinstance(refine_iterations, bool) or not isinstance(refine_iterations, int) or refine_iterations < 0:
        raise OptionError(f"refine_iterations: expected an integer >= 0, got {refine_iterations!r}")
    check_fits(source, *grey.shape[:2])
    iterations = refine_iterations if refine else 0
    classic_path = partial(fit_image, grey, tolerance=tolerance, refine_iterations=iterations, source=source,
                           progress=progress)
    if method == "classic":
        curves, strokes = classic_path()
        return curves, Extraction(strokes.ink, strokes.inverted, strokes.width, "classic", strokes)
    if method == "hybrid":
        return _hybrid(classic_path, grey, tolerance, refine_iterations, progress)
    from .classic import stroke_width
    from .nets.predict import network_curves, refined_curves

    grey = even_background(grey)  # as fit_image does for the classical path (a photographed drawing)
    ink, inverted = ink_mask(grey, source)
    if method == "network":
        if iterations:
            curves = refined_curves(grey, ink, mode, inverted, iterations)
        else:
            curves = network_curves(grey, mode, inverted)
        # the width too, so that a caller can tell a drawing thicker than the networks know
        return curves, Extraction(ink, inverted, stroke_width(ink), "network", None)
    classic, strokes = fit_image(grey, tolerance=tolerance, refine_iterations=iterations, source=source,
                                 progress=progress)
    net = refined_curves(grey, ink, "MV", inverted, refine_iterations)
    score = [chamfer_to_ink(c, ink)["symmetric"] if c else float("inf") for c in (classic, net)]
    if score[1] < score[0]:
        return net, Extraction(ink, inverted, strokes.width, "network", strokes)
    return classic, Extraction(ink, inverted, strokes.width, "classic", strokes)


# The hybrid method keeps the classical curves unless the network's vote for another count
# is stronger by more than this (nats: log P(other) - log P(classical count)).
HYBRID_SWITCH = 3.0
# On large drawings the pairing search (with the vote) is rerun where the vote's count is
# more likely than the classical count by more than this (nats). On the 512 px development
# drawings (seeds 300000 + i, 60 per count), with the vote of the ninth session: 0 (any
# disagreement) 85.6 % counted right and 20 % of the drawings over 300 ms; 3: 87.8 %; 4-6:
# 88.9 %, 11 % over 300 ms; 10: 87.2 %. With the twelfth session's vote (89.9 % right on
# its own, against 87.5 %), 300 drawings each of seeds 300000 + i and 310000 + i: 5: 89.0
# and 91.0 %; 3: 90.0 and 91.7 %.
HYBRID_LARGE = 3.0
# The networks were trained on strokes 1 to 3 px wide in 128 px drawings: at most about
# 5 % of the ink's extent (the classical path's width estimate, on development drawings at
# 128 and 512 px: 0.4 to 4.8 %). On drawings whose strokes are wider than this share of the
# ink's extent (upsampled digits: MNIST x4 10 to 25 %, scikit-learn's x4 12 to 31 %) the
# vote is not used: the twelfth session's vote read 299 of 300 scikit-learn digits as two or
# three curves, and the network's curves ran along the edges of the thick strokes.
HYBRID_MAX_WIDTH = 0.08
# On large drawings the network's curves serve only as guides for regrouping the classical
# pieces (see ``_hybrid``): they are refined on the ink reduced to at most this many pixels
# across, the networks' own world being coarser still (64 px). The full-size refinement cost
# 0.1 to 0.3 s at 512 px and over a second at 2048 px.
GUIDE_EXTENT = 256


def _ink_extent(ink: np.ndarray) -> int:
    """The larger side in pixels of the box around the ink ``(H, W)`` bool (0 without ink)."""
    rows, cols = np.nonzero(ink)
    if not len(rows):
        return 0
    return max(int(rows.max() - rows.min()), int(cols.max() - cols.min())) + 1


def thin_enough(width: float, ink: np.ndarray) -> bool:
    """Whether strokes ``width`` px wide in ``ink (H, W)`` bool are as thin, relative to the
    ink's extent, as the networks' training drawings (see ``HYBRID_MAX_WIDTH``)."""
    extent = _ink_extent(ink)
    return extent > 0 and width <= HYBRID_MAX_WIDTH * extent


def _hybrid(classic_path, grey, tolerance, refine_iterations, progress):
    """The classical path with the MV network's count vote (see :func:`extract`); without the
    shipped ``curves_mv_redrawn`` weights, the classical path alone. ``classic_path(**options)``:
    :func:`~nurbskit.curves.classic.fit_image` on the drawing with the call's options."""
    from .classic import _PRIOR_COUNTS, refine, refine_counts, regrouped
    from .nets.models import MAX_POINTS, MIN_POINTS
    from .nets.predict import count_probabilities, curves_of_count, load_model, redrawn

    try:
        load_model("MV", "redrawn")
    except InputError:  # no shipped weights (a stripped install): the classical path alone
        curves, strokes = classic_path()
        return curves, Extraction(strokes.ink, strokes.inverted, strokes.width, "classic", strokes)
    vote = {}

    def read_vote(skeleton):
        vote["skeleton"], vote["p"] = skeleton, count_probabilities(skeleton, "MV")
        return vote["p"]

    def prior(skeleton, width, ink):
        if not thin_enough(width, ink):
            vote["thick"] = True  # no vote: the search runs as the classical path's
            return None
        return read_vote(skeleton)

    curves, strokes = classic_path(count_prior=prior)
    found = Extraction(strokes.ink, strokes.inverted, strokes.width, "classic", strokes)
    if vote.get("thick") or not thin_enough(strokes.width, strokes.ink):
        # Outside what the networks know: the classical reading alone. The width is known
        # before the vote where the search runs, and then the vote is not read at all.
        if "p" in vote:  # the search ran with the vote: run it again without
            curves, strokes = classic_path()
            found = Extraction(strokes.ink, strokes.inverted, strokes.width, "classic", strokes)
        return curves, found
    if not 1 <= len(curves) <= _PRIOR_COUNTS:
        return curves, found
    large = "p" not in vote
    if large:
        # The pairing search did not run (a drawing over 256 px across: it would cost
        # several times the time of the rest). The vote first; where it disagrees with the
        # count, the search with the vote as evidence, then the same test as below.
        from skimage.morphology import skeletonize

        from .classic import _fill_slivers

        log_p = np.log(np.maximum(read_vote(skeletonize(_fill_slivers(strokes.ink))), 1e-9))
        k = int(np.argmax(log_p[:3])) + 1
        if k == len(curves) or log_p[k - 1] - log_p[len(curves) - 1] <= HYBRID_LARGE:
            return curves, found
        curves, strokes = classic_path(count_prior=lambda skeleton, width, ink: vote["p"],
                                       search_extent=float("inf"))
        found = Extraction(strokes.ink, strokes.inverted, strokes.width, "classic", strokes)
        if not 1 <= len(curves) <= _PRIOR_COUNTS:
            return curves, found
    log_p = np.log(np.maximum(vote["p"], 1e-9))
    k = int(np.argmax(log_p[:3])) + 1  # the networks were trained on 1 to 3 curves
    if k == len(curves) or log_p[k - 1] - log_p[len(curves) - 1] <= HYBRID_SWITCH:
        return curves, found
    start = curves_of_count(redrawn(vote["skeleton"]), k, grey.shape)
    start = (_coarse_refined if large else refine)(start, strokes.ink, refine_iterations, progress=progress)
    joined = regrouped(curves, start, tolerance)
    if joined is not None:  # the classical pieces, grouped as the network's curves group them
        found.chosen = "regrouped"
        return refine(joined, strokes.ink, refine_iterations, progress=progress), found
    if large:
        # The network's own curves, refined from their coarse start, lie pixels from the
        # true curves at this size (3.5 to 3.8 px on the development drawings at 512 px) and
        # cost a second or two: the classical curves stay.
        return curves, found
    found.chosen = "network"
    return refine_counts(start, strokes.ink, refine_iterations, MIN_POINTS, MAX_POINTS), found


def _coarse_refined(curves: list, ink: np.ndarray, iterations: int, progress=None) -> list:
    """``curves`` refined (``classic.refine``) against ``ink`` reduced by an integer factor
    to at most ``GUIDE_EXTENT`` px across (a block is ink where any of its pixels is), in
    the full drawing's pixel coordinates: guides good to about the factor in pixels, at
    the cost of a drawing of ``GUIDE_EXTENT`` px."""
    from skimage.measure import block_reduce

    from ..core import NURBSCurve
    from .classic import refine

    factor = -(-max(ink.shape) // GUIDE_EXTENT)
    if factor == 1:
        return refine(curves, ink, iterations, progress=progress)

    def scaled(cs, by):  # the origin is a pixel corner, so a block's corner maps to its pixel's
        return [NURBSCurve(c.control_points * by, degree=c.degree, knot_vector=c.knot_vector) for c in cs]

    small = block_reduce(ink, (factor, factor), np.max)
    return scaled(refine(scaled(curves, 1.0 / factor), small, iterations, progress=progress), float(factor))


def thick_note(extraction: "Extraction") -> str | None:
    """A note for the network's curves on strokes thicker than the networks know (see
    ``HYBRID_MAX_WIDTH``), or None. The hybrid method reads such drawings classically on
    its own; ``method="network"`` (and ``"auto"`` when the network's curves are closer to
    the ink) returns the network's curves all the same."""
    extent = _ink_extent(extraction.ink)
    if extraction.chosen != "network" or extraction.width is None or not extent:
        return None
    if thin_enough(extraction.width, extraction.ink):
        return None
    return (f"the strokes are {extraction.width:.1f} px wide, {100 * extraction.width / extent:.0f} % of the ink's "
            f"extent; the networks know strokes up to {100 * HYBRID_MAX_WIDTH:.0f} % (1-3 px at 128 px), so their "
            f"curves may run along the strokes' edges or collapse inside them; the default method (hybrid) reads "
            f"such drawings classically")


class Extraction:
    """What :func:`extract` found besides the curves.

    Attributes:
        ink: ``(H, W)`` bool ink mask (Otsu).
        inverted: True for light ink on a dark background.
        width: stroke width in pixels estimated by the classical path (None when it did not run).
        chosen: whose curves were returned: ``"classic"``, ``"network"``, or
            ``"regrouped"`` (the classical curves joined as the network's group them;
            the hybrid method only).
        strokes: the classical path's :class:`~nurbskit.curves.classic.Strokes`, or None.
    """

    def __init__(self, ink, inverted, width, chosen, strokes):
        self.ink, self.inverted, self.width, self.chosen, self.strokes = ink, inverted, width, chosen, strokes


def curves_from_image(image, method: str = DEFAULT_METHOD, tolerance: float = 1.0, refine: bool = False,
                      refine_iterations: int = 20, mode: str = "MV", progress=None) -> list:
    """B-spline curves drawn in ``image``, in pixel coordinates (see the module's convention).

    Args:
        image: a path to an image file, or an ``(H, W)`` grey / ``(H, W, 3|4)`` colour array.
            Dark on light and light on dark are both detected.
        method: ``"hybrid"`` (the default: the classical path with the MV network's vote
            on the number of curves; see :func:`extract`), ``"classic"`` (skeleton,
            strokes, least squares, no network; see :mod:`nurbskit.curves.classic`), ``"network"`` (the shipped DeepSpline network
            of ``mode``; weights load once, on first use) or ``"auto"`` (both, the one
            closer to the ink kept; see :func:`extract`).
        tolerance: largest distance in pixels from a stroke's skeleton to its curve (classic).
        refine: refine the control points by Chamfer against the ink pixels (L-BFGS); with
            ``method="network"`` the network's curves are the start.
        refine_iterations: L-BFGS iterations of the refinement.
        mode: the network: ``"V"`` one curve of 4-6 control points, ``"M"`` 1-3 curves of
            5, ``"MV"`` 1-3 curves of 4-6 (the default).
        progress: None, or called as ``progress(stage, done, total)`` as the stages go
            (see :func:`extract`); an exception it raises ends the call.

    Returns:
        A list of :class:`~nurbskit.NURBSCurve` (float64, 2D), one per stroke.

    Example:
        >>> import numpy as np, nurbskit
        >>> img = np.ones((40, 60)); img[19:22, 5:55] = 0       # a horizontal line, centre y = 20.5
        >>> [c] = nurbskit.curves_from_image(img)
        >>> c.control_points[:, 1].sub(20.5).abs().max().item() < 1, c.control_points[0, 0].item() < 10
        (True, True)
    """
    from .classic import to_grey

    source = "image"
    if isinstance(image, (str, os.PathLike)):
        source = str(image)
        image = read_image(image)
    curves, _ = extract(to_grey(image, source), method=method, mode=mode, tolerance=tolerance, refine=refine,
                        refine_iterations=refine_iterations, source=source, progress=progress)
    return curves

"""A striped cable's second colour, learnt from the gaps between the bands of its first.

A cable striped in two colours is found by one of them (the other is often the table's, or
a colour the table's print has): its seed is a row of bands, a gap of the other colour
between each two. A colour model learnt from that seed calls the second colour background
(the pixels in a long gap lie farther than a width from the seed, where the background is
sampled), and each frame's mask is a row of dashes.

The gaps show the second colour: close the seed along the cable (a closing by a disc of
``stripe_reach`` cable widths bridges gaps up to twice that long) and what the closing adds,
away from the seed's and the closing's outlines (their mixed pixels are neither colour), is
the gaps. A plain cable's closing adds pixels too (between close strands, inside tight
bends, at crossings), but they are the table's colours, as common far from the cable as in
the closing, and they lie in a few patches. So the colours of the added pixels are compared
with those of the background farther than :data:`FAR` widths from the seed, over the few
frames the model learns from, and those :data:`ENRICHMENT` times more frequent in the gaps
are the cable's: when they make most (:data:`GAP_SHARE`) of the gaps' pixels, enough of them
(:data:`SEED_SHARE` of the seed's) and in enough separate bands (:data:`BANDS` a frame) to be
a stripe's, the pixels of those colours within ``stripe_reach`` widths of the seed join it,
and the model learns from both colours (:func:`with_second_colour`). A cast shadow's colours
are not taken: darker than the background and of its chromaticity.

Where the second colour is the table's (a grey and green cable on grey tiles, cream and blue
on cream paper), no colour is enriched in the gaps, and each frame's mask would be a row of
dashes, each smaller than a speck, so removed: nothing was left of the cable. The seed's shape
still tells: most of its pixels (:data:`BANDED_SHARE`) lie in pieces smaller than a speck that
the same closing joins into chains of several specks' area (measured on the seeds of 132
tuning scenes: 0.90 and 0.98 for two such cables, at most 0.1 for a plain cable, whose seed
is a few long pieces, and 0.46 and 0.55 for two other striped ones). Such masks
are *banded* (:func:`banded`, asked of the colour model's masks on the frames it learns
from: :func:`engine.stages.segmentation._with_bands`), and each frame's mask is then its
dashes closed along the cable (:func:`bridged`) before specks are removed.

The thresholds were set on the tuning looks (:mod:`engine.synthetic.looks`, tuning seeds of
every family: the plain cables' closings stay below them, the striped ones above), not on
the held-out looks or the captures.
"""

import math

import cv2
import numpy as np
from scipy.ndimage import gaussian_filter

from .pixels import brightness, cable_box, chroma

__all__ = ["with_second_colour", "gap_pixels", "banded", "bridged"]

#: Levels per colour channel of the histograms the gaps and the background are compared in.
BINS = 16
#: Their smoothing, bins.
SMOOTHING = 0.5
#: A colour is the cable's when this many times more frequent among the gaps' pixels than in
#: the background (with a floor: a colour the background lacks is not infinitely so).
ENRICHMENT = 8.0
_FLOOR = 1e-4
#: The background is sampled farther than this many cable widths from the seed.
FAR = 3.0
#: Pixels within this many pixels of the seed (or one of the closing's outline) are mixed.
CORE = 2
#: The second colour is taken when its pixels make at least this share of the gaps' pixels
#: and this share of the seed's, in at least this many bands a frame (pieces of a quarter of a
#: width squared or more; on average): a stripe's bands run the cable's whole length, a plain
#: cable's closing adds a few patches where strands come close.
GAP_SHARE = 0.5
SEED_SHARE = 0.05
BANDS = 20
#: A gap pixel darker than this share of the background's brightness, within
#: ``SHADOW_CHROMA`` of its chromaticity, is a shadow.
SHADOW_DARK = 0.9
SHADOW_CHROMA = 0.04
#: Masks are rows of bands (:func:`banded`) when at least this share of their pixels (on
#: average over the frames) lies in pieces smaller than a speck that their closing joins into
#: chains of at least two specks' area.
BANDED_SHARE = 0.5
#: A model learnt again from a banded model's masks takes in the second colour where it is not
#: the table's, and its masks are the bands of both colours; the seam between two bands (a
#: pixel or two whose colour is a mix of both, neither colour's) then parts the mask into
#: pieces, the short ones under a speck's area (patterned tuning seed 54: orange and blue
#: bands, whole stretches of the cable lost, IoU 0.73). Such masks are closed by a disc of
#: this many cable widths, which fills a gap up to one width long: a seam, not a band's gap.
SEAM_REACH = 0.5


def gap_pixels(seed, width, reach):
    """The gaps a closing of ``seed`` by ``reach`` cable widths fills, away from both
    outlines; the pixels beside the seed (within ``reach`` widths, past its mixed pixels);
    the background, farther than :data:`FAR` widths from the seed.

    Discs of many pixels are slow to dilate with, so distances stand for them: a pixel is in
    the dilation when it lies within the radius of the seed, in the erosion of a region when
    it lies farther than the radius from its outside.

    Parameters
    ----------
    seed : ndarray of bool, shape (H, W)
    width : float
        The cable's width in pixels.
    reach : float
        Cable widths.

    Returns
    -------
    gaps, beside, background : ndarray of bool, shape (H, W)
    """
    gaps, beside, background = np.zeros_like(seed), np.zeros_like(seed), np.ones_like(seed)
    radius = reach * width
    box = cable_box(seed, int(math.ceil(max(radius, FAR * width))) + CORE + 2)
    if box is None:
        return gaps, beside, background
    outside = (~seed[box]).view(np.uint8)
    from_seed = cv2.distanceTransform(outside, cv2.DIST_L2, cv2.DIST_MASK_5)
    grown = (from_seed <= radius).view(np.uint8)
    # the closing (one pixel in from its outline: the cable's edges are mixed pixels)
    closed = cv2.distanceTransform(grown, cv2.DIST_L2, cv2.DIST_MASK_5) > radius + 1.0
    gaps[box] = closed & (from_seed > CORE)
    beside[box] = (grown > 0) & (from_seed > CORE)
    background[box] = from_seed > FAR * width
    return gaps, beside, background


def _bins(pixels):
    levels = (pixels // (256 // BINS)).astype(np.int32)
    return (levels[:, 0] * BINS + levels[:, 1]) * BINS + levels[:, 2]


def _distribution(counts):
    share = counts / max(counts.sum(), 1.0)
    return gaussian_filter(share.reshape((BINS,) * 3), SMOOTHING, mode="constant").ravel()


def with_second_colour(frames, seeds, reach):
    """The seeds with the gaps between their bands added, where those gaps hold a second
    colour of the cable (see the module's docstring); the seeds themselves otherwise.

    Parameters
    ----------
    frames : sequence of ndarray
        RGB uint8.
    seeds : sequence of (ndarray, ndarray, float)
        Per frame, the cable's seed, the pieces shaped like objects (neither gap nor
        background) and the cable's width, as :func:`engine.stages.segmentation.colour_seed`
        gives them.
    reach : float
        The closing's disc, cable widths (0: the seeds as they are).

    Returns
    -------
    list of (ndarray, ndarray, float)
    """
    seeds = list(seeds)
    if reach <= 0:
        return seeds
    gap_counts, background_counts = np.zeros(BINS ** 3), np.zeros(BINS ** 3)
    found, seed_pixels = [], 0
    for frame, (seed, objects, width) in zip(frames, seeds):
        if not seed.any():
            found.append(None)
            continue
        gaps, beside, background = gap_pixels(seed, width, reach)
        gaps &= ~objects
        background &= ~objects
        rows, cols = np.nonzero(gaps)
        # the background's colours from every other row and column: as many as needed
        colours, far = frame[rows, cols], frame[::2, ::2][background[::2, ::2]]
        gap_bins = _bins(colours)
        gap_counts += np.bincount(gap_bins, minlength=BINS ** 3)
        background_counts += np.bincount(_bins(far), minlength=BINS ** 3)
        seed_pixels += int(np.count_nonzero(seed))
        found.append((rows, cols, colours, gap_bins, _typical(far), beside & ~objects))
    gap_total = gap_counts.sum()
    if not gap_total:
        return seeds
    cable_colour = _distribution(gap_counts) > ENRICHMENT * _distribution(background_counts) \
        + _FLOOR
    taken = []
    for item in found:
        if item is None:
            taken.append(None)
            continue
        rows, cols, colours, gap_bins, typical, _ = item
        keep = cable_colour[gap_bins] & ~_shadow(colours, typical)
        taken.append((rows[keep], cols[keep]))
    count = sum(len(rows) for rows, _ in filter(None, taken))
    if (count < GAP_SHARE * gap_total or count < SEED_SHARE * seed_pixels
            or np.mean([_bands(pixels, width) for pixels, (_, _, width)
                        in zip(taken, seeds) if pixels is not None]) < BANDS):
        return seeds
    # the gaps' cores decided it; the whole gaps join (a thin cable's closing fills only the
    # middle of each gap: the disc dips into it from both sides)
    grown = []
    for frame, (seed, objects, width), item in zip(frames, seeds, found):
        if item is not None:
            typical, beside = item[-2:]
            rows, cols = np.nonzero(beside)
            colours = frame[rows, cols]
            keep = cable_colour[_bins(colours)] & ~_shadow(colours, typical)
            seed = seed.copy()
            seed[rows[keep], cols[keep]] = True
        grown.append((seed, objects, width))
    return grown


def _bands(pixels, width):
    """How many pieces the pixels ``(rows, cols)`` make, each at least a quarter of ``width``
    squared."""
    rows, cols = pixels
    if not len(rows):
        return 0
    top, left = rows.min(), cols.min()
    image = np.zeros((rows.max() - top + 1, cols.max() - left + 1), np.uint8)
    image[rows - top, cols - left] = 1
    _, _, stats, _ = cv2.connectedComponentsWithStats(image, connectivity=8)
    return int(np.count_nonzero(stats[1:, cv2.CC_STAT_AREA] >= 0.25 * width * width))


def _typical(background):
    """The median chromaticity and brightness of the ``background`` pixels (None if none)."""
    if not len(background):
        return None
    return np.median(chroma(background), axis=0), np.median(brightness(background))


def _shadow(colours, typical):
    """Which ``colours`` are a shadow on a background of ``typical`` chromaticity and
    brightness (:func:`_typical`): darker than :data:`SHADOW_DARK` of its brightness and
    within :data:`SHADOW_CHROMA` of its chromaticity."""
    if typical is None or not len(colours):
        return np.zeros(len(colours), dtype=bool)
    shade, light = typical
    return ((np.linalg.norm(chroma(colours) - shade, axis=1) < SHADOW_CHROMA)
            & (brightness(colours) < SHADOW_DARK * light))


def banded(masks, widths, reach, speck_area):
    """Whether the masks are rows of bands with gaps of the table's colours between them: at
    least :data:`BANDED_SHARE` of their pixels (on average over the frames with a mask) lie in
    pieces under ``speck_area`` cable widths squared that a closing by ``reach`` widths joins
    into chains of twice that area or more.

    Parameters
    ----------
    masks : sequence of ndarray of bool
        Per frame, the cable's pixels (a colour model's, before specks are removed).
    widths : sequence of float
        Per frame, the cable's width in pixels.
    reach : float
        The closing's disc, cable widths (0: never banded).
    speck_area : float
        Cable widths squared (``SegmentationSettings.speck_area``).

    Returns
    -------
    bool
    """
    if reach <= 0:
        return False
    shares = []
    for mask, width in zip(masks, widths):
        if not mask.any():
            continue
        speck = speck_area * width * width
        _, pieces, stats, _ = cv2.connectedComponentsWithStats(mask.view(np.uint8),
                                                               connectivity=8)
        small = stats[:, cv2.CC_STAT_AREA] < speck
        small[0] = False
        _, chains, stats, _ = cv2.connectedComponentsWithStats(
            bridged(mask, width, reach).view(np.uint8), connectivity=8)
        long = stats[:, cv2.CC_STAT_AREA] >= 2 * speck
        long[0] = False
        shares.append(np.count_nonzero(small[pieces] & long[chains]) / np.count_nonzero(mask))
    return bool(shares) and float(np.mean(shares)) >= BANDED_SHARE


def bridged(mask, width, reach):
    """``mask`` closed by a disc of ``reach`` cable widths (``width`` pixels): a row of bands'
    gaps, up to twice ``reach`` widths long, filled.

    Parameters
    ----------
    mask : ndarray of bool, shape (H, W)
    width, reach : float

    Returns
    -------
    ndarray of bool
        A new mask (``mask`` itself when it is empty or ``reach`` is 0).
    """
    radius = reach * width
    box = cable_box(mask, int(math.ceil(radius)) + 2)
    if box is None or radius <= 0:
        return mask
    from_mask = cv2.distanceTransform((~mask[box]).view(np.uint8), cv2.DIST_L2,
                                      cv2.DIST_MASK_5)
    grown = (from_mask <= radius).view(np.uint8)
    closed = mask.copy()
    closed[box] |= cv2.distanceTransform(grown, cv2.DIST_L2, cv2.DIST_MASK_5) > radius
    return closed

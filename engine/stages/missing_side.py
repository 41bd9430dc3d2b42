"""The side of a cable its colour model missed, put back by the cable's shape.

A colour model finds the pixels of the cable's colours. Where one side of the cable has a
colour the background also has (a white cable's grey shade side on grey print, the second
colour of a two-tone cable, a green cable's dark side on dark tiles), it finds half the cable:
a band of half the width, whose one outline is the cable's edge and the other runs along its
middle. Colour cannot put that side back; the cable's shape can. A cable is a band between
two edges, and what lies between the found half and the cable's far edge is unlike the
background beyond it.

So the pixels beside the mask's thin pieces (not beside a piece shaped like an object: that
would grow to the object's other faces), out to about a cable width, are taken back when they
differ from the background around them (:func:`with_missing_side`): from its local colour
(the pixels a little farther out, averaged over a few cable widths, without the ones far
darker: a shadow beside the cable is not its background) in chromaticity and in colour, and
from the background's typical colour (in chromaticity, or in colour when lighter: a darker
pixel of its chromaticity is a darker part of a textured table). A pixel darker than its
background and of its chromaticity, or far darker, is shadow and never taken; but one whose
chromaticity is clearly nearer the found side's (its local average) than the background's is
the cable's other side, even when the two chromaticities are too close for the tests above (a
grey cable's lit side on pinkish paper, only its shaded side found: tuning look neutral seed
3, 0.36 mask IoU without this, 0.54 with it). What is taken
must look like a missing side: pieces that run along the mask (their contact with it at least
``side_contact`` cable widths long), at least a cable width square in area, that stop short
of the search's reach (a piece still unlike the background there is a different thing, lying
beside the cable). The mixed pixels on the outline's rim differ from the background too, so
only pieces reaching beyond the rim count, and each brings the rim beside it.

The segmentation searches twice: before the outline's classifier, and again after it. Before
it, the mask often holds a rim of the missed side's mixed pixels, so the strip it misses is
as narrow as the rim and no piece reaches beyond it; the classifier then takes those mixed
pixels for the table (its cable colour is the found side's), and the strip beside the clean
outline is the side's whole width (tuning look patterned seed 33, orange and pinkish white
along its length on blue-grey print: 0.60 mask IoU with the first search alone, 0.82 with
both).

The rules and their thresholds were set on the tuning looks (:mod:`engine.synthetic.looks`,
tuning seeds 0-7); the bench's held-out looks and captures were not used
(``python -m engine bench looks``).
"""

import math

import cv2
import numpy as np

from .colour_model import thin_pieces
from .pixels import brightness, cable_box, chroma

__all__ = ["with_missing_side"]

#: Pixels within this distance (pixels) of the mask are its outline's rim: mixed pixels, unlike
#: the background whatever the cable's side; a taken piece must reach beyond them.
_RIM = 2.5

#: A cable wider than twice this (pixels) is searched on the frame reduced by a whole factor
#: to about this width.
_WORK_WIDTH = 6.0

#: The background's ring lies this many cable widths wide beyond the search's reach; its colour
#: is averaged over a square of this many cable widths.
_RING = 0.75
_AVERAGE = 3.0

#: A ring pixel darker than this share of the ring's average brightness is a shadow, not the
#: background.
_LIT = 0.6

#: A pixel darker than its background and within this chromaticity of it, or darker than
#: this share of its brightness, is shadow.
_SHADOW_CHROMA = 0.06
_SHADOW_DARK = 0.4

#: A pixel is the found side's other side, not a shadow, when its chromaticity is nearer the
#: found side's than this share of its distance to the background's, where those two lie at
#: least ``_OWN_APART`` apart (closer, noise decides which is nearer).
_OWN_SHARE = 0.5
_OWN_APART = 0.012

#: A taken piece has at most this share of its pixels at the search's reach.
_FAR_SHARE = 0.25


def with_missing_side(mask, image_rgb, width, *, reach, chroma_gap, contrast, contact):
    """``mask`` with the side of the cable its colours missed (see the module notes).

    The segmentation's settings give the options (``SegmentationSettings.side_reach``,
    ``side_chroma``, ``side_contrast``, ``side_contact``).

    Parameters
    ----------
    mask : ndarray of bool, shape (H, W)
        The cable mask (one cable, or several).
    image_rgb : ndarray, shape (H, W, 3), uint8
    width : float
        The mask's cable width in pixels (0: the mask is returned as is).
    reach : float
        Cable widths beside the mask searched (0: none).
    chroma_gap : float
        A taken pixel's chromaticity differs from its local background's by more than this,
        and from the background's typical colour by more than this (or the pixel is lighter
        than that colour and more than twice ``contrast`` from it).
    contrast : float
        A taken pixel's colour differs from its local background's by more than this (RGB
        distance, 8-bit levels, after a 3x3 average).
    contact : float
        A taken piece touches the mask along at least this many cable widths.

    Returns
    -------
    ndarray of bool
        ``mask`` itself when nothing is taken.
    """
    if width <= 0 or reach <= 0:
        return mask
    box = cable_box(mask, int(math.ceil((reach + _RING) * width)) + 4)
    if box is None:
        return mask
    cable, image = mask[box], image_rgb[box]
    # a wide cable is searched on the frame reduced to about _WORK_WIDTH pixels across it:
    # the side's pieces are as clear, at a fraction of the cost
    scale = max(int(width // _WORK_WIDTH), 1)
    if scale > 1:  # by a whole factor (OpenCV's fast path): the box's last rows may go
        rows, cols = cable.shape[0] // scale, cable.shape[1] // scale
        small = np.ascontiguousarray(cable[scale // 2:rows * scale:scale,
                                           scale // 2:cols * scale:scale])
        image = cv2.resize(np.ascontiguousarray(image[:rows * scale, :cols * scale]),
                           (cols, rows), interpolation=cv2.INTER_AREA)
    else:
        small, image = np.ascontiguousarray(cable), np.ascontiguousarray(image)
    side = _side(small, image, width / scale, scale, reach, chroma_gap, contrast, contact)
    if side is None:
        return mask
    out = mask.copy()
    if scale > 1:
        side = side.repeat(scale, axis=0).repeat(scale, axis=1)
    out[box][:side.shape[0], :side.shape[1]] |= side
    return out


def _side(cable, image, width, scale, reach, chroma_gap, contrast, contact):
    """:func:`with_missing_side` on the (reduced) box: the pixels taken, or None."""
    far = reach * width + 1.5 / scale
    # searched from the mask's thin pieces only: a piece of an object of the cable's colour
    # would grow to the object's other faces
    labels, thin, _, _ = thin_pieces(cable)
    source = thin[labels]
    if not source.any():
        return None
    distance = cv2.distanceTransform((~source).view(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_5)
    near = np.flatnonzero((distance > 0) & (distance <= far) & ~cable)
    rows, cols = np.divmod(near, cable.shape[1])
    halved = _halved(image).astype(np.float32)
    local, typical = _background(halved, distance, far, width, rows, cols)
    if local is None:
        return None
    # the found side's colour
    own = _at(_local_average(halved, _halved(cable.view(np.uint8) * np.float32(1.0)), width),
              rows, cols)
    known = ~np.isnan(local[:, 0])
    near, local, own = near[known], local[known], own[known]
    # a pixel's colour is averaged with its neighbours' (a reduced frame's already is)
    pixels = (image if scale > 1 else cv2.blur(image, (3, 3))).reshape(-1, 3)[near]
    pixels = pixels.astype(np.float32)
    tint = chroma(pixels)
    gap = _squared(tint - chroma(local))
    lit = brightness(pixels) / np.maximum(brightness(local), 1.0)
    shadow = (lit < 1.0) & ((gap < _SHADOW_CHROMA**2) | (lit < _SHADOW_DARK))
    # of the typical background's chromaticity, only lighter: a darker one is its shade
    unlike_typical = (_squared(tint - chroma(typical)) > chroma_gap**2) \
        | ((_squared(pixels - typical) > (2.0 * contrast) ** 2)
           & (brightness(pixels) > brightness(typical)))
    # of the found side's chromaticity rather than the background's: the cable's other side
    # (NaN, no found pixel near, compares False)
    like_own = (_squared(chroma(own) - chroma(local)) > _OWN_APART**2) \
        & (_squared(tint - chroma(own)) < _OWN_SHARE**2 * gap)
    shadow &= ~like_own | (lit < _SHADOW_DARK)
    unlike = (((gap > chroma_gap**2) & unlike_typical) | like_own) \
        & (_squared(pixels - local) > contrast**2) & ~shadow
    if not unlike.any():
        return None
    taken = np.zeros(cable.shape, dtype=bool)
    taken.ravel()[near[unlike]] = True
    return _side_pieces(taken, distance, far, width, contact, max(_RIM / scale, 1.5))


def _squared(vectors):
    """Squared lengths of the rows of ``vectors``."""
    return np.einsum("ij,ij->i", vectors, vectors)


def _background(halved, distance, far, width, rows, cols):
    """The local background's colour at pixels ``(rows, cols)``: the ring's pixels beyond
    ``far``, :data:`_RING` cable widths wide, averaged over :data:`_AVERAGE` cable widths,
    without the ones darker than :data:`_LIT` of that average (NaN where no ring pixel is
    near), and the median colour of those ring pixels; ``(None, None)`` without a ring. The
    background is smooth: averaged at half size (``halved``, the image there, float32)."""
    ring = (distance > far) & (distance <= far + _RING * width)
    if not ring.any():
        return None, None
    weights = _halved(ring.view(np.uint8) * np.float32(1.0))
    # again without the shadows the first average shows (where none is near, none is dark)
    weights = weights * (brightness(halved) >= _LIT * brightness(
        np.nan_to_num(_local_average(halved, weights, width))))
    lit = weights > 0.5
    if not lit.any():
        return None, None
    return _at(_local_average(halved, weights, width), rows, cols), \
        np.median(halved[lit], axis=0)


def _local_average(halved, weights, width):
    """``halved``'s colours averaged with ``weights`` over a square of :data:`_AVERAGE` cable
    widths (both at half size; NaN where no weight is near)."""
    kernel = (2 * int(math.ceil(0.25 * _AVERAGE * width)) + 1,) * 2
    total = cv2.blur(weights, kernel)
    average = cv2.blur(halved * weights[..., None], kernel) / np.maximum(total, 1e-6)[..., None]
    average[total <= 1e-3] = np.nan
    return average


def _at(halved, rows, cols):
    """The values of the half-size ``halved`` at the full-size pixels ``(rows, cols)``."""
    return halved[np.minimum(rows // 2, halved.shape[0] - 1),
                  np.minimum(cols // 2, halved.shape[1] - 1)]


def _halved(array):
    """``array`` at half size, each pixel the mean of four (an odd last row or column goes: a
    whole factor is OpenCV's fast path)."""
    rows, cols = max(array.shape[0] // 2, 1), max(array.shape[1] // 2, 1)
    return cv2.resize(np.ascontiguousarray(array[:2 * rows, :2 * cols]), (cols, rows),
                      interpolation=cv2.INTER_AREA)


def _side_pieces(taken, distance, far, width, contact, rim):
    """The pieces of ``taken`` that look like a missing side (see the module notes), with the
    ``rim`` pixels beside them; None when there is none."""
    core = taken & (distance > rim)
    count, labels, stats, _ = cv2.connectedComponentsWithStats(core.view(np.uint8),
                                                                connectivity=8)
    if count <= 1:
        return None
    touching = np.bincount(labels[core & (distance <= rim + 1.0)], minlength=count)
    at_reach = np.bincount(labels[core & (distance > far - 1.5)], minlength=count)
    area = stats[:, cv2.CC_STAT_AREA]
    keep = (touching >= contact * width) & (at_reach <= _FAR_SHARE * area) \
        & (area >= width * width)
    keep[0] = False
    if not keep.any():
        return None
    pieces = keep[labels]
    beside = cv2.dilate(pieces.view(np.uint8), np.ones((3, 3), np.uint8),
                        iterations=int(rim) + 1) > 0
    return pieces | (taken & beside)

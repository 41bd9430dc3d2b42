"""Cable masks and junction maps from images (paper §3.1).

A cable is found by its colour: an HSV range set on one frame (by hand, from a picked pixel,
or automatically from the frame's dominant saturated colour) and applied to every frame. A
cable with no colour of its own, darker or lighter than a grey background, is found by its
brightness instead. Specks are removed, the desaturated specular streak along a glossy cable
is filled back in, and the cable's width in pixels is measured per frame.

Junctions are where the cable overlaps itself: a disc around such a pixel holds more cable than
a single strand can. The disc and the threshold are derived from the measured width.

HSV values are OpenCV's: hue 0–179 (wrapping: a range whose low hue is above its high hue,
e.g. 170–8, is red), saturation and value 0–255.
"""

import math
from dataclasses import dataclass

import cv2
import numpy as np

from .errors import InputError

__all__ = ["ColourRange", "SegmentationSettings", "FrameSegmentation", "auto_colour",
           "colour_at", "segment_frame", "cable_mask", "cable_width", "junction_map"]


@dataclass(frozen=True)
class ColourRange:
    """A cable colour: an HSV box, or a brightness class for a colourless cable.

    Attributes
    ----------
    low, high : tuple of int
        ``(H, S, V)`` bounds, inclusive; the hue wraps when ``low[0] > high[0]``.
    """

    low: tuple = (0, 0, 0)
    high: tuple = (179, 255, 255)

    def __post_init__(self):
        low, high = tuple(int(v) for v in self.low), tuple(int(v) for v in self.high)
        if len(low) != 3 or len(high) != 3:
            raise ValueError("an HSV range needs three low and three high values")
        for name, value, top in zip("HSV", zip(low, high), (179, 255, 255)):
            if not (0 <= value[0] <= top and 0 <= value[1] <= top):
                raise ValueError(f"{name} must lie in 0..{top}")
        if low[1] > high[1] or low[2] > high[2]:
            raise ValueError("saturation and value ranges must have low <= high")
        object.__setattr__(self, "low", low)
        object.__setattr__(self, "high", high)

    @classmethod
    def parse(cls, text):
        """From ``"H1,S1,V1,H2,S2,V2"`` (the ``--hsv`` option); :class:`InputError` if bad."""
        try:
            values = [int(v) for v in text.split(",")]
            if len(values) != 6:
                raise ValueError("six numbers expected")
            return cls(tuple(values[:3]), tuple(values[3:]))
        except ValueError as error:
            raise InputError(f"--hsv {text!r}: {error} (H1,S1,V1,H2,S2,V2 with H 0-179, "
                             "S and V 0-255)") from None

    def __str__(self):
        return ",".join(str(v) for v in (*self.low, *self.high))

    @property
    def has_hue(self):
        """False for a brightness range (any hue): a cable with no colour of its own."""
        return not (self.low[0] == 0 and self.high[0] == 179)

    def select(self, hsv):
        """Boolean mask of the pixels of an HSV image inside the range."""
        h, s, v = hsv[..., 0], hsv[..., 1], hsv[..., 2]
        (h1, s1, v1), (h2, s2, v2) = self.low, self.high
        hue = (h >= h1) & (h <= h2) if h1 <= h2 else (h >= h1) | (h <= h2)
        return hue & (s >= s1) & (s <= s2) & (v >= v1) & (v <= v2)


@dataclass(frozen=True)
class SegmentationSettings:
    """How masks and junctions are made (widths in units of the measured cable width).

    Attributes
    ----------
    speck_area : float
        Connected pieces smaller than ``speck_area * width**2`` pixels are removed.
    fill_highlights : bool
        Fill the desaturated specular streak along a glossy cable.
    shade_value : float
        Edge correction on the shadow side: a mask pixel on the edge leaves it when it is darker than
        ``shade_value`` times the cable's median value and less saturated than its median
        (light bounced off the cable tints its shadow with the cable's hue).
    junction_radius : float
        Radius of the counting disc.
    junction_ratio : float
        A pixel is a junction when its disc holds more than this many times the cable pixels
        a single straight strand through the disc would.
    """

    speck_area: float = 3.0
    fill_highlights: bool = True
    shade_value: float = 0.5
    junction_radius: float = 1.5
    junction_ratio: float = 1.33


@dataclass(frozen=True, eq=False)
class FrameSegmentation:
    """One frame's result: cable mask, junction map and the cable's width in pixels."""

    mask: np.ndarray
    junctions: np.ndarray
    width: float


def _hsv(image_rgb):
    return cv2.cvtColor(np.ascontiguousarray(image_rgb), cv2.COLOR_RGB2HSV)


def _hue_peak(hues, weights=None):
    histogram = np.bincount(hues.ravel(), weights=None if weights is None else weights.ravel(),
                            minlength=180)[:180].astype(float)
    smooth = np.convolve(np.concatenate([histogram[-5:], histogram, histogram[:5]]),
                         np.ones(5) / 5, mode="same")[5:-5]
    return int(np.argmax(smooth))


def _hue_distance(hues, centre):
    d = np.abs(hues.astype(int) - centre)
    return np.minimum(d, 180 - d)


def _otsu(values):
    values = np.asarray(values, dtype=np.uint8).reshape(-1, 1)
    threshold, _ = cv2.threshold(values, 0, 255, cv2.THRESH_BINARY + cv2.THRESH_OTSU)
    return int(threshold)


def auto_colour(image_rgb):
    """The cable colour of a frame: its dominant strongly saturated colour.

    The most saturated few percent of the pixels vote for a hue; the pixels of about that hue
    are split by saturation (Otsu) into the cable and whatever else shares its hue. A frame
    with no strongly coloured object gives a brightness range instead: the minority side of
    an Otsu split of the value channel (a dark cable on a light table, or the reverse).

    Returns
    -------
    ColourRange
    """
    hsv = _hsv(image_rgb)
    h, s, v = hsv[..., 0], hsv[..., 1], hsv[..., 2]
    lit = v > 40
    top = s >= max(np.percentile(s[lit], 97.0), 1) if lit.any() else s > 0
    if s[top].size == 0 or np.median(s[top]) < 90:  # nothing strongly coloured
        threshold = _otsu(v)
        dark = (v <= threshold).mean() < 0.5
        return ColourRange((0, 0, 0), (179, 255, threshold)) if dark else \
            ColourRange((0, 0, threshold + 1), (179, 255, 255))
    peak = _hue_peak(h[top], s[top].astype(float))
    spread = np.percentile(_hue_distance(h[top], peak), 95)
    band = int(np.clip(spread + 4, 6, 25))
    same_hue = (_hue_distance(h, peak) <= band) & lit
    saturation = max(_otsu(s[same_hue]), 40)
    low_v = max(int(np.percentile(v[same_hue & (s > saturation)], 0.5)) - 10, 20)
    return ColourRange(((peak - band) % 180, saturation, low_v), ((peak + band) % 180, 255, 255))


def colour_at(image_rgb, x, y, *, radius=3):
    """The cable colour under a picked pixel (column ``x``, row ``y``).

    Returns
    -------
    ColourRange
        A hue band around the picked colour with saturation and value ranges that admit its
        shading; a brightness range if the picked pixel has no colour of its own.
    """
    hsv = _hsv(image_rgb)
    rows, cols = hsv.shape[:2]
    if not (0 <= x < cols and 0 <= y < rows):
        raise ValueError(f"pixel ({x}, {y}) lies outside the {cols}x{rows} frame")
    patch = hsv[max(y - radius, 0):y + radius + 1, max(x - radius, 0):x + radius + 1]
    hue = _hue_peak(patch[..., 0])
    saturation = int(np.median(patch[..., 1]))
    value = int(np.median(patch[..., 2]))
    if saturation < 60:
        threshold = min(value + 45, 255) if value < 128 else max(value - 45, 0)
        return ColourRange((0, 0, 0), (179, 255, threshold)) if value < 128 else \
            ColourRange((0, 0, threshold), (179, 255, 255))
    return ColourRange(((hue - 10) % 180, max(saturation // 2, 40), max(value // 4, 20)),
                       ((hue + 10) % 180, 255, 255))


def cable_width(mask):
    """Typical cable width in pixels: twice the distance transform along the mask's ridge.

    Parameters
    ----------
    mask : ndarray of bool

    Returns
    -------
    float
        0 for an empty mask.
    """
    if not mask.any():
        return 0.0
    distance = cv2.distanceTransform(mask.astype(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
    ridge = (distance >= cv2.dilate(distance, np.ones((3, 3), np.uint8))) & mask
    # Pixel centres: a band w pixels wide peaks at (w + 1) / 2 when w is odd and at w / 2 on
    # its two middle rows when w is even; 2 d - 1/2 is within half a pixel of both.
    return float(max(2.0 * np.median(distance[ridge]) - 0.5, 1.0))


def _remove_specks(mask, min_area):
    count, labels, stats, _ = cv2.connectedComponentsWithStats(mask.astype(np.uint8), 8)
    keep = stats[:, cv2.CC_STAT_AREA] >= min_area
    keep[0] = False
    return keep[labels]


def _fill_highlights(mask, hsv, width):
    """Bridge the bright, desaturated streak a glossy cable shows along its middle."""
    span = max(int(round(width * 0.6)), 1) | 1
    closed = cv2.morphologyEx(mask.astype(np.uint8), cv2.MORPH_CLOSE,
                              cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (span, span))) > 0
    bright = hsv[..., 2] >= np.percentile(hsv[..., 2][mask], 60) if mask.any() else closed
    return mask | (closed & bright)


def cable_mask(image_rgb, colour, settings=SegmentationSettings()):
    """The cable pixels of one frame.

    Parameters
    ----------
    image_rgb : ndarray, shape (H, W, 3), uint8
    colour : ColourRange
    settings : SegmentationSettings, optional

    Returns
    -------
    mask : ndarray of bool
    width : float
        The cable's width in pixels (0 if there is no cable).
    """
    hsv = _hsv(image_rgb)
    raw = colour.select(hsv)
    # A symmetric kernel: an even one would shift the whole mask by a pixel.
    cross = cv2.getStructuringElement(cv2.MORPH_CROSS, (3, 3))
    raw = cv2.morphologyEx(raw.astype(np.uint8), cv2.MORPH_OPEN, cross) > 0
    width = cable_width(raw)
    if width == 0:
        return raw, 0.0
    mask = _remove_specks(raw, settings.speck_area * width * width)
    if settings.fill_highlights:
        mask = _fill_highlights(mask, hsv, width)
    if colour.has_hue:
        mask = _correct_edges(mask, hsv, settings)
    width = cable_width(mask)
    return mask, width


def _correct_edges(mask, hsv, settings):
    """Drop edge pixels that are only the cable's colour bounced into its own shadow."""
    if not mask.any():
        return mask
    saturation, value = hsv[..., 1].astype(np.float32), hsv[..., 2].astype(np.float32)
    edge = mask & ~(cv2.erode(mask.astype(np.uint8), np.ones((3, 3), np.uint8)) > 0)
    shade = edge & (value < settings.shade_value * np.median(value[mask])) \
        & (saturation < np.median(saturation[mask]))
    return mask & ~shade


def junction_map(mask, width, settings=SegmentationSettings()):
    """Pixels where the cable overlaps itself (§3.1).

    A disc of radius ``junction_radius * width`` around a junction pixel holds more than
    ``junction_ratio`` times the cable pixels of a single straight strand through it
    (``2 * radius * width``).

    Parameters
    ----------
    mask : ndarray of bool
    width : float
        Cable width in pixels (:func:`cable_width`).
    settings : SegmentationSettings, optional

    Returns
    -------
    ndarray of bool
    """
    if width <= 0 or not mask.any():
        return np.zeros_like(mask, dtype=bool)
    radius = max(settings.junction_radius * width, 1.5)
    size = 2 * int(math.ceil(radius)) + 1
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (size, size)).astype(np.float32)
    count = cv2.filter2D(mask.astype(np.float32), -1, kernel, borderType=cv2.BORDER_CONSTANT)
    single = 2.0 * radius * width
    return (count > settings.junction_ratio * single) & mask


def segment_frame(image_rgb, colour, settings=SegmentationSettings()):
    """Mask, junctions and width of one frame."""
    mask, width = cable_mask(image_rgb, colour, settings)
    return FrameSegmentation(mask=mask, junctions=junction_map(mask, width, settings),
                             width=width)

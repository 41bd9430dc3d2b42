"""The cable's outline decided pixel by pixel by a small classifier learnt on synthetic looks.

Most of what a cable's mask gets wrong lies within two pixels of its outline: measured on the
tuning looks, putting the truth in place of the mask there alone lifts the mean IoU from 0.85 to
0.97 (0.94 within one pixel). A colour rule decides those pixels badly where the look departs
from a cable of one colour on a plain table: a black cable's dark rim looks like a shadow, a
cast shadow like a dark rim, a two-tone cable's second colour like the table. Here each pixel
within :data:`REACH` pixels of the mask's outline is decided from what lies around it, in
terms that mean the same on any look:

- the colours along the outline's normal through it (:data:`STEPS`, a pixel apart), each
  placed on the axis from the local background's colour (0) to the local cable's (1), with its
  distance off that axis, its distances from both colours, its chromaticity on the
  chromaticities' axis and its brightness against the background's;
- how far it lies inside or outside the mask.

How strongly cable and background differ is left out: it changes from look to look and photo
to photo, and a network reads such a feature beyond the range it learnt it on (with it, a flat
dark band on a light table was taken for a shadow and half of it dropped).

The cable's colour is the mean of the mask's pixels just inside that band, the background's
the mean of the pixels up to half a cable width beyond it, both within a window of two cable
widths: local, so uneven light or a printed table do not mislead them. Such a window holds
the cable's rim on both of its edges, and a two-tone cable's are of its two colours: where
the rim within a smaller window (:data:`RIM_WINDOW`), on the pixel's side, is of another
chromaticity than the whole window's, and of another hue (:data:`HUE_APART`: not a shade
side of the cable's own hue, tinted by the light around), it is the cable's colour (with the
mean of both, the dark rim of a blue side beside a red one lay off the axis and was taken for
the table).

A small network (one hidden layer of :data:`HIDDEN` units, ``tanh``, logistic output) turns the
features into the pixel's label; its weights (``outline_weights.json`` beside this module)
were learnt on synthetic scenes of tuning seeds only, at several sizes
(:mod:`engine.evaluation.outline_training`, which says how to learn them again). The
decision can be repeated: each pass decides the band around the outline the last pass left.
"""

import functools
import json
import math
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from .pixels import CHROMA_FLOOR, cable_box, chroma, sample_at

__all__ = ["OutlineClassifier", "REACH", "STEPS", "HIDDEN", "outline_features",
           "outline_classifier", "classify_outline"]

#: Pixels within this many pixels of the mask's outline are decided.
REACH = 2
#: Offsets (pixels) along the outline's outward normal where the colours are read.
STEPS = np.arange(-3, 4, dtype=np.float32)
#: Where the cable's rim near a pixel, within a square this many cable widths wide (odd, 3
#: pixels at least: the rim on the pixel's side of the cable), is more than
#: :data:`SECOND_COLOUR` in chromaticity from the rim within the whole window, it is the
#: cable's local colour (see :func:`_colours_around`).
RIM_WINDOW = 0.6
#: How far apart (chromaticity) the near rim and the whole window's are for the near one to
#: be the cable's colour: a two-tone cable's other side, not a shaded rim (a tinted light
#: parts a lit rim from a shaded one by as much, but keeps their hue: :data:`HUE_APART`).
SECOND_COLOUR = 0.05
#: A near rim is of a second colour only if its hue is this many degrees (around grey, in
#: chromaticity) from the whole window's rim, or either is within :data:`GREYISH` times the
#: other's distance of grey: a glossy red cable's shade side, tinted by the light a wooden
#: table throws, is over :data:`SECOND_COLOUR` from its lit side but of its hue.
HUE_APART = 25.0
#: See :data:`HUE_APART`.
GREYISH = 0.5
#: Hidden units of the classifier.
HIDDEN = 16
#: The weights shipped with the engine.
WEIGHTS = Path(__file__).with_name("outline_weights.json")
#: Squared colour distances below this (8-bit levels) are this: a flat patch is no axis.
_LEAST_CONTRAST = 25.0
_LEAST_CHROMA = 0.03**2


@dataclass(frozen=True, eq=False)
class OutlineClassifier:
    """The outline's classifier: features standardised, one hidden layer, a logistic output.

    Attributes
    ----------
    mean, scale : ndarray, shape (F,)
        Features are standardised as ``(features - mean) / scale``.
    hidden, hidden_bias : ndarray, shape (F, H) and (H,)
    output, output_bias : ndarray and float, shape (H,)
    """

    mean: np.ndarray
    scale: np.ndarray
    hidden: np.ndarray
    hidden_bias: np.ndarray
    output: np.ndarray
    output_bias: float

    def __post_init__(self):
        # the standardisation folded into the hidden layer: one product a pixel fewer
        folded = np.asarray(self.hidden, np.float64) / np.asarray(self.scale, np.float64)[:, None]
        object.__setattr__(self, "_folded", folded)
        object.__setattr__(self, "_folded_bias", np.asarray(self.hidden_bias, np.float64)
                           - np.asarray(self.mean, np.float64) @ folded)
        object.__setattr__(self, "_output", np.asarray(self.output, np.float64))
        for name in ("_folded", "_folded_bias", "_output"):
            object.__setattr__(self, name + "32", getattr(self, name).astype(np.float32))

    def logits(self, features):
        """The log-odds of cable for each row of ``features`` (shape (N, F)), in float64: a
        pixel's label must not depend on the BLAS's rounding (the Blender lines' numpy and
        OpenBLAS differ, and their curves are compared to 1e-6 r)."""
        units = np.asarray(features, np.float64) @ self._folded
        units += self._folded_bias
        return np.tanh(units, out=units) @ self._output + self.output_bias

    def labels(self, features):
        """Whether each row of ``features`` is cable: ``logits(features) > 0``, computed in
        float32 (several times faster: float64's ``tanh`` was most of the classifier's
        arithmetic) and in float64 again for the rows whose float32 log-odds lie within
        :meth:`margin` of zero, where float32's rounding could have changed the sign."""
        features = np.asarray(features, np.float32)
        units = features @ self._folded32
        units += self._folded_bias32
        fast = np.tanh(units, out=units) @ self._output32 + np.float32(self.output_bias)
        cable = fast > 0
        unsure = np.flatnonzero(np.abs(fast) <= self.margin(features))
        if len(unsure):
            cable[unsure] = self.logits(features[unsure]) > 0
        return cable

    def margin(self, features):
        """A bound, twice over, on how far the float32 log-odds of :meth:`labels` can lie
        from the exact ones for rows no larger than ``features``' largest in each column.

        Sums of n float32 products are within ``γ(n) = n u / (1 - n u)`` (u = 2⁻²⁴) of the
        sum of the magnitudes whatever the order of summation (Higham, *Accuracy and
        Stability of Numerical Algorithms*, §3.1); the weights' own rounding to float32 adds a
        term to each sum; float32 ``tanh`` is taken to be within 8 u, and a hidden unit's
        error passes through it at most unchanged (its slope is at most 1)."""
        if not len(features):
            return 0.0
        unit = 2.0 ** -24
        gamma = lambda n: n * unit / (1.0 - n * unit)  # noqa: E731
        largest = np.abs(features).max(axis=0).astype(np.float64)
        hidden = gamma(len(largest) + 2) * (largest @ np.abs(self._folded)
                                            + np.abs(self._folded_bias))
        output = np.abs(self._output)
        bound = output @ (hidden + 8 * unit) + gamma(len(output) + 2) * (
            output.sum() + abs(self.output_bias))
        return 2.0 * float(bound)

    def to_dict(self):
        """The weights as plain lists (the JSON file's content)."""
        return {"format": "cable_recon.outline/1", "features": len(self.mean),
                "hidden_units": len(self.hidden_bias), "reach": REACH,
                "steps": STEPS.tolist(),
                **{name: np.asarray(getattr(self, name)).tolist()
                   for name in ("mean", "scale", "hidden", "hidden_bias", "output",
                                "output_bias")}}

    @classmethod
    def from_dict(cls, data):
        """The classifier of :meth:`to_dict`'s output.

        Raises
        ------
        ValueError
            Another format, or weights that do not fit the features.
        """
        if data.get("format") != "cable_recon.outline/1":
            raise ValueError(f"not outline weights: format {data.get('format')!r}")
        if data.get("reach") != REACH or data.get("steps") != STEPS.tolist():
            raise ValueError("the outline weights were learnt on other features")
        arrays = {name: np.asarray(data[name], dtype=np.float32)
                  for name in ("mean", "scale", "hidden", "hidden_bias", "output")}
        features = len(arrays["mean"])
        if (features != FEATURES or arrays["hidden"].shape != (features, len(arrays["output"]))
                or arrays["hidden_bias"].shape != arrays["output"].shape):
            raise ValueError("the outline weights do not fit the features")
        return cls(output_bias=float(data["output_bias"]), **arrays)


@functools.lru_cache(maxsize=1)
def outline_classifier():
    """The classifier shipped with the engine (read once)."""
    return OutlineClassifier.from_dict(json.loads(WEIGHTS.read_text()))


def _window_sums(image, where, window, flat):
    """Sums of the colours of ``where``'s pixels (``image`` uint8) in a ``window``-wide square
    around the pixels ``flat``, and how many they are (float32, exact: integer sums); with a
    tuple of windows, a ``(sums, counts)`` pair for each.

    As a box filter with OpenCV's default border (reflected, the edge pixel once) would give
    them, from the integral image of the frame so bordered: four look-ups a pixel, not a
    filter over the whole box; one integral for every window."""
    windows = (window,) if np.isscalar(window) else tuple(window)
    weight = where.view(np.uint8)
    # colours and count as the four channels of one image: one integral, not two
    four = cv2.merge([*cv2.split(cv2.bitwise_and(image, image, mask=weight)), weight])
    border = max(windows) // 2
    four = cv2.copyMakeBorder(four, border, border, border, border, cv2.BORDER_REFLECT_101)
    # integer sums; past what 32 bits hold (a 4K box), in float64, exact to 2**53
    exact = cv2.CV_32S if four.shape[0] * four.shape[1] * 255 < 2**31 else cv2.CV_64F
    integral = cv2.integral(four, sdepth=exact)
    stride = integral.shape[1]
    rows, cols = np.divmod(flat, where.shape[1])
    corners = _pixels_of(integral)
    found = []
    for size in windows:
        # the window of frame pixel (row, col) covers the bordered frame's rows and columns
        # from (row, col) + border - size // 2, size of each: integral corners there and
        # ``size`` further
        shift = border - size // 2
        corner = (rows + shift) * stride + cols + shift
        total = (_taken(corners, corner + size * stride + size)
                 - _taken(corners, corner + size * stride) - _taken(corners, corner + size)
                 + _taken(corners, corner)).astype(np.float32)
        found.append((total[:, :3], total[:, 3]))
    return found[0] if np.isscalar(window) else found


def _pixels_of(image):
    """A four-channel image's pixels as one item each (a 16-byte item for 32-bit channels:
    gathering whole items is several times faster than gathering rows of four)."""
    pixels = image.reshape(-1, 4)
    return pixels.view(np.complex128).ravel() if pixels.itemsize == 4 else pixels


def _taken(pixels, flat):
    """The four channels of :func:`_pixels_of`'s pixels ``flat``, shape (len(flat), 4)."""
    if pixels.ndim == 2:
        return pixels[flat]
    return pixels.take(flat).view(np.int32).reshape(-1, 4)


def _mean(total, count):
    return total / np.maximum(count, 1e-3)[:, None]


#: Features per pixel: six per step (along the colour axis, off it, along the chromaticity
#: axis, brightness, distance from the cable's colour and from the background's), then depth
#: into the mask.
FEATURES = 6 * len(STEPS) + 1


def outline_features(mask, image_rgb, width):
    """The pixels within :data:`REACH` of the mask's outline and their features.

    Parameters
    ----------
    mask : ndarray of bool, shape (H, W)
    image_rgb : ndarray, shape (H, W, 3), uint8
    width : float
        The cable's width in pixels.

    Returns
    -------
    pixels : ndarray of int64
        Flat indices into the frame.
    features : ndarray of float32, shape (len(pixels), FEATURES)
    """
    width = max(float(width), 3.0)
    window = int(2.0 * width) | 1
    box = cable_box(mask, window + REACH + 4)
    if box is None:
        return np.zeros(0, np.int64), np.zeros((0, FEATURES), np.float32)
    cable = np.ascontiguousarray(mask[box]).view(np.uint8)
    image = np.ascontiguousarray(image_rgb[box])
    inside, outside = _distances(cable)
    inner, outer = inside > REACH, outside > REACH
    flat, nx, ny = _band_normals(cable, ~(inner | outer))
    rows, cols = np.divmod(flat, cable.shape[1])
    cable_colour, background = _colours_around(image, inside, outside, inner, flat, width,
                                               window)
    profile = sample_at(image.astype(np.float32), cols[:, None] + STEPS * nx[:, None],
                        rows[:, None] + STEPS * ny[:, None])
    depth = inside.ravel()[flat] - outside.ravel()[flat]
    features = np.empty((len(flat), FEATURES), np.float32)
    _profile_features(profile, cable_colour, background, features)
    np.clip(depth, -REACH - 1, REACH + 1, out=features[:, -1])
    # flat indices into the frame
    top, left = box[0].start, box[1].start
    return (rows + top) * mask.shape[1] + cols + left, features


def _band_normals(cable, band):
    """The band's pixels (flat indices into ``cable``'s box) where the outline has a
    direction, and its outward unit normal there (from the mask blurred)."""
    smooth = cv2.blur(cable * np.uint8(250), (5, 5))
    out_x = -cv2.Sobel(smooth, cv2.CV_32F, 1, 0)
    out_y = -cv2.Sobel(smooth, cv2.CV_32F, 0, 1)
    flat = np.flatnonzero(band)
    out_x, out_y = out_x.ravel()[flat], out_y.ravel()[flat]
    norm = np.hypot(out_x, out_y)
    usable = norm > 0
    norm = norm[usable]
    return flat[usable], out_x[usable] / norm, out_y[usable] / norm


def _distances(cable):
    """Each pixel's distance (pixels, float32) to the nearest pixel outside the mask (0 off
    it; the frame's edge counts as outside: the cable's outline runs along it) and to the
    nearest pixel of the mask (0 on it)."""
    framed = cv2.copyMakeBorder(cable, 1, 1, 1, 1, cv2.BORDER_CONSTANT, value=0)
    inside = cv2.distanceTransform(framed, cv2.DIST_L2, cv2.DIST_MASK_5)[1:-1, 1:-1]
    outside = cv2.distanceTransform(1 - cable, cv2.DIST_L2, cv2.DIST_MASK_5)
    return np.ascontiguousarray(inside), outside


def _colours_around(image, inside, outside, inner, flat, width, window):
    """The cable's and the background's local colours at the pixels ``flat``: the mean of the
    mask's pixels right inside the band within ``window`` (a glossy cable's highlight farther
    in is not its rim's colour; the whole inside where the rim has none there), or within
    :data:`RIM_WINDOW` cable widths where the rim there is of another chromaticity
    (:data:`SECOND_COLOUR`) and hue (:func:`_another_hue`): a two-tone cable's side, whose rim
    across the cable is the other colour; and of the pixels up to half a width beyond the
    band, within ``window``. ``inner``: the mask's pixels past the band (``inside`` over
    :data:`REACH`)."""
    rim = inner & (inside <= REACH + 2)
    beyond = (outside > REACH) & (outside <= REACH + width // 2)
    near = min(max(int(RIM_WINDOW * width) | 1, 3), window)
    (rim_total, rim_count), (near_total, near_count) = _window_sums(image, rim, (window, near),
                                                                   flat)
    cable_colour = _mean(rim_total, rim_count)
    near_colour = _mean(near_total, near_count)
    near_chroma = chroma(near_colour, CHROMA_FLOOR)
    whole_chroma = chroma(cable_colour, CHROMA_FLOOR)
    apart = near_chroma - whole_chroma
    second = (near_count > 0) & (np.einsum("ij,ij->i", apart, apart) > SECOND_COLOUR**2) \
        & _another_hue(near_chroma, whole_chroma)
    cable_colour[second] = near_colour[second]
    alone = rim_count == 0
    if alone.any():  # the inside's sums only where they are needed (rarely)
        cable_colour[alone] = _mean(*_window_sums(image, inner, window, flat[alone]))
    return cable_colour, _mean(*_window_sums(image, beyond, window, flat))


def _another_hue(first, second):
    """Whether chromaticities ``first`` and ``second`` (rows) are of other hues: more than
    :data:`HUE_APART` apart around grey's, or one of them within :data:`GREYISH` times the
    other's distance of grey (a white or grey side beside a coloured one). One hue more or
    less saturated is a cable's shade side tinted by the light around it, not a second colour."""
    grey = np.float32(1.0 / 3.0)
    a, b = first - grey, second - grey
    na, nb = np.sqrt(np.einsum("ij,ij->i", a, a)), np.sqrt(np.einsum("ij,ij->i", b, b))
    cosine = np.einsum("ij,ij->i", a, b) / np.maximum(na * nb, 1e-9)
    return (cosine < math.cos(math.radians(HUE_APART))) \
        | (np.minimum(na, nb) < GREYISH * np.maximum(na, nb))


def _profile_features(profile, cable_colour, background, features):
    """The six features of every step of the profiles (shape (N, S, 3)), written into
    ``features``' first ``6 * S`` columns, a block of S each: along the colour axis from the
    background (0) to the cable (1), off it, along the chromaticity axis, brightness against
    the background's, distance from the cable's and the background's colours (in lengths of
    the axis). In place where it can be: a band holds tens of thousands of pixels."""
    steps = profile.shape[1]
    blocks = [features[:, column:column + steps] for column in range(0, 6 * steps, steps)]
    # each channel as a plane of its own: arithmetic on contiguous arrays is several times faster
    channels = np.ascontiguousarray(np.moveaxis(profile, -1, 0))
    plain_total = channels[0] + channels[1]
    plain_total += channels[2]
    axis = cable_colour - background
    contrast = np.maximum(np.einsum("ij,ij->i", axis, axis), _LEAST_CONTRAST)[:, None]
    length = np.sqrt(contrast)
    offsets = channels - np.moveaxis(background, -1, 0)[:, :, None]
    along, apart, term = (np.empty_like(plain_total) for _ in range(3))
    np.multiply(offsets[0], axis[:, 0, None], out=along)
    np.multiply(offsets[0], offsets[0], out=apart)
    for c in (1, 2):
        along += np.multiply(offsets[c], axis[:, c, None], out=term)
        apart += np.multiply(offsets[c], offsets[c], out=term)
    along /= contrast
    np.clip(along, -3, 4, out=blocks[0])
    np.square(along, out=term)
    term *= contrast
    np.subtract(apart, term, out=term)
    np.maximum(term, 0.0, out=term)
    np.sqrt(term, out=term)
    term /= length
    np.clip(term, 0, 4, out=blocks[1])
    np.sqrt(apart, out=apart)
    apart /= length
    np.clip(apart, 0, 4, out=blocks[5])
    # the distance from the cable's colour (``offsets`` reused)
    np.subtract(channels, np.moveaxis(cable_colour, -1, 0)[:, :, None], out=offsets)
    np.square(offsets, out=offsets)
    distance = offsets[0] + offsets[1]
    distance += offsets[2]
    np.sqrt(distance, out=distance)
    distance /= length
    np.clip(distance, 0, 4, out=blocks[4])
    # a dark pixel's chromaticity is noise: below CHROMA_FLOOR it is shrunk towards nothing
    total = np.maximum(plain_total, CHROMA_FLOOR)
    background_total = np.maximum(background.sum(axis=1), CHROMA_FLOOR)[:, None]
    shade = background / background_total
    chroma_axis = cable_colour / np.maximum(cable_colour.sum(axis=1), CHROMA_FLOOR)[:, None] \
        - shade
    chroma_contrast = np.maximum(np.einsum("ij,ij->i", chroma_axis, chroma_axis),
                                 _LEAST_CHROMA)[:, None]
    chroma_along = distance  # reused
    for c in range(3):
        part = term if c else chroma_along
        np.divide(channels[c], total, out=part)
        part -= shade[:, c, None]
        part *= chroma_axis[:, c, None]
        if c:
            chroma_along += part
    chroma_along /= chroma_contrast
    np.clip(chroma_along, -3, 4, out=blocks[2])
    plain_total /= background_total
    np.clip(plain_total, 0, 4, out=blocks[3])


def classify_outline(mask, image_rgb, width, *, passes=1, classifier=None):
    """``mask`` with the pixels near its outline decided by the classifier.

    Parameters
    ----------
    mask : ndarray of bool, shape (H, W)
    image_rgb : ndarray, shape (H, W, 3), uint8
    width : float
        The cable's width in pixels.
    passes : int, optional
        How many times the band around the (last) outline is decided.
    classifier : OutlineClassifier, optional
        The engine's own (:func:`outline_classifier`) if None.

    Returns
    -------
    ndarray of bool
        A new mask (``mask`` itself when ``passes`` is 0 or the mask is empty).
    """
    classifier = classifier or outline_classifier()
    for _ in range(passes):
        pixels, features = outline_features(mask, image_rgb, width)
        if not len(pixels):
            break
        mask = np.array(mask, dtype=bool, order="C")
        mask.ravel()[pixels] = classifier.labels(features)
    return mask

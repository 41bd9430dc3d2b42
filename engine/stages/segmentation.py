"""Cable masks and junction maps from images (paper §3.1, and beyond it).

The paper thresholds an HSV range set on one frame. Here the range (set by hand, picked, or
found automatically: :func:`engine.stages.colour_model.find_cable` picks the most cable-like group
of colour clusters, not the most saturated colour) only seeds a colour model of the cable against
the background learnt on a few frames of the sequence (:func:`sequence_colour`,
:class:`engine.stages.colour_model.ColourModel`; a striped cable's second colour, found in the
gaps between its first colour's bands, joins the seed: :mod:`engine.stages.stripes`), then
learnt again from the masks it gives on those frames (:func:`_relearnt`: a found colour is
often a band of the cable only). Each frame's pixels are classified by that model: sure pixels,
and likely ones right beside them (a shade side, a strand darkened under another).
A cable striped in its colour and the table's is found as a row of dashes: each frame's
dashes are bridged along the cable first (:func:`engine.stages.stripes.bridged`).
Specks are removed, the side of the cable its colours missed is put back by the cable's shape
(:mod:`engine.stages.missing_side`), pieces shaped like objects rather than cable are removed,
the desaturated specular streak along a glossy cable is filled back in, the outline is refined
along its normal (:func:`refine_edges`), the pixels near it are decided again by a classifier
learnt on synthetic looks (:mod:`engine.stages.outline`), and the cable's width in pixels is
measured per frame.

Junctions are where the cable overlaps itself: forks of the mask's skeleton where a disc holds
more cable than a single strand can (:func:`junction_centres`). Every length is derived from
the measured width.

HSV values are OpenCV's: hue 0–179 (wrapping: a range whose low hue is above its high hue,
e.g. 170–8, is red), saturation and value 0–255.
"""

import math
from dataclasses import dataclass, replace

import cv2
import numpy as np

from ..settings import check_settings, setting
from .colour_model import (_HUE_APART, _HUED, CableCandidate, ColourModel, _hue_gap, find_cable,
                           find_cables, opened, range_of, reduced, samples, shaped, thin_pieces)
from .colour_range import ColourRange, hsv_image
from .missing_side import with_missing_side
from .outline import classify_outline
from .pixels import CHROMA_FLOOR as _CHROMA_FLOOR
from .pixels import brightness as _brightness
from .pixels import cable_box as _cable_box
from .pixels import chroma as _chroma
from .pixels import sample_at
from .skeleton_2d import fill_small_holes, skeleton_clusters, thin
from .stripes import SEAM_REACH, banded, bridged, with_second_colour
from .union_find import DisjointSets

#: :func:`_shade_side` compares the shade side with the pixels up to this many pixels beyond it.
_AROUND = 2.5

#: :func:`_without_shadow`: a mask is of a cable with a colour of its own when this share of
#: its pixels are farther than ``_COLOURED`` times ``shadow_chroma`` from the background's
#: chromaticity (and more saturated); a pixel of such a mask darker than the background is
#: shadow when nearer the background's chromaticity than ``_SHADOW_GAP`` times the cable's
#: (median) distance from it.
_COLOURED, _COLOURED_SHARE, _SHADOW_GAP = 3.0, 0.25, 1.0 / 3.0

#: :func:`_drop_blobs` measures a piece again with its holes smaller than this many square
#: cable widths filled (a ring around a cylinder's top).
_RING_HOLE = 25.0

#: :func:`calibrated_level` tries the probabilities this far apart and takes the highest whose
#: IoU of the samples is within ``_LEVEL_MARGIN`` of the best one's.
_LEVEL_STEP, _LEVEL_MARGIN = 0.05, 0.01

#: :func:`_drop_blobs`: an object is about convex; a piece of cable thick enough to be one
#: (where strands cross) is not: it fills less than this share of its convex hull.
_SOLID = 0.8

#: :func:`refine_edges` takes the cable's and the background's colours from every this many
#: of their pixels.
_EDGE_SAMPLE = 7

#: The colour and its model are learnt on frames reduced to at most this (longer side, pixels;
#: 4K): they are colours, whatever the size, and the search for the cable costs with the
#: frame's pixels.
_COLOUR_SIZE = 3840

#: :func:`_relearnt`: the background's samples lie farther than this (pixels) from the first
#: masks' pixels but their outline (the cable's lie two pixels inside it): about two pixels
#: either side of the outline, mixed by the frame's blur, are neither.
_RELEARN_RIM = 3.0

#: :func:`_split_by_hue`: seed pixels of saturation and value at least ``_HUED`` have a hue;
#: hues whose peaks lie at least ``_HUE_APART`` apart (OpenCV units, 2 degrees each) and hold
#: ``_HUE_SHARE`` of those pixels each are different cables when each hue's pixels lie mostly
#: (``_THIN_SHARE``) in thin pieces (a stripe's bands do not).
_HUE_SHARE = 0.15
_THIN_SHARE = 0.5

#: :func:`_with_bands`: a model learnt again whose masks cover this share of the first
#: model's bridged masks found a striped cable's second colour.
_WHOLE = 0.7

#: :func:`_joined`: the seam between two cables' masks is filled up to this many cable widths.
_SEAM = 0.15

__all__ = ["ColourRange", "SegmentationSettings", "FrameSegmentation", "SeveralCables",
           "auto_colour", "reference_frames", "sequence_colour", "learn_colour_model",
           "colour_from_masks", "colour_seed", "colour_at", "segment_frame", "segment_all",
           "segment_images", "cable_mask", "refine_edges", "cable_width", "junction_map",
           "junction_centres"]


@dataclass(frozen=True)
class SegmentationSettings:
    """How masks and junctions are made (widths in units of the measured cable width).

    Attributes
    ----------
    speck_area : float
        Connected pieces smaller than ``speck_area * width**2`` pixels are removed.
    fill_highlights : bool
        Fill the desaturated specular streak along a glossy cable.
    highlight_probability : float
        A pixel of the streak must be at least this likely to the colour model (the default:
        any likelihood at all, 2 in 255): a colour the model rules out, because the background
        is full of it, is not the cable's highlight (the table seen in a narrow gap between
        two strands that nearly touch is bright and closed over too). 0 turns this off.
    shade_value, shade_saturation : float
        Edge correction on the shadow side: a mask pixel on the edge leaves it when it is darker
        than ``shade_value`` times the cable's median value and less saturated than
        ``shade_saturation`` times its median (light bounced off the cable tints its shadow
        with the cable's hue, paler; the cable's own shade side keeps its saturation).
    junction_radius : float
        Radius of the counting disc.
    junction_ratio : float
        A junction's disc holds more than this many times the cable pixels a single straight
        strand through the disc would.
    junction_disc : float
        Junction pixels lie within this radius of a junction centre.
    junction_pair : float
        Two skeleton forks closer than this along the skeleton are one shallow crossing.
    junction_spur : float
        Skeleton branches with a free end shorter than this are noise.
    junction_hole : float
        Holes in the mask smaller than this times the width squared are filled before thinning.
    edge_reach : int
        Pixels within this many pixels of the mask's outline are re-decided by their colour
        against the cable's and the background's colours (:func:`refine_edges`) before the
        outline's classifier; 0 (the default) leaves the outline to the classifier. The
        refinement reads one colour for the whole cable, so on a two-tone cable it takes the
        edge between its two colours for the outline and cuts a side off; with it on, the
        classifier (learnt on masks without it) decides the outline less well (README,
        *The outline left to the classifier*).
    edge_contrast : float
        An edge pixel is re-decided only where the local cable and background colours differ
        by at least this much (RGB distance, 8-bit levels).
    model : bool
        Classify pixels by a colour model of the cable against the background learnt from the
        colour range's thin pieces (:class:`ColourModel`), not by the range itself.
    model_frames : int
        The reconstruction learns the model from this many frames spread over the sequence.
    model_smoothing : float
        Smoothing of the model's colour histograms, in bins of 8 levels: colours near the
        cable's (its shading the range missed) count as cable.
    probability : float
        A pixel is cable when the model gives its colour at least this probability, or a
        lower one, down to ``probability_least``, chosen on the frames the model was learnt
        from when it tells their cable samples from their background clearly better
        (:func:`calibrated_level`; a pale cable's colours are common in the background too,
        so few of its pixels reach a probability of one half). ``probability_near`` is
        lowered in proportion.
    probability_least : float
        See ``probability``; ``probability`` or more: the level is never lowered.
    probability_near : float
        Within ``near_reach`` cable widths of such pixels, this probability is enough, or
        being in the colour range.
    near_reach : float
        See ``probability_near``.
    range_share : float
        The colour range counts there only when it holds at most this many times the sure
        pixels.
    blob_elongation, blob_thickness : float
        Pieces of the mask less elongated than ``blob_elongation`` (length over width,
        :func:`thin_pieces`) that hold a disc of radius ``blob_thickness`` cable widths (no
        crossing does, unless the width is underestimated) and are about convex (a crossing
        is not) are objects of the cable's colour, not cable.
    shade_chroma, shade_reach : float
        Within ``shade_reach`` cable widths of sure pixels, pixels of their chromaticity
        (nearer it than ``shade_chroma`` times its distance from the surroundings'
        chromaticity) and darker than the surroundings are the cable's shade side
        (:func:`_shade_side`); ``shade_chroma`` 0 turns this off.
    seed_shade_reach, seed_shade_chroma : float
        The model's cable pixels (:func:`colour_seed`) take in the pixels within
        ``seed_shade_reach`` cable widths of them whose chromaticity is within
        ``seed_shade_chroma`` of theirs: the shade side, which a found colour's clusters
        miss (shading darkens a colour, it keeps its chromaticity). A cable whose
        chromaticity is within twice ``seed_shade_chroma`` of its surroundings' counts as
        colourless: neither this nor ``shade_chroma`` applies.
    stripe_reach : float
        The gaps between a striped cable's bands, up to twice this many cable widths long,
        are looked at for its second colour, which the model then learns as the cable's
        (:mod:`engine.stages.stripes`); where none is (the second colour is the table's)
        and the model's masks are rows of dashes (:func:`engine.stages.stripes.banded`),
        each frame's mask is closed by a disc of this many widths. 0 turns both off.
    all_cables : bool
        Find every cable of its own colour, not only the most cable-like thing (automatic
        colour only): each cable is segmented with its own colour model and the masks are
        their union, so each becomes a path.
    shadow_chroma, shadow_depth : float
        A pixel the colour range or model calls cable is the cable's shadow when it is of
        the local background's chromaticity (within ``shadow_chroma``), darker than it, and
        lighter than the cable: its share of the background's brightness over
        ``shadow_depth`` times that of the mask's darkest quarter (:func:`_without_shadow`);
        ``shadow_chroma`` 0 keeps every pixel. Of a cable with a colour of its own (a
        quarter of its pixels over ``3 * shadow_chroma`` from the background's
        chromaticity, and more saturated), a shadow may be darker than the cable, and
        nearer the background's chromaticity than a third of the cable's distance from it
        is enough; of a colourless cable on a tinted table (as many pixels as far, but not
        more saturated), that reach holds too, and a pixel is lighter than the cable from
        those far pixels' median share up.
    side_reach, side_chroma, side_contrast, side_contact : float
        The side of the cable its colours missed is put back
        (:func:`engine.stages.missing_side.with_missing_side`): pixels within ``side_reach``
        cable widths of the mask's thin pieces that differ from the background around them
        by more than ``side_chroma`` in chromaticity and ``side_contrast`` in colour, in
        pieces that run along the mask for at least ``side_contact`` cable widths; searched
        before the outline's classifier and again after it (``outline_passes`` over 0).
        ``side_reach`` 0 turns both off. Not with ``all_cables``.
    outline_passes : int
        The pixels within two pixels of the mask's outline are decided by a classifier learnt
        on synthetic looks (:mod:`engine.stages.outline`), this many times, each around the
        last outline; 0 keeps the refined outline.
    width_floor : float
        A cable is about as wide in every view of a sequence: a frame whose cable width
        comes out under ``width_floor`` times the median over the frames (where only a
        glossy grey cable's highlight was found, say) is segmented again with that width as
        the least it can be (:func:`segment_all`); 0 turns this off.
    relearn : bool
        The automatically found cable's colour model is learnt a second time, from the masks
        the first one gives on the frames it was learnt from: a found colour is often a band
        of the cable only (a glossy grey cable's highlight), and the first model takes the
        rest of the cable for background. With ``all_cables`` each cable's model is learnt
        again from its own masks. Not with a colour given.
    """

    speck_area: float = setting(3.0, low=0, unit="widths²")
    fill_highlights: bool = True
    highlight_probability: float = setting(0.004, low=0, high=1)
    shade_value: float = setting(0.5, low=0, high=1)
    shade_saturation: float = setting(0.95, low=0, high=1)
    junction_radius: float = setting(1.5, above=0, unit="widths")
    junction_ratio: float = setting(1.33, above=0)
    junction_disc: float = setting(1.0, low=0, unit="widths")
    junction_pair: float = setting(2.5, low=0, unit="widths")
    junction_spur: float = setting(1.0, low=0, unit="widths")
    junction_hole: float = setting(0.5, low=0, unit="widths²")
    edge_reach: int = setting(0, low=0, unit="px")
    edge_contrast: float = setting(20.0, low=0, unit="levels")
    model: bool = True
    model_frames: int = setting(3, low=1)
    model_smoothing: float = setting(1.0, low=0, unit="bins")
    probability: float = setting(0.5, low=0, high=1)
    probability_least: float = setting(0.1, low=0, high=1)
    probability_near: float = setting(0.4, low=0, high=1)
    near_reach: float = setting(0.5, low=0, unit="widths")
    range_share: float = setting(3.0, low=0)
    blob_elongation: float = setting(10.0, low=0)
    blob_thickness: float = setting(1.0, low=0, unit="widths")
    shade_chroma: float = setting(0.4, low=0)
    shade_reach: float = setting(0.75, low=0, unit="widths")
    seed_shade_reach: float = setting(0.8, low=0, unit="widths")
    seed_shade_chroma: float = setting(0.03, low=0)
    stripe_reach: float = setting(1.5, low=0, unit="widths")
    shadow_chroma: float = setting(0.02, low=0)
    shadow_depth: float = setting(1.5, low=0)
    side_reach: float = setting(1.1, low=0, unit="widths")
    side_chroma: float = setting(0.02, low=0)
    side_contrast: float = setting(20.0, low=0, unit="levels")
    side_contact: float = setting(2.0, low=0, unit="widths")
    outline_passes: int = setting(2, low=0)
    width_floor: float = setting(0.9, low=0, high=1)
    relearn: bool = True
    all_cables: bool = False

    def __post_init__(self):
        check_settings(self)


@dataclass(frozen=True, eq=False)
class SeveralCables:
    """Every cable found (``SegmentationSettings.all_cables``): what :func:`segment_frame`
    takes as its ``model`` to segment each and join the masks.

    Attributes
    ----------
    cables : tuple of (ColourRange, ColourModel or None)
        Each cable's colour and colour model, the most cable-like first.
    """

    cables: tuple

    def __post_init__(self):
        if not self.cables:
            raise ValueError("SeveralCables needs at least one cable")
        object.__setattr__(self, "cables", tuple(self.cables))


@dataclass(frozen=True, eq=False)
class FrameSegmentation:
    """One frame's result: cable mask, junction map and the cable's width in pixels."""

    mask: np.ndarray
    junctions: np.ndarray
    width: float


def _hue_peak(hues, weights=None):
    histogram = np.bincount(hues.ravel(), weights=None if weights is None else weights.ravel(),
                            minlength=180)[:180].astype(float)
    smooth = np.convolve(np.concatenate([histogram[-5:], histogram, histogram[:5]]),
                         np.ones(5) / 5, mode="same")[5:-5]
    return int(np.argmax(smooth))


def auto_colour(image_rgb):
    """The cable colour of one frame, found automatically (:func:`sequence_colour`).

    Returns
    -------
    ColourRange
    """
    return sequence_colour([image_rgb], settings=SegmentationSettings(model=False))[0]


def reference_frames(count, reference, number):
    """``number`` frame indices spread over a sequence of ``count``, ``reference`` first."""
    spread = np.linspace(0, count - 1, max(number, 1) + 1).astype(int)
    others = [int(k) for k in spread if k != reference]
    return [reference] + list(dict.fromkeys(others))[:max(number - 1, 0)]


def sequence_colour(frames, colour=None, settings=SegmentationSettings()):
    """The cable's colour and colour model of a sequence, from a few of its frames.

    Parameters
    ----------
    frames : sequence of ndarray
        A few frames spread over the sequence (:func:`reference_frames`), RGB uint8; the
        automatic colour's candidates come from the first. Frames over :data:`_COLOUR_SIZE`
        pixels are reduced first.
    colour : ColourRange, optional
        Set by hand or picked; found automatically if None.
    settings : SegmentationSettings, optional

    Returns
    -------
    colour : ColourRange
        The (first) cable's colour.
    model : ColourModel, SeveralCables or None
        None when ``settings.model`` is off or the range has no thin piece in the frames; with
        ``settings.all_cables`` and no ``colour`` given, every cable found
        (:class:`SeveralCables`, hues split by :func:`_split_by_hue`).
    """
    frames = [reduced(frame, _COLOUR_SIZE) for frame in frames]
    if colour is not None:
        return colour, learn_colour_model(frames, colour, settings) if settings.model else None
    if not settings.all_cables:
        colour, candidate = find_cable(frames)
        seeds = [colour_seed(frame, candidate, settings) for frame in frames]
        colour, model = _learnt(frames, seeds, colour, settings)
        relearnt = _relearnt(frames, seeds, colour, model, settings)
        return colour, _with_bands(frames, colour, model, settings, relearnt)
    # split by hue first, then each cable's shade side is found with its own colour
    bare = replace(settings, seed_shade_reach=0.0)
    parts = [(colour, part) for colour, candidate in find_cables(frames)
             for part in _split_by_hue(frames, [colour_seed(frame, candidate, bare)
                                                for frame in frames])]
    if settings.seed_shade_reach > 0:
        parts = [(colour, [(_with_shade(frame, seed, objects, width, settings)
                            if seed.any() else seed, objects, width)
                           for frame, (seed, objects, width) in zip(frames, part)])
                 for colour, part in parts]
    # each cable's model learnt again from its own masks, without the missing side as a run
    # segments each cable (_several_masks), its specks removed cable by cable
    alone = replace(settings, side_reach=0.0)
    cables = []
    for colour, part in parts:
        colour, model = _learnt(frames, part, colour, settings)
        relearnt = _relearnt(frames, part, colour, model, alone)
        cables.append((colour, _with_bands(frames, colour, model, settings, relearnt)))
    return cables[0][0], SeveralCables(cables)


def colour_from_masks(frames, masks, settings=SegmentationSettings()):
    """The cable's colour and colour model learnt from given cable masks of a few frames
    (masks corrected by hand, or the truth, as the looks bench's *oracle seed* does) instead
    of a found or picked colour's thin pieces.

    Parameters
    ----------
    frames : sequence of ndarray
        RGB uint8.
    masks : sequence of ndarray of bool
        The cable's pixels in each frame.
    settings : SegmentationSettings, optional

    Returns
    -------
    colour : ColourRange
        The range around the masks' pixels.
    model : ColourModel or None
        None when ``settings.model`` is off.

    Raises
    ------
    ValueError
        The masks hold no pixel, or their number is not the frames'.
    """
    frames, masks = list(frames), [np.asarray(mask, dtype=bool) for mask in masks]
    if len(frames) != len(masks):
        raise ValueError(f"{len(frames)} frames but {len(masks)} masks")
    if not any(mask.any() for mask in masks):
        raise ValueError("the masks hold no cable pixel")
    seeds = [(mask, np.zeros_like(mask), cable_width(mask)) for mask in masks]
    colour, model = _learnt(frames, seeds, None, settings)
    return colour, _with_bands(frames, colour, model, settings)


def _learnt(frames, seeds, colour, settings):
    """``(colour, model)`` of one cable from its seeds in the frames: the range around the
    seeds (which hold the shade side the candidate's clusters miss; ``colour`` if they are
    empty) and the model learnt from them."""
    pixels = np.concatenate([hsv_image(frame)[seed] for frame, (seed, _, _) in zip(frames, seeds)])
    if len(pixels):
        colour = range_of(pixels, shade=1.0)
    return colour, _model_of(frames, seeds, settings) if settings.model else None


def _relearnt(frames, seeds, colour, model, settings):
    """``model`` learnt again from the masks it gives on the frames it was learnt from (with
    ``settings.relearn``; ``model`` itself without it, or when it is None).

    A found colour's clusters are often one band of the cable only: a glossy grey cable's
    highlight, one colour of a cable two-toned in long sections. The first model learns the
    rest of the cable as background (a strand in shade, without a highlight, wholly), and only
    the masks' later steps (the missing side, the outline's classifier) put part of it back.
    Those masks are far nearer the cable than the seed, and a model learnt from them finds
    more of it (tuning look neutral seed 2 at 24 views: the first model's pixels cover a third
    of the cable, and the masks' IoU goes 0.91 -> 0.94; patterned seed 23, red and white
    sections, 0.70 -> 0.82 at 640x480).

    The cable's samples are the masks' pixels but those within two pixels of their outline
    (mixed), the background's those beyond :data:`_RELEARN_RIM` pixels of them: the first
    learning left a seed's width between the two (the seed narrower than the cable), where a
    shadow beside the cable lies; left again, the shadow is learnt as neither and joins the
    cable (neutral seed 11: IoU 0.949 learnt once; learnt again with a gap of the masks' cable
    width 0.844, with this one 0.978). A frame whose mask is empty keeps its seed. A model
    whose masks are rows of dashes may keep its first learning (:func:`_with_bands`)."""
    if not settings.relearn or model is None:
        return model
    again = []
    for frame, (seed, objects, width) in zip(frames, seeds):
        mask = _cable_masks(frame, colour, settings, model)[0]
        core = cv2.erode(mask.view(np.uint8), np.ones((3, 3), np.uint8)) > 0
        again.append((core, objects & ~mask, _RELEARN_RIM) if core.any()
                     else (seed, objects, width))
    return _model_of(frames, again, settings) or model


def _split_by_hue(frames, seeds):
    """A cable's seeds (:func:`colour_seed` per frame) split into one set per cable when they
    hold cables of clearly different hues (two cables crossing are often found as one thin
    object of two colours); ``[seeds]`` otherwise. Pixels without a hue (dark, grey) go with
    the nearest pixel that has one."""
    hsvs = [hsv_image(frame) for frame in frames]
    hues = np.concatenate([hsv[seed][:, 0] for hsv, (seed, _, _) in zip(hsvs, seeds)
                           if seed.any()] or [np.zeros(0, np.uint8)])
    hued = np.concatenate([(hsv[seed][:, 1] >= _HUED) & (hsv[seed][:, 2] >= _HUED)
                           for hsv, (seed, _, _) in zip(hsvs, seeds) if seed.any()]
                          or [np.zeros(0, bool)])
    peaks = _hue_peaks(hues[hued])
    if len(peaks) < 2:
        return [seeds]
    parts = [[] for _ in peaks]
    for hsv, (seed, objects, width) in zip(hsvs, seeds):
        nearest = _nearest_peak(hsv, seed, peaks)
        for number, part in enumerate(parts):
            mask = nearest == number
            part.append((mask, objects, cable_width(mask) if mask.any() else width))
    for part in parts:  # a stripe's bands are short pieces, not a cable
        area = sum(np.count_nonzero(mask) for mask, _, _ in part)
        thin_area = sum(np.count_nonzero(thin[labels]) for labels, thin, _, _ in
                        (thin_pieces(mask) for mask, _, _ in part))
        if thin_area < _THIN_SHARE * max(area, 1):
            return [seeds]
    return parts


def _hue_peaks(hues):
    """Peaks of a circular hue histogram, each holding ``_HUE_SHARE`` of the pixels (within
    half ``_HUE_APART`` of it) and ``_HUE_APART`` from a larger one."""
    if len(hues) == 0:
        return []
    histogram = np.bincount(hues.astype(np.int64), minlength=180)[:180].astype(float)
    reach = _HUE_APART // 2
    window = np.ones(2 * reach + 1)
    mass = np.convolve(np.concatenate([histogram[-reach:], histogram, histogram[:reach]]),
                       window, mode="valid")
    peaks = []
    for hue in np.argsort(-mass, kind="stable"):
        if mass[hue] < _HUE_SHARE * len(hues):
            break
        if all(_hue_gap(hue, p) >= _HUE_APART for p in peaks):
            peaks.append(int(hue))
    return peaks


def _nearest_peak(hsv, seed, peaks):
    """Per pixel of ``seed``: the index of the hue peak nearest its hue (pixels without a hue:
    that of the nearest seed pixel with one); -1 off the seed."""
    nearest = np.full(seed.shape, -1, dtype=np.int64)
    if not seed.any():
        return nearest
    hue = hsv[..., 0].astype(np.int64)
    closest = np.argmin(np.stack([_hue_gap(hue, p) for p in peaks]), axis=0)
    hued = seed & (hsv[..., 1] >= _HUED) & (hsv[..., 2] >= _HUED)
    if not hued.any():
        return nearest
    _, labels = cv2.distanceTransformWithLabels((~hued).view(np.uint8), cv2.DIST_L2, 5,
                                                labelType=cv2.DIST_LABEL_PIXEL)
    rows, cols = np.nonzero(hued)
    owner = np.zeros(labels.max() + 1, dtype=np.int64)
    owner[labels[rows, cols]] = closest[rows, cols]
    nearest[seed] = owner[labels[seed]]
    return nearest


def colour_at(image_rgb, x, y, *, radius=3):
    """The cable colour under a picked pixel (column ``x``, row ``y``).

    Returns
    -------
    ColourRange
        A hue band around the picked colour with saturation and value ranges that admit its
        shading; a brightness range if the picked pixel has no colour of its own.
    """
    hsv = hsv_image(image_rgb)
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
    rows, cols = np.nonzero(mask.any(axis=1))[0], np.nonzero(mask.any(axis=0))[0]
    if not len(rows):
        return 0.0
    mask = np.pad(mask[rows[0]:rows[-1] + 1, cols[0]:cols[-1] + 1], 1)
    # the 5x5 mask: close to the exact transform at a fraction of its cost
    distance = cv2.distanceTransform(mask.astype(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_5)
    ridge = (distance >= cv2.dilate(distance, np.ones((3, 3), np.uint8))) & mask
    # Pixel centres: a band w pixels wide peaks at (w + 1) / 2 when w is odd and at w / 2 on
    # its two middle rows when w is even; 2 d - 1/2 is within half a pixel of both.
    return float(max(2.0 * np.median(distance[ridge]) - 0.5, 1.0))


def _at_least(width, least):
    """``width``, raised to ``least`` unless it is 0 (no cable)."""
    return max(width, least) if width > 0 else width


def _rough_width(mask, least_width):
    """``mask`` (bool) at half size and the full-size width measured on it (raised to
    ``least_width``): a rough width, enough to size the clean-up, costs a quarter of a full
    one."""
    half = cv2.resize(mask.view(np.uint8), (mask.shape[1] // 2, mask.shape[0] // 2),
                      interpolation=cv2.INTER_AREA) > 0
    return half, _at_least(2.0 * cable_width(half), least_width)


def _remove_specks(mask, half, min_area):
    """``mask`` without pieces under ``min_area`` pixels, judged on its half-size copy."""
    kept = np.zeros(half.shape, dtype=np.uint8)
    box = _cable_box(half, 1)  # the pieces' box (with room for the dilation) is enough
    if box is None:
        return np.zeros_like(mask)
    count, labels, stats, _ = cv2.connectedComponentsWithStats(
        np.ascontiguousarray(half[box]).view(np.uint8), 8)
    keep = stats[:, cv2.CC_STAT_AREA] >= min_area / 4.0
    keep[0] = False
    kept[box] = cv2.dilate(keep[labels].astype(np.uint8), np.ones((3, 3), np.uint8))
    # to the mask's own size (an odd last row or column too)
    kept = cv2.resize(kept, (mask.shape[1], mask.shape[0]), interpolation=cv2.INTER_NEAREST)
    return mask & (kept > 0)


def _fill_highlights(mask, hsv, width, likely=None):
    """Bridge the bright, desaturated streak a glossy cable shows along its middle: what a
    closing adds that is as bright as the mask's brighter pixels (and, where ``likely`` is
    given, a colour the model does not rule out: the table seen between two strands that
    nearly touch is closed over and bright too)."""
    span = max(int(round(width * 0.6)), 1) | 1
    closed = cv2.morphologyEx(mask.view(np.uint8), cv2.MORPH_CLOSE,
                              cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (span, span))) > 0
    closed &= hsv[..., 2] >= _channel_percentile(hsv, 2, mask, 60)
    if likely is not None:
        closed &= likely
    return mask | closed


def colour_seed(image_rgb, colour, settings=SegmentationSettings()):
    """The cable's sure pixels in a frame: the thin pieces of a colour range's (or a found
    candidate's) pixels with their shade side (:func:`_with_shade`); the pieces shaped like
    objects; the cable's width. A found candidate's pieces are shaped as they were scored
    (:func:`engine.stages.colour_model.shaped`, with its shadow's clusters), and only its own
    colours' pixels in them are the seed.

    Parameters
    ----------
    image_rgb : ndarray
    colour : ColourRange or CableCandidate
    settings : SegmentationSettings, optional

    Returns
    -------
    seed, objects : ndarray of bool
    width : float
    """
    if isinstance(colour, CableCandidate):  # shaped as it was scored, with its shadow
        selected, cast = colour.select_with_shadow_rgb(image_rgb)
        labels, thin, half_width, area = thin_pieces(shaped(selected | cast))
        seed = opened(thin[labels] & selected)
    else:
        labels, thin, half_width, area = thin_pieces(opened(colour.select_rgb(image_rgb)))
        seed = thin[labels]
    width = cable_width(seed)
    objects = ~thin & (half_width > 0.5 * width) & (area > 4 * width * width)
    objects[0] = False
    objects = objects[labels]
    if seed.any() and settings.seed_shade_reach > 0:
        seed = _with_shade(image_rgb, seed, objects, width, settings)
    return seed, objects, width


def _with_shade(image_rgb, seed, objects, width, settings):
    """``seed`` and the pixels within ``seed_shade_reach`` widths of it of its chromaticity
    (within ``seed_shade_chroma``), neither too dark to have one nor in ``objects``; the seed
    alone when its chromaticity is its surroundings' (a colourless cable)."""
    reach = settings.seed_shade_reach * width
    near = _within(seed, reach)
    around = _within(near, reach) & ~near
    # chromaticities of the pixels that matter only, not of the whole frame
    inside, gap = _chroma_gap(_chroma(image_rgb[seed]), _chroma(image_rgb[around]))
    if gap < 2 * settings.seed_shade_chroma:
        return seed
    rows, cols = np.nonzero(near & ~seed & ~objects)
    pixels = image_rgb[rows, cols]
    grow = (np.linalg.norm(_chroma(pixels) - inside, axis=-1) < settings.seed_shade_chroma) \
        & (_brightness(pixels) >= _CHROMA_FLOOR)
    grown = seed.copy()
    grown[rows[grow], cols[grow]] = True
    return grown


def learn_colour_model(images_rgb, colour, settings=SegmentationSettings()):
    """A colour model of the cable learnt from frames and a colour (:func:`colour_seed`).

    Parameters
    ----------
    images_rgb : sequence of ndarray
    colour : ColourRange or CableCandidate
    settings : SegmentationSettings, optional

    Returns
    -------
    ColourModel or None
        None when the colour has no thin piece in any of the frames (the range is then used
        as it is).
    """
    images_rgb = list(images_rgb)
    model = _model_of(images_rgb, [colour_seed(image, colour, settings) for image in images_rgb],
                      settings)
    return _with_bands(images_rgb, colour, model, settings)


def _model_of(images_rgb, seeds, settings):
    """:func:`learn_colour_model` from the frames' :func:`colour_seed` results."""
    if not any(seed.any() for seed, _, _ in seeds):
        return None
    seeds = with_second_colour(images_rgb, seeds, settings.stripe_reach)
    try:
        model = ColourModel.learn(images_rgb, [seed for seed, _, _ in seeds],
                                  widths=[width for _, _, width in seeds],
                                  others=[objects for _, objects, _ in seeds],
                                  smoothing=settings.model_smoothing)
    except ValueError:
        return None
    model.level = calibrated_level(model, images_rgb, seeds, settings)
    return model


def _with_bands(images_rgb, colour, model, settings, relearnt=None):
    """The model to segment with: ``relearnt`` (``model`` learnt again, :func:`_relearnt`; None:
    ``model`` itself), or ``model`` marked
    :attr:`~engine.stages.colour_model.ColourModel.banded` when the masks it gives on the
    frames it was learnt from are rows of dashes under a speck's area
    (:func:`engine.stages.stripes.banded`: a cable striped in its colour and another) and
    learning again did not find the other colour.

    Learning again from the first model's masks finds a striped cable's second colour where
    it is not the table's (its dashes touch here and there, and those pieces are learnt
    from): the masks of the model learnt again then cover as much as the first model's
    bridged ones (:data:`_WHOLE` of their area), and are nearer the cable (patterned tuning
    seeds 44 and 51, yellow and blue on dark tiles, magenta and green on wood: 0.90 IoU
    learnt again, 0.84 and 0.85 bridged). Where it is the table's, the model learnt again
    covers less, a thin line of the cable or its shadow (seed 62: 0.03 IoU), and the first
    one, bridged, is kept (0.74). A model learnt from bridged masks would learn the table's
    colours in their gaps as the cable's (seeds 132 and 62: 0.51 and 0.55). The model learnt
    again is marked :attr:`~engine.stages.colour_model.ColourModel.seams`: its masks are bands
    of both colours, parted by the seams between them (seed 54, orange and blue bands on teal
    tiles: 0.73 IoU, 0.88 with the seams closed). Its masks are compared with the seams open:
    closed, the model learnt again from seed 132's grey table wins and takes it in (0.77 ->
    0.67)."""
    relearnt = model if relearnt is None else relearnt
    if not isinstance(model, ColourModel) or settings.stripe_reach <= 0:
        return relearnt
    dashes = [opened(_model_mask(image, model, settings)[1]) for image in images_rgb]
    widths = [_rough_width(mask, 0.0)[1] for mask in dashes]
    if not banded(dashes, widths, settings.stripe_reach, settings.speck_area):
        return relearnt
    model.banded = True
    if relearnt is not model and (_masks_area(images_rgb, colour, relearnt, settings)
                                  >= _WHOLE * _masks_area(images_rgb, colour, model, settings)):
        model.banded, relearnt.seams = False, True
        return relearnt
    return model


def _masks_area(images_rgb, colour, model, settings):
    """How many pixels the model's masks of the frames hold, together."""
    return sum(np.count_nonzero(_cable_masks(image, colour, settings, model)[0])
               for image in images_rgb)


def _probability(model, image_rgb):
    """The model's probability of each pixel, 0 to 255, smoothed a little (a pixel's colour
    is noisy; its neighbours' agree)."""
    return cv2.GaussianBlur(model.probability(image_rgb), (3, 3), 0)


def calibrated_level(model, images_rgb, seeds, settings=SegmentationSettings()):
    """The probability from which ``model`` calls a pixel the cable, chosen on the frames it
    was learnt from.

    Each level from ``settings.probability`` down to ``settings.probability_least``
    (:data:`_LEVEL_STEP` apart) is scored by how well it tells the frames' cable samples from
    their background samples (:func:`engine.stages.colour_model.samples`): the IoU of the
    pixels at or above it with the cable samples. The highest level within
    :data:`_LEVEL_MARGIN` of the best score is taken: a lower level only where it is clearly
    better (a pale cable's colours, common in the background, get a low probability).

    Parameters
    ----------
    model : ColourModel
    images_rgb : sequence of ndarray
    seeds : sequence of (ndarray, ndarray, float)
        Per frame, the cable's seed, the objects of its colour and its width
        (:func:`colour_seed`).
    settings : SegmentationSettings, optional

    Returns
    -------
    float
    """
    top = settings.probability
    if settings.probability_least >= top:
        return top
    levels = np.round(np.arange(top, settings.probability_least - 1e-6, -_LEVEL_STEP), 6)
    steps = np.ceil(255.0 * levels).astype(int)
    found, false, cable = np.zeros(len(levels)), np.zeros(len(levels)), 0
    for image, (seed, objects, width) in zip(images_rgb, seeds):
        if not seed.any():
            continue
        inside, far = samples(seed, width, objects)
        probability = _probability(model, image)
        # counts at or above each level, from a histogram of the probabilities
        counts = [np.cumsum(np.bincount(probability[where], minlength=256)[::-1])[::-1]
                  for where in (inside, far)]
        found += counts[0][steps]
        false += counts[1][steps]
        cable += np.count_nonzero(inside)
    if cable == 0:
        return top
    score = found / (cable + false)
    return float(levels[np.flatnonzero(score >= score.max() - _LEVEL_MARGIN)[0]])


def _model_mask(image_rgb, model, settings, in_range=None, least_width=0.0):
    """Pixels the model calls cable: ``(sure, sure or likely, probability)``, the last the
    model's probability of each pixel (0 to 255, :func:`_probability`). Sure at ``probability``;
    likely within half a cable width of a sure one, at ``probability_near`` or inside the
    colour range (a cable's shade side, or a strand darkened where another passes over it,
    is a colour the background has too, but not right beside the cable). The range counts
    only when it holds at most ``range_share`` times the sure pixels (a range around a
    striped cable holds the whole frame). The shade side beside sure pixels is likely too
    (:func:`_shade_side`)."""
    probability = _probability(model, image_rgb)
    level = settings.probability if model.level is None else model.level
    sure = probability >= 255.0 * level
    if not settings.probability_near < settings.probability:
        return sure, sure, probability
    # lowered with the level
    near_level = settings.probability_near * level / settings.probability
    small = cv2.resize(sure.view(np.uint8), (sure.shape[1] // 2, sure.shape[0] // 2),
                       interpolation=cv2.INTER_AREA) > 0
    # the half-size width is half the full-size width
    width = _at_least(2.0 * cable_width(opened(small)), least_width)
    near_reach = max(settings.near_reach * width, 1.0)
    shade_reach = max(settings.shade_reach * width, 1.0) if settings.shade_chroma > 0 else 0.0
    # the rest happens on the box of the sure pixels grown by the reaches
    box = _cable_box(sure, int(math.ceil(max(near_reach, shade_reach) + _AROUND)) + 1)
    if box is None:
        return sure, sure, probability
    distance = cv2.distanceTransform(np.ascontiguousarray(~sure[box]).view(np.uint8),
                                     cv2.DIST_L2, cv2.DIST_MASK_5)
    likely = probability[box] >= 255.0 * near_level
    if in_range is not None and (np.count_nonzero(in_range)
                                 <= settings.range_share * np.count_nonzero(sure)):
        likely |= in_range[box]
    likely &= distance <= near_reach
    if shade_reach > 0:
        likely |= _shade_side(image_rgb[box], sure[box], distance, shade_reach, settings)
    mask = sure.copy()
    mask[box] |= likely
    return sure, mask, probability


def _shade_side(image_rgb, sure, distance, reach, settings):
    """The pixels within ``reach`` of the ``sure`` ones (``distance`` from them) that are the
    cable's shade side: of the sure pixels' chromaticity (nearer it than ``shade_chroma``
    times its distance from the surroundings' chromaticity; shading keeps a colour's
    chromaticity), and darker than the surroundings (the pixels up to :data:`_AROUND` pixels
    farther; a brighter pixel of that chromaticity beside a cable is its glow or light it
    throws on the table). No pixel for a cable of its surroundings' chromaticity (closer than
    ``2 * seed_shade_chroma``, the same cut-off as the seed's)."""
    side = np.zeros(sure.shape, dtype=bool)  # contiguous: written through ravel()
    around = (distance > reach) & (distance <= reach + _AROUND)
    # the colours of every third row and column are plenty
    sample = image_rgb[::3, ::3]
    surroundings = sample[around[::3, ::3]]
    inside, gap = _chroma_gap(_chroma(sample[sure[::3, ::3]]), _chroma(surroundings))
    if gap < 2.0 * settings.seed_shade_chroma:
        return side
    # flat indices: a third faster than rows and columns
    near = np.flatnonzero((distance <= reach) & ~sure)
    pixels = cv2.blur(image_rgb, (3, 3)).reshape(-1, 3)[near]  # a dark pixel's chroma is noisy
    brightness = _brightness(pixels)
    offset = _chroma(pixels) - inside
    shade = (np.einsum("ij,ij->i", offset, offset) < (settings.shade_chroma * gap) ** 2) \
        & (brightness >= _CHROMA_FLOOR) \
        & (brightness < np.median(_brightness(surroundings)))
    side.ravel()[near[shade]] = True
    return side


def _without_shadow(mask, image_rgb, width, settings):
    """``mask`` without the shadow it took in (a dark cable's soft shadow is as dark as the
    cable to a colour range or model).

    A shadow is the background, darker: a mask pixel is shadow when its chromaticity is the
    local background's (within ``shadow_chroma``; the background: the pixels up to a cable
    width outside the mask, averaged over a few widths around the pixel), it is darker than
    that background, and it is lighter than the cable: its brightness, as a share of the
    background's, is over ``shadow_depth`` times that of the mask's darkest quarter. A cable
    of the background's chromaticity and about as dark as a shadow (a grey cable on a grey
    table) keeps every pixel; a pixel too dark for a chromaticity is kept too. ``width``: the
    mask's width in pixels, which sizes the background's ring and neighbourhood.

    A cable with a colour of its own (at least :data:`_COLOURED_SHARE` of the mask's pixels
    farther than :data:`_COLOURED` times ``shadow_chroma`` from the background's chromaticity
    and farther from grey's than it; :func:`_shadow_rule`) is told from a shadow by
    chromaticity alone: under a hard light its shadow is darker than the cable, and light
    from the sky tints it, so a darker pixel than the background is shadow when nearer the
    background's chromaticity than :data:`_SHADOW_GAP` times the cable's median distance from
    it (and at least ``shadow_chroma``), decided pixel by pixel at full size where a
    half-size pixel may hold both.

    A colourless cable on a tinted table (a quarter of its pixels as far from the background's
    chromaticity as a cable of its own colour's, but no more saturated than the background)
    keeps the rule of a cable darker than its shadow, with two changes measured from those
    far pixels, the cable's own: a pixel near the background's chromaticity (the reach of a
    cable with a colour of its own) is shadow from the cable's median brightness up (as a
    share of the background's), not only from ``shadow_depth`` times the darkest quarter's.
    A soft shadow beside a dark grey cable on a green table is darker than that quarter's
    bound, and the mask took it whole (tuning look neutral seed 14: IoU 0.83 -> 0.93).
    """
    box = _cable_box(mask, int(math.ceil(3 * width)) + 2)
    if box is None or width == 0:
        return mask
    cable = mask[box]
    # the background is smooth enough to be averaged at half size (a quarter of the cost)
    size = (max(cable.shape[1] // 2, 1), max(cable.shape[0] // 2, 1))
    small = cv2.resize(np.ascontiguousarray(cable).view(np.uint8), size,
                       interpolation=cv2.INTER_AREA) > 0
    image = cv2.resize(np.ascontiguousarray(image_rgb[box]), size,
                       interpolation=cv2.INTER_AREA).astype(np.float32)
    distance = cv2.distanceTransform(np.ascontiguousarray(~small).view(np.uint8),
                                     cv2.DIST_L2, cv2.DIST_MASK_5)
    ring = ((distance > 0.5) & (distance <= 0.5 + 0.5 * width)).astype(np.float32)
    kernel = (2 * int(math.ceil(width)) + 1,) * 2
    weight = cv2.blur(ring, kernel)
    total = cv2.blur(image * ring[..., None], kernel)
    # decided at half size too: a shadow is wide and soft
    rows, cols = np.nonzero(small & (weight > 1e-3))
    if not len(rows):
        return mask
    pixels, behind = image[rows, cols], total[rows, cols] / weight[rows, cols, None]
    brightness = _brightness(pixels)
    share = brightness / np.maximum(_brightness(behind), 1.0)
    lit = brightness >= _CHROMA_FLOOR
    offset, lightest, reach, own_colour = _shadow_rule(pixels, behind, share, lit, settings)
    dark = lit & (share < 1.0) & (share > lightest)
    rows, cols = rows[dark], cols[dark]
    shade = offset[dark] < reach
    if not shade.any():
        return mask
    shadow = np.zeros(small.shape, dtype=bool)
    shadow[rows[shade], cols[shade]] = True
    if own_colour:  # a half-size pixel on the shadow's outline may hold cable and shadow
        shadow = cv2.dilate(shadow.view(np.uint8), np.ones((3, 3), np.uint8)) > 0
    # full size: of a half-size pixel on the cable's outline, only its lighter pixels go (of
    # a cable of its own colour, only its pixels of the background's chromaticity)
    shadow = shadow.repeat(2, axis=0).repeat(2, axis=1)
    shadow = np.pad(shadow, [(0, n - m) for n, m in zip(cable.shape, shadow.shape)], "edge")
    rows, cols = np.nonzero(cable & shadow)
    at = (np.minimum(rows // 2, size[1] - 1), np.minimum(cols // 2, size[0] - 1))
    pixels = image_rgb[box][rows, cols]
    behind = total[at] / np.maximum(weight[at], 1e-3)[:, None]
    if own_colour:
        gone = (_brightness(pixels) < _brightness(behind)) \
            & (np.linalg.norm(_chroma(pixels) - _chroma(behind), axis=-1) < reach)
    else:
        gone = _brightness(pixels) > lightest * _brightness(behind)
    kept = mask.copy()
    kept[box][rows[gone], cols[gone]] = False
    return kept


def _shadow_rule(pixels, behind, share, lit, settings):
    """:func:`_without_shadow`'s rule for a mask's ``pixels`` (float32 RGB) with the
    background ``behind`` them, their brightness as a ``share`` of its and whether they are
    ``lit`` enough to have a chromaticity: ``(offset, lightest, reach, own_colour)``, each
    pixel's chromaticity's distance from the background's, the least share of a shadow's
    pixel, the greatest offset, and whether the cable has a colour of its own."""
    pixel_chroma, behind_chroma = _chroma(pixels), _chroma(behind)
    offset = np.linalg.norm(pixel_chroma - behind_chroma, axis=-1)
    distinct = lit & (offset > _COLOURED * settings.shadow_chroma)
    # of a colour of its own: far from the background's chromaticity and more saturated (a
    # black cable on a tinted table is far from its chromaticity too)
    coloured = distinct & (_saturation(pixel_chroma) > _saturation(behind_chroma))
    if np.count_nonzero(coloured) >= _COLOURED_SHARE * len(share):
        # what is nearer the background's chromaticity is not cable, however dark (a hard
        # shadow is darker than a bright cable)
        return offset, 0.0, max(settings.shadow_chroma,
                                _SHADOW_GAP * float(np.median(offset[coloured]))), True
    # the cable is darker than its shadow
    lightest = settings.shadow_depth * np.percentile(share, 25)
    reach = settings.shadow_chroma
    if np.count_nonzero(distinct) >= _COLOURED_SHARE * len(share):
        # a colourless cable on a tinted table (its chromaticity is not the table's, but it
        # is no more saturated): a darker pixel near the table's chromaticity is shadow from
        # the cable's median share up (a dark cable's soft shadow may be darker than
        # shadow_depth times the mask's darkest quarter)
        lightest = min(lightest, float(np.median(share[distinct])))
        reach = max(reach, _SHADOW_GAP * float(np.median(offset[distinct])))
    return offset, lightest, reach, False


def _saturation(chroma):
    """A chromaticity's distance from grey's."""
    return np.linalg.norm(chroma - np.float32(1.0 / 3.0), axis=-1)


def _chroma_gap(cable, surroundings):
    """The cable's median chromaticity and its distance from the surroundings' (0 when
    either has no pixel): below ``2 * seed_shade_chroma`` the cable is colourless there."""
    if not (len(cable) and len(surroundings)):
        return np.zeros(3, np.float32), 0.0
    inside = np.median(cable, axis=0)
    return inside, float(np.linalg.norm(inside - np.median(surroundings, axis=0)))


def _within(mask, distance):
    """The pixels within ``distance`` pixels (at least 1) of ``mask``'s (a disc dilation, on
    the mask's box only: a large disc is slow over a whole frame)."""
    reach = max(int(round(distance)), 1)
    grown = np.zeros_like(mask)
    box = _cable_box(mask, reach)
    if box is not None:
        grown[box] = cv2.dilate(np.ascontiguousarray(mask[box]).view(np.uint8),
                                cv2.getStructuringElement(
                                    cv2.MORPH_ELLIPSE, (2 * reach + 1, 2 * reach + 1))) > 0
    return grown


def _drop_blobs(mask, width, settings):
    """``mask`` without pieces shaped like objects rather than cable: holding a disc wider
    than ``2 * blob_thickness`` cable widths, shorter than ``blob_elongation`` widths (a
    piece's length in widths as :func:`thin_pieces` measures it) and about convex (filling
    :data:`_SOLID` of its convex hull or more: strands crossing, in a mask broken into
    pieces, are as thick and as short, but not convex).

    A piece is measured again with its holes under :data:`_RING_HOLE` square cable widths
    filled: a cylinder of the cable's hue whose lit top the model misses leaves a ring of its
    dark side, as thin as the cable, that filled is a disc (tuning looks clutter seeds 3, 5,
    7, 12 and 14: IoU 0.88 -> 0.93, 0.92 -> 0.98, 0.92 -> 0.95, 0.87 -> 0.94, 0.91 -> 0.99).
    A cable's loop filled is a disc too, but with the cable running on from it the piece is
    long or not convex; only a loop broken off alone would go."""
    box = _cable_box(mask, 0)  # the pieces lie in the mask's box
    if box is None:
        return mask
    count, labels, stats, _ = cv2.connectedComponentsWithStats(
        np.ascontiguousarray(mask[box]).view(np.uint8), 8, cv2.CV_32S)
    area = stats[:, cv2.CC_STAT_AREA]
    # only pieces larger than a disc of that radius can be objects; each is measured on its
    # own box (a distance transform over the whole frame costs more than the few pieces')
    thick = settings.blob_thickness * width
    blob = np.zeros(count, dtype=bool)
    least = math.pi * thick ** 2
    # a ring's box holds its hole
    for piece in np.flatnonzero(stats[:, cv2.CC_STAT_WIDTH] * stats[:, cv2.CC_STAT_HEIGHT]
                                > least):
        if piece == 0:
            continue
        x, y, w, h = stats[piece, :4]
        inside = np.pad(labels[y:y + h, x:x + w] == piece, 1)
        blob[piece] = area[piece] > least and _blob_like(inside, area[piece], thick, settings)
        if not blob[piece]:
            filled = _holes_filled(inside, _RING_HOLE * width * width)
            if filled is not inside:
                blob[piece] = _blob_like(filled, np.count_nonzero(filled), thick, settings,
                                         ring=True)
    if not blob.any():
        return mask
    kept = mask.copy()
    kept[box] &= ~blob[labels]
    return kept


def _holes_filled(piece, max_area):
    """``piece`` (a bool mask whose border is off it) with the holes it encloses under
    ``max_area`` pixels filled; ``piece`` itself when it has none."""
    _, labels, stats, _ = cv2.connectedComponentsWithStats((~piece).view(np.uint8), 4,
                                                           cv2.CV_32S)
    hole = stats[:, cv2.CC_STAT_AREA] < max_area
    hole[0] = False  # the piece
    hole[labels[0, 0]] = False  # what lies around it
    if not hole.any():
        return piece
    return piece | hole[labels]


def _blob_like(piece, area, thick, settings, *, ring=False):
    """:func:`_drop_blobs`' test of one piece (a bool mask whose border is off it, of ``area``
    pixels). A ring's holes filled (``ring``), its half-width is its ridge's mean weighted by
    the ridge's distances: a filled ring's ridge is its centre and a few pixels of its ragged
    outline, a distance or two from the edge, whose plain mean makes a disc look long."""
    distance = cv2.distanceTransform(piece.view(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_5)
    if distance.max() <= thick:
        return False
    ridge = distance[(distance >= cv2.dilate(distance, np.ones((3, 3), np.uint8))) & piece]
    half_width = float((ridge ** 2).sum() / ridge.sum()) if ring else ridge.mean()
    return area / max(4.0 * half_width ** 2, 1e-9) < settings.blob_elongation \
        and _solidity(piece) >= _SOLID


def _solidity(piece):
    """A piece's area over its convex hull's."""
    hull = cv2.convexHull(cv2.findNonZero(piece.view(np.uint8)))
    return float(np.count_nonzero(piece)) / max(cv2.contourArea(hull), 1.0)


def cable_mask(image_rgb, colour, settings=SegmentationSettings(), *, model=None):
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
    mask, _, width = _cable_masks(image_rgb, colour, settings, model)
    return mask, width


def _cable_masks(image_rgb, colour, settings, model=None, least_width=0.0):
    """``(mask, colour-range mask, width)``: the cable mask with its outline refined
    (:func:`refine_edges`) and the mask before that, whose topology the junctions are read
    from (on the realistic sample, junctions from the refined outline put 12% of their pixels
    farther than 3 r from any crossing; from the colour range's mask, 3.5%)."""
    if isinstance(model, SeveralCables):
        return _several_masks(image_rgb, model, settings, least_width)
    hsv = hsv_image(image_rgb)
    if settings.model and model is None:
        model = learn_colour_model([image_rgb], colour, settings)
    if settings.model and model is not None:
        _, raw, probability = _model_mask(image_rgb, model, settings, colour.select(hsv),
                                          least_width)
    else:
        raw, probability = colour.select(hsv), None
    raw = opened(raw)
    half, width = _rough_width(raw, least_width)
    if model is not None and (model.banded or model.seams) and width > 0:
        # dashes, each under a speck; or bands of two colours parted by their seams
        raw = bridged(raw, width, settings.stripe_reach if model.banded else SEAM_REACH)
        half, width = _rough_width(raw, least_width)
    if settings.shadow_chroma > 0 and width > 0:
        without = _without_shadow(raw, image_rgb, width, settings)
        if without is not raw:  # the shadow made the cable look wider
            raw = opened(without)
            half, width = _rough_width(raw, least_width)
    if width == 0:
        return raw, raw, 0.0
    mask = _remove_specks(raw, half, settings.speck_area * width * width)
    # before the blobs go: a piece of an object of the cable's colour grows to the object's
    # other faces, a blob then
    mask = _with_side(mask, image_rgb, width, settings)
    if settings.blob_elongation > 0:
        mask = _drop_blobs(mask, width, settings)
    # the rest only looks at the cable and its surroundings: its box with room for a closing
    box = _cable_box(mask, int(width) + 2)
    if box is None:
        return mask, mask, 0.0
    cable, cable_hsv = mask[box], hsv[box]
    if settings.fill_highlights:
        likely = None if probability is None \
            else probability[box] >= 255.0 * settings.highlight_probability
        cable = _fill_highlights(cable, cable_hsv, width, likely)
    plain = _correct_edges(cable, cable_hsv, settings) if colour.has_hue else cable
    refined = plain
    if settings.edge_reach > 0:
        refined = _refine_edges(cable, image_rgb[box], settings)
        if colour.has_hue:  # after the refinement: a tinted contact crevice is not cable
            refined = _correct_edges(refined, cable_hsv, settings)
    colour_range_mask = mask.copy()
    colour_range_mask[box] = plain
    mask[box] = refined
    width = _at_least(cable_width(refined), least_width)
    if settings.outline_passes > 0:
        mask = classify_outline(mask, image_rgb, width, passes=settings.outline_passes)
        width = _at_least(cable_width(mask), least_width)
        # searched again: the classifier took the mixed pixels between a two-tone cable's
        # found side and its missed one for the table, and the missed side's strip now
        # reaches beyond the rim (see engine.stages.missing_side)
        sided = _with_side(mask, image_rgb, width, settings)
        if sided is not mask:
            mask, width = sided, _at_least(cable_width(sided), least_width)
    return mask, colour_range_mask, width


def _with_side(mask, image_rgb, width, settings):
    """:func:`engine.stages.missing_side.with_missing_side` with the settings' options."""
    return with_missing_side(mask, image_rgb, width, reach=settings.side_reach,
                             chroma_gap=settings.side_chroma, contrast=settings.side_contrast,
                             contact=settings.side_contact)


def _several_masks(image_rgb, several, settings, least_width=0.0):
    """:func:`_cable_masks` of every cable, joined; the width is the cables' mean, each
    weighted by its area. Specks are removed from the joined masks: a stretch of cable seen
    between two passes of another is a small piece of its own mask, not of the joined one.
    No cable's missing side is searched for (``side_reach``): beside a cable of the table's
    hue it took the table's darker texture (tuning look two_cables seed 0: mask IoU 0.89 ->
    0.79, then 0.88 with darker pixels of the table's chromaticity left out)."""
    alone = replace(settings, speck_area=0.0, side_reach=0.0)
    found = [_cable_masks(image_rgb, colour, alone, model, least_width)
             for colour, model in several.cables]
    areas = np.array([np.count_nonzero(m) if w > 0 else 0 for m, _, w in found], dtype=float)
    width = float(np.dot(areas, [w for _, _, w in found]) / areas.sum()) if areas.sum() else 0.0
    mask = _joined([m for m, _, _ in found], width)
    colour_range_mask = _joined([m for _, m, _ in found], width)
    if width > 0 and settings.speck_area > 0:
        for joined in (mask, colour_range_mask):
            half = cv2.resize(joined.view(np.uint8), (joined.shape[1] // 2, joined.shape[0] // 2),
                              interpolation=cv2.INTER_AREA) > 0
            joined &= _remove_specks(joined, half, settings.speck_area * width * width)
    return mask, colour_range_mask, width


def _joined(masks, width):
    """The union of several cables' masks with the seam where two touch filled: where one
    passes over the other, each outline stops short of the dark contact line between them,
    and a gap there would cut the strand below off at the crossing (no junction, a break).
    Seam pixels lie within ``_SEAM`` widths (a pixel at least) of two of the masks."""
    union = np.logical_or.reduce(masks)
    if len(masks) < 2 or width <= 0:
        return union
    reach = max(int(round(_SEAM * width)), 1)
    disc = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * reach + 1, 2 * reach + 1))
    near = [cv2.dilate(m.view(np.uint8), disc) > 0 for m in masks]
    for a in range(len(near)):
        for b in range(a + 1, len(near)):
            union |= near[a] & near[b]
    return union


def _channel_percentile(image, channel, mask, percent):
    """Percentile of one uint8 channel over the mask's pixels (a masked histogram: no copy)."""
    histogram = cv2.calcHist([image], [channel], mask.view(np.uint8), [256], [0, 256]).ravel()
    cumulative = np.cumsum(histogram)
    return int(np.searchsorted(cumulative, percent / 100.0 * cumulative[-1]))


def _correct_edges(mask, hsv, settings):
    """Drop edge pixels that are only the cable's colour bounced into its own shadow."""
    if not mask.any():
        return mask
    median_saturation = _channel_percentile(hsv, 1, mask, 50)
    median_value = _channel_percentile(hsv, 2, mask, 50)
    edge = mask & ~(cv2.erode(mask.view(np.uint8), np.ones((3, 3), np.uint8)) > 0)
    rows, cols = np.nonzero(edge)
    saturation, value = hsv[rows, cols, 1], hsv[rows, cols, 2]
    shade = (value < settings.shade_value * median_value) \
        & (saturation < settings.shade_saturation * median_saturation)
    corrected = mask.copy()
    corrected[rows[shade], cols[shade]] = False
    return corrected


def _refine_edges(mask, image_rgb, settings):
    """:func:`refine_edges` with the settings' reach and contrast."""
    return refine_edges(mask, image_rgb, reach=settings.edge_reach,
                        contrast=settings.edge_contrast)


def refine_edges(mask, image_rgb, *, reach=2, contrast=20.0):
    """The mask's outline moved onto the image's edge between cable and background.

    A colour range puts the outline wherever a blurred edge pixel's hue, saturation and value
    happen to leave the range: on a light background it takes in pixels that are mostly
    background, on a dark one (the cable's shade side and its shadow) it drops pixels that
    are mostly cable. The mask's centre then shifts towards the light, and the fitted
    centreline with it. A threshold between
    the cable's colour and the background's fails too: the cable darkens towards its
    outline, and the table next to it. So each pixel within ``reach`` pixels of the outline
    is decided in two steps, along the outline's normal through it:

    1. The edge: where the chromaticity, projected on the cable's minus the background's,
       changes fastest. Shading does not change chromaticity, so the cable's darkening
       towards its outline does not move this edge (a dark side moves it by a fraction of
       the blur, as a mix's chromaticity leans to its brighter part).
    2. The pixel is cable when its colour is nearer the colour 1.5 pixels inside that edge
       than the colour 1.5 pixels outside it: a blurred edge is half cable, half background.

    A colourless cable (chromaticity as the background's) uses the colour projected on the
    cable's minus the background's in step 1.

    Parameters
    ----------
    mask : ndarray of bool, shape (H, W)
    image_rgb : ndarray, shape (H, W, 3), uint8
    reach : int, optional
        Pixels; the outline is searched within this distance of the colour range's.
    contrast : float, optional
        Pixels whose colours inside and outside the edge differ by less than this (RGB
        distance, 8-bit levels) keep their label.

    Returns
    -------
    ndarray of bool
    """
    if reach <= 0 or not mask.any():
        return mask
    size = 2 * int(reach) + 1
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (size, size))
    inner = cv2.erode(mask.view(np.uint8), kernel, borderType=cv2.BORDER_CONSTANT,
                      borderValue=0) > 0
    outer = cv2.dilate(mask.view(np.uint8), kernel) == 0
    if not (inner.any() and outer.any()):
        return mask
    band = ~(inner | outer)
    image = np.ascontiguousarray(image_rgb)
    # the cable's and the background's colours: medians of (a sample of) the pixels a reach
    # inside the outline and a reach outside it
    ring = outer & (cv2.dilate(band.view(np.uint8), kernel) > 0)
    cable_colour, background_colour = (
        np.median(image.reshape(-1, 3)[np.flatnonzero(where)[::_EDGE_SAMPLE]],
                  axis=0).astype(np.float32) for where in (inner, ring))
    # outward normals of the outline
    smooth = cv2.blur(mask.view(np.uint8) * np.uint8(250), (5, 5))
    out_x, out_y = -cv2.Sobel(smooth, cv2.CV_16S, 1, 0), -cv2.Sobel(smooth, cv2.CV_16S, 0, 1)
    # flat indices into the (contiguous) box: faster to find and to gather than rows, cols
    flat = np.flatnonzero(band)
    out_x, out_y = out_x.ravel()[flat], out_y.ravel()[flat]
    norm = np.hypot(out_x, out_y, dtype=np.float32)
    usable = norm > 0
    flat, norm = flat[usable], norm[usable]
    nx, ny = (out_x[usable] / norm).astype(np.float32), (out_y[usable] / norm).astype(np.float32)
    rows, cols = np.divmod(flat, mask.shape[1])
    # 1. the edge along the normal (samples a pixel apart from -reach - 1 to reach + 1)
    across = _chroma(cable_colour) - _chroma(background_colour)
    colourless = np.linalg.norm(across) < 0.05
    steps = np.arange(-reach - 1, reach + 2, dtype=np.float32)
    x, y = cols.astype(np.float32)[:, None], rows.astype(np.float32)[:, None]
    red, green, blue = np.moveaxis(sample_at(image, x + steps * nx[:, None],
                                              y + steps * ny[:, None]), -1, 0)
    if colourless:  # the colour itself
        across = cable_colour - background_colour
    level = across[0] * red + across[1] * green + across[2] * blue
    if not colourless:
        level /= np.maximum(red + green + blue, 1.0)
    fall = level[:, :-2] - level[:, 2:]  # cable to background, at steps[1:-1]
    peak = np.clip(np.argmax(fall, axis=1), 1, fall.shape[1] - 2)
    index = np.arange(len(peak))
    before, centre, after = fall[index, peak - 1], fall[index, peak], fall[index, peak + 1]
    bend = before - 2.0 * centre + after
    offset = np.clip(0.5 * (before - after) / np.where(bend < 0, bend, -np.inf), -0.5, 0.5)
    edge = steps[1:-1][peak] + offset
    # 2. half cable, half background
    ends = np.stack([edge - 1.5, edge + 1.5], axis=1)
    inside, outside = np.moveaxis(sample_at(image, x + ends * nx[:, None],
                                             y + ends * ny[:, None]), 1, 0)
    across = inside - outside
    spread = np.einsum("ij,ij->i", across, across)
    share = np.einsum("ij,ij->i", image.reshape(-1, 3)[flat].astype(np.float32) - outside,
                      across)
    decided = spread >= contrast**2
    refined = np.array(mask, dtype=bool, order="C")  # a copy, written through ravel()
    refined.ravel()[flat[decided]] = share[decided] >= 0.5 * spread[decided]
    return refined


def junction_map(mask, width, settings=SegmentationSettings()):
    """Pixels where the cable overlaps itself (§3.1): discs around :func:`junction_centres`.

    Parameters
    ----------
    mask : ndarray of bool
    width : float
        Cable width in pixels (:func:`cable_width`).
    settings : SegmentationSettings, optional

    Returns
    -------
    ndarray of bool
        Cable pixels within ``junction_disc * width`` of a junction centre.
    """
    junctions = np.zeros(mask.shape, dtype=np.uint8)
    radius = settings.junction_disc * width
    for x, y in junction_centres(mask, width, settings):
        cv2.circle(junctions, (int(round(x * 16 - 8)), int(round(y * 16 - 8))),
                   int(round(radius * 16)), 1, thickness=-1, shift=4)
    return (junctions > 0) & mask


def junction_centres(mask, width, settings=SegmentationSettings()):
    """Where the cable crosses or touches itself in one frame.

    The paper's test alone (a disc holding more cable than one strand can) also fires beside
    tight bends and where two strands run close, and along both arms of a shallow crossing, so
    the centres come from the mask's topology and the paper's test confirms them:

    1. At a scale where the cable is about five pixels wide, small holes (a dark contact line
       between strands) are filled and the mask is thinned to a one-pixel skeleton.
    2. Skeleton clusters with three or more branches (spurs shorter than
       ``junction_spur * width`` ignored) are junctions; two joined by a branch shorter than
       ``junction_pair * width`` are the two forks of one shallow crossing, merged.
    3. A junction is kept when somewhere within ``junction_disc * width`` of it a disc of
       radius ``junction_radius * width`` holds more than ``junction_ratio`` times the cable of
       a single straight strand.

    Parameters
    ----------
    mask : ndarray of bool
    width : float
        Cable width in pixels (:func:`cable_width`).
    settings : SegmentationSettings, optional

    Returns
    -------
    ndarray, shape (K, 2)
        COLMAP image coordinates ``(x, y)`` of the junctions.
    """
    if width <= 0 or not mask.any():
        return np.zeros((0, 2))
    # work on the cable's bounding box, at a scale where the cable is about 8 pixels wide
    factor = max(int(width // 8), 1)
    rows, cols = np.nonzero(mask.any(axis=1))[0], np.nonzero(mask.any(axis=0))[0]
    top, left = rows[0] - rows[0] % factor, cols[0] - cols[0] % factor
    crop = mask[top:rows[-1] + 1, left:cols[-1] + 1]
    small = crop
    if factor > 1:
        size = (-(-crop.shape[0] // factor), -(-crop.shape[1] // factor))
        padded = np.zeros((size[0] * factor, size[1] * factor), dtype=np.float32)
        padded[:crop.shape[0], :crop.shape[1]] = crop
        small = cv2.resize(padded, size[::-1], interpolation=cv2.INTER_AREA) > 0.5
    small_width = width / factor
    filled = fill_small_holes(small, settings.junction_hole * small_width ** 2)
    clusters = skeleton_clusters(thin(filled), min_spur=settings.junction_spur * small_width)
    centres = _merge_forks(clusters, settings.junction_pair * small_width)
    if not len(centres):
        return np.zeros((0, 2))
    kept = np.array([centre for centre in centres
                     if _confirmed(small, small_width, centre, settings)]).reshape(-1, 2)
    # working pixel (i, j) covers crop pixels factor*i .. factor*(i+1)
    return (kept[:, ::-1] + 0.5) * factor + (left, top)


def _merge_forks(clusters, max_link):
    """Centres of junction clusters (degree >= 3), the two forks of a shallow crossing merged."""
    junction = clusters.degree >= 3
    forks = DisjointSets(range(len(junction)))
    for a, b, length in clusters.links:
        if junction[a] and junction[b] and length < max_link:
            forks.union(int(a), int(b))
    groups = forks.groups(int(index) for index in np.flatnonzero(junction))
    return [clusters.centres[members].mean(axis=0) for members in groups.values()]


def _confirmed(mask, width, centre, settings):
    """The paper's test near ``centre``: some disc of radius ``junction_radius * width``
    within ``junction_disc * width`` of it holds more than ``junction_ratio`` times the cable of
    one straight strand."""
    radius = max(settings.junction_radius * width, 1.5)
    reach = settings.junction_disc * width
    size = 2 * int(math.ceil(radius)) + 1
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (size, size)).astype(np.float32)
    row, col = centre
    span = int(math.ceil(reach + radius)) + 1
    r0, c0 = max(int(row) - span, 0), max(int(col) - span, 0)
    window = mask[r0:int(row) + span + 1, c0:int(col) + span + 1].astype(np.float32)
    count = cv2.filter2D(window, -1, kernel, borderType=cv2.BORDER_CONSTANT)
    rr, cc = np.indices(window.shape)
    near = (rr + r0 - row) ** 2 + (cc + c0 - col) ** 2 <= reach ** 2
    return bool((count[near] > settings.junction_ratio * 2.0 * radius * width).any())


def segment_frame(image_rgb, colour, settings=SegmentationSettings(), *, model=None,
                  least_width=0.0):
    """Mask, junctions and width of one frame (junctions from the mask before its outline
    is refined).

    Parameters
    ----------
    image_rgb : ndarray, shape (H, W, 3), uint8
    colour : ColourRange
    settings : SegmentationSettings, optional
    model : ColourModel or SeveralCables, optional
        The sequence's colour model (:func:`learn_colour_model`); learnt from this frame
        alone if None and ``settings.model``. Several cables (:func:`sequence_colour`): each
        is segmented with its own colour and model, the masks joined, and the junctions read
        from the joined mask (a cable crossing another is a junction).
    least_width : float, optional
        Every width the frame's cable is measured at, in pixels, is raised to this (the
        sequence's width, :func:`segment_all`); 0 leaves them as measured.

    Returns
    -------
    FrameSegmentation
    """
    mask, colour_range_mask, width = _cable_masks(image_rgb, colour, settings, model,
                                                  least_width)
    junctions = junction_map(colour_range_mask, width, settings) & mask
    return FrameSegmentation(mask=mask, junctions=junctions, width=width)


def segment_all(segment, count, settings=SegmentationSettings(), *, map_frames=None,
                width_of=None):
    """Every frame of a sequence segmented, the frames whose cable came out too thin
    (``settings.width_floor``) again.

    Parameters
    ----------
    segment : callable
        ``segment(number, least_width)``: frame ``number`` segmented (:func:`segment_frame`
        with ``least_width``).
    count : int
        Frames in the sequence.
    settings : SegmentationSettings, optional
    map_frames : callable, optional
        ``map_frames(function, numbers, first)``: ``function`` of each number, in order (the
        frames in order, on this thread, if None); ``first`` is True on the first pass.
    width_of : callable, optional
        The cable width of a result of ``segment`` (its ``width`` if None).

    Returns
    -------
    list
        ``segment``'s result for each frame.
    """
    if map_frames is None:
        def map_frames(function, numbers, first):
            return [function(number) for number in numbers]
    found = list(map_frames(lambda number: segment(number, 0.0), range(count), True))
    widths = np.array([result.width if width_of is None else width_of(result)
                       for result in found], dtype=float)
    if settings.width_floor <= 0 or not np.any(widths > 0):
        return found
    least = settings.width_floor * float(np.median(widths[widths > 0]))
    thin = [int(k) for k in np.flatnonzero((widths > 0) & (widths < least))]
    for number, result in zip(thin, map_frames(lambda k: segment(k, least), thin, False)):
        found[number] = result
    return found


def segment_images(images_rgb, colour, settings=SegmentationSettings(), *, model=None):
    """:func:`segment_all` of frames held in memory: a :class:`FrameSegmentation` each."""
    return segment_all(lambda number, least: segment_frame(
        images_rgb[number], colour, settings, model=model, least_width=least),
        len(images_rgb), settings)

"""Which thing in the frames is the cable, and a colour model of it against the background.

The paper thresholds one HSV box set by hand on one frame (§3.1). A box fails as soon as the
look departs from a saturated cable on a grey table: a pale cable's shade side leaves it, a
black cable's box takes in every shadow, and an automatic box picks whatever is most saturated.
Here a box (set by hand, picked, or found automatically) only *seeds* the cable:

1. :func:`find_cable` (automatic): the frame's colours are clustered (k-means in Lab)
   and every cluster, and every pair of clusters (a cable's lit and shade sides), is scored as
   a candidate cable: how much of it is *thin* (long connected pieces of one width, at most a
   few percent of the frame), how long those pieces are, and how much it stands out from what
   lies around it, chromaticity counting double (a shadow has its surface's chromaticity, only
   darker; a coloured cable does not). A candidate's pixels are scored with one-pixel gaps
   closed (:func:`shaped`: a striped cable's bands meet in mixed pixels of other colours),
   unless the closing widens its pieces: then it joined something beside the cable, and the
   candidate scores no better than without it (:func:`_shaped_score`).
   The best candidate without the clusters of the shadow it casts (:func:`without_its_shadow`),
   its pixels with the shade side beside them
   (:func:`engine.stages.segmentation.colour_seed`), give the HSV box.
2. :class:`ColourModel`: the box's thin pieces on a few frames are the cable's samples, the
   pixels well away from them the background's; their colour histograms (RGB, smoothed) give
   each colour's probability of being cable, looked up per pixel (a histogram back-projection,
   a few milliseconds a frame). Shading the box missed is learnt from its neighbours in colour,
   and objects sharing the cable's colour but not its shape (:func:`thin_pieces`) are left out
   of both samples and removed from the masks by their shape.
"""

import math
from dataclasses import dataclass

import cv2
import numpy as np
from scipy.ndimage import gaussian_filter

from ..errors import ReconstructionError
from .colour_range import ColourRange, hsv_image

__all__ = ["ColourModel", "find_cable", "find_cables", "range_of", "thin_pieces", "reduced",
           "colour_candidates", "CableCandidate", "opened", "shaped", "samples"]

#: Frames are clustered and scored at this size (the longer side, pixels); larger frames are
#: also tried at twice, four times... the size, and a larger size is chosen when its best
#: candidate is at least ``_SHARPER`` times more cable-like than the best so far (a wire a few
#: pixels wide in a large frame vanishes when the frame is reduced to this size).
_SMALL = 480
_SHARPER = 2.0
_CLUSTERS = 8
#: A candidate enclosing more holes than this is penalised as a net, not a cable.
_MAX_LOOPS = 12
#: A candidate parting the frame into more regions that touch its border than this is
#: penalised as a net too: a table's grout or print lines run out of the view, so most of the
#: cells between them touch the border, where a cable lying in the view leaves one such region
#: (its loops lie inside it), two or three where it runs out of the view.
_MAX_BORDER_REGIONS = 3
#: A cable covers at most this share of a frame.
_MAX_COVERAGE = 0.3
#: :func:`find_cables`: weighs ``_MORE`` candidates; another cable scores at least ``_ANOTHER``
#: of the best over the frames, and its hue lies ``_HUE_APART`` (OpenCV units) from theirs;
#: pixels of saturation and value of ``_HUED`` or more have a hue.
_ANOTHER = 0.3
_MORE = 6
_HUE_APART = 25
_HUED = 50
#: :func:`find_cables`: another cable grouped with a found one holds at least this share of
#: the group's pixels.
_PART = 0.2
#: :func:`find_cables`: another candidate at least this shadow-like (:func:`_shadow_likeness`,
#: the found cables' pixels left out of its surroundings) is the shadow the cables cast.
_ANOTHER_CAST = 0.25
#: :func:`without_its_shadow`: a candidate's cluster at least this shadow-like
#: (:func:`_shadow_likeness`) and this far in chromaticity from its other clusters is the
#: shadow the cable casts.
_CAST = 0.5
_OTHER_CHROMA = 0.08
#: :func:`_shaped_score`: a closing that makes a candidate's pieces this many times wider (on
#: average, weighted by area) joined something beside the cable, not bands end to end.
_WIDENED = 1.1


def reduced(image_rgb, size=_SMALL):
    """The frame reduced so its longer side is at most ``size`` pixels."""
    rows, cols = image_rgb.shape[:2]
    factor = max(rows, cols) / size
    if factor <= 1:
        return image_rgb
    shape = (int(round(cols / factor)), int(round(rows / factor)))
    return cv2.resize(image_rgb, shape, interpolation=cv2.INTER_AREA)


def _lab(image_rgb):
    return cv2.cvtColor(image_rgb.astype(np.float32) / 255.0, cv2.COLOR_RGB2Lab)


def thin_pieces(mask, *, min_elongation=8.0, min_area=12):
    """Which connected pieces of a mask are thin (cable-like), and their half-widths.

    A piece's half-width ``h`` is the mean of the distance transform along its ridge; its
    elongation ``area / (2 h)**2`` is its length in widths (a square is about 4, a cable as
    many as it is widths long).

    Parameters
    ----------
    mask : ndarray of bool
    min_elongation : float, optional
    min_area : int, optional
        Pieces smaller than this (pixels) are neither.

    Returns
    -------
    labels : ndarray of int32
        Connected pieces (8-connected), 0 the background.
    thin : ndarray of bool, shape (pieces + 1,)
        Per label: the piece is thin.
    half_width : ndarray, shape (pieces + 1,)
    area : ndarray, shape (pieces + 1,)
    """
    count, labels, stats, _ = cv2.connectedComponentsWithStats(mask.view(np.uint8), 8,
                                                               cv2.CV_32S)
    area = stats[:, cv2.CC_STAT_AREA].astype(float)
    distance = cv2.distanceTransform(mask.view(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_5)
    ridge = (distance >= cv2.dilate(distance, np.ones((3, 3), np.uint8))) & mask
    ridge_labels = labels[ridge]
    total = np.bincount(ridge_labels, weights=distance[ridge], minlength=count)
    number = np.bincount(ridge_labels, minlength=count)
    half_width = total / np.maximum(number, 1)
    elongation = area / np.maximum(4.0 * half_width ** 2, 1e-9)
    thin = (elongation >= min_elongation) & (area >= min_area)
    thin[0] = False
    return labels, thin, half_width, area


def _score(mask, lab, diagonal, pieces=None):
    """How cable-like a candidate mask is (see the module docstring); 0 if not at all.
    ``pieces``: the mask's :func:`thin_pieces`, when already known."""
    coverage = mask.mean()
    if coverage < 5e-4 or coverage > _MAX_COVERAGE:
        return 0.0
    labels, thin, half_width, area = thin_pieces(mask) if pieces is None else pieces
    thin_area = area[thin].sum()
    thin_share = thin_area / max(mask.sum(), 1)
    if not thin.any():
        return 0.0
    lengths = np.sort(area[thin] / np.maximum(2.0 * half_width[thin], 1e-9))[::-1]
    length = float(lengths[:3].sum() / diagonal)
    # contrast against a ring around the thin pieces
    cable = thin[labels]
    width = float(np.median(2.0 * half_width[thin]))
    grow = int(math.ceil(width)) + 2
    ring = (cv2.dilate(cable.view(np.uint8), cv2.getStructuringElement(
        cv2.MORPH_ELLIPSE, (2 * grow + 1, 2 * grow + 1))) > 0) & ~mask
    if not ring.any():
        return 0.0
    inside, outside = np.median(lab[cable], axis=0), np.median(lab[ring], axis=0)
    lightness, chroma = abs(inside[0] - outside[0]), np.hypot(*(inside[1:] - outside[1:]))
    contrast = float(np.hypot(lightness, 2.0 * chroma))
    # a net (tiles' grout, a weave) encloses many holes; a cable only a loop per crossing. A
    # net's lines also run out of the view, its cells to the frame's border
    regions = cv2.connectedComponentsWithStats((~cable).view(np.uint8), connectivity=4)[2][1:]
    large = regions[:, cv2.CC_STAT_AREA] > 4.0 * width * width
    left, top = regions[:, cv2.CC_STAT_LEFT], regions[:, cv2.CC_STAT_TOP]
    right = left + regions[:, cv2.CC_STAT_WIDTH]
    bottom = top + regions[:, cv2.CC_STAT_HEIGHT]
    border = large & ((left == 0) | (top == 0) | (right == mask.shape[1])
                      | (bottom == mask.shape[0]))
    net = 1.0 / (1.0 + max(int(large.sum()) - 1 - _MAX_LOOPS, 0) / _MAX_LOOPS)
    net /= 1.0 + max(int(border.sum()) - _MAX_BORDER_REGIONS, 0) / _MAX_BORDER_REGIONS
    score = thin_share ** 2 * min(length, 1.5) * contrast * net
    return float(score)


def _clusters(image_rgb, clusters=_CLUSTERS, size=_SMALL):
    """The frame at the scoring size, in Lab, each pixel's colour cluster (k-means) and the
    clusters' centres (Lab)."""
    small = reduced(image_rgb, size)
    lab = _lab(small)
    samples = lab.reshape(-1, 3)[::3].astype(np.float32)
    cv2.setRNGSeed(7)  # the same frame, the same clusters
    criteria = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 30, 0.2)
    _, _, centres = cv2.kmeans(samples, clusters, None, criteria, 2, cv2.KMEANS_PP_CENTERS)
    return small, lab, _nearest(lab, centres), centres


def _nearest(lab, centres):
    """Each pixel's nearest cluster centre (Lab; the first of equals), one centre at a time
    on whole colour planes (all centres at once took 100 bytes a pixel: 3 GB for an 8K
    frame; a centre at a time on the pixels' colour triples was 9 times slower). The squared
    distance adds the channels in their order, as a sum over the last axis does."""
    planes = [np.ascontiguousarray(lab[..., channel], dtype=np.float32) for channel in range(3)]
    shape = lab.shape[:2]
    nearest = np.zeros(shape, dtype=np.int64)
    best = np.full(shape, np.inf, dtype=np.float32)
    distance, term = np.empty(shape, np.float32), np.empty(shape, np.float32)
    closer = np.empty(shape, dtype=bool)
    for k, centre in enumerate(np.asarray(centres, dtype=np.float32)):
        np.subtract(planes[0], centre[0], out=distance)
        np.multiply(distance, distance, out=distance)
        for channel in (1, 2):
            np.subtract(planes[channel], centre[channel], out=term)
            np.multiply(term, term, out=term)
            np.add(distance, term, out=distance)
        np.less(distance, best, out=closer)
        np.putmask(nearest, closer, k)
        np.putmask(best, closer, distance)
    return nearest


def opened(mask):
    """A 3x3 cross opening (a symmetric kernel: an even one would shift the mask a pixel)."""
    cross = cv2.getStructuringElement(cv2.MORPH_CROSS, (3, 3))
    return cv2.morphologyEx(mask.astype(np.uint8), cv2.MORPH_OPEN, cross) > 0


def shaped(mask):
    """A candidate's pixels as they are scored (:func:`_shaped_score`): closed by a 3x3 cross,
    then :func:`opened`. A striped cable's bands meet in a line of mixed pixels, often of a
    table's colour: each band alone is a short piece, and the cable is thin only with those
    lines bridged."""
    cross = cv2.getStructuringElement(cv2.MORPH_CROSS, (3, 3))
    return opened(cv2.morphologyEx(mask.view(np.uint8), cv2.MORPH_CLOSE, cross) > 0)


def _shaped_score(mask, lab, diagonal):
    """A candidate's :func:`_score` on its pixels as :func:`shaped` makes them, but no more
    than on the plain :func:`opened` pixels when the closing widens the pieces
    (:data:`_WIDENED`). Bands bridged end to end keep the cable's width; a line along the
    cable's edge, one pixel off it (a hard light's rim, a cluster of mixed edge pixels), is
    joined to it side by side and widens it, and must not make its cluster the cable's."""
    closed, plain = shaped(mask), opened(mask)
    closed_pieces, plain_pieces = thin_pieces(closed), thin_pieces(plain)
    value = _score(closed, lab, diagonal, closed_pieces)
    if _mean_width(closed_pieces) > _WIDENED * _mean_width(plain_pieces):
        value = min(value, _score(plain, lab, diagonal, plain_pieces))
    return value


def _mean_width(pieces):
    """The mean width (pixels) of a mask's connected pieces (its :func:`thin_pieces`),
    weighted by their areas."""
    _, _, half_width, area = pieces
    return 2.0 * float(np.average(half_width[1:], weights=area[1:])) if area[1:].any() else 0.0


def _chromaticity(rgb):
    rgb = np.asarray(rgb, dtype=np.float32)
    return rgb[..., :2] / np.maximum(rgb.sum(axis=-1, keepdims=True), 1.0)


def _shadow_likeness(small, mask, beside=None):
    """0 to 1: how much a cluster looks like a shadow: the chromaticity of what lies around
    it (but for ``beside``'s pixels), only darker (a shadow changes the light, not the
    surface)."""
    if not mask.any():
        return 0.0
    ring = (cv2.dilate(mask.view(np.uint8), np.ones((7, 7), np.uint8)) > 0) & ~mask
    if beside is not None:
        ring &= ~beside
    if not ring.any():
        return 0.0
    inside, outside = np.median(small[mask], axis=0), np.median(small[ring], axis=0)
    darker = inside.sum() < 0.8 * outside.sum()
    gap = float(np.linalg.norm(_chromaticity(inside) - _chromaticity(outside)))
    return float(darker) * float(np.clip(1.0 - gap / 0.04, 0.0, 1.0))


@dataclass(frozen=True, eq=False)
class CableCandidate:
    """A group of colour clusters that may be the cable (see :func:`colour_candidates`).

    Attributes
    ----------
    score : float
    members : tuple of int
        Its clusters.
    centres : ndarray, shape (K, 3)
        Every cluster's centre (Lab): a pixel belongs to the candidate when its nearest centre
        is one of ``members``.
    mask : ndarray of bool
        Its pixels at the scoring size.
    shadow : tuple of int
        Clusters of the shadow the cable casts (:func:`without_its_shadow`): not the cable's
        colours, but the cable's pieces are thin together with them.
    """

    score: float
    members: tuple
    centres: np.ndarray
    mask: np.ndarray
    shadow: tuple = ()

    def select_rgb(self, image_rgb):
        """The candidate's pixels in a frame (any size)."""
        return np.isin(_nearest(_lab(image_rgb), self.centres), self.members)

    def select_with_shadow_rgb(self, image_rgb):
        """The candidate's pixels in a frame and those of its :attr:`shadow` clusters."""
        nearest = _nearest(_lab(image_rgb), self.centres)
        return np.isin(nearest, self.members), np.isin(nearest, self.shadow)


def colour_candidates(image_rgb, *, clusters=_CLUSTERS, keep=3, size=_SMALL):
    """The most cable-like groups of colour clusters of a frame, best first.

    Each cluster and each pair of clusters starts a group; clusters are added to it while they
    make it more cable-like (a cable's lit side, shade side, highlight or stripes are different
    clusters of one thin object). A cluster that looks like a shadow
    (:func:`_shadow_likeness`) counts for less.

    Parameters
    ----------
    image_rgb : ndarray
        RGB uint8.
    clusters : int, optional
        Colour clusters (k-means in Lab).
    keep : int, optional
        Candidates returned.
    size : int, optional
        The frame is reduced so its longer side is at most this many pixels.

    Returns
    -------
    small : ndarray
        The frame at the scoring size (RGB).
    candidates : list of CableCandidate
        Best first, at most ``keep``.
    """
    small, lab, labels, centres = _clusters(image_rgb, clusters, size)
    diagonal = math.hypot(*small.shape[:2])
    single = [labels == k for k in range(clusters)]
    penalty = [1.0 - 0.7 * _shadow_likeness(small, mask) for mask in single]

    scored = {}

    coverage = [mask.mean() for mask in single]

    def score(members):
        key = tuple(sorted(members))
        if sum(coverage[k] for k in key) > _MAX_COVERAGE:  # too much of the frame
            return 0.0
        if key not in scored:
            value = _shaped_score(np.any([single[k] for k in key], axis=0), lab, diagonal)
            scored[key] = value * float(np.prod([penalty[k] for k in key]))
        return scored[key]

    # every cluster and every pair of clusters starts a group (a striped cable's bands are
    # short pieces, thin only together; its colours' pairs may all rank below a table's
    # grout, so the best few starts are not enough), the best first
    singles = [((k,), score([k])) for k in range(clusters)]
    pairs = [((a, b), score([a, b])) for a in range(clusters) for b in range(a + 1, clusters)]
    starts = sorted(singles, key=lambda item: -item[1]) + sorted(pairs, key=lambda item: -item[1])
    groups = {}
    for start, value in starts:
        members, best = list(start), value
        while True:
            trials = [(score(members + [k]), k) for k in range(clusters) if k not in members]
            if not trials:
                break
            value, k = max(trials)
            if value <= 1.05 * best:
                break
            members, best = members + [k], value
        groups[tuple(sorted(members))] = best
    ranked = sorted(groups.items(), key=lambda item: -item[1])[:keep]
    return small, [CableCandidate(value, members, centres,
                                  shaped(np.any([single[k] for k in members], axis=0)))
                   for members, value in ranked]


def without_its_shadow(candidate, small):
    """A candidate without its clusters that are a shadow the cable casts: a cluster that is
    its surroundings' chromaticity only darker (:func:`_shadow_likeness` of at least
    :data:`_CAST`, the candidate's other pixels left out of the surroundings) and of another
    chromaticity than the candidate's other clusters (:data:`_OTHER_CHROMA`: a colourless
    cable's shade side is its own chromaticity, and stays). A cable's dark shadow ring on a
    pale table is as thin as the cable and hugs it, so the greedy grouping takes it in; it
    then teaches the colour model the shadow's grey and halves the seed's width.

    Parameters
    ----------
    candidate : CableCandidate
    small : ndarray
        The frame at the candidate's scoring size (RGB).

    Returns
    -------
    CableCandidate
        ``candidate`` itself when no cluster is dropped.
    """
    if len(candidate.members) < 2:
        return candidate
    labels = _nearest(_lab(small), candidate.centres)
    group = np.isin(labels, candidate.members)
    parts = {k: candidate.mask & (labels == k) for k in candidate.members}
    kept = []
    for k, part in parts.items():
        rest = candidate.mask & ~part
        if part.any() and rest.any() and _shadow_likeness(small, part, group) >= _CAST:
            gap = np.linalg.norm(_chromaticity(np.median(small[part], axis=0))
                                 - _chromaticity(np.median(small[rest], axis=0)))
            if gap >= _OTHER_CHROMA:
                continue
        kept.append(k)
    if len(kept) == len(candidate.members) or not kept:
        return candidate
    return CableCandidate(candidate.score, tuple(kept), candidate.centres,
                          candidate.mask & np.isin(labels, kept),
                          tuple(k for k in candidate.members if k not in kept))


def range_of(hsv_pixels, *, shade=0.5):
    """An HSV box around a cable's pixels, generous towards the shade: the hue's 1st to
    99th percentiles (circular) widened by 4, saturation from 0.7 times its 2nd percentile,
    value from ``shade`` times its 1st percentile (a colourless cable: value from its 1st to
    99.5th percentile, any hue).

    Parameters
    ----------
    hsv_pixels : ndarray, shape (N, 3)
        OpenCV HSV values.
    shade : float, optional
        Below 1 for pixels that may miss the cable's shade side (a candidate's clusters).

    Returns
    -------
    ColourRange
    """
    h, s, v = (hsv_pixels[:, k].astype(float) for k in range(3))
    v_low, v_high = np.percentile(v, [1.0, 99.5])
    s_low, s_high = np.percentile(s, [2.0, 99.5])
    if np.median(s) < 50:  # a colourless cable: brightness, any hue
        return ColourRange((0, 0, int(v_low)), (179, int(max(s_high, 60)), int(v_high)))
    angle = h * (2 * math.pi / 180.0)
    centre = math.atan2(np.sin(angle).mean(), np.cos(angle).mean()) * 180.0 / (2 * math.pi)
    offset = (h - centre + 90.0) % 180.0 - 90.0
    low, high = np.percentile(offset, [1.0, 99.0])
    low, high = int(math.floor(centre + low - 4)) % 180, int(math.ceil(centre + high + 4)) % 180
    return ColourRange((low, int(0.7 * s_low), int(shade * v_low)), (high, 255, 255))


def _best_score(candidates):
    return candidates[0].score if candidates else 0.0


def find_cable(images_rgb):
    """The cable, found automatically: the most cable-like candidate of the frames.

    Parameters
    ----------
    images_rgb : sequence of ndarray
        One or more frames of the sequence (RGB uint8); candidates come from the first, and
        each is scored on every frame (a cable is thin in every view; a chance alignment of
        a table's pattern is not). Frames more than twice ``_SMALL`` are also scored at
        larger sizes (:data:`_SHARPER`).

    Returns
    -------
    colour : ColourRange
        An HSV box around the candidate's pixels (what the panel and ``--hsv`` show).
    candidate : CableCandidate

    Raises
    ------
    ReconstructionError
        No candidate is thin (no cable pixels).
    """
    small, candidates, totals = _ranked(list(images_rgb), keep=3)
    best = without_its_shadow(candidates[int(np.argmax(totals))], small)
    return range_of(hsv_image(small)[best.mask]), best


def find_cables(images_rgb):
    """Every cable the frames hold in a colour of its own: the most cable-like of
    :data:`_MORE` candidates (more than :func:`find_cable` weighs: a group of two cables'
    colours may rank below one cable's on the first frame and above it over the frames),
    then each further candidate at least :data:`_ANOTHER` as cable-like over the frames,
    sharing no colour cluster with those found, of a hue (not colourless) at least
    :data:`_HUE_APART` from theirs (a candidate of a found cable's hue is its shading or a
    table of its hue), and not the shadow the cables cast (:data:`_ANOTHER_CAST`: a dark
    ring around two cables on a tinted table is thin, long and of the table's hue, so of a hue
    apart from theirs; on tuning look two_cables seeds 0-99 it was found as a further cable
    in 9 scenes, its likeness 0.48-0.96, and every true second cable's was 0.00). A candidate
    that holds a found cable's clusters offers its clusters of another hue
    (:func:`_other_part`).

    Two cables that cross are often one candidate (one thin object of two colours), which
    :func:`engine.stages.segmentation.sequence_colour` splits by hue.

    Returns
    -------
    list of (ColourRange, CableCandidate)
        The most cable-like first.
    """
    small, candidates, totals = _ranked(list(images_rgb), keep=_MORE)
    hsv = hsv_image(small)
    best = without_its_shadow(candidates[int(np.argmax(totals))], small)
    found, taken = [(range_of(hsv[best.mask]), best)], set(best.members)
    hues = [_hue_of(hsv[best.mask])]
    reference = max(totals)
    labels = _nearest(_lab(small), best.centres)
    for total, candidate in sorted(zip(totals, candidates), key=lambda item: -item[0]):
        if total < _ANOTHER * reference:
            continue
        if taken & set(candidate.members):  # a found cable with another: keep the other
            candidate = _other_part(candidate, taken, labels, hsv, hues)
            if candidate is None:
                continue
        hue = _hue_of(hsv[candidate.mask])
        if not _apart(hue, hues):
            continue
        cables = np.any([cable.mask for _, cable in found], axis=0)
        if _shadow_likeness(small, candidate.mask, cables) >= _ANOTHER_CAST:
            continue
        found.append((range_of(hsv[candidate.mask]), candidate))
        taken |= set(candidate.members)
        hues.append(hue)
    return found


def _apart(hue, hues):
    """Whether ``hue`` (None: colourless) lies :data:`_HUE_APART` or more from each of
    ``hues`` that has one."""
    return hue is not None and all(h is None or _hue_gap(h, hue) >= _HUE_APART for h in hues)


def _other_part(candidate, taken, labels, hsv, found_hues):
    """The clusters of a candidate that holds found clusters (``taken``) and others of a hue
    of their own, as a candidate of their own, or None. Their own: :func:`_apart` from the
    found cables' hues and from each found cluster's (a found candidate may hold two cables,
    and its mean hue is then neither's).

    The greedy grouping of :func:`colour_candidates` adds a cluster only when it makes the
    group more cable-like, so a found cable's clusters grouped with another hue's are often
    two cables crossing (a cable of a table's hue is found no other way: its shade side is
    the table's cluster). The other hue's pixels must be :data:`_PART` of the group's.
    """
    hues = {k: _hue_of(hsv[labels == k]) for k in taken | set(candidate.members)}
    against = list(found_hues) + [hues[k] for k in taken]
    others = [k for k in candidate.members if k not in taken and _apart(hues[k], against)]
    mask = candidate.mask & np.isin(labels, others)
    if not others or mask.sum() < _PART * candidate.mask.sum():
        return None
    return CableCandidate(candidate.score, tuple(others), candidate.centres, mask)


def _hue_of(hsv_pixels):
    """The circular mean hue of pixels (OpenCV units) of saturation and value of
    :data:`_HUED` or more, None when fewer than half of them are."""
    hued = (hsv_pixels[:, 1] >= _HUED) & (hsv_pixels[:, 2] >= _HUED)
    if not len(hsv_pixels) or hued.mean() < 0.5:
        return None
    angle = hsv_pixels[hued, 0].astype(float) * (2 * math.pi / 180.0)
    return (math.degrees(math.atan2(np.sin(angle).mean(), np.cos(angle).mean())) / 2.0) % 180.0


def _hue_gap(a, b):
    """How far apart two hues (or arrays of them) lie around OpenCV's circle of 180."""
    gap = np.abs(np.asarray(a, dtype=np.float64) - b) % 180.0
    return np.minimum(gap, 180.0 - gap)


def _ranked(images_rgb, keep, size=None):
    """The first frame's ``keep`` best candidates and their scores summed over the frames.

    The scoring size is ``size``, or :data:`_SMALL` or larger (:data:`_SHARPER`).

    Returns
    -------
    small : ndarray
        The first frame at the scoring size.
    candidates : list of CableCandidate
    totals : ndarray

    Raises
    ------
    ReconstructionError
        No candidate is thin (no cable pixels).
    """
    if size is None:
        size, (small, candidates) = _SMALL, colour_candidates(images_rgb[0], keep=keep)
        larger = 2 * _SMALL
        while larger < max(images_rgb[0].shape[:2]):
            found = colour_candidates(images_rgb[0], size=larger, keep=keep)
            if _best_score(found[1]) >= _SHARPER * _best_score(candidates):
                size, (small, candidates) = larger, found
            larger *= 2
    else:
        small, candidates = colour_candidates(images_rgb[0], size=size, keep=keep)
    candidates = [candidate for candidate in candidates if candidate.score > 0]
    if not candidates:
        raise ReconstructionError("no cable pixels: nothing thin of one colour stands out in "
                                  "the frames (pick the cable's colour, or give --hsv)")
    totals = np.array([candidate.score for candidate in candidates], dtype=float)
    for image in images_rgb[1:]:  # agreement across frames: each candidate scored on the others
        other = reduced(image, size)
        other_lab = _lab(other)
        diagonal = math.hypot(*other.shape[:2])
        labels = _nearest(other_lab, candidates[0].centres)
        for index, candidate in enumerate(candidates):
            totals[index] += _shaped_score(np.isin(labels, candidate.members), other_lab,
                                           diagonal)
    return small, candidates, totals


def model_space(image_rgb):
    """The colour space the model works in: chromaticity (red and green shares, which shading
    does not change) and brightness, each 0-255 (uint8, three channels)."""
    image = np.ascontiguousarray(image_rgb)
    total = cv2.transform(image.astype(np.float32), np.ones((1, 3), np.float32))
    share = cv2.divide(255.0, total)  # 0 where the total is 0 (so are red and green)
    red, green, _ = cv2.split(image)  # contiguous planes multiply faster than views
    red = cv2.multiply(red, share, dtype=cv2.CV_8U)
    green = cv2.multiply(green, share, dtype=cv2.CV_8U)
    brightness = cv2.convertScaleAbs(total, alpha=1.0 / 3.0)
    return cv2.merge([red, green, brightness])


def _rgb_space(image_rgb):
    return np.ascontiguousarray(image_rgb)


#: The model's colour spaces; its probability is the mean of theirs (RGB separates a cable
#: from a table of its own hue by brightness; chromaticity keeps a cable's shade side with its
#: lit side, and a shadow with its surface).
_SPACES = (_rgb_space, model_space)


def _histograms(images_rgb, seeds, widths, bins, others=None):
    """Per colour space (:data:`_SPACES`), colour histograms (``bins`` per channel) of seed
    pixels and of background pixels (far from the seed, plus ``others``), summed over the
    frames: a list of ``[cable, background]``."""
    ranges = [0, 256] * 3
    counts = [[np.zeros((bins,) * 3), np.zeros((bins,) * 3)] for _ in _SPACES]
    others = [None] * len(seeds) if others is None else others
    for image, seed, width, other in zip(images_rgb, seeds, widths, others):
        if not seed.any():
            continue
        cable, far = samples(seed, width, other)
        cable, far = cable.view(np.uint8), far.view(np.uint8)
        for space, pair in zip(_SPACES, counts):
            converted = space(image)
            pair[0] += cv2.calcHist([converted], [0, 1, 2], cable, [bins] * 3, ranges)
            pair[1] += cv2.calcHist([converted], [0, 1, 2], far, [bins] * 3, ranges)
    return counts


def samples(seed, width, other=None):
    """A frame's samples of the cable (the seed's pixels but its outline, unless that is all
    of it) and of the background (the pixels farther than ``width`` from the seed, and
    ``other``), boolean masks."""
    seed = np.ascontiguousarray(seed, dtype=bool).view(np.uint8)
    core = cv2.erode(seed, cv2.getStructuringElement(cv2.MORPH_CROSS, (3, 3)))
    grow = max(int(math.ceil(width)), 2)
    far = cv2.dilate(seed, cv2.getStructuringElement(
        cv2.MORPH_ELLIPSE, (2 * grow + 1, 2 * grow + 1))) == 0
    if other is not None:
        far |= other
    return (core if core.any() else seed) > 0, far


class ColourModel:
    """Each colour's probability of being the cable, from colour histograms of the cable and
    of the background (in each of :data:`_SPACES`) and the cable's share of the samples.

    Parameters
    ----------
    histograms : list of (ndarray, ndarray)
        Per colour space, the cable's and the background's smoothed, normalised histograms.
    prior : float
        The cable's share of the pixels (a colour as common in the cable as in the background
        is background).
    smoothing : float
        The smoothing they had, bins.

    Attributes
    ----------
    luts : list of ndarray, shape (bins, bins, bins)
        Per colour space, each bin's probability (0 to 255).
    level : float or None
        The probability (0 to 1) from which a pixel is the cable, when the model's own
        samples chose one (:func:`engine.stages.segmentation.calibrated_level`); None: the
        settings' ``probability``.
    banded : bool
        The cable is a row of bands of this colour with gaps of the table's colours between
        them (:func:`engine.stages.stripes.banded`): each frame's mask is bridged along the
        cable. Set by :func:`engine.stages.segmentation.sequence_colour` and the other
        learners, from the masks the model gives on the frames it was learnt from.
    seams : bool
        The model was learnt again from a banded model's masks and holds both colours of the
        bands (:func:`engine.stages.segmentation.sequence_colour`): the seams between the
        bands, mixed pixels of the two colours that neither calls cable, are closed
        (:data:`engine.stages.stripes.SEAM_REACH`).
    """

    def __init__(self, histograms, prior, smoothing=1.0):
        self.histograms, self.prior, self.smoothing = histograms, prior, smoothing
        self.level = None
        self.banded = False
        self.seams = False
        self.bins = histograms[0][0].shape[0]
        self.luts, self._mats = [], []
        for cable, background in histograms:
            weighted = prior * cable
            probability = weighted / (weighted + (1.0 - prior) * background + 1e-9)
            lut = np.ascontiguousarray(255.0 * probability, dtype=np.float32)
            self.luts.append(lut)
            # as one 3-D Mat: OpenCV's bindings would read a (b, b, b) array as b channels
            self._mats.append(cv2.Mat(lut, wrap_channels=False))

    @staticmethod
    def _smoothed(counts, smoothing):
        return [tuple(gaussian_filter(h / h.sum(), smoothing, mode="constant") for h in pair)
                for pair in counts]

    @classmethod
    def learn(cls, images_rgb, seeds, *, widths, others=None, bins=32, smoothing=1.0,
              prior_range=(0.05, 0.5)):
        """Learn from frames and their seed masks.

        Parameters
        ----------
        images_rgb : sequence of ndarray
        seeds : sequence of ndarray of bool
            The cable's sure pixels in each frame.
        widths : sequence of float
            The cable's width in each frame, pixels: background samples lie farther than a
            width from the seed.
        others : sequence of ndarray of bool, optional
            More background samples per frame (objects of the cable's colour but not its
            shape).
        bins : int, optional
            Histogram bins per channel.
        smoothing : float, optional
            Gaussian smoothing of the histograms, bins.
        prior_range : tuple of float, optional
            Bounds of the cable's share of the samples.

        Returns
        -------
        ColourModel

        Raises
        ------
        ValueError
            No cable or no background sample.
        """
        counts = _histograms(images_rgb, seeds, widths, bins, others)
        cable, background = counts[0]
        if cable.sum() == 0 or background.sum() == 0:
            raise ValueError("the colour model needs cable and background samples")
        prior = float(np.clip(cable.sum() / (cable.sum() + background.sum()), *prior_range))
        return cls(cls._smoothed(counts, smoothing), prior, smoothing)

    def probability(self, image_rgb):
        """Per pixel, 0 to 255: how likely its colour is the cable's (uint8), the mean over
        the colour spaces."""
        first, second = (cv2.calcBackProject([space(image_rgb)], [0, 1, 2], mat, [0, 256] * 3,
                                             1.0) for space, mat in zip(_SPACES, self._mats))
        return cv2.addWeighted(first, 0.5, second, 0.5, 0.0)

"""Masks that agree across views: each frame's mask checked against what the others carve.

A frame's mask is made from that frame alone, so it breaks where the cable's colour is lost
under a highlight or in shade, and it takes in whatever else has the cable's colour there: a
stray object seen in one view, a shadow's false strand, clutter. The other views know better.
In rounds:

1. Carve the masks (:func:`~engine.stages.carving.carve`, coarse to fine, in voxels somewhat larger
   than the reconstruction's: what follows needs a cable width, not a fraction of one).
2. In each view, judge the occupied voxels by the *other* views only (leave one out: the
   fraction of the other views seeing a voxel in which it falls on cable pixels), so that a
   view's mistakes never back themselves, and project their centres into it:

   * **remove**: mask pixels within the cable's radius plus ``keep_distance`` cable widths
     of a voxel the others agree on (``keep_agreement``) stay. Every other piece of the mask
     is removed when it reaches farther than the radius plus ``remove_distance`` widths
     from all the voxels the others would carve at all (their ``vote``): a stray object or a
     false strand goes whole, while the cable where other views lost it (their voxels fall
     short of ``keep_agreement`` but not of the vote) stays. Voxels need be seen by only
     ``keep_view_fraction`` of the views here: where the cable leaves many frames, the
     frames that do show it keep it.
   * **fill**: voxels the others agree on (``fill_agreement``) and seen by as many views as
     the reconstruction asks for make the fill footprint, about the cable's width. Where it
     bridges a *break* of the mask (see :func:`_breaks`: two pieces of the mask that end
     facing each other across it), the break is filled: up to ``max_gap`` cable widths
     unless the evidence says background, longer ones where the evidence says cable.

3. Carve again with the new masks while that still changes enough (``rounds``,
   ``min_change``).

A real object of the cable's colour is seen by every view and carves: it stays (that is the
segmentation's business). Voxels outside a view's frame take no part in judging it, and a
view in whose frame the others carve nothing, or that would lose more than ``max_removed``
of its mask (its camera is probably wrong), is left as it is. With few views the hull is
fat (the silhouettes meet in a hull much wider than the cable): near a crossing it covers much
of the image around the cable, so a false blob touching the cable there cannot be told from
cable and stays.
"""

import logging
from dataclasses import dataclass, replace

import cv2
import numpy as np

from ..io.packed_mask import PackedMask, unpacked
from ..progress import StageProgress, check_cancel
from ..settings import check_settings, setting
from ..threads import map_in_threads
from .carving import CarvingSettings, carve
from .segmentation import SegmentationSettings, cable_width, junction_map
from .skeleton_2d import fill_small_holes, thin

__all__ = ["MaskAgreementSettings", "MaskAgreementReport", "agree_masks"]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class MaskAgreementSettings:
    """How masks are made to agree across views (lengths in cable widths).

    Attributes
    ----------
    rounds : int
        Carve-and-correct rounds at most (0 turns the agreement off).
    min_change : float
        Another round is carved only while the last one changed at least this fraction of
        the mask pixels (and fewer than the round before it).
    voxels_per_radius : float
        The agreement's carves use voxels of the cable radius divided by this (coarser than
        the reconstruction's: cheaper, and still a few voxels across the cable).
    keep_agreement : float
        Voxels on cable pixels in at least this fraction of the other views seeing them make
        a view's keep footprint.
    keep_distance : float
        Mask pixels within the cable's radius plus this many cable widths of such a voxel
        stay.
    remove_distance : float
        Any other piece of the mask is removed when it reaches farther than the cable's
        radius plus this many cable widths from every voxel the other views would carve.
    keep_view_fraction : float
        Voxels that keep mask pixels need be seen by only this fraction of the views (and
        the carving's ``min_views``): where the cable leaves many frames, it still counts.
    fill_agreement : float
        Voxels on cable pixels in at least this fraction of the other views seeing them make
        a view's fill footprint.
    max_gap : float
        Breaks up to this long are filled without evidence (unless it says background).
    fill_evidence : float
        Longer breaks are filled where the cable evidence is at least this.
    background_evidence : float
        Pixels whose cable evidence is below this are never filled.
    max_removed : float
        A view that would lose more than this fraction of its mask pixels is left as it is
        (its camera is probably wrong).
    """

    rounds: int = setting(2, low=0)
    min_change: float = setting(0.005, low=0)
    voxels_per_radius: float = setting(2.0, above=0)
    keep_agreement: float = setting(0.8, above=0, high=1)
    keep_distance: float = setting(0.25, low=0, unit="widths")
    remove_distance: float = setting(1.0, low=0, unit="widths")
    keep_view_fraction: float = setting(0.25, above=0, high=1)
    fill_agreement: float = setting(0.8, above=0, high=1)
    max_gap: float = setting(3.0, low=0, unit="widths")
    fill_evidence: float = setting(0.35, low=0, high=1)
    background_evidence: float = setting(0.1, low=0, high=1)
    max_removed: float = setting(0.5, above=0, high=1)

    def __post_init__(self):
        check_settings(self)
        if self.background_evidence > self.fill_evidence:
            raise ValueError("MaskAgreementSettings.background_evidence must not exceed "
                             "fill_evidence")
        if self.remove_distance < self.keep_distance:
            raise ValueError("MaskAgreementSettings.remove_distance must be at least "
                             "keep_distance")


@dataclass(frozen=True, eq=False)
class MaskAgreementReport:
    """What the agreement changed.

    Attributes
    ----------
    names : tuple of str
        The views (camera names), in the order of the masks.
    removed, filled : tuple of int
        Per view, mask pixels removed and filled (the agreed mask against the given one).
    rounds : int
        Carve-and-correct rounds run.
    changed : tuple of int
        Pixels changed by each round (all views).
    left_alone : tuple of str
        Views the last round left as they were: no voxel the other views carve lies in
        their frame, or their mask would have lost more than ``max_removed`` (probably a
        wrong camera).
    junctions : list of ndarray of bool (PackedMask when packed), or None
        The junction maps given, brought up to date with the agreed masks (given ones kept
        on the mask, new ones found where breaks were filled); None if none were given.
    """

    names: tuple
    removed: tuple
    filled: tuple
    rounds: int
    changed: tuple
    left_alone: tuple = ()
    junctions: list = None

    def summary(self):
        """One line: pixels removed and filled, in how many views and rounds."""
        removed, filled = np.asarray(self.removed), np.asarray(self.filled)
        return (f"masks agreed across views in {self.rounds} round(s): {removed.sum()} pixels "
                f"removed in {(removed > 0).sum()} view(s), {filled.sum()} filled in "
                f"{(filled > 0).sum()} view(s)")


def _packed(item):
    return item if isinstance(item, PackedMask) else PackedMask(unpacked(item))


def agree_masks(cameras, masks, *, evidence=None, junctions=None, carving=CarvingSettings(),
                settings=MaskAgreementSettings(), segmentation=SegmentationSettings(),
                progress=None, cancel=None, packed=False, workers=1):
    """Masks with what no other view backs removed and breaks the others bridge filled.

    Parameters
    ----------
    cameras : sequence of Camera
    masks : sequence of (ndarray of bool, or callable returning one)
        One per camera, at its image size.
    evidence : sequence of (ndarray of float, callable returning one, or None), optional
        Per view, how surely each pixel is cable (0..1). Without it, only breaks up to
        ``settings.max_gap`` cable widths are filled.
    junctions : sequence of (ndarray of bool, or callable returning one), optional
        Junction maps of the masks, brought up to date in the report.
    carving : CarvingSettings, optional
        The reconstruction's carving (votes, views needed, threads); the agreement carves
        with ``settings.voxels_per_radius``.
    settings : MaskAgreementSettings, optional
    segmentation : SegmentationSettings, optional
        How junction maps are made where breaks are filled.
    progress : callable, optional
        ``progress(fraction, message)``.
    cancel : threading.Event, optional
    packed : bool, optional
        Return the masks and the report's junction maps as :class:`.PackedMask`: the masks
        are held packed throughout (one view's arrays at a time on each worker), for long
        sequences of large frames.
    workers : int, optional
        Threads agreeing the views' masks with the voxels, a view each at a time (0: one per
        CPU, at most :data:`~engine.threads.MOST_THREADS`); the masks are the same on any
        number.

    Returns
    -------
    masks : list of ndarray of bool, or of PackedMask
        The agreed masks (the given ones, as arrays, if nothing changed).
    report : MaskAgreementReport

    Raises
    ------
    ValueError
        Masks, evidence or junctions do not match the cameras.
    Cancelled
    """
    cameras = list(cameras)
    given, evidence = _checked_inputs(cameras, masks, evidence, junctions)
    stage = StageProgress(progress)
    current = list(given)  # packed masks are never changed, only replaced
    changed, left_alone, radius = [], [], None
    rounds = settings.rounds if len(cameras) >= carving.min_views else 0
    for number in range(rounds):
        part = stage.part(number / rounds, (number + 1) / rounds)
        check_cancel(cancel, "the mask agreement")
        try:
            grid = carve(cameras, current, radius=radius,
                         settings=_agreement_carving(carving, settings),
                         progress=part.part(0.0, 0.6), cancel=cancel)
        except ValueError as error:  # no view shows the cable: nothing to agree on
            log.info("masks not agreed: %s", error)
            break
        if not len(grid):
            log.info("masks not agreed: the views agree on no voxel")
            break
        radius = grid.radius
        voxels = _Voxels(grid, carving, len(cameras))
        pixels, count, left_alone = _agree_views(cameras, current, evidence, voxels, settings,
                                                 part.part(0.6, 1.0), cancel, workers)
        changed.append(pixels)
        log.debug("agreement round %d: %d pixels changed", number + 1, pixels)
        if (pixels <= settings.min_change * max(count, 1)
                or (len(changed) > 1 and pixels >= changed[-2])):
            break
    stage(1.0, "masks agreed")
    report = _report(cameras, given, current, junctions, changed, left_alone, segmentation,
                     packed)
    log.debug(report.summary())
    return (current if packed else [mask() for mask in current]), report


def _checked_inputs(cameras, masks, evidence, junctions):
    """The masks packed and the evidence as a list, one of each per camera (a ValueError
    otherwise)."""
    given = [_packed(item) for item in masks]
    if len(given) != len(cameras):
        raise ValueError(f"{len(given)} masks for {len(cameras)} cameras")
    for camera, mask in zip(cameras, given):
        if mask.shape != (camera.height, camera.width):
            raise ValueError(f"the mask of {camera.name!r} is {mask.shape[1]}x{mask.shape[0]}, "
                             f"its image {camera.width}x{camera.height}")
    evidence = [None] * len(cameras) if evidence is None else list(evidence)
    if len(evidence) != len(cameras):
        raise ValueError(f"{len(evidence)} evidence maps for {len(cameras)} cameras")
    if junctions is not None and len(junctions) != len(cameras):
        raise ValueError(f"{len(junctions)} junction maps for {len(cameras)} cameras")
    return given, evidence


def _agree_views(cameras, current, evidence, voxels, settings, progress, cancel, workers):
    """One round: every view's mask agreed with the voxels (``current`` updated in place);
    ``(pixels changed, cable pixels now, views left alone)``."""

    def agreed(k):
        check_cancel(cancel, "the mask agreement")
        mask = current[k]()
        new, judged = _agree_view(cameras[k], mask, unpacked(evidence[k], np.float32), voxels,
                                  settings)
        if not judged:
            return None, None
        return (None, 0) if new is mask else (PackedMask(new), int(np.count_nonzero(new != mask)))

    def done(k):
        progress((k + 1) / len(cameras), "agreeing masks")

    outcomes = map_in_threads(workers, "agree", agreed, range(len(cameras)), done)
    pixels, count, left_alone = 0, 0, []
    for k, (new, changed) in enumerate(outcomes):
        if changed is None:
            left_alone.append(cameras[k].name)
        elif new is not None:
            pixels += changed
            current[k] = new
        count += current[k].count
    return pixels, count, left_alone


def _report(cameras, given, current, junctions, changed, left_alone, segmentation, packed):
    """What the agreement did to each view, with its junction maps brought up to date."""
    removed, filled, updated = [], [], None if junctions is None else []
    for k, (before, after) in enumerate(zip(given, current)):
        old = before()
        new = old if after is before else after()
        removed.append(int(np.count_nonzero(old & ~new)))
        filled.append(int(np.count_nonzero(new & ~old)))
        if junctions is not None:
            junction = _updated_junctions(unpacked(junctions[k]), old, new, segmentation)
            updated.append(PackedMask(junction) if packed else junction)
    return MaskAgreementReport(names=tuple(camera.name for camera in cameras),
                               removed=tuple(removed), filled=tuple(filled),
                               rounds=len(changed), changed=tuple(changed),
                               left_alone=tuple(left_alone), junctions=updated)


def _agreement_carving(carving, settings):
    """The reconstruction's carving, in the agreement's voxels, keeping the voxels seen by
    ``keep_view_fraction`` of the views (the fill footprint asks for more afterwards)."""
    return replace(carving, voxels_per_radius=settings.voxels_per_radius,
                   min_view_fraction=min(carving.min_view_fraction,
                                         settings.keep_view_fraction))


class _Voxels:
    """The occupied voxels of an agreement carve: centres, views seeing them, views hit."""

    def __init__(self, grid, carving, views):
        self.points = grid.occupied_points()
        self.visible = grid.visible.astype(np.float64)
        self.hits = np.rint(grid.agreement * self.visible)
        self.radius, self.size = grid.radius, grid.voxel_size
        self.vote = carving.vote
        self.strict = max(carving.min_views, carving.min_view_fraction * views - 1e-9)


def _agree_view(camera, mask, evidence, voxels, settings):
    """One view's agreed mask (the mask itself if unchanged) and whether it was judged."""
    if evidence is not None and evidence.shape != mask.shape:
        raise ValueError(f"the evidence of {camera.name!r} is {evidence.shape[1]}x"
                         f"{evidence.shape[0]}, its image {camera.width}x{camera.height}")
    if not mask.any():
        return mask, True  # nothing to remove, and no two pieces to bridge
    seen, row, col, depth, agreement = _others_verdict(camera, mask, voxels)
    carved = seen & (agreement >= voxels.vote - 1e-9)
    if not carved.any():
        return mask, False
    focal = float(np.mean(camera.focal))
    depth_px = focal / float(np.median(depth[carved]))
    radius_px, voxel_px = voxels.radius * depth_px, voxels.size * depth_px
    width = 2.0 * radius_px
    near = radius_px + settings.keep_distance * width
    far = radius_px + settings.remove_distance * width
    # the work is done in the box of the mask and the footprints
    rows = np.concatenate([row[carved], np.nonzero(mask.any(axis=1))[0]])
    cols = np.concatenate([col[carved], np.nonzero(mask.any(axis=0))[0]])
    margin = int(np.ceil(far + 2 * width)) + 2
    top, left = max(rows.min() - margin, 0), max(cols.min() - margin, 0)
    bottom = min(rows.max() + margin + 1, camera.height)
    right = min(cols.max() + margin + 1, camera.width)
    box = np.s_[top:bottom, left:right]
    local = mask[box]

    def distance(select):
        """Pixels to the nearest selected voxel's centre."""
        marks = np.ones(local.shape, np.uint8)
        marks[row[select] - top, col[select] - left] = 0
        return cv2.distanceTransform(marks, cv2.DIST_L2, cv2.DIST_MASK_5)

    # pieces of the mask off the keep footprint that reach beyond all the others carve
    keep = carved & (agreement >= settings.keep_agreement - 1e-9)
    kept = _without_strays(local, local & (distance(keep) > near),
                           lambda: distance(carved) > far)
    total = int(np.count_nonzero(local))
    lost = total - int(np.count_nonzero(kept))
    if lost > settings.max_removed * total:
        log.info("%s: the other views back only %d of its %d mask pixels; left as it is",
                 camera.name, total - lost, total)
        return mask, False
    fill = (seen & (agreement >= settings.fill_agreement - 1e-9)
            & (voxels.visible >= voxels.strict))
    filled = kept
    if fill.any():
        # the fill footprint: the voxels' centres, splatted just enough to close the lattice
        footprint = distance(fill) <= max(0.7 * voxel_px, 1.0)
        bridge = _breaks(kept, footprint, None if evidence is None else evidence[box], width,
                         settings)
        if bridge is not None:
            filled = kept | bridge
    if filled is local:
        return mask, True
    new = mask.copy()
    new[box] = filled
    return new, True


def _others_verdict(camera, mask, voxels):
    """Where the voxels fall in ``camera``'s view and what the other views say of each, leaving
    this one out: ``(seen, row, col, depth, agreement)``, ``agreement`` the share of the other
    views that see a voxel and put it on cable."""
    pixels, depth = camera.project(voxels.points)
    with np.errstate(invalid="ignore"):
        col, row = np.floor(pixels[:, 0]), np.floor(pixels[:, 1])
        seen = (depth > 0) & (col >= 0) & (row >= 0) & (col < camera.width) & (row < camera.height)
    col = np.where(seen, col, 0).astype(np.int64)
    row = np.where(seen, row, 0).astype(np.int64)
    hit = seen & mask[row, col]
    others = voxels.visible - seen
    agreement = np.where(others > 0, (voxels.hits - hit) / np.maximum(others, 1), 0.0)
    return seen, row, col, depth, agreement


def _without_strays(local, doubtful, beyond):
    """``local`` without its ``doubtful`` pieces that reach somewhere ``beyond()`` (a callable
    giving a mask: only computed when some piece is doubtful)."""
    if not doubtful.any():
        return local
    count, labels = cv2.connectedComponents(doubtful.view(np.uint8), connectivity=8)
    wrong = np.zeros(count, dtype=bool)
    wrong[labels[doubtful & beyond()]] = True
    wrong[0] = False
    return local & ~wrong[labels] if wrong.any() else local


def _grown(mask, radius):
    """``mask`` dilated by a disc of ``radius`` pixels."""
    return cv2.distanceTransform((~mask).view(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_5) <= radius


def _skeleton_ends(mask, width):
    """The ends of the mask's skeleton, away from the window's border (where pieces are cut).

    Before thinning, small holes are filled (each would make a loop) and threads thinner
    than a third of the cable removed (an opening); after it, branches shorter than
    :func:`_spur` are cut, which draws each end back by as much.
    """
    spur = _spur(width)
    size = 2 * max(int(round(width / 6.0)), 1) + 1
    opened = cv2.morphologyEx(fill_small_holes(mask, spur * spur).view(np.uint8),
                              cv2.MORPH_OPEN,
                              cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (size, size)))
    skeleton = thin(opened > 0)
    kernel = np.ones((3, 3), np.float32)

    def neighbours(image):
        return cv2.filter2D(image.view(np.uint8), -1, kernel,
                            borderType=cv2.BORDER_CONSTANT) - image

    for _ in range(int(np.ceil(spur))):
        skeleton &= neighbours(skeleton) > 1
    ends = skeleton & (neighbours(skeleton) == 1)
    # thinning draws a piece cut by the border back from it by its half width, then the cut
    border = _border(width)
    ends[:border], ends[-border:], ends[:, :border], ends[:, -border:] = False, False, False, False
    return ends


def _spur(width):
    """Skeleton branches shorter than this (pixels) are noise of the outline."""
    return 0.5 * width + 1.0


def _border(width):
    """Skeleton ends this near a window's border may be where the window cut the piece."""
    return int(np.ceil(2.0 * _spur(width))) + 2


def _tube(first, second, to_first, to_second, length, width):
    """A tube across the gap between two pieces' ends, as wide as they are.

    Each end is its face (its pixels beside the gap: within the ellipse ``to_first +
    to_second <= length + width``), with a centre, a width (the face's extent across its
    direction) and a direction (from the pixels a cable width behind the face to it). The
    tube's centre is the cubic (Hermite) curve from one face's centre to the other's along
    those directions, so it follows a bend; it is as wide as the narrower face.
    """
    zone = (to_first + to_second <= length + width) & ~first & ~second
    beside = cv2.dilate(zone.view(np.uint8), np.ones((3, 3), np.uint8)) > 0
    ends = []
    for piece, to_other in ((first, to_second), (second, to_first)):
        face = np.argwhere(piece & beside)[:, ::-1].astype(np.float64)
        behind = np.argwhere(piece & (to_other > length + width)
                             & (to_other <= length + 2 * width))[:, ::-1].astype(np.float64)
        if not len(face):
            return np.zeros(first.shape, dtype=bool)
        centre = face.mean(axis=0)
        ends.append((face, centre, centre - behind.mean(axis=0) if len(behind) else None))
    (face_a, start, out), (face_b, stop, back) = ends
    span = float(np.linalg.norm(stop - start))
    tube = np.zeros(first.shape, np.uint8)
    if span < 1e-9:
        return tube > 0
    chord = (stop - start) / span
    out = chord if out is None or not np.linalg.norm(out) else out / np.linalg.norm(out)
    back = -chord if back is None or not np.linalg.norm(back) else back / np.linalg.norm(back)
    radii = []
    for face, centre, direction in ((face_a, start, out), (face_b, stop, back)):
        across = (face - centre) @ np.array([-direction[1], direction[0]])
        radii.append(0.5 * (across.max() - across.min()))
    s = np.linspace(0.0, 1.0, max(int(np.ceil(span)) + 1, 2))[:, None]
    curve = ((2 * s**3 - 3 * s**2 + 1) * start + (s**3 - 2 * s**2 + s) * span * out
             + (-2 * s**3 + 3 * s**2) * stop - (s**3 - s**2) * span * back)
    # the narrower face (a face on a crossing's blob is wider than the cable)
    radius = int(round(min(min(radii), 0.5 * width) * 16))
    for x, y in curve:
        cv2.circle(tube, (int(round(x * 16)), int(round(y * 16))), radius, 1, thickness=-1,
                   lineType=cv2.LINE_8, shift=4)
    return tube > 0


def _breaks(mask, footprint, evidence, width, settings):
    """Pixels near the fill footprint that bridge a break of the mask; None if none do.

    A break is a stretch of the footprint the mask misses whose middle lies some way from
    the mask (a sliver of the footprint along the mask's side does not), beside two pieces
    of the mask that do not meet nearby (the two arms of a crossing's corner do) and that
    both *end* there (their skeletons, spurs cut, end beside the gap: two strands side by
    side, or a cable's end beside another strand, are no break; nor, alas, is a break
    right beside a crossing, whose blob does not end). A break no longer than ``max_gap``
    cable widths is filled with a tube between the two ends (:func:`_tube`) unless the
    evidence says background; a longer one where the evidence says cable. The fill stays
    within half a cable width of the footprint.
    """
    outside = cv2.distanceTransform((~mask).view(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_5)
    gaps = footprint & ~mask
    depth = max(0.25 * width, 1.5)
    seeds = gaps & (outside > depth)
    count, labels, stats, _ = cv2.connectedComponentsWithStats(seeds.view(np.uint8),
                                                               connectivity=8)
    if count < 2:
        return None
    reach = int(np.ceil(depth + 1.5))
    disc = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * reach + 1, 2 * reach + 1))
    bridge = np.zeros(mask.shape, dtype=bool)
    # a break a cable width long already has this much of it that deep
    least = max(0.1 * width * width, 4.0)
    for label in np.flatnonzero(stats[:, cv2.CC_STAT_AREA] >= least):
        if label == 0:
            continue
        x, y, w, h = stats[label, :4]
        margin = int(np.ceil(1.5 * width)) + reach
        top, left = max(y - margin, 0), max(x - margin, 0)
        window = np.s_[top:y + h + margin, left:x + w + margin]
        local_mask = mask[window]
        seed = labels[window] == label
        # the mask's pieces in the window, and those beside the seed
        _, parts = cv2.connectedComponents(local_mask.view(np.uint8), connectivity=8)
        beside = np.unique(parts[(cv2.dilate(seed.view(np.uint8), disc) > 0) & local_mask])
        beside = beside[beside > 0]
        if len(beside) < 2:
            continue
        distances = [cv2.distanceTransform((parts != part).view(np.uint8), cv2.DIST_L2,
                                           cv2.DIST_MASK_5) for part in beside]
        # skeleton ends, from a wider window (the pieces' stubs in this one are short)
        wide = margin + _border(width) + 1
        outer = np.s_[max(y - wide, 0):y + h + wide, max(x - wide, 0):x + w + wide]
        tips = _skeleton_ends(mask[outer], width)
        tips = tips[top - outer[0].start:top - outer[0].start + local_mask.shape[0],
                    left - outer[1].start:left - outer[1].start + local_mask.shape[1]]
        ends = [tips & (parts == part) for part in beside]
        # the footprint says where the break is, the mask's pieces how wide: a cable's
        # voxels need not project out to the edges of its mask
        gap = _grown(footprint[window], 0.5 * width) & ~local_mask
        local_evidence = None if evidence is None else evidence[window]
        for i in range(len(beside)):
            for j in range(i + 1, len(beside)):
                between = _between(parts, beside[[i, j]], distances[i], distances[j],
                                   ends[i], ends[j], gap, local_evidence, width, settings)
                if between is not None:
                    bridge[window] |= between
    return bridge if bridge.any() else None


def _between(parts, pair, distance_a, distance_b, ends_a, ends_b, gap, evidence, width,
             settings):
    """The fill between two pieces of the mask (labels ``pair`` in ``parts``) across the break
    ``gap``, or None: both must end beside the break; a short break is filled with a tube
    unless the evidence says background, a long one where the evidence says cable."""
    length = float(distance_a[parts == pair[1]].min())
    near = length + 2.0 * width + _spur(width)
    if not ((ends_a & (distance_b <= near)).any() and (ends_b & (distance_a <= near)).any()):
        return None
    if length <= settings.max_gap * width:
        between = gap & _tube(parts == pair[0], parts == pair[1], distance_a, distance_b,
                              length, width)
        if evidence is not None:
            between &= evidence >= settings.background_evidence
        return between
    if evidence is None:
        return None
    # within the ellipse around the gap that holds a bent stretch too
    return (gap & (distance_a + distance_b <= 2.0 * length)
            & (evidence >= settings.fill_evidence))


def _updated_junctions(junctions, given, agreed, segmentation):
    """Junction maps for an agreed mask: the given ones on the mask, and new ones found near
    the filled pixels (a crossing the segmentation broke could not show its junction)."""
    if junctions is None:
        junctions = np.zeros(agreed.shape, dtype=bool)
    kept = junctions & agreed
    filled = agreed & ~given
    if not filled.any():
        return kept
    width = cable_width(agreed)
    found = junction_map(agreed, width, segmentation)
    grow = 2 * int(np.ceil(width)) + 1
    near = cv2.dilate(filled.view(np.uint8), np.ones((grow, grow), np.uint8)) > 0
    # a new junction disc counts whole when it touches a filled break
    count, labels = cv2.connectedComponents(found.view(np.uint8), connectivity=8)
    touching = np.unique(labels[found & near])
    return kept | np.isin(labels, touching[touching > 0])

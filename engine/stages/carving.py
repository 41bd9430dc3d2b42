"""Occupancy and junction voxel grids from masks and cameras (paper §3.2).

A voxel is *occupied* when its centre falls on cable pixels in at least half (``vote``) of the
views in which it lies inside the frame; a *junction* voxel is an occupied one that falls on
junction pixels in at least half of those views.

Coarse to fine, so the work follows the cable and not its box: the region is first carved in
big voxels, only the occupied ones are split into eight, and so on down to the fine size. A
coarse voxel must never be dropped when one of its fine voxels would be occupied, so it is
tested against its whole footprint in each view (a disc around its centre's projection that
holds the projection of the whole voxel): it *hits* a view when a cable pixel lies in that
disc (the distance transform of the mask tells at once), it *counts* in a view only when its
footprint lies entirely inside the frame, and it survives when it hits at least ``vote`` of
the views it counts in. Every fine voxel inside hits no more views and counts in no fewer, so
the coarse test never loses one (a test checks the result equals a carve of every fine voxel
of the region).

Nothing here depends on the image count or size for memory: masks are read one view at a time
(arrays or callables that load them), kept bit-packed between levels, and only the voxels of
the current level are held. The voxels follow the masks, though: masks that take in much of
the table, or too few views to bound the cable, make billions of them. The carved grid is a
list of the occupied voxels, never a box (a thin wire across a large floor has a box of
hundreds of millions of voxels, and a few hundred thousand occupied). Before each split and
before the grid is built, the voxels' memory (and what the stages after carving build on them)
is checked against a budget (``memory_mb``); past it, the
carve starts again in voxels twice as large (down to one per cable radius: the grid's
``voxel_size`` says so), and past that it stops with a clear error rather than run the
machine out of memory.

The region comes from the data: the cameras' common look-at point and what they see around it
at that distance, carved at the coarsest level with the cable's own masks. The fine voxel size
comes from the cable's radius, estimated from its width in the images unless given.
"""

import logging
import math
from dataclasses import dataclass

import cv2
import numpy as np

from ..errors import ReconstructionError
from ..geometry.upright import look_at_point
from ..io.packed_mask import PackedMask, unpacked
from ..progress import StageProgress, check_cancel
from ..settings import check_settings, setting
from ..threads import worker_pool
from . import sparse_voxels
from .segmentation import cable_width

__all__ = ["CarvingSettings", "VoxelGrid", "carve", "scene_region"]

log = logging.getLogger(__name__)

#: The 8 children of a voxel, as offsets of twice its index.
_CHILDREN = np.array([[i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)], dtype=np.int64)
#: Voxels projected per batch (bounds the memory of one view's projection).
_BATCH = 1 << 17
#: Views voted on between two drops of the voxels that cannot pass any more (their votes are
#: shared out to the threads, a view each).
_GROUP = 5
#: A view's vote on a voxel, a bit each (and 8: on a junction pixel, at the fine level).
_SEEN, _COUNTED, _HIT = 1, 2, 4
#: Bytes a voxel of a level costs while it is voted on (its index, lattice and votes).
_LEVEL_BYTES = 80
#: Past the memory budget, the carve is tried again in voxels twice as large while there are
#: at least this many voxels per cable radius (two across the cable).
_LEAST_VOXELS_PER_RADIUS = 1.0
#: Bytes the carved grid costs per occupied voxel (its index, junction flag, views and
#: agreement: 31), and the segment graph at its peak per voxel of the grid's core (its
#: neighbour tables, adjacency and distances, as tracemalloc counts them; the rod fit's voxel
#: points cost less). ``python -m engine bench memory`` runs whole captures against the budget.
_VOXEL_BYTES, _CORE_BYTES = 32, 1200


@dataclass(frozen=True)
class CarvingSettings:
    """How the grids are carved.

    Attributes
    ----------
    voxels_per_radius : float
        Fine voxel size is the cable radius divided by this (3 puts 6 voxels across the cable).
    vote : float
        Fraction of the views seeing a voxel in which it must fall on cable (or junction)
        pixels.
    min_views : int
        A voxel seen by fewer views is never occupied.
    min_view_fraction : float
        Nor is one seen by fewer than this fraction of all views: far from the cable, a voxel
        seen by a few cameras only can fall on cable pixels in all of them. Low, because a view
        that does not frame a voxel is no evidence against it: where the views each frame part
        of the cable (``bench topology``'s hard scenes), 0.5 lost the stretches out of most
        frames; 0.3 keeps them and changes no row of ``bench pipeline`` or ``bench carve``
        (README, *Hard topology*).
    min_piece_length : float
        Occupied pieces (26-connected) whose box has a diagonal shorter than this many radii
        are dropped: with few views, rays of different parts of the cable meet in small
        ghost blobs away from it.
    core_agreement : float
        The segment graph is built on the hull's core: occupied voxels on cable pixels in at
        least this fraction of their views (the half-vote hull is several radii wide and tall
        where views look along the cable; its core is about one radius from the centreline).
    follow_length : float
        Each free end of the core's graph is followed through the hull, up to this many
        radii, to the junction missing a branch or the free end it broke from; what the walk
        passes joins the core (where a strand's masks miss it in some views, its core
        breaks; README, *Free ends followed through the hull*). 0: not followed.
    root_cells : int
        The coarsest level has about this many voxels along the region's side.
    coarse_to_fine : bool
        Carve coarse to fine; off, every fine voxel of the region is tested (slow: for tests).
    threads : int
        Threads voting on voxels, a view each (0: one per CPU, at most 4); the grid is the
        same on any number.
    cache_mb : float
        The views' distance maps (2 bytes a pixel) are kept between levels when they fit in
        this many megabytes, and recomputed at each level when not.
    memory_mb : float
        The voxels (while carved, and the grid and what the stages after it build on it) may
        take this many megabytes: a carve that would need more starts again in voxels twice
        as large (at least one per radius), and past that stops with a
        :class:`.ReconstructionError` before it allocates them (masks that take in far more
        than a cable, or too few views to bound it).
    """

    voxels_per_radius: float = setting(3.0, above=0)
    vote: float = setting(0.5, above=0, high=1)
    min_views: int = setting(3, low=1, unit="views")
    min_view_fraction: float = setting(0.3, low=0, high=1)
    min_piece_length: float = setting(10.0, low=0, unit="r")
    core_agreement: float = setting(0.95, above=0, high=1)
    follow_length: float = setting(25.0, low=0, unit="r")
    root_cells: int = setting(64, low=2)
    coarse_to_fine: bool = True
    threads: int = setting(0, low=0)
    cache_mb: float = setting(256.0, low=0, unit="MB")
    memory_mb: float = setting(2048.0, above=0, unit="MB")

    def __post_init__(self):
        check_settings(self)


@dataclass(frozen=True, eq=False)
class VoxelGrid:
    """The carved voxels, kept as a list: memory follows the cable, not its box.

    Attributes
    ----------
    index : ndarray of int64, shape (N, 3)
        The occupied voxels' indices along world x, y, z, in C order (as ``numpy.argwhere``
        lists them), each at least 1 (one empty voxel of margin before the first).
    junction : ndarray of bool, shape (N,)
        Which of them are junction voxels.
    origin : ndarray, shape (3,)
        World position of the centre of voxel ``[0, 0, 0]``.
    voxel_size : float
    radius : float
        The cable radius the grid was made for (world units).
    visible : ndarray of int16, shape (N,)
        Views in which each voxel lies inside the frame.
    agreement : ndarray of float32, shape (N,)
        Fraction of those views in which it falls on cable pixels. The half-vote hull is fat;
        its voxels where (nearly) all views agree are the cable's core.
    """

    index: np.ndarray
    junction: np.ndarray
    origin: np.ndarray
    voxel_size: float
    radius: float
    visible: np.ndarray = None
    agreement: np.ndarray = None

    def __len__(self):
        return len(self.index)

    def core(self, agreement):
        """Which voxels, ``(N,)`` bool, fall on cable pixels in at least this fraction of
        their views."""
        return self.agreement >= agreement - 1e-6

    def centres(self, index):
        """World positions of voxel indices ``(M, 3)``."""
        return self.origin + np.asarray(index, dtype=np.float64) * self.voxel_size

    def occupied_points(self, which=None):
        """World positions of the voxels' centres (those where ``which`` is True), ``(M, 3)``."""
        return self.centres(self.index if which is None else self.index[which])

    @property
    def shape(self):
        """The voxels' box with one empty voxel of margin on each side."""
        return tuple(int(n) for n in self.index.max(axis=0) + 2) if len(self) else (1, 1, 1)


def _radius_in_view(camera, mask, centre):
    """Half the cable's width in ``mask`` at the depth of ``centre``, in world units (None if
    the view shows no cable or looks away)."""
    width = cable_width(mask)
    depth = camera.world_to_camera(centre[None])[0, 2]
    if width > 0 and depth > 0:
        return 0.5 * width * depth / np.mean(camera.focal)
    return None


def scene_region(cameras):
    """A cube holding everything the cameras see around the point they look at.

    Returns
    -------
    lower : ndarray, shape (3,)
        The cube's lower corner.
    side : float
    """
    centre = look_at_point(cameras)
    half = 0.0
    for camera in cameras:
        depth = camera.world_to_camera(centre[None])[0, 2]
        if depth > 0:
            half = max(half, depth * max(camera.width, camera.height) / (2 * min(camera.focal)))
    if half == 0.0:
        raise ValueError("the cameras look away from each other: no common region")
    return centre - half, 2.0 * half


class _View:
    """One view's mask kept bit-packed between levels, and its distance map if it may be kept.

    The distance map (pixels to the nearest cable pixel) serves every coarse level; kept, it is
    rounded down to 1/8 pixel in 16 bits (never more than the true distance, so the coarse test
    stays conservative).
    """

    def __init__(self, camera, mask, junction, keep_distance):
        self.camera = camera
        self.mask = mask if isinstance(mask, PackedMask) else PackedMask(mask)
        self.junction = junction
        self.keep_distance = keep_distance
        self._distance = None

    def distance(self, mask):
        if self._distance is not None:
            return self._distance.astype(np.float32) / 8
        distance = cv2.distanceTransform((~mask).view(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_5)
        if self.keep_distance:
            self._distance = np.floor(np.minimum(distance, 65535 / 8) * 8).astype(np.uint16)
        return distance


def _pixels(camera, lattice, lower, size):
    """Image coordinates and depth of voxel centres ``lower + size * lattice`` (``lattice``:
    three float32 columns of index + 1/2), in float32: a lattice needs no matrix product."""
    rotation = camera.R
    base = rotation @ lower + camera.t
    x, y, z = (np.float32(base[k]) + np.float32(size * rotation[k, 0]) * lattice[0]
               + np.float32(size * rotation[k, 1]) * lattice[1]
               + np.float32(size * rotation[k, 2]) * lattice[2] for k in range(3))
    u, v = camera.image_coordinates(x, y, z)
    return u, v, z


def _fine_votes(camera, mask, lattice, lower, size, junction=None):
    """Per voxel: inside the frame (seen), on a mask pixel (hit) and on a junction pixel."""
    u, v, depth = _pixels(camera, lattice, lower, size)
    with np.errstate(invalid="ignore"):
        col, row = np.floor(u), np.floor(v)
        seen = (depth > 0) & (col >= 0) & (row >= 0) & (col < camera.width) & (row < camera.height)
    rows, cols = row[seen].astype(np.int64), col[seen].astype(np.int64)
    hit = np.zeros(len(depth), dtype=bool)
    hit[seen] = mask[rows, cols]
    if junction is None:
        return seen, hit, None
    on_junction = np.zeros(len(depth), dtype=bool)
    on_junction[seen] = junction[rows, cols]
    return seen, hit, on_junction


def _coarse_votes(camera, distance, lattice, lower, size):
    """Per coarse voxel: footprint touching the frame, wholly inside it, holding cable."""
    u, v, depth = _pixels(camera, lattice, lower, size)
    half_diagonal = 0.5 * math.sqrt(3.0) * size
    near = depth - half_diagonal
    # the voxel's projection lies in this disc (10% more with lens distortion), and the pixel
    # a fine voxel inside falls on has its centre within 1/sqrt(2) pixel of its projection
    scale = max(camera.focal) * (1.1 if np.any(camera.distortion) else 1.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        reach = np.where(near > 0, scale * half_diagonal / near + 0.71, np.inf)
    unbounded = ~np.isfinite(reach) | ~np.isfinite(u) | ~np.isfinite(v)
    u, v = np.where(unbounded, 0.0, u), np.where(unbounded, 0.0, v)
    reach = np.where(unbounded, np.inf, reach)
    width, height = camera.width, camera.height
    inside = (u - reach >= 0) & (v - reach >= 0) & (u + reach <= width) & (v + reach <= height)
    touches = (u + reach >= 0) & (v + reach >= 0) & (u - reach <= width) & (v - reach <= height)
    col = np.clip(np.floor(u), 0, width - 1)
    row = np.clip(np.floor(v), 0, height - 1)
    # nearest cable pixel centre from the footprint's centre: within the pixel's distance
    # value, plus the way from the centre to that pixel's centre
    slack = np.hypot(u - (col + 0.5), v - (row + 0.5))
    # (the 5x5 chamfer distance is within 2% of the true one: 3% keeps the test conservative)
    hit = touches & (distance[row.astype(np.int64), col.astype(np.int64)]
                     <= 1.03 * (reach + slack))
    hit |= unbounded
    return touches, inside, hit


class _Carver:
    """Votes of one level's voxels over every view."""

    def __init__(self, views, lower, settings, pool, progress, cancel):
        self.views, self.lower, self.settings, self.pool = views, lower, settings, pool
        self.progress, self.cancel = progress, cancel

    def level(self, index, size, fine):
        """Vote on the voxels ``index`` (int, (N, 3)) of edge ``size``.

        Returns
        -------
        kept : ndarray of int
            Positions in ``index`` of the voxels that pass.
        counted, hits : ndarray of int
            Their views counted and views hit.
        junction : ndarray of bool or None
            At the fine level, their junction vote.
        """
        settings, total = self.settings, len(self.views)
        least = max(settings.min_views, settings.min_view_fraction * total - 1e-9)
        alive = np.arange(len(index))  # the voxels still in the running, and their votes:
        seen, counted, hits, junction_hits = (np.zeros(len(index), dtype=np.int32)
                                              for _ in range(4))
        # The views are voted on a group at a time, a view a thread (its mask unpacked, its
        # distance map made and every voxel projected into it there), and their votes added
        # in the views' order: whole numbers, so the sums are the same on any number of
        # threads. After each group the voxels that cannot pass any more are dropped.
        batches = list(_batches(index))
        for first in range(0, total, _GROUP):
            group = range(first, min(first + _GROUP, total))
            check_cancel(self.cancel, "carving")
            codes = self.pool.map(lambda number: self._view_votes(
                self.views[number], batches, len(index), size, fine), group)
            for number, code in zip(group, codes):
                seen += code & _SEEN
                counted += (code & _COUNTED) >> 1
                hits += (code & _HIT) >> 2
                if fine:
                    junction_hits += code >> 3
                self.progress((number + 1) / total, "carving")
            remaining = total - group[-1] - 1
            if remaining:
                # drop the voxels that cannot pass any more: at best every remaining view sees
                # and hits them (a coarse voxel's hit need not count)
                gain = remaining * (1.0 - settings.vote) if fine else remaining
                possible = ((hits + gain >= settings.vote * counted - 1e-9)
                            & (seen + remaining >= least))
                if not possible.all():
                    alive, index = alive[possible], index[possible]
                    seen, counted, hits, junction_hits = (
                        votes[possible] for votes in (seen, counted, hits, junction_hits))
                    batches = list(_batches(index))
        passed = (seen >= least) & (hits >= settings.vote * counted - 1e-9)
        junction = (junction_hits >= settings.vote * counted - 1e-9) & passed if fine else None
        return alive[passed], counted[passed], hits[passed], \
            (junction[passed] if fine else None)

    def _view_votes(self, view, batches, count, size, fine):
        """One view's votes on the ``count`` voxels of ``batches``, a byte each: seen
        (:data:`_SEEN`), counted, hit and, at the fine level, on a junction."""
        check_cancel(self.cancel, "carving")
        mask = view.mask()
        junction = unpacked(view.junction) if fine and view.junction is not None else None
        distance = None if fine else view.distance(mask)
        code = np.zeros(count, dtype=np.uint8)
        for part, lattice in batches:
            if fine:
                s, h, j = _fine_votes(view.camera, mask, lattice, self.lower, size, junction)
                c = s  # a fine voxel counts where it is seen
            else:
                s, c, h = _coarse_votes(view.camera, distance, lattice, self.lower, size)
                j = None
            votes = s.view(np.uint8) | (c.view(np.uint8) << 1) | (h.view(np.uint8) << 2)
            code[part] = votes if j is None else votes | (j.view(np.uint8) << 3)
        return code


def _batches(index):
    """Slices of at most ``_BATCH`` voxels and their float32 lattice columns (index + 1/2)."""
    for start in range(0, len(index), _BATCH):
        part = slice(start, start + _BATCH)
        yield part, [index[part, k].astype(np.float32) + np.float32(0.5) for k in range(3)]


def carve(cameras, masks, junctions=None, *, radius=None, region=None,
          settings=CarvingSettings(), progress=None, cancel=None):
    """Carve the occupancy and junction grids of a cable.

    Parameters
    ----------
    cameras : sequence of Camera
    masks : sequence of (ndarray of bool, or callable returning one)
        The cable masks, one per camera, at the camera's image size.
    junctions : sequence of (ndarray of bool, or callable returning one), optional
        Junction masks, one per camera; without them no voxel is a junction.
    radius : float, optional
        The cable radius in world units (estimated from the masks if not given).
    region : tuple (lower corner, side), optional
        The cube to carve (default: :func:`scene_region`).
    settings : CarvingSettings, optional
    progress : callable, optional
        ``progress(fraction, message)``.
    cancel : threading.Event, optional
        Checked once per view and level.

    Returns
    -------
    VoxelGrid

    Raises
    ------
    ValueError
        Masks and cameras do not match, or no view shows the cable.
    ReconstructionError
        The voxels would take more than ``settings.memory_mb`` even one per radius.
    Cancelled
    """
    cameras = list(cameras)
    masks = list(masks)
    if len(masks) != len(cameras):
        raise ValueError(f"{len(masks)} masks for {len(cameras)} cameras")
    junctions = [None] * len(cameras) if junctions is None else list(junctions)
    if len(junctions) != len(cameras):
        raise ValueError(f"{len(junctions)} junction masks for {len(cameras)} cameras")
    stage = StageProgress(progress)
    views, radii = [], []
    lower, side = scene_region(cameras) if region is None else region
    lower = np.asarray(lower, dtype=np.float64)
    centre = lower + 0.5 * side
    pixels = sum(camera.width * camera.height for camera in cameras)
    keep_distances = 2 * pixels <= settings.cache_mb * 2 ** 20
    for camera, item, junction in zip(cameras, masks, junctions):
        check_cancel(cancel, "carving")
        mask = unpacked(item)
        if mask.shape != (camera.height, camera.width):
            raise ValueError(f"the mask of {camera.name!r} is {mask.shape[1]}x{mask.shape[0]}, "
                             f"its image {camera.width}x{camera.height}")
        if radius is None:
            radii.append(_radius_in_view(camera, mask, centre))
        views.append(_View(camera, item if isinstance(item, PackedMask) else mask, junction,
                           keep_distances))
    if radius is None:
        radii = [value for value in radii if value is not None]
        if not radii:
            raise ValueError("no view shows the cable")
        # the median over views of half the width times depth over focal length
        radius = float(np.median(radii))
    fine = radius / settings.voxels_per_radius
    while True:
        try:
            return _carve_levels(views, lower, side, fine, radius, settings, stage, cancel)
        except _OverBudget as error:
            if radius / (2 * fine) < _LEAST_VOXELS_PER_RADIUS:
                raise ReconstructionError(str(error)) from None
            log.info("%s: carving in voxels twice as large", error)
            fine *= 2


def _carve_levels(views, lower, side, fine, radius, settings, stage, cancel):
    """The grids carved coarse to fine down to voxels of ``fine``."""
    levels = 0 if not settings.coarse_to_fine else max(
        int(math.ceil(math.log2(side / (fine * settings.root_cells)))), 0)
    cells = int(math.ceil(side / (fine * 2 ** levels)))
    log.debug("carving %d views: radius %.4g, voxel %.4g, %d levels from %d^3",
              len(views), radius, fine, levels, cells)
    _check_memory(cells ** 3 * _LEVEL_BYTES, settings, f"{cells ** 3:,} voxels at level {levels}")
    index = np.argwhere(np.ones((cells,) * 3, dtype=bool)).astype(np.int64)
    steps = levels + 1
    with worker_pool(settings.threads, "carve") as pool:
        for level in range(levels, -1, -1):
            size = fine * 2 ** level
            carver = _Carver(views, lower, settings, pool,
                             stage.part((levels - level) / steps, (levels - level + 1) / steps),
                             cancel)
            kept, counted, hits, junction = carver.level(index, size, fine=level == 0)
            index = index[kept]
            if level > 0:
                _check_memory(8 * len(index) * _LEVEL_BYTES, settings,
                              f"{8 * len(index):,} voxels of {size / 2:.3g} at level {level - 1}")
                index = (2 * index[:, None, :] + _CHILDREN[None]).reshape(-1, 3)
    large = _large_pieces(index, fine, settings.min_piece_length * radius)
    index = index[large]  # without the small pieces (ghosts far from the cable)
    core = int(np.count_nonzero(hits[large] >= (settings.core_agreement - 1e-6)
                                * np.maximum(counted[large], 1)))
    _check_memory(len(index) * _VOXEL_BYTES + core * _CORE_BYTES, settings,
                  f"{len(index):,} occupied voxels ({core:,} in the core)")
    stage(1.0, "carved")
    return _grid(index, junction[large], counted[large], hits[large], lower, fine, radius)


class _OverBudget(ReconstructionError):
    """The voxels would take more than the memory budget."""


def _check_memory(needed, settings, what):
    """A :class:`.ReconstructionError` when ``needed`` bytes exceed the budget."""
    budget = settings.memory_mb * 2 ** 20
    if needed > budget:
        raise _OverBudget(
            f"carving would need {needed / 2 ** 30:.1f} GB for {what}, over its budget of "
            f"{budget / 2 ** 30:.1f} GB: the masks take in far more than a thin cable (check "
            f"them: segment writes them), or the views are too few to bound it")


def _large_pieces(index, size, min_length):
    """Which voxels ``index`` belong to pieces whose box diagonal reaches ``min_length``.

    Pieces are found among the voxels pooled 2x2x2 (pieces one voxel apart merge, and are kept
    together), as a list, so the cost follows the voxels, not their box.
    """
    if not len(index):
        return np.ones(0, dtype=bool)
    cells = (index - index.min(axis=0)) // 2
    _, first, voxel_cell = np.unique(sparse_voxels.keys(cells), return_index=True,
                                     return_inverse=True)
    pooled = cells[first]
    count, labels = sparse_voxels.pieces(pooled)
    low = np.full((count, 3), np.iinfo(np.int64).max)
    high = np.full((count, 3), np.iinfo(np.int64).min)
    np.minimum.at(low, labels, pooled)
    np.maximum.at(high, labels, pooled)
    large = np.linalg.norm((high - low + 1) * 2 * size, axis=1) >= min_length
    keep = large[labels[voxel_cell.reshape(-1)]]
    if not keep.all():
        log.debug("dropped %d small occupied pieces (%d voxels)",
                  count - large.sum(), (~keep).sum())
    return keep


def _grid(index, junction, counted, hits, lower, size, radius):
    """The grid of the carved voxels, in C order, indexed from one voxel of margin."""
    if not len(index):
        return VoxelGrid(np.zeros((0, 3), np.int64), np.zeros(0, bool), lower + 0.5 * size,
                         size, radius, np.zeros(0, np.int16), np.zeros(0, np.float32))
    start = index.min(axis=0) - 1
    order = sparse_voxels.sorted_voxels(index)
    origin = lower + (start + 0.5) * size
    return VoxelGrid((index - start)[order], junction[order], origin, size, radius,
                     counted[order].astype(np.int16),
                     (hits / np.maximum(counted, 1)).astype(np.float32)[order])

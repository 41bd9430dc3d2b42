"""Fitting a discrete elastic rod to a carved cable and its images (paper §3.4 and §3.6).

The rod (:mod:`engine.stages.rod`) is fitted quasi-statically: its elastic energy plus data terms is
minimised by Newton's method. Every length is relative to the cable radius ``r`` and every
weight to the bending energy unit ``U = E I / r`` (energies are reported in ``U``), so scaling
the world scales the fit, and the material's stiffness does not matter, only the balance of
bending and data.

Data terms:

* **Voxels** (§3.4): occupied voxel centres within ``voxel_reach`` of the rod pull their
  nearest vertex with a spring. Each voxel weighs its volume, so the term approximates an
  integral over the occupied volume and does not depend on the grid's resolution. "Nearest"
  is taken through the rod smoothed over ``voxel_smoothing`` (see :func:`assign_voxels`): plain
  nearest-vertex assignment is k-means, and in a hull several radii wide it folds the rod into
  zigzags. Assignments are made at the start of each pass and kept during it.
* **Images** (beyond the paper): the visual hull is fat, so its voxels and its medial ridge
  place the centreline only roughly (``bench carve``'s chain distances); so in every view
  the rod's projected centreline is pulled onto the cable's 2D centre: the ridge of the mask's
  distance transform, located to a fraction of a pixel. A vertex's residual is its distance
  from the tangent line of its ridge point, in projected radii, under a Cauchy loss of scale
  ``image_scale``: a view where the strand is hidden, or where another strand's ridge is
  nearer, gives a large residual that counts little. Where a vertex projects into a junction
  mask (grown by ``junction_margin``), the 2D ridge of the X is distorted and the lower strand
  hidden: its residual there weighs ``junction_weight``. Ridge points are re-matched every
  Newton iteration, with hysteresis.
* **Contacts**: at a crossing the caller says which strand is over; the over strand's vertices
  are pushed to at least ``2 r (1 + contact_gap)`` above the under strand's vertices within that
  horizontal distance (a one-sided quadratic penalty; ``up`` says what "above" is).
* **Anchor**: a weak spring to the initial chain, so a fit with little data stays put.

The cable's length is not known in advance: the rod's rest lengths are reset to its fitted
length (evenly spaced) between passes, so it may lengthen or shorten to what the data say while
staying nearly inextensible within a pass. With views, the first pass is guided by the voxels
and the later ones let the images lead (voxel weight times ``refine_voxel_weight``).
"""

import math
from dataclasses import dataclass

import cv2
import numpy as np
from scipy.ndimage import gaussian_filter, gaussian_filter1d
from scipy.spatial import cKDTree

from ..geometry.camera import Camera
from ..geometry.polylines import arc_length
from ..progress import StageProgress
from ..settings import check_settings, setting
from .rod import Derivatives, ElasticEnergy, Rod, RodSettings, minimise_energy
from .segmentation import cable_width

__all__ = ["RodFitSettings", "Voxels", "ImageEvidence", "Contact", "Obstacle", "RodFit",
           "fit_rod", "resample_polyline", "assign_voxels", "voxel_attraction", "Springs",
           "ImageAttraction", "ContactPenalty", "ObstaclePenalty"]

#: Young's modulus the fit works with: it cancels out, as every weight is relative to bending.
_FIT_MODULUS = 1e6
#: Ridge pixels whose distance to the background is below this share of the largest one
#: within 1.5 half widths are spurs.
_SPUR_RATIO = 0.8
#: A vertex keeps its ridge point until another is closer by this many half widths.
_REMATCH = 0.1


@dataclass(frozen=True)
class RodFitSettings:
    """How a rod is fitted; every length in units of the cable radius ``r``, every weight
    relative to the bending stiffness (see the module notes).

    Attributes
    ----------
    spacing : float
        Vertex spacing of the fitted rod.
    smoothing : float
        Gaussian smoothing (standard deviation along the chain) of the initial chain; 0 for none.
    voxel_weight : float
        Weight of the voxel attraction, per unit of occupied volume ``pi r**3``.
    voxel_reach : float
        Voxels farther than this from every vertex do not pull.
    voxel_smoothing : float
        Voxels are assigned to vertices through the rod smoothed by a Gaussian of this standard
        deviation (along the rod), so that wiggles smaller than the hull cannot partition it.
    image_weight : float
        Weight of the image term, per unit of rod length ``r``, averaged over the views.
    image_scale : float
        Scale of the Cauchy loss of an image residual (in projected radii).
    image_reach : float
        Pixels farther than this from the mask's ridge carry no evidence (in the view's
        typical cable half width, i.e. projected radii).
    junction_margin : float
        Junction masks are grown by this many half widths.
    junction_weight : float
        Weight of an image residual of a vertex projecting into a grown junction mask (0 leaves
        it out of that view).
    refine_voxel_weight : float
        With views, the voxel weight of the passes after the first is multiplied by this.
    passes : int
        Fitting passes; the rest lengths are reset between them.
    contact_weight : float
        Weight of the crossing penalty.
    contact_gap : float
        Extra clearance at a crossing, relative: strands are kept ``2 r (1 + contact_gap)`` apart.
    contact_span : float
        A crossing given by one index covers the vertices within this arc length of it.
    anchor_weight : float
        Weight of the spring to the initial chain, per unit of rod length ``r``.
    max_iterations : int
        Newton iterations per pass.
    step_tolerance : float
        A pass has converged when the full Newton step moves no vertex farther than this.
    max_step : float
        No vertex moves farther than this in one Newton iteration.
    """

    spacing: float = setting(1.0, above=0, unit="r")
    smoothing: float = setting(2.0, low=0, unit="vertices")
    voxel_weight: float = setting(1.0, low=0)
    voxel_reach: float = setting(3.0, above=0, unit="r")
    voxel_smoothing: float = setting(3.0, low=0, unit="r")
    image_weight: float = setting(10.0, low=0)
    image_scale: float = setting(1.0, above=0)
    image_reach: float = setting(4.0, above=0)
    junction_margin: float = setting(1.0, low=0)
    junction_weight: float = setting(0.5, low=0)
    refine_voxel_weight: float = setting(0.01, low=0)
    passes: int = setting(2, low=1)
    contact_weight: float = setting(1000.0, low=0)
    contact_gap: float = setting(0.02, low=0)
    contact_span: float = setting(4.0, above=0, unit="r")
    anchor_weight: float = setting(0.01, low=0)
    max_iterations: int = setting(100, low=1)
    step_tolerance: float = setting(1e-3, above=0, unit="r")
    max_step: float = setting(1.0, above=0, unit="r")

    def __post_init__(self):
        check_settings(self)


# -- inputs -----------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class Voxels:
    """Occupied voxels of a carved grid.

    Parameters
    ----------
    centres : array_like, shape (M, 3)
        Centres of the occupied voxels (world units).
    size : float
        Edge length of a voxel.
    """

    centres: np.ndarray
    size: float

    def __post_init__(self):
        centres = np.array(self.centres, dtype=np.float64).reshape(-1, 3)
        if not np.all(np.isfinite(centres)):
            raise ValueError("voxel centres must be finite")
        if not (math.isfinite(self.size) and self.size > 0):
            raise ValueError("voxel size must be positive")
        centres.setflags(write=False)
        object.__setattr__(self, "centres", centres)
        object.__setattr__(self, "size", float(self.size))

    @classmethod
    def from_grid(cls, grid, *, agreement=None):
        """The occupied voxels of a carved grid.

        Parameters
        ----------
        grid : engine.stages.carving.VoxelGrid
        agreement : float, optional
            Keep only the grid's core (:meth:`~engine.stages.carving.VoxelGrid.core`): the voxels
            on cable pixels in at least this fraction of the views that see them. The
            half-vote hull is fat; its core is thinner and nearer the centreline.

        Returns
        -------
        Voxels
        """
        if agreement is None:
            return cls(grid.occupied_points(), grid.voxel_size)
        if not 0.0 < agreement <= 1.0:
            raise ValueError("agreement must lie in (0, 1]")
        return cls(grid.occupied_points(grid.core(agreement)), grid.voxel_size)

    def near(self, points, reach):
        """The voxels within ``reach`` (world units) of any of ``points`` (e.g. a densely
        sampled stretch of cable), as :class:`Voxels`."""
        points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        if not len(self.centres) or not len(points):
            return Voxels(self.centres[:0], self.size)
        distance, _ = cKDTree(points).query(self.centres, distance_upper_bound=reach)
        return Voxels(self.centres[np.isfinite(distance)], self.size)


def _undistorted(camera, images):
    """A PINHOLE twin of ``camera`` and ``images`` (bool) remapped to it."""
    (fx, fy), (cx, cy) = camera.focal, camera.principal_point
    pinhole = Camera(name=camera.name, width=camera.width, height=camera.height,
                     model="PINHOLE", params=[fx, fy, cx, cy], R=camera.R, t=camera.t)
    if not np.any(camera.distortion):
        return pinhole, images
    matrix = np.array([[fx, 0.0, cx - 0.5], [0.0, fy, cy - 0.5], [0.0, 0.0, 1.0]])  # OpenCV
    map_x, map_y = cv2.initUndistortRectifyMap(matrix, camera.distortion, None, matrix,
                                               (camera.width, camera.height), cv2.CV_32FC1)
    remapped = [None if image is None else
                cv2.remap(image.astype(np.uint8), map_x, map_y, cv2.INTER_NEAREST) > 0
                for image in images]
    return pinhole, remapped


def _across(smooth):
    """Per pixel, the curvature across a ridge of ``smooth`` (its Hessian's most negative
    eigenvalue) and the unit direction ``(x, y)`` it is taken along."""
    d_rr, d_rc = np.gradient(np.gradient(smooth, axis=0), axis=(0, 1))
    d_cc = np.gradient(np.gradient(smooth, axis=1), axis=1)
    curvature = 0.5 * (d_cc + d_rr) - np.hypot(0.5 * (d_cc - d_rr), d_rc)
    angle = 0.5 * np.arctan2(-2.0 * d_rc, d_rr - d_cc)
    return curvature, np.cos(angle), np.sin(angle)


#: A cable wider than twice this (pixels; 4K and 8K frames) has its ridge found on its mask
#: reduced by a whole factor (:func:`_reduction`), and its evidence kept in cells of that many
#: pixels: the ridge's cost and the evidence's memory grow with the square of the width, and a
#: dozen pixels across the cable place its centre as well.
_WIDE_HALF_WIDTH = 12.0
#: ... reduced so its half width is about this.
_REDUCED_HALF_WIDTH = 6.0


def _reduction(half_width):
    """The whole factor a cable's mask is reduced by for its ridge and evidence (1: none)."""
    if half_width <= _WIDE_HALF_WIDTH:
        return 1
    return int(math.ceil(half_width / _REDUCED_HALF_WIDTH))


def _blocks(image, factor):
    """A 2-D ``image`` (as uint8) padded with zeros to whole ``factor`` x ``factor`` cells,
    shaped ``(rows, factor, columns, factor)``."""
    rows, cols = -(-image.shape[0] // factor), -(-image.shape[1] // factor)
    padded = np.zeros((rows * factor, cols * factor), np.uint8)
    padded[:image.shape[0], :image.shape[1]] = image
    return padded.reshape(rows, factor, cols, factor)


def _ridge(mask, half_width):
    """Sub-pixel centre line of a mask: points ``(K, 2)`` (COLMAP coordinates) and unit normals.

    A pixel is on the ridge when the smoothed distance transform is a maximum across the ridge
    (the direction of its most negative curvature, rounded to a neighbour); a parabola through
    the three values across places the point to a fraction of a pixel. Spurs (towards the
    corners of a cable's end or bumps of the outline) are dropped: their distance to the
    background is well below the largest one nearby.
    """
    rows, cols = np.nonzero(mask.any(axis=1))[0], np.nonzero(mask.any(axis=0))[0]
    if not len(rows):
        return np.zeros((0, 2)), np.zeros((0, 2))
    # the mask's box with a margin: nothing outside it is near the ridge
    margin = int(math.ceil(1.5 * half_width)) + 4
    top, left = max(rows[0] - margin, 0), max(cols[0] - margin, 0)
    box = mask[top:rows[-1] + margin + 1, left:cols[-1] + margin + 1]
    factor = _reduction(half_width)
    if factor < 2:
        points, normals = _ridge_in_box(box, half_width)
        return points + (left, top), normals
    # a wide cable (a 4K or 8K frame): the ridge of the mask reduced ``factor`` times (a
    # pixel (j, i) there covers [j f, (j + 1) f) here, so its coordinates scale by f)
    small = _blocks(box, factor).mean(axis=(1, 3)) >= 0.5  # a cell is cable if half is
    points, normals = _ridge_in_box(small, half_width / factor)
    return points * factor + (left, top), normals


def _ridge_in_box(mask, half_width):
    distance = cv2.distanceTransform(mask.astype(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
    size = 2 * int(math.ceil(1.5 * half_width)) + 1
    nearby = cv2.dilate(distance, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (size, size)))
    smooth = gaussian_filter(distance.astype(np.float64), 1.0)
    curvature, nx, ny = _across(smooth)
    rows, cols = np.nonzero(mask & (curvature < -0.05) & (distance >= 1.0)
                            & (distance >= _SPUR_RATIO * nearby))
    nx, ny = nx[rows, cols], ny[rows, cols]
    dc = np.clip(np.rint(1.5 * nx), -1, 1).astype(int)  # the neighbour across the ridge
    dr = np.clip(np.rint(1.5 * ny), -1, 1).astype(int)
    height, width = mask.shape
    centre = smooth[rows, cols]
    ahead = smooth[np.clip(rows + dr, 0, height - 1), np.clip(cols + dc, 0, width - 1)]
    behind = smooth[np.clip(rows - dr, 0, height - 1), np.clip(cols - dc, 0, width - 1)]
    keep = (centre >= ahead) & (centre >= behind) & ((dr != 0) | (dc != 0))
    centre, ahead, behind = centre[keep], ahead[keep], behind[keep]
    bend = behind - 2.0 * centre + ahead  # <= 0 at a maximum, 0 on a plateau
    offset = 0.5 * (behind - ahead) / np.where(bend < 0, bend, -np.inf)
    offset = np.clip(offset, -0.5, 0.5)
    points = np.column_stack([cols[keep] + 0.5 + offset * dc[keep],
                              rows[keep] + 0.5 + offset * dr[keep]])
    return points, np.column_stack([nx[keep], ny[keep]])


@dataclass(frozen=True, eq=False)
class ImageEvidence:
    """Where the cable's 2D centre lies in one view.

    Build it with :meth:`from_mask`. Only pixels within reach of the centre ridge are kept
    (sorted linear pixel indices), so large images stay cheap.

    Attributes
    ----------
    camera : Camera
        A PINHOLE camera (distortion removed: the maps are undistorted).
    ridge_points : ndarray, shape (K, 2)
        Sub-pixel points of the mask's centre ridge, COLMAP image coordinates.
    ridge_normals : ndarray, shape (K, 2)
        Unit normals of the ridge there.
    pixels : ndarray of int, shape (P,)
        Sorted linear indices (``row * columns + col`` of the grid of cells) of the cells
        within reach of the ridge.
    nearest : ndarray of int, shape (P,)
        The ridge point nearest to each of those cells.
    weights : ndarray, shape (P,)
        Weight of a vertex projecting there: ``junction_weight`` in (grown) junctions, else 1.
    half_width : float
        The cable's typical half width in pixels.
    cell : int
        Pixels per cell side: 1, or more for a cable wider than ``2 * _WIDE_HALF_WIDTH``
        pixels (:func:`_reduction`).
    """

    camera: Camera
    ridge_points: np.ndarray
    ridge_normals: np.ndarray
    pixels: np.ndarray
    nearest: np.ndarray
    weights: np.ndarray
    half_width: float
    cell: int = 1

    @classmethod
    def from_mask(cls, camera, mask, junction_mask=None, *, settings=RodFitSettings()):
        """Evidence of one view from its cable mask (and, optionally, its junction map).

        Parameters
        ----------
        camera : Camera
        mask : ndarray of bool, shape (height, width)
            Cable pixels.
        junction_mask : ndarray of bool, optional
            Pixels where the cable overlaps itself
            (:func:`engine.stages.segmentation.junction_map`).
        settings : RodFitSettings, optional
            ``image_reach``, ``junction_margin`` and ``junction_weight`` are used.

        Returns
        -------
        ImageEvidence
        """
        if not isinstance(camera, Camera):
            raise ValueError("camera must be an engine.geometry.camera.Camera")
        mask = np.asarray(mask, dtype=bool)
        shape = (camera.height, camera.width)
        if mask.shape != shape:
            raise ValueError(f"mask of {camera.name!r} is {mask.shape[::-1]}, the camera's image "
                             f"is {shape[::-1]}")
        if junction_mask is not None:
            junction_mask = np.asarray(junction_mask, dtype=bool)
            if junction_mask.shape != shape:
                raise ValueError(f"junction mask of {camera.name!r} does not match its image")
        pinhole, (mask, junction_mask) = _undistorted(camera, [mask, junction_mask])
        half_width = 0.5 * cable_width(mask)
        points, normals = _ridge(mask, half_width)
        cell = _reduction(half_width)
        cells = (-(-shape[0] // cell), -(-shape[1] // cell))
        pixels, nearest = _near_ridge(points / cell, cells,
                                      settings.image_reach * max(half_width, 1.0) / cell)
        weights = np.ones(len(pixels))
        if junction_mask is not None and junction_mask.any():
            # a cell is in a junction when any of its pixels is
            junctions = _blocks(junction_mask, cell).max(axis=(1, 3))
            grow = int(math.ceil(settings.junction_margin * half_width / cell))
            kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * grow + 1, 2 * grow + 1))
            grown = cv2.dilate(junctions, kernel).ravel() > 0
            weights[grown[pixels]] = settings.junction_weight
        for array in (points, normals, pixels, nearest, weights):
            array.setflags(write=False)
        return cls(pinhole, points, normals, pixels, nearest, weights, half_width, cell)

    def lookup(self, pixels):
        """Nearest ridge point (-1 for none) and weight at image points ``(M, 2)`` inside the
        image (COLMAP coordinates)."""
        if not len(self.pixels):
            return np.full(len(pixels), -1), np.zeros(len(pixels))
        cell, columns = self.cell, -(-self.camera.width // self.cell)
        linear = ((pixels[:, 1] // cell).astype(np.int64) * columns
                  + (pixels[:, 0] // cell).astype(np.int64))
        slot = np.minimum(np.searchsorted(self.pixels, linear), len(self.pixels) - 1)
        found = self.pixels[slot] == linear
        return np.where(found, self.nearest[slot], -1), np.where(found, self.weights[slot], 0.0)


def _near_ridge(points, shape, reach):
    """Linear indices of the pixels within ``reach`` of ridge ``points`` and their nearest."""
    if not len(points):
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    seeds = np.ones(shape, dtype=np.uint8)
    seed_rows = np.clip(points[:, 1].astype(int), 0, shape[0] - 1)
    seed_cols = np.clip(points[:, 0].astype(int), 0, shape[1] - 1)
    seeds[seed_rows, seed_cols] = 0
    # each pixel's nearest seed pixel comes with the distance transform (labels number the
    # seed pixels in raster order); the seed's ridge point is that pixel's nearest point
    distance, labels = cv2.distanceTransformWithLabels(seeds, cv2.DIST_L2, cv2.DIST_MASK_5,
                                                       labelType=cv2.DIST_LABEL_PIXEL)
    pixels = np.flatnonzero(distance.ravel() <= reach + 1.0)
    point_at = np.full(shape[0] * shape[1], -1, dtype=np.int64)
    point_at[seed_rows * shape[1] + seed_cols] = np.arange(len(points))
    seed_pixels = np.flatnonzero(seeds.ravel() == 0)
    nearest = point_at[seed_pixels[labels.ravel()[pixels] - 1]]
    return pixels, nearest


@dataclass(frozen=True)
class Contact:
    """A crossing: which strand goes over, as indices into the input chain of :func:`fit_rod`.

    Attributes
    ----------
    over, under : int or tuple of int
        One index (the strand around it, ``contact_span`` each way, takes part) or an inclusive
        ``(first, last)`` index range (``first <= last``).
    """

    over: object
    under: object


@dataclass(frozen=True, eq=False)
class Obstacle:
    """Another cable crossing this rod, held where it is (e.g. a cable fitted before).

    Attributes
    ----------
    strand : int or tuple of int
        This rod's strand at the crossing, as in :class:`Contact` (indices into the input
        chain of :func:`fit_rod`).
    points : ndarray, shape (K, 3)
        The other cable's centreline near the crossing.
    over : bool
        This rod goes over the other cable there (else under it).
    """

    strand: object
    points: np.ndarray
    over: bool


# -- energy terms -----------------------------------------------------------------------------
class Springs:
    """Zero-length springs from vertices to fixed points, gathered per vertex.

    Energy ``sum_i (w_i |x_i|**2 - 2 x_i . s_i) + constant``: vertex ``i`` is pulled towards
    ``s_i / w_i`` (the weighted centroid of its springs' ends) with stiffness ``2 w_i``.

    Parameters
    ----------
    name : str
        The term's name in energy reports.
    weights : ndarray, shape (N,)
        Total spring weight per vertex.
    sums : ndarray, shape (N, 3)
        Weighted sum of the springs' ends per vertex.
    constant : float
        Weighted sum of the ends' squared norms (and anything constant), so the energy is the
        sum of the springs' ``w |x - p|**2``.
    """

    def __init__(self, name, weights, sums, constant):
        self.name, self.weights, self.sums, self.constant = name, weights, sums, constant

    @classmethod
    def to_points(cls, targets, weights, *, name="anchor"):
        """One spring per vertex to ``targets`` ``(N, 3)`` with ``weights`` ``(N,)``."""
        targets = np.asarray(targets, dtype=np.float64)
        weights = np.asarray(weights, dtype=np.float64)
        return cls(name, weights, weights[:, None] * targets,
                   float(np.sum(weights * np.sum(targets**2, axis=1))))

    def model(self, points):
        """Nothing to refresh: itself."""
        return self

    def energy(self, points):
        """Energy at ``points``."""
        return float(np.sum(self.weights * np.sum(points**2, axis=1))
                     - 2.0 * np.sum(points * self.sums) + self.constant)

    def derivatives(self, points, *, exact=False):
        """:class:`~engine.stages.rod.Derivatives` at ``points``."""
        gradient = 2.0 * (self.weights[:, None] * points - self.sums)
        blocks = 2.0 * self.weights[:, None, None] * np.eye(3)
        vertices = np.arange(len(points))[:, None]
        return Derivatives.from_blocks(self.energy(points), gradient, vertices, blocks)


def assign_voxels(centres, points, *, reach, closed=False, smoothing=0.0):
    """The rod vertices each voxel pulls, and how much (paper §3.4).

    A voxel pulls the two vertices of the rod's edge nearest to it, shared in proportion to
    where its closest point on that edge lies (all of it to the nearer vertex at the edge's
    end), the rod being first smoothed by a Gaussian of ``smoothing`` vertices. Plain
    nearest-vertex assignment is k-means clustering: in a hull several radii wide it folds the
    rod into zigzags that cover the cross-section. Through the smoothed rod's closest point each
    vertex gets the slab of hull around it, whose centroid lies near the tube's axis; sharing
    voxels between neighbours (a tent rather than a box) keeps the slabs' centroids from
    jumping with the grid.

    Parameters
    ----------
    centres : ndarray, shape (M, 3)
    points : ndarray, shape (N, 3)
        The rod.
    reach : float
        Voxels farther than this from every vertex pull none.
    closed : bool, optional
    smoothing : float, optional
        Standard deviation in vertices; 0 for none.

    Returns
    -------
    vertices : ndarray of int, shape (M, 2)
        -1 for voxels out of reach.
    shares : ndarray, shape (M, 2)
        Summing to 1 per voxel in reach.
    """
    if smoothing > 0:
        points = gaussian_filter1d(points, smoothing, axis=0,
                                   mode="wrap" if closed else "nearest")
    distance, nearest = cKDTree(points).query(centres, distance_upper_bound=reach)
    inside = np.flatnonzero(distance < reach)
    vertex, near = nearest[inside], centres[inside]
    count = len(points)
    other, share, best = vertex.copy(), np.zeros(len(vertex)), np.full(len(vertex), np.inf)
    for side in (-1, 1):
        neighbour = vertex + side
        valid = np.ones(len(vertex), dtype=bool) if closed else (neighbour >= 0) & (
            neighbour < count)
        neighbour = neighbour % count
        edge = points[neighbour] - points[vertex]
        t = np.einsum("ij,ij->i", near - points[vertex], edge) / np.maximum(
            np.einsum("ij,ij->i", edge, edge), 1e-300)
        t = np.clip(t, 0.0, 1.0)
        gap = np.linalg.norm(points[vertex] + t[:, None] * edge - near, axis=1)
        better = valid & (gap < best)
        best[better], other[better], share[better] = gap[better], neighbour[better], t[better]
    vertices = np.full((len(centres), 2), -1)
    shares = np.zeros((len(centres), 2))
    vertices[inside] = np.column_stack([vertex, other])
    shares[inside] = np.column_stack([1.0 - share, share])
    return vertices, shares


def voxel_attraction(voxels, points, *, weight, reach, closed=False, smoothing=0.0):
    """Springs from rod vertices to the occupied voxels they are assigned (paper §3.4).

    Energy ``w sum_v sum_k s_vk |x_a(v,k) - c_v|**2`` with the vertices ``a`` and shares ``s``
    of :func:`assign_voxels` at ``points`` (kept fixed while the rod moves: reassign by calling
    again), plus ``w reach**2`` per voxel out of reach; ``w`` is the voxel's volume times
    ``weight``, so the sum approximates an integral over the occupied volume.

    Parameters
    ----------
    voxels : Voxels
    points : ndarray, shape (N, 3)
        The rod where the assignment is made.
    weight : float
        Energy per unit volume per squared length.
    reach, closed, smoothing
        See :func:`assign_voxels`.

    Returns
    -------
    Springs
    """
    vertices, shares = assign_voxels(voxels.centres, points, reach=reach, closed=closed,
                                     smoothing=smoothing)
    inside = vertices[:, 0] >= 0
    count, spring = len(points), weight * voxels.size**3
    pulled = np.repeat(voxels.centres[inside], 2, axis=0)
    index, share = vertices[inside].ravel(), shares[inside].ravel() * spring
    weights = np.bincount(index, share, minlength=count)
    sums = np.column_stack([np.bincount(index, share * pulled[:, k], minlength=count)
                            for k in range(3)])
    constant = spring * (float(np.sum(voxels.centres[inside] ** 2))
                         + reach**2 * float(np.count_nonzero(~inside)))
    return Springs("voxels", weights, sums, constant)


class ImageAttraction:
    """Projected vertices pulled onto the cable's 2D centre in every view (module notes).

    Each vertex seen in a view has a residual: its projection's distance from the tangent line
    of the nearest ridge point, in units of its projected radius; the energy is the Cauchy loss
    ``c**2 log(1 + s**2 / c**2)`` of it, times the vertex's weight (and the view's junction
    weight there).

    Parameters
    ----------
    views : sequence of ImageEvidence
    radius : ndarray, shape (N,)
        Per-vertex radius.
    weights : ndarray, shape (N,)
        Per-vertex weight (already divided by the number of views).
    scale : float
        Cauchy scale ``c`` in projected radii.
    """

    name = "images"

    def __init__(self, views, radius, weights, scale):
        self.views, self.radius, self.weights, self.scale = views, radius, weights, scale
        self._last = [np.full(len(radius), -1) for _ in views]  # ridge point matched per vertex

    def model(self, points):
        """Fix, per view, which vertices count, their weights and ridge points.

        A vertex keeps the ridge point it was matched to last time unless the nearest one is
        closer by more than :data:`_REMATCH` half widths: near a crossing two ridges meet and
        a vertex switching between them at every refresh would never settle.
        """
        return _ImageModel(self, [self._matches(k, view, points)
                                  for k, view in enumerate(self.views)])

    def _matches(self, k, view, points):
        pixels, depth = view.camera.project(points)
        inside = (depth > 0) & np.all(np.isfinite(pixels), axis=1)
        inside &= (pixels[:, 0] >= 0) & (pixels[:, 0] < view.camera.width)
        inside &= (pixels[:, 1] >= 0) & (pixels[:, 1] < view.camera.height)
        vertices = np.flatnonzero(inside)
        index, weight = view.lookup(pixels[vertices])
        keep = (index >= 0) & (weight > 0)
        vertices, index, weight = vertices[keep], index[keep], weight[keep]
        last = self._last[k][vertices]
        had = last >= 0
        ridge = view.ridge_points
        distance = np.linalg.norm(pixels[vertices] - ridge[index], axis=1)
        previous = np.linalg.norm(pixels[vertices[had]] - ridge[last[had]], axis=1)
        stay = previous <= distance[had] + _REMATCH * view.half_width
        index[np.flatnonzero(had)[stay]] = last[had][stay]
        self._last[k][:] = -1
        self._last[k][vertices] = index
        return vertices, self.weights[vertices] * weight, ridge[index], view.ridge_normals[index]


class _ImageModel:
    def __init__(self, term, matches):
        self.term, self.matches = term, matches

    def _residuals(self, view, points, vertices, anchors, normals, want_jacobian):
        """Distances ``(M,)`` from the ridge lines in projected radii, and their gradients."""
        camera = view.camera
        local = points[vertices] @ camera.R.T + camera.t
        z = local[:, 2]
        (fx, fy), (cx, cy) = camera.focal, camera.principal_point
        u, v = fx * local[:, 0] / z + cx, fy * local[:, 1] / z + cy
        unit = 0.5 * (fx + fy) * self.term.radius[vertices] / z  # projected radius, pixels
        residual = (normals[:, 0] * (u - anchors[:, 0])
                    + normals[:, 1] * (v - anchors[:, 1])) / unit
        if not want_jacobian:
            return residual, None
        nx, ny = normals[:, 0] * fx / z, normals[:, 1] * fy / z  # d offset / d local
        jacobian = np.column_stack([nx, ny, -(nx * local[:, 0] + ny * local[:, 1]) / z]) \
            / unit[:, None]
        jacobian[:, 2] += residual / z  # the projected radius shrinks with depth
        return residual, jacobian @ camera.R

    def _loss(self, residual, weights):
        """Cauchy loss per vertex and its IRLS weight ``loss' / residual``."""
        c2 = self.term.scale**2
        return weights * c2 * np.log1p(residual**2 / c2), 2.0 * weights / (1.0 + residual**2 / c2)

    def energy(self, points):
        total = 0.0
        for view, (vertices, weights, anchors, normals) in zip(self.term.views, self.matches):
            residual, _ = self._residuals(view, points, vertices, anchors, normals, False)
            total += float(np.sum(self._loss(residual, weights)[0]))
        return total

    def derivatives(self, points, *, exact=False):
        count = len(points)
        gradient, blocks, energy = np.zeros((count, 3)), np.zeros((count, 3, 3)), 0.0
        for view, (vertices, weights, anchors, normals) in zip(self.term.views, self.matches):
            residual, jacobian = self._residuals(view, points, vertices, anchors, normals, True)
            loss, irls = self._loss(residual, weights)
            energy += float(np.sum(loss))
            np.add.at(gradient, vertices, (irls * residual)[:, None] * jacobian)
            np.add.at(blocks, vertices, irls[:, None, None] * jacobian[:, :, None]
                      * jacobian[:, None, :])
        vertices = np.arange(count)[:, None]
        return Derivatives.from_blocks(energy, gradient, vertices, blocks)


class ContactPenalty:
    """Keeps the over strands of crossings ``gap`` above their under strands.

    For each pair ``(i, j)`` of an over vertex and an under vertex, energy
    ``w f_ij max(0, gap - dz)**2`` with ``dz`` the height of ``x_i`` above ``x_j`` along ``up``
    and ``f_ij = (1 - (rho / gap)**2)**2`` for their horizontal distance ``rho < gap`` (else 0):
    the over strand clears the under strand by ``gap`` where they cross, the requirement fading
    out to the side. ``f`` is fixed when the model is made (every Newton iteration), so the
    penalty pushes only along ``up`` and its Hessian is exact.

    Parameters
    ----------
    pairs : ndarray of int, shape (P, 2)
        ``(over vertex, under vertex)``.
    up : array_like, shape (3,)
    gap : float
        World units (``2 r (1 + contact_gap)``).
    weight : float
    """

    name = "contacts"

    def __init__(self, pairs, up, gap, weight):
        self.pairs = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
        up = np.asarray(up, dtype=np.float64)
        self.up = up / np.linalg.norm(up)
        self.gap, self.weight = gap, weight

    def _heights(self, points):
        return (points[self.pairs[:, 0]] - points[self.pairs[:, 1]]) @ self.up

    def model(self, points):
        """The penalty with the fading weights of the pairs fixed at ``points``."""
        fade = _fade(points[self.pairs[:, 0]] - points[self.pairs[:, 1]], self.up, self.gap)
        return _ContactModel(self, self.weight * fade)

    def clearance(self, points):
        """Per pair, how far the over vertex is above the under one minus ``gap`` (negative:
        too low), and whether they are within ``gap`` horizontally."""
        delta = points[self.pairs[:, 0]] - points[self.pairs[:, 1]]
        across = delta - np.outer(delta @ self.up, self.up)
        return delta @ self.up - self.gap, np.linalg.norm(across, axis=1) < self.gap


class ObstaclePenalty:
    """Keeps vertices ``gap`` above (or below) fixed points of another cable.

    :class:`ContactPenalty` with the other strand held fixed: for each pair of a vertex
    ``x_i`` and a fixed point ``q_k``, energy ``w f_ik max(0, gap - s (x_i - q_k) . up)**2``,
    ``s`` = +1 where the rod goes over, -1 under, ``f`` fading with the horizontal distance.

    Parameters
    ----------
    vertices : ndarray of int, shape (P,)
    fixed : ndarray, shape (P, 3)
        The fixed point of each pair.
    signs : ndarray, shape (P,)
    up : array_like, shape (3,)
    gap, weight : float
    """

    name = "obstacles"

    def __init__(self, vertices, fixed, signs, up, gap, weight):
        self.vertices = np.asarray(vertices, dtype=np.int64).reshape(-1)
        self.fixed = np.asarray(fixed, dtype=np.float64).reshape(-1, 3)
        self.signs = np.asarray(signs, dtype=np.float64).reshape(-1)
        up = np.asarray(up, dtype=np.float64)
        self.up = up / np.linalg.norm(up)
        self.gap, self.weight = gap, weight

    def _heights(self, points):
        return self.signs * ((points[self.vertices] - self.fixed) @ self.up)

    def model(self, points):
        """The penalty with the fading weights of the pairs fixed at ``points``."""
        fade = _fade(points[self.vertices] - self.fixed, self.up, self.gap)
        return _ObstacleModel(self, self.weight * fade)


def _fade(delta, up, gap):
    """``(1 - (rho / gap)**2)**2`` for the horizontal part ``rho`` of ``delta`` (0 beyond)."""
    across = delta - np.outer(delta @ up, up)
    fraction = np.sum(across**2, axis=1) / gap**2
    return np.where(fraction < 1.0, (1.0 - fraction) ** 2, 0.0)


class _ClearanceModel:
    """A clearance penalty with its fading weights fixed (energy; derivatives per kind)."""

    def __init__(self, term, weights):
        self.term, self.weights = term, weights

    def energy(self, points):
        short = np.maximum(self.term.gap - self.term._heights(points), 0.0)
        return float(np.sum(self.weights * short**2))


class _ObstacleModel(_ClearanceModel):
    def derivatives(self, points, *, exact=False):
        term = self.term
        short = np.maximum(term.gap - term._heights(points), 0.0)
        push = -2.0 * (self.weights * short * term.signs)[:, None] * term.up
        gradient = np.zeros_like(points)
        np.add.at(gradient, term.vertices, push)
        stiffness = 2.0 * np.where(short > 0, self.weights, 0.0)
        blocks = stiffness[:, None, None] * np.outer(term.up, term.up)[None]
        return Derivatives.from_blocks(self.energy(points), gradient, term.vertices[:, None],
                                       blocks)


class _ContactModel(_ClearanceModel):
    def derivatives(self, points, *, exact=False):
        term = self.term
        short = np.maximum(term.gap - term._heights(points), 0.0)
        push = -2.0 * (self.weights * short)[:, None] * term.up  # d energy / d x_over
        gradient = np.zeros_like(points)
        np.add.at(gradient, term.pairs[:, 0], push)
        np.add.at(gradient, term.pairs[:, 1], -push)
        stiffness = 2.0 * np.where(short > 0, self.weights, 0.0)
        block = np.kron(np.array([[1.0, -1.0], [-1.0, 1.0]]), np.outer(term.up, term.up))
        return Derivatives.from_blocks(self.energy(points), gradient, term.pairs,
                                       stiffness[:, None, None] * block)


# -- the chain ---------------------------------------------------------------------------------
def resample_polyline(points, spacing, *, closed=False):
    """Evenly spaced points along a polyline, about ``spacing`` apart.

    Parameters
    ----------
    points : array_like, shape (M, 3)
    spacing : float
    closed : bool, optional
        The polyline returns to its first point (which is not repeated at the end).

    Returns
    -------
    ndarray, shape (N, 3)
        Both ends kept for an open polyline; at least 2 points (3 when closed).
    """
    points = np.asarray(points, dtype=np.float64)
    arc = arc_length(points, closed=closed)
    length = arc[-1]
    edges = max(int(round(length / spacing)), 3 if closed else 1)
    targets = np.linspace(0.0, length, edges + 1)
    if closed:
        points, targets = np.vstack([points, points[:1]]), targets[:-1]
    return np.column_stack([np.interp(targets, arc, points[:, k]) for k in range(3)])


def _initial_chain(points, radius, closed, settings):
    """The input chain resampled, smoothed and resampled again, about one vertex per
    ``spacing * radius``."""
    spacing = settings.spacing * radius
    chain = resample_polyline(points, spacing, closed=closed)
    if settings.smoothing > 0:
        sigma = settings.smoothing / settings.spacing
        chain = gaussian_filter1d(chain, sigma, axis=0, mode="wrap" if closed else "nearest")
        chain = resample_polyline(chain, spacing, closed=closed)
    return chain


def _strand_vertices(strand, input_arc, count, closed, span):
    """The rod vertices of one strand of a :class:`Contact` (see there)."""
    first, last = _strand_range(strand, input_arc, count, closed, span)
    vertices = np.arange(first, last + 1)
    return np.unique(vertices % count if closed else np.clip(vertices, 0, count - 1))


def _strand_middle(strand, input_arc, count, closed):
    """The rod vertex in the middle of a strand (a closed rod's numbering wraps)."""
    first, last = _strand_range(strand, input_arc, count, closed, 0)
    middle = (first + last) // 2
    return middle % count if closed else int(np.clip(middle, 0, count - 1))


def _strand_range(strand, input_arc, count, closed, span):
    """``(first, last)`` rod vertex of a strand, unwrapped (checked as :class:`Contact`
    says)."""
    indices = np.atleast_1d(np.asarray(strand))
    if indices.dtype.kind not in "iu" or indices.size not in (1, 2):
        raise ValueError("a strand is an index or a (first, last) pair of indices")
    if indices.min() < 0 or indices.max() >= len(input_arc):
        raise ValueError(f"indices must lie in 0..{len(input_arc) - 1}")
    if indices.size == 2 and indices[0] > indices[1]:
        raise ValueError("a range must be (first, last) with first <= last")
    ends = np.rint(input_arc[indices] * (count if closed else count - 1)).astype(int)
    return (ends[0] - span, ends[0] + span) if indices.size == 1 else (ends[0], ends[1])


def _obstacle_pairs(obstacles, input_arc, count, closed, settings):
    """``(vertices, fixed points, signs)`` of all obstacles, on the rod's vertex numbering."""
    span = int(math.ceil(settings.contact_span / settings.spacing))
    vertices, fixed, signs = [], [], []
    for obstacle in obstacles:
        try:
            strand = _strand_vertices(obstacle.strand, input_arc, count, closed, span)
        except ValueError as error:
            raise ValueError(f"bad obstacle strand {obstacle.strand}: {error}") from None
        points = np.asarray(obstacle.points, dtype=np.float64).reshape(-1, 3)
        grid = np.stack(np.meshgrid(np.arange(len(strand)), np.arange(len(points)),
                                    indexing="ij"), -1).reshape(-1, 2)
        vertices.append(strand[grid[:, 0]])
        fixed.append(points[grid[:, 1]])
        signs.append(np.full(len(grid), 1.0 if obstacle.over else -1.0))
    if not vertices:
        return np.zeros(0, dtype=np.int64), np.zeros((0, 3)), np.zeros(0)
    return np.concatenate(vertices), np.concatenate(fixed), np.concatenate(signs)


def _contact_pairs(contacts, input_arc, count, closed, settings):
    """``(over, under)`` vertex pairs of all contacts, on the rod's vertex numbering, and
    warnings.

    Two crossings close along the cable (a tight kink) can give a contact whose over and
    under strands share vertices: the shared ones are left out of both; a contact whose
    strands' middles lie in each other's (one place of the cable, not a crossing) is dropped.
    Each is a warning, not a failure.
    """
    span = int(math.ceil(settings.contact_span / settings.spacing))
    pairs, warnings = [], []
    for contact in contacts:
        try:
            over, under = (_strand_vertices(strand, input_arc, count, closed, span)
                           for strand in (contact.over, contact.under))
        except ValueError as error:
            raise ValueError(f"bad contact {contact}: {error}") from None
        shared = np.intersect1d(over, under)
        if shared.size:
            # a strand's middle inside the other strand: one place, not a crossing
            inside = (np.isin(_strand_middle(contact.over, input_arc, count, closed), under)
                      or np.isin(_strand_middle(contact.under, input_arc, count, closed), over))
            over, under = np.setdiff1d(over, shared), np.setdiff1d(under, shared)
            if inside or not (over.size and under.size):
                warnings.append(f"a crossing (points {contact.over} over {contact.under}) "
                                "was left out of the fit: its strands are too close along "
                                "the cable to be told apart")
                continue
            warnings.append(f"a crossing (points {contact.over} over {contact.under}) holds "
                            "its strands apart over a shorter length: they are close along "
                            "the cable")
        pairs.append(np.stack(np.meshgrid(over, under, indexing="ij"), -1).reshape(-1, 2))
    pairs = np.concatenate(pairs) if pairs else np.zeros((0, 2), dtype=np.int64)
    return pairs, warnings


# -- the fit -------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class RodFit:
    """A fitted rod.

    Attributes
    ----------
    points : ndarray, shape (N, 3)
        Fitted centreline.
    radii : ndarray, shape (N,)
        Radius per vertex.
    closed : bool
    energy : float
        Total energy at the end, in units of ``E I / r``.
    energies : dict
        Energy per term (``elastic``, ``voxels``, ``images``, ``contacts``, ``anchor``), in
        units of ``E I / r``.
    iterations : int
        Newton iterations over all passes.
    converged : bool
        The last pass converged.
    input_arc : ndarray, shape (M,)
        Arc-length position (0..1) of each input point along the rod: input point ``k`` lies
        near vertex ``round(input_arc[k] * edges)``.
    warnings : tuple of str
        What the fit had to give up (a contact it could not hold), one sentence each.
    """

    points: np.ndarray
    radii: np.ndarray
    closed: bool
    energy: float
    energies: dict
    iterations: int
    converged: bool
    input_arc: np.ndarray
    warnings: tuple = ()

    def vertex_of(self, index):
        """The fitted vertex nearest to input point ``index``."""
        edges = len(self.points) if self.closed else len(self.points) - 1
        return int(round(self.input_arc[index] * edges)) % len(self.points)


def _check_inputs(points, radius, voxels, views, settings):
    points = np.array(points, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 3 or len(points) < 2:
        raise ValueError("points must be an (N, 3) array with N >= 2")
    if not np.all(np.isfinite(points)):
        raise ValueError("points must be finite")
    if not (isinstance(radius, (int, float, np.floating)) and math.isfinite(radius)
            and radius > 0):
        raise ValueError("radius must be a positive number")
    if voxels is not None and not isinstance(voxels, Voxels):
        raise ValueError("voxels must be a Voxels (or None)")
    if not all(isinstance(view, ImageEvidence) for view in views):
        raise ValueError("views must be ImageEvidence objects (ImageEvidence.from_mask)")
    if voxels is None and not views and settings.anchor_weight == 0:
        raise ValueError("nothing to fit to: give voxels, views or an anchor weight")
    if arc_length(points)[-1] <= settings.spacing * radius:
        raise ValueError("the chain is shorter than one vertex spacing")
    return points


def _data_terms(chain, current, radius, voxels, views, contact_pairs, up, closed, settings,
                unit, first_pass, obstacle_pairs=None):
    """The fit's energy terms other than the rod's own, for one pass."""
    r = radius
    lengths = np.full(len(chain), settings.spacing)  # Voronoi lengths in r
    terms = []
    if settings.anchor_weight > 0:
        terms.append(Springs.to_points(chain, settings.anchor_weight * unit / r**2 * lengths))
    voxel_weight = settings.voxel_weight * (1.0 if first_pass or not views
                                            else settings.refine_voxel_weight)
    if voxels is not None and voxel_weight > 0:
        per_volume = voxel_weight * unit / (math.pi * r**3) / r**2
        terms.append(voxel_attraction(voxels, current, weight=per_volume,
                                      reach=settings.voxel_reach * r, closed=closed,
                                      smoothing=settings.voxel_smoothing / settings.spacing))
    if views and settings.image_weight > 0:
        weights = settings.image_weight * unit * lengths / len(views)
        terms.append(ImageAttraction(tuple(views), np.full(len(chain), r), weights,
                                     settings.image_scale))
    if len(contact_pairs) and settings.contact_weight > 0:
        terms.append(ContactPenalty(contact_pairs, up, 2.0 * r * (1.0 + settings.contact_gap),
                                    settings.contact_weight * unit / r**2))
    if obstacle_pairs is not None and len(obstacle_pairs[0]) and settings.contact_weight > 0:
        terms.append(ObstaclePenalty(*obstacle_pairs, up, 2.0 * r * (1.0 + settings.contact_gap),
                                     settings.contact_weight * unit / r**2))
    return terms


def fit_rod(points, radius, *, voxels=None, views=(), contacts=(), obstacles=(), closed=False,
            up=(0.0, 0.0, 1.0), settings=RodFitSettings(), progress=None, cancel=None):
    """Fit a discrete elastic rod to a cable's voxels and images.

    Parameters
    ----------
    points : array_like, shape (M, 3)
        Initial ordered chain along the cable (e.g. a segment of the carved grid); it is
        resampled to one vertex per ``settings.spacing * radius`` and smoothed.
    radius : float
        Cable radius (world units).
    voxels : Voxels, optional
        Occupied voxels near this cable.
    views : sequence of ImageEvidence, optional
        One per view (:meth:`ImageEvidence.from_mask`).
    contacts : sequence of Contact, optional
        Crossings of the rod with itself and which strand is over (indices into ``points``).
    obstacles : sequence of Obstacle, optional
        Crossings with other cables, held fixed, and whether this rod goes over them.
    closed : bool, optional
        The cable is a loop.
    up : array_like, shape (3,), optional
        "Over" means higher along this direction.
    settings : RodFitSettings, optional
    progress : callable, optional
        ``progress(fraction, message)``.
    cancel : threading.Event, optional
        Raises :class:`~engine.errors.Cancelled` when set.

    Returns
    -------
    RodFit

    Raises
    ------
    ValueError
        Malformed input, or nothing to fit to.
    """
    views = tuple(views)
    points = _check_inputs(points, radius, voxels, views, settings)
    up = np.asarray(up, dtype=np.float64)
    if up.shape != (3,) or not np.linalg.norm(up) > 0:
        raise ValueError("up must be a non-zero 3-vector")
    radius = float(radius)
    chain = _initial_chain(points, radius, closed, settings)
    input_arc = arc_length(points)
    input_arc = input_arc / (arc_length(points, closed=closed)[-1])
    pairs, warnings = _contact_pairs(tuple(contacts), input_arc, len(chain), closed, settings)
    obstacle_pairs = _obstacle_pairs(tuple(obstacles), input_arc, len(chain), closed, settings)
    rod_settings = RodSettings(youngs_modulus=_FIT_MODULUS, max_iterations=settings.max_iterations,
                               step_tolerance=settings.step_tolerance, max_step=settings.max_step)
    unit = _FIT_MODULUS * math.pi * radius**4 / 4.0 / radius  # E I / r
    current, iterations = chain, 0
    rest = None
    for index in range(settings.passes):
        rod = Rod(current, radius, closed=closed, rest_lengths=rest)
        terms = [ElasticEnergy(rod, rod_settings),
                 *_data_terms(chain, current, radius, voxels, views, pairs, up, closed,
                              settings, unit, index == 0, obstacle_pairs)]
        stage = StageProgress(progress).part(index / settings.passes,
                                             (index + 1) / settings.passes)
        result = minimise_energy(terms, current, length_scale=radius, settings=rod_settings,
                                 progress=stage, cancel=cancel)
        current, iterations = np.array(result.points), iterations + result.iterations
        edges = len(current) if closed else len(current) - 1
        rest = np.full(edges, arc_length(current, closed=closed)[-1] / edges)
    current.setflags(write=False)
    radii = np.full(len(current), radius)
    radii.setflags(write=False)
    input_arc.setflags(write=False)
    energies = {name: value / unit for name, value in result.energies.items()}
    return RodFit(points=current, radii=radii, closed=bool(closed),
                  energy=float(sum(energies.values())), energies=energies,
                  iterations=iterations, converged=result.converged, input_arc=input_arc,
                  warnings=tuple(warnings))

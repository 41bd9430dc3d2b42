"""Segment graph from the occupancy and junction voxel grids (paper §3.3).

The carved grid knows where the cable is but not how it is connected. This module turns it into a
graph: nodes are junctions (where the cable crosses itself) and free ends, edges are segments,
each with a centreline through the middle of the cable's cross-section.

Method
------
All distances are geodesic, measured inside the occupied voxels (26-neighbour steps weighted by
their length). Fronts are grown from every junction region at once; a component of the cable
with no junction is grown from its extremity (its end, or any slab of a closed loop). The grown
distance is cut into bands about half a radius thick, and each connected piece of a band is one
*front*. Fronts in consecutive bands that touch are linked, which gives a graph (the Reeb graph
of the distance) where a front that splits is a branching, a front that ends is a free end and a
junction region is where fronts start.

That graph is then read as the paper does: a junction region is grown until its front falls
apart, i.e. it absorbs the branchings its fronts meet within ``junction_growth`` radii; the
number of pieces its front has then is its number of branches. Junctions whose grown regions meet
are merged. Chains of fronts between junctions and ends are the segments, so several segments
between the same two junctions, loops from a junction back to itself and closed loops with no
junction at all survive. Dead ends that stick out of the cable less than ``spur_length`` (bumps
of carving noise, and the remnant where two fronts collide in a thick cable) and tiny loops
(``min_loop_length``) are removed. A crossing the images missed still shows as fronts that
split; such splits close together become one junction (``voted`` False).

Each segment's centreline starts from the centroids of its fronts and is refined a few times:
the segment's voxels are cut into slabs square to the (smoothed) line, one voxel thick, and the
line goes through the slabs' centroids. Lopsided slabs at a tip or against a junction's grown
region are left out; there the line goes straight on to the cable's tip, or curves into the
junction's centre.
"""

import logging
import math
from dataclasses import dataclass

import networkx as nx
import numpy as np
from scipy import ndimage, sparse
from scipy.sparse import csgraph
from scipy.spatial import cKDTree

from ..geometry.polylines import arc_length
from ..progress import StageProgress, check_cancel
from ..settings import check_settings, setting
from . import sparse_voxels

__all__ = ["SegmentGraphSettings", "SegmentGraph", "extract_segment_graph",
           "extract_segment_graph_from_voxels", "voxelize_tubes"]

log = logging.getLogger(__name__)

#: The 26 neighbour steps of a voxel and their lengths.
_STEPS = sparse_voxels.NEIGHBOUR_STEPS
_STEP_LENGTHS = np.linalg.norm(_STEPS, axis=1)

#: Node kinds of the segment graph.
JUNCTION, END, CLOSURE = "junction", "end", "closure"
# Kinds used only while the graph is simplified: a front that splits, and a component's seed.
_BRANCH, _SEED = "branch", "seed"
#: Which kind a node merged from two takes.
_KIND_RANK = [JUNCTION, _BRANCH, _SEED, END]


@dataclass(frozen=True)
class SegmentGraphSettings:
    """How the segment graph is extracted (lengths in units of the cable radius r or of voxels).

    Attributes
    ----------
    speck_volume : float
        Pieces of occupied voxels smaller than this many r³ are ignored.
    junction_min_volume : float
        Junction voxel regions smaller than this many r³ are ignored.
    seed_depth : float
        A piece of cable with no junction is grown from its far end: the voxels within this many
        r of its farthest voxel.
    band_width : float
        Thickness of a front (one band of geodesic distance), in r; at least √3 voxels so that
        fronts in consecutive bands always touch.
    junction_growth : float
        A junction region grows up to this many r while its front still splits: branchings of
        its fronts closer than this are part of the junction. Also the distance under which two
        branchings found from the shape alone are one junction.
    junction_merge_gap : float
        Two junctions are merged when, once grown, less than this many r of cable is left
        between them.
    spur_length : float
        Dead ends sticking out less than this many r beyond the cable around them are carving
        noise and are removed (a real end of the cable reaching less than this beyond a
        junction's grown region is removed too).
    min_loop_length : float
        Loops shorter than this many r (holes in the carved hull) are filled.
    slab_radius : float
        Voxels farther than this many r from the centreline are left out of its centroids.
    smoothing : float
        Standard deviation of the Gaussian that smooths a centreline, in r.
    refine_iterations : int
        Number of centroid-and-smooth passes over each centreline.
    junction_trim : float
        Slabs within this many r of a junction's grown region are cut by it and lopsided: the
        centreline leaves them out and curves from there into the junction.
    point_spacing : float
        Distance between consecutive centreline points, in voxels.
    end_length : float
        Each end of a centreline goes straight on along the line's direction over its last two
        times this many r: to the cable's tip, or into its junction; that direction is the
        branch direction at the end.
    """

    speck_volume: float = setting(2.0, low=0, unit="r³")
    junction_min_volume: float = setting(1.0, low=0, unit="r³")
    seed_depth: float = setting(2.0, above=0, unit="r")
    band_width: float = setting(0.5, above=0, unit="r")
    junction_growth: float = setting(4.0, low=0, unit="r")
    junction_merge_gap: float = setting(1.0, low=0, unit="r")
    spur_length: float = setting(2.0, low=0, unit="r")
    min_loop_length: float = setting(6.0, low=0, unit="r")
    slab_radius: float = setting(3.0, above=0, unit="r")
    smoothing: float = setting(1.0, low=0, unit="r")
    refine_iterations: int = setting(3, low=0)
    junction_trim: float = setting(1.0, low=0, unit="r")
    point_spacing: float = setting(1.0, above=0, unit="voxels")
    end_length: float = setting(1.0, above=0)

    def __post_init__(self):
        check_settings(self)


class SegmentGraph:
    """Junctions, free ends and the segments between them, in world coordinates.

    Parameters
    ----------
    graph : networkx.MultiGraph
        Nodes carry ``kind`` (``"junction"``, ``"end"`` or ``"closure"``) and ``position``
        (world, shape (3,)); junctions also carry ``voxels`` (grid indices [i, j, k] of the
        junction's grown region, shape (n, 3)) and ``voted`` (True if it holds junction voxels
        voted by the images, False if it was found from the shape of the occupied voxels alone).
        A ``"closure"`` node is an arbitrary point of a closed cable with no junction; its
        segment is a self-loop. Edges (segments) carry ``points`` (world, shape (m, 3), from
        node ``start`` to node ``end``), ``start``, ``end``, ``start_direction`` and
        ``end_direction`` (unit vectors pointing from the node into the segment), ``closed``
        (True only for a closure's segment, whose points are then listed once, without repeating
        the first), ``length`` (world units) and ``voxels`` (grid indices of the voxels that
        belong to the segment).
    origin : array_like, shape (3,)
        World position of the centre of voxel [0, 0, 0].
    voxel_size : float
        Edge length of a voxel.
    radius : float
        Cable radius used for the extraction.
    """

    def __init__(self, graph, *, origin, voxel_size, radius):
        self.graph = graph
        self.origin = np.asarray(origin, dtype=float)
        self.voxel_size = float(voxel_size)
        self.radius = float(radius)

    def _nodes(self, kind):
        return ((n, d) for n, d in self.graph.nodes(data=True) if d["kind"] == kind)

    def junctions(self):
        """Iterate ``(node, data)`` over the junctions."""
        return self._nodes(JUNCTION)

    def ends(self):
        """Iterate ``(node, data)`` over the free ends."""
        return self._nodes(END)

    def segments(self):
        """Iterate ``(u, v, key, points)`` over the segments, ``points`` running from u to v."""
        for u, v, key, data in self.graph.edges(keys=True, data=True):
            if data["start"] != u:
                u, v = v, u
            yield u, v, key, data["points"]

    def degree(self, node):
        """Number of segment ends at ``node`` (a self-loop counts twice)."""
        return self.graph.degree(node)

    @property
    def n_junctions(self):
        """Number of junctions."""
        return sum(1 for _ in self.junctions())

    @property
    def n_ends(self):
        """Number of free ends."""
        return sum(1 for _ in self.ends())

    @property
    def n_segments(self):
        """Number of segments (closed loops included)."""
        return self.graph.number_of_edges()

    def __repr__(self):
        return (f"SegmentGraph({self.n_junctions} junctions, {self.n_ends} ends, "
                f"{self.n_segments} segments)")


def extract_segment_graph(occupied, junction, *, origin, voxel_size, radius,
                          settings=SegmentGraphSettings(), progress=None, cancel=None):
    """Junctions, free ends and segments of a carved cable (paper §3.3).

    Parameters
    ----------
    occupied : numpy.ndarray of bool, shape (nx, ny, nz)
        Voxels inside the cable, indexed [i, j, k] along world x, y, z.
    junction : numpy.ndarray of bool, same shape
        Voxels voted as junctions (where the cable crosses itself); only those also occupied
        count.
    origin : array_like, shape (3,)
        World position of the centre of voxel [0, 0, 0].
    voxel_size : float
        Edge length of a voxel, in world units.
    radius : float
        Estimated cable radius, in world units.
    settings : SegmentGraphSettings, optional
        Thresholds, relative to the radius or the voxel size.
    progress : callable, optional
        Called as ``progress(fraction, message)`` between steps.
    cancel : threading.Event, optional
        When set, :class:`~engine.errors.Cancelled` is raised at the next step.

    Returns
    -------
    SegmentGraph
        The graph; see :class:`SegmentGraph` for what nodes and edges carry.

    Raises
    ------
    ValueError
        If the grids are not 3D boolean arrays of the same shape or a length is not positive.
    """
    occupied, junction = _check_grids(occupied, junction)
    return extract_segment_graph_from_voxels(
        np.argwhere(occupied), junction[occupied], origin=origin, voxel_size=voxel_size,
        radius=radius, settings=settings, progress=progress, cancel=cancel)


def extract_segment_graph_from_voxels(index, junction, *, origin, voxel_size, radius,
                                      settings=SegmentGraphSettings(), progress=None,
                                      cancel=None):
    """:func:`extract_segment_graph` of voxels given as a list, not a grid.

    Time and memory follow the number of voxels, not their bounding box (a thin wire
    across a large, loosely bounded scene).

    Parameters
    ----------
    index : numpy.ndarray of int, shape (n, 3)
        The occupied voxels' indices [i, j, k] along world x, y, z, distinct, in C order (as
        ``numpy.argwhere`` lists them: the result does not depend on the order otherwise, but
        ties between equal distances are broken by it).
    junction : numpy.ndarray of bool, shape (n,)
        Which of them are voted as junctions.
    origin, voxel_size, radius, settings, progress, cancel
        As for :func:`extract_segment_graph`.

    Returns
    -------
    SegmentGraph
    """
    index = np.asarray(index)
    junction = np.asarray(junction)
    if (index.ndim != 2 or index.shape[1:] != (3,) or junction.shape != index.shape[:1]
            or not np.issubdtype(index.dtype, np.integer) or junction.dtype != bool):
        raise ValueError("index must be (n, 3) integers and junction (n,) booleans")
    if not voxel_size > 0 or not radius > 0:
        raise ValueError("voxel_size and radius must be positive")
    report = _Progress(progress, cancel)
    scale = _Scale(radius / voxel_size, settings)
    graph = nx.MultiGraph()
    if len(index):
        offset = index.min(axis=0) - 1  # the voxels' box, padded by one voxel
        voxels = _VoxelGraph(index - offset, junction)
        report("grow fronts", 0.1)
        fronts = _Fronts(voxels, scale)
        report("link fronts", 0.4)
        topology = _Topology(fronts, scale)
        topology.simplify()
        report("centrelines", 0.6)
        graph = _assemble(topology, fronts, scale, offset, report)
    report("done", 1.0)
    result = SegmentGraph(_to_world(graph, origin, voxel_size), origin=origin,
                          voxel_size=voxel_size, radius=radius)
    log.debug("segment graph: %r", result)
    return result


def voxelize_tubes(polylines, radius, *, voxel_size=1.0, origin=None, shape=None,
                   vertical_scale=1.0):
    """Occupancy grid of tubes swept along polylines (for tests and synthetic data).

    Parameters
    ----------
    polylines : sequence of array_like, each shape (n, 3)
        Tube axes in world coordinates; repeat the first point at the end for a closed tube.
        A single point makes a ball.
    radius : float
        Tube radius (horizontal semi-axis), in world units.
    voxel_size : float, optional
        Edge length of a voxel.
    origin : array_like, shape (3,), optional
        World position of the centre of voxel [0, 0, 0]; by default the grid covers the tubes
        with a margin of two voxels and its origin is a multiple of ``voxel_size``.
    shape : tuple of int, optional
        Grid shape; given with ``origin``.
    vertical_scale : float, optional
        Vertical semi-axis over the horizontal one: a horizontal tube's cross-section is an
        ellipse this many times taller than wide.

    Returns
    -------
    occupied : numpy.ndarray of bool
        Voxels whose centre lies inside a tube.
    origin : numpy.ndarray, shape (3,)
        World position of the centre of voxel [0, 0, 0].
    """
    if (origin is None) != (shape is None):
        raise ValueError("give both origin and shape, or neither")
    polylines = [np.atleast_2d(np.asarray(p, dtype=float)) for p in polylines]
    squash = np.array([1.0, 1.0, 1.0 / vertical_scale])
    reach = radius * np.array([1.0, 1.0, vertical_scale])
    if origin is None:
        points = np.vstack(polylines)
        low = np.floor((points.min(0) - reach) / voxel_size - 2) * voxel_size
        high = points.max(0) + reach + 2 * voxel_size
        origin = low
        shape = tuple(int(n) for n in np.ceil((high - low) / voxel_size) + 1)
    origin = np.asarray(origin, dtype=float)
    occupied = np.zeros(shape, dtype=bool)
    for line in polylines:
        pairs = zip(line, line[1:]) if len(line) > 1 else [(line[0], line[0])]
        for a, b in pairs:
            lo = np.maximum(np.floor((np.minimum(a, b) - reach - origin) / voxel_size), 0)
            hi = np.minimum(np.ceil((np.maximum(a, b) + reach - origin) / voxel_size) + 1, shape)
            if np.any(hi <= lo):
                continue
            axes = [np.arange(l, h) for l, h in zip(lo.astype(int), hi.astype(int))]
            centres = np.stack(np.meshgrid(*axes, indexing="ij"), -1) * voxel_size + origin
            inside = _segment_distance(centres * squash, a * squash, b * squash) <= radius
            occupied[tuple(slice(ax[0], ax[-1] + 1) for ax in axes)] |= inside
    return occupied, origin


def _segment_distance(points, a, b):
    """Distance from each point to the segment a–b."""
    ab = b - a
    t = np.clip(((points - a) @ ab) / max(ab @ ab, 1e-300), 0.0, 1.0)
    return np.linalg.norm(points - (a + t[..., None] * ab), axis=-1)


# -- input and bookkeeping -----------------------------------------------------------------------

def _check_grids(occupied, junction):
    occupied, junction = np.asarray(occupied), np.asarray(junction)
    if occupied.ndim != 3 or occupied.shape != junction.shape:
        raise ValueError("occupied and junction must be 3D grids of the same shape")
    if occupied.dtype != bool or junction.dtype != bool:
        raise ValueError("occupied and junction must be boolean grids")
    return occupied, junction


class _Progress:
    """Reports progress and honours cancellation between steps."""

    def __init__(self, progress, cancel):
        self.progress, self.cancel = StageProgress(progress), cancel

    def __call__(self, message, fraction):
        check_cancel(self.cancel, "segment graph extraction")
        self.progress(fraction, message)


class _Scale:
    """The settings' lengths converted to voxels."""

    def __init__(self, radius_voxels, settings):
        r = radius_voxels
        self.settings = settings
        self.radius = r
        self.band = max(math.sqrt(3.0) + 1e-9, settings.band_width * r)
        self.speck_voxels = settings.speck_volume * r ** 3
        self.junction_voxels = settings.junction_min_volume * r ** 3
        self.seed = settings.seed_depth * r
        self.growth = settings.junction_growth * r
        self.merge_gap = settings.junction_merge_gap * r
        self.spur = settings.spur_length * r
        self.min_loop = settings.min_loop_length * r
        self.slab = settings.slab_radius * r
        self.sigma = settings.smoothing * r
        self.spacing = settings.point_spacing
        self.end = settings.end_length * r
        self.trim = settings.junction_trim * r


# -- voxels as a sparse graph --------------------------------------------------------------------

class _VoxelGraph:
    """Voxels as a graph of 26-neighbours.

    Every voxel has 26 edge slots; a slot with no occupied neighbour holds a loop back to the
    voxel itself, which changes no distance and no component, so the arrays stay rectangular.

    Attributes
    ----------
    coords : numpy.ndarray, shape (n, 3)
        Voxel indices (in the voxels' box padded by one voxel).
    junction : numpy.ndarray of bool, shape (n,)
        Which voxels are junction votes.
    graph : scipy.sparse.csr_matrix
        Symmetric adjacency weighted by step length.
    rows, cols : numpy.ndarray
        The two voxels of every (directed) edge slot.
    """

    def __init__(self, coords, junction):
        n = len(coords)
        neighbours = sparse_voxels.neighbours(coords, _STEPS)
        self.rows = np.repeat(np.arange(n, dtype=np.int32), len(_STEPS))
        self.cols = np.where(neighbours >= 0, neighbours, self.rows.reshape(n, -1)).ravel()
        self.coords = coords
        self.junction = junction
        indptr = np.arange(0, len(self.cols) + 1, len(_STEPS))
        self.graph = sparse.csr_matrix((np.tile(_STEP_LENGTHS, n), self.cols, indptr),
                                       shape=(n, n))

    def __len__(self):
        return len(self.coords)

    def components(self, keep_edge=None):
        """Connected components using only the edges where ``keep_edge`` is True.

        Returns the number of components and each voxel's component label.
        """
        graph = self.graph
        if keep_edge is not None:  # dropped edges become loops
            graph = sparse.csr_matrix((graph.data, np.where(keep_edge, self.cols, self.rows),
                                       graph.indptr), shape=graph.shape)
        # The graph is symmetric, so strong components are the components (and much faster).
        return csgraph.connected_components(graph, directed=True, connection="strong")

    def distance(self, sources):
        """Geodesic distance from the nearest of ``sources`` (inf where unreachable)."""
        if len(sources) == 0:
            return np.full(len(self), np.inf)
        return csgraph.dijkstra(self.graph, directed=True, indices=sources, min_only=True)


def _group(labels, count):
    """Indices of the items carrying each label in 0..count-1 (negative labels are dropped)."""
    order = np.argsort(labels, kind="stable")
    bounds = np.searchsorted(labels[order], np.arange(count + 1))
    return [order[bounds[i]:bounds[i + 1]] for i in range(count)]


# -- fronts --------------------------------------------------------------------------------------

class _Fronts:
    """Geodesic distance from the sources, cut into bands whose connected pieces are fronts.

    Attributes
    ----------
    label : numpy.ndarray of int, shape (n,)
        Each voxel's front, -1 for ignored voxels (specks).
    band, count, centroid, radius : numpy.ndarray
        Per front: its band index, number of voxels, centroid (padded-box voxel coordinates) and
        the largest distance of its voxels from its centroid.
    voted, seed : numpy.ndarray of bool
        Per front: whether it holds a junction region or a seed (a source of the distance).
    links : numpy.ndarray, shape (m, 2)
        Pairs of touching fronts in consecutive bands.
    """

    def __init__(self, voxels, scale):
        self.voxels = voxels
        self.scale = scale
        component, kept = self._components()
        regions = self._junction_regions(kept)
        seeds = self._seeds(component, kept, regions)
        distance = voxels.distance(np.flatnonzero(regions | seeds))
        reached = np.isfinite(distance)
        band = np.full(len(distance), -1, dtype=np.int64)
        band[reached] = distance[reached] // scale.band
        self._label_fronts(band, regions, seeds)

    def _components(self):
        """Each voxel's component and whether that component is big enough to keep."""
        count, component = self.voxels.components()
        size = np.bincount(component, minlength=count)
        kept = size[component] >= self.scale.speck_voxels
        log.debug("%d occupied voxels in %d pieces, %d voxels in specks", len(self.voxels),
                  count, np.count_nonzero(~kept))
        return component, kept

    def _junction_regions(self, kept):
        """Junction voxels in regions big enough to count."""
        v = self.voxels
        is_junction = v.junction & kept
        count, region = v.components(is_junction[v.rows] & is_junction[v.cols])
        size = np.bincount(region[is_junction], minlength=count)
        regions = is_junction & (size[region] >= self.scale.junction_voxels)
        log.debug("%d junction regions kept of %d", len(np.unique(region[regions])),
                  len(np.unique(region[is_junction])))
        return regions

    def _seeds(self, component, kept, regions):
        """Sources for the components with no junction: their far ends.

        The far end is what lies within ``seed_depth`` of the voxel farthest from an arbitrary
        voxel of the component: the tip of an open cable (or of one of its branches), or a
        stretch of a closed one. It spans the cable's cross-section, so the fronts grown from it
        are slabs across the cable from the start.
        """
        free = kept & ~np.isin(component, np.unique(component[regions]))
        if not free.any():
            return np.zeros(len(self.voxels), dtype=bool)
        _, first = np.unique(np.where(free, component, -1), return_index=True)
        first = first[free[first]]
        distance = self.voxels.distance(first)
        farthest = np.zeros(component.max() + 1)
        np.maximum.at(farthest, component[free], distance[free])
        return free & (distance >= farthest[component] - self.scale.seed)

    def _label_fronts(self, band, regions, seeds):
        v = self.voxels
        active = band >= 0
        row_band, col_band = band[v.rows], band[v.cols]
        same_band = (row_band == col_band) & (row_band >= 0)
        count, label = v.components(same_band)
        used = np.zeros(count, dtype=bool)
        used[label[active]] = True
        compact = np.cumsum(used) - 1  # number the fronts of active voxels 0, 1, ...
        self.label = np.where(active, compact[label], -1)
        n = int(used.sum())
        label = self.label[active]
        self.count = np.bincount(label, minlength=n)
        self.sums = np.stack([np.bincount(label, v.coords[active, i], minlength=n)
                              for i in range(3)], 1)
        self.centroid = self.sums / np.maximum(self.count, 1)[:, None]
        self.radius = np.zeros(n)
        np.maximum.at(self.radius, label,
                      np.linalg.norm(v.coords[active] - self.centroid[label], axis=1))
        self.band = np.zeros(n, dtype=np.int64)
        self.band[label] = band[active]
        self.voted = np.zeros(n, dtype=bool)
        self.voted[self.label[regions]] = True
        self.seed = np.zeros(n, dtype=bool)
        self.seed[self.label[seeds]] = True
        rising = (col_band == row_band + 1) & (row_band >= 0)
        pairs = np.unique(self.label[v.rows[rising]].astype(np.int64) * n
                          + self.label[v.cols[rising]])
        self.links = np.column_stack([pairs // max(n, 1), pairs % max(n, 1)])
        log.debug("%d fronts, %d links", n, len(self.links))

    def __len__(self):
        return len(self.count)

    def depth(self, front):
        """Geodesic distance (voxels) of a front from the nearest source."""
        return self.band[front] * self.scale.band

    def centre(self, fronts):
        """Centroid of the voxels of several fronts."""
        fronts = np.asarray(fronts, dtype=np.int64)
        return self.sums[fronts].sum(0) / max(self.count[fronts].sum(), 1)

    def reach(self, fronts, centre):
        """How far from ``centre`` the voxels of several fronts go (at most)."""
        fronts = np.asarray(fronts, dtype=np.int64)
        return float(np.max(np.linalg.norm(self.centroid[fronts] - centre, axis=1)
                            + self.radius[fronts]))


# -- topology ------------------------------------------------------------------------------------

class _Topology:
    """Key fronts (sources, splits, ends) joined by chains of fronts, then simplified.

    ``graph`` is a networkx MultiGraph. Node data: ``kind``, ``members`` (fronts merged into the
    node), ``depth`` (smallest depth of its fronts), ``growth`` (how far a junction grew: the
    largest depth of the fronts it absorbed while growing), ``voted``. Edge data: ``chain``
    (list of beads, each a list of fronts, from ``start`` to ``end``), ``start``, ``end``.
    """

    def __init__(self, fronts, scale):
        self.fronts = fronts
        self.scale = scale
        links = nx.Graph()
        links.add_nodes_from(range(len(fronts)))
        links.add_edges_from(map(tuple, fronts.links))
        self.graph = nx.MultiGraph()
        for front in links:
            kind = self._kind(front, links.degree(front))
            if kind is not None:
                depth = float(fronts.depth(front))
                self.graph.add_node(front, kind=kind, members=[front], depth=depth,
                                    growth=depth, voted=bool(fronts.voted[front]))
        self._add_chains(links)

    def _kind(self, front, degree):
        if self.fronts.voted[front]:
            return JUNCTION
        if self.fronts.seed[front]:
            return _SEED
        if degree == 1:
            return END
        if degree >= 3:
            return _BRANCH
        return None  # an ordinary front inside a chain

    def _add_chains(self, links):
        """One edge per chain of ordinary fronts between two key fronts."""
        walked = set()
        for start in self.graph:
            for first in links[start]:
                if (start, first) in walked:
                    continue
                previous, current, chain = start, first, []
                while current not in self.graph:
                    walked.update([(previous, current), (current, previous)])
                    chain.append([current])
                    previous, current = current, next(n for n in links[current]
                                                      if n != previous)
                walked.update([(previous, current), (current, previous)])
                self.graph.add_edge(start, current, chain=chain, start=start, end=current)

    # -- simplification --------------------------------------------------------------------------

    def simplify(self):
        """Prune spurs, grow and merge junctions, fill small loops, then settle node kinds."""
        self._dissolve_all()
        while self._prune_spurs():
            self._dissolve_all()
        while True:
            operation = self._next_contraction() or self._next_small_loop()
            if operation is None:
                break
            operation()
            self._dissolve_all()
            while self._prune_spurs():
                self._dissolve_all()
        self._finish()

    def _length(self, data):
        return (len(data["chain"]) + 1) * self.scale.band

    def _is_leaf(self, node):
        g = self.graph
        return g.degree(node) == 1 and g.nodes[node]["kind"] in (END, _SEED, _BRANCH)

    def _cheapest(self, candidates):
        """The operation with the lowest cost, or None."""
        candidates = [c for c in candidates if c is not None]
        return min(candidates, key=lambda c: c[0])[1] if candidates else None

    def _prune_spurs(self):
        """Prune the dead ends shorter than ``spur_length``, shortest first; True if any.

        A node is left with at least two branches, so a spur only goes where something else
        carries on (the nodes left with two are dissolved afterwards and looked at again).
        """
        g = self.graph
        spurs = []
        for u, v, key, data in g.edges(keys=True, data=True):
            for node, leaf in ((u, v), (v, u)):
                if node != leaf and self._is_leaf(leaf) and g.degree(node) >= 3:
                    length = self._protrusion(node, leaf, data)
                    if length < self.scale.spur:
                        spurs.append((length, leaf, key, node))
        pruned = False
        for _, leaf, key, node in sorted(spurs, key=lambda spur: spur[0]):
            if g.has_edge(leaf, node, key) and g.degree(node) >= 3:
                self._prune(leaf, key, node)
                pruned = True
        return pruned

    def _protrusion(self, node, leaf, data):
        """How far a dead end sticks out of the cable around the node it hangs from.

        That is how far its voxels reach from the node's centroid, less how far the node's own
        voxels reach: the thickness of the cable there does not count, so the remnant where two
        fronts collide in a thick cable is no branch, while a bump counts by its height.
        """
        fronts = self.fronts
        members = self.graph.nodes[node]["members"]
        centre = fronts.centre(members)
        spur = _flatten(data["chain"]) + self.graph.nodes[leaf]["members"]
        return fronts.reach(spur, centre) - fronts.reach(members, centre)

    def _next_contraction(self):
        g = self.graph

        def cost(u, v, key, data):
            a, b = g.nodes[u], g.nodes[v]
            kinds = {a["kind"], b["kind"]}
            if u == v or END in kinds or (_BRANCH not in kinds and kinds != {JUNCTION}):
                return None
            if kinds == {JUNCTION}:  # grown regions that (nearly) meet: one junction
                value, limit = self._gap(a, b, data), self.scale.merge_gap
            elif kinds == {_BRANCH}:  # splits found from the shape alone, close together
                value, limit = self._length(data), self.scale.growth
            else:  # a source (junction or seed) growing over a split of its own front
                value = self._length(data)
                limit = self.scale.growth
                if (b if b["kind"] == _BRANCH else a)["depth"] > limit:
                    return None
            return (value, lambda: self._contract(u, v, key)) if value <= limit else None
        return self._cheapest(cost(u, v, k, d) for u, v, k, d in g.edges(keys=True, data=True))

    def _gap(self, a, b, data):
        """Length of cable left between two junctions' grown regions along an edge.

        The fronts of the two junctions meet halfway, at the chain's deepest front; each
        junction's region covers its half up to the depth it grew to.
        """
        fronts = self.fronts
        chain = np.asarray(_flatten(data["chain"]), dtype=np.int64)
        meet = (fronts.depth(chain).max() if len(chain) else 0.0) + self.scale.band / 2
        return 2 * meet - min(a["growth"], meet) - min(b["growth"], meet)

    def _next_small_loop(self):
        g = self.graph
        loops = ((self._length(d), u, k) for u, v, k, d in g.edges(keys=True, data=True)
                 if u == v and self._length(d) < self.scale.min_loop)
        return self._cheapest((length, lambda u=u, k=k: self._absorb_loop(u, k))
                              for length, u, k in loops)

    def _prune(self, leaf, key, node):
        """Remove a dead end.

        Its voxels join a junction it hangs from (without growing it: a spur says nothing about
        how far the junction reaches) and are dropped elsewhere, where they would pull the
        centreline towards the bump.
        """
        if self.graph.nodes[node]["kind"] == JUNCTION:
            chain = self.graph.edges[leaf, node, key]["chain"]
            self._absorb(node, self.graph.nodes[leaf]["members"] + _flatten(chain), grow=False)
        self.graph.remove_node(leaf)

    def _absorb_loop(self, node, key):
        self._absorb(node, _flatten(self.graph.edges[node, node, key]["chain"]))
        self.graph.remove_edge(node, node, key)

    def _absorb(self, node, members, *, grow=True):
        data = self.graph.nodes[node]
        data["members"] = data["members"] + list(members)
        if members and grow:
            data["growth"] = max(data["growth"],
                                 float(self.fronts.depth(np.asarray(members)).max()))

    def _contract(self, u, v, key):
        """Merge node v into node u across the edge ``key``."""
        g = self.graph
        chain = g.edges[u, v, key]["chain"]
        g.remove_edge(u, v, key)
        a, b = g.nodes[u], g.nodes[v]
        self._absorb(u, b["members"] + _flatten(chain))
        a["growth"] = max(a["growth"], b["growth"])
        a["depth"] = min(a["depth"], b["depth"])
        a["voted"] = a["voted"] or b["voted"]
        a["kind"] = min(a["kind"], b["kind"], key=_KIND_RANK.index)
        for _, other, data in list(g.edges(v, data=True)):
            beads = _oriented(data, v)
            target = u if other == v else other
            g.add_edge(u, target, chain=beads, start=u, end=target)
        g.remove_node(v)

    def _dissolve_all(self, kinds=(_BRANCH, _SEED)):
        """Turn nodes that only pass a chain through (two distinct edges) into chain beads."""
        g = self.graph
        for node in [n for n, d in g.nodes(data=True) if d["kind"] in kinds]:
            ends = list(g.edges(node, keys=True, data=True))
            if len(ends) != 2 or any(o == node for _, o, _, _ in ends):
                continue
            (_, a, ka, da), (_, b, kb, db) = ends
            chain = _oriented(da, a) + [list(g.nodes[node]["members"])] + _oriented(db, node)
            g.remove_node(node)
            g.add_edge(a, b, chain=chain, start=a, end=b)

    def _finish(self):
        """Final kinds: junction (three or more branches), end, or closure (a lone loop)."""
        g = self.graph
        for u, v, key, data in list(g.edges(keys=True, data=True)):
            if (u != v and g.degree(u) == 1 and g.degree(v) == 1
                    and self._length(data) < self.scale.spur):
                g.remove_nodes_from([u, v])  # a short isolated piece
        g.remove_nodes_from([n for n in list(g) if g.degree(n) == 0])
        self._dissolve_all(kinds=(JUNCTION, _BRANCH, _SEED))
        for node, data in g.nodes(data=True):
            degree = g.degree(node)
            if degree >= 3:
                data["kind"] = JUNCTION
            elif degree == 1:
                data["kind"] = END
            else:
                data["kind"] = CLOSURE  # the only node left on a closed loop


def _flatten(chain):
    """All fronts of a chain of beads."""
    return [front for bead in chain for front in bead]


def _oriented(data, node):
    """The chain of an edge as seen walking away from ``node`` (a copy)."""
    chain = list(data["chain"])
    return chain if data["start"] == node else chain[::-1]


# -- geometry ------------------------------------------------------------------------------------

def _assemble(topology, fronts, scale, offset, report):
    """The final graph with centrelines, in (fractional) indices of the full grid."""
    g = topology.graph
    voxels_of = _voxels_by_owner(topology, fronts)
    ids = {node: i for i, node in enumerate(g)}
    centres = {node: fronts.centre(data["members"]) for node, data in g.nodes(data=True)
               if data["kind"] == JUNCTION}
    out = nx.MultiGraph()
    for node, data in g.nodes(data=True):
        attrs = {"kind": data["kind"]}
        if node in centres:
            attrs.update(position=centres[node] + offset, voted=data["voted"],
                         voxels=voxels_of[("node", node)] + offset)
        out.add_node(ids[node], **attrs)
    edges = list(g.edges(keys=True, data=True))
    for index, (u, v, key, data) in enumerate(edges):
        if index % 16 == 0:
            report("centrelines", 0.6 + 0.4 * index / len(edges))
        start, end = data["start"], data["end"]
        closed = g.nodes[start]["kind"] == CLOSURE
        voxels = voxels_of[("edge", u, v, key)]
        coarse = np.array([fronts.centre(bead) for bead in data["chain"]]).reshape(-1, 3)
        if len(coarse) < 3 or closed:  # else the line is extended to the tips from its middle
            coarse = np.array([fronts.centre(b) for b in _edge_beads(g, data)]).reshape(-1, 3)
        line = _centreline(coarse, voxels, closed=closed, scale=scale,
                           targets=(centres.get(start), centres.get(end)))
        out.add_edge(ids[start], ids[end], start=ids[start], end=ids[end], closed=closed,
                     points=line + offset, voxels=voxels + offset,
                     start_direction=_direction(line, scale),
                     end_direction=_direction(line[::-1], scale))
    for node, data in out.nodes(data=True):  # ends and closures sit on their segment's line
        if data["kind"] != JUNCTION:
            _, _, edge = next(iter(out.edges(node, data=True)))
            data["position"] = edge["points"][0 if edge["start"] == node else -1].copy()
    return out


def _edge_beads(g, data):
    """Beads of an edge with the fronts of its non-junction end nodes included."""
    start, end = data["start"], data["end"]
    beads = list(data["chain"])
    if g.nodes[start]["kind"] != JUNCTION:
        beads.insert(0, g.nodes[start]["members"])
    if end != start and g.nodes[end]["kind"] != JUNCTION:
        beads.append(g.nodes[end]["members"])
    return beads


def _voxels_by_owner(topology, fronts):
    """Voxel indices of every junction ``("node", n)`` and segment ``("edge", u, v, k)``."""
    g = topology.graph
    owner = np.full(len(fronts), -1, dtype=np.int64)
    keys = []
    for node, data in g.nodes(data=True):
        if data["kind"] == JUNCTION:
            owner[np.asarray(data["members"], dtype=np.int64)] = len(keys)
            keys.append(("node", node))
    for u, v, key, data in g.edges(keys=True, data=True):
        owner[np.asarray(_flatten(_edge_beads(g, data)), dtype=np.int64)] = len(keys)
        keys.append(("edge", u, v, key))
    voxel_owner = np.full(fronts.label.shape, -1, dtype=np.int64)
    labelled = fronts.label >= 0  # (no front at all: nothing is owned)
    voxel_owner[labelled] = owner[fronts.label[labelled]]
    coords = fronts.voxels.coords
    return {key: coords[group] for key, group in zip(keys, _group(voxel_owner, len(keys)))}


def _centreline(coarse, voxels, *, closed, targets, scale):
    """A segment's line through the centroids of its cross-sections, ending at its targets.

    ``targets`` are the positions of the junctions at the start and end (None for a free end).
    """
    line = _resample(coarse, scale.spacing, closed=closed)
    voxels = voxels.astype(float)
    if len(line) >= 3 and len(voxels):
        sigma = scale.sigma / scale.spacing
        for _ in range(scale.settings.refine_iterations):
            line = _smooth(line, sigma, closed=closed)  # slabs square to a smooth line are stable
            line = _slab_centroids(line, voxels, scale, closed=closed)
            if not closed:
                line = _extend_ends(line, voxels, scale, targets, attach=False)
            line = _resample(line, scale.spacing, closed=closed)
        line = _resample(_smooth(line, sigma, closed=closed), scale.spacing, closed=closed)
    return line if closed else _extend_ends(line, voxels, scale, targets, attach=True)


def _slab_centroids(line, voxels, scale, *, closed):
    """Centroids of the voxels in slabs one ``point_spacing`` thick, square to the line.

    Each voxel is placed along the line by projecting it on the tangent at its nearest line
    point; voxels farther than ``slab_radius`` from the line, or past an open line's ends, are
    left out, and so are the thin slabs at an open line's ends.
    """
    tangent = _tangents(line, max(1, int(round(scale.radius / scale.spacing))), closed=closed)
    arc = arc_length(line)
    distance, nearest = cKDTree(line).query(voxels, distance_upper_bound=scale.slab)
    inside = np.isfinite(distance)
    voxels, nearest = voxels[inside], nearest[inside]
    offset = voxels - line[nearest]
    along = np.einsum("ij,ij->i", offset, tangent[nearest])
    across = np.linalg.norm(offset - along[:, None] * tangent[nearest], axis=1)
    position = arc[nearest] + along
    keep = across <= scale.slab
    if not closed:
        half = scale.spacing / 2
        keep &= (position >= -half) & (position <= arc[-1] + half)
    slab = np.floor(position[keep] / scale.spacing + 0.5).astype(np.int64)
    if closed:
        total = arc[-1] + np.linalg.norm(line[0] - line[-1])
        slab %= max(int(round(total / scale.spacing)), 1)
    slab -= slab.min(initial=0)
    count = np.bincount(slab)
    sums = np.stack([np.bincount(slab, voxels[keep, i], minlength=len(count))
                     for i in range(3)], 1)
    filled = count > 0
    if not filled.any():
        return line
    if not closed:  # thin slabs at the ends (the last voxels of a tip) are lopsided
        full = np.flatnonzero(count >= 0.75 * np.median(count[filled]))
        filled[:full[0]] = filled[full[-1] + 1:] = False
    return sums[filled] / count[filled, None]


def _tangents(line, span, *, closed):
    """Unit tangents by differences over ``span`` points each way."""
    index = np.arange(len(line))
    if closed:
        ahead, behind = line[(index + span) % len(line)], line[(index - span) % len(line)]
    else:
        ahead = line[np.minimum(index + span, len(line) - 1)]
        behind = line[np.maximum(index - span, 0)]
    tangent = ahead - behind
    return tangent / np.maximum(np.linalg.norm(tangent, axis=1), 1e-9)[:, None]


def _extend_ends(line, voxels, scale, targets, *, attach):
    """Carry both ends of an open line straight on, to where the cable ends.

    Each end goes on along the line's direction over its last ``end_length`` to the last voxel
    ahead within a radius of that direction: the cable's tip at a free end. At an end with a
    junction (its target) the last ``junction_trim`` is dropped first, since slabs cut by the
    junction's grown region are lopsided; with ``attach`` that end then curves into the
    junction.
    """
    arc = arc_length(line)
    trims = [0.0 if target is None else scale.trim for target in targets]
    if len(line) < 3 or arc[-1] < sum(trims) + 2 * scale.end:  # too short to fit
        ends = [t[None] if attach and t is not None else np.zeros((0, 3)) for t in targets]
        return _resample(np.vstack([ends[0], line.reshape(-1, 3), ends[1]]), scale.spacing,
                         closed=False)
    runs = [_end_run(points, voxels, target, trim, scale, attach=attach)
            for points, target, trim in zip((line, line[::-1]), targets, trims)]
    middle = line[(arc > trims[0]) & (arc < arc[-1] - trims[1])]
    return _resample(np.vstack([runs[0], middle, runs[1][::-1]]), scale.spacing, closed=False)


def _end_run(points, voxels, target, trim, scale, *, attach):
    """The run that replaces the first ``trim`` of ``points``, from its far end in.

    Straight along the line to the last voxel ahead, or, when attaching to a junction, a
    parabola leaving the line tangentially and ending at the junction.
    """
    anchor, axis = _end_axis(points, scale, skip=trim)
    if not (attach and target is not None):
        return np.array([anchor + _reach(anchor, axis, voxels, scale.radius) * axis, anchor])
    control = anchor + max(float((target - anchor) @ axis), 0.0) * axis
    count = max(int(np.ceil(np.linalg.norm(target - anchor) / scale.spacing)), 1) + 1
    t = np.linspace(1.0, 0.0, count)[:, None]
    return (1 - t) ** 2 * anchor + 2 * (1 - t) * t * control + t ** 2 * target


def _reach(anchor, axis, voxels, radius):
    """How far the voxels within ``radius`` of a ray go on along it without a gap."""
    offset = voxels - anchor
    along = offset @ axis
    across2 = np.einsum("ij,ij->i", offset, offset) - along ** 2
    ahead = np.sort(along[(along > 0) & (across2 <= radius ** 2)])
    gaps = np.flatnonzero(np.diff(np.concatenate([[0.0], ahead])) > 2.0)
    ahead = ahead[:gaps[0]] if len(gaps) else ahead
    return float(ahead[-1]) if len(ahead) else 0.0


def _end_axis(points, scale, *, skip=0.0):
    """A point ``skip`` along a line from its start, and the line's outward direction there.

    A straight line is fitted to the points within 2 ``end_length`` around that point (from
    the start if it is closer than ``end_length`` to it).
    """
    distance = arc_length(points)
    low = max(skip - scale.end, 0.0)
    window = (distance >= low) & (distance <= low + 2 * scale.end)
    if window.sum() < 3:  # too few points there: the last three (or all)
        window = distance >= min(low, distance[max(len(points) - 3, 0)])
    anchor, slope = np.polynomial.polynomial.polyfit(distance[window] - skip, points[window], 1)
    return anchor, -slope / max(np.linalg.norm(slope), 1e-12)


def _direction(points, scale):
    """Unit direction from the start of a line into it (the branch direction at that end)."""
    if len(points) < 2:
        return np.zeros(3)
    return -_end_axis(points, scale)[1]


def _resample(points, spacing, *, closed):
    """Points evenly spaced about ``spacing`` apart along the line (ends kept if open)."""
    points = np.asarray(points, dtype=float).reshape(-1, 3)
    if len(points) > 1:
        keep = np.concatenate([[True], np.linalg.norm(np.diff(points, axis=0), axis=1) > 1e-9])
        points = points[keep]
    if len(points) < 2:
        return points.copy()
    path = np.vstack([points, points[:1]]) if closed else points
    arc = arc_length(path)
    count = max(int(round(arc[-1] / spacing)), 3 if closed else 1)
    at = np.linspace(0.0, arc[-1], count + 1)
    at = at[:-1] if closed else at
    return np.column_stack([np.interp(at, arc, path[:, i]) for i in range(3)])


def _smooth(points, sigma, *, closed):
    """Gaussian smoothing along the line (an open line's ends are pulled in a little)."""
    if sigma <= 0 or len(points) < 3:
        return points
    return ndimage.gaussian_filter1d(points, sigma, axis=0, mode="wrap" if closed else "nearest")


def _to_world(graph, origin, voxel_size):
    """Convert positions and points from grid indices to world coordinates; add lengths."""
    origin = np.asarray(origin, dtype=float)
    for _, data in graph.nodes(data=True):
        data["position"] = origin + data["position"] * voxel_size
        if "voxels" in data:
            data["voxels"] = data["voxels"].astype(np.int64)
    for _, _, data in graph.edges(data=True):
        data["points"] = origin + data["points"] * voxel_size
        data["voxels"] = data["voxels"].astype(np.int64)
        path = np.vstack([data["points"], data["points"][:1]]) if data["closed"] else data["points"]
        data["length"] = float(arc_length(path)[-1])
    return graph

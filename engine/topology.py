"""Crossings and one path per cable (paper §3.5, and beyond it).

The segment graph (:mod:`engine.segment_graph`) says where the cable meets itself (junctions) and
which pieces of cable (segments) leave each junction, but not which branch continues into which,
nor which strand lies on top. This module decides both and joins the segments into ordered
centrelines: one path per cable, with the crossings listed (which strand is over, how sure).

Method
------
At every junction each way of pairing its branches into strands that go through it (a
*matching*), together with an over/under order for every two strands that cross there (their
branches alternate around the junction), is a *hypothesis*. Its score is a sum of log-likelihood
terms from independent cues:

* **Bending** (continuity, the paper's implicit assumption): a strand goes straight through.
  The two branch points of a strand (on its centreline just beyond where the strands overlap)
  are joined by a cubic Hermite curve along their tangents; its dimensionless bending energy
  ``L * integral(kappa**2 ds)`` (the squared turning angle for a circular arc) costs
  ``energy / (2 bend_scale**2)``.
* **Height** (beyond the paper): the carved cable is higher where it passes over. The height
  along ``up`` of each branch's centreline next to its branch point is averaged per strand; the
  difference, over ``height_scale``, is the log-odds that the higher strand is over.
* **Images** (the paper's cue, voted over every view that sees the junction instead of one):
  the strand on top shows no edge across the junction, the one below shows two occlusion
  edges. In each view the branch points are projected, moved to the brightest cable pixel
  nearby, and joined by shortest paths (Dijkstra on a small patch) whose pixels cost
  ``edge_floor + g**2 / edge_scale`` for the colour gradient ``g``; off the cable mask they
  cost much more. Before the gradient is taken the brightest cable pixels are clipped, so a
  specular highlight makes no edge. For crossing strands ``O`` over ``U`` a view scores
  ``(c_U - c_O) / (c_U + c_O)``, ``c`` the path cost between a strand's two branch points.
  Views weigh by how straight down they look at the junction, by the largest angle between
  the projected branches and by the cable's size in pixels (and half where the view's junction
  map shows no junction there); views where another part of the cable, nearer the camera,
  crosses the paths are left out. The cue's log-odds is ``image_gain`` times the weighted
  t statistic of the view scores, shrunk when the views are few.

Each cue is capped, so that no single cue can make a crossing certain, and when the heights and
the images disagree the weaker one counts twice: the confidence then drops towards one half. A
junction's hypotheses get probabilities from their scores (softmax). A crossing's confidence is
the probability of its matching (given the one-path check below) times that of its order.

Measured on 79 synthetic scenes (open, closed and knotted cables; 12-24 views at 640x480 or
800x600; orbits and hand-held paths): all 307 crossings right, 304 of them with confidence
above 0.999 and none below 0.75; each cue alone also gets all of them right (confidence
0.9-0.998). With the heights mirrored against the images no crossing is reported above 0.9.

Paths: the segments are followed through the junctions along the chosen matchings. Each strand's
branches are cut ``bridge_distance`` from the junction (the carved centreline bends into the
junction's middle there) and joined by a smooth Hermite bridge; where two strands cross, the
over strand is lifted and the under one lowered by a smooth bump until they are ``separation``
apart, so the geometry says over and under as the crossing list does, and each crossing's
indices point at the two strands' closest pass. The paper's combinatorial check comes after: a
connected piece of the graph must give one path (open between two free ends, or closed), or
as few as its free ends allow. If the best matchings give more, the least confident junctions
are revisited first (a best-first search over combinations of matchings ranked by
probability), and the probabilities are conditioned on the check. Several connected pieces give
several paths (several cables).

Imperfect graphs: a short branch to a free end at a junction with an odd number of branches (or
more than four) may be a spur of carving noise: it may stay unpaired, and is then dropped; a
junction with an odd number of branches and no spur, near a free end whose cable heads towards
it, has lost a branch: the gap is bridged. Two such junctions joined by a short segment
(``bigon_length``) are two crossings of a twist whose strands lie together between them:
the segment is doubled, its copies a radius either side. Degree 2 junctions are passed
through, degree 3 junctions join their straightest two branches and end the third, junctions
of more than ``max_degree`` branches are paired greedily by bending, and paths shorter than
``min_path_length`` are dropped; each gives a warning.
"""

import heapq
import itertools
import logging
import math
from dataclasses import dataclass, field

import cv2
import networkx as nx
import numpy as np
from scipy import sparse
from scipy.sparse import csgraph

from .errors import ReconstructionError
from .progress import StageProgress, check_cancel
from .segment_graph import SegmentGraph

__all__ = ["TopologySettings", "TopologyView", "TopologyPath", "TopologyCrossing", "Topology",
           "resolve_topology"]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class TopologySettings:
    """How crossings are resolved and paths are joined (lengths in units of the radius r).

    Attributes
    ----------
    anchor_distance : float
        Least horizontal distance from a junction's centre to the branch points the cues
        compare; it grows for shallow crossings, whose strands overlap farther out.
    anchor_margin : float
        The branch points lie this far beyond where two strands of width 2 r crossing at the
        junction's smallest angle between branches stop overlapping.
    max_anchor_distance : float
        Greatest distance of the branch points from the junction's centre.
    height_window : float
        A branch's height is the mean height of its centreline within this arc length each way
        of its branch point (and on its own half of a segment between two junctions).
    bend_scale : float
        Turning angle (radians) of a strand through a junction that costs half a unit of
        log-likelihood: the bending cost is ``energy / (2 bend_scale**2)``.
    vertical_weight : float
        Heights count this much in the bending energy (the over strand's ramp is a real bend
        that the height cue already reads, and carving noise is largest along ``up``).
    height_scale : float
        Height difference between two crossing strands worth one unit of log-odds.
    height_cap : float
        The height cue gives one order at most twice this log-odds over the other.
    image_gain : float
        Log-odds per unit of the image cue's statistic: the views' weighted mean score over its
        standard error (a t statistic).
    image_spread : float
        Least standard deviation of the view scores assumed by that statistic.
    image_prior_views : float
        The statistic shrinks by ``n / (n + image_prior_views)`` for ``n`` effective views: one
        or two views that happen to agree closely are not taken as certain.
    image_cap : float
        The image cue gives one order at most twice this log-odds over the other.
    top_down_power : float
        A view weighs ``cos(zenith angle) ** top_down_power``: views straight down count most.
    min_pixel_radius : float
        Views where the cable's radius is below this many pixels are not used; the weight grows
        to 1 over the next two pixels.
    occluder_margin : float
        A view is not used for a junction when another part of the cable, nearer the camera,
        projects within this many projected radii (plus one) of the paths between its branch
        points and centre.
    highlight_search : float
        A projected branch point moves to the brightest cable pixel within this many projected
        radii (the paper's answer to specular highlights: a path starting on a highlight
        follows it along the cable).
    highlight_clip : float
        Before the gradient is taken, each colour channel is clipped at this quantile of its
        values on the cable's pixels, so the edges of specular highlights cost nothing.
    edge_scale : float
        A pixel costs ``edge_floor + g**2 / edge_scale`` for a gradient magnitude ``g`` (8-bit
        levels per pixel, the largest over the colour channels): squaring makes the few strong
        occlusion edges count more than many weak ripples of shading and noise.
    edge_floor : float
        Cost of every pixel: paths are short as well as smooth, and a view of noise scores near
        zero.
    path_radius : float
        The paths are found where the cable's radius is at most this many pixels: a view that
        shows it larger is reduced around the junction first (the cost of the paths grows
        with the square of the patch's side; the edges they weigh are as clear).
    spur_length : float
        At a junction with an odd number of branches or more than four, a branch to a free end
        shorter than this may be a spur of carving noise (or a stub of cable): it may stay
        unpaired, and a piece made of it alone is dropped.
    unpaired_cost : float
        Log-likelihood cost of leaving a branch that is not such a spur unpaired, and gain of
        leaving a spur unpaired.
    gap_length : float
        A junction with an odd number of branches and no spur (one branch was missed by the
        carving) is joined to a free end within this horizontal distance whose cable heads
        towards it: the gap is bridged straight.
    bigon_length : float
        A segment up to this long between two junctions that each miss a branch is taken for
        two strands lying together between two crossings, and doubled (0: never).
    min_path_length : float
        Paths shorter than this (specks of carving noise) are dropped, unless nothing else is
        left.
    bridge_distance : float
        Branches are cut this far (horizontally) from the junction's centre and joined by a
        smooth bridge.
    separation : float
        Vertical distance between the over and the under strand that the bridges are given.
    lift_width : float
        Half width (horizontal arc length) of the bump that lifts or lowers a strand there.
    confident : float
        Crossings less sure than this are reported with a warning.
    max_degree : int
        Junctions with more branches are paired greedily by bending.
    search_budget : int
        Largest number of combinations of matchings the one-path search tries per cable (when
        one makes the cable one path it comes early: by the 18th in every hard tuning heap;
        the whole budget is spent only where none does).
    search_window : float
        Having found the most likely combination that makes each cable one path, the search
        weighs the others up to this many log-units less likely (each then weighs under
        e^-window of it) into every junction's probability.
    """

    anchor_distance: float = 3.0
    anchor_margin: float = 1.5
    max_anchor_distance: float = 7.0
    height_window: float = 1.5
    bend_scale: float = 0.5
    vertical_weight: float = 0.3
    height_scale: float = 0.4
    height_cap: float = 3.0
    image_gain: float = 0.5
    image_spread: float = 0.1
    image_prior_views: float = 3.0
    image_cap: float = 3.0
    top_down_power: float = 2.0
    min_pixel_radius: float = 1.5
    occluder_margin: float = 1.5
    highlight_search: float = 0.7
    highlight_clip: float = 0.8
    edge_scale: float = 10.0
    edge_floor: float = 1.0
    path_radius: float = 3.0
    spur_length: float = 15.0
    unpaired_cost: float = 4.0
    gap_length: float = 10.0
    bigon_length: float = 30.0
    min_path_length: float = 10.0
    bridge_distance: float = 2.5
    separation: float = 2.2
    lift_width: float = 4.0
    confident: float = 0.9
    max_degree: int = 8
    search_budget: int = 2000
    search_window: float = 9.0

    def __post_init__(self):
        for name in ("anchor_distance", "max_anchor_distance", "height_window", "bend_scale",
                     "height_scale", "image_gain", "image_spread", "highlight_search",
                     "edge_scale", "path_radius", "bridge_distance", "lift_width"):
            if not getattr(self, name) > 0:
                raise ValueError(f"TopologySettings.{name} must be positive")
        for name in ("anchor_margin", "vertical_weight", "height_cap", "image_prior_views",
                     "image_cap", "top_down_power", "min_pixel_radius", "occluder_margin",
                     "edge_floor", "spur_length", "unpaired_cost", "gap_length", "bigon_length",
                     "min_path_length", "separation"):
            if not getattr(self, name) >= 0:
                raise ValueError(f"TopologySettings.{name} must not be negative")
        if not 0.0 < self.highlight_clip <= 1.0:
            raise ValueError("TopologySettings.highlight_clip must lie in (0, 1]")
        if not 0.0 <= self.confident <= 1.0:
            raise ValueError("TopologySettings.confident must lie in [0, 1]")
        if self.max_degree < 2 or self.search_budget < 1 or not self.search_window >= 0:
            raise ValueError("TopologySettings.max_degree must be >= 2, search_budget >= 1 "
                             "and search_window >= 0")


@dataclass(frozen=True, eq=False)
class TopologyView:
    """One view for :func:`resolve_topology`.

    Attributes
    ----------
    camera : Camera
    image : ndarray or callable
        RGB image (H, W, 3) uint8, or a callable returning it (loaded only when needed).
    mask : ndarray or callable
        Cable pixels (H, W) bool, or a callable returning them.
    junctions : ndarray or callable or None
        Pixels where the cable overlaps itself (optional).
    """

    camera: object
    image: object
    mask: object
    junctions: object = None


@dataclass(frozen=True, eq=False)
class TopologyPath:
    """One cable's centreline, in order.

    Attributes
    ----------
    points : ndarray, shape (N, 3)
        World positions along the cable (a closed path does not repeat its first point).
    closed : bool
        The cable is a loop.
    segments : tuple of tuple
        The segment graph's edges ``(start, end, key)`` followed, in order (a segment extended
        over a bridged gap keeps its far node and gets a new key).
    """

    points: np.ndarray
    closed: bool
    segments: tuple = ()


@dataclass(frozen=True, eq=False)
class TopologyCrossing:
    """Where one strand passes over another.

    Attributes
    ----------
    position : ndarray, shape (3,)
        Midway between the two strands at the crossing.
    over, under : tuple of int
        ``(path index, point index)`` of the upper and the lower strand at the crossing.
    confidence : float
        Probability that this crossing is right (strands paired and ordered as said), in [0, 1].
    junction : int or None
        The segment graph's junction node it was found at.
    cues : dict
        What decided it, for debugging: ``"height"`` and ``"image"``, the log-odds each cue
        gives this order over the flipped one (positive: for it); ``"pairing"``, the
        log-probability margin of the junction's matching over the next best;
        ``"pairing_probability"``, the matching's probability; ``"views"``, the number of
        views the image cue used.
    views : tuple of tuple
        ``(view index, weight, score)`` of the views the image cue used; a positive score
        supports this order.
    """

    position: np.ndarray
    over: tuple
    under: tuple
    confidence: float
    junction: object = None
    cues: dict = field(default_factory=dict)
    views: tuple = ()


@dataclass(frozen=True, eq=False)
class Topology:
    """Paths and crossings of the cable(s).

    Attributes
    ----------
    paths : tuple of TopologyPath
        One per cable.
    crossings : tuple of TopologyCrossing
        ``over``/``under`` index into ``paths`` and their points.
    warnings : tuple of str
        Ambiguous crossings, odd junctions, pieces that could not be joined.
    up : ndarray, shape (3,)
        What "over" means.
    bump_width : float
        Half width (world units, arc length) of the bump that lifts a strand at a crossing.
    """

    paths: tuple
    crossings: tuple
    warnings: tuple = ()
    up: np.ndarray = field(default_factory=lambda: np.array([0.0, 0.0, 1.0]))
    bump_width: float = 1.0

    def flipped(self, index):
        """The same topology with crossing ``index``'s over and under swapped.

        The two strands' heights at the crossing are swapped too (with the same smooth bump
        that lifted them), so the paths keep saying what the crossing list says. The
        crossing's confidence becomes that of the flipped order (its matching's probability
        less the old confidence); flipping twice gives the original back.

        Parameters
        ----------
        index : int

        Returns
        -------
        Topology
        """
        crossing = self.crossings[index]
        (op, oi), (upath, ui) = crossing.over, crossing.under
        points = [np.array(path.points, dtype=float) for path in self.paths]
        gap = float((points[op][oi] - points[upath][ui]) @ self.up)
        width = self.bump_width
        _add_bump(points[op], self.paths[op].closed, oi, -gap, width, self.up)
        _add_bump(points[upath], self.paths[upath].closed, ui, gap, width, self.up)
        paths = tuple(TopologyPath(p, path.closed, path.segments)
                      for p, path in zip(points, self.paths))
        crossings = list(self.crossings)
        pairing = crossing.cues.get("pairing_probability", 1.0)
        crossings[index] = TopologyCrossing(
            crossing.position, crossing.under, crossing.over,
            float(np.clip(pairing - crossing.confidence, 0.0, 1.0)), crossing.junction,
            {k: (-v if k in ("height", "image") else v) for k, v in crossing.cues.items()},
            tuple((v, w, -s) for v, w, s in crossing.views))
        return Topology(paths, tuple(crossings), self.warnings, self.up, self.bump_width)

    def to_result(self, radius, **fields):
        """A :class:`~engine.result.Result` with these paths and crossings.

        Parameters
        ----------
        radius : float
        **fields
            Other :class:`~engine.result.Result` fields (``cameras``, ``units``, ...).

        Returns
        -------
        Result
        """
        from .result import CablePath, Crossing, Result, StrandRef

        paths = tuple(CablePath(path.points, closed=path.closed) for path in self.paths)
        crossings = tuple(Crossing(c.position, StrandRef(*c.over), StrandRef(*c.under),
                                   min(max(c.confidence, 0.0), 1.0)) for c in self.crossings)
        warnings = tuple(fields.pop("warnings", ())) + tuple(self.warnings)
        return Result(radius=radius, paths=paths, crossings=crossings, warnings=warnings,
                      **fields)


# -- public entry ---------------------------------------------------------------------------------

def resolve_topology(graph, views, *, radius, up, settings=TopologySettings(), progress=None,
                     cancel=None):
    """Decide over/under at every junction and join the segments into one path per cable.

    Parameters
    ----------
    graph : SegmentGraph
        Junctions, free ends and segments (:func:`engine.segment_graph.extract_segment_graph`).
    views : sequence
        Each a :class:`TopologyView`, an object with ``camera``, ``image`` and ``mask`` (and
        optionally ``junctions``) attributes, or a tuple ``(camera, image, mask[, junctions])``.
        Images and masks may be callables that load them. May be empty: then only the heights
        and the bending decide.
    radius : float
        Cable radius, world units.
    up : array_like, shape (3,)
        The table normal / world up: "over" means higher along it.
    settings : TopologySettings, optional
    progress : callable, optional
        ``progress(fraction, message)``.
    cancel : threading.Event, optional
        When set, :class:`~engine.errors.Cancelled` is raised at the next check.

    Returns
    -------
    Topology

    Raises
    ------
    ValueError
        ``radius`` not positive or ``up`` not a non-zero 3-vector.
    ReconstructionError
        The graph holds no segment: there is no path at all.
    """
    if not (isinstance(radius, (int, float, np.floating)) and math.isfinite(radius)
            and radius > 0):
        raise ValueError("radius must be a positive number")
    up = np.asarray(up, dtype=np.float64).reshape(-1)
    if up.shape != (3,) or not np.linalg.norm(up) > 0 or not np.all(np.isfinite(up)):
        raise ValueError("up must be a non-zero 3-vector")
    up = up / np.linalg.norm(up)
    views = [_as_view(view, k) for k, view in enumerate(views)]
    report = StageProgress(progress)
    check_cancel(cancel, "resolving the topology")
    g = graph.graph
    if g.number_of_edges() == 0:
        raise ReconstructionError("no path could be formed: the segment graph holds no segment")
    warnings = []
    report(0.0, "branches")
    context, junctions = _prepare(graph, float(radius), up, settings, warnings)
    check_cancel(cancel, "resolving the topology")
    _image_cue(junctions, views, context, report.part(0.05, 0.8), cancel)
    report(0.8, "hypotheses")
    return _resolve(junctions, context, warnings, report, cancel)


def _prepare(graph, radius, up, settings, warnings):
    """The context (with missed branches bridged) and the junctions with their hypotheses."""
    context = _Context(graph, radius, up, settings)
    context = _Context(_close_gaps(context, warnings), radius, up, settings)
    context = _Context(_double_bigons(context, warnings), radius, up, settings)
    return context, _junctions(context.graph, context, warnings)


def _junctions(graph, context, warnings):
    """Every junction with its branches and hypotheses (no image evidence yet)."""
    junctions = [_Junction.build(node, data, context, warnings)
                 for node, data in sorted(graph.junctions(), key=lambda item: item[0])]
    for junction in junctions:
        junction.enumerate_hypotheses(context, warnings)
    return junctions


def _resolve(junctions, context, warnings, report, cancel):
    """Score the hypotheses, choose one path per cable, build the paths and crossings."""
    for junction in junctions:
        junction.score(context)
    check_cancel(cancel, "resolving the topology")
    choice, marginals = _one_path_per_cable(junctions, context, warnings)
    check_cancel(cancel, "resolving the topology")
    report(0.9, "paths")
    topology = _assemble(junctions, choice, marginals, context, warnings)
    report(1.0, "done")
    log.debug("topology: %d path(s), %d crossing(s), %d warning(s)", len(topology.paths),
              len(topology.crossings), len(topology.warnings))
    return topology


# -- inputs ---------------------------------------------------------------------------------------

def _as_view(view, index):
    if isinstance(view, TopologyView):
        return view
    if isinstance(view, (tuple, list)):
        if not 3 <= len(view) <= 4:
            raise ValueError(f"views[{index}] must be (camera, image, mask[, junctions])")
        return TopologyView(*view)
    try:
        camera, image, mask = view.camera, view.image, view.mask
    except AttributeError:
        raise ValueError(f"views[{index}] has no camera, image and mask") from None
    junctions = getattr(view, "junctions", getattr(view, "junction_mask", None))
    return TopologyView(camera, image, mask, junctions)


def _load(item, dtype=None):
    value = item() if callable(item) else item
    if value is None:
        return None
    return np.asarray(value) if dtype is None else np.asarray(value, dtype=dtype)


class _Context:
    """What every step needs: the graph, radius, up and a horizontal basis, the settings."""

    def __init__(self, graph, radius, up, settings):
        self.graph, self.r, self.up, self.settings = graph, radius, up, settings
        helper = np.eye(3)[np.argmin(np.abs(up))]
        self.e1 = np.cross(up, helper)
        self.e1 /= np.linalg.norm(self.e1)
        self.e2 = np.cross(up, self.e1)
        spacings = [np.median(np.linalg.norm(np.diff(d["points"], axis=0), axis=1))
                    for _, _, d in graph.graph.edges(data=True) if len(d["points"]) > 1]
        self.spacing = float(np.median(spacings)) if spacings else 0.3 * radius

    def flat(self, vectors):
        """Horizontal coordinates (along e1, e2) of vectors or points."""
        vectors = np.asarray(vectors, dtype=float)
        return np.stack([vectors @ self.e1, vectors @ self.e2], axis=-1)


def _arc(points):
    if len(points) < 2:
        return np.zeros(len(points))
    return np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(points, axis=0), axis=1))])


def _at_arc(points, arc, s):
    """Point at arc length ``s`` along a polyline (clamped)."""
    s = min(max(s, 0.0), arc[-1])
    return np.array([np.interp(s, arc, points[:, k]) for k in range(3)])


def _close_gaps(context, warnings):
    """The graph with branches the carving missed bridged (a copy; the input is not changed).

    At a junction with an odd number of branches and no spur among them, a free end within
    ``gap_length`` whose cable heads towards the junction (and is not a spur of another junction)
    is taken for the rest of a missed branch: its segment is extended straight to the junction (a
    segment that already leaves that junction becomes a loop).
    """
    graph, r, s = context.graph, context.r, context.settings
    g = graph.graph
    pairs = []
    for node, data in g.nodes(data=True):
        if data["kind"] != "junction" or g.degree(node) % 2 == 0:
            continue
        centre = np.asarray(data["position"], dtype=float)
        if any(g.nodes[v]["kind"] == "end" and d["length"] < s.spur_length * r
               for _, v, d in g.edges(node, data=True)):
            continue  # the odd branch is a spur, not a missed one
        best = None
        for end, end_data in g.nodes(data=True):
            if end_data["kind"] != "end" or g.degree(end) != 1:
                continue
            (u, v, key, edge), = g.edges(end, keys=True, data=True)
            far = u if v == end else v
            if (edge["length"] < s.spur_length * r and g.nodes[far]["kind"] == "junction"
                    and g.degree(far) % 2):
                continue  # a spur of its own junction
            points = np.asarray(edge["points"], dtype=float)
            points = points[::-1] if edge["start"] == end else points  # ends at the free end
            gap = context.flat(centre - points[-1])
            distance = float(np.linalg.norm(gap))
            if distance > s.gap_length * r or len(points) < 2:
                continue
            heading = _end_tangent(points, context, False)
            heading = context.flat(heading)
            if distance > 0.5 * r and heading @ gap < 0.5 * np.linalg.norm(heading) * distance:
                continue
            if best is None or distance < best[0]:
                best = (distance, end, (u, v, key), points)
        if best is not None:
            pairs.append((node, centre) + best)
    if not pairs:
        return graph
    g = g.copy()
    taken = set()
    for node, centre, distance, end, edge, points in sorted(pairs, key=lambda p: p[2]):
        far = edge[0] if edge[1] == end else edge[1]
        # each free end and each edge once; an edge between two free ends is bridged at one
        if taken & {end, far, edge} or node not in g:
            continue
        taken.update([end, edge])
        count = max(int(math.ceil(np.linalg.norm(centre - points[-1]) / context.spacing)), 1)
        bridge = points[-1] + np.linspace(0.0, 1.0, count + 1)[1:, None] * (centre - points[-1])
        chain = np.vstack([points, bridge])[::-1]  # from the junction to the far node
        g.remove_node(end)
        length = float(_arc(chain)[-1])
        g.add_edge(node, far, points=chain, start=node, end=far, closed=False, length=length,
                   start_direction=_unit(chain[min(3, len(chain) - 1)] - chain[0]),
                   end_direction=_unit(chain[max(len(chain) - 4, 0)] - chain[-1]),
                   voxels=np.zeros((0, 3), dtype=np.int64))
        warnings.append(f"junction {node}: bridged a gap of {distance / r:.1f} r to a free end "
                        "(a branch the carving missed)")
    return SegmentGraph(g, origin=graph.origin, voxel_size=graph.voxel_size,
                        radius=graph.radius)


def _odd_junctions(g, r, settings):
    """Junctions with an odd number of branches and no spur among them (a branch is
    missing)."""
    return {node for node, data in g.nodes(data=True)
            if data["kind"] == "junction" and g.degree(node) % 2
            and not any(g.nodes[v]["kind"] == "end" and d["length"] < settings.spur_length * r
                        for _, v, d in g.edges(node, data=True))}


def _double_bigons(context, warnings):
    """The graph with a second segment beside each short one joining two junctions that
    each miss a branch (a copy; the input is not changed).

    Two strands that cross twice close together (a twist) lie side by side between the two
    crossings; the carving often gives one segment there, and each crossing then has three
    branches. The missing branch of each is that second strand: the segment is doubled, and
    the topology pairs and orders the strands through both junctions as at any crossing.
    """
    graph, r, s = context.graph, context.r, context.settings
    if s.bigon_length <= 0:
        return graph
    g = graph.graph
    odd = _odd_junctions(g, r, s)
    candidates = sorted((data["length"], u, v, key) for u, v, key, data in g.edges(keys=True,
                                                                                   data=True)
                        if u != v and u in odd and v in odd
                        and data["length"] <= s.bigon_length * r)
    if not candidates:
        return graph
    g = g.copy()
    used = set()
    for length, u, v, key in candidates:
        if u in used or v in used:
            continue
        used.update((u, v))
        data = dict(g.edges[u, v, key])
        points = np.asarray(data["points"], dtype=float)
        # side by side: each copy half a cable's width off the carved chain, in the plane, so
        # that the strands' order around each junction (and so whether they cross) is defined
        tangent = np.gradient(points, axis=0)
        side = np.cross(context.up, tangent)
        side /= np.maximum(np.linalg.norm(side, axis=1, keepdims=True), 1e-12)
        g.remove_edge(u, v, key)
        for sign in (1.0, -1.0):
            g.add_edge(u, v, **{**data, "points": points + sign * r * side})
        warnings.append(f"junctions {min(u, v)} and {max(u, v)}: the segment of "
                        f"{length / r:.1f} r between them taken for two strands (each junction "
                        "missed a branch)")
    return SegmentGraph(g, origin=graph.origin, voxel_size=graph.voxel_size,
                        radius=graph.radius)


def _unit(vector):
    norm = np.linalg.norm(vector)
    return vector / norm if norm > 0 else np.zeros_like(vector)


# -- junctions and their branches ----------------------------------------------------------------

class _Branch:
    """One segment end at a junction, its centreline walking away from the junction."""

    def __init__(self, index, edge, side, chain, other, context):
        self.index, self.edge, self.side, self.other = index, edge, side, other
        self.chain = np.asarray(chain, dtype=float)
        self.arc = _arc(self.chain)
        self.length = float(self.arc[-1]) if len(self.arc) else 0.0
        self.anchor = self.tangent = None
        self.height = 0.0
        self.reach = self.length if other is None else 0.5 * self.length
        self.spur = False

    def place(self, centre, distance, context):
        """Branch point at horizontal ``distance`` from the centre (within reach), its tangent
        and height."""
        r = context.r
        if len(self.chain) < 2:
            self.anchor = self.chain[0] if len(self.chain) else centre.copy()
            self.tangent = np.zeros(3)
            self.anchor_arc = 0.0
            self.height = float((self.anchor - centre) @ context.up)
            return
        dist = np.linalg.norm(context.flat(self.chain - centre), axis=1)
        beyond = np.flatnonzero(dist >= distance)
        s = self.arc[beyond[0]] if len(beyond) else self.arc[-1]
        s = min(s, self.reach)
        self.anchor_arc = float(s)
        self.anchor = _at_arc(self.chain, self.arc, s)
        ahead = _at_arc(self.chain, self.arc, min(s + 1.5 * r, self.reach if self.other is not None
                                                 else self.length))
        behind = _at_arc(self.chain, self.arc, max(s - 1.0 * r, 0.0))
        tangent = ahead - behind
        if np.linalg.norm(tangent) < 1e-12:
            tangent = self.anchor - centre
        self.tangent = tangent / max(np.linalg.norm(tangent), 1e-12)
        window = context.settings.height_window * r
        near = (self.arc >= max(s - window, 0.0)) & (self.arc <= min(s + window, self.reach))
        heights = (self.chain[near] if near.any() else self.anchor[None]) @ context.up
        self.height = float(np.mean(heights) - centre @ context.up)


class _Junction:
    """A junction, its branches, hypotheses and the evidence about them."""

    def __init__(self, node, centre, branches):
        self.node, self.centre, self.branches = node, centre, branches
        self.hypotheses = []       # (matching index, over/under order of each crossing pair)
        self.matchings = []        # distinct matchings, each (pairs, unpaired, crossing pairs)
        self.view_costs = []       # (view index, weight, {branch pair: path cost})
        self.scores = None
        self.greedy = False
        self.bend = {}

    @classmethod
    def build(cls, node, data, context, warnings):
        g = context.graph.graph
        centre = np.asarray(data["position"], dtype=float)
        branches = []
        for u, v, key, edge in sorted(g.edges(node, keys=True, data=True),
                                      key=lambda e: (min(e[0], e[1]), max(e[0], e[1]), e[2])):
            start, end = edge["start"], edge["end"]
            points = np.asarray(edge["points"], dtype=float)
            for side in ("start", "end"):
                if (start if side == "start" else end) != node:
                    continue
                chain = points if side == "start" else points[::-1]
                far = end if side == "start" else start
                other = far if g.nodes[far]["kind"] == "junction" else None
                branches.append(_Branch(len(branches), (start, end, key), side, chain, other,
                                        context))
        junction = cls(node, centre, branches)
        if (len(branches) % 2 and len(branches) >= 3) or len(branches) >= 5:
            for branch in branches:
                branch.spur = (branch.other is None and branch.edge[0] != branch.edge[1]
                               and g.nodes[branch.edge[1] if branch.side == "start"
                                           else branch.edge[0]]["kind"] == "end"
                               and branch.length < context.settings.spur_length * context.r)
        junction._place(context)
        degree = len(branches)
        if degree == 2:
            warnings.append(f"junction {node} has only 2 branches: passed straight through")
        elif degree == 3:
            warnings.append(f"junction {node} has 3 branches (a cable end touching the cable, "
                            "a spur, or a missed branch): the straightest two are joined, the "
                            "third ends there")
        elif degree > 4:
            warnings.append(f"junction {node} has {degree} branches: several crossings merged "
                            "into one")
        elif degree < 2:
            warnings.append(f"junction {node} has {degree} branch(es): left as an end")
        return junction

    def _place(self, context):
        """Branch points: beyond the zone where the strands overlap, at most max distance."""
        r, s = context.r, context.settings
        preliminary = []
        for branch in self.branches:
            point = (_at_arc(branch.chain, branch.arc, min(4.0 * r, branch.reach))
                     if len(branch.chain) > 1 else self.centre)
            preliminary.append(context.flat(point - self.centre))
        kept = [p for p, b in zip(preliminary, self.branches) if not b.spur]
        angles = np.sort([math.atan2(p[1], p[0]) for p in kept])
        distance = s.anchor_distance
        if len(angles) >= 3:
            gaps = np.diff(np.append(angles, angles[0] + 2 * math.pi))
            theta = float(np.clip(gaps.min(), math.radians(10), math.radians(90)))
            overlap = 1.0 / math.sin(theta) + 1.0 / math.tan(theta)
            distance = max(distance, overlap + s.anchor_margin)
        self.anchor_distance = min(distance, s.max_anchor_distance) * r
        for branch in self.branches:
            branch.place(self.centre, self.anchor_distance, context)

    # -- hypotheses ----------------------------------------------------------------------------
    def enumerate_hypotheses(self, context, warnings):
        degree = len(self.branches)
        if degree < 2:
            matchings = [((), tuple(range(degree)))]
        elif degree > context.settings.max_degree:
            matchings = [self._greedy_matching(context)]
            self.greedy = True
            warnings.append(f"junction {self.node} has {degree} branches (more than "
                            f"{context.settings.max_degree}): paired greedily by bending")
        else:
            spurs = tuple(b.index for b in self.branches if b.spur)
            matchings = list(_matchings(tuple(range(degree)), spurs))
        angles = [math.atan2(*context.flat(b.anchor - self.centre)[::-1]) for b in self.branches]
        for pairs, unpaired in matchings:
            crossing = tuple((a, b) for a, b in itertools.combinations(range(len(pairs)), 2)
                             if _interleaved(pairs[a], pairs[b], angles))
            index = len(self.matchings)
            self.matchings.append((pairs, unpaired, crossing))
            for orders in itertools.product((True, False), repeat=len(crossing)):
                self.hypotheses.append((index, orders))
        for pairs, _, _ in self.matchings:
            for pair in pairs:
                if pair not in self.bend:
                    self.bend[pair] = _bending_energy(self.branches[pair[0]],
                                                      self.branches[pair[1]], context)

    def _greedy_matching(self, context):
        degree = len(self.branches)
        energies = sorted((_bending_energy(self.branches[i], self.branches[j], context), i, j)
                          for i, j in itertools.combinations(range(degree), 2))
        used, pairs = set(), []
        for _, i, j in energies:
            if i not in used and j not in used:
                pairs.append((i, j))
                used.update((i, j))
        return tuple(sorted(pairs)), tuple(k for k in range(degree) if k not in used)

    def score(self, context):
        """Log-scores of the hypotheses and the per-crossing cue values behind them."""
        s = context.settings
        self.cue_values = {}
        scores = []
        for matching_index, orders in self.hypotheses:
            pairs, unpaired, crossing = self.matchings[matching_index]
            total = -sum(self.bend[pair] for pair in pairs) / (2.0 * s.bend_scale ** 2)
            spurs = sum(self.branches[k].spur for k in unpaired)
            total += s.unpaired_cost * (2 * spurs - len(unpaired))
            for (a, b), first_over in zip(crossing, orders):
                over, under = (pairs[a], pairs[b]) if first_over else (pairs[b], pairs[a])
                total += _combine(*self.crossing_cues(over, under, context)[:2])
            scores.append(total)
        self.scores = np.array(scores, dtype=float)
        if len(self.scores):
            self.log_p = self.scores - _logsumexp(self.scores)
        else:
            self.log_p = np.zeros(0)
        self.matching_log_p = np.array([
            _logsumexp(self.log_p[[k for k, h in enumerate(self.hypotheses) if h[0] == m]])
            for m in range(len(self.matchings))])

    def crossing_cues(self, over, under, context):
        """(height log-odds, image log-odds, view votes) that strand ``over`` is over ``under``.

        Each log-odds is half the log-ratio of this order against the flipped one.
        """
        key = (over, under)
        if key in self.cue_values:
            return self.cue_values[key]
        s = context.settings
        h_over = np.mean([self.branches[k].height for k in over])
        h_under = np.mean([self.branches[k].height for k in under])
        height = float(np.clip((h_over - h_under) / (s.height_scale * context.r),
                               -s.height_cap, s.height_cap))
        votes = []
        for view, weight, costs in self.view_costs:
            c_over, c_under = costs[over], costs[under]
            if not (np.isfinite(c_over) and np.isfinite(c_under)):
                continue
            votes.append((view, weight, float((c_under - c_over) / (c_under + c_over + 1e-9))))
        image = _image_log_odds(votes, s)
        self.cue_values[key] = (height, image, tuple(votes))
        return self.cue_values[key]


def _combine(height, image):
    """The two cues' log-odds together; when they disagree the weaker one counts twice (and
    the sum stops at zero).

    Each cue is capped, which bounds how far one can be trusted; when they point opposite
    ways one of them is wrong for a reason of its own (a shadow, a carving artefact), so the
    agreement left is discounted further.
    """
    total = height + image
    if height * image < 0:
        total = math.copysign(max(abs(total) - min(abs(height), abs(image)), 0.0), total)
    return total


def _matchings(items, optional=()):
    """Every way of pairing ``items``, leaving out any of ``optional`` and, when the number left
    is odd, one more.

    Yields ``(pairs, unpaired)`` with both sorted, each once.
    """
    items = tuple(items)
    seen = set()
    for size in range(len(optional) + 1):
        for left_out in itertools.combinations(optional, size):
            rest = tuple(k for k in items if k not in left_out)
            choices = [((), rest)] if len(rest) % 2 == 0 else \
                [((k,), rest[:i] + rest[i + 1:]) for i, k in enumerate(rest)]
            for extra, paired in choices:
                unpaired = tuple(sorted(left_out + extra))
                for pairs in _perfect(paired):
                    key = (tuple(sorted(pairs)), unpaired)
                    if key not in seen:
                        seen.add(key)
                        yield key


def _perfect(items):
    if not items:
        yield []
        return
    first = items[0]
    for k in range(1, len(items)):
        rest = items[1:k] + items[k + 1:]
        for pairs in _perfect(rest):
            yield [(first, items[k])] + pairs


def _interleaved(pair_a, pair_b, angles):
    """Whether two strands cross in the horizontal plane: their branches alternate around it."""
    a0, a1 = angles[pair_a[0]], angles[pair_a[1]]
    span = (a1 - a0) % (2 * math.pi)
    inside = [0.0 < (angles[k] - a0) % (2 * math.pi) < span for k in pair_b]
    return inside[0] != inside[1]


def _bending_energy(first, second, context, samples=48):
    """Dimensionless bending energy of a smooth curve from one branch point to the other.

    A cubic Hermite curve leaves ``first``'s branch point against its (outward) tangent and
    reaches ``second``'s along its tangent; ``L * integral(kappa**2 ds)``, the squared turning
    angle for a circular arc. Heights are scaled by ``vertical_weight`` first.
    """
    scale = np.eye(3) + (context.settings.vertical_weight - 1.0) * np.outer(context.up,
                                                                            context.up)
    p0, p1 = scale @ first.anchor, scale @ second.anchor
    t0, t1 = -(scale @ first.tangent), scale @ second.tangent
    chord = np.linalg.norm(p1 - p0)
    n0, n1 = np.linalg.norm(t0), np.linalg.norm(t1)
    if chord < 1e-12 or n0 < 1e-9 or n1 < 1e-9:
        return float(math.pi ** 2)
    curve, d1, d2 = _hermite(p0, t0 / n0 * chord, p1, t1 / n1 * chord, samples)
    speed = np.linalg.norm(d1, axis=1)
    kappa = np.linalg.norm(np.cross(d1, d2), axis=1) / np.maximum(speed ** 3, 1e-30)
    ds = speed / (samples - 1)
    length = float(np.sum(ds))
    return float(length * np.sum(kappa ** 2 * ds))


def _hermite(p0, m0, p1, m1, samples):
    """Points, first and second derivatives of a cubic Hermite curve at ``samples`` t in [0, 1]."""
    t = np.linspace(0.0, 1.0, samples)[:, None]
    h00, h10, h01, h11 = 2 * t**3 - 3 * t**2 + 1, t**3 - 2 * t**2 + t, -2 * t**3 + 3 * t**2, \
        t**3 - t**2
    points = h00 * p0 + h10 * m0 + h01 * p1 + h11 * m1
    d1 = (6 * t**2 - 6 * t) * p0 + (3 * t**2 - 4 * t + 1) * m0 + (-6 * t**2 + 6 * t) * p1 \
        + (3 * t**2 - 2 * t) * m1
    d2 = (12 * t - 6) * p0 + (6 * t - 4) * m0 + (-12 * t + 6) * p1 + (6 * t - 2) * m1
    return points, d1, d2


def _logsumexp(values):
    values = np.asarray(values, dtype=float)
    if len(values) == 0:
        return -np.inf
    top = values.max()
    return float(top + np.log(np.sum(np.exp(values - top))))


def _image_log_odds(votes, settings):
    """Log-odds from view scores: ``image_gain`` times a weighted t statistic, capped.

    The statistic is the weighted mean score over its standard error (the weighted standard
    deviation, at least ``image_spread``, over the square root of the views' effective
    number): views that agree count, views that disagree cancel. It shrinks by
    ``n / (n + image_prior_views)`` for ``n`` effective views: a view or two that happen to
    agree are not taken as certain.
    """
    if not votes:
        return 0.0
    weights = np.array([w for _, w, _ in votes])
    scores = np.array([s for _, _, s in votes])
    total = weights.sum()
    if total <= 0:
        return 0.0
    mean = float(weights @ scores / total)
    spread = math.sqrt(float(weights @ (scores - mean) ** 2) / total)
    effective = total ** 2 / float(weights @ weights)
    statistic = mean / max(spread, settings.image_spread) * math.sqrt(effective)
    statistic *= effective / (effective + settings.image_prior_views)
    return float(np.clip(settings.image_gain * statistic, -settings.image_cap,
                         settings.image_cap))


# -- image cue ------------------------------------------------------------------------------------

def _image_cue(junctions, views, context, report, cancel):
    """Fill each junction's ``view_costs``: shortest-path costs between its branch points."""
    r, s = context.r, context.settings
    usable = [j for j in junctions if len(j.branches) >= 3 and not j.greedy]
    if not usable or not views:
        return
    # Points of the whole cable (about one per radius), to find views where it hides a junction.
    cable = []
    for _, _, data in context.graph.graph.edges(data=True):
        points = np.asarray(data["points"], dtype=float)
        step = max(int(round(r / max(context.spacing, 1e-12))), 1)
        cable.append(points[::step])
    cable = np.vstack(cable) if cable else np.zeros((0, 3))
    local = [np.linalg.norm(cable - j.centre, axis=1) <= j.anchor_distance + 3.0 * r
             for j in usable]
    for index, view in enumerate(views):
        check_cancel(cancel, "resolving the topology")
        report(index / len(views), "reading the images at the junctions")
        camera = view.camera
        mask = image = junction_mask = None
        cable_px, cable_depth = camera.project(cable)
        for junction, near in zip(usable, local):
            points = np.vstack([junction.centre] + [b.anchor for b in junction.branches])
            pixels, depth = camera.project(points)
            if not np.all(depth > 0) or not np.all(np.isfinite(pixels)):
                continue
            r_px = camera.focal[0] * r / depth[0]
            if r_px < s.min_pixel_radius:
                continue
            pad = 2.0 * r_px + 3.0
            if (pixels[:, 0].min() < pad or pixels[:, 1].min() < pad
                    or pixels[:, 0].max() > camera.width - pad
                    or pixels[:, 1].max() > camera.height - pad):
                continue
            weight = _view_weight(camera, junction, pixels, r_px, context)
            if weight <= 0:
                continue
            if _occluded(pixels, depth[0], cable_px[~near], cable_depth[~near], r_px, r, camera,
                         s):
                continue
            if mask is None:
                mask = _load(view.mask, bool)
                image = _load(view.image)
                junction_mask = _load(view.junctions, bool) if view.junctions is not None \
                    else None
                if image is None or mask is None:
                    raise ValueError(f"views[{index}]: no image or no mask")
                if mask.shape != image.shape[:2]:
                    raise ValueError(f"views[{index}]: the image is {image.shape[1::-1]}, its "
                                     f"mask {mask.shape[::-1]}")
            if junction_mask is not None and not _near_junction_pixel(junction_mask, pixels[0],
                                                                      2.0 * r_px):
                weight *= 0.5
            costs = _path_costs(image, mask, pixels[1:], r_px, s)
            if costs is not None:
                junction.view_costs.append((index, weight, costs))
    report(1.0, "reading the images at the junctions")


def _view_weight(camera, junction, pixels, r_px, context):
    """How much a view can say about a junction: top-down, strands apart, cable large enough."""
    s = context.settings
    towards = camera.center - junction.centre
    cosine = float(towards @ context.up / max(np.linalg.norm(towards), 1e-12))
    if cosine <= 0:
        return 0.0
    top = cosine ** s.top_down_power
    # The largest sine of the angle between two projected chords through the junction.
    chords = pixels[1:] - pixels[0]
    norms = np.linalg.norm(chords, axis=1)
    if np.any(norms < 1e-9):
        return 0.0
    units = chords / norms[:, None]
    sines = np.abs(units[:, None, 0] * units[None, :, 1] - units[:, None, 1] * units[None, :, 0])
    angle = float(np.sort(sines.ravel())[-1]) if sines.size else 0.0
    size = float(np.clip((r_px - s.min_pixel_radius) / 2.0, 0.0, 1.0))
    return top * angle * size


def _occluded(pixels, depth, other_px, other_depth, r_px, r_world, camera, settings):
    """Another part of the cable, in front, projects onto the strands' paths."""
    if len(other_px) == 0:
        return False
    ahead = np.isfinite(other_px[:, 0]) & (other_depth > 0) & (other_depth < depth - r_world)
    if not ahead.any():
        return False
    candidates = other_px[ahead]
    reach = (settings.occluder_margin + 1.0) * r_px
    centre = pixels[0]
    for end in pixels[1:]:
        d = end - centre
        t = np.clip((candidates - centre) @ d / max(d @ d, 1e-12), 0.0, 1.0)
        if np.any(np.linalg.norm(candidates - centre - t[:, None] * d, axis=1) < reach):
            return True
    return False


def _near_junction_pixel(junction_mask, pixel, reach):
    x, y = pixel
    rows = slice(max(int(y - reach), 0), int(y + reach) + 1)
    cols = slice(max(int(x - reach), 0), int(x + reach) + 1)
    return bool(junction_mask[rows, cols].any())


def _path_costs(image, mask, anchors, r_px, settings):
    """Shortest-path costs on the image gradient between every two projected branch points.

    Returns a dict ``{(i, j): cost}`` over branch index pairs (i < j), infinite for a branch
    point that finds no cable pixel near it; None when fewer than two find one.
    """
    height, width = mask.shape
    pad = int(math.ceil(2.0 * r_px + 3))
    x0 = max(int(math.floor(anchors[:, 0].min())) - pad, 0)
    x1 = min(int(math.ceil(anchors[:, 0].max())) + pad + 1, width)
    y0 = max(int(math.floor(anchors[:, 1].min())) - pad, 0)
    y1 = min(int(math.ceil(anchors[:, 1].max())) + pad + 1, height)
    if x1 - x0 < 3 or y1 - y0 < 3:
        return None
    patch = np.asarray(image[y0:y1, x0:x1], dtype=np.float32)
    cable = np.asarray(mask[y0:y1, x0:x1], dtype=bool)
    anchors = np.asarray(anchors, dtype=float) - [x0, y0]  # COLMAP coordinates in the patch
    if r_px > settings.path_radius:  # reduced: the cable's radius path_radius pixels
        scale = settings.path_radius / r_px
        size = (max(int(round((x1 - x0) * scale)), 3), max(int(round((y1 - y0) * scale)), 3))
        patch = cv2.resize(patch, size, interpolation=cv2.INTER_AREA)
        cable = cv2.resize(cable.view(np.uint8) * np.float32(1.0), size,
                           interpolation=cv2.INTER_AREA) >= 0.5
        anchors = anchors * [size[0] / (x1 - x0), size[1] / (y1 - y0)]
        r_px = settings.path_radius
    if patch.ndim == 2:
        patch = patch[..., None]
    if not cable.any():
        return None
    smooth = cv2.GaussianBlur(patch, (0, 0), 0.7)
    if smooth.ndim == 2:
        smooth = smooth[..., None]
    # Specular highlights are the brightest cable pixels: clipped, they make no edges.
    clip = np.percentile(smooth[cable], 100.0 * settings.highlight_clip, axis=0)
    clipped = np.ascontiguousarray(np.minimum(smooth, clip[None, None, :]), dtype=np.float32)
    gx = cv2.Sobel(clipped, cv2.CV_32F, 1, 0, ksize=3) / 8.0
    gy = cv2.Sobel(clipped, cv2.CV_32F, 0, 1, ksize=3) / 8.0
    if gx.ndim == 2:
        gx, gy = gx[..., None], gy[..., None]
    gradient = np.sqrt(gx ** 2 + gy ** 2).max(axis=2)
    inside = cv2.dilate(cable.view(np.uint8), np.ones((3, 3), np.uint8)) > 0
    cost = settings.edge_floor + 1e-3 + gradient ** 2 / settings.edge_scale
    cost[~inside] += 255.0
    value = smooth.max(axis=2)
    sources = {}
    search = max(settings.highlight_search * r_px, 1.5)
    rows, cols = np.indices(cable.shape)
    for k, (x, y) in enumerate(anchors):
        col, row = x - 0.5, y - 0.5
        for reach in (search, 2.0 * search):
            near = ((rows - row) ** 2 + (cols - col) ** 2 <= reach ** 2) & cable
            if near.any():
                flat = np.flatnonzero(near)
                sources[k] = int(flat[np.argmax(value.ravel()[flat])])
                break
    if len(sources) < 2:
        return None
    found = sorted(sources)
    distances = _dijkstra(cost, [sources[k] for k in found])
    costs = {}
    for i, j in itertools.combinations(range(len(anchors)), 2):
        costs[(i, j)] = (float(distances[found.index(i), sources[j]])
                         if i in sources and j in sources else math.inf)
    return costs


def _dijkstra(cost, sources):
    """Path costs (mean of the two pixels' costs times the step length) from ``sources``."""
    h, w = cost.shape
    index = np.arange(h * w).reshape(h, w)
    rows, cols, weights = [], [], []
    for dr, dc in ((0, 1), (1, 0), (1, 1), (1, -1)):
        first, last = max(-dc, 0), w - max(dc, 0)
        a = index[0:h - dr, first:last]
        b = index[dr:h, first + dc:last + dc]
        step = math.hypot(dr, dc)
        rows.append(a.ravel())
        cols.append(b.ravel())
        weights.append(0.5 * (cost.ravel()[a.ravel()] + cost.ravel()[b.ravel()]) * step)
    graph = sparse.csr_matrix((np.concatenate(weights), (np.concatenate(rows),
                                                        np.concatenate(cols))), shape=(h * w,) * 2)
    return csgraph.dijkstra(graph, directed=False, indices=sources)


# -- one path per cable ---------------------------------------------------------------------------

def _slot_of(branch):
    """The segment end a branch is: ``(edge, side)``."""
    return branch.edge, branch.side


class _Pieces:
    """How many pieces the chosen matchings make of one connected component, fast enough for
    the one-path search to try thousands of combinations.

    A segment's two ends always belong to one piece, so the pieces are the segments joined by
    the matchings' pairs: each junction's matchings are turned once into pairs of segment
    indices, and each combination is a small union-find over the segments.
    """

    def __init__(self, edges, ends, junctions):
        index = {edge: k for k, edge in enumerate(edges)}
        self.count, self.ends = len(edges), ends
        self.links, self.unpaired, self.spurs = [], [], []
        for junction in junctions:
            links, unpaired, spurs = [], [], []
            for matching in junction.ranked:
                pairs, left, _ = junction.matchings[matching]
                links.append([(index[junction.branches[i].edge], index[junction.branches[j].edge])
                              for i, j in pairs])
                unpaired.append(len(left))
                spurs.append(sum(junction.branches[k].spur for k in left))
            self.links.append(links)
            self.unpaired.append(unpaired)
            self.spurs.append(spurs)

    def __call__(self, ranks):
        """``(pieces, fewest)`` for a combination (each junction's rank): spurs left unpaired
        are not counted (they are dropped); the fewest is one, or half the open ends (free
        ends and unpaired branches) when there are more than two."""
        parent = list(range(self.count))

        def root(k):
            while parent[k] != k:
                parent[k] = parent[parent[k]]
                k = parent[k]
            return k

        pieces, open_ends, spurs = self.count, self.ends, 0
        for links, unpaired, spur, rank in zip(self.links, self.unpaired, self.spurs, ranks):
            for a, b in links[rank]:
                a, b = root(a), root(b)
                if a != b:
                    parent[a] = b
                    pieces -= 1
            open_ends += unpaired[rank]
            spurs += spur[rank]
        return pieces - spurs, max(1, (open_ends - 2 * spurs) // 2)


def _one_path_per_cable(junctions, context, warnings):
    """Matchings that make each connected piece of the graph one path, and their probabilities.

    Returns ``choice`` (junction node -> matching index) and ``marginals`` (junction node ->
    probability of that matching given the one-path constraint).
    """
    g = context.graph.graph
    by_node = {j.node: j for j in junctions}
    for junction in junctions:
        junction.ranked = list(np.argsort(-junction.matching_log_p, kind="stable"))
    choice, marginals = {}, {}
    budget, window = context.settings.search_budget, context.settings.search_window
    for component in _components(g):
        edges = [(d["start"], d["end"], k) for u, v, k, d in g.subgraph(component).edges(
            keys=True, data=True)]
        members = [by_node[n] for n in sorted(component) if n in by_node]
        ends = sum(1 for n in component if g.nodes[n]["kind"] == "end")
        if not members:
            continue
        logs = [[float(v) for v in j.matching_log_p[j.ranked]] for j in members]
        count_pieces = _Pieces(edges, ends, members)

        def total(ranks):
            return float(sum(log[k] for log, k in zip(logs, ranks)))

        def valid(ranks):
            pieces, fewest = count_pieces(ranks)
            return pieces <= fewest

        start = tuple(0 for _ in members)
        heap = [(-total(start), start)]
        seen = {start}
        found = []
        tried = 0
        while heap and tried < budget:
            negative, ranks = heapq.heappop(heap)
            tried += 1
            if found and -negative < found[0][0] - window:
                break
            if valid(ranks):
                found.append((-negative, ranks))
            for k in range(len(members)):
                if ranks[k] + 1 < len(logs[k]) and math.isfinite(logs[k][ranks[k] + 1]):
                    step = ranks[:k] + (ranks[k] + 1,) + ranks[k + 1:]
                    if step not in seen:
                        seen.add(step)  # one rank down at one junction: its score moves
                        heapq.heappush(heap, (negative + logs[k][ranks[k]]
                                              - logs[k][ranks[k] + 1], step))
        if not found:
            pieces, fewest = count_pieces(start)
            warnings.append(
                f"no pairing at junction(s) {', '.join(str(j.node) for j in members)} "
                f"(of {tried} tried) joins their cable into {fewest} path(s): kept as "
                f"{pieces}")
            found = [(total(start), start)]
        best = found[0][1]
        if best != start:
            changed = [str(j.node) for j, k in zip(members, best) if k != 0]
            warnings.append(f"the most likely pairings split a cable into several pieces; "
                            f"changed the pairing at junction(s) {', '.join(changed)} to make "
                            "one path")
        weights = np.array([score for score, _ in found])
        weights = np.exp(weights - weights.max())
        weights /= weights.sum()
        for k, junction in enumerate(members):
            chosen = best[k]
            choice[junction.node] = junction.ranked[chosen]
            marginals[junction.node] = float(sum(w for w, (_, ranks) in zip(weights, found)
                                                 if ranks[k] == chosen))
    return choice, marginals


def _components(g):
    return [set(c) for c in nx.connected_components(g)]


# -- assembling the paths -------------------------------------------------------------------------

def _assemble(junctions, choice, marginals, context, warnings):
    g = context.graph.graph
    r, s = context.r, context.settings
    branch_of = {}        # slot -> (junction, branch index)
    partner = {}          # slot -> slot it continues into at a junction
    spurs = {}            # edge of an unpaired spur -> its junction
    for junction in junctions:
        for branch in junction.branches:
            branch_of[_slot_of(branch)] = (junction, branch.index)
        if junction.node not in choice:
            continue
        pairs, unpaired, _ = junction.matchings[choice[junction.node]]
        for k in unpaired:
            if junction.branches[k].spur:
                spurs[junction.branches[k].edge] = junction
        for i, j in pairs:
            a, b = _slot_of(junction.branches[i]), _slot_of(junction.branches[j])
            partner[a], partner[b] = b, a
    edges = {(d["start"], d["end"], k): d for _, _, k, d in g.edges(keys=True, data=True)}

    def other(slot):
        return slot[0], "end" if slot[1] == "start" else "start"

    def walk(first):
        """Legs ``(edge, forward)`` from the slot ``first`` on; closed if back at it."""
        legs, slot = [], first
        while True:
            legs.append((slot[0], slot[1] == "start"))
            arrival = other(slot)
            if arrival in partner:
                slot = partner[arrival]
                if slot == first:
                    return legs, True
                continue
            if g.nodes[arrival[0][0 if arrival[1] == "start" else 1]]["kind"] == "closure":
                return legs, True
            return legs, False

    pieces, used = [], set()
    starts = []
    for slot in sorted(((e, side) for e in edges for side in ("start", "end")), key=str):
        node = slot[0][0 if slot[1] == "start" else 1]
        kind = g.nodes[node]["kind"]
        if kind == "end" or (kind == "junction" and slot not in partner):
            starts.append(slot)
    for slot in starts:
        if slot[0] in used:
            continue
        legs, closed = walk(slot)
        used.update(edge for edge, _ in legs)
        pieces.append((legs, closed))
    for edge in sorted(edges, key=str):
        if edge in used:
            continue
        legs, closed = walk((edge, "start"))
        used.update(e for e, _ in legs)
        pieces.append((legs, closed))

    paths, bridges = [], {}
    for legs, closed in pieces:
        if len(legs) == 1 and not closed and legs[0][0] in spurs:
            warnings.append(f"dropped a spur of {edges[legs[0][0]]['length'] / r:.1f} r at "
                            f"junction {spurs[legs[0][0]].node} (carving noise, or a stub of "
                            "cable too short to tell)")
            continue
        points, spans = _piece_points(legs, closed, edges, branch_of, partner, context)
        if len(points) < 2:
            warnings.append(f"a piece of cable along {len(legs)} segment(s) was too short to "
                            "keep")
            continue
        number = len(paths)
        paths.append([points, closed, tuple(edge for edge, _ in legs)])
        for key, span in spans.items():
            bridges[key] = (number, span)
    if not paths:
        raise ReconstructionError("no path could be formed from the segment graph")
    paths, bridges = _drop_specks(paths, bridges, context, warnings)

    crossings = _place_crossings(junctions, choice, marginals, bridges, paths, context)
    for _ in range(2):  # bumps of nearby crossings overlap: settle them twice
        for crossing in crossings:
            _separate(paths, crossing, context)
    result = []
    for crossing in crossings:
        (op, oi), (upath, ui) = crossing["over"], crossing["under"]
        position = 0.5 * (paths[op][0][oi] + paths[upath][0][ui])
        result.append(TopologyCrossing(position, (op, oi), (upath, ui),
                                       float(np.clip(crossing["confidence"], 0.0, 1.0)),
                                       crossing["junction"], crossing["cues"],
                                       crossing["views"]))
    for k, crossing in enumerate(result):
        if crossing.confidence < s.confident:
            cues = crossing.cues
            warnings.append(
                f"crossing {k} (junction {crossing.junction}) is ambiguous: confidence "
                f"{crossing.confidence:.2f} (heights {cues.get('height', 0.0):+.1f}, images "
                f"{cues.get('image', 0.0):+.1f} from {cues.get('views', 0)} view(s), pairing "
                f"{cues.get('pairing', 0.0):.2f}); flip it if the result looks wrong")
    topology_paths = tuple(TopologyPath(p, bool(c), e) for p, c, e in paths)
    return Topology(topology_paths, tuple(result), tuple(warnings), context.up.copy(),
                    s.lift_width * r)


def _drop_specks(paths, bridges, context, warnings):
    """Paths shorter than ``min_path_length`` left out (unless all are); bridges renumbered."""
    limit = context.settings.min_path_length * context.r
    lengths = [float(_arc(np.vstack([p, p[:1]]) if closed else p)[-1]) for p, closed, _ in paths]
    keep = [k for k, length in enumerate(lengths) if length >= limit]
    if not keep or len(keep) == len(paths):
        return paths, bridges
    for k, length in enumerate(lengths):
        if k not in keep:
            warnings.append(f"dropped a piece of cable {length / context.r:.1f} r long (a speck "
                            "of carving noise)")
    number = {old: new for new, old in enumerate(keep)}
    bridges = {key: (number[p], span) for key, (p, span) in bridges.items() if p in number}
    return [paths[k] for k in keep], bridges


def _piece_points(legs, closed, edges, branch_of, partner, context):
    """Points of a piece: legs cut near junctions and joined by smooth bridges.

    Returns the points and, per bridge, ``(junction node, strand) -> (first, last)`` indices of
    the bridge (from the last point of one leg to the first of the next).
    """
    r, s = context.r, context.settings
    g = context.graph.graph
    cut = s.bridge_distance * r
    trimmed = []
    for edge, forward in legs:
        data = edges[edge]
        points = np.asarray(data["points"], dtype=float)
        points = points if forward else points[::-1]
        if data["closed"]:
            trimmed.append(points)
            continue
        first_slot = (edge, "start" if forward else "end")
        last_slot = (edge, "end" if forward else "start")
        head = first_slot in branch_of
        tail = last_slot in branch_of
        trimmed.append(_trim(points, head, tail, cut, g, context))
    chunks, spans = [], {}
    count = 0
    for k, points in enumerate(trimmed):
        chunks.append(points)
        count += len(points)
        nxt = k + 1
        if nxt == len(trimmed):
            if not closed or len(legs) == 1 and edges[legs[0][0]]["closed"]:
                break
            nxt = 0
        edge, forward = legs[k]
        arrival = (edge, "end" if forward else "start")
        if arrival not in partner:
            break
        bridge = _bridge(points, trimmed[nxt], context)
        junction, i = branch_of[arrival]
        _, j = branch_of[partner[arrival]]
        first = count - 1
        chunks.append(bridge)
        count += len(bridge)
        last = 0 if nxt == 0 else count
        spans[(junction.node, tuple(sorted((i, j))))] = (first, last)
    points = np.vstack(chunks) if chunks else np.zeros((0, 3))
    return points, spans


def _trim(points, head, tail, cut, g, context):
    """Drop the parts of a leg within ``cut`` of the junctions at its ends."""
    arc = _arc(points)
    if len(points) < 2:
        return points
    length = arc[-1]
    limit = (0.45 if head and tail else 0.9) * length
    low, high = 0.0, length
    if head:
        dist = np.linalg.norm(context.flat(points - points[0]), axis=1)
        beyond = np.flatnonzero(dist >= cut)
        low = min(arc[beyond[0]] if len(beyond) else length, limit)
    if tail:
        dist = np.linalg.norm(context.flat(points - points[-1]), axis=1)
        beyond = np.flatnonzero(dist >= cut)
        high = max(arc[beyond[-1]] if len(beyond) else 0.0, length - limit)
    keep = (arc >= low) & (arc <= high)
    if keep.sum() < 2:
        middle = 0.5 * (low + high)
        return np.vstack([_at_arc(points, arc, middle - 1e-3 * length),
                          _at_arc(points, arc, middle + 1e-3 * length)])
    inner = points[keep]
    ends = [_at_arc(points, arc, low)[None]] if arc[keep][0] > low + 1e-12 else []
    tail_end = [_at_arc(points, arc, high)[None]] if arc[keep][-1] < high - 1e-12 else []
    return np.vstack(ends + [inner] + tail_end)


def _end_tangent(points, context, at_start):
    """Unit direction of travel at one end of a polyline (over about 1.5 r)."""
    arc = _arc(points)
    span = min(1.5 * context.r, arc[-1]) if len(arc) else 0.0
    if len(points) < 2 or span <= 0:
        return np.zeros(3)
    if at_start:
        d = _at_arc(points, arc, span) - points[0]
    else:
        d = points[-1] - _at_arc(points, arc, arc[-1] - span)
    return d / max(np.linalg.norm(d), 1e-12)


def _bridge(incoming, outgoing, context):
    """Interior points of a smooth curve from the end of ``incoming`` to the start of
    ``outgoing``."""
    p0, p1 = incoming[-1], outgoing[0]
    chord = float(np.linalg.norm(p1 - p0))
    if chord < 1e-12:
        return np.zeros((0, 3))
    t0, t1 = _end_tangent(incoming, context, False), _end_tangent(outgoing, context, True)
    count = max(int(math.ceil(1.2 * chord / max(context.spacing, 1e-12))), 2) + 1
    curve, _, _ = _hermite(p0, t0 * chord, p1, t1 * chord, count)
    return curve[1:-1]


def _place_crossings(junctions, choice, marginals, bridges, paths, context):
    """Crossings at the chosen matchings: where the bridges of two strands pass each other."""
    crossings = []
    for junction in junctions:
        if junction.node not in choice:
            continue
        m = choice[junction.node]
        pairs, _, crossing_pairs = junction.matchings[m]
        members = [k for k, h in enumerate(junction.hypotheses) if h[0] == m]
        if not crossing_pairs or not members:
            continue
        log_p = junction.log_p[members]
        best = members[int(np.argmax(log_p))]
        orders = junction.hypotheses[best][1]
        within = np.exp(log_p - _logsumexp(log_p))
        matching_p = marginals.get(junction.node, 1.0)
        others = np.delete(junction.matching_log_p, m)
        margin = float(junction.matching_log_p[m] - (others.max() if len(others) else -np.inf))
        for c, ((a, b), first_over) in enumerate(zip(crossing_pairs, orders)):
            over, under = (pairs[a], pairs[b]) if first_over else (pairs[b], pairs[a])
            if (junction.node, over) not in bridges or (junction.node, under) not in bridges:
                continue
            same = sum(w for w, k in zip(within, members) if junction.hypotheses[k][1][c]
                       == first_over)
            confidence = matching_p * same
            height, image, votes = junction.crossing_cues(over, under, context)
            o_path, o_span = bridges[(junction.node, over)]
            u_path, u_span = bridges[(junction.node, under)]
            oi, ui = _closest_pass(paths[o_path][0], o_span, paths[u_path][0], u_span, context)
            crossings.append(dict(
                over=(o_path, oi), under=(u_path, ui), confidence=confidence,
                junction=junction.node,
                cues={"height": 2.0 * height, "image": 2.0 * image,
                      "pairing": margin if np.isfinite(margin) else 99.0,
                      "pairing_probability": matching_p, "views": len(votes)},
                views=votes))
    return crossings


def _span_indices(span, count):
    first, last = span
    if last >= first:
        return np.arange(first, last + 1) % count
    return np.concatenate([np.arange(first, count), np.arange(0, last + 1)])


def _closest_pass(over_points, over_span, under_points, under_span, context):
    """Indices on two bridges where they pass closest in the horizontal plane."""
    oi = _span_indices(over_span, len(over_points))
    ui = _span_indices(under_span, len(under_points))
    a, b = context.flat(over_points[oi]), context.flat(under_points[ui])
    distance = np.linalg.norm(a[:, None] - b[None], axis=2)
    i, j = np.unravel_index(np.argmin(distance), distance.shape)
    return int(oi[i]), int(ui[j])


def _separate(paths, crossing, context):
    """Lift the over strand and lower the under strand until they are ``separation`` apart."""
    (op, oi), (upath, ui) = crossing["over"], crossing["under"]
    over, under = paths[op][0], paths[upath][0]
    gap = float((over[oi] - under[ui]) @ context.up)
    target = context.settings.separation * context.r
    if gap >= target:
        return
    shift = 0.5 * (target - gap)
    width = context.settings.lift_width * context.r
    _add_bump(over, paths[op][1], oi, shift, width, context.up)
    _add_bump(under, paths[upath][1], ui, -shift, width, context.up)


def _add_bump(points, closed, index, height, width, up):
    """Add ``height`` along ``up`` at ``index``, fading (cos²) to 0 at ``width``.

    Distances are arc lengths of the horizontal projection, which the bump does not change
    (so a bump can be undone exactly).
    """
    if len(points) < 2:
        points[index] += height * up
        return
    flat = points - np.outer(points @ up, up)
    arc = _arc(np.vstack([flat, flat[:1]]) if closed else flat)
    total = arc[-1]
    arc = arc[:len(points)]
    offset = arc - arc[index]
    if closed and total > 0:
        offset = (offset + 0.5 * total) % total - 0.5 * total
    x = np.clip(np.abs(offset) / width, 0.0, 1.0)
    points += (height * np.cos(0.5 * np.pi * x) ** 2)[:, None] * up
"""The topology stage's entry: the graph made ready, every junction decided, one path per cable,
the paths assembled."""

import logging
import math

import numpy as np

from ...errors import ReconstructionError
from ...progress import StageProgress, check_cancel
from .assembly import assemble
from .context import Context, as_view, close_gaps, double_bigons
from .image_cue import image_cue
from .junctions import Junction
from .one_path import one_path_per_cable
from .settings import TopologySettings

__all__ = ["resolve_topology"]

log = logging.getLogger(__name__)


def resolve_topology(graph, views, *, radius, up, settings=TopologySettings(), progress=None,
                     cancel=None, workers=1):
    """Decide over/under at every junction and join the segments into one path per cable.

    Parameters
    ----------
    graph : SegmentGraph
        Junctions, free ends and segments
        (:func:`engine.stages.segment_graph.extract_segment_graph`).
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
    workers : int, optional
        Threads reading the views at the junctions (0: one per CPU, at most
        :data:`~engine.threads.MOST_THREADS`); the topology is the same on any number.

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
    views = [as_view(view, k) for k, view in enumerate(views)]
    report = StageProgress(progress)
    check_cancel(cancel, "resolving the topology")
    g = graph.graph
    if g.number_of_edges() == 0:
        raise ReconstructionError("no path could be formed: the segment graph holds no segment")
    warnings = []
    report(0.0, "branches")
    context, junctions = _prepare(graph, float(radius), up, settings, warnings)
    check_cancel(cancel, "resolving the topology")
    image_cue(junctions, views, context, report.part(0.05, 0.8), cancel, workers)
    report(0.8, "hypotheses")
    return _resolve(junctions, context, warnings, report, cancel)


def _prepare(graph, radius, up, settings, warnings):
    """The context (with missed branches bridged) and the junctions with their hypotheses."""
    context = Context(graph, radius, up, settings)
    context = Context(close_gaps(context, warnings), radius, up, settings)
    context = Context(double_bigons(context, warnings), radius, up, settings)
    return context, _junctions(context.graph, context, warnings)


def _junctions(graph, context, warnings):
    """Every junction with its branches and hypotheses (no image evidence yet)."""
    junctions = [Junction.build(node, data, context, warnings)
                 for node, data in sorted(graph.junctions(), key=lambda item: item[0])]
    for junction in junctions:
        junction.enumerate_hypotheses(context, warnings)
    return junctions


def _resolve(junctions, context, warnings, report, cancel):
    """Score the hypotheses, choose one path per cable, build the paths and crossings."""
    for junction in junctions:
        junction.score(context)
    check_cancel(cancel, "resolving the topology")
    choice, marginals = one_path_per_cable(junctions, context, warnings)
    check_cancel(cancel, "resolving the topology")
    report(0.9, "paths")
    topology = assemble(junctions, choice, marginals, context, warnings)
    report(1.0, "done")
    log.debug("topology: %d path(s), %d crossing(s), %d warning(s)", len(topology.paths),
              len(topology.crossings), len(topology.warnings))
    return topology

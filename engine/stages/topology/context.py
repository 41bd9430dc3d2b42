"""The stage's inputs made ready: views loaded, the graph's gaps closed and twists doubled."""

import math

import numpy as np

from ...geometry.polylines import arc_length, unit
from ..segment_graph import SegmentGraph
from .model import TopologyView
from .polylines import end_tangent

__all__ = ["as_view", "load", "Context", "close_gaps", "double_bigons"]


def as_view(view, index):
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


def load(item, dtype=None):
    value = item() if callable(item) else item
    if value is None:
        return None
    return np.asarray(value) if dtype is None else np.asarray(value, dtype=dtype)


class Context:
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


def close_gaps(context, warnings):
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
            heading = end_tangent(points, context, False)
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
        length = float(arc_length(chain)[-1])
        g.add_edge(node, far, points=chain, start=node, end=far, closed=False, length=length,
                   start_direction=unit(chain[min(3, len(chain) - 1)] - chain[0]),
                   end_direction=unit(chain[max(len(chain) - 4, 0)] - chain[-1]),
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


def double_bigons(context, warnings):
    """The graph with a second segment beside each short one joining two junctions that
    each miss a branch (a copy; the input is not changed).

    Two strands that cross twice close together (a twist) lie side by side between the two
    crossings; the carving often gives one segment there, and each crossing then has three
    branches. The missing branch of each is that second strand: the segment is doubled, and
    the topology pairs and orders the strands through both junctions as at any crossing.
    Where several segments join the same two junctions, the highest is doubled: a small loop
    closing at a shallow crossing joins them too, on the table, while the two strands lie one
    over the other along the other segment (hard tuning seed 9: the loop, the shorter, was
    doubled, and the cable came out wrongly joined).
    """
    graph, r, s = context.graph, context.r, context.settings
    if s.bigon_length <= 0:
        return graph
    g = graph.graph
    odd = _odd_junctions(g, r, s)
    # of several segments joining the same two junctions, the highest: two strands that cross
    # at a shallow angle lie one over the other along it (a small loop closing at such a
    # crossing joins the two junctions too, lying on the table)
    highest = {}
    for u, v, key, data in g.edges(keys=True, data=True):
        if u != v and u in odd and v in odd and data["length"] <= s.bigon_length * r:
            height = float(np.mean(np.asarray(data["points"], dtype=float) @ context.up))
            ends = (min(u, v), max(u, v))
            if ends not in highest or height > highest[ends][0]:
                highest[ends] = (height, (data["length"], u, v, key))
    candidates = sorted(candidate for _, candidate in highest.values())
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

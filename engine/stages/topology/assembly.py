"""The paths assembled: segments followed through the chosen matchings, bridged at the
junctions, over and under strands separated, crossings placed."""

import math

import numpy as np

from ...errors import ReconstructionError
from ...geometry.polylines import arc_length
from .junctions import logsumexp
from .model import Topology, TopologyCrossing, TopologyPath
from .one_path import slot_of
from .polylines import add_bump, at_arc, end_tangent, hermite

__all__ = ["assemble"]


def assemble(junctions, choice, marginals, context, warnings):
    """The stage's answer from the chosen matchings: the segments followed through them into
    paths, each crossing placed at its strands' closest pass and the strands moved apart there.

    Parameters
    ----------
    junctions : list of Junction
    choice : dict
        Junction node -> index of its chosen matching.
    marginals : dict
        Junction node -> the probability of each of its matchings.
    context : Context
    warnings : list of str
        Appended to.

    Returns
    -------
    Topology
    """
    branch_of, partner, spurs = _continuations(junctions, choice)
    g = context.graph.graph
    edges = {(d["start"], d["end"], k): d for _, _, k, d in g.edges(keys=True, data=True)}
    pieces = _walk_pieces(g, edges, partner)
    paths, bridges = _piece_paths(pieces, edges, spurs, branch_of, partner, context, warnings)
    ends = _end_crossings(junctions, choice, marginals, bridges, paths, context, warnings)
    crossings = _place_crossings(junctions, choice, marginals, bridges, paths, context) + ends
    for _ in range(2):  # bumps of nearby crossings overlap: settle them twice
        for crossing in crossings:
            _separate(paths, crossing, context)
    result = _listed_crossings(paths, crossings, context, warnings)
    topology_paths = tuple(TopologyPath(p, bool(c), e) for p, c, e in paths)
    return Topology(topology_paths, result, tuple(warnings), context.up.copy(),
                    context.settings.lift_width * context.r)


def _continuations(junctions, choice):
    """Which branch each segment end is (``branch_of``: slot -> (junction, branch index)),
    which slot it continues into at its junction (``partner``), and the unpaired spurs (edge ->
    junction)."""
    branch_of, partner, spurs = {}, {}, {}
    for junction in junctions:
        for branch in junction.branches:
            branch_of[slot_of(branch)] = (junction, branch.index)
        if junction.node not in choice:
            continue
        pairs, unpaired, _ = junction.matchings[choice[junction.node]]
        for k in unpaired:
            if junction.branches[k].spur:
                spurs[junction.branches[k].edge] = junction
        for i, j in pairs:
            a, b = slot_of(junction.branches[i]), slot_of(junction.branches[j])
            partner[a], partner[b] = b, a
    return branch_of, partner, spurs


def _walk_pieces(g, edges, partner):
    """The pieces of cable ``(legs, closed)``: walks along the segments through the junctions'
    pairings, from every free end and unpaired branch first, then around closed loops; each leg
    is ``(edge, forward)``."""
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
    return pieces


def _piece_paths(pieces, edges, spurs, branch_of, partner, context, warnings):
    """Each piece's points (``[points, closed, edges]``; spurs and specks left out, each with a
    warning) and where each junction's bridges lie in them (``(junction, branch) -> (path,
    span)``)."""
    paths, bridges = [], {}
    for legs, closed in pieces:
        if len(legs) == 1 and not closed and legs[0][0] in spurs:
            warnings.append(f"dropped a spur of {edges[legs[0][0]]['length'] / context.r:.1f} r "
                            f"at junction {spurs[legs[0][0]].node} (carving noise, or a stub of "
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
    return _drop_specks(paths, bridges, context, warnings)


def _listed_crossings(paths, crossings, context, warnings):
    """The placed crossings as :class:`TopologyCrossing`; an ambiguous one gets a warning."""
    result = []
    for crossing in crossings:
        (op, oi), (upath, ui) = crossing["over"], crossing["under"]
        position = 0.5 * (paths[op][0][oi] + paths[upath][0][ui])
        result.append(TopologyCrossing(position, (op, oi), (upath, ui),
                                       float(np.clip(crossing["confidence"], 0.0, 1.0)),
                                       crossing["junction"], crossing["cues"],
                                       crossing["views"]))
    for k, crossing in enumerate(result):
        if crossing.confidence < context.settings.confident:
            cues = crossing.cues
            warnings.append(
                f"crossing {k} (junction {crossing.junction}) is ambiguous: confidence "
                f"{crossing.confidence:.2f} (heights {cues.get('height', 0.0):+.1f}, images "
                f"{cues.get('image', 0.0):+.1f} from {cues.get('views', 0)} view(s), pairing "
                f"{cues.get('pairing', 0.0):.2f}); flip it if the result looks wrong")
    return tuple(result)


def _drop_specks(paths, bridges, context, warnings):
    """Paths shorter than ``min_path_length`` left out (unless all are); bridges renumbered."""
    limit = context.settings.min_path_length * context.r
    lengths = [float(arc_length(np.vstack([p, p[:1]]) if closed else p)[-1])
               for p, closed, _ in paths]
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
    arc = arc_length(points)
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
        return np.vstack([at_arc(points, arc, middle - 1e-3 * length),
                          at_arc(points, arc, middle + 1e-3 * length)])
    inner = points[keep]
    ends = [at_arc(points, arc, low)[None]] if arc[keep][0] > low + 1e-12 else []
    tail_end = [at_arc(points, arc, high)[None]] if arc[keep][-1] < high - 1e-12 else []
    return np.vstack(ends + [inner] + tail_end)


def _bridge(incoming, outgoing, context):
    """Interior points of a smooth curve from the end of ``incoming`` to the start of
    ``outgoing``."""
    p0, p1 = incoming[-1], outgoing[0]
    chord = float(np.linalg.norm(p1 - p0))
    if chord < 1e-12:
        return np.zeros((0, 3))
    t0, t1 = end_tangent(incoming, context, False), end_tangent(outgoing, context, True)
    count = max(int(math.ceil(1.2 * chord / max(context.spacing, 1e-12))), 2) + 1
    curve, _, _ = hermite(p0, t0 * chord, p1, t1 * chord, count)
    return curve[1:-1]


def _place_crossings(junctions, choice, marginals, bridges, paths, context):
    """Crossings at the chosen matchings: where the bridges of two strands pass each other."""
    crossings = []
    for junction, m, (pairs, _, crossing_pairs) in _chosen(junctions, choice):
        members = [k for k, h in enumerate(junction.hypotheses) if h[0] == m]
        if not crossing_pairs or not members:
            continue
        log_p = junction.log_p[members]
        best = members[int(np.argmax(log_p))]
        orders = junction.hypotheses[best][1]
        within = np.exp(log_p - logsumexp(log_p))
        for c, ((a, b), first_over) in enumerate(zip(crossing_pairs, orders)):
            over, under = (pairs[a], pairs[b]) if first_over else (pairs[b], pairs[a])
            if (junction.node, over) not in bridges or (junction.node, under) not in bridges:
                continue
            same = sum(w for w, k in zip(within, members) if junction.hypotheses[k][1][c]
                       == first_over)
            o_path, o_span = bridges[(junction.node, over)]
            u_path, u_span = bridges[(junction.node, under)]
            oi, ui = _closest_pass(paths[o_path][0], o_span, paths[u_path][0], u_span, context)
            crossings.append(_crossing((o_path, oi), (u_path, ui), same, junction, m, marginals,
                                       *junction.crossing_cues(over, under, context)))
    return crossings


def _chosen(junctions, choice):
    """``(junction, matching index, matching)`` of each junction with a chosen matching."""
    for junction in junctions:
        if junction.node in choice:
            m = choice[junction.node]
            yield junction, m, junction.matchings[m]


def _crossing(over, under, order_p, junction, m, marginals, height, image, votes):
    """A placed crossing: ``over`` and ``under`` (path, index), its confidence (the matching's
    probability times ``order_p``, the order's within it) and its cues (each cue's log-odds
    for the order, the matching's margin over the next and the views' votes)."""
    matching_p = marginals.get(junction.node, 1.0)
    others = np.delete(junction.matching_log_p, m)
    margin = float(junction.matching_log_p[m] - (others.max() if len(others) else -np.inf))
    return dict(over=over, under=under, confidence=matching_p * order_p, junction=junction.node,
                cues={"height": 2.0 * height, "image": 2.0 * image,
                      "pairing": margin if np.isfinite(margin) else 99.0,
                      "pairing_probability": matching_p, "views": len(votes)},
                views=votes)


def _end_crossings(junctions, choice, marginals, bridges, paths, context, warnings):
    """Third branches that cross a strand: at a junction whose chosen matching pairs one strand
    and leaves one branch unpaired (not a spur), where that branch lies at least
    ``end_crossing_height`` higher or lower than the strand (each as high as its branches'
    centrelines near their branch points), the branch's path goes on through the junction's
    centre to ``end_crossing_reach`` beyond it, and crosses the strand there, over when
    higher. A cable end lying across a strand ends a few radii beyond it, a stub the carving
    leaves out (the segment graph removes short dead ends), and a strand crossing another may
    have lost its continuation to the carving with no free end left to bridge to: either way
    the junction has three branches. An end touching a strand, or a spur, lies at the strand's
    height and stays an end.

    The paths are extended in place (spans of ``bridges`` on a path extended at its start
    move with it). Returns the crossings as :func:`_place_crossings` gives them, the
    confidence the matching's probability times the height cue's for the order.
    """
    s, r = context.settings, context.r
    if s.end_crossing_height <= 0:
        return []
    found = []
    for junction, m, (pairs, unpaired, _) in _chosen(junctions, choice):
        ends = [k for k in unpaired if not junction.branches[k].spur]
        if len(pairs) != 1 or len(ends) != 1 or (junction.node, pairs[0]) not in bridges:
            continue
        branch = junction.branches[ends[0]]
        lift = branch.height - float(np.mean([junction.branches[k].height for k in pairs[0]]))
        located = _path_end(paths, branch, junction.centre, context)
        if abs(lift) < s.end_crossing_height * r or located is None:
            continue
        number, at_start = located
        span, shift = _extend_end(paths, bridges, number, at_start, junction.centre, context)
        for crossing in found:  # ends found before on the path move with it too
            for side in ("over", "under"):
                if crossing[side][0] == number:
                    crossing[side] = (number, crossing[side][1] + shift)
        height = float(np.clip(abs(lift) / (s.height_scale * r), 0.0, s.height_cap))
        strand_path, strand_span = bridges[(junction.node, pairs[0])]
        end_index, strand_index = _closest_pass(paths[number][0], span,
                                                paths[strand_path][0], strand_span, context)
        end, strand = (number, end_index), (strand_path, strand_index)
        over, under = (end, strand) if lift > 0 else (strand, end)
        found.append(_crossing(over, under, 1.0 / (1.0 + math.exp(-2.0 * height)), junction, m,
                               marginals, height, 0.0, ()))
        warnings.append(f"junction {junction.node}: its third branch, {abs(lift) / r:.1f} r "
                        f"{'above' if lift > 0 else 'below'} the strand through it, taken to "
                        f"cross {'over' if lift > 0 else 'under'} it (a cable end lying across "
                        "it, or a branch the carving missed)")
    return found


def _path_end(paths, branch, centre, context):
    """``(path, at its start)``: the open path's end that is the unpaired ``branch``'s cut end
    at the junction (``centre``), or None."""
    best = None
    for number, (points, closed, path_edges) in enumerate(paths):
        if closed or not path_edges:
            continue
        for at_start, edge in ((True, path_edges[0]), (False, path_edges[-1])):
            if edge != branch.edge:
                continue
            distance = float(np.linalg.norm(context.flat(points[0 if at_start else -1]
                                                         - centre)))
            if best is None or distance < best[0]:
                best = (distance, number, at_start)
    if best is None or best[0] > (context.settings.bridge_distance + 2.0) * context.r:
        return None
    return best[1], best[2]


def _extend_end(paths, bridges, number, at_start, centre, context):
    """Path ``number`` carried on from its end (its start if ``at_start``) through the
    junction's ``centre`` to ``end_crossing_reach`` beyond it, at the end's height; the
    extension's span on the path, and how far the path's old points moved along it."""
    points = paths[number][0]
    tip = points[0] if at_start else points[-1]
    across = (centre - tip) - ((centre - tip) @ context.up) * context.up  # horizontal
    inward = across / max(np.linalg.norm(across), 1e-12)
    far = tip + across + context.settings.end_crossing_reach * context.r * inward
    chord = float(np.linalg.norm(far - tip))
    count = max(int(math.ceil(chord / max(context.spacing, 1e-12))), 2) + 1
    tangent = end_tangent(points, context, at_start)
    curve, _, _ = hermite(tip, (-tangent if at_start else tangent) * chord, far,
                          inward * chord, count)
    added = curve[1:]
    if at_start:
        paths[number][0] = np.vstack([added[::-1], points])
        shift = len(added)
        for key, (path, (first, last)) in list(bridges.items()):
            if path == number:
                bridges[key] = (path, (first + shift, last + shift))
        return (0, shift), shift
    paths[number][0] = np.vstack([points, added])
    return (len(points) - 1, len(points) + len(added) - 1), 0


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
    add_bump(over, paths[op][1], oi, shift, width, context.up)
    add_bump(under, paths[upath][1], ui, -shift, width, context.up)

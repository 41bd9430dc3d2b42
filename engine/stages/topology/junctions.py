"""Junctions and their branches: the pairing and order hypotheses, scored by bending and by the
grid's heights, and the cues combined."""

import itertools
import math

import numpy as np
from ...geometry.polylines import arc_length
from .polylines import at_arc, hermite


__all__ = ["Junction", "logsumexp"]


class _Branch:
    """One segment end at a junction, its centreline walking away from the junction."""

    def __init__(self, index, edge, side, chain, other, context):
        self.index, self.edge, self.side, self.other = index, edge, side, other
        self.chain = np.asarray(chain, dtype=float)
        self.arc = arc_length(self.chain)
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
        self.anchor = at_arc(self.chain, self.arc, s)
        ahead = at_arc(self.chain, self.arc, min(s + 1.5 * r, self.reach if self.other is not None
                                                 else self.length))
        behind = at_arc(self.chain, self.arc, max(s - 1.0 * r, 0.0))
        tangent = ahead - behind
        if np.linalg.norm(tangent) < 1e-12:
            tangent = self.anchor - centre
        self.tangent = tangent / max(np.linalg.norm(tangent), 1e-12)
        window = context.settings.height_window * r
        near = (self.arc >= max(s - window, 0.0)) & (self.arc <= min(s + window, self.reach))
        heights = (self.chain[near] if near.any() else self.anchor[None]) @ context.up
        self.height = float(np.mean(heights) - centre @ context.up)


class Junction:
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
                            "third ends there, across the strand if it lies above or below it")
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
            point = (at_arc(branch.chain, branch.arc, min(4.0 * r, branch.reach))
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
            self.log_p = self.scores - logsumexp(self.scores)
        else:
            self.log_p = np.zeros(0)
        self.matching_log_p = np.array([
            logsumexp(self.log_p[[k for k, h in enumerate(self.hypotheses) if h[0] == m]])
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
    curve, d1, d2 = hermite(p0, t0 / n0 * chord, p1, t1 / n1 * chord, samples)
    speed = np.linalg.norm(d1, axis=1)
    kappa = np.linalg.norm(np.cross(d1, d2), axis=1) / np.maximum(speed ** 3, 1e-30)
    ds = speed / (samples - 1)
    length = float(np.sum(ds))
    return float(length * np.sum(kappa ** 2 * ds))


def logsumexp(values):
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

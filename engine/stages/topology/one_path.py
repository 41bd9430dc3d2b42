"""One path per cable (the paper's combinatorial check): the least confident junctions revisited
until each connected piece of the graph gives one path, or as few as its free ends allow."""

import heapq
import math

import networkx as nx
import numpy as np

from ..union_find import DisjointSets

__all__ = ["slot_of", "one_path_per_cable"]


def slot_of(branch):
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
        pieces = DisjointSets(range(self.count))
        open_ends, spurs = self.ends, 0
        for links, unpaired, spur, rank in zip(self.links, self.unpaired, self.spurs, ranks):
            for a, b in links[rank]:
                pieces.union(a, b)
            open_ends += unpaired[rank]
            spurs += spur[rank]
        return pieces.count - spurs, max(1, (open_ends - 2 * spurs) // 2)


def one_path_per_cable(junctions, context, warnings):
    """Matchings that make each connected piece of the graph one path, and their probabilities.

    Returns ``choice`` (junction node -> matching index) and ``marginals`` (junction node ->
    probability of that matching given the one-path constraint).
    """
    g = context.graph.graph
    by_node = {j.node: j for j in junctions}
    for junction in junctions:
        junction.ranked = list(np.argsort(-junction.matching_log_p, kind="stable"))
    choice, marginals = {}, {}
    for component in _components(g):
        edges = [(d["start"], d["end"], k) for u, v, k, d in g.subgraph(component).edges(
            keys=True, data=True)]
        members = [by_node[n] for n in sorted(component) if n in by_node]
        ends = sum(1 for n in component if g.nodes[n]["kind"] == "end")
        if not members:
            continue
        logs = [[float(v) for v in j.matching_log_p[j.ranked]] for j in members]
        count_pieces = _Pieces(edges, ends, members)
        found, tried = _best_first(logs, count_pieces, context.settings)
        start = tuple(0 for _ in members)
        if not found:
            pieces, fewest = count_pieces(start)
            warnings.append(
                f"no pairing at junction(s) {', '.join(str(j.node) for j in members)} "
                f"(of {tried} tried) joins their cable into {fewest} path(s): kept as "
                f"{pieces}")
            found = [(float(sum(log[0] for log in logs)), start)]
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


def _best_first(logs, count_pieces, settings):
    """Combinations of the junctions' matchings (each junction's rank in ``logs``, its ranked
    log-probabilities) that give as few paths as the free ends allow, best first: at most
    ``search_budget`` tried, none more than ``search_window`` below the best found. Returns
    ``(found, tried)``, ``found`` a list of ``(log-probability, ranks)``."""
    def total(ranks):
        return float(sum(log[k] for log, k in zip(logs, ranks)))

    start = tuple(0 for _ in logs)
    heap = [(-total(start), start)]
    seen = {start}
    found = []
    tried = 0
    while heap and tried < settings.search_budget:
        negative, ranks = heapq.heappop(heap)
        tried += 1
        if found and -negative < found[0][0] - settings.search_window:
            break
        pieces, fewest = count_pieces(ranks)
        if pieces <= fewest:
            found.append((-negative, ranks))
        for k in range(len(logs)):
            if ranks[k] + 1 < len(logs[k]) and math.isfinite(logs[k][ranks[k] + 1]):
                step = ranks[:k] + (ranks[k] + 1,) + ranks[k + 1:]
                if step not in seen:
                    seen.add(step)  # one rank down at one junction: its score moves
                    heapq.heappush(heap, (negative + logs[k][ranks[k]]
                                          - logs[k][ranks[k] + 1], step))
    return found, tried


def _components(g):
    return [set(c) for c in nx.connected_components(g)]

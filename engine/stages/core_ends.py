"""Free ends of the carved core followed through the half-vote hull.

Where one strand passes under another, the upper strand's cast shadow darkens the lower one, and
in some views the masks miss it there. Its voxels then fall under the core's agreement (95% of
the views) while staying in the half-vote hull, and the core breaks: the graph gets a free end
that is not the cable's and, at the crossing, a junction with a branch missing (the lower
strand's share of the views falls to 0.38-0.79 beside the crossings a run loses, where the
exact masks give 1.0). Lowering the core's agreement everywhere is no cure: it fattens the
core where it is whole, and as many crossings are lost as gained (README, *Free ends followed
through the hull*).

Here each free end of the graph is *followed*: stepped along its heading through the hull,
each step re-centred on the hull's cross-section (its voxels of about the highest agreement
within a radius of the point ahead), turning as a cable bends, through any strand it passes
under or over, until it reaches a junction with an odd number of branches (a branch is
missing there) or another free end heading back at it. The hull's voxels within 0.7 radii of
the walk then join the core, and the graph is built again, so the crossings the walk passes
become junctions of their own. A walk that leaves the hull (the cable's real end) or goes
farther than ``follow_length`` changes nothing.
"""

import math

import numpy as np

from ..geometry.polylines import arc_length
from .sparse_voxels import key_box

__all__ = ["follow_free_ends", "FollowedEnd"]

#: A walk steps this many radii at a time and re-centres on the hull's voxels within this many
#: radii of the point a step ahead (so also within a radius of its height: a strand it passes
#: under, two radii above it, does not lift it).
_STEP = 0.5
_REACH = 1.0
#: The hull's voxels within this many radii of a walk join the core (a core is about a
#: radius thick; a thinner tube keeps a strand lying beside the walk apart from it).
_TUBE = 0.7
#: The cross-section's voxels of at least this share of its best agreement re-centre a step.
_RIDGE = 0.9
#: A walk arrives within this many radii, across the up direction, of a junction or free end,
#: and within ``_JUNCTION_HEIGHT`` radii of a junction's height (its centre lies between its
#: strands'), ``_END_HEIGHT`` of a free end's (on the walk's own strand, not on one passing
#: two radii over or under it).
_ARRIVE = 2.0
_JUNCTION_HEIGHT = 3.0
_END_HEIGHT = 1.0
#: A free end heads back at a walk when its heading and the walk's are this opposed (cosine).
_FACING = -0.5
#: A walk's heading turns by at most this many radians a step (a cable bends smoothly; this
#: is a bend of 4 radii's radius).
_TURN = 0.12
#: A free end's heading is measured over this many radii of its segment.
_HEADING = 2.0


class FollowedEnd:
    """A free end followed to a junction or another free end.

    Attributes
    ----------
    end : hashable
        The free end's node in the graph.
    target : hashable
        The node the walk reached.
    points : ndarray, shape (M, 3)
        The walk, world positions from the end to the target.
    length : float
        Its length, world units.
    """

    def __init__(self, end, target, points):
        self.end, self.target, self.points = end, target, points
        self.length = float(arc_length(points)[-1])


class _Hull:
    """The grid's voxels, looked up by position."""

    def __init__(self, grid):
        self.grid = grid
        self.low, self.extent, self.strides = key_box(grid.index)
        keys = (grid.index - self.low) @ self.strides
        # the grid lists its voxels in C order, key order: the sort finds them sorted
        self.order = np.argsort(keys, kind="stable")
        self.sorted = keys[self.order]

    def around(self, centre, radius):
        """Rows of the grid's voxels whose centres lie within ``radius`` (world) of ``centre``
        and their centres."""
        grid = self.grid
        middle = (np.asarray(centre) - grid.origin) / grid.voxel_size
        reach = int(math.ceil(radius / grid.voxel_size))
        low = np.floor(middle).astype(np.int64) - reach
        span = np.arange(2 * reach + 2)
        box = (low[:, None] + span[None, :])
        cube = np.stack(np.meshgrid(*box, indexing="ij"), axis=-1).reshape(-1, 3)
        inside = np.all((cube > self.low) & (cube < self.low + self.extent - 1), axis=1)
        cube = cube[inside]
        centres = grid.centres(cube)
        near = np.linalg.norm(centres - centre, axis=1) <= radius
        cube, centres = cube[near], centres[near]
        wanted = (cube - self.low) @ self.strides
        at = np.searchsorted(self.sorted, wanted)
        at = np.minimum(at, len(self.sorted) - 1)
        found = self.sorted[at] == wanted
        return self.order[at[found]], centres[found]


def _heading(points, span):
    """Unit direction of travel at the last point of a polyline, over ``span``."""
    back = arc_length(points[::-1])
    first = int(np.searchsorted(back, span))
    start = points[::-1][min(first, len(points) - 1)]
    direction = points[-1] - start
    size = np.linalg.norm(direction)
    return direction / size if size > 0 else None


def _free_ends(graph, r):
    """Per free end: its node, position and outward heading."""
    g = graph.graph
    ends = []
    for node, data in g.nodes(data=True):
        if data["kind"] != "end" or g.degree(node) != 1:
            continue
        (_, _, edge), = g.edges(node, data=True)
        points = np.asarray(edge["points"], dtype=float)
        if edge["start"] == node:
            points = points[::-1]  # ends at the free end
        if len(points) < 2:
            continue
        heading = _heading(points, _HEADING * r)
        if heading is not None:
            ends.append((node, points[-1], heading))
    return ends


def _turned(heading, wanted, most):
    """``heading`` turned towards ``wanted`` (unit vectors) by at most ``most`` radians."""
    angle = math.acos(float(np.clip(heading @ wanted, -1.0, 1.0)))
    if angle <= most:
        return wanted
    side = wanted - (heading @ wanted) * heading
    size = np.linalg.norm(side)
    if size == 0:
        return heading
    return math.cos(most) * heading + math.sin(most) * side / size


def _walk(hull, start, heading, r, length, arrive):
    """Step from ``start`` along ``heading`` through the hull; ``arrive(position, heading)``
    names the node a step reaches (or None). The walk's points and the node, or None."""
    position, points = np.asarray(start, dtype=float), [np.asarray(start, dtype=float)]
    step = _STEP * r
    for _ in range(int(math.ceil(length / step))):
        ahead = position + step * heading
        rows, centres = hull.around(ahead, _REACH * r)
        if len(rows):
            offset = centres - ahead
            keep = np.abs(offset @ heading) <= 0.5 * step
            rows, offset = rows[keep], offset[keep]
        if not len(rows):
            return None  # out of the hull: the cable's end
        agreement = hull.grid.agreement[rows]
        ridge = agreement >= _RIDGE * agreement.max()
        shift = np.average(offset[ridge], axis=0, weights=agreement[ridge])
        shift -= (shift @ heading) * heading  # re-centred across the walk only
        moved = ahead + shift - position
        heading = _turned(heading, moved / np.linalg.norm(moved), _TURN)
        position = position + step * heading
        points.append(position)
        node = arrive(position, heading)
        if node is not None:
            return np.array(points), node
    return None


def follow_free_ends(grid, core, graph, *, up, length):
    """Free ends of the core's graph followed through the hull (module docstring).

    Parameters
    ----------
    grid : engine.stages.carving.VoxelGrid
        The half-vote hull, with each voxel's agreement.
    core : ndarray of bool, shape (N,)
        Which of the grid's voxels are the core the graph was built on.
    graph : engine.stages.segment_graph.SegmentGraph
        The core's graph.
    up : ndarray, shape (3,)
        The world's up direction (unit).
    length : float
        The farthest a walk goes, world units (0: none).

    Returns
    -------
    core : ndarray of bool, shape (N,)
        The core with the walks' voxels (a copy; ``core`` itself when no walk arrived).
    followed : list of FollowedEnd
    """
    r = grid.radius
    ends = _free_ends(graph, r) if length > 0 and len(grid) else []
    if not ends:
        return core, []
    g = graph.graph
    odd = [(node, np.asarray(data["position"], dtype=float))
           for node, data in g.nodes(data=True)
           if data["kind"] == "junction" and g.degree(node) % 2]
    hull = _Hull(grid)
    up = np.asarray(up, dtype=float)

    def flat(offset):
        return float(np.linalg.norm(offset - (offset @ up) * up))
    followed, used = [], set()
    for node, position, heading in ends:
        if node in used:
            continue

        def arrive(at, going, node=node):
            for junction, centre in odd:
                if (junction not in used and flat(at - centre) <= _ARRIVE * r
                        and abs((at - centre) @ up) <= _JUNCTION_HEIGHT * r):
                    return junction
            for other, place, facing in ends:
                if (other != node and other not in used and facing @ going <= _FACING
                        and flat(at - place) <= _ARRIVE * r
                        and abs((at - place) @ up) <= _END_HEIGHT * r):
                    return other
            return None

        walked = _walk(hull, position, heading, r, length, arrive)
        if walked is None:
            continue
        points, target = walked
        target_at = np.asarray(g.nodes[target]["position"], dtype=float)
        followed.append(FollowedEnd(node, target, np.vstack([points, target_at])))
        used.update([node, target])
    if not followed:
        return core, []
    core = core.copy()
    for walk in followed:
        for point in _densified(walk.points, _STEP * r):
            rows, _ = hull.around(point, _TUBE * r)
            core[rows] = True
    return core, followed


def _densified(points, spacing):
    """Points along a polyline no more than ``spacing`` apart."""
    out = [points[:1]]
    for a, b in zip(points[:-1], points[1:]):
        count = max(int(math.ceil(np.linalg.norm(b - a) / spacing)), 1)
        out.append(a + np.linspace(0.0, 1.0, count + 1)[1:, None] * (b - a))
    return np.vstack(out)

"""Seeded cable layouts with known topology: the ground truth of synthetic scenes.

Layouts are built in units of the cable radius (r = 1) and scaled to metres at the end, so the
same seed gives the same shape at every size. Five kinds:

* :func:`table_layout`: a cable lying on a table (z = 0 is the table, the cable's centre rests
  at z = r) with exactly N crossings, free ends or a closed loop, the upper strand lifted over
  the lower one;
* :func:`knot_layout`: an overhand knot (three alternating crossings) with free tails;
* :func:`hanging_layout`: a cable hanging in the air between two points, bent out of its
  plane: a 3D shape that no single image captures;
* :func:`pair_layout`: two cables on a table crossing each other (and maybe themselves);
* :func:`hard_layout`: a cable heaped on a table, as real cables on a desk lie: 12 to 20
  crossings in clusters, some 3 r apart along the cable and in the plane, shallow ones down to
  15°, tight loops, strands running side by side, an end lying near a crossing (the rules of
  :data:`HARD_SETTINGS`); a strand may pass over one strand and under the next.

Guarantees, checked on every layout before it is returned (else the next candidate is drawn):
strands never closer than 2 r in 3D, and never closer than ``clearance`` in the table plane
away from crossings; crossing angles at least ``min_crossing_angle``; crossings at least
``min_crossing_spacing`` apart along the cable and from its ends (except inside a knot); bends
no tighter than ``min_bend_radius``.
"""

import math
from dataclasses import dataclass, replace

import numpy as np
from scipy.ndimage import gaussian_filter1d
from scipy.spatial import cKDTree

from ..geometry.polylines import arc_length, unit
from ..io.ground_truth import GroundTruth, TrueCrossing

__all__ = ["LayoutSettings", "HARD_SETTINGS", "table_layout", "knot_layout", "hanging_layout",
           "pair_layout", "hard_layout", "find_crossings_2d", "default_extent", "LayoutError"]

SAMPLE_SPACING = 0.25  # r: centreline samples
MAX_CLOSED_CROSSINGS = 8
LOCAL_ARC = 2.5        # r: samples closer than this along the cable are neighbours, not strands


class LayoutError(RuntimeError):
    """No layout satisfying the settings was found within the allowed number of tries."""


@dataclass(frozen=True)
class LayoutSettings:
    """Shape rules shared by the generators (lengths in units of the radius r).

    Attributes
    ----------
    min_crossing_angle : float
        Degrees; crossings flatter than this are rejected (no grazing crossings).
    min_crossing_spacing : float
        Minimum distance along the cable between two crossings, and from a crossing to an end.
    clearance : float
        Minimum centre distance in the table plane between strands that do not cross there
        (2 would let them touch).
    lift_margin : float
        The upper strand's centre is lifted ``2 (1 + lift_margin)`` above the lower one's.
    min_bend_radius : float
        Tightest allowed bend of the centreline.
    max_tries : int
        Candidates drawn before giving up with :class:`LayoutError`.
    """

    min_crossing_angle: float = 30.0
    min_crossing_spacing: float = 8.0
    clearance: float = 3.0
    lift_margin: float = 0.1
    min_bend_radius: float = 3.0
    max_tries: int = 3000


#: The rules of :func:`hard_layout`: crossings down to 15°, 3 r apart along the cable (and
#: from its ends), strands side by side with 0.2 r between them, bends down to 2 r.
HARD_SETTINGS = LayoutSettings(min_crossing_angle=15.0, min_crossing_spacing=3.0,
                               clearance=2.2, min_bend_radius=2.0, max_tries=400)


# -- geometry helpers ---------------------------------------------------------------------------

def _arc_resample(points, spacing, closed=False):
    """Resample a polyline at equal arc-length ``spacing`` (keeps both ends of an open one)."""
    if closed:
        points = np.vstack([points, points[:1]])
    arc = arc_length(points)
    count = max(int(round(arc[-1] / spacing)), 2)
    targets = np.linspace(0.0, arc[-1], count + (0 if closed else 1), endpoint=not closed)
    return np.column_stack([np.interp(targets, arc, points[:, k])
                            for k in range(points.shape[1])])


def _segments(points, closed):
    ends = np.roll(points, -1, axis=0) if closed else points[1:]
    starts = points if closed else points[:-1]
    return starts, ends


def find_crossings_2d(points, *, closed=False):
    """Self-intersections of a polyline in the xy plane.

    Parameters
    ----------
    points : ndarray, shape (N, 2) or (N, 3)
        Only x and y are used.
    closed : bool, optional

    Returns
    -------
    list of tuple
        ``(arc_a, arc_b, angle_degrees)`` per crossing with ``arc_a < arc_b`` the arc-length
        positions of the two passes, sorted by ``arc_a``.
    """
    xy = np.asarray(points, dtype=np.float64)[:, :2]
    starts, ends = _segments(xy, closed)
    vectors = ends - starts
    lengths = np.linalg.norm(vectors, axis=1)
    arc = np.concatenate([[0.0], np.cumsum(lengths)])
    tree = cKDTree(0.5 * (starts + ends))
    pairs = tree.query_pairs(lengths.max() * 1.0001, output_type="ndarray")
    if len(pairs) == 0:
        return []
    i, j = pairs.min(axis=1), pairs.max(axis=1)
    count = len(starts)
    keep = (j - i > 1) & ~(closed & (i == 0) & (j == count - 1))
    i, j = i[keep], j[keep]
    d1, d2, offset = vectors[i], vectors[j], starts[j] - starts[i]
    denom = d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (offset[:, 0] * d2[:, 1] - offset[:, 1] * d2[:, 0]) / denom
        u = (offset[:, 0] * d1[:, 1] - offset[:, 1] * d1[:, 0]) / denom
    hit = (denom != 0) & (t >= 0) & (t < 1) & (u >= 0) & (u < 1)
    crossings = []
    for a, b, ta, ub in zip(i[hit], j[hit], t[hit], u[hit]):
        cosine = abs(np.dot(vectors[a], vectors[b]))
        cosine /= lengths[a] * lengths[b]
        angle = math.degrees(math.acos(min(1.0, cosine)))
        crossings.append((arc[a] + ta * lengths[a], arc[b] + ub * lengths[b], angle))
    crossings.sort()
    return crossings


def _bump(offset, half_width):
    """Smooth compact bump: 1 at 0, 0 beyond ``half_width``."""
    x = np.clip(np.abs(offset) / half_width, 0.0, 1.0)
    return np.cos(0.5 * np.pi * x) ** 2


def _lift(points, crossings, over_first, settings, closed):
    """Heights: resting on the table (z = 1), the upper strand lifted over each crossing."""
    arc = np.arange(len(points)) * SAMPLE_SPACING
    length = len(points) * SAMPLE_SPACING if closed else arc[-1]
    height = 2.0 * (1.0 + settings.lift_margin)
    ground = np.ones(len(points))  # 1 - lift / height, multiplied over the crossings
    for (arc_a, arc_b, angle), a_over in zip(crossings, over_first):
        over_arc = arc_a if a_over else arc_b
        offset = arc - over_arc
        if closed:
            offset = (offset + 0.5 * length) % length - 0.5 * length
        half_width = 8.0 / math.sin(math.radians(max(angle, 1.0)))  # keeps bends >= 3 r
        ground *= 1.0 - _bump(offset, half_width)
    # A smooth union of the bumps (a plain maximum would kink where two bumps meet).
    return np.column_stack([points[:, :2], 1.0 + height * (1.0 - ground)])


def _stacked_lift(points, crossings, over_first, settings, rounds=12):
    """Heights of an open cable whose crossings lie close together: each upper strand raised
    until it clears the strand under it by ``2 (1 + lift_margin)`` there, however high that
    one lies (it may pass over another strand nearby), by smooth bumps, in rounds until no
    crossing needs more (or ``rounds`` run out: :func:`_check` then rejects the layout)."""
    arc = np.arange(len(points)) * SAMPLE_SPACING
    height = 2.0 * (1.0 + settings.lift_margin)
    z = np.ones(len(points))
    passes = []
    for (arc_a, arc_b, angle), a_over in zip(crossings, over_first):
        over, under = (arc_a, arc_b) if a_over else (arc_b, arc_a)
        # wide enough to clear a shallow crossing's lower strand
        passes.append((over, int(round(over / SAMPLE_SPACING)),
                       int(round(under / SAMPLE_SPACING)),
                       4.0 + 2.5 / math.sin(math.radians(max(angle, 1.0)))))
    for _ in range(rounds):
        raised = False
        for over_arc, over, under, half_width in passes:
            need = z[under] + height - z[over]
            if need > 1e-6:
                # a bump of height h bends by h pi^2 / (2 w^2) at most: 0.2 / r at w = 5 sqrt(h)
                z += (need + 1e-3) * _bump(arc - over_arc, max(half_width, 5.0 * math.sqrt(need)))
                raised = True
        if not raised:
            break
    return np.column_stack([points[:, :2], z])


def _arc_gap(a, b, length, closed):
    gap = np.abs(a - b)
    return np.minimum(gap, length - gap) if closed else gap


def _check(points, crossings, settings, closed):
    """Return None if the lifted layout honours every rule, else the broken rule's name."""
    count = len(points)
    arc = np.arange(count) * SAMPLE_SPACING
    length = count * SAMPLE_SPACING if closed else arc[-1]
    # Bends.
    previous, following = (np.roll(points, 1, 0), np.roll(points, -1, 0)) if closed else \
        (points[:-2], points[2:])
    middle = points if closed else points[1:-1]
    curvature = np.linalg.norm(previous + following - 2 * middle, axis=1) / SAMPLE_SPACING ** 2
    if curvature.max() > 1.0 / settings.min_bend_radius:
        return "bend"
    # Angles and spacing along the cable.
    passes = []
    for arc_a, arc_b, angle in crossings:
        if angle < settings.min_crossing_angle:
            return "angle"
        passes += [arc_a, arc_b]
    if passes:
        passes = np.sort(passes)
        gaps = np.diff(passes)
        if closed:
            gaps = np.append(gaps, passes[0] + length - passes[-1])
        else:
            gaps = np.concatenate([[passes[0]], gaps, [length - passes[-1]]])
        if gaps.min() < settings.min_crossing_spacing:
            return "spacing"
    # 3D separation of distinct strands.
    tree = cKDTree(points)
    pairs = tree.query_pairs(2.0 * (1 - 1e-9), output_type="ndarray")
    if len(pairs) and np.any(_arc_gap(arc[pairs[:, 0]], arc[pairs[:, 1]], length, closed)
                             > LOCAL_ARC):
        return "separation"
    # Clearance in the table plane, except where the strands cross.
    tree2 = cKDTree(points[:, :2])
    pairs = tree2.query_pairs(settings.clearance, output_type="ndarray")
    if len(pairs):
        a, b = arc[pairs[:, 0]], arc[pairs[:, 1]]
        distinct = _arc_gap(a, b, length, closed) > 2 * settings.clearance
        a, b = a[distinct], b[distinct]
        if not np.all(_near_crossings(a, b, crossings, settings, length, closed)):
            return "clearance"
    return None


def _finish(points, crossings, over_first, radius, closed, kind):
    """Scale an r-unit layout to metres and describe its crossings by sample indices."""
    true_crossings = []
    for (arc_a, arc_b, angle), a_over in zip(crossings, over_first):
        index_a = int(round(arc_a / SAMPLE_SPACING)) % len(points)
        index_b = int(round(arc_b / SAMPLE_SPACING)) % len(points)
        over, under = (index_a, index_b) if a_over else (index_b, index_a)
        true_crossings.append(TrueCrossing(over=over, under=under, angle=float(angle)))
    return GroundTruth(centreline=points * radius, radius=radius, crossings=tuple(true_crossings),
                       closed=closed, kind=kind)


LOOP_RADIUS = 5.0    # r: the tightest turn a walk makes (the bend limit is checked too)
CORRELATION = 12.0   # r: how far along the cable the bending keeps its sense
WIGGLE = 0.45        # how often the bending saturates into a loop


def _bending(rng, count, loop_radius=LOOP_RADIUS):
    """Smooth random curvature along a walk, at most ``1 / loop_radius``."""
    noise = gaussian_filter1d(rng.normal(size=count), CORRELATION / SAMPLE_SPACING, mode="wrap")
    noise /= noise.std() + 1e-12
    return np.clip(WIGGLE * noise, -1.0, 1.0) / loop_radius


def _confined_walk(rng, length, bound, loop_radius=LOOP_RADIUS):
    """An open cable dropped in a disk of radius ``bound``: smooth bends, loops, no kinks.

    Heading integrates a random curvature. At the rim the walk turns back inwards as tightly
    as allowed and then crosses the table on a straighter course, as a thrown cable does,
    rather than creeping along the rim (which would lay strands side by side).
    """
    count = int(length / SAMPLE_SPACING)
    kappa = _bending(rng, count, loop_radius)
    straight_run = int(bound / SAMPLE_SPACING)
    x = y = 0.0
    heading = float(rng.uniform(0.0, 2.0 * np.pi))
    points = np.empty((count, 2))
    calm = 0
    turning = 0.0
    for i in range(count):
        points[i] = x, y
        k = kappa[i] * (0.2 if calm else 1.0)
        calm = max(calm - 1, 0)
        radius = math.hypot(x, y)
        if turning or radius > 0.8 * bound:
            cos_h, sin_h = math.cos(heading), math.sin(heading)
            inwards = -(x * cos_h + y * sin_h) / max(radius, 1e-9)
            if inwards < 0.7:  # turn until heading well inwards
                if not turning:
                    side = x * sin_h - y * cos_h
                    turning = math.copysign(1.0 / loop_radius, side if side else 1.0)
                k = turning
            elif turning:
                turning = 0.0
                calm = straight_run
        heading += k * SAMPLE_SPACING
        x += SAMPLE_SPACING * math.cos(heading)
        y += SAMPLE_SPACING * math.sin(heading)
    return points


def _closed_walk(rng, length, turns):
    """A closed cable turning ``turns`` times in total, its end sheared back onto its start.

    A closed curve turning k times crosses itself an odd number of times when k is even and
    an even number when k is odd (Whitney), so the caller picks ``turns`` by parity.
    """
    count = int(length / SAMPLE_SPACING)
    kappa = _bending(rng, count)
    kappa += (2.0 * np.pi * turns / length) - kappa.mean()
    heading = np.cumsum(kappa) * SAMPLE_SPACING
    tangent = np.column_stack([np.cos(heading), np.sin(heading)])
    gap = tangent.sum(axis=0) * SAMPLE_SPACING
    if np.linalg.norm(gap) > 0.25 * length:
        return None
    tangent -= gap / length
    points = np.cumsum(tangent, axis=0) * SAMPLE_SPACING
    return _arc_resample(points - points.mean(axis=0), SAMPLE_SPACING, closed=True)


def _window_with_crossings(found, wanted, count, min_length, settings):
    """The longest stretch of a walk holding exactly ``wanted`` crossings, none grazing.

    A crossing belongs to the stretch ``[a, b]`` when both its passes lie inside; crossings
    with only one pass inside are not crossings of the cut cable. Passes keep
    ``min_crossing_spacing`` from the cut ends.

    Returns
    -------
    tuple of int or None
        First and last sample index of the stretch.
    """
    spacing = settings.min_crossing_spacing
    end = (count - 1) * SAMPLE_SPACING
    best = None
    starts = [0.0] + [c[0] + 0.5 * spacing for c in found] + [c[1] + 0.5 * spacing for c in found]
    for a in sorted(set(starts)):
        inside = sorted((c for c in found if c[0] >= a), key=lambda c: c[1])
        passes = [a]  # the cut end keeps its distance from crossings too
        good = 0
        lower = a + min_length
        upper = end
        for crossing in inside:
            crowded = min(abs(p - q) for p in passes for q in crossing[:2]) < spacing
            if (good == wanted or crossing[2] < settings.min_crossing_angle or crowded
                    or crossing[1] - crossing[0] < spacing):
                upper = min(upper, crossing[1] - spacing)
                break
            passes += crossing[:2]
            good += 1
            lower = max(lower, crossing[1] + spacing)
        if good == wanted and upper >= lower and (best is None or upper - a > best[1] - best[0]):
            best = (a, upper)
    if best is None:
        return None
    return int(math.ceil(best[0] / SAMPLE_SPACING)), int(best[1] / SAMPLE_SPACING)


def _check_extent(extent, radius):
    if not radius > 0:
        raise ValueError("radius must be positive")
    if extent / radius < 40:
        raise ValueError(f"extent {extent} is too small for radius {radius} (need >= 40 r)")


def default_extent(radius, crossings=3):
    """A table extent (metres) with room for ``crossings`` crossings of a cable of ``radius``.

    Between 20 cm and 2 m, and at most 200 r so the cable stays at least 5 pixels wide in a
    720-pixel-high view of the whole layout.
    """
    wanted = max(0.2, radius * (90.0 + 8.0 * crossings))
    return float(min(wanted, 2.0, 200.0 * radius))


def table_layout(crossings, *, seed=0, radius=0.004, extent=None, closed=False,
                 settings=LayoutSettings()):
    """A cable lying on a table with exactly ``crossings`` crossings.

    Parameters
    ----------
    crossings : int
        Number of crossings, 0 to 12.
    seed : int, optional
        Same seed, same layout.
    radius : float, optional
        Cable radius in metres (1–10 mm in the tests).
    extent : float, optional
        Diameter of the table area the cable lies in, metres; :func:`default_extent` if None.
    closed : bool, optional
        A closed loop instead of a cable with two free ends.
    settings : LayoutSettings, optional

    Returns
    -------
    GroundTruth
        ``kind="table"``, cameras empty.

    Raises
    ------
    LayoutError
        No layout found within ``settings.max_tries`` candidates.
    """
    if not 0 <= crossings <= (MAX_CLOSED_CROSSINGS if closed else 12):
        raise ValueError("crossings must be between 0 and 12 "
                         f"({MAX_CLOSED_CROSSINGS} for a closed loop)")
    extent = default_extent(radius, crossings) if extent is None else float(extent)
    _check_extent(extent, radius)
    rng = np.random.default_rng([seed, crossings, int(closed), 7])
    bound = 0.5 * extent / radius - settings.clearance
    min_length = 1.2 * extent / radius
    length = min_length + 60.0 * crossings
    max_length = 3.0 * length
    for _ in range(settings.max_tries):
        if closed:
            turns = 1 if crossings % 2 == 0 else int(rng.choice([0, 2]))
            flat = _closed_walk(rng, length, turns)
            if flat is None:
                continue
            if np.linalg.norm(flat, axis=1).max() > bound:
                length *= 0.97
                continue
            found = find_crossings_2d(flat, closed=True)
            if len(found) != crossings:
                length *= 1.02 if len(found) < crossings else 0.98
                continue
        else:
            walk = _confined_walk(rng, length + 2 * min_length, bound)
            window = _window_with_crossings(find_crossings_2d(walk), crossings, len(walk),
                                            min_length, settings)
            if window is None:
                length = min(1.1 * length, max_length)
                continue
            first, last = window
            flat = walk[first:last + 1]
            found = find_crossings_2d(flat)
        over_first = rng.random(len(found)) < 0.5
        lifted = _lift(flat, found, over_first, settings, closed)
        if _check(lifted, found, settings, closed) is None:
            return _finish(lifted, found, over_first, radius, closed, "table")
    raise LayoutError(f"no table layout with {crossings} crossings after {settings.max_tries} "
                      f"tries (seed {seed}, extent {extent} m, radius {radius} m)")


def pair_layout(crossings=3, *, seed=0, radius=0.004, extent=None, gap=24.0,
                settings=LayoutSettings()):
    """Two cables lying on a table, crossing each other at least once.

    A :func:`table_layout` with ``crossings`` crossings is cut in two near its middle: ``gap``
    of cable is taken out where no crossing lies within ``min_crossing_spacing`` of the cut,
    so that at least one crossing joins the two cables and the two new ends lie at least
    ``gap / 2`` apart (two ends closer than that would read as one cable with a break).

    Parameters
    ----------
    crossings : int, optional
        Crossings of the uncut layout, 1 to 12 (each is a crossing of the pair).
    seed : int, optional
    radius, extent : float, optional
        As :func:`table_layout`.
    gap : float, optional
        Cable taken out at the cut, r.
    settings : LayoutSettings, optional

    Returns
    -------
    GroundTruth
        ``kind="pair"``, one break.
    """
    if not 1 <= crossings <= 12:
        raise ValueError("crossings must be between 1 and 12")
    rng = np.random.default_rng([seed, crossings, 29])
    half = int(round(0.5 * gap / SAMPLE_SPACING))
    keep_off = half + int(math.ceil(settings.min_crossing_spacing / SAMPLE_SPACING))
    for _ in range(50):
        truth = table_layout(crossings, seed=int(rng.integers(2 ** 31)), radius=radius,
                             extent=extent, settings=settings)
        count = len(truth.centreline)
        passes = np.array([[c.over, c.under] for c in truth.crossings])
        for cut in rng.permutation(np.arange(int(0.3 * count), int(0.7 * count))):
            if np.abs(passes - cut).min() < keep_off:
                continue
            if not np.any((passes < cut).sum(axis=1) == 1):  # no crossing joins the two
                continue
            ends = truth.centreline[[cut - half - 1, cut + half + 1], :2] / radius
            if np.linalg.norm(ends[0] - ends[1]) < 0.5 * gap:
                continue
            keep = np.r_[0:cut - half, cut + half + 1:count]
            after = passes > cut  # samples after the cut move back by those taken out
            moved = passes - after * (2 * half + 1)
            found = tuple(TrueCrossing(int(over), int(under), c.angle)
                          for (over, under), c in zip(moved, truth.crossings))
            return GroundTruth(truth.centreline[keep], radius, found, kind="pair",
                               breaks=(cut - half,))
    raise LayoutError(f"no pair layout with {crossings} crossings (seed {seed})")


def _near_crossings(arc_a, arc_b, crossings, settings, length=None, closed=False):
    """Per pair of arc positions: whether both lie within a crossing's window (where strands
    are close in the plane because they cross; :func:`_check` spares the same windows)."""
    near = np.zeros(len(arc_a), dtype=bool)
    length = 0.0 if length is None else length
    for cross_a, cross_b, angle in crossings:
        window = 1.5 * settings.clearance / math.sin(math.radians(angle)) + 1.0
        da, db = _arc_gap(arc_a, cross_a, length, closed), _arc_gap(arc_b, cross_b, length, closed)
        da2, db2 = (_arc_gap(arc_a, cross_b, length, closed),
                    _arc_gap(arc_b, cross_a, length, closed))
        near |= ((da < window) & (db < window)) | ((da2 < window) & (db2 < window))
    return near


def _pushed_apart(flat, crossings, settings, rounds=40):
    """An open walk whose strands lie closer than ``clearance`` in the plane without crossing
    there pushed apart until they clear it (a heaped cable lies in contact, it does not
    overlap): each close pair moves apart along the line between them, the moves spread
    smoothly along the cable. The crossings stay where they are unless a push undoes one
    (the caller counts them again)."""
    points = np.array(flat, dtype=np.float64)
    arc = np.arange(len(points)) * SAMPLE_SPACING
    wanted = 1.02 * settings.clearance
    for _ in range(rounds):
        pairs = cKDTree(points).query_pairs(wanted, output_type="ndarray")
        if len(pairs):
            a, b = arc[pairs[:, 0]], arc[pairs[:, 1]]
            keep = (np.abs(a - b) > 2 * settings.clearance) \
                & ~_near_crossings(a, b, crossings, settings)
            pairs = pairs[keep]
        if not len(pairs):
            break
        offset = points[pairs[:, 0]] - points[pairs[:, 1]]
        distance = np.maximum(np.linalg.norm(offset, axis=1, keepdims=True), 1e-9)
        push = 0.5 * (wanted - distance) * offset / distance
        move = np.zeros_like(points)
        np.add.at(move, pairs[:, 0], push)
        np.add.at(move, pairs[:, 1], -push)
        count = np.bincount(pairs.ravel(), minlength=len(points))  # a sample's close pairs
        move /= np.maximum(count, 1)[:, None]
        # spread along the cable (a radius or so), keeping the bends smooth; the spread
        # pushes weaker, so the rounds repeat it
        points += gaussian_filter1d(move, 1.0 / SAMPLE_SPACING, axis=0, mode="nearest")
        points = _unkinked(points, 0.9 / settings.min_bend_radius)
    return _arc_resample(points, SAMPLE_SPACING)


def _unkinked(points, limit, rounds=20):
    """An open polyline whose samples bending more than ``limit`` (1 / r) are moved towards
    their neighbours' midpoint, in rounds, until none does."""
    points = points.copy()
    for _ in range(rounds):
        middle = 0.5 * (points[:-2] + points[2:])
        curvature = 2.0 * np.linalg.norm(middle - points[1:-1], axis=1) / SAMPLE_SPACING ** 2
        sharp = np.flatnonzero(curvature > limit)
        if not len(sharp):
            break
        points[sharp + 1] += 0.5 * (middle[sharp] - points[sharp + 1])
    return points


def hard_layout(*, seed=0, radius=0.004, extent=None, crossings=(12, 20),
                settings=HARD_SETTINGS):
    """A cable heaped on a table: many crossings close together, as on a real desk.

    A walk dropped in a small disk (tight loops allowed) is cut to its longest stretch holding
    as many crossings as allowed, none flatter than the rules allow; strands that come closer
    than the clearance without crossing are pushed apart (:func:`_pushed_apart`), and the
    strands are lifted over each other however they stack (:func:`_stacked_lift`): a strand
    may pass over one strand and under the next 3 r on.

    Parameters
    ----------
    seed : int, optional
    radius : float, optional
        Metres.
    extent : float, optional
        Diameter of the heap's disk, metres; ``radius * (60 + 2.5 * most)`` if None, where
        ``most`` is the largest number of crossings allowed.
    crossings : int or (int, int), optional
        The number of crossings, or its range (8 to 24).
    settings : LayoutSettings, optional

    Returns
    -------
    GroundTruth
        ``kind="hard"``.

    Raises
    ------
    LayoutError
        No layout found within ``settings.max_tries`` walks.
    """
    fewest, most = (crossings, crossings) if np.ndim(crossings) == 0 else crossings
    if not 8 <= fewest <= most <= 24:
        raise ValueError("crossings must lie between 8 and 24")
    rng = np.random.default_rng([seed, fewest, most, 41])
    extent = radius * (60.0 + 2.5 * most) if extent is None else float(extent)
    _check_extent(extent, radius)
    bound = 0.5 * extent / radius - settings.clearance
    length = 4.0 * bound + 12.0 * most
    for _ in range(settings.max_tries):
        walk = _confined_walk(rng, length, bound, loop_radius=3.2)
        found = find_crossings_2d(walk)
        window = next((w for w in (_window_with_crossings(found, wanted, len(walk),
                                                          2.0 * bound, settings)
                                   for wanted in range(most, fewest - 1, -1))
                       if w is not None), None)
        if window is None:
            length = min(1.05 * length, 40.0 * bound)
            continue
        flat = walk[window[0]:window[1] + 1]
        before = find_crossings_2d(flat)
        flat = _pushed_apart(flat, before, settings)
        found = find_crossings_2d(flat)
        if len(found) != len(before):
            continue
        over_first = rng.random(len(found)) < 0.5
        lifted = _stacked_lift(flat, found, over_first, settings)
        if _check(lifted, found, settings, False) is None:
            return _finish(lifted, found, over_first, radius, False, "hard")
    raise LayoutError(f"no hard layout with {fewest} to {most} crossings after "
                      f"{settings.max_tries} tries (seed {seed})")


def _tail(rng, start, direction, length, turn):
    """A free end leaving ``start`` along ``direction``, turning by ``turn`` radians over its
    first 20 r (as gently as the bend limit allows), then bending at random."""
    count = int(length / SAMPLE_SPACING)
    arc = np.arange(1, count + 1) * SAMPLE_SPACING
    ease = np.clip(arc / 20.0, 0.0, 1.0)
    heading = (math.atan2(direction[1], direction[0]) + turn * ease * ease * (3 - 2 * ease)
               + np.cumsum(0.5 * _bending(rng, count)) * SAMPLE_SPACING)
    steps = np.column_stack([np.cos(heading), np.sin(heading)]) * SAMPLE_SPACING
    return start + np.cumsum(steps, axis=0)


def knot_layout(*, seed=0, radius=0.004, extent=None, settings=LayoutSettings()):
    """An overhand knot lying on a table, with two free tails.

    The knot is an opened trefoil: three crossings met alternately over and under along the
    cable, so it is a true knot and not three independent crossings. Inside the knot crossings
    may be closer than ``min_crossing_spacing`` (down to 4 r).

    Parameters
    ----------
    seed : int, optional
    radius : float, optional
        Metres.
    extent : float, optional
        Metres; :func:`default_extent` for three crossings if None.
    settings : LayoutSettings, optional

    Returns
    -------
    GroundTruth
        ``kind="knot"``, three crossings.
    """
    extent = default_extent(radius, 3) if extent is None else float(extent)
    _check_extent(extent, radius)
    settings = replace(settings, min_crossing_spacing=min(settings.min_crossing_spacing, 4.0))
    rng = np.random.default_rng([seed, 3, 11])
    bound = 0.5 * extent / radius - settings.clearance
    for _ in range(settings.max_tries):
        size = rng.uniform(6.5, 9.0)  # r: loose enough to bend and lift within the rules
        cut = 0.7
        t = np.linspace(np.pi + cut, 3 * np.pi - cut, 4000)
        knot = size * np.column_stack([np.sin(t) + 2 * np.sin(2 * t),
                                       np.cos(t) - 2 * np.cos(2 * t)])
        spread = math.radians(rng.uniform(10.0, 35.0))  # the tails leave diverging
        tail_length = rng.uniform(0.45, 0.8) * bound
        head = _tail(rng, knot[0], unit(knot[0] - knot[1]), tail_length, spread)[::-1]
        end = _tail(rng, knot[-1], unit(knot[-1] - knot[-2]), tail_length, -spread)
        flat = _arc_resample(np.vstack([head, knot, end]), SAMPLE_SPACING)
        angle = rng.uniform(0, 2 * np.pi)
        flat = flat @ np.array([[math.cos(angle), math.sin(angle)],
                                [-math.sin(angle), math.cos(angle)]])
        flat -= 0.5 * (flat.min(axis=0) + flat.max(axis=0))
        if np.linalg.norm(flat, axis=1).max() > bound:
            continue
        found = find_crossings_2d(flat)
        if len(found) != 3:
            continue
        passes = sorted((arc, k, first) for k, c in enumerate(found)
                        for arc, first in ((c[0], True), (c[1], False)))
        # Alternate over, under, over ... along the cable.
        over_first = [None] * 3
        for order, (_, k, first) in enumerate(passes):
            if first:
                over_first[k] = order % 2 == 0
        if any(over_first[k] == (order % 2 == 0) for order, (_, k, first) in enumerate(passes)
               if not first):
            continue  # not alternating: not a knot diagram
        lifted = _lift(flat, found, np.array(over_first), settings, False)
        if _check(lifted, found, settings, False) is None:
            return _finish(lifted, found, over_first, radius, False, "knot")
    raise LayoutError(f"no knot layout after {settings.max_tries} tries (seed {seed})")


def hanging_layout(*, seed=0, radius=0.004, extent=None, settings=LayoutSettings()):
    """A cable hanging in the air between two points, bent out of its vertical plane.

    A catenary between two anchors at different heights, its plane turned at random and its
    span bowed sideways, so its depth cannot be read from any single view. No crossings; the
    table (z = 0) lies below it.

    Parameters
    ----------
    seed : int, optional
    radius : float, optional
        Metres.
    extent : float, optional
        Metres; :func:`default_extent` if None.
    settings : LayoutSettings, optional

    Returns
    -------
    GroundTruth
        ``kind="hanging"``.
    """
    extent = default_extent(radius, 0) if extent is None else float(extent)
    _check_extent(extent, radius)
    rng = np.random.default_rng([seed, 0, 13])
    span = 0.8 * extent / radius
    for _ in range(settings.max_tries):
        x = np.linspace(-0.5 * span, 0.5 * span, 4000)
        stiffness = rng.uniform(0.25, 0.6) * span  # catenary parameter: smaller sags more
        lowest = rng.uniform(-0.15, 0.15) * span
        sag = stiffness * (np.cosh((x - lowest) / stiffness) - 1.0)
        z = 3.0 + rng.uniform(0.05, 0.2) * span + sag
        # Sideways, an S rather than an arc: an arc shaped like the sag would only tilt
        # the cable's plane, not take the cable out of it.
        along = x / span + 0.5
        bow = rng.uniform(0.1, 0.2) * span * np.sin(2 * np.pi * along) * rng.choice([-1.0, 1.0])
        drift = rng.uniform(0.0, 0.08) * span * np.sin(np.pi * along)
        points = np.column_stack([x, bow + drift, z])
        if z.max() > 0.6 * span:
            continue
        angle = rng.uniform(0, 2 * np.pi)
        rotation = np.array([[math.cos(angle), -math.sin(angle), 0.0],
                             [math.sin(angle), math.cos(angle), 0.0], [0.0, 0.0, 1.0]])
        points = _arc_resample(points @ rotation.T, SAMPLE_SPACING)
        points[:, :2] -= 0.5 * (points[:, :2].min(axis=0) + points[:, :2].max(axis=0))
        if _check(points, [], settings, False) is None:
            return _finish(points, [], [], radius, False, "hanging")
    raise LayoutError(f"no hanging layout after {settings.max_tries} tries (seed {seed})")

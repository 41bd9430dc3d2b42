"""Cubic Bézier curves with few control points that follow a reconstructed centreline.

An artist edits the cable as a Blender Bézier curve, so it should have as few control points
as keep it within a tolerance (0.1 r by default) of the reconstruction, measured densely along
the curve both ways, and it must keep the two strands of every crossing apart.

The fit walks along the centreline and makes each cubic piece as long as it can (an
exponential then binary search over where the piece ends), with knots on centreline samples,
tangents taken from the centreline (so the handles are aligned, G1, as Blender's "Aligned"
handles keep them while editing) and handle lengths by least squares with Newton
re-parametrisation (Schneider, "An algorithm for automatically fitting digitized curves",
Graphics Gems 1990). Greedy furthest reach gives the fewest pieces whenever a piece that fits
also fits when shortened, which holds for these smooth curves up to rounding.
"""

from dataclasses import dataclass

import numpy as np

from ..geometry.arrays import as_points
from ..geometry.polylines import arc_length
from ..settings import check_settings, setting

__all__ = ["BezierSettings", "BezierCurve", "fit_bezier", "fit_result_curves",
           "distance_to_polyline"]


@dataclass(frozen=True)
class BezierSettings:
    """How closely the editable curve follows the reconstruction.

    Attributes
    ----------
    tolerance : float
        Largest distance between the curve and the reconstructed centreline, in cable radii.
    crossing_gap : float
        Least distance between the two strands of a crossing, in cable radii (2 is touching).
    samples_per_piece : int
        Samples per cubic piece when the distance is checked.
    """

    tolerance: float = setting(0.1, above=0, unit="r")
    crossing_gap: float = setting(2.0, low=0, unit="r")
    samples_per_piece: int = setting(64, low=2)

    def __post_init__(self):
        check_settings(self)


@dataclass(frozen=True, eq=False)
class BezierCurve:
    """A G1 cubic Bézier spline: knots with a left and a right handle each.

    Attributes
    ----------
    knots, left, right : ndarray, shape (M, 3)
        Knot positions and their incoming and outgoing handles.
    closed : bool
        The last knot joins the first (a cyclic spline).
    knot_index : ndarray of int, shape (M,)
        The centreline sample each knot sits on.
    samples : int
        Number of centreline samples the curve was fitted to.
    """

    knots: np.ndarray
    left: np.ndarray
    right: np.ndarray
    closed: bool
    knot_index: np.ndarray
    samples: int = 0

    @property
    def n_pieces(self):
        """Number of cubic pieces."""
        return len(self.knots) if self.closed else len(self.knots) - 1

    def controls(self, piece):
        """The four control points of cubic ``piece``."""
        following = (piece + 1) % len(self.knots)
        return np.stack([self.knots[piece], self.right[piece], self.left[following],
                         self.knots[following]])

    def sample(self, per_piece=64):
        """Points along the curve, ``per_piece`` per cubic piece (both ends included once).

        Returns
        -------
        ndarray, shape (S, 3)
        """
        return self.sample_with_index(per_piece)[0]

    def sample_with_index(self, per_piece=64):
        """Points along the curve and, for each, about which centreline sample it follows.

        Returns
        -------
        points : ndarray, shape (S, 3)
        index : ndarray, shape (S,)
            Fractional centreline sample index, interpolated between the knots' samples.
        """
        u = np.linspace(0.0, 1.0, per_piece, endpoint=False)
        points, index = [], []
        for k in range(self.n_pieces):
            points.append(_bezier(self.controls(k), u))
            start, end = self.knot_index[k], self.knot_index[(k + 1) % len(self.knots)]
            if end <= start:  # the piece that closes a loop wraps past the last sample
                end = end + self.samples
            index.append(start + u * (end - start))
        if not self.closed:
            points.append(self.knots[-1:])
            index.append(self.knot_index[-1:].astype(float))
        return np.concatenate(points), np.concatenate(index)


def _bezier(controls, u):
    u = np.asarray(u, dtype=float)[:, None]
    v = 1.0 - u
    return (v ** 3 * controls[0] + 3 * v * v * u * controls[1] + 3 * v * u * u * controls[2]
            + u ** 3 * controls[3])


def _bezier_derivatives(controls, u):
    u = np.asarray(u, dtype=float)[:, None]
    v = 1.0 - u
    d1 = 3 * (v * v * (controls[1] - controls[0]) + 2 * v * u * (controls[2] - controls[1])
              + u * u * (controls[3] - controls[2]))
    d2 = 6 * (v * (controls[2] - 2 * controls[1] + controls[0])
              + u * (controls[3] - 2 * controls[2] + controls[1]))
    return d1, d2


def _segment_distance(points, a, b):
    """Distance from each of ``points`` to the segment from ``a`` to ``b`` (row-wise)."""
    ab = b - a
    length2 = np.einsum("ij,ij->i", ab, ab)
    t = np.einsum("ij,ij->i", points - a, ab) / np.where(length2 > 0, length2, 1.0)
    t = np.clip(t, 0.0, 1.0)
    return np.linalg.norm(points - (a + t[:, None] * ab), axis=1)


def distance_to_polyline(samples, polyline, *, closed=False):
    """Distance from each sample to the nearest segment of a polyline.

    Parameters
    ----------
    samples : array_like, shape (S, 3)
    polyline : array_like, shape (N, 3)
    closed : bool, optional

    Returns
    -------
    ndarray, shape (S,)
    """
    from scipy.spatial import cKDTree

    samples, polyline = as_points(samples), as_points(polyline)
    ends = np.roll(polyline, -1, axis=0) if closed else polyline[1:]
    starts = polyline if closed else polyline[:-1]
    lengths = np.linalg.norm(ends - starts, axis=1)
    mids = 0.5 * (starts + ends)
    # every segment within reach of the nearest midpoint's segment is a candidate
    reach = 0.5 * lengths.max() if len(lengths) else 0.0
    tree = cKDTree(mids)
    nearest, _ = tree.query(samples)
    best = np.full(len(samples), np.inf)
    candidates = tree.query_ball_point(samples, nearest + 2 * reach + 1e-12)
    rows = np.repeat(np.arange(len(samples)), [len(c) for c in candidates])
    cols = np.concatenate([np.asarray(c, dtype=int) for c in candidates])
    distance = _segment_distance(samples[rows], starts[cols], ends[cols])
    np.minimum.at(best, rows, distance)
    return best


def _tangents(points, closed):
    """Unit tangents of a polyline (central differences, one-sided at open ends)."""
    if closed:
        forward = np.roll(points, -1, axis=0) - np.roll(points, 1, axis=0)
    else:
        forward = np.empty_like(points)
        forward[1:-1] = points[2:] - points[:-2]
        forward[0], forward[-1] = points[1] - points[0], points[-1] - points[-2]
    norms = np.linalg.norm(forward, axis=1, keepdims=True)
    return forward / np.where(norms > 0, norms, 1.0)


class _PieceFitter:
    """Fits one cubic to a run of centreline samples with fixed end tangents."""

    def __init__(self, points, tangents, tolerance):
        self.points, self.tangents, self.tolerance = points, tangents, tolerance
        self.arc = arc_length(points)

    def fit(self, first, last):
        """Controls for samples ``first..last`` and whether they stay within tolerance."""
        data = self.points[first:last + 1]
        p0, p3 = data[0], data[-1]
        t1, t2 = self.tangents[first], -self.tangents[last]
        arc = self.arc[first:last + 1] - self.arc[first]
        chord = arc[-1]
        if chord <= 0:
            return np.stack([p0, p0, p3, p3]), True
        u = arc / chord
        controls = None
        for _ in range(4):
            controls = self._handles(data, u, p0, p3, t1, t2, chord)
            u = self._reparametrise(controls, data, u)
        return controls, self._within(controls, data, u, first, last)

    @staticmethod
    def _handles(data, u, p0, p3, t1, t2, chord):
        v = 1.0 - u
        b0, b1, b2, b3 = v ** 3, 3 * u * v * v, 3 * u * u * v, u ** 3
        a1, a2 = b1[:, None] * t1, b2[:, None] * t2
        residual = data - (b0 + b1)[:, None] * p0 - (b2 + b3)[:, None] * p3
        c = np.array([[np.sum(a1 * a1), np.sum(a1 * a2)], [np.sum(a1 * a2), np.sum(a2 * a2)]])
        x = np.array([np.sum(a1 * residual), np.sum(a2 * residual)])
        det = c[0, 0] * c[1, 1] - c[0, 1] * c[1, 0]
        alpha = None
        if abs(det) > 1e-12 * max(c[0, 0] * c[1, 1], 1e-300):
            alpha = np.array([x[0] * c[1, 1] - x[1] * c[0, 1], c[0, 0] * x[1] - c[1, 0] * x[0]])
            alpha /= det
        if alpha is None or np.any(alpha < 1e-6 * chord) or np.any(alpha > 2.0 * chord):
            alpha = np.full(2, chord / 3.0)  # Wu-Barsky: a third of the chord
        return np.stack([p0, p0 + alpha[0] * t1, p3 + alpha[1] * t2, p3])

    @staticmethod
    def _reparametrise(controls, data, u):
        """One Newton step of each sample's parameter towards its nearest curve point."""
        point = _bezier(controls, u)
        d1, d2 = _bezier_derivatives(controls, u)
        delta = point - data
        numerator = np.sum(delta * d1, axis=1)
        denominator = np.sum(d1 * d1, axis=1) + np.sum(delta * d2, axis=1)
        step = np.where(np.abs(denominator) > 1e-300, numerator / denominator, 0.0)
        u = np.clip(u - step, 0.0, 1.0)
        u[0], u[-1] = 0.0, 1.0
        return np.maximum.accumulate(u)

    def _within(self, controls, data, u, first, last):
        tolerance = self.tolerance[first:last + 1]
        if np.any(np.linalg.norm(_bezier(controls, u) - data, axis=1) > tolerance):
            return False
        # the curve between samples: 4 samples per interval, against the nearest 3 segments
        count = last - first
        fine = np.linspace(0.0, 1.0, 4 * count + 1)
        curve = _bezier(controls, fine)
        interval = np.clip(np.searchsorted(u, fine, side="right") - 1, 0, count - 1)
        best = np.full(len(fine), np.inf)
        for offset in (-1, 0, 1):
            k = np.clip(interval + offset, 0, count - 1)
            best = np.minimum(best, _segment_distance(curve, data[k], data[k + 1]))
        return bool(np.all(best <= np.minimum(tolerance[interval], tolerance[interval + 1])))


def fit_bezier(points, *, tolerance, closed=False, breaks=(), tolerances=None):
    """The cubic Bézier spline with the fewest knots that stays within ``tolerance``.

    Parameters
    ----------
    points : array_like, shape (N, 3)
        The centreline in order, N >= 2.
    tolerance : float
        Largest distance allowed between the spline and the polyline through ``points``
        (world units).
    closed : bool, optional
        The centreline is a loop.
    breaks : sequence of int, optional
        Samples that must be knots (e.g. crossings, so they stay exactly in place).
    tolerances : array_like, shape (N,), optional
        A tighter tolerance per sample (e.g. near crossings); ``tolerance`` caps it.

    Returns
    -------
    BezierCurve
    """
    points = as_points(points)
    if len(points) < 2:
        raise ValueError("a curve needs at least 2 points")
    if not tolerance > 0:
        raise ValueError("tolerance must be positive")
    n = len(points)
    limit = np.full(n, float(tolerance))
    if tolerances is not None:
        limit = np.minimum(limit, np.asarray(tolerances, dtype=float).reshape(n))
    # a few percent of margin so the dense check of the finished curve passes too
    limit = 0.97 * limit
    tangents = _tangents(points, closed)
    breaks = sorted({int(b) % n for b in breaks})
    start = 0
    if closed:
        start = breaks[0] if breaks else 0
        order = np.r_[np.arange(start, n), np.arange(0, start), start]
        points, tangents, limit = points[order], tangents[order], limit[order]
        breaks = sorted({(b - start) % n for b in breaks} | {n})
    else:
        breaks = sorted(set(breaks) | {n - 1})
    fitter = _PieceFitter(points, tangents, limit)
    knots, pieces = [0], []
    first = 0
    for stop in breaks:
        while first < stop:
            last, controls = _furthest(fitter, first, stop)
            pieces.append(controls)
            knots.append(last)
            first = last
    knots = np.array(knots)
    positions = points[knots]
    left, right = positions.copy(), positions.copy()
    for k, controls in enumerate(pieces):
        right[k], left[k + 1] = controls[1], controls[2]
    if closed:  # the last knot is the first one again
        left[0] = left[-1]
        positions, left, right, knots = positions[:-1], left[:-1], right[:-1], knots[:-1]
        knots = (knots + start) % n
    else:  # the outer handles of the ends mirror the inner ones (ready to extend the cable)
        left[0] = 2 * positions[0] - right[0]
        right[-1] = 2 * positions[-1] - left[-1]
    return BezierCurve(positions, left, right, bool(closed), knots, n)


def _furthest(fitter, first, stop):
    """The furthest sample a single cubic from ``first`` reaches (at most ``stop``)."""
    best, (best_controls, ok) = first + 1, fitter.fit(first, first + 1)
    if not ok:  # samples too far apart for the tolerance: a straight piece (a corner)
        a, b = fitter.points[first], fitter.points[first + 1]
        best_controls = np.stack([a, (2 * a + b) / 3, (a + 2 * b) / 3, b])
    step, low, high = 1, first + 1, None
    while True:  # exponential search for a sample the piece cannot reach
        candidate = min(first + 2 * step, stop)
        controls, ok = fitter.fit(first, candidate)
        if not ok:
            high = candidate
            break
        best, best_controls, low = candidate, controls, candidate
        if candidate == stop:
            return best, best_controls
        step *= 2
    while high - low > 1:  # binary search between the last reach and the first miss
        middle = (low + high) // 2
        controls, ok = fitter.fit(first, middle)
        if ok:
            best, best_controls, low = middle, controls, middle
        else:
            high = middle
    return best, best_controls


def fit_result_curves(result, *, settings=BezierSettings()):
    """Editable Bézier curves for every path of a result, crossings kept apart.

    Each crossing's two samples become knots. Where the reconstruction's strands are less
    than ``crossing_gap`` radii plus the tolerance apart, the curve is fitted to strands eased
    apart (a smooth bump on each, along the line between them, of at most the tolerance), so
    the curve keeps ``crossing_gap`` radii while it stays within the tolerance of the
    reconstruction; near a crossing the tolerance left over is shared so the strands cannot
    come back closer.

    Parameters
    ----------
    result : Result
    settings : BezierSettings, optional

    Returns
    -------
    curves : list of BezierCurve
        One per path.
    report : dict
        ``control_points`` (knots over all curves), ``max_error`` (largest distance to the
        reconstruction, in r), ``crossing_gaps`` (least strand distance per crossing, in r,
        curve and reconstruction), ``warnings`` (crossings whose strands the curve could not
        keep ``crossing_gap`` radii apart within the tolerance).
    """
    r = result.radius
    tolerance = settings.tolerance * r
    reach = 4.0 * r
    gaps = [_strand_gap(result, crossing, reach) for crossing in result.crossings]
    extra = np.zeros(len(gaps))
    for _ in range(4):  # ease apart further wherever the curve still comes too close
        curves = _fit_eased(result, gaps, extra, tolerance, reach, settings)
        curve_gaps = np.array([_curve_gap(curves, result, crossing, reach,
                                          settings.samples_per_piece)
                               for crossing in result.crossings])
        short = settings.crossing_gap * r - curve_gaps
        if not np.any(short > 0):
            break
        extra = np.where(short > 0, extra + short + 0.01 * r, extra)
    errors = []
    for curve, path in zip(curves, result.paths):
        dense = curve.sample(settings.samples_per_piece)
        there = distance_to_polyline(dense, path.points, closed=path.closed).max()
        back = distance_to_polyline(path.points, dense, closed=path.closed).max()
        errors.append(max(there, back) / r)
    warnings = [f"the curve's strands at crossing {number + 1} are {gap / r:.2f} r apart, "
                f"less than {settings.crossing_gap:g} r: they may touch"
                for number, (gap, missing) in enumerate(zip(curve_gaps, short)) if missing > 0]
    report = {"control_points": int(sum(len(c.knots) for c in curves)),
              "max_error": float(max(errors)),
              "crossing_gaps": [(float(c) / r, g / r) for c, g in zip(curve_gaps, gaps)],
              "warnings": warnings}
    return curves, report


def _fit_eased(result, gaps, extra, tolerance, reach, settings):
    """The curves of :func:`fit_result_curves` with each crossing's strands eased apart."""
    r = result.radius
    breaks = [[] for _ in result.paths]
    limits = [np.full(len(p.points), tolerance) for p in result.paths]
    targets = [np.array(p.points, dtype=float) for p in result.paths]
    for crossing, gap, more in zip(result.crossings, gaps, extra):
        # ease the strands apart so they are crossing_gap + tolerance apart, each by `push`
        push = min(max(0.5 * (settings.crossing_gap * r + tolerance - gap), 0.0) + more,
                   tolerance)
        over = result.paths[crossing.over.path].points[crossing.over.index]
        under = result.paths[crossing.under.path].points[crossing.under.index]
        apart = (over - under) / max(np.linalg.norm(over - under), 1e-12 * r)
        # each strand may then move half the slack towards the other, within the tolerance
        allowed = max(min(0.5 * (gap + 2 * push - settings.crossing_gap * r),
                          tolerance - push), 0.02 * tolerance)
        for ref, sign in ((crossing.over, 1.0), (crossing.under, -1.0)):
            breaks[ref.path].append(ref.index)
            path = result.paths[ref.path]
            offsets = _window(path, ref.index, reach)
            where = (ref.index + offsets) % len(path.points)
            arc = _arc_from(path, ref.index, offsets)
            # flat over the middle half, easing out to nothing at `reach`
            taper = np.clip((arc - 0.5 * reach) / (0.5 * reach), 0.0, 1.0)
            weight = np.cos(0.5 * np.pi * taper) ** 2
            targets[ref.path][where] += sign * push * weight[:, None] * apart
            limits[ref.path][where] = np.minimum(limits[ref.path][where], allowed)
    return [fit_bezier(targets[number], tolerance=tolerance, closed=path.closed,
                       breaks=breaks[number], tolerances=limits[number])
            for number, path in enumerate(result.paths)]


def _arc_from(path, index, offsets):
    """Arc length from sample ``index`` to each of ``index + offsets`` (offsets in order)."""
    points, n = path.points, len(path.points)
    where = (index + offsets) % n
    arc = arc_length(points[where])
    return np.abs(arc - arc[list(offsets).index(0)])


def _window(path, index, reach):
    """Offsets (from sample ``index``, in order) of the samples within arc length ``reach``."""
    points, n = path.points, len(path.points)
    steps = np.linalg.norm(np.diff(points, axis=0), axis=1)  # steps[i]: sample i to i + 1
    if path.closed:
        steps = np.append(steps, np.linalg.norm(points[0] - points[-1]))
    offsets = [0]
    for direction in (1, -1):
        walked, k = 0.0, 0
        while True:
            following = k + direction
            if path.closed and abs(following) > (n - 1) // 2:
                break
            if not path.closed and not 0 <= index + following < n:
                break
            walked += steps[(index + min(k, following)) % len(steps)]
            if walked > reach:
                break
            k = following
            offsets.append(k)
    return np.array(sorted(offsets))


def _strand(path, index, reach):
    """The polyline of ``path`` within arc length ``reach`` of sample ``index``, in order."""
    return path.points[(index + _window(path, index, reach)) % len(path.points)]


def _strand_gap(result, crossing, reach):
    """Least distance between the two strands of a crossing in the reconstruction."""
    a = _strand(result.paths[crossing.over.path], crossing.over.index, reach)
    b = _strand(result.paths[crossing.under.path], crossing.under.index, reach)
    return _polyline_gap(a, b)


def _polyline_gap(a, b, per_segment=8):
    """Least distance between two polylines (the first one densified)."""
    u = np.linspace(0.0, 1.0, per_segment, endpoint=False)[:, None, None]
    dense = (a[:-1][None] * (1 - u) + a[1:][None] * u).reshape(-1, 3)
    dense = np.vstack([dense, a[-1:]])
    return float(distance_to_polyline(dense, b).min())


def _curve_gap(curves, result, crossing, reach, per_piece):
    """Least distance between the two strands of a crossing on the fitted curves."""
    strands = []
    for ref in (crossing.over, crossing.under):
        path, curve = result.paths[ref.path], curves[ref.path]
        n = len(path.points)
        window = _window(path, ref.index, reach)
        dense, at = curve.sample_with_index(per_piece)
        offset = at - ref.index
        if path.closed:
            offset = (offset + n / 2) % n - n / 2
        keep = (offset >= window[0]) & (offset <= window[-1])
        strands.append(dense[keep][np.argsort(offset[keep], kind="stable")])
    return _polyline_gap(*strands)

"""How good a reconstruction is, measured against the ground truth of a synthetic scene.

Every length reported here is in units of the TRUE cable radius ``r`` (``truth.radius``), except
:attr:`Metrics.radius_error`, which is relative. The reconstruction may live in another frame
than the truth (cameras from SfM); :func:`align_result_to_truth` brings it into the truth's frame
through the cameras both share, and ``evaluate(..., align=True)`` does that first.

What is measured (see :class:`Metrics`):

* geometry: how far the reconstructed centreline lies from the true one (accuracy) and how much
  of the true cable it covers (completeness);
* topology: whether the reconstruction is one path that follows the cable in order, without
  jumping from one strand to another (wrong connections);
* crossings: whether the reconstructed strands go over and under as the true ones do, judged on
  the reconstructed geometry, and whether the result's crossing list says so.

How a reconstructed sample is placed on the true cable: each sample is mapped to the arc-length
position of its nearest point on the true centreline. Where that nearest point is ambiguous (a
flattened or slightly wrong crossing puts a sample of one strand nearer to the other strand), the
sample keeps following its strand as long as it lies at most ``MetricSettings.ambiguity`` farther
from the continuation of that strand than from its nearest point; only a sample that clearly left
its strand counts as a jump. A path's direction along the cable is that of most of its steps (a
reconstruction may run backwards), and positions on a closed cable wrap around its seam.
"""

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from ..geometry.similarity import align_cameras
from ..io.ground_truth import GroundTruth
from ..io.result import CablePath, Crossing, Result
from ..settings import check_settings, setting

__all__ = ["MetricSettings", "CrossingCheck", "Metrics", "align_result_to_truth", "evaluate"]


@dataclass(frozen=True)
class MetricSettings:
    """Tunables of :func:`evaluate`; every length in units of the true radius ``r``.

    Attributes
    ----------
    sample_spacing : float
        Largest spacing of the dense samples taken along the reconstruction (and along the truth
        for completeness).
    truth_spacing : float
        Spacing of the truth samples that seed nearest-point queries (distances are then refined
        exactly on the polyline's segments).
    coverage : float
        A true sample within this distance of the reconstruction counts as covered.
    jump : float
        A step whose true arc position moves back by more than this, or forward by more than
        the step's own length plus this, is a wrong connection; so is a path running back along
        the cable by more than this from the farthest point it reached (doubling back).
    ambiguity : float
        A sample keeps following its current strand while it lies at most this much farther
        from that strand's continuation than from its nearest true point.
    crossing_arc : float
        Reconstructed samples within this arc distance of a true crossing's strand sample
        describe that strand at the crossing ...
    crossing_reach : float
        ... if they also lie within this 3D distance of it.
    crossing_height : float
        The over strand must be at least this much higher than the under strand.
    listed_reach : float
        A listed crossing (``result.crossings``) describes a true crossing within this distance,
        and its ``over`` sample must lie within this distance of the true strand it names.
    """

    sample_spacing: float = setting(0.1, above=0, unit="r")
    truth_spacing: float = setting(0.02, above=0, unit="r")
    coverage: float = setting(1.0, above=0, unit="r")
    jump: float = setting(2.0, above=0, unit="r")
    ambiguity: float = setting(2.5, low=0, unit="r")
    crossing_arc: float = setting(1.5, above=0, unit="r")
    crossing_reach: float = setting(2.0, above=0, unit="r")
    crossing_height: float = setting(1.0, low=0, unit="r")
    listed_reach: float = setting(3.0, above=0, unit="r")

    def __post_init__(self):
        check_settings(self)


def align_result_to_truth(result, truth):
    """Bring a result into the truth's frame through the cameras both hold.

    Cameras are matched by image name; the similarity is fitted by :func:`align_cameras`.

    Parameters
    ----------
    result : Result
    truth : GroundTruth

    Returns
    -------
    aligned : Result
        Path points, per-point radii, radius, crossing positions and cameras transformed; the
        rest unchanged.
    similarity : Similarity
        The transform from the result's frame to the truth's (``scale`` is truth length per
        result length).

    Raises
    ------
    ValueError
        Fewer than 3 camera names in common, or their centres are collinear.
    """
    _check_types(result, truth)
    true_centres = {camera.name: camera.center for camera in truth.cameras}
    names = [camera.name for camera in result.cameras if camera.name in true_centres]
    if len(set(names)) < 3:
        raise ValueError(
            f"aligning to the truth needs at least 3 cameras with the same image name in the "
            f"result ({len(result.cameras)} cameras) and the truth ({len(truth.cameras)} "
            f"cameras); {len(set(names))} in common")
    names = set(names)
    try:
        similarity = align_cameras([c for c in result.cameras if c.name in names],
                                   [c for c in truth.cameras if c.name in names])
    except ValueError as error:
        raise ValueError(f"cannot align the result's cameras to the truth's: {error}") from None
    paths = tuple(CablePath(similarity.apply(path.points),
                            None if path.radii is None else path.radii * similarity.scale,
                            path.closed)
                  for path in result.paths)
    crossings = tuple(Crossing(similarity.apply(c.position), c.over, c.under, c.confidence)
                      for c in result.crossings)
    cameras = tuple(similarity.apply_camera(camera) for camera in result.cameras)
    aligned = Result(radius=result.radius * similarity.scale, paths=paths, crossings=crossings,
                     cameras=cameras, units=result.units, warnings=result.warnings,
                     timings=dict(result.timings))
    return aligned, similarity


# -- polylines with exact nearest-point queries -------------------------------------------------

class _Polylines:
    """Segments of one or more polylines, densely sampled, with exact nearest-point queries.

    Dense samples of each path are contiguous and in order; each vertex of a path is a dense
    sample. ``weights`` give each dense sample its share of the length (trapezoid rule), and
    ``steps`` the length from each dense sample to the next one of its path (for a closed path
    the last step is the closing one).
    """

    def __init__(self, paths, spacing):
        starts, ends, seg_arc, prev, nxt = [], [], [], [], []
        dense, dense_seg, weights, steps = [], [], [], []
        self.slices, self.closed, self.vertex_dense, self.lengths = [], [], [], []
        seg_offset = dense_offset = 0
        for points, closed in paths:
            a = points if closed else points[:-1]
            b = np.roll(points, -1, axis=0) if closed else points[1:]
            m = len(a)
            vectors = b - a
            lengths = np.linalg.norm(vectors, axis=1)
            counts = np.maximum(1, np.ceil(lengths / spacing).astype(int))
            seg_of = np.repeat(np.arange(m), counts)
            first = np.concatenate([[0], np.cumsum(counts)[:-1]])
            t = (np.arange(counts.sum()) - first[seg_of]) / counts[seg_of]
            pts = a[seg_of] + t[:, None] * vectors[seg_of]
            sub = (lengths / counts)[seg_of]  # step from each sample to the next
            if not closed:
                pts = np.vstack([pts, b[-1:]])
                seg_of = np.append(seg_of, m - 1)
                w = np.zeros(len(pts))
                w[:-1] += 0.5 * sub
                w[1:] += 0.5 * sub
                vertex = np.append(first, len(pts) - 1)
            else:
                w = 0.5 * sub + 0.5 * np.roll(sub, 1)
                vertex = first
            index = np.arange(m)
            if closed:
                prev_local, next_local = np.roll(index, 1), np.roll(index, -1)
            else:
                prev_local = np.maximum(index - 1, 0)
                next_local = np.minimum(index + 1, m - 1)
            starts.append(a)
            ends.append(b)
            seg_arc.append(np.concatenate([[0.0], np.cumsum(lengths)[:-1]]))
            prev.append(prev_local + seg_offset)
            nxt.append(next_local + seg_offset)
            dense.append(pts)
            dense_seg.append(seg_of + seg_offset)
            weights.append(w)
            steps.append(sub)
            self.slices.append(slice(dense_offset, dense_offset + len(pts)))
            self.closed.append(bool(closed))
            self.vertex_dense.append(vertex + dense_offset)
            self.lengths.append(float(lengths.sum()))
            seg_offset += m
            dense_offset += len(pts)
        self.starts, self.ends = np.vstack(starts), np.vstack(ends)
        self.vectors = self.ends - self.starts
        self.seg_len2 = np.sum(self.vectors ** 2, axis=1)
        self.seg_len = np.sqrt(self.seg_len2)
        self.seg_arc = np.concatenate(seg_arc)
        self.prev, self.next = np.concatenate(prev), np.concatenate(nxt)
        self.dense = np.vstack(dense)
        self.dense_seg = np.concatenate(dense_seg)
        self.weights = np.concatenate(weights)
        self.steps = steps
        self.tree = cKDTree(self.dense)

    def _project(self, points, candidates):
        """Nearest point of ``candidates`` (Q, K) segments to each of ``points`` (Q, 3)."""
        a = self.starts[candidates]
        v = self.vectors[candidates]
        len2 = self.seg_len2[candidates]
        offset = points[:, None, :] - a
        with np.errstate(divide="ignore", invalid="ignore"):
            t = np.where(len2 > 0, np.einsum("qkj,qkj->qk", offset, v) / len2, 0.0)
        t = np.clip(t, 0.0, 1.0)
        distance = np.linalg.norm(offset - t[..., None] * v, axis=2)
        best = np.argmin(distance, axis=1)
        rows = np.arange(len(points))
        return distance[rows, best], candidates[rows, best], t[rows, best]

    def nearest(self, points, *, k=4):
        """Exact distance, segment and arc position (along its path) of the nearest point."""
        points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        k = min(k, len(self.dense))
        _, idx = self.tree.query(points, k=k)
        idx = idx.reshape(len(points), k)
        seg = self.dense_seg[idx]
        candidates = np.concatenate([seg, self.prev[seg], self.next[seg]], axis=1)
        distance, seg, t = self._project(points, candidates)
        return distance, seg, self.seg_arc[seg] + t * self.seg_len[seg]


class _TrueLine(_Polylines):
    """The true cables with arc-window projections for strand following; arc positions are
    those of :attr:`engine.io.ground_truth.GroundTruth.arc_length` (cables far apart)."""

    def __init__(self, truth, spacing):
        super().__init__(truth.lines, spacing)
        arc = truth.arc_length
        offsets = [np.full(len(points) - (0 if closed else 1), arc[cable.start])
                   for (points, closed), cable in zip(truth.lines, truth.cables)]
        self.seg_arc = self.seg_arc + np.concatenate(offsets)
        self.seg_cable = np.concatenate([np.full(len(offset), number)
                                         for number, offset in enumerate(offsets)])
        self.length = float(self.seg_arc[-1] + self.seg_len[-1])
        self.is_closed = truth.closed
        self.seg_arc_twice = np.concatenate([self.seg_arc, self.seg_arc + self.length])

    def wrap(self, delta):
        """Signed arc difference; across the seam of a closed cable it is the short way."""
        if self.is_closed:
            return (delta + 0.5 * self.length) % self.length - 0.5 * self.length
        return delta

    def arc_distance(self, a, b):
        return np.abs(self.wrap(np.asarray(a) - b))

    def project_window(self, point, low, high):
        """Nearest point to ``point`` among the segments covering arc ``[low, high]``."""
        count = len(self.seg_arc)
        if self.is_closed:
            if high - low >= self.length:
                segments = np.arange(count)
            else:
                low_wrapped = low % self.length
                high_wrapped = low_wrapped + (high - low)
                first = np.searchsorted(self.seg_arc_twice, low_wrapped, side="right") - 1
                last = np.searchsorted(self.seg_arc_twice, high_wrapped, side="right") - 1
                segments = np.arange(first, last + 1) % count
        else:
            low, high = max(low, 0.0), min(high, self.length)
            first = max(np.searchsorted(self.seg_arc, low, side="right") - 1, 0)
            last = max(np.searchsorted(self.seg_arc, high, side="right") - 1, first)
            segments = np.arange(first, min(last, count - 1) + 1)
        distance, seg, t = self._project(point[None, :], segments[None, :])
        return float(distance[0]), float(self.seg_arc[seg[0]] + t[0] * self.seg_len[seg[0]])


# -- metrics ------------------------------------------------------------------------------------

@dataclass(frozen=True)
class CrossingCheck:
    """How the reconstruction handles one true crossing.

    Attributes
    ----------
    index : int
        Index into ``truth.crossings``.
    right : bool
        The reconstructed over strand lies at least ``crossing_height`` r above the under one.
    height_difference : float
        Mean height of the reconstructed over strand minus that of the under strand, in r
        (NaN when one of them is missing near the crossing).
    listed : bool or None
        A crossing in ``result.crossings`` lies near and names the right strand as over (True)
        or the under strand (False); None when none lies near.
    confidence : float or None
        The confidence of the nearest listed crossing within reach (None when none lies near).
    """

    index: int
    right: bool
    height_difference: float
    listed: object
    confidence: object = None


@dataclass(frozen=True)
class Metrics:
    """Quality of a reconstruction against the ground truth (lengths in true radii r).

    Attributes
    ----------
    accuracy_mean, accuracy_p95, accuracy_max : float
        Distance from the reconstructed centreline to the true one: length-weighted mean, 95th
        percentile and maximum.
    completeness : float
        Fraction of the true centreline's length within ``coverage`` (1 r) of the reconstruction.
    one_path : bool
        Exactly one path per true cable (each on its own cable) and no wrong connection.
    path_count : int
    wrong_connections : int
        Steps along a reconstructed path that jump along the true cable, plus the times a path
        doubles back along it (see :class:`MetricSettings`). A path may run either way.
    crossings_right, crossings_total : int
        True crossings whose over/under the reconstructed geometry gets right, and all of them.
    crossing_details : tuple of CrossingCheck
    radius_error : float
        ``|result.radius - truth.radius| / truth.radius`` (relative, not in r).
    aligned : bool
        A similarity alignment through the cameras was applied first.
    scale : float
        Its scale (truth length per result length), 1.0 without alignment.
    """

    accuracy_mean: float
    accuracy_p95: float
    accuracy_max: float
    completeness: float
    one_path: bool
    path_count: int
    wrong_connections: int
    crossings_right: int
    crossings_total: int
    crossing_details: tuple
    radius_error: float
    aligned: bool
    scale: float

    def as_row(self):
        """The scalar fields as a dict (for a table), ``crossing_details`` left out."""
        return {name: getattr(self, name) for name in self.__dataclass_fields__
                if name != "crossing_details"}


def _check_types(result, truth):
    if not isinstance(result, Result):
        raise TypeError(f"result must be a Result, not {type(result).__name__}")
    if not isinstance(truth, GroundTruth):
        raise TypeError(f"truth must be a GroundTruth, not {type(truth).__name__}")


def _weighted_percentile(values, weights, fraction):
    order = np.argsort(values)
    cumulative = np.cumsum(weights[order])
    index = np.searchsorted(cumulative, fraction * cumulative[-1])
    return float(values[order][min(index, len(values) - 1)])


def _follow_path(line, points, arc, distance, steps, closed, settings, r):
    """Arc positions along one reconstructed path, following strands; and its wrong connections.

    A wrong connection is a step whose arc position jumps (see :class:`MetricSettings`), or a
    reversal: the path running back along the cable by more than ``jump`` from the farthest
    point it reached (a path that doubles back over itself has no single jumping step).
    """
    count = len(points)
    position = arc.copy()
    if count < 2:
        return position, 0
    raw = line.wrap(np.diff(arc))
    median = np.median(raw)
    sign = 1.0 if median > 0 else -1.0 if median < 0 else (1.0 if raw.sum() >= 0 else -1.0)
    jump = settings.jump * r
    ambiguity = settings.ambiguity * r

    def is_jump(delta, spacing):
        return (delta > spacing + jump) | (delta < -jump)

    # Follow the strands: where the nearest position jumps, keep the sample on its strand if it
    # lies close enough to the strand's continuation (a flattened or mislaid crossing).
    i = 1
    while i < count:
        delta = sign * line.wrap(position[i:] - position[i - 1:-1])
        found = np.flatnonzero(is_jump(delta, steps[i - 1:count - 1]))
        if len(found) == 0:
            break
        i += int(found[0])
        while i < count:  # the step i-1 -> i jumps: does the sample still fit its strand?
            step = steps[i - 1]
            low, high = (position[i - 1] - jump, position[i - 1] + step + jump) if sign > 0 \
                else (position[i - 1] - step - jump, position[i - 1] + jump)
            follow_distance, follow_arc = line.project_window(points[i], low, high)
            if follow_distance > distance[i] + ambiguity:
                i += 1  # a real jump
                break
            position[i] = follow_arc % line.length if line.is_closed else follow_arc
            i += 1
            if i < count and not is_jump(sign * line.wrap(position[i] - position[i - 1]),
                                         steps[i - 1]):
                break

    # Count the jumps, the closing step of a closed path included.
    sequence = np.append(position, position[0]) if closed else position
    delta = sign * line.wrap(np.diff(sequence))
    jumps = is_jump(delta, steps[:len(delta)])
    wrong = int(np.count_nonzero(jumps))

    # Count the reversals in each stretch between jumps.
    bounds = np.concatenate([[-1], np.flatnonzero(jumps), [len(delta)]])
    for first, stop in zip(bounds[:-1], bounds[1:]):
        wrong += _reversals(delta[first + 1:stop], jump)
    return position, wrong


def _reversals(delta, limit):
    """How often a run of arc steps turns back by more than ``limit`` from its farthest point.

    The run starts out the way it first moves by more than ``limit``; after each reversal it
    runs the other way.
    """
    travel = np.concatenate([[0.0], np.cumsum(delta)])
    moved = np.flatnonzero(np.abs(travel) > limit)
    if len(moved) == 0:
        return 0
    start, count = 0, 0
    direction = 1.0 if travel[moved[0]] > 0 else -1.0
    for _ in range(len(travel)):
        run = direction * (travel[start:] - travel[start])
        back = np.flatnonzero(run < np.maximum.accumulate(run) - limit)
        if len(back) == 0:
            break
        count += 1
        start += int(np.argmax(run[:back[0] + 1]))
        direction = -direction
    return count


def _crossing_checks(truth, line, recon, positions, result, settings, r):
    """Per true crossing: geometry right or wrong, height difference, what the list says."""
    up = truth.up
    heights = recon.dense @ up
    true_arc = truth.arc_length
    checks = []
    for k, crossing in enumerate(truth.crossings):
        means = []
        for sample in (crossing.over, crossing.under):
            near = (line.arc_distance(positions, true_arc[sample]) <= settings.crossing_arc * r)
            near &= np.linalg.norm(recon.dense - truth.centreline[sample], axis=1) \
                <= settings.crossing_reach * r
            means.append(heights[near].mean() if near.any() else np.nan)
        difference = (means[0] - means[1]) / r
        right = bool(np.isfinite(difference) and difference >= settings.crossing_height)
        checks.append(CrossingCheck(k, right, float(difference),
                                    *_listed(truth, crossing, line, recon, positions, result,
                                             settings, r)))
    return tuple(checks)


def _listed(truth, crossing, line, recon, positions, result, settings, r):
    """What the listed crossings say about ``crossing``, and the nearest one's confidence."""
    reach = settings.listed_reach * r
    place = truth.crossing_position(crossing)
    true_arc = truth.arc_length
    answer = None
    near = [entry for entry in result.crossings
            if np.linalg.norm(entry.position - place) <= reach]
    confidence = (min(near, key=lambda e: np.linalg.norm(e.position - place)).confidence
                  if near else None)
    for entry in near:
        dense_index = recon.vertex_dense[entry.over.path][entry.over.index]
        point, arc = recon.dense[dense_index], positions[dense_index]
        to_over = line.arc_distance(arc, true_arc[crossing.over])
        to_under = line.arc_distance(arc, true_arc[crossing.under])
        if to_over <= to_under and np.linalg.norm(point - truth.centreline[crossing.over]) <= reach:
            return True, confidence
        if to_under < to_over and np.linalg.norm(point - truth.centreline[crossing.under]) <= reach:
            answer = False
    return answer, confidence


def _one_path_per_cable(line, recon, seg, cables):
    """As many paths as true cables, each on a cable of its own (the one most of its samples
    lie nearest to)."""
    if len(recon.slices) != cables:
        return False
    owners = {int(np.bincount(line.seg_cable[seg[part]], minlength=cables).argmax())
              for part in recon.slices}
    return len(owners) == cables


def evaluate(result, truth, *, align=False, settings=None):
    """Measure a reconstruction against the ground truth.

    Parameters
    ----------
    result : Result
        The reconstruction, in the truth's frame unless ``align``.
    truth : GroundTruth
    align : bool, optional
        First bring the result into the truth's frame with :func:`align_result_to_truth`
        (needs at least 3 cameras named alike in both).
    settings : MetricSettings, optional

    Returns
    -------
    Metrics
        Lengths in units of the true radius.

    Raises
    ------
    ValueError
        ``align`` without enough common cameras.
    """
    _check_types(result, truth)
    settings = MetricSettings() if settings is None else settings
    if not isinstance(settings, MetricSettings):
        raise TypeError("settings must be a MetricSettings")
    if not (np.isfinite(truth.radius) and truth.radius > 0):
        raise ValueError("truth.radius must be a positive number")
    scale = 1.0
    if align:
        result, similarity = align_result_to_truth(result, truth)
        scale = similarity.scale
    r = truth.radius

    line = _TrueLine(truth, settings.truth_spacing * r)
    recon = _Polylines([(path.points, path.closed) for path in result.paths],
                       settings.sample_spacing * r)

    # Accuracy: reconstruction samples to the true polyline.
    distance, seg, arc = line.nearest(recon.dense)
    weights = recon.weights if recon.weights.sum() > 0 else np.ones(len(recon.dense))
    accuracy = distance / r
    accuracy_mean = float(np.sum(accuracy * weights) / weights.sum())
    accuracy_p95 = _weighted_percentile(accuracy, weights, 0.95)
    accuracy_max = float(accuracy.max())

    # Completeness: true samples to the reconstructed polylines.
    coarse = _Polylines(truth.lines, settings.sample_spacing * r)
    gap, _, _ = recon.nearest(coarse.dense)
    covered = gap <= settings.coverage * r
    completeness = float(coarse.weights[covered].sum() / coarse.weights.sum()) \
        if coarse.weights.sum() > 0 else float(covered.mean())

    # Topology: follow each path along the true cable.
    positions = arc.copy()
    wrong = 0
    for p, part in enumerate(recon.slices):
        positions[part], count = _follow_path(line, recon.dense[part], arc[part], distance[part],
                                              recon.steps[p], recon.closed[p], settings, r)
        wrong += count

    details = _crossing_checks(truth, line, recon, positions, result, settings, r)
    return Metrics(
        accuracy_mean=accuracy_mean,
        accuracy_p95=accuracy_p95,
        accuracy_max=accuracy_max,
        completeness=completeness,
        one_path=_one_path_per_cable(line, recon, seg, len(truth.cables)) and wrong == 0,
        path_count=len(result.paths),
        wrong_connections=int(wrong),
        crossings_right=sum(check.right for check in details),
        crossings_total=len(details),
        crossing_details=details,
        radius_error=abs(result.radius - truth.radius) / truth.radius,
        aligned=bool(align),
        scale=float(scale),
    )

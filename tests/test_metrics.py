"""engine.evaluation.metrics on small analytic ground truths: a looping cable on a table and a
closed ring."""


import numpy as np
import pytest
from scipy.optimize import brentq

from conftest import look_at_camera
from engine import CablePath, Crossing, Result, StrandRef
from engine.evaluation.metrics import Metrics, MetricSettings, align_result_to_truth, evaluate
from engine.geometry.similarity import Similarity, align_similarity
from engine.io.ground_truth import GroundTruth, TrueCrossing

R = 0.01       # the true radius; the shapes below are built in units of R and scaled
SPACING = 0.25  # truth sample spacing, in R
BUMP = 8.0      # half-width (arc length, in R) of the lift of an over strand
LIFT = 2.0      # the over strand's centre is this much higher than the under strand's, in R


def _bump(offset):
    x = np.clip(np.abs(offset) / BUMP, 0.0, 1.0)
    return np.cos(0.5 * np.pi * x) ** 2


def _resample(points, spacing):
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(points, axis=0), axis=1))])
    targets = np.arange(0.0, arc[-1], spacing)
    return np.column_stack([np.interp(targets, arc, points[:, k]) for k in range(2)]), arc


def looping_truth(loops=2, *, a=3.0, b=8.0):
    """A prolate cycloid ``x = a s - b sin s, y = -b cos s`` on a table (centre at z = r).

    Each period makes one loop that crosses itself once, at ``s = 2 pi k -+ s0`` with
    ``sin s0 = (a / b) s0``; the first pass is over on even loops, the second on odd ones. The
    over strand is lifted by ``LIFT`` r with a smooth bump.
    """
    s0 = brentq(lambda s: np.sin(s) - a / b * s, 1e-3, np.pi)
    s = np.linspace(-np.pi, 2 * np.pi * (loops - 1) + np.pi, 40000 * loops)
    fine = np.column_stack([a * s - b * np.sin(s), -b * np.cos(s)])
    xy, fine_arc = _resample(fine, SPACING)
    arc = np.arange(len(xy)) * SPACING
    height = np.ones(len(xy))
    crossings = []
    for k in range(loops):
        first, second = np.interp([2 * np.pi * k - s0, 2 * np.pi * k + s0], s, fine_arc)
        i, j = int(round(first / SPACING)), int(round(second / SPACING))
        over, under = (i, j) if k % 2 == 0 else (j, i)
        height += LIFT * _bump(arc - arc[over])
        crossings.append(TrueCrossing(over=over, under=under, angle=80.0))
    points = np.column_stack([xy, height]) * R
    return GroundTruth(points, R, tuple(crossings), closed=False, kind="test")


def ring_truth(radius=20.0):
    """A closed circle of ``radius`` r lying on the table, no crossings."""
    count = int(round(2 * np.pi * radius / SPACING))
    s = np.arange(count) * 2 * np.pi / count
    points = np.column_stack([radius * np.cos(s), radius * np.sin(s), np.ones(count)]) * R
    return GroundTruth(points, R, (), closed=True, kind="test")


def listed_crossings(truth, *, reverse=False, flip=()):
    """The truth's crossings as a result would list them (for a path that is the centreline)."""
    count = len(truth.centreline)
    entries = []
    for k, crossing in enumerate(truth.crossings):
        over, under = crossing.over, crossing.under
        if reverse:
            over, under = count - 1 - over, count - 1 - under
        if k in flip:
            over, under = under, over
        entries.append(Crossing(truth.crossing_position(crossing), StrandRef(0, over),
                                StrandRef(0, under), 0.9))
    return tuple(entries)


def make_result(*paths, radius=R, crossings=(), cameras=(), closed=False):
    return Result(radius=radius, paths=tuple(CablePath(p, closed=closed) for p in paths),
                  crossings=crossings, cameras=cameras, units="model")


def assert_perfect(metrics, truth):
    assert metrics.accuracy_mean == pytest.approx(0.0, abs=1e-9)
    assert metrics.accuracy_max == pytest.approx(0.0, abs=1e-9)
    assert metrics.completeness == pytest.approx(1.0, abs=1e-9)
    assert metrics.wrong_connections == 0
    assert metrics.path_count == 1
    assert metrics.one_path
    assert metrics.crossings_total == len(truth.crossings)
    assert metrics.crossings_right == metrics.crossings_total
    assert metrics.radius_error == pytest.approx(0.0, abs=1e-12)


@pytest.fixture(scope="module")
def truth():
    return looping_truth()


@pytest.fixture(scope="module")
def ring():
    return ring_truth()


def test_the_test_truth_is_what_it_claims(truth):
    # Two crossings, each with the over strand about 2 r above the under one at the same place.
    assert len(truth.crossings) == 2
    for crossing in truth.crossings:
        over, under = truth.centreline[crossing.over], truth.centreline[crossing.under]
        assert np.linalg.norm((over - under)[:2]) < 0.3 * R
        assert (over - under)[2] == pytest.approx(LIFT * R, abs=0.05 * R)
    assert truth.crossings[0].over < truth.crossings[0].under
    assert truth.crossings[1].over > truth.crossings[1].under


# -- perfect reconstructions --------------------------------------------------------------------

def test_the_truth_itself_is_perfect(truth):
    result = make_result(truth.centreline, crossings=listed_crossings(truth))
    metrics = evaluate(result, truth)
    assert_perfect(metrics, truth)
    assert [d.listed for d in metrics.crossing_details] == [True, True]
    assert all(d.height_difference > 1.5 for d in metrics.crossing_details)
    assert not metrics.aligned and metrics.scale == 1.0


def test_a_backwards_path_is_perfect_too(truth):
    result = make_result(truth.centreline[::-1], crossings=listed_crossings(truth, reverse=True))
    metrics = evaluate(result, truth)
    assert_perfect(metrics, truth)
    assert [d.listed for d in metrics.crossing_details] == [True, True]


def test_a_closed_ring_starting_anywhere_in_either_direction_is_perfect(ring):
    for points in (np.roll(ring.centreline, 137, axis=0), ring.centreline,
                   np.roll(ring.centreline[::-1], 52, axis=0), ring.centreline[::-1]):
        metrics = evaluate(make_result(points, closed=True), ring)
        assert_perfect(metrics, ring)


def test_a_ring_missing_its_closing_edge_is_not_complete(ring):
    # The closing edge is part of both the true and the reconstructed ring.
    points = np.roll(ring.centreline, 137, axis=0)[:-40]  # a 41-sample gap between the ends
    metrics = evaluate(make_result(points, closed=False), ring)
    uncovered = 41 * SPACING - 2  # the ends cover 1 r of the gap each
    assert metrics.completeness == pytest.approx(1 - uncovered / (ring.length / R), abs=2e-3)
    assert evaluate(make_result(points, closed=True), ring).completeness == pytest.approx(1.0)


# -- crossings ----------------------------------------------------------------------------------

def test_a_flipped_crossing_is_detected(truth):
    points = truth.centreline.copy()
    arc = truth.arc_length / R
    first = truth.crossings[0]
    # Move the lift of crossing 0 from its over strand to its under strand.
    points[:, 2] -= LIFT * R * _bump(arc - arc[first.over])
    points[:, 2] += LIFT * R * _bump(arc - arc[first.under])
    result = make_result(points, crossings=listed_crossings(truth, flip=(0,)))
    metrics = evaluate(result, truth)
    assert metrics.crossings_total == 2
    assert metrics.crossings_right == 1
    flipped, kept = metrics.crossing_details
    assert not flipped.right and flipped.height_difference == pytest.approx(-LIFT, abs=0.2)
    assert kept.right
    assert flipped.listed is False and kept.listed is True
    # The strands still follow the cable: a wrong height is not a wrong connection.
    assert metrics.wrong_connections == 0 and metrics.one_path


def test_a_listed_crossing_far_from_the_true_one_is_not_counted(truth):
    entries = listed_crossings(truth)
    moved = Crossing(entries[0].position + [5 * R, 0, 0], entries[0].over, entries[0].under)
    metrics = evaluate(make_result(truth.centreline, crossings=(moved, entries[1])), truth)
    assert [d.listed for d in metrics.crossing_details] == [None, True]
    assert metrics.crossings_right == 2  # judged on the geometry, not on the list


def test_a_flattened_cable_gets_every_crossing_wrong(truth):
    points = truth.centreline.copy()
    points[:, 2] = R
    metrics = evaluate(make_result(points), truth)
    assert metrics.crossings_right == 0
    assert all(not d.right for d in metrics.crossing_details)
    assert 1.6 < metrics.accuracy_max <= LIFT + 1e-9
    # A lift of a fraction of a radius is not enough either.
    points[:, 2] = R + 0.2 * (truth.centreline[:, 2] - R)
    metrics = evaluate(make_result(points), truth)
    assert metrics.crossings_right == 0
    assert all(0.2 < d.height_difference < 0.6 for d in metrics.crossing_details)
    assert metrics.wrong_connections == 0  # flat, yet each strand is followed through


# -- topology -----------------------------------------------------------------------------------

def test_skipping_a_stretch_is_a_wrong_connection(truth):
    i, j = 150, 150 + int(40 / SPACING)  # skips 40 r of cable
    points = np.vstack([truth.centreline[:i], truth.centreline[j:]])
    metrics = evaluate(make_result(points), truth)
    assert metrics.wrong_connections >= 1
    assert not metrics.one_path and metrics.path_count == 1
    assert metrics.completeness < 1 - 30 / (truth.length / R)


def test_turning_into_the_other_strand_at_a_crossing_is_a_wrong_connection(truth):
    crossing = truth.crossings[0]  # over is the first pass: the turn skips the loop
    points = np.vstack([truth.centreline[:crossing.over], truth.centreline[crossing.under:]])
    metrics = evaluate(make_result(points), truth)
    assert metrics.wrong_connections >= 1
    assert not metrics.one_path
    # Backwards it is just as wrong.
    assert evaluate(make_result(points[::-1]), truth).wrong_connections >= 1
    # So is turning into the other strand and running it backwards (round the loop again).
    loop_back = np.vstack([truth.centreline[:crossing.over],
                           truth.centreline[crossing.over + 8:crossing.under + 1][::-1]])
    assert evaluate(make_result(loop_back), truth).wrong_connections >= 1


def test_doubling_back_is_one_wrong_connection(truth):
    k, back = 300, int(20 / SPACING)
    points = np.vstack([truth.centreline[:k], truth.centreline[k - back:k - 1][::-1]])
    for path in (points, points[::-1]):
        metrics = evaluate(make_result(path), truth)
        assert metrics.wrong_connections == 1
        assert not metrics.one_path
    # Out and back along the whole cable.
    there_and_back = np.vstack([truth.centreline, truth.centreline[-2::-1]])
    assert evaluate(make_result(there_and_back), truth).wrong_connections == 1


def test_closing_an_open_cable_is_a_wrong_connection(truth, ring):
    metrics = evaluate(make_result(truth.centreline, closed=True), truth)
    assert metrics.wrong_connections >= 1
    assert not metrics.one_path
    # An open cable whose ends almost touch: only the closing step joins them.
    almost = GroundTruth(ring.centreline, R, (), closed=False)
    assert evaluate(make_result(ring.centreline, closed=False), almost).wrong_connections == 0
    assert evaluate(make_result(ring.centreline, closed=True), almost).wrong_connections == 1


def test_a_split_path_is_complete_but_not_one_path(truth):
    cut = len(truth.centreline) // 2
    result = make_result(truth.centreline[:cut + 1], truth.centreline[cut:])
    metrics = evaluate(result, truth)
    assert metrics.path_count == 2
    assert not metrics.one_path
    assert metrics.wrong_connections == 0
    assert metrics.completeness == pytest.approx(1.0)
    assert metrics.crossings_right == 2


# -- geometry and units -------------------------------------------------------------------------

def offset_sideways(truth, distance):
    tangent = np.gradient(truth.centreline, axis=0)
    side = np.cross(truth.up, tangent)
    side /= np.linalg.norm(side, axis=1, keepdims=True)
    return truth.centreline + distance * truth.radius * side


def test_accuracy_is_in_true_radii(truth):
    metrics = evaluate(make_result(offset_sideways(truth, 0.5)), truth)
    assert metrics.accuracy_mean == pytest.approx(0.5, abs=0.02)
    assert metrics.accuracy_p95 == pytest.approx(0.5, abs=0.02)
    assert metrics.completeness == pytest.approx(1.0)
    assert metrics.wrong_connections == 0
    # The same shape at another scale gives the same numbers.
    big = GroundTruth(truth.centreline * 7, truth.radius * 7, truth.crossings)
    scaled = evaluate(make_result(offset_sideways(truth, 0.5) * 7, radius=R * 7), big)
    assert scaled.accuracy_mean == pytest.approx(metrics.accuracy_mean, rel=1e-6)


def test_completeness_drops_to_zero_three_radii_away(truth):
    metrics = evaluate(make_result(offset_sideways(truth, 3.0)), truth)
    assert metrics.completeness < 0.01
    assert metrics.accuracy_mean == pytest.approx(3.0, abs=0.2)


def test_radius_error_is_relative(truth):
    metrics = evaluate(make_result(truth.centreline, radius=1.25 * R), truth)
    assert metrics.radius_error == pytest.approx(0.25)


def test_as_row_holds_the_scalars(truth):
    row = evaluate(make_result(truth.centreline), truth).as_row()
    assert "crossing_details" not in row
    assert row["completeness"] == pytest.approx(1.0) and row["one_path"] is True
    assert set(row) == set(Metrics.__dataclass_fields__) - {"crossing_details"}


def test_noisy_reconstruction_of_a_long_tangle():
    # Speed is measured by the bench, not here; this checks the metrics on a long cable.
    truth = looping_truth(loops=24)
    assert len(truth.centreline) > 4500
    rng = np.random.default_rng(0)
    points = truth.centreline + rng.normal(0, 0.1 * R, truth.centreline.shape)
    metrics = evaluate(make_result(points, crossings=listed_crossings(truth)), truth)
    assert metrics.crossings_right == metrics.crossings_total == 24
    assert metrics.wrong_connections == 0
    assert 0.05 < metrics.accuracy_mean < 0.2


def test_bad_arguments_are_refused(truth):
    with pytest.raises(TypeError, match="GroundTruth"):
        evaluate(make_result(truth.centreline), truth.centreline)
    with pytest.raises(ValueError, match="sample_spacing"):
        MetricSettings(sample_spacing=0)


# -- alignment ----------------------------------------------------------------------------------

def rotation_about(axis, angle):
    axis = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * k @ k


KNOWN = Similarity(2.5, rotation_about([1, 2, 3], 0.7), np.array([0.3, -1.2, 0.8]))


def test_align_similarity_recovers_a_known_transform():
    rng = np.random.default_rng(1)
    source = rng.normal(size=(8, 3))
    found = align_similarity(source, KNOWN.apply(source))
    assert found.scale == pytest.approx(2.5)
    assert np.allclose(found.R, KNOWN.R) and np.allclose(found.t, KNOWN.t)
    # A mirrored target still gives a rotation, never a reflection.
    mirrored = align_similarity(source, source * [1, 1, -1])
    assert np.linalg.det(mirrored.R) == pytest.approx(1.0)


def test_align_similarity_refuses_degenerate_points():
    with pytest.raises(ValueError, match="at least 3"):
        align_similarity(np.eye(3)[:2], np.eye(3)[:2])
    line = np.outer(np.arange(5.0), [1, 2, 3])
    with pytest.raises(ValueError, match="line"):
        align_similarity(line, line)


def test_a_transformed_camera_keeps_its_view_of_the_transformed_world():
    camera = look_at_camera("a.jpg", [0.4, -0.3, 0.5], [0.05, 0.02, 0.0])
    moved = KNOWN.apply_camera(camera)
    assert np.allclose(moved.center, KNOWN.apply(camera.center))
    points = np.random.default_rng(2).normal(0, 0.05, (10, 3))
    before, depth_before = camera.project(points)
    after, depth_after = moved.project(KNOWN.apply(points))
    assert np.allclose(before, after)
    assert np.allclose(depth_after, KNOWN.scale * depth_before)


def scene_cameras(count=6):
    return tuple(look_at_camera(f"{k:03d}.png", [0.4 * np.cos(k), 0.4 * np.sin(k), 0.3 + 0.02 * k],
                                [0.05, 0.0, 0.0]) for k in range(count))


def test_evaluate_aligns_a_result_in_another_frame(truth):
    truth = truth.with_cameras(scene_cameras())
    moved = Result(radius=R * KNOWN.scale, paths=(CablePath(KNOWN.apply(truth.centreline)),),
                   crossings=tuple(Crossing(KNOWN.apply(c.position), c.over, c.under)
                                   for c in listed_crossings(truth)),
                   cameras=tuple(KNOWN.apply_camera(c) for c in truth.cameras[::-1]))
    unaligned = evaluate(moved, truth)
    assert unaligned.accuracy_mean > 10 and unaligned.crossings_right < 2
    metrics = evaluate(moved, truth, align=True)
    assert metrics.aligned and metrics.scale == pytest.approx(1 / KNOWN.scale)
    assert metrics.accuracy_max == pytest.approx(0.0, abs=1e-6)
    assert metrics.radius_error == pytest.approx(0.0, abs=1e-9)
    assert metrics.completeness == pytest.approx(1.0)
    assert metrics.crossings_right == 2 and metrics.one_path
    assert [d.listed for d in metrics.crossing_details] == [True, True]
    aligned, similarity = align_result_to_truth(moved, truth)
    assert similarity.scale == pytest.approx(metrics.scale)
    true_centres = {c.name: c.center for c in truth.cameras}
    for camera in aligned.cameras:
        assert np.allclose(camera.center, true_centres[camera.name], atol=1e-9)


def test_alignment_needs_three_common_cameras(truth):
    cameras = scene_cameras()
    truth = truth.with_cameras(cameras)
    result = make_result(truth.centreline, cameras=cameras[:2] + tuple(
        look_at_camera(f"other{k}.png", [0.3, 0.1 * k, 0.4]) for k in range(3)))
    with pytest.raises(ValueError, match="at least 3 cameras"):
        evaluate(result, truth, align=True)
    with pytest.raises(ValueError, match="at least 3 cameras"):
        align_result_to_truth(make_result(truth.centreline), truth)

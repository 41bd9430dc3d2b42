"""The editable Bézier curve: within tolerance everywhere, fewest knots, crossings kept apart."""

import numpy as np
import pytest

from engine.stages.bezier import _PieceFitter, _tangents, distance_to_polyline, fit_bezier, \
    fit_result_curves
from engine.io.result import CablePath, Crossing, Result, StrandRef


def wavy(n=1200, turns=3.0):
    s = np.linspace(0.0, 2 * np.pi * turns, n)
    radius = 1.0 + 0.3 * np.cos(3 * s)
    return np.column_stack([radius * np.cos(s), radius * np.sin(s), 0.05 * s])


def two_way_error(curve, points, closed=False):
    dense = curve.sample(128)
    return max(distance_to_polyline(dense, points, closed=closed).max(),
               distance_to_polyline(points, dense, closed=closed).max())


@pytest.mark.parametrize("tolerance", [0.02, 0.005, 0.001])
def test_stays_within_tolerance_both_ways_and_needs_more_knots_when_tighter(tolerance):
    points = wavy()
    curve = fit_bezier(points, tolerance=tolerance)
    assert two_way_error(curve, points) <= tolerance
    np.testing.assert_array_equal(curve.knots[[0, -1]], points[[0, -1]])
    assert curve.knot_index[0] == 0 and curve.knot_index[-1] == len(points) - 1
    # handles are aligned (G1): each knot's two handles point in opposite directions
    incoming = curve.knots[1:-1] - curve.left[1:-1]
    outgoing = curve.right[1:-1] - curve.knots[1:-1]
    cosine = np.einsum("ij,ij->i", incoming, outgoing) / (
        np.linalg.norm(incoming, axis=1) * np.linalg.norm(outgoing, axis=1))
    assert cosine.min() > 1 - 1e-9
    assert len(curve.knots) < len(points) / 4


def test_knot_count_grows_with_tighter_tolerance_and_a_line_needs_two():
    points = wavy()
    counts = [len(fit_bezier(points, tolerance=t).knots) for t in (0.02, 0.005, 0.001)]
    assert counts[0] < counts[1] < counts[2]
    line = np.column_stack([np.linspace(0, 1, 50), np.zeros(50), np.zeros(50)])
    assert len(fit_bezier(line, tolerance=1e-6).knots) == 2


def test_as_few_knots_as_an_exhaustive_search_finds():
    points = wavy(n=90, turns=1.0)
    tolerance = 0.004
    fitter = _PieceFitter(points, _tangents(points, False), np.full(len(points), 0.97 * tolerance))
    fewest = np.full(len(points), np.inf)
    fewest[0] = 0
    for last in range(1, len(points)):  # shortest path over every piece that fits
        for first in range(last):
            if fewest[first] + 1 < fewest[last] and fitter.fit(first, last)[1]:
                fewest[last] = fewest[first] + 1
    curve = fit_bezier(points, tolerance=tolerance)
    assert curve.n_pieces == fewest[-1]


def test_a_closed_loop_is_cyclic_and_keeps_its_breaks():
    s = np.linspace(0, 2 * np.pi, 300, endpoint=False)
    loop = np.column_stack([np.cos(s), 0.5 * np.sin(2 * s), 0.1 * np.sin(s)])
    curve = fit_bezier(loop, tolerance=0.002, closed=True, breaks=[40, 250])
    assert curve.closed and curve.n_pieces == len(curve.knots)
    assert {40, 250} <= set(curve.knot_index.tolist())
    assert two_way_error(curve, loop, closed=True) <= 0.002
    dense, index = curve.sample_with_index(16)
    assert np.all((index >= 0) & (index < 2 * len(loop)))


def test_scaling_the_world_scales_the_curve():
    points = wavy()
    curve = fit_bezier(points, tolerance=0.005)
    scaled = fit_bezier(points * 1000.0, tolerance=5.0)
    np.testing.assert_array_equal(curve.knot_index, scaled.knot_index)
    np.testing.assert_allclose(scaled.right, curve.right * 1000.0, rtol=1e-6, atol=1e-6)


def crossing_result(gap):
    """Two straight strands crossing at 60 degrees, ``gap`` radii apart, r = 1."""
    t = np.linspace(-20, 20, 81)[:, None]
    bump = gap / 2 * np.exp(-(t[:, 0] / 4) ** 2)
    over = np.column_stack([t[:, 0], np.zeros(81), bump])
    direction = np.array([np.cos(np.pi / 3), np.sin(np.pi / 3), 0.0])
    under = t * direction - np.column_stack([np.zeros((81, 2)), bump])
    return Result(radius=1.0, paths=(CablePath(over), CablePath(under)),
                  crossings=(Crossing([0, 0, 0], StrandRef(0, 40), StrandRef(1, 40)),))


@pytest.mark.parametrize("gap", [1.94, 2.05, 2.3])
def test_crossings_keep_two_radii_between_the_strands(gap):
    result = crossing_result(gap)
    curves, report = fit_result_curves(result)
    (curve_gap, reconstructed_gap), = report["crossing_gaps"]
    assert reconstructed_gap == pytest.approx(gap, abs=0.01)
    assert curve_gap >= 2.0
    assert report["max_error"] <= 0.1
    assert all(40 in curve.knot_index for curve in curves)
    assert report["control_points"] == sum(len(c.knots) for c in curves)


def test_without_the_crossing_rule_the_strands_would_touch():
    # the same fit with the plain tolerance lets a 2.05 r gap close below 2 r: the rule matters
    result = crossing_result(2.05)
    plain = [fit_bezier(p.points, tolerance=0.1) for p in result.paths]
    over, under = (c.sample(128) for c in plain)
    assert distance_to_polyline(over, under).min() < 2.0

"""Segment graph (paper §3.3) on small hand-made voxel volumes, checked exactly."""

import argparse
import dataclasses
import threading

import networkx as nx
import numpy as np
import pytest

from engine.cli.settings import add_settings_arguments, settings_from_arguments
from engine.errors import Cancelled
from engine.stages.segment_graph import (SegmentGraph, SegmentGraphSettings, extract_segment_graph,
                                         extract_segment_graph_from_voxels, voxelize_tubes)

R = 2.5  # cable radius in voxels (voxel size 1): five voxels across


# -- volumes -------------------------------------------------------------------------------------

def volume(lines, *, radius=R, blobs=(), blob_radius=1.5 * R, vertical_scale=1.0):
    """Occupied grid of tubes along ``lines``, junction votes in balls around ``blobs``."""
    occupied, origin = voxelize_tubes(lines, radius, vertical_scale=vertical_scale)
    junction = np.zeros_like(occupied)
    if len(blobs):
        junction, _ = voxelize_tubes([[b] for b in blobs], blob_radius, origin=origin,
                                     shape=occupied.shape)
    return occupied, junction & occupied, origin


def extract(occupied, junction, origin, *, radius=R, **settings):
    return extract_segment_graph(occupied, junction, origin=origin, voxel_size=1.0,
                                 radius=radius, settings=SegmentGraphSettings(**settings))


def distance_to_lines(points, lines, *, beyond_ends=2 * R):
    """Distance from each point to the nearest polyline, prolonged past its ends (the tips)."""
    best = np.full(len(points), np.inf)
    for line in lines:
        line = np.asarray(line, dtype=float)
        line = line[np.r_[True, np.linalg.norm(np.diff(line, axis=0), axis=1) > 0]]
        last = len(line) - 2
        for index, (a, b) in enumerate(zip(line, line[1:])):
            ab = b - a
            extra = beyond_ends / np.linalg.norm(ab)
            low, high = -extra if index == 0 else 0, 1 + extra if index == last else 1
            t = np.clip((points - a) @ ab / (ab @ ab), low, high)
            best = np.minimum(best, np.linalg.norm(points - a - t[:, None] * ab, axis=1))
    return best


def arc(centre, radius, start, stop, count=120, z=0.0):
    """Points on a horizontal circular arc (angles in radians)."""
    angle = np.linspace(start, stop, count)
    return np.column_stack([centre[0] + radius * np.cos(angle),
                            centre[1] + radius * np.sin(angle), np.full(count, z)])


def kinds(graph):
    return sorted(d["kind"] for _, d in graph.graph.nodes(data=True))


def junction_degrees(graph):
    return sorted(graph.degree(n) for n, _ in graph.junctions())


def assert_centred(graph, lines, tolerance=0.5, *, tips=1.0):
    """Segments run within ``tolerance`` of the tube axes.

    Within r of a free end (a straight run to the tip) the bound is ``tips``; points inside a
    junction's grown region are not checked, since the strands overlap there.
    """
    ends = np.array([d["position"] for _, d in graph.ends()]).reshape(-1, 3)
    cores = [(d["position"], np.linalg.norm(d["voxels"] - d["position"], axis=1).max())
             for _, d in graph.junctions()]
    for _, _, _, points in graph.segments():
        error = distance_to_lines(points, lines)
        checked = np.ones(len(points), dtype=bool)
        for centre, reach in cores:
            checked &= np.linalg.norm(points - centre, axis=1) > reach
        near_tip = np.zeros(len(points), dtype=bool)
        for end in ends:
            near_tip |= np.linalg.norm(points - end, axis=1) <= R
        assert error[checked & ~near_tip].max(initial=0) <= tolerance
        assert error[checked & near_tip].max(initial=0) <= tips


def assert_attached(graph):
    """Every segment starts and ends exactly at its nodes."""
    for u, v, key, points in graph.segments():
        assert np.allclose(points[0], graph.graph.nodes[u]["position"])
        if not graph.graph.edges[u, v, key]["closed"]:
            assert np.allclose(points[-1], graph.graph.nodes[v]["position"])


# -- single tubes --------------------------------------------------------------------------------

def test_straight_tube_is_one_segment_between_two_ends():
    line = [[0, 0, 0], [40, 0, 0]]
    graph = extract(*volume([line]))
    assert (graph.n_junctions, graph.n_ends, graph.n_segments) == (0, 2, 1)
    assert kinds(graph) == ["end", "end"]
    assert_attached(graph)
    assert_centred(graph, [line])
    (u, v, _, points), = graph.segments()
    tips = sorted([points[0][0], points[-1][0]])
    assert tips == pytest.approx([-R, 40 + R], abs=1.0)  # the chain reaches the cable's tips
    data = next(iter(graph.graph.edges(data=True)))[2]
    assert abs(data["start_direction"] @ data["end_direction"] + 1) < 1e-6
    assert data["length"] == pytest.approx(40 + 2 * R, abs=1.5)


def test_oblique_tube_runs_through_its_centre():
    line = [[0, 0, 0], [30, 18, 9]]
    graph = extract(*volume([line]))
    assert (graph.n_junctions, graph.n_ends, graph.n_segments) == (0, 2, 1)
    assert_centred(graph, [line])


@pytest.mark.parametrize("width", [3, 4, 5, 6])
@pytest.mark.parametrize("shape", ["straight", "bent"])
def test_even_and_odd_widths_give_one_centred_segment(width, shape):
    # odd widths: axis on voxel centres; even widths: axis between them
    shift = 0.0 if width % 2 else 0.5
    if shape == "straight":
        line = np.array([[0, shift, shift], [30, shift, shift]])
    else:  # a quarter circle then a straight run
        line = np.vstack([arc((0, 0), 16, 0, np.pi / 2, z=shift),
                          [[-20, 16, shift]]]) + [shift, 0, 0]
    occupied, junction, origin = volume([line], radius=width / 2)
    if shape == "straight":
        j, k = np.round(-origin[1:] + shift).astype(int)
        i = 15 - int(origin[0])
        assert occupied[i, :, k].sum() == width and occupied[i, j, :].sum() == width
    graph = extract(occupied, junction, origin, radius=width / 2)
    assert (graph.n_junctions, graph.n_ends, graph.n_segments) == (0, 2, 1)
    assert_centred(graph, [line])


def test_closed_loop_without_junction_is_one_closed_segment():
    ring = arc((0, 0), 20, 0, 2 * np.pi, count=200)
    graph = extract(*volume([ring]))
    assert (graph.n_junctions, graph.n_ends, graph.n_segments) == (0, 0, 1)
    assert kinds(graph) == ["closure"]
    (u, v, _, points), = graph.segments()
    data = graph.graph.edges[u, v, 0]
    assert u == v and data["closed"]
    assert np.allclose(points[0], graph.graph.nodes[u]["position"])
    assert data["length"] == pytest.approx(2 * np.pi * 20, rel=0.02)
    assert_centred(graph, [ring])


def test_fat_vertically_elongated_tube_follows_its_centroid():
    # an ellipse cross-section twice as tall as wide, off the voxel centres in z
    line = np.vstack([arc((0, 0), 20, -0.3, np.pi / 2, z=0.3), [[-25, 20, 0.3]]])
    occupied, junction, origin = volume([line], radius=2.0, vertical_scale=2.0)
    graph = extract(occupied, junction, origin, radius=2.0)
    assert (graph.n_junctions, graph.n_ends, graph.n_segments) == (0, 2, 1)
    assert_centred(graph, [line])


def test_short_spur_is_pruned_and_long_branch_is_kept():
    main = [[0, 0, 0], [60, 0, 0]]
    _, junction, origin = volume([main, [[30, 0, 0], [30, 20, 0]]])  # a grid with room
    grid = dict(origin=origin, shape=junction.shape)
    occupied, _ = voxelize_tubes([main], R, **grid)
    # a stub 1.8 r out of the surface (it makes a dead end of the fronts): carving noise
    stub, _ = voxelize_tubes([[[30, 0, 0], [30, 7, 0]]], 1.5, **grid)
    graph = extract(occupied | stub, junction, origin)
    assert (graph.n_junctions, graph.n_ends, graph.n_segments) == (0, 2, 1)
    assert_centred(graph, [main], tolerance=1.0)  # the stub pulls the slabs it sits on
    # a branch 5 r out: real, though no junction was voted there; found from the shape
    branch, _ = voxelize_tubes([[[30, 0, 0], [30, 15, 0]]], R, **grid)
    graph = extract(occupied | branch, junction, origin)
    assert (graph.n_junctions, graph.n_ends, graph.n_segments) == (1, 3, 3)
    (_, data), = graph.junctions()
    assert not data["voted"]
    assert np.linalg.norm(data["position"] - [30, 0, 0]) < 2 * R
    # a longer pruning length removes that branch too
    graph = extract(occupied | branch, junction, origin, spur_length=6.0)
    assert (graph.n_junctions, graph.n_ends, graph.n_segments) == (0, 2, 1)


# -- junctions -----------------------------------------------------------------------------------

L = 30
X_LINES = [[[-L, 0, 0], [L, 0, 0]], [[0, -L, 0], [0, L, 0]]]


def test_x_crossing_is_one_junction_of_degree_four():
    graph = extract(*volume(X_LINES, blobs=[[0, 0, 0]]))
    assert (graph.n_junctions, graph.n_ends, graph.n_segments) == (1, 4, 4)
    assert junction_degrees(graph) == [4]
    (node, data), = graph.junctions()
    assert data["voted"] and np.linalg.norm(data["position"]) < 1.0
    assert_attached(graph)
    assert_centred(graph, X_LINES)
    directions = []
    for _, other, edge in graph.graph.edges(node, data=True):
        end = graph.graph.nodes[other]["position"]
        assert np.abs(end).max() == pytest.approx(L + R, abs=1.0)  # at the tube's tip
        direction = edge["start_direction"] if edge["start"] == node else edge["end_direction"]
        assert direction @ end / np.linalg.norm(end) > 0.99
        directions.append(direction)
    assert np.allclose(np.sum(directions, axis=0), 0, atol=0.05)


def test_t_is_one_junction_of_degree_three():
    lines = [[[-L, 0, 0], [L, 0, 0]], [[0, 0, 0], [0, L, 0]]]
    graph = extract(*volume(lines, blobs=[[0, 0, 0]]))
    assert (graph.n_junctions, graph.n_ends, graph.n_segments) == (1, 3, 3)
    assert junction_degrees(graph) == [3]
    assert_attached(graph)


def test_shallow_crossing_with_small_junction_region_has_degree_four():
    # 30 degrees between the strands: the fronts split late; the votes cover little
    c, s = np.cos(np.radians(15)), np.sin(np.radians(15))
    lines = [[[-L * c, -L * s, 0], [L * c, L * s, 0]], [[-L * c, L * s, 0], [L * c, -L * s, 0]]]
    graph = extract(*volume(lines, blobs=[[0, 0, 0]], blob_radius=R))
    assert (graph.n_junctions, graph.n_ends, graph.n_segments) == (1, 4, 4)
    assert junction_degrees(graph) == [4]


def test_stacked_crossing_with_fused_hull_has_degree_four():
    # one strand passes 2 r over the other; the fat hulls (1.3 r, 1.5 times taller) fuse
    lines = [[[-L, 0, 0], [L, 0, 0]], [[0, -L, 2 * R], [0, L, 2 * R]]]
    occupied, junction, origin = volume(lines, radius=1.3 * R, vertical_scale=1.5,
                                        blobs=[[0, 0, R]], blob_radius=2 * R)
    graph = extract(occupied, junction, origin)
    assert (graph.n_junctions, graph.n_ends, graph.n_segments) == (1, 4, 4)
    assert junction_degrees(graph) == [4]
    assert_centred(graph, lines, tolerance=1.0)


def lens_lines():
    """Two strands crossing twice, at x = -20 and x = 20, with tails: a lens with four ends."""
    x = np.linspace(-45, 45, 181)
    slope = 10 * np.pi / 40
    y = np.where(np.abs(x) <= 20, 10 * np.sin(np.pi * (x + 20) / 40),
                 -slope * (np.abs(x) - 20))
    upper = np.column_stack([x, y, np.zeros_like(x)])
    return [upper, upper * [1, -1, 1]]


def test_two_segments_between_the_same_two_junctions():
    lines = lens_lines()
    graph = extract(*volume(lines, blobs=[[-20, 0, 0], [20, 0, 0]]))
    assert (graph.n_junctions, graph.n_ends, graph.n_segments) == (2, 4, 6)
    assert junction_degrees(graph) == [4, 4]
    (a, _), (b, _) = graph.junctions()
    assert graph.graph.number_of_edges(a, b) == 2
    assert_attached(graph)
    assert_centred(graph, lines, tolerance=0.75)


def curl_lines():
    """A strand that loops back over itself (an alpha): tail, crossing, loop, crossing, tail."""
    u1 = np.array([1.0, 0.6]) / np.linalg.norm([1.0, 0.6])
    u2 = u1 * [-1, 1]
    loop_radius = 12.0
    centre = np.array([0.0, loop_radius * np.hypot(1, 0.6)])  # tangent to both lines
    t1, t2 = (centre @ u1) * u1, (centre @ u2) * u2
    a1 = np.arctan2(*(t1 - centre)[::-1])
    a2 = np.arctan2(*(t2 - centre)[::-1]) + 2 * np.pi
    loop = arc(centre, loop_radius, a1, a2, count=150)
    tail_in = np.column_stack([np.linspace(-35, 0, 10)[:, None] * u1, np.zeros(10)])
    tail_out = np.column_stack([-np.linspace(0, 35, 10)[:, None] * u2, np.zeros(10)])
    to_loop = np.array([[0, 0, 0], [*t1, 0]])
    from_loop = np.array([[*t2, 0], [0, 0, 0]])
    return [np.vstack([tail_in, to_loop, loop, from_loop, tail_out])]


def test_loop_from_a_junction_back_to_itself():
    lines = curl_lines()
    graph = extract(*volume(lines, blobs=[[0, 0, 0]], blob_radius=2 * R))
    assert (graph.n_junctions, graph.n_ends, graph.n_segments) == (1, 2, 3)
    assert junction_degrees(graph) == [4]
    (node, _), = graph.junctions()
    assert graph.graph.number_of_edges(node, node) == 1
    loop = graph.graph.edges[node, node, 0]
    assert not loop["closed"] and loop["length"] > 2 * np.pi * 10
    assert_attached(graph)
    assert_centred(graph, lines, tolerance=0.75)


def test_figure_eight_is_two_loops_at_one_junction():
    s = np.linspace(0, 2 * np.pi, 241)
    eight = np.column_stack([30 * np.sin(s), 15 * np.sin(2 * s), np.zeros_like(s)])
    graph = extract(*volume([eight], blobs=[[0, 0, 0]], blob_radius=2 * R))
    assert (graph.n_junctions, graph.n_ends, graph.n_segments) == (1, 0, 2)
    (node, _), = graph.junctions()
    assert graph.degree(node) == 4 and graph.graph.number_of_edges(node, node) == 2
    assert_centred(graph, [eight])


def test_open_cable_with_n_crossings_has_2n_plus_1_segments():
    # a cable curling into three loops (prolate trochoid), each crossing itself once
    t = np.linspace(np.pi, 7 * np.pi, 600)
    line = np.column_stack([4.5 * t - 12 * np.sin(t), -12 * np.cos(t), np.zeros_like(t)])
    # loop k crosses itself at t = 2 k pi -+ tau, where x(t) agrees: 4.5 tau = 12 sin tau
    tau = np.linspace(0.01, np.pi, 20000)
    tau = tau[np.argmin(np.abs(4.5 * tau - 12 * np.sin(tau)))]
    sites = [[4.5 * 2 * np.pi * k, -12 * np.cos(tau), 0.0] for k in (1, 2, 3)]
    graph = extract(*volume([line], blobs=sites, blob_radius=1.5 * R))
    n = len(sites)
    assert (graph.n_junctions, graph.n_ends, graph.n_segments) == (n, 2, 2 * n + 1)
    assert junction_degrees(graph) == [4] * n
    assert_centred(graph, [line], tolerance=0.75)


def test_short_segment_between_two_junctions_is_kept():
    # a strand crossed by two others 12 voxels apart: the blobs leave under 2 r between them
    lines = [[[-L, 0, 0], [L, 0, 0]], [[-6, -L, 0], [-6, L, 0]], [[6, -L, 0], [6, L, 0]]]
    graph = extract(*volume(lines, blobs=[[-6, 0, 0], [6, 0, 0]]))
    assert (graph.n_junctions, graph.n_ends, graph.n_segments) == (2, 6, 7)
    assert junction_degrees(graph) == [4, 4]
    (a, _), (b, _) = graph.junctions()
    assert graph.graph.number_of_edges(a, b) == 1
    assert graph.graph.edges[a, b, 0]["length"] == pytest.approx(12, abs=1.0)


def test_junction_votes_in_two_close_pieces_are_one_junction():
    occupied, _, origin = volume(X_LINES)
    junction, _ = voxelize_tubes([[[-2, -2, 0]], [[2.5, 2.5, 0]]], 2.2, origin=origin,
                                 shape=occupied.shape)
    graph = extract(occupied, junction & occupied, origin)
    assert (graph.n_junctions, graph.n_ends, graph.n_segments) == (1, 4, 4)
    assert junction_degrees(graph) == [4]


def test_noisy_fat_crossing_keeps_its_topology():
    # a hull 1.7 r wide, one voxel in ten of its surface flipped, off-centre irregular votes
    rng = np.random.default_rng(5)
    occupied, _, origin = volume(X_LINES, radius=1.7 * R, vertical_scale=1.3)
    surface = occupied ^ np.roll(occupied, 1, axis=0) | occupied ^ np.roll(occupied, 1, axis=1)
    occupied ^= surface & (rng.random(occupied.shape) < 0.1)
    votes = rng.normal([1.5, -1.0, 0.0], 2.0, size=(40, 3))
    junction, _ = voxelize_tubes([[v] for v in votes], 1.2, origin=origin,
                                 shape=occupied.shape)
    graph = extract(occupied, junction & occupied, origin)
    assert (graph.n_junctions, graph.n_ends, graph.n_segments) == (1, 4, 4)
    assert junction_degrees(graph) == [4]
    assert_centred(graph, X_LINES, tolerance=1.0)


# -- interface -----------------------------------------------------------------------------------

def test_several_pieces_and_specks():
    lines = [[[0, 0, 0], [30, 0, 0]], arc((0, 40), 12, 0, 2 * np.pi, count=100)]
    occupied, junction, origin = volume(lines)
    occupied[-3, -3, -3] = True  # a lone speck
    graph = extract(occupied, junction, origin)
    assert (graph.n_junctions, graph.n_ends, graph.n_segments) == (0, 2, 2)
    assert nx.number_connected_components(graph.graph) == 2


def test_world_coordinates_follow_origin_and_voxel_size():
    occupied, junction, origin = volume(X_LINES, blobs=[[0, 0, 0]])
    graph = extract_segment_graph(occupied, junction, origin=origin * 0.01 + [1, 2, 3],
                                  voxel_size=0.01, radius=R * 0.01)
    (_, data), = graph.junctions()
    assert np.allclose(data["position"], [1, 2, 3], atol=0.01)
    index = data["voxels"]
    assert occupied[tuple(index.T)].all()
    for _, _, _, points in graph.segments():
        assert distance_to_lines((points - [1, 2, 3]) / 0.01, X_LINES).max() <= 0.5


def test_voxels_as_a_list_give_the_grid_s_graph_at_any_offset_in_any_box():
    """The graph of voxels listed (as carving gives them) is the dense grid's graph, and
    neither its time nor its memory follow the box: the same crossing a hundred thousand
    voxels away from another voxel (a box of 10^15 voxels as a grid) gives the same graph."""
    occupied, junction, origin = volume(X_LINES, blobs=[[0, 0, 0]])
    dense = extract(occupied, junction, origin)
    index = np.argwhere(occupied)
    listed = extract_segment_graph_from_voxels(index, junction[occupied], origin=origin,
                                               voxel_size=1.0, radius=R)
    far = 100_000
    shifted = extract_segment_graph_from_voxels(
        np.vstack([index + far, [[0, 0, 0]]]), np.append(junction[occupied], False),
        origin=origin - far, voxel_size=1.0, radius=R)
    for graph in (listed, shifted):
        assert (graph.n_junctions, graph.n_ends, graph.n_segments) == (1, 4, 4)
        for (_, a), (_, b) in zip(dense.junctions(), graph.junctions()):
            np.testing.assert_allclose(a["position"], b["position"], atol=1e-9)
        for (*_, a), (*_, b) in zip(dense.segments(), graph.segments()):
            np.testing.assert_allclose(a, b, atol=1e-9)
    with pytest.raises(ValueError):
        extract_segment_graph_from_voxels(index.astype(float), junction[occupied],
                                          origin=origin, voxel_size=1.0, radius=R)
    with pytest.raises(ValueError):
        extract_segment_graph_from_voxels(index, junction[occupied][1:],
                                          origin=origin, voxel_size=1.0, radius=R)


def test_empty_grid_and_bad_input():
    empty = np.zeros((5, 5, 5), dtype=bool)
    graph = extract_segment_graph(empty, empty, origin=(0, 0, 0), voxel_size=1, radius=1)
    assert isinstance(graph, SegmentGraph) and graph.n_segments == 0
    with pytest.raises(ValueError):
        extract_segment_graph(empty, empty[:4], origin=(0, 0, 0), voxel_size=1, radius=1)
    with pytest.raises(ValueError):
        extract_segment_graph(empty, empty, origin=(0, 0, 0), voxel_size=1, radius=0)
    with pytest.raises(ValueError):
        SegmentGraphSettings(band_width=0)


def test_cancel_and_progress():
    occupied, junction, origin = volume(X_LINES, blobs=[[0, 0, 0]])
    cancel = threading.Event()
    cancel.set()
    with pytest.raises(Cancelled):
        extract_segment_graph(occupied, junction, origin=origin, voxel_size=1, radius=R,
                              cancel=cancel)
    seen = []
    extract_segment_graph(occupied, junction, origin=origin, voxel_size=1, radius=R,
                          progress=lambda fraction, message: seen.append(fraction))
    assert seen == sorted(seen) and seen[-1] == 1.0


def test_every_setting_is_a_documented_command_line_flag():
    parser = argparse.ArgumentParser()
    add_settings_arguments(parser, SegmentGraphSettings)
    flags = {action.dest: action for action in parser._actions}
    for field in dataclasses.fields(SegmentGraphSettings):
        assert field.name in flags and len(flags[field.name].help) > 20
    arguments = parser.parse_args(["--spur-length", "3", "--refine-iterations", "1"])
    settings = settings_from_arguments(SegmentGraphSettings, arguments)
    assert settings == SegmentGraphSettings(spur_length=3.0, refine_iterations=1)

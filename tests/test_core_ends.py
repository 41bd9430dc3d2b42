"""Free ends of the carved core followed through the half-vote hull (engine.stages.core_ends),
on hand-made grids: a strand whose core breaks before it passes under another."""

import numpy as np
import pytest

from engine.stages.carving import VoxelGrid
from engine.stages.core_ends import follow_free_ends
from engine.stages.segment_graph import extract_segment_graph_from_voxels, voxelize_tubes

R = 2.5  # cable radius in voxels (voxel size 1)
UP = np.array([0.0, 0.0, 1.0])
L = 60.0


def grid_of(lines, weak=(), *, hull=1.6, core=1.0, junctions=()):
    """A grid whose hull is fat tubes (``hull`` radii) along ``lines`` at agreement 0.6, their
    cores (``core`` radii) at 1.0 but along the ``weak`` polylines, at 0.8 there (under the
    core's 0.95: the masks missed them in some views); junction votes in balls at
    ``junctions``."""
    fat, origin = voxelize_tubes(lines, hull * R)
    inner, _ = voxelize_tubes(lines, core * R, origin=origin, shape=fat.shape)
    agreement = np.where(inner, 1.0, 0.6).astype(np.float32)
    if len(weak):
        broken, _ = voxelize_tubes(weak, 1.2 * core * R, origin=origin, shape=fat.shape)
        agreement[broken & inner] = 0.8
    junction = np.zeros_like(fat)
    if len(junctions):
        junction, _ = voxelize_tubes([[j] for j in junctions], 2 * R, origin=origin,
                                     shape=fat.shape)
    index = np.argwhere(fat)
    return VoxelGrid(index=index, junction=junction[fat], origin=origin, voxel_size=1.0,
                     radius=R, visible=np.full(len(index), 24, np.int16),
                     agreement=agreement[fat])


def graph_of(grid, core):
    return extract_segment_graph_from_voxels(grid.index[core], grid.junction[core],
                                             origin=grid.origin, voxel_size=grid.voxel_size,
                                             radius=grid.radius)


def degrees(graph):
    g = graph.graph
    return sorted(g.degree(n) for n, d in g.nodes(data=True) if d["kind"] == "junction")


def crossing(weak_from):
    """A strand along x on the table passing under one along y at x = 0 (2 r above it); the
    lower strand's core is weak from x = ``weak_from`` to x = -1.5 r (beside the crossing)."""
    lines = [[[-L, 0, R], [L, 0, R]], [[0, -L, 3 * R], [0, L, 3 * R]]]
    weak = [[[weak_from, 0, R], [-1.5 * R, 0, R]]]
    return grid_of(lines, weak, junctions=[[0, 0, 2 * R]])


def test_a_core_broken_beside_a_crossing_is_mended():
    grid = crossing(-7 * R)
    core = grid.core(0.95)
    graph = graph_of(grid, core)
    # the break: a free end at x = -7 r and a junction of three branches
    assert degrees(graph) == [3] and graph.n_ends == 5
    mended, followed = follow_free_ends(grid, core, graph, up=UP, length=25 * R)
    assert len(followed) == 1
    walk = followed[0]
    assert 5 * R < walk.length < 9 * R
    # the walk stays on the lower strand, under the upper one
    assert np.abs(walk.points[:-1, 1]).max() < 0.5 * R
    assert np.abs(walk.points[:-1, 2] - R).max() < 0.5 * R
    assert mended.sum() > core.sum() and not (core & ~mended).any()
    again = graph_of(grid, mended)
    assert degrees(again) == [4] and again.n_ends == 4


def test_the_cable_s_own_end_and_a_long_break_are_left_alone():
    grid = crossing(-7 * R)
    core = grid.core(0.95)
    graph = graph_of(grid, core)
    # the walk from the strand's end at x = -L leaves the hull at once; none reaches 5 r
    same, followed = follow_free_ends(grid, core, graph, up=UP, length=5 * R)
    assert followed == [] and same is core
    same, followed = follow_free_ends(grid, core, graph, up=UP, length=0.0)
    assert followed == [] and same is core


def test_a_break_between_two_free_ends_is_mended():
    lines = [[[-L, 0, R], [L, 0, R]]]
    grid = grid_of(lines, [[[-5 * R, 0, R], [5 * R, 0, R]]])
    core = grid.core(0.95)
    graph = graph_of(grid, core)
    assert graph.n_ends == 4 and graph.n_junctions == 0
    mended, followed = follow_free_ends(grid, core, graph, up=UP, length=25 * R)
    assert len(followed) == 1
    again = graph_of(grid, mended)
    assert again.n_ends == 2 and again.n_segments == 1


@pytest.mark.parametrize("angle", [0.0, 0.7])
def test_a_walk_bends_with_the_cable(angle):
    # an arc of 12 r's radius (any heading): the walk from the break follows it to the far end
    t = np.linspace(-1.2, 1.2, 200) + angle
    arc = np.column_stack([12 * R * np.cos(t), 12 * R * np.sin(t), np.full_like(t, R)])
    weak = arc[(t - angle > -0.3) & (t - angle < 0.3)]
    grid = grid_of([arc], [weak])
    core = grid.core(0.95)
    graph = graph_of(grid, core)
    assert graph.n_ends == 4
    mended, followed = follow_free_ends(grid, core, graph, up=UP, length=25 * R)
    assert len(followed) == 1
    distance = np.abs(np.linalg.norm(followed[0].points[:, :2], axis=1) - 12 * R)
    assert distance.max() < 0.5 * R
    assert graph_of(grid, mended).n_ends == 2


def test_a_walk_passes_under_a_strand_at_its_own_height():
    # the lower strand's core is broken from x = -7 r to 2 r past the crossing: at the crossing
    # only the upper strand's voxels agree fully, yet the walk keeps to the table
    weak = [[[-7 * R, 0, R], [2 * R, 0, R]]]
    lines = [[[-L, 0, R], [L, 0, R]], [[0, -L, 3 * R], [0, L, 3 * R]]]
    grid = grid_of(lines, weak, junctions=[[0, 0, 2 * R]])
    core = grid.core(0.95)
    graph = graph_of(grid, core)
    mended, followed = follow_free_ends(grid, core, graph, up=UP, length=25 * R)
    assert len(followed) == 1
    points = followed[0].points
    assert points[-1, 0] > 0 and np.abs(points[:, 2] - R).max() < 0.5 * R
    assert np.abs(points[:, 1]).max() < 0.5 * R
    again = graph_of(grid, mended)
    assert again.n_ends == 4

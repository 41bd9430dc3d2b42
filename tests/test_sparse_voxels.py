"""Voxels as a list: neighbours and pieces against a dense grid's."""

import numpy as np
import pytest
from scipy import ndimage

from engine.stages.sparse_voxels import NEIGHBOUR_STEPS, neighbours, pieces, sorted_voxels


def _random_voxels(seed, shape=(9, 11, 7), fill=0.3):
    grid = np.random.default_rng(seed).random(shape) < fill
    return grid, np.argwhere(grid)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_neighbours_are_the_dense_grid_s(seed):
    grid, index = _random_voxels(seed)
    shuffled = index[np.random.default_rng(seed).permutation(len(index))]
    found = neighbours(shuffled)
    assert found.shape == (len(index), 26) and found.dtype == np.int32
    padded = np.pad(grid, 1)
    row = -np.ones(padded.shape, dtype=np.int64)
    row[tuple((shuffled + 1).T)] = np.arange(len(shuffled))
    for column, step in enumerate(NEIGHBOUR_STEPS):
        expected = row[tuple((shuffled + 1 + step).T)]
        np.testing.assert_array_equal(found[:, column], expected)
    np.testing.assert_array_equal(shuffled[sorted_voxels(shuffled)], index)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_pieces_are_the_dense_grid_s_26_connected_labels(seed):
    grid, index = _random_voxels(seed, fill=0.12)
    labels, count = ndimage.label(grid, structure=np.ones((3, 3, 3)))
    found_count, found = pieces(index)
    assert found_count == count
    expected = labels[tuple(index.T)]
    # the same partition, whatever the numbering
    pairs = np.unique(np.column_stack([found, expected]), axis=0)
    assert len(pairs) == count


def test_far_apart_voxels_cost_nothing_more():
    """Two voxels a million apart: a dense box would hold 10^18 voxels."""
    index = np.array([[0, 0, 0], [1, 1, 1], [10 ** 6, 5, 10 ** 6]])
    found = neighbours(index)
    assert found[0, list(map(tuple, NEIGHBOUR_STEPS)).index((1, 1, 1))] == 1
    assert (found[2] == -1).all()
    assert pieces(index)[0] == 2


def test_bad_input():
    assert neighbours(np.zeros((0, 3), int)).shape == (0, 26)
    with pytest.raises(ValueError, match="distinct"):
        neighbours([[0, 0, 0], [0, 0, 0]])
    with pytest.raises(ValueError, match="too large"):
        neighbours([[0, 0, 0], [2 ** 21, 2 ** 21, 2 ** 21]])
    with pytest.raises(ValueError, match="-1, 0, 1"):
        neighbours([[0, 0, 0]], steps=[[2, 0, 0]])


def test_keys_follow_c_order_and_tell_voxels_apart():
    from engine.stages.sparse_voxels import keys

    _, index = _random_voxels(3)
    found = keys(index)
    assert np.all(np.diff(found) > 0)  # argwhere's C order is key order
    assert keys(np.zeros((0, 3), int)).shape == (0,)

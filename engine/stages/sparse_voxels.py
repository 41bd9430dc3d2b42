"""Voxels kept as a list of integer indices, never as a box: neighbours and connected pieces
found in time and memory that follow the voxels, however loose their bounding box.

A cable's voxels fill a tiny part of their box (a thin wire across a room fills less than a
thousandth), so a dense grid over the box costs what the box costs. Here each voxel gets one
64-bit key (its index raveled in the padded box) and its neighbours are found by binary search
among the sorted keys: measured faster than a gather from a dense look-up table as soon as the
box is large, and with no memory beyond a few arrays of the voxels' length.
"""

import numpy as np
from scipy import sparse
from scipy.sparse import csgraph

__all__ = ["NEIGHBOUR_STEPS", "key_box", "keys", "sorted_voxels", "neighbours", "pieces"]

#: The 26 neighbour steps of a voxel, in C order (the same order as the dense gather gave).
NEIGHBOUR_STEPS = np.array([(a, b, c) for a in (-1, 0, 1) for b in (-1, 0, 1)
                            for c in (-1, 0, 1) if (a, b, c) != (0, 0, 0)])


def key_box(index):
    """The box the keys are made in: its low corner (one voxel below the voxels' least
    indices), its extent (one voxel of margin past the greatest) and its strides.

    Parameters
    ----------
    index : ndarray of int64, shape (n, 3), n > 0

    Returns
    -------
    low, extent, strides : ndarray of int64, shape (3,)

    Raises
    ------
    ValueError
        The box holds over 2^62 voxels.
    """
    low = index.min(axis=0) - 1
    extent = index.max(axis=0) - low + 2
    if np.prod(extent.astype(np.float64)) >= 2.0 ** 62:
        raise ValueError("the voxels span a box too large to index (over 2^62 voxels)")
    strides = np.array([extent[1] * extent[2], extent[2], 1], dtype=np.int64)
    return low, extent, strides


def _keys(index):
    """Each voxel's key in the box padded by one voxel, and the box's strides."""
    low, _, strides = key_box(index)
    return (index - low) @ strides, strides


def keys(index):
    """One 64-bit key per voxel: equal keys, equal voxels; C order is key order.

    Parameters
    ----------
    index : array_like of int, shape (n, 3)

    Returns
    -------
    numpy.ndarray of int64, shape (n,)

    Raises
    ------
    ValueError
        The voxels span a box of over 2^62 voxels.
    """
    index = np.asarray(index, dtype=np.int64).reshape(-1, 3)
    return _keys(index)[0] if len(index) else np.zeros(0, dtype=np.int64)


def sorted_voxels(index):
    """The order that sorts voxel indices in C order (as ``numpy.argwhere`` lists them).

    Parameters
    ----------
    index : array_like of int, shape (n, 3)
        Distinct voxel indices.

    Returns
    -------
    numpy.ndarray of int, shape (n,)
    """
    return np.argsort(keys(index), kind="stable")


def neighbours(index, steps=NEIGHBOUR_STEPS):
    """For every voxel and step, the row of the voxel ``index + step`` in ``index``, or -1.

    Parameters
    ----------
    index : array_like of int, shape (n, 3)
        Distinct voxel indices, in any order.
    steps : array_like of int, shape (m, 3), optional
        Offsets with components in {-1, 0, 1} (default: the 26 neighbours).

    Returns
    -------
    numpy.ndarray of int32, shape (n, m)
    """
    index = np.asarray(index, dtype=np.int64).reshape(-1, 3)
    steps = np.asarray(steps, dtype=np.int64).reshape(-1, 3)
    if np.abs(steps).max(initial=0) > 1:
        raise ValueError("neighbour steps must have components in -1, 0, 1")
    n = len(index)
    found = np.full((n, len(steps)), -1, dtype=np.int32)
    if not n:
        return found
    key, strides = _keys(index)
    order = np.argsort(key, kind="stable")
    ordered = key[order]
    if np.any(ordered[1:] == ordered[:-1]):
        raise ValueError("voxel indices must be distinct")
    # The box is padded by one voxel, so a step never wraps onto a voxel of another row.
    for column, step in enumerate(steps @ strides):
        wanted = key + step
        at = np.minimum(np.searchsorted(ordered, wanted), n - 1)
        found[:, column] = np.where(ordered[at] == wanted, order[at], -1)
    return found


def pieces(index):
    """The 26-connected pieces of a set of voxels.

    Parameters
    ----------
    index : array_like of int, shape (n, 3)
        Distinct voxel indices.

    Returns
    -------
    count : int
        The number of pieces.
    labels : numpy.ndarray of int, shape (n,)
        Each voxel's piece, 0..count-1.
    """
    near = neighbours(index)
    n = len(near)
    rows = np.repeat(np.arange(n, dtype=np.int32), near.shape[1])
    cols = near.ravel()
    edge = cols >= 0
    graph = sparse.csr_matrix((np.ones(int(edge.sum()), dtype=np.int8),
                               (rows[edge], cols[edge])), shape=(n, n))
    # symmetric, so the strong components are the components (and faster to find)
    return csgraph.connected_components(graph, directed=True, connection="strong")

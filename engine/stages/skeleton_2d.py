"""One-pixel skeletons of binary images and the junctions of their branches.

Zhang–Suen thinning leaves two-pixel-thick staircases on diagonals, which turn every diagonal
into a cloud of false branch pixels; a final pass removes the remaining *simple* pixels (whose
8-neighbours form one connected piece), four interleaved sub-lattices at a time so that no two
neighbours are removed together, which leaves a skeleton one pixel thick with its topology.

Branch pixels (three or more skeleton neighbours) are grouped into clusters; a cluster's
*degree* is the number of skeleton branches leaving it, so a bend's corner pixel (degree 2) is
not a junction while an X (degree 4) or a T (degree 3) is.
"""

from dataclasses import dataclass

import cv2
import numpy as np

from .union_find import DisjointSets

__all__ = ["thin", "skeleton_clusters", "SkeletonClusters", "fill_small_holes"]

# Neighbours in ring order P2..P9 of Zhang & Suen (1984): N, NE, E, SE, S, SW, W, NW.
_RING = ((-1, 0), (-1, 1), (0, 1), (1, 1), (1, 0), (1, -1), (0, -1), (-1, -1))
_BITS = np.array([[(code >> k) & 1 for k in range(8)] for code in range(256)], dtype=np.uint8)
_COUNT = _BITS.sum(axis=1).astype(np.uint8)


def _zhang_suen_tables():
    p = _BITS.astype(bool)
    n, e, s, w = p[:, 0], p[:, 2], p[:, 4], p[:, 6]
    transitions = (~p & np.roll(p, -1, axis=1)).sum(axis=1)
    base = (_COUNT >= 2) & (_COUNT <= 6) & (transitions == 1)
    first = base & ~(n & e & s) & ~(e & s & w)
    second = base & ~(n & e & w) & ~(n & s & w)
    return first, second


def _component_table():
    """Number of 8-connected pieces among the set neighbours, for each neighbourhood code."""
    table = np.zeros(256, dtype=np.uint8)
    for code in range(256):
        on = [k for k in range(8) if (code >> k) & 1]
        pieces = DisjointSets(on)
        for a in on:
            for b in on:
                step = (b - a) % 8
                # ring neighbours touch; two edge neighbours (N, E, S, W) touch across a corner
                if step == 1 or (step == 2 and a % 2 == 0):
                    pieces.union(a, b)
        table[code] = pieces.count
    return table


_ZS_FIRST, _ZS_SECOND = _zhang_suen_tables()
_PIECES = _component_table()


def _codes(image):
    """8-neighbourhood code of every pixel (bit k set when ring neighbour k is set)."""
    rows, cols = image.shape
    padded = np.pad(image, 1).astype(np.uint8)
    code = np.zeros((rows, cols), dtype=np.uint8)
    for bit, (dy, dx) in enumerate(_RING):
        code |= padded[1 + dy:1 + dy + rows, 1 + dx:1 + dx + cols] << bit
    return code


def thin(mask):
    """A one-pixel-thick, 8-connected skeleton with the topology of ``mask``.

    Parameters
    ----------
    mask : ndarray of bool, shape (H, W)

    Returns
    -------
    ndarray of bool
    """
    mask = np.asarray(mask, dtype=bool)
    image = np.pad(mask, 1).astype(np.uint8)
    stride = image.shape[1]
    flat = image.ravel()
    pixels = np.flatnonzero(flat)
    offsets = [dy * stride + dx for dy, dx in _RING]
    weights = np.array([1 << bit for bit in range(8)], dtype=np.uint8)

    def codes():
        code = np.zeros(len(pixels), dtype=np.uint8)
        for offset, weight in zip(offsets, weights):
            code |= flat[pixels + offset] * weight
        return code

    def sweep(select):
        """Remove the selected pixels until none is; the survivors stay listed."""
        nonlocal pixels
        changed = True
        while changed:
            changed = False
            for choose in select:
                remove = choose(codes())
                if remove.any():
                    flat[pixels[remove]] = 0
                    pixels = pixels[~remove]
                    changed = True

    sweep([lambda code: _ZS_FIRST[code], lambda code: _ZS_SECOND[code]])
    # no two pixels of one sub-lattice are neighbours, so removing them together is safe
    sweep([lambda code, a=a, b=b: (pixels // stride % 2 == a) & (pixels % stride % 2 == b)
           & (_PIECES[code] == 1) & (_COUNT[code] >= 2) for a in (0, 1) for b in (0, 1)])
    return image[1:-1, 1:-1].astype(bool)


def fill_small_holes(mask, max_area):
    """``mask`` with its holes (background pieces enclosed by it) under ``max_area`` pixels
    filled."""
    outside = np.pad(~mask, 1).astype(np.uint8)
    cv2.floodFill(outside, None, (0, 0), 2)  # the frame joins every piece touching the border
    holes = (outside[1:-1, 1:-1] == 1).astype(np.uint8)
    if not holes.any():
        return mask
    count, labels, stats, _ = cv2.connectedComponentsWithStats(holes, connectivity=4)
    small = stats[:, cv2.CC_STAT_AREA] < max_area
    small[0] = False  # label 0 is everything but the holes
    return mask | small[labels]


@dataclass(frozen=True)
class SkeletonClusters:
    """Branch clusters of a skeleton and how its branches connect them.

    Attributes
    ----------
    centres : ndarray, shape (K, 2)
        Each cluster's centroid ``(row, col)``.
    degree : ndarray of int, shape (K,)
        Branches leaving each cluster (a loop back to the same cluster counts twice); spurs
        shorter than the pruning length are not counted.
    links : ndarray of int, shape (L, 3)
        ``(cluster a, cluster b, branch length in pixels)`` for branches joining two clusters.
    """

    centres: np.ndarray
    degree: np.ndarray
    links: np.ndarray


def skeleton_clusters(skeleton, *, min_spur):
    """Cluster a skeleton's branch pixels and count the branches leaving each cluster.

    Parameters
    ----------
    skeleton : ndarray of bool
        One pixel thick (:func:`thin`).
    min_spur : float
        Branches with a free end that are shorter than this (pixels) are spurs: not counted.

    Returns
    -------
    SkeletonClusters
    """
    code = _codes(skeleton)
    branch = skeleton & (_COUNT[code] >= 3)
    ring = np.ones((3, 3), np.uint8)
    region = cv2.dilate(branch.astype(np.uint8), ring) > 0
    count, region_label = cv2.connectedComponents(region.astype(np.uint8), connectivity=8)
    if count <= 1:
        empty = np.zeros((0, 2))
        return SkeletonClusters(empty, np.zeros(0, int), np.zeros((0, 3), int))
    pieces = skeleton & ~region
    piece_count, piece_label = cv2.connectedComponents(pieces.astype(np.uint8), connectivity=8)
    length = np.bincount(piece_label.ravel(), minlength=piece_count)
    near_region = cv2.dilate(region.astype(np.uint8), ring) > 0
    neighbours = _COUNT[_codes(pieces)]
    # a piece's free end has one neighbour in the piece (none: a lone pixel, two free ends)
    free = pieces & ~near_region
    free_ends = (np.bincount(piece_label[free & (neighbours == 1)], minlength=piece_count)
                 + 2 * np.bincount(piece_label[free & (neighbours == 0)], minlength=piece_count))

    touch = pieces & near_region
    ys, xs = np.nonzero(touch)
    padded = np.pad(region_label, 1)
    pairs = []
    for dy, dx in _RING:
        neighbour = padded[ys + 1 + dy, xs + 1 + dx]
        hit = neighbour > 0
        pairs.append(np.column_stack([piece_label[ys[hit], xs[hit]], neighbour[hit]]))
    pairs = np.unique(np.concatenate(pairs), axis=0) if pairs else np.zeros((0, 2), int)

    degree = np.zeros(count, dtype=int)
    links = []
    for piece in np.unique(pairs[:, 0]):
        clusters = pairs[pairs[:, 0] == piece, 1]
        if free_ends[piece] and length[piece] < min_spur:
            continue
        if len(clusters) == 1:
            degree[clusters[0]] += 2 - min(int(free_ends[piece]), 2)
        else:
            degree[clusters] += 1
            if len(clusters) == 2:
                links.append((clusters[0] - 1, clusters[1] - 1, int(length[piece])))
    labels = region_label.ravel()
    flat = np.flatnonzero(labels)
    sums_r = np.bincount(labels[flat], weights=flat // skeleton.shape[1], minlength=count)
    sums_c = np.bincount(labels[flat], weights=flat % skeleton.shape[1], minlength=count)
    sizes = np.maximum(np.bincount(labels[flat], minlength=count), 1)
    centres = np.column_stack([sums_r / sizes, sums_c / sizes])[1:]
    return SkeletonClusters(centres, degree[1:],
                            np.array(links, dtype=int).reshape(-1, 3))

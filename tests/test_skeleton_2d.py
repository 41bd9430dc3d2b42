"""One-pixel skeletons and their branch clusters, checked exactly on drawn shapes."""

import cv2
import numpy as np
import pytest

from engine.stages.segmentation import cable_width, junction_centres, junction_map
from engine.stages.skeleton_2d import fill_small_holes, skeleton_clusters, thin


def _draw(size, lines, width):
    image = np.zeros(size, np.uint8)
    for start, end in lines:
        cv2.line(image, start, end, 1, width)
    return image > 0


def _neighbours(skeleton):
    padded = np.pad(skeleton, 1).astype(int)
    total = sum(np.roll(np.roll(padded, dy, 0), dx, 1)
                for dy in (-1, 0, 1) for dx in (-1, 0, 1) if dy or dx)
    return total[1:-1, 1:-1]


@pytest.mark.parametrize("width", [3, 4, 5, 6, 9])
@pytest.mark.parametrize("end", [(180, 100), (170, 160), (60, 175)])
def test_a_strand_thins_to_one_pixel_wide_line_without_forks(width, end):
    strand = _draw((200, 200), [((20, 30), end)], width)
    skeleton = thin(strand)
    assert skeleton.any() and (skeleton <= strand).all()
    assert cv2.connectedComponents(skeleton.astype(np.uint8), connectivity=8)[0] == 2
    degree = _neighbours(skeleton)[skeleton]
    assert degree.max() <= 2  # one pixel thick: no staircases
    assert (degree == 1).sum() == 2  # two ends
    assert len(skeleton_clusters(skeleton, min_spur=width).centres) == 0


def test_a_ring_keeps_its_hole():
    ring = np.zeros((120, 120), np.uint8)
    cv2.circle(ring, (60, 60), 40, 1, 8)
    skeleton = thin(ring > 0)
    count, labels = cv2.connectedComponents((~skeleton).astype(np.uint8), connectivity=4)
    assert count == 3  # outside and the hole
    assert _neighbours(skeleton)[skeleton].min() == 2


@pytest.mark.parametrize("width", [4, 5, 8])
def test_an_x_is_one_cluster_of_four_branches_and_a_t_of_three(width):
    x = _draw((200, 200), [((20, 20), (180, 180)), ((20, 180), (180, 20))], width)
    clusters = skeleton_clusters(thin(x), min_spur=width)
    junctions = clusters.degree >= 3
    if junctions.sum() == 1:
        assert clusters.degree[junctions][0] == 4
    else:  # two forks joined by a short branch
        assert junctions.sum() == 2 and sorted(clusters.degree[junctions]) == [3, 3]
        assert len(clusters.links) >= 1 and clusters.links[:, 2].min() <= width
    assert np.abs(clusters.centres[junctions].mean(axis=0) - 100).max() < 2

    t = _draw((200, 200), [((20, 100), (180, 100)), ((100, 100), (100, 185))], width)
    clusters = skeleton_clusters(thin(t), min_spur=width)
    assert sorted(clusters.degree[clusters.degree >= 3]) == [3]


def test_spurs_shorter_than_the_limit_are_not_branches():
    strand = _draw((120, 200), [((10, 60), (190, 60))], 9)
    strand[50:56, 100:104] = True  # a bump: its skeleton twig is a short spur
    clusters = skeleton_clusters(thin(strand), min_spur=9)
    assert not (clusters.degree >= 3).any()


def test_small_holes_are_filled_and_a_loops_middle_is_not():
    mask = np.zeros((100, 100), bool)
    cv2.circle(mask.view(np.uint8), (50, 50), 35, 1, 10)
    mask[20:80, 45:55] = True  # a bar across the loop
    mask[48:51, 49:51] = False  # a speck of background inside the bar
    filled = fill_small_holes(mask, 20)
    assert filled[49, 50] and not filled[50, 30] and not filled[50, 70]


@pytest.mark.parametrize("angle", [35, 45, 90])
def test_one_junction_centre_per_crossing_whatever_its_angle(angle):
    half = np.radians(angle / 2)
    centre = np.array([200, 150])
    arm = 140 * np.array([np.cos(half), np.sin(half)])
    lines = [(tuple((centre - arm).astype(int)), tuple((centre + arm).astype(int))),
             (tuple((centre - arm * [1, -1]).astype(int)),
              tuple((centre + arm * [1, -1]).astype(int)))]
    mask = _draw((300, 400), lines, 12)
    width = cable_width(mask)
    centres = junction_centres(mask, width)
    assert len(centres) == 1
    assert np.hypot(*(centres[0] - (centre + 0.5))) < 0.5 * width
    junctions = junction_map(mask, width)
    ys, xs = np.nonzero(junctions)
    # only the middle of the crossing (3 r = 1.5 widths), never along the arms
    assert np.hypot(xs - centre[0], ys - centre[1]).max() <= 1.5 * width


def test_a_very_shallow_crossing_is_marked_at_its_two_forks():
    # at 20 degrees the strands overlap over 5 widths and the skeleton's two forks are too far
    # apart to be one crossing in this view: each fork is a junction, where the strands part
    half = np.radians(10)
    arm = 150 * np.array([np.cos(half), np.sin(half)])
    centre = np.array([200, 150])
    lines = [(tuple((centre - arm).astype(int)), tuple((centre + arm).astype(int))),
             (tuple((centre - arm * [1, -1]).astype(int)),
              tuple((centre + arm * [1, -1]).astype(int)))]
    mask = _draw((300, 400), lines, 12)
    width = cable_width(mask)
    centres = junction_centres(mask, width) - 0.5
    assert len(centres) == 2
    assert np.abs(centres[:, 1] - centre[1]).max() < 1
    assert abs(centres[:, 0].mean() - centre[0]) < 1
    overlap = 0.5 * width / np.tan(half)  # where the two strands' edges part
    distance = np.abs(centres[:, 0] - centre[0])
    assert ((distance > 0.6 * overlap) & (distance < overlap)).all()  # inside the overlap


def test_no_junction_at_a_tight_bend_or_beside_a_close_parallel_strand():
    mask = np.zeros((300, 400), np.uint8)
    cv2.ellipse(mask, (200, 150), (24, 24), 0, 0, 180, 1, 12)  # a U-turn of radius 2 widths
    cv2.line(mask, (176, 150), (176, 20), 1, 12)
    cv2.line(mask, (224, 150), (224, 20), 1, 12)
    cv2.line(mask, (30, 280), (370, 280), 1, 12)
    cv2.line(mask, (30, 262), (370, 262), 1, 12)  # 1.5 widths apart, centre to centre
    mask = mask > 0
    assert len(junction_centres(mask, cable_width(mask))) == 0
    assert not junction_map(mask, cable_width(mask)).any()

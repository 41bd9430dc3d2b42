"""Several cables in one capture: their ground truth, their rendering, their metrics, their
masks (``SegmentationSettings.all_cables``) and one path each end to end."""

import dataclasses

import cv2
import numpy as np
import pytest

from engine.evaluation.metrics import evaluate
from engine.io.ground_truth import GroundTruth, TrueCrossing, read_ground_truth
from engine.io.result import CablePath, Result
from engine.pipeline import PipelineSettings, run_reconstruction
from engine.stages.segmentation import (SegmentationSettings, SeveralCables, _joined,
                                        reference_frames, segment_frame, sequence_colour)
from engine.synthetic.layouts import find_crossings_2d, pair_layout
from engine.synthetic.scene import look_scene, look_spec, make_scene, write_scene


def iou(a, b):
    return (a & b).sum() / max((a | b).sum(), 1)


@pytest.mark.parametrize("seed", range(4))
def test_a_pair_layout_is_two_cables_that_cross(seed):
    truth = pair_layout(3, seed=seed)
    assert len(truth.breaks) == 1 and len(truth.cables) == 2
    first, second = (truth.centreline[cable] / truth.radius for cable in truth.cables)
    # the crossings are those of the two cables in the table plane, at least one between them
    between = [c for c in truth.crossings if truth.cable_of(c.over) != truth.cable_of(c.under)]
    assert between and len(truth.crossings) == 3
    within = sum(len(find_crossings_2d(points)) for points in (first, second))
    assert within == len(truth.crossings) - len(between)
    for crossing in truth.crossings:  # the over strand lies above the under one
        over, under = truth.centreline[[crossing.over, crossing.under]] / truth.radius
        assert np.linalg.norm(over[:2] - under[:2]) < 0.5 and over[2] - under[2] >= 2.0
    # the two new ends lie apart, and lengths leave the gap out
    assert np.linalg.norm(first[-1, :2] - second[0, :2]) >= 12.0
    steps = sum(np.linalg.norm(np.diff(p, axis=0), axis=1).sum() for p in (first, second))
    assert truth.length / truth.radius == pytest.approx(steps)
    arc = truth.arc_length / truth.radius
    assert arc[truth.breaks[0]] - arc[truth.breaks[0] - 1] >= 100.0


def test_breaks_are_checked_and_written():
    points = np.column_stack([np.arange(10.0), np.zeros(10), np.zeros(10)])
    with pytest.raises(ValueError, match="breaks"):
        GroundTruth(points, 1.0, breaks=(9,))
    with pytest.raises(ValueError, match="open"):
        GroundTruth(points, 1.0, closed=True, breaks=(5,))
    truth = GroundTruth(points, 1.0, (TrueCrossing(2, 7, 90.0),), breaks=(5,))
    assert truth.cable_of(4) == 0 and truth.cable_of(5) == 1
    assert truth.length == pytest.approx(8.0)
    back = GroundTruth.from_dict(truth.to_dict())
    assert back.breaks == (5,)
    result = truth.as_result()
    assert [len(path.points) for path in result.paths] == [5, 5]
    crossing = result.crossings[0]
    assert (crossing.over.path, crossing.over.index) == (0, 2)
    assert (crossing.under.path, crossing.under.index) == (1, 2)


def test_metrics_want_one_path_per_cable():
    truth = pair_layout(3, seed=1)
    perfect = evaluate(truth.as_result(), truth)
    assert perfect.one_path and perfect.path_count == 2 and perfect.wrong_connections == 0
    assert perfect.accuracy_max < 1e-9 and perfect.crossings_right == 3
    joined = evaluate(Result(radius=truth.radius, paths=(CablePath(truth.centreline),)), truth)
    assert not joined.one_path and joined.wrong_connections >= 1
    half = evaluate(Result(radius=truth.radius,
                           paths=(CablePath(truth.centreline[truth.cables[0]]),)), truth)
    assert not half.one_path and half.completeness < 0.8
    first = truth.centreline[truth.cables[0]]  # two paths, both on the first cable
    twice = evaluate(Result(radius=truth.radius, paths=(
        CablePath(first[:len(first) // 2]), CablePath(first[len(first) // 2:]))), truth)
    assert twice.path_count == 2 and twice.wrong_connections == 0 and not twice.one_path


@pytest.fixture(scope="module")
def pair_scene():
    """A two-cable look (tuning seed) at 640x480."""
    return look_scene("two_cables", 0, views=10, width=640, height=480)


def hue_of(rgb):
    return int(cv2.cvtColor(np.uint8([[rgb]]), cv2.COLOR_RGB2HSV)[0, 0, 0])


def test_each_cable_is_drawn_in_its_colour_and_nothing_in_the_gap(pair_scene):
    truth, look = pair_scene.truth, pair_scene.spec.look
    assert pair_scene.spec.kind == "pair" and look.other_cable_colour is not None
    camera, image, mask = pair_scene.cameras[0], pair_scene.images[0], pair_scene.masks[0]
    hue = cv2.cvtColor(image, cv2.COLOR_RGB2HSV)[..., 0].astype(int)
    for cable, colour in zip(truth.cables, (look.cable_colour, look.other_cable_colour)):
        pixels, _ = camera.project(truth.centreline[cable])
        cols, rows = np.round(pixels - 0.5).astype(int).T
        seen = mask[rows, cols]
        gap = np.abs(hue[rows, cols][seen] - hue_of(colour))
        assert np.mean(np.minimum(gap, 180 - gap) < 12) > 0.6
    # the table between the two cut ends is the table (no shadow drawn across the gap)
    ends = truth.centreline[[truth.breaks[0] - 1, truth.breaks[0]]]
    middle, _ = camera.project(0.5 * (ends[0] + ends[1])[None, :] * [1, 1, 0])
    col, row = np.round(middle[0] - 0.5).astype(int)
    around = image[row - 2:row + 3, col - 2:col + 3].reshape(-1, 3).mean(axis=0)
    ring = image[row - 30:row + 31, col - 30:col + 31]
    ring = ring[~mask[row - 30:row + 31, col - 30:col + 31]].reshape(-1, 3)
    assert np.linalg.norm(around - np.median(ring, axis=0)) < 40


def test_all_cables_learns_a_model_per_cable_and_masks_both(pair_scene):
    images = list(pair_scene.images)
    frames = [images[k] for k in reference_frames(len(images), 0, 3)]
    _, one_model = sequence_colour(frames)
    assert not isinstance(one_model, SeveralCables)
    settings = SegmentationSettings(all_cables=True)
    colour, several = sequence_colour(frames, None, settings)
    assert isinstance(several, SeveralCables) and len(several.cables) == 2
    hues = sorted(hue_of(c) for c in (pair_scene.spec.look.cable_colour,
                                      pair_scene.spec.look.other_cable_colour))
    centres = sorted(((c.low[0] + ((c.high[0] - c.low[0]) % 180) / 2) % 180)
                     for c, _ in several.cables)
    for centre, hue in zip(centres, hues):
        assert min(abs(centre - hue), 180 - abs(centre - hue)) < 15
    # the joined masks hold each cable's centreline where it is seen (the one-colour run's
    # masks hold 0.97-0.99 of each here too, since the outline's classifier was learnt on
    # masks without the colour refinement: they are not the measure)
    truth = pair_scene.truth
    for k in (0, 5):
        joined = segment_frame(images[k], colour, settings, model=several)
        assert iou(joined.mask, pair_scene.masks[k]) > 0.85
        camera, seen = pair_scene.cameras[k], pair_scene.masks[k]
        for cable in truth.cables:
            pixels, _ = camera.project(truth.centreline[cable])
            cols, rows = np.round(pixels - 0.5).astype(int).T
            inside = (cols >= 0) & (cols < seen.shape[1]) & (rows >= 0) & (rows < seen.shape[0])
            cols, rows = cols[inside], rows[inside]
            visible = seen[rows, cols]
            assert visible.sum() > 100
            assert joined.mask[rows, cols][visible].mean() >= 0.98, (k, cable)


@pytest.mark.parametrize("family, seed, count", [
    ("two_cables", 11, 2),  # the best candidate holds one cable's colours only
    ("two_cables", 48, 2),  # the dark ring both cast on a tinted table is no third (was 4)
    ("two_cables", 44, 2),  # nor on a green weave (was 3)
    ("saturated", 1, 1),
    ("same_hue", 1, 1),  # a table of the cable's hue is not another cable
    ("pale", 0, 1),  # nor is a colourless part of the table
])
def test_all_cables_finds_each_cable_and_nothing_else(family, seed, count):
    scene = look_scene(family, seed, views=10, width=640, height=480)
    frames = [scene.images[k] for k in reference_frames(10, 0, 3)]
    _, several = sequence_colour(frames, None, SegmentationSettings(all_cables=True))
    assert len(several.cables) == count


def test_two_cables_give_two_paths_and_their_crossings(tmp_path):
    spec = look_spec("two_cables", 1, views=16, width=800, height=600)
    scene = make_scene(spec)
    folder = write_scene(scene, tmp_path / "pair")
    settings = PipelineSettings()
    settings = dataclasses.replace(settings, segmentation=dataclasses.replace(
        settings.segmentation, all_cables=True))
    state = run_reconstruction(folder / "images", cameras=folder / "sparse", settings=settings)
    metrics = evaluate(state.result, read_ground_truth(folder / "ground_truth.json"))
    assert metrics.path_count == 2 and metrics.one_path
    assert metrics.crossings_right == metrics.crossings_total == 3
    assert metrics.accuracy_mean < 0.3
    # each path carries its own cable's colour (the material Blender gives it)
    truth = scene.truth
    for path in state.result.paths:
        cable = truth.cable_of(int(np.argmin(np.linalg.norm(
            truth.centreline - path.points[len(path.points) // 2], axis=1))))
        colour = (spec.look.cable_colour, spec.look.other_cable_colour)[cable]
        seen = tuple(int(round(255 * c)) for c in path.colour)
        gap = abs(hue_of(seen) - hue_of(colour))
        assert min(gap, 180 - gap) < 12


def test_the_seam_where_one_cable_passes_over_another_is_filled():
    first = np.zeros((60, 80), bool)
    first[:, 30:42] = True  # a cable 12 pixels wide, passing over...
    second = np.zeros_like(first)
    second[24:36, :29] = True  # ...another, whose outline stops a pixel short of it
    second[24:36, 43:] = True
    joined = _joined([first, second], 12.0)
    assert joined[30, 29] and joined[30, 42]  # the seam
    assert cv2.connectedComponents(joined.view(np.uint8))[0] == 2  # one piece
    apart = np.zeros_like(first)
    apart[24:36, :20] = True  # ten pixels away: not a seam
    assert not _joined([first, apart], 12.0)[30, 25]


def test_each_cable_s_model_is_learnt_again_from_its_masks():
    # tuning look two_cables seed 68: the green cable's first model finds a lit strip of it
    # only in most views (frame 7's mask 1.5 pixels wide, IoU 0.56 with both cables); learnt
    # again from its own masks it finds the whole of it
    scene = look_scene("two_cables", 68, views=10, width=960, height=720)
    frames = [scene.images[k] for k in reference_frames(10, 0, 3)]
    settings = SegmentationSettings(all_cables=True)
    colour, several = sequence_colour(frames, None, settings)
    mask, truth = segment_frame(scene.images[7], colour, settings, model=several).mask, \
        scene.masks[7]
    assert (mask & truth).sum() / (mask | truth).sum() > 0.9

"""The side of a cable its colours missed, put back by its shape (engine.stages.missing_side),
and never a shadow or a rim of mixed pixels."""

from dataclasses import replace

import cv2
import numpy as np
import pytest

from engine.stages import missing_side
from engine.stages.segmentation import SegmentationSettings, cable_mask, cable_width

TABLE = (120, 95, 125)  # a purple-grey table


def table(seed=0, shape=(240, 320)):
    """A table of slightly noisy colour."""
    noise = np.random.default_rng(seed).normal(0.0, 4.0, shape + (3,))
    return np.clip(np.array(TABLE, float) + noise, 0, 255).astype(np.uint8)


def band(shape, offset, width):
    """A curved band: the pixels between two parallel arcs ``offset`` to ``offset + width``
    pixels below the curve y = 70 + 0.002 (x - 160)^2 (x from 30 to 290)."""
    rows, cols = np.mgrid[:shape[0], :shape[1]].astype(float)
    below = rows - (70.0 + 0.002 * (cols - 160.0) ** 2)
    return (below >= offset) & (below < offset + width) & (cols >= 30) & (cols < 290)


def with_missing_side(mask, image, width, settings=SegmentationSettings()):
    """The step with the segmentation's default options."""
    return missing_side.with_missing_side(
        mask, image, width, reach=settings.side_reach, chroma_gap=settings.side_chroma,
        contrast=settings.side_contrast, contact=settings.side_contact)


def iou(a, b):
    return (a & b).sum() / (a | b).sum()


def test_a_two_tone_cables_missed_half_comes_back():
    image = table()
    found, missed = band(image.shape[:2], 0, 6), band(image.shape[:2], 6, 6)
    image[found] = (220, 40, 40)   # the colour the model knows
    image[missed] = (60, 160, 70)  # the second colour, which it missed
    out = with_missing_side(found, image, cable_width(found))
    assert iou(found, found | missed) < 0.55
    assert iou(out, found | missed) > 0.9


def test_a_shadow_beside_the_cable_is_never_taken():
    image = table()
    cable, shadow = band(image.shape[:2], 0, 8), band(image.shape[:2], 8, 8)
    image[cable] = (230, 230, 225)
    image[shadow] = (np.array(TABLE) * 0.55).astype(np.uint8)  # the table, darker
    out = with_missing_side(cable, image, cable_width(cable))
    assert not (out & shadow).any()


def test_a_grey_cables_lit_side_comes_back_but_not_the_shadow_beside_it():
    """Tuning look neutral seed 3: a dark grey cable on pinkish paper, only its shaded side
    found. Its lit side is darker than the paper and within the chromaticity gap of it that
    calls a pixel shadow, but its chromaticity is the found side's, not the paper's; the cast
    shadow beyond the shaded side is the paper's, darker, and stays out."""
    paper = (190, 175, 182)
    noise = np.random.default_rng(1).normal(0.0, 3.0, (240, 320, 3))
    image = np.clip(np.array(paper, float) + noise, 0, 255).astype(np.uint8)
    lit, found = band(image.shape[:2], 0, 6), band(image.shape[:2], 6, 6)
    shadow = band(image.shape[:2], 12, 8)
    image[lit] = (104, 104, 106)
    image[found] = (50, 50, 50)
    image[shadow] = (np.array(paper) * 0.55).astype(np.uint8)  # the paper, darker
    out = with_missing_side(found, image, cable_width(found))
    assert iou(found, found | lit) < 0.55
    assert iou(out, found | lit) > 0.9
    assert not (out & shadow).any()
    # the same side of the paper's chromaticity is its shadow, not the cable's
    image[lit] = (np.array(paper) * 0.55).astype(np.uint8)
    assert not (with_missing_side(found, image, cable_width(found)) & lit).any()


def test_a_whole_cable_keeps_its_outline():
    image = table()
    cable = band(image.shape[:2], 0, 10)
    image[cable] = (40, 170, 60)
    image = cv2.GaussianBlur(image, (5, 5), 1.0)  # mixed pixels on the outline
    out = with_missing_side(cable, image, cable_width(cable))
    assert (out ^ cable).sum() <= 0.02 * cable.sum()


def test_a_thing_of_another_colour_beside_the_cable_is_not_its_side():
    image = table()
    cable = band(image.shape[:2], 0, 6)
    image[cable] = (220, 40, 40)
    image[150:230, 140:200] = (40, 60, 200)  # a blue box under the cable's lowest point
    out = with_missing_side(cable, image, cable_width(cable))
    assert not out[150:230, 140:200].any()


def test_an_object_of_the_cables_colour_does_not_grow_to_its_other_faces():
    image = table()
    cable = band(image.shape[:2], 0, 6)
    image[cable] = (220, 40, 40)
    face = np.zeros(cable.shape, dtype=bool)
    face[160:190, 40:70] = True  # a box's lit face, of the cable's colour, in the mask
    image[face] = (220, 40, 40)
    image[160:190, 70:76] = (110, 20, 20)  # its shaded face, which the colours missed
    out = with_missing_side(cable | face, image, cable_width(cable))
    assert not out[160:190, 70:76].any()


def test_the_segmentation_puts_a_missed_side_back_and_reach_0_does_not():
    image = table()
    found, missed = band(image.shape[:2], 0, 6), band(image.shape[:2], 6, 6)
    image[found] = (220, 40, 40)
    image[missed] = (60, 160, 70)
    from engine.stages.segmentation import ColourRange

    red = ColourRange(np.array([170, 120, 120]), np.array([8, 255, 255]))
    # the step alone: on this flat two-tone band the outline's classifier, whose cable colour
    # is the two tones' mean, takes part of the second side away again (0.77 IoU)
    settings = replace(SegmentationSettings(), model=False, outline_passes=0)
    with_side, _ = cable_mask(image, red, settings)
    without, _ = cable_mask(image, red, replace(settings, side_reach=0.0))
    assert iou(with_side, found | missed) > 0.9
    assert iou(without, found | missed) < 0.6


@pytest.mark.parametrize("width", [0.0])
def test_nothing_to_do_without_a_width(width):
    mask = band((240, 320), 0, 6)
    assert with_missing_side(mask, table(), width) is mask


def test_a_white_cables_grey_side_on_grey_print_comes_back():
    """Tuning look neutral seed 2: a white cable on printed paper, whose grey shade side the
    colours miss (0.64 IoU without the step)."""
    from engine.stages.segmentation import reference_frames, segment_frame, sequence_colour
    from engine.synthetic.looks import TUNING_SEEDS
    from engine.synthetic.scene import look_scene

    scene = look_scene("neutral", TUNING_SEEDS[2], views=4, width=960, height=720)
    images, truths = list(scene.images), list(scene.masks)
    # the step alone: the outline's classifier after it puts back part of that side too
    settings = SegmentationSettings(outline_passes=0)
    frames = reference_frames(len(images), 0, settings.model_frames)
    colour, model = sequence_colour([images[k] for k in frames], None, settings)
    scores = {reach: np.mean([iou(segment_frame(image, colour, replace(settings,
                                                                     side_reach=reach),
                                                model=model).mask, truth)
                              for image, truth in zip(images, truths)])
              for reach in (0.0, settings.side_reach)}
    assert scores[0.0] < 0.75 and scores[settings.side_reach] > scores[0.0] + 0.1


def test_a_two_tone_cable_s_pale_side_is_searched_again_after_the_outline():
    """Before the outline's classifier the mask holds mixed pixels of a two-tone cable's
    missed side, so the strip it misses lies within the rim; the classifier takes them for
    the table, and a second search after it puts more of the side back. Tuning look patterned
    seed 4 (green along one side, a pale lilac along the other, on grey paper), frames 0-2:
    0.630 IoU without the second search, 0.675 with it (each frame 0.62-0.64 and 0.67-0.68).
    Seed 33 (orange and pinkish white on blue-grey print), which this test used until the
    classifier read a two-tone cable's colour from the rim on the pixel's own side (30d1f83),
    now keeps most of its white side by the classifier alone: 0.710 without, 0.737 with."""
    from engine.stages.segmentation import reference_frames, segment_frame, sequence_colour
    from engine.synthetic.scene import look_scene

    scene = look_scene("patterned", 4, views=10, width=960, height=720)
    colour, model = sequence_colour([scene.images[k] for k in reference_frames(10, 0, 3)])
    ious = [iou(segment_frame(scene.images[k], colour, model=model).mask, scene.masks[k])
            for k in range(3)]
    assert np.mean(ious) > 0.66

"""The automatic choice of the cable and its colour model (engine.stages.colour_model)."""

from pathlib import Path

import cv2
import numpy as np
import pytest

from engine.bench.looks import naive_mask
from engine.errors import ReconstructionError
from engine.io.image_sequence import read_image
from engine.stages.colour_model import _SPACES, ColourModel, _nearest, find_cable, thin_pieces
from engine.stages.segmentation import reference_frames, segment_frame, sequence_colour
from engine.synthetic.scene import look_scene

REAL = Path(__file__).resolve().parents[2] / "shared" / "real" / "mbest-s1"


def iou(a, b):
    return (a & b).sum() / max((a | b).sum(), 1)


def test_thin_pieces_tell_a_cable_from_a_box():
    mask = np.zeros((200, 300), np.uint8)
    cv2.polylines(mask, [np.array([[10, 20], [150, 60], [280, 30]], np.int32)], False, 1, 7)
    cv2.rectangle(mask, (40, 120), (90, 170), 1, -1)
    labels, thin, half_width, area = thin_pieces(mask > 0)
    line, box = labels[22, 12], labels[140, 60]
    assert thin[line] and not thin[box]
    # the ridge's distance to the outside is half the width plus half a pixel
    assert 6.0 <= 2 * half_width[line] <= 10.0  # a 7 px line


def test_each_pixel_goes_to_its_nearest_centre_and_the_first_of_equals():
    rng = np.random.default_rng(4)
    lab = rng.uniform([0, -60, -60], [100, 60, 60], (37, 23, 3)).astype(np.float32)
    centres = rng.uniform([0, -60, -60], [100, 60, 60], (7, 3)).astype(np.float32)
    lab[0, :3] = centres[2]  # on a centre
    centres[5] = centres[1]  # two equal centres: the first wins
    lab[1, :3] = centres[1]
    distances = ((lab[:, :, None, :] - centres[None, None]) ** 2).sum(axis=3)
    expected = np.argmin(distances, axis=2)  # argmin takes the first of equals
    nearest = _nearest(lab, centres)
    np.testing.assert_array_equal(nearest, expected)
    assert (nearest[0, :3] == 2).all() and (nearest[1, :3] == 1).all() and not (nearest == 5).any()


def test_the_model_looks_colours_up_as_its_histograms_say():
    rng = np.random.default_rng(1)
    image = np.full((120, 160, 3), (120, 110, 90), np.uint8)
    image = np.clip(image + rng.normal(0, 6, image.shape), 0, 255).astype(np.uint8)
    seed = np.zeros(image.shape[:2], bool)
    seed[50:58, 10:150] = True
    image[seed] = (200, 40, 40)
    model = ColourModel.learn([image], [seed], widths=[8.0])
    probability = model.probability(image)
    assert probability[seed].min() > 200 and probability[~seed].max() < 60
    # the mean of the two colour spaces' look-ups, bin by bin (OpenCV's bindings would read a
    # (b, b, b) table as b channels of a 2-D one: the look-up must stay 3-D)
    expected = np.zeros(image.shape[:2])
    for space, lut in zip(_SPACES, model.luts):
        index = space(image).astype(int) * lut.shape[0] // 256
        expected += 0.5 * lut[index[..., 0], index[..., 1], index[..., 2]]
    assert np.abs(probability - expected).max() <= 1.0


@pytest.mark.parametrize("family", ["pale", "air", "neutral", "patterned"])
def test_the_cable_is_found_on_every_look(family):
    scene = look_scene(family, 0, views=10, width=640, height=480)
    frames = [scene.images[k] for k in reference_frames(10, 0, 3)]
    colour, candidate = find_cable(frames)
    found = candidate.select_rgb(scene.images[0])
    truth = scene.masks[0]
    # most of what is chosen lies on the cable, and it covers much of the cable
    assert (found & truth).sum() > 0.5 * found.sum()
    assert (found & truth).sum() > 0.3 * truth.sum()


def test_the_cable_is_found_among_objects_of_other_colours():
    # clutter tuning seed 0: a green cable among objects, two of them green boxes. The chosen
    # clusters hold other pixels too (72% of them on the cable at this size; 48% while a
    # closing that widened the pieces still raised a candidate's score), but their shape keeps
    # the boxes out of the masks
    scene = look_scene("clutter", 0, views=10, width=640, height=480)
    colour, model = sequence_colour([scene.images[k] for k in reference_frames(10, 0, 3)])
    ious = [iou(segment_frame(image, colour, model=model).mask, truth)
            for image, truth in zip(scene.images, scene.masks)]
    assert np.mean(ious) > 0.85
    assert np.mean(ious) > np.mean([iou(naive_mask(i), t)
                                    for i, t in zip(scene.images, scene.masks)]) + 0.3


@pytest.mark.parametrize("seed", [16, 54], ids=["no pair ranks high", "bands a pixel apart"])
def test_a_striped_cable_is_found_not_the_tiles_grout(seed):
    # 16: blue and white stripes on green tiles: each stripe colour alone, and each pair of
    # the cable's four colour clusters, is less cable-like than the tiles' grout, so a search
    # started from the best few clusters and pairs chose the grout.
    # 54: orange and cyan stripes on teal tiles: at the scoring size the bands meet in a pixel
    # of a mixed colour, a tile's cluster, so the cable's clusters were eighty short pieces and
    # the grout (a net, penalised) still scored higher, until one-pixel gaps were closed
    scene = look_scene("patterned", seed, views=10, width=640, height=480)
    _, candidate = find_cable([scene.images[k] for k in reference_frames(10, 0, 3)])
    found, truth = candidate.select_rgb(scene.images[0]), scene.masks[0]
    assert (found & truth).sum() > 0.8 * found.sum()
    assert (found & truth).sum() > 0.6 * truth.sum()


def test_a_line_along_the_cable_s_edge_is_not_joined_to_it():
    # hard light tuning seed 2 (the pipeline's 24 views): a dark green cluster, half of it a
    # one-pixel line along the cable's edge, one pixel off it. Closed, that line widened the
    # cable and its cluster outscored the shade side's in the chosen group, whose colours then
    # covered half the cable in the first frame; a closing that widens the pieces no longer
    # raises a candidate's score
    scene = look_scene("hard_light", 2, views=24, width=960, height=720)
    frames = reference_frames(24, 0, 3)
    _, candidate = find_cable([scene.images[k] for k in frames])
    for k in frames:
        found, truth = candidate.select_rgb(scene.images[k]), scene.masks[k]
        assert (found & truth).sum() > 0.9 * found.sum()
        assert (found & truth).sum() > 0.85 * truth.sum()


def test_a_cast_shadow_is_not_the_cable():
    scene = look_scene("air", 3, views=10, width=640, height=480)
    colour, model = sequence_colour([scene.images[k] for k in reference_frames(10, 0, 3)])
    masks = [segment_frame(image, colour, model=model).mask for image in scene.images]
    ious = [iou(mask, truth) for mask, truth in zip(masks, scene.masks)]
    assert np.mean(ious) > 0.8
    # beats a plain threshold, which takes the shadow or the table
    assert np.mean(ious) > np.mean([iou(naive_mask(i), t)
                                    for i, t in zip(scene.images, scene.masks)])


def test_a_net_of_thin_lines_is_not_the_cable():
    # dark grout lines between tiles are thin too, but enclose many holes
    image = np.full((480, 640, 3), (150, 170, 150), np.uint8)
    for x in range(0, 640, 60):
        cv2.line(image, (x, 0), (x, 479), (40, 45, 40), 4)
    for y in range(0, 480, 60):
        cv2.line(image, (0, y), (639, y), (40, 45, 40), 4)
    curve = np.array([[60, 400], [200, 120], [380, 330], [580, 90]], np.int32)
    cable = np.zeros(image.shape[:2], np.uint8)
    cv2.polylines(cable, [curve], False, 1, 9)
    image[cable > 0] = (150, 60, 200)
    _, candidate = find_cable([image])
    found = candidate.select_rgb(image)
    assert (found & (cable > 0)).sum() > 0.8 * found.sum()


def test_lines_running_out_of_the_view_are_not_the_cable():
    """Grout lines that enclose few holes but run out of the view (same-hue tuning seed 372:
    a blue cable on blue-grey tiles, the grout chosen, 0.19 IoU; 0.93 since): every cell
    between them touches the frame's border, while a cable in the view leaves one region
    there. The dark lines stand out more than the cable of nearly the table's colour, and
    part the frame into 16 cells, too few for the holes' penalty to count for much (0.8): the
    lines were chosen."""
    image = np.full((480, 640, 3), (120, 140, 170), np.uint8)
    for x in range(40, 640, 80):
        cv2.line(image, (x, 0), (x, 479), (50, 55, 65), 4)
    cv2.line(image, (0, 240), (639, 240), (50, 55, 65), 4)
    cable = np.zeros(image.shape[:2], np.uint8)
    cv2.polylines(cable, [np.array([[90, 400], [200, 120], [380, 330], [560, 90]], np.int32)],
                  False, 1, 9)
    image[cable > 0] = (105, 135, 190)
    _, candidate = find_cable([image])
    found = candidate.select_rgb(image)
    assert (found & (cable > 0)).sum() > 0.8 * found.sum()


def _wire_on_a_busy_table(width, height, wire):
    """A red wire ``wire`` pixels wide on a table of beige and brown blobs."""
    rng = np.random.default_rng(3)
    image = np.full((height, width, 3), (170, 150, 120), np.uint8)
    for _ in range(300):
        centre = (int(rng.integers(0, width)), int(rng.integers(0, height)))
        axes = (int(rng.integers(20, 120)), int(rng.integers(10, 60)))
        colour = tuple(int(c) for c in rng.integers(90, 200, 3))
        cv2.ellipse(image, centre, axes, float(rng.uniform(0, 180)), 0, 360, colour, -1)
    curve = np.column_stack([np.linspace(0.1, 0.9, 40) * width,
                             (0.5 + 0.3 * np.sin(np.linspace(0, 9, 40))) * height])
    cable = np.zeros((height, width), np.uint8)
    cv2.polylines(cable, [curve.astype(np.int32)], False, 1, wire)
    image[cable > 0] = (180, 30, 30)
    return image, cable > 0


def test_a_thin_wire_in_a_large_frame_is_found(monkeypatch):
    from engine.stages import colour_model

    image, cable = _wire_on_a_busy_table(2880, 1920, 5)
    _, candidate = find_cable([image])
    assert iou(candidate.select_rgb(image), cable) > 0.7
    # at the first scoring size alone the wire is under a pixel wide and a blob is chosen
    monkeypatch.setattr(colour_model, "_SHARPER", np.inf)
    _, candidate = find_cable([image])
    assert iou(candidate.select_rgb(image), cable) < 0.3


def test_no_cable_is_a_clear_error():
    with pytest.raises(ReconstructionError, match="no cable pixels"):
        find_cable([np.full((240, 320, 3), 128, np.uint8)])


@pytest.mark.skipif(not (REAL / "labels").is_dir(), reason="the real photos are not here")
def test_real_photos_of_a_pink_cable_on_black():
    paths = sorted((REAL / "images").iterdir())
    images = [read_image(p) for p in paths]
    labels = [cv2.imread(str(REAL / "labels" / (p.stem + ".png")), cv2.IMREAD_GRAYSCALE) > 127
              for p in paths]
    colour, model = sequence_colour([images[k] for k in reference_frames(len(images), 0, 3)])
    ours = [iou(segment_frame(i, colour, model=model).mask, t) for i, t in zip(images, labels)]
    naive = [iou(naive_mask(i), t) for i, t in zip(images, labels)]
    assert np.mean(ours) >= 0.90 and np.mean(ours) > np.mean(naive)


def _sine_bands(seed, *bands, shape=(240, 320)):
    """Masks of bands along a sine curve across a frame: each ``(start, stop)`` rows from
    the curve."""
    xs = np.arange(20, 300)
    ys = (120 + 40 * np.sin(xs / 45.0 + seed)).astype(int)
    masks = [np.zeros(shape, bool) for _ in bands]
    for x, y in zip(xs, ys):
        for mask, (start, stop) in zip(masks, bands):
            mask[y + start:y + stop, x] = True
    return masks


def _shaded_cable_frame(seed):
    """A red cable (a sine curve) lit from above on a grey, noisy table: its lower third is
    its shade side, a third as bright, of the same chromaticity."""
    rng = np.random.default_rng(seed)
    image = np.clip(rng.normal(128, 5, (240, 320, 3)), 0, 255).astype(np.uint8)
    cable, shade = _sine_bands(seed, (-5, 5), (2, 5))
    image[cable & ~shade] = (210, 45, 30)
    image[shade] = (70, 15, 10)
    return image, cable


def test_the_shade_side_is_cable():
    """The shade side is darker than the table and a cluster of its own: the found colour's
    clusters miss it, its chromaticity brings it back."""
    frames, truths = zip(*(_shaded_cable_frame(seed) for seed in range(3)))
    colour, model = sequence_colour(frames)
    ious = [iou(segment_frame(frame, colour, model=model).mask, truth)
            for frame, truth in zip(frames, truths)]
    assert min(ious) >= 0.97, ious


def _cable_with_shadow(seed, *, table=(185, 150, 195), cable_colour=(22, 22, 26), shadow=0.55):
    """A dark cable (a sine curve, 10 px) on a noisy lilac table, its soft shadow 8 px wide
    below it: the table darkened, its chromaticity kept."""
    rng = np.random.default_rng(seed)
    image = np.clip(rng.normal(0, 4, (240, 320, 3)) + table, 0, 255)
    cable, dark = _sine_bands(seed, (-5, 5), (5, 13))
    dark &= ~cable
    image[dark] *= shadow
    image[cable] = cable_colour
    return image.astype(np.uint8), cable, dark


def test_a_dark_cable_s_soft_shadow_is_not_cable():
    """A black cable's soft shadow is dark too: the table darkened, of its chromaticity,
    leaves the mask; the cable stays whole."""
    from engine.stages.segmentation import SegmentationSettings, _without_shadow

    for seed in range(3):
        image, cable, dark = _cable_with_shadow(seed)
        kept = _without_shadow(cable | dark, image, 18.0, SegmentationSettings())
        assert (kept & cable).sum() >= 0.97 * cable.sum()
        assert (kept & dark).sum() <= 0.1 * dark.sum()


def test_a_rendered_black_cable_s_shadow_leaves_its_masks():
    """A black cable on a lilac table (a tuning scene of the neutral looks): the colour model
    takes its soft shadow in, and the masks lose most of it."""
    from engine.stages.segmentation import SegmentationSettings

    scene = look_scene("neutral", 6, views=3, width=960, height=720)
    colour, model = sequence_colour(list(scene.images))
    for frame, truth in zip(scene.images, scene.masks):
        found = segment_frame(frame, colour, model=model).mask
        plain = segment_frame(frame, colour, SegmentationSettings(shadow_chroma=0),
                              model=model).mask
        assert iou(found, truth) >= iou(plain, truth) + 0.1
        assert (found & ~truth).sum() <= 0.6 * (plain & ~truth).sum()


def test_a_grey_cable_s_soft_shadow_on_a_tinted_table_is_not_cable():
    """A grey cable on a green table: its soft shadow is darker than the darkest quarter's
    bound of a cable darker than its shadow, but of the table's chromaticity, and the cable's
    is not: the shadow leaves the mask from the cable's median brightness up."""
    from engine.stages.segmentation import SegmentationSettings, _without_shadow

    for seed in range(3):
        image, cable, dark = _cable_with_shadow(seed, table=(126, 181, 124),
                                                cable_colour=(60, 60, 60), shadow=0.55)
        kept = _without_shadow(cable | dark, image, 18.0, SegmentationSettings())
        assert (kept & cable).sum() >= 0.97 * cable.sum()
        assert (kept & dark).sum() <= 0.1 * dark.sum()


def _two_strands_nearly_touching():
    """An olive cable with a white highlight streak along it, two strands of it 16 px wide
    whose outlines come within 4 px of each other, on a pale blue table: the image, the true
    mask, the streak and the table's pixels between the strands where they are that close."""
    rng = np.random.default_rng(0)
    image = np.empty((360, 480, 3), np.float32)
    image[:] = (172, 182, 226)
    image += rng.normal(0, 3, image.shape)
    cable, streak = np.zeros((360, 480), np.uint8), np.zeros((360, 480), np.uint8)
    xs = np.arange(40, 440)
    bent = (170 + 0.0012 * (xs - 240) ** 2).astype(int)
    for ys in (np.full_like(xs, 150), bent):
        points = np.stack([xs, ys], 1).astype(np.int32)
        cv2.polylines(cable, [points], False, 1, 16)
        cv2.polylines(streak, [points], False, 1, 2)
    image[cable > 0] = (120, 112, 34)
    image[streak > 0] = (236, 236, 222)
    gap = np.zeros((360, 480), bool)
    for x, y in zip(xs, bent):
        if y - 8 - 158 < 8:
            gap[158:y - 8 + 1, x] = True
    return np.clip(image, 0, 255).astype(np.uint8), cable > 0, streak > 0, gap & (cable == 0)


def test_the_table_between_two_strands_nearly_touching_is_not_a_highlight():
    """The closing that bridges a glossy cable's highlight streak closes the narrow gap
    between two strands too, and the table there is as bright as a highlight; the colour
    model rules its colour out (the background is full of it), so it stays background while
    the streak still joins the cable."""
    from dataclasses import replace

    from engine.stages.segmentation import SegmentationSettings, cable_mask

    image, truth, streak, gap = _two_strands_nearly_touching()
    settings = SegmentationSettings()
    colour, model = sequence_colour([image], None, settings)
    mask, _ = cable_mask(image, colour, settings, model=model)
    assert (mask & gap).sum() <= 0.25 * gap.sum()
    assert mask[streak].mean() >= 0.95
    assert (mask & truth).sum() / (mask | truth).sum() > 0.98
    # without the model's say about half the gap is closed over: the scene tests the rule
    unguarded, _ = cable_mask(image, colour, replace(settings, highlight_probability=0.0),
                              model=model)
    assert (unguarded & gap).sum() >= 0.4 * gap.sum()


@pytest.mark.parametrize("table, cable_colour, shadow", [
    ((150, 150, 150), (70, 70, 70), 1.0),   # a grey cable on a grey table: as dark as a shadow
    ((150, 150, 150), (200, 40, 30), 0.4),  # a red cable's own shade side is not the table's
], ids=["grey on grey", "red shade side"])
def test_a_cable_like_a_shadow_keeps_every_pixel(table, cable_colour, shadow):
    from engine.stages.segmentation import SegmentationSettings, _without_shadow

    image, cable, dark = _cable_with_shadow(0, table=table, cable_colour=cable_colour,
                                            shadow=shadow)
    if shadow < 1.0:  # the dark band is the cable's shade side: its colour, darker
        image[dark] = np.array(cable_colour) * shadow
        cable = cable | dark
    assert _without_shadow(cable, image, 18.0, SegmentationSettings()).sum() >= \
        0.99 * cable.sum()


def test_a_bright_cable_s_hard_shadow_darker_than_it_is_not_cable():
    """Under a low hard sun a bright green cable casts a shadow darker than itself (so the
    mask's darkest quarter is the shadow, not the cable), tinted a little by the blue sky
    light: it still leaves the mask, and the cable stays whole."""
    from engine.stages.segmentation import SegmentationSettings, _without_shadow

    for seed in range(3):
        image, cable, dark = _cable_with_shadow(seed, cable_colour=(60, 190, 70), shadow=0.3)
        image[dark] = np.clip(image[dark] * np.array([0.95, 1.0, 1.15]), 0, 255)
        kept = _without_shadow(cable | dark, image, 18.0, SegmentationSettings())
        assert (kept & cable).sum() >= 0.97 * cable.sum()
        assert (kept & dark).sum() <= 0.1 * dark.sum()


def test_a_model_learnt_from_given_masks_segments_the_other_frames():
    from engine.stages.segmentation import colour_from_masks

    scene = look_scene("saturated", 0, views=4, width=640, height=480)
    images, truths = list(scene.images), list(scene.masks)
    colour, model = colour_from_masks(images[:2], truths[:2])
    assert model is not None and colour.has_hue
    for image, truth in zip(images[2:], truths[2:]):
        mask = segment_frame(image, colour, model=model).mask
        assert (mask & truth).sum() / (mask | truth).sum() > 0.85
    # masks of the table, not the cable, learn the table: the cable is not what they find
    table = [~cv2.dilate(t.view(np.uint8), np.ones((15, 15), np.uint8)).astype(bool)
             for t in truths[:2]]
    colour, model = colour_from_masks(images[:2], table)
    mask = segment_frame(images[2], colour, model=model).mask
    assert (mask & truths[2]).sum() / (mask | truths[2]).sum() < 0.5
    with pytest.raises(ValueError, match="2 frames but 1 masks"):
        colour_from_masks(images[:2], truths[:1])
    with pytest.raises(ValueError, match="no cable pixel"):
        colour_from_masks(images[:1], [np.zeros_like(truths[0])])


def test_the_looks_bench_s_oracle_seed_is_labelled_and_only_where_it_applies():
    from dataclasses import replace

    from engine.bench.looks import _oracle_mean, score_sequence
    from engine.stages.segmentation import SegmentationSettings

    scene = look_scene("saturated", 0, views=4, width=640, height=480)
    images, truths = list(scene.images), list(scene.masks)
    plain = score_sequence(images, truths)
    assert plain["oracle"] is None
    scored = score_sequence(images, truths, oracle=True)
    assert len(scored["oracle"]) == len(images) and scored["iou"] == plain["iou"]
    assert all(0.0 <= v <= 1.0 for v in scored["oracle"])
    several = score_sequence(images, truths, replace(SegmentationSettings(), all_cables=True),
                             oracle=True)
    assert several["oracle"] is None
    assert _oracle_mean([scored, scored]) == f"{np.mean(scored['oracle']):.3f}"
    assert _oracle_mean([scored, several]).endswith(" (1)")
    assert _oracle_mean([several]) == ""


class _FixedModel:
    """A colour model whose probabilities are given (0 to 255), whatever the frame."""

    def __init__(self, probability):
        self.level, self._probability = None, probability

    def probability(self, image_rgb):
        return self._probability


@pytest.mark.parametrize("on_cable, level", [(80, 0.3), (200, 0.5)])
def test_the_level_is_lowered_only_where_it_tells_the_samples_apart_better(on_cable, level):
    """A band of cable samples at a probability of 80/255 over a background at 20: only a
    level of 0.3 (77) or lower finds them, and 0.3 is the highest that does. At 200 the
    settings' level (0.5) finds them already and stays."""
    from engine.stages.segmentation import SegmentationSettings, calibrated_level

    probability = np.full((120, 160), 20, np.uint8)
    seed = np.zeros(probability.shape, bool)
    seed[50:62, 10:150] = True
    probability[seed] = on_cable
    seeds = [(seed, np.zeros_like(seed), 12.0)]
    model, image = _FixedModel(probability), np.zeros((*probability.shape, 3), np.uint8)
    assert calibrated_level(model, [image], seeds) == pytest.approx(level)
    # never below probability_least: none of 0.5, 0.45 and 0.4 is better than another
    assert calibrated_level(model, [image], seeds,
                            SegmentationSettings(probability_least=0.4)) == pytest.approx(0.5)


def test_a_pale_cable_whose_colours_the_background_shares_is_found_whole():
    """A pale blue-grey cable on purple tiles (tuning look pale, seed 5): the model gives
    its pixels a probability far below one half, though above the background's; the level
    its own samples choose finds the cable."""
    scene = look_scene("pale", 5, views=3, width=960, height=720)
    colour, model = sequence_colour(list(scene.images))
    assert model.level < 0.3
    ious = [iou(segment_frame(frame, colour, model=model).mask, truth)
            for frame, truth in zip(scene.images, scene.masks)]
    model.level = None  # the settings' level, one half
    plain = [iou(segment_frame(frame, colour, model=model).mask, truth)
             for frame, truth in zip(scene.images, scene.masks)]
    assert min(ious) >= 0.85 and np.mean(ious) >= np.mean(plain) + 0.1, (ious, plain)


class _Found:
    def __init__(self, width):
        self.width = width


def test_only_the_frames_whose_cable_came_out_thin_are_segmented_again():
    """Widths 10, 10, 2, 10 and 0 (no cable): frame 2 again, with the settings' share (0.9)
    of the median of the frames that have a cable as its least width; none with the floor
    off."""
    from engine.stages.segmentation import SegmentationSettings, segment_all

    widths, calls = [10.0, 10.0, 2.0, 10.0, 0.0], []

    def segment(number, least):
        calls.append((number, least))
        return _Found(max(widths[number], least) if widths[number] else 0.0)

    found = segment_all(segment, len(widths))
    assert calls == [(k, 0.0) for k in range(5)] + [(2, 9.0)]
    assert [f.width for f in found] == [10.0, 10.0, 9.0, 10.0, 0.0]
    calls.clear()
    segment_all(segment, len(widths), SegmentationSettings(width_floor=0.0))
    assert calls == [(k, 0.0) for k in range(5)]


def test_a_frame_whose_cable_came_out_thin_gets_the_sequence_s_width():
    """A green cable on a green table (tuning look same_hue, seed 1): in three of ten frames
    the mask's width comes out about half the other frames' (8-10 pixels against 17-20),
    and the steps it sizes (the missing side, the outline's classifier) keep too little of
    the cable. Segmented again with nine tenths of the median width as the least, those
    frames' masks cover more of the cable; the others do not change. (The scene of this test
    was a grey glossy cable, tuning look neutral seed 7, whose model found only its highlight
    in three frames, until the outline's classifier was learnt on masks without the colour
    refinement: it keeps that cable's body in every frame now.) The model is learnt once, as
    before the second learning (``relearn``), which widens those frames' masks too (two of
    them still come out under the floor, by less)."""
    from engine.stages.segmentation import SegmentationSettings, segment_images

    scene = look_scene("same_hue", 1, views=10, width=960, height=720)
    colour, model = sequence_colour([scene.images[k] for k in reference_frames(10, 0, 3)],
                                    None, SegmentationSettings(relearn=False))
    alone = [segment_frame(frame, colour, model=model) for frame in scene.images]
    found = segment_images(scene.images, colour, model=model)
    least = 0.9 * np.median([f.width for f in alone])
    thin = [k for k, f in enumerate(alone) if f.width < least]
    assert len(thin) >= 2 and all(alone[k].width < 0.6 * least for k in thin)
    for k in range(10):
        if k in thin:
            assert found[k].width >= least
            assert iou(found[k].mask, scene.masks[k]) >= iou(alone[k].mask,
                                                             scene.masks[k]) + 0.04, k
        else:
            assert np.array_equal(found[k].mask, alone[k].mask)


def test_the_model_is_learnt_again_from_the_masks_it_gives():
    """A cable in two colours along long sections (tuning look patterned, seed 23: red and
    white on dark print): the colour found is the red, and the first model learns the white
    sections as background; the missing side and the outline's classifier put only some of
    them back. Learnt again from the masks it gives on its frames, the model calls the white
    sections cable too (mask IoU over six 640x480 views 0.70 -> 0.82)."""
    from engine.stages.segmentation import SegmentationSettings

    scene = look_scene("patterned", 23, views=6, width=640, height=480)
    frames = [scene.images[k] for k in reference_frames(6, 0, 3)]
    scores = {}
    for relearn in (False, True):
        settings = SegmentationSettings(relearn=relearn)
        colour, model = sequence_colour(frames, None, settings)
        scores[relearn] = np.mean([iou(segment_frame(image, colour, settings, model=model).mask,
                                       truth) for image, truth in zip(scene.images, scene.masks)])
    assert scores[False] < 0.72 and scores[True] > 0.78, scores


def _striped_cable_with_shadow(seed):
    """A cable (a sine curve, 10 px) striped blue and the table's own grey-green (bands 12 px
    long) on a noisy table, its hard shadow 6 px wide below it: its blue bands are short
    pieces, thin only joined by the shadow."""
    rng = np.random.default_rng(seed)
    table = np.array((135, 144, 133))
    image = np.clip(rng.normal(0, 3, (240, 320, 3)) + table, 0, 255)
    cable, dark = _sine_bands(seed, (-5, 5), (5, 11))
    dark &= ~cable
    image[dark] *= 0.45
    blue = cable & ((np.arange(320) // 12) % 2 == 0)[None, :]
    image[blue] = (28, 20, 120)
    return image.astype(np.uint8), cable, blue


def test_the_shadow_a_striped_cable_casts_is_not_its_colour():
    """The blue bands and the shadow below them are one thin object, so the greedy grouping
    takes the shadow's cluster in with the blue (patterned tuning seed 62: the colour model
    then learnt the shadow's grey, the seed came out half as wide as the cable and its range
    missed the blue). The shadow's cluster shapes the pieces but is not the cable's colour."""
    from engine.stages.segmentation import colour_seed, hsv_image

    frames, cables, blues = zip(*(_striped_cable_with_shadow(seed) for seed in range(3)))
    colour, candidate = find_cable(frames)
    for frame, cable, blue in zip(frames, cables, blues):
        seed, _, width = colour_seed(frame, candidate)
        assert (seed & cable).sum() >= 0.95 * seed.sum()
        assert (seed & blue).sum() >= 0.8 * blue.sum()
        assert 7 <= width <= 11  # the blue bands, not the shadow or a speck
    assert colour.select(hsv_image(frames[0]))[blues[0]].mean() >= 0.9

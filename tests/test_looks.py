"""Looks in the fast renderer: every family renders, seeded, with its shadows, clutter, stripes
and JPEG frames; the exact masks do not depend on the look (except where clutter hides the
cable)."""

import json
from dataclasses import asdict, replace

import cv2
import numpy as np
import pytest

from engine.synthetic.cameras import orbit_cameras
from engine.synthetic.layouts import table_layout
from engine.synthetic.looks import (DEFAULT_LOOK, LOOK_FAMILIES, TABLE_KINDS, ClutterObject, Look,
                                    sample_look, with_camera_effects_off)
from engine.synthetic.render import (CLUTTER_CLEARANCE, jpeg_round_trip, place_clutter,
                                     render_masks, render_views)
from engine.synthetic.scene import look_spec, make_scene, read_look, write_scene
from engine.synthetic.textures import legacy_wood_texture, table_texture

TEXTURE = 512  # small textures keep the tests fast


@pytest.fixture(scope="module")
def layout():
    """A 2-crossing table layout and four of its orbit views at 240x180."""
    truth = table_layout(2, seed=5, radius=0.006)
    cameras = orbit_cameras(truth, views=12, width=240, height=180)[::3]
    return truth, cameras


def render(truth, cameras, look):
    return list(render_views(truth, cameras, look, texture_size=TEXTURE))


def plain_look(**fields):
    """An even grey table, no camera effects: what the look draws, nothing else."""
    base = dict(family="saturated", table="plain", table_colour=(150, 150, 150),
                table_accent=(140, 140, 140), table_contrast=0.0, uneven=0.0)
    base.update(fields)
    return with_camera_effects_off(Look(**base))


@pytest.mark.parametrize("family", LOOK_FAMILIES)
def test_every_family_renders_the_same_for_the_same_seed(layout, family):
    truth, cameras = layout
    look = sample_look(family, 3)
    first, second = render(truth, cameras[:2], look), render(truth, cameras[:2], look)
    default = render(truth, cameras[:1], DEFAULT_LOOK)[0][0]
    for (image, mask), (again, mask_again) in zip(first, second):
        assert image.shape == (180, 240, 3) and image.dtype == np.uint8
        np.testing.assert_array_equal(image, again)
        np.testing.assert_array_equal(mask, mask_again)
        assert mask.sum() > 100 and image.std() > 5
    assert np.abs(first[0][0].astype(int) - default).mean() > 5  # not the default look
    other = render(truth, cameras[:1], sample_look(family, 4))[0][0]
    assert not np.array_equal(other, first[0][0])


def test_masks_do_not_depend_on_the_look(layout):
    truth, cameras = layout
    exact = list(render_masks(truth, cameras))
    for family in LOOK_FAMILIES:
        look = sample_look(family, 1)
        if look.clutter:
            continue  # below
        for (_, mask), expected in zip(render(truth, cameras, look), exact):
            np.testing.assert_array_equal(mask, expected)


def test_clutter_hides_the_cable_behind_it_in_the_mask(layout):
    truth = layout[0]
    cameras = orbit_cameras(truth, views=12, width=240, height=180)[6:9]
    # A tall blue post beside the cable hides it from some of the views.
    look = plain_look(family="clutter", clutter=(ClutterObject("box", (0, 0, 255), size=8.0,
                                                               height=80.0),))
    placed = place_clutter(truth, look)
    assert len(placed) == 1
    hidden_somewhere = 0
    for camera, (image, mask), bare, masked in zip(cameras, render(truth, cameras, look),
                                                   render_masks(truth, cameras),
                                                   render_masks(truth, cameras, look)):
        np.testing.assert_array_equal(mask, masked)
        assert not np.any(mask & ~bare)  # clutter only ever removes cable pixels
        hidden = bare & ~mask
        hidden_somewhere += hidden.sum()
        if hidden.any():
            # Hidden pixels lie inside the post's outline in the view and show its blue.
            outline = cv2.convexHull(camera.project(placed[0].corners())[0].astype(np.float32))
            rows, cols = np.nonzero(hidden)
            inside = [cv2.pointPolygonTest(outline, (c + 0.5, r + 0.5), True) > -1.0
                      for r, c in zip(rows, cols)]
            assert all(inside), camera.name
            rgb = image[hidden].astype(int)
            assert np.mean(rgb[:, 2] > rgb[:, 0] + 40) > 0.9, camera.name
    assert hidden_somewhere > 50


def test_clutter_stays_off_the_cable_and_near_it():
    for seed in range(6):
        truth = table_layout(3 + seed % 3, seed=seed)
        look = sample_look("clutter", seed)
        placed = place_clutter(truth, look)
        assert len(placed) == len(look.clutter) >= 3
        footprint = truth.centreline[:, :2]
        low, high = footprint.min(axis=0), footprint.max(axis=0)
        extent = np.max(high - low)
        for thing in placed:
            outline = thing.footprint().astype(np.float32)
            distance = np.array([cv2.pointPolygonTest(outline, (float(x), float(y)), True)
                                 for x, y in footprint])
            # Positive inside the outline: every cable point is outside and clear of it.
            assert distance.max() <= -(1.0 + CLUTTER_CLEARANCE) * truth.radius * 0.99
            centre = np.asarray(thing.centre)
            assert np.all(centre > low - 0.5 * extent) and np.all(centre < high + 0.5 * extent)
        for a in range(len(placed)):
            for b in range(a + 1, len(placed)):
                gap = np.hypot(*np.subtract(placed[a].centre, placed[b].centre))
                assert gap > placed[a].reach + placed[b].reach


def test_lifted_cable_casts_its_hard_shadow_beside_it(layout):
    truth = layout[0]
    camera = orbit_cameras(truth, views=12, width=320, height=240)[6]
    r = truth.radius
    width = 2 * r * camera.focal[0] / camera.project(truth.centreline)[1].mean()  # pixels

    def shadow_of(lift):
        """Dark pixels off the cable, their distance to it, and the cast centreline's."""
        look = plain_look(family="air", light="hard", light_azimuth=30.0,
                          light_elevation=45.0, ambient=0.2, lift=lift)
        lifted = type(truth)(truth.centreline + [0.0, 0.0, lift * r], r, truth.crossings,
                             truth.closed)
        image, mask = render(lifted, [camera], look)[0]
        value = image.astype(float).mean(axis=2)
        beside = cv2.dilate(mask.astype(np.uint8), np.ones((5, 5), np.uint8)) > 0
        dark = (value < 0.5 * np.median(value[~beside])) & ~beside
        to_cable = cv2.distanceTransform((~mask).astype(np.uint8), cv2.DIST_L2, 5)
        # Where the shadow should be: the centreline cast along the light onto the table.
        light = look.light_direction
        cast = lifted.centreline - lifted.centreline[:, 2:3] * light / light[2]
        curve = np.zeros(mask.shape, dtype=np.uint8)
        cv2.polylines(curve, [np.round(camera.project(cast)[0] - 0.5).astype(np.int32)], False,
                      255, 1)
        return dark, to_cable, cv2.distanceTransform(255 - curve, cv2.DIST_L2, 5), mask

    dark, to_cable, to_cast, mask = shadow_of(12.0)
    lying_dark, lying_to_cable, lying_cast, _ = shadow_of(0.0)
    assert dark.sum() > 0.3 * mask.sum()
    # The lifted cable's shadow lies where the light casts it, not where a lying cable's
    # would be, and away from the cable itself.
    assert np.median(to_cast[dark]) < 0.5 * width
    assert np.median(lying_cast[dark]) > 2 * width
    assert np.median(to_cable[dark]) > 2 * width
    assert np.mean(to_cable[dark] <= width) < 0.25
    # A lying cable's shadow hugs it (mostly hidden by the cable and its rim).
    assert lying_dark.sum() < 0.3 * dark.sum()
    if lying_dark.sum() > 10:
        assert np.mean(lying_to_cable[lying_dark] <= width) > 0.5


def colour_share(image, mask, colour):
    """Share of the mask's inner pixels whose hue is ``colour``'s."""
    inner = cv2.erode(mask.astype(np.uint8), np.ones((3, 3), np.uint8)) > 0
    hue = cv2.cvtColor(image, cv2.COLOR_RGB2HSV)[..., 0][inner].astype(int)
    target = int(cv2.cvtColor(np.uint8([[colour]]), cv2.COLOR_RGB2HSV)[0, 0, 0])
    gap = np.minimum(np.abs(hue - target), 180 - np.abs(hue - target))
    return np.mean(gap < 12)


@pytest.mark.parametrize("period", [6.0, 0.0])
def test_striped_and_two_tone_cables_show_both_colours(layout, period):
    truth, cameras = layout
    red, blue = (210, 40, 30), (40, 70, 220)
    plain = render(truth, cameras[:1], plain_look(cable_colour=red))[0]
    assert colour_share(*plain, red) > 0.9 and colour_share(*plain, blue) < 0.02
    image, mask = render(truth, cameras[:1], plain_look(family="patterned", cable_colour=red,
                                                         stripe_colour=blue,
                                                         stripe_period=period))[0]
    assert colour_share(image, mask, red) > 0.25 and colour_share(image, mask, blue) > 0.25


def test_frames_are_jpeg_compressed_at_the_look_quality(layout):
    truth, cameras = layout
    look = replace(sample_look("saturated", 2), jpeg_quality=100)
    raw = render(truth, cameras[:1], look)[0][0]
    compressed = render(truth, cameras[:1], replace(look, jpeg_quality=40))[0][0]
    np.testing.assert_array_equal(compressed, jpeg_round_trip(raw, 40)[0])
    assert np.abs(compressed.astype(int) - raw).mean() > 0.5


def test_a_look_scene_is_lifted_framed_and_written(tmp_path):
    spec = look_spec("air", 1, views=10, width=480, height=360)
    assert spec.look == sample_look("air", 1) and spec.file_format == "jpg"
    scene = make_scene(spec)
    flat = spec.layout()
    r = flat.radius
    np.testing.assert_allclose(scene.truth.centreline[:, 2] - flat.centreline[:, 2],
                               spec.look.lift * r)
    assert scene.truth.centreline[:, 2].min() == pytest.approx((1.0 + spec.look.lift) * r)
    assert [c.over for c in scene.truth.crossings] == [c.over for c in flat.crossings]
    for camera in scene.cameras:  # the lifted cable is framed
        pixels, depth = camera.project(scene.truth.centreline)
        assert np.all(depth > 0)
        assert np.all((pixels >= 0) & (pixels < [camera.width, camera.height]))
    folder = write_scene(scene, tmp_path / "air")
    for camera, image in zip(scene.cameras, scene.images):
        assert camera.name.endswith(".jpg")
        disk = cv2.imread(str(folder / "images" / camera.name))
        np.testing.assert_array_equal(cv2.cvtColor(disk, cv2.COLOR_BGR2RGB), image)
    written = json.loads((folder / "look.json").read_text())
    assert written["family"] == "air" and written["lift"] == spec.look.lift
    assert read_look(folder) == spec.look
    clutter = look_spec("clutter", 2)
    assert read_look_round_trip(clutter.look, tmp_path) == clutter.look
    # The default look still writes PNG frames.
    assert look_spec("default", 1).file_format == "png"


def read_look_round_trip(look, folder):
    (folder / "look.json").write_text(json.dumps(asdict(look)))
    return read_look(folder / "look.json")


def test_textures_of_every_kind():
    sift = cv2.SIFT_create()
    for kind in TABLE_KINDS:
        look = replace(sample_look("hard_light", 5), table=kind,  # a dark, low-contrast table
                       table_contrast=0.0 if kind == "plain" else 0.3)
        texture = table_texture(look, 1024)
        assert texture.shape == (1024, 1024, 3) and texture.dtype == np.uint8
        np.testing.assert_array_equal(texture, table_texture(look, 1024))
        features = len(sift.detect(cv2.cvtColor(texture, cv2.COLOR_RGB2GRAY)))
        if kind == "plain":
            assert features < 20
        else:  # enough corners and blobs for structure-from-motion
            assert features > 300, kind
        # Coloured from the look: the mean lies between the table colour and the accent.
        mean = texture.reshape(-1, 3).mean(axis=0)
        assert np.abs(mean - look.table_colour).max() < 45, kind
    np.testing.assert_array_equal(table_texture(DEFAULT_LOOK, 256), legacy_wood_texture(0, 256))

"""Ground-truth scenes: layout guarantees over many seeds, exact masks, written scenes."""

import json
import math

import cv2
import numpy as np
import pytest
from scipy.spatial import cKDTree

from engine import read_colmap_model
from engine.evaluation.metrics import evaluate
from engine.io.ground_truth import read_ground_truth
from engine.io.result import CablePath, Result
from engine.synthetic.cameras import (cable_pixel_width, handheld_cameras, orbit_cameras,
                                      out_of_frame)
from engine.synthetic.layouts import (HARD_SETTINGS, LayoutSettings, find_crossings_2d,
                                      hanging_layout, hard_layout, knot_layout, table_layout)
from engine.synthetic.render import render_masks
from engine.synthetic.scene import (HARD_FRAMING, SceneSpec, hard_spec, make_scene,
                                    render_scene_to, write_scene)

RULES = LayoutSettings()


def strand_pairs(truth, distance):
    """Pairs of samples closer than ``distance`` that are not neighbours along the cable."""
    points = truth.centreline / truth.radius
    arc = truth.arc_length / truth.radius
    pairs = cKDTree(points).query_pairs(distance, output_type="ndarray")
    gap = np.abs(arc[pairs[:, 0]] - arc[pairs[:, 1]]) if len(pairs) else np.zeros(0)
    if truth.closed and len(pairs):
        gap = np.minimum(gap, truth.length / truth.radius - gap)
    return pairs[gap > 2.5] if len(pairs) else pairs


def assert_layout_rules(truth, *, knot=False, rules=RULES):
    r = truth.radius
    points = truth.centreline / r
    # Strands never closer than 2 r in 3D.
    assert len(strand_pairs(truth, 2.0 * (1 - 1e-6))) == 0
    # Crossings: the count the truth claims is the count in the table plane, none grazing.
    found = find_crossings_2d(points, closed=truth.closed)
    assert len(found) == len(truth.crossings)
    for crossing in truth.crossings:
        assert crossing.angle >= rules.min_crossing_angle
        over, under = points[crossing.over], points[crossing.under]
        assert np.linalg.norm(over[:2] - under[:2]) < 0.5  # same place on the table
        assert over[2] - under[2] >= 2.0  # the upper strand is lifted over the lower one
    # Spacing of crossings along the cable (a knot may be tighter inside).
    arc = truth.arc_length / r
    passes = np.sort([arc[i] for c in truth.crossings for i in (c.over, c.under)])
    if len(passes) > 1:
        assert np.diff(passes).min() >= (4.0 if knot else rules.min_crossing_spacing) - 0.5
    if len(passes) and not truth.closed:
        assert passes[0] >= rules.min_crossing_spacing - 0.5
        assert arc[-1] - passes[-1] >= rules.min_crossing_spacing - 0.5
    # Bends no tighter than the rule.
    ds = np.linalg.norm(np.diff(points, axis=0), axis=1).mean()
    bend = np.linalg.norm(points[:-2] + points[2:] - 2 * points[1:-1], axis=1) / ds ** 2
    assert bend.max() <= 1.0 / rules.min_bend_radius + 0.02
    # Lying on the table: never below it.
    assert points[:, 2].min() >= 1.0 - 1e-9


@pytest.mark.parametrize("crossings", [0, 1, 2, 3, 5, 8, 12])
def test_table_layouts_honour_their_guarantees(crossings):
    for seed in range(8):
        truth = table_layout(crossings, seed=seed)
        assert truth.kind == "table" and not truth.closed
        assert_layout_rules(truth)


@pytest.mark.parametrize("crossings", [0, 1, 4, 7])
def test_closed_loops(crossings):
    for seed in range(3):
        truth = table_layout(crossings, seed=seed, closed=True)
        assert truth.closed
        assert_layout_rules(truth)


def test_hard_layouts_are_heaps_within_their_own_rules():
    shallow = close = 0
    for seed in range(4):
        truth = hard_layout(seed=seed)
        assert truth.kind == "hard" and 12 <= len(truth.crossings) <= 20
        assert_layout_rules(truth, rules=HARD_SETTINGS)
        arc = truth.arc_length / truth.radius
        passes = np.sort([arc[i] for c in truth.crossings for i in (c.over, c.under)])
        close += np.diff(passes).min() < RULES.min_crossing_spacing
        shallow += min(c.angle for c in truth.crossings) < RULES.min_crossing_angle
        # strands in contact without crossing: closer in the plane than the easy clearance
        flat = truth.centreline[:, :2] / truth.radius
        pairs = cKDTree(flat).query_pairs(RULES.clearance, output_type="ndarray")
        assert len(pairs) > 0
    # what the easy rules forbid happens on most of them
    assert close >= 3 and shallow >= 1
    again = hard_layout(seed=1)
    assert np.array_equal(again.centreline, hard_layout(seed=1).centreline)
    assert not np.array_equal(again.centreline, hard_layout(seed=2).centreline)
    exact = hard_layout(seed=0, crossings=14)
    assert len(exact.crossings) == 14
    with pytest.raises(ValueError, match="between 8 and 24"):
        hard_layout(crossings=(5, 30))


def test_a_strand_passes_over_one_and_under_the_next_close_by():
    from engine.synthetic.layouts import SAMPLE_SPACING, _arc_resample, _stacked_lift

    # two strands 3 r apart (x = -1.5 up, x = 1.5 down), then along y = 0 back across both:
    # the last stretch passes over the strand at x = 1.5 and under the one at x = -1.5, so
    # that one is lifted over the last stretch's raised part
    corners = np.array([[-1.5, -40], [-1.5, 40], [1.5, 40], [1.5, -40], [60, -40], [60, 0],
                        [-40, 0]], dtype=float)
    points = _arc_resample(corners, SAMPLE_SPACING)
    found = find_crossings_2d(points)
    assert len(found) == 2
    # the first pass of each crossing is the vertical strand's, the second the last stretch's
    at = [points[int(round(c[0] / SAMPLE_SPACING)), 0] for c in found]
    over_first = [x < 0 for x in at]  # over at x = -1.5, under at x = 1.5
    lifted = _stacked_lift(points, found, over_first, HARD_SETTINGS)
    height = 2.0 * (1.0 + HARD_SETTINGS.lift_margin)
    for (a, b, _), first_over in zip(found, over_first):
        za, zb = (lifted[int(round(x / SAMPLE_SPACING)), 2] for x in (a, b))
        assert (za - zb if first_over else zb - za) >= height - 1e-6
    # stacked: the strand at x = -1.5 clears the last stretch, itself raised over x = 1.5
    # (a plain lift over the table, as _lift does, would leave it at 1 + height)
    assert lifted[:, 2].min() >= 1.0 - 1e-9 and lifted[:, 2].max() > 1.0 + height + 1.0


def test_strands_closer_than_the_clearance_are_pushed_apart():
    from engine.synthetic.layouts import SAMPLE_SPACING, _arc_resample, _pushed_apart

    # a hairpin whose two legs lie 1 r apart: pushed to the clearance, no crossing made
    corners = np.array([[0, -0.5], [40, -0.5], [40, 0.5], [0, 0.5]], dtype=float)
    points = _arc_resample(corners, SAMPLE_SPACING)
    pushed = _pushed_apart(points, [], HARD_SETTINGS)
    legs = pushed[pushed[:, 0] < 30]
    gap = legs[legs[:, 1] > 0, 1].min() - legs[legs[:, 1] < 0, 1].max()
    assert HARD_SETTINGS.clearance <= gap <= 1.1 * HARD_SETTINGS.clearance
    assert find_crossings_2d(pushed) == []
    steps = np.linalg.norm(np.diff(pushed, axis=0), axis=1)
    assert np.allclose(steps, SAMPLE_SPACING, rtol=0.05)


def test_views_that_frame_part_of_the_cable():
    truth = hard_layout(seed=0)
    whole = orbit_cameras(truth, views=30)
    assert out_of_frame(truth, whole).max() == 0.0
    part = out_of_frame(truth, orbit_cameras(truth, views=30, framing=HARD_FRAMING))
    assert 0.15 <= part.mean() <= 0.45 and part.max() < 0.8
    ends = np.r_[part[:len(part) // 20], part[-len(part) // 20:]]
    assert ends.mean() >= 0.1
    held = out_of_frame(truth, handheld_cameras(truth, views=30, framing=HARD_FRAMING))
    assert held.mean() > 0.1
    with pytest.raises(ValueError, match="framing"):
        orbit_cameras(truth, framing=0.1)
    spec = hard_spec(3, views=10, width=640, height=480)
    assert spec.kind == "hard" and spec.framing == HARD_FRAMING
    scene = make_scene(spec)
    # the exact masks leave out what is out of frame: some view misses part of the cable
    assert min(mask.sum() for mask in scene.masks) < 0.8 * max(mask.sum() for mask in scene.masks)


def test_knots_alternate_over_and_under():
    for seed in range(6):
        truth = knot_layout(seed=seed)
        assert len(truth.crossings) == 3
        assert_layout_rules(truth, knot=True)
        arc = truth.arc_length
        passes = sorted((arc[i], role) for c in truth.crossings
                        for i, role in ((c.over, "over"), (c.under, "under")))
        roles = [role for _, role in passes]
        assert all(a != b for a, b in zip(roles, roles[1:]))  # a true overhand knot


def test_hanging_cables_are_3d():
    for seed in range(4):
        truth = hanging_layout(seed=seed)
        points = truth.centreline / truth.radius
        assert len(strand_pairs(truth, 2.0)) == 0 and not truth.crossings
        assert points[:, 2].min() > 1.0  # in the air
        # Not planar: the best-fitting plane leaves several radii of residual.
        centred = points - points.mean(axis=0)
        assert np.linalg.svd(centred, compute_uv=False)[-1] / math.sqrt(len(points)) > 2.0


def test_same_seed_same_layout_and_sizes_scale():
    a, b = table_layout(4, seed=9), table_layout(4, seed=9)
    np.testing.assert_array_equal(a.centreline, b.centreline)
    assert not np.array_equal(a.centreline, table_layout(4, seed=10).centreline)
    small = table_layout(2, seed=1, radius=0.001, extent=0.2)
    large = table_layout(2, seed=1, radius=0.01, extent=2.0)
    np.testing.assert_allclose(small.centreline / small.radius, large.centreline / large.radius)


@pytest.mark.parametrize("radius, extent", [(0.001, 0.2), (0.004, None), (0.01, 2.0)])
def test_cable_is_at_least_five_pixels_wide(radius, extent):
    truth = table_layout(3, seed=2, radius=radius, extent=extent)
    for rig in (orbit_cameras, handheld_cameras):
        assert cable_pixel_width(truth, rig(truth, views=12)) >= 5.0


def test_too_thin_a_cable_is_refused():
    with pytest.raises(ValueError, match="pixels wide"):
        make_scene(SceneSpec(radius=0.001, extent=0.25, width=320, height=240, views=10))


def tube_mask_by_distance(truth, camera):
    """Independent check: pixels whose centre ray passes within r of the centreline."""
    (fx, fy), (cx, cy) = camera.focal, camera.principal_point
    rows, cols = np.mgrid[0:camera.height, 0:camera.width]
    rays = np.stack([(cols + 0.5 - cx) / fx, (rows + 0.5 - cy) / fy,
                     np.ones_like(cols, dtype=float)], axis=-1).reshape(-1, 3)
    rays = rays @ camera.R  # to world directions
    rays /= np.linalg.norm(rays, axis=1, keepdims=True)
    origin = camera.center
    points = truth.centreline
    a, b = points[:-1], points[1:]
    best = np.full(len(rays), np.inf)
    for start in range(0, len(a), 64):  # closest approach of each ray to each segment
        p0, p1 = a[start:start + 64], b[start:start + 64]
        d = p1 - p0
        samples = np.linspace(0, 1, 5)
        for s in samples:
            q = p0 + s * d
            w = q - origin
            along = w @ rays.T
            distance2 = (w * w).sum(axis=1)[:, None] - along ** 2
            best = np.minimum(best, np.sqrt(np.maximum(distance2.min(axis=0), 0)))
    return best.reshape(camera.height, camera.width) <= truth.radius


def test_masks_are_the_projected_tube():
    truth = table_layout(2, seed=5, radius=0.004)
    camera = orbit_cameras(truth, views=10, width=320, height=240)[3]
    mask = next(render_masks(truth, [camera]))
    expected = tube_mask_by_distance(truth, camera)
    assert mask.sum() > 500
    disagree = mask ^ expected
    # Only pixels on the silhouette may differ (sphere sweep vs sampled segments).
    edges = cv2.dilate(expected.astype(np.uint8), None) ^ cv2.erode(expected.astype(np.uint8), None)
    assert np.all(edges[disagree])
    assert disagree.sum() < 0.05 * expected.sum()


def test_renderer_shows_the_cable_and_the_occlusion_cue():
    scene = make_scene(SceneSpec(crossings=3, seed=1, views=10, width=480, height=360))
    assert len(scene.images) == 10 and scene.images[0].shape == (360, 480, 3)
    for image, mask in zip(scene.images, scene.masks):
        hsv = cv2.cvtColor(image, cv2.COLOR_RGB2HSV)
        red = ((hsv[..., 0] < 10) | (hsv[..., 0] > 170)) & (hsv[..., 1] > 120)
        # The cable is the red thing in the picture, the table is not.
        assert (red & mask).sum() > 0.8 * mask.sum()
        beside = cv2.dilate(mask.astype(np.uint8), np.ones((3, 3), np.uint8)) > 0  # blurred rim
        assert (red & ~beside).sum() < 0.01 * mask.sum()
    # Where a strand passes under another it is darker than elsewhere on the cable.
    truth, camera = scene.truth, scene.cameras[0]
    image, mask = scene.images[0], scene.masks[0]
    value = cv2.cvtColor(image, cv2.COLOR_RGB2HSV)[..., 2].astype(float)
    pixels, depth = camera.project(truth.centreline)
    under = [truth.crossings[k].under for k in range(3)]
    near_under = np.zeros(mask.shape, dtype=bool)
    for index in under:
        for step in (-6, 6):  # beside the crossing, where the upper strand does not hide it
            u, v = pixels[(index + step) % len(pixels)].astype(int)
            near_under[max(v - 2, 0):v + 3, max(u - 2, 0):u + 3] = True
    assert value[near_under & mask].mean() < value[mask].mean()


def test_written_scene_round_trips(tmp_path):
    scene = make_scene(SceneSpec(kind="knot", views=10, width=320, height=240, rig="handheld"))
    folder = write_scene(scene, tmp_path / "knot")
    names = sorted(p.name for p in (folder / "images").iterdir())
    assert names == sorted(c.name for c in scene.cameras)
    mask = cv2.imread(str(folder / "masks" / "000.png"), cv2.IMREAD_UNCHANGED)
    assert mask.dtype == np.uint8 and set(np.unique(mask)) <= {0, 255}
    np.testing.assert_array_equal(mask > 0, scene.masks[0])
    model = read_colmap_model(folder / "sparse")
    for original, back in zip(scene.cameras, model.cameras):
        np.testing.assert_allclose(back.R, original.R, atol=1e-12)
    truth = read_ground_truth(folder / "ground_truth.json")
    np.testing.assert_allclose(truth.centreline, scene.truth.centreline)
    assert [c.over for c in truth.crossings] == [c.over for c in scene.truth.crossings]
    assert json.loads((folder / "ground_truth.json").read_text())["kind"] == "knot"
    with pytest.raises(FileExistsError):
        write_scene(scene, folder)


def test_a_scene_written_view_by_view_is_the_same_scene(tmp_path):
    spec = SceneSpec(crossings=2, views=3, width=480, height=360, image_format="jpg")
    held = write_scene(make_scene(spec), tmp_path / "held")
    streamed = render_scene_to(spec, tmp_path / "streamed")
    files = sorted(p.relative_to(held) for p in held.rglob("*") if p.is_file())
    assert len(files) == 2 * 3 + 2 + 5  # images, masks, truth, look, the model (COLMAP, text)
    assert files == sorted(p.relative_to(streamed) for p in streamed.rglob("*") if p.is_file())
    for name in files:
        assert (held / name).read_bytes() == (streamed / name).read_bytes(), name
    with pytest.raises(FileExistsError):
        render_scene_to(spec, streamed)
    with pytest.raises(ValueError, match="between 3 and 400"):
        make_scene(SceneSpec(views=2))


def test_metrics_score_the_truth_of_every_kind_as_perfect():
    for truth in (table_layout(5, seed=3), knot_layout(seed=2), hanging_layout(seed=1),
                  table_layout(3, seed=1, closed=True)):
        result = Result(radius=truth.radius,
                        paths=(CablePath(truth.centreline, closed=truth.closed),))
        metrics = evaluate(result, truth)
        assert metrics.accuracy_max < 1e-6 and metrics.completeness == 1.0
        assert metrics.one_path and metrics.crossings_right == len(truth.crossings)
        flat = truth.centreline.copy()
        flat[:, 2] = truth.radius
        flattened = evaluate(Result(radius=truth.radius,
                                    paths=(CablePath(flat, closed=truth.closed),)), truth)
        assert flattened.crossings_right == 0

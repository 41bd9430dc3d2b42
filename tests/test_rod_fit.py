"""engine.stages.rod_fit: rods fitted to voxels, masks and crossings of small ground-truth
scenes."""

import threading

import cv2
import numpy as np
import pytest
from scipy.optimize import brentq
from scipy.spatial import cKDTree

from conftest import finite_gradient, look_at_camera
from engine import CablePath, Result
from engine.bench.rod import carve_stretch, noisy_chain, scene_masks
from engine.errors import Cancelled
from engine.evaluation.metrics import evaluate
from engine.geometry.camera import Camera
from engine.stages.carving import CarvingSettings, carve
from engine.stages.rod_fit import (Contact, ContactPenalty, ImageAttraction, ImageEvidence,
                                   Obstacle, ObstaclePenalty, RodFitSettings, Springs, Voxels,
                                   fit_rod, resample_polyline, voxel_attraction)
from engine.stages.segmentation import cable_width, junction_map
from engine.synthetic.scene import SceneSpec


@pytest.fixture(scope="module")
def scene():
    """A cable with one crossing on a table, 12 views of 480x360 (exact masks)."""
    spec = SceneSpec(kind="table", crossings=1, seed=0, radius=0.004, extent=0.2, views=12,
                     width=480, height=360)
    truth, masks = scene_masks(spec)
    junctions = [junction_map(mask, cable_width(mask)) for mask in masks]
    views = [ImageEvidence.from_mask(camera, mask, junction)
             for camera, mask, junction in zip(truth.cameras, masks, junctions)]
    chain, stride = noisy_chain(truth.centreline, truth.radius, seed=1)  # about 1 r of noise
    voxels = carve_stretch(truth.centreline, truth.radius, truth.cameras, masks)
    contacts = [Contact(over=c.over // stride, under=c.under // stride) for c in truth.crossings]
    return {"truth": truth, "masks": masks, "junctions": junctions, "views": views,
            "chain": chain, "voxels": voxels, "contacts": contacts}


def accuracy(fit, truth):
    return evaluate(Result(radius=truth.radius, paths=(CablePath(fit.points),)), truth)


def distances(points, polyline, radius):
    """Distance (in radii) of each point to a polyline."""
    dense = resample_polyline(polyline, 0.05 * radius)
    return cKDTree(dense).query(points)[0] / radius


# -- accuracy -------------------------------------------------------------------------------------
def test_noisy_segment_with_image_term_lands_on_the_centreline(scene):
    truth = scene["truth"]
    fit = fit_rod(scene["chain"], truth.radius, voxels=scene["voxels"], views=scene["views"],
                  contacts=scene["contacts"])
    voxels_only = fit_rod(scene["chain"], truth.radius, voxels=scene["voxels"])
    with_images, without = accuracy(fit, truth), accuracy(voxels_only, truth)
    assert with_images.accuracy_mean < 0.1
    assert with_images.accuracy_p95 < 0.25
    assert with_images.completeness > 0.97
    assert with_images.crossings_right == with_images.crossings_total == 1
    assert without.accuracy_mean > 2 * with_images.accuracy_mean  # the hull alone is biased
    assert fit.converged
    assert fit.radii.shape == (len(fit.points),) and np.all(fit.radii == truth.radius)


def test_images_alone_also_fit_without_voxels(scene):
    truth = scene["truth"]
    fit = fit_rod(scene["chain"], truth.radius, views=scene["views"])
    assert accuracy(fit, truth).accuracy_mean < 0.1


def test_closed_loop_is_fitted_as_a_loop():
    spec = SceneSpec(kind="loop", crossings=2, seed=0, radius=0.004, extent=0.25, views=12,
                     width=480, height=360)
    truth, masks = scene_masks(spec)
    r = truth.radius
    views = [ImageEvidence.from_mask(camera, mask, junction_map(mask, cable_width(mask)))
             for camera, mask in zip(truth.cameras, masks)]
    chain, stride = noisy_chain(truth.centreline, r, seed=1)
    contacts = [Contact(over=c.over // stride, under=c.under // stride) for c in truth.crossings]
    fit = fit_rod(chain, r, voxels=carve_stretch(truth.centreline, r, truth.cameras, masks),
                  views=views, contacts=contacts, closed=True)
    metrics = evaluate(Result(radius=r, paths=(CablePath(fit.points, closed=True),)), truth)
    assert fit.closed
    assert np.linalg.norm(fit.points[0] - fit.points[-1]) < 1.5 * r  # the seam closes
    assert metrics.accuracy_mean < 0.1 and metrics.completeness > 0.99
    assert metrics.crossings_right == metrics.crossings_total == 2


def test_voxels_from_a_real_carve_and_its_core(scene):
    truth, r = scene["truth"], scene["truth"].radius
    lower = truth.centreline.min(axis=0) - 4 * r
    side = float(np.ptp(truth.centreline, axis=0).max()) + 8 * r
    grid = carve(truth.cameras, scene["masks"], radius=r, region=(lower, side),
                 settings=CarvingSettings(voxels_per_radius=2.0))
    hull, core = Voxels.from_grid(grid), Voxels.from_grid(grid, agreement=1.0)
    assert hull.size == grid.voxel_size == pytest.approx(r / 2)
    np.testing.assert_array_equal(hull.centres, grid.occupied_points())
    assert 0 < len(core.centres) < 0.5 * len(hull.centres)
    near = hull.near(truth.centreline, 4 * r)
    assert len(near.centres) < len(hull.centres)  # ghosts away from the cable
    assert distances(near.centres, truth.centreline, r).max() < 4
    # the core is thinner and nearer the centreline: a better guide for a voxel-only fit
    assert (np.median(distances(core.centres, truth.centreline, r))
            < 0.5 * np.median(distances(hull.centres, truth.centreline, r)))
    from_hull, from_core = (accuracy(fit_rod(scene["chain"], r, voxels=voxels), truth)
                            for voxels in (near, core))
    assert from_core.accuracy_mean < 0.1 and from_core.completeness > 0.97
    assert from_hull.accuracy_mean > 2 * from_core.accuracy_mean
    with pytest.raises(ValueError, match="agreement"):
        Voxels.from_grid(grid, agreement=0.0)


@pytest.fixture(scope="module")
def two_grids(scene):
    """A stretch of 80 r, a noisy chain along it and its voxels on two different, shifted
    grids (r/3 and r/6)."""
    truth, r = scene["truth"], scene["truth"].radius
    piece = truth.centreline[truth.arc_length < 80 * r]
    chain, _ = noisy_chain(piece, r, seed=2)
    voxels = [carve_stretch(piece, r, truth.cameras, scene["masks"],
                            voxels_per_radius=per_radius, shift=shift)
              for per_radius, shift in ((3, 0.3), (6, 0.7))]
    return chain, voxels


@pytest.mark.parametrize("weight", [1.0, 0.005])
def test_voxel_fit_does_not_depend_on_grid_resolution(scene, two_grids, weight):
    # With a weak voxel term its balance with bending and the anchor shapes the fit: weights
    # per voxel instead of per volume would move it by 0.09 r here.
    r = scene["truth"].radius
    chain, grids = two_grids
    fits = [fit_rod(chain, r, voxels=voxels, settings=RodFitSettings(voxel_weight=weight))
            for voxels in grids]
    assert len(fits[0].points) == len(fits[1].points)
    assert np.mean(distances(fits[0].points, fits[1].points, r)) < 0.05


def test_scaling_the_world_scales_the_fit(scene):
    truth, r, scale = scene["truth"], scene["truth"].radius, 10.0
    small = fit_rod(scene["chain"], r, voxels=scene["voxels"], views=scene["views"])
    cameras = [Camera(c.name, c.width, c.height, c.model, c.params, c.R, scale * c.t)
               for c in truth.cameras]
    big_views = [ImageEvidence.from_mask(camera, mask, junction) for camera, mask, junction
                 in zip(cameras, scene["masks"], scene["junctions"])]
    voxels = Voxels(scale * scene["voxels"].centres, scale * scene["voxels"].size)
    big = fit_rod(scale * scene["chain"], scale * r, voxels=voxels, views=big_views)
    assert np.abs(big.points / scale - small.points).max() < 0.01 * r
    assert big.energy == pytest.approx(small.energy, rel=1e-3)  # in units of E I / r


# -- crossings ------------------------------------------------------------------------------------
def curl(radius, a=2.2, b=8.0):
    """A flat chain at table height that loops over itself once (a prolate cycloid
    ``x = a s - b sin s, y = -b cos s`` in radii), and the indices where it crosses itself."""
    s0 = brentq(lambda s: np.sin(s) - a / b * s, 1e-3, np.pi)  # crossing at s = -s0 and s0
    s = np.linspace(-s0 - 3.0, s0 + 3.0, 400)
    xy = np.column_stack([a * s - b * np.sin(s), -b * np.cos(s)]) * radius
    points = np.column_stack([xy, np.full(len(s), radius)])
    first, second = np.argmin(np.abs(s + s0)), np.argmin(np.abs(s - s0))
    assert np.linalg.norm(points[first, :2] - points[second, :2]) < 0.5 * radius
    return points, first, second


def strand_gap(points, first, second, span):
    """Smallest distance between the two strands' polylines near a crossing."""
    a = resample_polyline(points[max(first - span, 0):first + span + 1], 0.01)
    b = resample_polyline(points[max(second - span, 0):second + span + 1], 0.01)
    return cKDTree(a).query(b)[0].min()


@pytest.mark.parametrize("first_over", [True, False])
def test_crossing_strands_end_apart_with_the_requested_one_on_top(first_over):
    r = 0.004
    points, first, second = curl(r)
    over, under = (first, second) if first_over else (second, first)
    fit = fit_rod(points, r, contacts=[Contact(over=over, under=under)])
    i, j = fit.vertex_of(over), fit.vertex_of(under)
    assert strand_gap(fit.points, i, j, 6) > (2 - 0.05) * r
    assert fit.points[i, 2] - fit.points[j, 2] > 1.9 * r
    plain = fit_rod(points, r)
    assert strand_gap(plain.points, i, j, 6) < 1.5 * r  # without the contact they overlap


def test_contact_given_as_index_ranges():
    r = 0.004
    points, first, second = curl(r)
    contact = Contact(over=(second - 20, second + 20), under=(first - 20, first + 20))
    fit = fit_rod(points, r, contacts=[contact])
    i, j = fit.vertex_of(second), fit.vertex_of(first)
    assert fit.points[i, 2] - fit.points[j, 2] > 1.9 * r


@pytest.mark.parametrize("over", [True, False])
def test_another_cable_held_fixed_is_cleared_on_the_requested_side(over):
    r = 0.004
    t = np.linspace(-30 * r, 30 * r, 121)
    other = np.column_stack([t, np.zeros_like(t), np.full_like(t, r)])  # fitted before
    mine = np.column_stack([np.zeros_like(t), t, np.full_like(t, r)])  # crosses it at 60
    near = np.abs(t) <= 4 * r
    fit = fit_rod(mine, r, obstacles=[Obstacle(60, other[near], over)])
    centre = fit.points[fit.vertex_of(60)]
    assert (centre[2] - r) * (1 if over else -1) > 1.9 * r
    assert cKDTree(resample_polyline(fit.points, 0.01 * r)).query(other)[0].min() > 1.9 * r
    plain = fit_rod(mine, r)
    assert abs(plain.points[plain.vertex_of(60), 2] - r) < 0.1 * r  # without it they meet


def test_obstacle_gradient_matches_finite_differences():
    from conftest import finite_gradient

    rng = np.random.default_rng(4)
    points = rng.normal(size=(6, 3)) * 0.5
    term = ObstaclePenalty([1, 2, 2, 4], rng.normal(size=(4, 3)) * 0.5, [1, -1, 1, -1],
                           (0.0, 0.2, 1.0), 2.0, 3.0)
    model = term.model(points)
    derivatives = model.derivatives(points)
    np.testing.assert_allclose(derivatives.gradient, finite_gradient(model.energy, points),
                               atol=1e-6)


# -- derivatives ---------------------------------------------------------------------------------
def test_fit_terms_gradients_match_finite_differences(scene):
    truth, r = scene["truth"], scene["truth"].radius
    rng = np.random.default_rng(3)
    points = resample_polyline(truth.centreline[:120], r) + 0.3 * r * rng.normal(size=(1, 3))
    points = points + 0.3 * r * rng.normal(size=points.shape)
    count = len(points)
    weights = rng.uniform(0.5, 2.0, count)
    pairs = np.array([[2, 20], [3, 21], [4, 20], [2, 22]])
    points[20:23] = points[2:5] + r * np.array([0.5, -0.4, -1.5])  # crossing too close
    terms = [Springs.to_points(points + r, weights),
             voxel_attraction(scene["voxels"], points, weight=3.0, reach=3 * r, smoothing=2.0),
             ImageAttraction(scene["views"][:3], np.full(count, r), weights, 1.0),
             ContactPenalty(pairs, (0, 0, 1), 2.04 * r, 5.0)]
    for term in terms:
        model = term.model(points)
        derivatives = model.derivatives(points)
        assert derivatives.energy == pytest.approx(model.energy(points))
        numeric = finite_gradient(model.energy, points, 1e-4 * r)
        assert np.abs(numeric).max() > 0, term.name
        np.testing.assert_allclose(derivatives.gradient, numeric,
                                   atol=1e-5 * np.abs(numeric).max(), err_msg=term.name)
        hessian = np.zeros((3 * count, 3 * count))
        np.add.at(hessian, (derivatives.rows, derivatives.cols), derivatives.values)
        assert np.linalg.eigvalsh(hessian).min() > -1e-9 * np.abs(hessian).max(), term.name


# -- image evidence -------------------------------------------------------------------------------
@pytest.mark.parametrize("width", [6, 7])
@pytest.mark.parametrize("angle", [0.0, 23.0])
def test_ridge_is_the_band_centre_to_a_fraction_of_a_pixel(width, angle):
    camera = look_at_camera("000.png", [0.0, -1.0, 1.0], width=320, height=240)
    rows, cols = np.mgrid[0:240, 0:320]
    direction = np.array([np.cos(np.radians(angle)), np.sin(np.radians(angle))])
    centre = np.array([160.3, 120.0])  # a band through this point (COLMAP coordinates)
    offset = np.stack([cols + 0.5 - centre[0], rows + 0.5 - centre[1]], -1)
    across = offset @ np.array([-direction[1], direction[0]])
    along = offset @ direction
    mask = (np.abs(across) <= width / 2) & (np.abs(along) < 100)
    evidence = ImageEvidence.from_mask(camera, mask)
    assert evidence.half_width == pytest.approx(width / 2, abs=0.5)
    inner = np.abs((evidence.ridge_points - centre) @ direction) < 80
    lateral = (evidence.ridge_points[inner] - centre) @ np.array([-direction[1], direction[0]])
    assert inner.sum() > 100
    assert np.abs(lateral).max() < 0.15  # pixels


@pytest.mark.parametrize("width, reduced", [(20, 1), (30, 3), (61, 6), (90, 8)])
def test_a_wide_band_s_ridge_is_its_centre_too(width, reduced):
    camera = look_at_camera("000.png", [0.0, -1.0, 1.0], width=900, height=700)
    rows, cols = np.mgrid[0:700, 0:900]
    direction = np.array([np.cos(np.radians(23.0)), np.sin(np.radians(23.0))])
    centre = np.array([450.3, 351.7])
    offset = np.stack([cols + 0.5 - centre[0], rows + 0.5 - centre[1]], -1)
    across = offset @ np.array([-direction[1], direction[0]])
    mask = (np.abs(across) <= width / 2) & (np.abs(offset @ direction) < 300)
    evidence = ImageEvidence.from_mask(camera, mask)
    inner = np.abs((evidence.ridge_points - centre) @ direction) < 250
    lateral = (evidence.ridge_points[inner] - centre) @ np.array([-direction[1], direction[0]])
    assert evidence.cell == reduced  # (the ridge found on the mask reduced as many times)
    assert inner.sum() > 0.8 * 500 / reduced
    assert np.abs(lateral).max() < 0.02 * width  # pixels
    # looked up (in cells of ``reduced`` pixels): the centre's nearest ridge point, nothing
    # three widths away
    side = np.array([-direction[1], direction[0]])
    index, weight = evidence.lookup(np.array([centre + 0.3 * width * side,
                                              centre + 3.0 * width * side]))
    assert index[1] == -1 and weight[1] == 0 and weight[0] == 1
    assert np.linalg.norm(evidence.ridge_points[index[0]] - centre) < 0.5 * width
    # a junction at the centre weighs the cells there down, not those a few widths along
    junction = np.hypot(cols + 0.5 - centre[0], rows + 0.5 - centre[1]) < 0.5 * width
    evidence = ImageEvidence.from_mask(camera, mask, junction)
    _, weight = evidence.lookup(np.array([centre, centre + 4.0 * width * direction]))
    assert weight[0] == RodFitSettings().junction_weight and weight[1] == 1
    normals = evidence.ridge_normals[inner]
    assert np.abs(normals @ np.array([-direction[1], direction[0]])).min() > 0.95


def test_evidence_from_a_distorted_camera_is_undistorted():
    pinhole = look_at_camera("000.png", [0.0, -1.0, 1.0], width=320, height=240)
    (fx, fy), (cx, cy) = pinhole.focal, pinhole.principal_point
    distorted = Camera("000.png", 320, 240, "OPENCV", [fx, fy, cx, cy, -0.25, 0.08, 0.0, 0.0],
                       pinhole.R, pinhole.t)
    # The mask a straight band in the undistorted image leaves in the distorted one.
    rows, cols = np.mgrid[0:240, 0:320]
    pixels = np.stack([cols + 0.5, rows + 0.5], -1).reshape(-1, 1, 2).astype(np.float64)
    matrix = np.array([[fx, 0, cx], [0, fy, cy], [0, 0, 1.0]])
    ideal = cv2.undistortPoints(pixels, matrix, distorted.distortion, P=matrix).reshape(240, 320, 2)
    line_y = 60.0 + 0.4 * ideal[..., 0]  # in the undistorted image
    mask = np.abs(ideal[..., 1] - line_y) <= 3.5
    evidence = ImageEvidence.from_mask(distorted, mask)
    assert evidence.camera.model == "PINHOLE"
    inner = (evidence.ridge_points[:, 0] > 40) & (evidence.ridge_points[:, 0] < 280)
    points = evidence.ridge_points[inner]
    error = np.abs(points[:, 1] - (60.0 + 0.4 * points[:, 0])) / np.hypot(1, 0.4)
    assert inner.sum() > 100 and np.median(error) < 0.3


def test_junction_masks_weigh_down_vertices_there(scene):
    truth = scene["truth"]
    camera, mask = truth.cameras[0], scene["masks"][0]
    junction = np.zeros_like(mask)
    junction[:, : camera.width // 2] = True
    evidence = ImageEvidence.from_mask(camera, mask, junction,
                                       settings=RodFitSettings(junction_weight=0.25))
    rows, cols = np.divmod(evidence.pixels, camera.width)
    assert set(np.unique(evidence.weights[cols < camera.width // 2 - 10])) == {0.25}
    assert set(np.unique(evidence.weights[cols > camera.width // 2 + 10])) == {1.0}


# -- interface ------------------------------------------------------------------------------------
def test_crossings_too_close_along_the_cable_degrade_with_a_warning(scene):
    """Two points a vertex apart cannot be held apart (it used to be a ValueError that
    stopped the whole run): the contact is left out, and the fit says so."""
    chain, r = scene["chain"], scene["truth"].radius
    plain = fit_rod(chain, r, voxels=scene["voxels"])
    fit = fit_rod(chain, r, voxels=scene["voxels"], contacts=[Contact(over=10, under=11)])
    assert plain.warnings == ()
    assert len(fit.warnings) == 1 and "left out of the fit" in fit.warnings[0]
    np.testing.assert_allclose(fit.points, plain.points)
    # strands that share part of their span keep the rest of it apart
    first = fit_rod(chain, r, voxels=scene["voxels"], contacts=[Contact(over=10, under=16)])
    assert len(first.warnings) == 1 and "shorter length" in first.warnings[0]


def test_fit_rod_rejects_bad_input(scene):
    chain, r = scene["chain"], scene["truth"].radius
    with pytest.raises(ValueError, match="radius"):
        fit_rod(chain, -1.0, voxels=scene["voxels"])
    with pytest.raises(ValueError, match="points"):
        fit_rod(chain[:, :2], r, voxels=scene["voxels"])
    with pytest.raises(ValueError, match="nothing to fit"):
        fit_rod(chain, r, settings=RodFitSettings(anchor_weight=0.0))
    with pytest.raises(ValueError, match="views"):
        fit_rod(chain, r, views=[scene["masks"][0]])
    with pytest.raises(ValueError, match="bad contact"):
        fit_rod(chain, r, voxels=scene["voxels"], contacts=[Contact(over=len(chain), under=3)])
    with pytest.raises(ValueError, match="mask"):
        ImageEvidence.from_mask(scene["truth"].cameras[0], scene["masks"][0][:-1])
    with pytest.raises(ValueError, match="spacing"):
        RodFitSettings(spacing=0.0)


def test_fit_reports_progress_and_honours_cancel(scene):
    r = scene["truth"].radius
    reports = []
    fit_rod(scene["chain"], r, voxels=scene["voxels"],
            progress=lambda fraction, message: reports.append((fraction, message)))
    fractions = [f for f, _ in reports]
    assert fractions and all(0 < f <= 1 for f in fractions) and fractions == sorted(fractions)
    cancel = threading.Event()
    cancel.set()
    with pytest.raises(Cancelled):
        fit_rod(scene["chain"], r, voxels=scene["voxels"], cancel=cancel)

"""Camera estimation with real pycolmap on small fast-rendered scenes, and the upright frame."""

import threading
import time
from pathlib import Path

import cv2
import numpy as np
import pytest

from conftest import look_at_camera
from engine import Cancelled, InputError, ReconstructionError, read_colmap_model
from engine.cli.cameras import cameras_command
from engine.evaluation.cameras import compare_to_truth
from engine.geometry.similarity import Similarity, align_similarity
from engine.geometry.upright import UprightSettings, fit_plane, look_at_point, make_upright
from engine.io.ground_truth import read_ground_truth
from engine.stages.cameras import CameraEstimate, CameraEstimationSettings, estimate_cameras
from engine.synthetic.scene import SceneSpec, make_scene, write_scene

VIEWS, WIDTH, HEIGHT = 12, 640, 480


@pytest.fixture(scope="module")
def scene_dir(tmp_path_factory):
    """A 12-view table scene at 640x480 written as PNGs (about 2 s to render)."""
    folder = tmp_path_factory.mktemp("scene")
    scene = make_scene(SceneSpec(views=VIEWS, seed=1, crossings=2, width=WIDTH, height=HEIGHT))
    write_scene(scene, folder)
    return folder, scene


def image_paths(folder):
    return sorted((Path(folder) / "images").glob("*.png"))


@pytest.fixture(scope="module")
def estimated(scene_dir):
    folder, scene = scene_dir
    calls = []
    estimate = estimate_cameras(image_paths(folder),
                                progress=lambda fraction, message: calls.append(fraction))
    return estimate, scene, calls


def write_noise(path, seed, *, grey=False):
    if grey:
        image = np.full((HEIGHT, WIDTH, 3), 128, np.uint8)
    else:
        image = np.random.default_rng(seed).integers(0, 256, (HEIGHT, WIDTH, 3), dtype=np.uint8)
    cv2.imwrite(str(path), image)


# -- estimation against the truth ----------------------------------------------------------------

def test_estimated_cameras_match_the_true_ones(estimated):
    estimate, scene, calls = estimated
    assert isinstance(estimate, CameraEstimate)
    assert estimate.names == tuple(camera.name for camera in scene.cameras)
    assert estimate.unregistered == ()
    assert estimate.matching == "sequential"
    assert estimate.reprojection_error < 1.5
    assert estimate.points.dtype == np.float64 and estimate.points.shape[1] == 3
    assert len(estimate.points) > 100
    camera = estimate.cameras[0]
    assert (camera.width, camera.height, camera.model) == (WIDTH, HEIGHT, "SIMPLE_RADIAL")
    assert len({tuple(camera.params) for camera in estimate.cameras}) == 1  # one shared camera
    errors = compare_to_truth(estimate, scene.cameras)
    assert errors["centre_error_max_pct"] < 2.0  # % of the camera distance
    assert errors["rotation_error_max_deg"] < 1.0
    assert errors["focal_error_pct"] < 3.0
    # Progress: monotonic, from 0 to 1.
    assert calls[0] == 0.0 and calls[-1] == 1.0
    assert all(a <= b for a, b in zip(calls, calls[1:]))


def test_cameras_of_the_realistic_sample_match_the_true_ones():
    """The Cycles sample (24 JPEG views, 960x720): every view registers, and the true cable
    seen through the estimated cameras lands where the true cameras put it."""
    sample = Path(__file__).resolve().parent.parent / "samples" / "sequence"
    truth = read_ground_truth(sample / "ground_truth.json")
    estimate = estimate_cameras(sorted((sample / "images").glob("*.jpg")))
    assert estimate.unregistered == () and len(estimate.cameras) == len(truth.cameras)
    assert estimate.plane_found
    errors = compare_to_truth(estimate, truth.cameras, truth.centreline)
    assert errors["centreline_px"] < 0.5
    assert errors["up_error_deg"] < 1.0


def test_estimate_is_upright(estimated):
    estimate, scene, _ = estimated
    assert estimate.plane_found
    assert estimate.transform.scale == 1.0
    similarity = align_similarity([c.center for c in estimate.cameras],
                                  [c.center for c in scene.cameras])
    true_up_here = similarity.R.T @ np.array([0.0, 0.0, 1.0])
    assert np.degrees(np.arccos(true_up_here[2])) < 1.0
    # The true table z = 0 is z = 0 here too: true points on it map to z ~ 0.
    table = np.array([[0.05, 0.02, 0.0], [-0.04, 0.03, 0.0], [0.01, -0.05, 0.0]])
    inverse = (table - similarity.t) @ similarity.R / similarity.scale
    size = np.mean([np.linalg.norm(c.center) for c in estimate.cameras])
    assert np.abs(inverse[:, 2]).max() < 0.01 * size
    assert min(camera.center[2] for camera in estimate.cameras) > 0
    # Most sparse points lie on the table; their centroid is near x = y = 0.
    on_table = np.abs(estimate.points[:, 2]) < 0.01 * size
    assert on_table.mean() > 0.8
    assert np.linalg.norm(estimate.points[on_table, :2].mean(axis=0)) < 1e-6 * size


def test_the_truth_compares_as_perfect(estimated):
    _, scene, _ = estimated
    truth = CameraEstimate(cameras=scene.cameras, points=np.zeros((0, 3)), unregistered=(),
                           transform=Similarity(1.0, np.eye(3), np.zeros(3)), plane_found=True)
    errors = compare_to_truth(truth, scene.cameras, scene.truth.centreline)
    assert max(errors.values()) < 1e-6 and "centreline_px" in errors


def test_same_seed_same_result(scene_dir, estimated):
    folder, _ = scene_dir
    again = estimate_cameras(image_paths(folder))
    first = estimated[0]
    assert again.names == first.names
    for a, b in zip(first.cameras, again.cameras):
        np.testing.assert_array_equal(a.R, b.R)
        np.testing.assert_array_equal(a.t, b.t)


def test_frames_that_cannot_register_are_reported(scene_dir, tmp_path):
    folder, scene = scene_dir
    extra = tmp_path / "extra"  # frames from two folders: staged together in the work folder
    extra.mkdir()
    write_noise(extra / "005_noise.png", 1)  # sorts right after 005.png
    write_noise(extra / "zz_grey.png", 0, grey=True)
    paths = sorted(image_paths(folder) + list(extra.iterdir()), key=lambda path: path.name)
    work = tmp_path / "work"
    estimate = estimate_cameras(paths, focal_length_px=scene.cameras[0].focal[0], work_dir=work)
    assert set(estimate.unregistered) == {"005_noise.png", "zz_grey.png"}
    assert estimate.names == tuple(camera.name for camera in scene.cameras)
    assert (work / "database.db").is_file()
    assert not list(work.glob("images_*"))  # the staged links are gone


def test_too_few_registered_frames_fail_naming_them(tmp_path):
    for k in range(5):
        write_noise(tmp_path / f"noise{k}.png", k)
    with pytest.raises(ReconstructionError, match=r"0 of 5 frames registered.*noise0\.png"):
        estimate_cameras(sorted(tmp_path.iterdir()))


def test_bad_inputs(tmp_path):
    with pytest.raises(InputError, match="none"):
        estimate_cameras([])
    write_noise(tmp_path / "a.png", 0)
    with pytest.raises(InputError, match="at least 3"):
        estimate_cameras([tmp_path / "a.png"])
    with pytest.raises(InputError, match="not found"):
        estimate_cameras([tmp_path / "a.png", tmp_path / "b.png", tmp_path / "c.png"])
    with pytest.raises(ValueError, match="camera_model"):
        CameraEstimationSettings(camera_model="FISHEYE")


def test_an_already_set_cancel_stops_at_once(scene_dir):
    folder, _ = scene_dir
    cancel = threading.Event()
    cancel.set()
    start = time.perf_counter()
    with pytest.raises(Cancelled):
        estimate_cameras(image_paths(folder), cancel=cancel)
    assert time.perf_counter() - start < 1.0


def test_cancel_during_the_work_stops_it(scene_dir):
    folder, _ = scene_dir
    cancel = threading.Event()
    messages = []

    def progress(fraction, message):
        messages.append(message)
        if fraction > 0.2:
            cancel.set()

    start = time.perf_counter()
    with pytest.raises(Cancelled):
        estimate_cameras(image_paths(folder), cancel=cancel, progress=progress)
    assert time.perf_counter() - start < 10.0
    assert not any(message.startswith("mapping") for message in messages)


# -- the command ---------------------------------------------------------------------------------

def test_cameras_command_writes_a_model(scene_dir, tmp_path):
    folder, scene = scene_dir
    output = tmp_path / "model"
    estimate = cameras_command(folder / "images", output)
    model = read_colmap_model(output)
    assert tuple(camera.name for camera in model.cameras) == estimate.names
    assert estimate.names == tuple(camera.name for camera in scene.cameras)
    np.testing.assert_allclose(model.cameras[3].center, estimate.cameras[3].center, atol=1e-9)
    assert len(model.points) == len(estimate.points)
    with pytest.raises(InputError, match="already holds"):
        cameras_command(folder / "images", output)


def test_cameras_command_refuses_missing_or_empty_folders(tmp_path):
    with pytest.raises(InputError, match="does not exist") as error:
        cameras_command(tmp_path / "nowhere", tmp_path / "model")
    assert "nowhere" in str(error.value)
    (tmp_path / "empty").mkdir()
    (tmp_path / "empty" / "notes.txt").write_text("no images")
    with pytest.raises(InputError, match="holds no") as error:
        cameras_command(tmp_path / "empty", tmp_path / "model")
    assert "empty" in str(error.value)


# -- the upright frame alone ---------------------------------------------------------------------

def random_rotation(rng):
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q *= np.sign(np.diag(r))
    return q if np.linalg.det(q) > 0 else -q


def tilted_world(rng, *, flat):
    """Cameras above a table z = 0 and points on it (or scattered), then moved rigidly."""
    angles = np.linspace(0, 2 * np.pi, 8, endpoint=False)
    cameras = [look_at_camera(f"{k:03d}.png", [0.5 * np.cos(a), 0.5 * np.sin(a), 0.4],
                              target=[0.02, -0.01, 0.0])
               for k, a in enumerate(angles)]
    if flat:
        points = np.column_stack([rng.uniform(-0.3, 0.3, (400, 2)), np.zeros(400)])
        above = np.column_stack([rng.uniform(-0.05, 0.05, (40, 2)), rng.uniform(0.03, 0.08, 40)])
        points = np.vstack([points, above])  # a cable on the table: off the plane
    else:
        points = rng.uniform(-0.3, 0.3, (400, 3))
    move = Similarity(1.0, random_rotation(rng), rng.normal(size=3))
    moved = [move.apply_camera(camera) for camera in cameras]
    return cameras, points, moved, move.apply(points), move


def test_make_upright_recovers_the_table_frame_exactly():
    rng = np.random.default_rng(3)
    cameras, points, moved, moved_points, _ = tilted_world(rng, flat=True)
    upright, new_points, transform, plane_found = make_upright(moved, moved_points,
                                                               settings=UprightSettings())
    assert plane_found and transform.scale == 1.0
    on_table = np.arange(400)
    np.testing.assert_allclose(new_points[on_table, 2], 0.0, atol=1e-9)
    np.testing.assert_allclose(new_points[on_table, :2].mean(axis=0), 0.0, atol=1e-9)
    # Rigid: distances kept; only an in-plane rotation and shift separate it from the truth.
    true_heights = np.array([camera.center[2] for camera in cameras])
    np.testing.assert_allclose([camera.center[2] for camera in upright], true_heights, atol=1e-9)
    np.testing.assert_allclose(new_points[400:, 2], points[400:, 2], atol=1e-9)
    # Cameras move with the world: new centres are the transformed old centres, and every
    # point projects to the same pixel as before.
    for old, new in zip(moved, upright):
        np.testing.assert_allclose(new.center, transform.apply(old.center), atol=1e-9)
        before, _ = old.project(moved_points[:5])
        after, _ = new.project(new_points[:5])
        np.testing.assert_allclose(after, before, atol=1e-6)
    # The first camera looks along +y.
    forward = upright[0].R[2]
    assert abs(forward[0]) < 1e-9 and forward[1] > 0


def test_make_upright_falls_back_to_the_cameras_up():
    rng = np.random.default_rng(4)
    cameras, _, moved, moved_points, move = tilted_world(rng, flat=False)
    upright, _, transform, plane_found = make_upright(moved, moved_points)
    assert not plane_found
    # look_at_camera keeps image up = world +z as far as it can; their mean is +z.
    mean_up = -np.mean([camera.R[1] for camera in cameras], axis=0)
    mean_up /= np.linalg.norm(mean_up)
    np.testing.assert_allclose(transform.R @ move.R @ mean_up, [0, 0, 1], atol=1e-9)
    # The look-at point becomes the origin.
    np.testing.assert_allclose(look_at_point(upright), 0.0, atol=1e-9)
    assert min(camera.center[2] for camera in upright) > 0


def test_fit_plane_ignores_outliers():
    rng = np.random.default_rng(5)
    plane = np.column_stack([rng.uniform(-1, 1, (200, 2)), rng.normal(0, 1e-3, 200)])
    outliers = rng.uniform(-1, 1, (100, 3))
    normal, offset, inliers = fit_plane(np.vstack([plane, outliers]), 0.01)
    assert abs(abs(normal[2]) - 1) < 1e-4 and abs(offset) < 1e-3
    assert inliers[:200].all() and inliers[200:].mean() < 0.05

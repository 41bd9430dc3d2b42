"""The camera type and COLMAP models in and out through pycolmap."""

import numpy as np
import pycolmap
import pytest

from conftest import look_at_camera
from engine import CAMERA_MODELS, Camera, InputError, read_colmap_model, write_colmap_model

MODEL_PARAMS = {
    "SIMPLE_PINHOLE": [520.0, 318.0, 243.0],
    "PINHOLE": [520.0, 530.0, 318.0, 243.0],
    "SIMPLE_RADIAL": [520.0, 318.0, 243.0, -0.08],
    "RADIAL": [520.0, 318.0, 243.0, -0.08, 0.02],
    "OPENCV": [520.0, 530.0, 318.0, 243.0, -0.08, 0.02, 0.003, -0.002],
}


def rig_of_cameras():
    """One camera of each supported model around the origin."""
    rng = np.random.default_rng(7)
    cameras = []
    for k, (model, params) in enumerate(MODEL_PARAMS.items()):
        azimuth = 2 * np.pi * k / len(MODEL_PARAMS)
        center = [0.6 * np.cos(azimuth), 0.6 * np.sin(azimuth), 0.4 + 0.1 * rng.random()]
        cameras.append(look_at_camera(f"frame{k + 1}.png", center, rng.normal(0, 0.02, 3),
                                      model=model, params=params))
    return cameras


def test_every_supported_model_is_exercised():
    assert set(MODEL_PARAMS) == set(CAMERA_MODELS)


@pytest.mark.parametrize("binary", [False, True])
def test_model_round_trips_with_same_poses_and_intrinsics(tmp_path, binary):
    cameras = rig_of_cameras()
    points = np.random.default_rng(1).normal(size=(25, 3))
    write_colmap_model(tmp_path, cameras, points=points, binary=binary)
    suffix = ".bin" if binary else ".txt"
    assert (tmp_path / f"cameras{suffix}").is_file() and (tmp_path / f"images{suffix}").is_file()
    model = read_colmap_model(tmp_path)
    assert [c.name for c in model.cameras] == [c.name for c in cameras]
    for original, back in zip(cameras, model.cameras):
        assert back.model == original.model
        assert (back.width, back.height) == (original.width, original.height)
        np.testing.assert_allclose(back.params, original.params, rtol=0, atol=1e-12)
        np.testing.assert_allclose(back.R, original.R, atol=1e-12)
        np.testing.assert_allclose(back.t, original.t, atol=1e-12)
    np.testing.assert_allclose(np.sort(model.points, axis=0), np.sort(points, axis=0), atol=1e-12)


def test_shared_intrinsics_are_written_once(tmp_path):
    cameras = [look_at_camera(f"{k}.jpg", [np.cos(k), np.sin(k), 0.5]) for k in range(4)]
    write_colmap_model(tmp_path, cameras)
    assert pycolmap.Reconstruction(str(tmp_path)).num_cameras() == 1


@pytest.mark.parametrize("model", list(MODEL_PARAMS))
def test_projection_matches_pycolmap(tmp_path, model):
    camera = next(c for c in rig_of_cameras() if c.model == model)
    write_colmap_model(tmp_path, [camera])
    reconstruction = pycolmap.Reconstruction(str(tmp_path))
    image = next(iter(reconstruction.images.values()))
    points = np.random.default_rng(3).uniform(-0.15, 0.15, size=(50, 3))
    ours, depth = camera.project(points)
    assert np.all(depth > 0)
    theirs = np.array([image.project_point(p) for p in points])
    np.testing.assert_allclose(ours, theirs, atol=1e-9)
    # Distortion really is applied: a pinhole projection differs off-centre for distorting models.
    pinhole = Camera(camera.name, camera.width, camera.height, "PINHOLE",
                     [*camera.focal, *camera.principal_point], camera.R, camera.t)
    moved = np.abs(pinhole.project(points)[0] - ours).max()
    assert (moved > 0.05) == (model not in ("PINHOLE", "SIMPLE_PINHOLE"))


def test_points_behind_the_camera_do_not_project():
    camera = look_at_camera("a.jpg", [0, 0, 1])
    pixels, depth = camera.project(np.array([[0, 0, 0], [0, 0, 2]]))
    assert depth[0] > 0 > depth[1]
    assert np.all(np.isfinite(pixels[0])) and np.all(np.isnan(pixels[1]))
    pixel, single_depth = camera.project([0, 0, 0])
    np.testing.assert_allclose(pixel, camera.principal_point)
    assert single_depth == pytest.approx(1.0)


def test_centre_and_calibration_follow_the_convention():
    camera = look_at_camera("a.jpg", [0.3, -0.2, 0.7])
    np.testing.assert_allclose(camera.center, [0.3, -0.2, 0.7], atol=1e-12)
    np.testing.assert_allclose(camera.world_to_camera(camera.center), 0, atol=1e-12)
    np.testing.assert_allclose(camera.K, [[500, 0, 330], [0, 510, 235], [0, 0, 1]])


def test_legacy_model_without_rigs_and_frames(tmp_path):
    (tmp_path / "cameras.txt").write_text("1 PINHOLE 640 480 500 500 320 240\n")
    (tmp_path / "images.txt").write_text(
        "# a comment\n1 1 0 0 0 0.1 0.2 3 1 b.jpg\n\n2 1 0 0 0 1 0 3 1 a.jpg\n\n")
    model = read_colmap_model(tmp_path)
    assert [c.name for c in model.cameras] == ["a.jpg", "b.jpg"]
    np.testing.assert_allclose(model.camera("b.jpg").t, [0.1, 0.2, 3])
    assert model.points.shape == (0, 3)


def test_bad_models_name_the_folder(tmp_path):
    missing = tmp_path / "nowhere"
    with pytest.raises(InputError, match=f"{missing} does not exist"):
        read_colmap_model(missing)
    empty = tmp_path / "empty"
    empty.mkdir()
    with pytest.raises(InputError, match=f"{empty} holds no COLMAP model"):
        read_colmap_model(empty)
    broken = tmp_path / "broken"
    broken.mkdir()
    (broken / "cameras.txt").write_text("1 PINHOLE 640 abc 500 500 320 240\n")
    (broken / "images.txt").write_text("")
    with pytest.raises(InputError, match=f"model in {broken} is malformed") as info:
        read_colmap_model(broken)
    assert "\n" not in str(info.value) and ".cc:" not in str(info.value)
    fisheye = tmp_path / "fisheye"
    fisheye.mkdir()
    (fisheye / "cameras.txt").write_text("1 OPENCV_FISHEYE 640 480 500 500 320 240 0 0 0 0\n")
    (fisheye / "images.txt").write_text("1 1 0 0 0 0 0 3 1 a.jpg\n\n")
    with pytest.raises(InputError, match="OPENCV_FISHEYE, which is not supported"):
        read_colmap_model(fisheye)


def test_writing_never_replaces_a_model_unasked(tmp_path):
    cameras = rig_of_cameras()
    write_colmap_model(tmp_path, cameras[:2])
    with pytest.raises(FileExistsError):
        write_colmap_model(tmp_path, cameras)
    assert len(read_colmap_model(tmp_path).cameras) == 2
    write_colmap_model(tmp_path, cameras, binary=True, overwrite=True)
    assert len(read_colmap_model(tmp_path).cameras) == len(cameras)
    assert not (tmp_path / "cameras.txt").exists()  # one model, not two flavours


@pytest.mark.parametrize("kwargs, message", [
    ({"model": "FISHEYE"}, "not supported"),
    ({"params": [1, 2]}, "takes 4 parameters"),
    ({"R": np.diag([1, 1, -1])}, "not a rotation"),
    ({"t": [0, 0, np.nan]}, "finite"),
    ({"width": 0}, "positive"),
])
def test_invalid_cameras_are_rejected(kwargs, message):
    fields = dict(name="a.jpg", width=640, height=480, model="PINHOLE",
                  params=[500, 500, 320, 240], R=np.eye(3), t=[0, 0, 1])
    fields.update(kwargs)
    with pytest.raises(InputError, match=message):
        Camera(**fields)


def test_binary_model_without_points(tmp_path):
    write_colmap_model(tmp_path, rig_of_cameras()[:2], binary=True)
    (tmp_path / "points3D.bin").unlink()
    model = read_colmap_model(tmp_path)
    assert len(model.cameras) == 2 and model.points.shape == (0, 3)

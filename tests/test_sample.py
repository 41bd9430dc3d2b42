"""The committed realistic sample, and the Cycles renderer that makes it (at a tiny size)."""

import os
import subprocess
import sys

import cv2
import numpy as np

from conftest import ROOT
from engine import read_colmap_model
from engine.io.ground_truth import read_ground_truth
from engine.synthetic.cameras import cable_pixel_width

SAMPLE = ROOT / "samples" / "sequence"


def iou(a, b):
    return (a & b).sum() / max((a | b).sum(), 1)


def red_pixels(image_bgr):
    hsv = cv2.cvtColor(image_bgr, cv2.COLOR_BGR2HSV)
    return ((hsv[..., 0] < 10) | (hsv[..., 0] > 170)) & (hsv[..., 1] > 110) & (hsv[..., 2] > 40)


def test_sample_is_complete():
    truth = read_ground_truth(SAMPLE / "ground_truth.json")
    model = read_colmap_model(SAMPLE / "sparse")
    assert len(truth.crossings) >= 3
    assert len(model.cameras) >= 24
    assert [c.name for c in model.cameras] == [c.name for c in truth.cameras]
    for camera, true_camera in zip(model.cameras, truth.cameras):
        np.testing.assert_allclose(camera.t, true_camera.t, atol=1e-12)
        image = cv2.imread(str(SAMPLE / "images" / camera.name))
        assert camera.name.endswith(".jpg") and image.shape == (camera.height, camera.width, 3)
        assert camera.width >= 960 and camera.height >= 720
        mask = cv2.imread(str(SAMPLE / "masks" / camera.name.replace(".jpg", ".png")), 0)
        assert mask.shape == image.shape[:2] and set(np.unique(mask)) <= {0, 255}
    assert cable_pixel_width(truth, truth.cameras) >= 5.0


def test_exact_masks_match_the_rendered_cable():
    # A plain colour threshold on Cycles' images against the engine's ray-cast masks: the two
    # were made independently, so agreement proves the cameras and geometry line up.
    truth = read_ground_truth(SAMPLE / "ground_truth.json")
    scores = []
    for camera in truth.cameras[::6]:
        image = cv2.imread(str(SAMPLE / "images" / camera.name))
        mask = cv2.imread(str(SAMPLE / "masks" / camera.name.replace(".jpg", ".png")), 0) > 0
        scores.append(iou(red_pixels(image), mask))
    assert min(scores) > 0.8


def test_cycles_renderer_at_a_tiny_size(tmp_path):
    out = tmp_path / "tiny"
    run = subprocess.run(
        [sys.executable, str(ROOT / "tools" / "render_sample.py"), "-o", str(out),
         "--views", "2", "--size", "200x150", "--samples", "4", "--crossings", "2",
         "--seed", "1", "--radius", "0.006"],
        capture_output=True, text=True, timeout=600, cwd=tmp_path,
        env=dict(os.environ, BLENDER_USER_RESOURCES=str(tmp_path / "user")))
    assert run.returncode == 0, run.stderr[-3000:]
    truth = read_ground_truth(out / "ground_truth.json")
    assert len(truth.crossings) == 2 and len(truth.cameras) == 2
    assert len(read_colmap_model(out / "sparse").cameras) == 2
    image = cv2.imread(str(out / "images" / "000.jpg"))
    mask = cv2.imread(str(out / "masks" / "000.png"), 0) > 0
    assert image.shape == (150, 200, 3)
    assert iou(red_pixels(image), mask) > 0.6  # tiny, so edges weigh a lot
    again = subprocess.run([sys.executable, str(ROOT / "tools" / "render_sample.py"), "-o",
                            str(out), "--views", "2", "--size", "200x150"],
                           capture_output=True, text=True, timeout=60)
    assert again.returncode != 0 and "already holds a sample" in again.stderr
    assert (out / "preview.jpg").is_file()


def test_exact_masks_are_blenders_own_silhouette(tmp_path):
    # Unlit white cable on black without pixel filter: a pixel is above half brightness
    # (sRGB 188) exactly when more than half of it is covered, i.e. its centre is inside.
    out = tmp_path / "flat"
    run = subprocess.run(
        [sys.executable, str(ROOT / "tools" / "render_sample.py"), "-o", str(out),
         "--views", "2", "--size", "320x240", "--samples", "16", "--crossings", "3",
         "--seed", "3", "--radius", "0.006", "--silhouette"],
        capture_output=True, text=True, timeout=600, cwd=tmp_path,
        env=dict(os.environ, BLENDER_USER_RESOURCES=str(tmp_path / "user")))
    assert run.returncode == 0, run.stderr[-3000:]
    for name in ("000", "001"):
        silhouette = cv2.imread(str(out / "images" / f"{name}.png"))[..., 2] > 188
        mask = cv2.imread(str(out / "masks" / f"{name}.png"), 0) > 0
        assert mask.sum() > 2000
        assert iou(silhouette, mask) > 0.98
        (dx, dy), _ = cv2.phaseCorrelate(mask.astype(np.float32), silhouette.astype(np.float32))
        assert abs(dx) < 0.1 and abs(dy) < 0.1  # no offset between the conventions

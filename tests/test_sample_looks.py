"""The Cycles sample renderer's looks and hard layouts (at a tiny size): look.json, the lifted
truth, clutter that never hides the cable, a heap framed in part, and the pre-rendered held-out
captures in samples/looks and samples/hard."""

import dataclasses
import json
import os
import subprocess
import sys

import cv2
import numpy as np
import pytest

from conftest import ROOT
from engine import read_colmap_model
from engine.io.ground_truth import read_ground_truth
from engine.synthetic.cameras import cable_pixel_width, out_of_frame
from engine.synthetic.layouts import hard_layout, table_layout
from engine.synthetic.looks import HELD_OUT_SEEDS, sample_look

LOOKS = ROOT / "samples" / "looks"
HARD = ROOT / "samples" / "hard"

sys.path.insert(0, str(ROOT / "tools"))
import render_sample  # noqa: E402  (no bpy at import)


def render(tmp_path, name, *args):
    out = tmp_path / name
    run = subprocess.run(
        [sys.executable, str(ROOT / "tools" / "render_sample.py"), "-o", str(out),
         "--views", "2", "--crossings", "2", "--seed", "1", "--radius", "0.006",
         "--texture-size", "256", "--threads", "1", *args],
        capture_output=True, text=True, timeout=600, cwd=tmp_path,
        env=dict(os.environ, BLENDER_USER_RESOURCES=str(tmp_path / "user")))
    assert run.returncode == 0, run.stderr[-3000:]
    return out


def silhouettes(out, name):
    """Cable (white: more than half covered) and clutter (green) pixels of a --silhouette frame."""
    image = cv2.imread(str(out / "images" / f"{name}.png"))
    cable = image[..., 2] > 188
    clutter = (image[..., 1] > 128) & (image[..., 2] < 100)
    mask = cv2.imread(str(out / "masks" / f"{name}.png"), 0) > 0
    return cable, clutter, mask


def test_a_lifted_look_writes_its_look_and_the_lifted_truth(tmp_path):
    out = render(tmp_path, "air", "--look", "air", "--look-seed", "1002", "--size", "160x120",
                 "--samples", "1", "--silhouette")
    look = sample_look("air", 1002)
    assert json.loads((out / "look.json").read_text()) == \
        json.loads(json.dumps(dataclasses.asdict(look)))
    truth = read_ground_truth(out / "ground_truth.json")
    flat = table_layout(2, seed=1, radius=0.006)
    assert look.lift > 5
    np.testing.assert_allclose(truth.centreline[:, :2], flat.centreline[:, :2])
    np.testing.assert_allclose(truth.centreline[:, 2], flat.centreline[:, 2] + look.lift * 0.006)
    for name in ("000", "001"):  # Blender's cable is where the lifted truth says
        cable, _, mask = silhouettes(out, name)
        assert mask.sum() > 300
        assert (cable & mask).sum() / (cable | mask).sum() > 0.9


def test_a_hard_layout_renders_as_the_heap_of_its_seed(tmp_path):
    out = render(tmp_path, "hard", "--layout", "hard", "--size", "160x120", "--samples", "1",
                 "--silhouette")
    truth = read_ground_truth(out / "ground_truth.json")
    assert truth.kind == "hard" and len(truth.crossings) >= 12  # --crossings 2 is ignored
    np.testing.assert_allclose(truth.centreline,
                               hard_layout(seed=1, radius=0.006).centreline)
    for name in ("000", "001"):
        cable, _, mask = silhouettes(out, name)
        assert mask.sum() > 300
        assert (cable & mask).sum() / (cable | mask).sum() > 0.9


def test_clutter_never_hides_the_cable(tmp_path):
    out = render(tmp_path, "clutter", "--look", "clutter", "--look-seed", "1002", "--size",
                 "160x120", "--samples", "1", "--silhouette")
    placed = json.loads((out / "clutter.json").read_text())
    assert len(placed) == len(sample_look("clutter", 1002).clutter)
    seen = 0
    for name in ("000", "001"):
        cable, clutter, mask = silhouettes(out, name)
        seen += clutter.sum()
        assert not (clutter & mask).any()  # no cable pixel of the exact mask is hidden
        assert (cable & mask).sum() / (cable | mask).sum() > 0.9
    assert seen > 50  # the clutter is in view


def test_a_look_renders_with_its_camera_effects(tmp_path):
    out = render(tmp_path, "patterned", "--look", "patterned", "--look-seed", "1000",
                 "--size", "80x60", "--samples", "2")
    assert json.loads((out / "look.json").read_text())["family"] == "patterned"
    image = cv2.imread(str(out / "images" / "000.jpg"))
    assert image.shape == (60, 80, 3) and image.std() > 5
    assert (out / "preview.jpg").is_file()


@pytest.mark.skipif(not LOOKS.is_dir(), reason="no pre-rendered looks")
def test_prerendered_looks_are_complete_and_held_out():
    folders = sorted(p for p in LOOKS.iterdir() if p.is_dir())
    families = {json.loads((p / "look.json").read_text())["family"] for p in folders}
    assert len(folders) >= 6
    assert {"pale", "neutral", "hard_light", "air", "clutter"} <= families
    assert families & {"patterned", "same_hue"}
    for folder in folders:
        look = json.loads((folder / "look.json").read_text())
        assert look["seed"] in HELD_OUT_SEEDS
        assert folder.name == f"{look['family']}-{look['seed']}"
        truth = read_ground_truth(folder / "ground_truth.json")
        model = read_colmap_model(folder / "sparse")
        assert 16 <= len(truth.cameras) <= 24 and 2 <= len(truth.crossings) <= 6
        assert [c.name for c in model.cameras] == [c.name for c in truth.cameras]
        assert cable_pixel_width(truth, truth.cameras) >= 5.0
        for camera in truth.cameras:
            assert (camera.width, camera.height) == (640, 480)
            assert (folder / "images" / camera.name).is_file()
            assert (folder / "masks" / camera.name.replace(".jpg", ".png")).is_file()
        if look["lift"]:
            assert truth.centreline[:, 2].min() > (1 + 0.9 * look["lift"]) * truth.radius
        if look["clutter"]:  # every object stands clear of the cable's exact mask in every view
            masks = [cv2.imread(str(folder / "masks" / c.name.replace(".jpg", ".png")), 0) > 0
                     for c in truth.cameras]
            placed = [render_sample.PlacedClutter(**obj)
                      for obj in json.loads((folder / "clutter.json").read_text())]
            assert placed
            for obj in placed:
                assert render_sample.clear_of_cable(obj, truth.cameras, masks)[0]


@pytest.mark.skipif(not HARD.is_dir(), reason="no pre-rendered hard layouts")
def test_prerendered_hard_layouts_are_held_out_heaps_partly_out_of_frame():
    folders = sorted(p for p in HARD.iterdir() if p.is_dir())
    assert len(folders) >= 2
    for folder in folders:
        seed = json.loads((folder / "look.json").read_text())["seed"]
        truth = read_ground_truth(folder / "ground_truth.json")
        assert folder.name.startswith("hard-") and int(folder.name[5:]) in HELD_OUT_SEEDS
        assert seed in HELD_OUT_SEEDS
        assert truth.kind == "hard" and 12 <= len(truth.crossings) <= 20
        np.testing.assert_allclose(truth.centreline,
                                   hard_layout(seed=int(folder.name[5:])).centreline)
        model = read_colmap_model(folder / "sparse")
        assert len(truth.cameras) == 30
        assert [c.name for c in model.cameras] == [c.name for c in truth.cameras]
        for camera in truth.cameras:
            assert (camera.width, camera.height) == (960, 720)
            assert (folder / "images" / camera.name).is_file()
            assert (folder / "masks" / camera.name.replace(".jpg", ".png")).is_file()
        outside = out_of_frame(truth, truth.cameras)  # each view frames part of the heap
        assert outside.mean() > 0.1 and outside.max() < 0.9

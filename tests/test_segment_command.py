"""`python -m engine segment` and the segmentation bench's scoring."""

import subprocess
import sys

import cv2
import numpy as np
import pytest

from conftest import ROOT
from engine.bench.common import format_table
from engine.bench.segment import junction_scores
from engine.synthetic.scene import SceneSpec, make_scene, write_scene


@pytest.fixture(scope="module")
def scene_folder(tmp_path_factory):
    scene = make_scene(SceneSpec(crossings=3, seed=6, views=10, width=480, height=360))
    return write_scene(scene, tmp_path_factory.mktemp("scene") / "s"), scene


def run_engine(*args):
    return subprocess.run([sys.executable, "-m", "engine", *map(str, args)], cwd=ROOT,
                          capture_output=True, text=True, timeout=300)


def test_segment_writes_masks_junctions_and_a_contact_sheet(scene_folder, tmp_path):
    folder, scene = scene_folder
    run = run_engine("segment", folder / "images", "-o", tmp_path / "out", "--cameras",
                     folder / "sparse")
    assert run.returncode == 0, run.stderr
    assert "100%" in run.stderr and "--hsv" in run.stderr
    assert "masks agreed across views" in run.stderr
    for camera, truth in zip(scene.cameras, scene.masks):
        stem = camera.name.rsplit(".", 1)[0] + ".png"
        mask = cv2.imread(str(tmp_path / "out" / "masks" / stem), cv2.IMREAD_GRAYSCALE)
        assert set(np.unique(mask)) <= {0, 255}
        assert ((mask > 0) & truth).sum() / ((mask > 0) | truth).sum() > 0.85
        junctions = cv2.imread(str(tmp_path / "out" / "junctions" / stem), cv2.IMREAD_GRAYSCALE)
        assert junctions.shape == mask.shape and not (junctions > mask).any()
    assert cv2.imread(str(tmp_path / "out" / "contact_sheet.png")) is not None
    again = run_engine("segment", folder / "images", "-o", tmp_path / "out")
    assert again.returncode == 2 and "already holds masks" in again.stderr
    assert run_engine("segment", folder / "images", "-o", tmp_path / "out",
                      "--overwrite", "--no-agreement", "-q").returncode == 0


def test_segment_with_a_given_colour_and_bad_colours(scene_folder, tmp_path):
    folder, _ = scene_folder
    run = run_engine("segment", folder / "images", "-o", tmp_path / "a",
                     "--hsv", "170,100,40,10,255,255", "--no-agreement")
    assert run.returncode == 0, run.stderr
    bad = run_engine("segment", folder / "images", "-o", tmp_path / "b", "--hsv", "1,2,3")
    assert bad.returncode == 2 and bad.stderr.strip().startswith("error: --hsv")


def test_a_frame_without_cable_is_named(scene_folder, tmp_path):
    folder, _ = scene_folder
    frames = tmp_path / "frames"
    frames.mkdir()
    for path in sorted((folder / "images").iterdir())[:3]:
        (frames / path.name).write_bytes(path.read_bytes())
    table_only = cv2.imread(str(frames / "000.png"))
    table_only[:] = cv2.GaussianBlur(table_only, (0, 0), 3)
    table_only[..., 2] = table_only[..., 1]  # no red left anywhere
    cv2.imwrite(str(frames / "009.png"), table_only)
    run = run_engine("segment", frames, "-o", tmp_path / "out")
    assert run.returncode == 2
    assert "no cable pixels in 009.png" in run.stderr.splitlines()[-1]


def test_masks_agree_across_views_with_given_or_estimated_cameras(scene_folder, tmp_path):
    """A red stroke painted in one frame is cable to the segmentation; the other views do
    not see it: the agreement removes it (shown red on the contact sheet), with the true
    cameras or estimated ones, and --no-agreement keeps it."""
    folder, scene = scene_folder
    frames = tmp_path / "frames"
    frames.mkdir()
    for path in sorted((folder / "images").iterdir()):
        (frames / path.name).write_bytes(path.read_bytes())
    image = cv2.imread(str(frames / "003.png"))
    truth = scene.masks[3]
    colour = tuple(int(c) for c in image[truth].mean(axis=0))
    stroke = np.array([[20, 330], [70, 300], [120, 320], [170, 290]], np.int32)
    assert not truth[280:340, 10:180].any()
    cv2.polylines(image, [stroke], False, colour, thickness=5, lineType=cv2.LINE_AA)
    cv2.imwrite(str(frames / "003.png"), image)

    def read(output, stem):
        return cv2.imread(str(output / "masks" / f"{stem}.png"), cv2.IMREAD_GRAYSCALE) > 0

    def iou(a, b):
        return (a & b).sum() / (a | b).sum()

    plain = run_engine("segment", frames, "-o", tmp_path / "plain", "--no-agreement")
    assert plain.returncode == 0, plain.stderr
    assert read(tmp_path / "plain", "003")[280:340, 10:180].sum() > 500
    for cameras in (("--cameras", folder / "sparse"), ()):
        output = tmp_path / ("given" if cameras else "estimated")
        run = run_engine("segment", frames, "-o", output, *cameras)
        assert run.returncode == 0, run.stderr
        assert not read(output, "003")[280:340, 10:180].any()
        for camera, truth in zip(scene.cameras, scene.masks):
            stem = camera.name.rsplit(".", 1)[0]
            segmented = read(tmp_path / "plain", stem)
            assert iou(read(output, stem), truth) >= iou(segmented, truth) - 0.005
        sheet = cv2.imread(str(output / "contact_sheet.png"))
        red = (sheet[..., 2] > 200) & (sheet[..., 1] < 80) & (sheet[..., 0] < 80)
        assert red.sum() > 20
    bad = run_engine("segment", frames, "-o", tmp_path / "bad", "--cameras", tmp_path / "none")
    assert bad.returncode == 2
    assert bad.stderr.strip() == f"error: --cameras {tmp_path / 'none'}: not a folder"


def test_missing_folder_exits_2(tmp_path):
    run = run_engine("segment", tmp_path / "nowhere", "-o", tmp_path / "out")
    assert run.returncode == 2 and "does not exist" in run.stderr


def test_junction_scores_count_found_and_stray(scene_folder):
    _, scene = scene_folder
    truth, camera = scene.truth, scene.cameras[0]
    junctions = np.zeros((camera.height, camera.width), bool)
    for crossing in truth.crossings:
        u, v = camera.project(truth.crossing_position(crossing))[0]
        junctions[int(v), int(u)] = True
    found, visible, stray, total = junction_scores(junctions, truth, camera)
    assert found == visible == len(truth.crossings) and stray == 0 and total == 3
    junctions[:] = False
    junctions[0, 0] = True
    assert junction_scores(junctions, truth, camera) == (0, 3, 1, 1)


def test_format_table():
    table = format_table([{"scene": "a", "iou": 0.91234, "n": 3}])
    assert table.splitlines() == ["| scene | iou | n |", "|---|---|---|", "| a | 0.912 | 3 |"]


def test_a_failed_row_shows_its_error_whatever_the_first_row_held():
    rows = [{"scene": "a", "iou": 0.5}, {"scene": "b", "error": "no cable | found"}]
    assert format_table(rows).splitlines()[0] == "| scene | iou | error |"
    assert format_table(rows).splitlines()[-1] == "| b |  | no cable / found |"
    assert format_table(rows, ["scene"]).splitlines()[-1] == "| b | no cable / found |"


def test_segment_all_cables_writes_every_cable(tmp_path):
    from engine.synthetic.scene import look_scene

    scene = look_scene("two_cables", 3, views=6, width=640, height=480)
    folder = write_scene(scene, tmp_path / "pair")
    run = run_engine("segment", folder / "images", "-o", tmp_path / "out", "--all-cables",
                     "--no-agreement")
    assert run.returncode == 0, run.stderr
    assert "2 cables found on 000.jpg" in run.stderr and "every cable" in run.stderr
    for camera, truth in zip(scene.cameras, scene.masks):
        mask = cv2.imread(str(tmp_path / "out" / "masks" / (camera.name[:-4] + ".png")),
                          cv2.IMREAD_GRAYSCALE) > 0
        assert (mask & truth).sum() / (mask | truth).sum() > 0.85

"""The Blender experience with real bpy: settings, live preview, Reconstruct, Flip, batch."""

import json
import threading

import bpy
import numpy as np
import pytest
from mathutils.geometry import interpolate_bezier

from engine.pipeline import PipelineSettings, reconstruct
from engine.stages.bezier import BezierSettings, distance_to_polyline
from engine.stages.mask_preview import mask_preview
from engine.stages.segmentation import SegmentationSettings, auto_colour, segment_frame
from engine.synthetic.scene import SceneSpec, make_scene, write_scene


@pytest.fixture(scope="module")
def capture(tmp_path_factory):
    """A 2-crossing table scene, 20 views at 640x480, with its true cameras."""
    scene = make_scene(SceneSpec(crossings=2, seed=3, views=20, width=640, height=480,
                                 image_format="jpg"))
    return write_scene(scene, tmp_path_factory.mktemp("capture") / "twist")


@pytest.fixture(scope="module")
def api_result(capture):
    return reconstruct(capture / "images", cameras=capture / "sparse")


def configure(scene, capture, **changes):
    settings = scene.cable_recon
    settings.images = str(capture / "images")
    settings.camera_source = "MODEL"
    settings.camera_model = str(capture / "sparse")
    settings.scale = "NONE"
    for name, value in changes.items():
        setattr(settings, name, value)
    return settings


def curve_samples(obj, per_piece=32):
    """Points along the Blender curve, evaluated by Blender's own Bézier interpolation."""
    samples = []
    for spline in obj.data.splines:
        points = list(spline.bezier_points)
        pairs = list(zip(points, points[1:] + (points[:1] if spline.use_cyclic_u else [])))
        for a, b in pairs:
            samples += interpolate_bezier(a.co, a.handle_right, b.handle_left, b.co, per_piece)
    return np.array([tuple(p) for p in samples])


def test_settings_come_from_the_engine_and_are_saved_in_the_blend(empty_scene, tmp_path):
    from cable_reconstruction.addon.properties import QUALITY_GROUPS, pipeline_settings
    from cable_reconstruction.engine.pipeline import PipelineSettings as AddonPipelineSettings

    settings = empty_scene.cable_recon
    # the add-on's copy of the engine (inside Blender: bl_ext....engine) has the same defaults
    assert pipeline_settings(settings) == AddonPipelineSettings()
    assert repr(AddonPipelineSettings()) == repr(PipelineSettings())
    names = {name for name, _, _ in QUALITY_GROUPS}
    assert {"segmentation", "carving", "fit", "topology", "curve"} <= names
    assert settings.curve.tolerance == pytest.approx(BezierSettings().tolerance)
    settings.carving.voxels_per_radius = 5
    settings.diameter = 7.5
    path = tmp_path / "settings.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    bpy.ops.wm.read_homefile(use_empty=True)
    assert bpy.context.scene.cable_recon.diameter != pytest.approx(7.5)
    bpy.ops.wm.open_mainfile(filepath=str(path))
    reopened = bpy.context.scene.cable_recon
    assert reopened.diameter == pytest.approx(7.5)
    assert pipeline_settings(reopened).carving.voxels_per_radius == 5


def test_the_panels_limits_and_defaults_are_the_engines(empty_scene):
    from cable_reconstruction.engine.pipeline import RunInputs

    settings = empty_scene.cable_recon
    vote = settings.carving.bl_rna.properties["vote"]
    assert vote.hard_max == 1.0 and 0.0 < vote.hard_min < 1e-5  # (0, 1]
    assert "> 0 and <= 1" in vote.description
    assert settings.topology.bl_rna.properties["max_degree"].hard_min == 2
    assert "r)" in settings.topology.bl_rna.properties["spur_length"].description  # its unit
    settings.carving.vote = 5.0  # Blender clamps to the engine's range
    assert settings.carving.vote == 1.0
    assert settings.diameter == pytest.approx(RunInputs.PANEL_DIAMETER)
    assert ",".join(map(str, (*settings.hsv_low, *settings.hsv_high))) == RunInputs.PANEL_HSV


def test_a_run_made_in_blender_repeats_from_the_command_line(empty_scene, capture, tmp_path):
    from cable_reconstruction.addon.reconstruction import sessions
    from engine.cli.main import main
    from engine.io.result import read_result

    settings = configure(empty_scene, capture, with_cameras=False, scale="DIAMETER",
                         diameter=6.0)
    settings.carving.voxels_per_radius = 2.5
    settings.fit.passes = 1
    assert bpy.ops.cable_recon.reconstruct() == {"FINISHED"}
    obj = bpy.data.objects["twist"]
    made = sessions[obj.cable_recon.run].result
    path = tmp_path / "twist.run.json"
    assert bpy.ops.cable_recon.save_run(filepath=str(path)) == {"FINISHED"}
    with pytest.raises(RuntimeError, match="already exists"):  # never over a file unasked
        bpy.ops.cable_recon.save_run(filepath=str(path))
    assert main(["-q", "reconstruct", str(capture / "images"), "--cameras",
                 str(capture / "sparse"), "--settings", str(path),
                 "-o", str(tmp_path / "again.json")]) == 0
    again = read_result(tmp_path / "again.json")
    assert again.run == made.run and again.units == "m"
    assert again.run["settings"]["carving"]["voxels_per_radius"] == 2.5
    assert again.radius == made.radius
    for a, b in zip(made.paths, again.paths):
        assert (a.points == b.points).all()


def test_live_preview_is_the_engines_mask_and_follows_the_colour(empty_scene, capture):
    from cable_reconstruction.addon.mask_preview import PREVIEW_IMAGE, refresh_preview

    settings = configure(empty_scene, capture)
    assert refresh_preview(bpy.context) is None  # nothing until the preview is shown
    assert bpy.ops.cable_recon.show_preview() == {"FINISHED"}
    image = bpy.data.images[PREVIEW_IMAGE]
    frame = bpy.data.images.load(str(sorted((capture / "images").iterdir())[0]))
    frame_rgb = (np.array(frame.pixels[:]).reshape(frame.size[1], frame.size[0], 4)[::-1, :, :3]
                 * 255).round().astype(np.uint8)
    expected = mask_preview(frame_rgb, None).pixels
    shown = np.array(image.pixels[:], dtype=np.float32).reshape(expected.shape)
    assert np.abs(shown - expected).max() < 2 / 255  # JPEG decoders may differ by a level
    bright = shown[..., :3].sum()
    settings.hsv_low, settings.hsv_high = (90, 250, 250), (91, 255, 255)
    settings.colour_mode = "HSV"  # a colour that is not there: the frame goes dim
    dim = np.array(image.pixels[:], dtype=np.float32).reshape(expected.shape)
    assert dim[..., :3].sum() < bright
    assert "no cable" in bpy.context.window_manager.cable_recon_status
    # the preview follows the segmentation's quality settings (the colour panel's "All
    # cables" among them) as it follows the colour
    settings.colour_mode = "AUTO"
    settings.segmentation.speck_area = 10000.0  # every piece is a speck
    strict = np.array(image.pixels[:], dtype=np.float32).reshape(expected.shape)
    wanted = mask_preview(frame_rgb, None, SegmentationSettings(speck_area=10000.0)).pixels
    assert np.abs(strict - wanted).max() < 2 / 255
    assert (np.abs(strict - shown).max(axis=-1) > 0.1).sum() > 50  # it changed


def test_picking_the_cable_sets_a_colour_that_finds_it(empty_scene, capture):
    from cable_reconstruction.addon.mask_preview import frame_image

    settings = configure(empty_scene, capture)
    frame, _ = frame_image(settings)
    mask = segment_frame(frame, auto_colour(frame)).mask
    rows, cols = np.nonzero(mask)
    middle = len(rows) // 2
    assert bpy.ops.cable_recon.pick_colour(x=int(cols[middle]), y=int(rows[middle])) \
        == {"FINISHED"}
    assert settings.colour_mode == "HSV"
    from cable_reconstruction.addon.properties import colour_range

    picked = segment_frame(frame, colour_range(settings)).mask
    assert (picked & mask).sum() > 0.9 * mask.sum()
    with pytest.raises(RuntimeError, match="outside"):
        bpy.ops.cable_recon.pick_colour(x=5000, y=10)


def test_reconstruct_makes_an_editable_bezier_that_agrees_with_the_api(
        empty_scene, capture, api_result):
    configure(empty_scene, capture)
    assert bpy.ops.cable_recon.reconstruct() == {"FINISHED"}
    collection = bpy.data.collections["twist"]
    curves = [o for o in collection.objects if o.type == "CURVE"]
    assert len(curves) == 1
    obj = curves[0]
    assert obj.name == "twist" and obj.select_get()
    radius = api_result.radius
    assert obj.data.bevel_depth == pytest.approx(radius, rel=1e-5)
    assert obj.data.bevel_mode == "ROUND" and obj.data.use_fill_caps
    splines = obj.data.splines
    assert len(splines) == 1 and splines[0].type == "BEZIER"
    count = len(splines[0].bezier_points)
    assert count == obj.cable_recon.control_points
    assert count < len(api_result.paths[0].points) / 4  # editable: few control points
    # Blender's own evaluation of the curve stays within 0.1 r of the engine's result
    dense = curve_samples(obj)
    truth_line = api_result.paths[0].points
    assert distance_to_polyline(dense, truth_line).max() <= 0.1 * radius * 1.001
    assert distance_to_polyline(truth_line, dense).max() <= 0.1 * radius * 1.001
    assert obj.cable_recon.max_error <= 0.1
    assert len(obj.cable_recon.crossings) == 2
    material = obj.data.materials[0]
    red, green, blue, _ = material.diffuse_color
    assert red > 3 * max(green, blue)  # the cable is red
    cameras = bpy.data.collections["twist cameras"].objects
    assert len(cameras) == 20 and all(c.type == "CAMERA" for c in cameras)
    assert all(c.data.show_background_images and c.data.background_images[0].image
               for c in cameras)


def test_running_again_replaces_the_result(empty_scene, capture):
    configure(empty_scene, capture, with_cameras=False)
    bpy.ops.cable_recon.reconstruct("INVOKE_DEFAULT")  # no window here: it blocks
    first = {o.name for o in bpy.data.objects}
    bpy.ops.cable_recon.reconstruct()
    assert {o.name for o in bpy.data.objects} == first == {"twist"}
    assert [c.name for c in bpy.data.collections] == ["twist"]
    assert len(bpy.data.curves) == 1 and len(bpy.data.materials) == 1


def test_flipping_a_crossing_swaps_it_and_refits(empty_scene, capture):
    # the add-on's own copy of the engine made the result, so it is checked with that copy
    from cable_reconstruction.engine import read_ground_truth
    from cable_reconstruction.engine.evaluation.metrics import evaluate

    truth = read_ground_truth(capture / "ground_truth.json")
    configure(empty_scene, capture, with_cameras=False)
    bpy.ops.cable_recon.reconstruct()
    before = [(c.over_index, c.under_index)
              for c in bpy.data.objects["twist"].cable_recon.crossings]
    assert bpy.ops.cable_recon.flip_crossing(index=1) == {"FINISHED"}
    obj = bpy.data.objects["twist"]
    after = [(c.over_index, c.under_index) for c in obj.cable_recon.crossings]
    assert abs(after[0][0] - before[0][0]) <= 2 and abs(after[0][1] - before[0][1]) <= 2
    assert abs(after[1][0] - before[1][1]) <= 2 and abs(after[1][1] - before[1][0]) <= 2
    # the curve itself now passes the other way: one crossing right, one wrong
    from cable_reconstruction.addon.reconstruction import sessions

    state = sessions[obj.cable_recon.run]
    assert evaluate(state.result, truth).crossings_right == 1
    over = obj.cable_recon.crossings[1]
    dense = curve_samples(obj)
    heights = [dense[np.linalg.norm(dense - state.result.paths[0].points[i], axis=1)
                     < 0.5 * state.result.radius][:, 2].mean()
               for i in (over.over_index, over.under_index)]
    assert heights[0] > heights[1]
    assert len(bpy.data.objects) == 1
    with pytest.raises(RuntimeError, match="no crossing 7"):
        bpy.ops.cable_recon.flip_crossing(index=7)


def test_flip_after_a_restart_reruns_from_the_stored_arguments(empty_scene, capture):
    from cable_reconstruction.addon.reconstruction import sessions

    configure(empty_scene, capture, with_cameras=False)
    bpy.ops.cable_recon.reconstruct()
    sessions.clear()  # as after reopening the .blend in a new Blender
    assert bpy.ops.cable_recon.flip_crossing(index=0) == {"FINISHED"}
    assert len(bpy.data.objects["twist"].cable_recon.crossings) == 2


@pytest.mark.parametrize("images, message", [
    ("", "choose the folder"),
    ("does/not/exist", "does not exist"),
    ("EMPTY", "holds no .jpg or .png"),
])
def test_bad_folders_are_reported_and_add_nothing(empty_scene, tmp_path, images, message):
    settings = empty_scene.cable_recon
    if images == "EMPTY":
        images = str(tmp_path)
    settings.images = images
    with pytest.raises(RuntimeError, match=message):
        bpy.ops.cable_recon.reconstruct()
    assert len(bpy.data.objects) == 0 and len(bpy.data.collections) == 0


def test_a_failed_run_reports_the_engines_reason_and_leaves_the_scene(empty_scene, capture):
    configure(empty_scene, capture, colour_mode="HSV", hsv_low=(90, 250, 250),
              hsv_high=(91, 255, 255))
    bpy.ops.mesh.primitive_cube_add()
    with pytest.raises(RuntimeError, match="no cable pixels in any frame"):
        bpy.ops.cable_recon.reconstruct()
    assert [o.name for o in bpy.data.objects] == ["Cube"]


def test_modal_run_cancels_at_once_and_leaves_the_scene(empty_scene, capture):
    from cable_reconstruction.addon.background_job import BackgroundJob, ModalRun
    from cable_reconstruction.addon.reconstruction import reconstruct_work, request_from_scene
    from cable_reconstruction.engine import Cancelled

    configure(empty_scene, capture)
    request = request_from_scene(empty_scene)
    started = threading.Event()

    def work(progress, cancel):
        started.set()
        return reconstruct_work(request)(progress, cancel)

    run = ModalRun(BackgroundJob(work, cancelled_errors=(Cancelled,)), title="Reconstructing")
    assert run.start().action == "RUNNING"
    started.wait(10)
    assert run.on_timer().action == "RUNNING"
    step = run.on_escape()
    assert step.action == "CANCELLED"
    assert run.job.wait(30)  # the worker reached a check and stopped
    assert run.job.poll().state == "CANCELLED"
    assert len(bpy.data.objects) == 0


#: Progress messages (in order) that show each stage is running (the carving's first ones are
#: the mask agreement's).
STAGE_MESSAGES = {"masks": ("masks",), "cameras": ("cameras",), "agreement": ("agreeing masks",),
                  "carving": ("masks agreed", "carving"), "graph": ("grow fronts",),
                  "topology": ("branches",), "fit": ("rod: iteration",), "curve": ("curve",)}


@pytest.mark.parametrize("stage", list(STAGE_MESSAGES))
def test_esc_in_any_stage_leaves_the_scene_as_it_was(empty_scene, capture, stage):
    from cable_reconstruction.addon.background_job import BackgroundJob, ModalRun
    from cable_reconstruction.addon.reconstruction import reconstruct_work, request_from_scene
    from cable_reconstruction.engine import Cancelled

    configure(empty_scene, capture)
    bpy.ops.mesh.primitive_cube_add()  # the user's own scene
    before = {kind: sorted(block.name for block in getattr(bpy.data, kind))
              for kind in ("objects", "curves", "cameras", "collections", "materials")}
    request = request_from_scene(empty_scene)
    waiting, reached, escaped = list(STAGE_MESSAGES[stage]), threading.Event(), threading.Event()

    def work(progress, cancel):
        def watched(fraction, message):
            progress(fraction, message)
            if waiting and waiting[0] in message:
                waiting.pop(0)
                if not waiting:  # hold the stage until Esc was pressed
                    reached.set()
                    escaped.wait(30)
        return reconstruct_work(request)(watched, cancel)

    run = ModalRun(BackgroundJob(work, cancelled_errors=(Cancelled,)), title="Reconstructing")
    run.start()
    assert reached.wait(120), f"the {stage} stage never showed"
    assert run.on_escape().action == "CANCELLED"
    escaped.set()
    assert run.job.wait(60)
    assert run.job.poll().state == "CANCELLED"
    assert {kind: sorted(block.name for block in getattr(bpy.data, kind))
            for kind in before} == before


def test_modal_run_reports_progress_and_failures():
    from cable_reconstruction.addon.background_job import BackgroundJob, ModalRun

    from engine import InputError

    gate, seen = threading.Event(), threading.Event()

    def work(progress, cancel):
        progress(0.25, "carving")
        seen.set()
        gate.wait(10)
        return "value"

    ticks = iter(range(100))
    run = ModalRun(BackgroundJob(work), title="Reconstructing", clock=lambda: next(ticks))
    run.start()
    seen.wait(10)
    step = run.on_timer()
    assert step.action == "RUNNING" and step.fraction == 0.25
    assert step.text.startswith("Reconstructing carving 25%") and "Esc" in step.text
    gate.set()
    run.job.wait(10)
    step = run.on_timer()
    assert (step.action, step.value) == ("FINISHED", "value")
    with pytest.raises(RuntimeError):
        run.on_timer()

    def bad_input(progress, cancel):
        raise InputError("frame 3 cannot be read")

    run = ModalRun(BackgroundJob(bad_input, expected_errors=(InputError,)))
    run.start()
    run.job.wait(10)
    assert run.on_timer().text == "frame 3 cannot be read"

    def bug(progress, cancel):
        raise KeyError("oops")

    status = BackgroundJob(bug).run_here()
    assert status.state == "FAILED" and status.error == "KeyError: 'oops'"


def test_batch_command_names_an_output_it_cannot_write_before_the_work(addon, capture,
                                                                      capsys):
    from cable_reconstruction.addon.batch_command import handle_command

    code = handle_command(["reconstruct", str(capture / "images"), "--cameras",
                           str(capture / "sparse"), "-o", "/sys/twist.blend", "-q"])
    assert code == 2
    assert capsys.readouterr().err.strip() == "error: cannot write in /sys: Permission denied"


def test_batch_command_writes_a_blend_that_reopens_with_the_curve(addon, capture, tmp_path,
                                                                  capsys, monkeypatch):
    from cable_reconstruction.addon.batch_command import handle_command

    bpy.ops.wm.read_homefile(use_empty=True)
    output = tmp_path / "twist.blend"
    monkeypatch.chdir(capture)  # paths relative to where the command runs
    code = handle_command(["reconstruct", "images", "--cameras", "sparse", "-o", str(output),
                           "--no-cameras", "-q"])
    monkeypatch.undo()
    assert code == 0, capsys.readouterr().err
    assert "control points" in capsys.readouterr().err
    bpy.ops.wm.read_homefile(use_empty=True)
    bpy.ops.wm.open_mainfile(filepath=str(output))
    obj = bpy.data.objects["twist"]
    assert obj.type == "CURVE" and obj.data.splines[0].type == "BEZIER"
    # stored absolute, so a flip after the file is reopened elsewhere finds them
    stored = json.loads(obj.cable_recon.arguments)
    assert stored["images"] == str((capture / "images").resolve())
    assert stored["cameras"] == str((capture / "sparse").resolve())
    assert not [o for o in bpy.data.objects if o.type == "CAMERA"]
    before = output.read_bytes()
    again = handle_command(["reconstruct", str(capture / "images"), "-o", str(output), "-q"])
    assert again == 2 and "--overwrite" in capsys.readouterr().err
    assert output.read_bytes() == before
    assert handle_command(["reconstruct", str(tmp_path / "nothing"), "-o",
                           str(tmp_path / "x.blend"), "-q"]) == 2
    assert "does not exist" in capsys.readouterr().err
    assert handle_command(["reconstruct"]) == 2


def test_each_cable_gets_a_material_in_its_colour(empty_scene, small_result):
    from dataclasses import replace

    from cable_reconstruction.addon.scene_objects import add_cable_materials, build_cable_curve

    collection = bpy.data.collections.new("pair")
    one = build_cable_curve(small_result, "one", collection)
    add_cable_materials(one, replace(small_result, colour=(0.8, 0.1, 0.1)), "one")
    assert len(one.data.materials) == 1  # no path colours: one material, the cable's
    red, blue = (0.8, 0.1, 0.1), (0.1, 0.2, 0.9)
    result = replace(small_result, paths=tuple(
        replace(path, colour=colour) for path, colour in zip(small_result.paths, (red, blue))))
    two = build_cable_curve(result, "two", collection)
    add_cable_materials(two, result, "two")
    assert [spline.material_index for spline in two.data.splines] == [0, 1]
    first, second = (material.diffuse_color[:3] for material in two.data.materials)
    assert first[0] > 5 * first[2] and second[2] > 5 * second[0]

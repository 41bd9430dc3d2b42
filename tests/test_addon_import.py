"""Import cable result: a result file becomes a bevelled curve (real bpy, add-on registered)."""

import json

import bpy
import numpy as np
import pytest
from bpy_extras.object_utils import world_to_camera_view
from mathutils import Vector

from engine import write_result


def spline_points(spline):
    coords = np.empty(len(spline.points) * 4, dtype=np.float32)
    spline.points.foreach_get("co", coords)
    radii = np.empty(len(spline.points), dtype=np.float32)
    spline.points.foreach_get("radius", radii)
    return coords.reshape(-1, 4)[:, :3], radii


def test_import_builds_one_bevelled_spline_per_path(empty_scene, small_result, tmp_path):
    path = write_result(small_result, tmp_path / "my_cable.json")
    assert bpy.ops.cable_recon.import_result(filepath=str(path)) == {"FINISHED"}

    obj = bpy.data.objects["my_cable"]
    assert obj.type == "CURVE" and obj.name in empty_scene.collection.all_objects
    assert bpy.context.view_layer.objects.active == obj and obj.select_get()
    curve = obj.data
    assert curve.dimensions == "3D"
    assert curve.bevel_mode == "ROUND" and curve.use_fill_caps
    assert curve.bevel_depth == pytest.approx(small_result.radius)
    assert len(curve.splines) == len(small_result.paths)
    for spline, path_in_file in zip(curve.splines, small_result.paths):
        coords, radii = spline_points(spline)
        np.testing.assert_allclose(coords, path_in_file.points, atol=1e-6)  # same points, in order
        assert spline.use_cyclic_u == path_in_file.closed
        expected = (np.ones(len(coords)) if path_in_file.radii is None
                    else path_in_file.radii / small_result.radius)
        np.testing.assert_allclose(radii, expected, rtol=1e-6)
    # The evaluated tube really is as thick as the cable: its mesh spans 2 r around the line.
    mesh = obj.evaluated_get(bpy.context.evaluated_depsgraph_get()).to_mesh()
    zs = np.array([v.co.z for v in mesh.vertices])
    line = small_result.paths[1].points
    tube_top = zs[np.abs(np.array([v.co.y for v in mesh.vertices])) < 0.02].max()
    assert tube_top == pytest.approx(line[:, 2].max() + small_result.paths[1].radii.max(), rel=0.05)


def test_import_is_undoable():
    assert "UNDO" in bpy.types.CABLE_RECON_OT_import_result.bl_options


def test_cameras_project_like_the_engine(empty_scene, small_result, tmp_path):
    path = write_result(small_result, tmp_path / "cable.json")
    bpy.ops.cable_recon.import_result(filepath=str(path))
    camera = small_result.cameras[0]  # pinhole: Blender cameras have no lens distortion
    obj = bpy.data.objects[camera.name]
    assert obj.type == "CAMERA" and obj.users_collection[0].name == "cable cameras"
    render = empty_scene.render
    render.resolution_x, render.resolution_y = camera.width, camera.height
    render.resolution_percentage = 100
    render.pixel_aspect_x = render.pixel_aspect_y = 1.0
    # Square pixels in Blender: compare with the mean focal length of the engine camera.
    fx, fy = camera.focal
    square = type(camera)(camera.name, camera.width, camera.height, "PINHOLE",
                          [fx, fx, *camera.principal_point], camera.R, camera.t)
    bpy.context.view_layer.update()
    for point in small_result.paths[0].points[::5]:
        ndc = world_to_camera_view(empty_scene, obj, Vector(point.tolist()))
        blender_pixel = np.array([ndc.x * camera.width, (1.0 - ndc.y) * camera.height])
        engine_pixel, depth = square.project(point)
        np.testing.assert_allclose(blender_pixel, engine_pixel, atol=1e-3)
        assert ndc.z == pytest.approx(depth, rel=1e-5)


def test_cameras_are_optional(empty_scene, small_result, tmp_path):
    path = write_result(small_result, tmp_path / "cable.json")
    bpy.ops.cable_recon.import_result(filepath=str(path), with_cameras=False)
    assert [o.type for o in bpy.data.objects] == ["CURVE"]


def test_a_malformed_file_is_reported_and_adds_nothing(empty_scene, tmp_path):
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"format": "cable_recon.result/1", "units": "m", "radius": 1,
                               "paths": []}))
    with pytest.raises(RuntimeError, match="paths is empty"):
        bpy.ops.cable_recon.import_result(filepath=str(bad))
    assert len(bpy.data.objects) == 0 and len(bpy.data.curves) == 0


def test_several_files_at_once(empty_scene, small_result, tmp_path):
    for name in ("a", "b"):
        write_result(small_result, tmp_path / f"{name}.json")
    bpy.ops.cable_recon.import_result(directory=str(tmp_path),
                                      files=[{"name": "a.json"}, {"name": "b.json"}])
    assert {o.name for o in bpy.data.objects if o.type == "CURVE"} == {"a", "b"}


def test_panel_and_menu_are_registered(addon):
    assert hasattr(bpy.types, "VIEW3D_PT_cable_recon")
    assert bpy.types.VIEW3D_PT_cable_recon.bl_category == "Cable"
    assert hasattr(bpy.types, "CABLE_RECON_FH_result")

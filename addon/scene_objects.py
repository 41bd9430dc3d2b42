"""Turning an engine :class:`Result` into Blender data: the bevelled cable curve and cameras.

Main thread only: nothing here may run from a worker thread.
"""

import bpy
import numpy as np
from mathutils import Matrix

__all__ = ["build_cable_curve", "build_cameras", "OPENCV_TO_BLENDER_CAMERA"]

#: Flips an OpenCV camera (looking along +z, y down) into Blender's (looking along -z, y up).
OPENCV_TO_BLENDER_CAMERA = Matrix(((1, 0, 0), (0, -1, 0), (0, 0, -1)))

BEVEL_RESOLUTION = 4


def build_cable_curve(result, name, collection):
    """Create a curve object holding every path of ``result`` as one spline each.

    The bevel is the cable: round profile of depth ``result.radius`` with filled caps; per-point
    radii (when the result has them) scale the bevel along the cable.

    Parameters
    ----------
    result : engine.Result
    name : str
        Name of the new object and its curve data.
    collection : bpy.types.Collection
        Where the object is linked.

    Returns
    -------
    bpy.types.Object
    """
    curve = bpy.data.curves.new(name, type="CURVE")
    curve.dimensions = "3D"
    curve.twist_mode = "MINIMUM"
    curve.bevel_mode = "ROUND"
    curve.bevel_depth = result.radius
    curve.bevel_resolution = BEVEL_RESOLUTION
    curve.use_fill_caps = True
    for path in result.paths:
        spline = curve.splines.new("POLY")
        spline.points.add(len(path.points) - 1)
        homogeneous = np.column_stack([path.points, np.ones(len(path.points))])
        spline.points.foreach_set("co", homogeneous.astype(np.float32).ravel())
        if path.radii is not None:
            spline.points.foreach_set("radius", (path.radii / result.radius).astype(np.float32))
        spline.use_cyclic_u = path.closed
    obj = bpy.data.objects.new(name, curve)
    collection.objects.link(obj)
    return obj


def build_cameras(cameras, collection, *, name_prefix=""):
    """Create one Blender camera object per engine camera, matching its projection.

    Focal length and principal point become lens and shift on a 36 mm sensor fitted to the
    image's larger side; lens distortion is not representable in a Blender camera and is left
    out.

    Parameters
    ----------
    cameras : sequence of engine.Camera
    collection : bpy.types.Collection
    name_prefix : str, optional

    Returns
    -------
    list of bpy.types.Object
    """
    objects = []
    for camera in cameras:
        data = bpy.data.cameras.new(f"{name_prefix}{camera.name}")
        largest = max(camera.width, camera.height)
        data.sensor_fit = "HORIZONTAL" if camera.width >= camera.height else "VERTICAL"
        data.sensor_width = data.sensor_height = 36.0
        fx, _ = camera.focal
        cx, cy = camera.principal_point
        data.lens = fx * 36.0 / largest
        data.shift_x = (camera.width / 2.0 - cx) / largest
        data.shift_y = (cy - camera.height / 2.0) / largest
        obj = bpy.data.objects.new(f"{name_prefix}{camera.name}", data)
        rotation = Matrix(camera.R.T.tolist()) @ OPENCV_TO_BLENDER_CAMERA
        obj.matrix_world = Matrix.Translation(camera.center.tolist()) @ rotation.to_4x4()
        obj["cable_recon_image"] = camera.name
        obj["cable_recon_resolution"] = (camera.width, camera.height)
        collection.objects.link(obj)
        objects.append(obj)
    return objects

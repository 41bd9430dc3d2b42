"""Turning an engine :class:`Result` into Blender data: the bevelled cable curve and cameras.

Main thread only: nothing here may run from a worker thread.
"""

import bpy
import numpy as np
from mathutils import Matrix

__all__ = ["build_cable_curve", "build_bezier_curve", "build_cameras", "cable_material",
           "add_cable_materials",
           "remove_collection", "OPENCV_TO_BLENDER_CAMERA"]

#: Flips an OpenCV camera (looking along +z, y down) into Blender's (looking along -z, y up).
OPENCV_TO_BLENDER_CAMERA = Matrix(((1, 0, 0), (0, -1, 0), (0, 0, -1)))

BEVEL_RESOLUTION = 4
#: Segments per Bézier piece when Blender evaluates the curve (pieces are long: few knots).
BEZIER_RESOLUTION = 24


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
    curve = _bevelled_curve(name, result.radius)
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


def _bevelled_curve(name, radius):
    curve = bpy.data.curves.new(name, type="CURVE")
    curve.dimensions = "3D"
    curve.twist_mode = "MINIMUM"
    curve.bevel_mode = "ROUND"
    curve.bevel_depth = radius
    curve.bevel_resolution = BEVEL_RESOLUTION
    curve.use_fill_caps = True
    return curve


def build_bezier_curve(result, curves, name, collection):
    """Create a curve object of Bézier splines (one per path) with the cable as its bevel.

    Parameters
    ----------
    result : engine.Result
        Gives the radius (the bevel's depth).
    curves : sequence of engine.stages.bezier.BezierCurve
        One per path, from :func:`engine.stages.bezier.fit_result_curves`.
    name : str
    collection : bpy.types.Collection

    Returns
    -------
    bpy.types.Object
    """
    curve = _bevelled_curve(name, result.radius)
    curve.resolution_u = BEZIER_RESOLUTION
    for bezier in curves:
        spline = curve.splines.new("BEZIER")
        points = spline.bezier_points
        points.add(len(bezier.knots) - 1)
        for point in points:  # aligned handles keep the curve smooth while it is edited
            point.handle_left_type = point.handle_right_type = "ALIGNED"
        for attribute, values in (("co", bezier.knots), ("handle_left", bezier.left),
                                  ("handle_right", bezier.right)):
            points.foreach_set(attribute, np.asarray(values, dtype=np.float32).ravel())
        spline.use_cyclic_u = bezier.closed
        spline.resolution_u = BEZIER_RESOLUTION
    obj = bpy.data.objects.new(name, curve)
    collection.objects.link(obj)
    return obj


def cable_material(name, colour):
    """A material in the cable's colour (sRGB, 0 to 1), or a neutral grey when unknown."""
    material = bpy.data.materials.new(name)
    srgb = colour if colour is not None else (0.5, 0.5, 0.5)
    linear = [c / 12.92 if c <= 0.04045 else ((c + 0.055) / 1.055) ** 2.4 for c in srgb]
    material.diffuse_color = (*linear, 1.0)
    if material.node_tree is None and hasattr(material, "use_nodes"):
        material.use_nodes = True
    nodes = material.node_tree.nodes if material.node_tree else ()
    for node in nodes:
        if node.type == "BSDF_PRINCIPLED":
            node.inputs["Base Color"].default_value = (*linear, 1.0)
            node.inputs["Roughness"].default_value = 0.45
    return material


def add_cable_materials(obj, result, name):
    """Give a curve of ``result`` (one spline per path, in order) its cable materials: one
    per path in that path's colour when the paths have colours (several cables), else one in
    the cable's colour."""
    colours = [path.colour for path in result.paths]
    if len(colours) < 2 or all(colour is None for colour in colours):
        obj.data.materials.append(cable_material(f"{name} cable", result.colour))
        return
    for number, (spline, colour) in enumerate(zip(obj.data.splines, colours)):
        obj.data.materials.append(cable_material(
            f"{name} cable {number + 1}", colour if colour is not None else result.colour))
        spline.material_index = number


def remove_collection(collection):
    """Delete a collection with its objects, their data and materials (unless used elsewhere)."""
    stores = {"CURVE": bpy.data.curves, "CAMERA": bpy.data.cameras, "MESH": bpy.data.meshes}
    for child in list(collection.children):
        remove_collection(child)
    for obj in list(collection.objects):
        data, store = obj.data, stores.get(obj.type)
        materials = [m for m in getattr(data, "materials", ()) if m is not None]
        images = [b.image for b in getattr(data, "background_images", ()) if b.image]
        bpy.data.objects.remove(obj)
        if store is not None and data.users == 0:
            store.remove(data)
        for material in materials:
            if material.users == 0:
                bpy.data.materials.remove(material)
        for image in images:
            if image.users == 0:
                bpy.data.images.remove(image)
    bpy.data.collections.remove(collection)


def build_cameras(cameras, collection, *, name_prefix="", frames=None):
    """Create one Blender camera object per engine camera, matching its projection.

    Focal length and principal point become lens and shift on a 36 mm sensor fitted to the
    image's larger side; lens distortion is not representable in a Blender camera and is left
    out.

    Parameters
    ----------
    cameras : sequence of engine.Camera
    collection : bpy.types.Collection
    name_prefix : str, optional
    frames : mapping of str to path, optional
        Frame file per camera name: shown as the camera's background image.

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
        frame = (frames or {}).get(camera.name)
        if frame is not None:
            background = data.background_images.new()
            background.image = bpy.data.images.load(str(frame), check_existing=True)
            background.alpha = 0.8
            data.show_background_images = True
        collection.objects.link(obj)
        objects.append(obj)
    return objects

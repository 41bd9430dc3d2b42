"""Render a realistic sample sequence with Blender's Cycles (CPU): `make sample`.

A seeded table layout, or a hard one (a heap of crossings close together, each view framing part
of it: `--layout hard`; engine.synthetic.layouts), is built in Blender as a bevelled curve on a
textured table (the engine's table texture, so structure-from-motion has features), lit by a
sun and a sky, and rendered from hand-held-like cameras. Written next to the JPEG frames: the
exact cable masks (ray-cast by the engine from the same geometry), a COLMAP text model of the
true cameras, the ground truth and the look (look.json; clutter.json: where the clutter
stands). Slow: never run by CI; tests call it only at tiny sizes. A 640x480 frame at 16 samples
with denoising takes 8.7 s on one thread and 4.4 s on two (`--threads`) on this otherwise
quiet two-core machine, 10-38 s on one thread while other jobs share the cores (`--threads 1`
leaves one core to them); 960x720 at 32 samples, 15-60 s.

The scene follows a seeded *look* (engine.synthetic.looks): the cable's colour, stripes or two
tones and gloss; the table texture (engine.synthetic.textures at 2048 pixels, as the fast
renderer draws it: some kinds change with the texture's size);
a soft or hard, tinted, possibly uneven light; a cable lifted above its shadow; clutter on the
table; and camera effects (exposure in Blender; vignetting, blur, noise and the JPEG quality
applied to each written frame). The default look is the original sample's: a red glossy cable
on light oak under a soft sun (``make sample`` reproduces samples/sequence).

Clutter never hides the cable: every object is placed so its projection, in every view, keeps
clear of the cable's exact mask (checked again before anything is rendered), so the ray-cast
masks stay exact.

    python tools/render_sample.py [-o samples/sequence] [--views 24] [--size 960x720]
                                  [--layout table|hard] [--crossings 3] [--seed 3]
                                  [--radius 0.004] [--extent M]
                                  [--samples 32] [--look FAMILY] [--look-seed N]
                                  [--threads N] [--texture-size N] [--overwrite]
                                  [--silhouette]

The held-out captures in samples/looks were made with, e.g.:

    python tools/render_sample.py -o samples/looks/air-1002 --look air --look-seed 1002
        --seed 1002 --crossings 3 --extent 0.42 --views 20 --size 640x480 --samples 16
        --threads 1
"""

import argparse
import dataclasses
import json
import math
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from blender_package import ROOT, load_addon_package  # noqa: E402
from sample_preview import write_preview  # noqa: E402

#: Colour (sRGB) of clutter in a --silhouette render: tells clutter from cable (white).
SILHOUETTE_CLUTTER = (0.0, 1.0, 0.0)
#: Pixels of clear space kept between a clutter object's outline and the cable's mask.
CLUTTER_MARGIN_PX = 2


def srgb_to_linear(colour):
    """Linear RGBA (Blender's colour space) of an sRGB 0-255 colour."""
    c = np.asarray(colour, dtype=float) / 255.0
    linear = np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)
    return (*linear.tolist(), 1.0)


def lifted(truth, look):
    """The truth raised by ``look.lift`` radii (the fast renderer's convention: z += lift r)."""
    from cable_reconstruction.engine.io.ground_truth import GroundTruth

    if not look.lift:
        return truth
    centreline = truth.centreline + np.array([0.0, 0.0, look.lift * truth.radius])
    return GroundTruth(centreline, truth.radius, truth.crossings, truth.closed, truth.cameras,
                       truth.kind, truth.up, truth.breaks)


# --- clutter ------------------------------------------------------------------------------------

@dataclasses.dataclass(frozen=True)
class PlacedClutter:
    """A clutter object where it stands: footprint centre (x, y), in world units."""

    shape: str
    colour: tuple
    x: float
    y: float
    size: float
    height: float
    angle: float

    def outline(self, segments=24):
        """3D points whose convex hull contains the object (a cylinder's polygon circumscribes
        it, so the hull of any view's projection covers the object)."""
        if self.shape == "box":
            half = 0.5 * self.size
            corners = np.array([[-half, -half], [half, -half], [half, half], [-half, half]])
            a = math.radians(self.angle)
            rotation = np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])
            ring = corners @ rotation.T
        else:
            radius = 0.5 * self.size / math.cos(math.pi / segments)
            theta = np.linspace(0.0, 2 * math.pi, segments, endpoint=False)
            ring = radius * np.column_stack([np.cos(theta), np.sin(theta)])
        ring = ring + [self.x, self.y]
        return np.vstack([np.column_stack([ring, np.zeros(len(ring))]),
                          np.column_stack([ring, np.full(len(ring), self.height)])])

    def footprint_reach(self):
        """Radius of the footprint's bounding circle."""
        return 0.5 * self.size * (math.sqrt(2.0) if self.shape == "box" else 1.0)


def clutter_silhouette(placed, camera):
    """Pixels (H, W, bool) the object may cover in ``camera`` (its projected convex hull)."""
    import cv2

    image = np.zeros((camera.height, camera.width), dtype=np.uint8)
    points = placed.outline()
    depth = camera.world_to_camera(points)[:, 2]
    if np.any(depth <= 0):  # partly behind the camera: treat as covering everything
        image[:] = 1
        return image.astype(bool)
    pixels, _ = camera.project(points)  # COLMAP: pixel (i, j) spans i..i+1, j..j+1
    hull = cv2.convexHull(np.round((pixels - 0.5) * 16).astype(np.int32))
    cv2.fillConvexPoly(image, hull, 1, lineType=cv2.LINE_8, shift=4)
    return image.astype(bool)


def clear_of_cable(placed, cameras, masks, margin=CLUTTER_MARGIN_PX):
    """Whether ``placed`` keeps ``margin`` pixels clear of the cable's mask in every view; and
    in how many views it shows."""
    import cv2

    kernel = np.ones((2 * margin + 1, 2 * margin + 1), np.uint8)
    shown = 0
    for camera, mask in zip(cameras, masks):
        covered = clutter_silhouette(placed, camera)
        if (cv2.dilate(covered.astype(np.uint8), kernel).astype(bool) & mask).any():
            return False, 0
        shown += bool(covered.any())
    return True, shown


def place_clutter(truth, cameras, masks, look, *, tries=400):
    """Stand the look's clutter objects on the table near the cable, clear of it in every view.

    Seeded by the look. An object is put where its footprint keeps clear of the cable's and of
    the other objects' footprints and, in every view, its projected outline keeps
    :data:`CLUTTER_MARGIN_PX` pixels clear of the cable's exact mask (so it can never hide the
    cable); candidates seen in more views are preferred. An object that finds no such place is
    left out (with a warning).

    Returns
    -------
    list of PlacedClutter
    """
    if not look.clutter:
        return []
    rng = np.random.default_rng([look.seed, len(look.clutter), 8803])
    r = truth.radius
    flat = truth.centreline[:, :2]
    low, high = flat.min(axis=0), flat.max(axis=0)
    pad = 0.12 * float((high - low).max())
    placed = []
    for index, obj in enumerate(look.clutter):
        best, best_shown = None, 0
        for _ in range(tries):
            x, y = rng.uniform(low - pad, high + pad)
            candidate = PlacedClutter(obj.shape, tuple(obj.colour), float(x), float(y),
                                      obj.size * r, obj.height * r, obj.angle)
            reach = candidate.footprint_reach()
            if np.hypot(*(flat - [x, y]).T).min() < reach + 3 * r:
                continue
            if any(math.hypot(x - o.x, y - o.y) < reach + o.footprint_reach() + 2 * r
                   for o in placed):
                continue
            clear, shown = clear_of_cable(candidate, cameras, masks)
            if clear and shown > best_shown:
                best, best_shown = candidate, shown
                if shown >= 0.75 * len(cameras):
                    break
        if best is None:
            print(f"warning: clutter object {index} ({obj.shape}) found no place clear of the "
                  "cable in every view; left out", file=sys.stderr)
            continue
        placed.append(best)
    return placed


# --- camera effects -----------------------------------------------------------------------------

def camera_effects(image_bgr, look, seed):
    """Vignetting, optical blur and sensor noise of ``look`` on a rendered frame (uint8 BGR).

    Exposure is Blender's (the linear image is scaled before the view transform); the JPEG
    quality is applied when the frame is written.
    """
    import cv2

    height, width = image_bgr.shape[:2]
    image = image_bgr.astype(np.float32) / 255.0
    if look.vignetting:
        linear = np.where(image <= 0.04045, image / 12.92, ((image + 0.055) / 1.055) ** 2.4)
        rows, cols = np.mgrid[0:height, 0:width].astype(np.float32)
        reach = np.hypot((cols - 0.5 * (width - 1)) / (0.5 * width),
                         (rows - 0.5 * (height - 1)) / (0.5 * height)) / math.sqrt(2.0)
        linear *= (1.0 - look.vignetting * reach ** 2)[..., None]
        image = np.where(linear <= 0.0031308, 12.92 * linear,
                         1.055 * np.maximum(linear, 0) ** (1 / 2.4) - 0.055)
    image *= 255.0
    if look.blur > 0:
        image = cv2.GaussianBlur(image, (0, 0), look.blur)
    if look.noise > 0:
        image += np.random.default_rng([look.seed, seed, 77]).normal(
            0.0, look.noise, image.shape).astype(np.float32)
    return np.clip(np.round(image), 0, 255).astype(np.uint8)


# --- the Blender scene --------------------------------------------------------------------------

def _new_material(bpy, name):
    material = bpy.data.materials.new(name)
    material.use_nodes = True
    return material


def _cable_material(bpy, look, truth):
    """Plastic of the look's colour and gloss; two-tone or striped via the curve's UV map."""
    plastic = _new_material(bpy, "cable")
    tree = plastic.node_tree
    bsdf = tree.nodes["Principled BSDF"]
    if look.family == "default":  # the original sample, exactly
        bsdf.inputs["Base Color"].default_value = (0.62, 0.03, 0.02, 1.0)
        bsdf.inputs["Roughness"].default_value = 0.22
        return plastic
    bsdf.inputs["Base Color"].default_value = srgb_to_linear(look.cable_colour)
    bsdf.inputs["Roughness"].default_value = 0.55 - 0.45 * look.gloss
    bsdf.inputs["Specular IOR Level"].default_value = 0.2 + 0.6 * look.gloss
    if look.stripe_colour is None:
        return plastic
    # The curve's UV map: U runs 0..1 along the spline (by point index; the layouts are
    # sampled evenly), V 0..1 around the cross-section.
    uv = tree.nodes.new("ShaderNodeUVMap")
    uv.uv_map = "UVMap"
    split = tree.nodes.new("ShaderNodeSeparateXYZ")
    tree.links.new(uv.outputs["UV"], split.inputs[0])
    bands = tree.nodes.new("ShaderNodeMath")
    if look.stripe_period > 0:  # bands across the cable: one band + one gap per period
        cable_length = truth.length
        repeats = cable_length / (look.stripe_period * truth.radius)
        scale = tree.nodes.new("ShaderNodeMath")
        scale.operation = "MULTIPLY"
        scale.inputs[1].default_value = repeats
        tree.links.new(split.outputs["X"], scale.inputs[0])
        fraction = tree.nodes.new("ShaderNodeMath")
        fraction.operation = "FRACT"
        tree.links.new(scale.outputs[0], fraction.inputs[0])
        source = fraction.outputs[0]
    else:  # two tones: the two halves of the cross-section
        source = split.outputs["Y"]
    bands.operation = "LESS_THAN"
    bands.inputs[1].default_value = 0.5
    tree.links.new(source, bands.inputs[0])
    mix = tree.nodes.new("ShaderNodeMix")
    mix.data_type = "RGBA"
    mix.inputs["A"].default_value = srgb_to_linear(look.cable_colour)
    mix.inputs["B"].default_value = srgb_to_linear(look.stripe_colour)
    tree.links.new(bands.outputs[0], mix.inputs["Factor"])
    tree.links.new(mix.outputs["Result"], bsdf.inputs["Base Color"])
    return plastic


def _lights(bpy, scene, look, truth):
    """Sun, sky and (for an uneven light) an area light off to one side of the cable."""
    from mathutils import Vector

    sun_data = bpy.data.lights.new("sun", type="SUN")
    sun = bpy.data.objects.new("sun", sun_data)
    scene.collection.objects.link(sun)
    world = bpy.data.worlds.new("sky")
    world.use_nodes = True
    background = world.node_tree.nodes["Background"]
    background.inputs["Color"].default_value = (0.45, 0.47, 0.5, 1.0)
    scene.world = world
    if look.family == "default":  # the original sample, exactly
        sun_data.energy = 3.5
        sun_data.angle = 0.12
        sun.rotation_euler = (0.6, 0.15, 0.8)
        background.inputs["Strength"].default_value = 0.9
        return
    direction = Vector(look.light_direction.tolist())
    sun.rotation_euler = direction.to_track_quat("Z", "Y").to_euler()
    sun_data.color = tuple(float(c) for c in look.light_tint)
    # A low sun lights the table less: the camera's exposure makes up for some of it.
    compensation = (math.sin(math.radians(55.0))
                    / max(math.sin(math.radians(look.light_elevation)), 0.1)) ** 0.5
    if look.light == "soft":
        sun_data.angle = 0.35
        sky = 0.9 * look.ambient / 0.35
    else:
        sun_data.angle = 0.01
        sky = 0.6 * look.ambient / 0.35
    sun_data.energy = 3.5 * (1.0 - look.ambient) / 0.65 * compensation
    background.inputs["Strength"].default_value = sky
    if look.uneven > 0.01:
        flat = truth.centreline[:, :2]
        centre = 0.5 * (flat.min(axis=0) + flat.max(axis=0))
        extent = float(np.ptp(flat, axis=0).max())
        azimuth = float(np.random.default_rng([look.seed, 5107]).uniform(0, 2 * math.pi))
        height = 0.6 * extent
        position = Vector((centre[0] + 0.8 * extent * math.cos(azimuth),
                           centre[1] + 0.8 * extent * math.sin(azimuth), height))
        distance = (position - Vector((centre[0], centre[1], 0.0))).length
        # Irradiance at the cable's centre ~ uneven x that of the sun and sky there.
        ambient_irradiance = math.pi * sky * 0.47
        sun_irradiance = sun_data.energy * math.sin(math.radians(look.light_elevation))
        wanted = look.uneven * (sun_irradiance + ambient_irradiance)
        area_data = bpy.data.lights.new("uneven", type="AREA")
        area_data.size = 0.3 * extent
        area_data.color = sun_data.color
        area_data.energy = wanted * math.pi * distance ** 2 / (height / distance)
        area = bpy.data.objects.new("uneven", area_data)
        area.location = position
        aim = position - Vector((centre[0], centre[1], 0.0))
        area.rotation_euler = aim.to_track_quat("Z", "Y").to_euler()
        scene.collection.objects.link(area)


def _clutter_objects(bpy, scene, placed):
    for k, obj in enumerate(placed):
        location = (obj.x, obj.y, 0.5 * obj.height)
        if obj.shape == "box":
            bpy.ops.mesh.primitive_cube_add(size=1.0, location=location,
                                            rotation=(0.0, 0.0, math.radians(obj.angle)))
            item = bpy.context.active_object
            item.scale = (obj.size, obj.size, obj.height)
        else:
            bpy.ops.mesh.primitive_cylinder_add(vertices=48, radius=0.5 * obj.size,
                                                depth=obj.height, location=location)
            item = bpy.context.active_object
        item.name = f"clutter{k}"
        material = _new_material(bpy, f"clutter{k}")
        bsdf = material.node_tree.nodes["Principled BSDF"]
        bsdf.inputs["Base Color"].default_value = srgb_to_linear(obj.colour)
        bsdf.inputs["Roughness"].default_value = 0.75
        item.data.materials.append(material)


def build_scene(bpy, package, truth, texture_path, samples, look, placed=(), threads=0):
    """Table, cable, clutter, light and render settings in a fresh empty scene."""
    from cable_reconstruction.addon.scene_objects import build_cable_curve
    from cable_reconstruction.engine import CablePath, Result
    from cable_reconstruction.engine.synthetic.render import table_square

    bpy.ops.wm.read_homefile(use_empty=True)
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = samples
    scene.cycles.use_denoising = True
    scene.cycles.seed = 0
    scene.render.use_persistent_data = True  # only the camera changes between frames
    if threads:
        scene.render.threads_mode = "FIXED"
        scene.render.threads = threads
    scene.render.image_settings.file_format = "JPEG"
    scene.render.image_settings.quality = 90
    scene.render.film_transparent = False
    scene.view_settings.view_transform = "Standard"
    scene.view_settings.exposure = -0.5 + (math.log2(look.exposure)
                                           if look.family != "default" else 0.0)

    # Table: a square plane textured with the look's table texture.
    centre, side = table_square(truth)
    bpy.ops.mesh.primitive_plane_add(size=side, location=(centre[0], centre[1], 0.0))
    table = bpy.context.active_object
    table.name = "table"
    material = _new_material(bpy, "table")
    nodes = material.node_tree.nodes
    principled = nodes["Principled BSDF"]
    image_node = nodes.new("ShaderNodeTexImage")
    image_node.image = bpy.data.images.load(str(texture_path))
    material.node_tree.links.new(image_node.outputs["Color"], principled.inputs["Base Color"])
    principled.inputs["Roughness"].default_value = 0.55
    table.data.materials.append(material)

    # Cable: the add-on's own curve builder, smoother bevel.
    result = Result(radius=truth.radius, paths=(CablePath(truth.centreline, closed=truth.closed),))
    cable = build_cable_curve(result, "cable", scene.collection)
    cable.data.bevel_resolution = 6
    cable.data.materials.append(_cable_material(bpy, look, truth))

    _clutter_objects(bpy, scene, placed)
    _lights(bpy, scene, look, truth)
    return scene


def flatten_to_silhouette(bpy, scene):
    """White unlit cable on black, clutter pure green, no pixel filter: a pixel's value is the
    cable's coverage."""
    cable = bpy.data.materials["cable"].node_tree
    emission = cable.nodes.new("ShaderNodeEmission")
    cable.links.new(emission.outputs[0], cable.nodes["Material Output"].inputs["Surface"])
    table = bpy.data.materials["table"].node_tree
    for link in list(table.links):
        table.links.remove(link)
    table.nodes["Principled BSDF"].inputs["Base Color"].default_value = (0, 0, 0, 1)
    table.links.new(table.nodes["Principled BSDF"].outputs[0],
                    table.nodes["Material Output"].inputs["Surface"])
    for material in bpy.data.materials:
        if material.name.startswith("clutter"):
            tree = material.node_tree
            green = tree.nodes.new("ShaderNodeEmission")
            green.inputs["Color"].default_value = (*SILHOUETTE_CLUTTER, 1.0)
            tree.links.new(green.outputs[0], tree.nodes["Material Output"].inputs["Surface"])
    scene.world.node_tree.nodes["Background"].inputs["Strength"].default_value = 0.0
    for light in bpy.data.lights:
        light.energy = 0.0
    scene.view_settings.exposure = 0.0
    scene.cycles.filter_width = 0.01
    scene.cycles.use_denoising = False
    scene.render.image_settings.file_format = "PNG"


def choose_look(family, look_seed, layout_seed):
    """The look to render: the original sample's (seeded like the layout) or a family's."""
    from cable_reconstruction.engine.synthetic.looks import (DEFAULT_LOOK, sample_look,
                                                             with_camera_effects_off)

    if family == "default":  # Cycles adds no camera effects to it; Blender writes JPEG 90
        return dataclasses.replace(with_camera_effects_off(DEFAULT_LOOK), seed=layout_seed,
                                   jpeg_quality=90)
    return sample_look(family, layout_seed if look_seed is None else look_seed)


def parse_args(argv=None):
    from cable_reconstruction.engine.synthetic.looks import LOOK_FAMILIES

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("-o", "--output", default=str(ROOT / "samples" / "sequence"))
    parser.add_argument("--views", type=int, default=24)
    parser.add_argument("--size", default="960x720")
    parser.add_argument("--layout", default="table", choices=("table", "hard"),
                        help="table: a cable with --crossings crossings far apart, every view "
                             "framing it; hard: a heap of 12-20 crossings close together "
                             "(engine.synthetic.layouts.hard_layout; --crossings ignored), "
                             "each view framing part of it")
    parser.add_argument("--crossings", type=int, default=3)
    parser.add_argument("--seed", type=int, default=3, help="seeds the layout and the cameras")
    parser.add_argument("--radius", type=float, default=0.004, help="metres")
    parser.add_argument("--extent", type=float, default=None,
                        help="metres across the table area the cable lies in (default: the "
                             "layouts' default for the radius and crossings); smaller makes "
                             "the cable thicker in the images")
    parser.add_argument("--samples", type=int, default=32, help="Cycles samples per pixel")
    parser.add_argument("--look", default="default", choices=("default",) + LOOK_FAMILIES,
                        help="look family (engine.synthetic.looks); 'default' is the original "
                             "red glossy cable on light oak under a soft sun")
    parser.add_argument("--look-seed", type=int, default=None,
                        help="seeds the look (default: --seed), e.g. one of HELD_OUT_SEEDS")
    parser.add_argument("--threads", type=int, default=0,
                        help="Cycles render threads (0: every core); 1 leaves a core free")
    parser.add_argument("--texture-size", type=int, default=None,
                        help="pixels per side of the table texture (default: 2048 for a look, "
                             "as the fast renderer, so both draw the same table; 4096 for the "
                             "default look, as samples/sequence)")
    parser.add_argument("--overwrite", action="store_true")
    parser.add_argument("--silhouette", action="store_true",
                        help="render the bare silhouette (unlit white cable, green clutter, "
                             "black table, PNG): for checking the exact masks against "
                             "Blender's own geometry")
    return parser.parse_args(argv)


def main():
    package = load_addon_package()
    args = parse_args()
    width, height = (int(v) for v in args.size.lower().split("x"))
    output = Path(args.output)
    if (output / "ground_truth.json").exists() and not args.overwrite:
        sys.exit(f"{output} already holds a sample (pass --overwrite to replace it)")

    import bpy
    import cv2

    from cable_reconstruction.addon.scene_objects import build_cameras
    from cable_reconstruction.engine import write_colmap_model
    from cable_reconstruction.engine.io.ground_truth import write_ground_truth
    from cable_reconstruction.engine.synthetic.cameras import cable_pixel_width, handheld_cameras
    from cable_reconstruction.engine.synthetic.layouts import hard_layout, table_layout
    from cable_reconstruction.engine.synthetic.scene import HARD_FRAMING
    from cable_reconstruction.engine.synthetic.render import render_masks
    from cable_reconstruction.engine.synthetic.textures import table_texture

    look = choose_look(args.look, args.look_seed, args.seed)
    if args.layout == "hard":  # a heap, each view framing part of it (as `bench topology`)
        layout = hard_layout(seed=args.seed, radius=args.radius, extent=args.extent)
    else:
        layout = table_layout(args.crossings, seed=args.seed, radius=args.radius,
                              extent=args.extent)
    truth = lifted(layout, look)
    cameras = handheld_cameras(truth, views=args.views, width=width, height=height,
                               elevations=(45.0, 75.0), name_format="{:03d}.jpg", seed=args.seed,
                               framing=HARD_FRAMING if args.layout == "hard" else 1.0)
    truth = truth.with_cameras(cameras)
    masks = list(render_masks(truth, cameras))
    placed = place_clutter(truth, cameras, masks, look)
    for obj in placed:  # never trust a placement: masks are exact only if nothing hides the cable
        assert clear_of_cable(obj, cameras, masks)[0], f"clutter hides the cable: {obj}"
    print(f"look {look.family} {look.seed}: {len(truth.crossings)} crossings, cable "
          f"{truth.length:.2f} m, thinnest {cable_pixel_width(truth, cameras):.1f} px, "
          f"{len(placed)} clutter objects", file=sys.stderr)

    post = look.family != "default" and not args.silhouette
    with tempfile.TemporaryDirectory() as scratch:
        texture_path = Path(scratch) / "table.png"
        texture_size = args.texture_size or (4096 if look.family == "default" else 2048)
        cv2.imwrite(str(texture_path), cv2.cvtColor(table_texture(look, texture_size),
                                                    cv2.COLOR_RGB2BGR))
        scene = build_scene(bpy, package, truth, texture_path, args.samples, look, placed,
                            threads=args.threads)
        if args.silhouette:
            flatten_to_silhouette(bpy, scene)
        elif post:  # lossless render; the camera effects and JPEG come after
            scene.render.image_settings.file_format = "PNG"
            scene.render.image_settings.color_depth = "8"
            scene.render.image_settings.compression = 0
        rig = bpy.data.collections.new("cameras")
        scene.collection.children.link(rig)
        camera_objects = build_cameras(cameras, rig)
        scene.render.resolution_x, scene.render.resolution_y = width, height
        scene.render.resolution_percentage = 100
        if output.exists() and args.overwrite:
            shutil.rmtree(output)
        (output / "images").mkdir(parents=True)
        (output / "masks").mkdir()
        for k, (camera, obj) in enumerate(zip(cameras, camera_objects)):
            started = time.time()
            scene.camera = obj
            name = Path(camera.name).with_suffix(".png").name if args.silhouette else camera.name
            frame = Path(scratch) / "frame.png" if post else output / "images" / name
            scene.render.filepath = str(frame)
            bpy.ops.render.render(write_still=True)
            if post:
                image = camera_effects(cv2.imread(str(frame)), look, k)
                cv2.imwrite(str(output / "images" / name), image,
                            [cv2.IMWRITE_JPEG_QUALITY, int(look.jpeg_quality)])
            print(f"[{k + 1}/{len(cameras)}] {camera.name} {time.time() - started:.1f} s",
                  file=sys.stderr, flush=True)
    for camera, mask in zip(cameras, masks):
        cv2.imwrite(str(output / "masks" / (Path(camera.name).stem + ".png")),
                    mask.astype(np.uint8) * 255)
    write_colmap_model(output / "sparse", cameras)
    write_ground_truth(truth, output / "ground_truth.json")
    (output / "look.json").write_text(json.dumps(dataclasses.asdict(look), indent=1) + "\n",
                                      encoding="utf-8")
    if placed:
        (output / "clutter.json").write_text(json.dumps(
            [dataclasses.asdict(obj) for obj in placed], indent=1) + "\n", encoding="utf-8")
    print(write_preview(output))


if __name__ == "__main__":
    main()

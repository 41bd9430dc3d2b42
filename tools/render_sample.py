"""Render a realistic sample sequence with Blender's Cycles (CPU): `make sample`.

A seeded table layout (engine.synthetic_layouts) is built in Blender as a glossy bevelled
curve on a textured table (the engine's table texture, so structure-from-motion has features),
lit by a soft sun and a grey sky, and rendered from hand-held-like cameras. Written next to the
JPEG frames: the exact cable masks (ray-cast by the engine from the same geometry), a COLMAP
text model of the true cameras and the ground truth. Slow (15-60 s a frame at 960x720 on two
cores): never run by CI; tests call it only at tiny sizes.

    python tools/render_sample.py [-o samples/sequence] [--views 24] [--size 960x720]
                                  [--crossings 3] [--seed 3] [--samples 32] [--overwrite]
"""

import argparse
import shutil
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from blender_package import ROOT, load_addon_package  # noqa: E402
from sample_preview import write_preview  # noqa: E402


def build_scene(bpy, package, truth, texture_path, samples):
    """Table, cable, light and render settings in a fresh empty scene."""
    from cable_reconstruction.addon.scene_objects import build_cable_curve
    from cable_reconstruction.engine import CablePath, Result
    from cable_reconstruction.engine.synthetic_render import table_square

    bpy.ops.wm.read_homefile(use_empty=True)
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = samples
    scene.cycles.use_denoising = True
    scene.cycles.seed = 0
    scene.render.image_settings.file_format = "JPEG"
    scene.render.image_settings.quality = 90
    scene.render.film_transparent = False
    scene.view_settings.view_transform = "Standard"
    scene.view_settings.exposure = -0.5

    # Table: a square plane textured with the engine's table texture.
    centre, side = table_square(truth)
    bpy.ops.mesh.primitive_plane_add(size=side, location=(centre[0], centre[1], 0.0))
    table = bpy.context.active_object
    table.name = "table"
    material = bpy.data.materials.new("table")
    material.use_nodes = True
    nodes = material.node_tree.nodes
    principled = nodes["Principled BSDF"]
    image_node = nodes.new("ShaderNodeTexImage")
    image_node.image = bpy.data.images.load(str(texture_path))
    material.node_tree.links.new(image_node.outputs["Color"], principled.inputs["Base Color"])
    principled.inputs["Roughness"].default_value = 0.55
    table.data.materials.append(material)

    # Cable: the add-on's own curve builder, smoother bevel, glossy plastic.
    result = Result(radius=truth.radius, paths=(CablePath(truth.centreline, closed=truth.closed),))
    cable = build_cable_curve(result, "cable", scene.collection)
    cable.data.bevel_resolution = 6
    plastic = bpy.data.materials.new("cable")
    plastic.use_nodes = True
    bsdf = plastic.node_tree.nodes["Principled BSDF"]
    bsdf.inputs["Base Color"].default_value = (0.62, 0.03, 0.02, 1.0)
    bsdf.inputs["Roughness"].default_value = 0.22
    cable.data.materials.append(plastic)

    # Light: a soft sun and a grey sky for the ambient light.
    sun_data = bpy.data.lights.new("sun", type="SUN")
    sun_data.energy = 3.5
    sun_data.angle = 0.12
    sun = bpy.data.objects.new("sun", sun_data)
    sun.rotation_euler = (0.6, 0.15, 0.8)
    scene.collection.objects.link(sun)
    world = bpy.data.worlds.new("sky")
    world.use_nodes = True
    world.node_tree.nodes["Background"].inputs["Color"].default_value = (0.45, 0.47, 0.5, 1.0)
    world.node_tree.nodes["Background"].inputs["Strength"].default_value = 0.9
    scene.world = world
    return scene


def flatten_to_silhouette(bpy, scene):
    """White unlit cable on black, no pixel filter: pixel value = the cable's coverage."""
    cable = bpy.data.materials["cable"].node_tree
    emission = cable.nodes.new("ShaderNodeEmission")
    cable.links.new(emission.outputs[0], cable.nodes["Material Output"].inputs["Surface"])
    table = bpy.data.materials["table"].node_tree
    for link in list(table.links):
        table.links.remove(link)
    table.nodes["Principled BSDF"].inputs["Base Color"].default_value = (0, 0, 0, 1)
    table.links.new(table.nodes["Principled BSDF"].outputs[0],
                    table.nodes["Material Output"].inputs["Surface"])
    scene.world.node_tree.nodes["Background"].inputs["Strength"].default_value = 0.0
    bpy.data.objects["sun"].data.energy = 0.0
    scene.view_settings.exposure = 0.0
    scene.cycles.filter_width = 0.01
    scene.cycles.use_denoising = False
    scene.render.image_settings.file_format = "PNG"


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("-o", "--output", default=str(ROOT / "samples" / "sequence"))
    parser.add_argument("--views", type=int, default=24)
    parser.add_argument("--size", default="960x720")
    parser.add_argument("--crossings", type=int, default=3)
    parser.add_argument("--seed", type=int, default=3)
    parser.add_argument("--radius", type=float, default=0.004, help="metres")
    parser.add_argument("--samples", type=int, default=32, help="Cycles samples per pixel")
    parser.add_argument("--overwrite", action="store_true")
    parser.add_argument("--silhouette", action="store_true",
                        help="render the bare silhouette (unlit cable, black table): for "
                             "checking the exact masks against Blender's own geometry")
    args = parser.parse_args()
    width, height = (int(v) for v in args.size.lower().split("x"))
    output = Path(args.output)
    if (output / "ground_truth.json").exists() and not args.overwrite:
        sys.exit(f"{output} already holds a sample (pass --overwrite to replace it)")

    import bpy
    import cv2
    import numpy as np

    package = load_addon_package()
    from cable_reconstruction.addon.scene_objects import build_cameras
    from cable_reconstruction.engine import write_colmap_model
    from cable_reconstruction.engine.ground_truth import write_ground_truth
    from cable_reconstruction.engine.synthetic_cameras import cable_pixel_width, handheld_cameras
    from cable_reconstruction.engine.synthetic_layouts import table_layout
    from cable_reconstruction.engine.synthetic_render import render_masks, table_texture

    truth = table_layout(args.crossings, seed=args.seed, radius=args.radius)
    cameras = handheld_cameras(truth, views=args.views, width=width, height=height,
                               elevations=(45.0, 75.0), name_format="{:03d}.jpg", seed=args.seed)
    truth = truth.with_cameras(cameras)
    print(f"{len(truth.crossings)} crossings, cable {truth.length:.2f} m, thinnest "
          f"{cable_pixel_width(truth, cameras):.1f} px", file=sys.stderr)

    with tempfile.TemporaryDirectory() as scratch:
        texture_path = Path(scratch) / "table.png"
        cv2.imwrite(str(texture_path), cv2.cvtColor(table_texture(args.seed, 4096),
                                                    cv2.COLOR_RGB2BGR))
        scene = build_scene(bpy, package, truth, texture_path, args.samples)
        if args.silhouette:
            flatten_to_silhouette(bpy, scene)
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
            scene.render.filepath = str(output / "images" / name)
            bpy.ops.render.render(write_still=True)
            print(f"[{k + 1}/{len(cameras)}] {camera.name} {time.time() - started:.0f} s",
                  file=sys.stderr, flush=True)
    for camera, mask in zip(cameras, render_masks(truth, cameras)):
        cv2.imwrite(str(output / "masks" / (Path(camera.name).stem + ".png")),
                    mask.astype(np.uint8) * 255)
    write_colmap_model(output / "sparse", cameras)
    write_ground_truth(truth, output / "ground_truth.json")
    print(write_preview(output))


if __name__ == "__main__":
    main()

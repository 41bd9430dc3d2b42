"""Render the reconstructed cable of `make demo` over one of its photos (for the README).

Opens build/demo/sample.blend (written by `make demo`), renders the bevelled curve with Cycles
from the reconstructed camera of one frame (transparent film), lays the render over that frame
dimmed, and writes [photo | render over the photo] side by side:

    python tools/render_result.py [--blend build/demo/sample.blend] [--frame 000.jpg]
                                  [-o docs/result.jpg] [--samples 32]
"""

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from blender_package import ROOT  # noqa: E402


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--blend", default=str(ROOT / "build" / "demo" / "sample.blend"))
    parser.add_argument("--frame", default="000.jpg")
    parser.add_argument("--images", default=str(ROOT / "samples" / "sequence" / "images"))
    parser.add_argument("-o", "--output", default=str(ROOT / "docs" / "result.jpg"))
    parser.add_argument("--samples", type=int, default=32)
    args = parser.parse_args()

    import bpy
    import cv2

    bpy.ops.wm.open_mainfile(filepath=args.blend)
    scene = bpy.context.scene
    camera = next(o for o in bpy.data.objects
                  if o.type == "CAMERA" and o.get("cable_recon_image") == args.frame)
    width, height = camera["cable_recon_resolution"]
    scene.camera = camera
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = args.samples
    scene.render.resolution_x, scene.render.resolution_y = width, height
    scene.render.resolution_percentage = 100
    scene.render.film_transparent = True
    scene.render.image_settings.file_format = "PNG"
    scene.render.image_settings.color_mode = "RGBA"
    if scene.world is None:
        scene.world = bpy.data.worlds.new("World")
    scene.world.color = (0.6, 0.6, 0.6)
    sun = bpy.data.objects.new("Sun", bpy.data.lights.new("Sun", type="SUN"))
    sun.data.energy = 3.0
    sun.rotation_euler = (0.6, 0.2, 0.8)
    scene.collection.objects.link(sun)
    for obj in bpy.data.objects:  # the cameras' frames are for the viewport, not the render
        obj.hide_render = obj.type == "CAMERA"
    render_path = Path(args.output).with_suffix(".render.png")
    scene.render.filepath = str(render_path)
    bpy.ops.render.render(write_still=True)

    render = cv2.imread(str(render_path), cv2.IMREAD_UNCHANGED).astype(np.float32) / 255.0
    render_path.unlink()
    photo = cv2.imread(str(Path(args.images) / args.frame)).astype(np.float32) / 255.0
    alpha = render[..., 3:4]
    over = render[..., :3] * alpha + 0.45 * photo * (1.0 - alpha)
    side_by_side = np.concatenate([photo, over], axis=1)
    output = Path(args.output)
    output.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(output), (side_by_side * 255).round().astype(np.uint8),
                [cv2.IMWRITE_JPEG_QUALITY, 88])
    print(output)


if __name__ == "__main__":
    main()

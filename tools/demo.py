"""`make demo`: reconstruct the bundled sample from its images, as a user would.

Cameras are estimated with pycolmap (the sample's true cameras are only used to score), the
cable's diameter (8 mm) scales the result to metres. Writes into build/demo/:

    sample.cable.json   the result (cable_recon.result/1)
    sample.blend        the bevelled curve and the cameras, imported by the add-on
    overlay.png         the curve drawn over the first frame, crossings marked over/under

and prints the accuracy against the sample's ground truth.

    python tools/demo.py [-o build/demo]
"""

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from blender_package import ROOT, load_addon_package  # noqa: E402

SAMPLE = ROOT / "samples" / "sequence"
DIAMETER_MM = 8.0


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("-o", "--output", default=str(ROOT / "build" / "demo"))
    args = parser.parse_args()
    output = Path(args.output).resolve()
    output.mkdir(parents=True, exist_ok=True)

    import bpy

    package = load_addon_package()
    package.register()
    from cable_reconstruction.engine import evaluate, read_ground_truth, write_result
    from cable_reconstruction.engine.cli import ProgressBar
    from cable_reconstruction.engine.image_sequence import read_image
    from cable_reconstruction.engine.overlay import draw_overlay
    from cable_reconstruction.engine.pipeline import reconstruct

    result = reconstruct(SAMPLE / "images", diameter=DIAMETER_MM, progress=ProgressBar())
    source = write_result(result, output / "sample.cable.json", overwrite=True)

    import cv2

    camera = result.cameras[0]
    overlay = draw_overlay(read_image(SAMPLE / "images" / camera.name), result, camera)
    cv2.imwrite(str(output / "overlay.png"), cv2.cvtColor(overlay, cv2.COLOR_RGB2BGR))

    bpy.ops.wm.read_homefile(use_empty=True)
    if bpy.ops.cable_recon.import_result(filepath=str(source)) != {"FINISHED"}:
        sys.exit(f"importing {source} failed")
    obj = bpy.data.objects[source.stem]
    blend = output / "sample.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    points = sum(len(spline.points) for spline in obj.data.splines)
    cameras = sum(1 for o in bpy.data.objects if o.type == "CAMERA")

    truth = read_ground_truth(SAMPLE / "ground_truth.json")
    metrics = evaluate(result, truth, align=True)
    print(f"{blend}: curve {obj.name!r}, {len(obj.data.splines)} spline(s), {points} points, "
          f"bevel {obj.data.bevel_depth * 1000:.2f} mm, {cameras} cameras")
    print(f"{source}, {output / 'overlay.png'}")
    for warning in result.warnings:
        print(f"warning: {warning}")
    print("against the ground truth (after a similarity alignment, lengths in cable radii):")
    print(f"  accuracy mean {metrics.accuracy_mean:.3f} r, p95 {metrics.accuracy_p95:.3f} r, "
          f"completeness {metrics.completeness:.3f}, one path: {metrics.one_path}, "
          f"crossings right {metrics.crossings_right}/{metrics.crossings_total}, "
          f"radius {result.radius * 1000:.2f} mm (true {truth.radius * 1000:.2f} mm)")
    print("  seconds per stage: " + ", ".join(f"{k} {v:.1f}" for k, v in result.timings.items()))
    package.unregister()


if __name__ == "__main__":
    main()

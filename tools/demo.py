"""`make demo`: reconstruct the bundled sample from its images, as a user would.

Cameras are estimated with pycolmap (the sample's true cameras are only used to score), the
cable's diameter (8 mm) scales the result to metres. Writes into build/demo/:

    sample.blend        the add-on's batch command's output, as
                        `blender -b --command cable_recon reconstruct IMAGES -o sample.blend
                        --diameter 8` writes it: the cable as a bevelled Bézier curve with few
                        control points, its material, the cameras with their frames
    sample.cable.json   the result (cable_recon.result/1)
    overlay.png         the curve drawn over the first frame, crossings marked over/under

and prints the accuracy against the sample's ground truth.

    python tools/demo.py [-o build/demo]
"""

import argparse
import sys
from dataclasses import replace
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
    from cable_reconstruction.addon.batch_command import handle_command
    from cable_reconstruction.addon.reconstruction import sessions
    from cable_reconstruction.engine import CablePath, read_ground_truth, write_result
    from cable_reconstruction.engine.evaluation.metrics import align_result_to_truth, evaluate
    from cable_reconstruction.engine.stages.bezier import fit_result_curves
    from cable_reconstruction.engine.io.image_sequence import read_image
    from cable_reconstruction.engine.io.overlay import draw_overlay

    bpy.ops.wm.read_homefile(use_empty=True)
    blend = output / "sample.blend"
    code = handle_command(["reconstruct", str(SAMPLE / "images"), "--diameter",
                           str(DIAMETER_MM), "-o", str(blend), "--overwrite"])
    if code != 0:
        sys.exit(code)
    obj = bpy.data.objects["sequence"]
    result = sessions[obj.cable_recon.run].result
    source = write_result(result, output / "sample.cable.json", overwrite=True)

    import cv2

    camera = result.cameras[0]
    overlay = draw_overlay(read_image(SAMPLE / "images" / camera.name), result, camera)
    cv2.imwrite(str(output / "overlay.png"), cv2.cvtColor(overlay, cv2.COLOR_RGB2BGR))
    points = sum(len(spline.bezier_points) for spline in obj.data.splines)
    dense = sum(len(path.points) for path in result.paths)
    cameras = sum(1 for o in bpy.data.objects if o.type == "CAMERA")

    truth = read_ground_truth(SAMPLE / "ground_truth.json")
    metrics = evaluate(result, truth, align=True)
    print(f"{blend}: curve {obj.name!r}, {len(obj.data.splines)} Bezier spline(s), {points} "
          f"control points (the reconstruction has {dense} points; the curve stays within "
          f"{obj.cable_recon.max_error:.3f} r of it), bevel {obj.data.bevel_depth * 1000:.2f} "
          f"mm, {cameras} cameras")
    print(f"{source}, {output / 'overlay.png'}")
    for warning in result.warnings:
        print(f"warning: {warning}")
    # given: the photos and the diameter, which sets the result's radius to 4 mm exactly;
    # measured: all else. The radius the images gave shows in the truth's frame, where the
    # cameras (not the diameter) decide the scale.
    measured = align_result_to_truth(result, truth)[0].radius
    print(f"given: {len(result.cameras)} photos and the cable's diameter ({DIAMETER_MM:g} mm, "
          f"which makes the radius {result.radius * 1000:.2f} mm); measured: all else")
    print("against the ground truth (after a similarity alignment of the cameras, lengths in "
          "cable radii):")
    print(f"  accuracy mean {metrics.accuracy_mean:.3f} r, p95 {metrics.accuracy_p95:.3f} r, "
          f"completeness {metrics.completeness:.3f}, one path: {metrics.one_path}, "
          f"crossings right {metrics.crossings_right}/{metrics.crossings_total}, "
          f"radius measured in the images {measured * 1000:.2f} mm in the truth's scale "
          f"(true {truth.radius * 1000:.2f} mm, {100 * metrics.radius_error:.1f}% off)")
    curves, _ = fit_result_curves(result)
    editable = replace(result, paths=[CablePath(c.sample(16), closed=c.closed) for c in curves],
                       crossings=())
    curve_metrics = evaluate(editable, truth, align=True)
    print(f"  the Bezier curve itself: accuracy mean {curve_metrics.accuracy_mean:.3f} r, "
          f"p95 {curve_metrics.accuracy_p95:.3f} r")
    print("  seconds per stage: " + ", ".join(f"{k} {v:.1f}" for k, v in result.timings.items()))
    package.unregister()


if __name__ == "__main__":
    main()

"""`make demo`: turn the bundled sample into a .blend with the bevelled cable curve.

Until the reconstruction pipeline exists this imports the sample's true cable (its ground
truth written as a result file) with the add-on's own import operator and saves the scene.

    python tools/demo.py [-o build/demo/sample.blend]
"""

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from blender_package import ROOT, load_addon_package  # noqa: E402


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("-o", "--output", default=str(ROOT / "build" / "demo" / "sample.blend"))
    args = parser.parse_args()

    import bpy

    package = load_addon_package()
    package.register()
    bpy.ops.wm.read_homefile(use_empty=True)
    from cable_reconstruction.engine import write_result
    from cable_reconstruction.engine.ground_truth import read_ground_truth

    output = Path(args.output).resolve()
    output.parent.mkdir(parents=True, exist_ok=True)
    truth = read_ground_truth(ROOT / "samples" / "sequence" / "ground_truth.json")
    source = write_result(truth.as_result(), output.with_suffix(".json"), overwrite=True)
    if bpy.ops.cable_recon.import_result(filepath=str(source)) != {"FINISHED"}:
        sys.exit(f"importing {source} failed")
    obj = bpy.data.objects[source.stem]
    bpy.ops.wm.save_as_mainfile(filepath=str(output))
    points = sum(len(spline.points) for spline in obj.data.splines)
    cameras = sum(1 for o in bpy.data.objects if o.type == "CAMERA")
    print(f"{output}: curve {obj.name!r} with {len(obj.data.splines)} spline(s), {points} points, "
          f"bevel {obj.data.bevel_depth * 1000:.1f} mm, {cameras} cameras")
    package.unregister()


if __name__ == "__main__":
    main()

"""`make demo`: turn the bundled sample into a .blend with the bevelled cable curve.

Until the reconstruction pipeline exists this imports the sample's result file
(samples/cable_result.json) with the add-on's own import operator and saves the scene.

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
    source = ROOT / "samples" / "cable_result.json"
    if bpy.ops.cable_recon.import_result(filepath=str(source)) != {"FINISHED"}:
        sys.exit(f"importing {source} failed")
    obj = bpy.data.objects[source.stem]
    output = Path(args.output).resolve()
    output.parent.mkdir(parents=True, exist_ok=True)
    bpy.ops.wm.save_as_mainfile(filepath=str(output))
    points = sum(len(spline.points) for spline in obj.data.splines)
    cameras = sum(1 for o in bpy.data.objects if o.type == "CAMERA")
    print(f"{output}: curve {obj.name!r} with {len(obj.data.splines)} spline(s), {points} points, "
          f"bevel {obj.data.bevel_depth * 1000:.1f} mm, {cameras} cameras")
    package.unregister()


if __name__ == "__main__":
    main()

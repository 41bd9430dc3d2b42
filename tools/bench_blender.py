"""The add-on's side of the live preview and the operators, measured with real bpy.

    python tools/bench_blender.py        (or: make bench-blender)

Prints two tables: the time from a change in the panel to the preview image's pixels being
rewritten (through the property's update, as in Blender), per frame size: showing the preview
(first_ms: the image is created), choosing another frame (other_frame_ms: it is decoded) and
changing the colour range (change_ms); and Reconstruct and Flip Crossing run by their
blocking ``execute()`` on the sample (cameras estimated, 8 mm diameter).
"""

import statistics
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from blender_package import ROOT, load_addon_package  # noqa: E402

SAMPLE = ROOT / "samples" / "sequence"


def table(rows):
    columns = list(rows[0])
    lines = ["| " + " | ".join(columns) + " |", "|" + "---|" * len(columns)]
    lines += ["| " + " | ".join(str(row[c]) for c in columns) + " |" for row in rows]
    return "\n".join(lines)


def bench_preview(bpy, repeats=10):
    import cv2

    from cable_reconstruction.addon.mask_preview import PREVIEW_IMAGE

    rows = []
    frame = cv2.imread(str(SAMPLE / "images" / "000.jpg"))
    with tempfile.TemporaryDirectory() as folder:
        for width, height in ((960, 720), (1920, 1080), (3840, 2160)):
            path = Path(folder) / f"{width}" / "000.jpg"
            path.parent.mkdir()
            for name in ("000.jpg", "001.jpg"):
                cv2.imwrite(str(path.parent / name), cv2.resize(
                    frame, (width, height), interpolation=cv2.INTER_CUBIC))
            bpy.ops.wm.read_homefile(use_empty=True)
            settings = bpy.context.scene.cable_recon
            started = time.perf_counter()
            settings.images = str(path.parent)
            bpy.ops.cable_recon.show_preview()
            first = time.perf_counter() - started
            bpy.ops.cable_recon.auto_colour()
            low = list(settings.hsv_low)
            times = []
            for number in range(repeats):  # what dragging the saturation slider does
                low[1] = 80 + 5 * (number % 4)
                started = time.perf_counter()
                settings.hsv_low = low
                times.append(time.perf_counter() - started)
            started = time.perf_counter()
            settings.frame = 1  # another frame of the same capture
            other = time.perf_counter() - started
            image = bpy.data.images[PREVIEW_IMAGE]
            rows.append({"frame": f"{width}x{height}", "preview": "x".join(map(str, image.size)),
                         "first_ms": round(1000 * first, 1),
                         "other_frame_ms": round(1000 * other, 1),
                         "change_ms_mean": round(1000 * statistics.mean(times), 1),
                         "change_ms_max": round(1000 * max(times), 1)})
    return rows


def bench_operators(bpy):
    bpy.ops.wm.read_homefile(use_empty=True)
    settings = bpy.context.scene.cable_recon
    settings.images = str(SAMPLE / "images")
    settings.scale, settings.diameter = "DIAMETER", 8.0
    rows = []
    started = time.perf_counter()
    bpy.ops.cable_recon.reconstruct()
    obj = bpy.data.objects["sequence"]
    rows.append({"operator": "reconstruct (cameras estimated)",
                 "seconds": round(time.perf_counter() - started, 2),
                 "control_points": obj.cable_recon.control_points,
                 "max_error_r": round(obj.cable_recon.max_error, 3),
                 "objects": len(bpy.data.objects)})
    started = time.perf_counter()
    bpy.ops.cable_recon.flip_crossing(index=0)
    obj = bpy.data.objects["sequence"]
    rows.append({"operator": "flip crossing 0 (final fit only)",
                 "seconds": round(time.perf_counter() - started, 2),
                 "control_points": obj.cable_recon.control_points,
                 "max_error_r": round(obj.cable_recon.max_error, 3),
                 "objects": len(bpy.data.objects)})
    return rows


def main():
    import bpy

    package = load_addon_package()
    package.register()
    print(table(bench_preview(bpy)))
    print()
    print(table(bench_operators(bpy)))
    package.unregister()


if __name__ == "__main__":
    main()

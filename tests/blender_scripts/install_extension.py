"""Run in a fresh Python process with bpy: install the extension zip like a user, then use it.

Usage: python install_extension.py EXTENSION_ZIP RESULT_JSON SCENE_DIR OUT_BLEND
BLENDER_USER_RESOURCES must point at an empty folder. Prints one JSON line of findings.
"""

import json
import sys
from pathlib import Path

import bpy

zip_path, result_path, scene_dir, out_blend = sys.argv[1:5]
report = {"install": sorted(bpy.ops.extensions.package_install_files(
    filepath=zip_path, repo="user_default", enable_on_install=True))}
module = "bl_ext.user_default.cable_reconstruction"
report["enabled"] = module in bpy.context.preferences.addons
report["operators"] = sorted(name for name in dir(bpy.types) if name.startswith("CABLE_RECON_OT"))
report["panel"] = hasattr(bpy.types, "VIEW3D_PT_cable_recon")
report["import_menu"] = any(getattr(f, "__module__", "").startswith(module)
                            for f in bpy.types.TOPBAR_MT_file_import._dyn_ui_initialize())

# The bundled wheels were unpacked for Blender and load from there (put first on the path so
# the test environment's own copies cannot stand in for them).
python = f"python{sys.version_info.major}.{sys.version_info.minor}"  # Blender's own Python
site = Path(bpy.utils.user_resource("EXTENSIONS")) / ".local" / "lib" / python / "site-packages"
sys.path.insert(0, str(site))
report["wheels"] = {}
for name in ("cv2", "pycolmap", "scipy", "networkx"):
    for key in [k for k in sys.modules if k == name or k.startswith(name + ".")]:
        del sys.modules[key]
    module_file = Path(__import__(name).__file__)
    report["wheels"][name] = str(module_file).startswith(str(site))

bpy.ops.wm.read_homefile(use_empty=True)
report["import_result"] = sorted(bpy.ops.cable_recon.import_result(filepath=result_path))
curves = [o for o in bpy.data.objects if o.type == "CURVE"]
report["curve"] = {"name": curves[0].name, "bevel": curves[0].data.bevel_depth,
                   "points": sum(len(s.points) for s in curves[0].data.splines)} if curves else None
print("REPORT " + json.dumps(report))

# The whole job through the installed extension: Reconstruct on a ground-truth capture with its
# true cameras, then the batch command's handler (what `blender --command cable_recon` runs).
bpy.ops.wm.read_homefile(use_empty=True)
settings = bpy.context.scene.cable_recon
settings.images = str(Path(scene_dir) / "images")
settings.camera_source, settings.camera_model = "MODEL", str(Path(scene_dir) / "sparse")
settings.scale, settings.with_cameras = "NONE", False
report["reconstruct"] = sorted(bpy.ops.cable_recon.reconstruct())
curves = [o for o in bpy.data.objects if o.type == "CURVE"]
report["reconstructed"] = [{
    "name": o.name, "bevel": o.data.bevel_depth, "type": o.data.splines[0].type,
    "control_points": sum(len(s.bezier_points) for s in o.data.splines),
    "reported": o.cable_recon.control_points, "crossings": len(o.cable_recon.crossings),
    "knots": [list(p.co) for p in o.data.splines[0].bezier_points]} for o in curves]
batch = sys.modules[module + ".addon.batch_command"]
report["batch_exit"] = batch.handle_command(
    ["reconstruct", str(Path(scene_dir) / "images"), "--cameras",
     str(Path(scene_dir) / "sparse"), "-o", out_blend, "-q"])
bpy.ops.wm.open_mainfile(filepath=out_blend)
report["batch_objects"] = sorted(o.name for o in bpy.data.objects if o.type == "CURVE")
# A folder of sequences (the capture's own folder holds the one): each run in a process of its
# own, which finds the engine and the wheels where the installer put them.
shots = Path(out_blend).parent / "shots"
report["batch_folder_exit"] = batch.handle_command(
    ["batch", str(Path(scene_dir).parent), "-o", str(shots), "--cameras", "sparse", "-q"])
report["batch_folder"] = sorted(p.name for p in shots.glob("*.blend"))
print("REPORT " + json.dumps(report))

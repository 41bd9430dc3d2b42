"""File > Import > Cable Result (.json): a result file becomes a bevelled curve (and cameras)."""

from pathlib import Path

import bpy
from bpy.props import BoolProperty, CollectionProperty, StringProperty
from bpy_extras.io_utils import ImportHelper

from ..engine import InputError, read_result
from .scene_objects import build_cable_curve, build_cameras

__all__ = ["CABLE_RECON_OT_import_result", "CABLE_RECON_FH_result", "menu_import"]


def import_result_file(context, filepath, *, with_cameras):
    """Read ``filepath`` and add its curve (and cameras) to the active collection.

    Returns
    -------
    bpy.types.Object
        The new curve object, named after the file.
    """
    result = read_result(filepath)
    name = Path(filepath).stem
    collection = context.collection or context.scene.collection
    obj = build_cable_curve(result, name, collection)
    obj["cable_recon_source"] = str(filepath)
    obj["cable_recon_units"] = result.units
    if with_cameras and result.cameras:
        cameras = bpy.data.collections.new(f"{name} cameras")
        collection.children.link(cameras)
        build_cameras(result.cameras, cameras)
    return obj


class CABLE_RECON_OT_import_result(bpy.types.Operator, ImportHelper):
    """Import a cable reconstruction result (.json) as a bevelled curve"""

    bl_idname = "cable_recon.import_result"
    bl_label = "Import Cable Result"
    bl_options = {"REGISTER", "UNDO", "PRESET"}

    filename_ext = ".json"
    filter_glob: StringProperty(default="*.json", options={"HIDDEN"})
    files: CollectionProperty(type=bpy.types.OperatorFileListElement,
                              options={"HIDDEN", "SKIP_SAVE"})
    directory: StringProperty(subtype="DIR_PATH", options={"HIDDEN", "SKIP_SAVE"})
    with_cameras: BoolProperty(
        name="Cameras",
        description="Also add the result's cameras as camera objects",
        default=True,
    )

    def execute(self, context):
        if self.files and self.directory:
            paths = [Path(self.directory) / entry.name for entry in self.files if entry.name]
        else:
            paths = [Path(self.filepath)]
        created = []
        for path in paths:
            try:
                created.append(import_result_file(context, path, with_cameras=self.with_cameras))
            except InputError as error:
                self.report({"ERROR"}, str(error))
                return {"CANCELLED"} if not created else {"FINISHED"}
        for obj in context.view_layer.objects.selected:
            obj.select_set(False)
        for obj in created:
            obj.select_set(True)
        context.view_layer.objects.active = created[-1]
        self.report({"INFO"}, f"Imported {', '.join(obj.name for obj in created)}")
        return {"FINISHED"}


class CABLE_RECON_FH_result(bpy.types.FileHandler):
    """Drop a result .json onto the 3D viewport to import it."""

    bl_idname = "CABLE_RECON_FH_result"
    bl_label = "Cable Result"
    bl_import_operator = CABLE_RECON_OT_import_result.bl_idname
    bl_file_extensions = ".json"

    @classmethod
    def poll_drop(cls, context):
        return context.area is not None and context.area.type == "VIEW_3D"


def menu_import(self, context):
    """File > Import entry."""
    self.layout.operator(CABLE_RECON_OT_import_result.bl_idname, text="Cable Result (.json)")

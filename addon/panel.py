"""The sidebar panel (3D viewport > N panel > Cable)."""

import bpy

from .import_result import CABLE_RECON_OT_import_result

__all__ = ["VIEW3D_PT_cable_recon"]


class VIEW3D_PT_cable_recon(bpy.types.Panel):
    """Cable Reconstruction tools in the 3D viewport's sidebar."""

    bl_idname = "VIEW3D_PT_cable_recon"
    bl_label = "Cable Reconstruction"
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "Cable"

    def draw(self, context):
        layout = self.layout
        layout.operator(CABLE_RECON_OT_import_result.bl_idname, icon="IMPORT")

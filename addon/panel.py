"""The sidebar panel (3D viewport > N panel > Cable): images, colour, cameras, Reconstruct,
quality settings and the crossings of the active result."""

import bpy

from .import_result import CABLE_RECON_OT_import_result
from .mask_preview import frame_paths
from .properties import QUALITY_GROUPS

__all__ = ["CLASSES", "VIEW3D_PT_cable_recon"]


class _CablePanel:
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "Cable"


class VIEW3D_PT_cable_recon(_CablePanel, bpy.types.Panel):
    """Cable Reconstruction tools in the 3D viewport's sidebar."""

    bl_idname = "VIEW3D_PT_cable_recon"
    bl_label = "Cable Reconstruction"

    def draw(self, context):
        layout = self.layout
        settings = context.scene.cable_recon
        manager = context.window_manager
        layout.use_property_split = True
        layout.use_property_decorate = False

        column = layout.column()
        column.prop(settings, "images")
        count = len(frame_paths(settings.images))
        row = column.row(align=True)
        row.prop(settings, "frame")
        row.label(text=f"of {count}" if count else "no frames")
        column.operator("cable_recon.show_preview", icon="IMAGE_DATA")

        column = layout.column(heading="Colour")
        column.prop(settings, "colour_mode", expand=True)
        row = column.row(align=True)
        row.operator("cable_recon.pick_colour", text="Pick", icon="EYEDROPPER")
        row.operator("cable_recon.auto_colour", text="Automatic", icon="AUTO")
        sub = column.column(align=True)
        sub.active = settings.colour_mode == "HSV"
        sub.prop(settings, "hsv_low")
        sub.prop(settings, "hsv_high")
        sub = column.column()
        sub.active = settings.colour_mode == "AUTO"
        sub.prop(settings.segmentation, "all_cables")

        column = layout.column()
        column.prop(settings, "camera_source")
        if settings.camera_source == "MODEL":
            column.prop(settings, "camera_model")
        column.prop(settings, "masks")
        column.prop(settings, "scale")
        if settings.scale == "DIAMETER":
            column.prop(settings, "diameter")
        elif settings.scale == "LENGTH":
            column.prop(settings, "length")
        column = layout.column(heading="Add")
        column.prop(settings, "with_cameras")
        sub = column.column()
        sub.active = settings.with_cameras
        sub.prop(settings, "background_images")

        if manager.cable_recon_status:
            layout.label(text=manager.cable_recon_status)
        if manager.cable_recon_progress > 0.0:
            layout.progress(factor=manager.cable_recon_progress, type="BAR",
                            text=f"{100 * manager.cable_recon_progress:.0f}%")
        layout.operator("cable_recon.reconstruct", icon="CURVE_BEZCURVE")
        layout.operator(CABLE_RECON_OT_import_result.bl_idname, icon="IMPORT")


class VIEW3D_PT_cable_recon_quality(_CablePanel, bpy.types.Panel):
    """The engine's settings, stage by stage (defaults from the engine)."""

    bl_idname = "VIEW3D_PT_cable_recon_quality"
    bl_label = "Quality"
    bl_parent_id = VIEW3D_PT_cable_recon.bl_idname
    bl_options = {"DEFAULT_CLOSED"}

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        layout.use_property_decorate = False
        settings = context.scene.cable_recon
        for name, label, _ in QUALITY_GROUPS:
            header, body = layout.panel(f"cable_recon_quality_{name}", default_closed=True)
            header.label(text=label)
            if body is not None:
                group = getattr(settings, name)
                for prop in group.bl_rna.properties:
                    if prop.identifier not in {"rna_type", "name"}:
                        body.prop(group, prop.identifier)


class CABLE_RECON_UL_crossings(bpy.types.UIList):
    """Crossings of a result: which strand is over, and how sure the reconstruction is."""

    def draw_item(self, context, layout, data, item, icon, active_data, active_property,
                  index=0, flt_flag=0):
        row = layout.row(align=True)
        sure = item.confidence >= 0.9
        row.label(text=f"{index}: point {item.over_index} over {item.under_index}",
                  icon="CHECKMARK" if sure else "ERROR")
        row.label(text=f"{item.confidence:.2f}")
        row.operator("cable_recon.flip_crossing", text="", icon="ARROW_LEFTRIGHT").index = index


class VIEW3D_PT_cable_recon_crossings(_CablePanel, bpy.types.Panel):
    """The active result's crossings, to check and flip."""

    bl_idname = "VIEW3D_PT_cable_recon_crossings"
    bl_label = "Crossings"
    bl_parent_id = VIEW3D_PT_cable_recon.bl_idname

    @classmethod
    def poll(cls, context):
        obj = context.active_object
        return obj is not None and obj.type == "CURVE" and bool(obj.cable_recon.arguments)

    def draw(self, context):
        layout = self.layout
        props = context.active_object.cable_recon
        layout.label(text=f"{props.control_points} control points, within "
                          f"{props.max_error:.2f} r of the reconstruction")
        layout.operator("cable_recon.save_run", icon="EXPORT")
        if not props.crossings:
            layout.label(text="No crossings")
            return
        layout.template_list("CABLE_RECON_UL_crossings", "", props, "crossings", props,
                             "active_crossing", rows=3)
        row = layout.row()
        row.operator("cable_recon.flip_crossing", icon="ARROW_LEFTRIGHT").index = \
            props.active_crossing
        low = sum(1 for c in props.crossings if c.confidence < 0.9)
        if low:
            layout.label(text=f"{low} crossing(s) below 0.9 confidence: check them",
                         icon="ERROR")


CLASSES = (VIEW3D_PT_cable_recon, VIEW3D_PT_cable_recon_quality, CABLE_RECON_UL_crossings,
           VIEW3D_PT_cable_recon_crossings)

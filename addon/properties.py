"""The add-on's settings (saved in the .blend with the scene) and what a result object keeps.

``scene.cable_recon``: the image folder, the cable colour, the camera source, the scale and
the quality settings (one group per engine settings dataclass, defaults from the dataclass).
``object.cable_recon``: on a reconstructed curve, its crossings (to flip) and how well the
Bézier curve follows the reconstruction. ``window_manager.cable_recon_progress`` and
``cable_recon_status``: the running job, for the panel (not saved).
"""

import dataclasses

import bpy
from bpy.props import (BoolProperty, CollectionProperty, EnumProperty, FloatProperty,
                       FloatVectorProperty, IntProperty, IntVectorProperty, PointerProperty,
                       StringProperty)

from ..engine.pipeline import PipelineSettings, RunInputs
from ..engine.stages.bezier import BezierSettings
from ..engine.stages.segmentation import ColourRange
from .settings_properties import property_group_for, settings_from_group

__all__ = ["CLASSES", "QUALITY_GROUPS", "register_properties", "unregister_properties",
           "pipeline_settings", "colour_range", "set_colour_range"]


def _update_preview(self, context):
    from .mask_preview import refresh_preview

    refresh_preview(context)


#: Quality settings shown in the panel: (attribute, label, engine dataclass).
QUALITY_GROUPS = tuple(
    (field.name, field.name.replace("_", " ").capitalize(), field.default_factory)
    for field in dataclasses.fields(PipelineSettings)
    if field.default_factory is not dataclasses.MISSING) + (("curve", "Curve", BezierSettings),)

# the preview follows the segmentation's settings as it follows the colour
_GROUP_CLASSES = tuple(property_group_for(cls, f"CABLE_RECON_PG_{name}",
                                          update=_update_preview if name == "segmentation"
                                          else None)
                       for name, _, cls in QUALITY_GROUPS)

_DEFAULT_COLOUR = ColourRange.parse(RunInputs.PANEL_HSV)


class CABLE_RECON_PG_settings(bpy.types.PropertyGroup):
    """What the Reconstruct operator uses: saved with the scene."""

    images: StringProperty(
        name="Images", subtype="DIR_PATH", update=_update_preview,
        description="Folder of the cable's photos or video frames (.jpg, .png)")
    frame: IntProperty(
        name="Frame", min=0, default=PipelineSettings().reference_frame, update=_update_preview,
        description="Frame the colour is tuned on and the mask preview shows")
    colour_mode: EnumProperty(
        name="Colour", default="AUTO", update=_update_preview,
        items=[("AUTO", "Automatic", "The most cable-like thing in the frames (a thin object of "
                                     "one or a few colours standing out from its surroundings)"),
               ("HSV", "HSV range", "The range below (set it by hand, or pick the cable)")])
    hsv_low: IntVectorProperty(
        name="Low", size=3, min=0, max=255, default=_DEFAULT_COLOUR.low,
        update=_update_preview,
        description="Lowest hue (0-179), saturation and value (0-255); a low hue above the "
                    "high hue wraps around red")
    hsv_high: IntVectorProperty(
        name="High", size=3, min=0, max=255, default=_DEFAULT_COLOUR.high,
        update=_update_preview, description="Highest hue (0-179), saturation and value (0-255)")
    camera_source: EnumProperty(
        name="Cameras", default="ESTIMATE",
        items=[("ESTIMATE", "Estimate", "Find the cameras from the photos (pycolmap)"),
               ("MODEL", "COLMAP model", "Use a COLMAP model of these frames as is")])
    camera_model: StringProperty(
        name="Model", subtype="DIR_PATH",
        description="COLMAP model folder (cameras, images[, points3D]; text or binary) whose "
                    "image names are the frames' file names")
    masks: StringProperty(
        name="Masks", subtype="DIR_PATH",
        description="Optional: masks written by 'python -m engine segment' (perhaps corrected "
                    "by hand), used instead of segmenting")
    scale: EnumProperty(
        name="Scale", default="DIAMETER",
        items=[("NONE", "As found", "Estimated cameras: arbitrary units; a model: its units"),
               ("DIAMETER", "Diameter", "The cable's measured diameter gives metres"),
               ("LENGTH", "Length", "The cable's length gives metres")])
    diameter: FloatProperty(
        name="Diameter (mm)", min=0.01, default=RunInputs.PANEL_DIAMETER, precision=2,
        description="The cable's diameter in millimetres (calipers)")
    length: FloatProperty(
        name="Length (m)", min=0.001, default=RunInputs.PANEL_LENGTH, precision=3,
        description="The cable's length in metres")
    with_cameras: BoolProperty(
        name="Cameras", default=True, description="Add the cameras as camera objects")
    background_images: BoolProperty(
        name="Frames as backgrounds", default=True,
        description="Show each camera's frame as its background image")
    show_quality: BoolProperty(name="Quality", default=False)

    __annotations__.update({
        name: PointerProperty(type=cls, name=label)
        for (name, label, _), cls in zip(QUALITY_GROUPS, _GROUP_CLASSES)})


class CABLE_RECON_PG_crossing(bpy.types.PropertyGroup):
    """One crossing of a reconstructed curve (indices into the result's points)."""

    over_path: IntProperty()
    over_index: IntProperty()
    under_path: IntProperty()
    under_index: IntProperty()
    confidence: FloatProperty(min=0.0, max=1.0, subtype="FACTOR")
    position: FloatVectorProperty(size=3, subtype="XYZ")


class CABLE_RECON_PG_result(bpy.types.PropertyGroup):
    """What a reconstructed curve object keeps: its crossings and how it was made."""

    run: StringProperty(description="The run this curve came from (to re-fit it)")
    arguments: StringProperty(description="The engine call that made it (JSON)")
    crossings: CollectionProperty(type=CABLE_RECON_PG_crossing)
    active_crossing: IntProperty(name="Crossing")
    control_points: IntProperty(name="Control points")
    max_error: FloatProperty(name="Largest distance (r)", precision=3)
    radius: FloatProperty(name="Radius", precision=5)


CLASSES = (*_GROUP_CLASSES, CABLE_RECON_PG_settings, CABLE_RECON_PG_crossing,
           CABLE_RECON_PG_result)


def register_properties():
    """Attach the property groups to Scene, Object and WindowManager (classes registered)."""
    bpy.types.Scene.cable_recon = PointerProperty(type=CABLE_RECON_PG_settings)
    bpy.types.Object.cable_recon = PointerProperty(type=CABLE_RECON_PG_result)
    bpy.types.WindowManager.cable_recon_progress = FloatProperty(
        name="Progress", min=0.0, max=1.0, subtype="FACTOR", options={"SKIP_SAVE"})
    bpy.types.WindowManager.cable_recon_status = StringProperty(options={"SKIP_SAVE"})


def unregister_properties():
    """Undo :func:`register_properties`."""
    del bpy.types.WindowManager.cable_recon_status
    del bpy.types.WindowManager.cable_recon_progress
    del bpy.types.Object.cable_recon
    del bpy.types.Scene.cable_recon


def pipeline_settings(settings):
    """The engine's :class:`PipelineSettings` from the scene's settings."""
    groups = {name: settings_from_group(getattr(settings, name))
              for name, _, cls in QUALITY_GROUPS if cls is not BezierSettings}
    return PipelineSettings(reference_frame=settings.frame, **groups)


def colour_range(settings):
    """The HSV range set in the panel, or None for automatic."""
    if settings.colour_mode == "AUTO":
        return None
    low, high = tuple(settings.hsv_low), tuple(settings.hsv_high)
    low, high = (min(low[0], 179),) + low[1:], (min(high[0], 179),) + high[1:]
    return ColourRange(low, high)


def set_colour_range(settings, colour):
    """Show ``colour`` in the panel (switches to the HSV range; refreshes the preview once)."""
    settings["hsv_low"], settings["hsv_high"] = list(colour.low), list(colour.high)
    settings.colour_mode = "HSV"  # its update refreshes the preview

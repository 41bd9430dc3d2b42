"""The Blender side of Cable Reconstruction: the only package that imports bpy.

Operators stay thin: they call the engine's public API and turn its results into Blender data.
"""

import bpy

from . import operators, panel, properties
from .batch_command import COMMAND, handle_command
from .import_result import CABLE_RECON_FH_result, CABLE_RECON_OT_import_result, menu_import
from .panel import VIEW3D_PT_cable_recon

__all__ = ["register", "unregister", "CLASSES", "VIEW3D_PT_cable_recon"]

CLASSES = (
    *properties.CLASSES,
    *operators.CLASSES,
    CABLE_RECON_OT_import_result,
    CABLE_RECON_FH_result,
    *panel.CLASSES,
)

_register_classes, _unregister_classes = bpy.utils.register_classes_factory(CLASSES)
_command = None


def register():
    """Register the add-on's classes, properties, menu entry and batch command."""
    global _command
    _register_classes()
    properties.register_properties()
    bpy.types.TOPBAR_MT_file_import.append(menu_import)
    _command = bpy.utils.register_cli_command(COMMAND, handle_command)


def unregister():
    """Undo :func:`register`."""
    global _command
    if _command is not None:
        bpy.utils.unregister_cli_command(_command)
        _command = None
    bpy.types.TOPBAR_MT_file_import.remove(menu_import)
    properties.unregister_properties()
    _unregister_classes()

"""The Blender side of Cable Reconstruction: the only package that imports bpy.

Operators stay thin: they call the engine's public API and turn its results into Blender data.
"""

import bpy

from .import_result import CABLE_RECON_FH_result, CABLE_RECON_OT_import_result, menu_import
from .panel import VIEW3D_PT_cable_recon

__all__ = ["register", "unregister", "CLASSES"]

CLASSES = (
    CABLE_RECON_OT_import_result,
    CABLE_RECON_FH_result,
    VIEW3D_PT_cable_recon,
)

_register_classes, _unregister_classes = bpy.utils.register_classes_factory(CLASSES)


def register():
    """Register the add-on's classes and menu entries."""
    _register_classes()
    bpy.types.TOPBAR_MT_file_import.append(menu_import)


def unregister():
    """Undo :func:`register`."""
    bpy.types.TOPBAR_MT_file_import.remove(menu_import)
    _unregister_classes()

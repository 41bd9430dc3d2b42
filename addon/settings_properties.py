"""Blender properties derived from the engine's settings dataclasses (the single source of
defaults): one PropertyGroup class per dataclass, and the dataclass back from a group."""

import dataclasses

import bpy
import numpy as np
from bpy.props import BoolProperty, FloatProperty, IntProperty

from ..engine.cli.settings import field_help

__all__ = ["property_group_for", "settings_from_group"]

_KINDS = {int: int, float: float, bool: bool, "int": int, "float": float, "bool": bool}


def _simple_fields(cls):
    return [f for f in dataclasses.fields(cls) if f.type in _KINDS]


def property_group_for(cls, idname, *, update=None):
    """A PropertyGroup class with one property per int/float/bool field of ``cls``.

    Names, defaults and tooltips come from the dataclass (its numpydoc ``Attributes``).

    Parameters
    ----------
    cls : type
        A frozen settings dataclass of the engine.
    idname : str
        The class name (``CABLE_RECON_PG_...``).
    update : callable, optional
        Called as ``update(group, context)`` when any of its properties changes.

    Returns
    -------
    type
        Register it before use; ``settings_class`` holds ``cls``.
    """
    texts = field_help(cls)
    annotations = {}
    for field in _simple_fields(cls):
        kind = _KINDS[field.type]
        label = field.name.replace("_", " ").capitalize()
        options = dict(name=label, description=texts.get(field.name, ""), default=field.default)
        if update is not None:
            options["update"] = update
        if kind is bool:
            annotations[field.name] = BoolProperty(**options)
        elif kind is int:
            annotations[field.name] = IntProperty(**options)
        else:
            annotations[field.name] = FloatProperty(precision=3, step=1, **options)
    return type(idname, (bpy.types.PropertyGroup,),
                {"__annotations__": annotations, "settings_class": cls,
                 "__doc__": f"Blender properties of the engine's {cls.__name__}"})


def _value(group, field):
    value = getattr(group, field.name)
    if _KINDS[field.type] is float:
        # Blender stores floats in single precision: the shortest decimal that reads back
        # as the same float32 gives the dataclass's own default (0.01, not 0.0099999998)
        value = float(str(np.float32(value)))
    return value


def settings_from_group(group):
    """The engine dataclass a group (made by :func:`property_group_for`) describes."""
    cls = group.settings_class
    return cls(**{f.name: _value(group, f) for f in _simple_fields(cls)})

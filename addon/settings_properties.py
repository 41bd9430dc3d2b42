"""Blender properties derived from the engine's settings dataclasses (the single source of
defaults): one PropertyGroup class per dataclass, and the dataclass back from a group."""

import bpy
import numpy as np
from bpy.props import BoolProperty, FloatProperty, IntProperty

from ..engine.settings import (bounds, describe_range, field_help, kind_of, simple_fields,
                               unit_of)

__all__ = ["property_group_for", "settings_from_group"]

#: How far inside an exclusive bound (``above``) a float property starts.
_INSIDE = 1e-6


def _limits(field, kind):
    """The property's ``min``/``max`` from the field's range (none where it has none)."""
    low, high, above = bounds(field)
    limits = {}
    if above is not None:
        limits["min"] = above + 1 if kind is int else above + _INSIDE
    elif low is not None:
        limits["min"] = low
    if high is not None:
        limits["max"] = high
    return limits


def _description(field, text):
    """The tooltip: the field's first sentence, its range and unit."""
    limits = ", ".join(part for part in (describe_range(field), unit_of(field)) if part)
    return f"{text} ({limits})" if limits else text


def property_group_for(cls, idname, *, update=None):
    """A PropertyGroup class with one property per int/float/bool field of ``cls``.

    Names, defaults, limits and tooltips come from the dataclass (its fields' ranges and units,
    its numpydoc ``Attributes``).

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
    for field in simple_fields(cls):
        kind = kind_of(field)
        label = field.name.replace("_", " ").capitalize()
        options = dict(name=label, description=_description(field, texts.get(field.name, "")),
                       default=field.default)
        if update is not None:
            options["update"] = update
        if kind is bool:
            annotations[field.name] = BoolProperty(**options)
        elif kind is int:
            annotations[field.name] = IntProperty(**options, **_limits(field, int))
        else:
            annotations[field.name] = FloatProperty(precision=3, step=1, **options,
                                                    **_limits(field, float))
    return type(idname, (bpy.types.PropertyGroup,),
                {"__annotations__": annotations, "settings_class": cls,
                 "__doc__": f"Blender properties of the engine's {cls.__name__}"})


def _value(group, field):
    value = getattr(group, field.name)
    if kind_of(field) is float:
        # Blender stores floats in single precision: the shortest decimal that reads back
        # as the same float32 gives the dataclass's own default (0.01, not 0.0099999998)
        value = float(str(np.float32(value)))
    return value


def settings_from_group(group):
    """The engine dataclass a group (made by :func:`property_group_for`) describes."""
    cls = group.settings_class
    return cls(**{f.name: _value(group, f) for f in simple_fields(cls)})

"""Command-line flags derived from the engine's settings dataclasses, so defaults never drift.

Every settings group of :class:`~engine.pipeline.PipelineSettings` is reachable with its own
prefix (``--carving-voxels-per-radius``, ``--topology-spur-length``), the same fields the panel
shows in Blender; each value is checked against its field's range as it is parsed. Flags left
out keep the defaults, or the values of a run read with ``--settings``.
"""

import argparse
import dataclasses

from ..errors import InputError
from ..settings import (describe_range, field_help, kind_of, out_of_range, simple_fields,
                        unit_of)

__all__ = ["add_settings_arguments", "settings_from_arguments", "checked_type",
           "add_pipeline_arguments", "pipeline_from_arguments", "PIPELINE_GROUPS"]

#: The settings groups of a reconstruction, as ``PipelineSettings`` names them (each one's
#: flags carry its name as prefix).
PIPELINE_GROUPS = ("segmentation", "cameras", "agreement", "carving", "graph", "topology",
                   "fit", "upright", "checks")

def checked_type(field, flag):
    """An argparse ``type``: the field's kind, refused out of its range."""
    kind = kind_of(field)

    def parse(text):
        try:
            value = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(
                f"{flag} must be {'a whole number' if kind is int else 'a number'}, "
                f"not {text!r}") from None
        problem = out_of_range(field, value)
        if problem:
            raise argparse.ArgumentTypeError(f"{flag} {problem}")
        return value

    return parse


def add_settings_arguments(parser, cls, *, prefix="", aliases=False, skip=()):
    """Add a flag for every int/float/bool field of the dataclass ``cls``.

    The flags are ``--prefix-field-name`` (destination ``prefix_field_name``), or
    ``--field-name`` without a prefix; a true boolean turns off with ``--no-...``. A flag left
    out leaves its destination unset: the value comes from :func:`settings_from_arguments`'s
    ``base``.

    Parameters
    ----------
    parser : argparse.ArgumentParser
    cls : type
        A settings dataclass of the engine.
    prefix : str, optional
    aliases : bool, optional
        Also accept ``--field-name`` without the prefix (flags of earlier versions).
    skip : sequence of str, optional
        Fields left out.
    """
    group = parser.add_argument_group(
        f"{cls.__name__}" + (f" (--{prefix.replace('_', '-')}-...)" if prefix else ""))
    texts = field_help(cls)
    for field in simple_fields(cls):
        if field.name in skip:
            continue
        dest = f"{prefix}_{field.name}" if prefix else field.name
        names = [dest] + ([field.name] if aliases and prefix else [])
        text = texts.get(field.name, "")
        if kind_of(field) is bool:
            flags = [("--no-" if field.default else "--") + name.replace("_", "-")
                     for name in names]
            group.add_argument(*flags, dest=dest, default=argparse.SUPPRESS,
                               action="store_false" if field.default else "store_true",
                               help=("turn off: " if field.default else "") + text)
            continue
        flags = ["--" + name.replace("_", "-") for name in names]
        limits = ", ".join(part for part in (describe_range(field), unit_of(field)) if part)
        group.add_argument(*flags, dest=dest, type=checked_type(field, flags[0]),
                           default=argparse.SUPPRESS, metavar=field.name.upper(),
                           help=f"{text} (default {field.default}"
                                + (f"; {limits})" if limits else ")"))


def settings_from_arguments(cls, args, *, prefix="", base=None):
    """``base`` (default ``cls()``) with the fields given on the command line replaced (named
    as :func:`add_settings_arguments` named them)."""
    values = vars(args)
    given = {}
    for field in dataclasses.fields(cls):
        key = f"{prefix}_{field.name}" if prefix else field.name
        if key in values:
            given[field.name] = values[key]
    try:
        return dataclasses.replace(base if base is not None else cls(), **given)
    except ValueError as error:  # values that do not fit together (each fits its range)
        raise InputError(str(error)) from None


def add_pipeline_arguments(parser, groups=PIPELINE_GROUPS, *, aliases=("segmentation", "carving")):
    """Flags for the settings groups ``groups`` of a reconstruction, each with its prefix.

    ``aliases``: the groups whose flags also work without their prefix, as in earlier
    versions (``--all-cables``, ``--memory-mb``).
    """
    from ..pipeline import PipelineSettings

    classes = {field.name: field.default_factory
               for field in dataclasses.fields(PipelineSettings)}
    for name in groups:
        add_settings_arguments(parser, classes[name], prefix=name, aliases=name in aliases)


def pipeline_from_arguments(args, base=None, groups=PIPELINE_GROUPS):
    """A :class:`~engine.pipeline.PipelineSettings`: ``base`` (default the defaults) with what
    the command line gives for ``groups``, and ``--reference-frame`` and ``--workers`` if
    given."""
    from ..pipeline import PipelineSettings

    base = base if base is not None else PipelineSettings()
    changed = {name: settings_from_arguments(type(getattr(base, name)), args, prefix=name,
                                             base=getattr(base, name))
               for name in groups}
    for name in ("reference_frame", "workers"):
        if getattr(args, name, None) is not None:
            changed[name] = getattr(args, name)
    return dataclasses.replace(base, **changed)

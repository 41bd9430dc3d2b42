"""What every settings dataclass of the engine shares: fields with a range and a unit, checked
when the settings are made, and the settings as plain data (a result's record of its run).

The ranges feed the command line's checks and help (``engine.cli.settings``) and the panel's
limits in Blender, so a value is refused where it is typed, with the same bounds everywhere.
"""

import dataclasses
import inspect
import math
import re

from .errors import InputError

__all__ = ["setting", "bounds", "unit_of", "describe_range", "out_of_range", "simple_fields",
           "kind_of", "check_settings", "field_help", "settings_to_dict", "settings_from_dict"]


def setting(default, *, low=None, high=None, above=None, unit=""):
    """A dataclass field with its range and unit.

    Parameters
    ----------
    default : int, float or bool
    low, high : float, optional
        Inclusive bounds.
    above : float, optional
        Exclusive lower bound (a value must be greater).
    unit : str, optional
        What the value counts: ``"r"`` (cable radii), ``"px"``, ``"widths"`` ...

    Returns
    -------
    dataclasses.Field
    """
    return dataclasses.field(default=default, metadata={
        "low": low, "high": high, "above": above, "unit": unit})


def bounds(field):
    """``(low, high, above)`` of a field made by :func:`setting` (each None when absent)."""
    meta = field.metadata
    return meta.get("low"), meta.get("high"), meta.get("above")


def unit_of(field):
    """A field's unit ("" when none was given)."""
    return field.metadata.get("unit", "")


def describe_range(field):
    """The range in words: ``"> 0"``, ``"0 to 1"``, ``">= 1"``, or "" when unbounded."""
    low, high, above = bounds(field)
    if above is not None:
        text = f"> {above:g}"
        return text + (f" and <= {high:g}" if high is not None else "")
    if low is not None and high is not None:
        return f"{low:g} to {high:g}"
    if low is not None:
        return f">= {low:g}"
    if high is not None:
        return f"<= {high:g}"
    return ""


def out_of_range(field, value):
    """Why ``value`` does not fit ``field`` (its type and range), or None when it does."""
    kind = kind_of(field)
    if kind is bool:
        return None if isinstance(value, bool) else "must be true or false"
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return f"must be a number, not {value!r}"
    if kind is int and value != int(value):
        return f"must be a whole number, not {value!r}"
    if not math.isfinite(value):
        return f"must be a finite number, not {value!r}"
    low, high, above = bounds(field)
    if ((above is not None and not value > above) or (low is not None and value < low)
            or (high is not None and value > high)):
        return f"must be {describe_range(field)}, not {value!r}"
    return None


def kind_of(field):
    """``int``, ``float``, ``bool`` or ``str``: a field's type (its annotation may be a string)."""
    return {"int": int, "float": float, "bool": bool, "str": str}.get(field.type, field.type)


def simple_fields(cls):
    """The int, float and bool fields of a settings dataclass: those the command line and the
    panel offer."""
    return [field for field in dataclasses.fields(cls) if kind_of(field) in (int, float, bool)]


def check_settings(settings):
    """Raise a ``ValueError`` naming the first field of ``settings`` out of its range.

    Called by each settings dataclass's ``__post_init__``.
    """
    for field in dataclasses.fields(settings):
        if "low" not in field.metadata:
            continue
        problem = out_of_range(field, getattr(settings, field.name))
        if problem:
            raise ValueError(f"{type(settings).__name__}.{field.name} {problem}")


def field_help(cls):
    """Per field, the first sentence of its numpydoc ``Attributes`` entry.

    The docstring is dedented first: Python 3.13 strips a docstring's indentation when it
    compiles it, 3.11 keeps it.
    """
    entries, current = {}, None
    for line in inspect.cleandoc(cls.__doc__ or "").splitlines():
        if re.match(r"^\w+(, \w+)* : ", line):
            current = re.findall(r"\w+", line.split(" : ")[0])
            for name in current:
                entries[name] = []
        elif current and line.startswith("    ") and line.strip():
            for name in current:
                entries[name].append(line.strip())
        elif not line.strip():
            current = None
    texts = {}
    for name, lines in entries.items():
        text = " ".join(lines).replace("``", "")
        texts[name] = text.split(". ")[0].rstrip(".") + "."
    return texts


def settings_to_dict(settings):
    """A settings dataclass (and those nested in it) as plain JSON-able data."""
    return dataclasses.asdict(settings)


def settings_from_dict(cls, data, where="settings", *, strict=True):
    """The settings dataclass ``cls`` from :func:`settings_to_dict`'s data.

    Fields left out keep their defaults; nested settings are read the same way. Not
    ``strict``, fields ``cls`` no longer has (data an earlier version wrote) are passed over.

    Raises
    ------
    InputError
        ``data`` is not an object, names a field ``cls`` does not have, or a value does not
        fit its field (the message names it, under ``where``).
    """
    if not isinstance(data, dict):
        raise InputError(f"{where} must be an object")
    fields = {field.name: field for field in dataclasses.fields(cls)}
    unknown = sorted(set(data) - set(fields))
    if not strict:
        data = {name: value for name, value in data.items() if name in fields}
    elif unknown:
        raise InputError(f"{where}: {', '.join(unknown)} "
                         f"{'is not a setting' if len(unknown) == 1 else 'are not settings'} "
                         f"of {cls.__name__}")
    values = {}
    for name, value in data.items():
        field = fields[name]
        factory = field.default_factory
        if factory is not dataclasses.MISSING and dataclasses.is_dataclass(factory):
            value = settings_from_dict(factory, value, f"{where}.{name}", strict=strict)
        elif isinstance(value, list):
            value = tuple(value)
        elif kind_of(field) is float and isinstance(value, int) and not isinstance(value, bool):
            value = float(value)
        values[name] = value
    try:
        return cls(**values)
    except (TypeError, ValueError) as error:
        raise InputError(f"{where}: {error}") from None

"""Command-line flags derived from the engine's settings dataclasses, so defaults never drift."""

import dataclasses
import inspect
import re

__all__ = ["add_settings_arguments", "settings_from_arguments", "field_help"]


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


def add_settings_arguments(parser, cls, *, skip=(), prefix=""):
    """Add ``--field-name`` for every int/float/bool field of the dataclass ``cls``.

    With a ``prefix`` (e.g. ``"agreement"``) the flags are ``--agreement-field-name`` and
    their destinations ``agreement_field_name``: for settings whose field names would be
    unclear, or clash with another class's, among a command's flags.
    """
    group = parser.add_argument_group(cls.__name__)
    texts = field_help(cls)
    for field in dataclasses.fields(cls):
        if field.name in skip or field.type not in (int, float, bool, "int", "float", "bool"):
            continue
        name = f"{prefix}_{field.name}" if prefix else field.name
        flag = "--" + name.replace("_", "-")
        kind = {"int": int, "float": float, "bool": bool}.get(field.type, field.type)
        if kind is bool:  # a flag that changes the default
            flag = flag if not field.default else "--no-" + name.replace("_", "-")
            group.add_argument(flag, dest=name, default=field.default,
                               action="store_false" if field.default else "store_true",
                               help=("turn off: " if field.default else "")
                               + texts.get(field.name, ""))
            continue
        group.add_argument(flag, dest=name, type=kind, default=field.default,
                           metavar=field.name.upper(),
                           help=f"{texts.get(field.name, '')} (default {field.default})")


def settings_from_arguments(cls, args, *, prefix=""):
    """Build ``cls`` from parsed arguments named after its fields (with ``prefix``, as
    :func:`add_settings_arguments` named them)."""
    values = vars(args)
    names = [f.name for f in dataclasses.fields(cls)]
    keys = {name: f"{prefix}_{name}" if prefix else name for name in names}
    return cls(**{name: values[key] for name, key in keys.items() if key in values})

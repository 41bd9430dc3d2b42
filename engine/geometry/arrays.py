"""Array arguments checked and frozen, as the engine's public functions and records take them."""

import numpy as np

__all__ = ["as_points", "read_only"]


def as_points(value, name="points"):
    """``value`` as a new float64 ``(N, 3)`` array of finite numbers.

    Raises
    ------
    ValueError
        Naming ``name``, when the shape is not ``(N, 3)`` or a value is not finite.
    """
    points = np.array(value, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 3:
        raise ValueError(f"{name} must be an (N, 3) array, got shape {points.shape}")
    if not np.all(np.isfinite(points)):
        raise ValueError(f"{name} holds a value that is not a finite number")
    return points


def read_only(value, dtype=np.float64):
    """``value`` as a new array of ``dtype`` that cannot be written to (the frozen data of a
    frozen dataclass)."""
    array = np.array(value, dtype=dtype)
    array.setflags(write=False)
    return array

"""Checks of array arguments shared by the engine's public functions."""

import numpy as np

__all__ = ["as_points"]


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

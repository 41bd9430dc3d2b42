"""Polylines (a cable's centreline as ordered points): arc length and unit directions."""

import numpy as np

__all__ = ["arc_length", "unit"]


def arc_length(points, *, closed=False):
    """Cumulative arc length at each point of a polyline, starting at 0.

    Parameters
    ----------
    points : array_like, shape (N, D)
    closed : bool, optional
        The polyline returns to its first point: one more entry, the whole loop's length.

    Returns
    -------
    ndarray, shape (N,) or (N + 1,) when closed
    """
    points = np.asarray(points, dtype=np.float64)
    if closed:
        points = np.vstack([points, points[:1]])
    steps = np.linalg.norm(np.diff(points, axis=0), axis=1)
    return np.concatenate([[0.0], np.cumsum(steps)])


def unit(vector):
    """``vector`` scaled to length 1 (a zero vector stays zero)."""
    norm = np.linalg.norm(vector)
    return vector / norm if norm > 0 else np.zeros_like(vector)

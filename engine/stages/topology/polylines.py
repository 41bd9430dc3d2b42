"""Polylines along the cable: points at an arc position, end tangents, smooth bridges and
the bump that lifts a strand over another."""

import numpy as np

from ...geometry.polylines import arc_length

__all__ = ["at_arc", "hermite", "end_tangent", "add_bump"]


def at_arc(points, arc, s):
    """Point at arc length ``s`` along a polyline (clamped)."""
    s = min(max(s, 0.0), arc[-1])
    return np.array([np.interp(s, arc, points[:, k]) for k in range(3)])


def hermite(p0, m0, p1, m1, samples):
    """Points, first and second derivatives of a cubic Hermite curve at ``samples`` t in [0, 1]."""
    t = np.linspace(0.0, 1.0, samples)[:, None]
    h00, h10, h01, h11 = 2 * t**3 - 3 * t**2 + 1, t**3 - 2 * t**2 + t, -2 * t**3 + 3 * t**2, \
        t**3 - t**2
    points = h00 * p0 + h10 * m0 + h01 * p1 + h11 * m1
    d1 = (6 * t**2 - 6 * t) * p0 + (3 * t**2 - 4 * t + 1) * m0 + (-6 * t**2 + 6 * t) * p1 \
        + (3 * t**2 - 2 * t) * m1
    d2 = (12 * t - 6) * p0 + (6 * t - 4) * m0 + (-12 * t + 6) * p1 + (6 * t - 2) * m1
    return points, d1, d2


def end_tangent(points, context, at_start):
    """Unit direction of travel at one end of a polyline (over about 1.5 r)."""
    arc = arc_length(points)
    span = min(1.5 * context.r, arc[-1]) if len(arc) else 0.0
    if len(points) < 2 or span <= 0:
        return np.zeros(3)
    if at_start:
        d = at_arc(points, arc, span) - points[0]
    else:
        d = points[-1] - at_arc(points, arc, arc[-1] - span)
    return d / max(np.linalg.norm(d), 1e-12)


def add_bump(points, closed, index, height, width, up):
    """Add ``height`` along ``up`` at ``index``, fading (cos²) to 0 at ``width``.

    Distances are arc lengths of the horizontal projection, which the bump does not change
    (so a bump can be undone exactly).
    """
    if len(points) < 2:
        points[index] += height * up
        return
    flat = points - np.outer(points @ up, up)
    arc = arc_length(np.vstack([flat, flat[:1]]) if closed else flat)
    total = arc[-1]
    arc = arc[:len(points)]
    offset = arc - arc[index]
    if closed and total > 0:
        offset = (offset + 0.5 * total) % total - 0.5 * total
    x = np.clip(np.abs(offset) / width, 0.0, 1.0)
    points += (height * np.cos(0.5 * np.pi * x) ** 2)[:, None] * up

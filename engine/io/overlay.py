"""A reconstruction drawn over one of its frames, to check it at a glance."""

import cv2
import numpy as np

from ..geometry.polylines import arc_length

__all__ = ["draw_overlay", "draw_projected"]

_PATH, _OVER, _UNDER = (255, 220, 0), (40, 220, 40), (40, 120, 255)  # RGB


def draw_projected(image, camera, points, colour, thickness, *, line_type=cv2.LINE_AA):
    """Draw a 3D polyline's projection into ``image`` (in place), broken where it passes
    behind the camera.

    Parameters
    ----------
    image : ndarray
        The frame's size (one or three channels).
    camera : Camera
    points : array_like, shape (N, 3)
        In order; repeat the first point at the end for a closed curve.
    colour : int or tuple
    thickness : int
        Pixels.
    line_type : int, optional
        ``cv2.LINE_AA`` (smooth) or ``cv2.LINE_8`` (hard-edged, for masks).
    """
    pixels, depth = camera.project(np.asarray(points, dtype=float))
    visible = depth > 0
    # cv2 draws with 4 fractional bits; COLMAP's pixel centres are at +0.5; a point near the
    # camera's plane projects far out, kept within cv2's int32
    fixed = np.clip(np.round(np.nan_to_num(pixels - 0.5) * 16), -2 ** 30, 2 ** 30)
    fixed = fixed.astype(np.int32)
    start = 0
    for end in np.flatnonzero(~visible).tolist() + [len(fixed)]:
        if end - start >= 2:
            cv2.polylines(image, [fixed[start:end].reshape(-1, 1, 2)], False, colour,
                          thickness, line_type, shift=4)
        start = end + 1


def _stretch(path, index, span):
    """Points of ``path`` within ``span`` of arc length of sample ``index``."""
    arc = arc_length(path.points)
    return path.points[np.abs(arc - arc[index]) <= span]


def draw_overlay(image, result, camera, *, thickness=2):
    """The frame with the result's centrelines and its crossings drawn on it.

    Each path is drawn in yellow; at each crossing the upper strand is drawn in green over the
    lower one in blue, and the crossing's confidence is written beside it.

    Parameters
    ----------
    image : ndarray, shape (H, W, 3), uint8
        The frame (RGB), the size of ``camera``'s image.
    result : Result
    camera : Camera
        The frame's camera, in the result's frame.

    Returns
    -------
    ndarray
        A new RGB image.
    """
    canvas = np.ascontiguousarray(image).copy()
    for path in result.paths:
        points = np.vstack([path.points, path.points[:1]]) if path.closed else path.points
        draw_projected(canvas, camera, points, _PATH, thickness)
    span = 4.0 * result.radius
    for crossing in result.crossings:
        under = _stretch(result.paths[crossing.under.path], crossing.under.index, span)
        over = _stretch(result.paths[crossing.over.path], crossing.over.index, span)
        draw_projected(canvas, camera, under, _UNDER, thickness + 2)
        draw_projected(canvas, camera, over, _OVER, thickness + 2)
        (u, v), depth = camera.project(crossing.position)
        if depth > 0:
            cv2.putText(canvas, f"{crossing.confidence:.2f}", (int(u) + 12, int(v) - 12),
                        cv2.FONT_HERSHEY_SIMPLEX, 0.5, (255, 255, 255), 1, cv2.LINE_AA)
    return canvas

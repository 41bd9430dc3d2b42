"""An upright world frame for cameras from structure-from-motion: the table is z = 0.

Structure-from-motion leaves the world frame arbitrary (COLMAP puts it wherever its first image
pair was). A cable lies on a table that the photos look down on, so :func:`make_upright` fits that
plane to the sparse points and moves the world so that

* the table is the plane z = 0 and +z points from it towards the cameras (up),
* the table points' centroid is at x = y = 0,
* the first camera looks along +y (seen from above, it stands on the -y side, as Blender's
  front view does), so the in-plane heading is reproducible,
* lengths are unchanged (rotation and translation only: scale 1; SfM's unit stays unknown).

Without a plane (too few points close to one plane), the cameras' mean "up" direction (image
up, ``-R[1]``) becomes +z and the point the cameras look at (:func:`look_at_point`) the origin.
"""

import logging
from dataclasses import dataclass

import numpy as np

from ..settings import check_settings, setting
from .camera import look_at_point
from .similarity import Similarity

__all__ = ["UprightSettings", "fit_plane", "look_at_point", "make_upright"]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class UprightSettings:
    """Tunables of :func:`make_upright`.

    Attributes
    ----------
    plane_threshold : float
        A point belongs to the table plane when it lies within this fraction of the scene size
        of it; the scene size is the median distance from the cameras to the points' median.
    plane_min_inlier_share : float
        The plane counts as the table only if at least this share of the sparse points lies
        on it (and at least 10 points); otherwise the cameras' up direction is used.
    plane_iterations : int
        RANSAC iterations of the plane fit.
    seed : int
        Seed of the RANSAC sampling (the result is deterministic for a given seed).
    """

    plane_threshold: float = setting(0.01, above=0)
    plane_min_inlier_share: float = setting(0.4, above=0, high=1)
    plane_iterations: int = setting(500, low=1)
    seed: int = setting(0, low=0)

    def __post_init__(self):
        check_settings(self)


#: A plane needs at least this many inliers to be believed, whatever the share.
MIN_PLANE_POINTS = 10


def _scene_size(centres, points):
    if len(points) == 0:
        return 0.0
    middle = np.median(points, axis=0)
    return float(np.median(np.linalg.norm(centres - middle, axis=1)))


def _plane_through(points):
    """Least-squares plane ``(normal, offset)`` with ``normal @ x = offset``."""
    centroid = points.mean(axis=0)
    _, _, vt = np.linalg.svd(points - centroid, full_matrices=False)
    normal = vt[2]
    return normal, float(normal @ centroid)


def fit_plane(points, threshold, *, iterations=500, seed=0):
    """Fit a plane to 3D points robustly (RANSAC on 3-point samples, then least squares).

    Parameters
    ----------
    points : array_like, shape (N, 3)
    threshold : float
        Largest distance of an inlier from the plane.
    iterations : int, optional
        RANSAC samples drawn.
    seed : int, optional
        Seed of the sampling.

    Returns
    -------
    normal : ndarray, shape (3,) or None
        Unit normal (sign arbitrary); None with fewer than 3 points or all degenerate samples.
    offset : float
        The plane is ``normal @ x = offset``.
    inliers : ndarray of bool, shape (N,)
    """
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    count = len(points)
    none = (None, 0.0, np.zeros(count, dtype=bool))
    if count < 3:
        return none
    rng = np.random.default_rng(seed)
    samples = np.array([rng.choice(count, 3, replace=False) for _ in range(int(iterations))])
    a, b, c = points[samples[:, 0]], points[samples[:, 1]], points[samples[:, 2]]
    normals = np.cross(b - a, c - a)
    lengths = np.linalg.norm(normals, axis=1)
    usable = lengths > 1e-12 * max(1.0, float(np.abs(points).max()) ** 2)
    if not usable.any():
        return none
    normals = normals[usable] / lengths[usable, None]
    offsets = np.einsum("ij,ij->i", normals, a[usable])
    best, best_count = None, -1
    # Chunks keep the (samples x points) distance matrix small.
    for start in range(0, len(normals), 64):
        distances = np.abs(points @ normals[start:start + 64].T - offsets[start:start + 64])
        counts = (distances <= threshold).sum(axis=0)
        index = int(np.argmax(counts))
        if counts[index] > best_count:
            best_count, best = int(counts[index]), start + index
    normal, offset = normals[best], float(offsets[best])
    inliers = np.abs(points @ normal - offset) <= threshold
    for _ in range(3):  # refine: least squares on the inliers, then re-select them
        if inliers.sum() < 3:
            break
        normal, offset = _plane_through(points[inliers])
        refined = np.abs(points @ normal - offset) <= threshold
        if np.array_equal(refined, inliers):
            break
        inliers = refined
    return normal, offset, inliers


def _heading(cameras, up):
    """Unit vector in the plane normal to ``up``: the first camera's horizontal view direction."""
    for camera in cameras:
        for direction in (camera.R[2], -camera.R[1], camera.R[0]):
            horizontal = direction - (direction @ up) * up
            norm = np.linalg.norm(horizontal)
            if norm > 1e-3:
                return horizontal / norm
    # No camera (or all degenerate): any vector normal to up.
    helper = np.eye(3)[int(np.argmin(np.abs(up)))]
    horizontal = helper - (helper @ up) * up
    return horizontal / np.linalg.norm(horizontal)


def make_upright(cameras, points, *, settings=UprightSettings()):
    """Move the world so the table plane is z = 0 with +z up; cameras and points move along.

    Parameters
    ----------
    cameras : sequence of Camera
        The registered views (at least one).
    points : array_like, shape (M, 3)
        Sparse points in the same frame (may be empty: then no plane is found).
    settings : UprightSettings, optional

    Returns
    -------
    cameras : tuple of Camera
        The same views in the new frame (``R' = R Q^T``, ``t' = t - R' tq``).
    points : ndarray, shape (M, 3)
        ``Q @ x + tq`` for every point.
    transform : Similarity
        The move, ``x' = Q x + tq`` (scale 1).
    plane_found : bool
        True if the table plane was found; False if the cameras' up direction was used.
    """
    cameras = tuple(cameras)
    if not cameras:
        raise ValueError("make_upright needs at least one camera")
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    centres = np.array([camera.center for camera in cameras])

    size = _scene_size(centres, points)
    normal, plane_found = None, False
    if size > 0 and len(points) >= MIN_PLANE_POINTS:
        normal, offset, inliers = fit_plane(points, settings.plane_threshold * size,
                                            iterations=settings.plane_iterations,
                                            seed=settings.seed)
        share = inliers.mean() if len(points) else 0.0
        plane_found = (normal is not None and inliers.sum() >= MIN_PLANE_POINTS
                       and share >= settings.plane_min_inlier_share)
        log.info("table plane: %d of %d sparse points within %.3g (%.0f%%)%s",
                 int(inliers.sum()), len(points), settings.plane_threshold * size, 100 * share,
                 "" if plane_found else ": too few, using the cameras' up direction")
    if plane_found:
        heights = centres @ normal - offset
        if np.median(heights) < 0:  # the cameras look down on the table from above
            normal, offset = -normal, -offset
        up = normal
        origin = points[inliers].mean(axis=0)
        origin = origin - (origin @ up - offset) * up  # on the plane
    else:
        up = -np.mean([camera.R[1] for camera in cameras], axis=0)
        norm = np.linalg.norm(up)
        up = up / norm if norm > 1e-9 else np.array([0.0, 0.0, 1.0])
        origin = look_at_point(cameras)

    forward = _heading(cameras, up)
    right = np.cross(forward, up)
    rotation = np.stack([right, forward, up])  # rows: the new x, y, z axes in the old frame
    transform = Similarity(scale=1.0, R=rotation, t=-rotation @ origin)
    moved = tuple(transform.apply_camera(camera) for camera in cameras)
    return moved, transform.apply(points), transform, plane_found

"""Similarity transforms (``x -> scale * R @ x + t``) and their least-squares fits: to point
pairs (Umeyama) and to two sets of cameras of the same images."""

from dataclasses import dataclass

import numpy as np

from .arrays import as_points, read_only
from .camera import Camera, look_at_point

__all__ = ["Similarity", "align_similarity", "align_cameras"]


@dataclass(frozen=True, eq=False)
class Similarity:
    """A similarity transform ``x -> scale * R @ x + t``.

    Attributes
    ----------
    scale : float
    R : ndarray, shape (3, 3)
        A rotation (determinant +1).
    t : ndarray, shape (3,)
    """

    scale: float
    R: np.ndarray
    t: np.ndarray

    def __post_init__(self):
        rotation = read_only(self.R)
        translation = read_only(self.t).reshape(-1)
        if rotation.shape != (3, 3) or translation.shape != (3,):
            raise ValueError("a similarity needs a 3x3 R and a 3-vector t")
        if not (np.isfinite(self.scale) and self.scale > 0):
            raise ValueError(f"a similarity's scale must be positive, not {self.scale!r}")
        object.__setattr__(self, "scale", float(self.scale))
        object.__setattr__(self, "R", rotation)
        object.__setattr__(self, "t", translation)

    def apply(self, points):
        """Transform points.

        Parameters
        ----------
        points : array_like, shape (N, 3) or (3,)

        Returns
        -------
        ndarray
            Same shape as ``points``.
        """
        points = np.asarray(points, dtype=np.float64)
        return self.scale * points @ self.R.T + self.t

    def apply_camera(self, camera):
        """The camera seen in the transformed world: same image, centre moved with the world.

        With ``x' = s Rs x + ts``, the camera frame is scaled by ``s`` too, so
        ``R' = R Rs^T`` and ``t' = s t - R' ts``; its centre becomes ``s Rs c + ts``.

        Parameters
        ----------
        camera : Camera

        Returns
        -------
        Camera
        """
        rotation = camera.R @ self.R.T
        translation = self.scale * camera.t - rotation @ self.t
        return Camera(camera.name, camera.width, camera.height, camera.model, camera.params,
                      rotation, translation)


def _collinear(centred):
    singular = np.linalg.svd(centred, compute_uv=False)
    return singular[0] == 0 or singular[1] <= 1e-9 * singular[0]


def align_similarity(source_points, target_points):
    """Least-squares similarity from ``source_points`` to ``target_points`` (Umeyama 1991).

    Parameters
    ----------
    source_points, target_points : array_like, shape (N, 3)
        Corresponding points, N >= 3, not all on one line.

    Returns
    -------
    Similarity
        The ``scale``, rotation (no reflection) and translation that minimise
        ``sum |target - (scale * R @ source + t)|^2``.

    Raises
    ------
    ValueError
        Shapes differ, fewer than 3 points, or the points are collinear.
    """
    source = as_points(source_points, "source_points")
    target = as_points(target_points, "target_points")
    if source.shape != target.shape:
        raise ValueError(f"source_points {source.shape} and target_points {target.shape} "
                         "must have the same shape")
    if len(source) < 3:
        raise ValueError(f"a similarity needs at least 3 point pairs, got {len(source)}")
    mean_source, mean_target = source.mean(axis=0), target.mean(axis=0)
    source_c, target_c = source - mean_source, target - mean_target
    if _collinear(source_c) or _collinear(target_c):
        raise ValueError("a similarity needs at least 3 points that are not on one line")
    covariance = target_c.T @ source_c / len(source)
    U, D, Vt = np.linalg.svd(covariance)
    sign = np.ones(3)
    if np.linalg.det(U) * np.linalg.det(Vt) < 0:
        sign[2] = -1.0
    rotation = (U * sign) @ Vt
    variance = np.mean(np.sum(source_c ** 2, axis=1))
    scale = float(np.sum(D * sign) / variance)
    translation = mean_target - scale * rotation @ mean_source
    return Similarity(scale, rotation, translation)


def align_cameras(source, target):
    """The similarity that best maps cameras ``source`` onto ``target`` (matched by name).

    It is fitted to the cameras' centres and to the points they look at (one scene distance
    along each optical axis): centres alone leave the rotation loose by about their own error
    over the rig's size, which moves the whole scene by pixels in every view.

    Parameters
    ----------
    source, target : sequence of Camera
        At least 3 names in common.

    Returns
    -------
    Similarity
    """
    by_name = {camera.name: camera for camera in target}
    pairs = [(camera, by_name[camera.name]) for camera in source if camera.name in by_name]
    points = []
    for side in (0, 1):
        cameras = [pair[side] for pair in pairs]
        if len(cameras) < 3:
            raise ValueError("at least 3 cameras with the same names are needed")
        centres = np.array([camera.center for camera in cameras])
        distance = np.mean(np.linalg.norm(centres - look_at_point(cameras), axis=1))
        axes = np.array([camera.R[2] for camera in cameras])
        points.append(np.concatenate([centres, centres + distance * axes]))
    return align_similarity(points[0], points[1])

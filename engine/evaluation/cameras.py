"""How close estimated cameras are to the true ones of a synthetic scene or the sample."""

import numpy as np

from ..geometry.camera import look_at_point
from ..geometry.similarity import align_cameras

__all__ = ["compare_to_truth"]


def _rotation_angle(rotation):
    from scipy.spatial.transform import Rotation

    return float(np.degrees(Rotation.from_matrix(rotation).magnitude()))


def compare_to_truth(estimate, true_cameras, centreline=None):
    """How close estimated cameras are to the true ones, after a similarity alignment of their
    centres and of the points they look at.

    Parameters
    ----------
    estimate : CameraEstimate
    true_cameras : sequence of Camera
        Matched by name.
    centreline : array_like, shape (N, 3), optional
        The true cable centreline: adds ``centreline_px`` (mean) and ``centreline_max_px``,
        the distance between where the estimated cameras (after alignment) and the true ones
        put it in the images.

    Returns
    -------
    dict
        ``centre_error_pct`` (mean centre error after alignment, % of the scene size: the mean
        distance of the true cameras to the point they look at), ``centre_error_max_pct``,
        ``rotation_error_deg`` (mean), ``rotation_error_max_deg``, ``up_error_deg`` (angle
        between the true up direction, mapped into the estimate's frame, and +z) and
        ``focal_error_pct`` (mean focal length vs the true one).
    """
    truth = {camera.name: camera for camera in true_cameras}
    pairs = [(camera, truth[camera.name]) for camera in estimate.cameras if camera.name in truth]
    est_centres = np.array([camera.center for camera, _ in pairs])
    true_centres = np.array([camera.center for _, camera in pairs])
    size = float(np.mean(np.linalg.norm(true_centres - look_at_point(list(truth.values())),
                                        axis=1)))
    similarity = align_cameras([camera for camera, _ in pairs], [true for _, true in pairs])
    centre_errors = np.linalg.norm(similarity.apply(est_centres) - true_centres, axis=1) / size
    rotation_errors = [_rotation_angle(true.R @ (camera.R @ similarity.R.T).T)
                       for camera, true in pairs]
    up = similarity.R.T @ np.array([0.0, 0.0, 1.0])  # the true +z, in the estimate's frame
    focal = [abs(np.mean(camera.focal) / np.mean(true.focal) - 1.0) for camera, true in pairs]
    reprojection = {}
    if centreline is not None:
        offsets = _reprojection_offsets(pairs, similarity, np.asarray(centreline, dtype=float))
        reprojection = {"centreline_px": float(np.mean(offsets)),
                        "centreline_max_px": float(np.max(offsets))}
    return reprojection | {
        "centre_error_pct": 100.0 * float(np.mean(centre_errors)),
        "centre_error_max_pct": 100.0 * float(np.max(centre_errors)),
        "rotation_error_deg": float(np.mean(rotation_errors)),
        "rotation_error_max_deg": float(np.max(rotation_errors)),
        "up_error_deg": float(np.degrees(np.arctan2(np.linalg.norm(up[:2]), up[2]))),
        "focal_error_pct": 100.0 * float(np.mean(focal)),
    }


def _reprojection_offsets(pairs, similarity, points):
    """Pixel distances between each point's image through the estimated (aligned) and the true
    cameras, over every pair's view where it lies in the frame."""
    in_estimate = (points - similarity.t) @ similarity.R / similarity.scale
    offsets = []
    for camera, true in pairs:
        expected, depth = true.project(points)
        found, _ = camera.project(in_estimate)
        seen = ((depth > 0) & (expected[:, 0] >= 0) & (expected[:, 0] < true.width)
                & (expected[:, 1] >= 0) & (expected[:, 1] < true.height))
        offsets.append(np.linalg.norm(found[seen] - expected[seen], axis=1))
    return np.concatenate(offsets)

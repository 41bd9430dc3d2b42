"""Camera paths around a synthetic cable: an orbit, or a hand-held-like arc.

Every camera is a square-pixel PINHOLE looking at the cable, framed so the whole cable fits in
the image (or, with ``framing`` under 1, closer and aimed around it, so that parts of the cable
leave some frames: :func:`out_of_frame` tells how often); :func:`cable_pixel_width` tells how
thick the cable appears.
"""

import math

import numpy as np

from ..geometry.camera import Camera

__all__ = ["orbit_cameras", "handheld_cameras", "cable_pixel_width", "out_of_frame"]


def _look_at(center, target, up=(0.0, 0.0, 1.0), roll=0.0):
    forward = np.asarray(target, dtype=float) - center
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, up)
    right /= np.linalg.norm(right)
    down = np.cross(forward, right)
    R = np.stack([right, down, forward])
    if roll:
        c, s = math.cos(roll), math.sin(roll)
        R = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]) @ R
    return R, -R @ center


def _framing(truth, width, height, focal):
    """Target point and viewing distance that keep the cable's bounding sphere in view."""
    points = truth.centreline
    target = 0.5 * (points.min(axis=0) + points.max(axis=0))
    reach = np.linalg.norm(points - target, axis=1).max() + truth.radius
    half_fov = math.atan(0.5 * min(width, height) / focal)
    return target, 1.08 * reach / math.sin(half_fov)


def _camera(name, width, height, focal, R, t):
    return Camera(name=name, width=width, height=height, model="PINHOLE",
                  params=[focal, focal, width / 2.0, height / 2.0], R=R, t=t)


def _aims(rng, views, target, reach, framing):
    """Per view, the point looked at: the target, or with ``framing`` under 1 a point around
    it (up to ``1 - framing`` of the cable's reach away in the table plane, turning slowly
    from view to view as a hand-held camera's aim does)."""
    if framing >= 1.0:
        return [target] * views
    phase = rng.uniform(0.0, 2 * math.pi, size=2)
    aims = []
    for k in range(views):
        s = 2 * math.pi * k / views
        offset = np.array([math.sin(2 * s + phase[0]), math.sin(3 * s + phase[1]), 0.0])
        aims.append(target + (1.0 - framing) * reach * offset)
    return aims


def _framed(truth, width, height, focal, framing, rng, views):
    """The target, the viewing distance (``framing`` times the whole cable's) and each view's
    aim (:func:`_aims`)."""
    if not 0.2 <= framing <= 1.0:
        raise ValueError("framing must lie between 0.2 and 1")
    target, distance = _framing(truth, width, height, focal)
    aims = _aims(rng, views, target,
                 distance * math.sin(math.atan(0.5 * min(width, height) / focal)), framing)
    return target, framing * distance, aims


def orbit_cameras(truth, *, views=30, width=960, height=720, elevations=(45.0, 75.0),
                  focal=None, name_format="{:03d}.png", seed=0, framing=1.0):
    """Cameras on a ring around the cable, looking at its centre.

    Parameters
    ----------
    truth : GroundTruth
    views : int, optional
        10 to 60.
    width, height : int, optional
        Image size.
    elevations : (float, float), optional
        Degrees above the table; the views alternate between both ends of the range.
    focal : float, optional
        Pixels; ``1.1 * width`` if None.
    name_format : str, optional
        Image file name of view ``k``.
    seed : int, optional
        Seeds a small jitter of azimuth and elevation.
    framing : float, optional
        The share of the cable's bounding sphere's radius a view holds: 1 frames the whole
        cable; under 1 the cameras come that much closer and aim around the cable
        (:func:`_aims`), so parts of it leave some frames.

    Returns
    -------
    tuple of Camera
    """
    focal = 1.1 * width if focal is None else float(focal)
    rng = np.random.default_rng([seed, views, 5])
    _, distance, aims = _framed(truth, width, height, focal, framing,
                                np.random.default_rng([seed, views, 6]), views)
    low, high = elevations
    cameras = []
    for k in range(views):
        azimuth = 2 * math.pi * k / views + rng.normal(0.0, 0.3 / views)
        fraction = 0.5 + 0.5 * math.sin(3 * 2 * math.pi * k / views)  # three up-down swings
        elevation = math.radians(low + (high - low) * fraction + rng.normal(0.0, 1.0))
        center = aims[k] + distance * np.array([math.cos(azimuth) * math.cos(elevation),
                                                math.sin(azimuth) * math.cos(elevation),
                                                math.sin(elevation)])
        R, t = _look_at(center, aims[k])
        cameras.append(_camera(name_format.format(k), width, height, focal, R, t))
    return tuple(cameras)


def handheld_cameras(truth, *, views=30, width=960, height=720, arc_degrees=240.0,
                     elevations=(40.0, 70.0), focal=None, name_format="{:03d}.png", seed=0,
                     framing=1.0):
    """Cameras along a partial arc with the wobble of a hand-held phone.

    Distance, height, aim and roll vary smoothly from view to view, as in a video walked
    around a table.

    Parameters
    ----------
    truth : GroundTruth
    views : int, optional
    width, height : int, optional
    arc_degrees : float, optional
        How far around the cable the path goes.
    elevations : (float, float), optional
        Degrees above the table.
    focal : float, optional
        Pixels; ``1.1 * width`` if None.
    name_format : str, optional
    seed : int, optional
    framing : float, optional
        As :func:`orbit_cameras`.

    Returns
    -------
    tuple of Camera
    """
    focal = 1.1 * width if focal is None else float(focal)
    rng = np.random.default_rng([seed, views, 9])
    target, distance, around = _framed(truth, width, height, focal, framing,
                                       np.random.default_rng([seed, views, 10]), views)
    start = rng.uniform(0.0, 2 * math.pi)
    phases = rng.uniform(0.0, 2 * math.pi, size=4)
    low, high = elevations
    reach = distance * math.sin(math.atan(0.5 * min(width, height) / focal))
    cameras = []
    for k in range(views):
        s = k / max(views - 1, 1)
        azimuth = start + math.radians(arc_degrees) * s
        elevation = math.radians(low + (high - low) * (0.5 + 0.5 * math.sin(2 * math.pi * s
                                                                            + phases[0])))
        scale = 1.0 + 0.08 * math.sin(3 * math.pi * s + phases[1])
        center = target + scale * distance * np.array([
            math.cos(azimuth) * math.cos(elevation), math.sin(azimuth) * math.cos(elevation),
            math.sin(elevation)])
        aim = around[k] + 0.05 * reach * np.array([math.sin(5 * s + phases[2]),
                                                   math.cos(4 * s + phases[3]), 0.0])
        roll = math.radians(4.0 * math.sin(4 * math.pi * s + phases[2]))
        R, t = _look_at(center, aim, roll=roll)
        cameras.append(_camera(name_format.format(k), width, height, focal, R, t))
    return tuple(cameras)


def cable_pixel_width(truth, cameras):
    """Thinnest apparent cable diameter, in pixels, over every view and centreline sample.

    Parameters
    ----------
    truth : GroundTruth
    cameras : sequence of Camera

    Returns
    -------
    float
    """
    thinnest = math.inf
    for camera in cameras:
        depth = camera.world_to_camera(truth.centreline)[:, 2]
        fx, fy = camera.focal
        thinnest = min(thinnest, float((2.0 * truth.radius * min(fx, fy) / depth).min()))
    return thinnest


def out_of_frame(truth, cameras):
    """Per centreline sample, the share of the views in whose frame it does not lie.

    Parameters
    ----------
    truth : GroundTruth
    cameras : sequence of Camera

    Returns
    -------
    ndarray, shape (N,)
    """
    outside = np.zeros(len(truth.centreline))
    for camera in cameras:
        pixels, depth = camera.project(truth.centreline)
        inside = (depth > 0) & (pixels[:, 0] >= 0) & (pixels[:, 0] < camera.width) \
            & (pixels[:, 1] >= 0) & (pixels[:, 1] < camera.height)
        outside += ~inside
    return outside / max(len(cameras), 1)

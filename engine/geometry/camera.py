"""The engine's camera: COLMAP intrinsics and an OpenCV/COLMAP world-to-camera pose.

Conventions (the same as COLMAP and the result JSON):

* ``R, t`` map world to camera: ``x_cam = R @ x_world + t``; the camera looks along +z, with
  +x to the right and +y down in the image; its centre is ``-R.T @ t``.
* ``params`` are ordered as COLMAP orders them for ``model`` (see :data:`CAMERA_MODELS`).
* Image coordinates are COLMAP's: the top-left corner of the image is (0, 0), so the centre
  of the pixel in row ``i``, column ``j`` is ``(j + 0.5, i + 0.5)``.
"""

from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from .arrays import read_only

__all__ = ["CAMERA_MODELS", "Camera", "look_at_point"]

#: Supported COLMAP camera models and the names of their parameters, in COLMAP's order.
CAMERA_MODELS = {
    "SIMPLE_PINHOLE": ("f", "cx", "cy"),
    "PINHOLE": ("fx", "fy", "cx", "cy"),
    "SIMPLE_RADIAL": ("f", "cx", "cy", "k"),
    "RADIAL": ("f", "cx", "cy", "k1", "k2"),
    "OPENCV": ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2"),
}


@dataclass(frozen=True, eq=False)
class Camera:
    """One calibrated view: intrinsics, world-to-camera pose and the image it belongs to.

    Parameters
    ----------
    name : str
        Image file name (no folder), as in the COLMAP model.
    width, height : int
        Image size in pixels.
    model : str
        A key of :data:`CAMERA_MODELS`.
    params : array_like
        Intrinsic parameters in COLMAP's order for ``model``.
    R : array_like, shape (3, 3)
        World-to-camera rotation.
    t : array_like, shape (3,)
        World-to-camera translation.
    """

    name: str
    width: int
    height: int
    model: str
    params: np.ndarray
    R: np.ndarray
    t: np.ndarray

    def __post_init__(self):
        if self.model not in CAMERA_MODELS:
            raise InputError(
                f"camera {self.name!r}: model {self.model!r} is not supported "
                f"(use one of {', '.join(CAMERA_MODELS)})"
            )
        params = read_only(self.params).reshape(-1)
        expected = len(CAMERA_MODELS[self.model])
        if params.size != expected:
            raise InputError(
                f"camera {self.name!r}: model {self.model} takes {expected} parameters "
                f"({', '.join(CAMERA_MODELS[self.model])}), got {params.size}"
            )
        rotation = read_only(self.R)
        translation = read_only(self.t).reshape(-1)
        if rotation.shape != (3, 3) or translation.shape != (3,):
            raise InputError(f"camera {self.name!r}: R must be 3x3 and t must have 3 values")
        if not (np.all(np.isfinite(params)) and np.all(np.isfinite(rotation))
                and np.all(np.isfinite(translation))):
            raise InputError(f"camera {self.name!r}: parameters and pose must be finite numbers")
        if (np.abs(rotation).max() > 1.0 + 1e-6  # (a rotation's entries; no overflow below)
                or np.abs(rotation @ rotation.T - np.eye(3)).max() > 1e-6
                or np.linalg.det(rotation) < 0):
            raise InputError(f"camera {self.name!r}: R is not a rotation matrix")
        if int(self.width) <= 0 or int(self.height) <= 0:
            raise InputError(f"camera {self.name!r}: width and height must be positive")
        object.__setattr__(self, "width", int(self.width))
        object.__setattr__(self, "height", int(self.height))
        object.__setattr__(self, "params", params)
        object.__setattr__(self, "R", rotation)
        object.__setattr__(self, "t", translation)

    # -- intrinsics -------------------------------------------------------------------------
    @property
    def focal(self):
        """Focal lengths ``(fx, fy)`` in pixels."""
        p = self.params
        return (p[0], p[1]) if self.model in ("PINHOLE", "OPENCV") else (p[0], p[0])

    @property
    def principal_point(self):
        """Principal point ``(cx, cy)`` in COLMAP image coordinates."""
        p = self.params
        return (p[2], p[3]) if self.model in ("PINHOLE", "OPENCV") else (p[1], p[2])

    @property
    def distortion(self):
        """OpenCV distortion coefficients ``(k1, k2, p1, p2)`` (zeros for pinhole models)."""
        p = self.params
        if self.model == "SIMPLE_RADIAL":
            return np.array([p[3], 0.0, 0.0, 0.0])
        if self.model == "RADIAL":
            return np.array([p[3], p[4], 0.0, 0.0])
        if self.model == "OPENCV":
            return np.array(p[4:8])
        return np.zeros(4)

    @property
    def K(self):
        """3x3 calibration matrix (distortion not included)."""
        (fx, fy), (cx, cy) = self.focal, self.principal_point
        return np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])

    @property
    def center(self):
        """Camera centre in world coordinates, ``-R.T @ t``."""
        return -self.R.T @ self.t

    # -- projection -------------------------------------------------------------------------
    def world_to_camera(self, points):
        """Transform world points ``(N, 3)`` into this camera's frame."""
        points = np.asarray(points, dtype=np.float64)
        return points @ self.R.T + self.t

    def project(self, points):
        """Project world points into the image, distortion included.

        Parameters
        ----------
        points : array_like, shape (N, 3) or (3,)
            World coordinates.

        Returns
        -------
        pixels : ndarray, shape (N, 2) or (2,)
            COLMAP image coordinates; NaN for points not in front of the camera.
        depth : ndarray, shape (N,) or ()
            Distance along the optical axis (``z`` in the camera frame).
        """
        points = np.asarray(points, dtype=np.float64)
        single = points.ndim == 1
        cam = self.world_to_camera(points.reshape(-1, 3))
        depth = cam[:, 2]
        pixels = np.stack(self.image_coordinates(cam[:, 0], cam[:, 1], depth), axis=1)
        if single:
            return pixels[0], depth[0]
        return pixels, depth

    def image_coordinates(self, x, y, z):
        """Image coordinates ``(u, v)`` of points given in the camera frame, distortion included.

        Works on arrays of any float dtype (float32 keeps it); NaN where ``z <= 0``.
        """
        with np.errstate(divide="ignore", invalid="ignore"):
            u = np.where(z > 0, x / z, np.nan).astype(x.dtype, copy=False)
            v = np.where(z > 0, y / z, np.nan).astype(x.dtype, copy=False)
        k1, k2, p1, p2 = self.distortion
        if k1 or k2 or p1 or p2:
            r2 = u * u + v * v
            radial = k1 * r2 + k2 * r2 * r2
            du = u * radial + 2.0 * p1 * u * v + p2 * (r2 + 2.0 * u * u)
            dv = v * radial + 2.0 * p2 * u * v + p1 * (r2 + 2.0 * v * v)
            u, v = u + du, v + dv
        (fx, fy), (cx, cy) = self.focal, self.principal_point
        return (fx * u + cx).astype(x.dtype, copy=False), (fy * v + cy).astype(x.dtype, copy=False)

    # -- serialisation ----------------------------------------------------------------------
    def to_dict(self):
        """The camera as a JSON-ready dict (the result format's ``cameras`` entry)."""
        return {
            "name": self.name,
            "width": self.width,
            "height": self.height,
            "model": self.model,
            "params": self.params.tolist(),
            "K": self.K.tolist(),
            "R": self.R.tolist(),
            "t": self.t.tolist(),
            "center": self.center.tolist(),
        }

    @classmethod
    def from_dict(cls, data):
        """Build a camera from :meth:`to_dict` output (``K`` and ``center`` are derived).

        Raises
        ------
        InputError
            A field is missing or has the wrong type or shape.
        """
        if not isinstance(data, dict):
            raise InputError("a camera must be a JSON object")
        missing = [key for key in ("name", "width", "height", "model", "params", "R", "t")
                   if key not in data]
        if missing:
            raise InputError(f"camera is missing {', '.join(missing)}")
        name = data["name"]
        if not isinstance(name, str) or not name:
            raise InputError("camera name must be a non-empty string")
        try:
            params = np.asarray(data["params"], dtype=np.float64)
            rotation = np.asarray(data["R"], dtype=np.float64)
            translation = np.asarray(data["t"], dtype=np.float64)
        except (TypeError, ValueError):
            raise InputError(f"camera {name!r}: params, R and t must be numbers") from None
        for key in ("width", "height"):
            if not isinstance(data[key], int) or isinstance(data[key], bool):
                raise InputError(f"camera {name!r}: {key} must be an integer")
        return cls(name=name, width=data["width"], height=data["height"],
                   model=str(data["model"]), params=params, R=rotation, t=translation)


def look_at_point(cameras):
    """The point nearest (least squares) to all cameras' optical axes.

    Parameters
    ----------
    cameras : sequence of Camera

    Returns
    -------
    ndarray, shape (3,)
        Where the cameras look; the centres' mean if the axes are (nearly) parallel.
    """
    centres = np.array([camera.center for camera in cameras], dtype=np.float64).reshape(-1, 3)
    if len(centres) == 0:
        raise ValueError("look_at_point needs at least one camera")
    system, rhs = np.zeros((3, 3)), np.zeros(3)
    for camera, centre in zip(cameras, centres):
        axis = camera.R[2]
        projector = np.eye(3) - np.outer(axis, axis)
        system += projector
        rhs += projector @ centre
    eigenvalues = np.linalg.eigvalsh(system)
    if eigenvalues[0] < 1e-6 * max(eigenvalues[-1], 1e-300):
        return centres.mean(axis=0)
    return np.linalg.solve(system, rhs)

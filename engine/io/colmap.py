"""COLMAP models in and out, through pycolmap (text or binary, as COLMAP writes them).

A model holds the registered cameras (:class:`~engine.geometry.camera.Camera`, one per image) and
the sparse 3D points; the world frame is the model's own.
"""

import os
import re
import shutil
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..geometry.camera import CAMERA_MODELS, Camera

__all__ = ["ColmapModel", "read_colmap_model", "write_colmap_model", "natural_key"]

_MODEL_FILES = ("cameras", "images", "points3D", "rigs", "frames")


def natural_key(name):
    """Sort key that orders ``frame2`` before ``frame10``."""
    return [int(part) if part.isdigit() else part.lower() for part in re.split(r"(\d+)", name)]


@dataclass(frozen=True, eq=False)
class ColmapModel:
    """Registered cameras and sparse points of a COLMAP model.

    Attributes
    ----------
    cameras : tuple of Camera
        One per registered image, in natural order of the image names.
    points : ndarray, shape (M, 3)
        Sparse 3D points (may be empty).
    """

    cameras: tuple
    points: np.ndarray

    def camera(self, name):
        """The camera of image ``name``; :class:`KeyError` if it is not registered."""
        for camera in self.cameras:
            if camera.name == name:
                return camera
        raise KeyError(name)


def _clean_colmap_message(error):
    # pycolmap prefixes its messages with "[file.cc:123] "; users do not need that.
    return re.sub(r"^\[[^\]]*\]\s*", "", str(error)).strip()


def _model_kind(folder):
    if (folder / "cameras.bin").is_file() and (folder / "images.bin").is_file():
        return "binary"
    if (folder / "cameras.txt").is_file() and (folder / "images.txt").is_file():
        return "text"
    return None


def _load_reconstruction(folder):
    """pycolmap's reader, also for models without points3D (which pycolmap insists on)."""
    import pycolmap

    suffix = ".bin" if _model_kind(folder) == "binary" else ".txt"
    if (folder / f"points3D{suffix}").is_file():
        return pycolmap.Reconstruction(str(folder))
    with tempfile.TemporaryDirectory(prefix="colmap_model_") as staging:
        staging = Path(staging)
        for stem in _MODEL_FILES:
            if (folder / f"{stem}{suffix}").is_file():
                os.symlink((folder / f"{stem}{suffix}").resolve(), staging / f"{stem}{suffix}")
        # An empty point list: no lines of text, or a zero uint64 count in binary.
        (staging / f"points3D{suffix}").write_bytes(b"" if suffix == ".txt" else bytes(8))
        return pycolmap.Reconstruction(str(staging))


def read_colmap_model(folder):
    """Read a COLMAP text or binary model with pycolmap.

    Parameters
    ----------
    folder : str or os.PathLike
        Folder holding ``cameras`` and ``images`` (and optionally ``points3D``, ``rigs``,
        ``frames``) as ``.txt`` or ``.bin`` files.

    Returns
    -------
    ColmapModel

    Raises
    ------
    InputError
        The folder is missing, holds no model, the model is malformed, uses a camera model
        that is not supported, or registers no image. The message names the folder.
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise InputError(f"COLMAP model folder {folder} does not exist")
    if _model_kind(folder) is None:
        raise InputError(
            f"{folder} holds no COLMAP model (expected cameras.txt and images.txt, "
            "or cameras.bin and images.bin)"
        )
    try:
        reconstruction = _load_reconstruction(folder)
    except (ValueError, RuntimeError) as error:
        raise InputError(
            f"COLMAP model in {folder} is malformed: {_clean_colmap_message(error)}"
        ) from None
    except (IndexError, KeyError):  # pycolmap's std::out_of_range ("unordered_map::at")
        raise InputError(
            f"COLMAP model in {folder} is malformed: a line is cut short or refers to a "
            "camera, image or point that the model does not hold"
        ) from None
    cameras = []
    for image in reconstruction.images.values():
        if not image.has_pose:
            continue
        intrinsics = reconstruction.cameras[image.camera_id]
        if intrinsics.model.name not in CAMERA_MODELS:
            raise InputError(
                f"COLMAP model in {folder}: image {image.name} uses camera model "
                f"{intrinsics.model.name}, which is not supported "
                f"(use one of {', '.join(CAMERA_MODELS)})"
            )
        pose = image.cam_from_world().matrix()
        try:
            cameras.append(Camera(
                name=image.name, width=intrinsics.width, height=intrinsics.height,
                model=intrinsics.model.name, params=np.array(intrinsics.params),
                R=pose[:, :3], t=pose[:, 3],
            ))
        except InputError as error:
            raise InputError(f"COLMAP model in {folder}: {error}") from None
    if not cameras:
        raise InputError(f"COLMAP model in {folder} has no registered image")
    cameras.sort(key=lambda camera: natural_key(camera.name))
    points = np.array([point.xyz for point in reconstruction.points3D.values()],
                      dtype=np.float64).reshape(-1, 3)
    return ColmapModel(cameras=tuple(cameras), points=points)


def write_colmap_model(folder, cameras, *, points=None, binary=False, overwrite=False):
    """Write cameras (and sparse points) as a COLMAP model with pycolmap.

    Cameras with identical intrinsics share one COLMAP camera, as structure-from-motion with
    shared intrinsics writes them. Files appear all at once (written beside, then moved in).

    Parameters
    ----------
    folder : str or os.PathLike
        Destination folder; created if missing.
    cameras : sequence of Camera
        The views, with unique image names.
    points : array_like, shape (M, 3), optional
        Sparse points, written with empty tracks.
    binary : bool, optional
        Write ``.bin`` files instead of ``.txt``.
    overwrite : bool, optional
        Replace a model already in ``folder``; without it :class:`FileExistsError` is raised.

    Returns
    -------
    pathlib.Path
        The folder written.
    """
    import pycolmap

    folder = Path(folder)
    cameras = list(cameras)
    if not cameras:
        raise ValueError("write_colmap_model needs at least one camera")
    names = [camera.name for camera in cameras]
    if len(set(names)) != len(names):
        raise ValueError("camera names must be unique")
    folder.mkdir(parents=True, exist_ok=True)
    if not overwrite and _model_kind(folder) is not None:
        raise FileExistsError(f"{folder} already holds a COLMAP model "
                              "(pass overwrite to replace it)")

    reconstruction = pycolmap.Reconstruction()
    intrinsics_ids = {}
    for image_id, camera in enumerate(cameras, start=1):
        key = (camera.model, camera.width, camera.height, tuple(camera.params))
        if key not in intrinsics_ids:
            camera_id = len(intrinsics_ids) + 1
            intrinsics = pycolmap.Camera.create_from_model_name(
                camera_id, camera.model, float(camera.focal[0]), camera.width, camera.height)
            intrinsics.params = camera.params
            reconstruction.add_camera_with_trivial_rig(intrinsics)
            intrinsics_ids[key] = camera_id
        image = pycolmap.Image(name=camera.name, camera_id=intrinsics_ids[key], image_id=image_id)
        pose = pycolmap.Rigid3d(pycolmap.Rotation3d(camera.R), camera.t)
        reconstruction.add_image_with_trivial_frame(image, pose)
    if points is not None:
        for xyz in np.asarray(points, dtype=np.float64).reshape(-1, 3):
            reconstruction.add_point3D(xyz, pycolmap.Track())

    staging = Path(tempfile.mkdtemp(prefix=".colmap.", dir=folder))
    try:
        if binary:
            reconstruction.write_binary(str(staging))
        else:
            reconstruction.write_text(str(staging))
        # Remove the other flavour so the folder holds exactly one model.
        for stem in _MODEL_FILES:
            for suffix in (".txt", ".bin"):
                stale = folder / f"{stem}{suffix}"
                if stale.is_file() and not (staging / stale.name).is_file():
                    stale.unlink()
        for written in staging.iterdir():
            os.replace(written, folder / written.name)
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    return folder

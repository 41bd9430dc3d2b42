"""``python -m engine cameras``: estimate a folder's cameras and write them as a COLMAP model."""

from pathlib import Path

from ..errors import InputError, OutputError
from ..geometry.upright import UprightSettings
from ..io.colmap import write_colmap_model
from ..io.files import check_writable
from ..io.image_sequence import open_image_sequence
from ..stages.cameras import CameraEstimationSettings, estimate_cameras

__all__ = ["cameras_command"]


def cameras_command(images_dir, output_dir, *, overwrite=False, progress=None,
                    settings=CameraEstimationSettings(), upright=UprightSettings(), cancel=None):
    """Estimate the cameras of a folder of frames and write them as a COLMAP text model.

    What ``python -m engine cameras IMAGES_DIR -o MODEL_DIR`` does.

    Parameters
    ----------
    images_dir : str or os.PathLike
        Folder of .jpg/.jpeg/.png frames, in natural order of their names.
    output_dir : str or os.PathLike
        Model folder (created if missing); gets cameras.txt, images.txt and points3D.txt.
    overwrite : bool, optional
        Replace a model already in ``output_dir``.
    progress : callable, optional
        ``progress(fraction, message)``.
    settings : CameraEstimationSettings, optional
    upright : UprightSettings, optional
    cancel : threading.Event, optional

    Returns
    -------
    CameraEstimate

    Raises
    ------
    InputError
        The folder is missing or holds no images, or ``output_dir`` already holds a model and
        ``overwrite`` is off, or cannot be written (:class:`.OutputError`; checked before
        any work).
    ReconstructionError
        Too few frames registered.
    """
    output = Path(output_dir)
    if not overwrite and any((output / f"{stem}{suffix}").is_file()
                             for stem in ("cameras", "images") for suffix in (".txt", ".bin")):
        raise InputError(f"{output} already holds a COLMAP model (use --overwrite to replace it)")
    check_writable(output, created=True)
    with open_image_sequence(images_dir) as sequence:
        estimate = estimate_cameras(list(sequence.paths), settings=settings,
                                    focal_length_px=sequence.focal_length_px,
                                    progress=progress, cancel=cancel, upright=upright)
    try:
        write_colmap_model(output, estimate.cameras, points=estimate.points, overwrite=overwrite)
    except FileExistsError as error:
        raise InputError(str(error)) from None
    except OSError as error:  # a full disk
        raise OutputError(f"cannot write the model in {output}: {error.strerror or error}") \
            from None
    return estimate

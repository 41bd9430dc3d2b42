"""Image sequences: a folder of frames, or a video sampled to frames, checked before any work.

Every problem a user can have with the input gets a one-line :class:`InputError` naming the
file: a missing or empty folder, a file that is not an image, a truncated JPEG (which the
decoder would fill with grey and only warn about), frames of different sizes.
"""

import logging
import shutil
import tempfile
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from ..errors import InputError
from .colmap import natural_key

__all__ = ["IMAGE_SUFFIXES", "VIDEO_SUFFIXES", "IMREAD_FRAME", "ImageSequence", "frame_files",
           "open_image_sequence", "read_image"]

IMAGE_SUFFIXES = (".jpg", ".jpeg", ".png")
VIDEO_SUFFIXES = (".mp4", ".mov", ".m4v", ".avi", ".mkv", ".webm")
log = logging.getLogger(__name__)


#: How frames are decoded: colour, and the stored pixel grid whatever a phone's EXIF
#: orientation says (pycolmap reads that grid, so masks and cameras agree on it).
IMREAD_FRAME = cv2.IMREAD_COLOR | cv2.IMREAD_IGNORE_ORIENTATION


def read_image(path):
    """Read an image file as RGB uint8, in its stored pixel grid (EXIF orientation ignored,
    as pycolmap does); :class:`InputError` naming the file if it cannot be."""
    data = cv2.imread(str(path), IMREAD_FRAME)
    if data is None:
        raise InputError(f"{path} cannot be read as an image")
    return cv2.cvtColor(data, cv2.COLOR_BGR2RGB)


def jpeg_is_complete(data):
    """Whether JPEG bytes hold their whole image: the end-of-image marker follows the first
    scan. (The decoder fills a truncated file's missing rows with grey and only warns.)

    The marker segments before the scan are walked by their lengths, so an embedded
    thumbnail's end marker does not count; within the scan a 0xFF byte is always followed by
    0x00 or a restart marker, so the first 0xFFD9 there is the image's end. Data after it
    (a phone's appended video) is allowed.
    """
    if data[:2] != b"\xff\xd8":
        return False
    position = 2
    while position + 4 <= len(data):
        if data[position] != 0xFF:
            return False
        marker = data[position + 1]
        if marker == 0xFF:  # fill byte
            position += 1
            continue
        if marker == 0xD9:  # end of image before any scan
            return False
        length = int.from_bytes(data[position + 2:position + 4], "big")
        if marker == 0xDA:  # start of scan
            return data.find(b"\xff\xd9", position + 2 + length) >= 0
        position += 2 + length
    return False


@dataclass(frozen=True, eq=False)
class ImageSequence:
    """The frames of one capture, all the same size, in order.

    Attributes
    ----------
    source : pathlib.Path
        The folder or video the user gave.
    paths : tuple of pathlib.Path
        One image file per frame (for a video: frames extracted into ``work_dir``).
    width, height : int
    focal_length_px : float or None
        Focal length from the frames' EXIF data (35 mm equivalent scaled to the image), if any.
    work_dir : pathlib.Path or None
        Where a video's frames were extracted; removed by :meth:`close`.
    """

    source: Path
    paths: tuple
    width: int
    height: int
    focal_length_px: float = None
    work_dir: Path = None

    def __len__(self):
        return len(self.paths)

    @property
    def names(self):
        """Frame file names, as cameras and masks are named."""
        return tuple(path.name for path in self.paths)

    def read(self, index):
        """Frame ``index`` as an RGB uint8 array."""
        return read_image(self.paths[index])

    def close(self):
        """Remove extracted video frames (a folder of images is left alone)."""
        if self.work_dir is not None:
            shutil.rmtree(self.work_dir, ignore_errors=True)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def _exif_focal_length(path, width, height):
    """Focal length in pixels from EXIF, through pycolmap's reader; None without EXIF."""
    try:
        import pycolmap

        camera = pycolmap.infer_camera_from_image(str(path))
    except Exception:  # no EXIF reader or unreadable metadata: no prior, not an error
        return None
    if not camera.has_prior_focal_length or (camera.width, camera.height) != (width, height):
        return None
    return float(camera.mean_focal_length())


def _extract_video(video, frames, work_dir):
    capture = cv2.VideoCapture(str(video))
    if not capture.isOpened():
        raise InputError(f"{video} cannot be read as a video")
    try:
        count = int(capture.get(cv2.CAP_PROP_FRAME_COUNT))
        if count <= 0:
            raise InputError(f"{video} holds no frames")
        wanted = np.unique(np.linspace(0, count - 1, min(frames, count)).round().astype(int))
        paths = []
        for number in wanted:
            capture.set(cv2.CAP_PROP_POS_FRAMES, int(number))
            ok, frame = capture.read()
            if not ok:
                continue
            path = work_dir / f"frame_{number:06d}.jpg"
            cv2.imwrite(str(path), frame, [cv2.IMWRITE_JPEG_QUALITY, 95])
            paths.append(path)
    finally:
        capture.release()
    if not paths:
        raise InputError(f"{video}: no frame could be decoded")
    return paths


def frame_files(folder):
    """The .jpg/.png files in ``folder``, in natural order (``frame2`` before ``frame10``;
    their contents unchecked)."""
    return sorted((p for p in Path(folder).iterdir()
                   if p.is_file() and p.suffix.lower() in IMAGE_SUFFIXES),
                  key=lambda p: natural_key(p.name))


def open_image_sequence(source, *, video_frames=40, work_dir=None):
    """Open a folder of frames (natural order) or a video (sampled evenly) and check it.

    Parameters
    ----------
    source : str or os.PathLike
        A folder of .jpg/.jpeg/.png frames, or a video file.
    video_frames : int, optional
        How many frames to take from a video.
    work_dir : str or os.PathLike, optional
        Where to put a video's frames; a temporary folder (removed by ``close``) if None.

    Returns
    -------
    ImageSequence

    Raises
    ------
    InputError
        Missing source, no frames, an unreadable frame, frames of different sizes.
    """
    source = Path(source)
    extracted = None
    if source.is_file() and source.suffix.lower() in VIDEO_SUFFIXES:
        if work_dir is None:
            extracted = Path(tempfile.mkdtemp(prefix="cable_recon_frames_"))
        else:
            extracted = Path(work_dir)
            extracted.mkdir(parents=True, exist_ok=True)
        try:
            paths = _extract_video(source, video_frames, extracted)
        except BaseException:
            if work_dir is None:
                shutil.rmtree(extracted, ignore_errors=True)
            raise
    elif source.is_dir():
        paths = frame_files(source)
        if not paths:
            raise InputError(f"{source} holds no .jpg or .png images")
    elif source.exists():
        raise InputError(f"{source} is neither a folder of images nor a video "
                         f"({', '.join(VIDEO_SUFFIXES)})")
    else:
        raise InputError(f"{source} does not exist")

    size = None
    for path in paths:
        data = np.fromfile(path, dtype=np.uint8)
        if path.suffix.lower() in (".jpg", ".jpeg") and data[:2].tobytes() == b"\xff\xd8" \
                and not jpeg_is_complete(data.tobytes()):
            raise InputError(f"{path} is truncated or corrupt: its JPEG data ends before the "
                             "image does")
        image = cv2.imdecode(data, cv2.IMREAD_UNCHANGED) if data.size else None
        if image is None:
            raise InputError(f"{path} cannot be read as an image")
        shape = (image.shape[1], image.shape[0])
        if size is None:
            size, first = shape, path
        elif shape != size:
            raise InputError(f"{path} is {shape[0]}x{shape[1]} but {first.name} is "
                             f"{size[0]}x{size[1]}: all frames must have the same size")
    focal = _exif_focal_length(paths[0], *size)
    log.info("%d frames of %dx%d from %s", len(paths), size[0], size[1], source)
    return ImageSequence(source=source, paths=tuple(paths), width=size[0], height=size[1],
                         focal_length_px=focal, work_dir=extracted if work_dir is None else None)

"""``python -m engine segment``: masks and junction maps of every frame, to check a capture."""

import logging
from pathlib import Path

import cv2
import numpy as np

from .errors import InputError
from .image_sequence import open_image_sequence
from .segmentation import SegmentationSettings, auto_colour, segment_frame

__all__ = ["segment_sequence_to_folder", "contact_sheet"]

log = logging.getLogger(__name__)


def contact_sheet(thumbnails, columns=6):
    """Tile RGB thumbnails of equal size into one image."""
    rows = -(-len(thumbnails) // columns)
    height, width = thumbnails[0].shape[:2]
    sheet = np.full((rows * height, columns * width, 3), 32, np.uint8)
    for k, thumbnail in enumerate(thumbnails):
        r, c = divmod(k, columns)
        sheet[r * height:(r + 1) * height, c * width:(c + 1) * width] = thumbnail
    return sheet


def _overlay(image, segmentation, width=240):
    shown = (image * 0.45).astype(np.uint8)
    shown[segmentation.mask] = (40, 200, 40)
    shown[segmentation.junctions] = (255, 220, 0)
    height = round(width * image.shape[0] / image.shape[1])
    return cv2.resize(shown, (width, height), interpolation=cv2.INTER_AREA)


def segment_sequence_to_folder(images, output, *, colour=None, settings=SegmentationSettings(),
                               reference_frame=0, overwrite=False, progress=None):
    """Segment every frame and write ``masks/``, ``junctions/`` and ``contact_sheet.png``.

    Parameters
    ----------
    images : str or os.PathLike
        Folder of frames or a video.
    output : str or os.PathLike
        Destination folder (created).
    colour : ColourRange, optional
        The cable colour; found automatically on ``reference_frame`` if None.
    settings : SegmentationSettings, optional
    reference_frame : int, optional
    overwrite : bool, optional
        Replace masks already in ``output``.
    progress : callable, optional
        ``progress(fraction, message)``.

    Returns
    -------
    colour : ColourRange
        The colour used.
    widths : list of float
        Cable width in pixels per frame.

    Raises
    ------
    InputError
        Bad input, existing output without ``overwrite``, or a frame with no cable pixels.
    """
    output = Path(output)
    masks, junctions = output / "masks", output / "junctions"
    if not overwrite and masks.is_dir() and any(masks.iterdir()):
        raise InputError(f"{masks} already holds masks (pass --overwrite to replace them)")
    with open_image_sequence(images) as sequence:
        if not 0 <= reference_frame < len(sequence):
            raise InputError(f"reference frame {reference_frame} does not exist "
                             f"({len(sequence)} frames)")
        if colour is None:
            colour = auto_colour(sequence.read(reference_frame))
            log.info("cable colour found on %s: --hsv %s", sequence.names[reference_frame], colour)
        masks.mkdir(parents=True, exist_ok=True)
        junctions.mkdir(exist_ok=True)
        thumbnails, widths, empty = [], [], []
        for k, (name, path) in enumerate(zip(sequence.names, sequence.paths)):
            image = sequence.read(k)
            segmentation = segment_frame(image, colour, settings)
            stem = Path(name).stem + ".png"
            cv2.imwrite(str(masks / stem), segmentation.mask.astype(np.uint8) * 255)
            cv2.imwrite(str(junctions / stem), segmentation.junctions.astype(np.uint8) * 255)
            thumbnails.append(_overlay(image, segmentation))
            widths.append(segmentation.width)
            if not segmentation.mask.any():
                empty.append(name)
            if progress is not None:
                progress((k + 1) / len(sequence), f"segment {name}")
        sheet = contact_sheet(thumbnails)
        cv2.imwrite(str(output / "contact_sheet.png"), cv2.cvtColor(sheet, cv2.COLOR_RGB2BGR))
    if empty:
        shown = ", ".join(empty[:5]) + (f" and {len(empty) - 5} more" if len(empty) > 5 else "")
        raise InputError(f"no cable pixels in {shown} with --hsv {colour}: check the colour "
                         f"on {output / 'contact_sheet.png'}")
    return colour, widths

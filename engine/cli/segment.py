"""``python -m engine segment``: masks and junction maps of every frame, agreed across views,
to check a capture and correct by hand before ``reconstruct --masks``."""

import logging
from pathlib import Path

import cv2
import numpy as np

from ..errors import InputError, ReconstructionError
from ..io.files import check_writable, write_image
from ..io.image_sequence import open_image_sequence
from ..pipeline import PipelineSettings, segment_frames, sequence_cameras
from ..progress import StageProgress
from ..stages.mask_agreement import agree_masks
from ..stages.segmentation import (SeveralCables, reference_frames,
                                   sequence_colour)

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


def _overlay(image, mask, junctions, removed=None, filled=None, width=240):
    """A thumbnail: the mask green, junctions yellow; pixels the agreement across views
    removed red, those it filled cyan."""
    shown = (image * 0.45).astype(np.uint8)
    shown[mask] = (40, 200, 40)
    shown[junctions] = (255, 220, 0)
    if removed is not None:
        shown[removed] = (230, 40, 40)
        shown[filled] = (40, 220, 255)
    height = round(width * image.shape[0] / image.shape[1])
    return cv2.resize(shown, (width, height), interpolation=cv2.INTER_AREA)


def segment_sequence_to_folder(images, output, *, colour=None, settings=PipelineSettings(),
                               overwrite=False, cameras=None, progress=None, cancel=None):
    """Segment every frame, agree the masks across views, and write ``masks/``,
    ``junctions/`` and ``contact_sheet.png``.

    The masks written are those a reconstruction from these frames would carve: each frame's
    mask checked against the other views (:func:`~engine.stages.mask_agreement.agree_masks`), so
    that a user corrects what is left. The contact sheet shows what the agreement removed
    (red) and filled (cyan).

    Parameters
    ----------
    images : str or os.PathLike
        Folder of frames or a video.
    output : str or os.PathLike
        Destination folder (created).
    colour : ColourRange, optional
        The cable colour; found automatically on ``settings.reference_frame`` if None.
    settings : PipelineSettings, optional
        The reconstruction's: its segmentation, reference frame, and for the agreement across
        views (``agreement.rounds=0`` writes the masks as segmented, and needs no cameras) its
        agreement, carving, camera estimation and upright frame.
    overwrite : bool, optional
        Replace masks already in ``output``.
    cameras : str, os.PathLike or sequence of Camera, optional
        A COLMAP model of the frames for the agreement; estimated as the reconstruction does
        if None (frames that do not register keep their masks as segmented).
    progress : callable, optional
        ``progress(fraction, message)``.
    cancel : threading.Event, optional

    Returns
    -------
    colour : ColourRange
        The colour used.
    widths : list of float
        Cable width in pixels per frame (as segmented).

    Raises
    ------
    InputError
        Bad input (a model with no camera named after a frame), existing output without
        ``overwrite``, an output folder that cannot be written (:class:`.OutputError`), or
        a frame with no cable pixels (the masks are written as segmented,
        with no agreement, to show it).
    Cancelled
    """
    output = Path(output)
    masks = output / "masks"
    if not overwrite and masks.is_dir() and any(masks.iterdir()):
        raise InputError(f"{masks} already holds masks (pass --overwrite to replace them)")
    agree = settings.agreement.rounds > 0
    if agree and isinstance(cameras, (str, Path)) and not Path(cameras).is_dir():
        raise InputError(f"--cameras {cameras}: not a folder")  # before segmenting
    check_writable(output, created=True)
    stage = StageProgress(progress)
    with open_image_sequence(images) as sequence:
        reference_frame = settings.reference_frame
        if not 0 <= reference_frame < len(sequence):
            raise InputError(f"reference frame {reference_frame} does not exist "
                             f"({len(sequence)} frames)")
        colour, model = _colour_model(sequence, colour, settings.segmentation, reference_frame)
        # the segmentation's share of the progress bar (estimating cameras takes long)
        share = (0.3 if cameras is None else 0.6) if agree else 1.0
        frame_masks, frame_junctions, widths = segment_frames(
            sequence, colour, model, settings, progress=stage.part(0.0, share), cancel=cancel)
        empty = [name for name, mask in zip(sequence.names, frame_masks) if not mask.any()]
        segmented = list(frame_masks)
        if agree and not empty:
            frame_masks, frame_junctions = _agreed(sequence, frame_masks, frame_junctions,
                                                   cameras, settings, stage.part(share, 0.95),
                                                   cancel)
        _write_masks(output, sequence, segmented, frame_masks, frame_junctions)
        stage(1.0, "masks written")
    if empty:
        shown = ", ".join(empty[:5]) + (f" and {len(empty) - 5} more" if len(empty) > 5 else "")
        raise InputError(f"no cable pixels in {shown} with --hsv {colour}: check the colour "
                         f"on {output / 'contact_sheet.png'}")
    return colour, widths


def _colour_model(sequence, colour, settings, reference_frame):
    """The cable's colour (found on the reference frames if None, and logged as ``--hsv``) and
    the colour model learnt there."""
    frames = reference_frames(len(sequence), reference_frame, settings.model_frames)
    found = colour is None
    colour, model = sequence_colour([sequence.read(k) for k in frames], colour, settings)
    if found and isinstance(model, SeveralCables) and len(model.cables) > 1:
        log.info("%d cables found on %s, their colours (as --hsv): %s", len(model.cables),
                 sequence.names[reference_frame],
                 "; ".join(str(cable) for cable, _ in model.cables))
    elif found:
        log.info("cable colour found on %s: --hsv %s", sequence.names[reference_frame], colour)
    return colour, model


def _write_masks(output, sequence, segmented, frame_masks, frame_junctions):
    """OUT/masks/*.png, OUT/junctions/*.png and OUT/contact_sheet.png (what the agreement
    removed in red, what it filled in cyan)."""
    masks, junctions = output / "masks", output / "junctions"
    masks.mkdir(parents=True, exist_ok=True)
    junctions.mkdir(exist_ok=True)
    thumbnails = []
    for k, name in enumerate(sequence.names):
        stem = Path(name).stem + ".png"
        mask, junction = frame_masks[k](), frame_junctions[k]()
        write_image(masks / stem, mask.astype(np.uint8) * 255, overwrite=True)
        write_image(junctions / stem, junction.astype(np.uint8) * 255, overwrite=True)
        changes = (None, None)
        if segmented[k] is not frame_masks[k]:
            before = segmented[k]()
            changes = (before & ~mask, mask & ~before)
        thumbnails.append(_overlay(sequence.read(k), mask, junction, *changes))
    sheet = contact_sheet(thumbnails)
    write_image(output / "contact_sheet.png", cv2.cvtColor(sheet, cv2.COLOR_RGB2BGR),
                overwrite=True)


def _agreed(sequence, masks, junctions, cameras, settings, stage, cancel):
    """The frames' masks and junction maps agreed across views, with the cameras given or
    estimated as the reconstruction does; as segmented if the cameras cannot be estimated."""
    try:
        found, _, warnings = sequence_cameras(sequence, cameras, settings=settings,
                                              progress=stage.part(0.0, 0.8 if cameras is None
                                                                  else 0.05), cancel=cancel)
    except ReconstructionError as error:
        log.warning("warning: masks written as segmented, not agreed across views: %s", error)
        return masks, junctions
    for warning in warnings:
        log.warning("warning: %s", warning)
    index = {name: k for k, name in enumerate(sequence.names)}
    numbers = [index[camera.name] for camera in found]
    try:
        agreed, report = agree_masks(found, [masks[k] for k in numbers],
                                     junctions=[junctions[k] for k in numbers],
                                     carving=settings.carving, settings=settings.agreement,
                                     segmentation=settings.segmentation,
                                     progress=stage.part(0.8 if cameras is None else 0.05, 1.0),
                                     cancel=cancel, packed=True, workers=settings.workers)
    except ReconstructionError as error:  # the carve is over its memory budget
        log.warning("warning: masks written as segmented, not agreed across views: %s", error)
        return masks, junctions
    log.info(report.summary())
    if report.left_alone:
        log.warning("warning: the masks of %d frame(s) disagree with the other views and were "
                    "written as segmented: %s", len(report.left_alone),
                    ", ".join(report.left_alone))
    masks, junctions = list(masks), list(junctions)
    for k, mask, junction in zip(numbers, agreed, report.junctions):
        masks[k], junctions[k] = mask, junction
    return masks, junctions

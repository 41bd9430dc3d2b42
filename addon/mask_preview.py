"""The live mask preview: an image datablock the Image Editor shows while the colour is tuned.

Every change of the folder, frame or colour re-segments the chosen frame (the decoded frame is
cached) and rewrites the image's pixels; nothing happens until the preview was opened once.
"""

import logging
import os
import time
from pathlib import Path

import bpy
import cv2

from ..engine.errors import InputError, ReconstructionError
from ..engine.io.image_sequence import frame_files, read_image
from ..engine.stages.mask_preview import mask_preview

__all__ = ["PREVIEW_IMAGE", "frame_paths", "frame_image", "refresh_preview", "show_preview"]

PREVIEW_IMAGE = "Cable Mask Preview"
log = logging.getLogger(__name__)
_cache = {}  # (path, mtime, reduction) -> RGB frame: the last frame, full and for preview
_sizes = {}  # folder -> (width, height) of its frames, once one was decoded at full size
#: The preview's larger side (larger frames are decoded at 1/2, 1/4 or 1/8 of their size).
PREVIEW_SIDE = 1280
_REDUCED = {1: cv2.IMREAD_COLOR, 2: cv2.IMREAD_REDUCED_COLOR_2,
            4: cv2.IMREAD_REDUCED_COLOR_4, 8: cv2.IMREAD_REDUCED_COLOR_8}


def frame_paths(folder):
    """The frames of ``folder`` in natural order (no check of their contents)."""
    folder = Path(bpy.path.abspath(folder)) if folder else None
    if folder is None or not folder.is_dir():
        return []
    return frame_files(folder)


def frame_image(settings, *, max_side=None):
    """The chosen frame (RGB) and its path; :class:`InputError` if there is none.

    With ``max_side``, the frame is decoded at the largest reduction (1/2, 1/4, 1/8) that
    keeps its larger side at least ``max_side``: a 4K JPEG decodes several times faster at a
    quarter of its size.
    """
    paths = frame_paths(settings.images)
    if not paths:
        raise InputError(f"{settings.images or 'no folder'}: no .jpg or .png images")
    path = paths[min(settings.frame, len(paths) - 1)]
    size = _sizes.get(str(path.parent))
    if max_side and size is None:  # an eighth-size decode is quick and tells the size
        small = cv2.imread(str(path),
                           cv2.IMREAD_REDUCED_GRAYSCALE_8 | cv2.IMREAD_IGNORE_ORIENTATION)
        if small is not None:
            size = _sizes[str(path.parent)] = (8 * small.shape[1], 8 * small.shape[0])
    reduction = 1
    if max_side and size:
        reduction = max(f for f in _REDUCED if max(size) / f >= max_side or f == 1)
    key = (str(path), os.stat(path).st_mtime_ns, reduction)
    if key not in _cache:
        if reduction == 1:
            frame = read_image(path)
            _sizes[str(path.parent)] = frame.shape[1::-1]
        else:
            data = cv2.imread(str(path), _REDUCED[reduction] | cv2.IMREAD_IGNORE_ORIENTATION)
            if data is None:
                raise InputError(f"{path} cannot be read as an image")
            frame = cv2.cvtColor(data, cv2.COLOR_BGR2RGB)
        for old in [k for k in _cache if k[2] == reduction or k[:2] != key[:2]]:
            del _cache[old]
        _cache[key] = frame
    return _cache[key], path


def _colour(settings):
    """The colour range set or picked, None for the automatic colour (found per preview)."""
    from .properties import colour_range

    return colour_range(settings)


def refresh_preview(context, *, force=False):
    """Rewrite the preview image from the current settings.

    Does nothing unless the preview image exists (it was shown) or ``force``. Errors (no
    frames, an unreadable frame) go into the window manager's status line, not exceptions:
    this runs from property updates.

    Returns
    -------
    float or None
        Seconds it took, None if nothing was done.
    """
    image = bpy.data.images.get(PREVIEW_IMAGE)
    if image is None and not force:
        return None
    started = time.perf_counter()
    settings = context.scene.cable_recon
    try:
        frame, path = frame_image(settings, max_side=PREVIEW_SIDE)
        preview = mask_preview(frame, _colour(settings),
                               _quality_segmentation(settings), max_side=PREVIEW_SIDE)
    except (InputError, ReconstructionError, ValueError, OSError) as error:
        context.window_manager.cable_recon_status = f"Preview: {error}"
        return None
    height, width = preview.pixels.shape[:2]
    if image is None:
        image = bpy.data.images.new(PREVIEW_IMAGE, width, height, alpha=False)
    elif tuple(image.size) != (width, height):
        image.scale(width, height)
    image.pixels.foreach_set(preview.pixels.ravel())
    image.update()
    cable = ("no cable pixels: widen the range" if preview.width == 0 else
             f"cable {preview.width:.1f} px wide, {100 * preview.cable_fraction:.1f}% of frame")
    context.window_manager.cable_recon_status = f"{path.name}: {cable}"
    for window in context.window_manager.windows:
        for area in window.screen.areas:
            if area.type == "IMAGE_EDITOR":
                area.tag_redraw()
    return time.perf_counter() - started


def _quality_segmentation(settings):
    from .settings_properties import settings_from_group

    return settings_from_group(settings.segmentation)


def show_preview(context):
    """Make the preview and show it in an Image Editor (a new window if there is none).

    Returns
    -------
    bpy.types.Image or None
        None if the preview could not be made (the reason is in the status line).
    """
    refresh_preview(context, force=True)
    image = bpy.data.images.get(PREVIEW_IMAGE)
    if image is None:
        return None
    editors = [area for window in context.window_manager.windows
               for area in window.screen.areas if area.type == "IMAGE_EDITOR"]
    if not editors and context.window is not None and not bpy.app.background:
        before = set(context.window_manager.windows[:])
        bpy.ops.wm.window_new()
        new = [w for w in context.window_manager.windows if w not in before]
        if new:
            area = new[0].screen.areas[0]
            area.type = "IMAGE_EDITOR"
            editors = [area]
    for area in editors:
        area.spaces.active.image = image
    return image

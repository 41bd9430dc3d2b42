"""The live mask preview: a frame with the cable mask the current colour range gives.

The add-on shows it in an Image Editor while the user tunes the cable colour, so it must be
quick (``python -m engine bench preview`` measures it): one segmentation of the chosen frame
and a composite, shrunk to at most ``max_side`` pixels. With a colour range given, the colour
model the frame is segmented with is learnt from a quarter of its pixels.
"""

from dataclasses import dataclass

import cv2
import numpy as np

from .segmentation import (SegmentationSettings, learn_colour_model, segment_frame,
                           sequence_colour)

__all__ = ["MaskPreview", "mask_preview"]

#: Colours of the composite (RGB, 0-255): junction pixels; the rest of the frame is dimmed.
JUNCTION_COLOUR = (255, 0, 255)
DIM = 0.3


@dataclass(frozen=True, eq=False)
class MaskPreview:
    """A preview image and what the mask says.

    Attributes
    ----------
    pixels : ndarray, shape (H, W, 4), float32
        RGBA in 0..1, rows bottom-up (the order Blender's images use).
    cable_fraction : float
        Share of the frame's pixels on the cable.
    width : float
        The cable's width in pixels of the preview (0 without cable).
    """

    pixels: np.ndarray
    cable_fraction: float
    width: float


def mask_preview(image_rgb, colour, settings=SegmentationSettings(), *, max_side=1280):
    """The frame dimmed to 30% with the cable at full brightness and junctions in magenta.

    Parameters
    ----------
    image_rgb : ndarray, shape (H, W, 3), uint8
    colour : ColourRange or None
        None: found automatically on this frame, as the reconstruction would
        (:func:`engine.stages.segmentation.sequence_colour`).
    settings : SegmentationSettings, optional
    max_side : int, optional
        A larger frame is shrunk so that its larger side is at most this before it is
        segmented (the preview's mask is then the shrunk frame's; the reconstruction segments
        every frame at full size).

    Returns
    -------
    MaskPreview
    """
    height, width = image_rgb.shape[:2]
    scale = max_side / max(height, width)
    if scale < 1.0:  # segment the shrunk frame: every length is relative to the cable's width
        image_rgb = cv2.resize(image_rgb, (max(int(width * scale), 1),
                                           max(int(height * scale), 1)),
                               interpolation=cv2.INTER_AREA)
    model = None
    if colour is None:
        colour, model = sequence_colour([image_rgb], None, settings)
    elif settings.model:
        # each refresh (a dragged slider: a new colour each time) learns the colour model; a
        # quarter of the frame's pixels, every second one of every second row, hold its
        # colours as well and take a quarter of the time (none found: learnt from the whole)
        model = learn_colour_model([np.ascontiguousarray(image_rgb[::2, ::2])], colour,
                                   settings)
    segmentation = segment_frame(image_rgb, colour, settings, model=model)
    # in OpenCV's passes, which are quicker than numpy's on a whole frame (bench preview)
    image_rgb = np.ascontiguousarray(image_rgb)
    composite = cv2.convertScaleAbs(image_rgb, alpha=DIM)
    cv2.copyTo(image_rgb, segmentation.mask.view(np.uint8), composite)
    composite[segmentation.junctions & segmentation.mask] = JUNCTION_COLOUR
    rgba = cv2.cvtColor(cv2.flip(composite, 0), cv2.COLOR_RGB2RGBA).astype(np.float32)
    rgba *= np.float32(1.0 / 255.0)
    return MaskPreview(rgba, float(segmentation.mask.mean()), float(segmentation.width))

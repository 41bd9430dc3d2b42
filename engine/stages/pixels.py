"""Per-pixel helpers the mask steps share: chromaticity, brightness, the cable's box and colours
read between pixels."""

import cv2
import numpy as np

__all__ = ["CHROMA_FLOOR", "brightness", "cable_box", "chroma", "sample_at"]

#: Pixels darker than this (sum of R, G, B) have no reliable chromaticity.
CHROMA_FLOOR = 60


def chroma(rgb, floor=1.0):
    """Chromaticity: colours divided by their sum (the last axis), a sum under ``floor``
    counted as it (:data:`CHROMA_FLOOR`: a dark colour's chromaticity is noise)."""
    rgb = np.asarray(rgb, dtype=np.float32)
    return rgb / np.maximum(brightness(rgb), floor)[..., None]


def brightness(rgb):
    """The sum of the colours (the last axis; int32 for integer colours): three additions
    are several times faster than numpy's reduction over an axis of three."""
    first = rgb[..., 0].astype(np.int32) if rgb.dtype.kind in "ui" else rgb[..., 0]
    return first + rgb[..., 1] + rgb[..., 2]


def cable_box(mask, margin):
    """Slice of the mask's bounding box grown by ``margin`` pixels (None for an empty mask)."""
    rows, cols = np.nonzero(mask.any(axis=1))[0], np.nonzero(mask.any(axis=0))[0]
    if not len(rows):
        return None
    return np.s_[max(rows[0] - margin, 0):rows[-1] + margin + 1,
                 max(cols[0] - margin, 0):cols[-1] + margin + 1]


def sample_at(image, xs, ys):
    """Values (float32) of ``image`` (one or three channels) at points ``(xs, ys)`` of any
    shape, bilinear; shape ``xs.shape`` (+ ``(3,)``)."""
    shape, count, width = np.shape(xs), np.size(xs), 4096
    pad = -count % width
    grid = [np.concatenate([np.ravel(v).astype(np.float32), np.zeros(pad, np.float32)])
            .reshape(-1, width) for v in (xs, ys)]
    values = cv2.remap(image, grid[0], grid[1], cv2.INTER_LINEAR,
                       borderMode=cv2.BORDER_REPLICATE)
    channels = image.shape[2:]
    return values.reshape(-1, *channels)[:count].reshape(*shape, *channels).astype(np.float32)

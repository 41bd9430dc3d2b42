"""A cable colour as an HSV range (OpenCV units: hue 0-179, wrapping; saturation and value
0-255), set by hand, picked, or found automatically."""

from dataclasses import dataclass

import cv2
import numpy as np

from ..errors import InputError

__all__ = ["ColourRange", "hsv_image"]


def hsv_image(image_rgb):
    """An RGB uint8 frame in OpenCV's HSV."""
    return cv2.cvtColor(np.ascontiguousarray(image_rgb), cv2.COLOR_RGB2HSV)


@dataclass(frozen=True)
class ColourRange:
    """A cable colour: an HSV box, or a brightness class for a colourless cable.

    Attributes
    ----------
    low, high : tuple of int
        ``(H, S, V)`` bounds, inclusive; the hue wraps when ``low[0] > high[0]``.
    """

    low: tuple = (0, 0, 0)
    high: tuple = (179, 255, 255)

    def __post_init__(self):
        low, high = tuple(int(v) for v in self.low), tuple(int(v) for v in self.high)
        if len(low) != 3 or len(high) != 3:
            raise ValueError("an HSV range needs three low and three high values")
        for name, value, top in zip("HSV", zip(low, high), (179, 255, 255)):
            if not (0 <= value[0] <= top and 0 <= value[1] <= top):
                raise ValueError(f"{name} must lie in 0..{top}")
        if low[1] > high[1] or low[2] > high[2]:
            raise ValueError("saturation and value ranges must have low <= high")
        object.__setattr__(self, "low", low)
        object.__setattr__(self, "high", high)

    @classmethod
    def parse(cls, text):
        """From ``"H1,S1,V1,H2,S2,V2"`` (the ``--hsv`` option); :class:`InputError` if bad."""
        try:
            values = [int(v) for v in text.split(",")]
            if len(values) != 6:
                raise ValueError("six numbers expected")
            return cls(tuple(values[:3]), tuple(values[3:]))
        except ValueError as error:
            raise InputError(f"--hsv {text!r}: {error} (H1,S1,V1,H2,S2,V2 with H 0-179, "
                             "S and V 0-255)") from None

    def __str__(self):
        return ",".join(str(v) for v in (*self.low, *self.high))

    @property
    def has_hue(self):
        """False for a brightness range (any hue): a cable with no colour of its own."""
        return not (self.low[0] == 0 and self.high[0] == 179)

    def select_rgb(self, image_rgb):
        """Boolean mask of the pixels of an RGB uint8 image inside the range."""
        return self.select(hsv_image(image_rgb))

    def select(self, hsv):
        """Boolean mask of the pixels of an HSV image inside the range."""
        (h1, s1, v1), (h2, s2, v2) = self.low, self.high
        if h1 <= h2:
            return cv2.inRange(hsv, self.low, self.high) > 0
        # the hue wraps: two boxes
        return (cv2.inRange(hsv, (h1, s1, v1), (179, s2, v2))
                | cv2.inRange(hsv, (0, s1, v1), (h2, s2, v2))) > 0

"""Boolean images kept bit-packed, so a long sequence of large frames fits in memory.

A 4K mask is 8.3 MB as a bool array and about 1 MB packed; 200 views of masks and junction
maps are 3.3 GB as arrays and 0.4 GB packed. Stages that hold every view's mask keep them as
:class:`PackedMask` and unpack one view at a time.
"""

import numpy as np

__all__ = ["PackedMask", "unpacked"]


class PackedMask:
    """A boolean image, bit-packed; calling it gives the array back.

    Being callable, it can be passed wherever a mask or "a callable returning one" is taken
    (:func:`engine.stages.carving.carve`, :func:`engine.stages.mask_agreement.agree_masks`,
    the topology's views).

    Parameters
    ----------
    mask : array_like of bool, shape (height, width)

    Attributes
    ----------
    shape : tuple of int
    count : int
        Its true pixels.
    """

    __slots__ = ("shape", "count", "_bits")

    def __init__(self, mask):
        mask = np.asarray(mask, dtype=bool)
        if mask.ndim != 2:
            raise ValueError(f"a mask is 2-D, not of shape {mask.shape}")
        self.shape = mask.shape
        self.count = int(np.count_nonzero(mask))
        self._bits = np.packbits(mask, axis=None)
        self._bits.setflags(write=False)

    def __call__(self):
        """The mask, a new bool array of ``shape``."""
        size = self.shape[0] * self.shape[1]
        return np.unpackbits(self._bits, count=size).reshape(self.shape).view(bool)

    def any(self):
        """Whether any pixel is true."""
        return self.count > 0

    @property
    def nbytes(self):
        """Bytes held."""
        return self._bits.nbytes

    def __repr__(self):
        return f"PackedMask({self.shape[1]}x{self.shape[0]}, {self.count} true)"


def unpacked(item, dtype=bool):
    """An array from an array, a :class:`PackedMask` or any callable returning one (None
    stays None)."""
    value = item() if callable(item) else item
    if value is None:
        return None
    return np.asarray(value, dtype=dtype)

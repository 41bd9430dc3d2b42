"""Exceptions the engine raises, each mapped to one command-line exit code.

The command line (``python -m engine``) and the Blender add-on both turn these into a clear
one-line message: :class:`InputError` means the user's input is wrong (exit code 2; its
:class:`OutputError` means an output cannot be written: an unwritable folder, a full disk),
:class:`ReconstructionError` means the input was fine but no cable could be reconstructed
(exit code 3), :class:`Cancelled` means the caller asked the work to stop.
"""

__all__ = ["InputError", "OutputError", "ReconstructionError", "Cancelled"]


class InputError(ValueError):
    """The input is unusable: a missing or malformed file, an empty folder, a bad option."""


class OutputError(InputError):
    """An output cannot be written (a folder one may not write in, a full disk); nothing of
    it is left behind."""


class ReconstructionError(RuntimeError):
    """The input was readable but the reconstruction failed (cameras, path, ...)."""


class Cancelled(Exception):
    """The caller cancelled the work through its progress callback."""

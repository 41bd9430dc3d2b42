"""Progress reporting and cancellation shared by the engine's stages.

Every long stage takes ``progress`` (a callable ``progress(fraction, message)``, fraction in
0..1) and ``cancel`` (anything with ``is_set()``, e.g. a :class:`threading.Event`); a set
cancel makes the stage raise :class:`~engine.errors.Cancelled` at its next check.
"""

from .errors import Cancelled

__all__ = ["StageProgress", "AnySet", "check_cancel"]


class StageProgress:
    """Maps a stage's own 0..1 progress into its slice ``start..stop`` of the overall 0..1."""

    def __init__(self, progress, start=0.0, stop=1.0):
        self.progress, self.start, self.stop = progress, start, stop

    def __call__(self, fraction, message):
        if self.progress is not None:
            fraction = min(max(fraction, 0.0), 1.0)
            self.progress(self.start + (self.stop - self.start) * fraction, message)

    def part(self, start, stop):
        """The slice ``start..stop`` of this stage's own 0..1, as a progress of its own."""
        span = self.stop - self.start
        return StageProgress(self.progress, self.start + span * start, self.start + span * stop)


class AnySet:
    """A cancel that is set when any of ``events`` is (those that are None left out): the
    user's cancel, or a sibling's failure that makes the work pointless."""

    def __init__(self, *events):
        self.events = tuple(event for event in events if event is not None)

    def is_set(self):
        return any(event.is_set() for event in self.events)


def check_cancel(cancel, what):
    """Raise :class:`Cancelled` ("``what`` was cancelled") if ``cancel`` is set."""
    if cancel is not None and cancel.is_set():
        raise Cancelled(f"{what} was cancelled")

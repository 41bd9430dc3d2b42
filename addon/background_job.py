"""Work off Blender's main thread, and what a modal operator does on each event.

Plain Python, no bpy: timers and modal operators do not run under the bpy module, so the
modal logic is this state machine, which the operators translate events into and tests drive
directly.

The work runs on a daemon thread (NumPy, OpenCV, SciPy and pycolmap release the GIL, so the UI
stays live). Cancelling sets an event the engine checks between steps; the progress callback
checks it too, so a run stops at its next progress report. Esc is answered at once: the
operator ends on the spot and whatever the thread still returns is thrown away.
"""

import logging
import threading
import time
from dataclasses import dataclass, replace

__all__ = ["BackgroundJob", "JobStatus", "ModalRun", "Step", "step_of"]

log = logging.getLogger(__name__)

PENDING, RUNNING, FINISHED, FAILED, CANCELLED = (
    "PENDING", "RUNNING", "FINISHED", "FAILED", "CANCELLED")


class _Stopped(Exception):
    """Raised inside the worker by the progress callback once cancel was asked for."""


@dataclass(frozen=True)
class JobStatus:
    """A snapshot of a :class:`BackgroundJob`.

    Attributes
    ----------
    state : str
        ``"PENDING"``, ``"RUNNING"``, ``"FINISHED"``, ``"FAILED"`` or ``"CANCELLED"``.
    fraction : float
        Progress from 0 to 1.
    message : str
        What the work is doing (the engine's stage).
    value : object
        What the work returned (FINISHED).
    error : str
        One line saying why it failed (FAILED).
    """

    state: str
    fraction: float = 0.0
    message: str = ""
    value: object = None
    error: str = ""


class BackgroundJob:
    """``work(progress, cancel)`` on a daemon thread, polled from the main thread.

    Parameters
    ----------
    work : callable
        ``work(progress, cancel) -> value``; ``progress(fraction, message)`` and ``cancel`` a
        :class:`threading.Event` follow the engine's conventions.
    expected_errors : tuple of type, optional
        Exceptions whose message is the whole story (bad input, a failed reconstruction); any
        other exception is logged with its traceback and reported by its type and message.
    cancelled_errors : tuple of type, optional
        Exceptions that mean the work honoured a cancel.
    """

    def __init__(self, work, *, expected_errors=(), cancelled_errors=()):
        self._work = work
        self._expected = tuple(expected_errors) + (ValueError,)
        self._cancelled = tuple(cancelled_errors) + (_Stopped,)
        self.cancel_event = threading.Event()
        self._lock = threading.Lock()
        self._status = JobStatus(PENDING)
        self._thread = None

    def start(self):
        """Start the work on its thread; returns ``self``."""
        if self._thread is not None:
            raise RuntimeError("a job runs once")
        self._set(state=RUNNING)
        self._thread = threading.Thread(target=self._run, name="cable_recon job", daemon=True)
        self._thread.start()
        return self

    def run_here(self):
        """Run the work on the calling thread (blocking) and return the final status."""
        self._set(state=RUNNING)
        self._run()
        return self.poll()

    def poll(self):
        """The current :class:`JobStatus` (cheap; call it from a timer)."""
        with self._lock:
            return self._status

    def cancel(self):
        """Ask the work to stop at its next check; returns at once."""
        self.cancel_event.set()

    def wait(self, timeout=None):
        """Wait until the thread ended; True if it did within ``timeout`` seconds."""
        if self._thread is None:
            return True
        self._thread.join(timeout)
        return not self._thread.is_alive()

    def _progress(self, fraction, message=""):
        if self.cancel_event.is_set():
            raise _Stopped()
        self._set(fraction=min(max(float(fraction), 0.0), 1.0), message=str(message))

    def _set(self, **changes):
        with self._lock:
            self._status = replace(self._status, **changes)

    def _run(self):
        try:
            value = self._work(self._progress, self.cancel_event)
        except self._cancelled:
            self._set(state=CANCELLED, message="cancelled")
        except self._expected as error:
            self._set(state=FAILED, error=str(error))
        except Exception as error:  # a bug: keep the traceback in the log, one line for the UI
            log.exception("cable reconstruction failed")
            self._set(state=FAILED, error=f"{type(error).__name__}: {error}")
        else:
            if self.cancel_event.is_set():
                self._set(state=CANCELLED, message="cancelled")
            else:
                self._set(state=FINISHED, fraction=1.0, value=value)


@dataclass(frozen=True)
class Step:
    """What the operator does after an event.

    Attributes
    ----------
    action : str
        ``"RUNNING"`` (keep going), ``"FINISHED"`` (build the result), ``"FAILED"`` or
        ``"CANCELLED"`` (leave everything as it was).
    text : str
        Status line for the UI ("Carving 42%", the error, "Cancelled").
    fraction : float
    value : object
        The work's value when FINISHED.
    """

    action: str
    text: str = ""
    fraction: float = 0.0
    value: object = None


def step_of(status, title, elapsed=None):
    """The :class:`Step` a job's status calls for."""
    if status.state == FINISHED:
        return Step(FINISHED, f"{title}: done", 1.0, status.value)
    if status.state == FAILED:
        return Step(FAILED, status.error, status.fraction)
    if status.state == CANCELLED:
        return Step(CANCELLED, "Cancelled", status.fraction)
    message = f" {status.message}" if status.message else ""
    seconds = f" ({elapsed:.0f} s, Esc to cancel)" if elapsed is not None else ""
    return Step(RUNNING, f"{title}{message} {100 * status.fraction:.0f}%{seconds}",
                status.fraction)


class ModalRun:
    """The modal operator's logic: a timer tick polls the job, Esc cancels.

    Parameters
    ----------
    job : BackgroundJob
        Started by :meth:`start`.
    title : str
        What the status line calls the work ("Reconstructing").
    clock : callable, optional
        Seconds (for the elapsed time in the status line).
    """

    def __init__(self, job, *, title="Working", clock=time.monotonic):
        self.job, self.title, self.clock = job, title, clock
        self.started = None
        self.done = False

    def start(self):
        """Start the job; the first :class:`Step`."""
        self.started = self.clock()
        self.job.start()
        return Step(RUNNING, f"{self.title}...", 0.0)

    def on_timer(self):
        """Poll the job: keep running, or say how it ended."""
        if self.done:
            raise RuntimeError("the run has ended")
        step = step_of(self.job.poll(), self.title, self.clock() - self.started)
        self.done = step.action != RUNNING
        return step

    def on_escape(self):
        """Cancel: answered at once; the thread stops at its next check, its value dropped."""
        self.job.cancel()
        self.done = True
        return Step(CANCELLED, "Cancelled", self.job.poll().fraction)

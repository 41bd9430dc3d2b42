"""Many sequences at once: a folder of captures reconstructed into one result each.

Each sequence runs in a process of its own, the very ``python -m engine reconstruct`` a user
runs for one capture: a crash or a memory error in one leaves the others running, a cancel
stops them at once, and ``jobs`` of them run side by side to use the machine's cores. Every
sequence is given the same settings, through a run file written in the output folder
(``reconstruct --settings``). A batch can be run again: a sequence whose result is there,
made with the same settings and inputs (the result records its settings, colour and scale;
the summary its cameras' and masks' folders), is skipped; a failed one is tried again; a
result made otherwise, or that no summary row accounts for, is left alone (and named) unless
``overwrite``.

Output folder: ``<name>.cable.json`` per sequence (and ``<name>.obj`` when asked for),
``<name>.log`` (the run's messages: progress, warnings, the reason it failed), the run file
:data:`RUN_FILE` and :data:`SUMMARY` (``"format": "cable_recon.batch/1"``), one row per
sequence.
"""

import json
import logging
import os
import re
import signal
import subprocess
import sys
import time
from collections import deque
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

from .errors import Cancelled, InputError
from .io.colmap import natural_key
from .io.files import check_writable, write_atomic
from .io.image_sequence import VIDEO_SUFFIXES, frame_files
from .threads import MOST_THREADS, cpu_count

__all__ = ["BATCH_FORMAT", "RUN_FILE", "SUMMARY", "STOP_ON_SIGINT", "Sequence", "SequenceOutcome",
           "engine_command", "find_sequences", "run_batch", "sequence_outputs", "batch_exit_code",
           "summary_table"]

log = logging.getLogger(__name__)

BATCH_FORMAT = "cable_recon.batch/1"
#: The settings and inputs every sequence of the batch is run with (a run file).
RUN_FILE = "batch.run.json"
#: One row per sequence: :class:`SequenceOutcome` as JSON.
SUMMARY = "summary.json"
RESULT_SUFFIX = ".cable.json"
#: A progress line of ``python -m engine reconstruct`` on a pipe: ``[##....]  45% masks``.
_PROGRESS = re.compile(r"^\[[#.]*\]\s*(\d+)% ?(.*)$")
#: How often the running processes are looked at, seconds.
_POLL = 0.1
#: How long a stopped run may take to clean up (its temporary files) before it is killed.
_GRACE = 5.0
#: Set (to "1") in the environment of the runs a batch starts: a run stops on SIGINT even when
#: it inherited an ignored one (a batch started in the background by a shell script ignores
#: SIGINT, and so would its runs, which the cancel stops with one).
STOP_ON_SIGINT = "CABLE_RECON_STOP_ON_SIGINT"
#: What a summary row says of folders it cannot know (a result made outside this batch).
_UNKNOWN = "(unknown)"
#: The exit codes a run ends with (any other is a crash: counted as a bug, 4).
_CODES = (0, 2, 3, 4, 130)


@dataclass(frozen=True)
class Sequence:
    """One capture of a batch.

    Attributes
    ----------
    name : str
        Names its outputs (``<name>.cable.json``).
    images : pathlib.Path
        Its frames' folder, or its video.
    folder : pathlib.Path
        Where its own inputs are looked for (``cameras`` and ``masks`` of :func:`run_batch`
        name folders in it): the sequence's folder; for a video, the folder named after it
        beside it.
    """

    name: str
    images: Path
    folder: Path


@dataclass(frozen=True)
class SequenceOutcome:
    """What became of one sequence.

    Attributes
    ----------
    name : str
    status : str
        ``"done"`` (reconstructed now), ``"skipped"`` (its result was there, made with the same
        settings and inputs), ``"failed"`` or ``"cancelled"``.
    exit_code : int
        The run's exit code (0 done or skipped, 2 bad input, 3 reconstruction failed, 4 a bug,
        130 cancelled).
    seconds : float
        The run's wall time (0 when skipped).
    paths, crossings, warnings : int
        Of the result (0 without one).
    reason : str
        Why it failed (the run's one-line message), or what was left alone.
    cameras, masks : str or None
        The folder names its result was made with (``"(unknown)"`` for a result made
        outside the batch): a later batch skips the sequence only when they are its own.
    """

    name: str
    status: str
    exit_code: int
    seconds: float = 0.0
    paths: int = 0
    crossings: int = 0
    warnings: int = 0
    reason: str = ""
    cameras: str = None
    masks: str = None


def find_sequences(folder):
    """The sequences in ``folder``, in natural order of their names.

    A sequence is a subfolder holding .jpg/.png frames, or holding them in an ``images``
    folder (the layout ``make sample`` and the synthetic captures write, beside ``sparse``
    and ``masks``), or a video file. Names starting with a dot are left out.

    Parameters
    ----------
    folder : str or os.PathLike

    Returns
    -------
    list of Sequence

    Raises
    ------
    InputError
        ``folder`` is not a folder, holds no sequence (or is one), or two sequences share a
        name (a video and a folder).
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise InputError(f"{folder} {'is not a folder' if folder.exists() else 'does not exist'}")
    found = {}  # by the name as a file system that ignores case sees it
    for entry in sorted(folder.iterdir(), key=lambda p: natural_key(p.name)):
        if entry.name.startswith("."):
            continue
        sequence = None
        if entry.is_dir():
            images = next((f for f in (entry, entry / "images") if f.is_dir() and frame_files(f)),
                          None)
            if images is not None:
                sequence = Sequence(entry.name, images, entry)
        elif entry.is_file() and entry.suffix.lower() in VIDEO_SUFFIXES:
            sequence = Sequence(entry.stem, entry, entry.with_suffix(""))
        if sequence is None:
            continue
        key = sequence.name.casefold()
        if key in found:
            raise InputError(f"{found[key].images.name} and {entry.name} in {folder} "
                             f"would both be sequence {sequence.name!r}: rename one")
        found[key] = sequence
    if not found and frame_files(folder):
        raise InputError(f"{folder} holds frames: it is one sequence ('reconstruct' takes it); "
                         "a batch takes the folder that holds the sequences")
    if not found:
        raise InputError(f"{folder} holds no sequence: folders of .jpg/.png frames (or each "
                         "with an images/ folder of them), or videos")
    return list(found.values())


def engine_command():
    """``python -m engine`` as a child process runs it, and the environment it needs: the
    engine's parent folder and this process's import path (in Blender: the extension's
    wheels) on its path, and :data:`STOP_ON_SIGINT`."""
    package_root = Path(__file__).resolve().parent
    paths = [str(package_root.parent), *(p for p in sys.path if p)]
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(paths))
    env["PYTHONIOENCODING"] = "utf-8"  # the log is read as UTF-8 on every system
    env[STOP_ON_SIGINT] = "1"
    # -P: the working folder is not searched first (a folder there named engine, or numpy)
    return [sys.executable, "-P", "-m", package_root.name], env


@dataclass(eq=False)
class _Child:
    """A running sequence: its process, its log, and how far it got."""

    sequence: Sequence
    process: subprocess.Popen
    log_path: Path
    reader: object
    started: float
    fraction: float = 0.0
    stage: str = ""
    lines: list = field(default_factory=list)
    pending: str = ""  # a line the run is still writing
    inputs: tuple = (None, None)  # the cameras' and masks' folder names it was given

    def read(self, *, ended=False):
        """Take in the lines the run wrote since the last look (with ``ended``, its last one
        too, whether or not it ends in a newline)."""
        text = self.pending + self.reader.read()
        complete, _, self.pending = text.rpartition("\n") if not ended else (text, "", "")
        for line in complete.splitlines():
            match = _PROGRESS.match(line.strip())
            if match:
                self.fraction, self.stage = int(match.group(1)) / 100.0, match.group(2)
            elif line.strip():
                self.lines.append(line.strip())

    def stop(self):
        """Stop the run as Ctrl-C would (it removes its temporary files and exits 130), or
        kill it after :data:`_GRACE` seconds."""
        if self.process.poll() is None:
            if os.name == "posix":
                self.process.send_signal(signal.SIGINT)
            else:
                self.process.terminate()
            try:
                self.process.wait(_GRACE)
            except subprocess.TimeoutExpired:
                self.process.kill()
        self.process.wait()
        self.reader.close()


def run_batch(sequences, output, settings, inputs, *, cameras=None, masks=None, obj=False,
              jobs=None, overwrite=False, progress=None, cancel=None):
    """Reconstruct every sequence into ``output``, ``jobs`` at a time.

    Parameters
    ----------
    sequences : sequence of Sequence
        :func:`find_sequences`.
    output : str or os.PathLike
        The output folder (made if missing).
    settings : PipelineSettings
        Its ``workers`` of 0 gives each run its share of the cores (the cores over ``jobs``,
        at least 1); the results are the same on any number, and a result made with other
        ``workers`` still counts as made with these settings.
    inputs : RunInputs
        The colour and scale every sequence is given.
    cameras, masks : str, optional
        Names of folders inside each sequence's folder: its COLMAP model, its masks (as
        ``reconstruct --cameras`` and ``--masks`` take them).
    obj : bool, optional
        Also write ``<name>.obj`` (a tube mesh) beside each result.
    jobs : int, optional
        Sequences run side by side; the machine's cores if None.
    overwrite : bool, optional
        Run every sequence again, replacing its outputs.
    progress : callable, optional
        ``progress(fraction, message)`` over the whole batch.
    cancel : object with ``is_set()``, optional
        Once set, the running sequences are stopped and :class:`Cancelled` is raised (the
        summary is written first; nothing half-written is left: a result is written whole
        or not at all).

    Returns
    -------
    list of SequenceOutcome
        In the order of ``sequences``; also written to ``output / SUMMARY``.
    """
    from .pipeline import run_record, write_run

    if not sequences:
        raise InputError("no sequence to reconstruct")
    jobs = max(int(jobs or cpu_count()), 1)
    if not settings.workers:  # the cores shared out to the runs side by side
        settings = replace(settings, workers=max(min(cpu_count() // jobs, MOST_THREADS), 1))
    output = Path(output).resolve()
    earlier = _earlier_rows(output)
    check_writable(output, created=True)
    output.mkdir(parents=True, exist_ok=True)
    run_file = write_run(output / RUN_FILE, settings, inputs, overwrite=True)
    record = run_record(settings, inputs)
    outcomes, waiting = {}, deque()
    for sequence in sequences:
        done = None if overwrite else _finished(sequence, output, (record, cameras, masks),
                                                earlier.get(sequence.name), obj)
        if done is None:
            waiting.append(sequence)
        else:
            outcomes[sequence.name] = done
    options = dict(run_file=run_file, cameras=cameras, masks=masks, obj=obj,
                   overwrite=overwrite)
    try:
        _run_all(waiting, output, options, jobs, outcomes, len(sequences), progress, cancel)
    finally:
        ordered = [outcomes.get(s.name) or SequenceOutcome(
            s.name, "cancelled", 130, reason="not started", **_made_with(earlier.get(s.name)))
            for s in sequences]
        write_atomic(output / SUMMARY, json.dumps(
            {"format": BATCH_FORMAT, "sequences": [asdict(o) for o in ordered]}, indent=1)
            + "\n", overwrite=True)
    return ordered


def _earlier_rows(output):
    """The rows of an earlier batch's summary in ``output``, by sequence name (none when
    there is none); :class:`InputError` when ``output`` is not a folder a batch may write."""
    if output.exists() and not output.is_dir():
        raise InputError(f"{output} is a file, not a folder")
    summary = output / SUMMARY
    if not summary.exists():
        return {}
    try:
        data = json.loads(summary.read_text(encoding="utf-8"))
        assert data["format"] == BATCH_FORMAT
        return {row["name"]: row for row in data["sequences"]}
    except (OSError, ValueError, KeyError, TypeError, AssertionError):
        raise InputError(f"{summary} is not a batch's summary: choose another output "
                         "folder") from None


def _run_all(waiting, output, options, jobs, outcomes, total, progress, cancel):
    running = []
    try:
        while waiting or running:
            if cancel is not None and cancel.is_set():
                raise Cancelled("the batch was cancelled")
            while waiting and len(running) < jobs:
                running.append(_start(waiting.popleft(), output, options))
            for child in list(running):
                child.read()
                if child.process.poll() is not None:
                    running.remove(child)
                    outcomes[child.sequence.name] = _ended(child, output)
            if progress is not None:
                progress((len(outcomes) + sum(c.fraction for c in running)) / total,
                         _message(outcomes, running, total))
            if running:
                time.sleep(_POLL)
        if progress is not None:
            progress(1.0, _message(outcomes, running, total))
    finally:
        for child in running:  # a cancel, Ctrl-C or an error here: no run left behind
            child.stop()
            outcomes[child.sequence.name] = _outcome(child, SequenceOutcome(
                child.sequence.name, "cancelled", 130, _since(child), reason="cancelled"))


def _message(outcomes, running, total):
    finished = sum(o.status in ("done", "skipped") for o in outcomes.values())
    failed = sum(o.status == "failed" for o in outcomes.values())
    parts = [f"{finished}/{total} done" + (f", {failed} failed" if failed else "")]
    parts += [f"{c.sequence.name} {100 * c.fraction:.0f}% {c.stage}".rstrip() for c in running]
    return "; ".join(parts)


def sequence_outputs(sequence, output):
    """The result file and the OBJ of ``sequence`` in the output folder ``output``."""
    output = Path(output)
    return output / f"{sequence.name}{RESULT_SUFFIX}", output / f"{sequence.name}.obj"


def _finished(sequence, output, wanted, earlier, obj):
    """The outcome of a sequence whose result is already there (None: run it): skipped when
    made as ``wanted`` says (``(run record, cameras, masks)``: its settings, colour and scale
    as the result records them, the folders the earlier batch's summary row names), its
    missing OBJ then written from it; failed when made otherwise."""
    from .io.obj import write_obj
    from .io.result import read_result

    result_path, obj_path = sequence_outputs(sequence, output)
    if not result_path.exists():
        return None
    record, cameras, masks = wanted
    try:
        result = read_result(result_path)
    except (OSError, ValueError):
        result = None
    made = None if result is None or earlier is None else (
        _without_workers(result.run), earlier.get("cameras"), earlier.get("masks"))
    if made != (_without_workers(json.loads(json.dumps(record))), cameras, masks):
        return SequenceOutcome(sequence.name, "failed", 2, reason=(
            f"{result_path.name} is there, made with other settings or inputs (or unreadable): "
            "left alone (--overwrite replaces it)"), **_made_with(earlier))
    if obj and not obj_path.exists():
        write_obj(result, obj_path)
    return _with_result(SequenceOutcome(sequence.name, "skipped", 0, cameras=cameras,
                                        masks=masks), result)


def _without_workers(record):
    """A run record without its ``workers`` (the result is the same on any number of
    threads, and a batch gives each run its share of the cores)."""
    if not isinstance(record, dict) or not isinstance(record.get("settings"), dict):
        return record
    settings = {key: value for key, value in record["settings"].items() if key != "workers"}
    return {**record, "settings": settings}


def _made_with(earlier):
    """The cameras' and masks' folders a result there was made with, as the earlier summary
    row says (:data:`_UNKNOWN` without one)."""
    if earlier is None:
        return {"cameras": _UNKNOWN, "masks": _UNKNOWN}
    return {"cameras": earlier.get("cameras"), "masks": earlier.get("masks")}


def _with_result(outcome, result):
    return SequenceOutcome(outcome.name, outcome.status, outcome.exit_code, outcome.seconds,
                           paths=len(result.paths), crossings=len(result.crossings),
                           warnings=len(result.warnings), reason=outcome.reason,
                           cameras=outcome.cameras, masks=outcome.masks)


def _start(sequence, output, options):
    command, env = engine_command()
    result_path, obj_path = sequence_outputs(sequence, output)
    command += ["reconstruct", str(sequence.images.resolve()), "-o", str(result_path),
                "--settings", str(options["run_file"])]
    for flag, name in (("--cameras", options["cameras"]), ("--masks", options["masks"])):
        if name:
            command += [flag, str((sequence.folder / name).resolve())]
    if options["obj"]:
        command += ["--obj", str(obj_path)]
    if options["overwrite"]:
        command += ["--overwrite"]
    log_path = output / f"{sequence.name}.log"
    with open(log_path, "w", encoding="utf-8") as stream:  # the child keeps its own handle
        # a session of its own (POSIX): a Ctrl-C in the terminal reaches the batch alone,
        # which stops each run with one SIGINT (a second one could cut its clean-up short)
        process = subprocess.Popen(command, stdin=subprocess.DEVNULL, stdout=stream,
                                   stderr=subprocess.STDOUT, env=env,
                                   start_new_session=os.name == "posix")
    return _Child(sequence, process, log_path, open(log_path, encoding="utf-8",
                                                    errors="replace"), time.perf_counter(),
                  inputs=(options["cameras"], options["masks"]))


def _ended(child, output):
    """The outcome of a run that has ended."""
    from .io.result import read_result

    child.read(ended=True)
    child.reader.close()
    code, name, seconds = child.process.returncode, child.sequence.name, _since(child)
    if code == 0:
        return _with_result(_outcome(child, SequenceOutcome(name, "done", 0, seconds)),
                            read_result(sequence_outputs(child.sequence, output)[0]))
    if code < 0:  # killed: the system ran out of memory, or someone stopped it
        return _outcome(child, SequenceOutcome(name, "failed", 3, seconds,
                                               reason=f"the run was killed (signal {-code})"))
    reason = child.lines[-1] if child.lines else "no message"
    if code not in _CODES:  # it crashed (or Python could not start it)
        code, reason = 4, f"exit code {code}: {reason}"
    return _outcome(child, SequenceOutcome(name, "cancelled" if code == 130 else "failed",
                                           code, seconds, reason=reason))


def _since(child):
    return round(time.perf_counter() - child.started, 3)


def _outcome(child, outcome):
    """``outcome`` with the cameras' and masks' folder names ``child`` was given."""
    cameras, masks = child.inputs
    return SequenceOutcome(**{**asdict(outcome), "cameras": cameras, "masks": masks})


def batch_exit_code(outcomes):
    """The batch's exit code: 0 when every sequence is done or skipped, 130 when one was
    cancelled, else the highest of the failed runs' codes (2 bad input, 3 reconstruction
    failed, 4 a bug)."""
    codes = [o.exit_code for o in outcomes if o.status not in ("done", "skipped")]
    if not codes:
        return 0
    return 130 if 130 in codes else max(codes)


def summary_table(outcomes):
    """The outcomes as a plain-text table, one line per sequence."""
    header = ("sequence", "status", "seconds", "paths", "crossings", "warnings", "reason")
    rows = [(o.name, o.status, f"{o.seconds:.1f}", str(o.paths), str(o.crossings),
             str(o.warnings), o.reason) for o in outcomes]
    widths = [max(len(row[k]) for row in [header, *rows]) for k in range(len(header) - 1)]
    return "\n".join("  ".join(cell.ljust(width) for cell, width in zip(row, widths))
                     + "  " + row[-1] for row in [header, *rows]).rstrip()

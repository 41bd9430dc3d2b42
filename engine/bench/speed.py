"""``python -m engine bench speed``: seconds from process start to result written, as a user
runs it, against the floor of any method (decoding the frames).

Scenes: the pipeline bench's fast renders with up to 12 crossings (:func:`pipeline_suite`,
30 views at 960x720) and the realistic sample. Each is written as a capture and reconstructed
by ``python -m engine reconstruct`` in a process of its own, three ways:

* **exact**: its exact masks and true cameras (``--masks masks --cameras sparse``): no
  segmentation, as #17 measured;
* **ours**: our masks (automatic colour) and the true cameras (``--cameras sparse``);
* **estimated**: our masks and cameras estimated by pycolmap (no flags; the result aligned to
  the truth by a similarity to be scored).

*floor_s*: decoding the capture's frames once (``cv2.imread``, the least of three passes in
the bench's own process); each ``*_x`` column is that way's seconds over the floor. Each
way's accuracy (cable radii) and crossings right are beside its time, so that speed never
hides a loss. Rows end with the mean and the worst of each column.
"""

import subprocess
import tempfile
import time
from pathlib import Path

import cv2

from ..batch import engine_command
from ..evaluation.metrics import evaluate
from ..io.ground_truth import read_ground_truth
from ..io.image_sequence import frame_files
from ..io.result import read_result
from ..synthetic.scene import render_scene_to
from .common import DEFAULT_SAMPLE, mean_and_worst
from .pipeline import pipeline_suite

__all__ = ["bench_speed", "SPEED_COLUMNS", "WAYS"]

#: The ways a capture is reconstructed: name and the ``reconstruct`` flags (folders relative
#: to the capture).
WAYS = (("exact", ("--masks", "masks", "--cameras", "sparse")),
        ("ours", ("--cameras", "sparse")),
        ("estimated", ()))
SPEED_COLUMNS = ("scene", "views", "crossings", "floor_s",
                 *(f"{way}_{column}" for way, _ in WAYS for column in ("s", "x")),
                 *(f"{way}_accuracy" for way, _ in WAYS),
                 *(f"{way}_crossings" for way, _ in WAYS), "error")
#: Most crossings of a scene in the bench (#17's targets are for scenes up to 12).
_MOST_CROSSINGS = 12


def _decode_floor(folder):
    """Seconds to decode every frame of ``folder`` once (the least of three passes)."""
    paths = [str(path) for path in frame_files(folder)]
    best = float("inf")
    for _ in range(3):
        started = time.perf_counter()
        for path in paths:
            cv2.imread(path, cv2.IMREAD_COLOR)
        best = min(best, time.perf_counter() - started)
    return best


def _timed_reconstruct(folder, flags, out):
    """Wall seconds of ``python -m engine reconstruct`` on a capture (process start to exit),
    started as a batch starts its runs, and the error it printed, if it failed."""
    command, env = engine_command()
    command += ["reconstruct", "images", *flags, "-o", str(out), "--overwrite", "-q"]
    started = time.perf_counter()
    process = subprocess.run(command, cwd=folder, capture_output=True, text=True, env=env)
    seconds = time.perf_counter() - started
    error = None
    if process.returncode != 0:
        error = (process.stderr.strip().splitlines() or [f"exit {process.returncode}"])[-1]
    return seconds, error


def _row(label, folder, truth):
    """One scene's row: the floor and each way's seconds, accuracy and crossings."""
    row = {"scene": label, "views": len(frame_files(folder / "images")),
           "crossings": len(truth.crossings), "floor_s": _decode_floor(folder / "images")}
    errors = []
    for way, flags in WAYS:
        out = folder / f"{way}.json"
        seconds, error = _timed_reconstruct(folder, flags, out)
        if error is not None:
            errors.append(f"{way}: {error}")
            continue
        metrics = evaluate(read_result(out), truth, align=way == "estimated")
        row.update({f"{way}_s": seconds, f"{way}_x": seconds / row["floor_s"],
                    f"{way}_accuracy": metrics.accuracy_mean,
                    f"{way}_crossings": f"{metrics.crossings_right}/{metrics.crossings_total}"})
    if errors:
        row["error"] = "; ".join(errors)[:120]
    return row


def bench_speed(*, views=30, sample=DEFAULT_SAMPLE, progress=None):
    """The rows of the speed bench (see the module docstring), then the mean and the worst.

    Parameters
    ----------
    views : int, optional
        Views of each fast render.
    sample : str or os.PathLike, optional
        The realistic sample's folder (images, masks, sparse, ground_truth.json); skipped if
        missing.
    progress : callable, optional

    Returns
    -------
    list of dict
    """
    suite = [(label, spec) for label, spec in pipeline_suite(views)
             if spec.crossings <= _MOST_CROSSINGS]
    rows = []
    with tempfile.TemporaryDirectory(prefix="cable_recon_bench_speed_") as work:
        for number, (label, spec) in enumerate(suite):
            if progress is not None:
                progress(number / (len(suite) + 1), label)
            folder = render_scene_to(spec, Path(work) / f"scene{number}")
            rows.append(_row(label, folder, read_ground_truth(folder / "ground_truth.json")))
        sample = Path(sample)
        if (sample / "ground_truth.json").is_file():
            if progress is not None:
                progress(len(suite) / (len(suite) + 1), "sample")
            copy = Path(work) / "sample"
            copy.mkdir()
            for part in ("images", "masks", "sparse", "ground_truth.json"):
                (copy / part).symlink_to((sample / part).resolve())
            rows.append(_row("sample (Cycles)", copy,
                             read_ground_truth(copy / "ground_truth.json")))
    keys = [column for column in SPEED_COLUMNS
            if column.endswith(("_s", "_x", "_accuracy"))]
    for label, values in mean_and_worst(rows, keys):
        rows.append({"scene": label, **values})
    if progress is not None:
        progress(1.0, "done")
    return rows

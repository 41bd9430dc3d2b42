"""``python -m engine bench scaling``: how time and memory grow with views, cable and pixels.

Three series of table captures, each row reconstructed in a fresh process as ``python -m
engine reconstruct IMAGES --cameras sparse`` runs it (automatic colour, our masks, the true
cameras, radius estimated):

* **views**: 15, 30, 60 and 120 views of one 3-crossing layout at 960x720;
* **cable**: about 1, 2 and 4 m of cable (3, 6 and 12 crossings on a table that grows with
  it), 30 views at 960x720;
* **pixels**: the 3-crossing layout's 30 views at 1280x720, 1920x1080 and 3840x2160.

Each stage's seconds (the result's timings) and its peak memory: the most the process held
while the stage ran, from its resident size sampled every 20 ms (the stages run one after the
other, so a stage's span is its start plus its seconds); *peak_mb*: the process's peak.
*growth* compares the row with the series' first: its time over the first's, divided by how
much more the row has of what the series grows (views, metres of cable, pixels); 1.0 is
linear, the target is within 1.3.
"""

import shutil
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

from ..io.ground_truth import read_ground_truth
from ..synthetic.scene import SceneSpec, render_scene_to
from .common import in_fresh_process

__all__ = ["bench_scaling", "scaling_suite", "SCALING_COLUMNS"]

_STAGES = ("masks", "agreement", "carving", "graph", "topology", "fit")
SCALING_COLUMNS = ("series", "row", "views", "megapixels", "cable_m", "crossings",
                   "accuracy_mean", "crossings_right",
                   *(f"{stage}_s" for stage in _STAGES), "total_s",
                   *(f"{stage}_mb" for stage in _STAGES), "peak_mb", "growth", "error")
#: How often the child samples its resident size, seconds.
_SAMPLE = 0.02


def _length(truth):
    return float(sum(np.linalg.norm(np.diff(line, axis=0), axis=1).sum()
                     for line, _ in truth.lines))


def scaling_suite():
    """``(series, row label, how much of the series' quantity, SceneSpec)`` of every row."""
    table = dict(crossings=3, seed=1, image_format="jpg")
    suite = [("views", f"{n} views", n, SceneSpec(views=n, **table)) for n in (15, 30, 60, 120)]
    # of layout seeds 1 to 40, those whose cable is nearest 1, 2 and 4 m long
    for metres, crossings, extent, seed in ((1, 3, None, 14), (2, 6, 0.65, 24),
                                            (4, 12, 0.92, 6)):
        suite.append(("cable", f"{metres} m", None,
                      SceneSpec(crossings=crossings, seed=seed, extent=extent, views=30,
                                image_format="jpg")))
    for label, (width, height) in (("720p", (1280, 720)), ("1080p", (1920, 1080)),
                                   ("4K", (3840, 2160))):
        suite.append(("pixels", label, width * height / 1e6,
                      SceneSpec(views=30, width=width, height=height, **table)))
    return suite


def _resident_mb():
    with open("/proc/self/statm") as statm:
        return int(statm.read().split()[1]) * 4096 / 2 ** 20


def _sampled_run(folder):
    """In a fresh process: reconstruct a capture while a thread samples the resident size;
    the row's per-stage seconds and peak megabytes, its accuracy and crossings."""
    from ..evaluation.metrics import evaluate
    from ..pipeline import run_reconstruction

    folder = Path(folder)
    samples, done = [], threading.Event()

    def sample():
        while not done.is_set():
            samples.append((time.perf_counter(), _resident_mb()))
            done.wait(_SAMPLE)

    sampler = threading.Thread(target=sample, daemon=True)
    sampler.start()
    started = time.perf_counter()
    try:
        state = run_reconstruction(folder / "images", cameras=folder / "sparse")
    except Exception as error:  # the row says why (a failure is a measurement too)
        return {"error": f"{type(error).__name__}: {error}"[:80]}
    finally:
        done.set()
        sampler.join()
    row = {"total_s": time.perf_counter() - started}
    moments, sizes = np.array([t for t, _ in samples]), np.array([m for _, m in samples])
    begin = started
    for stage, seconds in state.result.timings.items():
        inside = (moments >= begin) & (moments <= begin + seconds + _SAMPLE)
        if stage in _STAGES:
            row[f"{stage}_s"] = seconds
            row[f"{stage}_mb"] = float(sizes[inside].max()) if inside.any() else None
        begin += seconds
    metrics = evaluate(state.result, read_ground_truth(folder / "ground_truth.json"),
                       align=False)
    row.update(accuracy_mean=metrics.accuracy_mean,
               crossings_right=f"{metrics.crossings_right}/{metrics.crossings_total}")
    return row


def bench_scaling(*, progress=None):
    """The rows of the scaling bench (see the module docstring).

    Returns
    -------
    list of dict
    """
    suite = scaling_suite()
    rows, first = [], {}
    with tempfile.TemporaryDirectory(prefix="cable_recon_bench_scaling_") as work:
        for number, (series, label, amount, spec) in enumerate(suite):
            if progress is not None:
                progress(number / len(suite), f"{series}: {label}")
            folder = render_scene_to(spec, Path(work) / f"row{number}")
            truth = read_ground_truth(folder / "ground_truth.json")
            amount = _length(truth) if amount is None else amount
            row = {"series": series, "row": label, "views": spec.views,
                   "megapixels": spec.width * spec.height / 1e6, "cable_m": _length(truth),
                   "crossings": len(truth.crossings)}
            row.update(in_fresh_process(_sampled_run, str(folder)))
            if "error" not in row:
                base = first.setdefault(series, (row["total_s"], amount))
                row["growth"] = (row["total_s"] / base[0]) / (amount / base[1])
            rows.append(row)
            shutil.rmtree(folder)  # 4K frames take room
    if progress is not None:
        progress(1.0, "done")
    return rows

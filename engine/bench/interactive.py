"""Benchmarks of what the artist feels in Blender (the engine's side of it).

``python -m engine bench preview``: the live mask preview (segmentation of one frame and the
composite the Image Editor shows) per frame size.
``python -m engine bench curve``: the editable Bézier curve of real reconstructions: control
points, distance to the reconstruction, strands' gap at crossings, accuracy against the truth.
``python -m engine bench cancel``: how long a reconstruction takes to stop after a cancel, by
the stage it was in.
"""

import tempfile
import threading
import time
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np

from ..errors import Cancelled
from ..evaluation.metrics import evaluate
from ..io.ground_truth import read_ground_truth
from ..io.image_sequence import open_image_sequence
from ..io.result import CablePath
from ..stages.bezier import fit_result_curves
from ..stages.mask_preview import mask_preview
from ..stages.segmentation import auto_colour
from ..synthetic.scene import SceneSpec, make_scene, write_scene
from .common import DEFAULT_SAMPLE

__all__ = ["bench_preview", "bench_curve", "bench_cancel"]


def bench_preview(*, sample=DEFAULT_SAMPLE, repeats=10):
    """Milliseconds per preview refresh at 960x720 up to 4K (the sample's first frame), with
    the colour range found automatically once (as after the panel's Automatic button): each
    refresh segments the frame with a colour model learnt from it."""
    with open_image_sequence(Path(sample) / "images") as sequence:
        frame = sequence.read(0)
    colour = auto_colour(frame)
    rows = []
    for width, height in ((960, 720), (1280, 720), (1920, 1080), (3840, 2160)):
        image = frame if (width, height) == frame.shape[1::-1] else cv2.resize(
            frame, (width, height), interpolation=cv2.INTER_CUBIC)
        mask_preview(image, colour)  # warm up
        times = []
        for _ in range(repeats):
            started = time.perf_counter()
            preview = mask_preview(image, colour)
            times.append(time.perf_counter() - started)
        rows.append({"frame": f"{width}x{height}",
                     "preview": "x".join(map(str, preview.pixels.shape[1::-1])),
                     "ms_mean": round(1000 * float(np.mean(times)), 1),
                     "ms_max": round(1000 * float(np.max(times)), 1),
                     "cable_px": round(preview.width, 1)})
    return rows


def _curve_scenes(views):
    table = dict(views=views, width=960, height=720, image_format="jpg")
    return [("table 3", SceneSpec(crossings=3, seed=1, **table)),
            ("table 8", SceneSpec(crossings=8, seed=5, **table)),
            ("table 12", SceneSpec(crossings=12, seed=3, radius=0.005, **table)),
            ("loop 4", SceneSpec(kind="loop", crossings=4, seed=6, **table)),
            ("knot", SceneSpec(kind="knot", seed=4, **table)),
            ("hanging", SceneSpec(kind="hanging", seed=5, **table))]


def bench_curve(*, sample=DEFAULT_SAMPLE, views=30):
    """The Bézier curve of each scene's reconstruction (true cameras), against the truth."""
    from ..pipeline import reconstruct

    captures = []
    work = tempfile.TemporaryDirectory(prefix="cable_recon_bench_")
    with work:
        if Path(sample).is_dir():
            captures.append(("sample (Cycles)", Path(sample)))
        for label, spec in _curve_scenes(views):
            captures.append((label, write_scene(make_scene(spec), Path(work.name) / label)))
        rows = []
        for label, folder in captures:
            truth = read_ground_truth(folder / "ground_truth.json")
            result = reconstruct(folder / "images", cameras=folder / "sparse")
            started = time.perf_counter()
            curves, report = fit_result_curves(result)
            seconds = time.perf_counter() - started
            editable = replace(result, crossings=(), paths=[
                CablePath(c.sample(16), closed=c.closed) for c in curves])
            gaps = np.array(report["crossing_gaps"]).reshape(-1, 2)
            points = sum(len(p.points) for p in result.paths)
            curve_metrics = evaluate(editable, truth)
            rows.append({
                "scene": label, "points": points, "control_points": report["control_points"],
                "points_per_control": round(points / report["control_points"], 1),
                "max_error_r": round(report["max_error"], 3),
                "min_gap_r": round(float(gaps[:, 0].min()), 2) if len(gaps) else "",
                "reconstruction_min_gap_r": round(float(gaps[:, 1].min()), 2) if len(gaps)
                else "",
                "accuracy_mean": round(evaluate(result, truth).accuracy_mean, 3),
                "curve_accuracy_mean": round(curve_metrics.accuracy_mean, 3),
                "curve_accuracy_p95": round(curve_metrics.accuracy_p95, 3),
                "fit_ms": round(1000 * seconds, 1)})
    return rows


def bench_cancel(*, sample=DEFAULT_SAMPLE, delays=(0.3, 2.0, 4.0, 5.5, 7.0, 8.5)):
    """Seconds from a cancel to the end of a reconstruction (cameras estimated), per stage
    (``stage``: the overall progress and the last message when the cancel came)."""
    from ..pipeline import reconstruct

    images = Path(sample) / "images"
    rows = []
    for delay in delays:
        cancel, state = threading.Event(), {"stage": "start", "outcome": "finished"}

        def progress(fraction, message, state=state):
            state["stage"] = f"{100 * fraction:.0f}% {message}"

        def run(state=state, cancel=cancel):
            try:
                reconstruct(images, progress=progress, cancel=cancel)
            except Cancelled:
                state["outcome"] = "cancelled"

        thread = threading.Thread(target=run, daemon=True)
        started = time.perf_counter()
        thread.start()
        thread.join(delay)
        stage = state["stage"]
        asked = time.perf_counter()
        cancel.set()
        thread.join()
        rows.append({"cancel_after_s": delay, "stage": stage, "outcome": state["outcome"],
                     "stop_s": round(time.perf_counter() - asked, 3),
                     "run_s": round(asked - started, 2)})
    return rows

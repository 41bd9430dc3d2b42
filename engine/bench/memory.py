"""``python -m engine bench memory``: the captures that strain memory, run as a user runs them.

Rows: a thin wire (about 6 pixels wide) in 3000x2000 frames, few views (3, 5 and 8: the hull
is loose), and 200 views of 4K. Each capture is rendered to disk view by view
(:func:`engine.synthetic.scene.render_scene_to`), then reconstructed in a fresh process as
``python -m engine reconstruct IMAGES --cameras sparse`` does it (automatic colour, masks
agreed across views, radius estimated; the true cameras, since pycolmap on 200 4K frames
would take the row's hour), with at most 8 GB of address space. A row says whether it
worked or why it stopped, its accuracy and crossings against the truth, the process's peak
resident memory (the target: at most the carving budget of 2 GB, interpreter and libraries
included) and its time.
"""

import tempfile
import time
from pathlib import Path

import cv2
import numpy as np

from ..synthetic.scene import SceneSpec, render_scene_to
from .common import in_fresh_process
from .pipeline import scored_run

__all__ = ["memory_suite", "bench_memory", "MEMORY_COLUMNS"]

MEMORY_COLUMNS = ("scene", "views", "frames", "wire_px", "accuracy_mean", "accuracy_p95",
                  "crossings", "one_path", "masks_s", "carving_s", "fit_s", "total_s",
                  "peak_mb", "render_s", "error")


def memory_suite(*, large=True):
    """The bench's captures: ``(label, SceneSpec)`` pairs (``large``: with 200 views of 4K)."""
    small = dict(crossings=3, width=960, height=720, image_format="jpg")
    suite = [
        # a 3.6 mm cable over 2.8 m of floor: 1500 radii, about 6 pixels wide
        ("thin wire in 3000x2000", SceneSpec(crossings=3, seed=1, views=30, width=3000,
                                             height=2000, radius=0.0018, extent=2.8,
                                             image_format="jpg")),
        ("3 views", SceneSpec(seed=11, views=3, **small)),
        ("5 views", SceneSpec(seed=12, views=5, **small)),
        ("8 views", SceneSpec(seed=13, views=8, **small)),
    ]
    if large:
        suite.append(("200 views of 4K", SceneSpec(crossings=6, seed=14, views=200, width=3840,
                                                   height=2160, image_format="jpg")))
    return suite


def _wire_width(folder):
    """The median width (pixels) of the exact masks' cable in three of the views."""
    from ..stages.segmentation import cable_width

    paths = sorted((Path(folder) / "masks").iterdir())
    widths = [cable_width(cv2.imread(str(path), cv2.IMREAD_GRAYSCALE) > 127)
              for path in paths[::max(len(paths) // 3, 1)][:3]]
    return float(np.median(widths))


def bench_memory(*, large=True, progress=None):
    """Reconstruct every capture of :func:`memory_suite` (see the module notes).

    Parameters
    ----------
    large : bool, optional
        Include 200 views of 4K (about 25 minutes on two cores, most of it rendering and
        segmenting).
    progress : callable, optional
        ``progress(fraction, message)`` over the captures.

    Returns
    -------
    list of dict
    """
    suite = memory_suite(large=large)
    rows = []
    with tempfile.TemporaryDirectory(prefix="bench_memory_") as work:
        for number, (label, spec) in enumerate(suite):
            if progress is not None:
                progress(number / len(suite), label)
            folder = Path(work) / f"capture{number}"
            started = time.perf_counter()
            render_scene_to(spec, folder)
            row = {"scene": label, "views": spec.views, "frames": f"{spec.width}x{spec.height}",
                   "wire_px": _wire_width(folder), "render_s": time.perf_counter() - started}
            row.update(in_fresh_process(scored_run, str(folder), str(folder / "ground_truth.json"),
                                        True))
            rows.append(row)
    if progress is not None:
        progress(1.0, "done")
    return [{column: row.get(column, "") for column in MEMORY_COLUMNS} for row in rows]

"""``python -m engine bench batch``: many sequences, one at a time and side by side.

A folder of synthetic captures (3-crossing table scenes at 960x720, written as a user's
capture: ``images/`` and the true cameras in ``sparse/``) is reconstructed by
:func:`engine.batch.run_batch` as ``python -m engine batch SEQUENCES --cameras sparse`` does,
with one job, then with one job per core, then once more to resume (every result there: all
skipped). A row: the jobs, the wall time, the sum of the sequences' own times, the speed-up
over one job, and whether every curve is the same as one job's.
"""

import os
import tempfile
import time
from pathlib import Path

import numpy as np

from ..batch import find_sequences, run_batch, sequence_outputs
from ..io.result import read_result
from ..pipeline import PipelineSettings, RunInputs
from ..synthetic.scene import SceneSpec, make_scene, write_scene

__all__ = ["bench_batch"]


def bench_batch(*, sequences=4, views=30, jobs=None, progress=None):
    """Rows of the batch bench (see the module docstring).

    Parameters
    ----------
    sequences : int, optional
        Captures in the folder (layout seeds 1, 2, ...).
    views : int, optional
    jobs : int, optional
        The side-by-side row's jobs; the machine's cores if None.
    progress : callable, optional

    Returns
    -------
    list of dict
    """
    jobs = jobs or os.cpu_count() or 1
    with tempfile.TemporaryDirectory(prefix="cable_recon_bench_batch_") as work:
        work = Path(work)
        for seed in range(1, sequences + 1):
            scene = make_scene(SceneSpec(crossings=3, seed=seed, views=views, width=960,
                                         height=720, image_format="jpg"))
            write_scene(scene, work / "shots" / f"shot{seed}")
        found = find_sequences(work / "shots")
        rows, first = [], None
        for label, count, output in (("one at a time", 1, "one"),
                                     ("side by side", jobs, "many"),
                                     ("again (resumed)", jobs, "many")):
            started = time.perf_counter()
            outcomes = run_batch(found, work / output, PipelineSettings(), RunInputs(),
                                 cameras="sparse", jobs=count, progress=progress)
            wall = time.perf_counter() - started
            points = [read_result(sequence_outputs(s, work / output)[0]).paths[0].points
                      for s in found]
            first = first or (wall, points)
            rows.append({
                "run": label, "jobs": count, "sequences": len(found),
                "finished": sum(o.status in ("done", "skipped") for o in outcomes),
                "skipped": sum(o.status == "skipped" for o in outcomes),
                "wall_s": wall, "sequences_s": sum(o.seconds for o in outcomes),
                "speed_up": first[0] / wall,
                "same_curves": all(np.array_equal(a, b) for a, b in zip(first[1], points))})
    return rows

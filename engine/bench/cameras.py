"""``bench cameras``: camera estimation against the true cameras, on synthetic scenes and the
bundled sample."""

import tempfile
import time
from pathlib import Path

from ..errors import ReconstructionError
from ..evaluation.cameras import compare_to_truth
from ..io.colmap import natural_key
from ..io.ground_truth import read_ground_truth
from ..io.image_sequence import open_image_sequence
from ..stages.cameras import CameraEstimationSettings, estimate_cameras
from ..synthetic.scene import SceneSpec, make_scene, write_scene
from .common import mean_and_worst

__all__ = ["bench_cameras"]


def _bench_one(scene, paths, true_cameras, settings, centreline):
    clock = time.perf_counter()
    try:
        estimate = estimate_cameras(paths, settings=settings)
    except ReconstructionError as error:
        return {"scene": scene, "registered": 0, "total": len(paths),
                "seconds": time.perf_counter() - clock, "error": str(error)}
    seconds = time.perf_counter() - clock
    row = {"scene": scene, "registered": len(estimate.cameras), "total": len(paths),
           "seconds": seconds, "reprojection_error_px": estimate.reprojection_error,
           "matching": estimate.matching, "plane_found": estimate.plane_found,
           "points": len(estimate.points)}
    row.update(compare_to_truth(estimate, true_cameras, centreline))
    return row


#: What the synthetic scenes' mean and worst rows summarise (the worst is the largest of each).
_SPREAD = ("seconds", "reprojection_error_px", "centreline_px", "centreline_max_px",
           "centre_error_pct", "centre_error_max_pct", "rotation_error_deg",
           "rotation_error_max_deg", "up_error_deg", "focal_error_pct")


def bench_cameras(*, views=30, seeds=(0,), include_sample=True,
                  settings=CameraEstimationSettings()):
    """Benchmark camera estimation on synthetic scenes and the bundled sample.

    Parameters
    ----------
    views : int, optional
        Views per synthetic scene (fast renderer, 960x720 PNGs, 3 crossings).
    seeds : sequence of int, optional
        One synthetic scene per seed; with more than one, their mean and worst follow them
        (the registered views summed).
    include_sample : bool, optional
        Also run on ``samples/sequence`` (Cycles renders) if its ground truth exists.
    settings : CameraEstimationSettings, optional

    Returns
    -------
    list of dict
        One row per scene: ``scene``, ``registered``, ``total``, ``seconds`` (estimation
        only), ``reprojection_error_px``, ``matching``, ``plane_found``, ``points`` and the
        keys of :func:`compare_to_truth`; a failed scene has ``error`` instead.
    """
    rows = []
    for seed in seeds:
        spec = SceneSpec(views=views, seed=seed, crossings=3, width=960, height=720)
        scene = make_scene(spec)
        with tempfile.TemporaryDirectory(prefix="bench_cameras_") as folder:
            write_scene(scene, folder)
            paths = sorted((Path(folder) / "images").iterdir(),
                           key=lambda path: natural_key(path.name))
            rows.append(_bench_one(f"synthetic table seed {seed} ({views} views)", paths,
                                   scene.cameras, settings, scene.truth.centreline))
    if len(seeds) > 1:
        registered = (f"{sum(row['registered'] for row in rows)}/"
                      f"{sum(row['total'] for row in rows)}")
        rows += [{"scene": f"synthetic table: {name} of {len(seeds)}", "registered": registered,
                  **values} for name, values in mean_and_worst(rows, _SPREAD)]
    sample = Path(__file__).resolve().parents[2] / "samples" / "sequence"
    truth_file = sample / "ground_truth.json"
    if include_sample and truth_file.is_file():
        truth = read_ground_truth(truth_file)
        rows.append(_bench_one("samples/sequence",
                               list(open_image_sequence(sample / "images").paths),
                               truth.cameras, settings, truth.centreline))
    return rows

"""``python -m engine bench rod``: speed and accuracy of the rod fit on ground-truth scenes.

The table scene of a cable of radius 2 mm with 12 crossings, about 1000 r long, 12 views at
960x720, in two configurations:

* **ours**, as a user runs it: the scene rendered, reconstructed with its true cameras by the
  whole pipeline (its masks, estimated radius, grid, initial shape from the segment graph and
  topology, and crossings as contacts), one row per seed and the mean and worst of them; the
  fit's time is the pipeline's fit stage.
* **oracle** (the scaling study, fed the truth): for each vertex count, a stretch of the cable
  as many radii long (the whole cable, more finely sampled, when it is shorter) fitted from its
  true centreline plus 1 r of noise, with the voxels the carving leaves within 4 r of the true
  centreline, the image evidence of the exact masks and the true crossings as contacts.

A row gives the fit's time, its size and its distance from the true centreline in radii.
"""

import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from ..evaluation.metrics import evaluate
from ..io.ground_truth import GroundTruth
from ..io.result import CablePath, Result
from ..stages.carving import CarvingSettings, carve
from ..stages.rod_fit import Contact, ImageEvidence, RodFitSettings, Voxels, fit_rod
from ..stages.segmentation import cable_width, junction_map
from ..synthetic.cameras import orbit_cameras
from ..synthetic.render import render_masks
from ..synthetic.scene import SceneSpec, make_scene, write_scene

__all__ = ["bench_rod", "scene_masks", "carve_stretch", "noisy_chain"]


def scene_masks(spec):
    """A scene's ground truth (with orbit cameras) and exact masks, without rendering images.

    Parameters
    ----------
    spec : SceneSpec

    Returns
    -------
    truth : GroundTruth
    masks : list of ndarray of bool
    """
    truth = spec.layout()
    cameras = orbit_cameras(truth, views=spec.views, width=spec.width, height=spec.height,
                            elevations=(45.0, 75.0), seed=spec.seed)
    truth = truth.with_cameras(cameras)
    return truth, list(render_masks(truth, cameras))


def carve_stretch(centreline, radius, cameras, masks, *, voxels_per_radius=2.0, reach=4.0,
                  shift=0.0, agreement=None):
    """The carving's voxels (:func:`engine.stages.carving.carve`) around a stretch of cable.

    The cube carved is the stretch's bounding box grown by ``reach`` radii; other parts of
    the cable may pass through it, so only the voxels within ``reach`` radii of the stretch
    are kept.

    Parameters
    ----------
    centreline : ndarray, shape (M, 3)
        The stretch, densely sampled.
    radius : float
    cameras : sequence of Camera
    masks : sequence of ndarray of bool
    voxels_per_radius : float, optional
        The voxel size is ``radius / voxels_per_radius``.
    reach : float, optional
        In radii.
    shift : float, optional
        Shift of the grid along every axis, in voxels (0 to 1).
    agreement : float, optional
        Keep only the grid's core (see :meth:`Voxels.from_grid`).

    Returns
    -------
    Voxels
    """
    size = radius / voxels_per_radius
    lower = centreline.min(axis=0) - reach * radius + shift * size
    side = float(np.max(np.ptp(centreline, axis=0))) + 2.0 * reach * radius + size
    grid = carve(cameras, masks, radius=radius, region=(lower, side),
                 settings=CarvingSettings(voxels_per_radius=voxels_per_radius))
    return Voxels.from_grid(grid, agreement=agreement).near(centreline, reach * radius)


def noisy_chain(centreline, radius, *, noise=1.0, seed=0):
    """Every ``stride``-th centreline point (about one per radius) plus Gaussian noise of
    ``noise`` radii (root mean square, in 3D).

    Returns
    -------
    chain : ndarray, shape (M, 3)
    stride : int
        Centreline point ``k * stride`` became chain point ``k``.
    """
    steps = np.linalg.norm(np.diff(centreline, axis=0), axis=1)
    stride = max(int(round(radius / max(float(np.median(steps)), 1e-300))), 1)
    chain = centreline[::stride]
    rng = np.random.default_rng(seed)
    return chain + rng.normal(scale=noise * radius / np.sqrt(3.0), size=chain.shape), stride


def _stretch_of(truth, length):
    """The true cable's first ``length`` (world units), with its crossings, as a GroundTruth."""
    keep = truth.arc_length <= length
    crossings = tuple(c for c in truth.crossings if keep[c.over] and keep[c.under])
    return GroundTruth(truth.centreline[keep], truth.radius, crossings,
                       cameras=truth.cameras, up=truth.up)


def bench_rod(*, counts=(250, 500, 1000, 2000), views=12, width=960, height=720, seed=3,
              seeds=(0, 1, 2), settings=RodFitSettings()):
    """The rod fit as the pipeline runs it, and fits of growing vertex counts fed the truth
    (see the module notes).

    Parameters
    ----------
    counts : sequence of int
        Vertex counts of the oracle rows (none: no oracle rows).
    views, width, height : int
    seed : int
        The oracle rows' scene.
    seeds : sequence of int
        The scenes of the pipeline's rows.
    settings : RodFitSettings

    Returns
    -------
    list of dict
        ``rows`` ("ours, seed N", their mean and worst, then "oracle: ..."), ``vertices``,
        ``fit_s``, ``ms_per_vertex``, ``accuracy_mean``, ``accuracy_p95``, ``crossings``
        (right/total); the oracle rows also ``length_r``, ``spacing_r``, ``voxels``,
        ``iterations``, ``converged``, ``accuracy_max`` and ``evidence_s`` (the image evidence
        of all views, shared by them); a failed run ``error``.
    """
    rows = _pipeline_rows(seeds, views, width, height, settings)
    if counts:
        rows += _oracle_rows(counts, views, width, height, seed, settings)
    return rows


def _pipeline_rows(seeds, views, width, height, settings):
    """One row per seed, as the pipeline fits (in a fresh process), then their mean and worst."""
    from ..pipeline import PipelineSettings
    from .common import in_fresh_process, mean_and_worst
    from .pipeline import scored_run

    pipeline = replace(PipelineSettings(), fit=settings)
    rows = []
    with tempfile.TemporaryDirectory(prefix="bench_rod_") as folder:
        for seed in seeds:
            spec = _scene(seed, views, width, height, image_format="jpg")
            capture = write_scene(make_scene(spec), Path(folder) / f"seed{seed}")
            run = in_fresh_process(scored_run, capture, capture / "ground_truth.json", True,
                                   None, pipeline)
            row = {"rows": f"ours, seed {seed}"}
            if "error" in run:
                rows.append({**row, "error": run["error"]})
                continue
            rows.append({**row, "vertices": run["points"], "fit_s": run["fit_s"],
                         "ms_per_vertex": 1000.0 * run["fit_s"] / run["points"],
                         "accuracy_mean": run["accuracy_mean"],
                         "accuracy_p95": run["accuracy_p95"], "crossings": run["crossings"]})
    done = [row for row in rows if "error" not in row]
    if len(done) > 1:
        for name, values in mean_and_worst(done, ("fit_s", "ms_per_vertex", "accuracy_mean",
                                                  "accuracy_p95")):
            rows.append({"rows": f"ours, {name} of {len(done)}", **values})
    return rows


def _scene(seed, views, width, height, **options):
    return SceneSpec(kind="table", crossings=12, seed=seed, radius=0.002, extent=0.4,
                     views=views, width=width, height=height, **options)


def _oracle_rows(counts, views, width, height, seed, settings):
    """The scaling study, fed the truth (see the module notes)."""
    truth, masks = scene_masks(_scene(seed, views, width, height))
    r = truth.radius
    started = time.perf_counter()
    evidence = [ImageEvidence.from_mask(camera, mask, junction_map(mask, cable_width(mask)),
                                        settings=settings)
                for camera, mask in zip(truth.cameras, masks)]
    evidence_s = time.perf_counter() - started
    rows = []
    for count in counts:
        length = min(count * r, truth.length)
        stretch = _stretch_of(truth, length)
        voxels = carve_stretch(stretch.centreline, r, truth.cameras, masks)
        chain, stride = noisy_chain(stretch.centreline, r, seed=seed)
        contacts = [Contact(over=c.over // stride, under=c.under // stride)
                    for c in stretch.crossings]
        spacing = length / r / count
        fit_settings = replace(settings, spacing=spacing)
        started = time.perf_counter()
        fit = fit_rod(chain, r, voxels=voxels, views=evidence, contacts=contacts,
                      settings=fit_settings)
        fit_s = time.perf_counter() - started
        metrics = evaluate(Result(radius=r, paths=(CablePath(fit.points),)), stretch)
        rows.append({"rows": "oracle: true centreline + 1 r, contacts, voxels near it",
                     "vertices": len(fit.points), "length_r": float(length / r),
                     "spacing_r": float(spacing), "voxels": len(voxels.centres),
                     "fit_s": fit_s, "ms_per_vertex": 1000.0 * fit_s / len(fit.points),
                     "iterations": fit.iterations, "converged": str(fit.converged),
                     "accuracy_mean": metrics.accuracy_mean, "accuracy_p95": metrics.accuracy_p95,
                     "accuracy_max": metrics.accuracy_max,
                     "crossings": f"{metrics.crossings_right}/{metrics.crossings_total}",
                     "evidence_s": evidence_s})
    return rows

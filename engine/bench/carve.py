"""``python -m engine bench carve``: voxel carving and the segment graph on ground-truth scenes.

Each scene's masks (segmented from its images, as a user's would be) and junction maps are
written as PNG files and carved by a fresh process that reads them one at a time, so the peak
memory of a row is that process's whole peak (interpreter and libraries included). A row gives
the carving and graph times, the grid, the graph against the truth (junctions of degree 4 at
the crossings, segments 2N+1 for an open cable) and how far the segments' centrelines lie from
the true one, in radii. Each scene has two rows: *ours*, carved as a reconstruction carves
(the radius estimated from the masks, the voxel size the settings' own), and an *oracle* row
fed the truth (256 voxels along the longest side of the cable's box, the issue's measure, with
the true radius). Each family (a table with 3, 6 and 8 crossings, a closed loop, an overhand
knot) has a scene per seed, then its mean and worst. The last row carves 200 views of
3840x2880 for memory alone.
"""

import tempfile
import time
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np
from scipy.spatial import cKDTree

from ..geometry.camera import Camera
from ..stages.carving import CarvingSettings, carve
from ..stages.segment_graph import extract_segment_graph_from_voxels
from ..stages.segmentation import (cable_width, junction_map, reference_frames,
                                   segment_images, sequence_colour)
from ..synthetic.cameras import orbit_cameras
from ..synthetic.render import render_masks
from ..synthetic.scene import SceneSpec, make_scene
from .common import in_fresh_process, mean_and_worst

__all__ = ["bench_carve", "graph_scores"]

#: Scale of the memory row's images over 960x720.
_MEMORY_SCALE = 4


def graph_scores(graph, truth):
    """The segment graph against the truth.

    Returns
    -------
    dict
        ``junctions`` (found), ``crossings`` (true), ``crossings_found`` (true crossings with
        exactly one junction of degree 4 within 3 r), ``segments`` and ``segments_expected``
        (2N+1 for an open cable with N crossings, 2N for a closed one with N > 0, 1 for a plain
        loop), ``chain_mean_r`` and ``chain_p95_r`` (segment centreline points' distance to
        the true centreline).
    """
    r = truth.radius
    junctions = [(data["position"], graph.degree(node)) for node, data in graph.junctions()]
    found = 0
    for crossing in truth.crossings:
        position = truth.crossing_position(crossing)
        near = [degree for place, degree in junctions if np.linalg.norm(place - position) < 3 * r]
        found += near == [4]
    crossings = len(truth.crossings)
    # each crossing is a junction of degree 4: 2N segments on a loop (one if N = 0), and the
    # two ends add one on an open cable
    expected = (max(2 * crossings, 1) if truth.closed else 2 * crossings + 1)
    tree = cKDTree(truth.centreline)
    distances = np.concatenate([tree.query(points)[0] for *_, points in graph.segments()]
                               or [np.full(1, np.nan)])
    return {"junctions": len(junctions), "crossings": crossings, "crossings_found": found,
            "segments": graph.n_segments, "segments_expected": expected,
            "chain_mean_r": float(np.mean(distances) / r),
            "chain_p95_r": float(np.percentile(distances, 95) / r)}


def _write_masks(folder, masks, junctions):
    paths = []
    for number, (mask, junction) in enumerate(zip(masks, junctions)):
        mask_path, junction_path = folder / f"{number:03d}.png", folder / f"{number:03d}_j.png"
        cv2.imwrite(str(mask_path), mask.astype(np.uint8) * 255)
        cv2.imwrite(str(junction_path), junction.astype(np.uint8) * 255)
        paths.append((str(mask_path), str(junction_path)))
    return paths


def _reader(path, scale=1):
    def read():
        mask = cv2.imread(path, cv2.IMREAD_GRAYSCALE) > 0
        if scale == 1:
            return mask
        return cv2.resize(mask.view(np.uint8), None, fx=scale, fy=scale,
                          interpolation=cv2.INTER_NEAREST) > 0
    return read


def _carve_row(cameras, paths, truth, settings, scale, cells):
    """Runs in a fresh process: carve from files, build the graph, score."""
    if cells:
        # the grid: ``cells`` voxels along the longest side of the cable's box
        side = float(np.ptp(truth.centreline, axis=0).max() + 2 * truth.radius)
        settings = replace(settings, voxels_per_radius=cells * truth.radius / side)
    started = time.perf_counter()
    grid = carve(cameras, [_reader(m, scale) for m, _ in paths],
                 [_reader(j, scale) for _, j in paths], radius=truth.radius if cells else None,
                 settings=settings)
    carved = time.perf_counter()
    row = {"carve_s": carved - started, "grid": "x".join(map(str, grid.shape)),
           "voxels_across": 2 * grid.radius / grid.voxel_size,
           "occupied": len(grid)}
    if scale == 1:
        core = grid.core(settings.core_agreement)
        graph = extract_segment_graph_from_voxels(grid.index[core], grid.junction[core],
                                                  origin=grid.origin,
                                                  voxel_size=grid.voxel_size, radius=grid.radius)
        row["graph_s"] = time.perf_counter() - carved
        row.update(graph_scores(graph, truth))
    return row


def _scene_rows(specs, settings, folder, cells):
    rows = []
    for label, spec in specs:
        scene = make_scene(spec)
        frames = [scene.images[k] for k in reference_frames(len(scene.images), 0, 3)]
        colour, model = sequence_colour(frames)  # as the reconstruction segments
        segmentations = segment_images(scene.images, colour, model=model)
        place = Path(folder) / label.replace(" ", "_")
        place.mkdir()
        paths = _write_masks(place, [s.mask for s in segmentations],
                             [s.junctions for s in segmentations])
        # as a reconstruction carves (the radius estimated, the grid its own), and beside
        # it the grid the issue measured, set from the true radius
        for grid, size in (("ours", 0), (f"oracle: true radius, {cells} across", cells)):
            if grid != "ours" and not cells:
                continue
            row = {"scene": label, "grid_from": grid, "views": spec.views,
                   "size": f"{spec.width}x{spec.height}"}
            row.update(in_fresh_process(_carve_row, scene.cameras, paths, scene.truth, settings,
                                        1, size))
            rows.append(row)
    return rows


#: What the mean and worst rows summarise (the worst is the largest of each).
_SPREAD = ("carve_s", "graph_s", "chain_mean_r", "chain_p95_r")


def _spread(family, rows):
    """Each grid's mean and worst over a family's scenes, the crossings found summed."""
    summary = []
    for grid in dict.fromkeys(row["grid_from"] for row in rows):
        done = [row for row in rows if row["grid_from"] == grid and "error" not in row]
        if not done:
            continue
        found = (f"{sum(row['crossings_found'] for row in done)}/"
                 f"{sum(row['crossings'] for row in done)}")
        for name, values in mean_and_worst(done, _SPREAD):
            summary.append({"scene": f"{family}: {name} of {len(done)}", "grid_from": grid,
                            **values, "crossings_found": found})
    return summary


def _memory_row(settings, folder, views=200):
    """200 views at 4x the size: 50 rendered masks, each used by 4 cameras at 4x resolution."""
    spec = SceneSpec(crossings=3, seed=1, views=50)
    truth = spec.layout()
    cameras = orbit_cameras(truth, views=50, width=960, height=720, elevations=(45.0, 75.0))
    masks = list(render_masks(truth, cameras))
    paths = _write_masks(Path(folder), masks, [junction_map(m, cable_width(m)) for m in masks])
    big = []
    for copy in range(views // len(cameras)):
        for camera in cameras:
            params = np.array(camera.params, dtype=float) * _MEMORY_SCALE
            big.append(Camera(f"{copy}_{camera.name}", camera.width * _MEMORY_SCALE,
                              camera.height * _MEMORY_SCALE, camera.model, params,
                              camera.R, camera.t))
    truth = truth.with_cameras(())
    row = {"scene": "memory: table 3", "grid_from": "ours", "views": len(big),
           "size": f"{960 * _MEMORY_SCALE}x{720 * _MEMORY_SCALE}"}
    row.update(in_fresh_process(_carve_row, big, paths * (views // len(cameras)), truth, settings,
                                 _MEMORY_SCALE, 0))
    return row


#: The scene families: (label, SceneSpec options).
FAMILIES = (("table 3", dict(crossings=3)), ("table 6", dict(crossings=6)),
            ("table 8", dict(crossings=8)), ("loop 4", dict(kind="loop", crossings=4)),
            ("knot", dict(kind="knot")))


def bench_carve(*, views=30, seeds=(1, 2, 3), settings=CarvingSettings(), cells=256,
                memory=True):
    """Carving and segment graph rows (see the module notes).

    Parameters
    ----------
    views : int, optional
        Views per scene.
    seeds : sequence of int, optional
        One scene per seed and family; with more than one, each family's rows are followed by
        their mean and worst.
    settings : CarvingSettings, optional
    cells : int, optional
        Each scene is carved as a reconstruction carves it (the radius estimated from the
        masks, the settings' own voxel size) and, in an *oracle* row beside it, with
        ``cells`` voxels along the longest side of the cable's box and the true radius (0:
        no oracle row).
    memory : bool, optional
        Add the 200-view 3840x2880 memory row (about a minute).

    Returns
    -------
    list of dict
    """
    rows = []
    with tempfile.TemporaryDirectory(prefix="bench_carve_") as folder:
        for family, options in FAMILIES:
            specs = [(f"{family} seed {seed}", SceneSpec(seed=seed, views=views, **options))
                     for seed in seeds]
            found = _scene_rows(specs, settings, folder, cells)
            rows += found + (_spread(family, found) if len(seeds) > 1 else [])
        if memory:
            memory_folder = Path(folder) / "memory"
            memory_folder.mkdir()
            rows.append(_memory_row(settings, memory_folder))
    return rows

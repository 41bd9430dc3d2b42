"""``bench segment``: the masks and junction maps of the fast renders and the sample against their
exact masks, and the segmentation's speed."""

import math
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from ..errors import ReconstructionError
from ..io.ground_truth import read_ground_truth
from ..io.image_sequence import read_image
from ..stages.segmentation import (SegmentationSettings, reference_frames, segment_images,
                                   sequence_colour)
from ..synthetic.scene import SceneSpec, make_scene
from .common import DEFAULT_SAMPLE, mean_and_worst

__all__ = ["FAMILIES", "bench_segment", "junction_scores"]


def junction_scores(junctions, truth, camera):
    """Junction recall and stray pixels of one view against the true crossings.

    Returns
    -------
    found : int
        True crossings in front of the camera and inside the frame with a junction pixel
        within 2 r (projected) of them. A crossing is where its two strands meet in the image
        (:meth:`GroundTruth.crossing_in_view`).
    visible : int
        Such crossings.
    stray : int
        Junction pixels farther than 3 r (projected) from every true crossing.
    total : int
        Junction pixels.
    """
    ys, xs = np.nonzero(junctions)
    pixels = np.column_stack([xs + 0.5, ys + 0.5])
    near = np.zeros(len(pixels), dtype=bool)
    found = visible = 0
    for crossing in truth.crossings:
        (u, v), depth = truth.crossing_in_view(crossing, camera)
        if not (depth > 0 and 0 <= u < camera.width and 0 <= v < camera.height):
            continue
        radius = camera.focal[0] * truth.radius / depth
        distance = np.hypot(pixels[:, 0] - u, pixels[:, 1] - v)
        visible += 1
        found += bool((distance <= 2 * radius).any())
        near |= distance <= 3 * radius
    return found, visible, int((~near).sum()), len(pixels)


def _timed(images, colour, settings, model, *, passes=3):
    """Every frame segmented as a reconstruction does (the scoring comes after,
    so it neither counts nor cools the caches between frames); of ``passes`` passes, the
    fastest (as :mod:`timeit` advises: the others measure the machine's other work too).
    Returns ``(seconds, segmentations)``."""
    best = math.inf
    for _ in range(passes):
        started = time.perf_counter()
        segmentations = segment_images(images, colour, settings, model=model)
        best = min(best, time.perf_counter() - started)
    return best, segmentations


def _score_frames(name, images, masks, truth, settings):
    """As a reconstruction segments: the cable found and its colour model learnt on a few
    frames (not timed), then every frame segmented with it (timed)."""
    frames = reference_frames(len(images), 0, settings.model_frames)
    colour, model = sequence_colour([images[k] for k in frames], None, settings)
    seconds, segmentations = _timed(images, colour, settings, model)
    refined_seconds, _ = _timed(images, colour, replace(settings, edge_reach=_REFINE_REACH),
                                model)
    sideless_seconds, _ = _timed(images, colour, replace(settings, side_reach=0.0), model)
    unclassified_seconds, _ = _timed(images, colour, replace(settings, outline_passes=0), model)
    ious, found, visible, stray, total = [], 0, 0, 0, 0
    for segmentation, mask, camera in zip(segmentations, masks, truth.cameras):
        ious.append((segmentation.mask & mask).sum() / max((segmentation.mask | mask).sum(), 1))
        f, v, s, t = junction_scores(segmentation.junctions, truth, camera)
        found, visible, stray, total = found + f, visible + v, stray + s, total + t
    return {"scene": name, "frames": len(images), "size": f"{images[0].shape[1]}x"
            f"{images[0].shape[0]}", "iou_mean": float(np.mean(ious)),
            "iou_min": float(np.min(ious)),
            "junction_recall": found / visible if visible else float("nan"),
            "junction_stray": stray / total if total else 0.0,
            "ms_per_frame": 1000 * seconds / len(images),
            "ms_with_refine": 1000 * refined_seconds / len(images),
            "ms_without_side": 1000 * sideless_seconds / len(images),
            "ms_without_outline": 1000 * unclassified_seconds / len(images), "hsv": str(colour)}


#: The reach (pixels) ``ms_with_refine`` times the outline's colour refinement with: its default
#: before the outline's classifier was learnt without it.
_REFINE_REACH = 2

#: The fast-render families: (label, SceneSpec options, first seed). A family's seeds are its
#: first seed, then that plus 100, 200, ...
FAMILIES = (("table 3", dict(crossings=3), 1), ("table 6", dict(crossings=6), 2),
            ("table 12", dict(crossings=12, radius=0.005), 3), ("knot", dict(kind="knot"), 4),
            ("hanging", dict(kind="hanging"), 5),
            ("table 3 at 1280x720", dict(crossings=3, width=1280, height=720), 1))

#: What a family's mean and worst rows summarise, and of those the columns where more is better.
_SPREAD = ("iou_mean", "iou_min", "junction_recall", "junction_stray", "ms_per_frame",
           "ms_with_refine", "ms_without_side", "ms_without_outline")
_HIGHER_IS_BETTER = ("iou_mean", "iou_min", "junction_recall")


def bench_segment(*, sample=DEFAULT_SAMPLE, views=30, seeds=3, settings=SegmentationSettings()):
    """Mask IoU, junction recall and stray junction pixels, time per frame on one core.

    Scenes: the realistic sample (if ``sample`` exists) and, ``seeds`` scenes each, fast
    renders with 3, 6 and 12 crossings, a knot and a hanging cable at 960x720, and the
    3-crossing scene at 1280x720 for the speed target; with more than one seed, each family's
    rows are followed by their mean and worst (the worst IoU and recall the smallest, the
    worst stray share and time the largest). ``ms_per_frame`` is every default,
    ``ms_with_refine`` every default and the outline's colour refinement, which is off by
    default (``edge_reach=2``; :func:`~engine.stages.segmentation.refine_edges`),
    ``ms_without_side`` every default but the missing side's search (``side_reach=0``),
    ``ms_without_outline`` every default but the outline's classifier (``outline_passes=0``);
    each the fastest of three passes over the frames, the four timed one after the other on
    the same frames (on a busy machine only their differences say much).
    """
    import cv2

    threads = cv2.getNumThreads()
    cv2.setNumThreads(1)
    try:
        return _bench_segment(sample, views, seeds, settings)
    finally:
        cv2.setNumThreads(threads)


def _bench_segment(sample, views, seeds, settings):
    import cv2

    rows = []
    sample = Path(sample)
    if (sample / "ground_truth.json").is_file():
        truth = read_ground_truth(sample / "ground_truth.json")
        images = [read_image(sample / "images" / c.name) for c in truth.cameras]
        masks = [cv2.imread(str(sample / "masks" / (Path(c.name).stem + ".png")),
                            cv2.IMREAD_GRAYSCALE) > 0 for c in truth.cameras]
        rows.append(_score_frames("sample (Cycles)", images, masks, truth, settings))
    for label, options, first in FAMILIES:
        family = []
        for seed in range(first, first + 100 * seeds, 100):
            scene = make_scene(SceneSpec(seed=seed, views=views, **options))
            size = f"{scene.images[0].shape[1]}x{scene.images[0].shape[0]}"
            name = f"fast {label} seed {seed}"
            try:
                family.append(_score_frames(name, list(scene.images), list(scene.masks),
                                            scene.truth, settings))
            except ReconstructionError as error:  # no cable found: the row says so
                family.append({"scene": name, "size": size, "error": str(error)})
        rows += family
        if seeds > 1:
            rows += [{"scene": f"fast {label}: {name} of {len(family)}", "size": size, **values}
                     for name, values in mean_and_worst(family, _SPREAD,
                                                        higher_is_better=_HIGHER_IS_BETTER)]
    return rows

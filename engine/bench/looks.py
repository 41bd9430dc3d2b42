"""``python -m engine bench looks``: the masks on every look family, tuning and held-out.

Each scene is segmented as a user's run would be: the cable found automatically on a few
frames (:func:`engine.stages.segmentation.sequence_colour`), its colour model learnt there, every
frame segmented with it. Beside each row, the *naive* mask: a plain threshold (saturation above 60
and value above 40 in OpenCV's HSV; a colourless cable: value below or above Otsu's split,
whichever side is smaller). Rows: each look family on its tuning seeds and on its held-out
seeds (:data:`engine.synthetic.looks.TUNING_SEEDS`, :data:`engine.synthetic.looks.HELD_OUT_SEEDS`;
code is tuned on the first only), the pre-rendered Cycles captures in ``samples/looks`` (held out)
and real photos with labels (``../shared/real/mbest-s1``, when present; they were looked at while
tuning, so they are not held out). Frames are segmented on one core. A family of several
cables (:data:`engine.synthetic.looks.SEVERAL_CABLES`) is segmented as a user asking for all of them
would (``all_cables``), and scored against the masks of every cable.

The *oracle seed* column is fed the truth and labelled so: every frame segmented with the
colour model learnt from the **true** masks of the frames the model is learnt from. Where it
is low, the classifier (the model and the rules after it) is what loses, not finding the
cable; where ours is far below it, finding the cable or its seed is.
"""

import time
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np

from ..io.image_sequence import read_image
from ..stages.segmentation import (SegmentationSettings, colour_from_masks, reference_frames,
                                   segment_images, sequence_colour)
from ..synthetic.looks import HELD_OUT_SEEDS, LOOK_FAMILIES, SEVERAL_CABLES, TUNING_SEEDS
from ..synthetic.scene import look_scene

__all__ = ["bench_looks", "naive_mask", "score_sequence"]

#: A scene counts as "cable found" when its mean IoU is above this.
FOUND_IOU = 0.5


def naive_mask(image_rgb):
    """The plain threshold the bench compares against (see the module docstring)."""
    hsv = cv2.cvtColor(np.ascontiguousarray(image_rgb), cv2.COLOR_RGB2HSV)
    coloured = (hsv[..., 1] > 60) & (hsv[..., 2] > 40)
    if coloured.mean() > 0.002:
        return coloured
    threshold, _ = cv2.threshold(hsv[..., 2], 0, 255, cv2.THRESH_BINARY + cv2.THRESH_OTSU)
    dark = hsv[..., 2] <= threshold
    return dark if dark.mean() < 0.5 else ~dark


def _iou(a, b):
    return float((a & b).sum() / max((a | b).sum(), 1))


def score_sequence(images, truths, settings=SegmentationSettings(), *, oracle=False):
    """Mask IoU of every frame (ours and the naive threshold's) and our times.

    Parameters
    ----------
    images, truths : sequence of ndarray
        The frames (RGB uint8) and their true cable masks.
    settings : SegmentationSettings, optional
    oracle : bool, optional
        Also segment with the colour model learnt from the true masks of the same frames
        (:func:`engine.stages.segmentation.colour_from_masks`): the *oracle seed*, what the model
        and the rules after it make of a perfect seed. Not with ``settings.all_cables``.

    Returns
    -------
    dict
        ``iou``, ``naive`` (lists, one per frame), ``oracle`` (a list, or None), ``setup_ms``
        (finding the cable and learning its colour model on three frames), ``ms_per_frame``
        and ``hsv``.
    """
    started = time.perf_counter()
    frames = reference_frames(len(images), 0, settings.model_frames)
    colour, model = sequence_colour([images[k] for k in frames], None, settings)
    setup = time.perf_counter() - started
    started = time.perf_counter()  # one pass, as a reconstruction segments; scored after
    masks = [found.mask for found in segment_images(images, colour, settings, model=model)]
    seconds = time.perf_counter() - started
    ious = [_iou(mask, truth) for mask, truth in zip(masks, truths)]
    oracle_ious = None
    if oracle and not settings.all_cables:
        known, known_model = colour_from_masks([images[k] for k in frames],
                                               [truths[k] for k in frames], settings)
        oracle_ious = [_iou(found.mask, truth) for found, truth in zip(
            segment_images(images, known, settings, model=known_model), truths)]
    return {"iou": ious, "naive": [_iou(naive_mask(i), t) for i, t in zip(images, truths)],
            "oracle": oracle_ious,
            "setup_ms": 1000.0 * setup, "ms_per_frame": 1000.0 * seconds / len(images),
            "hsv": str(colour)}


def _row(name, split, scores):
    scene_iou = [float(np.mean(s["iou"])) for s in scores]
    return {"looks": name, "set": split, "scenes": len(scores),
            "iou_mean": float(np.mean(scene_iou)), "iou_worst_scene": float(np.min(scene_iou)),
            "iou_worst_frame": float(min(np.min(s["iou"]) for s in scores)),
            "naive_iou_mean": float(np.mean([np.mean(s["naive"]) for s in scores])),
            "oracle_seed_iou": _oracle_mean(scores),
            "cable_found": f"{sum(v > FOUND_IOU for v in scene_iou)}/{len(scores)}",
            "setup_ms": float(np.mean([s["setup_ms"] for s in scores])),
            "ms_per_frame": float(np.mean([s["ms_per_frame"] for s in scores]))}


def _scene_row(name, split, scene, scores):
    """One scene's row (``bench looks --per-scene``): its mean and worst frame."""
    oracle = scores.get("oracle")
    return {"looks": name, "set": split, "scene": scene, "frames": len(scores["iou"]),
            "iou_mean": float(np.mean(scores["iou"])),
            "iou_worst_frame": float(np.min(scores["iou"])),
            "naive_iou_mean": float(np.mean(scores["naive"])),
            "oracle_seed_iou": "" if oracle is None else float(np.mean(oracle))}


def _oracle_mean(scores):
    """Mean over the scenes of the oracle seed's IoU; "" when no scene has one (several
    cables), marked "(n)" when only n of them do."""
    oracle = [float(np.mean(s["oracle"])) for s in scores if s.get("oracle") is not None]
    if not oracle:
        return ""
    mean = f"{np.mean(oracle):.3f}"
    return mean if len(oracle) == len(scores) else f"{mean} ({len(oracle)})"


def _read_capture(folder, mask_folder):
    paths = sorted(p for p in (folder / "images").iterdir() if p.suffix.lower() in
                   (".jpg", ".jpeg", ".png"))
    images = [read_image(p) for p in paths]
    truths = [cv2.imread(str(folder / mask_folder / (p.stem + ".png")), cv2.IMREAD_GRAYSCALE)
              > 127 for p in paths]
    return images, truths


def bench_looks(*, seeds=3, views=10, width=960, height=720, captures=Path("samples") / "looks",
                real=Path("..") / "shared" / "real" / "mbest-s1",
                settings=SegmentationSettings(), families=LOOK_FAMILIES, oracle=True,
                per_scene=False):
    """One row per look family and seed set, then the Cycles captures and real photos (with
    ``per_scene``, one row per scene and capture instead).

    Parameters
    ----------
    seeds : int, optional
        Scenes per family and set (the first seeds of each set).
    views, width, height : int, optional
        Of each synthetic scene.
    captures : path, optional
        Folder of pre-rendered captures (``<look>/images``, ``<look>/masks``); None: none.
    real : path, optional
        Real photos with labels (``images/``, ``labels/``); skipped when missing or None.
    settings : SegmentationSettings, optional
    families : sequence of str, optional
    oracle : bool, optional
        Add the *oracle seed* column (:func:`score_sequence`): what the colour model and the
        rules after it make of the true masks as their seed, beside what they make of the
        found cable's.
    per_scene : bool, optional
        One row per scene (its seed) and capture, not per family: two runs' tables then
        compare scene by scene.

    Returns
    -------
    list of dict
    """
    threads = cv2.getNumThreads()
    cv2.setNumThreads(1)
    rows, every = [], {"tuning": [], "held-out": []}
    try:
        for family in families:
            for split, pool in (("tuning", TUNING_SEEDS), ("held-out", HELD_OUT_SEEDS)):
                scores = []
                for seed in pool[:seeds]:
                    scene = look_scene(family, seed, views=views, width=width, height=height)
                    scores.append(score_sequence(
                        list(scene.images), list(scene.masks),
                        replace(settings, all_cables=True) if family in SEVERAL_CABLES
                        else settings, oracle=oracle))
                    if per_scene:
                        rows.append(_scene_row(family, split, f"seed {seed}", scores[-1]))
                every[split] += scores
                if not per_scene:
                    rows.append(_row(family, split, scores))
        if not per_scene:
            for split, scores in every.items():
                rows.append(_row("all families", split, scores))
        if captures is not None and Path(captures).is_dir():
            folders = [folder for folder in sorted(Path(captures).iterdir())
                       if (folder / "ground_truth.json").is_file()]
            scores = [score_sequence(*_read_capture(folder, "masks"), settings, oracle=oracle)
                      for folder in folders]
            if per_scene:
                rows += [_scene_row("Cycles captures", "held-out", folder.name, score)
                         for folder, score in zip(folders, scores)]
            elif scores:
                rows.append(_row("Cycles captures", "held-out", scores))
        if real is not None and (Path(real) / "labels").is_dir():
            real = Path(real)
            scores = score_sequence(*_read_capture(real, "labels"), settings, oracle=oracle)
            rows.append(_scene_row("real photos", "used in tuning", real.name, scores)
                        if per_scene else
                        _row(f"real photos ({real.name})", "used in tuning", [scores]))
    finally:
        cv2.setNumThreads(threads)
    return rows

"""Learning the outline's classifier (:mod:`engine.stages.outline`) on tuning looks.

Each scene of the tuning seeds is rendered (:func:`engine.synthetic.scene.look_scene`) and
segmented as a user's run would segment it (the cable found automatically, its colour model
learnt on three frames), with the outline's classifier off. The pixels near each mask's
outline, and near the true mask's grown and shrunk by a pixel or two, are sampled with their
features and true labels, and a network of one hidden layer is fitted to them (cross-entropy,
L-BFGS, a little weight decay; seeded, so the same scenes give the same weights). Held-out
seeds are never used.

``python -m engine.evaluation.outline_training -o engine/stages/outline_weights.json`` learns
the weights the engine ships (the defaults below; about a quarter of an hour on one core).
"""

import argparse
import json
import sys
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np
from scipy.optimize import minimize

from ..stages.outline import HIDDEN, OutlineClassifier, outline_features
from ..stages.segmentation import (SegmentationSettings, cable_mask, cable_width,
                                   reference_frames, sequence_colour)
from ..synthetic.looks import LOOK_FAMILIES, SEVERAL_CABLES, TUNING_SEEDS
from ..synthetic.scene import SceneSpec, look_spec, make_scene

__all__ = ["band_samples", "fit_outline", "learn_outline", "perturbed", "segmented",
           "training_scenes", "PERTURBATIONS", "TRAINING_SEEDS", "DEFAULT_LOOK_SEEDS"]

#: Tuning seeds the shipped weights were learnt on: not the seeds ``bench looks`` reports as
#: its tuning rows (the first eight), so those rows are not the training data.
TRAINING_SEEDS = TUNING_SEEDS[10:18]
#: Seeds of the default look's scenes (no bench draws these).
DEFAULT_LOOK_SEEDS = tuple(range(3000, 3008))
_DEFAULT_SIZES = ((960, 720), (480, 360), (1280, 720))


#: Besides the segmentation's masks, the classifier learns from the true masks grown (or,
#: negative, shrunk) by these many pixels: masks off by more than the segmentation's usual
#: pixel, so it holds where the colours misled the segmentation further and can decide again
#: around its own outline.
PERTURBATIONS = (-1, 1, 2)


def perturbed(truth, pixels):
    """``truth`` grown by ``pixels`` (shrunk when negative), a disc at a time."""
    size = 2 * abs(pixels) + 1
    disc = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (size, size))
    change = cv2.dilate if pixels > 0 else cv2.erode
    return change(truth.astype(np.uint8), disc) > 0


def band_samples(image_rgb, truth, mask, width, *, count, rng):
    """Up to ``count`` pixels near ``mask``'s outline: their features and true labels.

    Parameters
    ----------
    image_rgb : ndarray, shape (H, W, 3), uint8
    truth, mask : ndarray of bool, shape (H, W)
        The true cable mask and the segmentation's (before the outline's classifier).
    width : float
        The cable's width the segmentation measured.
    count : int
    rng : numpy.random.Generator

    Returns
    -------
    features : ndarray of float32, shape (N, F)
    labels : ndarray of float64, shape (N,)
    """
    pixels, features = outline_features(mask, image_rgb, width)
    if len(pixels) > count:
        pick = np.sort(rng.choice(len(pixels), count, replace=False))
        pixels, features = pixels[pick], features[pick]
    return features, truth.ravel()[pixels].astype(np.float64)


def _unpacked(theta, features, hidden):
    inputs = features
    weights = theta[:inputs * hidden].reshape(inputs, hidden)
    biases = theta[inputs * hidden:(inputs + 1) * hidden]
    output = theta[(inputs + 1) * hidden:(inputs + 2) * hidden]
    return weights, biases, output, theta[-1]


def _loss(theta, standard, labels, hidden, decay):
    """Mean cross-entropy plus weight decay, and its gradient."""
    weights, biases, output, bias = (np.asarray(part, np.float32) for part in
                                     _unpacked(theta, standard.shape[1], hidden))
    units = np.tanh(standard @ weights + biases)  # float32: twice as fast, precise enough
    logits = (units @ output + bias).astype(np.float64)
    loss = np.mean(np.logaddexp(0.0, logits) - labels * logits) + decay * theta @ theta
    error = (1.0 / (1.0 + np.exp(-logits)) - labels) / len(labels)
    error32 = error.astype(np.float32)
    back = np.outer(error32, output) * (1.0 - units**2)
    gradient = np.concatenate([(standard.T @ back).ravel(), back.sum(axis=0),
                               units.T @ error32, [error32.sum()]]).astype(np.float64)
    return loss, gradient + 2.0 * decay * theta


def fit_outline(features, labels, *, hidden=HIDDEN, decay=1e-4, iterations=500, seed=0):
    """The classifier fitted to sampled pixels.

    Parameters
    ----------
    features : ndarray, shape (N, F)
    labels : ndarray, shape (N,)
        1 for cable, 0 for background.
    hidden : int, optional
    decay : float, optional
        Weight decay on every weight.
    iterations : int, optional
        L-BFGS iterations at most.
    seed : int, optional
        Of the starting weights.

    Returns
    -------
    OutlineClassifier
    """
    features = np.asarray(features, dtype=np.float64)
    mean, scale = features.mean(axis=0), features.std(axis=0) + 1e-6
    standard = ((features - mean) / scale).astype(np.float32)
    start = np.random.default_rng(seed).normal(0.0, 0.1, (standard.shape[1] + 2) * hidden + 1)
    fitted = minimize(_loss, start, args=(standard, np.asarray(labels, np.float64), hidden,
                                          decay),
                      jac=True, method="L-BFGS-B", options={"maxiter": iterations})
    weights, biases, output, bias = _unpacked(fitted.x, standard.shape[1], hidden)
    return OutlineClassifier(mean=mean.astype(np.float32), scale=scale.astype(np.float32),
                             hidden=weights.astype(np.float32),
                             hidden_bias=biases.astype(np.float32),
                             output=output.astype(np.float32), output_bias=float(bias))


def segmented(images, settings=SegmentationSettings()):
    """Every frame's mask and width as a run segments them, the outline's classifier off, and
    the colour model learnt once (``relearn`` off): the masks the shipped weights were learnt
    from, before the model was learnt a second time (whose first masks the classifier makes)."""
    bare = replace(settings, outline_passes=0, relearn=False)
    frames = reference_frames(len(images), 0, bare.model_frames)
    colour, model = sequence_colour([images[k] for k in frames], None, bare)
    return [cable_mask(image, colour, bare, model=model) for image in images]


def training_scenes(seeds=TRAINING_SEEDS, *, small_seeds=4):
    """The scenes the shipped weights are learnt on: ``(name, spec)`` in the order they are
    sampled.

    Every family of one cable at 960x720 on ``seeds`` (families in alphabetical order), then,
    each group in the order of the scenes' names: the default look (the sample's and ``bench
    segment``'s, :data:`DEFAULT_LOOK_SEEDS`) at 1280x720, 480x360 and 960x720 with 3 to 12
    crossings, and the families at 640x480 on the first ``small_seeds`` seeds; narrower and
    wider cables than the looks' at 960x720 alone (learnt on those only, the classifier spoiled
    a 5-pixel cable's mask: its IoU fell from 0.94 to 0.84).

    Raises
    ------
    ValueError
        A seed that is not a tuning seed.
    """
    if any(seed not in TUNING_SEEDS for seed in seeds):
        raise ValueError("the outline's classifier is learnt on tuning seeds only")
    families = sorted(f for f in LOOK_FAMILIES if f not in SEVERAL_CABLES)
    looks = [(f"{family}_{seed}", look_spec(family, seed, views=10, width=960, height=720))
             for family in families for seed in seeds]
    default = sorted((f"default{width}_{seed}",
                      SceneSpec(crossings=3 + seed % 4 * 3, seed=seed, views=10, width=width,
                                height=height))
                     for seed in DEFAULT_LOOK_SEEDS for width, height in _DEFAULT_SIZES)
    small = sorted((f"{family}640_{seed}", look_spec(family, seed, views=10, width=640,
                                                     height=480))
                   for family in families for seed in seeds[:small_seeds])
    return looks + default + small


def learn_outline(scenes=None, *, frames=4, per_frame=1500, hidden=HIDDEN, progress=None):
    """The classifier learnt on synthetic scenes.

    Parameters
    ----------
    scenes : sequence of (str, SceneSpec), optional
        Named scenes, sampled in this order (:func:`training_scenes` if None). A scene the
        renderer refuses (a cable too narrow at its size) is left out.
    frames, per_frame : int, optional
        Frames sampled per scene (spread over it) and pixels per frame of the segmentation's
        mask; as many again from the true mask grown and shrunk (:data:`PERTURBATIONS`).
    hidden : int, optional
    progress : callable, optional
        Called with a line per scene.

    Returns
    -------
    OutlineClassifier
    """
    rng = np.random.default_rng(0)
    features, labels = [], []
    for name, spec in training_scenes() if scenes is None else scenes:
        try:
            scene = make_scene(spec)
        except ValueError as error:  # too narrow a cable at this size
            if progress is not None:
                progress(f"{name}: left out ({error})")
            continue
        images, truths = list(scene.images), list(scene.masks)
        results = segmented(images)
        for k in np.linspace(0, len(images) - 1, frames).round().astype(int):
            masks = [(*results[k], per_frame)] + [
                (changed, cable_width(changed), per_frame // len(PERTURBATIONS))
                for changed in (perturbed(truths[k], pixels) for pixels in PERTURBATIONS)]
            for mask, found, count in masks:
                if found > 0:
                    sampled = band_samples(images[k], truths[k], mask, found, count=count,
                                           rng=rng)
                    features.append(sampled[0])
                    labels.append(sampled[1])
        if progress is not None:
            progress(f"{name}: {sum(len(x) for x in labels)} pixels")
    return fit_outline(np.concatenate(features), np.concatenate(labels), hidden=hidden)


def main(argv=None):
    """``python -m engine.evaluation.outline_training -o WEIGHTS.json``."""
    parser = argparse.ArgumentParser(prog="python -m engine.evaluation.outline_training",
                                     description=__doc__.split("\n\n")[0])
    parser.add_argument("-o", "--output", type=Path, required=True)
    parser.add_argument("--overwrite", action="store_true")
    parser.add_argument("--seeds", type=int, default=len(TRAINING_SEEDS),
                        help="the first N of the training seeds")
    args = parser.parse_args(argv)
    if args.output.exists() and not args.overwrite:
        parser.error(f"{args.output} exists (--overwrite replaces it)")
    cv2.setNumThreads(1)
    classifier = learn_outline(training_scenes(TRAINING_SEEDS[:args.seeds]),
                               progress=lambda line: print(line, file=sys.stderr))
    args.output.write_text(json.dumps(classifier.to_dict()) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""``python -m engine bench topology``: the easy layouts beside the hard ones, several seeds.

Two families of scenes (30 views at 960x720, the default look, true cameras):

* **easy**: a cable on a table with 3 to 8 crossings (by the seed) far apart, as the other
  benches' scenes (:func:`engine.synthetic.layouts.table_layout`, every view framing the cable);
* **hard**: a heap of 12 to 20 crossings, some 3 r apart, shallow ones down to 15°, tight
  loops, strands side by side (:func:`engine.synthetic.layouts.hard_layout`), seen by views that
  each frame only part of it (:data:`engine.synthetic.scene.HARD_FRAMING`).

The Cycles captures of hard layouts in ``samples/hard`` (``make sample-hard``: realistic
renders of held-out seeds, 30 views at 960x720, the cable out of many frames) are a third,
held-out family, *Cycles hard*.

Each family runs on tuning seeds and on held-out seeds (:data:`engine.synthetic.looks.TUNING_SEEDS`,
:data:`engine.synthetic.looks.HELD_OUT_SEEDS`; tune on the first only), each scene reconstructed in
a fresh process twice: with the **exact** masks (labelled *oracle*: they are the truth) and
with **ours**, segmented as a user's run does. A row sums up a family, seed set and masks:
scenes with one path per cable and every crossing right, crossings right over all scenes,
accuracy (mean and worst of the scenes' means and 95th percentiles, in r), the crossings
listed with a confidence of at least 0.9 and how many of those are right, wrong crossings
not listed as doubtful (no confidence under 0.9), and the topology stage's slowest time.
"""

import tempfile
from pathlib import Path

import numpy as np

from ..io.ground_truth import read_ground_truth
from ..synthetic.looks import HELD_OUT_SEEDS, TUNING_SEEDS
from ..synthetic.scene import SceneSpec, hard_spec, make_scene, write_scene
from .common import in_fresh_process
from .pipeline import scored_run

__all__ = ["TOPOLOGY_FAMILIES", "CAPTURES", "CAPTURE_FAMILY", "SUMMARY_COLUMNS", "SCENE_COLUMNS",
           "topology_spec", "bench_topology"]

#: The scene families, easy first.
TOPOLOGY_FAMILIES = ("easy", "hard")
#: The Cycles captures of hard layouts (``make sample-hard``; held out) and their rows' family.
CAPTURES = Path("samples") / "hard"
CAPTURE_FAMILY = "Cycles hard"

_MASKS = (("oracle: exact", True), ("ours", False))

#: The columns of the two tables :func:`bench_topology` returns.
SUMMARY_COLUMNS = ("family", "set", "masks", "scenes", "all_right", "crossings",
                   "accuracy_mean", "accuracy_worst", "p95_mean", "p95_worst", "completeness",
                   "confident_right", "wrong_undoubted", "topology_s_max", "total_s_mean",
                   "errors")
SCENE_COLUMNS = ("family", "set", "seed", "masks", "true_crossings", "accuracy_mean",
                 "accuracy_p95", "completeness", "crossings", "one_path", "confident_right",
                 "masks_warned", "topology_s", "total_s", "error")


def topology_spec(family, seed, *, views=30):
    """The scene of ``family`` (:data:`TOPOLOGY_FAMILIES`) and ``seed``.

    Returns
    -------
    SceneSpec
    """
    if family == "easy":
        return SceneSpec(kind="table", crossings=3 + seed % 6, seed=seed, views=views,
                         width=960, height=720, image_format="jpg")
    if family == "hard":
        return hard_spec(seed, views=views, image_format="jpg")
    raise ValueError(f"unknown topology family {family!r}: choose from "
                     f"{', '.join(TOPOLOGY_FAMILIES)}")


def _summary(family, split, masks, rows):
    """One row of the summary table from the scenes' rows."""
    done = [row for row in rows if "error" not in row]
    summary = {"family": family, "set": split, "masks": masks, "scenes": len(rows),
               "errors": len(rows) - len(done)}
    if not done:
        return summary
    checks = [check for row in done for check in row["checks"]]
    right_scenes = sum(row["one_path"] == "yes" and all(right for right, _ in row["checks"])
                       for row in done)
    confident = [right for right, confidence in checks
                 if confidence is not None and confidence >= 0.9]
    means = [row["accuracy_mean"] for row in done]
    p95 = [row["accuracy_p95"] for row in done]
    summary.update({
        "all_right": f"{right_scenes}/{len(rows)}",
        "crossings": f"{sum(right for right, _ in checks)}/{len(checks)}",
        "accuracy_mean": float(np.mean(means)), "accuracy_worst": float(np.max(means)),
        "p95_mean": float(np.mean(p95)), "p95_worst": float(np.max(p95)),
        "completeness": float(np.mean([row["completeness"] for row in done])),
        "confident_right": f"{sum(confident)}/{len(confident)}",
        "wrong_undoubted": sum(not right and (confidence is None or confidence >= 0.9)
                               for right, confidence in checks),
        "topology_s_max": float(np.max([row["topology_s"] for row in done])),
        "total_s_mean": float(np.mean([row["total_s"] for row in done]))})
    return summary


def bench_topology(*, seeds=3, views=30, families=TOPOLOGY_FAMILIES, captures=CAPTURES,
                   progress=None):
    """Reconstruct each family's tuning and held-out scenes, and the Cycles captures of hard
    layouts, with the exact masks and ours.

    Parameters
    ----------
    seeds : int, optional
        Scenes per family and seed set.
    views : int, optional
    families : sequence of str, optional
        Of :data:`TOPOLOGY_FAMILIES`.
    captures : path, optional
        Folder of pre-rendered Cycles captures (one folder each, as ``make sample-hard``
        writes them; all held out); None or a missing folder: none.
    progress : callable, optional
        ``progress(fraction, message)``.

    Returns
    -------
    summary : list of dict
        One row per family, seed set and masks (see the module notes), then one per masks
        over the captures (family ``"Cycles hard"``).
    scenes : list of dict
        One row per scene and masks.
    """
    for family in families:
        topology_spec(family, 0, views=views)  # an unknown family fails before any work
    jobs = [(family, split, seed) for family in families
            for split, pool in (("tuning", TUNING_SEEDS), ("held-out", HELD_OUT_SEEDS))
            for seed in pool[:seeds]]
    jobs += [(CAPTURE_FAMILY, "held-out", folder) for folder in _captures(captures)]
    scenes = []
    with tempfile.TemporaryDirectory(prefix="bench_topology_") as work:
        for number, (family, split, seed) in enumerate(jobs):
            label = seed.name if isinstance(seed, Path) else seed
            if progress is not None:
                progress(number / len(jobs), f"{family} {split} {label}")
            head = {"family": family, "set": split, "seed": label}
            try:
                folder, crossings = _scene_folder(seed, family, views, Path(work))
            except Exception as error:  # a layout that cannot be drawn is a row, not a stop
                scenes += [{**head, "masks": masks, "error": f"scene: {error}"[:80]}
                           for masks, _ in _MASKS]
                continue
            for masks, exact in _MASKS:
                row = {**head, "masks": masks, "true_crossings": crossings}
                row.update(in_fresh_process(
                    scored_run, str(folder), str(folder / "ground_truth.json"), True,
                    str(folder / "masks") if exact else None, None, True))
                scenes.append(row)
    summary = []
    for family, split in dict.fromkeys((family, split) for family, split, _ in jobs):
        for masks, _ in _MASKS:
            chosen = [row for row in scenes
                      if (row["family"], row["set"], row["masks"]) == (family, split, masks)]
            summary.append(_summary(family, split, masks, chosen))
    if progress is not None:
        progress(1.0, "done")
    return summary, [{key: value for key, value in row.items() if key != "checks"}
                     for row in scenes]


def _captures(folder):
    """The capture folders (holding a ground truth) under ``folder``, sorted; none if None."""
    if folder is None or not Path(folder).is_dir():
        return []
    return [path for path in sorted(Path(folder).iterdir())
            if (path / "ground_truth.json").is_file()]


def _scene_folder(seed, family, views, work):
    """``(folder, true crossings)`` of a job: a capture's own folder, or the scene of
    ``family`` and ``seed`` rendered into ``work``."""
    if isinstance(seed, Path):
        return seed, len(read_ground_truth(seed / "ground_truth.json").crossings)
    scene = make_scene(topology_spec(family, seed, views=views))
    folder = work / f"{family}-{seed}"
    write_scene(scene, folder)
    return folder, len(scene.truth.crossings)

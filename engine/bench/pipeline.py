"""``python -m engine bench pipeline``: the whole reconstruction on a seeded suite of scenes.

Scenes: the realistic sample (Cycles) and fast renders: a table with 0, 3, 6, 8 and 12
crossings, a closed loop, an overhand knot, a hanging cable, and radii of 1 and 10 mm. Each is
written as a capture (images/ and the true cameras in sparse/) and reconstructed twice in a
fresh process: with the true cameras, and with cameras estimated by pycolmap (the result then
aligned to the truth by a similarity). A row gives the accuracy in cable radii, completeness,
crossings right, one path, the radius error, the time of each stage and the peak memory.
"""

import tempfile
import time
from dataclasses import replace
from pathlib import Path

from ..errors import ReconstructionError
from ..io.ground_truth import read_ground_truth
from ..stages.mask_checks import CHECK_HINT
from ..synthetic.scene import SceneSpec, make_scene, write_scene
from .common import DEFAULT_SAMPLE, in_fresh_process, mean_and_worst
from .profile import profiled, top_functions

__all__ = ["bench_pipeline", "pipeline_suite", "bench_pipeline_looks", "scored_run"]

_STAGE_COLUMNS = ("masks", "cameras", "agreement", "carving", "graph", "topology", "fit")

#: Address space a bench run may use (bytes).
MEMORY_LIMIT = 8 * 1024 ** 3


def pipeline_suite(views=30):
    """The bench's synthetic scenes: ``(label, SceneSpec)`` pairs."""
    table = dict(views=views, width=960, height=720, image_format="jpg")
    return [
        ("table 0", SceneSpec(crossings=0, seed=10, **table)),
        ("table 3", SceneSpec(crossings=3, seed=1, **table)),
        ("table 6", SceneSpec(crossings=6, seed=2, **table)),
        ("table 8", SceneSpec(crossings=8, seed=5, **table)),
        ("table 12", SceneSpec(crossings=12, seed=3, radius=0.005, **table)),
        ("loop 4", SceneSpec(kind="loop", crossings=4, seed=6, **table)),
        ("knot", SceneSpec(kind="knot", seed=4, **table)),
        ("hanging", SceneSpec(kind="hanging", seed=5, **table)),
        ("table 3, r 1 mm", SceneSpec(crossings=3, seed=7, radius=0.001, **table)),
        ("table 3, r 10 mm", SceneSpec(crossings=3, seed=8, radius=0.01, **table)),
        ("pair 3, one colour", SceneSpec(kind="pair", crossings=3, seed=1, **table)),
    ]


def scored_run(folder, truth_file, use_true_cameras, masks=None, settings=None, details=False,
               profile=False):
    """In a fresh process: reconstruct one capture (with ``masks`` if given, and ``settings``,
    a :class:`.pipeline.PipelineSettings`, if given) and score it; with ``details``, the row
    also holds ``checks``: ``(right, confidence)`` of each true crossing; with ``profile``,
    the reconstruction runs under cProfile, on one thread (OpenCV's, the carving's and the
    workers' too), and the row holds ``profile`` (:func:`engine.bench.profile.engine_times`).

    The process may use at most :data:`MEMORY_LIMIT` bytes: a run past it is a row with its
    error, not a machine out of memory.
    """
    import resource

    from ..evaluation.metrics import evaluate
    from ..pipeline import run_reconstruction

    resource.setrlimit(resource.RLIMIT_AS, (MEMORY_LIMIT, MEMORY_LIMIT))
    truth = read_ground_truth(truth_file)
    folder = Path(folder)
    started = time.perf_counter()
    if profile:  # on one thread: cProfile cannot tell threads' calls apart
        import cv2

        from ..pipeline import PipelineSettings

        cv2.setNumThreads(1)
        settings = settings or PipelineSettings()
        settings = replace(settings, workers=1, carving=replace(settings.carving, threads=1))
    inputs = dict(cameras=folder / "sparse" if use_true_cameras else None, masks=masks,
                  **({} if settings is None else {"settings": settings}))
    try:
        if profile:
            state, times = profiled(run_reconstruction, folder / "images", **inputs)
        else:
            state = run_reconstruction(folder / "images", **inputs)
    except (ReconstructionError, ValueError, MemoryError) as error:
        return {"error": str(error)[:80], "total_s": time.perf_counter() - started}
    except Exception as error:  # a bug: the row says so, the bench goes on
        return {"error": f"bug: {type(error).__name__}: {error}"[:80],
                "total_s": time.perf_counter() - started}
    total = time.perf_counter() - started
    result = state.result
    metrics = evaluate(result, truth, align=not use_true_cameras)
    row = {"accuracy_mean": metrics.accuracy_mean, "accuracy_p95": metrics.accuracy_p95,
           "completeness": metrics.completeness,
           "crossings": f"{metrics.crossings_right}/{metrics.crossings_total}",
           "one_path": "yes" if metrics.one_path else "no",
           "radius_error": metrics.radius_error,
           "confident_right": _confident_right(metrics),
           "core_thickness": state.checks["core_thickness"],
           "unexplained": state.checks["unexplained"],
           "masks_warned": "yes" if any(CHECK_HINT in w for w in result.warnings) else "no",
           "points": sum(len(path.points) for path in result.paths)}
    row.update({f"{stage}_s": result.timings.get(stage, 0.0) for stage in _STAGE_COLUMNS})
    row["total_s"] = total
    if details:
        row["checks"] = [(bool(check.right), check.confidence)
                         for check in metrics.crossing_details]
    if profile:
        row["profile"] = times
    return row


def _settings_for(family, segmentation=None):
    """The settings a user would run a look family with: all cables where there are several
    (:data:`engine.synthetic.looks.SEVERAL_CABLES`), else the defaults (None); with
    ``segmentation`` (a :class:`SegmentationSettings`) in place of the default one."""
    from ..pipeline import PipelineSettings
    from ..synthetic.looks import SEVERAL_CABLES

    if family not in SEVERAL_CABLES and segmentation is None:
        return None
    settings = PipelineSettings()
    segmentation = segmentation if segmentation is not None else settings.segmentation
    if family in SEVERAL_CABLES:
        segmentation = replace(segmentation, all_cables=True)
    return replace(settings, segmentation=segmentation)


def _confident_right(metrics):
    """``right/total`` of the true crossings listed with a confidence of at least 0.9."""
    confident = [check for check in metrics.crossing_details
                 if check.confidence is not None and check.confidence >= 0.9]
    return f"{sum(check.right for check in confident)}/{len(confident)}"


def bench_pipeline(*, views=30, sample=DEFAULT_SAMPLE, estimated=True, seeds=1,
                   progress=None, profile=False):
    """Reconstruct every scene of the suite (see the module notes).

    Parameters
    ----------
    views : int, optional
        Views per synthetic scene.
    seeds : int, optional
        Scenes per synthetic family: its own seed, then that seed plus 100, 200 ...; with more
        than one, each family's rows are followed by their mean and worst.
    sample : str or os.PathLike, optional
        The realistic sample (skipped if missing).
    estimated : bool, optional
        Also run with pycolmap's cameras.
    progress : callable, optional
        ``progress(fraction, message)`` over the scenes.
    profile : bool, optional
        Run each reconstruction under cProfile (slower: read the rows' times against each
        other only) and return the functions that took its time too.

    Returns
    -------
    list of dict
        The rows; with ``profile``, ``(rows, functions)``: the costliest functions over the
        runs of each camera source (:func:`engine.bench.profile.top_functions`).
    """
    runs = [(True, "true"), (False, "pycolmap")] if estimated else [(True, "true")]
    scenes = []
    sample = Path(sample)
    if (sample / "ground_truth.json").is_file():
        scenes.append(("sample (Cycles)", None))
    for label, spec in pipeline_suite(views):
        scenes += [(label if seeds == 1 else f"{label}, seed {spec.seed + 100 * k}",
                    replace(spec, seed=spec.seed + 100 * k)) for k in range(seeds)]
    rows = []
    with tempfile.TemporaryDirectory(prefix="bench_pipeline_") as work:
        for number, (label, spec) in enumerate(scenes):
            if progress is not None:
                progress(number / len(scenes), label)
            if spec is None:
                folder = sample
            else:
                folder = Path(work) / f"scene{number}"
                write_scene(make_scene(spec), folder)
            for use_true, camera_label in runs:
                row = {"scene": label, "cameras": camera_label}
                row.update(in_fresh_process(scored_run, str(folder),
                                            str(folder / "ground_truth.json"), use_true,
                                            None, None, False, profile))
                rows.append(row)
    if progress is not None:
        progress(1.0, "done")
    times = [(row["cameras"], row.pop("profile")) for row in rows if "profile" in row]
    rows = rows if seeds == 1 else _with_spread(rows)
    return (rows, top_functions(times)) if profile else rows


#: What a family's mean and worst rows summarise (the worst is the largest of each).
_SPREAD = ("accuracy_mean", "accuracy_p95", "radius_error", "total_s", "peak_mb")


def _with_spread(rows):
    """The rows with each family's mean and worst after its scenes, per camera source."""
    families = {}
    for row in rows:
        families.setdefault(row["scene"].split(", seed ")[0], []).append(row)
    out = []
    for family, members in families.items():
        out += members
        if len(members) <= 2:  # the sample: one capture
            continue
        for cameras in dict.fromkeys(row["cameras"] for row in members):
            done = [row for row in members if row["cameras"] == cameras and "error" not in row]
            if not done:
                continue
            right = [tuple(map(int, row["crossings"].split("/"))) for row in done]
            for name, values in mean_and_worst(done, _SPREAD):
                out.append({"scene": f"{family}: {name} of {len(done)}", "cameras": cameras,
                            **values,
                            "crossings": f"{sum(r for r, _ in right)}/{sum(t for _, t in right)}",
                            "one_path": f"{sum(row['one_path'] == 'yes' for row in done)}"
                                        f"/{len(done)}"})
    return out


_LOOK_COLUMNS = ("looks", "set", "scene", "masks", "accuracy_mean", "accuracy_p95",
                 "completeness", "crossings", "one_path", "radius_error", "core_thickness",
                 "unexplained", "masks_warned",
                 "masks_s", "agreement_s", "total_s", "error")


def _write_naive_masks(images, out):
    """The naive threshold's masks (:func:`engine.bench.looks.naive_mask`) of a folder of
    frames, written into ``out``."""
    import cv2

    from ..io.image_sequence import read_image
    from .looks import naive_mask

    out.mkdir(parents=True)
    for path in sorted(Path(images).iterdir()):
        mask = naive_mask(read_image(path))
        cv2.imwrite(str(out / (path.stem + ".png")), mask.astype("uint8") * 255)
    return out


#: The masks each scene of :func:`bench_pipeline_looks` is reconstructed from.
MASK_ROWS = ("ours", "naive threshold", "oracle: exact")


def bench_pipeline_looks(*, seeds=1, views=24, captures=Path("samples") / "looks",
                         families=None, segmentation=None, masks=MASK_ROWS, progress=None):
    """End to end on every look family (tuning and held-out seeds) and the Cycles captures,
    with the true cameras: our masks (as a user's run makes them), the naive threshold's,
    and the exact masks (the oracle).

    Parameters
    ----------
    seeds : int, optional
        Scenes per family and seed set.
    views : int, optional
        Views per synthetic scene (960x720, 3 crossings).
    captures : path, optional
        Pre-rendered Cycles captures (held out); None: none.
    families : sequence of str, optional
        Look families (all of :data:`engine.synthetic.looks.LOOK_FAMILIES` if None).
    segmentation : SegmentationSettings, optional
        Our masks' settings (the defaults if None; all cables for a family of several).
    masks : sequence of str, optional
        Which of :data:`MASK_ROWS` to run (our masks only: the other two do not depend on
        ``segmentation``).
    progress : callable, optional

    Returns
    -------
    list of dict
    """
    from ..synthetic.looks import HELD_OUT_SEEDS, LOOK_FAMILIES, TUNING_SEEDS
    from ..synthetic.scene import look_scene

    jobs = [(family, split, seed) for family in (LOOK_FAMILIES if families is None else families)
            for split, pool in (("tuning", TUNING_SEEDS), ("held-out", HELD_OUT_SEEDS))
            for seed in pool[:seeds]]
    if captures is not None and Path(captures).is_dir():
        captures = Path(captures)
        jobs += [("Cycles " + folder.name.split("-")[0], "held-out", folder)
                 for folder in sorted(captures.iterdir())
                 if (folder / "ground_truth.json").is_file()]
    rows = []
    with tempfile.TemporaryDirectory(prefix="bench_looks_") as work:
        for number, (family, split, seed) in enumerate(jobs):
            if progress is not None:
                progress(number / len(jobs), f"{family} {split}")
            if isinstance(seed, Path):
                folder, label = seed, seed.name
            else:
                folder, label = Path(work) / f"{family}-{seed}", f"seed {seed}"
                write_scene(look_scene(family, seed, views=views, width=960, height=720),
                            folder)
            given = {"ours": None, "oracle: exact": folder / "masks"}
            if "naive threshold" in masks:
                given["naive threshold"] = _write_naive_masks(folder / "images",
                                                              Path(work) / f"naive-{number}")
            for masks_label in (label for label in MASK_ROWS if label in masks):
                row = {"looks": family, "set": split, "scene": label, "masks": masks_label}
                mask_folder = given[masks_label]
                row.update(in_fresh_process(scored_run, str(folder),
                                            str(folder / "ground_truth.json"), True,
                                            None if mask_folder is None else str(mask_folder),
                                            _settings_for(family, segmentation)))
                rows.append(row)
    if progress is not None:
        progress(1.0, "done")
    return [{column: row.get(column, "") for column in _LOOK_COLUMNS} for row in rows]

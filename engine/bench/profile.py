"""Where a reconstruction's time goes: its engine functions' own time from a cProfile run.

cProfile's *own time* of a function leaves out what the libraries it calls spend (a
``cv2.remap``, a numpy reduction, a SciPy factorisation are functions of their own), which is
most of the time here. So each engine function is charged its *cumulative* time less that of
the engine functions it calls: its own Python work and every library call it makes itself.
Summed over the engine's functions this is the run's time (recursion aside; an engine
function reached through library code, a generator expression ``sum`` drives, is taken off
the engine functions that called that library code in the shares of its time), and each row
names code we can change. The run must be on one thread: cProfile cannot tell threads apart.
"""

import cProfile
import pstats
from pathlib import Path

__all__ = ["profiled", "engine_times", "top_functions", "PROFILE_COLUMNS"]

PROFILE_COLUMNS = ("cameras", "function", "stage", "seconds", "share", "calls", "scenes")
#: How many library calls up an engine function's time is followed to the engine function
#: that reached it.
_DEPTH = 8

#: The stage a module's time is charged to (the first prefix that matches its path under
#: engine/).
_STAGES = (("stages/segmentation", "masks"), ("stages/colour", "masks"),
           ("stages/missing_side", "masks"), ("stages/skeleton_2d", "masks"),
           ("stages/mask_agreement", "agreement"), ("stages/mask_checks", "checks"),
           ("stages/cameras", "cameras"), ("stages/carving", "carving"),
           ("stages/sparse_voxels", "carving"), ("stages/segment_graph", "graph"),
           ("stages/topology", "topology"), ("stages/rod", "fit"), ("stages/bezier", "curve"),
           ("io/", "reading and writing"), ("geometry/", "geometry"), ("pipeline", "pipeline"))


def profiled(function, *args, **kwargs):
    """``(function(*args, **kwargs), engine_times(...))`` of a run under cProfile."""
    profiler = cProfile.Profile()
    value = profiler.runcall(function, *args, **kwargs)
    return value, engine_times(pstats.Stats(profiler))


def _engine_label(key, root):
    """``module.function`` of an engine function's pstats key, None for other code."""
    filename, _, name = key
    if not filename.endswith(".py"):  # a built-in: "~"
        return None
    try:
        relative = Path(filename).resolve().relative_to(root / "engine")
    except ValueError:
        return None
    relative = Path("engine") / relative
    return ".".join(relative.with_suffix("").parts) + f".{name}"


def engine_times(stats):
    """Per engine function: ``{"module.function": (seconds, calls)}``, the seconds its own
    work and its library calls took (its cumulative time less its engine callees', also
    those it reached through library code: a generator expression ``sum`` drives, a sort
    key).

    The run must be on one thread: cProfile cannot tell threads' calls apart.
    """
    root = Path(__file__).resolve().parents[2]
    raw = stats.stats
    labels = {key: _engine_label(key, root) for key in raw}
    times = {key: [cumulative, calls] for key, (_, calls, _, cumulative, _) in raw.items()
             if labels[key] is not None}
    for key in times:
        for caller, (_, _, _, cumulative) in raw[key][4].items():
            if caller != key:
                _charge_up(raw, times, caller, cumulative)
    merged = {}
    for key, (seconds, calls) in times.items():
        seconds_before, calls_before = merged.get(labels[key], (0.0, 0))
        merged[labels[key]] = (seconds_before + max(seconds, 0.0), calls_before + calls)
    return merged


def _charge_up(raw, times, caller, seconds, depth=0):
    """Take ``seconds`` (an engine function's time) off the engine function that called it:
    ``caller``, or through library code (each library function's callers share the amount
    as they share that function's time), up to :data:`_DEPTH` calls up."""
    if caller in times:
        times[caller][0] -= seconds
        return
    if depth >= _DEPTH or caller not in raw:
        return
    callers = raw[caller][4]
    total = sum(cumulative for _, _, _, cumulative in callers.values())
    for up, (_, _, _, cumulative) in callers.items():
        if up != caller and total > 0:
            _charge_up(raw, times, up, seconds * cumulative / total, depth + 1)


def _stage(label):
    path = label.replace(".", "/")
    return next((stage for prefix, stage in _STAGES if path.startswith("engine/" + prefix)),
                "other")


def top_functions(runs, *, count=15):
    """The functions that took most of several runs' time.

    Parameters
    ----------
    runs : sequence of (str, dict)
        ``(cameras, engine_times)`` of each run: its camera source and :func:`engine_times`.
    count : int, optional
        Rows per camera source.

    Returns
    -------
    list of dict
        Per camera source, its ``count`` costliest functions over its runs: seconds, share of
        the runs' total, calls, and in how many of the runs they took time; then a row per
        stage with its total.
    """
    rows = []
    for cameras in dict.fromkeys(source for source, _ in runs):
        chosen = [times for source, times in runs if source == cameras]
        total, calls, scenes = {}, {}, {}
        for times in chosen:
            for label, (seconds, count_) in times.items():
                total[label] = total.get(label, 0.0) + seconds
                calls[label] = calls.get(label, 0) + count_
                scenes[label] = scenes.get(label, 0) + (seconds > 0)
        overall = sum(total.values()) or 1.0
        for label in sorted(total, key=total.get, reverse=True)[:count]:
            rows.append({"cameras": cameras, "function": label.removeprefix("engine."),
                         "stage": _stage(label), "seconds": total[label],
                         "share": total[label] / overall, "calls": calls[label],
                         "scenes": f"{scenes[label]}/{len(chosen)}"})
        stages = {}
        for label, seconds in total.items():
            stages[_stage(label)] = stages.get(_stage(label), 0.0) + seconds
        for stage in sorted(stages, key=stages.get, reverse=True):
            rows.append({"cameras": cameras, "function": "(all of the stage)", "stage": stage,
                         "seconds": stages[stage], "share": stages[stage] / overall,
                         "calls": "", "scenes": f"{len(chosen)}"})
    return rows

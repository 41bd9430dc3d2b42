"""What every bench shares: rows (dicts) printed as a table by :func:`format_table`, a run in a
fresh process with its peak memory, the bundled sample's folder. Nothing here is timed inside a
test."""

import multiprocessing
import resource
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

__all__ = ["format_table", "in_fresh_process", "mean_and_worst", "DEFAULT_SAMPLE"]

DEFAULT_SAMPLE = Path("samples") / "sequence"


def format_table(rows, columns=None):
    """Rows of dicts as a Markdown table (floats with 3 digits).

    The columns are ``columns`` (and ``error`` when a row failed: a failed row is never a row
    of blank cells), or else every key of every row in the order first seen.
    """
    seen = list(columns or [])
    for row in rows:
        seen += [key for key in row if key not in seen and (not columns or key == "error")]

    def cell(value):
        if isinstance(value, float):
            return f"{value:.3f}" if abs(value) < 100 else f"{value:.0f}"
        return str(value).replace("|", "/")

    lines = ["| " + " | ".join(seen) + " |", "|" + "---|" * len(seen)]
    lines += ["| " + " | ".join(cell(row.get(c, "")) for c in seen) + " |" for row in rows]
    return "\n".join(lines)


def mean_and_worst(rows, keys, *, higher_is_better=()):
    """The mean and the worst of ``keys`` over ``rows`` (the rows without an ``error``).

    Parameters
    ----------
    rows : list of dict
    keys : sequence of str
        The columns summarised; a column some row lacks is left out.
    higher_is_better : sequence of str, optional
        Columns whose worst is their smallest value (an IoU); every other column's worst is its
        largest (an error, a time).

    Returns
    -------
    list of (str, dict)
        ``("mean", values)`` and ``("worst", values)``; empty when no row is free of errors.
    """
    done = [row for row in rows if "error" not in row]
    if not done:
        return []
    keys = [key for key in keys if all(key in row for row in done)]
    mean = {key: float(np.mean([row[key] for row in done])) for key in keys}
    worst = {key: float((np.min if key in higher_is_better else np.max)(
        [row[key] for row in done])) for key in keys}
    return [("mean", mean), ("worst", worst)]


def _measured(function, args):
    """Run ``function(*args)`` (returning a dict) and add the process's peak memory to it."""
    try:  # a spawned process starts with its parent's peak: forget it (Linux)
        Path("/proc/self/clear_refs").write_text("5")
    except OSError:
        pass
    row = function(*args)
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("VmHWM:"):
                peak = int(line.split()[1]) / 1024.0
    except OSError:
        pass
    row["peak_mb"] = peak
    return row


def in_fresh_process(function, *args):
    """``function(*args)`` (a dict) run in a new process, with ``peak_mb`` (its peak resident
    memory, interpreter and libraries included) added."""
    # a pool's exit terminates its worker (which pycolmap's signal handler reports noisily):
    # an executor lets it finish
    with ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn")) as executor:
        return executor.submit(_measured, function, args).result()

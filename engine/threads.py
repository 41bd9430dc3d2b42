"""Threads for work that is the same item after item (frames, views, batches of voxels).

NumPy, OpenCV and pycolmap release the GIL in their heavy calls, so a few threads use the
cores without copying the frames to other processes. Each item's work must not depend on the
others', so the result is the same on any number of threads.
"""

import os
from concurrent.futures import ThreadPoolExecutor
from contextlib import nullcontext

__all__ = ["MOST_THREADS", "cpu_count", "thread_count", "worker_pool", "map_in_order",
           "map_in_threads", "ThisThread"]


#: Threads a setting of 0 stands for at most: each worker of a stage holds a frame's or a
#: view's arrays (hundreds of megabytes for a 4K frame), and past a few threads the engine's
#: work, much of it Python between NumPy calls, gains little.
MOST_THREADS = 4


def cpu_count():
    """The CPUs this process may run on (its affinity where the system tells it)."""
    if hasattr(os, "process_cpu_count"):  # Python 3.13
        return os.process_cpu_count() or 1
    if hasattr(os, "sched_getaffinity"):
        return len(os.sched_getaffinity(0)) or 1
    return os.cpu_count() or 1


def thread_count(threads):
    """Threads to use for a ``threads`` setting: itself, or for 0 one per CPU, at most
    :data:`MOST_THREADS`."""
    return int(threads) if threads else min(cpu_count(), MOST_THREADS)


def worker_pool(threads, name):
    """A context manager giving a pool with ``map``: :func:`thread_count` workers for the
    setting ``threads``, named ``name``, or :class:`ThisThread` when that is one."""
    count = thread_count(threads)
    if count > 1:
        return ThreadPoolExecutor(count, thread_name_prefix=name)
    return nullcontext(ThisThread())


def map_in_order(pool, function, items, done=None):
    """``[function(item) for item in items]`` on the ``pool``'s workers.

    ``done(k)`` (optional) is called on this thread as the result of item ``k`` is taken, in
    the items' order. When an item raises (an error, a cancel), its error is raised as soon
    as the items before it are done, and the items not yet begun are dropped.
    """
    items = list(items)
    futures = None if isinstance(pool, ThisThread) else [pool.submit(function, item)
                                                         for item in items]
    results = []
    try:
        for k, item in enumerate(items):
            results.append(function(item) if futures is None else futures[k].result())
            if done is not None:
                done(k)
    finally:
        for future in futures or ():
            future.cancel()
    return results


def map_in_threads(threads, name, function, items, done=None):
    """:func:`map_in_order` on a :func:`worker_pool` of its own (``threads``, ``name``)."""
    with worker_pool(threads, name) as pool:
        return map_in_order(pool, function, items, done)


class ThisThread:
    """A pool of one thread, this one: the items in order, with no worker to hand them to
    (a profiler then sees the work where it is asked for)."""

    @staticmethod
    def map(function, *items):
        return map(function, *items)

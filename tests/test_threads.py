"""Threads for per-item work: order kept, errors raised at once, cancels that combine."""

import threading
import time

import pytest

from engine.errors import Cancelled
from engine.progress import AnySet, check_cancel
from engine.threads import ThisThread, map_in_order, thread_count, worker_pool


@pytest.mark.parametrize("workers", [1, 2, 4])
def test_results_and_progress_come_in_the_items_order(workers):
    done = []

    def slow_first(k):  # the first items finish last
        time.sleep(0.002 * (10 - k))
        return k * k

    with worker_pool(workers, "test") as pool:
        assert isinstance(pool, ThisThread) == (workers == 1)
        results = map_in_order(pool, slow_first, range(10), done.append)
    assert results == [k * k for k in range(10)]
    assert done == list(range(10))


def test_an_error_is_raised_at_once_and_the_rest_is_dropped():
    begun = []
    release = threading.Event()

    def work(k):
        begun.append(k)
        if k == 0:
            raise ValueError("item 0 is bad")
        release.wait(5)  # the other items hold their workers until the error is raised
        return k

    with worker_pool(2, "test") as pool:
        with pytest.raises(ValueError, match="item 0"):
            map_in_order(pool, work, range(50))
        release.set()
    assert len(begun) < 5  # the items not begun when the error came were dropped


def test_one_thread_runs_the_items_in_turn_on_the_caller():
    threads = set()
    with worker_pool(1, "test") as pool:
        map_in_order(pool, lambda k: threads.add(threading.get_ident()), range(5))
    assert threads == {threading.get_ident()}
    assert thread_count(0) >= 1 and thread_count(3) == 3


def test_any_set_is_set_by_any_of_its_events():
    user, failed = threading.Event(), threading.Event()
    either = AnySet(user, None, failed)
    check_cancel(either, "work")  # neither set: goes on
    failed.set()
    with pytest.raises(Cancelled, match="work was cancelled"):
        check_cancel(either, "work")
    assert AnySet(None).is_set() is False

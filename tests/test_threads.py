"""The thread helpers: results in order, a worker's exception raised in the caller, nesting."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest

from calib_masonry._threads import background, cpu_count, thread_map


def test_thread_map_keeps_the_order_whatever_finishes_first():
    def slow_first(i):
        time.sleep(0.02 * (5 - i))
        return i * i

    assert thread_map(slow_first, range(5), workers=3) == [0, 1, 4, 9, 16]
    assert thread_map(slow_first, [], workers=3) == []
    assert cpu_count() >= 1


def test_background_returns_its_value_and_raises_its_error_in_the_caller():
    job = background(np.add, np.arange(3), 1)
    assert job.result().tolist() == [1, 2, 3]

    def fail():
        raise ValueError("from the worker")

    with pytest.raises(ValueError, match="from the worker"):
        background(fail).result()


def test_nested_use_does_not_wait_for_a_slot_its_caller_holds():
    # every call makes its own threads: a task that maps on threads itself finishes even when
    # all the outer workers are busy with such tasks
    def outer(i):
        inner = background(lambda: threading.current_thread().name)
        return (i, thread_map(lambda j: i + j, range(3), workers=2), inner.result().startswith("calib-masonry"))

    assert thread_map(outer, range(4), workers=2) == [(i, [i, i + 1, i + 2], True) for i in range(4)]

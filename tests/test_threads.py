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


def _gone(pid: int, seconds: float = 10.0) -> bool:
    """Whether process ``pid`` has ended (or is a zombie no one has reaped yet) within ``seconds``."""
    from pathlib import Path

    t0 = time.monotonic()
    while time.monotonic() - t0 < seconds:
        try:
            state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
        except OSError:
            return True
        if state == "Z":
            return True
        time.sleep(0.05)
    return False


def test_background_process_gives_the_value_of_the_call_made_in_another_process():
    import operator
    import os

    from calib_masonry._threads import background_process

    a, b = np.random.default_rng(3).normal(size=(2, 1000))
    with background_process(np.add, a, b) as job:
        assert np.array_equal(job.result(), a + b)  # pickled there and back: bit for bit
    assert background_process(os.getpid).result() != os.getpid()
    # a call that raises there is made again here, where its error shows as it would
    with pytest.raises(ZeroDivisionError):
        background_process(operator.truediv, 1, 0).result()


def test_background_process_is_gone_when_its_block_ends_early_or_a_stop_is_requested(monkeypatch):
    from calib_masonry import errors, process
    from calib_masonry._threads import background_process

    with pytest.raises(RuntimeError, match="the block's own"):
        with background_process(time.sleep, 60) as job:
            pid = job._proc.pid
            raise RuntimeError("the block's own error")
    assert _gone(pid)
    monkeypatch.setattr(process, "_STOP", threading.Event())
    with pytest.raises(errors.Terminated):
        with background_process(time.sleep, 60) as job:
            pid = job._proc.pid
            threading.Timer(0.3, process.request_stop).start()
            job.result()  # a stop ends the wait, and the block ends the process
    assert _gone(pid)


def test_background_process_leaves_when_its_caller_dies():
    import subprocess
    import sys

    parent = (
        "import os, signal, sys, time\n"
        "from calib_masonry._threads import background_process\n"
        "job = background_process(time.sleep, 60)\n"
        "print(job._proc.pid, flush=True)\n"
        "time.sleep(0.5)\n"
        "os.kill(os.getpid(), signal.SIGKILL)\n"
    )
    r = subprocess.run([sys.executable, "-c", parent], capture_output=True, text=True, timeout=60)
    assert r.returncode == -9, r.stderr
    assert _gone(int(r.stdout.split()[0]))  # its stdin closed with the caller: it left on its own


def test_background_process_that_ends_without_a_result_is_computed_here_with_a_warning(monkeypatch):
    from calib_masonry._threads import _BackgroundProcess, background_process

    # a process that reads a little and dies (as one killed for its memory would)
    crash = ("-c", "import os, sys; sys.stdin.buffer.read(1); os._exit(3)")
    monkeypatch.setattr(_BackgroundProcess, "command", crash)
    a = np.arange(5.0)
    with pytest.warns(RuntimeWarning, match=r"ended without a result \(exit code 3\)"):
        assert background_process(np.multiply, a, 2.0).result().tolist() == (2 * a).tolist()

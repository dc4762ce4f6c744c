"""Work on a second core by threads (and, for pure-Python work that would hold the GIL, by a process
of its own: :func:`background_process`): NumPy's large array operations and SciPy's ndimage filters,
interpolation and labelling release the GIL (two threads of ``gaussian_filter``,
``map_coordinates`` or ``grey_opening`` ran 1.7-1.9x faster than one after the other on this
project's 2-core machines, measured), so independent image operations overlap.

Every call makes its own threads (no shared pool), so a function that runs on one of them may
itself use these helpers without waiting for a slot its caller holds. Results never depend on
the order in which the threads run: each piece of work is a pure function of its inputs.
"""

from __future__ import annotations

import contextlib
import os
import threading
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import ThreadPoolExecutor
from typing import Any

__all__ = ["background", "background_process", "cpu_count", "loop_lock", "thread_imap", "thread_map"]


def cpu_count() -> int:
    """The CPUs this process may run on."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - not Linux
        return max(1, os.cpu_count() or 1)


class _Background:
    def __init__(self, fn: Callable, args: tuple, kwargs: dict) -> None:
        self._value: Any = None
        self._error: BaseException | None = None

        def run() -> None:
            try:
                self._value = fn(*args, **kwargs)
            except BaseException as exc:  # noqa: BLE001 - re-raised in the caller's thread by result()
                self._error = exc

        self._thread = threading.Thread(target=run, name="calib-masonry-work", daemon=True)
        self._thread.start()

    def result(self) -> Any:
        """The function's value, once it has returned (its exception, raised here, if it raised)."""
        self._thread.join()
        if self._error is not None:
            raise self._error
        return self._value

    def wait(self) -> None:
        """Wait for the function to end, without raising its exception."""
        self._thread.join()

    def __enter__(self) -> _Background:
        return self

    def __exit__(self, *exc_info) -> None:
        """Wait for the function however the block ends, so that nothing runs on after it (a
        writer in a staging folder being removed); an error of the block goes on, the function's
        own is raised by ``result()``."""
        self._thread.join()


def background(fn: Callable, *args, **kwargs) -> _Background:
    """Start ``fn(*args, **kwargs)`` on a thread of its own; ``.result()`` waits for it, and so
    does leaving a ``with background(...)`` block, by an error or not."""
    return _Background(fn, args, kwargs)


class _BackgroundProcess:
    """``fn(*args)`` in ``python -m calib_masonry._worker`` (see that module), with
    :class:`_Background`'s ``result()`` and ``with`` block. Where the process cannot be started, or ends without a value
    (killed, out of memory, or the function raised there), ``result()`` calls the function here:
    an error then shows as it would, and a value is the one the process would have sent (the same
    function of the same pickled inputs)."""

    #: the process's command (a test stands a failing one in)
    command: tuple[str, ...] = ("-m", "calib_masonry._worker")

    def __init__(self, fn: Callable, args: tuple) -> None:
        import pickle
        import subprocess
        import sys

        self._fn, self._args = fn, args
        self._code: int | None = None
        self._value: Any = None
        self._done = False
        self._reply: Any = None
        self._proc: subprocess.Popen | None = None
        try:
            payload = pickle.dumps((fn, args), protocol=pickle.HIGHEST_PROTOCOL)
            self._proc = subprocess.Popen(
                [sys.executable, *self.command], stdin=subprocess.PIPE, stdout=subprocess.PIPE
            )
        except (OSError, pickle.PicklingError, TypeError, AttributeError):  # no process, or inputs it cannot take
            self._proc = None
            return
        # the call is sent and the reply read on a thread: either is larger than a pipe holds
        self._talker = threading.Thread(
            target=self._talk, args=(self._proc, payload), name="calib-masonry-worker", daemon=True
        )
        self._talker.start()

    def _talk(self, proc, payload: bytes) -> None:
        """Send the call and read the reply's bytes (unpickled by ``result()``, on the caller's
        thread: this one touches no module and no array, only a pipe)."""
        try:
            proc.stdin.write(payload)
            proc.stdin.flush()  # stdin stays open: the process ends when it closes
            self._reply = proc.stdout.read()  # to end of file: the process leaves once it has sent
        except Exception:  # noqa: BLE001 - no reply: result() computes here
            self._reply = None

    def _end(self) -> None:
        """Close the process's stdin (it leaves at end of file) and make sure it is gone."""
        import subprocess

        proc, self._proc = self._proc, None
        if proc is None:
            return
        with contextlib.suppress(OSError):
            proc.stdin.close()  # type: ignore[union-attr]
        try:
            proc.wait(timeout=1.0)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
        self._talker.join()
        with contextlib.suppress(OSError):
            proc.stdout.close()  # type: ignore[union-attr]
        self._code = proc.returncode

    def result(self) -> Any:
        """The function's value: the process's, or, if it sent none, computed here. A stop
        request (:func:`calib_masonry.process.request_stop`) ends the wait with ``Terminated``."""
        if not self._done:
            import pickle

            from .process import raise_if_stopped

            started = self._proc is not None
            if started:
                while self._talker.is_alive():
                    self._talker.join(0.1)
                    raise_if_stopped()
                self._end()
            try:
                reply = pickle.loads(self._reply) if self._reply else None
            except Exception:  # noqa: BLE001 - cut short (the process was killed while sending)
                reply = None
            if started and not isinstance(reply, tuple):
                import warnings

                name = getattr(self._fn, "__qualname__", "the work")
                warnings.warn(
                    f"the process computing {name} ended without a result (exit code {self._code}); "
                    "computing it here instead",
                    RuntimeWarning,
                    stacklevel=2,
                )
            self._value = reply[1] if isinstance(reply, tuple) and reply[0] == "done" else self._fn(*self._args)
            self._done = True
        return self._value

    def __enter__(self) -> _BackgroundProcess:
        return self

    def __exit__(self, *exc_info) -> None:
        """However the block ends, the process is gone after it (killed if it still works: the
        block ended by an error or a stop before it needed the value)."""
        if self._proc is not None and self._proc.poll() is None and not self._done:
            self._proc.kill()
        self._end()


def background_process(fn: Callable, *args) -> _BackgroundProcess:
    """Start ``fn(*args)`` in a process of its own (a fresh interpreter; ``fn`` and ``args`` are
    pickled, ``fn`` by its module and name): for pure-Python work that would hold the GIL against
    the caller's thread. ``.result()`` waits for its value; leaving a ``with`` block ends the
    process. See :class:`_BackgroundProcess` for what happens when no process can do it."""
    return _BackgroundProcess(fn, args)


def thread_imap(fn: Callable, items: Iterable, *, workers: int | None = None, name: str = "work") -> Iterator:
    """``fn(x)`` for each of ``items``, yielded in order, computed on up to ``workers`` threads
    (default: one per CPU) named ``calib-masonry-<name>``. Leaving the loop early (an error, a
    stop request, ``close()``) cancels the items not yet started and waits for those running, so
    nothing runs on after the caller has moved on (a staging folder removed under a writer)."""
    items = list(items)
    workers = max(1, min(len(items), workers or cpu_count()))
    pool = ThreadPoolExecutor(max_workers=workers, thread_name_prefix=f"calib-masonry-{name}")
    try:
        yield from pool.map(fn, items)
    finally:
        pool.shutdown(wait=True, cancel_futures=True)


def thread_map(fn: Callable, items: Iterable, *, workers: int | None = None) -> list:
    """``[fn(x) for x in items]``, on up to ``workers`` threads (default: one per CPU), in order."""
    items = list(items)
    if min(len(items), workers or cpu_count()) <= 1:
        return [fn(x) for x in items]
    return list(thread_imap(fn, items, workers=workers))


_LOOP_LOCKS: dict = {}  # (event loop, name) -> asyncio.Lock


def loop_lock(name: str):
    """The running event loop's lock named ``name``: coroutines on one loop (a dask worker's, whose
    tasks share it however many threads the worker has) take turns with it."""
    import asyncio

    loop = asyncio.get_running_loop()
    for key in [k for k in _LOOP_LOCKS if k[0].is_closed()]:
        del _LOOP_LOCKS[key]
    return _LOOP_LOCKS.setdefault((loop, name), asyncio.Lock())

"""The process's own state, in one place: the stop flag (SIGTERM or a caller's request: the work
stops at its next progress step and commits nothing) and the deferral of signals while C code that
cannot take an exception runs (Blender). The CLI installs :func:`on_signal` for SIGTERM and SIGINT.
"""

from __future__ import annotations

import contextlib
import signal
import sys
import threading

from .errors import Terminated

__all__ = ["request_stop", "stop_requested", "raise_if_stopped", "on_signal", "signals_deferred", "print_warning"]


_STOP = threading.Event()


def request_stop() -> None:
    """Ask the running work to stop: it raises :class:`Terminated` at its next progress step and
    never commits an output folder. The CLI's SIGTERM handler calls this as well as raising, because
    a few third-party imports swallow an exception raised in a signal handler (a bare ``except``
    around an optional import), and the stop must not be lost there."""
    _STOP.set()


def stop_requested() -> bool:
    return _STOP.is_set()


def raise_if_stopped() -> None:
    if _STOP.is_set():
        raise Terminated()


_HELD = 0  # depth of signals_deferred() sections (entered on the main thread, where handlers run)
_PENDING: list[KeyboardInterrupt] = []


def on_signal(signum, frame) -> None:
    """The CLI's handler of SIGTERM and SIGINT: raise :class:`Terminated` (SIGTERM, after
    :func:`request_stop`, kept even if some library swallows the exception) or
    ``KeyboardInterrupt`` where the program is, or, inside :func:`signals_deferred`, on the way
    out of it. A SIGTERM while a stop is already under way does nothing: ``timeout`` sends its
    signal to the command and again to its process group, and a second exception raised during
    the first one's clean-up (a staging folder being removed, stdout being flushed) broke it
    ("Exception ignored ... TypeError: an integer is required" after the run's last line)."""
    if signum == signal.SIGTERM:
        if stop_requested():
            return
        request_stop()
        exc: KeyboardInterrupt = Terminated()
    else:
        exc = KeyboardInterrupt()
    if _HELD:
        _PENDING.append(exc)
        return
    raise exc


@contextlib.contextmanager
def signals_deferred():
    """Let :func:`on_signal` hold its exception back until the block has ended: for C code that
    calls back into Python and crashes if an exception appears there (Blender's start-up, its
    factory reset, saving and baking: a SIGTERM during ``import bpy`` ended in SIGSEGV). Blocking
    the signal with ``pthread_sigmask`` is not enough: a signal sent to the process goes to any
    thread that does not block it (a BLAS or XLA worker started earlier), and CPython then runs
    the handler on the main thread all the same."""
    global _HELD
    _HELD += 1
    held: list[KeyboardInterrupt] = []
    try:
        yield
    finally:
        _HELD -= 1
        if not _HELD:  # an error raised by the block itself goes on instead (a SIGTERM's stop stays requested)
            held, _PENDING[:] = _PENDING[:1], []
    if held:
        raise held[0]


def print_warning(message, category, filename, lineno, file=None, line=None) -> None:
    """A warning as one line ``warning: ...`` on stderr: ``warnings.showwarning`` of the CLI and of a
    study's Dask workers (whose warnings reach the same terminal)."""
    print(f"warning: {message}", file=sys.stderr)

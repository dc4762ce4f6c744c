"""The one small error hierarchy of calib_masonry.

Every message names the file or field, says what was wrong and what to do. The CLI prints
``error: <message>`` on one line and exits with code 2.
"""

from __future__ import annotations

import threading

__all__ = [
    "CalibMasonryError",
    "InputError",
    "BackendMissing",
    "FitFailed",
    "Terminated",
    "request_stop",
    "stop_requested",
    "raise_if_stopped",
]


class CalibMasonryError(Exception):
    """Base class of every error this package raises on purpose."""


class InputError(CalibMasonryError, ValueError):
    """A user's input (file, field, flag) is missing, unreadable or impossible."""


class BackendMissing(CalibMasonryError, ImportError):
    """An optional dependency is not installed; the message carries the install hint."""


class FitFailed(CalibMasonryError, RuntimeError):
    """A fit did not converge or its result failed a quality check."""


class Terminated(KeyboardInterrupt):
    """SIGTERM (or a stop requested by a caller), raised where the program is, so that every staging
    folder is removed on the way out. ``written`` says what was already complete when the signal was
    handled (an output renamed into place, a study's finished samples), else None."""

    def __init__(self, written: str | None = None) -> None:
        super().__init__()
        self.written = written


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

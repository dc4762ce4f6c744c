"""The one small error hierarchy of calib_masonry.

Every message names the file or field, says what was wrong and what to do. The CLI prints
``error: <message>`` on one line and exits with code 2.
"""

from __future__ import annotations

__all__ = [
    "CalibMasonryError",
    "InputError",
    "BackendMissing",
    "FitFailed",
    "Terminated",
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

"""The one small error hierarchy of calib_masonry.

Every message names the file or field, says what was wrong and what to do. The CLI prints
``error: <message>`` on one line and exits with code 2.
"""

from __future__ import annotations

__all__ = ["CalibMasonryError", "InputError", "BackendMissing", "FitFailed"]


class CalibMasonryError(Exception):
    """Base class of every error this package raises on purpose."""


class InputError(CalibMasonryError, ValueError):
    """A user's input (file, field, flag) is missing, unreadable or impossible."""


class BackendMissing(CalibMasonryError, ImportError):
    """An optional dependency is not installed; the message carries the install hint."""


class FitFailed(CalibMasonryError, RuntimeError):
    """A fit did not converge or its result failed a quality check."""

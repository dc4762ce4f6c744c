"""Progress of long steps: a bar on a terminal; when stderr is not a terminal (a log file, a pipe, a
scheduler, a Dask worker), a line at most every :data:`LOG_EVERY_S` seconds with what is done, the
percent and the time left, and a last line when a step that logged ends.

Every step also checks for a requested stop (:func:`calib_masonry.process.request_stop`, which the
CLI's SIGTERM handler calls), so a long loop ends at its next step even when the signal's own
exception was swallowed by a third-party import."""

from __future__ import annotations

import functools
import sys
import time
from collections.abc import Iterable, Iterator

from .process import raise_if_stopped

__all__ = ["LOG_EVERY_S", "progress"]

LOG_EVERY_S = 10.0
#: the time left is extrapolated only from at least this many items done (or all of them)
MIN_ITEMS_FOR_ETA = 3


class _LogLines:
    """tqdm's small interface (iterate, update, close) writing log lines instead of a bar."""

    def __init__(self, iterable: Iterable | None, total: int | None, desc: str, unit: str, stream) -> None:
        self.iterable = iterable
        self.total = total if total is not None else (len(iterable) if hasattr(iterable, "__len__") else None)
        self.desc, self.unit, self.stream = desc, unit, stream
        self.n = 0
        self.t0 = self.last = time.monotonic()
        self.logged = False
        self.postfix = ""

    def __iter__(self) -> Iterator:
        for item in self.iterable:
            yield item
            self.update()
        self.close()

    def _line(self, now: float) -> str:
        elapsed = now - self.t0
        if self.total:
            done = self.n / self.total
            if self.postfix:
                # an item that takes its time (the suffix says what it does): the items' pace says
                # nothing of it (the scale tower's line said "about 145 s left" during a 400 s frame)
                left = "time left not known"
            elif self.n >= min(MIN_ITEMS_FOR_ETA, self.total):
                left = f"about {elapsed / done - elapsed:.0f} s left"
            else:  # one item's time said "about 4771 s left" of a run done a second later
                left = "time left not known yet"
            line = f"{self.desc}: {self.n}/{self.total} {self.unit}s ({done:.0%}), {elapsed:.0f} s elapsed, {left}"
        else:
            line = f"{self.desc}: {self.n} {self.unit}s, {elapsed:.0f} s elapsed"
        return f"{line}; {self.postfix}" if self.postfix else line

    def set_postfix_str(self, s: str = "") -> None:
        """What the step is doing now, appended to the lines from here on (tqdm's name for it); ""
        clears it."""
        self.postfix = s

    def update(self, n: int = 1) -> None:
        raise_if_stopped()
        self.n += n
        now = time.monotonic()
        if now - self.last >= LOG_EVERY_S:
            print(self._line(now), file=self.stream, flush=True)
            self.last, self.logged = now, True

    def close(self) -> None:
        if self.logged:
            ended = ", done" if self.total is None or self.n >= self.total else ", stopped before the end"
            print(self._line(time.monotonic()) + ended, file=self.stream, flush=True)
            self.logged = False


class _Silent:
    def __init__(self, iterable: Iterable | None) -> None:
        self.iterable = iterable

    def __iter__(self) -> Iterator:
        return iter(self.iterable)

    def update(self, n: int = 1) -> None:
        raise_if_stopped()

    def set_postfix_str(self, s: str = "") -> None:
        pass

    def close(self) -> None:
        pass


def progress(
    iterable: Iterable | None = None,
    *,
    total: int | None = None,
    desc: str,
    unit: str = "it",
    enabled: bool | None = None,
):
    """Wrap a long loop (or count it with ``update()``): ``enabled`` False is silent, True or None
    shows a bar on a terminal and log lines elsewhere (None is the library's default)."""
    if iterable is not None:
        if total is None and hasattr(iterable, "__len__"):
            total = len(iterable)
        iterable = _checked(iterable)
    if enabled is False:
        return _Silent(iterable)
    stream = sys.stderr
    if stream is not None and hasattr(stream, "isatty") and stream.isatty():
        return _bar_class()(iterable, total=total, desc=desc, unit=unit, leave=False)
    return _LogLines(iterable, total, desc, unit, stream)


def _checked(iterable: Iterable) -> Iterator:
    for item in iterable:
        raise_if_stopped()
        yield item


@functools.cache  # one subclass, made on first use (tqdm loads only on a terminal)
def _bar_class():
    from tqdm.auto import tqdm

    class _Bar(tqdm):
        def update(self, n=1):
            raise_if_stopped()
            return super().update(n)

    return _Bar

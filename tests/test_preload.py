"""The imports paid before they are needed (:mod:`calib_masonry.preload`): its entries are strings,
so a renamed module or function would only show when a command runs; every group is loaded here."""

from __future__ import annotations

import subprocess
import sys

import pytest

from calib_masonry import preload


def test_entries_import_ask_call_and_skip(monkeypatch):
    calls = []
    monkeypatch.setitem(sys.modules, "_preload_probe", type(sys)("_preload_probe"))
    sys.modules["_preload_probe"].f = lambda *a: calls.append(a)
    monkeypatch.setattr(preload, "_LOADED", set())
    monkeypatch.setitem(
        preload.GROUPS, "_probe", ("_preload_probe", "_preload_probe:f()", "_preload_probe:f(12, 'a')", "?_no_such_mod")
    )
    monkeypatch.setitem(preload.GROUPS, "_outer", ("@_probe", "_preload_probe:f(1)"))
    preload.preload("_outer")
    assert calls == [(), (12, "a"), (1,)]
    preload.preload("_outer", "_probe")  # loaded once
    assert len(calls) == 3
    monkeypatch.setitem(preload.GROUPS, "_bad", ("_no_such_mod",))
    with pytest.raises(ImportError):
        preload.preload("_bad")
    monkeypatch.setitem(preload.GROUPS, "_missing_name", ("_preload_probe:g",))
    with pytest.raises(AttributeError):
        preload.preload("_missing_name")


def test_a_background_load_runs_on_its_thread_and_its_failure_is_silent(monkeypatch):
    import threading

    monkeypatch.setattr(preload, "_LOADED", set())
    monkeypatch.setattr(preload, "_STARTED", set())
    seen = []
    mod = type(sys)("_preload_probe2")
    mod.slow = lambda: (seen.append(threading.current_thread().name), threading.Event().wait(0.2))
    monkeypatch.setitem(sys.modules, "_preload_probe2", mod)
    monkeypatch.setitem(preload.GROUPS, "_slow", ("_preload_probe2:slow()",))
    monkeypatch.setitem(preload.GROUPS, "_fails", ("_no_such_mod",))
    thread = preload.preload_in_background("_slow", "_fails")
    assert preload.preload_in_background("_slow") is None  # started already: not twice
    thread.join()  # nothing raised for the one that failed
    assert seen == ["calib-masonry-imports"] and "_slow" in preload._LOADED
    assert "_fails" not in preload._LOADED


@pytest.mark.slow
def test_every_group_loads():
    groups = sorted(preload.GROUPS)
    code = f"from calib_masonry.preload import preload\nfor g in {groups!r}:\n    preload(g)\nprint('ok')"
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600)
    assert r.returncode == 0 and r.stdout.strip().endswith("ok"), r.stderr[-3000:]

"""Progress: a bar on a terminal, log lines with percent and time left elsewhere."""

import io

from calib_masonry import progress as progress_module
from calib_masonry.progress import progress


def test_log_lines_when_not_on_a_terminal(monkeypatch):
    stream = io.StringIO()
    monkeypatch.setattr(progress_module.sys, "stderr", stream)
    monkeypatch.setattr(progress_module, "LOG_EVERY_S", 0.0)  # a line per step here; 10 s in a real run
    assert list(progress(range(4), desc="simulate", unit="frame")) == [0, 1, 2, 3]
    lines = stream.getvalue().splitlines()
    # one item's time says nothing of the rest (it said "about 4771 s left" of a run done 1 s later)
    assert lines[0].startswith("simulate: 1/4 frames (25%)") and "time left not known yet" in lines[0]
    assert "about" in lines[2] and "s left" in lines[2]
    assert lines[-1].startswith("simulate: 4/4 frames (100%)") and lines[-1].endswith(", done")


def test_an_interrupted_step_is_not_called_done(monkeypatch):
    stream = io.StringIO()
    monkeypatch.setattr(progress_module.sys, "stderr", stream)
    monkeypatch.setattr(progress_module, "LOG_EVERY_S", 0.0)
    bar = progress(total=10, desc="study", unit="sample")
    bar.update()
    bar.update()
    bar.close()  # as a stopped run's finally block does
    last = stream.getvalue().splitlines()[-1]
    assert last.startswith("study: 2/10") and last.endswith("stopped before the end") and "done" not in last


def test_quiet_when_disabled_and_no_line_for_a_short_step(monkeypatch):
    stream = io.StringIO()
    monkeypatch.setattr(progress_module.sys, "stderr", stream)
    assert list(progress(range(3), desc="x", enabled=False)) == [0, 1, 2]
    bar = progress(total=2, desc="calibrate photos", unit="photo")
    bar.update()
    bar.update()
    bar.close()
    assert stream.getvalue() == ""  # under 10 s: nothing to report


def test_a_requested_stop_ends_a_loop_at_its_next_step(monkeypatch):
    import threading

    import pytest

    from calib_masonry import errors, process

    monkeypatch.setattr(process, "_STOP", threading.Event())
    for enabled in (False, None):
        seen = []
        with pytest.raises(errors.Terminated):
            for i in progress(range(5), desc="build", enabled=enabled):
                seen.append(i)
                if i == 1:
                    process.request_stop()
        assert seen == [0, 1]
        bar = progress(total=3, desc="build", enabled=enabled)
        with pytest.raises(errors.Terminated):
            bar.update()
        process._STOP.clear()


def test_a_signal_inside_a_deferred_section_is_raised_on_the_way_out(monkeypatch):
    import signal
    import threading

    import pytest

    from calib_masonry import errors, process

    monkeypatch.setattr(process, "_STOP", threading.Event())
    reached = []
    with pytest.raises(errors.Terminated):
        with process.signals_deferred():
            with process.signals_deferred():
                process.on_signal(signal.SIGTERM, None)  # held back, even in a nested section
                reached.append("inner")
            reached.append("outer")
    assert reached == ["inner", "outer"] and process.stop_requested() and not process._PENDING
    with pytest.raises(KeyboardInterrupt) as caught:
        process.on_signal(signal.SIGINT, None)  # outside a section: at once
    assert not isinstance(caught.value, errors.Terminated)
    with pytest.raises(ValueError):  # the block's own error wins; the held signal is dropped with it
        with process.signals_deferred():
            process.on_signal(signal.SIGINT, None)
            raise ValueError
    assert not process._PENDING


def test_a_second_sigterm_while_stopping_is_not_raised_again(monkeypatch):
    """``timeout`` signals the command and then its process group: the second SIGTERM must not
    raise inside the first one's clean-up."""
    import signal
    import threading

    import pytest

    from calib_masonry import errors, process

    monkeypatch.setattr(process, "_STOP", threading.Event())
    with pytest.raises(errors.Terminated):
        process.on_signal(signal.SIGTERM, None)
    assert process.on_signal(signal.SIGTERM, None) is None and process.stop_requested()
    with pytest.raises(KeyboardInterrupt):  # Ctrl-C still interrupts
        process.on_signal(signal.SIGINT, None)

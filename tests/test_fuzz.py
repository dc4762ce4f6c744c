"""Fuzzing with hypothesis: structure files and the command line's numeric flags.

Every generated input must end in success or in one line ``error: ...`` with exit code 2 (an
InputError in the library), never in a traceback. The number of examples is bounded so that the
suite stays a few tens of seconds in CI.
"""

import contextlib
import io
import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from PIL import Image

from calib_masonry.cli import main
from calib_masonry.errors import CalibMasonryError
from calib_masonry.spec import CORNER_KEYS, STRUCTURE_KEYS, WALL_KEYS, PhotoSpec, SyntheticSpec, load_structure

FUZZ = settings(
    max_examples=150,
    deadline=None,
    derandomize=True,  # the same examples in every CI run
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)

numbers = st.one_of(
    st.integers(min_value=-(2**70), max_value=2**70),
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([0, 1, -1, 0.0, 1e-300, 1e300, 0.5, 3, 64, 2**31, 2**63]),
)
scalars = st.one_of(
    numbers,
    st.booleans(),
    st.text(max_size=12),
    st.sampled_from(["m.png", "missing.png", "stretcher", "rubble", "", "w0"]),
)
values = st.one_of(scalars, st.lists(st.one_of(numbers, st.text(max_size=4)), max_size=5))


def _key(valid):
    return st.one_of(
        st.sampled_from(valid), st.sampled_from(valid), st.text("abcdefghijklmnopqrstuvwxyz_", max_size=10)
    )


def _table(valid):
    return st.dictionaries(_key(valid), values, max_size=len(valid) + 1)


documents = st.fixed_dictionaries(
    {},
    optional={
        "structure": _table(STRUCTURE_KEYS),
        "wall": st.lists(_table(WALL_KEYS), max_size=3),
        "corner": st.lists(_table(CORNER_KEYS), max_size=2),
        "synthetic": _table(tuple(SyntheticSpec.__dataclass_fields__)),
        "photos": _table(tuple(PhotoSpec.__dataclass_fields__)),
        "bogus": _table(("x",)),
    },
)


def _toml_value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        return "nan" if math.isnan(v) else ("inf" if v > 0 else "-inf") if math.isinf(v) else repr(v)
    if isinstance(v, str):
        return '"' + "".join(c if c.isprintable() and c not in '"\\' else f"\\u{ord(c):04x}" for c in v) + '"'
    return "[" + ", ".join(_toml_value(x) for x in v) + "]"


def _toml_key(k: str) -> str:
    return k if k and all(c.isalnum() or c in "_-" for c in k) else '"' + k.replace('"', "") + '"'


def _toml(doc: dict) -> str:
    lines = []
    for name, body in doc.items():
        for table in body if isinstance(body, list) else [body]:
            lines.append(f"[[{name}]]" if isinstance(body, list) else f"[{name}]")
            lines += [f"{_toml_key(k)} = {_toml_value(v)}" for k, v in table.items()]
    return "\n".join(lines) + "\n"


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    d = tmp_path_factory.mktemp("fuzz")
    a = np.zeros((40, 80), np.uint8)
    a[5:18, 5:38] = 255
    a[22:35, 42:75] = 255
    Image.fromarray(a).save(d / "m.png")
    return d


def _one_line(exc: BaseException) -> None:
    text = str(exc)
    assert text and "\n" not in text, f"not a one-line error: {text!r}"


@FUZZ
@given(doc=documents, require=st.booleans())
def test_structure_files_load_or_fail_in_one_line(folder, doc, require):
    path = folder / "s.toml"
    path.write_text(_toml(doc), encoding="utf-8")
    try:
        load_structure(path, require_sources=require)
    except CalibMasonryError as exc:
        _one_line(exc)


@FUZZ
@given(text=st.text(max_size=200))
def test_any_text_as_a_structure_file_loads_or_fails_in_one_line(folder, text):
    path = folder / "t.toml"
    path.write_text(text, encoding="utf-8")
    try:
        load_structure(path, require_sources=False)
    except CalibMasonryError as exc:
        _one_line(exc)


def _cli(argv) -> tuple[int, str]:
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        try:
            rc = main([str(a) for a in argv])
        except SystemExit as exc:  # argparse's own errors
            rc = exc.code
    return rc, err.getvalue()


def _assert_clean(rc: int, err: str) -> None:
    assert rc in (0, 2), (rc, err)
    if rc == 2:
        lines = [line for line in err.splitlines() if line.strip()]
        assert len(lines) == 1 and lines[0].startswith("error: "), err


def _flag(value) -> str:
    return repr(value) if isinstance(value, float) else str(value)


ints = st.one_of(st.integers(-(2**40), 2**40), st.sampled_from([0, -1, 1, 3, 2**31, 10**6]))
floats = st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.sampled_from([0.0, -1.0, 0.05, 1e-12, 1e9]))


@settings(FUZZ, max_examples=60)
@given(
    flags=st.dictionaries(
        st.sampled_from(
            [
                "--pga",
                "--duration",
                "--seed",
                "--fps",
                "--substeps",
                "--iterations",
                "--direction",
                "--pushover-rate",
                "--pushover-max",
                "--frames",
            ]
        ),
        st.one_of(ints, floats),
        max_size=5,
    ),
    pushover=st.booleans(),
)
def test_simulate_numeric_flags(folder, flags, pushover):
    argv = ["simulate", folder / "no-model"]
    for k, v in flags.items():
        argv += [k, _flag(v)]  # a float for an int flag: argparse's own one-line error
    if pushover:
        argv.append("--pushover")
    rc, err = _cli([*argv, "--out", folder / "sim"])
    _assert_clean(rc, err)
    assert rc == 2  # the model does not exist: a valid set of flags reaches that check
    assert "Traceback" not in err


@settings(FUZZ, max_examples=40)
@given(
    flags=st.dictionaries(
        st.sampled_from(["--camera-height", "--camera-height-sigma", "--focal-px", "--max-rms", "--known-width"]),
        floats,
        max_size=4,
    )
)
def test_rectify_numeric_flags(folder, flags):
    argv = ["rectify", folder / "no-photo.jpg"]
    for k, v in flags.items():
        argv += [k, _flag(v)]
    rc, err = _cli([*argv, "--out", folder / "rect"])
    _assert_clean(rc, err)
    assert rc == 2


@settings(FUZZ, max_examples=40)
@given(vertices=st.one_of(st.none(), ints), target=st.one_of(st.none(), floats))
def test_trace_numeric_flags(folder, vertices, target):
    argv = ["trace", folder / "m.png", "--no-figures", "--out", folder / "p.json"]
    if vertices is not None:
        argv += ["--vertices", str(min(vertices, 10**4) if vertices > 64 else vertices)]
    if target is not None:
        argv += ["--target-dice", _flag(target)]
    rc, err = _cli(argv)
    _assert_clean(rc, err)


@settings(FUZZ, max_examples=30)
@given(size=st.tuples(ints, ints))
def test_synth_photo_size(folder, size):
    rc, err = _cli(["synth", folder / "none.toml", "--photos", "--photo-size", *size, "--out", folder / "syn"])
    _assert_clean(rc, err)
    assert rc == 2  # the size is refused, or else the missing scenario

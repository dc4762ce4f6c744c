import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from calib_masonry.cli import main

from .conftest import DATA, SWAT


def _run(*args, cwd=None, timeout=600):
    """The CLI in a process of its own. One that hangs fails the test with its threads' Python
    stacks (faulthandler, on SIGABRT) instead of holding up the whole run."""
    env = dict(os.environ, PYTHONFAULTHANDLER="1")
    with subprocess.Popen(
        [sys.executable, "-m", "calib_masonry", *map(str, args)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        cwd=cwd,
        env=env,
    ) as p:
        try:
            out, err = p.communicate(timeout=timeout)
        except subprocess.TimeoutExpired:
            p.send_signal(signal.SIGABRT)
            out, err = p.communicate()
            pytest.fail(f"calib-masonry {' '.join(map(str, args))} hung for {timeout} s; its threads:\n{err[-6000:]}")
    return subprocess.CompletedProcess(p.args, p.returncode, out, err)


def test_trace_cli_writes_polygons_json(tmp_path):
    out = tmp_path / "polygons.json"
    assert main(["trace", str(SWAT), "--vertices", "8", "--out", str(out)]) == 0
    doc = json.loads(out.read_text())
    assert doc["image_shape"] == [1013, 843]
    assert len(doc["bricks"]) == 45 and doc["mean_dice"] >= 0.98
    b = doc["bricks"][0]
    assert {"id", "vertices_xy", "traced_vertices", "dice"} <= set(b)
    assert (tmp_path / "polygons.png").is_file()


def _structure(tmp_path, mask_name="m.png", width=2.0, height=1.0, vertices=5):
    p = tmp_path / "s.toml"
    p.write_text(
        f'[structure]\nthickness_m = 0.18\nvertices = {vertices}\n[[wall]]\nname = "a"\nmask = "{mask_name}"\n'
        f"width_m = {width}\nheight_m = {height}\ntheta_deg = 0\n"
    )
    return p


@pytest.mark.parametrize(
    "case, expect",
    [
        ("missing_mask", "not found"),
        ("corrupt", "cannot be read"),
        ("grey", "not a binary-like mask"),
        ("empty", "flat value"),
        ("aspect", "aspect ratio"),
        ("negative_width", "width_m"),
        ("t_ge_w", "thickness_m"),
        ("vertices", "vertices"),
        ("inverted", "looks inverted"),
    ],
)
def test_build_bad_input_one_line_exit_2(tmp_path, case, expect):
    a = np.zeros((100, 200), np.uint8)
    a[10:40, 10:90] = 255
    Image.fromarray(a).save(tmp_path / "m.png")
    kw = {}
    if case == "missing_mask":
        kw["mask_name"] = "gone.png"
    elif case == "corrupt":
        (tmp_path / "bad.png").write_bytes(b"garbage")
        kw["mask_name"] = "bad.png"
    elif case == "grey":
        Image.fromarray(np.random.default_rng(0).integers(0, 255, (100, 200), dtype=np.uint8)).save(tmp_path / "g.png")
        kw["mask_name"] = "g.png"
    elif case == "empty":
        Image.fromarray(np.zeros((100, 200), np.uint8)).save(tmp_path / "e.png")
        kw["mask_name"] = "e.png"
    elif case == "aspect":
        kw["width"] = 3.0
    elif case == "negative_width":
        kw["width"] = -2.0
    elif case == "t_ge_w":
        kw["width"] = 0.1
    elif case == "vertices":
        kw["vertices"] = 2
    elif case == "inverted":  # mortar white around eight bricks: one piece, not a wall of eight
        inv = np.full((100, 200), 255, np.uint8)
        for r in range(2):
            for c in range(4):
                inv[10 + 45 * r : 45 + 45 * r, 10 + 47 * c : 50 + 47 * c] = 0
        Image.fromarray(inv).save(tmp_path / "inv.png")
        kw["mask_name"] = "inv.png"
    s = _structure(tmp_path, **kw)
    out = tmp_path / "out"
    r = _run("build", s, "--out", out)
    assert r.returncode == 2, r.stderr
    lines = [line for line in r.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("error:") and expect in lines[0], r.stderr
    assert not out.exists()
    assert not any(p.name.startswith(".out") for p in tmp_path.iterdir())


def test_trace_missing_and_compare_bad_dirs(tmp_path):
    r = _run("trace", tmp_path / "none.png", "--out", tmp_path / "p.json")
    assert r.returncode == 2 and "not found" in r.stderr and not (tmp_path / "p.json").exists()
    r = _run("compare", tmp_path / "nope", tmp_path / "nada")
    assert r.returncode == 2 and r.stderr.count("\n") == 1


def test_synth_without_synthetic_table(tmp_path):
    p = tmp_path / "s.toml"
    p.write_text("[structure]\nthickness_m = 0.18\n[[wall]]\nwidth_m = 2\nheight_m = 1\n")
    r = _run("synth", p, "--out", tmp_path / "d")
    assert r.returncode == 2 and "[synthetic]" in r.stderr


@pytest.mark.slow
def test_demo_from_project_folder(tmp_path):
    r = _run("demo", "--out", tmp_path / "demo", cwd=DATA.parent)
    assert r.returncode == 0, r.stdout + r.stderr
    assert "FAIL" not in r.stdout
    m = json.loads((tmp_path / "demo" / "compare.json").read_text())
    assert m["precision"] == 1.0 and m["recall"] == 1.0


@pytest.mark.parametrize("command", ["build", "trace", "simulate", "synth"])
@pytest.mark.parametrize("where", ["is_a_file", "under_a_file"])
def test_out_that_cannot_be_written_is_refused_up_front(tmp_path, command, where):
    blocker = tmp_path / "blocker"
    blocker.write_text("not a folder")
    out = blocker if where == "is_a_file" else blocker / "sub" / "out"
    if command == "trace" and where == "is_a_file":
        out = tmp_path  # a folder where a file is wanted
    args = {
        "build": ["build", DATA / "paper_example" / "structure.toml"],
        "trace": ["trace", SWAT],
        "simulate": ["simulate", tmp_path / "no-model"],
        "synth": ["synth", DATA / "paper_example" / "scenario.toml"],
    }[command]
    r = _run(*args, "--out", out)
    assert r.returncode == 2, r.stderr
    lines = [line for line in r.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: --out"), r.stderr
    assert blocker.read_text() == "not a folder"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["blocker"]


@pytest.mark.parametrize("command", ["build", "simulate", "synth", "rectify", "footprint", "demo"])
def test_out_that_is_not_an_earlier_output_is_refused_up_front(tmp_path, command):
    out = tmp_path / "results"
    out.mkdir()
    (out / "thesis.tex").write_text("not ours")
    args = {
        "build": ["build", DATA / "paper_example" / "structure.toml"],
        "simulate": ["simulate", tmp_path / "no-model"],
        "synth": ["synth", DATA / "paper_example" / "scenario.toml"],
        "rectify": ["rectify", tmp_path / "no-photo.jpg"],
        "footprint": ["footprint", tmp_path / "no.json"],
        "demo": ["demo"],
    }[command]
    r = _run(*args, "--out", out)
    assert r.returncode == 2, r.stderr
    lines = [line for line in r.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: --out") and "--overwrite" in lines[0], r.stderr
    assert sorted(p.name for p in out.iterdir()) == ["thesis.tex"]


def test_a_build_into_an_earlier_output_replaces_it_whole(tmp_path):
    a = np.zeros((100, 200), np.uint8)
    a[10:40, 10:90] = 255
    a[60:90, 110:190] = 255
    Image.fromarray(a).save(tmp_path / "m.png")
    s = _structure(tmp_path)
    out = tmp_path / "out"
    assert _run("build", s, "--out", out).returncode == 0
    (out / "compare.json").write_text("{}")  # as the demo or `compare` leave it
    (out / "photos").mkdir()  # as a build from photos leaves it
    r = _run("build", s, "--out", out, "--no-figures")
    assert r.returncode == 0, r.stderr
    assert r.stdout.startswith("build: ") and "Info:" not in r.stdout  # no Blender line among the results
    names = {p.name for p in out.iterdir()}
    assert "compare.json" not in names and "photos" not in names and "walls.png" not in names
    assert {"bricks.json", "model.stl", "model.glb", "summary.json"} <= names
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m.png", "out", "s.toml"]
    # a folder holding the structure's own files is built into only with --overwrite, and they stay
    r = _run("build", s, "--out", tmp_path)
    assert r.returncode == 2 and "--overwrite" in r.stderr
    r = _run("build", tmp_path / "s.toml", "--out", tmp_path, "--overwrite", "--no-figures")
    assert r.returncode == 0, r.stderr
    assert {"m.png", "s.toml", "bricks.json"} <= {p.name for p in tmp_path.iterdir()}


def _staging(folder):
    return [p for p in folder.iterdir() if ".partial-" in p.name]


def _sigterm_build(tmp_path, gaps_s: tuple[float, ...]) -> str:
    """Run ``build`` of the paper example, send it SIGTERM 3 s in and again after each gap; assert
    exit code 2, the one line and nothing written; returns stderr."""
    import signal
    import time

    out = tmp_path / "model"
    p = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "calib_masonry",
            "build",
            str(DATA / "paper_example" / "structure.toml"),
            "--out",
            str(out),
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    time.sleep(3.0)  # into the work (the build took 6-7 s on 2026-11-26, imports 1.5 s; the Stylite one ended first)
    assert p.poll() is None, "the build ended before it could be killed; use a larger structure"
    p.send_signal(signal.SIGTERM)
    for gap in gaps_s:
        time.sleep(gap)
        p.send_signal(signal.SIGTERM)
    _, err = p.communicate(timeout=30)  # how fast is measured in the note, not asserted
    assert p.returncode == 2 and "terminated; nothing was written" in err
    assert not out.exists() and _staging(tmp_path) == []
    return err


@pytest.mark.slow
def test_sigterm_stops_build_and_leaves_nothing(tmp_path):
    _sigterm_build(tmp_path, ())


def test_sigterm_twice_as_timeout_sends_it_stops_once_and_cleanly(tmp_path):
    """GNU ``timeout`` signals the command and then its whole process group, so the command gets
    SIGTERM twice; the second one, raised in the first one's clean-up, once left "Exception ignored
    in: <stdout> TypeError" after the error line, or (after the handler was reset) killed it with
    -15 (1 of 8 and 1 of 10 runs of this test before the fix; 0 of 12 after)."""
    err = _sigterm_build(tmp_path, (0.01,))
    assert "Traceback" not in err and "Exception ignored" not in err


def _children(pid: int) -> list[int]:
    out = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[1]) == pid:
            out.append(int(stat.parent.name))
    return out


@pytest.mark.slow
def test_sigterm_stops_build_and_its_worker_processes(tmp_path):
    # build traces half of its walls, and computes the simulation geometry, in processes of their
    # own (_worker.py): SIGTERM to the command while one runs stops all and writes nothing
    import time

    out = tmp_path / "model"
    cmd = [sys.executable, "-m", "calib_masonry", "build", str(DATA / "paper_example" / "structure.toml")]
    p = subprocess.Popen([*cmd, "--out", str(out)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    kids: list[int] = []
    for _ in range(3000):
        kids = [k for k in _children(p.pid) if b"calib_masonry._worker" in _cmdline(k)]
        if kids or p.poll() is not None:
            break
        time.sleep(0.01)
    assert kids, "no worker process was started"
    time.sleep(0.5)  # into its work (the paper example's trace and geometry take seconds)
    assert p.poll() is None, "the build ended before it could be killed; use a larger structure"
    p.send_signal(signal.SIGTERM)
    _, err = p.communicate(timeout=30)
    assert p.returncode == 2 and "terminated; nothing was written" in err, err
    assert not out.exists() and _staging(tmp_path) == []
    for _ in range(100):
        if not any(Path(f"/proc/{k}").exists() for k in kids):
            break
        time.sleep(0.05)
    assert not any(Path(f"/proc/{k}").exists() for k in kids)


def _cmdline(pid: int) -> bytes:
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes()
    except OSError:
        return b""


@pytest.mark.slow
def test_sigterm_stops_trace_refine_and_its_solver_process(tmp_path):
    # trace --refine solves in a forked process: SIGTERM to the command stops both, writes nothing
    import time

    out = tmp_path / "p.json"
    cmd = [sys.executable, "-m", "calib_masonry", "trace", str(SWAT), "--refine", "--no-figures", "--out", str(out)]
    p = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    for _ in range(300):
        kids = _children(p.pid)
        if kids or p.poll() is not None:
            break
        time.sleep(0.02)
    assert kids, "no solver process was started"
    time.sleep(2.5)  # into the refinement (the SWAT wall's takes about 8 s)
    assert p.poll() is None, "the refinement ended before it could be killed; use a larger mask"
    p.send_signal(signal.SIGTERM)
    _, err = p.communicate(timeout=30)
    assert p.returncode == 2 and "terminated" in err, err
    assert not out.exists() and _staging(tmp_path) == []
    for _ in range(100):  # the solver process is gone too (killed or left on its own)
        if not any(Path(f"/proc/{k}").exists() for k in kids):
            break
        time.sleep(0.05)
    assert not any(Path(f"/proc/{k}").exists() for k in kids)


@pytest.mark.slow
def test_sigterm_stops_simulate_and_sigkill_staging_goes_with_the_next_run(tmp_path):
    import signal
    import time

    from calib_masonry.build_folder import build_to_folder
    from calib_masonry.spec import load_structure
    from calib_masonry.synthetic.truth import synthesize_to_folder

    from .conftest import scenario_text

    sc = tmp_path / "s.toml"
    sc.write_text(scenario_text([(1.6, 0.8, 0), (1.2, 0.8, 90), (1.6, 0.8, 180), (1.2, 0.8, 270)]))
    synthesize_to_folder(load_structure(sc, require_sources=False), tmp_path / "data", figures=False)
    build_to_folder(
        load_structure(tmp_path / "data" / "structure.toml"), tmp_path / "model", figures=False, progress=False
    )
    runs = tmp_path / "runs"
    runs.mkdir()
    out = runs / "sim"

    def start():
        return subprocess.Popen(
            [
                sys.executable,
                "-m",
                "calib_masonry",
                "simulate",
                str(tmp_path / "model"),
                "--duration",
                "60",
                "--out",
                str(out),
            ],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )

    def wait_for_staging(p):
        for _ in range(600):
            if _staging(runs):
                return
            assert p.poll() is None, p.communicate()[1]
            time.sleep(0.1)
        raise AssertionError("no staging folder appeared")

    p = start()
    wait_for_staging(p)
    time.sleep(1.0)  # stepping
    p.send_signal(signal.SIGTERM)
    _, err = p.communicate(timeout=30)
    assert p.returncode == 2 and "terminated" in err, err
    assert not out.exists() and _staging(runs) == []

    p = start()
    wait_for_staging(p)
    p.kill()  # SIGKILL: nothing can clean up
    p.communicate(timeout=10)
    assert len(_staging(runs)) == 1
    r = _run("simulate", tmp_path / "model", "--duration", "0.5", "--frames", "0", "--no-figures", "--out", out)
    assert r.returncode == 0, r.stderr
    assert _staging(runs) == [] and (out / "summary.json").is_file()


def test_oversized_and_misnamed_images_are_one_line_errors(tmp_path, monkeypatch):
    from calib_masonry import io
    from calib_masonry.errors import InputError

    mask = np.zeros((60, 80), np.uint8)
    mask[10:50, 10:70] = 255
    Image.fromarray(mask).save(tmp_path / "m.png")
    monkeypatch.setattr(io, "MAX_IMAGE_PIXELS", 4000)
    with pytest.raises(InputError, match="80 x 60 px .* above the 0 megapixel limit; downsample it"):
        io.read_mask(tmp_path / "m.png")
    monkeypatch.setattr(io, "_TRUST_LARGE_IMAGES", True)
    assert io.read_mask(tmp_path / "m.png").sum() == 40 * 60
    Image.fromarray(mask).save(tmp_path / "j.jpg", quality=95)
    (tmp_path / "j.jpg").rename(tmp_path / "j.png")
    r = _run("trace", tmp_path / "j.png", "--out", tmp_path / "p.json")
    assert r.returncode == 2 and r.stderr.count("\n") == 1
    assert "is a JPEG image named .png" in r.stderr and not (tmp_path / "p.json").exists()


def test_an_image_too_big_for_the_memory_is_refused_before_decoding(tmp_path, monkeypatch):
    from calib_masonry import io
    from calib_masonry.errors import InputError

    Image.fromarray(np.full((60, 80), 255, np.uint8)).save(tmp_path / "m.png")
    monkeypatch.setattr(io, "_available_bytes", lambda: 1000)
    with pytest.raises(InputError, match=r"m.png: 80 x 60 px needs about .* GiB .* free; downsample it"):
        io.read_mask(tmp_path / "m.png")


@pytest.mark.parametrize(
    "args, expect",
    [
        (["trace", SWAT, "--vertices", "0"], "vertices = 0 is too few"),
        (["rectify", SWAT, "--max-rms", "-1"], "--max-rms -1.0: must be > 0"),
        (["simulate", DATA, "--pga", "1e9"], "--pga 1000000000.0"),
        (["simulate", DATA, "--frames", "-1"], "--frames -1"),
        (["simulate", DATA, "--pga", "-1e+16"], "--pga -1e+16"),
        (["simulate", DATA, "--iterations", "1e9"], "invalid int value"),
    ],
)
def test_silently_accepted_values_are_one_line_errors(tmp_path, args, expect):
    """Values the earlier versions took without a word (--vertices 0 as 5, --pga 1e9 as a 242,329 km
    roof drift) end in one line and exit 2, before any work, with nothing written."""
    r = _run(*args, "--out", tmp_path / "out")
    assert r.returncode == 2, r.stderr
    lines = [line for line in r.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: ") and expect in lines[0], r.stderr
    assert list(tmp_path.iterdir()) == []


def test_no_command_writes_over_its_input(tmp_path):
    """`trace MASK --out MASK`, `trace M --figure M`, a polygons file whose figure would be the mask,
    and `compare RUN TRUTH --out TRUTH/truth.json` are refused before any work, the input intact."""
    import shutil

    mask = tmp_path / "m.png"
    shutil.copy(SWAT, mask)
    before = mask.read_bytes()
    for extra in (["--out", mask], ["--out", tmp_path / "p.json", "--figure", mask], ["--out", tmp_path / "m.json"]):
        r = _run("trace", mask, "--vertices", "6", *extra)
        assert r.returncode == 2 and r.stderr.count("\n") == 1, r.stderr
        assert "inputs" in r.stderr and mask.read_bytes() == before
    truth = tmp_path / "truth"
    shutil.copytree(DATA / "paper_example" / "truth", truth)
    doc = (truth / "truth.json").read_bytes()
    r = _run("compare", tmp_path, truth, "--out", truth / "truth.json")
    assert r.returncode == 2 and "inputs" in r.stderr and (truth / "truth.json").read_bytes() == doc


def test_contradictory_and_out_of_range_motion_inputs_are_refused(tmp_path):
    """--pushover with a quake's flags is refused; a record whose peak is above any recorded motion
    (cm/s2 read as g) is refused naming --units, where it ran at 267 g and 'collapsed'."""
    for extra in (["--pga", "0.3"], ["--accelerogram", tmp_path / "a.csv"]):
        r = _run("simulate", DATA, "--pushover", *extra, "--out", tmp_path / "o")
        assert r.returncode == 2 and "--pushover with" in r.stderr and r.stderr.count("\n") == 1, r.stderr
    t = np.arange(0, 4, 0.01)
    rec = tmp_path / "cms2.csv"
    rec.write_text("".join(f"{a:.4f},{b:.4f}\n" for a, b in zip(t, 250 * np.sin(2 * np.pi * t), strict=True)))
    from calib_masonry.errors import InputError
    from calib_masonry.simulation.ground_motion import read_accelerogram

    with pytest.raises(InputError, match=r"cms2.csv.*peak is 250 g.*--units m/s2"):
        read_accelerogram(rec)
    ms2 = tmp_path / "ms2.csv"  # a record in m/s2, as the message advises, starting and ending at rest
    env = np.sin(np.pi * t / t[-1]) ** 2
    ms2.write_text("".join(f"{a:.4f},{b:.6f}\n" for a, b in zip(t, 2.5 * env * np.sin(2 * np.pi * t), strict=True)))
    assert read_accelerogram(ms2, units="m/s2").source == "ms2.csv"


def test_negative_corner_lists_are_values_not_options():
    """`--corners -5000,0,...` (a corner left of the photo) is read as the list, not as a flag."""
    from calib_masonry.cli import _parser

    args = _parser().parse_args(["rectify", "p.jpg", "--corners", "-5000,0,10,0,10,10,0,10", "--out", "o"])
    assert args.corners == "-5000,0,10,0,10,10,0,10"
    args = _parser().parse_args(["rectify", "p.jpg", "--known-length", "-1.5e2,3,40,3,0.9", "--out", "o"])
    assert args.known_length.startswith("-1.5e2")


@pytest.mark.skipif(not os.path.isdir("/proc/self"), reason="Linux's /proc")
@pytest.mark.parametrize("command", ["build", "trace", "simulate", "study", "rectify"])
def test_out_where_nothing_can_be_written_is_refused_before_any_work(tmp_path, command):
    """--out under /proc (as on a read-only file system) is one line and exit 2 up front, where it
    was a traceback after the work (a study's after 15 s)."""
    from .conftest import ROOT

    first = {
        "build": [ROOT / "data_synthetic" / "paper_example" / "structure.toml"],
        "trace": [SWAT, "--vertices", "6"],
        "simulate": [DATA],
        "study": [next((ROOT / "data_synthetic" / "studies").glob("*.toml"))],
        "rectify": [SWAT],
    }[command]
    out = "/proc/calib-masonry-out.json" if command == "trace" else "/proc/calib-masonry-out"
    r = _run(command, *first, "--out", out, timeout=120)
    assert r.returncode == 2 and r.stderr.count("\n") == 1, r.stderr
    assert "nothing can be written in /proc" in r.stderr


@pytest.mark.parametrize("width", ["1e300", "5000"])
def test_an_impossible_dimension_is_a_short_line(tmp_path, width):
    """`width_m = 1e300` printed a 270-digit number; a wall larger than any masonry (a unit error)
    is refused in one short line that names the field and the unit."""
    import shutil

    shutil.copy(SWAT, tmp_path / "m.png")
    p = _structure(tmp_path)
    p.write_text(p.read_text().replace("width_m = 2.0", f"width_m = {width}"))
    r = _run("build", p, "--out", tmp_path / "out")
    assert r.returncode == 2 and r.stderr.count("\n") == 1, r.stderr
    assert "width_m" in r.stderr and "metres" in r.stderr and len(r.stderr) < 200


def test_every_argument_has_help_and_shows_its_default():
    """`simulate --help` showed --duration, --seed, --out and model_dir without help or default."""
    import argparse

    from calib_masonry.cli import _parser

    p = _parser()
    assert not p.description.startswith("``")  # a sentence, not a docstring fragment
    sub = next(a for a in p._actions if isinstance(a, argparse._SubParsersAction))
    missing, hidden = [], []
    for name, parser in sub.choices.items():
        for a in parser._actions:
            if not a.help:
                missing.append((name, a.dest))
            elif a.default not in (None, False, True, argparse.SUPPRESS) and "default" not in a.help:
                hidden.append((name, a.dest))
    assert missing == [] and hidden == []


@pytest.mark.parametrize("n", ["1000000000", "1e9"])
def test_a_study_too_large_is_refused_before_it_is_drawn(tmp_path, n):
    """n = 1e9 (an int or a float) ran out of memory drawing the design; it is one line, at once."""
    from .conftest import ROOT

    src = ROOT / "data_synthetic" / "studies" / "paper_example_geometry.toml"
    text = (
        src.read_text()
        .replace("n = 64", f"n = {n}")
        .replace("../paper_example", str(ROOT / "data_synthetic" / "paper_example"))
    )
    study = tmp_path / "big.toml"
    study.write_text(text)
    r = _run("study", study, "--out", tmp_path / "out", timeout=120)
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and "[sampling] n = 1e+09" in r.stderr, r.stderr
    assert not (tmp_path / "out").exists()


def test_a_scenario_too_fine_for_memory_is_refused_before_any_work(tmp_path):
    """px_per_m = 1e6 ran out of memory drawing the masks; it is one line naming the largest value."""
    from .conftest import ROOT

    text = (ROOT / "data_synthetic" / "paper_example" / "scenario.toml").read_text()
    import re

    text = re.sub(r"px_per_m = [0-9.]+", "px_per_m = 1e6", text, count=1)
    p = tmp_path / "scenario.toml"
    p.write_text(text)
    r = _run("synth", p, "--out", tmp_path / "out", timeout=120)
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and "lower px_per_m to at most" in r.stderr, r.stderr


_REFUSED_AFTER = """
import sys, time
import calib_masonry.calibrate.rectify as rectify
from calib_masonry.cli import main
from calib_masonry.errors import FitFailed

def refuse(photo, config):
    time.sleep(float(sys.argv[1]))
    raise FitFailed(f"{photo}: refused (test)")

rectify.calibrate_photo = refuse
sys.exit(main(["rectify", sys.argv[2], "--known-width", "1", "--out", sys.argv[3]]))
"""


def test_rectify_refused_while_jax_loads_beside_it_exits_2(tmp_path):
    """rectify loads JAX's compiled fit on a thread of its own while it reads the photo. A photo
    refused within a second (a 16-bit PNG read as a white photo) left the process while that
    thread was inside JAX's native code, and the interpreter's shutdown aborted it (exit code 134,
    "terminate called after throwing an instance of ''"): measured with the refusal 0.4 and 0.6 s
    after the start. The refusal is made at delays across that window: one line and exit code 2
    on every run, nothing written."""
    Image.fromarray(np.full((300, 200, 3), 128, np.uint8)).save(tmp_path / "flat.png")
    script = tmp_path / "refused.py"
    script.write_text(_REFUSED_AFTER)
    for delay in (0.3, 0.4, 0.45, 0.5, 0.55, 0.6, 0.7, 0.9):
        out = tmp_path / f"o{delay}"
        r = subprocess.run(
            [sys.executable, str(script), str(delay), str(tmp_path / "flat.png"), str(out)],
            capture_output=True,
            text=True,
            timeout=120,
        )
        assert r.returncode == 2, (delay, r.stderr[-2000:])
        assert r.stderr.count("\n") == 1 and "refused (test)" in r.stderr and not out.exists()


def test_the_quake_line_says_which_roof_drift_is_the_vibration():
    # a top piece that rocks 24 cm and comes back moves no brick by the end; the printed line said
    # "moved 0.0 % of bricks, max roof drift 244 mm" and left the held structure's vibration out
    from calib_masonry.cli import _quake_line

    s = {
        "bricks": 336,
        "bonds": 1971,
        "ground_motion": {"source": "E.ASC + N.ASC"},
        "outcome": "standing",
        "toppled_fraction": 0.0,
        "moved_fraction_final": 0.0,
        "bonds_broken_fraction": 0.06,
        "max_roof_drift_m": 0.2439,
        "dynamics": {"max_roof_drift_m": 0.00537},
        "seconds": {"stepping": 10.8},
    }
    line = _quake_line(s, "out")
    assert "moved 0.0% of bricks at the end" in line
    assert "max roof drift 244 mm (the held structure's vibration 5.4 mm)" in line
    s["dynamics"] = {"elastic": False}  # --quasi-static: no vibration to print
    assert "vibration" not in _quake_line(s, "out")

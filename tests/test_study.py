"""Studies: sampling, the analytic checks of what they report, Dask execution, resuming, bad files."""

from __future__ import annotations

import json
import math
import os
import signal
import subprocess
import sys
import time
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from calib_masonry.errors import InputError
from calib_masonry.study.analysis import fit_fragility
from calib_masonry.study.design import load_study, samples
from calib_masonry.study.run import run_study, study_to_folder

from .conftest import scenario_text

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "data_synthetic"
BOOKKEEPING = ("seconds", "worker")


def _study(tmp_path: Path, text: str, name: str = "s.toml") -> Path:
    p = tmp_path / name
    p.write_text(text)
    return p


@pytest.fixture
def small_structure(make_scenario):
    """Two small synthetic walls at a corner, their masks and structure.toml."""
    return make_scenario([(1.6, 0.8, 0), (1.2, 0.8, 90)], closed=False) / "structure.toml"


def test_lognormal_fragility_fit_recovers_the_curve_it_was_drawn_from():
    from scipy.stats import norm

    rng = np.random.default_rng(3)
    theta, beta = 0.35, 0.45
    pga = np.repeat(np.linspace(0.1, 0.9, 9), 150)
    collapsed = rng.random(len(pga)) < norm.cdf(np.log(pga / theta) / beta)
    fit = fit_fragility(pga, collapsed)
    assert fit is not None
    assert fit[0] == pytest.approx(theta, rel=0.08) and fit[1] == pytest.approx(beta, rel=0.15)
    # perfectly separated outcomes have no finite maximum-likelihood curve: no fit, not a step made up
    assert fit_fragility(np.array([0.1, 0.2, 0.4, 0.8]), np.array([0, 0, 1, 1])) is None


def test_the_convergence_sweeps_fragility_reads_its_own_lines_and_finds_a_known_median(tmp_path):
    # experiments/sim_convergence.py --fragility --logs: sweep lines printed by two processes (one
    # setting each, a model given by a long path) read back, and the median over records of
    # verdicts made from known thresholds: each record collapses from its own threshold on, the
    # thresholds the quantiles of a lognormal (median 0.9 g, beta 0.3), the second setting's 10 %
    # higher. The fit finds each median and their change, and its paired band holds the change
    from scipy.stats import norm

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "experiments"))
    import sim_convergence as sc

    seeds = list(range(40))
    grid = np.round(np.arange(0.4, 1.65, 0.1), 2)
    model = "/a/long/path/to/an/unseen/tower/structure.toml"
    logs = []
    for setting, scale in (("default", 1.0), ("1/2 check interval", 1.1)):
        lines = []
        for s in seeds:
            threshold = scale * 0.9 * math.exp(0.3 * norm.ppf((s + 0.5) / len(seeds)))
            for pga in grid:
                outcome = "collapsed" if pga >= threshold else "damaged"
                r = dict(cracked=0.1, in_pieces=None, freed=1.0, moved=0.5, bullet_moved=float("nan"))
                lines.append(
                    sc.sweep_line(model, setting, s, float(pga), dict(r, toppled=0.0, outcome=outcome, seconds=9))
                )
        logs.append(tmp_path / f"{len(logs)}.txt")
        logs[-1].write_text("\n".join(["a line that is not a run's", *lines, ""]))
    verdicts, models, settings, read = sc.read_logs(logs)
    assert models == [model] and settings == ["default", "1/2 check interval"] and read == seeds
    assert len(verdicts[(model, "default")]) == len(seeds) * len(grid)
    rows = sc.fragility(verdicts, models, settings, read, resamples=50)
    assert rows[0]["median"] == pytest.approx(0.9, rel=0.05) and rows[1]["median"] == pytest.approx(0.99, rel=0.05)
    assert rows[1]["change"] == pytest.approx(0.09, abs=0.03)
    assert rows[1]["change_band"][0] <= rows[1]["change"] <= rows[1]["change_band"][1]
    assert "change" not in rows[0]


def test_the_design_is_a_pure_function_of_the_study(tmp_path, small_structure):
    text = (
        f'[study]\nname = "d"\nstructure = "{small_structure}"\n[sampling]\nmethod = "lhs"\nn = 8\nseed = 4\n'
        "[inputs.w0]\nwidth_m = { sigma = 0.01 }\ntheta_deg = { range = [-1, 1] }\n"
        "[inputs.trace]\nvertices = { choices = [4, 5, 6] }\n"
    )
    a = samples(load_study(_study(tmp_path, text)))
    b = samples(load_study(_study(tmp_path, text, "again.toml")))
    assert [s.values for s in a] == [s.values for s in b] and len(a) == 8
    w = np.array([s.values["w0.width_m"] for s in a])
    # a Latin hypercube puts one draw in each of n equal-probability strata of every input
    from scipy.stats import norm

    strata = np.floor(norm.cdf((w - 1.6) / 0.01) * 8).astype(int)
    assert sorted(strata) == list(range(8))
    assert {s.values["trace.vertices"] for s in a} <= {4, 5, 6}


def test_sobol_gives_the_only_input_with_spread_all_of_the_variance(tmp_path, small_structure):
    text = (
        f'[study]\nname = "sobol"\nstructure = "{small_structure}"\n'
        '[sampling]\nmethod = "sobol"\nn = 16\nseed = 2\n'
        "[inputs.w0]\nwidth_m = { sigma = 0.05 }\nheight_m = { sigma = 0.0 }\n"
        "[inputs.w1]\nwidth_m = { sigma = 0.0 }\ntheta_deg = { sigma = 0.0 }\n"
    )
    study = load_study(_study(tmp_path, text))
    rows, summary = run_study(study, workers=0, progress=False)
    assert summary["failed"] == 0 and summary["samples"] == 16 * (4 + 2)
    si = summary["sobol"]["total_volume_m3"]
    assert si["w0.width_m"]["ST"] > 0.9
    for other in ("w0.height_m", "w1.width_m", "w1.theta_deg"):
        assert abs(si[other]["ST"]) < 0.05 and abs(si[other]["S1"]) < 0.05
    # an open L has no closure: its ends' distance (which varied with w0's width) is no output, and
    # an output the same in every sample has no spread (numpy's std left 1e-16 on the mean Dice)
    assert all(r["closure_error_m"] is None for r in rows) and summary["outputs"]["closure_error_m"] == {"n": 0}
    assert "closure_error_m" not in summary["sobol"]
    assert len({r["mean_dice"] for r in rows}) == 1 and summary["outputs"]["mean_dice"]["std"] == 0.0


@pytest.mark.slow
def test_geometry_study_spread_of_volume_matches_the_first_order_estimate(tmp_path):
    """64 LHS samples of the paper example on a LocalCluster: the standard deviation of the total
    brick volume against sqrt(sum (dV/dx_i sigma_i)^2), the derivatives by central differences of
    the build at the structure's values."""
    from calib_masonry.pipeline import build
    from calib_masonry.spec import load_structure

    sigma = {"width_m": 0.02, "height_m": 0.03, "thickness_m": 0.004}
    path = _study(
        tmp_path,
        f'[study]\nname = "geometry"\nstructure = "{DATA / "paper_example" / "structure.toml"}"\n'
        '[sampling]\nmethod = "lhs"\nn = 64\nseed = 5\n'
        "[inputs.every_wall]\n" + "".join(f"{k} = {{ sigma = {v} }}\n" for k, v in sigma.items()),
    )
    study = load_study(path)
    rows, summary = run_study(study, workers=2, progress=False)
    assert summary["failed"] == 0 and len(rows) == 64
    assert {r["worker"] for r in rows} != {"local"}  # ran on the cluster's workers

    spec = load_structure(DATA / "paper_example" / "structure.toml")
    base = build(spec, progress=False)
    traces = {w.name: t for w, t in zip(spec.walls, base.traces)}

    def volume(wall: str, key: str, value: float) -> float:
        walls = tuple(replace(w, **{key: value}) if w.name == wall else w for w in spec.walls)
        with warnings.catch_warnings():
            warnings.filterwarnings("ignore", "footprint does not close")  # a wider wall opens the corner
            result = build(spec.with_walls(walls), traces=traces, progress=False)
        return sum(b.volume for b in result.structure.bricks)

    var = 0.0
    for w in spec.walls:
        for key, s in sigma.items():
            x = getattr(w, key)
            h = 1e-3 * x
            var += ((volume(w.name, key, x + h) - volume(w.name, key, x - h)) / (2 * h) * s) ** 2
    estimate = math.sqrt(var)
    sampled = summary["outputs"]["total_volume_m3"]["std"]
    assert sampled == pytest.approx(estimate, rel=0.15), (sampled, estimate)


@pytest.mark.slow
def test_yaw_sweep_reports_width_height_and_dice_errors_per_yaw(tmp_path):
    scenario = _study(
        tmp_path,
        scenario_text([(4.0, 3.0, 0)], seed=11, closed=False),
        "scenario.toml",
    )
    path = _study(
        tmp_path,
        f'[study]\nname = "yaw"\nscenario = "{scenario}"\n[sweep]\n"photos.yaw_deg" = [0, 25]\n',
    )
    study = load_study(path)
    rows, summary = run_study(study, workers=0, progress=False)
    assert [r["photos.yaw_deg"] for r in rows] == [0.0, 25.0]
    assert all(r["status"] == "ok" for r in rows), [r["error"] for r in rows]
    table = summary["sweep"]["photos.yaw_deg"]
    assert [t["value"] for t in table] == [0.0, 25.0]
    for t in table:
        # the errors compare reports: a fitted W and H within 2 % of the truth, bricks found again
        assert t["max_abs_width_error_m"] < 0.02 * 4.0 and t["max_abs_height_error_m"] < 0.02 * 3.0
        assert 0.9 < t["dice_mean"] <= 1.0
    assert rows[0]["w0.width_error_m"] != rows[1]["w0.width_error_m"]  # each yaw was photographed anew


_WRITE_EVENTS = {"os.mkdir", "os.rename", "os.replace", "os.remove", "os.rmdir", "shutil.rmtree", "shutil.move"}
_WRITE_EVENTS |= {"tempfile.mkdtemp", "tempfile.mkstemp", "os.truncate", "os.link", "os.symlink"}


@pytest.mark.parametrize("photos", [False, True])
def test_a_sweep_sample_writes_no_file(tmp_path, photos):
    """A synthetic sweep's sample synthesises, builds and compares in memory: no file is written,
    no folder made (a study calls it thousands of times on workers). Every write the sample asks
    of the interpreter is recorded through its audit events (PEP 578); the process's compiled-code
    cache (JAX's, kept across runs) and /dev/null are not the sample's."""
    from calib_masonry._jax import cache_dir
    from calib_masonry.study.sample import evaluate_sample

    allowed = (os.devnull, str(cache_dir()))

    scenario = _study(tmp_path, scenario_text([(3.0, 2.4, 0)], seed=11, closed=False), "scenario.toml")
    sweep = '"photos.yaw_deg" = [20]' if photos else '"synthetic.seed" = [3]'
    extra = "" if photos else "[inputs.w0]\nwidth_m = { sigma = 0.01 }\n"
    study = load_study(_study(tmp_path, f'[study]\nname = "w"\nscenario = "{scenario}"\n[sweep]\n{sweep}\n{extra}'))
    writes: list = []
    watching = [True]

    def hook(event, args):
        if not watching[0]:
            return
        if event == "open" and isinstance(args[0], (str, bytes, os.PathLike)):
            mode, flags = args[1], args[2]
            if (mode is not None and any(c in str(mode) for c in "wax+")) or (
                mode is None and isinstance(flags, int) and flags & (os.O_WRONLY | os.O_RDWR | os.O_CREAT)
            ):
                writes.append(("open", str(args[0]), mode))
        elif event in _WRITE_EVENTS:
            writes.append((event, str(args[0]) if args else ""))

    sys.addaudithook(hook)  # a hook cannot be removed: it stops watching at the end
    try:
        outputs, job = evaluate_sample(study, samples(study)[0])
    finally:
        watching[0] = False
    assert job is None and outputs["recall"] == 1.0
    writes = [w for w in writes if not w[1].startswith(allowed)]
    assert writes == [], writes


def _fragility_study(tmp_path: Path) -> Path:
    return _study(
        tmp_path,
        f'[study]\nname = "stylite_fragility"\nstructure = "{DATA / "stylite" / "structure.toml"}"\n'
        "[sampling]\nseed = 3\n[simulate]\npga_g = [0.05, 0.15, 0.6]\nrecords = 1\nduration_s = 1.0\n",
    )


def _rows_of(folder: Path) -> dict[int, dict]:
    out = {}
    for f in sorted((folder / "samples").glob("*.json")):
        row = json.loads(f.read_text())
        out[row["sample"]] = {k: v for k, v in row.items() if k not in BOOKKEEPING}
    return out


def test_a_study_runs_its_simulations_at_the_check_interval_it_names(tmp_path, small_structure, monkeypatch):
    # [simulate] check_interval_s: the joint model's accuracy setting, so that a fragility's median
    # can be run again at half of it (the default: the solver's own)
    import calib_masonry.simulation.run as simulation_run
    from calib_masonry.simulation.scene import SolverSettings
    from calib_masonry.study.sample import run_sample

    head = f'[study]\nname = "ci"\nstructure = "{small_structure}"\n[simulate]\npga_g = [0.1]\nbullet = false\n'
    default = load_study(_study(tmp_path, head, "a.toml"))
    half = load_study(_study(tmp_path, head + "check_interval_s = 0.0025\n", "b.toml"))
    assert default.simulate.solver == SolverSettings() and half.simulate.solver.check_interval_s == 0.0025
    assert default.fingerprint() != half.fingerprint()  # a resumed study does not mix the two
    seen = []

    def simulate(geometry, load, settings, **kw):  # a stand-in: only what the sample hands on is tested
        seen.append(settings)
        raise RuntimeError("stop here")

    monkeypatch.setattr(simulation_run, "simulate", simulate)
    row = run_sample(half, samples(half)[0])
    assert seen == [half.simulate.solver] and row["status"] != "ok"


@pytest.mark.slow
def test_a_fragility_study_without_bullet_gives_the_same_samples(tmp_path):
    # its outputs are the verdict's (the joint model and the rigid pieces it sets free), which no
    # pose of Bullet's enters: [simulate] bullet = false skips Bullet's animation and keeps them
    with_bullet = load_study(_fragility_study(tmp_path))
    without = load_study(_study(tmp_path, _fragility_study(tmp_path).read_text() + "bullet = false\n", "nob.toml"))
    assert with_bullet.simulate.bullet and not without.simulate.bullet
    a, _, _ = study_to_folder(with_bullet, tmp_path / "a", workers=0, progress=False)
    b, _, _ = study_to_folder(without, tmp_path / "b", workers=0, progress=False)
    strip = [
        sorted(({k: v for k, v in row.items() if k not in BOOKKEEPING} for row in rows), key=lambda r: r["sample"])
        for rows in (a, b)
    ]
    assert all(row["status"] == "ok" for row in strip[0]) and strip[0] == strip[1]
    assert any(row["cracked_fraction"] > 0 for row in strip[1])  # the strongest record cracks joints
    # the joints left unchecked inside freed pieces are counted apart from the cracked ones
    assert all(0.0 <= row["unchecked_fraction"] <= 1.0 - row["cracked_fraction"] + 1e-12 for row in strip[1])


@pytest.mark.slow
def test_fragility_study_resumes_after_a_kill_and_matches_a_separate_scheduler_and_worker(tmp_path):
    path = _fragility_study(tmp_path)
    out = tmp_path / "out"
    cmd = [sys.executable, "-m", "calib_masonry", "study", str(path), "--out", str(out), "--workers", "2"]
    p = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 600
    while not list((out / "samples").glob("*.json")) if out.exists() else True:
        assert p.poll() is None, p.communicate()
        assert time.monotonic() < deadline
        time.sleep(0.5)
    p.send_signal(signal.SIGTERM)
    _, err = p.communicate(timeout=60)
    assert p.returncode == 2 and "run the same command again" in err, err
    kept = _rows_of(out)
    assert 1 <= len(kept) < 3, "the study finished before it could be killed"
    kept_bytes = {f.name: f.read_bytes() for f in (out / "samples").glob("*.json")}

    r = subprocess.run(cmd, capture_output=True, text=True, timeout=900)
    assert r.returncode == 0, r.stderr
    assert f"{3 - len(kept)} run now, {len(kept)} kept from before" in r.stdout
    assert {f.name: f.read_bytes() for f in (out / "samples").glob("*.json") if f.name in kept_bytes} == kept_bytes
    local = _rows_of(out)
    assert sorted(local) == [0, 1, 2] and all(row["status"] == "ok" for row in local.values())
    summary = json.loads((out / "summary.json").read_text())
    assert [t["pga_g"] for t in summary["fragility"]["per_pga"]] == [0.05, 0.15, 0.6]
    assert (out / "samples.parquet").is_file() and (out / "figures" / "fragility.png").is_file()

    # the same study on a scheduler and a worker started as separate processes on 127.0.0.1
    port = _free_port()
    env = dict(os.environ, PYTHONHASHSEED="0", OMP_NUM_THREADS="1")
    dask = str(Path(sys.executable).with_name("dask"))
    sched = subprocess.Popen(
        [dask, "scheduler", "--host", "127.0.0.1", "--port", str(port), "--no-dashboard"],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        env=env,
    )
    worker = None
    try:
        worker = subprocess.Popen(
            [dask, "worker", f"tcp://127.0.0.1:{port}", "--nthreads", "1", "--nworkers", "1", "--no-dashboard"],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
            env=env,
            cwd=tmp_path,
        )
        time.sleep(3.0)
        rows, _ = run_study(load_study(path), scheduler=f"tcp://127.0.0.1:{port}", progress=False)
        remote = {r["sample"]: {k: v for k, v in r.items() if k not in BOOKKEEPING} for r in rows}
        assert sorted(remote) == sorted(local)
        # identical rows, simulation included: every sample's simulation runs on its worker's event
        # loop, the worker process's main thread, where Blender's runs are reproducible whatever the
        # worker or the order (on a dask worker's task thread they were not: study/sample.py)
        differ = {
            i: {
                k: (local[i].get(k), remote[i].get(k))
                for k in set(local[i]) | set(remote[i])
                if local[i].get(k) != remote[i].get(k)
            }
            for i in local
        }
        assert remote == local, differ
    finally:
        for proc in (worker, sched):
            if proc is not None:
                proc.terminate()
                proc.wait(timeout=30)


KILL_DURING_CLUSTER_START = r"""
import multiprocessing, os, signal, sys, threading, time
from calib_masonry.cli import main

def kill():
    while not multiprocessing.active_children():  # the cluster's first worker process is starting
        time.sleep(0.005)
    time.sleep(0.2)
    os.kill(os.getpid(), signal.SIGTERM)

threading.Thread(target=kill, daemon=True).start()
sys.exit(main(sys.argv[1:]))
"""


@pytest.mark.slow
@pytest.mark.parametrize("when", ["cluster start", "samples running"])
def test_sigterm_to_a_study_ends_in_one_line(tmp_path, small_structure, when):
    """SIGTERM to `study` on a LocalCluster: exit code 2 and the CLI's one line (with the progress
    line at most), whenever it comes. Before: during the cluster's start distributed's own close
    failed at exit (an AssertionError traceback), and while samples ran the workers logged
    CommClosedError tracebacks (30 lines) as the scheduler closed."""
    path = _study(
        tmp_path,
        f'[study]\nname = "s"\nstructure = "{small_structure}"\n[sampling]\nn = 400\n'
        "[inputs.w0]\nwidth_m = { sigma = 0.01 }\n",
    )
    out = tmp_path / "out"
    argv = ["study", str(path), "--out", str(out), "--workers", "2"]
    if when == "cluster start":
        p = subprocess.Popen(
            [sys.executable, "-c", KILL_DURING_CLUSTER_START, *argv], stderr=subprocess.PIPE, text=True
        )
    else:
        p = subprocess.Popen([sys.executable, "-m", "calib_masonry", *argv], stderr=subprocess.PIPE, text=True)
        deadline = time.monotonic() + 300
        while not (out.is_dir() and len(list((out / "samples").glob("*.json"))) >= 2):
            assert p.poll() is None and time.monotonic() < deadline
            time.sleep(0.1)
        p.send_signal(signal.SIGTERM)
    _, err = p.communicate(timeout=120)
    lines = err.strip().splitlines()
    assert p.returncode == 2, err
    assert "Traceback" not in err and "CommClosedError" not in err, err
    assert lines[-1].startswith("error: terminated"), err
    assert all(line.startswith("study s:") for line in lines[:-1]) and len(lines) <= 2, err


def _free_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


BAD = {
    "unknown input": ("[inputs.w0]\nwidht_m = { sigma = 0.01 }\n", "did you mean width_m"),
    "negative sigma": ("[inputs.w0]\nwidth_m = { sigma = -0.01 }\n", "cannot be negative"),
    "no such wall": ("[inputs.wall9]\nwidth_m = { sigma = 0.01 }\n", "has no wall 'wall9'"),
    "n = 0": ("[sampling]\nn = 0\n[inputs.w0]\nwidth_m = { sigma = 0.01 }\n", "n = 0: must be > 0"),
    "sobol n": ('[sampling]\nmethod = "sobol"\nn = 12\n[inputs.w0]\nwidth_m = { sigma = 0.01 }\n', "power of 2"),
    "method": ('[sampling]\nmethod = "lhc"\n[inputs.w0]\nwidth_m = { sigma = 0.01 }\n', "did you mean lhs"),
    "nothing varies": ("", "nothing varies"),
    "two laws": ("[inputs.w0]\nwidth_m = { sigma = 0.01, range = [1, 2] }\n", "exactly one of"),
    "pga units": ("[simulate]\npga_g = [300]\n", "not an earthquake"),
    "pushover without bullet": ("[simulate]\npushover = true\nbullet = false\n", "bullet = false: only for ground"),
    "bullet flag": ("[simulate]\npga_g = [0.1]\nbullet = 0\n", "bullet = 0: give true or false"),
    "material key": ("[inputs.material]\nfricton = { range = [0.5, 0.8] }\n", "did you mean friction"),
    "material range": ("[inputs.material]\nfriction = { range = [-0.5, 0.8] }\n", "friction = -0.5: must be >= 0"),
    # 0 is "not given": a normal about it drew -791 MPa for one sample in four
    "modulus not given": (
        "[inputs.material]\nmasonry_youngs_modulus_mpa = { sigma = 500 }\n",
        "masonry_youngs_modulus_mpa: the structure gives no value to vary about; add mean = ",
    ),
    "no record file": ('[simulate]\npga_g = [0.1]\naccelerograms = ["gone.AT2"]\n', "gone.AT2: file not found"),
    "records and files": ('[simulate]\npga_g = [0.1]\nrecords = 2\naccelerograms = ["a.csv"]\n', "keep one"),
    "three components": ('[simulate]\npga_g = [0.1]\naccelerograms = [["a", "b", "c"]]\n', "give a file name, or"),
    "record units": (
        '[simulate]\npga_g = [0.1]\naccelerograms = ["a.csv"]\nunits = "gal"\n',
        "units = 'gal': the units",
    ),
    "units without records": ('[simulate]\npga_g = [0.1]\nunits = "m/s2"\n', "without accelerograms"),
    "step without records": ("[simulate]\npga_g = [0.1]\ndt_s = 0.01\n", "dt_s = 0.01 without accelerograms"),
    "check interval 0": ("[simulate]\npga_g = [0.1]\ncheck_interval_s = 0\n", "check_interval_s = 0: must be > 0"),
    "check interval": ("[simulate]\npga_g = [0.1]\ncheck_interval_s = 0.5\n", "check_interval_s = 0.5: the joints'"),
    # 1e9 records listed 3e9 loads before the count was checked (killed, out of memory)
    "records": ("[simulate]\npga_g = [0.1, 0.2]\nrecords = 1e9\n", "x 1e.09 records is more than 1000000 runs"),
    "negative pga": ("[simulate]\npga_g = [-0.1]\n", "pga_g = -0.1: must be >= 0$"),
    "joint reach": (
        "[inputs.structure]\nmax_joint_m = { range = [0.05, 0.5] }\n",
        "max_joint_m: .0.5. out of range (0.005..0.3 m",
    ),
    "structure key": ("[inputs.structure]\nmax_joint = { range = [0.05, 0.08] }\n", "did you mean max_joint_m"),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_study_files_are_one_line_errors_before_any_sample(tmp_path, small_structure, case):
    body, message = BAD[case]
    path = _study(tmp_path, f'[study]\nname = "bad"\nstructure = "{small_structure}"\n' + body)
    with pytest.raises(InputError, match=message.replace("(", r"\(")):
        load_study(path)
    r = subprocess.run(
        [sys.executable, "-m", "calib_masonry", "study", str(path), "--out", str(tmp_path / "out")],
        capture_output=True,
        text=True,
    )
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and str(path) in r.stderr, r.stderr
    assert not (tmp_path / "out").exists()


def test_an_unreachable_scheduler_is_refused_before_any_sample(tmp_path, small_structure):
    path = _study(
        tmp_path,
        f'[study]\nname = "s"\nstructure = "{small_structure}"\n[inputs.w0]\nwidth_m = {{ sigma = 0.01 }}\n',
    )
    out = tmp_path / "out"
    r = subprocess.run(
        [sys.executable, "-m", "calib_masonry", "study", str(path), "--out", str(out)]
        + ["--scheduler", f"tcp://127.0.0.1:{_free_port()}"],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert r.returncode == 2 and "--scheduler" in r.stderr and r.stderr.count("\n") == 1, r.stderr
    assert not out.exists()


def test_a_study_folder_is_resumed_only_by_the_same_study(tmp_path, small_structure):
    text = f'[study]\nname = "s"\nstructure = "{small_structure}"\n[sampling]\nn = 3\n[inputs.w0]\nwidth_m = {{ sigma = 0.01 }}\n'
    out = tmp_path / "out"
    rows, summary, ran = study_to_folder(load_study(_study(tmp_path, text)), out, workers=0, progress=False)
    assert ran == 3 and summary["ok"] == 3
    assert {"samples.csv", "samples.parquet", "summary.json", "study.json", "figures"} <= {
        p.name for p in out.iterdir()
    }
    again = study_to_folder(load_study(_study(tmp_path, text)), out, workers=0, progress=False)
    assert again[2] == 0 and again[0] == rows  # nothing left to compute: the same table
    edited = load_study(_study(tmp_path, text.replace("0.01", "0.02"), "edited.toml"))
    with pytest.raises(InputError, match="different study"):
        study_to_folder(edited, out, workers=0, progress=False)
    assert study_to_folder(edited, out, workers=0, progress=False, overwrite=True)[2] == 3


def test_a_calibration_input_draws_w_and_h_jointly_with_their_reported_correlation():
    from scipy.stats import qmc

    from calib_masonry.study.design import Input

    mean, cov = np.array([5.0, 3.0]), np.array([[0.02**2, 0.8 * 0.02 * 0.01], [0.8 * 0.02 * 0.01, 0.01**2]])
    u = qmc.LatinHypercube(d=2, seed=1).random(4000)
    draws = np.array([Input("w.width_m+height_m", "calibration").value(x, (mean, cov)) for x in u])
    assert np.allclose(draws.mean(axis=0), mean, atol=1e-3)
    assert np.allclose(np.cov(draws.T), cov, rtol=0.08)


@pytest.mark.slow
def test_from_calibration_draws_a_photo_walls_size_around_its_fit(tmp_path, make_scenario):
    from calib_masonry.spec import PhotoSpec, load_structure
    from calib_masonry.synthetic.truth import synthesize_to_folder

    sc = _study(tmp_path, scenario_text([(4.0, 3.0, 0)], seed=5, closed=False), "scenario.toml")
    truth = synthesize_to_folder(
        load_structure(sc, require_sources=False), tmp_path / "data", figures=False, photos=PhotoSpec()
    )
    eye = truth["photos"][0]["eye_height_m"]
    photos = (tmp_path / "data" / "structure_photos.toml").read_text()
    photos = photos.replace("width_m = 4.0\n", "").replace("height_m = 3.0\n", f"camera_height_m = {eye}\n")
    structure = _study(tmp_path, photos, "data/photo_structure.toml")
    path = _study(
        tmp_path,
        f'[study]\nname = "cal"\nstructure = "{structure}"\n[sampling]\nn = 6\nseed = 1\n'
        "[inputs.w0]\nfrom_calibration = true\n",
    )
    rows, summary = run_study(load_study(path), workers=0, progress=False)
    assert summary["failed"] == 0, summary["failures"]
    w = np.array([r["w0.width_m"] for r in rows])
    h = np.array([r["w0.height_m"] for r in rows])
    assert len(set(w)) == 6 and np.all(np.abs(w - 4.0) < 0.1) and np.all(np.abs(h - 3.0) < 0.1)
    vols = np.array([r["total_volume_m3"] for r in rows])
    assert np.allclose(vols / (w * h), vols[0] / (w[0] * h[0]), rtol=1e-6)  # the model follows each draw


def test_a_fragility_from_few_runs_carries_a_caveat():
    """Six runs gave p5 = p95 at every PGA and a median printed without caveat; a curve from too
    few runs now says so, and one from many does not."""
    from types import SimpleNamespace

    from scipy.stats import norm

    from calib_masonry.study.analysis import MIN_FRAGILITY_RUNS, _fragility

    study = SimpleNamespace(simulate=SimpleNamespace(pushover=False), seed=1)
    few = [{"pga_g": a, "collapsed": c} for a, c in ((0.1, 0), (0.1, 0), (0.2, 1), (0.2, 0), (0.3, 1), (0.3, 1))]
    out = _fragility(study, few)
    assert out["median_g"] is not None and f"at least {MIN_FRAGILITY_RUNS} runs" in out["caveat"]
    rng = np.random.default_rng(2)
    pga = np.repeat([0.1, 0.2, 0.3, 0.4, 0.5], 40)
    many = [{"pga_g": a, "collapsed": int(rng.random() < norm.cdf(np.log(a / 0.3) / 0.4))} for a in pga]
    out = _fragility(study, many)
    assert out["median_g"] == pytest.approx(0.3, rel=0.25) and "caveat" not in out


def test_output_against_inputs_is_a_grid_of_the_inputs_that_vary(tmp_path):
    """output_vs_inputs.png was one 2640 x 308 px row of the first eight inputs, constant ones too."""
    from types import SimpleNamespace

    from PIL import Image

    from calib_masonry.study.analysis import plot_study

    rng = np.random.default_rng(0)
    names = [f"w{k}.width_m" for k in range(9)] + ["w9.thickness_m"]
    rows = []
    for _ in range(20):
        row = {n: float(rng.normal(2.0, 0.02)) for n in names[:9]}
        row.update({"w9.thickness_m": 0.18, "status": "ok", "total_volume_m3": float(rng.normal(5, 0.1))})
        rows.append(row)
    summary = {"outputs": {"total_volume_m3": {"n": 20, "mean": 5.0, "std": 0.1}}, "inputs": names, "failed": 0}
    written = plot_study(SimpleNamespace(name="s"), rows, summary, tmp_path)
    assert tmp_path / "output_vs_inputs.png" in written
    with Image.open(tmp_path / "output_vs_inputs.png") as im:
        w, h = im.size
    assert w <= 1500 and h >= 900  # nine varying inputs in three rows of at most four


def test_a_studys_perturbed_footprint_does_not_warn_each_sample(make_scenario):
    """Every perturbed sample of a geometry study warned that the footprint does not close; its gap
    is the study's output closure_error_m, so the sample builds without that warning, while a build
    of the same perturbed structure still warns."""
    import warnings
    from dataclasses import replace

    import calib_masonry as cm

    data = make_scenario([(1.6, 0.8, 0), (1.2, 0.8, 90), (1.6, 0.8, 180), (1.2, 0.8, 270)])
    spec = cm.load_structure(data / "structure.toml")
    spec = replace(spec, walls=(replace(spec.walls[0], width_m=1.62), *spec.walls[1:]))
    with pytest.warns(UserWarning, match="footprint does not close"):
        cm.build(spec)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        result = cm.build(spec, warn_closure=False)
    assert np.linalg.norm(result.structure.closure_gap_xy) == pytest.approx(0.02, rel=0.05)


def test_closing_the_cluster_shows_nothing_distributed_logs():
    # a scheduler still reporting to the client as they close logs CRITICAL "Closed comm ... while
    # trying to write" with a CommClosedError traceback (once in CI, SIGTERM while samples ran):
    # closing shows none of it, and distributed's handlers are left as they were
    import io
    import logging

    import distributed  # noqa: F401 - its logging configuration

    from calib_masonry.study.run import _close

    root = logging.getLogger("distributed")
    ours = logging.StreamHandler()  # as distributed's configuration sets up (pytest's may differ)
    root.addHandler(ours)
    handler = next(h for h in root.handlers if isinstance(h, logging.StreamHandler))
    stream, level = io.StringIO(), handler.level
    old = handler.setStream(stream)

    class Closing:
        def close(self):
            try:
                raise OSError("Comm already closed.")
            except OSError:
                logging.getLogger("distributed.scheduler").critical("Closed comm while trying to write", exc_info=True)

    try:
        _close(Closing(), Closing())
        assert stream.getvalue() == ""
        assert handler.level == level
        logging.getLogger("distributed.scheduler").critical("after the close")
        assert "after the close" in stream.getvalue()  # the check above could fail
    finally:
        handler.setStream(old)
        root.removeHandler(ours)


def test_a_study_runs_recorded_accelerograms_scaled_to_each_pga(tmp_path, small_structure):
    # [simulate] accelerograms: a CSV record and an ESM record's two component files, each scaled to
    # every PGA (as simulate --accelerogram --pga does), run for their own length; the record files
    # are part of the study's fingerprint (a resumed study with another record is refused)
    from calib_masonry.simulation.ground_motion import G
    from calib_masonry.study.sample import _recorded

    from .test_ground_motion import _esm_file

    t = np.arange(0, 1.5, 0.005)
    env = np.sin(np.pi * t / t[-1]) ** 2
    (tmp_path / "rec.csv").write_text("\n".join(f"{x:.3f},{0.2 * e * np.sin(9 * x):.6f}" for x, e in zip(t, env)))
    _esm_file(tmp_path / "E.ASC", 100.0 * env * np.sin(2 * np.pi * 2 * t))
    _esm_file(tmp_path / "N.ASC", 50.0 * env * np.sin(2 * np.pi * 3 * t), stream="HNN")
    path = _study(
        tmp_path,
        f'[study]\nname = "rec"\nstructure = "{small_structure}"\n[simulate]\npga_g = [0.05, 0.4]\n'
        'accelerograms = ["rec.csv", ["E.ASC", "N.ASC"]]\nbullet = false\n',
    )
    study = load_study(path)
    assert study.loads == (
        {"pga_g": 0.05, "record": 0},
        {"pga_g": 0.05, "record": 1},
        {"pga_g": 0.4, "record": 0},
        {"pga_g": 0.4, "record": 1},
    )
    one = _recorded(study.simulate.accelerograms[0], 0.4, direction_deg=90.0)  # a study's direction
    assert np.abs(one.displacement[:, 0]).max() < 1e-12 < np.abs(one.displacement[:, 1]).max()
    assert one.pga == pytest.approx(0.4 * G, rel=1e-9)
    both = _recorded(study.simulate.accelerograms[1], 0.4)
    assert both.pga == pytest.approx(0.4 * G, rel=1e-9) and "N.ASC" in both.source
    assert np.abs(both.displacement[:, 1]).max() > 0.1 * np.abs(both.displacement[:, 0]).max()
    rows, _, _ = study_to_folder(study, tmp_path / "out", workers=0, progress=False)
    assert [r["status"] for r in rows] == ["ok"] * 4
    assert {r["record"] for r in rows} == {0, 1}
    before = study.fingerprint()
    _esm_file(tmp_path / "N.ASC", 60.0 * env * np.sin(2 * np.pi * 3 * t), stream="HNN")
    assert load_study(path).fingerprint() != before


def test_a_study_reads_a_record_in_gal_with_its_units(tmp_path, small_structure):
    # [simulate] units: a CSV record in cm/s2 (gal) was read in g: 150 gal as 150 g, refused with
    # advice to pass --units, which a study file could not; now as simulate --units does
    from calib_masonry.simulation.ground_motion import G
    from calib_masonry.study.sample import _recorded

    t = np.arange(0, 1.5, 0.005)
    env = np.sin(np.pi * t / t[-1]) ** 2
    (tmp_path / "gal.csv").write_text("\n".join(f"{x:.3f},{150 * e * np.sin(9 * x):.6f}" for x, e in zip(t, env)))
    head = f'[study]\nname = "gal"\nstructure = "{small_structure}"\n[simulate]\npga_g = [0.2]\naccelerograms = ["gal.csv"]\n'
    with pytest.raises(InputError, match=r"gal.csv.*peak is .* g read in g.*--units cm/s2"):
        load_study(_study(tmp_path, head))
    study = load_study(_study(tmp_path, head + 'units = "cm/s2"\n'))
    assert study.simulate.record_units == "cm/s2"
    as_recorded = _recorded(study.simulate.accelerograms[0], 0.2, units=study.simulate.record_units)
    assert as_recorded.pga == pytest.approx(0.2 * G, rel=1e-9)


def test_a_study_reads_a_record_of_accelerations_alone_with_its_time_step(tmp_path, small_structure):
    # [simulate] dt_s: a record without a time column (simulate --dt); a study file had no place
    # for the step, and its record was refused as one column
    from calib_masonry.simulation.ground_motion import G
    from calib_masonry.study.sample import _recorded

    t = np.arange(0, 1.5, 0.005)
    (tmp_path / "acc.txt").write_text("\n".join(f"{np.sin(np.pi * x / t[-1]) ** 2 * np.sin(9 * x):.6f}" for x in t))
    head = f'[study]\nname = "alone"\nstructure = "{small_structure}"\n[simulate]\npga_g = [0.2]\naccelerograms = ["acc.txt"]\n'
    with pytest.raises(InputError, match=r"acc.txt: line 1: one column.*dt_s in a study's \[simulate\]"):
        load_study(_study(tmp_path, head))
    study = load_study(_study(tmp_path, head + "dt_s = 0.005\n"))
    assert study.simulate.record_dt_s == 0.005
    motion = _recorded(study.simulate.accelerograms[0], 0.2, dt=study.simulate.record_dt_s)
    assert motion.dt == 0.005 and motion.pga == pytest.approx(0.2 * G, rel=1e-9)
    with pytest.raises(InputError, match=r"\[simulate\] dt_s 5: the record's time step must lie in 0..0.05 s"):
        load_study(_study(tmp_path, head + "dt_s = 5\n"))


def test_a_study_varies_the_joint_reach_that_each_samples_model_is_built_with(tmp_path, small_structure, monkeypatch):
    # [inputs.structure] max_joint_m: the widest mortar joint two units are joined across, a modelling
    # input like the tape's; each sample's simulation geometry is computed with its draw
    import calib_masonry.simulation.run as simulation_run
    from calib_masonry.study.sample import run_sample

    text = (
        f'[study]\nname = "reach"\nstructure = "{small_structure}"\n[sampling]\nmethod = "lhs"\nn = 3\n'
        "[inputs.structure]\nmax_joint_m = { choices = [0.04, 0.06, 0.1] }\n[simulate]\npga_g = [0.1]\nbullet = false\n"
    )
    study = load_study(_study(tmp_path, text))
    seen = []

    def simulate(geometry, load, settings, **kw):  # a stand-in: only the geometry handed on is tested
        seen.append(geometry.max_gap_m)
        raise RuntimeError("stop here")

    monkeypatch.setattr(simulation_run, "simulate", simulate)
    drawn = []
    for sample in samples(study):
        drawn.append(sample.values["structure.max_joint_m"])
        assert run_sample(study, sample)["status"] != "ok"
    assert sorted(drawn) == [0.04, 0.06, 0.1] and seen == drawn

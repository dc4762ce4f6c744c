"""The library API: stages as plain functions on objects, files only at the edge."""

from __future__ import annotations

import builtins
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]


def test_public_names_resolve_and_are_documented():
    import calib_masonry as cm

    for name in cm.__all__:
        obj = getattr(cm, name)
        assert obj is not None
        if callable(obj):
            assert obj.__doc__, f"calib_masonry.{name} has no docstring"
    # the stage functions are functions, not modules, whatever was imported before
    import calib_masonry.simulation.run  # noqa: F401

    for name in (
        "calibrate_photo",
        "rectify",
        "segment",
        "trace",
        "refine",
        "build",
        "simulate",
        "compare",
        "write_build",
        "read_build",
        "write_simulation",
    ):
        assert callable(getattr(cm, name)) and not isinstance(getattr(cm, name), type(sys))


@pytest.mark.slow
def test_api_tour_runs_in_memory_and_writes_nothing(tmp_path):
    """examples/api_tour.py: photo -> calibration -> polygons -> refined polygons -> model -> simulation."""
    env = {**os.environ, "CALIB_MASONRY_CACHE": "/dev/null/no-cache"}  # not even the compilation cache
    before = set(ROOT.rglob("*"))
    r = subprocess.run(
        [sys.executable, str(ROOT / "examples" / "api_tour.py")], cwd=tmp_path, env=env, capture_output=True, text=True
    )
    assert r.returncode == 0, r.stderr[-3000:]
    assert list(tmp_path.iterdir()) == []
    created = {  # tool caches (.pytest_cache, .ruff_cache, __pycache__) aside
        p for p in set(ROOT.rglob("*")) - before if not any(x.startswith((".", "__pycache__")) for x in p.parts)
    }
    assert created == set()
    lines = dict(line.split(":", 1) for line in r.stdout.splitlines() if ":" in line)
    assert "precision 1.000, recall 1.000" in lines["build"]
    assert "nothing written" in lines["tour"]


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    """A small four-wall structure built in memory from a synthetic scenario's masks."""
    from calib_masonry import build, load_structure
    from calib_masonry.synthetic.truth import synthesize_to_folder

    from .conftest import scenario_text

    root = tmp_path_factory.mktemp("api")
    sc = root / "s.toml"
    sc.write_text(scenario_text([(1.6, 0.8, 0), (1.2, 0.8, 90), (1.6, 0.8, 180), (1.2, 0.8, 270)], seed=31))
    synthesize_to_folder(load_structure(sc, require_sources=False), root / "data", figures=False)
    return root, build(load_structure(root / "data" / "structure.toml"), progress=False)


def test_two_simulate_calls_in_one_process_agree(built):
    """The same inputs give the same run in one process, with no re-executed child: bit-identical
    poses, the scene, its order, the gravity keys and the joint model's cracks.

    History: with BLAS threaded as the process set it, the poses differed by 0.01 mm in one of four
    CI runs (a threaded BLAS rounds the joint model's sums by its thread count); since ``simulate``
    runs BLAS on one thread (f8b3d13) they were bit-identical in every run measured (2026-11-26:
    three processes of three calls each, the other core loaded). Called from a thread other than
    the main one, beside busy Python threads, Blender's runs differ (``sim_determinism.py
    --thread --churn``): ``simulate`` warns there, and this test calls it on the main thread. bpy
    is imported as the library imports it (``need_bpy``)."""
    from .conftest import need_bpy

    need_bpy()
    from calib_masonry import Material, Pushover, simulate, synthetic_motion
    from calib_masonry.simulation.loop import gravity_per_frame
    from calib_masonry.simulation.run import scene_for

    _, result = built
    motion = synthetic_motion(0.5, 2.0, seed=3, components=2)
    weak = Material(tensile_strength=2e3, shear_strength=3e3)  # a weak mortar, so that joints crack and bricks bear
    a = simulate(result.structure, motion, material=weak, progress=False)
    push = simulate(result, Pushover(rate_g_per_s=0.5, max_g=0.5), progress=False)  # something else in between
    b = simulate(result.structure, motion, material=weak, progress=False)
    assert push.curve is not None
    assert a.summary["bonds_broken"] > 0  # joints cracked: the run exercised the joint model's switches
    sa, sb = a.scene, b.scene
    assert [x.name for x in sa.bodies] == [x.name for x in sb.bodies]
    assert all(
        np.array_equal(x.vertices, y.vertices) and np.array_equal(x.location, y.location)
        for x, y in zip(sa.bodies, sb.bodies)
    )
    assert all(np.array_equal(x.location, y.location) and (x.a, x.b) == (y.a, y.b) for x, y in zip(sa.bonds, sb.bonds))
    assert np.array_equal(gravity_per_frame(sa), gravity_per_frame(sb))
    again = scene_for(result.structure, motion, material=weak)
    assert np.array_equal(gravity_per_frame(again), gravity_per_frame(sa))
    assert np.array_equal(a.output.positions, b.output.positions), np.abs(a.output.positions - b.output.positions).max()
    assert np.array_equal(a.output.quaternions, b.output.quaternions)
    assert a.summary["bonds_broken"] == b.summary["bonds_broken"]
    assert a.summary["moved_fraction_final"] == b.summary["moved_fraction_final"]


def test_simulate_async_gives_the_same_run_and_hands_the_loop_back(built, monkeypatch):
    """Awaited on an event loop (here on the main thread, as a dask worker's loop is), the
    simulation gives simulate()'s poses bit for bit, lets the loop run other work between its
    frames, and a run cancelled halfway stops there: the joint model's thread gone, the next run
    the same as the first."""
    import asyncio
    import threading

    from .conftest import need_bpy

    need_bpy()
    from calib_masonry import Material, simulate, simulate_async, synthetic_motion
    from calib_masonry.simulation import run as run_module

    _, result = built
    motion = synthetic_motion(0.5, 1.0, seed=3, components=2)
    weak = Material(tensile_strength=2e3, shear_strength=3e3)
    stepped: list[int] = []  # the frames stepped, as the run yields them
    ticks: list[int] = []  # the frames stepped when the loop ran other work
    steps = run_module._scene_steps

    def tap(gen):
        try:
            while True:
                try:
                    f = next(gen)
                except StopIteration as end:
                    return end.value
                stepped.append(f)
                yield f
        finally:
            gen.close()

    monkeypatch.setattr(run_module, "_scene_steps", lambda *a, **k: tap(steps(*a, **k)))

    async def with_ticker(cancel_at: int | None):
        async def ticker():
            while True:
                ticks.append(len(stepped))
                await asyncio.sleep(0)

        tick = asyncio.create_task(ticker())
        run = asyncio.create_task(simulate_async(result.structure, motion, material=weak, progress=False))
        try:
            if cancel_at is None:
                return await run
            while len(stepped) < cancel_at:
                await asyncio.sleep(0)
            run.cancel()
            with pytest.raises(asyncio.CancelledError):
                await run
            return None
        finally:
            tick.cancel()

    a = simulate(result.structure, motion, material=weak, progress=False)
    frames = len(a.output.time) - 1
    stepped.clear()
    b = asyncio.run(with_ticker(None))
    assert a.summary["bonds_broken"] > 0
    assert np.array_equal(a.output.positions, b.output.positions)
    assert np.array_equal(a.output.quaternions, b.output.quaternions)
    # under a ground motion, the verdict's pass (no Bullet) and then Bullet's (loop._follow)
    assert stepped == [*range(1, frames + 1)] * 2
    assert set(range(1, 2 * frames)) <= set(ticks)  # the loop ran between every two frames
    for cancel_at in (frames // 2, frames + frames // 2):  # in either pass
        stepped.clear()
        assert asyncio.run(with_ticker(cancel_at)) is None
        assert cancel_at <= len(stepped) <= cancel_at + 1  # stopped at the next frame
        assert not [t for t in threading.enumerate() if t.name.startswith("calib-masonry-joints")]
    c = asyncio.run(with_ticker(None))
    assert np.array_equal(a.output.positions, c.output.positions)


def test_the_joint_thread_frees_its_factors_itself(built, monkeypatch):
    """The joint model ahead of Bullet drops its LU factors on its own thread as it ends, once a run,
    early stop or not: scipy frees a SuperLU factor only on the thread that made it (scipy issue
    15921; dropped on the caller's, each run kept about 2 MB: experiments/sim_memory.py)."""
    import threading

    from .conftest import need_bpy

    need_bpy()
    from calib_masonry import Material, Pushover, simulate, synthetic_motion
    from calib_masonry.simulation.joints import JointModel

    released: list[str] = []
    drop = JointModel.release_factors

    def record(self) -> None:
        released.append(threading.current_thread().name)
        drop(self)

    monkeypatch.setattr(JointModel, "release_factors", record)
    _, result = built
    weak = Material(tensile_strength=2e3, shear_strength=3e3)
    r = simulate(result.structure, synthetic_motion(0.5, 1.0, seed=3, components=2), material=weak, progress=False)
    assert r.summary["bonds_broken"] > 0  # the joint model factorised
    assert released == ["calib-masonry-joints"]
    released.clear()
    push = simulate(result, Pushover(rate_g_per_s=0.5, max_g=0.5), progress=False)  # may stop early
    assert push.curve is not None
    assert released == ["calib-masonry-joints"]
    assert not [t for t in threading.enumerate() if t.name == "calib-masonry-joints"]


@pytest.mark.slow
def test_a_dask_worker_simulates_on_its_main_thread_as_this_process_does(built):
    """A coroutine task runs on its dask worker's event loop, the worker process's main thread,
    and gives this process's poses bit for bit, although this process had started Blender (its
    script folders on sys.path, which a spawned worker inherits) and the worker profiles itself."""
    from distributed import Client, LocalCluster

    from .conftest import need_bpy

    need_bpy()
    from calib_masonry import Material, simulate, synthetic_motion
    from calib_masonry.build_folder import simulation_geometry

    _, result = built
    motion = synthetic_motion(0.5, 1.0, seed=3, components=2)
    weak = Material(tensile_strength=2e3, shear_strength=3e3)
    geometry = simulation_geometry(result.structure)
    here = simulate(geometry, motion, material=weak, progress=False)
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=True, dashboard_address=None) as cluster:
        with Client(cluster) as client:
            runs = [client.submit(_simulate_on_loop, geometry, motion, weak, pure=False).result() for _ in range(2)]
    for on_main, positions in runs:
        assert on_main
        assert np.array_equal(positions, here.output.positions), np.abs(positions - here.output.positions).max()


async def _simulate_on_loop(geometry, motion, material):
    import threading

    from calib_masonry import simulate_async

    r = await simulate_async(geometry, motion, material=material, progress=False)
    return threading.current_thread() is threading.main_thread(), r.output.positions


def test_no_subprocess_in_the_library():
    # simulate() runs in the caller's process (no re-exec), and a study's simulations run in its dask
    # workers' own processes, on their event loops (their main threads): nothing in src/ starts a
    # process of its own, but the refinement's solver process, which only the command line asks
    # for (`trace --refine`: JAX loads there while the command traces), and only around a trace
    # and the build's processes (_threads.background_process: half of the mask walls' traces, the
    # simulation geometry), which again only the command line asks for (`build`, `demo`:
    # processes=True)
    src = ROOT / "src" / "calib_masonry"
    refine, threads, cli = src / "wall2d" / "refine.py", src / "_threads.py", src / "cli.py"
    allowed = {refine: {"multiprocessing"}, threads: {"subprocess", "Popen"}}
    for path in (ROOT / "src").rglob("*.py"):
        text = path.read_text()
        for word in ("subprocess", "os.exec", "os.spawn", "os.fork", "multiprocessing", "Popen"):
            assert word not in text or word in allowed.get(path, ()), (path, word)
        if path not in (refine, cli):
            assert "solver_process(" not in text, path
        if path not in (threads, src / "build_folder.py", src / "pipeline.py"):
            assert "background_process" not in text, path
    assert "solver_process(refine" in cli.read_text()
    assert "if geometry_process else background" in (src / "build_folder.py").read_text()
    assert cli.read_text().count("processes=True") == 2  # build and demo
    import inspect

    from calib_masonry import build, build_to_folder, write_build

    for fn, name in ((write_build, "geometry_process"), (build_to_folder, "processes"), (build, "trace_process")):
        assert inspect.signature(fn).parameters[name].default is False


def test_build_writes_the_simulation_geometry_without_reading_what_it_wrote(built, tmp_path, monkeypatch):
    from calib_masonry import read_build, write_build
    from calib_masonry.build_folder import geometry_for_model

    _, result = built
    out = tmp_path / "model"
    real_open = builtins.open
    read_back = []

    def watched_open(file, mode="r", *args, **kwargs):
        if "r" in mode and "+" not in mode and str(out.parent) in str(file):
            read_back.append(str(file))
        return real_open(file, mode, *args, **kwargs)

    monkeypatch.setattr(builtins, "open", watched_open)
    summary = write_build(result, out, figures=False)
    monkeypatch.undo()
    assert read_back == []
    assert summary["bricks"] == len(result.structure.bricks)
    import trimesh

    glb = trimesh.load(out / "model.glb")  # one node and geometry per brick, named by wall and label
    assert len(glb.geometry) == len(result.structure.bricks)
    assert all(name.split("_brick_")[0] in {"w0", "w1", "w2", "w3"} for name in glb.geometry)
    assert sum(g.volume for g in glb.geometry.values()) == pytest.approx(
        sum(b.volume for b in result.structure.bricks), rel=1e-6
    )
    # glTF is Y-up: the model stands along the file's Y (its height there), not lying along Z
    pts = np.vstack([b.solid.vertices for b in result.structure.bricks])
    lo, hi = glb.bounds
    assert hi[1] == pytest.approx(pts[:, 2].max()) and lo[1] == pytest.approx(pts[:, 2].min(), abs=1e-9)
    assert hi[2] == pytest.approx(-pts[:, 1].min()) and lo[0] == pytest.approx(pts[:, 0].min())
    _check_model_blend(out / "model.blend", result.structure)
    geometry, stored = geometry_for_model(out)
    assert stored  # the copy build stored matches the bricks.json it wrote, byte for byte
    again = read_build(out)
    assert [b.id for b in again.bricks] == [b.id for b in result.structure.bricks]
    assert all(
        np.array_equal(x.solid.vertices, y.solid.vertices) for x, y in zip(again.bricks, result.structure.bricks)
    )


def _check_model_blend(path, structure) -> None:
    """model.blend opens in Blender with a collection per wall and every brick where the model has it."""
    from calib_masonry.simulation.blender import require_bpy

    bpy = require_bpy()
    bpy.ops.wm.open_mainfile(filepath=str(path))
    walls = [w.name for w in structure.footprint.walls]
    per_wall = {c.name: {o.name: o for o in c.objects} for c in bpy.data.collections}
    assert sorted(per_wall) == sorted(walls)
    for b in structure.bricks:
        ob = per_wall[walls[b.wall]][f"{walls[b.wall]}_brick_{b.label:05d}"]
        v = np.array([tuple(ob.matrix_world @ x.co) for x in ob.data.vertices])
        want = b.solid.to_trimesh().vertices
        assert len(v) == len(want) and np.abs(v - want).max() < 1e-5  # float32 in Blender
    assert sum(len(c) for c in per_wall.values()) == len(structure.bricks)
    bpy.ops.wm.read_factory_settings(use_empty=True)


def test_compare_in_memory_matches_compare_of_folders(built, tmp_path):
    from calib_masonry import compare, compare_dirs, read_build, write_build

    root, result = built
    write_build(result, tmp_path / "m", figures=False, simulation_geometry=False)
    truth = read_build(root / "data" / "truth")
    a = compare(result.structure, truth)
    b = compare_dirs(tmp_path / "m", root / "data" / "truth")
    assert a["precision"] == b["precision"] == 1.0 and a["dice"] == pytest.approx(b["dice"])


def _cli(*args, cwd=None):
    return subprocess.run(
        [sys.executable, "-m", "calib_masonry", *map(str, args)], capture_output=True, text=True, cwd=cwd
    )


def test_degenerate_footprint_is_a_one_line_error(tmp_path):
    """Three copies of one wall's calibration cannot close into a ring."""
    doc = {
        "width_m": 4.0,
        "width_sigma_m": 0.02,
        "theta_from_heading_deg": 30.0,
        "covariance": {"order": ["focal_px", "yaw_rad"], "matrix": [[1.0, 0.0], [0.0, 1e-6]]},
    }
    (tmp_path / "calibration.json").write_text(json.dumps(doc))
    c = tmp_path / "calibration.json"
    r = _cli("footprint", c, c, c, "--out", tmp_path / "fp")
    assert r.returncode == 2
    assert r.stderr.count("\n") == 1 and r.stderr.startswith("error: footprint:"), r.stderr
    assert "degenerate" in r.stderr or "did not converge" in r.stderr
    assert not (tmp_path / "fp").exists()


def test_footprint_fit_returns_the_shared_fit_result():
    from calib_masonry import FitResult, FitStatus, fit_footprint

    w = np.array([4.0, 3.0, 4.0, 3.0])
    res = fit_footprint(w + [0.01, -0.02, 0.0, 0.01], 0.02, np.radians([0, 90, 180, 270]) + 0.01, np.radians(1.0))
    assert isinstance(res.fit, FitResult) and res.fit.status is FitStatus.CONVERGED
    assert res.fit.covariance.shape == (8, 8) and res.fit.residuals.size >= 8 and res.fit.steps > 0
    assert res.closure_gap_m < 1e-5
    assert np.allclose(res.width_sigma_m, res.fit.sigmas[:4])


def test_simulate_off_the_main_thread_warns(monkeypatch):
    """simulate() from a thread other than the main one warns (Blender driven so, beside busy
    Python threads, was not reproducible: experiments/sim_determinism.py --thread). Blender itself
    is not run here: its import is replaced by a stop right after the check."""
    import threading
    import warnings

    from calib_masonry.simulation import blender
    from calib_masonry.simulation.run import simulate_scene

    class Stop(Exception):
        pass

    def stop():
        raise Stop

    monkeypatch.setattr(blender, "require_bpy", stop)
    caught: list = []

    def call() -> None:
        with warnings.catch_warnings(record=True) as w:
            warnings.simplefilter("always")
            try:
                simulate_scene(None, "x", progress=False, blend_path=None)
            except Stop:
                pass
        caught.extend(w)

    t = threading.Thread(target=call)
    t.start()
    t.join()
    assert [str(w.message).split(";")[0] for w in caught] == ["simulate: called from a thread other than the main one"]
    with pytest.raises(Stop):  # and not on the main thread
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            simulate_scene(None, "x", progress=False, blend_path=None)

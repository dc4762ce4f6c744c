"""Experiment: does a process that simulates again and again keep memory from each run?

The scene of ``sim_determinism.py`` (four stretcher walls, a weak mortar, a collapse at 1.2 g for
3 s). Each mode runs in a fresh process, ``--runs`` simulations one after another, and prints the
resident memory after the first and the last run and the growth per run:

* ``ahead``: ``simulate()`` as by default, the joint model ahead of Bullet on a thread of its own;
* ``inline``: ``simulate(..., joints_ahead=False)``, the joint model before each step, on this thread;
* ``bare``: Bullet alone on the same scene (``loop.run(record=False)``: no joint model), the peer;
* ``joints``: the joint model alone, replaying the first run's poses on a thread (no Blender);
* ``dask``: ``simulate_async`` as a study runs it, coroutine tasks on one LocalCluster worker
  (its event loop, the main thread); the worker's memory.

    .venv/bin/python experiments/sim_memory.py [--runs 21] [--modes ahead,inline,bare,joints,dask]

Measured 2026-11-26 (2-core Xeon VM, nothing else running), ``--runs 21``: ahead +2.12 MB a run,
inline +0.15, bare +0.21, joints -0.07, dask +0.09. The growth was scipy's SuperLU factors made on
the joint thread and dropped on the caller's (scipy issue 15921, found with heaptrack); since the
thread drops them itself (``JointModel.release_factors``): ahead +0.28 MB a run, inline +0.14.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent


def rss_mb(pid: str = "self") -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS"):
            return int(line.split()[1]) / 1024
    raise RuntimeError("no VmRSS")


def _scene():
    sys.path.insert(0, str(HERE))
    from sim_determinism import scenario

    result, motion, weak = scenario(1.2, 3.0)
    return result.structure, motion, weak


async def _on_loop(geometry, motion, material) -> float:
    import os

    import calib_masonry as cm

    await cm.simulate_async(geometry, motion, material=material, progress=False)
    return rss_mb(str(os.getpid()))


def one_mode(mode: str, runs: int) -> None:
    import calib_masonry as cm
    from calib_masonry.build_folder import simulation_geometry
    from calib_masonry.simulation.loop import gravity_per_frame, run
    from calib_masonry.simulation.run import scene_for

    structure, motion, weak = _scene()
    sizes = []
    if mode == "dask":
        from dask.distributed import Client, LocalCluster

        geometry = simulation_geometry(structure)
        with LocalCluster(n_workers=1, threads_per_worker=1, processes=True, dashboard_address=None) as cluster:
            with Client(cluster) as client:
                for _ in range(runs):
                    sizes.append(client.submit(_on_loop, geometry, motion, weak, pure=False).result())
    elif mode == "joints":
        from concurrent.futures import ThreadPoolExecutor

        from scipy.spatial.transform import Rotation
        from threadpoolctl import threadpool_limits

        from calib_masonry.simulation.tracker import CrackTracker

        scene = scene_for(structure, motion, material=weak)
        out = run(scene, progress=False)
        q = out.quaternions
        rot = Rotation.from_quat(q.reshape(-1, 4)[:, [1, 2, 3, 0]]).as_matrix().reshape(q.shape[:2] + (3, 3))
        gravity = gravity_per_frame(scene)
        warm, fps = scene.solver.warmup_frames, scene.solver.fps

        def replay() -> None:
            t = CrackTracker(scene, out.positions[warm], rot[warm], out.plate[warm], warm / fps)
            for f in range(warm + 1, len(out.time)):
                t.step((f - 1) / fps, gravity[f], out.positions[f - 1], rot[f - 1], out.plate[f - 1])

        with ThreadPoolExecutor(1) as pool, threadpool_limits(limits=1, user_api="blas"):
            for _ in range(runs):
                pool.submit(replay).result()
                sizes.append(rss_mb())
    else:
        scene = scene_for(structure, motion, material=weak)
        for _ in range(runs):
            if mode == "bare":
                run(scene, progress=False, record=False)
            else:
                cm.simulate(structure, motion, material=weak, progress=False, joints_ahead=mode == "ahead")
            sizes.append(rss_mb())
    per_run = (sizes[-1] - sizes[0]) / max(1, len(sizes) - 1)
    print(
        f"{mode}: {sizes[0]:.0f} MB after the first run, {sizes[-1]:.0f} MB after run {runs}: {per_run:+.2f} MB a run"
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=21)
    ap.add_argument("--modes", default="ahead,inline,bare,joints,dask")
    ap.add_argument("--one", help=argparse.SUPPRESS)  # a mode, in this process (the child of main)
    a = ap.parse_args()
    if a.one:
        one_mode(a.one, a.runs)
        return
    for mode in a.modes.split(","):
        p = subprocess.run(
            [sys.executable, __file__, "--one", mode, "--runs", str(a.runs)], capture_output=True, text=True
        )
        lines = [ln for ln in p.stdout.splitlines() if ln.startswith(f"{mode}:")]
        print(lines[-1] if lines else f"{mode}: failed ({p.returncode}): {p.stderr.strip().splitlines()[-1:]}")


if __name__ == "__main__":
    main()

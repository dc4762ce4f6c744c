"""Experiment: how long does a study's simulation keep its dask worker's event loop waiting?

``simulate_async`` steps a run one frame per turn of the event loop it runs on (a dask worker's,
its main thread). This runs one sample of a study the same way, on an event loop in this
process's main thread, beside a task that notes every turn of the loop, and prints the longest
waits between two turns, the run's frames and its seconds per frame. Dask reports a worker's
loop as unresponsive after 3 s.

    .venv/bin/python experiments/loop_wait.py [--study data_synthetic/studies/stylite_fragility.toml] [--sample 4]

Measured 2026-11-26 (2-core Xeon VM), the defaults (Stylite, 0.6 g, a collapse): 336 stones,
907 joints, 88 frames, 75-79 ms a frame on average, the longest wait 0.29-0.31 s (three runs).
"""

from __future__ import annotations

import argparse
import asyncio


async def on_loop(geometry, load) -> None:
    from sim_determinism import with_loop_waits

    import calib_masonry as cm

    r, gaps = await with_loop_waits(cm.simulate_async(geometry, load, progress=False))
    print(
        f"{len(r.scene.bodies)} stones, {len(r.scene.bonds)} joints, {len(r.output.time) - 1} frames, "
        f"{r.summary['seconds']['per_frame'] * 1000:.0f} ms a frame on average, moved {r.metrics.moved_fraction[-1]:.2f}"
    )
    print("the longest waits of the loop, ms:", [round(g * 1000) for g in gaps[:5]])


def main() -> None:
    from calib_masonry.simulation.blender import require_bpy
    from calib_masonry.study.design import load_study, samples
    from calib_masonry.study.sample import evaluate_sample

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--study", default="data_synthetic/studies/stylite_fragility.toml")
    ap.add_argument("--sample", type=int, default=4)
    a = ap.parse_args()
    study = load_study(a.study)
    _, job = evaluate_sample(study, samples(study)[a.sample])
    if job is None:
        raise SystemExit(f"{a.study}: no [simulate] table")
    require_bpy()  # as a study's worker does when the study starts
    asyncio.run(on_loop(*job))


if __name__ == "__main__":
    main()

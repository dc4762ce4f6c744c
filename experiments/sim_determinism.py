"""Experiment: do two simulate() calls in one process give the same poses, and does the C heap's layout matter?

The scene of ``tests/test_api.py::test_two_simulate_calls_in_one_process_agree`` (four stretcher
walls, 1.2-1.6 x 0.8 m, seed 31; a 2 s two-component motion at 0.5 g, seed 3; a weak mortar so
that joints crack). The run labels are done in order; ``scramble`` between them allocates 200,000
blocks of 16-200 bytes with malloc and frees two thirds of them in random order, so that the heap's
free lists (where Bullet's next tree nodes come from) are in another order; ``--direct-bpy``
imports bpy before the library does (Blender's task scheduler then has a thread per core);
``--churn`` runs, beside the simulations, a thread that allocates all the time and keeps a dask
LocalCluster (threads, in this process) and JAX busy, as a pytest process or a dask worker would.
Prints each run's largest difference from the first and whether it is bit-identical.

    .venv/bin/python experiments/sim_determinism.py a b scramble c scramble d [--direct-bpy] [--churn]
        [--churn KINDS] [--thread | --bpy-thread | --dask] [--pga G] [--duration S] [--save FIRST.npy]

Measured 2026-11-26 on 873bcfd (2-core Xeon VM, another job running): runs a-d bit-identical, with
``scramble`` between them, with ``--direct-bpy`` and with ``--churn``.
Measured 2026-11-26 (second session) on a98494c: ``a --save`` in processes with PYTHONHASHSEED 1,
2, 3, and ``a b --direct-bpy`` in four processes while CI ran: all bit-identical with each other.
A collapse (``a b c --churn --pga 1.2 --duration 3``: 112 joints cracked, 54 % of bricks moved)
with the other core loaded (``yes``): bit-identical.
``--thread`` runs each simulation on a new thread, as a dask worker runs its tasks. Alone, ``a b c
--thread --pga 1.2 --duration 3``: bit-identical with the main thread's runs (and a segmentation
fault as the interpreter exits). With another thread busy beside it, it is not: ``a b --thread
--churn`` differed by 78 mm (moved 54 % against 56 %); ``--churn python`` (a thread that only
holds the GIL) differed by 13 mm; ``--churn numpy`` gave 58 % and 50 % moved (158 mm). Three
more tries (full, python and numpy churn) crashed with a segmentation fault before the runs
ended, and runs on a new thread also crash as the interpreter exits, churn or not. The same churn beside runs on the main
thread: bit-identical every time. Blender driven from a thread that is not the process's main
one, beside other Python threads, is not reproducible.
Measured 2026-11-26 (third session): ``a b c --bpy-thread --churn python --pga 1.2 --duration 3``
(bpy imported on the simulating thread, so that Blender counts it as its main one): one of four
tries differed (238 mm), and every try crashed as the interpreter exited. A throwaway patch that
emptied the scene with ``bpy.data.batch_remove`` instead of the factory reset, with ``--thread``:
one of four differed (55 mm), two crashed in the depsgraph update of ``bpy.ops``.
``--dask`` runs every simulation after the first as a coroutine task on a LocalCluster of two
worker processes (``simulate_async``, on the worker's event loop: its main thread; the workers'
profilers on). ``a b c d e f g --dask --pga 1.2 --duration 3``: all seven bit-identical with the
first, run here (14.6 s); ``a b c d e --dask --churn python ...`` with the other core loaded
(``yes``): bit-identical. That is how a study runs its simulations (``study/sample.py``).
Measured 2026-11-27: the runs now compare the joints' break and release times and the elastic
history too (``other records that differ``). On the Stylite tower (336 bricks, over the 600
unknowns where the modes come from ARPACK), ``calib-masonry simulate --pga 0.4 --seed 2 --duration
4`` run four times gave the same poses but elastic histories that differed by 1e-14 m to 1e-11 (the
first mode) from run to run, and once (an earlier session, under load) other cracks (31.2 against
33.3 % of bricks moved): scipy 1.17's ``eigsh`` draws its start vector from fresh entropy. With a
fixed start vector two runs side by side were bit-identical in every record; ``a b --pga 1.2
--duration 3`` here: bit-identical, no record differing.
"""

from __future__ import annotations

import argparse
import ctypes
import tempfile
from pathlib import Path

import numpy as np

SCENARIO = """[structure]
name = "determinism"
thickness_m = 0.18
vertices = 5

[synthetic]
layout = "stretcher"
px_per_m = 200
seed = 31
"""


def _records(output) -> dict[str, np.ndarray]:
    """A run's records besides the poses: the joints' break and release times and the elastic
    history (round-off there, such as ARPACK's random start vector gave, can move a crack)."""
    out = {"break_time_s": output.bond_break_time_s, "release_time_s": output.bond_release_time_s}
    for k, v in (output.elastic or {}).items():
        out[f"elastic_{k}"] = v
    return {k: np.asarray(v, dtype=np.float64) for k, v in out.items() if v is not None}


def scramble(seed: int) -> list[int]:
    """Allocate 200,000 small blocks and free two thirds of them in random order; the kept third is returned."""
    libc = ctypes.CDLL(None)
    libc.malloc.restype = ctypes.c_void_p
    libc.malloc.argtypes = [ctypes.c_size_t]
    libc.free.argtypes = [ctypes.c_void_p]
    rng = np.random.default_rng(seed)
    blocks = [libc.malloc(int(n)) for n in rng.integers(16, 200, 200_000)]
    for i in rng.permutation(len(blocks)):
        if i % 3:
            libc.free(blocks[i])
    return [b for i, b in enumerate(blocks) if not i % 3]


def churn(kinds: str = "numpy,dask,jax") -> None:
    """Start a daemon thread that, all the time, allocates arrays (``numpy``), submits to an
    in-process dask cluster (``dask``) and runs JAX (``jax``), or only the ``kinds`` named, or
    only holds the GIL in pure Python (``python``)."""
    import threading
    import time

    kinds = set(kinds.split(","))
    client = None
    if "dask" in kinds:
        from dask.distributed import Client, LocalCluster

        client = Client(LocalCluster(processes=False, n_workers=1, threads_per_worker=1, dashboard_address=None))
    if "jax" in kinds:
        import jax.numpy as jnp

    def run() -> None:
        rng = np.random.default_rng()
        while True:
            if "numpy" in kinds:
                _ = [np.ones(int(n)) for n in rng.integers(1, 300, 200)]
            if "python" in kinds:
                _ = sum(i * i for i in range(20000))
            if client is not None:
                try:
                    client.submit(sum, [1, 2, 3], pure=False).result()
                except RuntimeError:  # the interpreter is shutting down
                    return
            if "jax" in kinds:
                jnp.ones(100).block_until_ready()
            time.sleep(0.001)

    threading.Thread(target=run, daemon=True).start()


def _cluster():
    from dask.distributed import Client, LocalCluster

    return Client(LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None))


async def with_loop_waits(coro) -> tuple:
    """Await ``coro`` beside a task that notes every turn of the running event loop: its value and
    the waits between two turns, seconds, longest first."""
    import asyncio
    import time

    turns = [time.perf_counter()]

    async def tick() -> None:
        while True:
            turns.append(time.perf_counter())
            await asyncio.sleep(0)

    ticker = asyncio.create_task(tick())
    try:
        value = await coro
    finally:
        ticker.cancel()
    return value, np.sort(np.diff(turns))[::-1]


async def _on_loop(geometry, motion, material):
    """A dask task's simulation on its worker's event loop (which must be the main thread), and
    the longest the loop waited for it between two turns, seconds."""
    import threading

    import calib_masonry as cm

    assert threading.current_thread() is threading.main_thread()
    out, waits = await with_loop_waits(cm.simulate_async(geometry, motion, material=material, progress=False))
    return out, float(waits[0])


def scenario(pga: float, duration: float) -> tuple:
    """The runs' scene: four stretcher walls built in a temporary folder (the BuildResult), a
    two-component motion (seed 3) at ``pga`` g for ``duration`` s, and the weak mortar."""
    import calib_masonry as cm
    from calib_masonry.synthetic.truth import synthesize_to_folder

    root = Path(tempfile.mkdtemp())
    walls = [(1.6, 0.8, 0), (1.2, 0.8, 90), (1.6, 0.8, 180), (1.2, 0.8, 270)]
    text = SCENARIO + "".join(
        f'\n[[wall]]\nname = "w{i}"\nwidth_m = {w}\nheight_m = {h}\ntheta_deg = {t}\n'
        for i, (w, h, t) in enumerate(walls)
    )
    (root / "s.toml").write_text(text)
    synthesize_to_folder(cm.load_structure(root / "s.toml", require_sources=False), root / "data", figures=False)
    result = cm.build(cm.load_structure(root / "data" / "structure.toml"), progress=False)
    motion = cm.synthetic_motion(pga, duration, seed=3, components=2)
    weak = cm.Material(tensile_strength=2e3, shear_strength=3e3)
    return result, motion, weak


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("runs", nargs="+", help="run labels, and 'scramble' between them")
    ap.add_argument("--direct-bpy", action="store_true")
    ap.add_argument("--churn", nargs="?", const="numpy,dask,jax", help="kinds of churn (numpy,dask,jax,python)")
    ap.add_argument("--pga", type=float, default=0.5, help="peak ground acceleration, g (default 0.5)")
    ap.add_argument("--duration", type=float, default=2.0, help="seconds of motion (default 2)")
    ap.add_argument("--thread", action="store_true", help="each simulation on a new thread, as in a dask worker")
    ap.add_argument(
        "--bpy-thread",
        action="store_true",
        help="one thread imports bpy first (Blender's main thread then) and runs every simulation",
    )
    ap.add_argument(
        "--dask",
        action="store_true",
        help="each simulation after the first as a coroutine task on a LocalCluster of two worker processes "
        "(simulate_async: on the worker's event loop, its main thread); the first runs here",
    )
    ap.add_argument("--save", type=Path, help="write the first run's positions here (.npy), to compare processes")
    a = ap.parse_args()
    if a.direct_bpy:
        import bpy  # noqa: F401, PLC0415 - before the library's own import, on purpose
    bpy_thread = None
    if a.bpy_thread:
        from concurrent.futures import ThreadPoolExecutor

        from calib_masonry.simulation.blender import require_bpy

        bpy_thread = ThreadPoolExecutor(1)
        bpy_thread.submit(require_bpy).result()
    if a.churn:
        churn(a.churn)

    import calib_masonry as cm

    result, motion, weak = scenario(a.pga, a.duration)
    kept, runs = [], []
    client = None
    for k, label in enumerate(a.runs):
        if label == "scramble":
            kept += scramble(k)
            continue
        if a.dask and runs:
            if client is None:
                client = _cluster()
            from calib_masonry.build_folder import simulation_geometry

            geometry = simulation_geometry(result.structure)
            out, gap = client.submit(_on_loop, geometry, motion, weak, pure=False).result()
            print(f"{label}: the worker's event loop waited {gap * 1000:.0f} ms at most between two turns")
        elif bpy_thread is not None:
            out = bpy_thread.submit(cm.simulate, result.structure, motion, material=weak, progress=False).result()
        elif a.thread:
            from concurrent.futures import ThreadPoolExecutor

            with ThreadPoolExecutor(1) as pool:
                out = pool.submit(cm.simulate, result.structure, motion, material=weak, progress=False).result()
        else:
            out = cm.simulate(result.structure, motion, material=weak, progress=False)
        runs.append(
            (
                label,
                out.output.positions.copy(),
                out.summary["bonds_broken"],
                out.summary["moved_fraction_final"],
                _records(out.output),
            )
        )
    if client is not None:
        client.close()
    first = runs[0][1]
    if a.save:
        np.save(a.save, first)
    for label, pos, broken, moved, records in runs:
        other = [k for k, v in records.items() if not np.array_equal(v, runs[0][4][k], equal_nan=True)]
        print(
            f"{label}: joints broken {broken}, moved {moved:.3f}, largest difference from the first run "
            f"{np.abs(pos - first).max() * 1000:.6f} mm, bit-identical {np.array_equal(pos, first)}; "
            f"other records that differ: {', '.join(other) or 'none'}"
        )


if __name__ == "__main__":
    main()

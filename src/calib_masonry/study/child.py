"""``python -m calib_masonry.study.child``: one simulation of a study sample, in a fresh process.

Reads a pickled job ``{"geometry": SceneGeometry, "load": GroundMotion | Pushover}`` on stdin and
writes the pickled outcome on stdout (see :func:`outcome`).

Why a process of its own: here the simulation runs on a process's main thread. A dask worker runs
its tasks on threads beside its event loop, and Blender driven from a thread other than the main
one, beside busy Python threads, gave other poses from the same inputs and crashed at times
(``experiments/sim_determinism.py --thread --churn``; in a worker's own process a collapsing
sample moved 79 % of its stones on one worker and 87 % on another, 2026-11-26). On a main thread
the runs are bit-identical, whatever runs beside them. The fixed PYTHONHASHSEED of
:func:`calib_masonry.study.sample.run_child` is kept for good measure: processes with hash seeds
1, 2 and 3 gave bit-identical runs.
"""

from __future__ import annotations

import pickle
import sys

__all__ = ["outcome"]


def outcome(result) -> dict:
    """What a study keeps of a :class:`~calib_masonry.simulation.run.SimulationResult`."""
    from ..simulation.results import outcome as verdict

    m = result.metrics
    moved = float(m.moved_fraction[-1])
    out = {
        "moved_fraction": moved,
        "cracked_fraction": float(m.broken_fraction[-1]),
        "roof_drift_m": float(m.roof_drift_m[-1]),
        "max_displacement_m": float(m.max_displacement_m.max()) if len(m.max_displacement_m) else 0.0,
        "outcome": verdict(moved),
        "collapsed": int(verdict(moved) == "collapsed"),
        "collapse_time_s": m.collapse_time_s,  # None: half the bricks never moved
    }
    if result.curve is not None:
        cm = result.collapse_multiplier_g
        out["collapse_multiplier_g"] = None if cm is None else float(cm)
    return out


def _end_with_parent() -> None:
    """Exit when the process that started this one is gone (a worker killed mid-sample)."""
    import os
    import threading
    import time

    parent = os.getppid()

    def watch() -> None:
        while os.getppid() == parent:
            time.sleep(0.5)
        os._exit(3)

    threading.Thread(target=watch, daemon=True).start()


def main() -> int:
    from ..errors import CalibMasonryError
    from ..simulation.run import simulate

    _end_with_parent()

    job = pickle.loads(sys.stdin.buffer.read())
    try:
        result = simulate(job["geometry"], job["load"], progress=False)
    except CalibMasonryError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    sys.stdout.buffer.write(pickle.dumps(outcome(result)))
    sys.stdout.buffer.flush()
    return 0


if __name__ == "__main__":
    sys.exit(main())

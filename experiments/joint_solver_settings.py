"""Experiment: does the joint model's outcome depend on its own numerical settings?

In a model where every body stands on a joint (no body bears on the plate without one), the joint
model reads no pose: which joints crack and which Bullet lets go, and when, follow from the load
history alone. So this runs the CrackTracker over a quake's loads frame by frame, without Bullet,
at the default ContactSettings and at a tighter tolerance and other iteration limits, and prints,
per setting, the joints cracked and let go over time, the factorisations and the seconds, and
whether every joint's crack time, failure mode and release time equal the default's.

    .venv/bin/python experiments/joint_solver_settings.py [--model stylite|paper_example|DIR] [--pga 0.3] [--seed 0]

An earlier commit's joint model runs the same script with PYTHONPATH pointing at its src/ (the
script uses only what has not changed: CrackTracker, ContactSettings, the scene of a model folder).
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from calib_masonry.build_folder import build_to_folder
from calib_masonry.simulation.joints import ContactSettings
from calib_masonry.simulation.loop import gravity_per_frame
from calib_masonry.simulation.run import SimulationConfig, scene_for_model
from calib_masonry.simulation.tracker import CrackTracker
from calib_masonry.spec import load_structure

ROOT = Path(__file__).resolve().parents[1]
VARIANTS = {
    "default": {},
    "tol 3e-4": {"tol": 3e-4},
    "tol 1e-4": {"tol": 1e-4},
    "tol 3e-5": {"tol": 3e-5},
    "tol 1e-5": {"tol": 1e-5},
    "30 iterations": {"max_iter": 30},
    "100 iterations": {"max_iter": 100},
    "release 1 cm": {"release_m": 0.01},
    "release 5 cm": {"release_m": 0.05},
    "no stall, 400 iterations": {"max_iter": 400, "stall_iter": 400},
    "pushover's settings": {"max_iter": 400, "stall_iter": 400, "release_m": 0.05},
}


def pose_free_tracker(scene, settings: ContactSettings | None):
    """A CrackTracker for a run of ``scene`` that reads no pose (every body on a joint), with the
    bodies at rest where the scene puts them; and the run's per-frame loads and those poses,
    ``(tracker, gravity, positions, rotations, plate)``: ``tracker.step((f - 1) / fps, gravity[f],
    positions, rotations, plate)`` for each frame ``f`` after the warm-up replays the run's joints."""
    s = scene.solver
    pos = np.array([b.location for b in scene.bodies], dtype=np.float64).reshape(-1, 3)
    rot = np.broadcast_to(np.eye(3), (len(pos), 3, 3)).copy()
    plate = np.zeros(3)
    tracker = CrackTracker(scene, pos, rot, plate, s.warmup_frames / s.fps, settings=settings)
    if tracker.reads_poses:
        raise SystemExit("this model has bodies bearing on the plate without a joint: its joint model reads poses")
    return tracker, gravity_per_frame(scene), pos, rot, plate


def replay(scene, settings: ContactSettings):
    """Crack and release times of every joint over the run's loads (the tracker alone)."""
    s = scene.solver
    tracker, gravity, pos, rot, plate = pose_free_tracker(scene, settings)
    t0 = time.perf_counter()
    for f in range(s.warmup_frames + 1, scene.frames + 1):
        tracker.step((f - 1) / s.fps, gravity[f], pos, rot, plate)
    return tracker, time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--model", default="stylite", help="stylite, paper_example or a model folder")
    ap.add_argument("--pga", type=float, default=0.3)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--duration", type=float, default=10.0)
    ap.add_argument("--variants", nargs="+", default=list(VARIANTS), choices=list(VARIANTS))
    args = ap.parse_args()
    config = SimulationConfig(pga_g=args.pga, duration_s=args.duration, seed=args.seed, figures=False)
    with tempfile.TemporaryDirectory() as tmp:
        model = Path(args.model)
        if not model.is_dir():
            model = Path(tmp) / "model"
            structure = load_structure(ROOT / "data_synthetic" / args.model / "structure.toml")
            build_to_folder(structure, model, figures=False, progress=False)
        scene = scene_for_model(model, config)
    print(
        f"{args.model}: {len(scene.bodies)} bodies, {len(scene.bonds)} joints; {args.duration:g} s quake at "
        f"PGA {args.pga:g} g, seed {args.seed}; the joint model alone over the run's loads"
    )
    times = (0.5, 1.0, 1.5, 2.0, 3.0, 5.0, args.duration)
    print(
        f"{'setting':16s} {'cracked by t = ' + ', '.join(f'{t:g}' for t in times) + ' s':44s} "
        f"{'let go by the same':30s} {'factorisations':>14s} {'seconds':>8s}  same as default"
    )
    base = None
    for name in args.variants:
        tracker, seconds = replay(scene, ContactSettings(**VARIANTS[name]))
        bt, rt = tracker.break_time_s, tracker.release_time_s
        cracked = [int(np.sum(bt <= t)) for t in times]
        released = [int(np.sum(rt <= t)) for t in times]
        record = (np.nan_to_num(bt, nan=-1.0), tracker.break_mode, np.nan_to_num(rt, nan=-1.0))
        if base is None:
            base = record
        same = all(np.array_equal(a, b) for a, b in zip(record, base))
        print(
            f"{name:16s} {', '.join(map(str, cracked)):44s} {', '.join(map(str, released)):30s} "
            f"{tracker.model.factorisations:14d} {seconds:8.1f}  {'yes' if same else 'no'}"
        )


if __name__ == "__main__":
    main()

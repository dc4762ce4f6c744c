"""Experiment: is a laboratory wall's shear-test peak a converged output of the joint model?

Why: the brief judges physics by physics (an outcome must not change when the solver is made more
accurate), and the laboratory walls' predicted peaks (experiments/lab_walls.py) moved by tens of
per cent when the joints' stiffness model changed (docs/stone_walls.md). Here the joint model's
own numerical settings and the load step are varied instead, with nothing else changed.

A shear test's wall stands on a footing, so its joint model reads no pose (simulation/tracker.py):
which joints crack and which Bullet lets go, and at what load, follow from the load history
alone. This runs the CrackTracker over the shear test's loads frame by frame, without Bullet
(as experiments/joint_solver_settings.py does for a quake), and prints per setting:

- ``first release``: the lateral force (kN, the test's top force) at which the model first found
  no equilibrium and handed joints to Bullet;
- ``beam free``: the force at which no held joint ties the loading beam to the ground any more (Bullet
  then moves the beam, and the peak Bullet's poses give lies between the two);
- the joints cracked by then, the solves that did not converge, and the seconds.

The settings: the run's own (``CrackTracker.default_settings``: for a shear test a release
displacement of the verdict's run-away, 5 cm on these walls, and a contact iteration that runs on
to 400 iterations without a stall window) at the default 25 frames a second of a ramp of 0.01 of
the vertical load per second and at 2, 4 and 8 times finer load steps; other release displacements,
iteration limits and tolerances; and a ground motion's settings (release at 1 mm, a solve stopped
after 10 iterations without progress or 50 in all), which were a shear test's until 2026-11-28. The
rigid cantilever's rocking bound ``(N + W) L / (2 H0)`` is printed beside the measured Vmax.

    .venv/bin/python experiments/shear_test_convergence.py [--only WI1.175 WI3.175 SW.30.1] [--variants ...]

Measured on 2026-11-28: see docs/stone_walls.md ("Is the peak converged?"); on 2026-12-01 with the
beam's load corrected and a crack round cracking the worst joint alone ("The beam's load, and one
joint a crack round"), then with a stall window of 50 iterations ("stall 50": not converged) and
the static programme's questions limited ("Where a shear test's time goes").
"""

from __future__ import annotations

import argparse
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import lab_walls
import numpy as np
from joint_solver_settings import pose_free_tracker

from calib_masonry.simulation.joints import ContactSettings
from calib_masonry.simulation.run import SimulationConfig, scene_for_model
from calib_masonry.simulation.scene import ShearTest, SolverSettings
from calib_masonry.simulation.tracker import CrackTracker

VARIANTS = {
    # the run's own settings (CrackTracker.default_settings: a pushover's or shear test's), at the
    # default frame rate and finer ones, and with some of them replaced
    "default (25 fps)": (25, {}),
    "50 fps": (50, {}),
    "100 fps": (100, {}),
    "200 fps": (200, {}),
    "release 10 mm": (25, {"release_m": 1e-2}),
    "release 30 mm": (25, {"release_m": 3e-2}),
    "release 100 mm": (25, {"release_m": 0.1}),
    "800 iterations": (25, {"max_iter": 800, "stall_iter": 800}),
    "tol 1e-4": (25, {"tol": 1e-4}),
    "tol 1e-5": (25, {"tol": 1e-5}),
    "tol 1e-5, 100 fps": (100, {"tol": 1e-5}),
    "tol per body": (25, {"tol_per_body": True}),
    "tol per body, 50 fps": (50, {"tol_per_body": True}),
    "tol per body, 100 fps": (100, {"tol_per_body": True}),
    "tol per body, 200 fps": (200, {"tol_per_body": True}),
    "tol 1e-4 per body": (25, {"tol": 1e-4, "tol_per_body": True}),
    # a crack round cracking every joint within 10 % of the worst at once (the shear test's until
    # 2026-12-01; a ground motion's still), against the worst alone (the default since)
    "band 10 %": (25, {"crack_band": 0.1}),
    "band 10 %, 50 fps": (50, {"crack_band": 0.1}),
    "band 10 %, 100 fps": (100, {"crack_band": 0.1}),
    # a solve that stalls for 50 iterations (its out-of-balance force not halved) asks the
    # programme then, instead of running on to 400
    "stall 50": (25, {"stall_iter": 50}),
    "stall 50, 50 fps": (50, {"stall_iter": 50}),
    "stall 50, 100 fps": (100, {"stall_iter": 50}),
    # a ground motion's settings (ContactSettings' defaults): release at 1 mm, a solve stops after
    # 10 iterations without progress or 50 in all
    "quake settings": (25, "quake"),
    "quake settings, 100 fps": (100, "quake"),
}


def replay(scene, settings: ContactSettings) -> dict:
    """The tracker alone over a shear test's loads: the loads of the first release and of the beam's
    release, in g."""
    s = scene.solver
    tracker, gravity, pos, rot, plate = pose_free_tracker(scene, settings)
    beam = scene.notes["shear_test"]["beam"]
    first = free = None
    stalled = 0
    t0 = time.perf_counter()
    for f in range(s.warmup_frames + 1, scene.frames + 1):
        lam = float(np.hypot(*gravity[f, :2]) / scene.gravity)
        released = tracker.step((f - 1) / s.fps, gravity[f], pos, rot, plate)
        stalled += not tracker.model.converged
        if released.size and first is None:
            first = (lam, int((~tracker.intact).sum()))
        if not tracker.model.grounded(tracker.held)[beam]:
            free = (lam, int((~tracker.intact).sum()))
            break
    return {
        "first": first,
        "free": free,
        "stalled": stalled,
        "unanswered": tracker.model.unanswered,
        "seconds": time.perf_counter() - t0,
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", nargs="+", default=["WI1.175", "WI3.175", "SW.30.1"], help="test units")
    ap.add_argument("--variants", nargs="+", default=list(VARIANTS), choices=list(VARIANTS))
    ap.add_argument("--out", default=None, help="keep each wall's mask and model here (default: a temporary folder)")
    args = ap.parse_args()
    base = Path(args.out) if args.out else Path(tempfile.mkdtemp(prefix="shear_convergence_"))
    for test in lab_walls.tests():
        if test["unit"] not in args.only:
            continue
        model = lab_walls.build_wall(test, base / test["unit"])
        st = None
        for name in args.variants:
            fps, over = VARIANTS[name]
            config = SimulationConfig(
                shear_test=ShearTest(precompression_pa=test["applied"] * 1e6, shear_span_ratio=test["H0"] / test["L"]),
                solver=SolverSettings(fps=fps),
            )
            scene = scene_for_model(model, config)
            st = scene.notes["shear_test"]
            if name == args.variants[0]:
                bound = (st["vertical_load_kn"] + st["wall_weight_kn"]) * st["length_m"] / (2 * st["shear_span_m"])
                print(
                    f"{test['unit']}: sigma0 {test['sigma0']:.3f} MPa (on the beam {test['applied']:.3f}), measured Vmax {test['vmax']:.1f} kN, rigid "
                    f"rocking bound {bound:.1f} kN; {len(scene.bodies) - 1} stones, {len(scene.bonds)} joints",
                    flush=True,
                )
            settings = ContactSettings() if over == "quake" else replace(CrackTracker.default_settings(scene), **over)
            r = replay(scene, settings)
            kn = st["force_per_g_kn"]

            def at(x):
                return "never" if x is None else f"{x[0] * kn:6.1f} kN ({x[1]} cracked)"

            print(
                f"  {name:>28}: first release {at(r['first'])}, beam free {at(r['free'])}; "
                f"{r['stalled']} solves unconverged, {r['unanswered']} questions unanswered, {r['seconds']:.1f} s",
                flush=True,
            )


if __name__ == "__main__":
    main()

"""Benchmark: the Stylite model under a 10 s quake, our simulate call against bare Bullet stepping.

Both runs use the same scene (bodies, bonds, plate, ground motion) and solver settings in the same
process. "Ours" is the whole simulate call (scene from the model folder, warm-up, stepping with
poses read every frame, joint-crack detection, metrics, poses.npz, summary.json and the .blend;
figures are off). The scene's geometry (bodies filled out to the joints, contact patches) is stored
by `build` in the model folder, as for any model; the bench also times computing it, and prints
the ratio a call that had to compute it would have. bpy is imported before the first timed run
(a fixed cost of any Blender use, about 0.7 s, not overhead). "Bare" builds the
same Blender scene and steps it frame by frame without reading anything back, switching joints
off at the frames where our run found them cracked (a schedule fixed in advance) and setting the
bodies free with the velocities our run gave them (poses.npz ``freed_velocity``), so that Bullet
has the same constraints, contacts and motion to solve in both. Since 2026-11-29 (the twenty-third
session) ours plays the verdict's pieces on kinematic bricks and gives Bullet only the pieces that
fell (``SolverSettings.bullet_moves``), so Bullet's work is no longer the same: the bare run is
what Bullet alone does with the freed pieces (``--bullet-moves freed`` without the joint model),
the peer ours replaces. Measured: Stylite 24.5 s against 68.3 s (ratio 0.36; 77 s against 71 s
before). The
method reports about 2 minutes for this job on an i7-9700; the aim is under 1 minute on 2 cores
and an overhead ratio <= 1.15.

Each model's line "this machine" gives the speed of one factorisation of its intact tangent and the
kernels cvxopt's OpenBLAS chose (the joint model's time is mostly factorisations; since the
thirty-first session, 2026-11-30). Then, on the 2-core Xeon VM (`--repeats 1 --no-paper-example`,
nothing else running): Stylite's tangent 2.0 ms, "Prescott"; ours 22.6 s against 81.1 s bare
(ratio 0.28), the joint model 16.3 s, without Bullet 18.1 s, the same verdict. Since the
thirty-third session (2026-12-01) Bullet is stepped only from the first fall (every body is
kinematic before it): `--repeats 1`, Stylite 19.0 s against 83.3 s bare (ratio 0.229), the paper
example 160.7 s, without Bullet 164.1 s, its joint model 148.8 s (its tangent 21.8 ms that day).

Each pair is followed by the same call without Bullet (``simulate --no-bullet``: the joint model
and the verdict's rigid pieces alone, the frames showing those pieces), with whether its verdict
is the same.

    .venv/bin/python experiments/bench_simulate.py [--pga 0.3] [--duration 10] [--repeats 5]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from calib_masonry.build_folder import build_to_folder, load_model
from calib_masonry.simulation.blender import require_bpy
from calib_masonry.simulation.loop import run
from calib_masonry.simulation.results import metrics
from calib_masonry.simulation.run import SimulationConfig, scene_for_model, simulate_to_folder
from calib_masonry.simulation.scene import scene_geometry
from calib_masonry.spec import load_structure

ROOT = Path(__file__).resolve().parents[1]


def machine_line(model: Path) -> str:
    """How fast this machine factorises the model's intact tangent, and which kernels cvxopt's
    bundled OpenBLAS chose: the joint model's time is mostly those factorisations, and on a
    processor that OpenBLAS 0.3.15 does not recognise it runs its generic ones ("Prescott"), 1.3-1.9x
    slower (docs/dynamics.md, "The factorisation's BLAS"), so figures from two machines compare
    only beside this line."""
    from joint_solve_cost import factor_size  # experiments/, the script's own folder
    from threadpoolctl import threadpool_info

    n, _, gflop, ms = factor_size(model)
    arch = [i.get("architecture") for i in threadpool_info() if "cvxopt" in i.get("filepath", "")]
    return (
        f"this machine: a factorisation of the intact tangent ({n} unknowns, {gflop:.2f} GFlop) {ms:.1f} ms; "
        f"cvxopt's OpenBLAS kernels: {arch[0] if arch else 'unknown'}"
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--structure", default=str(ROOT / "data_synthetic" / "stylite" / "structure.toml"))
    ap.add_argument("--pga", type=float, default=0.3)
    ap.add_argument("--duration", type=float, default=10.0)
    ap.add_argument("--repeats", type=int, default=5, help="pairs of runs (ours, then bare) to take the median of")
    ap.add_argument(
        "--paper-example",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="also time one simulate call of the paper example's quake (aim <= 120 s)",
    )
    args = ap.parse_args()
    config = SimulationConfig(pga_g=args.pga, duration_s=args.duration, seed=0, figures=False)
    with tempfile.TemporaryDirectory() as tmp:
        model = Path(tmp) / "model"
        build_to_folder(load_structure(args.structure), model, figures=False, progress=False)
        scene = scene_for_model(model, config)
        assert scene.notes["geometry_stored"], "build did not store the simulation geometry"
        print(machine_line(model))
        t0 = time.perf_counter()
        scene_geometry(*load_model(model)[:3])  # what a call on a model without the stored geometry adds
        t_geometry = time.perf_counter() - t0
        require_bpy()
        t_ours, t_bare, step_ours, step_bare, t_joints, t_still = [], [], [], [], [], []
        still_config = replace(config, bullet=False)
        for r in range(args.repeats):  # pairs in turn: a single pair moves by 10-15 % from run to run
            t0 = time.perf_counter()
            summary = simulate_to_folder(model, Path(tmp) / f"sim{r}", config, progress=False)
            t_ours.append(time.perf_counter() - t0)
            step_ours.append(summary["seconds"]["stepping"])
            t_joints.append(summary["joints"]["seconds"])
            # the bare run lets go of the joints when ours did (a cracked joint stays held until then)
            # (and sets the bodies free with the velocities ours started them with)
            poses = np.load(Path(tmp) / f"sim{r}" / "poses.npz")
            released, started = poses["bond_release_time_s"], poses["freed_velocity"].astype(np.float64)
            t0 = time.perf_counter()
            bare = run(scene, progress=False, record=False, switch_off_s=released, freed_velocity=started)
            t_bare.append(time.perf_counter() - t0)
            step_bare.append(bare.seconds_stepping)
            # the same call without Bullet (--no-bullet): the verdict's pieces in the frames
            t0 = time.perf_counter()
            nb = simulate_to_folder(model, Path(tmp) / f"nob{r}", still_config, progress=False)
            t_still.append(time.perf_counter() - t0)
            same = all(
                nb[k] == summary[k] for k in ("outcome", "toppled_fraction", "moved_fraction_final", "bonds_broken")
            )
        t0 = time.perf_counter()
        metrics(scene, run(scene, progress=False))
        t_rec = time.perf_counter() - t0
        # the same model and seconds under gravity alone: does the quake's outcome describe the quake?
        still = scene_for_model(model, SimulationConfig(pga_g=0.0, duration_s=args.duration, figures=False))
        out0 = run(still, progress=False)
        m0 = metrics(still, out0)
        w = m0.start_frame
        d0 = np.linalg.norm(out0.positions[-1] - out0.positions[w] - (out0.plate[-1] - out0.plate[w]), axis=1)
    s = scene.solver
    print(
        f"Stylite model: {len(scene.bodies)} bricks, {len(scene.bonds)} mortar joints (one rigid constraint each), "
        f"{args.duration:g} s at PGA {args.pga:g} g; {s.fps} fps x {s.substeps} substeps x {s.iterations} iterations, "
        f"{s.warmup_s:g} s warm-up"
    )
    ratios = np.array(t_ours) / np.array(t_bare)
    print(
        f"{'bare Bullet stepping (same scene)':40s} {np.median(t_bare):8.1f} s   median of {args.repeats} "
        f"({', '.join(f'{t:.1f}' for t in t_bare)}; each replays the joint switches of our run before it, "
        f"{int(np.isfinite(released).sum())} in the last, and the velocities it set "
        f"{int(np.isfinite(started[:, 0]).sum())} bodies free with)"
    )
    print(f"{'run() + metrics, poses read every frame':40s} {t_rec:8.1f} s")
    print(f"{'  of which the joint model':40s} {np.median(t_joints):8.1f} s   median")
    print(
        f"{'our whole simulate call (no figures)':40s} {np.median(t_ours):8.1f} s   median of {args.repeats} "
        f"({', '.join(f'{t:.1f}' for t in t_ours)}; aim < 60 s; the method: ~120 s)"
    )
    print(
        f"{'our simulate call without Bullet':40s} {np.median(t_still):8.1f} s   median of {args.repeats} "
        f"({', '.join(f'{t:.1f}' for t in t_still)}; --no-bullet: the same verdict: {same}; "
        f"{np.median(t_ours) / np.median(t_still):.1f}x faster than with Bullet)"
    )
    print(
        f"overhead ratio ours / bare: median {np.median(ratios):.3f} (pairs: {', '.join(f'{x:.3f}' for x in ratios)}; "
        f"aim <= 1.15)"
    )
    print(
        f"where it goes: stepping loop ours {np.median(step_ours):.1f} s / bare {np.median(step_bare):.1f} s "
        f"(medians; ours reads poses and watches joints every frame; the collapse differs from run to run, so "
        f"Bullet's work does too); ours outside the loop (scene, Blender build, metrics, files): median "
        f"{np.median(np.array(t_ours) - np.array(step_ours)):.2f} s, bare: {np.median(np.array(t_bare) - np.array(step_bare)):.2f} s"
    )
    print(
        f"computing the scene geometry (stored by build): {t_geometry:.2f} s; a call that computed it would have a "
        f"ratio of {(np.median(t_ours) + t_geometry) / np.median(t_bare):.3f}"
    )
    print(
        f"outcome: {summary['outcome']}, moved {summary['moved_fraction_final']:.1%} of bricks, "
        f"{summary['bonds_broken_fraction']:.1%} of bonds broken, max roof drift {summary['max_roof_drift_m']:.2f} m, "
        f"collapse time {summary['collapse_time_s']}, {summary['ground_motion']['source']}"
    )
    print(
        f"gravity alone, same {args.duration:g} s: moved {m0.moved_fraction[-1]:.1%} of bricks, "
        f"{np.isfinite(m0.bond_break_time_s).mean():.1%} of bonds cracked, displacement median "
        f"{np.median(d0) * 1000:.1f} mm, max {d0.max() * 1000:.1f} mm"
    )
    if args.paper_example:
        with tempfile.TemporaryDirectory() as tmp:
            model = Path(tmp) / "model"
            build_to_folder(
                load_structure(ROOT / "data_synthetic" / "paper_example" / "structure.toml"),
                model,
                figures=False,
                progress=False,
            )
            print(f"paper example: {machine_line(model)}")
            t0 = time.perf_counter()
            pe = simulate_to_folder(model, Path(tmp) / "sim", config, progress=False)
            t_pe = time.perf_counter() - t0
            t0 = time.perf_counter()
            pe_nb = simulate_to_folder(model, Path(tmp) / "nob", replace(config, bullet=False), progress=False)
            t_pe_nb = time.perf_counter() - t0
        print(
            f"paper example: {pe['bricks']} bricks, {pe['bonds']} joints, {args.duration:g} s at PGA {args.pga:g} g: "
            f"our whole simulate call {t_pe:.1f} s (aim <= 120 s; joint model {pe['joints']['seconds']:.1f} s, "
            f"stepping {pe['seconds']['stepping']:.1f} s); {pe['outcome']}, moved {pe['moved_fraction_final']:.1%}, "
            f"{pe['bonds_broken_fraction']:.1%} of joints cracked"
        )
        print(
            f"paper example without Bullet (--no-bullet): {t_pe_nb:.1f} s, {pe_nb['outcome']}, moved "
            f"{pe_nb['moved_fraction_final']:.1%}, {pe_nb['bonds_broken_fraction']:.1%} of joints cracked"
        )


if __name__ == "__main__":
    main()

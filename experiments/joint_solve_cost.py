"""Experiment: where a quake's joint-model time goes, solve by solve.

Runs `simulate` of a model folder without Bullet (the verdict's pieces moved by the joint model's
thread, as `--no-bullet` does) and times every contact solve of the joint model
(`JointModel.solve`: a check's first solve and each crack round's) and every factorisation of its
tangent (`_Tangent.factor`), by wrapping both for this run only. Prints the solves, Newton steps,
factorisations and their seconds; the solves that ran away (no equilibrium); the share of the time
in the solves of each band of cracked joints; and a factorisation's size and speed (unknowns,
entries of the factor, GFlop, milliseconds) on the intact tangent of the model. `--stop-after S`
ends the run once S seconds have gone into solves with cracked joints (a large tower's cascade
runs for hours).

    .venv/bin/python experiments/joint_solve_cost.py MODEL_DIR [--pga 0.3] [--duration 10] [--seed 0] [--stop-after S]

Measured 2026-11-30 (docs/dynamics.md, "The contact iteration's cost, measured again"): the paper
example, 10 s at 0.3 g: 2,284 solves, 13,768 steps, 14,829 factorisations in 89 s of the joint
model's 166 s; a factorisation of its 9,522 unknowns 13-15 ms. The scale tower (four 8 x 20 m
walls, 49,140 unknowns), 1 s at 0.3 g with `--stop-after 600`: 340 solves with cracked joints,
2,468 factorisations of 0.19 s.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from calib_masonry.simulation import joints as J
from calib_masonry.simulation.run import SimulationConfig, scene_for_model, simulate_to_folder


class _Enough(Exception):
    """--stop-after reached."""


def factor_size(model_dir: Path) -> tuple[int, int, float, float]:
    """Unknowns, entries of the Cholesky factor, GFlop and milliseconds of one factorisation of the
    model's intact tangent (every joint intact, the weak springs)."""
    from cvxopt import cholmod

    scene = scene_for_model(model_dir, SimulationConfig(pga_g=0.0, duration_s=1.0, figures=False))
    m = J.JointModel(scene)
    tan = J._Tangent(m.dofs, 6 * m.nb)
    intact = np.zeros(m.n_all, dtype=bool)
    intact[: m.nj] = True
    values = tan.values(np.flatnonzero(intact), m.Kj[intact][:, tan.ROW, tan.COL], m._reg.diagonal())
    tan.factor(values)
    t0 = time.perf_counter()
    for _ in range(5):
        tan.factor(values)
    ms = (time.perf_counter() - t0) / 5 * 1e3
    L = cholmod.getfactor(tan._symbolic)
    per_column = np.bincount(np.array(L.J).ravel(), minlength=tan.n).astype(np.float64)
    return tan.n, len(L), float((per_column**2).sum() / 1e9), ms


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("model", type=Path, help="a folder `calib-masonry build` wrote")
    ap.add_argument("--pga", type=float, default=0.3)
    ap.add_argument("--duration", type=float, default=10.0)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--stop-after", type=float, default=None, help="seconds of solves with cracked joints")
    args = ap.parse_args()

    n, nnz, gflop, ms = factor_size(args.model)
    print(
        f"factorisation of the intact tangent: {n} unknowns, {nnz} entries in the factor, {gflop:.2f} GFlop, {ms:.1f} ms"
    )

    solve, factor = J.JointModel.solve, J._Tangent.factor
    fac = {"n": 0, "s": 0.0}
    rows: list[tuple[int, int, int, float, float, bool]] = []  # cracked, steps, factorisations, s in them, s, converged

    def timed_factor(self, values):
        t0 = time.perf_counter()
        try:
            return factor(self, values)
        finally:
            fac["n"] += 1
            fac["s"] += time.perf_counter() - t0

    def timed_solve(self, g, intact, *a, **k):
        n0, s0, t0 = fac["n"], fac["s"], time.perf_counter()
        out = solve(self, g, intact, *a, **k)
        cracked = int(np.sum(~np.asarray(intact, dtype=bool)[: self.nj]))
        rows.append(
            (cracked, self.newton_iterations, fac["n"] - n0, fac["s"] - s0, time.perf_counter() - t0, self.converged)
        )
        if args.stop_after is not None and sum(r[4] for r in rows if r[0]) > args.stop_after:
            raise _Enough
        return out

    J.JointModel.solve, J._Tangent.factor = timed_solve, timed_factor
    config = SimulationConfig(pga_g=args.pga, duration_s=args.duration, seed=args.seed, figures=False, bullet=False)
    t0 = time.perf_counter()
    stopped = False
    try:
        with tempfile.TemporaryDirectory() as tmp:
            s = simulate_to_folder(args.model, Path(tmp) / "sim", config, progress=False)
        print(
            f"simulate without Bullet: {time.perf_counter() - t0:.1f} s, the joint model {s['joints']['seconds']:.1f} s"
        )
    except _Enough:
        stopped = True
        print(f"stopped after {time.perf_counter() - t0:.1f} s (--stop-after {args.stop_after:g})")
    finally:
        J.JointModel.solve, J._Tangent.factor = solve, factor
    if not rows:
        return
    a = np.array([r[:5] for r in rows], dtype=np.float64)
    ok = np.array([r[5] for r in rows])
    cracked, steps, nf, sf, st = a.T
    print(
        f"solves {len(a)}, Newton steps {steps.sum():.0f}, factorisations {nf.sum():.0f} in {sf.sum():.1f} s, "
        f"all solves {st.sum():.1f} s" + (" (the last one stopped)" if stopped else "")
    )
    print(
        f"ran away (no equilibrium): {(~ok).sum()} solves, {st[~ok].sum():.1f} s, {steps[~ok].mean() if (~ok).any() else 0:.1f} steps each"
    )
    edges = np.unique(np.quantile(cracked, [0.0, 0.25, 0.5, 0.75, 1.0]))
    print("cracked joints     solves  steps/solve  seconds")
    for lo, hi in zip(edges[:-1], edges[1:]):
        sel = (cracked >= lo) & ((cracked < hi) | (hi == edges[-1]))
        if sel.any():
            print(f"{lo:7.0f}-{hi:<7.0f} {sel.sum():9d} {steps[sel].mean():12.1f} {st[sel].sum():8.1f}")


if __name__ == "__main__":
    main()

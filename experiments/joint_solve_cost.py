"""Experiment: where a quake's joint-model time goes, solve by solve.

Runs `simulate` of a model folder without Bullet (the verdict's pieces moved by the joint model's
thread, as `--no-bullet` does) and times every contact solve of the joint model
(`JointModel.solve`: a check's first solve and each crack round's) and every factorisation of its
tangent (`_Tangent.factor`), by wrapping both for this run only. Prints the solves, Newton steps,
factorisations and their seconds; the solves that ran away (no equilibrium); the share of the time
in the solves of each band of cracked joints; and a factorisation's size and speed (unknowns,
entries of the factor, GFlop, milliseconds) on the intact tangent of the model. `--stop-after S`
ends the run once S seconds have gone into solves with cracked joints (a large tower's cascade
runs for hours). `--contact-state` also records, in every solve with cracked joints, each
iterate's contact state (each corner touching or not, sliding at its Coulomb limit or not) and
prints how many of the Newton steps came before that state stopped changing.

    .venv/bin/python experiments/joint_solve_cost.py MODEL_DIR [--pga 0.3] [--duration 10] [--seed 0] [--stop-after S] [--contact-state]

Measured 2026-11-30 (docs/dynamics.md, "The contact iteration's cost, measured again"): the paper
example, 10 s at 0.3 g: 2,284 solves, 13,768 steps, 14,829 factorisations in 89 s of the joint
model's 166 s; a factorisation of its 9,522 unknowns 13-15 ms. The scale tower (four 8 x 20 m
walls, 49,140 unknowns), 1 s at 0.3 g with `--stop-after 600`: 340 solves with cracked joints,
2,468 factorisations of 0.19 s. Where a cascade's steps go (`--duration 2.5 --contact-state` on the
paper example, 2026-11-30, twenty-seventh session): the same 724 solves and 8,057 factorised steps
as without the recording, 5,275 of them before the contacts' state settled.
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
    ap.add_argument("--contact-state", action="store_true", help="count the steps before the contacts' state settles")
    args = ap.parse_args()

    n, nnz, gflop, ms = factor_size(args.model)
    print(
        f"factorisation of the intact tangent: {n} unknowns, {nnz} entries in the factor, {gflop:.2f} GFlop, {ms:.1f} ms"
    )

    solve, factor = J.JointModel.solve, J._Tangent.factor
    residual, newton_step = J.JointModel._residual, J.JointModel._newton_step
    fac = {"n": 0, "s": 0.0}
    trail: list = []  # this solve's force evaluations (the contact state there) and steps, in order
    states: list[
        tuple[int, int, int]
    ] = []  # per solve with cracked joints: steps, evaluations, steps before it settled

    def observed_residual(self, K0, P, jc, kc, U, rhs):
        out = residual(self, K0, P, jc, kc, U, rhs)
        gap = out[1][0]
        F, _ = self._contact_forces(jc, kc, gap)
        limit = self.material.friction * -F[:, 2]
        sliding = (np.hypot(F[:, 0], F[:, 1]) >= (1.0 - self.settings.slip_band) * limit) & (limit > 0)
        trail.append(("state", gap[:, 2] < 0.0, sliding))
        return out

    def observed_step(self, *a, **k):
        trail.append(("step",))
        return newton_step(self, *a, **k)

    def settled(events: list) -> tuple[int, int, int]:
        steps = [i for i, e in enumerate(events) if e[0] == "step"]
        evaluations = len(events) - len(steps)
        # the state each step started from, and the last one
        at = [events[i - 1] for i in steps if i > 0 and events[i - 1][0] == "state"] + [events[-1]]
        changes = [int((a[1] != b[1]).sum() + (a[2] != b[2]).sum()) for a, b in zip(at[:-1], at[1:])]
        before = next((i for i in range(len(changes)) if not any(changes[i:])), len(changes))
        return len(steps), evaluations, before

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
        trail.clear()
        out = solve(self, g, intact, *a, **k)
        cracked = int(np.sum(~np.asarray(intact, dtype=bool)[: self.nj]))
        if args.contact_state and cracked and any(e[0] == "state" for e in trail):
            states.append(settled(trail))
        rows.append(
            (cracked, self.newton_iterations, fac["n"] - n0, fac["s"] - s0, time.perf_counter() - t0, self.converged)
        )
        if args.stop_after is not None and sum(r[4] for r in rows if r[0]) > args.stop_after:
            raise _Enough
        return out

    J.JointModel.solve, J._Tangent.factor = timed_solve, timed_factor
    if args.contact_state:
        J.JointModel._residual, J.JointModel._newton_step = observed_residual, observed_step
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
        J.JointModel._residual, J.JointModel._newton_step = residual, newton_step
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
    if states:
        c = np.array(states, dtype=np.float64)
        print(
            f"contact state, {len(c)} solves with cracked joints and contacts: {c[:, 0].sum():.0f} steps "
            f"({c[:, 1].sum():.0f} force evaluations), {c[:, 2].sum():.0f} of them before the state settled"
        )


if __name__ == "__main__":
    main()

"""Experiment: would the contact iteration's Newton steps be cheaper by conjugate gradients on the last factor?

The joint model factorises its tangent at every Newton step of a contact solve (CHOLMOD, 13.8 ms
on the paper example's 9,522 unknowns). This runs `simulate` of a model folder without Bullet and,
before each factorisation, solves the same step again by conjugate gradients preconditioned with
the factor still held (the step before's), to relative residuals of 1e-2, 1e-4 and 1e-8 (at most
`--max-iter` iterations each), then factorises as the code does: the run's own path is unchanged.
Prints, per tolerance, the share of steps within 3, 5, 8, 12 and 20 iterations, and the times of a
factorisation, a solve with the factor and a product with the matrix.

    .venv/bin/python experiments/cg_on_last_factor.py MODEL_DIR [--pga 0.3] [--duration 3]

Measured 2026-12-05 (docs/dynamics.md, "The Newton step by conjugate gradients on the last factor"):
the paper example, 3 s at 0.3 g, 10,020 steps with a factor before them: at 1e-2 54.0 % within 5
iterations, 74.5 % within 12, 6.1 % not within 60; a factorisation 13.8 ms, a solve 0.72 ms, a
product 0.32 ms: about a third of the factorisations' time to gain, not the aim of 120 s.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from calib_masonry.simulation import joints as J
from calib_masonry.simulation.run import SimulationConfig, simulate_to_folder

TOLERANCES = (1e-2, 1e-4, 1e-8)


def preconditioned_cg(tan, values: np.ndarray, b: np.ndarray, tol: float, max_iter: int, clock: dict):
    """``A x = b`` for the matrix of ``values`` by conjugate gradients preconditioned with ``tan``'s
    factor as it stands; returns the iterations to ``|r| <= tol |b|`` (None: not within ``max_iter``)."""
    x, r = np.zeros_like(b), b.copy()
    t = time.perf_counter()
    z = tan.solve_factored(r)
    clock["solve"].append(time.perf_counter() - t)
    p, rz, nb = z.copy(), r @ z, np.linalg.norm(b)
    for k in range(1, max_iter + 1):
        t = time.perf_counter()
        Ap = tan.matvec(values, p)
        clock["matvec"].append(time.perf_counter() - t)
        a = rz / (p @ Ap)
        x += a * p
        r -= a * Ap
        if np.linalg.norm(r) <= tol * nb:
            return k
        t = time.perf_counter()
        z = tan.solve_factored(r)
        clock["solve"].append(time.perf_counter() - t)
        rz_new = r @ z
        p, rz = z + (rz_new / rz) * p, rz_new
    return None


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("model", type=Path, help="a folder `calib-masonry build` wrote")
    ap.add_argument("--pga", type=float, default=0.3)
    ap.add_argument("--duration", type=float, default=3.0)
    ap.add_argument("--max-iter", type=int, default=60)
    args = ap.parse_args()

    iterations: list[list[float]] = []
    clock: dict[str, list[float]] = {"factor": [], "solve": [], "matvec": []}
    factor = J._Tangent.factor
    factored: set[int] = set()

    def solve(self, values, b):
        if id(self) in factored:
            its = [preconditioned_cg(self, values, b, tol, args.max_iter, clock) for tol in TOLERANCES]
            iterations.append([np.nan if k is None else k for k in its])
        t = time.perf_counter()
        factor(self, values)
        clock["factor"].append(time.perf_counter() - t)
        factored.add(id(self))
        return self.solve_factored(b)

    J._Tangent.solve = solve
    config = SimulationConfig(pga_g=args.pga, duration_s=args.duration, figures=False, bullet=False)
    with tempfile.TemporaryDirectory() as tmp:
        summary = simulate_to_folder(args.model, Path(tmp) / "run", config, progress=False)
    print(f"{summary['outcome']}, {summary['bonds_broken_fraction']:.1%} of the joints cracked")
    k = np.array(iterations, dtype=np.float64).reshape(-1, len(TOLERANCES))
    print(f"{len(k)} Newton steps with a factor before them")
    for j, tol in enumerate(TOLERANCES):
        within = ", ".join(f"{lim}: {np.mean(k[:, j] <= lim):.1%}" for lim in (3, 5, 8, 12, 20))
        print(
            f"relative residual {tol:g}: within {within}; not within {args.max_iter}: {np.isnan(k[:, j]).mean():.1%}; "
            f"median {np.nanmedian(k[:, j]):.0f}"
        )
    ms = {name: 1e3 * float(np.mean(v)) if v else float("nan") for name, v in clock.items()}
    print(
        f"a factorisation {ms['factor']:.2f} ms, a solve with the factor {ms['solve']:.2f} ms, "
        f"a product with the matrix {ms['matvec']:.2f} ms"
    )


if __name__ == "__main__":
    main()

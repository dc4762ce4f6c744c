"""The joint model alone against rigid-block limit analysis, on dry-stacked block assemblies.

Why: in a run, Bullet holds every cracked joint until the joint model has no equilibrium with it
(simulation/joints.py), so a structure's collapse load is the joint model's. This script takes
Bullet out: it ramps a uniform lateral acceleration in 0.005 g steps through the joint model alone
(every interface a joint of zero tensile strength and cohesion, friction mu; cracked joints as
frictional no-tension contacts at their corners) and reports the first load at which the model has
no equilibrium left (a joint corner moving over 1 mm, what makes a run let the joint go, or a solve
that does not reach its tolerance). Next to it, the limit-analysis load of the same blocks from the
static linear programme of the tests (associative friction).

With Coulomb (non-associative) friction the real collapse load is at most the programme's; where
the mechanism rocks it should be close to it. Measured on the 2026-11-24 code: within 6 % below to
2 % above the programme at mu 0.6 (the test's 12 x 3 panel 0.395 against 0.420 g; the same with the
quasi-Newton solve of 2026-11-25), and a side by side pair and the mu 5 panels well below it
(0.42-0.48 of it with that solve): where a mechanism needs the friction of a head joint
that carries no compression at rest (stiff blocks side by side have no normal force until they
lean on each other), the elastic path finds the weaker branch of the non-associative problem, or
the Newton iteration stalls on those untouched corners.

2026-11-28 (fourteenth session), the non-associative programme beside it (Gilbert et al. 2006,
tests/limit_analysis.py): at mu 0.6 the side by side pair 0.263 associative, 0.221 non-associative,
the joint model 0.205; the 12 x 3 panel 0.420 / 0.404 / 0.345 (0.395 with a pushover's contact
iteration, 400 iterations and no stall window: 0.98 of the non-associative load); the others equal
to both. At mu 5 the non-associative iteration equals the associative load everywhere (0.400 for
the pair), while the pair's rigid, non-dilatant mechanism (each block tipping about its own toe,
sliding along the head joint without opening, which builds no normal force there) collapses at
b/h = 0.2: the iteration keeps an indeterminate head-joint force the elastic path never develops,
so it is no bound, and where friction decides, not a reference either.

    .venv/bin/python experiments/joint_statics.py [--mu 0.6 5]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from calib_masonry.simulation.ground_motion import G  # noqa: E402
from calib_masonry.simulation.joints import JointModel  # noqa: E402
from calib_masonry.simulation.scene import Material, Plate, Scene  # noqa: E402
from tests.limit_analysis import limit_load  # noqa: E402
from tests.test_simulate import _block, _dry_joints, _limit_analysis, _panel  # noqa: E402

T = 0.2  # thickness, m


def dry_scene(blocks, mu: float) -> Scene:
    """The blocks ``((x0, x1), (z0, z1))`` on dry joints of friction ``mu``."""
    bodies = [
        _block((x1 - x0, T, z1 - z0), ((x0 + x1) / 2, 0.0, (z0 + z1) / 2), mu=mu) for (x0, x1), (z0, z1) in blocks
    ]
    dry = Material(tensile_strength=0.0, shear_strength=0.0, friction=mu)
    return Scene(bodies=tuple(bodies), bonds=tuple(_dry_joints(blocks, T)), plate=Plate(), material=dry)


def model_collapse(blocks, mu: float, top: float = 1.5, step: float = 0.005) -> float | None:
    """The first lateral load (g) at which the joint model has no equilibrium, or None up to ``top``."""
    jm = JointModel(dry_scene(blocks, mu))
    intact = np.ones(jm.nj, bool)
    for lam in np.arange(0.0, top + step / 2, step):
        new, _, state = jm.crack(np.array([lam * G, 0.0, -G]), intact)
        intact[new] = False
        if not jm.converged or jm.corner_motion().max() > 1e-3:
            return float(lam)
    return None


CASES = {
    "one block 0.2 x 1.0": [((0, 0.2), (0, 1.0))],
    "two blocks stacked": [((0, 0.2), (0, 0.5)), ((0, 0.2), (0.5, 1.0))],
    "two blocks side by side": [((0, 0.2), (0, 1.0)), ((0.2, 0.4), (0, 1.0))],
    "running bond 2 x 2": _panel(2, 2, 0.3, 0.15, T),
    "running bond 4 x 3": _panel(4, 3, 0.3, 0.15, T),
    "running bond 12 x 3 (the test's panel)": _panel(12, 3, 0.3, 0.15, T),
}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--mu", type=float, nargs="+", default=[0.6, 5.0])
    args = ap.parse_args()
    print(
        f"{'assembly':40s} {'mu':>4s} {'LP assoc. g':>12s} {'LP non-assoc. g':>16s} {'joint model g':>14s} "
        f"{'ratio':>6s} {'to non-assoc.':>14s}"
    )
    for mu in args.mu:
        for name, blocks in CASES.items():
            la = _limit_analysis(blocks, T, mu)
            na = limit_load(dry_scene(blocks, mu), mu, associative=False)
            jm = model_collapse(blocks, mu)
            shown = f"{jm:14.3f}" if jm is not None else f"{'> 1.5':>14s}"
            ratio = f"{jm / la:6.2f}" if jm is not None else f"{'-':>6s}"
            to_na = f"{jm / na:14.2f}" if jm is not None and na else f"{'-':>14s}"
            print(
                f"{name:40s} {mu:4.1f} {la:12.3f} {na if na is not None else float('nan'):16.3f} {shown} {ratio} {to_na}",
                flush=True,
            )


if __name__ == "__main__":
    main()

"""The joint model alone against rigid-block limit analysis, on dry-stacked block assemblies.

Why: the dry panel's pushover test (tests/test_simulate.py, strict xfail) is not only Bullet's
friction creep. This script takes Bullet out: it ramps a uniform lateral acceleration through the
joint model of simulation/joints.py alone (every interface a joint of zero tensile strength and
cohesion, friction mu; cracked joints as contacts at their corners, as in a run where every corner
stays closed) and reports the first load at which the model has no equilibrium left (a body held
only by the weak inertia-relief springs: a joint's relative displacement over 1 cm). Next to it,
the limit-analysis load of the same blocks from the static linear programme of the tests.

A sound joint model gives at most the limit-analysis load (any equilibrium it finds is statically
admissible) and, where the mechanism is pure rocking (mu = 5), close to it.

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
from calib_masonry.simulation.scene import Bond, Material, Plate, Scene  # noqa: E402
from tests.test_simulate import _block, _limit_analysis, _panel  # noqa: E402

T = 0.2  # thickness, m


def dry_joints(blocks) -> list[Bond]:
    """A joint on every interface of ``blocks`` ((x0, x1), (z0, z1)): footings, beds and heads."""
    tol, bonds = 1e-9, []
    for i, ((x0, x1), (z0, z1)) in enumerate(blocks):
        if z0 < tol:
            bonds.append(Bond.rectangle(i, -1, ((x0 + x1) / 2, 0, 0), (0, 0, -1.0), (1.0, 0, 0), x1 - x0, T))
        for j, ((y0, y1), (w0, _)) in enumerate(blocks):
            if abs(w0 - z1) < tol and min(x1, y1) - max(x0, y0) > tol:
                lo, hi = max(x0, y0), min(x1, y1)
                bonds.append(Bond.rectangle(i, j, ((lo + hi) / 2, 0, z1), (0, 0, 1.0), (1.0, 0, 0), hi - lo, T))
            if j > i and abs(y0 - x1) < tol and abs(w0 - z0) < tol:
                bonds.append(Bond.rectangle(i, j, (x1, 0, (z0 + z1) / 2), (1.0, 0, 0), (0, 0, 1.0), z1 - z0, T))
    return bonds


def model_collapse(blocks, mu: float, top: float = 1.5, step: float = 0.005) -> float | None:
    """The first lateral load (g) at which the joint model has no equilibrium, or None up to ``top``."""
    bodies = [
        _block((x1 - x0, T, z1 - z0), ((x0 + x1) / 2, 0.0, (z0 + z1) / 2), mu=mu) for (x0, x1), (z0, z1) in blocks
    ]
    dry = Material(tensile_strength=0.0, shear_strength=0.0, friction=mu)
    jm = JointModel(Scene(bodies=tuple(bodies), bonds=tuple(dry_joints(blocks)), plate=Plate(), material=dry))
    intact = np.ones(jm.nj, bool)
    for lam in np.arange(0.0, top + step / 2, step):
        new, _, state = jm.crack(np.array([lam * G, 0.0, -G]), intact)
        intact[new] = False
        if np.abs(state.relative[:, :3]).max() > 1e-2:
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
    print(f"{'assembly':40s} {'mu':>4s} {'limit analysis g':>17s} {'joint model g':>14s} {'ratio':>6s}")
    for mu in args.mu:
        for name, blocks in CASES.items():
            la = _limit_analysis(blocks, T, mu)
            jm = model_collapse(blocks, mu)
            shown = f"{jm:14.3f}" if jm is not None else f"{'> 1.5':>14s}"
            ratio = f"{jm / la:6.2f}" if jm is not None else f"{'-':>6s}"
            print(f"{name:40s} {mu:4.1f} {la:17.3f} {shown} {ratio}", flush=True)


if __name__ == "__main__":
    main()

"""Experiment: dry in-plane pushovers of walls built from real stone layouts against rigid-block
limit analysis, on walls the tests never see.

Issue 37 asks for a dry in-plane pushover within 10 % of limit analysis on a wall built from a real
stone mask; the tests check it on one mask (../shared's SWAT wall,
``pytest tests/test_stone_walls.py -k non_associative``: -8.4 % along +X, +0.8 % along -X). Here
the same check runs on the drawn stone layouts of the Stone Masonry Database's walls
(../shared/data/external/stone_masonry_db/crackmaps, turned into masks by
``experiments/lab_walls.py``'s :func:`stone_mask`): each wall built at its real L x H and thickness,
every joint dry (f_t = c = 0, mu = 0.6, granite 2650 kg/m^3), on a footing, pushed by a uniform
lateral acceleration rising at 0.01 g/s along +X (``--directions`` for others). Stones that cannot
stand even with their neighbours held (the programme says so) are left out first, as in the test.
Per wall: stones, the associative and the non-associative programme's load factor
(``tests/limit_analysis.py``: HiGHS; the non-associative one is the iteration of Gilbert, Casapulla
& Ahmed 2006), the pushover's collapse multiplier, its ratio to the non-associative load, and the
mechanism the pushover names; then the ratios' range and how many lie within 10 %.

    .venv/bin/python experiments/dry_pushover_lp.py [--only SW.30.1 WI1.100] [--directions 0,180]

Measured 2026-12-01 (thirty-fourth session): docs/stone_walls.md, "The database's walls, dry" (within 10 %
of the non-associative programme on 8 of the 10 walls that stand under both flow rules; WI2.175
at 0.10-0.23 g over nine rates and tolerances). Again after a stalled contact solve asks whether
the load has an equilibrium (thirty-fifth session, "A stalled solve is not a collapse"): 9 of the
10, WI2.175 at 0.232-0.234 g over the same nine; WI2.250 -13 % as before.
"""

from __future__ import annotations

import argparse
import math
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT / "experiments"), str(ROOT)]

from lab_walls import DB, tests, write_wall  # noqa: E402


def geometry(test: dict, folder: Path):
    """The simulation geometry of the wall drawn for ``test``, built at its real size (in this
    process; its material is this experiment's, not the row's)."""
    from tests.test_stone_walls import _structure_geometry

    write_wall(test, folder, material=False)
    return _structure_geometry(folder)


def pushover(scene) -> tuple[float | None, dict | None, dict | None]:
    """The collapse multiplier (g), the mechanism and the joint model's contact solves (how many
    ended unconverged) of a pushover scene, as ``simulate`` finds them (Bullet on, the ramp stopped
    after the collapse, one BLAS thread)."""
    from calib_masonry.simulation.run import simulate_scene

    r = simulate_scene(scene, "wall", progress=False)
    return r.curve[0], r.summary["mechanism"], r.output.contact_solves


def _g(value, stands: bool) -> str:
    if not stands:
        return "cannot stand under gravity alone"
    return "none" if value is None else f"{value:.4f} g"


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--only", nargs="*", help="test units to run (default: every wall with a drawing)")
    p.add_argument("--directions", default="0", help="push directions in degrees, comma-separated (default 0: +X)")
    p.add_argument("--rates", default="0.01", help="pushover rates in g/s, comma-separated (default 0.01)")
    p.add_argument(
        "--tols",
        default="",
        help="contact tolerances to run besides the run's own, comma-separated (e.g. 1e-4,1e-5)",
    )
    p.add_argument("--db", type=Path, default=DB)
    args = p.parse_args()

    from calib_masonry.simulation.scene import Material, Pushover, scene_from_geometry
    from calib_masonry.simulation.tracker import CrackTracker
    from tests.limit_analysis import limit_load
    from tests.test_stone_walls import _unsupported, _without

    own = CrackTracker.default_settings
    dry = Material(tensile_strength=0.0, shear_strength=0.0, friction=0.6, density=2650.0)
    rows = [t for t in tests(args.db) if "drawing" in t and (not args.only or t["unit"] in args.only)]
    tols = [None] + [float(x) for x in args.tols.split(",") if x]
    ratios = []
    with tempfile.TemporaryDirectory() as tmp:
        for t in rows:
            g = geometry(t, Path(tmp) / t["unit"])
            for deg in (float(d) for d in args.directions.split(",")):
                base = scene_from_geometry(g, duration_s=1.0, material=dry, foundation=True)
                drop = _unsupported(base)
                wall = _without(base, drop)
                d = (math.cos(math.radians(deg)), math.sin(math.radians(deg)), 0.0)
                t0 = time.perf_counter()
                # a wall that cannot stand under its weight alone has no lateral capacity, whatever
                # load factor the programme finds with a lateral load holding a leaning stone up
                stands = [
                    limit_load(wall, dry.friction, gravity_only=True, associative=a) == 0.0 for a in (True, False)
                ]
                assoc = limit_load(wall, dry.friction, d) if stands[0] else 0.0
                non = limit_load(wall, dry.friction, d, associative=False) if stands[1] else 0.0
                print(
                    f"{t['unit']:>9} {deg:5.0f} deg: {len(wall.bodies)} stones ({len(drop)} left out), "
                    f"LP associative {_g(assoc, stands[0])}, non-associative {_g(non, stands[1])} "
                    f"({time.perf_counter() - t0:.0f} s)",
                    flush=True,
                )
                for rate in (float(r) for r in args.rates.split(",")):
                    push = Pushover(rate_g_per_s=rate, max_g=1.5, direction_deg=deg)
                    scene = replace(wall, pushover=push, duration_s=push.duration_s)
                    for tol in tols:
                        # the run's own contact settings, or those with another tolerance
                        CrackTracker.default_settings = staticmethod(
                            own if tol is None else (lambda sc, tol=tol: replace(own(sc), tol=tol))
                        )
                        t0 = time.perf_counter()
                        try:
                            lam, mech, solves = pushover(scene)
                        finally:
                            CrackTracker.default_settings = staticmethod(own)
                        ratio = lam / non if lam is not None and non else float("nan")
                        if math.isfinite(ratio) and rate == 0.01 and tol is None:
                            ratios.append(ratio)
                        print(
                            f"    pushover at {rate:g} g/s, tol {tol or own(scene).tol:g}: {_g(lam, True)}, "
                            f"ratio {ratio:.3f}, mechanism {(mech or {}).get('mechanism')}, contact solves {solves} "
                            f"({time.perf_counter() - t0:.0f} s)",
                            flush=True,
                        )
    if ratios:
        within = sum(abs(r - 1) <= 0.10 for r in ratios)
        print(
            f"pushover (0.01 g/s, the run's own settings) / non-associative LP, walls that stand under "
            f"gravity: {min(ratios):.3f}-{max(ratios):.3f}, {within} of {len(ratios)} within 10 %"
        )


if __name__ == "__main__":
    main()

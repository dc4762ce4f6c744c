"""Does the simulation's outcome depend on the solver? The paper example and the Stylite tower at
the default Bullet settings, at 2x substeps, at 2x iterations and at both (and, asked for by
``--settings``, at 4x iterations and 4x both).

For each model and setting it prints
* gravity alone (``--gravity-s``, default 20 s): joints cracked, the largest brick displacement;
* a quake sweep (PGA 0.05 to 0.6 g in steps of 0.05, Kanai-Tajimi, two components, per seed):
  joints cracked, bricks set free (no joint Bullet still holds ties them to the plate: the joint
  model's decision) and bricks moved at every PGA run (the verdict's: the freed pieces moved as
  rigid bodies, simulation/pieces.py; Bullet's animation's beside it), the bricks in pieces that
  fell or overturn, and the collapse PGA (the lowest PGA whose verdict is "collapsed": under a
  ground motion, half of the bricks in pieces that fell or overturn; simulation/results.py
  ``outcome``). The sweep climbs the PGAs and stops at the first collapse: the collapse PGA is all
  a higher PGA could add.

Then the collapse PGA of every seed at every setting, and its largest change from the default.
``--settings`` also offers "2x fps" (Bullet's frame rate: the joint model checks the joints on a
grid of its own, common to all frame rates, so that wherever it reads no pose the verdict is the
same), "1/2 check interval" (that grid twice as fine: the joint model's own accuracy check), and
the joint model's contact iteration run further ("no stall, 400 iterations", "release 5 cm", both:
"pushover's contacts", the settings of a run without ground motion);
``--quasi-static`` holds the intact structure rigid under the quake instead of letting it vibrate
(simulation/dynamics.py).

``--fragility`` runs every PGA of every seed (no stop at the first collapse) and fits, per model
and setting, a lognormal fragility curve to all the verdicts (the study's maximum-likelihood fit,
``calib_masonry.study.analysis.fit_fragility``): its median (the PGA at which half of the records
collapse) and dispersion, and the median's change from the first setting, each with a 90 % band
from resampling the records (the same resample at every setting, so the change's band is that of
a paired comparison). Near a rocking tower's overturning threshold one record's first collapse
on a PGA grid flips with a thousandth of the record's scale (docs/dynamics.md, "The fall that was
not one"); the median over records is the quantity that can converge.

    .venv/bin/python experiments/sim_convergence.py                      # everything (hours on 2 cores)
    .venv/bin/python experiments/sim_convergence.py --models paper_example --seeds 0 --pga 0.2 0.3 0.4
    .venv/bin/python experiments/sim_convergence.py --models stylite --settings default "2x fps" \
        "1/2 check interval" --without-bullet --gravity-s 0   # frame rate and checks, without Bullet
    .venv/bin/python experiments/sim_convergence.py --models stylite --settings default \
        "1/2 check interval" --without-bullet --gravity-s 0 --fragility --seeds 0 1 2 3 4 5 6 7 8 9 \
        --pga 0.4 0.5 0.6 0.7 0.8 0.9 1.0 1.1 1.2 1.3 1.4   # the median collapse PGA over ten records
    .venv/bin/python experiments/sim_convergence.py --fragility --logs A.txt B.txt   # from runs printed
        # by processes of their own (one setting each, on two cores): their sweep lines, refitted

Each model is built into a temporary folder from data_synthetic/<model>/structure.toml, or from
any structure file given by its path (``--models path/to/structure.toml``: a structure never used
in tuning).
"""

from __future__ import annotations

import argparse
import re
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

from calib_masonry.build_folder import build_to_folder  # noqa: E402
from calib_masonry.simulation.joints import ContactSettings  # noqa: E402
from calib_masonry.simulation.loop import run  # noqa: E402
from calib_masonry.simulation.results import metrics  # noqa: E402
from calib_masonry.simulation.run import SimulationConfig, scene_for_model  # noqa: E402
from calib_masonry.simulation.scene import SolverSettings, grounded_bodies  # noqa: E402
from calib_masonry.simulation.tracker import CrackTracker  # noqa: E402
from calib_masonry.spec import load_structure  # noqa: E402

_DEFAULT_CONTACTS = CrackTracker.default_settings

DEFAULT = SolverSettings()
SETTINGS = {
    "default": DEFAULT,
    "2x substeps": replace(DEFAULT, substeps=2 * DEFAULT.substeps),
    "2x iterations": replace(DEFAULT, iterations=2 * DEFAULT.iterations),
    "2x both": replace(DEFAULT, substeps=2 * DEFAULT.substeps, iterations=2 * DEFAULT.iterations),
    # finer still, asked for by name (--settings): does the outcome settle beyond a doubling?
    "2x fps": replace(DEFAULT, fps=2 * DEFAULT.fps),
    # the joint model's checks of the joints twice as often (scene.SolverSettings.check_interval_s)
    "1/2 check interval": replace(DEFAULT, check_interval_s=DEFAULT.check_interval_s / 2),
    "2x check interval": replace(DEFAULT, check_interval_s=DEFAULT.check_interval_s * 2),  # coarser: 0.01 s
    "1/4 check interval": replace(DEFAULT, check_interval_s=DEFAULT.check_interval_s / 4),
    # the freed pieces' own joints checked (--piece-joints), at the default interval and at half
    "piece joints": replace(DEFAULT, piece_joints=True),
    "piece joints 1/2 check interval": replace(
        DEFAULT, piece_joints=True, check_interval_s=DEFAULT.check_interval_s / 2
    ),
    "4x iterations": replace(DEFAULT, iterations=4 * DEFAULT.iterations),
    "4x both": replace(DEFAULT, substeps=4 * DEFAULT.substeps, iterations=4 * DEFAULT.iterations),
}
# the joint model's own contact iteration, under the default Bullet settings (SETTINGS' entries set
# Bullet's and the checks' grid; these the ContactSettings a quake's CrackTracker uses)
CONTACT = {
    "no stall, 400 iterations": {"max_iter": 400, "stall_iter": 400},
    "release 5 cm": {"release_m": 0.05},
    "pushover's contacts": {"max_iter": 400, "stall_iter": 400, "release_m": 0.05},
}
for _name in CONTACT:
    SETTINGS[_name] = DEFAULT
# the tables of docs/measurements.md (Bullet as the verdict)
DOUBLED = ["default", "2x substeps", "2x iterations", "2x both"]


def one_run(
    model: Path, solver: SolverSettings, pga: float, seed: int, duration: float, *, bullet: bool = True
) -> dict:
    """One run and what the sweep prints of it; ``bullet=False``: :func:`verdict_without_bullet`."""
    scene = scene_for_model(
        model, SimulationConfig(pga_g=pga, duration_s=duration, seed=seed, solver=solver, figures=False)
    )
    if pga == 0.0:
        scene = replace(scene, motion=None)
    t = time.perf_counter()
    out = run(scene, progress=False, bullet=bullet)
    m = metrics(scene, out)
    w = m.start_frame
    # the stones no joint Bullet still held ties to the plate at the end: the joint model's doing
    held = ~np.isfinite(out.bond_release_time_s) if out.bond_release_time_s is not None else None
    freed = 1.0 - grounded_bodies(scene.bonds, len(scene.bodies), held).mean() if scene.bonds else 0.0
    return {
        "freed": float(freed),
        "cracked": float(np.isfinite(m.bond_break_time_s).mean()) if len(m.bond_break_time_s) else 0.0,
        # cracked inside the freed pieces by their own check (--piece-joints; None without it)
        "in_pieces": (
            float(np.isfinite(out.pieces.crack_time_s).mean())
            if solver.piece_joints and out.pieces is not None and len(out.pieces.crack_time_s)
            else None
        ),
        "moved": float(m.moved_fraction[-1]),
        "toppled": m.toppled_fraction,
        "outcome": m.outcome,
        "bullet_moved": float(metrics(scene, out, bullet=True).moved_fraction[-1]) if bullet else float("nan"),
        "max_disp_mm": float(np.linalg.norm(out.positions[w:] - out.positions[w], axis=2).max() * 1000),
        "seconds": time.perf_counter() - t,
    }


def verdict_without_bullet(model: Path, solver: SolverSettings, pga: float, seed: int, duration: float) -> dict:
    """The verdict of a quake run from the joint model and the freed pieces alone, Bullet left out
    (``simulate --no-bullet``: ``run(..., bullet=False)``): the same cracks, releases and pieces'
    motion as :func:`one_run` wherever the joint model reads no pose (every body on a joint), in a
    fraction of the time."""
    return one_run(model, solver, pga, seed, duration, bullet=False)


def _percent(x: float | None) -> str:
    return f"{'-':>6s}" if x is None else f"{x:6.1%}"


def sweep_line(name: str, setting: str, seed: int, pga: float, r: dict) -> str:
    """The line the sweep prints for one run ``r`` (:func:`one_run`), which :func:`read_logs` reads."""
    return (
        f"{name:14s} {setting:14s} seed {seed} PGA {pga:4.2f} g: cracked {r['cracked']:6.1%}"
        + (f" (+{r['in_pieces']:6.1%} in pieces)" if r["in_pieces"] is not None else "")
        + "  set free "
        f"{r['freed']:6.1%}  moved {r['moved']:6.1%} (Bullet's {r['bullet_moved']:6.1%})  "
        f"toppled {_percent(r['toppled'])}: {r['outcome']}  ({r['seconds']:.0f} s)"
    )


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument(
        "--models",
        nargs="+",
        default=["paper_example", "stylite"],
        help="names under data_synthetic/ or paths to any structure.toml",
    )
    p.add_argument("--settings", nargs="+", default=DOUBLED, choices=list(SETTINGS))
    p.add_argument(
        "--quasi-static",
        action="store_true",
        help="hold the intact structure rigid under the quake (simulate --quasi-static) instead of letting it vibrate",
    )
    p.add_argument(
        "--without-bullet",
        action="store_true",
        help="the verdict from the joint model and the rigid pieces alone (verdict_without_bullet): for the fps setting",
    )
    p.add_argument("--pga", nargs="+", type=float, default=[round(0.05 * k, 2) for k in range(1, 13)])
    p.add_argument("--seeds", nargs="*", type=int, default=[0, 1, 2], help="none: gravity only")
    p.add_argument("--duration", type=float, default=10.0, help="seconds of ground motion per quake run")
    p.add_argument("--gravity-s", type=float, default=20.0, help="seconds under gravity alone (0: skip)")
    p.add_argument(
        "--fragility",
        action="store_true",
        help="run every PGA (no stop at the first collapse) and fit a fragility curve per setting over the seeds",
    )
    p.add_argument(
        "--logs",
        nargs="+",
        type=Path,
        help="with --fragility: fit from the sweep lines these earlier runs printed instead of running",
    )
    args = p.parse_args()
    if args.logs:
        verdicts, models, settings, seeds = read_logs(args.logs)
        print_fragility(verdicts, models, settings, seeds)
        return

    collapse: dict[tuple[str, str, int], float | None] = {}
    # every verdict: (model, setting) -> [(seed, pga, collapsed)]
    verdicts: dict[tuple[str, str], list[tuple[int, float, bool]]] = {}
    with tempfile.TemporaryDirectory() as tmp:
        for name in args.models:
            model = Path(tmp) / Path(name).stem
            toml = Path(name) if name.endswith(".toml") else ROOT / "data_synthetic" / name / "structure.toml"
            build_to_folder(load_structure(toml), model, figures=False, progress=False)
            for setting in args.settings:
                solver = replace(SETTINGS[setting], dynamics=not args.quasi_static)
                contact = ContactSettings(**CONTACT[setting]) if setting in CONTACT else None
                CrackTracker.default_settings = staticmethod(
                    _DEFAULT_CONTACTS if contact is None else (lambda scene, c=contact: c)
                )
                label = f"{name:14s} {setting:14s}"
                if args.gravity_s > 0:
                    r = one_run(model, solver, 0.0, 0, args.gravity_s)
                    print(
                        f"{label} gravity {args.gravity_s:g} s: cracked {r['cracked']:6.1%}  largest displacement "
                        f"{r['max_disp_mm']:8.2f} mm  ({r['seconds']:.0f} s)",
                        flush=True,
                    )
                for seed in args.seeds:
                    collapse[(name, setting, seed)] = None
                    for pga in sorted(args.pga):
                        r = (verdict_without_bullet if args.without_bullet else one_run)(
                            model, solver, pga, seed, args.duration
                        )
                        print(sweep_line(name, setting, seed, pga, r), flush=True)
                        verdicts.setdefault((name, setting), []).append((seed, pga, r["outcome"] == "collapsed"))
                        if r["outcome"] == "collapsed" and collapse[(name, setting, seed)] is None:
                            collapse[(name, setting, seed)] = pga
                            if not args.fragility:
                                break

    print("\ncollapse PGA (g; '>' = none up to the largest PGA run), and its spread over the settings")
    print(f"{'model':14s} {'seed':>4s} " + " ".join(f"{s:>14s}" for s in args.settings) + f" {'max change':>11s}")
    top = max(args.pga)
    for name in args.models:
        for seed in args.seeds:
            vals = [collapse.get((name, s, seed)) for s in args.settings]
            cells = [f"{v:14.2f}" if v is not None else f"{'>' + format(top, '.2f'):>14s}" for v in vals]
            if all(v is None for v in vals):
                change = f"{0.0:11.2f}"  # none collapsed at any setting
            elif any(v is None for v in vals):
                change = f"{'mixed':>11s}"  # collapsed at some settings only: at least the gap to the top PGA
            else:
                change = f"{max(vals) - min(vals):11.2f}"
            print(f"{name:14s} {seed:4d} " + " ".join(cells) + f" {change}")
    if args.fragility:
        print_fragility(verdicts, args.models, args.settings, args.seeds)


_LINE = re.compile(
    r"^(?P<model>.+?) (?P<setting>"
    + "|".join(re.escape(k) for k in sorted(SETTINGS, key=len, reverse=True))
    + r") +seed +(?P<seed>\d+) PGA +(?P<pga>[\d.]+) g: .*: (?P<outcome>\w+) +\("
)


def read_logs(paths):
    """The verdicts of the sweep lines in these printed runs: ``(verdicts, models, settings, seeds)``
    in the order first met."""
    verdicts: dict[tuple[str, str], list[tuple[int, float, bool]]] = {}
    models: list[str] = []
    settings: list[str] = []
    seeds: list[int] = []
    for path in paths:
        for line in Path(path).read_text().splitlines():
            m = _LINE.match(line)
            if m is None:
                continue
            name, setting, seed = m["model"].strip(), m["setting"].strip(), int(m["seed"])
            for seen, x in ((models, name), (settings, setting), (seeds, seed)):
                if x not in seen:
                    seen.append(x)
            verdicts.setdefault((name, setting), []).append((seed, float(m["pga"]), m["outcome"] == "collapsed"))
    if not verdicts:
        raise SystemExit(f"no sweep lines in {', '.join(map(str, paths))}")
    return verdicts, models, settings, seeds


def _median(rows: list[tuple[int, float, bool]], seeds) -> tuple[float, float] | None:
    """The lognormal fragility (median g, dispersion) of the verdicts of these seeds (a seed
    drawn twice counts twice); None where the verdicts do not fix one."""
    from calib_masonry.study.analysis import fit_fragility

    picked = [(p, c) for s in seeds for (k, p, c) in rows if k == s]
    if not picked:
        return None
    pga, col = np.array(picked, dtype=float).T
    return fit_fragility(pga, col)


def fragility(verdicts, models, settings, seeds, resamples: int = 400) -> list[dict]:
    """Per model and setting: the fragility's ``median`` (g) and ``beta`` over all the seeds'
    verdicts (None where they fix no curve), the median's 90 % ``band`` over resampled seeds and,
    for every setting after the first, its ``change`` from the first and that change's
    ``change_band`` (paired: the same resample at every setting)."""
    rng = np.random.default_rng(0)
    draws = [rng.choice(seeds, len(seeds)) for _ in range(resamples)]
    out = []
    for name in models:
        first = _median(verdicts.get((name, settings[0]), []), seeds)
        base = [_median(verdicts.get((name, settings[0]), []), d) for d in draws]
        for setting in settings:
            rows = verdicts.get((name, setting), [])
            fit = _median(rows, seeds)
            row = {"model": name, "setting": setting, "median": None, "beta": None}
            out.append(row)
            if fit is None:
                continue
            boot = [_median(rows, d) for d in draws]
            med = np.array([b[0] for b in boot if b is not None])
            row.update(median=fit[0], beta=fit[1], band=(float(np.percentile(med, 5)), float(np.percentile(med, 95))))
            diff = np.array([b[0] - a[0] for a, b in zip(base, boot) if a is not None and b is not None])
            if setting != settings[0] and first is not None and len(diff):
                row["change"] = fit[0] - first[0]
                row["change_band"] = (float(np.percentile(diff, 5)), float(np.percentile(diff, 95)))
    return out


def print_fragility(verdicts, models, settings, seeds) -> None:
    """:func:`fragility`, a line per model and setting."""
    print(f"\nfragility over {len(seeds)} records (median g, dispersion; 90 % band from resampling the records)")
    for row in fragility(verdicts, models, settings, seeds):
        head = f"{row['model']:14s} {row['setting']:20s}"
        if row["median"] is None:
            print(f"{head} no curve (all or none collapsed, or the outcomes separate at one step)")
            continue
        (lo, hi), line = row["band"], f"{head} median {row['median']:.3f} g"
        line += f" (90 %: {lo:.3f}-{hi:.3f}), beta {row['beta']:.3f}"
        if "change" in row:
            a, b = row["change_band"]
            line += f"; change {row['change']:+.3f} g (90 %: {a:+.3f} to {b:+.3f})"
        print(line, flush=True)


if __name__ == "__main__":
    main()

"""What a study's table says: statistics of every output, Sobol' indices, the fragility curve, the
sweep's errors per swept value; and the figures.

Fragility: P(collapse | PGA = a) = Phi(ln(a / theta) / beta), fitted by maximum likelihood to every
simulated sample's collapsed flag (a binomial likelihood; theta the median capacity in g, beta the
lognormal dispersion); the band is the 5-95 % range of the curve over bootstrap resamples of the
samples within each PGA. Sobol': SALib's estimator on Saltelli's design (first-order S1 and total
ST, with 95 % confidence intervals from its bootstrap).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from .design import Study
from .sample import ROW_KEYS

__all__ = ["input_columns", "output_columns", "summarize", "fit_fragility", "plot_study"]

BOOTSTRAP = 200


def input_columns(study: Study, rows: list[dict]) -> list[str]:
    names = [k for k, _ in study.sweep]
    for inp in study.inputs:
        if inp.law == "calibration":
            wall = inp.name.split(".")[0]
            names += [f"{wall}.width_m", f"{wall}.height_m"]
        else:
            names.append(inp.name)
    if study.simulate is not None and not study.simulate.pushover:
        names += ["pga_g", "record"]
    return names


def output_columns(study: Study, rows: list[dict]) -> list[str]:
    skip = set(ROW_KEYS) | set(input_columns(study, rows)) | {"pushover"}
    seen: dict[str, None] = {}
    for r in rows:
        for k in r:
            if k not in skip:
                seen.setdefault(k)
    return list(seen)


def _numeric(rows: list[dict], key: str) -> np.ndarray | None:
    vals = [r.get(key) for r in rows]
    if not vals or not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in vals if v is not None):
        return None
    return np.array([np.nan if v is None else float(v) for v in vals])


def _varies(v: np.ndarray | None) -> bool:
    """Numbers with at least two different finite values."""
    if v is None:
        return False
    v = v[np.isfinite(v)]
    return bool(v.size) and bool(v.max() > v.min())


def _stats(v: np.ndarray) -> dict:
    v = v[np.isfinite(v)]
    if not len(v):
        return {"n": 0}
    p5, p50, p95 = np.percentile(v, [5, 50, 95])
    return {
        "n": len(v),
        "mean": float(v.mean()),
        # 0 where every sample is the same (numpy's std of equal values keeps its mean's rounding:
        # 1e-16 for a constant 0.9968, which the command line listed among the outputs that vary)
        "std": float(v.std(ddof=1)) if v.max() > v.min() else 0.0,
        "p5": float(p5),
        "p50": float(p50),
        "p95": float(p95),
    }


def fit_fragility(pga: np.ndarray, collapsed: np.ndarray) -> tuple[float, float] | None:
    """Maximum-likelihood lognormal fragility (median theta in g, dispersion beta); None when the
    data cannot fix both (every sample collapsed, or none did, or fewer than two PGAs > 0)."""
    from scipy.optimize import minimize
    from scipy.stats import norm

    pga, collapsed = np.asarray(pga, float), np.asarray(collapsed, float)
    keep = pga > 0
    pga, collapsed = pga[keep], collapsed[keep]
    if len(np.unique(pga)) < 2 or collapsed.min() == collapsed.max():
        return None
    if pga[collapsed == 0].max() < pga[collapsed == 1].min():
        return None  # perfectly separated: no finite maximum-likelihood curve
    x = np.log(pga)

    def nll(p):
        mu, log_beta = p
        prob = np.clip(norm.cdf((x - mu) / math.exp(log_beta)), 1e-12, 1 - 1e-12)
        return -float(np.sum(collapsed * np.log(prob) + (1 - collapsed) * np.log(1 - prob)))

    start = np.array([float(np.median(x)), math.log(0.4)])
    res = minimize(nll, start, method="Nelder-Mead", options={"xatol": 1e-6, "fatol": 1e-9, "maxiter": 4000})
    mu, log_beta = res.x
    beta = math.exp(log_beta)
    if not (math.isfinite(mu) and 1e-3 < beta < 50):
        return None  # perfectly separated data: the MLE runs off to a step
    return math.exp(mu), beta


#: fewer simulated runs than this give a fragility curve with a caveat
MIN_FRAGILITY_RUNS = 20


def _fragility(study: Study, ok: list[dict]) -> dict | None:
    from scipy.stats import norm

    if study.simulate is None or study.simulate.pushover:
        return None
    pga = np.array([r["pga_g"] for r in ok if "collapsed" in r], float)
    col = np.array([r["collapsed"] for r in ok if "collapsed" in r], float)
    if not len(pga):
        return None
    levels = sorted(set(pga.tolist()))
    table = [{"pga_g": a, "samples": int((pga == a).sum()), "collapsed": int(col[pga == a].sum())} for a in levels]
    for t in table:
        t["fraction"] = t["collapsed"] / t["samples"]
    out: dict = {"per_pga": table, "median_g": None, "beta": None, "band": None}
    if col.min() < col.max() and pga[col == 0].max() < pga[col == 1].min():
        lo, hi = float(pga[col == 0].max()), float(pga[col == 1].min())
        out["note"] = (
            f"every sample at or below {lo:g} g stood and every one at or above {hi:g} g collapsed: the "
            f"likelihood has no finite maximum (the median lies between, beta -> 0); add PGAs between "
            f"{lo:g} and {hi:g} g or more records"
        )
        out["median_between_g"] = [lo, hi]
        return out
    fit = fit_fragility(pga, col)
    if fit is None:
        out["note"] = "the outcomes do not fix a lognormal curve (all or none collapsed, or one PGA level)"
        return out
    out["median_g"], out["beta"] = fit
    grid = np.linspace(0.0, max(levels) * 1.5, 61)[1:]
    rng = np.random.default_rng([study.seed, 99])
    curves = []
    for _ in range(BOOTSTRAP):
        idx = np.concatenate([rng.choice(np.flatnonzero(pga == a), (pga == a).sum()) for a in levels])
        f = fit_fragility(pga[idx], col[idx])
        if f is not None:
            curves.append(norm.cdf(np.log(grid / f[0]) / f[1]))
    degenerate = True
    if curves:
        lo, hi = np.percentile(np.array(curves), [5, 95], axis=0)
        degenerate = bool(np.allclose(lo, hi, atol=1e-9))
        out["band"] = {
            "pga_g": grid.tolist(),
            "p5": lo.tolist(),
            "p95": hi.tolist(),
            "bootstrap_fits": len(curves),
            "bootstrap_resamples": BOOTSTRAP,
        }
    if len(pga) < MIN_FRAGILITY_RUNS or degenerate:
        why = "its bootstrap band is a single line (p5 = p95 at every PGA)" if degenerate else "its band is wide"
        out["caveat"] = (
            f"from {len(pga)} runs at {len(levels)} PGA levels the median and beta are only indicative: {why}; "
            f"use at least {MIN_FRAGILITY_RUNS} runs (more records at each PGA)"
        )
    return out


def _sobol(study: Study, rows: list[dict], outputs: list[str]) -> dict | None:
    if study.method != "sobol":
        return None
    from SALib.analyze import sobol

    if len(study.loads) != 1:
        return {"note": "Sobol' indices need one load per design point; give one PGA and records = 1"}
    names = []
    for inp in study.inputs:
        names += [f"{inp.name}[W]", f"{inp.name}[H]"] if inp.law == "calibration" else [inp.name]
    # names as an array: SALib 1.5 hands them to pandas.unique, which refuses a list from pandas 3 on
    problem = {"num_vars": len(names), "names": np.array(names), "bounds": [[0.0, 1.0]] * len(names)}
    result: dict = {}
    for key in outputs:
        y = _numeric(rows, key)
        if y is None or not np.isfinite(y).any():
            continue  # no sample has a value (an open footprint's closure, a collapse time where none fell)
        if not np.all(np.isfinite(y)):
            result[key] = {"note": "some samples failed or gave NaN; Saltelli's estimator needs every sample"}
            continue
        if np.ptp(y) == 0:
            result[key] = {n: {"S1": 0.0, "S1_conf": 0.0, "ST": 0.0, "ST_conf": 0.0} for n in names}
            continue
        si = sobol.analyze(problem, y, calc_second_order=False, seed=study.seed, print_to_console=False)
        result[key] = {
            n: {
                "S1": float(si["S1"][i]),
                "S1_conf": float(si["S1_conf"][i]),
                "ST": float(si["ST"][i]),
                "ST_conf": float(si["ST_conf"][i]),
            }
            for i, n in enumerate(names)
        }
    return result


def _sweep(study: Study, ok: list[dict], outputs: list[str]) -> dict | None:
    if not study.sweep:
        return None
    wanted = [
        k
        for k in outputs
        if k in ("max_abs_width_error_m", "max_abs_height_error_m", "max_abs_theta_error_deg", "dice_mean", "dice_min")
        or k.endswith((".width_error_m", ".height_error_m", ".dice_mean"))
        or k in ("precision", "recall", "volume_relative_error", "centroid_error_mm")
    ]
    out = {}
    for key, values in study.sweep:
        table = []
        for v in values:
            sel = [r for r in ok if r.get(key) == v]
            entry = {"value": v, "samples": len(sel)}
            for k in wanted:
                y = _numeric(sel, k)
                if y is not None and np.isfinite(y).any():
                    entry[k] = float(np.nanmean(y))
            table.append(entry)
        out[key] = table
    return out


def summarize(study: Study, rows: list[dict]) -> dict:
    """``summary.json``: counts, failures, statistics of every numeric output over the samples that
    ran, and (as the study calls for) Sobol' indices, the fragility curve and the sweep's table."""
    ok = [r for r in rows if r.get("status") == "ok"]
    failed = [r for r in rows if r.get("status") != "ok"]
    outputs = output_columns(study, rows)
    stats = {}
    for key in outputs:
        y = _numeric(ok, key)
        if y is not None:
            stats[key] = _stats(y)
    summary = {
        "study": study.name,
        "method": study.method,
        "samples": len(rows),
        "ok": len(ok),
        "failed": len(failed),
        "failures": [{"sample": r["sample"], "error": r.get("error", "")} for r in failed[:50]],
        "inputs": input_columns(study, rows),
        "outputs": stats,
        "seconds_per_sample": _stats(np.array([r.get("seconds", np.nan) for r in rows], float)),
    }
    sob = _sobol(study, rows, outputs)
    if sob is not None:
        summary["sobol"] = sob
    frag = _fragility(study, ok)
    if frag is not None:
        summary["fragility"] = frag
    sw = _sweep(study, ok, outputs)
    if sw is not None:
        summary["sweep"] = sw
    return summary


def _main_output(stats: dict) -> str | None:
    for k in ("collapse_multiplier_g", "moved_fraction", "max_abs_width_error_m", "total_volume_m3"):
        if k in stats:
            return k
    return next(iter(stats), None)


def plot_study(study: Study, rows: list[dict], summary: dict, folder: Path) -> list[Path]:
    """The study's figures in ``folder``: histograms of the outputs, the main output against each
    input, Sobol' bars, the fragility curve with its band, the sweep's errors per swept value."""
    from .. import _figure as plt

    folder.mkdir(parents=True, exist_ok=True)
    ok = [r for r in rows if r.get("status") == "ok"]
    written: list[Path] = []

    def save(fig, name: str) -> None:
        fig.tight_layout()
        written.append(folder / name)
        plt.save(fig, written[-1], dpi=110)
        plt.close(fig)

    stats = summary["outputs"]
    keys = [k for k in stats if stats[k].get("n", 0) and not k.startswith("com_")][:12]
    if keys:
        cols = min(4, len(keys))
        nrow = math.ceil(len(keys) / cols)
        fig, axes = plt.subplots(nrow, cols, figsize=(3.2 * cols, 2.6 * nrow), squeeze=False)
        for ax, k in zip(axes.flat, keys):
            y = _numeric(ok, k)
            ax.hist(y[np.isfinite(y)], bins=min(30, max(5, len(y) // 3)), color="#4a7fb0")
            ax.set_title(k, fontsize=8)
            ax.tick_params(labelsize=7)
        for ax in list(axes.flat)[len(keys) :]:
            ax.axis("off")
        fig.suptitle(f"{study.name}: outputs over {len(ok)} samples ({summary['failed']} failed)", fontsize=10)
        save(fig, "histograms.png")
    main = _main_output(stats)
    # the inputs that vary, at most twelve, in rows of four (one row of eight was 2640 x 308 px)
    inputs = [k for k in summary["inputs"] if _varies(_numeric(ok, k))][:12]
    if main and inputs:
        cols = min(4, len(inputs))
        rows = -(-len(inputs) // cols)
        fig, axes = plt.subplots(rows, cols, figsize=(3.2 * cols, 2.9 * rows + 0.4), squeeze=False)
        y = _numeric(ok, main)
        for ax, k in zip(axes.flat, inputs):
            ax.scatter(_numeric(ok, k), y, s=8, color="#b0504a")
            ax.set_xlabel(k, fontsize=8)
            ax.tick_params(labelsize=7)
        for row in axes:
            row[0].set_ylabel(main, fontsize=8)
        for ax in list(axes.flat)[len(inputs) :]:
            ax.axis("off")
        fig.suptitle(f"{study.name}: {main} against each input that varies ({len(ok)} samples)", fontsize=10)
        save(fig, "output_vs_inputs.png")
    sob = summary.get("sobol", {})
    if main and isinstance(sob.get(main), dict) and "note" not in sob[main]:
        names = list(sob[main])
        x = np.arange(len(names))
        fig, ax = plt.subplots(figsize=(max(4, 0.8 * len(names) + 2), 3))
        for off, which, colour in ((-0.2, "S1", "#4a7fb0"), (0.2, "ST", "#b0504a")):
            ax.bar(
                x + off,
                [sob[main][n][which] for n in names],
                0.4,
                yerr=[sob[main][n][which + "_conf"] for n in names],
                label=which,
                color=colour,
            )
        ax.set_xticks(x, names, rotation=30, ha="right", fontsize=8)
        ax.set_ylabel(f"Sobol' index of {main}")
        ax.legend()
        save(fig, "sobol.png")
    frag = summary.get("fragility")
    if frag:
        from scipy.stats import norm

        fig, ax = plt.subplots(figsize=(5, 3.5))
        ax.plot(
            [t["pga_g"] for t in frag["per_pga"]],
            [t["fraction"] for t in frag["per_pga"]],
            "o",
            color="k",
            label="fraction collapsed",
        )
        if frag.get("median_g"):
            band = frag.get("band")
            grid = np.array(band["pga_g"]) if band else np.linspace(0.01, 1.5 * frag["per_pga"][-1]["pga_g"], 60)
            ax.plot(
                grid,
                norm.cdf(np.log(grid / frag["median_g"]) / frag["beta"]),
                color="#b0504a",
                label=f"lognormal: median {frag['median_g']:.2f} g, beta {frag['beta']:.2f}",
            )
            if band:
                ax.fill_between(grid, band["p5"], band["p95"], color="#b0504a", alpha=0.2, label="5-95 % bootstrap")
        ax.set_xlabel("PGA (g)")
        ax.set_ylabel("P(collapse)")
        ax.set_ylim(-0.02, 1.02)
        ax.legend(fontsize=7)
        ax.set_title(f"{study.name}: fragility")
        save(fig, "fragility.png")
    sw = summary.get("sweep")
    if sw:
        errs = ["max_abs_width_error_m", "max_abs_height_error_m", "dice_mean"]
        fig, axes = plt.subplots(len(sw), len(errs), figsize=(3.2 * len(errs), 2.6 * len(sw)), squeeze=False)
        for row, (key, table) in zip(axes, sw.items()):
            for ax, e in zip(row, errs):
                ax.plot([t["value"] for t in table], [t.get(e, np.nan) for t in table], "o-")
                ax.set_xlabel(key, fontsize=8)
                ax.set_ylabel(e, fontsize=8)
                ax.tick_params(labelsize=7)
        save(fig, "sweep.png")
    return written

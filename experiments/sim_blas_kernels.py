"""Experiment: does a simulation's outcome depend on which BLAS kernels the machine's OpenBLAS picks?

OpenBLAS picks its kernels by the processor it finds at load time; ``OPENBLAS_CORETYPE`` names
others (the CPU must have their instructions). The joint model's factorisations (CHOLMOD through
cvxopt's own OpenBLAS) and numpy's products then round differently in their last digits. The same
``calib-masonry simulate MODEL ARGS --no-figures`` is run once per kernel, each in a fresh process
with ``OPENBLAS_CORETYPE`` set for every OpenBLAS it loads ("default": unset, the machine's own
choice); each run's outcome, bonds broken, bricks moved and stepping seconds are printed, and its
joints' crack times compared with the first run's (joints cracked in both at the same time, in
only one, the first time at which they differ). The kernels the first run's libraries chose are
printed (``OPENBLAS_VERBOSE=2``), with the processor's model.

    .venv/bin/python experiments/sim_blas_kernels.py MODEL [--kernels default,Haswell,SkylakeX]
        [--keep DIR] [-- simulate arguments, e.g. --pga 0.3 --seed 0]

Kernels the processor cannot run (SkylakeX without AVX-512, Haswell without AVX2 and FMA) are
skipped.

Measured 2026-12-01 (thirty-fourth session, 2-core Xeon VM reporting family 6 model 207, where
both cvxopt's and numpy's OpenBLAS fall back to "Prescott"), the 10 s quake at 0.3 g, seed 0
(docs/dynamics.md, "The cascade follows the BLAS kernels"):

- the paper example (built from data_synthetic/paper_example/structure.toml): default 15.4 % of
  the bonds broken, stepping 147 s; Haswell 18.5 %, 197 s; both standing. The joints crack at
  the same times until 2.355 s, then differ (418 cracked in both, 214 of them at the same time);
- the Stylite tower: 10.0 % broken under default, Haswell and SkylakeX, every crack and release
  at the same time; at its collapse thresholds (seed 0 at 0.75 and 0.80 g, seed 1 at 0.35 and
  0.40 g: ``-- --pga 0.75 --seed 0`` and so on) the same verdicts under every kernel;
- the unseen tower (``synth`` seed 41, docs/dynamics.md) at 0.75 and 0.80 g, seed 0: damaged and
  collapsed under both kernels (at 0.75 g 97 joints crack in one run only, from 1.205 s).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
NEEDS = {
    "Haswell": {"avx2", "fma"},
    "SkylakeX": {"avx512f", "avx512bw", "avx512vl", "avx512dq"},
    "Zen": {"avx2", "fma"},
}


def cpu() -> tuple[str, set[str]]:
    """The processor's name and model number, and its flags (Linux; empty elsewhere)."""
    try:
        text = Path("/proc/cpuinfo").read_text()
    except OSError:
        return platform.processor(), set()
    fields = {}
    for line in text.splitlines():
        if ":" in line:
            k, v = (s.strip() for s in line.split(":", 1))
            fields.setdefault(k, v)
    name = f"{fields.get('model name', '?')} (family {fields.get('cpu family', '?')} model {fields.get('model', '?')})"
    return name, set(fields.get("flags", "").split())


def environment(kernel: str) -> dict[str, str]:
    env = dict(os.environ)
    env.pop("OPENBLAS_CORETYPE", None)
    if kernel != "default":
        env["OPENBLAS_CORETYPE"] = kernel
    return env


def chosen(kernel: str) -> str:
    """The cores numpy's, cvxopt's and scipy's OpenBLAS report with this setting."""
    env = environment(kernel) | {"OPENBLAS_VERBOSE": "2"}
    code = "import numpy, cvxopt.cholmod, scipy.linalg"
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True)
    cores = [
        line.split(":", 1)[1].strip() for line in (out.stdout + out.stderr).splitlines() if line.startswith("Core:")
    ]
    return ", ".join(cores) or "not reported"


def run(model: Path, kernel: str, out: Path, extra: list[str]) -> dict:
    cli = Path(sys.executable).with_name("calib-masonry")
    cmd = [str(cli), "simulate", str(model), "--no-figures", "--out", str(out), "--overwrite", *extra]
    t = time.perf_counter()
    proc = subprocess.run(cmd, env=environment(kernel), capture_output=True, text=True)
    seconds = time.perf_counter() - t
    if proc.returncode != 0:
        sys.exit(f"{kernel}: simulate failed ({proc.returncode}): {proc.stderr.strip()[-500:]}")
    summary = json.loads((out / "summary.json").read_text())
    poses = np.load(out / "poses.npz")
    return {"summary": summary, "breaks": poses["bond_break_time_s"], "seconds": seconds}


def main() -> None:
    argv = sys.argv[1:]
    extra = argv[argv.index("--") + 1 :] if "--" in argv else []
    argv = argv[: argv.index("--")] if "--" in argv else argv
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("model", type=Path, help="a model folder (calib-masonry build --out)")
    p.add_argument("--kernels", default="default,Haswell,SkylakeX")
    p.add_argument("--keep", type=Path, help="keep each run's output folder here")
    args = p.parse_args(argv)
    name, flags = cpu()
    print(f"processor: {name}; the machine's own choice: {chosen('default')}")
    kernels = []
    for k in args.kernels.split(","):
        if k in NEEDS and not NEEDS[k] <= flags:
            print(f"{k}: skipped (the processor lacks {', '.join(sorted(NEEDS[k] - flags))})")
        else:
            kernels.append(k)
    work = Path(tempfile.mkdtemp(prefix="blas_kernels_"))
    try:
        first = None
        for k in kernels:
            out = (args.keep or work) / k
            r = run(args.model, k, out, extra)
            s = r["summary"]
            line = (
                f"{k:>9} ({chosen(k) if k != 'default' else 'as above'}): {s.get('outcome')}, "
                f"{100 * s.get('bonds_broken_fraction', float('nan')):.1f} % of the bonds broken, "
                f"{100 * s.get('moved_fraction_final', float('nan')):.1f} % of the bricks moved, "
                f"stepping {s.get('seconds', {}).get('stepping', float('nan')):.1f} s (run {r['seconds']:.1f} s)"
            )
            if first is None:
                first = r
            else:
                a, b = first["breaks"], r["breaks"]
                both = np.isfinite(a) & np.isfinite(b)
                differ = (a != b) & (np.isfinite(a) | np.isfinite(b))
                at = np.fmin(np.where(differ, a, np.inf), np.where(differ, b, np.inf)).min(initial=np.inf)
                line += (
                    f"; against {kernels[0]}: {int(both.sum())} joints cracked in both "
                    f"({int((a[both] == b[both]).sum())} at the same time), {int((np.isfinite(a) ^ np.isfinite(b)).sum())} "
                    f"in only one, "
                    + ("every crack time the same" if not np.isfinite(at) else f"the first difference at {at:.3f} s")
                )
            print(line, flush=True)
    finally:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()

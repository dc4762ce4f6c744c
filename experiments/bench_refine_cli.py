"""Benchmark: `trace --refine` from the command line against the same refinement warm in one process,
with scipy's Powell (the naive peer of experiments/bench_refine.py) beside them.

What a user pays: each `calib-masonry trace MASK --refine` is a new process; it forks a solver
process (`refine.solver_process`) that imports JAX and optimistix and loads the refinement's
programs, compiled ahead of time and kept on disk (`_jax.Precompiled`), while the command reads,
traces and prepares the mask, and then solves there. The refinement's cost from the command line is
the call minus a plain `trace` of the same mask (median of ``--repeats`` runs of each); the warm
cost is the same two commands called again and again through `calib_masonry.cli.main` in one
process that has imported JAX (so it solves in that process, as the library does; the first call
of each left out). The command line's pairs and the warm process's pairs are
alternated, so that a machine whose speed drifts (another job starting) weighs on both alike. Issue 39 asks for the command line at most 1.2x the warm
call. The peer refines a seeded subset of the stones, one at a time, and its time is scaled to all.

    .venv/bin/python experiments/bench_refine_cli.py [--mask PATH] [--repeats 3] [--peer 8]

The default mask is the real stone mask ../shared/data/external/swat/WR2_250_new.png (45 stones);
``--mask synthetic`` makes a held-out synthetic stone wall (3 x 3 m, 200 px/m, seed 101).
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_refine import SWAT, _job, _scenario, peer_one  # noqa: E402

WARM_CHILD = r"""
import json, sys, time
from pathlib import Path
from calib_masonry.cli import main
import calib_masonry.wall2d.refine_kernel  # JAX loaded here: the refinement solves in this process
mask, out = sys.argv[1], sys.argv[2]
# one pair (plain, refine) per line read, timed, its times written back: the parent alternates the
# command line's pairs with these, so that both see the machine as it is at the time
for line in sys.stdin:
    times = {}
    for name, extra in (("plain", []), ("refine", ["--refine"])):
        Path(out).unlink(missing_ok=True)
        t0 = time.perf_counter()
        assert main(["trace", mask, "--vertices", "8", "--no-figures", "--out", out, *extra]) == 0
        times[name] = time.perf_counter() - t0
    print("RESULT " + json.dumps(times), flush=True)
"""


def _cli(mask: str, out: Path, refine: bool) -> float:
    cmd = [sys.executable, "-m", "calib_masonry", "trace", mask, "--vertices", "8", "--no-figures"]
    cmd += ["--out", str(out)] + (["--refine"] if refine else [])
    t0 = time.perf_counter()
    subprocess.run(cmd, check=True, capture_output=True)
    return time.perf_counter() - t0


def _synthetic_mask(folder: Path) -> str:
    from calib_masonry.spec import load_structure
    from calib_masonry.synthetic.truth import synthesize_to_folder

    sc = folder / "scenario.toml"
    sc.write_text(_scenario("held_out", False, 200, 101, [(3.0, 3.0, 0)]))
    synthesize_to_folder(load_structure(sc, require_sources=False), folder / "data", figures=False)
    return str(folder / "data" / "masks" / "w0.png")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--mask", default=str(SWAT), help="a mask, or 'synthetic' for a held-out synthetic stone wall")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--peer", type=int, default=8, help="stones the peer refines (its time scaled to all)")
    a = ap.parse_args()
    from calib_masonry.io import read_mask

    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        mask = _synthetic_mask(tmp) if a.mask == "synthetic" else a.mask
        cli = {"plain": [], "refine": []}
        warm = {"plain": [], "refine": []}
        _cli(mask, tmp / "o.json", True)  # the compilation cache filled, as on any machine after one run
        child = subprocess.Popen(
            [sys.executable, "-c", WARM_CHILD, mask, str(tmp / "w.json")],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
        )
        try:
            for k in range(a.repeats + 1):
                child.stdin.write("go\n")
                child.stdin.flush()
                line = child.stdout.readline()
                while line and not line.startswith("RESULT "):  # the command's own output
                    line = child.stdout.readline()
                pair = json.loads(line.split("RESULT ", 1)[1])
                if k == 0:  # the warm process's first pair: its own first call, left out
                    continue
                for name in warm:
                    warm[name].append(pair[name])
                cli["plain"].append(_cli(mask, tmp / "o.json", False))
                cli["refine"].append(_cli(mask, tmp / "o.json", True))
        finally:
            child.stdin.close()
            child.wait()
        labels, tr, _ = _job(read_mask(mask), 8)
    n = len(tr.bricks)
    med = {k: statistics.median(v) for k, v in cli.items()}
    wmed = {k: statistics.median(v) for k, v in warm.items()}
    t_cli, t_warm = med["refine"] - med["plain"], wmed["refine"] - wmed["plain"]
    pick = np.random.default_rng(0).choice(n, size=min(a.peer, n), replace=False)
    t0 = time.perf_counter()
    for p in pick:
        peer_one(labels, tr.bricks[p].id, tr.bricks[p].vertices_xy)
    t_peer = (time.perf_counter() - t0) / len(pick) * n
    print(f"mask {mask}: {n} stones, {a.repeats} repeats (medians)")
    print(
        f"  command line: trace {med['plain']:.2f} s, trace --refine {med['refine']:.2f} s -> refinement {t_cli:.2f} s"
    )
    print(
        f"  warm, one process: trace {wmed['plain']:.2f} s, --refine {wmed['refine']:.2f} s -> refinement {t_warm:.2f} s"
    )
    print(f"  command line / warm: {t_cli / t_warm:.2f} (aim <= 1.2)")
    print(
        f"  peer (scipy Powell, {len(pick)} stones, scaled): {t_peer:.1f} s; "
        f"ours {t_peer / t_cli:.1f}x faster from the command line, {t_peer / t_warm:.1f}x warm"
    )


if __name__ == "__main__":
    main()

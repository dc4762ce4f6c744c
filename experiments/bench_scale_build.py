"""Benchmark: `build` of the scale tower (issue 38: "a tower of four 8 x 20 m stretcher-bond walls,
`synth` with 200 px/m, builds in at most 60 s"), against the same build in one process (the
library's default, and what `build` did before 2026-11-28: every wall traced here, the simulation
geometry on a thread), in the same run. The command line traces every second wall, and computes
the simulation geometry, in processes of their own.

The tower: four 8 x 20 m walls, 0.40 x 0.18 m bricks, 10 mm mortar, 0.18 m thick, stretcher bond,
`synth` seed 7980 at 200 px/m (8,190 bricks after the corners are cut; the issue's 7,980 came
from another thickness or corner cut). Each build runs as its own command (a fresh interpreter,
imports included); the wall time and the peak of the resident memory summed over the command's
processes (sampled every 0.1 s from /proc) are printed, and the two builds' sim_geometry.npz must
hold the same arrays.

    .venv/bin/python experiments/bench_scale_build.py [--data DIR] [--repeats N]

Measured 2026-11-28 on the 2-core VM, nothing else running (see the issue-38 note for the
figures of the commit that introduced this script).
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

SCENARIO = """[structure]
name = "scale_tower"
thickness_m = 0.18
vertices = 4
closed = true

[synthetic]
layout = "stretcher"
brick_length_m = 0.40
brick_height_m = 0.18
mortar_m = 0.01
px_per_m = 200
seed = 7980
"""
WALL = '\n[[wall]]\nname = "{name}"\nwidth_m = 8.0\nheight_m = 20.0\ntheta_deg = {theta}\n'

LIBRARY_BUILD = (
    "import sys\n"
    "from calib_masonry.build_folder import build_to_folder\n"
    "from calib_masonry.spec import load_structure\n"
    "build_to_folder(load_structure(sys.argv[1]), sys.argv[2], processes=False)\n"
)


def _tree_rss(pid: int) -> int:
    """Resident bytes of ``pid`` and every process below it."""
    parents: dict[int, int] = {}
    rss: dict[int, int] = {}
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        p = int(stat.parent.name)
        parents[p] = int(fields[1])
        rss[p] = int(fields[21]) * 4096
    total, todo = 0, [pid]
    while todo:
        p = todo.pop()
        total += rss.get(p, 0)
        todo += [c for c, pp in parents.items() if pp == p]
    return total


def timed(cmd: list[str]) -> tuple[float, float]:
    """Wall seconds and peak summed resident GB of ``cmd`` (it must succeed)."""
    t0 = time.perf_counter()
    p = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    peak = 0
    while p.poll() is None:
        peak = max(peak, _tree_rss(p.pid))
        time.sleep(0.1)
    seconds = time.perf_counter() - t0
    err = p.stderr.read() if p.stderr else ""
    if p.returncode != 0:
        raise SystemExit(f"{cmd[:3]} failed ({p.returncode}): {err[-2000:]}")
    return seconds, peak / 1e9


def same_geometry(a: Path, b: Path) -> bool:
    x, y = np.load(a / "sim_geometry.npz"), np.load(b / "sim_geometry.npz")
    return x.files == y.files and all(np.array_equal(x[k], y[k]) for k in x.files)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", type=Path, help="a synth output of the tower to reuse (made if missing)")
    ap.add_argument("--repeats", type=int, default=1)
    args = ap.parse_args()
    exe = Path(sys.executable).parent / "calib-masonry"
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        data = args.data or tmp / "data"
        if not (data / "structure.toml").exists():
            sc = tmp / "scenario.toml"
            sc.write_text(SCENARIO + "".join(WALL.format(name=n, theta=t) for n, t in zip("nesw", (0, 90, 180, 270))))
            t0 = time.perf_counter()
            subprocess.run([str(exe), "synth", str(sc), "--out", str(data), "--no-figures"], check=True)
            print(f"synth: {time.perf_counter() - t0:.1f} s -> {data}")
        structure = data / "structure.toml"
        rows = []
        for r in range(args.repeats):
            ours, peer = tmp / f"ours{r}", tmp / f"peer{r}"
            s1, m1 = timed([str(exe), "build", str(structure), "--out", str(ours)])
            s0, m0 = timed([sys.executable, "-c", LIBRARY_BUILD, str(structure), str(peer)])
            same = same_geometry(ours, peer)
            rows.append((s1, m1, s0, m0, same))
            print(
                f"repeat {r + 1}: build (command line: worker processes) {s1:.1f} s, {m1:.2f} GB; "
                f"in one process {s0:.1f} s, {m0:.2f} GB; ratio {s1 / s0:.3f}; "
                f"sim_geometry.npz {'identical' if same else 'DIFFERENT'}"
            )
        best = min(rows)
        print(
            f"best: {best[0]:.1f} s (aim 60 s), peer {min(r[2] for r in rows):.1f} s, "
            f"ratio {best[0] / min(r[2] for r in rows):.3f}; peak memory {best[1]:.2f} GB vs {best[3]:.2f} GB"
        )
        if not all(r[4] for r in rows):
            raise SystemExit("the two builds' geometries differ")


if __name__ == "__main__":
    main()

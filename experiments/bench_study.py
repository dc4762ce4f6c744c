"""Speed of the study machinery: one study on 1 and on 2 Dask workers, against the stages called
directly in a loop.

The study is the paper example's geometry study (data_synthetic/studies/paper_example_geometry.toml,
W, H and theta of every wall drawn, LHS) with ``--samples`` samples. The peer ("direct") draws the
same samples and calls the same build on each in this process, with the masks' traces computed
once, and reads the same outputs, as a careful script would. Printed: wall seconds of each (the clusters' start-up apart and
included), the speed-up of 2 workers over 1, and the machinery's overhead per sample over direct.

    .venv/bin/python experiments/bench_study.py [--samples 64] [--study FILE]
"""

from __future__ import annotations

import argparse
import time
import warnings
from dataclasses import replace
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def direct(study) -> float:
    """The peer: the same samples, the stages called directly (traces once), in this process."""
    import math

    from calib_masonry.pipeline import build, trace_wall
    from calib_masonry.spec import load_structure
    from calib_masonry.study.design import samples
    from calib_masonry.study.sample import build_outputs

    t0 = time.perf_counter()
    spec = load_structure(study.structure)
    traces = {w.name: trace_wall(w, spec) for w in spec.walls}
    for s in samples(study):
        walls = []
        for w in spec.walls:
            ch = {k: s.values[f"{w.name}.{k}"] for k in ("width_m", "height_m") if f"{w.name}.{k}" in s.values}
            if f"{w.name}.theta_deg" in s.values:
                ch["theta_rad"] = math.radians(s.values[f"{w.name}.theta_deg"])
            walls.append(replace(w, **ch))
        with warnings.catch_warnings(record=True):  # a sample records its warnings too
            warnings.simplefilter("always")
            r = build(spec.with_walls(tuple(walls)), traces=traces, progress=False)
        build_outputs(r)  # the same outputs a sample reads (volume, mass, centre of mass, ...)
    return time.perf_counter() - t0


def on_cluster(study, workers: int) -> tuple[float, float]:
    """Seconds of the whole study on a new LocalCluster, and of the cluster's start-up alone."""
    from calib_masonry.study.design import samples
    from calib_masonry.study.run import dask_client, execute_samples

    t0 = time.perf_counter()
    rows = []
    with dask_client(None, workers) as client:
        t_up = time.perf_counter() - t0
        execute_samples(study, samples(study), rows.append, client, progress=False)
    assert all(r["status"] == "ok" for r in rows), [r["error"] for r in rows if r["status"] != "ok"][:3]
    return time.perf_counter() - t0, t_up


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--samples", type=int, default=64)
    ap.add_argument("--study", default=str(ROOT / "data_synthetic" / "studies" / "paper_example_geometry.toml"))
    a = ap.parse_args()
    from calib_masonry.study.design import load_study

    study = replace(load_study(a.study), n=a.samples)
    n = a.samples
    t_direct = direct(study)
    t1, up1 = on_cluster(study, 1)
    t2, up2 = on_cluster(study, 2)
    print(f"study {study.name}: {n} samples")
    print(f"{'run':>22} {'wall s':>8} {'start-up s':>10} {'s/sample':>9}")
    print(f"{'direct (peer)':>22} {t_direct:>8.1f} {0.0:>10.1f} {t_direct / n:>9.3f}")
    print(f"{'study, 1 worker':>22} {t1:>8.1f} {up1:>10.1f} {(t1 - up1) / n:>9.3f}")
    print(f"{'study, 2 workers':>22} {t2:>8.1f} {up2:>10.1f} {(t2 - up2) / n:>9.3f}")
    print(
        f"speed-up 2 workers / 1 worker: {t1 / t2:.2f}x (start-up excluded: {(t1 - up1) / (t2 - up2):.2f}x; aim >= 1.7x)"
    )
    over = (t1 - t_direct) / t_direct
    over_run = (t1 - up1 - t_direct) / t_direct
    print(
        f"machinery overhead over direct calls, 1 worker: {over:+.1%} per sample "
        f"({(t1 - t_direct) / n * 1000:.0f} ms), start-up excluded {over_run:+.1%} "
        f"({(t1 - up1 - t_direct) / n * 1000:.0f} ms); aim <= 10 %"
    )


if __name__ == "__main__":
    main()

"""The paper example built from perspective photos instead of masks, compared with its truth.

For each seed (the tests and the tuning never used the defaults): `synth --photos` of the paper
example's scenario with that seed, `build` on structure_photos.toml (automatic calibration,
rectification at 300 px/m, top-hat segmentation, trace at 5 vertices, assemble), `compare` with
the truth; then where each build's time went (its summary.json's stage seconds). Twice per seed: W and H typed as in the method's Table 1, and W and H left out so that
the calibrated values (camera height given, as measured on site) are used.

    .venv/bin/python experiments/build_from_photos.py [--seeds 201 202]
"""

from __future__ import annotations

import argparse
import math
import tempfile
import time
from dataclasses import replace
from pathlib import Path

from calib_masonry.build_folder import build_to_folder
from calib_masonry.comparison import compare_dirs
from calib_masonry.spec import PhotoSpec, load_structure
from calib_masonry.synthetic.truth import synthesize_to_folder

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[201, 202])
    a = ap.parse_args()
    base = load_structure(ROOT / "data_synthetic" / "paper_example" / "scenario.toml", require_sources=False)
    print(
        f"{'seed':>5} {'W, H':>8} {'precision':>9} {'recall':>7} {'Dice min':>8} {'median':>7} {'centroid mm':>11} "
        f"{'volume':>7} {'seconds':>7}"
    )
    stages = []
    with tempfile.TemporaryDirectory() as tmp:
        for seed in a.seeds:
            spec = replace(base, synthetic=replace(base.synthetic, seed=seed))
            data = Path(tmp) / f"s{seed}"
            truth = synthesize_to_folder(spec, data, figures=False, photos=PhotoSpec(), progress=False)
            eye = {p["name"]: p["eye_height_m"] for p in truth["photos"]}
            photo_spec = load_structure(data / "structure_photos.toml")
            fitted = photo_spec.with_walls(
                tuple(
                    replace(w, width_m=math.nan, height_m=math.nan, camera_height_m=eye[w.name])
                    for w in photo_spec.walls
                )
            )
            for label, s in (("typed", photo_spec), ("fitted", fitted)):
                t0 = time.perf_counter()
                out = Path(tmp) / f"b{seed}{label}"
                summary = build_to_folder(s, out, figures=False, progress=False)
                stages.append((seed, label, summary["seconds"], time.perf_counter() - t0))
                m = compare_dirs(out, data / "truth")
                print(
                    f"{seed:>5} {label:>8} {m['precision']:>9.4f} {m['recall']:>7.4f} {m['dice']['min']:>8.4f} "
                    f"{m['dice']['median']:>7.4f} {m['centroid_error_mm']['mean']:>11.2f} "
                    f"{m['total_volume_m3']['relative_error']:>+7.2%} {time.perf_counter() - t0:>7.1f}",
                    flush=True,
                )

    names = list(dict.fromkeys(k for _, _, sec, _ in stages for k in sec))
    print("\nstage seconds per build (summary.json; the photo stage runs two photos at a time)")
    print(f"{'seed':>5} {'W, H':>8} " + " ".join(f"{n[:22]:>22}" for n in names) + f" {'whole':>7}")
    for seed, label, sec, whole in stages:
        print(f"{seed:>5} {label:>8} " + " ".join(f"{sec.get(n, 0.0):>22.2f}" for n in names) + f" {whole:>7.1f}")


if __name__ == "__main__":
    main()

"""Benchmark: automatic rectification of tall, narrow walls photographed from standing height.

Each case is a Stylite-like wall (irregular stones in courses) of a width and height drawn per
seed: 2.0-3.2 m wide and 4-6.5 times as high (aspect up to about 1:6.5, the top 8-20 m above the
camera), photographed by the synthetic camera (eye 1.5-1.8 m, 24-32 mm, yaw up to 35 degrees,
portrait). Automatic mode: no clicks; the focal length from EXIF and the eye height are given, as
the issue's user would. A case succeeds when the fit converges and W and H are within 2 % of the
truth. Printed: a row per photo and the success rate; a failure's one-line message in full, and
for a fit that converged outside 2 % the advice the calibration gives its user (the flag to add).

Seeds: 9001-9020 were used while fixing the detection, 9101-9120 and 9201-9220 to check it (and
then to fix what they showed); 9301-9320 (the default) were the set to report. Since then every
set up to 9901-9920 has been looked at while changing the detection, so each new change is
measured on sets never run before: 10001-10020 and 10101-10120 for the restart from the joints'
colours (17 and 16 of 20; all eleven sets, 220 photos: 190, 86 %); 10201-10220 and 10301-10320
for the block-mean shrink of the working image (17 and 17 of 20; the eleven sets again 190);
10401-10520 gave 17 and 14 of 20, 10601-10620 18 of 20.

2026-11-26, free wall ends as jambs (synthetic/layouts.py): the end stones used to stand 0-1.5 cm
inside the wall's end, behind a strip of mortar a pale sky hides, so every detected side lay
half a pixel inside the true one and W and H came out 0.3-2 % high (tall_wall_corners.py). With
the detection unchanged: sets never run before, 10701, 10801, 10901, 11001: 20, 20, 19, 19 of 20
(78 of 80, 97.5 %); the seventeen sets run before, 9001-10601: 318 of 340 (93.5 %), none below
17 of 20. Every failure names a flag (22 of 22). Then the first course bedded on the base line
(a mortar wedge under it tilted the detected base) and corners the joints contradict refused
(4a7653e): sets never run before, 11301-11601: 20, 20, 20, 18 of 20 (78 of 80); the 23 sets
9001-11201: 447 of 460 (97.2 %), 18-20 a set; every failure names a flag; the successes' larger
error of W and H median 0.19 %, largest 1.68 %.

    .venv/bin/python experiments/bench_tall_walls.py [--first 9301 --count 20] [--seeds ...]
"""

from __future__ import annotations

import argparse
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def case(seed: int):
    """A tall wall of this seed, its photo (an in-memory Photo) and the truth."""
    import calib_masonry as cm
    from calib_masonry.spec import PhotoSpec
    from calib_masonry.synthetic.photo import photograph_wall

    rng = np.random.default_rng(seed)
    width = float(rng.uniform(2.0, 3.2))
    height = float(width * rng.uniform(4.0, 6.5))
    base = cm.load_structure(ROOT / "data_synthetic" / "stylite" / "scenario.toml", require_sources=False)
    wall = replace(base.walls[0], name=f"tall{seed}", width_m=width, height_m=height)
    scenario = replace(base, walls=(wall,), closed=False, synthetic=replace(base.synthetic, seed=seed))
    pieces, _ = cm.truth_structure(scenario)
    shot = photograph_wall(wall, pieces[0], PhotoSpec(), rng)
    photo = cm.Photo(
        path=Path(f"tall wall seed {seed}"),
        rgb=shot["image"],
        focal_px=shot["truth"]["params"]["focal_px"],
        heading_deg=None,
    )
    return wall, photo, shot["truth"]


def automatic(truth: dict):
    """The calibration's configuration for a case: automatic mode, the eye height given (to 2 cm)
    and the focal length from the photo's EXIF, as the issue's user would run it."""
    import calib_masonry as cm

    return cm.CalibrateConfig(camera_height_m=truth["eye_height_m"], camera_height_sigma_m=0.02)


def main() -> None:
    import calib_masonry as cm
    from calib_masonry.errors import CalibMasonryError

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--first", type=int, default=9301)
    ap.add_argument("--count", type=int, default=20)
    ap.add_argument("--seeds", type=int, nargs="*")
    a = ap.parse_args()
    seeds = a.seeds or list(range(a.first, a.first + a.count))
    print(
        f"{'seed':>5} {'W m':>6} {'H m':>6} {'aspect':>6} {'yaw':>6} {'dist m':>6} {'W err':>7} {'H err':>7} {'s':>5}  result"
    )
    ok = flagged = 0
    for seed in seeds:
        wall, photo, truth = case(seed)
        t0 = time.perf_counter()
        try:
            cal = cm.calibrate_photo(photo, automatic(truth))
            res = cal.result
            ew = res.width_m / wall.width_m - 1
            eh = res.height_m / wall.height_m - 1
            good = res.status.value == "converged" and abs(ew) <= 0.02 and abs(eh) <= 0.02
            msg = "ok" if good else f"FAIL ({res.status.value}, W {res.width_m:.3f} H {res.height_m:.3f})"
            if not good and cal.advice():  # what the calibration itself tells its user
                msg += f": {cal.advice()}"
            ew_s, eh_s = f"{ew:+.2%}", f"{eh:+.2%}"
        except CalibMasonryError as exc:
            good, msg, ew_s, eh_s = False, f"FAIL: {exc}", "-", "-"
        ok += good
        flagged += not good and "--" in msg
        print(
            f"{seed:5d} {wall.width_m:6.2f} {wall.height_m:6.2f} {wall.height_m / wall.width_m:6.2f} "
            f"{truth['yaw_deg']:6.1f} {truth['distance_m']:6.1f} {ew_s:>7} {eh_s:>7} {time.perf_counter() - t0:5.1f}  {msg}"
        )
    print(f"automatic mode on tall walls: {ok} of {len(seeds)} succeeded ({ok / len(seeds):.0%}; aim >= 90 %)")
    print(f"failures whose message names the flag to add: {flagged} of {len(seeds) - ok}")


if __name__ == "__main__":
    main()

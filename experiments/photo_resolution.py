"""Experiment: does the automatic calibration give the same wall at every photo size?

A user's camera has 12-48 MP; the laboratory photos of data_external/real_photos are 594 x 891 px.
Each real photo is resampled to k times its pixels (Lanczos, saved as a JPEG of quality 92, as a
finer sensor would have taken the same scene; it adds no detail, so anything that changes with k
is the code's own dependence on the pixel size; k = 1 is the photo itself, not saved again) and
calibrated automatically with its width given. Printed per photo and size: H, its sigma, the error, the error in sigmas (z), the base
corners' sigma (px of the photo's own size: about 10 where the shaded base was carried across its
ramp, 0.2-4 where it was not), and the seconds.

    .venv/bin/python experiments/photo_resolution.py [--scales 1 2 3 4 6 8] [--truth data_external/real_photos/truth.json]

Measured 2026-12-04 (docs/photo_path.md, "The photo's size"; before: the same command with
`lines.SOFT_NOISE = 0`, `SOFT_WORK_PX = 1e9`): at 2-8 times their pixels the three photos gave H
-1.3 to -10.6 %, the truth within 2 sigma in 2 of the 15 (SC4 at 6 times: -10.6 % with a sigma
of 0.6 %, 14.9 sigma off). After: SC1 and SC2 at every size within 1.5 sigma (-5.2 to -1.3 %),
15 of the 18 within 2 sigma; SC4 at 3 and 6 times as at its own size (-4 %), at 2, 4 and 8 times
-7.7 to -8.2 % with a sigma of 1.7-1.9 % (3.6-4.4 sigma): a lens kept from its loading beam's
bow. Mended the next session (`fit.PLUMB_STRAIGHTNESS`, a line straight to L/500; before: the
same command with it 0): 18 of 18 within 2 sigma, SC4 -3.7 to -5.3 % at every size.
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "data_external" / "real_photos"


def main() -> None:
    from PIL import Image

    import calib_masonry as cm
    from calib_masonry.errors import CalibMasonryError

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scales", type=float, nargs="+", default=[1, 2, 3, 4, 6, 8])
    ap.add_argument("--truth", default=str(DATA / "truth.json"))
    a = ap.parse_args()
    truth_path = Path(a.truth)
    photos = json.loads(truth_path.read_text())["photos"]
    print(f"{'photo':>6} {'k':>4} {'px':>11} {'H m':>6} {'+-':>6} {'err':>7} {'z':>5} {'base sigma px':>14} {'s':>5}")
    with tempfile.TemporaryDirectory() as tmp:
        for t in photos:
            src = truth_path.parent / t["photo"]
            with Image.open(src) as im:
                im.load()
                for k in a.scales:
                    size = (round(k * im.width), round(k * im.height))
                    path = src  # the photo itself at its own size
                    if k != 1:
                        path = Path(tmp) / f"{t['wall']}_x{k:g}.jpg"
                        im.resize(size, Image.LANCZOS).save(path, quality=92)
                    t0 = time.perf_counter()
                    try:
                        cal = cm.calibrate_photo(path, cm.CalibrateConfig(known_width_m=t["width_m"]))
                    except CalibMasonryError as exc:
                        print(f"{t['wall']:>6} {k:>4g} {size[0]:>5}x{size[1]:<5} refused: {exc}")
                        continue
                    res = cal.result
                    err = res.height_m - t["height_m"]
                    z = err / res.sigma("height_m")
                    base = np.asarray(cal.corner_sigma_px[:2]) / k
                    print(
                        f"{t['wall']:>6} {k:>4g} {size[0]:>5}x{size[1]:<5} {res.height_m:6.3f} {res.sigma('height_m'):6.3f} "
                        f"{100 * err / t['height_m']:+6.2f}% {z:+5.1f} {base[0]:6.1f} {base[1]:6.1f}  "
                        f"{time.perf_counter() - t0:5.1f}",
                        flush=True,
                    )


if __name__ == "__main__":
    main()

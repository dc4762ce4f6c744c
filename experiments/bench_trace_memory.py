"""Benchmark: peak memory of tracing a 12,000 x 12,000 mask, against a naive peer in the same run.

The mask is the shared SWAT stone mask (real stone outlines, 60-150 px across) tiled to the size
asked for. Each side runs in its own process, and its peak resident memory (``ru_maxrss``) is read
at the end:

- ours: ``calib-masonry trace MASK --out polygons.json`` as a user runs it (figure included);
- peer: the textbook route with scikit-image: the image as float64, normalised, thresholded,
  ``skimage.measure.label`` and ``regionprops``, and ``find_contours`` on every region's crop.

    .venv/bin/python experiments/bench_trace_memory.py [--size 12000]
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from PIL import Image

ROOT = Path(__file__).resolve().parents[1]
SWAT = ROOT.parent / "shared" / "data" / "external" / "swat" / "WR2_250_new.png"

OURS = """
import resource, sys
from calib_masonry.cli import main
rc = main(["trace", sys.argv[1], "--out", sys.argv[2]])
print(rc, resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)
"""

PEER = """
import resource, sys
import numpy as np
from PIL import Image
from skimage.measure import find_contours, label, regionprops
Image.MAX_IMAGE_PIXELS = None
a = np.asarray(Image.open(sys.argv[1]), dtype=np.float64)
a = (a - a.min()) / (a.max() - a.min())
labels = label(a >= 0.5, connectivity=1)
n = 0
for r in regionprops(labels):
    n += len(find_contours(np.pad(r.image, 1).astype(float), 0.5)) > 0
print(n, resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)
"""


def tiled_mask(size: int, path: Path) -> None:
    tile = np.asarray(Image.open(SWAT).convert("L"))
    reps = (-(-size // tile.shape[0]), -(-size // tile.shape[1]))
    Image.fromarray(np.tile(tile, reps)[:size, :size]).save(path)


def peak(code: str, *args: str) -> tuple[float, float, str]:
    t0 = time.perf_counter()
    r = subprocess.run([sys.executable, "-c", code, *args], capture_output=True, text=True)
    if r.returncode != 0:
        raise SystemExit(f"run failed: {r.stderr.strip().splitlines()[-1]}")
    first, kb = r.stdout.strip().splitlines()[-1].split()
    return int(kb) * 1024, time.perf_counter() - t0, first


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=12000, help="mask side in px (default 12000)")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        mask = Path(tmp) / "mask.png"
        tiled_mask(args.size, mask)
        px = args.size**2
        ours, t_ours, _ = peak(OURS, str(mask), str(Path(tmp) / "polygons.json"))
        peer, t_peer, n = peak(PEER, str(mask))
    print(f"mask {args.size} x {args.size} px ({px / 1e6:.0f} MP), tiled from {SWAT.name}, {n} stones (peer)")
    print(f"{'':>6} {'peak GB':>8} {'B/px':>6} {'s':>6}")
    print(f"{'ours':>6} {ours / 1e9:8.2f} {ours / px:6.1f} {t_ours:6.1f}   calib-masonry trace (figure included)")
    print(
        f"{'peer':>6} {peer / 1e9:8.2f} {peer / px:6.1f} {t_peer:6.1f}   float64 + skimage label/regionprops/find_contours"
    )
    print(f"peak memory ratio ours / peer: {ours / peer:.2f} (aim: ours below 2.5 GB at 12,000 px)")


if __name__ == "__main__":
    main()

"""Line segments and quadrilaterals in an image: lines through segments, distances to vanishing
points, a vanishing point by RANSAC, the pixels inside a convex quadrilateral, an image shrunk.
The primitives that the joint-line detection (:mod:`~calib_masonry.calibrate.lines`) and the
wall's outline (:mod:`~calib_masonry.calibrate.outline`) share; imports neither."""

from __future__ import annotations

import numpy as np

from ..errors import FitFailed
from .camera import CORNERS_FLAG


def lines_through(seg: np.ndarray) -> np.ndarray:
    p1 = np.c_[seg[:, :2], np.ones(len(seg))]
    p2 = np.c_[seg[:, 2:], np.ones(len(seg))]
    ln = np.cross(p1, p2)
    return ln / np.linalg.norm(ln[:, :2], axis=1, keepdims=True)


def dist_to_vp(seg: np.ndarray, vp: np.ndarray) -> np.ndarray:
    """Distance of each segment's endpoints from the line through its midpoint and ``vp``."""
    return dist_to_vps(seg, np.asarray(vp)[None])[0]


def dist_to_vps(seg: np.ndarray, vps: np.ndarray) -> np.ndarray:
    """:func:`dist_to_vp` of every segment from each of the points ``vps`` ``(k, 3)``: ``(k, n)``."""
    mid = (seg[:, :2] + seg[:, 2:]) / 2
    d = seg[:, 2:] - seg[:, :2]
    to = vps[:, None, :2] - mid[None] * vps[:, None, 2:3]
    cross = d[:, 0] * to[..., 1] - d[:, 1] * to[..., 0]
    return 0.5 * np.abs(cross) / (np.linalg.norm(to, axis=-1) + 1e-300)


def vanishing_point(
    seg: np.ndarray, tol: float, ransac_iterations: int, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray]:
    """RANSAC + weighted least squares. Returns (vp, inlier mask); coordinates as given."""
    if len(seg) < 3:
        raise FitFailed("automatic mode: too few joint lines found to locate a vanishing point")
    lines = lines_through(seg)
    length = np.hypot(seg[:, 2] - seg[:, 0], seg[:, 3] - seg[:, 1])
    prob = length / length.sum()
    # the hypotheses drawn one at a time (the random stream of a loop that scored each in turn),
    # then scored together; each score is summed as that loop summed it, so the first of the best
    # is the same hypothesis, to the bit
    pairs = [rng.choice(len(seg), size=2, replace=False, p=prob) for _ in range(ransac_iterations)]
    pairs = np.array(pairs, dtype=np.intp).reshape(-1, 2)
    vps = np.cross(lines[pairs[:, 0]], lines[pairs[:, 1]])
    valid = np.all(np.isfinite(vps), axis=1) & (np.linalg.norm(vps, axis=1) != 0)
    if not valid.any():
        raise FitFailed(
            f"automatic mode: no two joint lines meet in a vanishing point; click the corners with {CORNERS_FLAG}"
        )
    scores = np.full(len(vps), -1.0)
    for k0 in range(0, len(vps), 64):  # 64 hypotheses at a time: (64, segments, 2) temporaries
        inliers = dist_to_vps(seg, vps[k0 : k0 + 64]) < tol
        for k, m in enumerate(inliers, start=k0):
            if valid[k]:
                scores[k] = float(length[m].sum())
    best = vps[int(np.argmax(scores))]
    inl = dist_to_vp(seg, best) < tol
    for _ in range(3):
        w = np.sqrt(length[inl])
        m = lines[inl] * w[:, None]
        # vt alone (its last row, the null vector): the full U of thousands of segments is
        # (n, n), 0.23 s for 3,000; with fewer rows than three the full vt holds the null vector
        _, _, vt = np.linalg.svd(m, full_matrices=len(m) < 3)
        vp = vt[-1]
        inl = dist_to_vp(seg, vp) < tol
    return vp, inl


def near_heads(horiz: np.ndarray, heads: np.ndarray) -> np.ndarray:
    """The horizontal segments in the region the head joints cover (their densest run across,
    their extent up and down, a tenth more each way), where the bed vanishing point is sought: a
    textured ground or paving below the wall has long, near-horizontal lines of its own that can
    outvote the bed joints (a tall wall's bed joints were lost to them, measured). All of them when
    that region holds fewer than eight."""
    if len(heads) < 4:
        return horiz
    mid_h = (heads[:, :2] + heads[:, 2:]) / 2
    x0, x1 = densest_run(mid_h[:, 0], np.hypot(heads[:, 2] - heads[:, 0], heads[:, 3] - heads[:, 1]))
    y0, y1 = np.min(heads[:, [1, 3]]), np.max(heads[:, [1, 3]])
    mx, my = 0.1 * (x1 - x0), 0.1 * (y1 - y0)
    mid = (horiz[:, :2] + horiz[:, 2:]) / 2
    keep = (mid[:, 0] > x0 - mx) & (mid[:, 0] < x1 + mx) & (mid[:, 1] > y0 - my) & (mid[:, 1] < y1 + my)
    return horiz[keep] if keep.sum() >= 8 else horiz


def densest_run(pos: np.ndarray, weight: np.ndarray, trim: float = 0.015) -> tuple[float, float]:
    """The extent of the heaviest run of ``pos`` (no gap wider than 12 % of the spread), with
    ``trim`` of its total weight cut from either end: a stray short segment beyond the wall's edge
    is dropped, the wall's long outline edge is kept."""
    order = np.argsort(pos)
    p, w = pos[order], weight[order]
    spread = np.percentile(p, 95) - np.percentile(p, 5)
    gap = max(0.12 * spread, 1e-9)
    best, best_w, start = (0, 1), -1.0, 0
    for k in range(1, len(p) + 1):
        if k == len(p) or p[k] - p[k - 1] > gap:
            total = float(w[start:k].sum())
            if total > best_w:
                best, best_w = (start, k), total
            start = k
    p, w = p[best[0] : best[1]], w[best[0] : best[1]]
    cum = np.cumsum(w) / w.sum()
    lo = int(np.searchsorted(cum, trim, side="right"))
    hi = int(np.searchsorted(cum, 1.0 - trim, side="left"))
    return float(p[min(lo, len(p) - 1)]), float(p[min(max(hi, lo), len(p) - 1)])


#: an edge this strong, relative to the strongest across a side's profile, counts as the outline


def inside_convex(shape: tuple[int, int], quad: np.ndarray) -> np.ndarray:
    """``(rows, cols)`` True at the pixel centres inside the convex quadrilateral ``quad`` (4, 2):
    each row's run between the sides' crossings, so the cost is a row's, not a point test per
    pixel (matplotlib's ``contains_points`` on every pixel, which this replaces, took a third of
    the colour model's time; the two differ only for a centre exactly on a side)."""
    rows, cols = shape
    y = np.arange(rows, dtype=np.float64)[:, None]
    a, b = quad, np.roll(quad, -1, axis=0)
    dy = b[:, 1] - a[:, 1]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (y - a[:, 1]) / dy  # (rows, 4): where each side's line crosses the row
        x = a[:, 0] + t * (b[:, 0] - a[:, 0])
    crosses = (dy != 0) & (t >= 0) & (t <= 1)
    lo = np.where(crosses, x, np.inf).min(axis=1)
    hi = np.where(crosses, x, -np.inf).max(axis=1)
    xs = np.arange(cols, dtype=np.float64)[None, :]
    return (xs > lo[:, None]) & (xs < hi[:, None])


def shrink(img: np.ndarray, s: float) -> np.ndarray:
    """An image (rows, cols[, channels]) shrunk by ``s`` (< 1; else returned as it is) to ``round(shape * s)``,
    antialiased, on scikit-image's ``rescale`` grid (output pixel ``o`` samples the input at
    ``(o + 0.5) * n / n_out - 0.5``), its float type kept.

    OpenCV's area average (``INTER_AREA``: each output pixel the mean of the input it covers, on
    that grid): within 0.003 on average (0.09 at the sharpest edges) of the block mean and Gaussian
    this replaced, and 5-20 times faster (10 against 69 ms a channel of a 3000 x 2000 photo taken
    to 1400 px, measured)."""
    import cv2

    if s >= 1:
        return img
    shape = np.array(img.shape[:2])
    rows, cols = (int(v) for v in np.maximum(np.round(shape * s), 1))
    dtype = img.dtype if img.dtype in (np.float32, np.float64) else np.float64
    return cv2.resize(np.ascontiguousarray(img, dtype=dtype), (cols, rows), interpolation=cv2.INTER_AREA)

"""Automatic mode: find the wall's outline and its mortar-joint lines in a photo.

1. Line segments: Canny edges and a probabilistic Hough transform (scikit-image) on a copy of the
   photo shrunk to ``work_long_side_px``.
2. Two families: roughly horizontal segments (bed joints, the wall's top and base) and roughly
   vertical ones (head joints, the wall's ends). For each family a vanishing point by RANSAC over
   segment pairs (inlier: both endpoints within ``vp_inlier_px`` of the line from the segment's midpoint to
   the candidate), refined by
   weighted least squares over the inliers.
3. A projective map that sends both vanishing points to infinity makes bed joints horizontal and
   head joints vertical. There the wall is an axis-aligned rectangle: its ends are the outermost
   head-family segments of the densest run, its top and base the outermost bed-family segments
   within those ends (the horizon, which also points at the bed vanishing point, lies outside them).
4. Each side of that quadrilateral is refined in the full-size photo: colour-gradient maxima on
   profiles across the side, a robust line fit, and the corners as intersections of adjacent sides.

The result gives the fit its four corners and every joint segment inside the wall.
"""

from __future__ import annotations

import math
import weakref
from dataclasses import dataclass, field

import numpy as np
from scipy import ndimage

from ..errors import FitFailed
from .camera import CORNERS_FLAG, order_corners
from .outline import OutlineConfig
from .segments import (
    dist_to_vp,
    shrink,
)

__all__ = ["DetectConfig", "Detection", "detect_wall", "refine_quad", "segments_in_quad"]


@dataclass(frozen=True)
class DetectConfig:
    work_long_side_px: int = 1400
    canny_sigma: float = 1.2
    min_length_px: int = 12  # at the working size
    line_gap_px: int = 4
    hough_threshold: int = 8
    horizontal_max_deg: float = 45.0
    vertical_max_deg: float = 30.0
    vp_inlier_px: float = 1.0  # endpoint distance from the line to the vanishing point, working px
    ransac_iterations: int = 400
    ridge_sigma_px: float = 0.0  # > 0: segments of joint centre lines (Hessian ridges at this scale) instead of edges
    refine_halfwidth_px: float | None = None  # full-size px of the coarse pass; default 6 working px
    seed: int = 0
    segments: str = "lsd"  # the fit's joint segments: "hough" (Canny + Hough, refitted) or "lsd"
    outline: OutlineConfig = field(default_factory=OutlineConfig)

    def __post_init__(self) -> None:
        if self.segments not in ("hough", "lsd"):
            raise ValueError(f"DetectConfig.segments = {self.segments!r}: choose 'hough' or 'lsd'")


@dataclass(frozen=True)
class Detection:
    corners_px: np.ndarray  # (4, 2) LL, LR, UR, UL in full-size pixels
    bed_segments: np.ndarray  # (n, 4)
    head_segments: np.ndarray  # (m, 4)
    vp_bed: np.ndarray  # homogeneous, full-size pixels
    vp_head: np.ndarray
    n_segments: int
    corner_sigma_px: np.ndarray | None = None  # (4,) from the edge evidence of the sides
    # every segment inside the outline, whatever its direction (an end face's courses among them)
    segments: np.ndarray | None = field(default=None, repr=False, compare=False)
    # where a side bowed (a lens, or a shadow's edge along part of it) and the corners were put on
    # its tangents: the corners and sigmas of straight sides, for a fit that finds no lens
    straight: tuple[np.ndarray, np.ndarray] | None = field(default=None, repr=False, compare=False)


def _edge_points(gray: np.ndarray, cfg: DetectConfig) -> tuple[np.ndarray, np.ndarray]:
    """Canny edge pixels and their sub-pixel positions (the gradient-magnitude peak across each
    pixel, a parabola through three samples along the gradient)."""
    from skimage.feature import canny

    edges = canny(gray, sigma=cfg.canny_sigma, low_threshold=0.03, high_threshold=0.08)
    sm = ndimage.gaussian_filter(gray, cfg.canny_sigma)
    gx, gy = ndimage.sobel(sm, axis=1), ndimage.sobel(sm, axis=0)
    return edges, _subpixel(edges, np.hypot(gx, gy), gx, gy)


def _subpixel(points: np.ndarray, strength: np.ndarray, nx: np.ndarray, ny: np.ndarray) -> np.ndarray:
    """Sub-pixel positions (rows, cols, 2) of ``points``: the peak of ``strength`` along (nx, ny)."""
    ey, ex = np.nonzero(points)
    ux, uy = nx[ey, ex], ny[ey, ex]
    nn = np.hypot(ux, uy) + 1e-12
    ux, uy = ux / nn, uy / nn
    m0 = strength[ey, ex]
    mp = ndimage.map_coordinates(strength, [ey + uy, ex + ux], order=1, mode="nearest")
    mm = ndimage.map_coordinates(strength, [ey - uy, ex - ux], order=1, mode="nearest")
    den = mm - 2 * m0 + mp
    delta = np.clip(np.where(den < -1e-12, 0.5 * (mm - mp) / np.where(den < -1e-12, den, -1.0), 0.0), -0.5, 0.5)
    sub = np.zeros(points.shape + (2,))
    sub[ey, ex, 0] = ex + delta * ux
    sub[ey, ex, 1] = ey + delta * uy
    return sub


def hessian_rc(gray: np.ndarray, sigma: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The Hessian ``(H_rr, H_rc, H_cc)`` of ``gray`` smoothed at ``sigma`` (a Gaussian, edges
    zero beyond, 4 sigma wide), by central differences: the arithmetic of scikit-image's
    ``hessian_matrix(order="rc", use_gaussian_derivatives=False)``, value for value on a float
    image (the working image always is; scikit-image would rescale an integer one to [0, 1]). Its
    ``skimage.feature`` imports ``scipy.stats``, 0.3 s of a rectify's start (measured) for one
    filter and two gradients."""
    img = np.asarray(gray)
    img = img.astype(np.float64 if img.dtype.kind != "f" else img.dtype, copy=False)
    smooth = ndimage.gaussian_filter(img, sigma, mode="constant", cval=0.0, truncate=4.0)
    gr, gc = np.gradient(smooth)
    return np.gradient(gr, axis=0), np.gradient(gr, axis=1), np.gradient(gc, axis=1)


def hessian_eigvals(hrr: np.ndarray, hrc: np.ndarray, hcc: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The two eigenvalues ``(l1 >= l2)`` of each pixel's symmetric 2 x 2 Hessian (scikit-image's
    explicit formula of ``hessian_matrix_eigvals``)."""
    mean = (hrr + hcc) / 2
    half = np.sqrt(hrc**2 + ((hrr - hcc) / 2) ** 2)
    return mean + half, mean - half


def _ridge_points(gray: np.ndarray, sigma: float) -> tuple[np.ndarray, np.ndarray]:
    """Centre lines of thin light or dark lines (mortar joints): Hessian ridge strength at scale
    ``sigma``, non-maximum suppression across the ridge, sub-pixel peaks. A joint's centre line is
    not displaced by blur the way its two edges are (they spread apart where the joint narrows with
    distance, which tilts each edge towards the image axes)."""
    hrr, hrc, hcc = hessian_rc(gray, sigma)
    l1, l2 = hessian_eigvals(hrr, hrc, hcc)  # l1 >= l2
    best = None
    for strength, lam in ((np.maximum(-l2, 0), l2), (np.maximum(l1, 0), l1)):  # light, dark lines
        # eigenvector of lam: across the ridge, (x, y) = (col, row)
        vx, vy = hrc, lam - hrr
        small = np.hypot(vx, vy) < 1e-12
        vx, vy = np.where(small, lam - hcc, vx), np.where(small, hrc, vy)
        nn = np.hypot(vx, vy) + 1e-12
        vx, vy = vx / nn, vy / nn
        rows, cols = gray.shape
        yy, xx = np.mgrid[0:rows, 0:cols]
        sp = ndimage.map_coordinates(strength, [yy + vy, xx + vx], order=1, mode="nearest")
        sm = ndimage.map_coordinates(strength, [yy - vy, xx - vx], order=1, mode="nearest")
        thr = 0.25 * np.percentile(strength, 99.5)
        peak = (strength >= sp) & (strength > sm) & (strength > thr)
        score = float(strength[peak].sum())
        if best is None or score > best[0]:
            best = (score, peak, strength, vx, vy)
    _, peak, strength, vx, vy = best
    return peak, _subpixel(peak, strength, vx, vy)


def _hough_segments(gray: np.ndarray, cfg: DetectConfig, *, ridges: bool = False) -> np.ndarray:
    """Hough segments of edge (or ridge) pixels, each re-fitted (total least squares) to the
    sub-pixel points along it. The Hough transform quantises a segment's angle to its accumulator's
    1 degree bins and integer pixels pull near-axis lines towards the axes; the refit removes both
    biases, which the vanishing points and the joint-line residuals would inherit."""
    from skimage.transform import probabilistic_hough_line

    points, sub = _ridge_points(gray, cfg.ridge_sigma_px) if ridges else _edge_points(gray, cfg)
    segs = probabilistic_hough_line(
        points, threshold=cfg.hough_threshold, line_length=cfg.min_length_px, line_gap=cfg.line_gap_px, rng=cfg.seed
    )
    out = []
    rows, cols = points.shape
    for (x0, y0), (x1, y1) in segs:
        lo0, lo1 = max(min(x0, x1) - 3, 0), max(min(y0, y1) - 3, 0)
        hi0, hi1 = min(max(x0, x1) + 4, cols), min(max(y0, y1) + 4, rows)
        yy, xx = np.nonzero(points[lo1:hi1, lo0:hi0])
        pts = sub[yy + lo1, xx + lo0]
        px, py = pts[:, 0], pts[:, 1]
        ax, ay, bx, by = float(x0), float(y0), float(x1), float(y1)
        length = math.hypot(bx - ax, by - ay)
        # re-select the points near the current line and refit, three times: points picked in the
        # band of the Hough line alone would pull the fit back towards its quantised angle. The fit
        # is total least squares: the principal axis of the points' 2 x 2 scatter, in closed form
        # (a Python loop over a thousand segments; numpy's SVD per segment took twice as long)
        for _ in range(3):
            n = math.hypot(bx - ax, by - ay)
            dx, dy = (bx - ax) / n, (by - ay) / n
            rx, ry = px - ax, py - ay
            along = rx * dx + ry * dy
            near = (np.abs(ry * dx - rx * dy) <= 1.0) & (along >= -0.5) & (along <= length + 0.5)
            k = int(np.count_nonzero(near))
            if k < max(5, 0.6 * length):
                break
            qx, qy = px[near], py[near]
            cx, cy = float(qx.sum()) / k, float(qy.sum()) / k  # mean()'s very bits, a tenth of its overhead
            qx, qy = qx - cx, qy - cy
            sxx, syy, sxy = float(qx @ qx), float(qy @ qy), float(qx @ qy)
            t = 0.5 * math.atan2(2.0 * sxy, sxx - syy)
            ex, ey = math.cos(t), math.sin(t)
            if ex * dx + ey * dy < 0:
                ex, ey = -ex, -ey
            ta, tb = (ax - cx) * ex + (ay - cy) * ey, (bx - cx) * ex + (by - cy) * ey
            ax, ay, bx, by = cx + ta * ex, cy + ta * ey, cx + tb * ex, cy + tb * ey
        out.append([ax, ay, bx, by])
    return np.array(out, dtype=np.float64).reshape(-1, 4)


OUTER_EDGE_FRACTION = 0.35
#: a base of the outline that turns more than this from the bed joints' vanishing point is sought
#: again (:func:`base_off_shadow`)
SIDE_TURN_RAD = math.radians(1.0)
#: and the corner it moves goes at most this fraction of the wall's extent along the side it moves
#: on (a cast shadow's far edge below a base: 1.2-1.5 % of the height on Blender-rendered walls;
#: a stone wall's courses 14 degrees off a laboratory photo's base asked for 25 %)
SIDE_MOVE_FRACTION = 0.03
#: where the base turns more than this, up to this fraction: a base held at one end by an end
#: face's foot and at the other by a long shadow's far edge turned 8-14 degrees and asked for
#: 3.1-5.1 % (Blender-rendered walls 12102-12140); a turn of 2 degrees is a vanishing point a
#: stone wall's courses leave that uncertain (an augmented laboratory view, whose base went 4.4 %
#: up into the wall)
STEEP_TURN_RAD = math.radians(5.0)
STEEP_MOVE_FRACTION = 0.06
#: the line :func:`base_in_pencil` finds is snapped to the photo's edge within this many px of it
PENCIL_SNAP_PX = 1.5
#: and steps along most of the base by at least this much (the median step of colour, RGB of 1,
#: between samples half a pixel apart): a flat ground has none
PENCIL_MIN_STEP = 0.01


#: the outline's edges are sought on the photo blurred by this sigma (px)
_SIDE_BLUR_PX = 0.7


def _blurred_samples(
    rgb: np.ndarray, rows: np.ndarray, cols: np.ndarray, *, gray: bool = False, blur_px: float = _SIDE_BLUR_PX
) -> np.ndarray:
    """The photo ``(R, C, 3)`` blurred by ``blur_px`` (default :data:`_SIDE_BLUR_PX`) and sampled
    bilinearly (nearest pixel beyond the edges) at the points ``rows``, ``cols`` ``(n,)``: ``(n, 3)``;
    with ``gray``, its channels' mean (in float32, as ``rgb.mean(axis=-1)`` makes it) blurred and
    sampled: ``(n,)``.

    Only the crop the points need is blurred, padded by the kernel's radius, so every sample is
    exactly (bit for bit) what blurring the whole photo would give, at a fraction of the cost (a
    6 MP photo's blur took 0.4 s for four thin bands along its outline; the whole photo's grey,
    0.12 s of every outline's soft sides)."""
    radius = int(4.0 * blur_px + 0.5) + 1  # scipy's kernel radius (truncate 4), and one more
    n_rows, n_cols = rgb.shape[:2]
    # the pixels the samples read (a point beyond an edge reads that edge's pixels), and the
    # kernel's reach around them
    r = np.clip([rows.min(), rows.max()], 0, n_rows - 1)
    c = np.clip([cols.min(), cols.max()], 0, n_cols - 1)
    lo_r, hi_r = max(0, int(r[0]) - radius), min(n_rows, int(r[1]) + 2 + radius)
    lo_c, hi_c = max(0, int(c[0]) - radius), min(n_cols, int(c[1]) + 2 + radius)
    crop = np.asarray(rgb[lo_r:hi_r, lo_c:hi_c, :3], dtype=np.float32)
    # a point beyond the photo's edge has the crop reach that edge, where "nearest" extends it
    # as it extends the whole photo
    coords = [rows - lo_r, cols - lo_c]
    if gray:  # the mean's own arithmetic: the three summed in order, then divided (the same bits)
        g = crop[..., 0] + crop[..., 1]
        g += crop[..., 2]
        g /= np.float32(3)
        g = ndimage.gaussian_filter(g, blur_px)
        return ndimage.map_coordinates(g, coords, order=1, mode="nearest")
    crop = ndimage.gaussian_filter(crop, (blur_px, blur_px, 0))
    return np.stack([ndimage.map_coordinates(crop[..., k], coords, order=1, mode="nearest") for k in range(3)], -1)


def _strong_edges(grad: np.ndarray, floor: float = 0.0) -> np.ndarray:
    """``(n, m)`` True at the strong edges of each profile of colour steps ``grad`` ``(n, m)``: its
    local maxima of at least :data:`OUTER_EDGE_FRACTION` of the profile's largest step and
    ``floor``."""
    peak = np.zeros_like(grad, dtype=bool)
    peak[:, 1:-1] = (grad[:, 1:-1] >= grad[:, :-2]) & (grad[:, 1:-1] >= grad[:, 2:])
    return peak & (grad >= np.maximum(OUTER_EDGE_FRACTION * grad.max(axis=1, keepdims=True), floor))


def _refine_side(
    rgb: np.ndarray,
    a: np.ndarray,
    b: np.ndarray,
    half: float,
    *,
    points: list | None = None,
    to_photo=None,
    inner: bool = False,
    strongest: bool = False,
) -> tuple[np.ndarray, np.ndarray] | None:
    """Sub-pixel line (point, direction) of the strongest colour edge along the side a-b (the edge
    points it was fitted to appended to ``points``, when given): of the strong edges across each
    profile, the outermost, or with ``inner`` the innermost, or with ``strongest`` the strongest.
    ``to_photo``: a map of ideal image points ``(..., 2)`` to the photo's (a lens): the side is then
    straight in ideal coordinates and the photo is sampled where the lens put each of its points."""
    length = float(np.linalg.norm(b - a))
    # a search narrower than the profiles' half-pixel step holds no edge (--snap-tolerance 0.01
    # ended in a traceback from an empty profile)
    if length < 10 or half < 0.5:
        return None
    n = side_normal(a, b)
    ts = np.linspace(0.08, 0.92, max(20, int(length / 6)))
    offs = np.arange(-half, half + 0.25, 0.5)
    pts = a[None, None, :] + ts[:, None, None] * (b - a)[None, None, :] + offs[None, :, None] * n[None, None, :]
    if to_photo is not None:
        pts = to_photo(pts.reshape(-1, 2)).reshape(pts.shape)
    prof = _blurred_samples(rgb, pts[..., 1].ravel(), pts[..., 0].ravel()).reshape(len(ts), len(offs), 3)
    grad = np.linalg.norm(np.diff(prof, axis=1), axis=-1)  # between samples
    # the outermost strong edge (the sides run LL, LR, UR, UL, so +n points out of the wall): a
    # mortar strip along the outline has a weaker edge to the background than to the stones
    # inside, and the strongest edge would put the side on the stones (1-3 px in, measured)
    strong = _strong_edges(grad)
    if strongest:
        k = np.argmax(grad, axis=1)
    elif inner:  # the innermost strong edge (see base_off_shadow)
        k = np.where(strong.any(axis=1), np.argmax(strong, axis=1), np.argmax(grad, axis=1))
    else:
        k = np.where(
            strong.any(axis=1), grad.shape[1] - 1 - np.argmax(strong[:, ::-1], axis=1), np.argmax(grad, axis=1)
        )
    edge = _edge_at(grad, k, offs, a[None, :] + ts[:, None] * (b - a)[None, :], n)
    line = _robust_fit(edge, pad=0.05)
    if points is not None:
        points.append(edge)
    return line


def inner_step(rgb: np.ndarray, a: np.ndarray, b: np.ndarray, reach: float) -> tuple | None:
    """The side a-b's edge (:func:`_refine_side`, the outermost strong one) and a second step of
    colour up to ``reach`` px in from it: ``(edge line, step line)``, each as (point, direction);
    None where fewer than a quarter of the profiles (or ten) show one. A profile's second step is
    its largest colour gradient between 1.5 px and ``reach`` in from the edge, kept only where the
    gradient falls between the two (by :data:`INNER_STEP_VALLEY`): a step of its own, not the
    edge's own ramp fading inward (a Blender render's colours bled over 3-4 px at one wall's end).
    The sides run LL, LR, UR, UL, so +n points out of the wall."""
    outer = _refine_side(rgb, a, b, 2.5)
    if outer is None:
        return None
    ts = np.linspace(0.05, 0.95, max(20, int(np.linalg.norm(b - a) / 6)))
    p = a[None] + ts[:, None] * (b - a)[None]
    n = side_normal(a, b)
    on = p + across(outer, p, n)[:, None] * n  # each profile starts on the edge's line, across the side
    offs = np.arange(-reach - 1.0, 1.0 + 1e-9, 0.5)
    pts = on[:, None, :] + offs[None, :, None] * n[None, None, :]
    prof = _blurred_samples(rgb, pts[..., 1].ravel(), pts[..., 0].ravel()).reshape(len(ts), len(offs), 3)
    grad = np.linalg.norm(np.diff(prof, axis=1), axis=-1)
    mids = (offs[:-1] + offs[1:]) / 2
    window = (mids <= -1.5) & (mids >= -reach)
    k = np.argmax(np.where(window[None], grad, -1.0), axis=1)
    kk = np.clip(k, 1, len(mids) - 2)
    rows = np.arange(len(ts))
    g0, g1, g2 = grad[rows, kk - 1], grad[rows, kk], grad[rows, kk + 1]
    edge_i = int(np.argmin(np.abs(mids)))
    valley = np.array([grad[i, kk[i] + 1 : edge_i].min(initial=np.inf) for i in rows])
    ok = (k == kk) & (g1 >= g0) & (g1 >= g2) & (g1 >= INNER_STEP_VALLEY * valley)
    if ok.sum() < max(10, 0.25 * len(ts)):
        return None
    inner = _robust_fit(_edge_at(grad, k, offs, on, n)[ok], pad=0.05)
    return None if inner is None else (outer, inner)


def side_normal(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The unit normal of the side a-b that points out of the wall (the sides run LL, LR, UR, UL)."""
    d = (b - a) / float(np.linalg.norm(b - a))
    return np.array([-d[1], d[0]])


def across(line: tuple[np.ndarray, np.ndarray], points: np.ndarray, n: np.ndarray) -> np.ndarray:
    """``(m,)`` how far along ``n`` from each of the ``points`` ``(m, 2)`` the ``line`` (point,
    direction) lies."""
    c, d = line
    return (d[0] * (c[1] - points[:, 1]) - d[1] * (c[0] - points[:, 0])) / (d[0] * n[1] - d[1] * n[0])


#: a second step of colour inside a side's edge is one of its own where its gradient is this many
#: times the least gradient between it and the edge (:func:`inner_step`)
INNER_STEP_VALLEY = 1.5


def _edge_at(grad, k, offs, base, n) -> np.ndarray:
    """The edge points ``(n, 2)`` of a side's profiles ``grad`` ``(n, m)`` (sampled at ``offs``
    along ``n`` from the points ``base`` ``(n, 2)``) at the profile index ``k`` ``(n,)`` of each,
    placed at sub-pixel by a parabola through the gradient's three samples."""
    kk = np.clip(k, 1, grad.shape[1] - 2)
    rows = np.arange(len(base))
    g0, g1, g2 = grad[rows, kk - 1], grad[rows, kk], grad[rows, kk + 1]
    den = g0 - 2 * g1 + g2
    frac = np.where(np.abs(den) > 1e-12, 0.5 * (g0 - g2) / np.where(np.abs(den) > 1e-12, den, 1.0), 0.0)
    off = offs[0] + 0.5 * (kk + np.clip(frac, -0.5, 0.5)) + 0.25
    return base + off[:, None] * n[None, :]


def _off_vp(line: tuple[np.ndarray, np.ndarray], vp: np.ndarray) -> float:
    """The angle (rad) between a line (point, direction) and the direction from its point to the
    vanishing point ``vp`` (homogeneous; at infinity, a direction)."""
    c, d = line
    to = _vp_direction(c, vp)
    return float(np.arcsin(min(1.0, abs(d[0] * to[1] - d[1] * to[0]))))


def side_turn(a: np.ndarray, b: np.ndarray, vp: np.ndarray) -> float:
    """The angle (rad) between the side a-b and the direction from its middle to the vanishing
    point ``vp`` (homogeneous)."""
    return _off_vp(((a + b) / 2, (b - a) / max(float(np.linalg.norm(b - a)), 1e-12)), vp)


def _bowed(edge: np.ndarray, line: tuple[np.ndarray, np.ndarray], a: np.ndarray, b: np.ndarray):
    """A side whose edge points bow (a lens bends a straight edge into nearly a parabola): the
    tangents of the parabola fitted to them (robustly) at the side's two ends ``a`` and ``b``, as
    ``((point, direction) at a, (point, direction) at b)``; None where the bow is not significant
    (three sigmas, and half a pixel at the middle), so that a straight side stays a line."""
    c, d = line
    nrm = np.array([-d[1], d[0]])
    t = (edge - c) @ d
    r = (edge - c) @ nrm
    keep = np.ones(len(t), dtype=bool)
    coef, cov = None, None
    for _ in range(3):
        if keep.sum() < 8:
            return None
        m = np.c_[np.ones(keep.sum()), t[keep], t[keep] ** 2]
        coef, *_ = np.linalg.lstsq(m, r[keep], rcond=None)
        res = r - np.c_[np.ones_like(t), t, t * t] @ coef
        sd = 1.4826 * float(np.median(np.abs(res[keep]))) + 1e-6
        keep = np.abs(res) < max(1.0, 3.0 * sd)
        cov = np.linalg.pinv(m.T @ m) * sd**2
    half = 0.5 * float(np.ptp(t))
    gamma = float(coef[2])
    if abs(gamma) < 3.0 * math.sqrt(max(cov[2, 2], 0.0)) or abs(gamma) * half**2 < 0.5:
        return None

    def tangent(p):
        tp = float((p - c) @ d)
        point = c + tp * d + (coef[0] + coef[1] * tp + gamma * tp * tp) * nrm
        direction = d + (coef[1] + 2.0 * gamma * tp) * nrm
        return point, direction / np.linalg.norm(direction)

    return tangent(a), tangent(b)


def _side_sigma(edge: np.ndarray, line: tuple[np.ndarray, np.ndarray], length: float) -> float:
    """How well a side's edge points ``(n, 2)`` pin its line at the side's ends (px): the line's
    offset and angle from the points' robust scatter about it, and a quarter of that scatter again
    for where along a ragged edge (stones' ends, a broken plaster) the wall's edge is meant to be,
    and 0.3 px for the photo's blur. A clean synthetic edge gives 0.3-0.4 px, a rubble wall's end
    several pixels."""
    c, d = line
    r = (edge - c) @ np.array([-d[1], d[0]])
    sd = 1.4826 * float(np.median(np.abs(r - np.median(r))))
    n_eff = max(1.0, min(len(edge), length / max(4.0 * sd, 2.0)))  # neighbours share a stone's edge
    return math.sqrt((2.0 * sd) ** 2 / n_eff + (0.25 * sd) ** 2 + 0.3**2)


def _robust_fit(pts: np.ndarray, *, pad: float = 0.0, floor: float = 0.0) -> tuple[np.ndarray, np.ndarray] | None:
    """Line (point, unit direction) through ``pts`` by total least squares, after three rounds of
    dropping points farther than ``max(floor, 3 x 1.4826 x (median distance + pad))``; None when
    fewer than five points are left. The first round's distances are from the Theil-Sen line (the
    median of the pairwise slopes, which a run of outliers up to about 29 % of the points does not
    move): from the least-squares line, a cast shadow along the last 15 % of a wall's base (its
    edge 2-6 px below) tilted the line enough to keep itself, and the far corner came out 4 px
    low (a Blender wall, seed 12040). Where nothing is dropped, the rounds are as before."""
    keep = np.ones(len(pts), dtype=bool)
    if len(pts) >= 5:
        c = pts.mean(axis=0)
        _, _, vt = np.linalg.svd(pts - c, full_matrices=False)  # vt alone: U would be (n, n)
        u, v = (pts - c) @ vt[0], (pts - c) @ vt[1]
        i, j = np.triu_indices(len(pts), k=1)
        du = u[j] - u[i]
        ok = np.abs(du) > 1e-9
        if ok.any():
            slope = float(np.median((v[j] - v[i])[ok] / du[ok]))
            r = (v - slope * u - float(np.median(v - slope * u))) / math.hypot(1.0, slope)
            keep = np.abs(r) < max(floor, 3.0 * 1.4826 * (float(np.median(np.abs(r))) + pad))
    for _ in range(4):
        if keep.sum() < 5:
            return None
        c = pts[keep].mean(axis=0)
        _, _, vt = np.linalg.svd(pts[keep] - c, full_matrices=False)
        r = (pts - c) @ np.array([-vt[0][1], vt[0][0]])
        keep = np.abs(r) < max(floor, 3.0 * 1.4826 * (float(np.median(np.abs(r[keep]))) + pad))
    return c, vt[0]


def base_off_shadow(
    rgb: np.ndarray, quad: np.ndarray, sigma: np.ndarray, vp: np.ndarray, half: float
) -> tuple[np.ndarray, np.ndarray]:
    """The outline ``quad`` (LL, LR, UR, UL, straight sides snapped to the photo's edges, corner
    sigmas ``sigma``) with a base that turns away from the bed joints' vanishing point ``vp`` put
    back on the wall's foot. A shadow that a sunlit wall casts at its foot joins the wall in the
    outline, and the base is then found along the shadow's far edge, which meets the wall's foot at
    one end only (measured on Blender-rendered walls: 1.6-6 degrees off the bed joints' vanishing
    point, a base corner 6-22 px low on a 1,500 px high wall, the scale from the camera height off by
    11 % to 2x).

    A base more than :data:`SIDE_TURN_RAD` off is tried again on the line from each of its ends
    towards the vanishing point (that end kept), where that takes the outline in by at most
    :data:`SIDE_MOVE_FRACTION` of the wall's height (:data:`STEEP_MOVE_FRACTION` where the base
    turns more than :data:`STEEP_TURN_RAD`): snapped to the innermost strong edge within
    ``half`` px, and kept where that edge runs towards the vanishing point (within a third of the
    first turn); of two, the one whose edge points scatter least. Only the base: a top moved so
    followed a stone wall's ragged plaster on the laboratory photos (H 2 % shorter, measured),
    and a shadow is cast at the foot. The corners it moves get their sigma from their sides' edge
    evidence (:func:`_side_sigma`), as :func:`refine_quad` gives it."""
    quad = np.asarray(quad, dtype=np.float64)
    sigma = np.asarray(sigma, dtype=np.float64)
    a, b = quad[0], quad[1]
    turn = side_turn(a, b, vp)
    # the top, which no shadow touches, must run towards the vanishing point: an irregular stone
    # wall's courses put it 7 degrees off its top and base alike (a synthetic Stylite wall), and
    # a base moved towards it went 40 px up onto a stone's edge
    if turn <= SIDE_TURN_RAD or side_turn(quad[3], quad[2], vp) > SIDE_TURN_RAD / 2:
        return quad, sigma
    centre = quad.mean(axis=0)
    left, right = (quad[0], quad[3] - quad[0]), (quad[1], quad[2] - quad[1])  # the ends, up from the base
    best = None
    for anchor, end, side in ((a, b, right), (b, a, left)):
        try:
            other = _intersect((anchor, _vp_direction(anchor, vp)), side)
        except np.linalg.LinAlgError:
            continue
        moved = other - end
        # only in, and not far: a stone wall's bed joints, cracks among them, put the vanishing
        # point 14 degrees off its base, which moved a corner 114 px (a quarter of H) up
        cap = STEEP_MOVE_FRACTION if turn > STEEP_TURN_RAD else SIDE_MOVE_FRACTION
        if not 1.0 <= float(np.linalg.norm(moved)) <= cap * float(np.linalg.norm(side[1])):
            continue
        if moved @ (centre - end) <= 0:
            continue
        ends = (anchor, other) if end is b else (other, anchor)
        pts: list = []
        line = _refine_side(rgb, *ends, half, inner=True, points=pts)
        if line is None or _off_vp(line, vp) > turn / 3:
            continue
        spread = _side_sigma(pts[0], line, float(np.linalg.norm(ends[1] - ends[0])))
        if best is None or spread < best[0]:
            best = (spread, line)
    if best is None:
        return quad, sigma
    lines = [best[1]] + [(quad[j], quad[(j + 1) % 4] - quad[j]) for j in (1, 2, 3)]
    try:
        new = np.array([_intersect(lines[(j - 1) % 4], lines[j]) for j in range(4)])
    except np.linalg.LinAlgError:
        return quad, sigma
    right, left = _end_sigmas(rgb, new, half, (sigma[1], sigma[3]))  # for the two corners on the new base
    sigma = sigma.copy()
    sigma[0] = _corner_sigma(left, best[0])  # LL: the left end and the base
    sigma[1] = _corner_sigma(best[0], right)  # LR: the base and the right end
    return new, sigma


def _end_sigmas(rgb: np.ndarray, quad: np.ndarray, half: float, fallback) -> tuple[float, float]:
    """The sigmas (px) of the outline ``quad``'s right end (LR -> UR) and left end (UL -> LL), each
    from its own edge evidence (:func:`_side_sigma`), or ``fallback`` ``(right, left)`` where an end
    finds no edge."""
    out = []
    for j, f in zip((1, 3), fallback):
        pts: list = []
        line = _refine_side(rgb, quad[j], quad[(j + 1) % 4], half, points=pts)
        length = float(np.linalg.norm(quad[(j + 1) % 4] - quad[j]))
        out.append(_side_sigma(pts[0], line, length) if line is not None else float(f))
    return out[0], out[1]


#: a band along the outline's top whose rows are this much less textured than the wall's (the
#: median deviation along each row from its own smooth course, against that of the rows deeper
#: in), in the median, is no masonry: an eave's soffit and fascia, a cornice, a parapet's coping
BAND_TEXTURE_RATIO = 0.3
#: ... and ends where three rows in a row are textured as much as this share of the wall's
MASONRY_TEXTURE_RATIO = 0.6
#: ... and is cut away only when at least this share of the wall's height thick: a mortar bed or a
#: top course's joint (16 px of a 1,450 px Blender wall, 1.1 %) belongs to the wall
BAND_MIN_FRACTION = 0.03
#: how far down from the top the band is sought, of the wall's height
BAND_REACH_FRACTION = 0.15
#: the parts' band edges are kept for the line through them when within this many px of it, or
#: three robust sigmas if more: a crossing on a blurred, textured row is good to a pixel or two,
#: and seven parts 33-41 px deep along a plain end face (a Blender facade) kept fewer than five
#: at three sigmas of their 1-px median residual
BAND_FIT_FLOOR_PX = 3.0
#: a band that overhangs the wall's ends (:func:`_ends_onset`) is cut away when at least this deep
#: (px): a photo's blur and a corner's anti-aliasing leave the ends' edges 1-3 px short of the top
BAND_MIN_PX = 6.0


def _row_texture(
    rgb: np.ndarray, a: np.ndarray, b: np.ndarray, n: np.ndarray, depths: np.ndarray, parts: int = 1
) -> np.ndarray:
    """``(len(depths), parts)`` the texture of the rows parallel to the side a-b, ``depths`` px in
    from it (against ``n``, which points out of the wall), in each of ``parts`` equal parts of the
    side's middle 70 %: per row, the median absolute deviation of the lightness along it from its
    own running mean over a sixth of the side (a shading gradient is no texture)."""
    length = float(np.linalg.norm(b - a))
    ts = np.linspace(0.15, 0.85, max(24, int(0.7 * length / 3)))
    pts = a[None, None, :] + ts[None, :, None] * (b - a)[None, None, :] - depths[:, None, None] * n[None, None, :]
    g = _blurred_samples(rgb, pts[..., 1].ravel(), pts[..., 0].ravel(), gray=True).reshape(len(depths), len(ts))
    smooth = ndimage.uniform_filter1d(g.astype(np.float64), size=max(3, len(ts) // 6), axis=1, mode="nearest")
    dev = np.abs(g - smooth)
    return np.stack([np.median(q, axis=1) for q in np.array_split(dev, parts, axis=1)], axis=1)


def _band_end(t: np.ndarray, wall: float, least: float) -> float | None:
    """Where a band ends on the profile ``t`` (one value a pixel, from the outline's top down):
    the rows down to where three in a row reach :data:`MASONRY_TEXTURE_RATIO` of ``wall`` (the
    value the wall's own rows have), to a sub-pixel where ``t`` crosses halfway from the band's
    median to ``wall`` (each row is blurred across the edge); None where that is under ``least``
    px deep or the band's median is over :data:`BAND_TEXTURE_RATIO` of ``wall``."""
    run = np.convolve((t >= MASONRY_TEXTURE_RATIO * wall).astype(int), np.ones(3, dtype=int), mode="valid") == 3
    if not run.any():
        return None
    k = int(np.argmax(run))
    if k < least or float(np.median(t[:k])) > BAND_TEXTURE_RATIO * wall:
        return None
    level = 0.5 * (float(np.median(t[:k])) + wall)
    j = k - 1
    while j > 0 and t[j] >= level:
        j -= 1
    lo, hi = float(t[j]), float(t[j + 1])
    return float(j) + (float(np.clip((level - lo) / (hi - lo), 0.0, 1.0)) if hi > lo else 1.0)


def band_top(
    rgb: np.ndarray,
    quad: np.ndarray,
    vp: np.ndarray | None,
    half: float,
    side_half: float = 6.0,
    *,
    overhang: bool = True,
) -> tuple | None:
    """The top line ``(point, direction, edge points)`` of the outline ``quad`` (LL, LR, UR, UL) put
    down off a band of the photo that is no masonry, or None where there is none: an eave (its
    soffit and fascia), a cornice or a coping that the wall's appearance takes in, because it is
    unlike the sky and the ground the wall is learnt against (Blender-rendered facades with a boxed
    eave: the top 30-67 px high, H 4-10 % too tall with a sigma of 0.1 % given the width; the sides,
    bent where the eave overhangs them, read as a lens's bow).

    The rows along the top (through the bed joints' vanishing point ``vp`` where there is one) are
    followed down to :data:`BAND_REACH_FRACTION` of the wall's height, in eight parts along it. In
    a part, the band is the rows from the top down to where three in a row are textured at least
    :data:`MASONRY_TEXTURE_RATIO` as much as the rows in the reach's lower half
    (:func:`_row_texture`); it counts where it is at least :data:`BAND_MIN_FRACTION` of the height
    deep and its rows' median texture under :data:`BAND_TEXTURE_RATIO` of the wall's, and its
    edge is where the texture crosses halfway. Where five parts or more have a band, the top is
    the strongest step within ``half`` px of the line through their edges (its direction within
    :data:`SIDE_TURN_RAD` of that line's), half the bands' depth down at least. Where they have
    none, or their line leads to no such step, the line through the places where the wall's two
    ends start to show an edge (:func:`_ends_onset`, each end sought within ``side_half`` px) is
    tried the same way: a band that overhangs the wall, too thin to tell from a mortar bed by its
    texture (a shaded soffit, 11-23 px of a 650-850 px facade), or on a wall no more textured than
    it (plaster, a rendered facade)."""
    quad = np.asarray(quad, dtype=np.float64)
    ur, ul = quad[2], quad[3]
    if vp is not None:  # the rows run along the courses: the top turned through the vanishing point
        mid = (ur + ul) / 2
        try:
            course = (mid, _vp_direction(mid, vp))
            ur, ul = _intersect((quad[1], quad[2] - quad[1]), course), _intersect((quad[0], quad[3] - quad[0]), course)
        except np.linalg.LinAlgError:
            return None
    top_len = float(np.linalg.norm(ul - ur))
    height = 0.5 * float(np.linalg.norm(ul - quad[0]) + np.linalg.norm(ur - quad[1]))
    if top_len < 40 or height < 40 or (ul - ur) @ (quad[3] - quad[2]) <= 0:
        return None
    n = side_normal(ur, ul)  # out of the wall, across the top
    depths = np.arange(0.0, BAND_REACH_FRACTION * height, 1.0)
    parts = 8
    tex = _row_texture(rgb, ur, ul, n, depths, parts)
    wall = np.median(tex[len(depths) // 2 :], axis=0)
    # a band on the top as thin as a mortar bed is the wall's; an end's (``overhang`` False) may
    # narrow to nothing at one end (a house's plain side wall beyond the facade's corner, hidden
    # under the eave: a wedge 0-40 px wide)
    least = max(BAND_MIN_PX, BAND_MIN_FRACTION * height) if overhang else BAND_MIN_PX
    at, onset = [], []
    for q in range(parts):
        t = tex[:, q]
        if wall[q] < 2e-3:  # no texture to tell masonry by
            continue
        edge = _band_end(t, float(wall[q]), least)
        if edge is not None:
            at.append(q)
            onset.append(edge)

    def guides():
        if len(at) >= 5:  # a band along most of the top: the line through the parts' crossings
            mids = ur[None, :] + (0.15 + 0.7 * (np.asarray(at) + 0.5) / parts)[:, None] * (ul - ur)[None, :]
            yield (
                _robust_fit(mids - np.asarray(onset)[:, None] * n[None, :], floor=BAND_FIT_FLOOR_PX),
                np.array([ur, ul]),
            )
        # or, where there is none (or it leads to no edge), the line where both ends' edges start
        # below the outline's own top corners: a band that overhangs the wall, too thin to tell
        # from a mortar bed by its texture (looked for only then: two ends' profiles)
        if overhang:
            yield _ends_onset(rgb, quad, quad[2], quad[3], height, side_half), quad[2:]

    for guide, corners in guides():
        if guide is None:
            continue
        band = -float(np.mean(across(guide, corners, n)))
        found = _step_along(rgb, quad, guide, half)
        if found is None:
            continue
        line, pts = found
        place = across(line, corners, n)
        if overhang and np.all((-2.0 * band <= place) & (place <= -0.5 * band)):  # down in the band, not on the top
            return line[0], line[1], pts
        deep = -across(guide, corners, n)  # an end's band, corner by corner: near the guide
        if not overhang and np.all(np.abs(place + deep) <= np.maximum(2.0, 0.5 * deep)) and deep.max() >= least:
            return line[0], line[1], pts
    return None


def _step_along(rgb: np.ndarray, quad: np.ndarray, guide: tuple, half: float):
    """The strongest colour step within ``half`` px of the line ``guide`` (point, direction)
    between the outline ``quad``'s two ends, its direction within :data:`SIDE_TURN_RAD` of the
    guide's: ``(line, edge points)``, or None. The strongest, not the outermost strong one, which
    may be a pixel out (a blurred step sampled every half pixel has a shoulder beside its peak),
    and a joint under the top course steps as much as the wall's edge does."""
    try:
        gur, gul = _intersect((quad[1], quad[2] - quad[1]), guide), _intersect((quad[0], quad[3] - quad[0]), guide)
    except np.linalg.LinAlgError:
        return None
    pts: list = []
    line = _refine_side(rgb, gur, gul, half, points=pts, strongest=True)
    if line is None or abs(float(np.cross(guide[1], line[1]))) > math.sin(SIDE_TURN_RAD):
        return None
    return line, pts[0]


def _end_steps(
    rgb: np.ndarray, lo: np.ndarray, top: np.ndarray, depths: np.ndarray, half: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Along the outline's end ``lo`` -> ``top``, at ``depths`` px below ``top`` (negative: above
    it, on the end's line carried on), the strongest colour step across the end within ``half`` px
    ``(len(depths),)``; with the unit directions down the end and across it."""
    down = (lo - top) / max(float(np.linalg.norm(lo - top)), 1e-9)
    n = np.array([down[1], -down[0]])
    offs = np.arange(-half, half + 0.25, 0.5)
    pts = top[None, None, :] + depths[:, None, None] * down[None, None, :] + offs[None, :, None] * n[None, None, :]
    prof = _blurred_samples(rgb, pts[..., 1].ravel(), pts[..., 0].ravel()).reshape(len(depths), len(offs), 3)
    return np.linalg.norm(np.diff(prof, axis=1), axis=-1).max(axis=1), down, n


def _band_beside(
    rgb: np.ndarray,
    top: np.ndarray,
    down: np.ndarray,
    normal: np.ndarray,
    centre: np.ndarray,
    at: float,
    depths: np.ndarray,
    half: float,
) -> bool | None:
    """Whether, beside an end whose edge starts ``at`` px below ``top`` (``down`` the end's
    direction, ``normal`` across it either way; the side away from the wall's ``centre`` is looked at),
    the colour changes where that band ends by at least
    :data:`BAND_TEXTURE_RATIO` of the change across the end below it: a band that runs on past the
    end (an eave's shaded soffit against the sky: 0.5), not a mortar bed of the sky's own colour,
    which ends with the wall. None where the search ``depths`` holds nothing below the band."""
    out = normal if float(normal @ (top - centre)) > 0 else -normal
    beside = top[None, :] + np.arange(half + 1.0, half + 5.5)[:, None] * out[None, :]
    deeper = depths[int(at) + 3 : 2 * int(at) + 3]
    if len(deeper) == 0:  # the band reaches the end of the search: nothing below it to compare
        return None
    band, below, inner = (
        _blurred_samples(rgb, q[..., 1].ravel(), q[..., 0].ravel()).reshape(-1, 3).mean(axis=0)
        for q in (
            beside[None, :, :] + depths[: max(1, int(at) - 1), None, None] * down[None, None, :],
            beside[None, :, :] + deeper[:, None, None] * down[None, None, :],
            beside[None, :, :] - (2 * half + 6.0) * out[None, None, :] + deeper[:, None, None] * down[None, None, :],
        )
    )
    return bool(np.linalg.norm(band - below) >= BAND_TEXTURE_RATIO * np.linalg.norm(inner - below))


def _line_through(points: list) -> tuple[np.ndarray, np.ndarray] | None:
    """The line (point, unit direction) through two points, None where they coincide."""
    d = points[1] - points[0]
    length = float(np.linalg.norm(d))
    return None if length < 1e-9 else (points[0], d / length)


def _ends_onset(
    rgb: np.ndarray, quad: np.ndarray, ur: np.ndarray, ul: np.ndarray, height: float, half: float
) -> tuple[np.ndarray, np.ndarray] | None:
    """The line (point, direction) through the places where the outline ``quad``'s two ends (LR ->
    UR, LL -> UL) start to show an edge, below its top ``ur``-``ul``, or None where either end
    shows one from the top down (to within :data:`BAND_MIN_PX`): a band that overhangs the wall (an
    eave's soffit and fascia, a loading beam) hides the ends, where a mortar bed on the wall's top,
    which the texture cannot tell from a soffit, does not (:func:`_band_beside`). Along each end,
    down to :data:`BAND_REACH_FRACTION` of the height, the strongest colour step across it within
    ``half`` px (:func:`_end_steps`); its edge starts where three rows in a row step by at least
    :data:`MASONRY_TEXTURE_RATIO` of the end's median step further down (and the rows above step
    under :data:`BAND_TEXTURE_RATIO` of it), to a sub-pixel by where the step crosses halfway."""
    depths = np.arange(0.0, BAND_REACH_FRACTION * height, 1.0)
    centre = np.asarray(quad, dtype=np.float64).mean(axis=0)
    points = []
    for lo, top in ((quad[1], ur), (quad[0], ul)):
        step, down, n = _end_steps(rgb, lo, top, depths, half)
        end = float(np.median(step[len(depths) // 2 :]))
        if end < 0.02:  # no edge to the end at all (a wall on a background of its own colour)
            return None
        at = _band_end(step, end, BAND_MIN_PX)
        if at is None:
            return None
        if not _band_beside(rgb, top, down, n, centre, at, depths, half):
            return None
        points.append(top + at * down)
    return _line_through(points)


def _end_stop(rgb: np.ndarray, lo: np.ndarray, top: np.ndarray, reach: float, half: float, centre: np.ndarray):
    """Where the edge along the outline's end ``lo`` -> ``top`` stops going up: px above ``top``
    (negative: below it), to a sub-pixel where its step crosses halfway, or None where the end
    shows no edge, the edge runs on past ``reach`` px above the top, or it starts
    :data:`BAND_MIN_PX` or more below the top beside no band (:func:`_band_beside`: a mortar bed
    of the background's colour on the wall's top). An edge that runs on above the top is one
    whose rows step by at least :data:`MASONRY_TEXTURE_RATIO` of the end's median (over the rows
    below the top) up to three in a row under half of it."""
    depths = np.arange(-math.floor(reach), math.floor(reach) + 1.0, 1.0)
    step, down, n = _end_steps(rgb, lo, top, depths, half)
    i0 = int(np.flatnonzero(depths == 0.0)[0])
    end = float(np.median(step[i0:]))
    if end < 0.02:
        return None
    if step[i0] < 0.5 * end:  # no edge at the top: where it starts below it
        at = _band_end(step[i0:], end, 0.0)
        if at is None:
            return None
        if at >= BAND_MIN_PX and not _band_beside(rgb, top, down, n, centre, at, depths[i0:], half):
            return None
        return -at
    up = step[: i0 + 1][::-1]  # from the top row upward, a row a pixel
    run = np.convolve((up < 0.5 * end).astype(int), np.ones(3, dtype=int), mode="valid") == 3
    if not run.any():
        return None
    k = int(np.argmax(run))
    if k == 0:
        return 0.0
    edge = float(np.median(up[:k]))
    if edge < MASONRY_TEXTURE_RATIO * end:
        return None
    level = 0.5 * (edge + float(np.median(up[k : k + max(3, k)])))
    under = np.flatnonzero(up < level)
    if not under.size:
        return None
    j = int(under[0])  # the first row above the crossing
    if j == 0:
        return 0.0
    a, b = float(up[j - 1]), float(up[j])
    return (j - 1) + ((a - level) / (a - b) if a > b else 1.0)


def top_by_ends(rgb: np.ndarray, quad: np.ndarray, vp: np.ndarray | None, half: float) -> tuple | None:
    """The top line ``(point, direction, edge points)`` of the outline ``quad`` (LL, LR, UR, UL)
    put where its two ends' edges stop (:func:`_end_stop`), or None where both stop within
    :data:`BAND_MIN_PX` of its top corners: a top snapped a few px off the wall's, onto a band
    whose colour the wall's appearance leaves out or takes in (a top mortar course like the
    soffit above it: the ends' edges run on 7-9 px above the top; an eave's fascia edge, which
    steps more than the crease under it, at one end: 6-18 px, on Blender-rendered facades). The
    top is then the strongest step within 2 px of the line through the two places, its direction
    within :data:`SIDE_TURN_RAD` of that line's and of the bed joints' vanishing point ``vp``'s
    (none without one) and within half each end's offset (2 px at least) of where that end stops;
    each end is sought within ``half`` px. (Without the vanishing point a Blender tall wall's top,
    10-16 px under a top mortar course of the sky's lightness, went to a line 2.5 degrees off
    the courses: an end's edge through the mortar steps less than through the bricks.)"""
    quad = np.asarray(quad, dtype=np.float64)
    height = 0.5 * float(np.linalg.norm(quad[3] - quad[0]) + np.linalg.norm(quad[2] - quad[1]))
    if vp is None or height < 40:
        return None
    centre = quad.mean(axis=0)
    stops, points = [], []
    for lo, top in ((quad[1], quad[2]), (quad[0], quad[3])):
        at = _end_stop(rgb, lo, top, BAND_REACH_FRACTION * height, half, centre)
        if at is None:
            return None
        stops.append(at)
        points.append(top - at * (lo - top) / max(float(np.linalg.norm(lo - top)), 1e-9))
    guide = _line_through(points)
    if guide is None or max(abs(v) for v in stops) < BAND_MIN_PX:
        return None
    found = _step_along(rgb, quad, guide, 2.0)
    if found is None:
        return None
    (point, direction), pts = found
    if _off_vp((point, direction), vp) > SIDE_TURN_RAD:
        return None
    stops = np.asarray(stops)
    place = across((point, direction), quad[2:], side_normal(quad[2], quad[3]))
    if np.all(np.abs(place - stops) <= np.maximum(2.0, 0.5 * np.abs(stops))):
        return point, direction, pts
    return None


def _with_ends(rgb: np.ndarray, quad: np.ndarray, sigma: np.ndarray, ends: dict, half: float):
    """The outline ``quad`` (corner sigmas ``sigma``) with each end in ``ends`` (rolled by its
    key, 1 for the right end and -1 for the left, as :func:`band_top` found it) put on its line,
    as :func:`with_top` puts the top."""
    for k, band in ends.items():
        q, sg = with_top(rgb, np.roll(quad, k, axis=0), np.roll(np.asarray(sigma, dtype=np.float64), k), band, half)
        quad, sigma = np.roll(q, -k, axis=0), np.roll(sg, -k)
    return quad, sigma


def _top_on(quad: np.ndarray, top: tuple) -> np.ndarray | None:
    """The outline ``quad`` (LL, LR, UR, UL) with its top on the line ``top`` (:func:`band_top`):
    its two ends met with that line; None where one runs parallel to it."""
    line = (top[0], top[1])
    new = np.asarray(quad, dtype=np.float64).copy()
    try:
        new[2] = _intersect((new[1], new[2] - new[1]), line)
        new[3] = _intersect((new[0], new[3] - new[0]), line)
    except np.linalg.LinAlgError:
        return None
    return new


def with_top(rgb: np.ndarray, quad: np.ndarray, sigma: np.ndarray, top: tuple, half: float):
    """The outline ``quad`` (LL, LR, UR, UL, corner sigmas ``sigma``) with its top on the line
    ``top`` (:func:`band_top`; :func:`_top_on`), its two top corners' sigmas from that line's edge
    evidence and the ends' (:func:`_side_sigma`)."""
    new = _top_on(quad, top)
    if new is None:
        return quad, sigma
    t = _side_sigma(top[2], (top[0], top[1]), float(np.linalg.norm(new[3] - new[2])))
    right, left = _end_sigmas(rgb, new, half, (2.0, 2.0))
    sigma = np.asarray(sigma, dtype=np.float64).copy()
    sigma[2], sigma[3] = _corner_sigma(right, t), _corner_sigma(t, left)
    return new, sigma


#: a base is put on the foot its head joints give where either of its corners lies further than this
#: fraction of the photo's long side from it (and at least HEAD_FOOT_MIN_PX): a course lost or
#: gained at an end (its bricks shaded as the ground, or the ground's shadow joined to them). On
#: 440 Blender walls (2,000 px high) 0.005 (10 px) mended three bases left 11-14 px low (two on a
#: cast shadow) and moved no other wall's; 0.003 (6 px) also moved a right base that was right 5 px
#: up (the foot the head joints give lies 0.5-5 px above the true one)
HEAD_FOOT_FRACTION = 0.005
HEAD_FOOT_MIN_PX = 10.0
#: the foot is the second lowest lower end of the head joints between the ends, where the lowest
#: lies within this many px below it (two head joints of the bottom course agree)
HEAD_FOOT_AGREE_PX = 6.0
#: and the colour steps across the new base (the median along it) by at least this share of the
#: step across the weaker of the wall's ends: 0.19-0.53 on the Blender walls it mends, 0.07-0.10 on
#: a laboratory stone wall (SC4) whose cracks, taken for head joints, put a foot through its stones
HEAD_FOOT_STEP_SHARE = 0.15


def _head_joints(seg: np.ndarray, vp_head: np.ndarray) -> np.ndarray:
    """The segments ``(n, 4)`` of ``seg`` that run towards the head joints' vanishing point
    ``vp_head`` (within 1.5 px) and are at least 8 px long."""
    from .segments import dist_to_vp

    length = np.hypot(seg[:, 2] - seg[:, 0], seg[:, 3] - seg[:, 1])
    return seg[(dist_to_vp(seg, vp_head) < 1.5) & (length >= 8.0)]


def _with_base_sigma(sigma: np.ndarray, edge: np.ndarray, line, new: np.ndarray) -> np.ndarray:
    """The corner sigmas ``sigma`` with the two base corners' taken from the new base's edge
    points ``edge`` about its ``line`` (:func:`_side_sigma`) and their ends' (:func:`_corner_sigma`)."""
    base = _side_sigma(edge, line, float(np.linalg.norm(new[1] - new[0])))
    sigma = np.array(sigma, dtype=np.float64)
    sigma[:2] = [_corner_sigma(float(v), base) for v in sigma[:2]]
    return sigma


def base_from_heads(
    rgb: np.ndarray,
    quad: np.ndarray,
    sigma: np.ndarray,
    seg: np.ndarray,
    vp_bed: np.ndarray,
    vp_head: np.ndarray,
    half: float,
) -> tuple[np.ndarray, np.ndarray]:
    """The outline ``quad`` (LL, LR, UR, UL, corner sigmas ``sigma``) with its base put on the wall's
    foot as its head joints give it, where a base corner lies far from it. A wall's head joints run
    down to its foot: those of the bottom course end on it. Of the photo's segments ``seg`` that
    run to the head joints' vanishing point ``vp_head`` and end between the outline's ends, the
    lower ends are carried along the bed joints' direction (``vp_bed``) onto the left end; the
    second lowest, where the lowest agrees with it within :data:`HEAD_FOOT_AGREE_PX`, is the foot.
    Where either base corner lies further than :data:`HEAD_FOOT_FRACTION` of the photo's long side
    (at least :data:`HEAD_FOOT_MIN_PX`) from the line through that foot towards ``vp_bed``, the
    base is that line snapped to the outermost strong edge within ``half`` px, where that edge runs
    towards ``vp_bed`` too (within :data:`SIDE_TURN_RAD`) and the colour steps across it by
    :data:`HEAD_FOOT_STEP_SHARE` of the step across the wall's ends; elsewhere the outline is kept
    (no edge of the photo confirms a foot there). The two corners it moves get their sigma from
    the new base's edge evidence (:func:`_side_sigma`), as :func:`base_off_shadow` gives it.

    Measured on tall walls rendered by Blender (experiments/bench_tall_walls_blender.py): an
    outline that lost the bottom course at one or both ends (its bricks in the foot's shadow) put a
    base corner 66-80 px high, W -62 to +43 %; the second lowest head joint's end lay 0.5-4.9 px
    above the foot on those walls."""

    quad = np.asarray(quad, dtype=np.float64)
    seg = np.asarray(seg, dtype=np.float64).reshape(-1, 4)
    rows, cols = rgb.shape[:2]
    if len(seg) < 2 or vp_bed is None or vp_head is None:
        return quad, sigma
    heads = _head_joints(seg, vp_head)
    if len(heads) < 2:
        return quad, sigma
    left, right = (quad[3], quad[0] - quad[3]), (quad[2], quad[1] - quad[2])  # down each end
    # every end carried along the beds onto the left end (homogeneous: the line through it and
    # the vanishing point, met with the left end's line), as the fraction down that end
    ends = heads.reshape(-1, 2, 2)
    hom = np.concatenate([ends.reshape(-1, 2), np.ones((2 * len(heads), 1))], axis=1)
    met = np.cross(np.cross(hom, vp_bed), np.cross(np.r_[quad[3], 1.0], np.r_[quad[0], 1.0]))
    with np.errstate(divide="ignore", invalid="ignore"):
        t = ((met[:, :2] / met[:, 2:] - left[0]) @ left[1] / (left[1] @ left[1])).reshape(-1, 2)
    t[~np.isfinite(t)] = -np.inf
    # each segment's lower end (the one farther down), between the ends (3 px in from each) only
    k = np.argmax(t, axis=1)
    t, low = t[np.arange(len(t)), k], ends[np.arange(len(t)), k]
    nl, nr = side_normal(quad[3], quad[0]), side_normal(quad[1], quad[2])
    ok = np.isfinite(t) & ((low - quad[0]) @ nl < -3.0) & ((low - quad[1]) @ nr < -3.0)
    if ok.sum() < 2:
        return quad, sigma
    order = np.argsort(-t[ok], kind="stable")
    t0, t1 = t[ok][order[:2]]
    p1 = low[ok][order[1]]
    if (t0 - t1) * float(np.linalg.norm(left[1])) > HEAD_FOOT_AGREE_PX:
        return quad, sigma
    try:
        foot = (p1, _vp_direction(p1, vp_bed))
        at = np.array([_intersect(foot, left), _intersect(foot, right)])
    except np.linalg.LinAlgError:
        return quad, sigma
    limit = max(HEAD_FOOT_MIN_PX, HEAD_FOOT_FRACTION * max(rows, cols))
    shift = np.linalg.norm(at - quad[:2], axis=1)
    if shift.max() <= limit:
        return quad, sigma
    new = quad.copy()
    pts: list = []
    line = _refine_side(rgb, at[0], at[1], half, points=pts)
    if line is None or _off_vp(line, vp_bed) > SIDE_TURN_RAD:
        return quad, sigma  # no edge of the photo runs there: no foot confirmed
    try:
        new[0], new[1] = _intersect(line, left), _intersect(line, right)
    except np.linalg.LinAlgError:
        return quad, sigma
    # a foot is an edge of the photo along its length, as the wall's ends are: a laboratory stone
    # wall's cracks, taken for head joints, put a foot through its stones
    weaker_end = min(_step_across(rgb, quad[3], quad[0]), _step_across(rgb, quad[1], quad[2]))
    if _step_across(rgb, new[0], new[1]) < HEAD_FOOT_STEP_SHARE * weaker_end:
        return quad, sigma
    return new, _with_base_sigma(sigma, pts[0], line, new)


#: a head joint runs on below the base when a segment towards the head joints' vanishing point
#: begins within this fraction of the photo's long side (at least HEAD_FOOT_MIN_PX) of the base
#: and ends further below it than HEAD_FOOT_FRACTION of the long side
HEAD_BELOW_GAP_FRACTION = 0.01
#: the base is moved by at most this share of the wall's ends (a course of a stone wall: 0.1-0.2 of
#: its height)
HEAD_BELOW_REACH = 0.25
#: the strip the base takes in must look like masonry in the shade: its relative contrast (the
#: lightness's deviation over its mean, which shade leaves as it is) at most this many times the
#: wall's. The laboratory photos: a bottom course shaded to a third of its light 1.4 times the wall's;
#: the steel and concrete footing under the three walls, whose blocks' edges run on below the foot
#: as head joints do, 2.3-3.1 times
HEAD_BELOW_TEXTURE = 1.75


def base_below_heads(
    rgb: np.ndarray, quad: np.ndarray, sigma: np.ndarray, seg: np.ndarray, vp_head: np.ndarray, half: float
) -> tuple[np.ndarray, np.ndarray]:
    """The outline ``quad`` (LL, LR, UR, UL, corner sigmas ``sigma``) with its base moved down where
    the wall's own head joints run on below it. A bottom course in shade (the light falling off
    towards the floor) is not taken for wall by its appearance, and the outline's base stops a
    course high at one end and tilts (a laboratory photo darkened towards its foot: 80 px high at
    the left end, H -24 % with the width given). The head joints of that course are still in the
    photo, dark lines in a dark course: of the segments of ``seg`` that run towards ``vp_head``
    between the ends, one that begins within :data:`HEAD_BELOW_GAP_FRACTION` of the long side of
    the base and ends more than :data:`HEAD_FOOT_FRACTION` of it below (at most
    :data:`HEAD_BELOW_REACH` of the ends' length) says that the base is too high somewhere. The
    lower ends of the head joints near the base or below it are then the feet, and the new base
    the line through the two feet farthest apart (a quarter of the base at least) that leaves no
    other foot below it (with one: through it and the other base corner), snapped to the photo's
    outermost strong edge within ``half`` px. It is kept where the colour steps across it by
    :data:`HEAD_FOOT_STEP_SHARE` of the step across the weaker end (as :func:`base_from_heads`
    asks of its foot, here each step relative to the lightness either side) and the strip it takes
    in is masonry's texture
    (:data:`HEAD_BELOW_TEXTURE`); elsewhere the outline is kept."""

    quad = np.asarray(quad, dtype=np.float64)
    seg = np.asarray(seg, dtype=np.float64).reshape(-1, 4)
    rows, cols = rgb.shape[:2]
    long_side = max(rows, cols)
    if len(seg) < 2 or vp_head is None:
        return quad, sigma
    heads = _head_joints(seg, vp_head).reshape(-1, 2, 2)
    if len(heads) < 2:
        return quad, sigma
    n = side_normal(quad[0], quad[1])  # out of the wall: down, below the base
    along = (quad[1] - quad[0]) / float(np.linalg.norm(quad[1] - quad[0]))
    below = (heads - quad[0]) @ n  # (k, 2): how far below the base each end lies
    upper = np.argmin(below, axis=1)
    k = np.arange(len(heads))
    top_b, low_b = below[k, upper], below[k, 1 - upper]
    low_p = heads[k, 1 - upper]
    nl, nr = side_normal(quad[3], quad[0]), side_normal(quad[1], quad[2])
    ends = heads.reshape(-1, 2)
    inside = ((ends - quad[0]) @ nl < -3.0) & ((ends - quad[1]) @ nr < -3.0)
    ok = inside.reshape(-1, 2).all(axis=1)
    gap = max(HEAD_FOOT_MIN_PX, HEAD_BELOW_GAP_FRACTION * long_side)
    margin = max(HEAD_FOOT_MIN_PX, HEAD_FOOT_FRACTION * long_side)
    reach = HEAD_BELOW_REACH * 0.5 * (np.linalg.norm(quad[3] - quad[0]) + np.linalg.norm(quad[2] - quad[1]))
    # a joint runs on below the base: a piece that begins at the base (within the gap) and ends
    # below it by more than the margin. Only then is the base looked for again (a footing's or a
    # rig's vertical edges below a right base are no wall's joints)
    if not np.any(ok & (top_b <= gap) & (margin < low_b) & (low_b <= reach)):
        return quad, sigma
    # the feet: the lower ends of the head joints near the base or below it
    feet = low_p[ok & (low_b > -gap) & (low_b <= reach)]
    feet = np.unique(np.round(feet, 3), axis=0)
    left, right = (quad[3], quad[0] - quad[3]), (quad[2], quad[1] - quad[2])
    width = float(np.linalg.norm(quad[1] - quad[0]))
    best = None
    for i in range(len(feet)):
        for j in range(i + 1, len(feet)):
            d = feet[j] - feet[i]
            span = abs(float(d @ along))
            if span < 0.25 * width:
                continue
            d = d / float(np.linalg.norm(d))
            lower = (feet - feet[i]) @ np.array([-d[1], d[0]]) * np.sign(np.array([-d[1], d[0]]) @ n)
            if lower.max() > 2.0:
                continue  # another foot lies below this line
            if best is None or span > best[0]:
                best = (span, (feet[i], d))
    if best is not None:
        line = best[1]
    else:  # one foot (or none far enough apart): through the lowest and the other base corner
        foot = feet[np.argmax((feet - quad[0]) @ n)]
        other = quad[1] if (foot - quad[0]) @ along < 0.5 * width else quad[0]
        if float(np.linalg.norm(other - foot)) < 0.25 * width:
            return quad, sigma
        line = (foot, (other - foot) / float(np.linalg.norm(other - foot)))
    try:
        new = quad.copy()
        new[0], new[1] = _intersect(line, left), _intersect(line, right)
    except np.linalg.LinAlgError:
        return quad, sigma
    pts: list = []
    snapped = _refine_side(rgb, new[0], new[1], half, points=pts)
    if snapped is None:
        return quad, sigma
    try:
        new[0], new[1] = _intersect(snapped, left), _intersect(snapped, right)
    except np.linalg.LinAlgError:
        return quad, sigma
    if np.any(np.abs((new[:2] - quad[:2]) @ n) > reach):
        return quad, sigma
    # the steps relative to the lightness on either side: the foot found lies in the shade
    # that hid it, the ends in the light (SC4 darkened towards its foot: 0.083 against 0.50 as RGB
    # steps, at the rule's share of 0.15 a hair's breadth either way)
    ends = min(_step_across(rgb, quad[3], quad[0], relative=True), _step_across(rgb, quad[1], quad[2], relative=True))
    if _step_across(rgb, new[0], new[1], relative=True) < HEAD_FOOT_STEP_SHARE * ends:
        return quad, sigma
    wall, strip = _wall_and_strip_contrast(rgb, quad, new)
    if not strip < HEAD_BELOW_TEXTURE * wall:
        return quad, sigma
    return new, _with_base_sigma(sigma, pts[0], snapped, new)


def _wall_and_strip_contrast(rgb: np.ndarray, quad: np.ndarray, new: np.ndarray) -> tuple[float, float]:
    """The median relative contrast (:func:`~calib_masonry.calibrate.outline.relative_contrast`)
    within the outline ``quad`` and within the strip that the outline ``new`` adds to it (photo
    pixels), on the photo shrunk to at most 1000 px; NaN for an empty strip."""
    from skimage.color import rgb2lab

    from .outline import polygon_mask, relative_contrast
    from .segments import shrink

    s = min(1.0, 1000.0 / max(rgb.shape[:2]))
    small = shrink(np.asarray(rgb, dtype=np.float32), s)
    rel = relative_contrast(rgb2lab(np.clip(small, 0.0, 1.0))[..., 0])
    wall, grown = (polygon_mask(rel.shape, (np.asarray(q) + 0.5) * s - 0.5) for q in (quad, new))
    strip = grown & ~wall
    return float(np.median(rel[wall])), float(np.median(rel[strip])) if strip.any() else float("nan")


def _step_across(rgb: np.ndarray, a: np.ndarray, b: np.ndarray, off: float = 2.5, *, relative: bool = False) -> float:
    """The median, along the side a-b, of the colour's step across it (RGB distance between the
    photo ``off`` px either side); ``relative``: each step over the lightness of the two sides
    (their RGB norms' mean), which shade, falling on both sides alike, leaves as it is."""
    n = side_normal(a, b)
    p = a[None, :] + np.linspace(0.05, 0.95, max(20, int(np.linalg.norm(b - a) / 6)))[:, None] * (b - a)[None, :]
    inner = _blurred_samples(rgb, (p - off * n)[:, 1], (p - off * n)[:, 0])
    outer = _blurred_samples(rgb, (p + off * n)[:, 1], (p + off * n)[:, 0])
    step = np.linalg.norm(inner - outer, axis=-1)
    if relative:
        step = step / np.maximum(0.5 * (np.linalg.norm(inner, axis=-1) + np.linalg.norm(outer, axis=-1)), 1e-3)
    return float(np.median(step))


def base_in_pencil(
    rgb: np.ndarray, quad: np.ndarray, vp: np.ndarray, *, reach_in: float, reach_out: float, to_photo=None
) -> tuple[np.ndarray, np.ndarray, tuple[np.ndarray, np.ndarray]] | None:
    """The outline's base sought again among the lines through the bed joints' vanishing point
    ``vp`` (homogeneous; a fitted camera's, whose top and sides fix it): of those lines from
    ``reach_in`` px in from the base's middle to ``reach_out`` px out, the outermost along which
    the colour steps strongly over most of the base (the median over the base of the step across
    each line, at least :data:`OUTER_EDGE_FRACTION` of the strongest such median and
    :data:`PENCIL_MIN_STEP`). A cast shadow's
    far edge, which meets the wall's foot at one end only, does not run through the vanishing
    point and steps along a few of the lines' points at most; the foot steps along all of them.

    Each profile of :func:`_refine_side` picks its own outermost edge, so a base along which a
    shadow's edge comes within the profiles' reach over part of the wall is fitted through both
    (a Blender wall, 12058: its base corners 12 and 20 px low, W 3.9 % and H 5.7 % off with the
    camera height given). Returns the outline with its two base corners moved along the ends to
    that line, the photo's edge points along it ``(n, 2)`` and the line fitted to them (point,
    direction; for :func:`_side_sigma`); None where no line steps. ``quad`` and the result are in the coordinates of ``vp``; ``to_photo`` as in
    :func:`_refine_side`."""
    quad = np.asarray(quad, dtype=np.float64)
    a, b = quad[0], quad[1]
    length = float(np.linalg.norm(b - a))
    if length < 10:
        return None
    n = side_normal(a, b)  # out of the wall: below the base
    along = (b - a) / length
    m = (a + b) / 2
    offs = np.arange(-reach_in, reach_out + 0.25, 0.5)
    s = np.linspace(-0.42, 0.42, max(20, int(length / 6))) * length
    centres = m[None, :] + offs[:, None] * n[None, :]
    dirs = np.array([_vp_direction(c, vp) for c in centres])
    dirs *= np.sign(dirs @ along)[:, None]
    pts = centres[:, None, :] + s[None, :, None] * dirs[:, None, :]  # (offsets, along, 2)
    if to_photo is not None:
        pts = to_photo(pts.reshape(-1, 2)).reshape(pts.shape)
    prof = _blurred_samples(rgb, pts[..., 1].ravel(), pts[..., 0].ravel()).reshape(len(offs), len(s), 3)
    step = np.median(np.linalg.norm(np.diff(prof, axis=0), axis=-1), axis=1)[None, :]  # (1, offsets - 1)
    strong = _strong_edges(step, PENCIL_MIN_STEP)[0]
    if not strong.any():
        return None
    k = step.shape[1] - 1 - int(np.argmax(strong[::-1]))  # the outermost
    c = _edge_at(step, np.array([k]), offs, m[None, :], n)[0]
    line = (c, _vp_direction(c, vp))
    left, right = (quad[0], quad[3] - quad[0]), (quad[1], quad[2] - quad[1])
    try:
        new = quad.copy()
        new[0], new[1] = _intersect(line, left), _intersect(line, right)
        # the line at sub-pixel from the photo's own edge along it, where that runs through the
        # vanishing point too (the fitted camera's point is itself a few tenths of a degree off)
        edge: list = []
        snapped = _refine_side(rgb, new[0], new[1], PENCIL_SNAP_PX, points=edge, to_photo=to_photo)
        if snapped is None:
            return None
        if _off_vp(snapped, vp) <= SIDE_TURN_RAD:
            new[0], new[1] = _intersect(snapped, left), _intersect(snapped, right)
    except np.linalg.LinAlgError:
        return None
    return new, edge[0], snapped


def _corner_sigma(before: float, after: float) -> float:
    """A corner's uncertainty (px, isotropic) from the edge evidence of its two sides, the one
    ending at it and the one starting there (:func:`_side_sigma`)."""
    return math.sqrt((before**2 + after**2) / 2)


def _vp_direction(p: np.ndarray, vp: np.ndarray) -> np.ndarray:
    """A unit direction along the line from the point ``p`` through the vanishing point ``vp``
    (homogeneous, so one at infinity needs no case of its own; as
    :func:`~calib_masonry.calibrate.segments.dist_to_vps` takes it)."""
    to = np.asarray(vp[:2], dtype=np.float64) - np.asarray(p, dtype=np.float64) * vp[2]
    return to / max(float(np.linalg.norm(to)), 1e-300)


def _intersect(l1, l2) -> np.ndarray:
    (c1, d1), (c2, d2) = l1, l2
    m = np.array([d1, -d2]).T
    t = np.linalg.solve(m, c2 - c1)
    return c1 + t[0] * d1


#: the wall's colours are learnt from this central part of the first outline (0.85 let a first
#: outline that reached into the ground teach the model the ground's colours, measured)
INNER_FRACTION = 0.6


def refine_quad(
    rgb: np.ndarray,
    quad: np.ndarray,
    halfwidths: tuple[float, ...] = (5.0, 2.5),
    *,
    with_sigma: bool = False,
    to_photo=None,
    curved: bool = False,
    bowed: list | None = None,
):
    """Snap a quadrilateral (LL, LR, UR, UL) to the wall's outline edges in the full photo.

    Each pass fits every side to the strongest colour edge within ``halfwidth`` pixels of it
    (sub-pixel profile maxima, robust line fit) and intersects adjacent sides. A pass that fails or
    moves a corner by more than four half-widths is discarded, so a quadrilateral with no clear
    edge nearby comes back unchanged. With ``with_sigma``, also each corner's uncertainty (px,
    ``(4,)``) from its two sides' edge evidence (:func:`_side_sigma`; 2 px for a corner whose sides
    found no edge). ``to_photo``: ``quad`` is in ideal image coordinates of a lens that maps them to
    the photo's so (:func:`_refine_side`); the result is too. ``curved``: a side whose edge bows
    significantly (an unknown lens) meets its neighbours along its tangents at the ends
    (:func:`_bowed`), not along its chord, which put the corners of a barrel-distorted wall 10-15 px
    off (measured at k1 = -0.15); ``bowed``, a list given, gets the index of each side found bowed
    in each pass (none: the result is that of straight sides)."""
    sigma = np.full(4, 2.0)
    for half in halfwidths:
        pts: list = []
        sides = [_refine_side(rgb, quad[i], quad[(i + 1) % 4], half, points=pts, to_photo=to_photo) for i in range(4)]
        if any(sd is None for sd in sides):
            break
        ends = [(sd, sd) for sd in sides]  # each side's line at its start and at its end
        if curved:
            for i in range(4):
                bow = _bowed(pts[i], sides[i], quad[i], quad[(i + 1) % 4])
                if bow is not None:
                    ends[i] = bow
                    if bowed is not None:
                        bowed.append(i)
        try:
            refined = np.array([_intersect(ends[(i - 1) % 4][1], ends[i][0]) for i in range(4)])
        except np.linalg.LinAlgError:
            break
        if not np.all(np.isfinite(refined)) or np.max(np.linalg.norm(refined - quad, axis=1)) > 4 * half:
            break
        side_sigma = [
            _side_sigma(pts[i], sides[i], float(np.linalg.norm(quad[(i + 1) % 4] - quad[i]))) for i in range(4)
        ]
        # the corner i is where sides i - 1 and i meet; isotropic, from the two sides' normals
        sigma = np.array([_corner_sigma(side_sigma[(i - 1) % 4], side_sigma[i]) for i in range(4)])
        quad = order_corners(refined, where="outline refinement")
    return (quad, sigma) if with_sigma else quad


def _in_convex(points: np.ndarray, quad: np.ndarray) -> np.ndarray:
    """``(n,)`` whether the points ``(n, 2)`` lie strictly inside the convex quadrilateral ``quad``."""
    a, b = quad, np.roll(quad, -1, axis=0)
    cross = (b[:, 0] - a[:, 0]) * (points[:, None, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (points[:, None, 0] - a[:, 0])
    return np.all(cross > 0, axis=1) | np.all(cross < 0, axis=1)


def segments_in_quad(seg: np.ndarray, quad: np.ndarray, shrink: float = 0.01) -> np.ndarray:
    """Segments whose both endpoints lie inside the (convex) quadrilateral, shrunk towards its centre."""
    c = quad.mean(axis=0)
    q = c + (quad - c) * (1 - shrink)
    return seg[_in_convex(seg[:, :2], q) & _in_convex(seg[:, 2:], q)]


def _work_scale(shape: tuple[int, ...], long_side_px: int) -> float:
    """The factor that shrinks an image of this shape to at most ``long_side_px`` (never enlarges)."""
    return min(1.0, long_side_px / max(shape[:2]))


#: the last photo's working image and its LSD segments: ``(weakref to the photo, long side, a
#: sample of its pixels, (gray, factor), {LSD's segments})``. The joints' detection and the
#: lens's straight lines each shrank the same photo and ran LSD on it (0.085 s and 0.1 s of a
#: rectify's main thread, measured, each twice)
_LAST_WORK: tuple | None = None


def _work_entry(rgb: np.ndarray, long_side_px: int) -> tuple:
    """The memo of :data:`_LAST_WORK` for this photo (the same array object, not written to since:
    a sample of its pixels is compared), made anew when it is another."""
    global _LAST_WORK
    sample = np.ascontiguousarray(rgb[::61, ::59]).tobytes()
    last = _LAST_WORK
    if last is not None and last[0]() is rgb and last[1] == long_side_px and last[2] == sample:
        return last
    gray, s = _working_gray(rgb, long_side_px)
    gray.setflags(write=False)  # shared by its callers
    _LAST_WORK = entry = (weakref.ref(rgb), long_side_px, sample, (gray, s), {})
    return entry


def working_gray(rgb: np.ndarray, long_side_px: int) -> tuple[np.ndarray, float]:
    """The photo's grey levels shrunk (antialiased) to at most ``long_side_px`` (read-only: the
    last photo's is kept), and the factor."""
    return _work_entry(rgb, long_side_px)[3]


def working_lsd(rgb: np.ndarray, long_side_px: int, min_length_px: float) -> tuple[np.ndarray, float]:
    """OpenCV's LSD segments ``(n, 4)`` of :func:`working_gray` (in its pixels) no shorter than
    ``min_length_px``, and the factor; the last photo's are kept."""
    from .outline import lsd_segments

    entry = _work_entry(rgb, long_side_px)
    gray, s = entry[3]
    if "all" not in entry[4]:
        entry[4]["all"] = lsd_segments(gray)
    seg = entry[4]["all"]
    length = np.hypot(seg[:, 2] - seg[:, 0], seg[:, 3] - seg[:, 1])
    return seg[length >= min_length_px], s


def _working_gray(rgb: np.ndarray, long_side_px: int) -> tuple[np.ndarray, float]:
    s = _work_scale(rgb.shape, long_side_px)
    # the channels' mean, as rgb.mean(axis=-1) sums and divides (the same bits), in a fifth of its time
    if rgb.dtype in (np.float32, np.float64):
        gray = rgb[..., 0] + rgb[..., 1]
        gray += rgb[..., 2]
        gray /= 3
    else:  # integers would overflow in the sum
        gray = rgb.mean(axis=-1)
    return shrink(gray, s), s


def detect_wall(rgb: np.ndarray, config: DetectConfig = DetectConfig(), *, occluders=()) -> Detection:
    """Find the wall's corners (with their uncertainty) and joint segments in an RGB photo
    ``(rows, cols, 3)`` in [0, 1]: the outline from the wall's appearance and the joints'
    directions (:func:`~calib_masonry.calibrate.outline.detect_outline`), each side then snapped to
    the photo's edge at sub-pixel (:func:`refine_quad`); the joint segments inside it for the fit.
    ``occluders``: polygons (photo pixels) left out of everything."""
    from .outline import detect_outline, occluded_mask, segments_outside

    outline = detect_outline(rgb, occluders=occluders, config=config.outline)
    s = _work_scale(rgb.shape, config.work_long_side_px)
    halfwidths = (config.refine_halfwidth_px or 6.0 / s, 2.5 / s)
    # an eave or a cornice taken in with the wall is cut away before the sides are snapped: they
    # bend where it overhangs them, which read as a lens's bow
    start = outline.corners_px
    top = band_top(rgb, start, outline.vp_bed, 2.0, halfwidths[0])
    if top is not None:  # only its corners: refine_quad gives the sigmas
        start = _top_on(start, top)
        start = outline.corners_px if start is None else start
    # so is a plain end face (a house's side wall beyond the facade's corner), by the same rule
    # turned to the ends: the columns along an end through the head joints' vanishing point
    ends = {}
    for k in (1, -1):  # the quad rolled so that the right (1) or the left (-1) end is its "top"
        band = band_top(rgb, np.roll(start, k, axis=0), outline.vp_head, 2.0, overhang=False)
        moved = None if band is None else _top_on(np.roll(start, k, axis=0), band)
        if moved is not None:
            ends[k], start = band, np.roll(moved, -k, axis=0)
    bowed: list = []
    quad, sigma = refine_quad(rgb, start, halfwidths, with_sigma=True, curved=True, bowed=bowed)
    if top is None:
        # the snap carries a top that stopped inside a thin eave out to the eave's own edge, which
        # steps more than the crease under it: the rule again on the snapped outline, whose ends
        # now start a band's depth below its top
        top = band_top(rgb, quad, outline.vp_bed, 2.0, halfwidths[0])
    if top is not None:  # the sides snapped below the band, the top kept on its own edge
        quad, sigma = with_top(rgb, quad, sigma, top, halfwidths[-1])
    # a top a few px off the wall's at one end or both (either rule's, or the snap's): where the
    # ends' edges stop
    by_ends = top_by_ends(rgb, quad, outline.vp_bed, halfwidths[0])
    if by_ends is not None:
        top = by_ends
        quad, sigma = with_top(rgb, quad, sigma, top, halfwidths[-1])
    quad, sigma = _with_ends(rgb, quad, sigma, ends, halfwidths[-1])
    if outline.vp_bed is not None and not bowed:
        quad, sigma = base_off_shadow(rgb, quad, sigma, outline.vp_bed, halfwidths[-1])
    straight = None
    if bowed:
        straight = refine_quad(rgb, start, halfwidths, with_sigma=True, curved=False)
        if top is not None:
            straight = with_top(rgb, *straight, top, halfwidths[-1])
        straight = _with_ends(rgb, *straight, ends, halfwidths[-1])
        if outline.vp_bed is not None:
            straight = base_off_shadow(rgb, *straight, outline.vp_bed, halfwidths[-1])
        if np.array_equal(straight[0], quad):
            straight = None
    rows, cols = rgb.shape[:2]
    every = segments_outside(joint_segments(rgb, config), occluded_mask((rows, cols), occluders))
    if outline.vp_bed is not None and outline.vp_head is not None and not set(bowed) - {0}:
        # a base that lost (or gained) a course at an end, put on the foot the head joints give;
        # not where an end or the top bowed as well (a lens, whose curves the foot is not carried
        # along straight: a corner of the lens photos of calibration_coverage.py moved 40-118 px)
        quad, sigma = base_from_heads(rgb, quad, sigma, every, outline.vp_bed, outline.vp_head, halfwidths[-1])
        if straight is not None:
            straight = base_from_heads(rgb, *straight, every, outline.vp_bed, outline.vp_head, halfwidths[-1])
    if outline.vp_head is not None:
        # a bottom course in shade, its head joints running on below the base
        quad, sigma = base_below_heads(rgb, quad, sigma, every, outline.vp_head, halfwidths[-1])
        if straight is not None:
            straight = base_below_heads(rgb, *straight, every, outline.vp_head, halfwidths[-1])
    slack = 0.02 * max(rows, cols)
    if np.any(quad < -slack) or np.any(quad[:, 0] > cols - 1 + slack) or np.any(quad[:, 1] > rows - 1 + slack):
        raise FitFailed(
            "automatic mode: the outline found runs outside the photo; click the wall's corners with " + CORNERS_FLAG
        )
    seg = segments_in_quad(every, quad)
    ang = np.degrees(np.arctan2(seg[:, 3] - seg[:, 1], seg[:, 2] - seg[:, 0])) % 180.0
    from_h = np.minimum(ang, 180.0 - ang)
    bed, head = seg[from_h < config.horizontal_max_deg], seg[np.abs(ang - 90.0) < config.vertical_max_deg]
    vp_bed = outline.vp_bed if outline.vp_bed is not None else np.array([1.0, 0.0, 0.0])
    vp_head = outline.vp_head if outline.vp_head is not None else np.array([0.0, 1.0, 0.0])
    # a first cut on the outline's vanishing points (the fit rejects outliers of its own after)
    tol = max(3.0, 0.004 * max(rows, cols))
    bed = bed[dist_to_vp(bed, vp_bed) < tol] if len(bed) else bed
    head = head[dist_to_vp(head, vp_head) < tol] if len(head) else head
    return Detection(
        corners_px=quad,
        bed_segments=bed,
        head_segments=head,
        vp_bed=vp_bed,
        vp_head=vp_head,
        n_segments=len(seg),
        corner_sigma_px=sigma,
        segments=seg,
        straight=straight,
    )


def joint_segments(rgb: np.ndarray, config: DetectConfig = DetectConfig()) -> np.ndarray:
    """Joint-line segments ``(n, 4)`` of the whole photo in its pixels: Hough segments of Canny edges
    refitted to sub-pixel edge points (``segments = "hough"``) or OpenCV's LSD (``"lsd"``), on the
    photo shrunk to ``work_long_side_px``."""
    if config.segments == "lsd":
        seg, s = working_lsd(rgb, config.work_long_side_px, config.min_length_px)
    else:
        small, s = working_gray(rgb, config.work_long_side_px)
        seg = _hough_segments(small, config)
    return np.c_[(seg[:, :2] + 0.5) / s - 0.5, (seg[:, 2:] + 0.5) / s - 0.5] if len(seg) else seg.reshape(-1, 4)


#: a side is soft when the step across it (4 px) is less than this share of the fall to where its
#: ramp of lightness ends; crisp outlines (a wall against the sky or the ground) step at once
SOFT_STEP_SHARE = 0.7
#: how far out a soft side is carried at most, of the wall's extent across it
SOFT_REACH = 0.06
#: the least fall of lightness (of 1) that is a ramp: a wall against a background of its own
#: lightness (a red brick wall over a grey-green ground, 0.28 against 0.30-0.33) drifts by a few
#: hundredths; the laboratory walls' shadowed rims fall by 0.25-0.45
SOFT_MIN_FALL = 0.1


#: how much a soft side's lightness profile (a quarter's samples averaged) wavers by itself: the
#: stones' grain, speckle and the JPEG's noise. A ramp goes on through a rise smaller than this, and
#: a side is lighter beyond only by more than this. Without it the laboratory photo SC1 drawn 3 and
#: 6 times larger lost its base's rim (a rise of 0.01 one pixel out ended the ramp in 2 of the 4
#: quarters): H 0.853 m against 0.889 m at its own size, with a sigma of 1.7 % instead of 3.0 %
SOFT_NOISE = 0.02
#: a rim darker than this (lightness of 1, where its ramp begins) need fall only as much less as it
#: is darker (SOFT_MIN_FALL times its lightness over this): shade and a shorter exposure scale a
#: ramp with the light. The laboratory photos' rims begin at 0.23-0.31; two stops darker, or shaded
#: towards the foot, at 0.12-0.18, where they fall by 0.08-0.14 and were not carried (SC1 two stops
#: darker: H -15.6 %, 4.3 sigma, against -1.2 % at its own light)
SOFT_LIGHT = 0.25
#: nor need a ramp fall by more than this share of the wall's own lightness spread (its 90th less
#: its 10th percentile, :func:`_wall_spread`): a flatter photo (haze, flare, a flat tone curve)
#: scales the rim's fall and the wall's spread alike. The laboratory photos spread 0.41-0.45 (so
#: SOFT_MIN_FALL rules there) and their rims fall 0.1-0.16 at the base; with the contrast at 0.7
#: or halved, 0.21-0.31 and 0.05-0.10, where the base was not carried (SC4 at 0.7: H -8.5 %, 3.9
#: sigma). Blender's renders spread 0.13-0.27; none of their sides changed (64 outlines)
SOFT_SPREAD_SHARE = 0.25
#: a photo longer than this (px) has its soft sides' profiles sampled and blurred at this
#: resolution's pixel, not its own, so that a ramp is read over the same share of the wall on a
#: 12 or 48 MP photo as on the 0.5-6 MP photos it was measured on
SOFT_WORK_PX = 3000


def _ramp_end(prof: np.ndarray, offs: np.ndarray, spread: float = math.inf) -> float:
    """Where a soft side's ramp ends on one lightness profile across it (0.0 when the side is
    crisp there): see :func:`carry_soft_sides` (``spread``: the wall's, :func:`_wall_spread`)."""
    h = float(offs[1] - offs[0]) if len(offs) > 1 else 1.0
    i0 = int(np.argmin(np.abs(offs)))
    inside = float(prof[max(0, i0 - 2)])
    if prof[min(len(prof) - 1, i0 + 2)] - inside >= SOFT_NOISE:
        return 0.0  # lighter beyond the side: no shaded rim of the wall (see SOFT_MIN_FALL)
    fall = inside - prof  # grows outward while lightness falls away from the wall's
    k = i0
    run_max = fall[i0]
    for j in range(i0 + 1, len(fall)):
        if fall[j] < run_max - max(0.1 * run_max, SOFT_NOISE):
            break  # the profile turns back: the ramp has ended before
        run_max = max(run_max, fall[j])
        k = j
    total = float(fall[i0 : k + 1].max())
    step = float(fall[min(len(fall) - 1, i0 + 2)])
    end = float(offs[int(np.argmax(fall[i0 : k + 1] >= 0.9 * total)) + i0]) if total > 0 else 0.0
    if end >= offs[-1] - 3.0 * h:
        return 0.0  # still falling at the reach: the background's own gradient (a sky), not a rim
    min_fall = min(SOFT_MIN_FALL * min(1.0, inside / SOFT_LIGHT), SOFT_SPREAD_SHARE * spread)
    return end if total > min_fall and step < SOFT_STEP_SHARE * total and end > 2.0 * h else 0.0


def _wall_spread(rgb: np.ndarray, quad: np.ndarray, *, to_photo=None) -> float:
    """How much the wall's lightness (its channels' mean) spreads: its 90th less its 10th percentile
    over a 40 x 40 grid of the quadrilateral ``quad`` (LL, LR, UR, UL; ideal coordinates of
    ``to_photo``'s lens where given), its middle 80 % each way, nearest pixels."""
    t = np.linspace(0.1, 0.9, 40)
    u, v = np.meshgrid(t, t)
    q = np.asarray(quad, dtype=np.float64)
    pts = ((1 - u) * (1 - v))[..., None] * q[0] + (u * (1 - v))[..., None] * q[1]
    pts = pts + (u * v)[..., None] * q[2] + ((1 - u) * v)[..., None] * q[3]
    pts = pts.reshape(-1, 2)
    if to_photo is not None:
        pts = to_photo(pts)
    rows, cols = rgb.shape[:2]
    r = np.clip(np.round(pts[:, 1]).astype(np.intp), 0, rows - 1)
    c = np.clip(np.round(pts[:, 0]).astype(np.intp), 0, cols - 1)
    gray = np.asarray(rgb[r, c, :3], dtype=np.float64).mean(axis=-1)
    lo, hi = np.percentile(gray, [10, 90])
    return float(hi - lo)


def carry_soft_sides(rgb: np.ndarray, quad: np.ndarray, *, to_photo=None) -> tuple[np.ndarray, np.ndarray]:
    """Carry each soft side of the outline ``quad`` (LL, LR, UR, UL) outward to where its ramp of
    lightness ends; returns the quadrilateral and, per corner, how far it moved (px, the sides'
    root sum square), which the corner's sigma takes on: where a wall ends inside a shadow, the
    outline is uncertain by about that much.

    The appearance of a wall's face ends where its plaster or its stones end; the masonry goes on
    where lightness fades gradually beyond: a mortar bed under a loading beam, a shadowed base on
    its footing (measured on the laboratory photos: 10-20 px ramps at the top and the base, which
    the database's height includes). Across a side, the lightness profile (the photo blurred by a
    pixel, averaged over each quarter of the side's middle 70 %) is followed outward from the side
    while it keeps falling towards its least within :data:`SOFT_REACH` of the wall's extent. Only a
    fall: a wall's rim in shade is darker than its face, while what is lighter beyond a side is not
    the wall's (a dark brick wall's cast shadow on a pale ground, lighter than the wall and
    brightening away from it, was carried across: Blender-rendered walls lost 10-22 % of their
    height to a base moved 42 px onto the shadow's far edge). A quarter is soft when its own step
    (2 px either side) is less than
    :data:`SOFT_STEP_SHARE` of the whole fall, and that fall is more than :data:`SOFT_MIN_FALL`
    (less on a rim darker than :data:`SOFT_LIGHT`, in proportion; at most :data:`SOFT_SPREAD_SHARE` of
    the wall's own spread of lightness, on a flat photo). A side soft in at least three quarters moves to
    where their falls end (the profile within 10 % of its extreme; the median of the quarters). A
    crisp side stays, also one that a lens bends (each quarter steps at once, at its own offset,
    where the side's average profile looked like a ramp). The profile wavers by itself (grain,
    speckle, JPEG): a rise or a lighter step beyond smaller than :data:`SOFT_NOISE` is not taken
    for the ramp's end. A photo longer than :data:`SOFT_WORK_PX` is sampled every
    ``long side / SOFT_WORK_PX`` pixels and blurred as much, so that the same wall photographed
    with more pixels is read alike. ``to_photo``: as :func:`refine_quad`'s (``quad`` in ideal
    coordinates of that lens)."""
    moved = np.zeros(4)
    lines = []
    centre = quad.mean(axis=0)
    h = 1.0 / _work_scale(rgb.shape, SOFT_WORK_PX)  # the profile's step, px
    spread = _wall_spread(rgb, quad, to_photo=to_photo)
    for i in range(4):
        a, b = quad[i], quad[(i + 1) % 4]
        d = b - a
        length = float(np.linalg.norm(d))
        d = d / max(length, 1e-9)
        n = np.array([d[1], -d[0]])
        if ((a + b) / 2 - centre) @ n < 0:
            n = -n
        across = float(np.linalg.norm(((quad[(i + 2) % 4] + quad[(i + 3) % 4]) - (a + b)) / 2))
        reach = max(3.0 * h, SOFT_REACH * across)
        offs = np.arange(-4.0 * h, reach + 0.5 * h, h)
        ts = np.linspace(0.15, 0.85, 4 * max(4, min(16, int(length / 32))))
        pts = a[None, None, :] + ts[None, :, None] * (b - a)[None, None, :] + offs[:, None, None] * n[None, None, :]
        if to_photo is not None:
            pts = to_photo(pts.reshape(-1, 2)).reshape(pts.shape)
        prof = _blurred_samples(rgb, pts[..., 1].ravel(), pts[..., 0].ravel(), gray=True, blur_px=_SIDE_BLUR_PX * h)
        prof = prof.reshape(len(offs), len(ts))
        ends = [_ramp_end(q.mean(axis=1), offs, spread) for q in np.array_split(prof, 4, axis=1)]
        soft = [e for e in ends if e > 0]
        shift = float(np.median(soft)) if len(soft) >= 3 else 0.0
        moved[i] = shift
        lines.append((a + shift * n, d))
    corners = []
    for i in range(4):
        try:
            corners.append(_intersect(lines[(i - 1) % 4], lines[i]))
        except np.linalg.LinAlgError:
            return quad, np.zeros(4)
    carried = np.array([math.hypot(moved[(i - 1) % 4], moved[i]) for i in range(4)])
    return order_corners(np.array(corners), where="outline refinement"), carried


def straight_lines(rgb: np.ndarray, *, min_fraction: float = 0.15, max_wiggle_px: float = 0.8) -> list[np.ndarray]:
    """Long straight lines of the whole photo (a loading beam's edges, a frame, a building's
    edge, the wall's own sides), as point sets ``(n, 2)`` in its pixels, for the lens's plumb-line
    fit: OpenCV's LSD segments on the photo shrunk to 1400 px, chained where one continues
    another (the same direction within 3 degrees and polarity, the same line within 2 px and 2 % of
    their distance, a gap under 10 % of the photo), kept when a chain spans ``min_fraction`` of the
    photo's diagonal and
    its points lie on a smooth curve (:func:`calib_masonry.calibrate.fit._wiggle` below
    ``max_wiggle_px``, so that a lens may bow it but nothing else does). A stone's edge or a
    crack does not span that far straight."""
    from scipy.sparse.csgraph import connected_components

    from .fit import _wiggle

    small, s = working_gray(rgb, 1400)
    diag = math.hypot(*small.shape[:2])
    seg, _ = working_lsd(rgb, 1400, 0.02 * diag)
    if len(seg) < 2:
        return []
    d = seg[:, 2:] - seg[:, :2]
    length = np.hypot(d[:, 0], d[:, 1])
    u = d / length[:, None]
    # undirected angle for the "same direction" test, but the direction's sign kept for polarity
    same_dir = (u @ u.T) > math.cos(math.radians(3.0))
    nrm = np.c_[-u[:, 1], u[:, 0]]
    # each segment's middle's distance from the other's line, allowed to grow by 2 % of the
    # distance between them (a short segment's direction is known to a degree or so)
    mid = (seg[:, :2] + seg[:, 2:]) / 2
    rel = mid[None, :, :] - seg[:, None, :2]
    dist = np.abs((rel * nrm[:, None, :]).sum(-1))
    apart = np.linalg.norm(mid[None, :, :] - mid[:, None, :], axis=-1)
    along1 = ((seg[None, :, :2] - seg[:, None, :2]) * u[:, None, :]).sum(-1)
    along2 = ((seg[None, :, 2:] - seg[:, None, :2]) * u[:, None, :]).sum(-1)
    gap = np.maximum(np.minimum(along1, along2) - length[:, None], -np.maximum(along1, along2))
    near = same_dir & (np.maximum(dist, dist.T) <= 2.0 + 0.02 * apart) & (np.minimum(gap, gap.T) <= 0.1 * diag)
    _, label = connected_components(near, directed=False)
    out = []
    for c in range(label.max() + 1):
        idx = np.nonzero(label == c)[0]
        pts = np.concatenate([seg[idx, :2], (seg[idx, :2] + seg[idx, 2:]) / 2, seg[idx, 2:]])
        span = float(np.max(np.linalg.norm(pts - pts[0], axis=1)))
        if span < min_fraction * diag or len(idx) < 2 and span < 2 * min_fraction * diag:
            continue
        if _wiggle(pts) > max_wiggle_px:
            continue
        # a single long segment is a line too (two of its points and its middle)
        if len(idx) == 1:
            t = np.linspace(0.0, 1.0, 9)[:, None]
            pts = seg[idx[0], :2] + t * (seg[idx[0], 2:] - seg[idx[0], :2])
        out.append((pts + 0.5) / s - 0.5)
    return out

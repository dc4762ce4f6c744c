"""The wall's outline in a real photo: where the masonry's appearance ends, along its joints' directions.

A real photo holds more than the wall: a test rig, a loading beam, a roof, windows, the ground,
people. Lines alone cannot tell the wall's edges from theirs (a beam's edge is as straight and as
horizontal as a bed joint), and texture (stone grain, painted speckle, stains) gives thousands of
short edges. The outline is found from two cues that do not depend on the scene:

1. **Appearance.** The wall is the one large region whose colour and texture are the masonry's.
   Its appearance is learnt from the photo's centre (a photo of a wall is framed on it) against the
   photo's border strip, as per-feature histograms (naive Bayes over CIELAB lightness and colour,
   both smoothed, and the local contrast, which tells a speckled or jointed wall from a smooth beam),
   and relearnt twice from the regions that result. The wall is the component of likely-wall pixels
   that holds the seed.
2. **Directions.** Long line segments (OpenCV's LSD, an a-contrario detector that does not fire on
   texture, run on the photo shrunk so that specks vanish) give the bed and head joints' vanishing
   points (RANSAC, as :mod:`.lines`); a projective map sends both to infinity, where the wall is an
   upright rectangle. The rectangle is the one that holds the most likely-wall pixels net of the
   unlikely ones (an integral image, coordinate ascent), then each side is let turn onto the region's
   boundary (a robust line), so a wrong vanishing point cannot tilt it.

What is not the wall is refused rather than taken: a side that runs along the photo's border (the
wall fills the frame and goes on beyond it) and a region whose appearance is not distinct from its
surroundings end in :class:`~calib_masonry.errors.FitFailed` naming ``--corners``. Occluders (a rig,
a beam, scaffolding, vegetation, people), given as polygons in photo pixels, take no part: they teach
the appearance model nothing and count as neither wall nor not-wall.

Convention: image points ``(x = column, y = row)``, pixel centres at integers, origin top-left.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from .._morphology import binary as _binary
from ..errors import FitFailed, InputError
from .camera import CORNERS_FLAG, FILLS_PHOTO_ADVICE, order_corners

__all__ = [
    "OutlineConfig",
    "Outline",
    "detect_outline",
    "lsd_segments",
    "occluded_mask",
    "polygon_mask",
    "segments_outside",
    "wall_probability",
]


@dataclass(frozen=True)
class OutlineConfig:
    """``appearance_long_side_px``: the size the appearance model works at; ``lsd_long_side_px``:
    the size the long segments are found at (texture smaller than a few pixels there vanishes);
    ``min_segment_fraction``: a segment's least length, of the photo's long side; ``seed_fraction``:
    the side of the central square the wall's appearance is first learnt from, of the photo's short
    side (small enough to lie on a tall, narrow wall); ``border_fraction``: the strip along
    the photo's edges the surroundings' appearance is first learnt from; ``border_touch_fraction``:
    a side closer than this (of the long side) to the photo's edge, over most of its length, lies on
    the photo's border, not on the wall's edge."""

    appearance_long_side_px: int = 600
    lsd_long_side_px: int = 700
    min_segment_fraction: float = 0.025
    seed_fraction: float = 0.15
    border_fraction: float = 0.06
    border_touch_fraction: float = 0.012
    bins: int = 32
    grid: int = 300  # the rectified grid the rectangle is sought on
    seed: int = 0


@dataclass(frozen=True)
class Outline:
    """The outline found: ``corners_px`` (4, 2) LL, LR, UR, UL in the photo's pixels; the vanishing
    points of the bed and head families (homogeneous, photo pixels; None when a family had too few
    segments and the image axis was assumed); the wall's probability map at ``scale`` (photo
    pixels times ``scale``); its mean inside the outline and in a band around it."""

    corners_px: np.ndarray
    vp_bed: np.ndarray | None
    vp_head: np.ndarray | None
    probability: np.ndarray
    scale: float
    inside: float
    around: float


def lsd_segments(gray: np.ndarray, *, long_side_px: int | None = None, min_length_px: float = 0.0) -> np.ndarray:
    """Line segments ``(n, 4)`` ``x1, y1, x2, y2`` (pixels of ``gray``) by OpenCV's Line Segment
    Detector, run at ``long_side_px`` (LSD's own Gaussian shrink; default: as given), no shorter
    than ``min_length_px``."""
    import cv2

    g8 = np.ascontiguousarray((np.clip(gray, 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8))
    scale = 1.0 if long_side_px is None else min(1.0, long_side_px / max(gray.shape[:2]))
    lsd = cv2.createLineSegmentDetector(cv2.LSD_REFINE_STD, scale)
    found = lsd.detect(g8)[0]
    if found is None:
        return np.zeros((0, 4))
    seg = found.reshape(-1, 4).astype(np.float64)
    length = np.hypot(seg[:, 2] - seg[:, 0], seg[:, 3] - seg[:, 1])
    return seg[length >= min_length_px]


def polygon_mask(shape: tuple[int, int], polygon: np.ndarray) -> np.ndarray:
    """``(rows, cols)`` True at the pixel centres inside ``polygon`` ``(n, 2)`` (x, y pixels)."""
    from skimage.draw import polygon as fill

    poly = np.asarray(polygon, dtype=np.float64).reshape(-1, 2)
    out = np.zeros(shape, dtype=bool)
    rr, cc = fill(poly[:, 1], poly[:, 0], shape)
    out[rr, cc] = True
    return out


def occluded_mask(shape: tuple[int, int], occluders, scale: float = 1.0) -> np.ndarray | None:
    """The union of the occluder polygons (photo pixels) at ``scale``, or None without any."""
    if not occluders:
        return None
    out = np.zeros(shape, dtype=bool)
    for poly in occluders:
        p = (np.asarray(poly, dtype=np.float64).reshape(-1, 2) + 0.5) * scale - 0.5
        out |= polygon_mask(shape, p)
    return out


def segments_outside(seg: np.ndarray, occluded: np.ndarray | None, scale: float = 1.0) -> np.ndarray:
    """The segments none of whose three points (ends and middle) lies in ``occluded`` (at ``scale``
    of the segments' pixels)."""
    if occluded is None or len(seg) == 0:
        return seg
    rows, cols = occluded.shape
    keep = np.ones(len(seg), dtype=bool)
    for t in (0.0, 0.5, 1.0):
        p = (seg[:, :2] * (1 - t) + seg[:, 2:] * t + 0.5) * scale - 0.5
        r = np.clip(np.round(p[:, 1]).astype(int), 0, rows - 1)
        c = np.clip(np.round(p[:, 0]).astype(int), 0, cols - 1)
        keep &= ~occluded[r, c]
    return seg[keep]


LIGHT_WEIGHT = 1.0


def _features(rgb_small: np.ndarray) -> list[tuple[np.ndarray, float]]:
    """Per-pixel appearance of a (shrunk) photo: CIELAB lightness (and, in a colour photo, a* and
    b*) smoothed by 2 px; the log of the local contrast (the lightness's standard deviation in a
    Gaussian window of 3 px); and the relative contrast (that deviation over the mean, in a window
    of 0.7 % of the long side), which a wall's grain, speckle or joints keep in its shadowed parts
    while its lightness falls (measured on the laboratory photos: 0.11-0.18 on the wall, lit or
    not, 0.34-0.53 on the steel beams and the concrete footing)."""
    from skimage.color import rgb2lab

    lab = rgb2lab(np.clip(rgb_small, 0.0, 1.0).astype(np.float32))
    light = lab[..., 0]
    smooth = ndimage.gaussian_filter(lab, (2.0, 2.0, 0.0))
    mean = ndimage.gaussian_filter(light, 3.0)
    mean_sq = ndimage.gaussian_filter(light * light, 3.0)
    contrast = np.log1p(np.sqrt(np.maximum(mean_sq - mean * mean, 0.0)))
    feats = [(smooth[..., 0], LIGHT_WEIGHT), (contrast, 1.0), (relative_contrast(light), 1.0)]
    if float(np.percentile(np.hypot(lab[..., 1], lab[..., 2]), 99)) > 3.0:  # a colour photo
        feats += [(smooth[..., 1], 1.0), (smooth[..., 2], 1.0)]
    return feats


def relative_contrast(light: np.ndarray) -> np.ndarray:
    """The relative contrast of a lightness image (CIELAB L, 0-100): its standard deviation over its
    mean in a Gaussian window of 0.7 % of the long side (at least 2 px). Shade, which scales both,
    leaves it as it is: masonry keeps 0.11-0.18 in its shadowed parts (the laboratory photos)."""
    w = max(2.0, 0.007 * max(light.shape))
    mean = ndimage.gaussian_filter(light, w)
    sd = np.sqrt(np.maximum(ndimage.gaussian_filter(light * light, w) - mean * mean, 0.0))
    return sd / np.maximum(mean, 1.0)


def _binned(feats: list[tuple[np.ndarray, float]], bins: int) -> list[tuple[np.ndarray, float]]:
    """Each feature of :func:`_features` as its bin ``(rows, cols)`` of ``bins`` between its 0.5 and
    99.5 percentiles, with its weight; a feature that is constant over the photo is left out. (The
    bins depend on the photo alone: computed once for every pass of :func:`wall_probability`.)"""
    out = []
    for f, weight in feats:
        lo, hi = np.percentile(f, [0.5, 99.5])
        if hi - lo < 1e-6:
            continue
        out.append((np.clip(((f - lo) / (hi - lo) * bins).astype(np.intp), 0, bins - 1), weight))
    return out


def _log_ratio(binned: list[tuple[np.ndarray, float]], inner: np.ndarray, outer: np.ndarray, bins: int) -> np.ndarray:
    """Naive Bayes: the sum over features of log p(f | wall) - log p(f | surroundings), from
    ``bins``-bin histograms (one count added to every bin) of the pixels ``inner`` and ``outer``
    (the features as :func:`_binned` gives them)."""
    score = np.zeros(inner.shape, dtype=np.float64)
    for idx, weight in binned:
        h_in = np.bincount(idx[inner], minlength=bins) + 1.0
        h_out = np.bincount(idx[outer], minlength=bins) + 1.0
        ratio = np.log(h_in / h_in.sum()) - np.log(h_out / h_out.sum())
        score += weight * ratio[idx]
    return score


def wall_probability(
    rgb_small: np.ndarray,
    seed: np.ndarray,
    *,
    occluded: np.ndarray | None = None,
    fill: np.ndarray | None = None,
    config: OutlineConfig = OutlineConfig(),
    fill_band: bool = True,
    binned: list[tuple[np.ndarray, float]] | None = None,
) -> np.ndarray:
    """The probability ``(rows, cols)`` that each pixel of a (shrunk) photo ``(rows, cols, 3)`` is
    the wall's, learnt from the pixels ``seed`` (the wall's) against the photo's border strip (and
    the strip along a filled margin ``fill``, which is itself no one's surroundings, unless
    ``fill_band`` is False), then twice from the regions that result (eroded and dilated by 5 px).
    ``occluded`` pixels teach nothing and are given 0.5 (neither). ``binned``: the photo's
    features as :func:`_binned` gives them, if computed already."""
    rows, cols = seed.shape
    feats = _binned(_features(rgb_small), config.bins) if binned is None else binned
    m = max(2, round(config.border_fraction * max(rows, cols)))
    outer = np.zeros((rows, cols), dtype=bool)
    outer[:m] = outer[-m:] = True
    outer[:, :m] = outer[:, -m:] = True
    if fill is not None and fill_band:  # a filled margin's edge is where the photo's own border is
        outer |= _binary("dilate", fill, m)
    inner = seed & ~outer
    free = np.ones((rows, cols), dtype=bool) if occluded is None else ~occluded
    prob = np.full((rows, cols), 0.5)
    for _ in range(3):
        a, b = inner & free, outer & free
        if a.sum() < 50 or b.sum() < 50:
            break
        score = ndimage.gaussian_filter(_log_ratio(feats, a, b, config.bins), 2.0)
        prob = 1.0 / (1.0 + np.exp(-np.clip(score, -30.0, 30.0)))
        likely = prob > 0.5
        inner = _binary("erode", likely, 5) & _component_of(likely, seed)
        outer = ~_binary("dilate", likely, 5)
    if occluded is not None:
        prob = np.where(occluded, 0.5, prob)
    return prob


def _border_fill(rgb_small: np.ndarray) -> np.ndarray | None:
    """Where a photo was filled, not photographed: flat regions (the colour constant to half a
    grey level over 5 x 5 pixels) that touch the photo's border and cover at least 0.5 % of it, as
    a rotated or perspective-corrected photo's black or white margins. They are no one's
    surroundings: the appearance model learnt the surroundings from them alone and took the dark
    laboratory for wall (measured on a rotated view of a laboratory photo). None without any."""
    g = np.asarray(rgb_small, dtype=np.float32).mean(axis=-1)
    mean = ndimage.uniform_filter(g, 5)
    var = ndimage.uniform_filter(g * g, 5) - mean * mean
    flat = var < (0.5 / 255.0) ** 2
    lab, n = ndimage.label(flat)
    if n == 0:
        return None
    border = np.unique(np.concatenate([lab[0], lab[-1], lab[:, 0], lab[:, -1]]))
    border = border[border > 0]
    if len(border) == 0:
        return None
    sizes = np.bincount(lab.ravel())
    keep = border[sizes[border] >= 0.005 * g.size]
    if len(keep) == 0:
        return None
    return _binary("dilate", np.isin(lab, keep), 2)


def _component_of(mask: np.ndarray, seed: np.ndarray) -> np.ndarray:
    """The connected components of ``mask`` that overlap ``seed`` most (the largest overlap)."""
    lab, n = ndimage.label(mask)
    if n == 0:
        return mask
    counts = np.bincount(lab[seed], minlength=n + 1)
    counts[0] = 0
    if counts.max() == 0:
        return np.zeros_like(mask)
    return lab == int(np.argmax(counts))


#: a hole in the wall's region is an opening (a window, a door's glass) where it holds at least this
#: share of the region: a Blender facade's windows 1.2-8.8 %; the laboratory photos' speckle targets,
#: cracks and dark stones at most 0.55 % (filled, they moved the laboratory views' H by up to 1.9 %)
OPENING_MIN_FRACTION = 0.01


def _openings(region: np.ndarray) -> np.ndarray:
    """The holes of ``region`` that are openings (:data:`OPENING_MIN_FRACTION`), as a mask: its
    holes, and its pockets open at the bottom alone (the region to the left and to the right in
    the same row and above in the same column: a door, or a row of windows whose sills the region
    does not close under them; a Blender facade's ground floor, its base on the windows' heads,
    H -44 %). A hole is such a pocket too: walking along its row or up its column from any of its
    pixels meets the region before the photo's border."""
    left = np.maximum.accumulate(region, axis=1)
    right = np.maximum.accumulate(region[:, ::-1], axis=1)[:, ::-1]
    above = np.maximum.accumulate(region, axis=0)
    holes = left & right & above & ~region
    if not holes.any():
        return holes
    lab, n = ndimage.label(holes)
    size = ndimage.sum(holes, lab, np.arange(1, n + 1))
    return np.r_[False, size >= OPENING_MIN_FRACTION * float(region.sum() + holes.sum())][lab]


def _with_openings(prob: np.ndarray, region: np.ndarray, occluded: np.ndarray | None) -> np.ndarray:
    """``prob`` with the openings in the wall's ``region`` (:func:`_openings`) as sure wall (but
    where ``occluded``: neutral, as before), for the outline's rectangle (:func:`_fit_rectangle`)
    alone: a facade's windows lie within its outline, but their glass and frames are unlike its
    masonry, and where they fill half a floor's width the rows through them held less wall than
    not, so the rectangle stopped on their heads (a Blender facade with a row of ground-floor
    windows: its base 240-310 px high, H -48 % at a sigma of 0.15 % with the width given). The
    region itself is left as it is: it also chooses the segments the vanishing points are found
    from, and filled it moved them on 99 of 440 Blender walls."""
    holes = _openings(region)
    if occluded is not None:
        holes &= ~occluded
    return np.where(holes, 1.0, prob) if holes.any() else prob


# A family's vanishing point is taken only where its segments lie at least this far apart across
# their direction (a fraction of the photo's long side; :func:`_across`): segments along one line,
# or a band of them (a loading beam's edges) and one more, meet anywhere along it, and the least
# squares put the point on the wall, beside the photo, or where that one segment's tilt says
# (measured on turned and zoomed laboratory photos: an outline out of the wall, or a base 76
# degrees from the rows). The wall's own joints on the three laboratory photos lie 11-57 % apart
MIN_VP_SPREAD = 0.05


def _rectifying_map(vp_bed: np.ndarray, vp_head: np.ndarray, centre: np.ndarray) -> np.ndarray:
    """A projective map of photo pixels that sends the bed vanishing point to infinity along +u and
    the head one along +v, fixing the photo's ``centre`` (homogeneous points in, ``(u, v, 1)`` out)."""
    o = np.array([centre[0], centre[1], 1.0])
    line = np.cross(vp_bed, vp_head)
    p = np.stack([np.cross(vp_head, o), np.cross(vp_bed, o), line])
    if (p @ o)[2] < 0:
        p = -p
    # scale u and v (each on its own, so that the axes stay the families' directions) so that a
    # pixel's step along x moves u, and one along y moves v, by one at the centre
    q0 = p @ o
    ex, ey = p @ (o + [1.0, 0, 0]), p @ (o + [0, 1.0, 0])
    du = ex[0] / ex[2] - q0[0] / q0[2]
    dv = ey[1] / ey[2] - q0[1] / q0[2]
    ku = 1.0 / du if abs(du) > 1e-12 else 1.0
    kv = 1.0 / dv if abs(dv) > 1e-12 else 1.0
    u0, v0 = q0[0] / q0[2], q0[1] / q0[2]
    t = np.array([[ku, 0.0, centre[0] - ku * u0], [0.0, kv, centre[1] - kv * v0], [0.0, 0.0, 1.0]])
    return t @ p


def _project(h: np.ndarray, pts: np.ndarray) -> np.ndarray:
    q = np.c_[pts, np.ones(len(pts))] @ h.T
    return q[:, :2] / q[:, 2:3]


def _last_argmax(a: np.ndarray) -> int:
    """The index of the last of the largest values of ``a``."""
    return len(a) - 1 - int(np.argmax(a[::-1]))


def _fit_rectangle(
    prob: np.ndarray,
    rect_from_px: np.ndarray,
    region: np.ndarray,
    n: int,
    reach: float = 0.04,
    core: np.ndarray | None = None,
) -> np.ndarray | None:
    """The quadrilateral that holds the most of ``prob - 0.5`` (likely-wall pixels net of unlikely
    ones), sought on an ``n x n`` grid over the ``region``'s extent in the rectified frame (grown by
    a third), where the wall is about an upright rectangle.

    First the upright rectangle, by coordinate ascent from the extent's 2-98 % box and from the
    ``core``'s (the region without its thin bands, as a horizon's soft edge that joins the wall's
    foot: from the extent alone the ascent settled on the horizon), the better of the two (an
    integral image gives each candidate's sum at once); then each side, in turn, is let tilt: its two ends
    move independently by up to ``reach`` of the grid, so that a side follows the region where the
    vanishing point was off (column or row sums of the grid give each candidate's sum). Returns the
    corners in pixels (any order), or None."""
    ys, xs = np.nonzero(region[::2, ::2])
    if len(xs) < 50:
        return None
    q = np.c_[2.0 * xs, 2.0 * ys, np.ones(len(xs))] @ rect_from_px.T
    if not (np.all(q[:, 2] > 0) or np.all(q[:, 2] < 0)):
        return None  # the region crosses the vanishing line: the directions cannot be right
    uv = q[:, :2] / q[:, 2:3]
    lo, hi = np.percentile(uv, 2, axis=0), np.percentile(uv, 98, axis=0)
    c, half = (lo + hi) / 2, np.maximum((hi - lo) / 2 * 1.33, 1.0)
    us = np.linspace(c[0] - half[0], c[0] + half[0], n)
    vs = np.linspace(c[1] - half[1], c[1] + half[1], n)
    uu, vv = np.meshgrid(us, vs)
    px_from_rect = np.linalg.inv(rect_from_px)
    back = px_from_rect @ np.stack([uu.ravel(), vv.ravel(), np.ones(uu.size)])
    with np.errstate(divide="ignore", invalid="ignore"):
        x, y = back[0] / back[2], back[1] / back[2]
    ok = np.isfinite(x) & np.isfinite(y)
    x, y = np.where(ok, x, -10.0), np.where(ok, y, -10.0)
    w = ndimage.map_coordinates(prob, [y, x], order=1, mode="constant", cval=0.0).reshape(n, n) - 0.5
    s = np.zeros((n + 1, n + 1))
    s[1:, 1:] = np.cumsum(np.cumsum(w, axis=0), axis=1)

    def energy(r0, r1, c0, c1):
        return s[r1, c1] - s[r0, c1] - s[r1, c0] + s[r0, c0]

    k = np.arange(n + 1)
    starts = [[round(0.125 * n), round(0.875 * n), round(0.125 * n), round(0.875 * n)]]
    if core is not None:
        cy, cx = np.nonzero(core[::2, ::2])
        if len(cx) >= 20:
            cq = np.c_[2.0 * cx, 2.0 * cy, np.ones(len(cx))] @ rect_from_px.T
            cuv = cq[:, :2] / cq[:, 2:3]
            clo, chi = np.percentile(cuv, 2, axis=0), np.percentile(cuv, 98, axis=0)
            gc0, gc1 = np.clip(np.round((np.array([clo[0], chi[0]]) - us[0]) / (us[1] - us[0])), 0, n)
            gr0, gr1 = np.clip(np.round((np.array([clo[1], chi[1]]) - vs[0]) / (vs[1] - vs[0])), 0, n)
            if gr1 - gr0 >= 2 and gc1 - gc0 >= 2:
                starts.append([int(gr0), int(gr1), int(gc0), int(gc1)])
    best = None
    for box in starts:
        for _ in range(20):
            old = list(box)
            r0, r1, c0, c1 = box
            # of equal sums the tightest box: rows and columns that carry no evidence (a
            # photo's flat fill, or an occluder: 0.5, so 0 here) are not taken in (the first
            # of equal tops took a Blender wall's uniform sky, 320 px above its top)
            box[0] = r0 = _last_argmax(energy(k[:r1], r1, c0, c1))
            box[1] = r1 = r0 + 1 + int(np.argmax(energy(r0, k[r0 + 1 :], c0, c1)))
            box[2] = c0 = _last_argmax(energy(r0, r1, k[:c1], c1))
            box[3] = c0 + 1 + int(np.argmax(energy(r0, r1, c0, k[c0 + 1 :])))
            if box == old:
                break
        if best is None or energy(*box) > energy(*best):
            best = box
    r0, r1, c0, c1 = best
    if r1 - r0 < 4 or c1 - c0 < 4:
        return None
    # the sides as lines of the grid: top and base rows as functions of the column, the ends'
    # columns as functions of the row, each given by its value at the two ends of its span
    sides = {"top": [r0, r0], "base": [r1, r1], "left": [c0, c0], "right": [c1, c1]}
    col_cum = np.vstack([np.zeros((1, n)), np.cumsum(w, axis=0)])  # (n + 1, n): rows above r in column j
    row_cum = np.hstack([np.zeros((n, 1)), np.cumsum(w, axis=1)])  # (n, n + 1)
    span = 2.0 * max(1, round(reach * n / 2))

    def interp(cum, pos, idx, along_rows):
        pos = np.clip(pos, 0, n)
        i0 = np.clip(np.floor(pos).astype(int), 0, n - 1)
        f = pos - i0
        if along_rows:  # cum (n + 1, n): value at row pos of column idx
            return cum[i0, idx] * (1 - f) + cum[i0 + 1, idx] * f
        return cum[idx, i0] * (1 - f) + cum[idx, i0 + 1] * f

    for _ in range(3):
        for name in ("top", "base", "left", "right"):
            horizontal = name in ("top", "base")
            if horizontal:
                a0, a1 = (sides["left"][0] + sides["left"][1]) / 2, (sides["right"][0] + sides["right"][1]) / 2
            else:
                a0, a1 = (sides["top"][0] + sides["top"][1]) / 2, (sides["base"][0] + sides["base"][1]) / 2
            idx = np.arange(max(0, math.ceil(a0)), min(n, math.floor(a1)))
            if len(idx) < 4:
                continue
            t = (idx - a0) / max(a1 - a0, 1e-9)
            other = {"top": "base", "base": "top", "left": "right", "right": "left"}[name]
            o0, o1 = sides[other]
            other_pos = o0 + (o1 - o0) * t
            cum = col_cum if horizontal else row_cum
            far = interp(cum, other_pos, idx, horizontal)
            sign = 1.0 if name in ("base", "right") else -1.0
            # coarse steps over the whole reach, then half-pixel steps about the best
            for steps in (np.arange(-span, span + 1e-9, 2.0), np.arange(-2.0, 2.0 + 1e-9, 0.5)):
                e0, e1 = sides[name]
                ca = e0 + steps[:, None, None]
                cb = e1 + steps[None, :, None]
                pos = ca + (cb - ca) * t[None, None, :]  # (k, k, len(idx))
                near = interp(cum, pos, idx[None, None, :], horizontal)
                total = (sign * (near - far[None, None, :])).sum(axis=-1)
                # of equal sums the side's position farthest in (as for the box above)
                ties = np.argwhere(total == total.max())
                i, j = ties[np.argmin(sign * (steps[ties[:, 0]] + steps[ties[:, 1]]))]
                sides[name] = [e0 + steps[i], e1 + steps[j]]

    def grid_to_px(points):  # (row, col) grid positions -> photo pixels
        rr, cc = points[:, 0], points[:, 1]
        u = us[0] + (cc - 0.5) * (us[1] - us[0])
        v = vs[0] + (rr - 0.5) * (vs[1] - vs[0])
        return _project(px_from_rect, np.c_[u, v])

    a0, a1 = (sides["left"][0] + sides["left"][1]) / 2, (sides["right"][0] + sides["right"][1]) / 2
    b0, b1 = (sides["top"][0] + sides["top"][1]) / 2, (sides["base"][0] + sides["base"][1]) / 2
    lines = []
    for name in ("base", "right", "top", "left"):
        e0, e1 = sides[name]
        if name in ("top", "base"):
            pts = np.array([[e0, a0], [e1, a1]])
        else:
            pts = np.array([[b0, e0], [b1, e1]])
        p = grid_to_px(pts)
        lines.append(np.cross(np.r_[p[0], 1.0], np.r_[p[1], 1.0]))
    corners = []
    for i in range(4):
        c_ = np.cross(lines[(i - 1) % 4], lines[i])
        if abs(c_[2]) < 1e-12:
            return None
        corners.append(c_[:2] / c_[2])
    corners = np.array(corners)
    return corners if np.all(np.isfinite(corners)) else None


def _upright(quad: np.ndarray, max_deg: float = 45.0) -> bool:
    """Whether a quadrilateral (corners in any order) is a wall's outline as a photo shows it: convex,
    its base and top within ``max_deg`` of the photo's rows and its ends of its columns. A pair of
    vanishing points that are not the joints' (from the few bed segments of a beam's edge, say)
    rectifies the photo into a shape whose best rectangle is none of the wall's sides (a base
    76 degrees from the rows was taken, measured on a turned laboratory photo)."""
    try:
        q = order_corners(quad, where="automatic mode")
    except InputError:
        return False
    d = np.roll(q, -1, axis=0) - q  # base, right end, top (reversed), left end (reversed)
    off_rows = np.degrees(np.arctan2(np.abs(d[:, 1]), np.abs(d[:, 0])))
    return bool(np.all(off_rows[[0, 2]] <= max_deg) and np.all(off_rows[[1, 3]] >= 90.0 - max_deg))


def _families(seg: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    ang = np.degrees(np.arctan2(seg[:, 3] - seg[:, 1], seg[:, 2] - seg[:, 0])) % 180.0
    from_h = np.minimum(ang, 180.0 - ang)
    return seg[from_h < 35.0], seg[np.abs(ang - 90.0) < 30.0]


def _across(seg: np.ndarray, vp: np.ndarray) -> float:
    """How far apart, across their direction, the segments ``(n, 4)`` that meet in ``vp`` lie: the
    range of their midpoints' offsets from the line through their mean midpoint and ``vp``, of
    four or more without the outermost at each end (one segment away from a band of them spreads
    nothing: its tilt alone would place the point)."""
    mid = (seg[:, :2] + seg[:, 2:]) / 2
    m = mid.mean(axis=0)
    d = vp[:2] - m * vp[2]  # towards the point (at infinity: its direction)
    norm = np.linalg.norm(d)
    if norm == 0:
        return 0.0
    off = np.sort((mid - m) @ (np.array([-d[1], d[0]]) / norm))
    return float(off[-2] - off[1]) if len(off) >= 4 else float(off[-1] - off[0])


def _vp(seg: np.ndarray, shape: tuple[int, int], axis: np.ndarray, rng: np.random.Generator, tol_px: float):
    """A family's vanishing point (homogeneous, pixels) by RANSAC and least squares, or the image
    axis's point at infinity when fewer than four segments support one, the point lies inside the
    photo, or its segments do not place it (:data:`MIN_VP_SPREAD`)."""
    from .segments import vanishing_point

    if len(seg) < 4:
        return axis, None
    centre = np.array([shape[1] - 1, shape[0] - 1]) / 2.0
    scale = float(max(shape))
    norm = np.c_[(seg[:, :2] - centre) / scale, (seg[:, 2:] - centre) / scale]
    try:
        vp, inl = vanishing_point(norm, tol_px / scale, 300, rng)
    except FitFailed:
        return axis, None
    # a point inside the photo is none: every short segment of a speckled or grained surface
    # points at a point among them (a laboratory photo's bed "vanishing point" was found on the
    # wall, 100 px from its corner)
    w = abs(vp[2])
    inside = abs(vp[0]) < 0.5 * shape[1] / scale * w and abs(vp[1]) < 0.5 * shape[0] / scale * w
    if inl.sum() < 3 or inside or _across(norm[inl], vp) < MIN_VP_SPREAD:
        return axis, None
    unscale = np.array([[scale, 0, centre[0]], [0, scale, centre[1]], [0, 0, 1.0]])
    return unscale @ vp, inl


def _inside_convex_mask(shape, quad, factor):
    from .segments import inside_convex

    c = quad.mean(axis=0)
    return inside_convex(shape, c + (quad - c) * factor)


def _band_means(prob: np.ndarray, quad: np.ndarray) -> tuple[float, float]:
    """The mean probability inside ``quad`` and in the band around it (out to 1.15 times its size)."""
    from .segments import inside_convex

    c = quad.mean(axis=0)
    inside = inside_convex(prob.shape, quad)
    outer = inside_convex(prob.shape, c + (quad - c) * 1.15) & ~inside
    a = float(prob[inside].mean()) if inside.any() else 0.0
    b = float(prob[outer].mean()) if outer.any() else 1.0
    return a, b


#: GrabCut runs on the photo shrunk to this long side (its cost grows with the pixels: 1.3 s at
#: 891 px, measured)
GRABCUT_LONG_SIDE_PX = 400
#: GrabCut's ring of "probably not the wall" reaches out to this many times its starting outline
#: (about the outline's centre); beyond it, surely not (:func:`_grab_cut`)
GRABCUT_RING = 1.35
#: GrabCut learns its background's colours first from that ring around the first outline. Where
#: a corner of GrabCut's own outline lies more than half-way out into the ring (this ratio of its
#: distance from the first outline's centre to the first corner's), the first outline cut the
#: wall short and the ring lay on the wall; GrabCut runs once more from
#: its own outline, and that is kept where its quadrilateral fits its cut at least as well
#: (intersection over union), or within one pixel row's share of the outline's height of it (a
#: re-render of 12196 whose third cut reached the foot fitted it 0.9891 against the second's
#: 0.9892, a tie: W +45 %; 12277's third cut, which lost a course, 0.979 against 0.988).
#: Measured: a Blender wall whose first outline stopped two courses above its foot, and GrabCut
#: one course above it (12196: corners 1.25-1.26, W +45 % -> +0.4 %);
#: 1.14 at most on the photos looked at before choosing it (a laboratory photo; the paper
#: example's and five Blender walls 1.05). Of 280 Blender walls it ran on five: one mended, one
#: not kept, three within 0.03 % of before (docs/photo_path.md, 2026-11-30)
GRABCUT_REGROW = 1.0 + (GRABCUT_RING - 1.0) / 2.0  # 1.175


def _grab_cut(small: np.ndarray, quad: np.ndarray, occluded: np.ndarray | None, iterations: int = 3) -> np.ndarray:
    """The wall's pixels (at ``small``'s size) by OpenCV's GrabCut (colour mixtures of the wall and
    of the rest, and a graph cut whose cost follows the photo's edges), on the photo shrunk to
    :data:`GRABCUT_LONG_SIDE_PX`, started from a first outline ``quad`` (``small``'s pixels): its
    core (60 %) is the wall, the outline itself probably the wall, a ring out to
    :data:`GRABCUT_RING` (1.35) times its size probably not, the rest not. The graph cut carries
    the wall through its shadowed parts (a darker course at the base) and stops at the beam or
    footing against it, where the per-pixel model alone did not (measured on the laboratory
    photos)."""
    import cv2

    from .segments import inside_convex, shrink

    rows, cols = small.shape[:2]
    f = min(1.0, GRABCUT_LONG_SIDE_PX / max(rows, cols))
    img = small
    if f < 1.0:
        img = np.stack([shrink(np.ascontiguousarray(small[..., k]), f) for k in range(3)], -1)
    img = np.ascontiguousarray((np.clip(img, 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8))
    shape = img.shape[:2]
    fy, fx = shape[0] / rows, shape[1] / cols
    q = (quad + 0.5) * [fx, fy] - 0.5
    c = q.mean(axis=0)
    mask = np.full(shape, cv2.GC_BGD, np.uint8)
    mask[inside_convex(shape, c + (q - c) * GRABCUT_RING)] = cv2.GC_PR_BGD
    mask[inside_convex(shape, q)] = cv2.GC_PR_FGD
    mask[inside_convex(shape, c + (q - c) * 0.6)] = cv2.GC_FGD
    if occluded is not None:
        occ = ndimage.zoom(occluded.astype(np.float32), (fy, fx), order=1, grid_mode=True, mode="grid-constant")
        mask[(occ[: shape[0], : shape[1]] > 0.5) & (mask != cv2.GC_BGD)] = cv2.GC_PR_BGD
    if (mask == cv2.GC_FGD).any() and (mask == cv2.GC_BGD).any():
        cv2.setRNGSeed(0)
        cv2.grabCut(img, mask, None, np.zeros((1, 65)), np.zeros((1, 65)), iterations, cv2.GC_INIT_WITH_MASK)
    wall = ((mask == cv2.GC_FGD) | (mask == cv2.GC_PR_FGD)).astype(np.float32)
    if f < 1.0:  # back to small's pixels (pixel centres matched as shrink matches them)
        ys = (np.arange(rows) + 0.5) * fy - 0.5
        xs = (np.arange(cols) + 0.5) * fx - 0.5
        wall = ndimage.map_coordinates(wall, np.meshgrid(ys, xs, indexing="ij"), order=1, mode="nearest")
    return wall > 0.5


def _cut_outline(small, start, occluded, no_wall, rect_from_px, grid):
    """GrabCut's wall from the outline ``start`` and the quadrilateral fitted to it (as
    :func:`_fit_rectangle`): ``(quad, its probability map, how well the quad fits the cut)``, the
    last the cut's intersection over union with the quad; None where the cut or the fit fails."""
    shape = small.shape[:2]
    cut = _component_of(_grab_cut(small, start, occluded), _inside_convex_mask(shape, start, 0.5))
    if cut.sum() <= 0.25 * _inside_convex_mask(shape, start, 1.0).sum():
        return None
    cut = cut | _openings(cut)  # the windows are the wall's (see _with_openings)
    prob = ndimage.gaussian_filter(cut.astype(np.float64), 1.0)
    if occluded is not None:
        prob = np.where(occluded, 0.5, prob)
    if no_wall is not None:
        # the fill teaches the appearance nothing, but the outline is not let into it: as
        # neutral (0.5) a side could pivot into it for the few hundredths a blurred corner
        # gave, a reach a round (a head-on Blender wall's top corner climbed 26 px into its
        # uniform sky, 12094). The first pass keeps it neutral: a first outline's top
        # changed that way started GrabCut on a wall's shadow as well (12055)
        prob = np.where(no_wall, 0.0, prob)
    quad = _fit_rectangle(prob, rect_from_px, cut, grid)
    if quad is None or not _upright(quad):
        return None
    try:
        quad = order_corners(quad, where="automatic mode")
    except Exception:  # noqa: BLE001 - a degenerate rectangle: no outline from this cut
        return None
    inside = _inside_convex_mask(shape, quad, 1.0)
    return quad, prob, float((inside & cut).sum() / max((inside | cut).sum(), 1))


def detect_outline(
    rgb: np.ndarray,
    *,
    occluders=(),
    config: OutlineConfig = OutlineConfig(),
) -> Outline:
    """The wall's outline in a photo ``(rows, cols, 3)`` in [0, 1]: see the module's docstring.
    ``occluders``: polygons ``(n, 2)`` in photo pixels to leave out. Raises FitFailed (naming
    ``--corners``) when the wall is not distinct from its surroundings or runs out of the photo."""
    from .segments import shrink

    rows, cols = rgb.shape[:2]
    s = min(1.0, config.appearance_long_side_px / max(rows, cols))
    small = shrink(np.asarray(rgb, dtype=np.float32), s) if s < 1.0 else np.array(rgb, dtype=np.float32)
    srows, scols = small.shape[:2]
    scale_s = scols / cols  # the shrunk photo's pixels per photo pixel (x); rows likewise
    occluded = occluded_mask((srows, scols), occluders, scale_s)
    given = occluded  # the user's occluders alone (a blank photo's fill is no one's occluder)
    fill = _border_fill(small)
    # where the photo holds nothing (a filled margin, or a flat sky taken for one) no wall is: see
    # the second pass below
    no_wall = None
    if fill is not None:
        no_wall = fill if occluded is None else fill & ~occluded
        occluded = fill if occluded is None else occluded | fill
    yy, xx = np.mgrid[0:srows, 0:scols]

    def square(half: float) -> np.ndarray:
        return (np.abs(xx - (scols - 1) / 2) < half) & (np.abs(yy - (srows - 1) / 2) < half)

    half = config.seed_fraction / 2 * min(srows, scols)
    seed = square(half)
    # an occluder over the photo's centre (a person in front of the wall) left the seed nothing to
    # learn the wall from ("no wall found"): the square grows until a quarter of it is free (its
    # occluded pixels teach nothing: wall_probability)
    while given is not None and (seed & ~given).sum() < 0.25 * seed.sum():
        if half >= 0.3 * min(srows, scols):
            raise FitFailed(
                "automatic mode: the occluders cover the middle of the photo, where the wall is looked for; "
                f"click the wall's corners with {CORNERS_FLAG}"
            )
        half *= 1.25
        seed = square(half)
    feats = _binned(_features(small), config.bins)
    prob = wall_probability(small, seed, occluded=occluded, fill=fill, config=config, binned=feats)
    region = _component_of(prob > 0.5, seed)
    small_wall = 0.02 * region.size  # a region under this is no wall found
    if fill is not None:
        # a wall against a uniform sky (flat, so taken for a fill): the strip along the fill's edge
        # is the wall's own rim, learnt as surroundings. On a narrow wall it took the seed with it
        # and left nothing to learn the wall from (Blender-rendered walls: no wall found in 4 of
        # 60); on a wall seen head on, with no end face along either side, it made the wall's
        # joints surroundings and broke the region at a third of its height (12093: 6.5 % of the
        # photo against 19.5 % without the strip). Learnt again without the strip, kept where the
        # wall so found is more than twice as large (elsewhere the strip took a third at most:
        # with it 0.65-1.0 of the region without it on the other 93 of 100 Blender walls and on
        # the 3 laboratory photos; none on 6 walls, the narrow ones above).
        prob_nb = wall_probability(
            small, seed, occluded=occluded, fill=fill, config=config, fill_band=False, binned=feats
        )
        region_nb = _component_of(prob_nb > 0.5, seed)
        if region_nb.sum() > 2.0 * region.sum() or region.sum() < small_wall <= region_nb.sum():
            prob, region = prob_nb, region_nb
    prob = _with_openings(prob, region, occluded)
    if region.sum() < small_wall:
        raise FitFailed(
            "automatic mode: no wall found (no region at the photo's centre looks unlike its surroundings); "
            f"click the wall's corners with {CORNERS_FLAG} {FILLS_PHOTO_ADVICE}"
        )
    # the region without its thin bands (a soft horizon joined to the wall's foot)
    r_open = max(2, round(0.015 * max(srows, scols)))
    disk = np.hypot(*np.mgrid[-r_open : r_open + 1, -r_open : r_open + 1]) <= r_open
    core = _component_of(_binary("dilate", _binary("erode", region, structure=disk), structure=disk), seed)
    # long segments of the whole photo at LSD's coarse size, in the shrunk photo's pixels
    gray = small.mean(axis=-1)
    seg = lsd_segments(
        gray,
        long_side_px=min(config.lsd_long_side_px, max(srows, scols)),
        min_length_px=config.min_segment_fraction * max(srows, scols),
    )
    seg = segments_outside(seg, occluded)
    # the wall's own: segments whose middle lies in the region grown by a tenth of its size
    grow = max(2, round(0.05 * math.sqrt(region.sum())))
    near = _binary("dilate", region, grow)
    mid = np.clip(np.round((seg[:, :2] + seg[:, 2:]) / 2).astype(int), 0, [scols - 1, srows - 1])
    seg = seg[near[mid[:, 1], mid[:, 0]]] if len(seg) else seg
    horiz, vert = _families(seg)
    rng = np.random.default_rng(config.seed)
    vp_head, inl_h = _vp(vert, (srows, scols), np.array([0.0, 1.0, 0.0]), rng, 1.5)
    if inl_h is not None and len(vert) >= 4:
        from .segments import near_heads

        centre = np.array([scols - 1, srows - 1]) / 2.0
        sc = float(max(srows, scols))
        hn = np.c_[(horiz[:, :2] - centre) / sc, (horiz[:, 2:] - centre) / sc]
        vn = np.c_[(vert[:, :2] - centre) / sc, (vert[:, 2:] - centre) / sc]
        near_h = near_heads(hn, vn[inl_h]) * sc
        horiz_use = np.c_[near_h[:, :2] + centre, near_h[:, 2:] + centre]
    else:
        horiz_use = horiz
    vp_bed, inl_b = _vp(horiz_use, (srows, scols), np.array([1.0, 0.0, 0.0]), rng, 1.5)
    centre = np.array([(scols - 1) / 2, (srows - 1) / 2])
    quad = None
    for vb, vh in ((vp_bed, vp_head), (np.array([1.0, 0, 0]), np.array([0, 1.0, 0]))):
        try:
            rect_from_px = _rectifying_map(vb, vh, centre)
        except np.linalg.LinAlgError:
            continue
        quad = _fit_rectangle(prob, rect_from_px, region, config.grid, core=core)
        if quad is not None and _upright(quad):
            break
        quad = None
    if quad is None:
        raise FitFailed(
            f"automatic mode: no wall outline found (the wall's region has no clear sides); click the wall's corners "
            f"with {CORNERS_FLAG}"
        )
    try:
        quad = order_corners(quad, where="automatic mode")
    except Exception:  # noqa: BLE001 - a degenerate rectangle: reported below as no outline
        raise FitFailed(
            f"automatic mode: no wall outline found (the wall's region is degenerate); click the wall's corners "
            f"with {CORNERS_FLAG}"
        ) from None
    # second pass: GrabCut from that outline, and the quadrilateral again on its wall (once more
    # from its own outline where that grew out of the first: GRABCUT_REGROW)
    second = _cut_outline(small, quad, occluded, no_wall, rect_from_px, config.grid)
    if second is not None:
        first, (quad, prob, fit) = quad, second
        c = first.mean(axis=0)
        if np.max(np.linalg.norm(quad - c, axis=1) / np.linalg.norm(first - c, axis=1)) > GRABCUT_REGROW:
            third = _cut_outline(small, quad, occluded, no_wall, rect_from_px, config.grid)
            # a fit within one pixel row of the outline's height of the other's is as good (a tie)
            rows_high = 0.5 * (np.linalg.norm(quad[3] - quad[0]) + np.linalg.norm(quad[2] - quad[1]))
            if third is not None and third[2] >= fit - 1.0 / max(rows_high, 1.0):
                quad, prob = third[:2]
    inside, around = _band_means(prob, quad)
    full = (quad + 0.5) / scale_s - 0.5
    touch = config.border_touch_fraction * max(rows, cols)
    _check_border(full, (rows, cols), touch)
    if inside < 0.6 or around > 0.45 or inside - around < 0.3:
        raise FitFailed(
            f"automatic mode: no clear wall outline (the masonry's appearance inside the outline, {inside:.2f}, is "
            f"not distinct from around it, {around:.2f}); click the wall's corners with {CORNERS_FLAG}"
        )
    unscale = np.array([[1 / scale_s, 0, 0.5 / scale_s - 0.5], [0, 1 / scale_s, 0.5 / scale_s - 0.5], [0, 0, 1.0]])
    return Outline(
        corners_px=full,
        vp_bed=None if inl_b is None else unscale @ vp_bed,
        vp_head=None if inl_h is None else unscale @ vp_head,
        probability=prob,
        scale=scale_s,
        inside=inside,
        around=around,
    )


_SIDE_NAMES = ("base", "right end", "top", "left end")
_EDGE_NAMES = {0: "left", 1: "top", 2: "right", 3: "bottom"}


def _check_border(quad: np.ndarray, shape: tuple[int, int], touch: float) -> None:
    """Refuse a side that runs along the photo's border: the wall goes on beyond the photo there,
    so its corner is not in it."""
    rows, cols = shape
    for i in range(4):
        a, b = quad[i], quad[(i + 1) % 4]
        t = np.linspace(0.1, 0.9, 9)[:, None]
        pts = a + t * (b - a)
        dist = np.stack([pts[:, 0], pts[:, 1], cols - 1 - pts[:, 0], rows - 1 - pts[:, 1]], axis=1)
        near = dist < touch
        for e in range(4):
            if near[:, e].mean() > 0.6:
                raise FitFailed(
                    f"automatic mode: the wall's {_SIDE_NAMES[i]} lies on the photo's {_EDGE_NAMES[e]} edge, so the wall "
                    f"goes on beyond the photo there and its corners are not in it; photograph the whole wall, or "
                    f"click the wall's corners with {CORNERS_FLAG}"
                )

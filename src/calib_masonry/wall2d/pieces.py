"""Masonry units in an orthophoto: the joints found as lines, the wall partitioned along them.

A real wall's face has texture at every scale below a unit: stone grain, painted speckle targets,
stains, plaster. A threshold on the mortar's colour or a morphological top-hat counts all of it as
mortar (on the laboratory photos, 1,527 pieces for about 35 stones). Joints differ from texture in
shape, not in colour: they are lines, long against their width, and in coursed masonry straight
along the courses. So:

1. **Joint evidence** ``J`` (:func:`joint_evidence`): the lightness normalised by its local mean and
   spread (a shadow or a stain changes neither), then line detectors at the joints' width: oriented
   second derivatives across the bed and the head joints (an orthophoto's courses run along its
   axes; each filter integrates along its joint, so a faint joint in speckle stands out) and
   Frangi's vesselness for slanted and curved joints and cracks. Blobs give neither. Of dark and
   light lines (dark joints or light mortar), the polarity with the more line-like response wins.
2. **The module** (course height and unit length, :func:`module_from_joints`): the length-weighted
   mean of the joint-free runs down the columns and along the rows; or as given.
3. **Over-segmentation**: a watershed of ``J`` from the maxima of the distance to likely joints.
4. **Merging** (:func:`merge_regions`): neighbours merge, the weakest shared boundary (its mean
   ``J``) first, while that boundary is weaker than ``merge_threshold`` (texture, not a joint) or
   one of the two is smaller than ``min_piece_fraction`` of a module; never into a piece of more
   than ``max_piece_modules`` modules. The size prior thus rejects implausible pieces both ways.
5. **Islands** (:func:`absorb_islands`): a piece whose one neighbour is another piece goes into it
   (a unit does not wrap around another; traced by its outer boundary, the encloser covered it).

The result says what it found: the pieces' count, their median and largest area, the module, and
a warning that names the cause when the count is implausible (one piece: no joints found; far more
pieces than modules fit: texture taken for joints).
"""

from __future__ import annotations

import heapq
import math
from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from .._morphology import binary

__all__ = [
    "PieceConfig",
    "Pieces",
    "absorb_islands",
    "joint_evidence",
    "merge_regions",
    "module_from_joints",
    "pieces_mask",
    "segment_pieces",
]


@dataclass(frozen=True)
class PieceConfig:
    """Lengths in metres on the wall (the orthophoto's ``px_per_m`` converts them).

    ``joint_width_m``: a joint's width (the line filters' scale); ``joint_length_m``: how far along
    a joint the oriented filters integrate; ``merge_threshold``: the mean joint evidence (of its
    99th percentile) below which a boundary is texture; ``min_piece_fraction``,
    ``max_piece_modules``: the size prior, of the module's area; ``module_m``: (course height,
    unit length), default measured from the joints."""

    joint_width_m: float = 0.008
    joint_length_m: float = 0.05
    merge_threshold: float = 0.3
    min_piece_fraction: float = 0.25
    max_piece_modules: float = 4.0
    module_m: tuple[float, float] | None = None


#: the median joint evidence (:func:`joint_evidence`) over a wall's face above which its lines are
#: texture, not joints: masonry's faces are mostly free of lines (0.07-0.13 on the three laboratory
#: photos and all 120 of their changed versions that calibrate, the highest through gamma 1.6), a
#: plastered or noisy face is lines everywhere (0.22-0.29 on noise smoothed over 0-8 px at 300 px/m)
TEXTURE_MEDIAN_EVIDENCE = 0.18
MASONRY_MEDIAN_EVIDENCE = 0.13


@dataclass(frozen=True)
class Pieces:
    """The partition ``labels`` (rows, cols) int32 (1..n, 0 outside the wall or occluded), the
    joint evidence it followed, the module (course height, unit length) in metres and the
    orthophoto's scale."""

    labels: np.ndarray
    joints: np.ndarray
    module_m: tuple[float, float]
    px_per_m: float
    module_source: str

    @property
    def count(self) -> int:
        return int(len(np.unique(self.labels[self.labels > 0])))

    def areas_m2(self) -> np.ndarray:
        a = np.bincount(self.labels.ravel())[1:]
        return a[a > 0] / self.px_per_m**2

    def warning(self, wall_area_m2: float | None = None) -> str:
        """Why the count is implausible ("" when it is not)."""
        n = self.count
        if wall_area_m2 is None:
            wall_area_m2 = float(self.labels.size) / self.px_per_m**2
        expected = wall_area_m2 / max(self.module_m[0] * self.module_m[1], 1e-12)
        if n <= 1:
            return (
                "the segmentation found one piece: no joints stand out from the face's texture (plastered or "
                "blurred); draw the units in the LabelMe file and build from it"
            )
        texture = float(np.median(self.joints)) if self.joints.size else 0.0
        if texture > TEXTURE_MEDIAN_EVIDENCE:
            # the module is measured from the same lines, so the count agrees with it: only the
            # evidence's spread over the face tells a partition of texture from one of units
            return (
                f"{n} pieces, but line-like evidence covers the whole face (its median {texture:.2f}; on masonry "
                f"at most {MASONRY_MEDIAN_EVIDENCE}): no joints stand out from the texture (plaster, render, "
                "noise), so the pieces follow it, not units; draw the units in the LabelMe file and build from it"
            )
        if n > 4.0 * expected:
            return (
                f"{n} pieces where about {expected:.0f} units of {self.module_m[0] * 100:.1f} x "
                f"{self.module_m[1] * 100:.1f} cm fit: texture taken for joints; check the pieces in the LabelMe file"
            )
        if n < 0.25 * expected:
            return (
                f"{n} pieces where about {expected:.0f} units of {self.module_m[0] * 100:.1f} x "
                f"{self.module_m[1] * 100:.1f} cm fit: many joints were not found; check the pieces in the LabelMe file"
            )
        return ""

    def summary(self) -> dict:
        a = self.areas_m2()
        return {
            "count": self.count,
            "median_area_m2": float(np.median(a)) if len(a) else 0.0,
            "max_area_m2": float(a.max()) if len(a) else 0.0,
            "min_area_m2": float(a.min()) if len(a) else 0.0,
            "module_m": [float(self.module_m[0]), float(self.module_m[1])],
            "module_source": self.module_source,
            "warning": self.warning(),
        }


def _normalised(gray: np.ndarray, sigma: float) -> np.ndarray:
    """``(gray - local mean) / local spread`` in a Gaussian window of ``sigma`` px."""
    mean = ndimage.gaussian_filter(gray, sigma)
    var = ndimage.gaussian_filter(gray * gray, sigma) - mean * mean
    return (gray - mean) / np.sqrt(np.maximum(var, 1e-6))


def joint_evidence(gray: np.ndarray, px_per_m: float, config: PieceConfig = PieceConfig()) -> np.ndarray:
    """Joint evidence ``(rows, cols)`` of an orthophoto's lightness: line responses at the joints'
    width, each divided by its 99th percentile (so about 1 on a clear joint), the best polarity."""
    from skimage.filters import frangi

    g = np.asarray(gray, dtype=np.float32)
    unit = max(px_per_m, 1e-9)
    n = _normalised(g, max(3.0, 0.05 * unit))
    across = max(0.8, 0.5 * config.joint_width_m * unit)
    along = max(2.0, 0.5 * config.joint_length_m * unit)
    sigmas = np.array([0.4, 0.6, 1.0]) * config.joint_width_m * unit
    sigmas = np.maximum(sigmas, 0.7)
    best, best_score = None, -1.0
    for dark in (True, False):
        # dark lines: lightness curves up across them (a positive second derivative)
        s = 1.0 if dark else -1.0
        bed = np.maximum(s * ndimage.gaussian_filter(n, (across, along), order=(2, 0)) * across**2, 0.0)
        head = np.maximum(s * ndimage.gaussian_filter(n, (along, across), order=(0, 2)) * across**2, 0.0)
        parts = [bed, head]
        if dark:  # slanted and curved joints, cracks (dark in any masonry)
            parts.append(frangi(n, sigmas=sigmas, black_ridges=True).astype(np.float32))
        scaled = []
        for p in parts:
            top = float(np.percentile(p, 99))
            scaled.append(p / top if top > 1e-12 else p)
        j = np.maximum.reduce(scaled)
        # line-likeness: how far the strong responses stand above the typical one
        score = float(np.percentile(bed + head, 99) / max(np.percentile(bed + head, 50), 1e-12))
        if score > best_score:
            best, best_score = j, score
    return best


def _runs(free: np.ndarray) -> np.ndarray:
    """Lengths of the runs of True down the columns of ``free``."""
    d = np.diff(np.pad(free.astype(np.int8), ((1, 1), (0, 0))), axis=0)
    starts = np.nonzero(d.T == 1)
    ends = np.nonzero(d.T == -1)
    return ends[1] - starts[1]


def module_from_joints(joints: np.ndarray, px_per_m: float, *, quantile: float = 85.0) -> tuple[float, float]:
    """(course height, unit length) in metres: the length-weighted mean joint-free run down the
    columns and along the rows, joints being the top ``100 - quantile`` % of the evidence, runs
    shorter than 2 cm left out."""
    free = joints < np.percentile(joints, quantile)
    least = 0.02 * px_per_m
    out = []
    for f in (free, free.T):
        r = _runs(f)
        r = r[r > least]
        out.append(float(np.average(r, weights=r)) / px_per_m if len(r) else 0.1)
    return out[0], out[1]


def merge_regions(labels: np.ndarray, strength: np.ndarray, threshold: float, min_area: float, max_area: float):
    """Merge the regions of ``labels`` (1..n, every pixel labelled), the weakest shared boundary
    first (the mean of ``strength`` over the boundary's pixel pairs), while it is below
    ``threshold`` or either region is smaller than ``min_area`` px (the smaller region first then),
    never into a region larger than ``max_area`` px unless one is below ``min_area``. Returns the
    merged labels, 1..m."""
    lab = np.asarray(labels)
    n = int(lab.max()) + 1
    area = np.bincount(lab.ravel(), minlength=n).astype(np.float64)
    keys, sums = [], []
    for a, b, sa, sb in (
        (lab[:, :-1], lab[:, 1:], strength[:, :-1], strength[:, 1:]),
        (lab[:-1], lab[1:], strength[:-1], strength[1:]),
    ):
        m = a != b
        lo = np.minimum(a[m], b[m]).astype(np.int64)
        hi = np.maximum(a[m], b[m]).astype(np.int64)
        keys.append(lo * n + hi)
        sums.append(0.5 * (sa[m] + sb[m]))
    keys_all = np.concatenate(keys)
    if len(keys_all) == 0:
        return lab
    uk, inv = np.unique(keys_all, return_inverse=True)
    s_sum = np.bincount(inv, weights=np.concatenate(sums))
    s_cnt = np.bincount(inv).astype(np.float64)
    parent = np.arange(n)

    def find(x: int) -> int:
        while parent[x] != x:
            parent[x] = parent[parent[x]]
            x = parent[x]
        return x

    nbr: list[dict] = [dict() for _ in range(n)]
    for key, s, c in zip(uk.tolist(), s_sum.tolist(), s_cnt.tolist()):
        a, b = divmod(key, n)
        edge = [s, c]
        nbr[a][b] = edge
        nbr[b][a] = edge

    def priority(a: int, b: int) -> tuple:
        s, c = nbr[a][b]
        smaller = min(area[a], area[b])
        if smaller < min_area:
            return (0, smaller, a, b)
        return (1, s / c, a, b)

    heap = [priority(a, b) for a in range(1, n) for b in nbr[a] if a < b]
    heapq.heapify(heap)
    while heap:
        item = heapq.heappop(heap)
        _, _, a, b = item
        if find(a) != a or find(b) != b or b not in nbr[a]:
            continue
        current = priority(a, b)
        if current != item:
            heapq.heappush(heap, current)
            continue
        small = current[0] == 0
        if not small and (current[1] >= threshold or area[a] + area[b] > max_area):
            continue
        if area[a] < area[b]:
            a, b = b, a  # b, the smaller, goes into a
        parent[b] = a
        area[a] += area[b]
        del nbr[a][b], nbr[b][a]
        for k, edge in nbr[b].items():
            del nbr[k][b]
            if k in nbr[a]:
                nbr[a][k][0] += edge[0]
                nbr[a][k][1] += edge[1]
            else:
                nbr[a][k] = edge
                nbr[k][a] = edge
        nbr[b] = {}
        for k in nbr[a]:
            heapq.heappush(heap, priority(min(a, k), max(a, k)))
    roots = np.array([find(i) for i in range(n)])
    roots[0] = 0
    _, out = np.unique(roots, return_inverse=True)
    return out.astype(np.int32)[lab]


def smooth_partition(labels: np.ndarray, sigma: float) -> np.ndarray:
    """Each pixel given the label that dominates around it (each label's indicator blurred by a
    Gaussian of ``sigma`` px, the largest wins): a merged region's thin arms along a joint and its
    ragged boundary through texture go to its neighbours; the labels are then renumbered 1..m
    (a label left with no pixels disappears)."""
    n = int(labels.max())
    best = np.full(labels.shape, -1.0, dtype=np.float32)
    out = np.zeros_like(labels)
    for k in range(1, n + 1):
        sl = ndimage.find_objects((labels == k).astype(np.int8))
        if not sl or sl[0] is None:
            continue
        pad = int(math.ceil(4 * sigma))
        r0, r1 = max(0, sl[0][0].start - pad), min(labels.shape[0], sl[0][0].stop + pad)
        c0, c1 = max(0, sl[0][1].start - pad), min(labels.shape[1], sl[0][1].stop + pad)
        w = ndimage.gaussian_filter((labels[r0:r1, c0:c1] == k).astype(np.float32), sigma)
        win = w > best[r0:r1, c0:c1]
        best[r0:r1, c0:c1] = np.where(win, w, best[r0:r1, c0:c1])
        out[r0:r1, c0:c1] = np.where(win, k, out[r0:r1, c0:c1])
    _, renum = np.unique(out, return_inverse=True)
    return renum.reshape(out.shape).astype(np.int32) + (0 if (out == 0).any() else 1)


def absorb_islands(labels: np.ndarray) -> np.ndarray:
    """Each piece whose every neighbour is one other piece (an island: not on the photo's edge,
    not beside an unlabelled pixel) merged into that piece; labels renumbered 1..m, 0 kept. One
    pass leaves none: an island touches its encloser alone, so merging it changes no other piece's
    neighbours, and an encloser is never an island itself (it touches the island and what lies
    beyond). A unit does not wrap around another in a wall's face, and a piece traced by its outer
    boundary covers what it encloses: the laboratory photo SC1 built a 46 cm^2 piece inside
    another (9.2e-4 m^3 of interpenetration in the 3D model, measured)."""
    lab = np.asarray(labels).astype(np.int64)
    n = int(lab.max()) + 1
    padded = np.pad(lab, 1, constant_values=n)  # the photo's edge: a neighbour of its own
    pairs = []
    for a, b in ((padded[:, :-1], padded[:, 1:]), (padded[:-1], padded[1:])):
        m = a != b
        pairs.append(np.c_[a[m], b[m]])
        pairs.append(np.c_[b[m], a[m]])
    pairs = np.unique(np.concatenate(pairs), axis=0)
    pairs = pairs[(pairs[:, 0] > 0) & (pairs[:, 0] < n)]  # from each piece to its neighbours
    piece, count = np.unique(pairs[:, 0], return_counts=True)
    only = pairs[np.isin(pairs[:, 0], piece[count == 1])]  # (island, its one neighbour)
    only = only[(only[:, 1] > 0) & (only[:, 1] < n)]  # that neighbour a piece, not the edge or 0
    table = np.arange(n + 1)
    table[only[:, 0]] = only[:, 1]
    lab = table[lab]
    _, renum = np.unique(lab, return_inverse=True)
    return (renum.reshape(lab.shape) + (0 if (lab == 0).any() else 1)).astype(np.int32)


def segment_pieces(
    rgb: np.ndarray,
    px_per_m: float,
    config: PieceConfig = PieceConfig(),
    *,
    valid: np.ndarray | None = None,
) -> Pieces:
    """Partition an orthophoto ``(rows, cols, 3)`` in [0, 1] at ``px_per_m`` into masonry units
    (see the module's docstring). ``valid``: the pixels that are wall (False where an occluder
    hides it or outside the photo); the pieces cover only those."""
    from skimage.morphology import h_maxima
    from skimage.segmentation import watershed

    img = np.asarray(rgb, dtype=np.float32)
    gray = img.mean(axis=-1) if img.ndim == 3 else img
    joints = joint_evidence(gray, px_per_m, config)
    if config.module_m is not None:
        module, source = (float(config.module_m[0]), float(config.module_m[1])), "given"
    else:
        module, source = module_from_joints(joints, px_per_m), "measured from the joints"
    a0 = module[0] * module[1] * px_per_m**2
    # lengths on the wall, not in pixels, so that the pieces do not change with the orthophoto's
    # resolution: a 2 mm smoothing, and a new region for every 4 mm of distance from the joints
    smooth = ndimage.gaussian_filter(joints, max(0.5, 0.002 * px_per_m))
    dist = ndimage.distance_transform_edt(joints < np.percentile(joints, 80))
    markers, _ = ndimage.label(h_maxima(dist, max(1.0, 0.004 * px_per_m)))
    labels = watershed(smooth, markers).astype(np.int32)
    labels = merge_regions(
        labels, smooth, config.merge_threshold, config.min_piece_fraction * a0, config.max_piece_modules * a0
    )
    labels = smooth_partition(labels, max(1.0, 0.01 * px_per_m))
    if valid is not None:
        labels = np.where(valid, labels, 0).astype(np.int32)
    labels = absorb_islands(labels)
    return Pieces(labels=labels, joints=joints, module_m=module, px_per_m=float(px_per_m), module_source=source)


def pieces_mask(pieces: Pieces, *, mortar: np.ndarray | None = None, joint_width_m: float | None = None) -> np.ndarray:
    """The pieces as a brick mask (bricks True) for tracing: each piece's pixels less a one-pixel
    line where it meets another, and less ``mortar`` (a mask of mortar pixels) within a joint's
    width of those lines, so that wide mortar joints are not counted as the units'."""
    lab = pieces.labels
    edge = np.zeros(lab.shape, dtype=bool)
    edge[1:] |= (lab[1:] != lab[:-1]) & (lab[1:] > 0) & (lab[:-1] > 0)
    edge[:, 1:] |= (lab[:, 1:] != lab[:, :-1]) & (lab[:, 1:] > 0) & (lab[:, :-1] > 0)
    mask = (lab > 0) & ~edge
    if mortar is not None:
        width = joint_width_m if joint_width_m is not None else PieceConfig.joint_width_m
        reach = max(1, int(math.ceil(width * pieces.px_per_m)))
        near = binary("dilate", edge | (lab == 0), reach)  # scipy's binary_dilation's pixels
        mask &= ~(np.asarray(mortar, dtype=bool) & near)
    return mask

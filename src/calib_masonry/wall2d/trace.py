"""Mask to brick polygons: label, trace each brick's outline, split it to N vertices, score Dice.

Convention: polygons are in image coordinates (x = column, y = row, pixels, origin top-left, pixel
centres at integers). The traced outline is scikit-image's iso-line at level 0.5 of the brick's
0/1 crop, so it runs half-way between brick and mortar pixel centres: a rectangle of pixels
``[c0, c1] x [r0, r1]`` traces to the rectangle ``[c0 - 0.5, c1 + 0.5] x [r0 - 0.5, r1 + 0.5]``
(with its corners cut by a quarter pixel), and rasterises back to exactly the same pixels.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from scipy import ndimage
from skimage.measure import find_contours

from ..errors import InputError
from ..io import xy_from_rc
from ..spec import DEFAULT_VERTICES
from .dice import dice_polygon_region
from .segment import SegmentConfig, label_bricks
from .split import splitting_sequence, visvalingam

if TYPE_CHECKING:  # pragma: no cover
    from .refine import RefineConfig

__all__ = [
    "TraceConfig",
    "TracedBrick",
    "TraceResult",
    "trace_labels",
    "trace_mask",
    "refine_trace",
    "trace_to_file",
    "trace_outline",
    "trace_outlines",
    "DEFAULT_VERTICES",
]


@dataclass(frozen=True)
class TraceConfig:
    """Exactly one of ``vertices`` (a fixed count N >= 3) or ``target_dice`` (the fewest vertices,
    up to ``max_vertices``, that reach it); neither means :data:`DEFAULT_VERTICES`."""

    vertices: int | None = None
    target_dice: float | None = None
    max_vertices: int = 64
    segment: SegmentConfig = SegmentConfig()
    refine: "RefineConfig | None" = None  # soft-Dice vertex refinement (wall2d.refine) when set

    def __post_init__(self) -> None:
        if self.vertices is not None and self.target_dice is not None:
            raise InputError("trace: give a vertex count (--vertices N) or a target Dice (--target-dice D), not both")
        if self.vertices is None and self.target_dice is None:
            object.__setattr__(self, "vertices", DEFAULT_VERTICES)
        if self.vertices is not None and (isinstance(self.vertices, bool) or not isinstance(self.vertices, int)):
            raise InputError(f"trace: vertices = {self.vertices!r} must be a whole number")
        if self.vertices is not None and self.vertices < 3:
            raise InputError(f"trace: vertices = {self.vertices} is too few; a polygon needs at least 3")
        if self.target_dice is not None and not 0 < self.target_dice < 1:
            raise InputError(f"trace: target Dice {self.target_dice} must lie between 0 and 1")


@dataclass(frozen=True)
class TracedBrick:
    id: int
    vertices_xy: np.ndarray  # (N, 2) image pixels, counter-clockwise on screen is not implied
    traced_vertices: int  # corners of the traced outline (collinear steps removed)
    dice: float  # against the brick's own pixel region
    area_px: int
    dice_splitting: float | None = None  # the splitting method's Dice, when refined
    refined: bool = False
    note: str = ""
    splitting_xy: np.ndarray | None = None  # the splitting polygon, when refined
    solver_status: str | None = None  # the refinement solver's FitStatus value, when refined


@dataclass(frozen=True)
class TraceResult:
    image_shape: tuple[int, int]
    bricks: tuple[TracedBrick, ...]

    @property
    def mean_dice(self) -> float:
        return float(np.mean([b.dice for b in self.bricks])) if self.bricks else float("nan")

    def to_json(self) -> dict:
        return {
            "image_shape": list(self.image_shape),
            "bricks": [
                {
                    "id": b.id,
                    "vertices_xy": b.vertices_xy.tolist(),
                    "traced_vertices": b.traced_vertices,
                    "dice": b.dice,
                    "area_px": b.area_px,
                    **(
                        {
                            "dice_splitting": b.dice_splitting,
                            "refined": b.refined,
                            "note": b.note,
                            "solver_status": b.solver_status,
                            "splitting_vertices_xy": b.splitting_xy.tolist(),
                        }
                        if b.dice_splitting is not None
                        else {}
                    ),
                }
                for b in self.bricks
            ],
            "mean_dice": self.mean_dice,
            **({"mean_dice_splitting": self.mean_dice_splitting} if self.refined else {}),
        }

    @property
    def refined(self) -> bool:
        return any(b.dice_splitting is not None for b in self.bricks)

    @property
    def mean_dice_splitting(self) -> float:
        return float(np.mean([b.dice if b.dice_splitting is None else b.dice_splitting for b in self.bricks]))


def _corner_count(outline: np.ndarray) -> int:
    d = np.diff(np.vstack([outline, outline[:1]]), axis=0)
    prev = np.roll(d, 1, axis=0)
    cross = prev[:, 0] * d[:, 1] - prev[:, 1] * d[:, 0]
    return int(np.count_nonzero(np.abs(cross) > 1e-9))


def trace_outline(region: np.ndarray) -> np.ndarray:
    """Outline ``(M, 2)`` (x, y in crop pixels, no repeated end point) of a 4-connected region crop.

    The outline runs along pixel edges (the "crack" boundary), so its area equals the pixel count
    and a rectangle of pixels has its four exact corners among the outline points. It is made from
    scikit-image's iso-line at 0.5, whose points are midpoints of pixel edges and whose diagonal
    steps cut a pixel corner: each diagonal step gets that corner inserted.
    """
    padded = np.pad(region.astype(np.float64), 1)
    contours = find_contours(padded, 0.5, fully_connected="low")
    mid = xy_from_rc(max(contours, key=len)[:-1] - 1.0)
    return _corners_inserted(mid, np.roll(mid, -1, axis=0))[0]


def _corners_inserted(mid: np.ndarray, nxt: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The iso-line's points ``mid`` ``(n, 2)`` (x, y), each followed by ``nxt`` (the next point
    of its outline), with the pixel corner that each diagonal step cuts inserted after it; and where
    each point of ``mid`` went ``(n,)``."""
    step = nxt - mid
    diagonal = (np.abs(step[:, 0]) > 1e-9) & (np.abs(step[:, 1]) > 1e-9)
    cand = np.column_stack([mid[:, 0], nxt[:, 1]])
    half = np.isclose(np.abs(cand - np.floor(cand)), 0.5).all(axis=1)
    corner = np.where(half[:, None], cand, np.column_stack([nxt[:, 0], mid[:, 1]]))
    out = np.empty((len(mid) + int(diagonal.sum()), 2))
    pos = np.arange(len(mid)) + np.concatenate([[0], np.cumsum(diagonal)[:-1]])
    out[pos] = mid
    out[pos[diagonal] + 1] = corner[diagonal]
    return out, pos


# The marching squares of a 0/1 image at level 0.5 as scikit-image's ``find_contours`` (with
# ``fully_connected="low"``) makes them: a 2 x 2 square of pixels (case tl + 2 tr + 4 bl + 8 br)
# gives up to two segments, in this order, each from one of its sides to another (0 top, 1 bottom,
# 2 left, 3 right); a side's point is the midpoint of the two pixel centres it joins, here in
# doubled coordinates (2 row, 2 col) from the square's top-left pixel (_SIDE_OFFSET).
_SEGMENT_TABLE = np.full((16, 2, 2), -1, dtype=np.int64)
for _case, _segs in {
    1: ((0, 2),),
    2: ((3, 0),),
    3: ((3, 2),),
    4: ((2, 1),),
    5: ((0, 1),),
    6: ((3, 0), (2, 1)),
    7: ((3, 1),),
    8: ((1, 3),),
    9: ((0, 2), (1, 3)),
    10: ((1, 0),),
    11: ((1, 2),),
    12: ((2, 3),),
    13: ((0, 3),),
    14: ((2, 0),),
}.items():
    _SEGMENT_TABLE[_case, : len(_segs)] = _segs
_SIDE_OFFSET = np.array([[0, 1], [2, 1], [1, 0], [1, 2]])


def _cycle_min(succ: np.ndarray) -> np.ndarray:
    """``(n,)`` the least index on each element's cycle of the permutation ``succ``, by pointer
    doubling (once a round changes nothing, every window covers its whole cycle)."""
    m = np.arange(len(succ))
    p = succ
    while True:
        new = np.minimum(m, m[p])
        if np.array_equal(new, m):
            return m
        m, p = new, p[p]


#: pixels of labels traced at once by :func:`trace_outlines` (its temporaries take about 40 bytes a
#: pixel, measured: 770 MB on a 20 MP label image in one go; a band of rows at a time instead)
_TRACE_BLOCK_PX = 1 << 21


def trace_outlines(labels: np.ndarray, ids, slices: list | None = None) -> list[np.ndarray]:
    """:func:`trace_outline` of ``labels[sl] == k`` (``sl`` the label's bounding box, from
    ``ndimage.find_objects``, or ``slices`` given: its list) for each label ``k`` of ``ids``, value
    for value, many at once.

    The same squares and segments as scikit-image's, of every label together, joined into loops
    through an index and ordered by pointer doubling instead of scikit-image's dictionaries of partial
    contours, one label at a time (0.3 ms a piece: 0.15-0.2 s of every ``rectify``'s 463 pieces,
    and of each photo wall of ``build``). scikit-image's contour closes at the segment it meets last
    (the loop's last square in row-major order) and so starts at that segment's end point; of a
    label's loops it is the longest (the first of equals, in the order of their first squares) that
    :func:`trace_outline` keeps (``tests/test_trace.py -k all_at_once``). The labels are taken a
    band of rows at a time (:data:`_TRACE_BLOCK_PX` pixels and each label's whole box), so that
    its temporaries stay those of one band whatever the image's size (measured: 106 MB in all on a
    20 MP image of 5,556 labels, the outlines returned included)."""
    ids = np.asarray(ids, dtype=np.int64)
    if ids.size == 0:
        return []
    labels = np.asarray(labels)
    if slices is None:
        slices = ndimage.find_objects(labels)
    top = np.array([sl[0].start if sl is not None else 0 for sl in slices], dtype=np.int64)
    left = np.array([sl[1].start if sl is not None else 0 for sl in slices], dtype=np.int64)
    bottom = np.array([sl[0].stop if sl is not None else 0 for sl in slices], dtype=np.int64)
    missing = [int(k) for k in ids if k < 1 or k > len(slices) or slices[k - 1] is None]
    if missing:
        raise ValueError(f"trace_outlines: label {missing[0]} has no pixels")
    rows_per_block = max(1, _TRACE_BLOCK_PX // max(1, labels.shape[1]))
    order = np.argsort(top[ids - 1], kind="stable")
    found: dict[int, np.ndarray] = {}
    i = 0
    while i < len(order):
        r0 = int(top[ids[order[i]] - 1])
        j = i + int(np.searchsorted(top[ids[order[i:]] - 1], r0 + rows_per_block))
        group = ids[order[i:j]]
        r1 = int(bottom[group - 1].max())
        # the band's rows and every box of its labels whole: each label's crop, as trace_outline sees it
        found.update(zip(group.tolist(), _trace_block(labels[r0:r1], group, top - r0, left)))
        i = j
    return [found[int(k)] for k in ids]


def _trace_block(labels: np.ndarray, ids: np.ndarray, top: np.ndarray, left: np.ndarray) -> list[np.ndarray]:
    """:func:`trace_outlines` of the labels ``ids`` of ``labels``, each of whose boxes lies wholly in
    it, from (``top``, ``left``) (per label, ``label - 1``), in the order of ``ids``."""
    lab = np.pad(np.asarray(labels), 1)
    h, w = lab.shape
    # the squares (by their top-left pixel, row-major over (h - 1) x (w - 1)) whose four pixels
    # are not all one label: the only ones with segments
    across = lab[:, 1:] != lab[:, :-1]
    down = lab[1:, :] != lab[:-1, :]
    mixed = np.flatnonzero(across[:-1] | across[1:] | down[:, :-1] | down[:, 1:])
    r, c = np.divmod(mixed, w - 1)
    tl = r * w + c
    flat = lab.ravel()
    cl = [flat[tl].astype(np.int64), flat[tl + 1].astype(np.int64), flat[tl + w].astype(np.int64)]
    cl.append(flat[tl + w + 1].astype(np.int64))  # the four corners' labels: tl, tr, bl, br
    wanted = np.zeros(int(max(flat.max(), ids.max())) + 1, dtype=bool)
    wanted[ids] = True
    # each (square, label) once: the label at each corner, where no earlier corner had it
    sq_parts, lab_parts, case_parts = [], [], []
    for j in range(4):
        take = wanted[cl[j]]
        for i in range(j):
            take &= cl[i] != cl[j]
        idx = np.flatnonzero(take)
        k = cl[j][idx]
        case = sum((cl[i][idx] == k).astype(np.int64) << i for i in range(4))
        sq_parts.append(mixed[idx])
        lab_parts.append(k)
        case_parts.append(case)
    sq, lb, case = (np.concatenate(x) for x in (sq_parts, lab_parts, case_parts))
    two = np.flatnonzero((case == 6) | (case == 9))
    sq = np.concatenate([sq, sq[two]])
    lb = np.concatenate([lb, lb[two]])
    case = np.concatenate([case, case[two]])
    k = np.concatenate([np.zeros(len(sq) - len(two), np.int64), np.ones(len(two), np.int64)])
    order = np.lexsort((k, sq, lb))  # by label, then in scikit-image's order within it
    sq, lb, case, k = sq[order], lb[order], case[order], k[order]
    sides = _SEGMENT_TABLE[case, k]
    base = 2 * np.column_stack([sq // (w - 1), sq % (w - 1)])
    start = base + _SIDE_OFFSET[sides[:, 0]]
    end = base + _SIDE_OFFSET[sides[:, 1]]
    span = (2 * h) * (2 * w)
    key_start = lb * span + start[:, 0] * (2 * w) + start[:, 1]
    key_end = lb * span + end[:, 0] * (2 * w) + end[:, 1]
    by_start = np.argsort(key_start)
    succ = by_start[np.searchsorted(key_start[by_start], key_end)]
    # the loops (each named by its first segment), their lengths, and each label's longest
    cyc = _cycle_min(succ)
    length = np.bincount(cyc, minlength=len(succ))
    heads = np.flatnonzero(length)
    pick = heads[np.lexsort((heads, -length[heads], lb[heads]))]
    pick = pick[np.r_[True, lb[pick][1:] != lb[pick][:-1]]]  # per label, the longest, first of equals
    # the chosen loops alone, each cut before its last segment (where scikit-image's starts)
    inside = np.flatnonzero(np.isin(cyc, pick))
    local = np.full(len(succ), -1, dtype=np.int64)
    local[inside] = np.arange(len(inside))
    nxt = local[succ[inside]]
    last = np.zeros(len(succ), dtype=np.int64)
    np.maximum.at(last, cyc[inside], inside)
    first = local[last[cyc[inside]]]  # each element's loop's first point (the last segment's end)
    tail = nxt == first
    # steps from each element to its loop's tail (list ranking by pointer doubling)
    nxt = np.where(tail, np.arange(len(inside)), nxt)
    dist = (~tail).astype(np.int64)
    while True:
        further = nxt[nxt]
        if np.array_equal(further, nxt):
            break
        dist = dist + dist[nxt]
        nxt = further
    pos = length[cyc[inside]] - 1 - dist  # each element's place in its outline
    label_of = lb[inside]
    order = np.lexsort((pos, label_of))
    pts, label_of = end[inside[order]], label_of[order]
    # to each label's crop (its bounding box, as trace_outline sees it): x, y from the doubled
    # coordinates of the padded labels, exactly (halves of integers)
    mid = np.column_stack([pts[:, 1] * 0.5 - 1.0 - left[label_of - 1], pts[:, 0] * 0.5 - 1.0 - top[label_of - 1]])
    starts = np.flatnonzero(np.r_[True, label_of[1:] != label_of[:-1]])
    ends = np.r_[starts[1:], len(mid)]
    follow = np.arange(1, len(mid) + 1)
    follow[ends - 1] = starts  # each outline's last point is followed by its first
    out, at = _corners_inserted(mid, mid[follow])
    bounds = np.r_[at[starts], len(out)]
    found = {int(label_of[a]): out[bounds[i] : bounds[i + 1]] for i, a in enumerate(starts)}
    return [found[int(k)] for k in ids]


def _simplify(outline: np.ndarray, region: np.ndarray, config: TraceConfig) -> tuple[np.ndarray, float]:
    if config.vertices is not None:
        n_max = config.vertices
    else:
        n_max = config.max_vertices
    best_poly, best_dice = None, -1.0
    for idx in splitting_sequence(outline, n_max):
        if len(idx) < 3 and len(idx) < len(outline):
            continue
        poly = outline[idx]
        if config.vertices is None or len(idx) == config.vertices or len(idx) == len(outline):
            d = dice_polygon_region(poly, region)
            if d > best_dice or config.vertices is None:
                best_poly, best_dice = poly, d
            if config.vertices is None and d >= config.target_dice:
                break
    if best_poly is None:  # outline shorter than requested: use it whole
        best_poly = outline
        best_dice = dice_polygon_region(outline, region)
    return best_poly, best_dice


def trace_mask(mask: np.ndarray, config: TraceConfig = TraceConfig(), *, progress: bool | None = None) -> TraceResult:
    """Label the bricks of ``mask`` ``(rows, cols)`` and simplify each to a polygon.

    With ``config.refine`` set, the polygons are then refined by soft Dice (all bricks at once):
    for a fixed count, from the better of the splitting and Visvalingam-Whyatt polygons; for a
    target Dice, count by count from 3 vertices, each brick stopping at the first count whose
    refined polygon reaches the target. ``progress``: as :func:`calib_masonry.progress.progress`'s
    ``enabled`` (False on a worker thread, whose bar would cut through the main thread's).
    """
    return trace_labels(label_bricks(mask, config.segment), config, progress=progress, connected=True)


def trace_labels(
    labels: np.ndarray, config: TraceConfig = TraceConfig(), *, progress: bool | None = None, connected: bool = False
) -> TraceResult:
    """:func:`trace_mask` of bricks already labelled: ``labels`` ``(rows, cols)`` int, 0 mortar,
    1..K the bricks (each traced as its largest 4-connected part). Pieces that touch one another
    (a partition, as :mod:`calib_masonry.wall2d.pieces` makes) stay apart, where a mask would
    merge them or fill the one-pixel line between them as a hole. ``connected``: every label is
    one 4-connected region already (a labelled mask's), so none is split."""
    from ..progress import progress as _progress

    labels = np.asarray(labels)
    slices = ndimage.find_objects(labels)
    regions = {}
    for k, slc in enumerate(_progress(slices, desc="trace outlines", unit="brick", enabled=progress), start=1):
        if slc is None:
            continue
        region = labels[slc] == k
        if not connected:
            parts, n_parts = ndimage.label(region, structure=ndimage.generate_binary_structure(2, 1))
            if n_parts > 1:  # a label in several pieces: its largest, traced on its own
                region = parts == 1 + int(np.argmax(np.bincount(parts.ravel())[1:]))
                regions[k] = (region, trace_outline(region))
                continue
        regions[k] = (region, None)
    whole = [k for k, (_, outline) in regions.items() if outline is None]
    outlines = dict(zip(whole, trace_outlines(labels, whole, slices)))
    items = []
    for k, (region, outline) in regions.items():
        slc = slices[k - 1]
        offset = np.array([slc[1].start, slc[0].start], dtype=np.float64)
        items.append((k, region, outlines[k] if outline is None else outline, offset))
    if config.refine is not None:
        bricks = _refined(labels, items, config)
    else:
        bricks = []
        for k, region, outline, offset in _progress(items, desc="simplify", unit="brick", enabled=progress):
            poly, dice = _simplify(outline, region, config)
            bricks.append(
                TracedBrick(
                    id=k,
                    vertices_xy=poly + offset,
                    traced_vertices=_corner_count(outline),
                    dice=float(dice),
                    area_px=int(region.sum()),
                )
            )
    return TraceResult(image_shape=tuple(int(s) for s in labels.shape), bricks=tuple(bricks))


def _splitting_count(outline: np.ndarray, region: np.ndarray, target: float, n_max: int) -> int:
    """The fewest vertices (3 to ``n_max``) whose splitting polygon reaches Dice ``target`` on
    ``region`` (``n_max``, or the whole outline, where none does)."""
    m = 3
    for idx in splitting_sequence(outline, n_max):
        m = len(idx)
        if m >= 3 and dice_polygon_region(outline[idx], region) >= target:
            break
    return max(3, min(m, n_max))


def _refined(labels: np.ndarray, items: list, config: TraceConfig) -> list[TracedBrick]:
    """Each brick refined by soft Dice (:func:`~calib_masonry.wall2d.refine.refine_polygons`, all
    pending bricks in one batch, each at its own vertex count). A fixed count: once. A target
    Dice: first at the count whose splitting polygon reaches it (refining never lowers Dice), then
    by bisection down to the fewest whose refined polygon still reaches it. Counting up from 3
    took one batch a count: a real stone wall's pieces (13 vertices on average, up to 42) did
    not finish in 5 minutes; now 51 s (counting down one at a time, or 1, 2, 4, ... fewer before
    bisecting: 61 s)."""
    from .refine import refine_polygons

    def start(i: int, n: int):
        k, region, outline, offset = items[i]
        m = min(n, len(outline))
        idx = dense = None
        for seq in splitting_sequence(outline, max(m, min(4 * m, len(outline)))):
            if len(seq) == m:
                idx = seq
            dense = seq
        # a second start: Visvalingam-Whyatt from a 4N-vertex splitting down to N
        alt = outline[dense[visvalingam(outline[dense], m)]] + offset
        return k, outline[idx] + offset, alt, dice_polygon_region(outline[idx], region)

    best: dict[int, tuple] = {}
    if config.vertices is not None:
        count = {
            i: config.vertices for i in range(len(items)) if len(items[i][2]) >= config.vertices or config.vertices <= 3
        }
    else:
        count = {
            i: _splitting_count(outline, region, config.target_dice, config.max_vertices)
            for i, (_, region, outline, _) in enumerate(items)
        }
    # a target: each brick's count bisected between one known short of it (lo) and one known to
    # reach it (hi, the splitting count at first)
    lo = dict.fromkeys(count, 2)
    hi: dict[int, int] = {}
    pending = sorted(count)
    while pending:
        jobs = [(i, *start(i, count[i])) for i in pending]
        results = refine_polygons(
            labels, [j[1] for j in jobs], [j[2] for j in jobs], config.refine, alternatives=[j[3] for j in jobs]
        )
        still = []
        for (i, _, st, _, sd), r in zip(jobs, results):
            reached = config.target_dice is None or r.dice >= config.target_dice
            if i not in hi or reached:  # the first result, then each fewer count that reaches it
                best[i] = (r.vertices_xy, r.dice, sd, r.refined, r.reason, st, r.status.value)
            if config.target_dice is None or (i not in hi and not reached):
                continue  # a fixed count, or not even the splitting count reaches it: done
            if reached:
                hi[i] = count[i]
            else:
                lo[i] = count[i]
            if hi[i] - lo[i] > 1:
                count[i] = (lo[i] + hi[i]) // 2
                still.append(i)
        pending = still
    out = []
    for i, (k, region, outline, offset) in enumerate(items):
        if i not in best:  # a tiny outline: use it whole
            d = dice_polygon_region(outline, region)
            best[i] = (outline + offset, d, d, False, "outline shorter than the vertex count", outline + offset, None)
        v, d, sd, refined, note, sp, status = best[i]
        out.append(
            TracedBrick(
                id=k,
                vertices_xy=v,
                traced_vertices=_corner_count(outline),
                dice=float(d),
                area_px=int(region.sum()),
                dice_splitting=float(sd),
                refined=bool(refined),
                note=note,
                splitting_xy=sp,
                solver_status=status,
            )
        )
    return out


def refine_trace(
    mask: np.ndarray,
    traced: TraceResult,
    config: "RefineConfig | None" = None,
    segment: SegmentConfig = SegmentConfig(),
) -> TraceResult:
    """Refine the polygons of a trace of ``mask`` by soft Dice (:mod:`calib_masonry.wall2d.refine`),
    keeping every vertex count; no brick ends with a lower Dice than its traced polygon. ``segment``
    must be the segmentation the trace used (its labels are the bricks' ids)."""
    from .refine import RefineConfig, refine_polygons

    if tuple(mask.shape) != tuple(traced.image_shape):
        raise InputError(
            f"refine: the mask is {mask.shape[1]} x {mask.shape[0]} px but the trace was made on "
            f"{traced.image_shape[1]} x {traced.image_shape[0]} px; refine the trace of this mask"
        )
    labels = label_bricks(mask, segment)
    bricks = list(traced.bricks)
    results = refine_polygons(labels, [b.id for b in bricks], [b.vertices_xy for b in bricks], config or RefineConfig())
    out = [
        replace(
            b,
            vertices_xy=r.vertices_xy,
            dice=float(r.dice),
            refined=bool(r.refined),
            note=r.reason,
            solver_status=r.status.value,
            dice_splitting=b.dice if b.dice_splitting is None else b.dice_splitting,
            splitting_xy=b.vertices_xy if b.splitting_xy is None else b.splitting_xy,
        )
        for b, r in zip(bricks, results)
    ]
    return TraceResult(image_shape=traced.image_shape, bricks=tuple(out))


#: A mask traced to at most this many pieces is checked for black pieces enclosed in white ones.
FEW_PIECES = 10


def enclosed_holes(mask: np.ndarray) -> int:
    """How many black regions of ``mask`` (bricks True) white ones enclose (not touching the
    border; at least 20 pixels and 1e-4 of the image). A mask with mortar white and units black
    shows its units so, as one white piece around them; a brick mask has none, or a few pores."""
    found, n = ndimage.label(~mask)
    if n == 0:
        return 0
    border = np.unique(np.concatenate([found[0], found[-1], found[:, 0], found[:, -1]]))
    sizes = np.bincount(found.ravel(), minlength=n + 1)
    keep = sizes >= max(20, 1e-4 * mask.size)
    keep[border] = False
    keep[0] = False
    return int(keep.sum())


def mortar_widths(mask: np.ndarray, max_px: float | None = None) -> np.ndarray:
    """The mortar's width (pixels) at every pixel of its medial axis (twice the distance to the
    nearest unit), away from the image's border: the local widths of the joints between the
    units of ``mask`` (bricks True), along their length. With ``max_px``, the parts of the mortar
    a disk ``max_px`` across fits in (an opening: a window, a door, a void) are no joint and left
    out, with their medial axis's branches of every width."""
    from scipy import ndimage
    from skimage.morphology import medial_axis

    axis, dist = medial_axis(~np.asarray(mask, dtype=bool), return_distance=True)
    axis[:2], axis[-2:], axis[:, :2], axis[:, -2:] = False, False, False, False
    if max_px is not None:
        core = dist > 0.5 * max_px  # the centres of the disks that fit
        if core.any():
            axis &= ndimage.distance_transform_edt(~core) > 0.5 * max_px + 1.0
    return 2.0 * dist[axis]


def check_not_inverted(mask: np.ndarray, pieces: int, where: str) -> None:
    """Refuse a mask traced to ``pieces`` pieces that are few and enclose more black regions than
    they are (at least 3): mortar drawn white (the units black), or units drawn touching, traced as
    one piece. ``where`` names the file in the one-line error."""
    if pieces > FEW_PIECES:
        return
    holes = enclosed_holes(mask)
    if holes >= 3 and holes > pieces:
        raise InputError(
            f"{where}: its white part is {pieces} piece{'' if pieces == 1 else 's'} around {holes} black ones: "
            "the mask looks inverted (mortar white) or its units touch; give the units white on black mortar, "
            "each apart (or a LabelMe file or a label image, whose pieces may touch)"
        )


def trace_to_file(
    mask_path: str | Path,
    out: str | Path,
    config: TraceConfig = TraceConfig(),
    *,
    figure: str | Path | None = None,
    figures: bool = True,
) -> tuple[TraceResult, float, Path]:
    """``calib-masonry trace``: read a mask, trace it, write polygons.json (and the overlay figure,
    beside it unless ``figure`` names another path). Returns the trace, its seconds and the figure."""
    import time

    from ..io import check_not_input, check_output, read_mask_labels, staged_file, write_json

    out = check_output(out, folder=False)
    check_not_input(out, [mask_path])
    given = figure is not None
    figure = check_output(Path(figure) if given else out.with_suffix(".png"), folder=False, flag="--figure")
    check_not_input(figure, [mask_path], flag="--figure" if given else f"--out's figure {figure.name}")
    mask, labels = read_mask_labels(mask_path, field="MASK")  # a LabelMe file's pieces, each its own
    t0 = time.perf_counter()
    result = trace_mask(mask, config) if labels is None else trace_labels(labels, config)
    if not result.bricks:
        raise InputError(f"MASK {mask_path}: no bricks found (no white regions); bricks must be white on black")
    if labels is None:
        check_not_inverted(mask, len(result.bricks), f"MASK {mask_path}")
    seconds = time.perf_counter() - t0
    with staged_file(out) as tmp_json, staged_file(figure) as tmp_png:
        doc = result.to_json()
        doc.update(mask=str(mask_path), vertices=config.vertices, target_dice=config.target_dice)
        write_json(tmp_json, doc)
        if figures:
            from .figures import plot_trace

            plot_trace(mask, result, tmp_png, title=f"{Path(mask_path).name}")
    if not figures:
        figure.unlink(missing_ok=True)
    return result, seconds, figure

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
    nxt = np.roll(mid, -1, axis=0)
    step = nxt - mid
    diagonal = (np.abs(step[:, 0]) > 1e-9) & (np.abs(step[:, 1]) > 1e-9)
    cand = np.column_stack([mid[:, 0], nxt[:, 1]])
    half = np.isclose(np.abs(cand - np.floor(cand)), 0.5).all(axis=1)
    corner = np.where(half[:, None], cand, np.column_stack([nxt[:, 0], mid[:, 1]]))
    out = np.empty((len(mid) + int(diagonal.sum()), 2))
    pos = np.arange(len(mid)) + np.concatenate([[0], np.cumsum(diagonal)[:-1]])
    out[pos] = mid
    out[pos[diagonal] + 1] = corner[diagonal]
    return out


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
    items = []
    for k, slc in enumerate(_progress(slices, desc="trace outlines", unit="brick", enabled=progress), start=1):
        if slc is None:
            continue
        region = labels[slc] == k
        if not connected:
            parts, n_parts = ndimage.label(region, structure=ndimage.generate_binary_structure(2, 1))
            if n_parts > 1:  # a label in several pieces: its largest
                region = parts == 1 + int(np.argmax(np.bincount(parts.ravel())[1:]))
        outline = trace_outline(region)
        offset = np.array([slc[1].start, slc[0].start], dtype=np.float64)
        items.append((k, region, outline, offset))
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

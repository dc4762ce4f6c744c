"""Soft-Dice vertex refinement: move each brick polygon's vertices to maximise Dice.

The splitting method keeps its vertices on the traced outline; here they are free. A soft
rasteriser gives every pixel centre an inside probability ``sigmoid(d / tau)`` from its signed
distance ``d`` to the polygon's boundary (positive inside, by crossing count), so Dice becomes
differentiable in the vertex positions. Each brick's pixels are those of a band around its
outline in a crop around it (so the cost follows the outline, not the image or the crop): they
are laid out in whole blocks in a pool of fixed size, which the loss sums block by block, with
its Jacobian written out, so that one compiled program per schedule serves bricks of every size
(the batch solver of :mod:`calib_masonry.wall2d.refine_kernel`, compiled ahead of time and
called once a brick, asynchronously); optimistix's BFGS minimises, over a
temperature schedule from smooth to sharp, the number of misclassified pixels
``sum(m) (1 - softDice) + penalty x sum(p over forbidden pixels)``. The smooth temperatures see
the pixels at half resolution (``coarse_stages``), the sharp ones every pixel.

Constraints, enforced by a penalty during the fit and checked exactly after it:

* forbidden pixels are those closer to another brick than to this one (beyond half the mortar
  gap) and pixels outside the image, so a refined brick never grows into its neighbour;
* a refined polygon must be simple (no self-crossing);
* no brick ends with a lower (hard, pixel-centre) Dice than its splitting start: otherwise the
  start is kept. Refined polygons of neighbours that still overlap fall back to their starts.

Convention: image coordinates (x = column, y = row, pixel centres at integers).
"""

from __future__ import annotations

import contextlib
import math
from dataclasses import dataclass, replace

import numpy as np
import shapely
from scipy import ndimage

from ..calibrate.fitresult import FitStatus
from ..progress import progress as _progress
from .dice import rasterise_polygon

__all__ = ["RefineConfig", "RefinedPolygon", "refine_polygons", "solver_process"]

_KERNEL = ("signed_distance", "soft_inside", "soft_dice", "hard_dice_points")


def __getattr__(name: str):
    # the JAX side's public names (the soft rasteriser's: refine_kernel.__all__), still found here,
    # imported (with JAX) when first asked for
    if name in _KERNEL:
        from . import refine_kernel

        return getattr(refine_kernel, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


@dataclass(frozen=True)
class RefineConfig:
    """``temperatures`` (pixels) run from smooth to sharp, ``max_steps`` BFGS steps each. Bricks
    whose start already has Dice >= ``easy_dice`` (most bricks of regular masonry) get the short
    schedule ``easy_temperatures`` x ``easy_steps``: they only need a polish."""

    temperatures: tuple[float, ...] = (3.0, 1.5, 0.75, 0.35, 0.2)
    max_steps: int = 40
    easy_dice: float = 0.99
    easy_temperatures: tuple[float, ...] = (1.0, 0.4)
    easy_steps: int = 15
    penalty: float = 4.0
    margin_px: int = 8
    band_px: float = 2.0
    # the first ``coarse_stages`` of ``temperatures`` (3, 1.5 and 0.75 px) see the band at half
    # resolution (each 2 x 2 block of pixels one point with their mean target, weighted by their
    # number); the sharp ones then see every pixel, from where the smooth ones left the polygon.
    # On the SWAT stones this cut the warm time by about a quarter; with 40 steps a stage (was 30)
    # the mean Dice at 4 to 8 vertices is no lower than with every stage at full resolution.
    # 0: every stage sees every pixel.
    coarse_stages: int = 3
    # bricks per call of the batch solver (vmapped lanes), points per block of the band's loop,
    # and points of the pool a call's bricks share: fixed, so that one compiled program per
    # schedule serves any wall (a brick of more than ``pool_points`` points gets a pool of its
    # own, one more compilation). One brick a call was the fastest on the SWAT stones (3.0-3.6 s
    # warm against 7.0-7.9 s with 16-32 bricks a call) and about as fast on small ones (1,000 at
    # 100 px/m: 4.4-4.6 s, the size buckets before it 4.1-4.5 s): a vmapped batch runs until its
    # slowest brick has converged.
    chunk: int = 1
    block: int = 512
    pool_points: int = 1 << 16
    rtol: float = 1e-6
    atol: float = 1e-4
    dtype: str = "float32"


@dataclass(frozen=True)
class RefinedPolygon:
    vertices_xy: np.ndarray
    dice_before: float
    dice: float
    refined: bool  # False when the start was kept
    reason: str = ""  # why the start was kept
    status: FitStatus = FitStatus.CONVERGED  # the BFGS solve's status at the sharpest temperature


#: the refinement's per-stage solver codes (see _refine_batch)
_SOLVER_STATUS = (FitStatus.CONVERGED, FitStatus.STEP_LIMIT, FitStatus.DIVERGED)


# ----------------------------------------------------------------------------------------------
# data preparation (numpy) and the batched driver


@dataclass(frozen=True)
class _Brick:
    origin: np.ndarray  # crop origin (x, y) in image pixels
    shape: tuple[int, int]
    points: np.ndarray  # (P, 2) band pixel centres relative to the crop centre
    centre: np.ndarray  # crop centre in crop pixels
    target: np.ndarray  # (P,)
    forbid: np.ndarray  # (P,)
    const: float  # pixels inside both the region and the start polygon, away from both outlines
    region: np.ndarray  # (rows, cols) crop bool
    allowed: np.ndarray  # (rows, cols) crop bool
    weight: np.ndarray | None = None  # (P,) pixels each point stands for (None: 1)


def _coarse(b: _Brick) -> _Brick:
    """The brick's band seen at half resolution: each 2 x 2 block of pixels becomes one point at
    its centre, with the block's mean target and mean forbidden value, weighted by its pixels in
    the band."""
    xy = np.rint(b.points + b.centre).astype(np.int64)
    block = xy // 2
    key = block[:, 1] * (b.shape[1] // 2 + 2) + block[:, 0]
    uniq, first, inv, count = np.unique(key, return_index=True, return_inverse=True, return_counts=True)
    tgt = np.bincount(inv, b.target, minlength=len(uniq)) / count
    fb = np.bincount(inv, b.forbid, minlength=len(uniq)) / count
    centres = 2.0 * block[first] + 0.5 - b.centre
    return replace(b, points=centres, target=tgt, forbid=fb, weight=count.astype(np.float64))


def _prepare(
    labels: np.ndarray,
    owner: np.ndarray,
    label: int,
    bbox: tuple[slice, slice],
    margin: int,
    start: np.ndarray,
    band: float,
) -> _Brick:
    rows, cols = labels.shape
    r0, r1 = bbox[0].start - margin, bbox[0].stop + margin
    c0, c1 = bbox[1].start - margin, bbox[1].stop + margin
    shape = (r1 - r0, c1 - c0)
    region = np.zeros(shape, bool)
    allowed = np.zeros(shape, bool)
    rr0, rr1, cc0, cc1 = max(r0, 0), min(r1, rows), max(c0, 0), min(c1, cols)
    region[rr0 - r0 : rr1 - r0, cc0 - c0 : cc1 - c0] = labels[rr0:rr1, cc0:cc1] == label
    allowed[rr0 - r0 : rr1 - r0, cc0 - c0 : cc1 - c0] = owner[rr0:rr1, cc0:cc1] == label
    origin = np.array([c0, r0], float)
    raster = rasterise_polygon(start - origin, shape)
    # only pixels near either outline (or where they disagree) can change; the rest are constants
    disagree = region != raster
    if disagree.any():
        # how far the start strays from the outline: the band must cover the moves that undo it
        dev = max(
            float(ndimage.distance_transform_edt(~raster)[region & ~raster].max(initial=0.0)),
            float(ndimage.distance_transform_edt(raster)[raster & ~region].max(initial=0.0)),
        )
        band = band + dev
    near = np.zeros(shape, bool)
    for m in (region, raster):
        near |= (ndimage.distance_transform_edt(m) <= band) & m
        near |= (ndimage.distance_transform_edt(~m) <= band) & ~m
    near |= region != raster
    const = float((region & raster & ~near).sum())
    yy, xx = np.nonzero(near)
    centre = np.array([(shape[1] - 1) / 2.0, (shape[0] - 1) / 2.0])
    points = np.column_stack([xx, yy]).astype(np.float64) - centre
    return _Brick(
        origin=origin,
        shape=shape,
        points=points,
        centre=centre,
        target=region[yy, xx].astype(np.float64),
        forbid=(~allowed[yy, xx]).astype(np.float64),
        const=const,
        region=region,
        allowed=allowed,
    )


def _owner_map(labels: np.ndarray) -> np.ndarray:
    """Each pixel's nearest brick label (the bricks' Voronoi cells in pixels)."""
    if not (labels == 0).any():
        return labels
    _, (ri, ci) = ndimage.distance_transform_edt(labels == 0, return_indices=True)
    return labels[ri, ci]


def _hard_dice(poly_crop: np.ndarray, region: np.ndarray, raster: np.ndarray | None = None) -> float:
    if raster is None:
        raster = rasterise_polygon(poly_crop, region.shape)
    total = raster.sum() + region.sum()
    return 1.0 if total == 0 else 2.0 * float((raster & region).sum()) / float(total)


def refine_polygons(
    labels: np.ndarray,
    ids: list[int],
    starts: list[np.ndarray],
    config: RefineConfig = RefineConfig(),
    *,
    alternatives: list[np.ndarray] | None = None,
) -> list[RefinedPolygon]:
    """Refine the polygons ``starts`` (image pixels, ``(n_i, 2)``) of the bricks ``ids`` of ``labels``.

    ``labels`` is the labelled mask ``(rows, cols)`` (0 = mortar) the polygons were traced from.
    ``alternatives`` (same vertex counts) are second starting polygons: a brick that is not easy
    (start Dice below ``config.easy_dice``) is refined from both and keeps the better result; an
    easy one starts from the better of the two. Every result is compared with ``starts`` (the
    splitting result): no brick ends with a lower Dice than that.
    """
    if not ids:
        return []
    owner = _owner_map(labels)
    slices = ndimage.find_objects(labels)
    splitting = list(starts)
    jobs: list[tuple[int, np.ndarray, bool]] = []  # (brick index, start, easy)
    for i, (k, s) in enumerate(zip(ids, splitting)):
        sl = slices[k - 1]
        origin = np.array([sl[1].start, sl[0].start], float)
        region = labels[sl] == k
        d_s = _hard_dice(s - origin, region)
        a = alternatives[i] if alternatives is not None else None
        ok_a = a is not None and len(a) == len(s) and shapely.Polygon(a).is_valid
        d_a = _hard_dice(a - origin, region) if ok_a else -1.0
        easy = max(d_s, d_a) >= config.easy_dice
        if easy or not ok_a:
            jobs.append((i, a if d_a > d_s else s, easy))
        else:
            jobs.append((i, s, False))
            jobs.append((i, a, False))
    bricks = [
        _prepare(labels, owner, ids[i], slices[ids[i] - 1], config.margin_px, s, config.band_px) for i, s, _ in jobs
    ]
    easy_schedule, hard_first, *hard_then = _schedules(config)
    k = len(hard_then)  # coarse stages first, then the sharp ones (1), or all at once (0)
    first = [easy_schedule if e else hard_first for _, _, e in jobs]
    fits, statuses = _run_jobs(
        [b if e or not k else _coarse(b) for b, (_, _, e) in zip(bricks, jobs)],
        [s for _, s, _ in jobs],
        first,
        config,
        desc="refine" if not k else "refine, smooth stages",
    )
    hard = [j for j, (_, _, e) in enumerate(jobs) if not e] if k else []
    if hard:
        # the sharp stages on every pixel, from where the smooth ones left each polygon
        again = [
            fits[j]
            if fits[j] is not None and np.all(np.isfinite(fits[j])) and shapely.Polygon(fits[j]).is_valid
            else jobs[j][1]
            for j in hard
        ]
        sharp, sharp_status = _run_jobs(
            [bricks[j] for j in hard],
            again,
            hard_then * len(hard),
            config,
            desc="refine, sharp stages",
        )
        for j, f, st in zip(hard, sharp, sharp_status):
            fits[j], statuses[j] = f, st
    best: dict[int, RefinedPolygon] = {}
    keep: dict[int, _Brick] = {}
    for (i, s, _), b, r, st in zip(jobs, bricks, fits, statuses):
        res = replace(_accept_one(b, splitting[i], s, r), status=st)
        if i not in best or res.dice > best[i].dice:
            best[i], keep[i] = res, b
    order = range(len(ids))
    return _resolve_overlaps([keep[i] for i in order], splitting, [best[i] for i in order])


def _chunks(sizes: list[int], lanes: int, pool: int) -> list[list[int]]:
    """Job indices in runs of at most ``lanes`` whose ``sizes`` (points) sum to at most ``pool``,
    by increasing size (bricks solved together take similar numbers of steps and blocks)."""
    out: list[list[int]] = []
    for i in sorted(range(len(sizes)), key=lambda i: (sizes[i], i)):
        if out and len(out[-1]) < lanes and sum(sizes[j] for j in out[-1]) + sizes[i] <= pool:
            out[-1].append(i)
        else:
            out.append([i])
    return out


def _run_jobs(
    bricks: list[_Brick],
    starts: list[np.ndarray],
    schedules: list[tuple[tuple[float, ...], int]],
    config: RefineConfig,
    *,
    desc: str,
) -> tuple[list[np.ndarray | None], list[FitStatus]]:
    """The BFGS solution of every job under its schedule (temperatures, steps per temperature) and
    its solver's status at the last temperature: in the solver process when one runs
    (:func:`solver_process`), else here."""
    bar = _progress(total=len(bricks), desc=desc, unit="brick")
    try:
        if _HELPER is not None and not _HELPER.broken:
            slim = [replace(b, region=None, allowed=None) for b in bricks]  # what the solver reads
            out = _HELPER.run(slim, starts, schedules, config, bar.update)
            if out is not None:
                return out
            _HELPER.broken = True  # from now on, here
        return _solve_jobs(bricks, starts, schedules, config, bar.update)
    finally:
        bar.close()


def _call_arrays(
    bricks: list[_Brick],
    starts: list[np.ndarray],
    sizes: list[int],
    n_max: int,
    config: RefineConfig,
    taus: tuple[float, ...],
) -> tuple[np.ndarray, ...]:
    """The batch solver's arguments for ``bricks`` (at most ``config.chunk``; none gives a call of
    unused lanes, for loading its program) at the temperatures ``taus``."""
    f = np.dtype(config.dtype).type  # numpy arrays of the solver's dtype: no conversion on the way in
    blk, lanes = config.block, config.chunk
    total = sum(sizes)
    length = config.pool_points if total <= config.pool_points else 1 << math.ceil(math.log2(total))
    pool_pts = np.full((length, 2), 1e4, f)  # padding: far outside every polygon, weight 0
    pool_coef = np.zeros((3, length), f)
    off = np.zeros(lanes, dtype=np.int32)
    nblk = np.zeros(lanes, dtype=np.int32)
    m = np.ones(lanes, f)  # an unused lane: no points, a constant loss (0/0 would be NaN)
    const = np.zeros(lanes, f)
    box = np.ones((lanes, 2), f)
    p0 = np.zeros((lanes, n_max, 2), f)
    n = np.ones(lanes, dtype=np.int32)
    at = 0
    for r, (b, start, size) in enumerate(zip(bricks, starts, sizes)):
        k = len(b.points)
        w = np.ones(k) if b.weight is None else b.weight
        pool_pts[at : at + k] = b.points
        pool_coef[:, at : at + k] = w * b.target, w, w * b.forbid
        off[r], nblk[r] = at, size // blk
        at += size
        m[r] = float(np.sum(w * b.target)) + b.const
        const[r] = b.const
        box[r] = b.centre - 0.5  # half the crop, less half a pixel
        s = start - b.origin - b.centre
        p0[r, : len(s)] = s
        p0[r, len(s) :] = s[-1]
        n[r] = len(s)
    return p0, n, pool_pts, pool_coef, off, nblk, m, const, box, np.asarray(config.penalty, f), np.asarray(taus, f)


def _n_max(vertices: int) -> int:
    return 4 * math.ceil(vertices / 4)  # few vertex-count shapes to compile


def _schedules(config: RefineConfig) -> list[tuple[tuple[float, ...], int]]:
    """The schedules (temperatures, steps per temperature) :func:`refine_polygons` solves with:
    the easy bricks', then the others' (their coarse stages and their sharp ones, or all)."""
    temps = tuple(config.temperatures)
    k = config.coarse_stages if 0 < config.coarse_stages < len(temps) else 0
    out = [(tuple(config.easy_temperatures), config.easy_steps)]
    return out + ([(temps[:k], config.max_steps), (temps[k:], config.max_steps)] if k else [(temps, config.max_steps)])


def _solver(config: RefineConfig, schedule: tuple[tuple[float, ...], int], n_max: int):
    from .refine_kernel import _batch_solver

    taus, steps = schedule
    return _batch_solver(n_max, len(taus), steps, config.rtol, config.atol, np.dtype(config.dtype).name, config.block)


def _solve_jobs(
    bricks: list[_Brick],
    starts: list[np.ndarray],
    schedules: list[tuple[tuple[float, ...], int]],
    config: RefineConfig,
    advance=lambda n: None,
) -> tuple[list[np.ndarray | None], list[FitStatus]]:
    """:func:`_run_jobs` in this process; ``advance(n)`` after each ``n`` bricks solved.

    Every call of the batch solver has the same shapes: ``config.chunk`` bricks (unused lanes have
    no points) and a pool of ``config.pool_points`` points (more only for a brick larger than
    that), each brick's band padded to whole blocks of ``config.block`` points. So one compiled
    program per schedule serves every wall, whatever its bricks' sizes."""
    n_max = _n_max(max(len(s) for s in starts))
    results: list[np.ndarray | None] = [None] * len(bricks)
    statuses: list[FitStatus] = [FitStatus.DIVERGED] * len(bricks)
    groups: dict[tuple[tuple[float, ...], int], list[int]] = {}
    for i in range(len(bricks)):
        groups.setdefault(schedules[i], []).append(i)
    blk = config.block
    sizes = [blk * math.ceil(len(b.points) / blk) for b in bricks]
    pending = []
    for schedule, members in sorted(groups.items()):
        solver = _solver(config, schedule, n_max)
        for run in _chunks([sizes[i] for i in members], config.chunk, config.pool_points):
            chunk = [members[r] for r in run]
            arrays = _call_arrays(
                [bricks[i] for i in chunk],
                [starts[i] for i in chunk],
                [sizes[i] for i in chunk],
                n_max,
                config,
                schedule[0],
            )
            pending.append((chunk, solver(*arrays)))
    for chunk, out in pending:  # dispatched above, asynchronously: collected as they finish
        out, codes = (np.asarray(a) for a in out)
        for r, i in enumerate(chunk):
            results[i] = out[r, : len(starts[i])] + bricks[i].centre + bricks[i].origin
            statuses[i] = _SOLVER_STATUS[int(codes[r])]
        advance(len(chunk))
    return results, statuses


def _load_programs(config: RefineConfig, vertices: int | None) -> None:
    """Import JAX and the solver and load (or compile once) the batch solver's programs for every
    schedule of ``config`` at its usual shapes, for polygons of up to ``vertices`` vertices (None:
    not known yet; they load when first called)."""
    from . import refine_kernel  # noqa: F401 - JAX

    if vertices is None:
        return
    n_max = _n_max(vertices)
    for schedule in _schedules(config):
        _solver(config, schedule, n_max).load(*_call_arrays([], [], [], n_max, config, schedule[0]))


# ----------------------------------------------------------------------------------------------
# the solver process


class _SolverProcess:
    """A process forked before the caller prepares its walls: it imports JAX and loads the batch
    solver's programs (about a second, on the other core) while the caller traces and prepares,
    then solves the jobs it is sent (:func:`_solve_jobs`). Results are bit for bit the local
    solve's (the same programs, the same arrays)."""

    def __init__(self, config: RefineConfig, vertices: int | None):
        import multiprocessing

        self.broken = False
        ctx = multiprocessing.get_context("fork")
        self._conn, child = ctx.Pipe()
        self._proc = ctx.Process(
            target=_serve, args=(child, self._conn, config, vertices), daemon=True, name="refine-solver"
        )
        self._proc.start()
        child.close()

    def run(self, bricks, starts, schedules, config, advance):
        """The jobs' results, solved there; None if the process cannot solve them (it ended, or
        its solve raised): the caller then solves here, where an error shows as it would."""
        from ..process import raise_if_stopped

        done = 0
        try:
            self._conn.send((bricks, starts, schedules, config))
            while True:
                while not self._conn.poll(0.1):
                    raise_if_stopped()
                    if not self._proc.is_alive():
                        raise EOFError
                kind, value = self._conn.recv()
                if kind == "done":
                    return value
                if kind != "progress":
                    raise EOFError
                done += value
                advance(value)
        except (OSError, EOFError):  # the pipe broke, the process is gone, or its solve raised
            advance(-done)  # the caller's solve counts them again
            return None

    def close(self) -> None:
        with contextlib.suppress(OSError):
            self._conn.close()  # an idle solver process reads end of file and leaves
        self._proc.terminate()  # a busy one (the caller stopped, or failed early) is stopped
        self._proc.join()


def _serve(conn, caller_end, config: RefineConfig, vertices: int | None) -> None:
    import os
    import signal

    caller_end.close()  # the fork's copy of the caller's end: the caller closing its own ends the loop
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the caller stops it (Ctrl-C reaches both)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    try:
        try:
            _load_programs(config, vertices)
        except Exception:  # noqa: BLE001 - a head start only: what fails here fails again, and is reported, on use
            pass
        while True:
            try:
                bricks, starts, schedules, cfg = conn.recv()
            except EOFError:  # the caller is done (or gone)
                break
            try:
                out = _solve_jobs(bricks, starts, schedules, cfg, lambda n: conn.send(("progress", n)))
            except Exception as exc:  # noqa: BLE001 - reported by the caller, on its side
                conn.send(("error", f"{type(exc).__name__}: {exc}"))
            else:
                conn.send(("done", out))
    except (EOFError, OSError, BrokenPipeError):
        pass
    finally:
        os._exit(0)  # none of the caller's exit handlers


_HELPER: _SolverProcess | None = None


@contextlib.contextmanager
def solver_process(config: RefineConfig = RefineConfig(), vertices: int | None = None):
    """Within the block, :func:`refine_polygons` solves in a process forked on entry, which loads
    JAX and the solver's programs (about a second) while this one traces and prepares: a command
    that refines once (``trace --refine``) then pays about the warm refinement's time. Where
    processes cannot be forked (or within another such block), the refinement runs here, as
    without the block. Enter it before importing JAX or starting threads (a fork copies only the
    calling thread)."""
    global _HELPER
    import sys
    import threading

    if _HELPER is not None or "jax" in sys.modules or threading.active_count() > 1:
        yield
        return
    try:
        helper = _SolverProcess(config, vertices)
    except (ValueError, OSError):  # no fork on this platform, or no process to be had
        yield
        return
    _HELPER = helper
    try:
        yield
    finally:
        _HELPER = None
        helper.close()


def _check(b: _Brick, v: np.ndarray, d0: float) -> tuple[str, float]:
    """Why ``v`` (image pixels) is not acceptable ("" when it is) and its hard Dice."""
    if not np.all(np.isfinite(v)):
        return "fit failed", d0
    if not shapely.Polygon(v).is_valid:
        return "self-crossing", d0
    crop = v - b.origin
    if crop.min() < -0.5 or crop[:, 0].max() > b.shape[1] - 0.5 or crop[:, 1].max() > b.shape[0] - 0.5:
        return "left its crop", d0
    raster = rasterise_polygon(crop, b.shape)
    if (raster & ~b.allowed).any():
        return "grew into a neighbour's half of the mortar", d0
    d1 = _hard_dice(crop, b.region, raster)
    if d1 < d0:
        return "no better than the start", d0
    return "", d1


def _accept_one(b: _Brick, splitting: np.ndarray, start: np.ndarray, fit: np.ndarray | None) -> RefinedPolygon:
    """The fit if it passes every check, else the largest step toward it from its start that
    does (the start itself included), else the splitting polygon."""
    d0 = _hard_dice(splitting - b.origin, b.region)
    if fit is None:
        return RefinedPolygon(splitting, d0, d0, False, "fit failed")
    reason, d1 = _check(b, fit, d0)
    if not reason:
        return RefinedPolygon(fit, d0, d1, True)
    for a in (0.75, 0.5, 0.25, 0.0):
        v = start + a * (fit - start)
        why, d = _check(b, v, d0)
        if not why:
            return RefinedPolygon(v, d0, d, True, f"{reason}: moved {a:.0%} of the way")
    return RefinedPolygon(splitting, d0, d0, False, reason)


def _resolve_overlaps(
    bricks: list[_Brick], starts: list[np.ndarray], out: list[RefinedPolygon]
) -> list[RefinedPolygon]:
    """Refined neighbours that overlap (between pixel centres) are moved back toward their starts.

    Each refined polygon of an overlapping pair is blended ``start + a (refined - start)`` with the
    largest ``a`` in 1, 3/4, ..., 0 that overlaps no neighbour, stays simple and is no worse
    than the start; ``a = 0`` is the start itself.
    """
    geoms = [shapely.Polygon(p.vertices_xy) for p in out]
    tree = shapely.STRtree([shapely.Polygon(p.vertices_xy).buffer(2.0) for p in out])

    def overlaps(k: int, g: shapely.Polygon) -> bool:
        return any(j != k and g.intersection(geoms[j]).area > 1e-9 for j in tree.query(g))

    for _ in range(3):
        changed = False
        for k, p in enumerate(out):
            if not p.refined or not overlaps(k, geoms[k]):
                continue
            for a in (0.75, 0.5, 0.25, 0.0):
                v = starts[k] + a * (p.vertices_xy - starts[k])
                g = shapely.Polygon(v)
                if a > 0 and (not g.is_valid or overlaps(k, g)):
                    continue
                d = _hard_dice(v - bricks[k].origin, bricks[k].region)
                if a > 0 and d < p.dice_before:
                    continue
                out[k] = (
                    RefinedPolygon(v, p.dice_before, d, True)
                    if a > 0
                    else RefinedPolygon(starts[k], p.dice_before, p.dice_before, False, "overlapped a neighbour")
                )
                geoms[k] = g
                changed = True
                break
        if not changed:
            break
    return out

"""Soft-Dice vertex refinement: move each brick polygon's vertices to maximise Dice.

The splitting method keeps its vertices on the traced outline; here they are free. A soft
rasteriser gives every pixel centre an inside probability ``sigmoid(d / tau)`` from its signed
distance ``d`` to the polygon's boundary (positive inside, by crossing count), so Dice becomes
differentiable in the vertex positions. Each brick's pixels are those of a band around its
outline in a crop around it (so the cost follows the outline, not the image or the crop): they
are laid out in whole blocks in a pool of fixed size, which the loss sums block by block, with
its Jacobian written out (:func:`_block_sums`), so that one compiled program per schedule serves
bricks of every size (the batch solver exported once, :func:`_batch_solver`, and called once a
brick, asynchronously); optimistix's BFGS minimises, over a
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

import math
from dataclasses import dataclass, replace
from functools import cache, partial

import numpy as np
import shapely
from scipy import ndimage

from .._jax import jax, jnp
from ..calibrate.fitresult import FitStatus
from ..progress import progress as _progress
from .dice import rasterise_polygon

__all__ = [
    "RefineConfig",
    "RefinedPolygon",
    "soft_inside",
    "soft_dice",
    "hard_dice_points",
    "refine_polygons",
    "signed_distance",
]


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
# the soft rasteriser (pure JAX)


def signed_distance(points: jnp.ndarray, verts: jnp.ndarray) -> jnp.ndarray:
    """Signed distance ``(P,)`` of ``points`` ``(P, 2)`` to the polygon ``verts`` ``(N, 2)``; > 0 inside.

    Inside is decided by the even-odd crossing rule (half-open in y), which is piecewise constant
    in the vertices, so gradients flow through the distance only. Zero-length edges (repeated
    vertices, used for padding) are harmless.
    """
    _, closest = _closest_on_edges(points, verts)
    d2 = jnp.min(jnp.sum(closest * closest, axis=-1), axis=1)
    dist = jnp.sqrt(d2 + 1e-12)
    return jnp.where(_inside(points, verts), dist, -dist)


def _closest_on_edges(points: jnp.ndarray, verts: jnp.ndarray) -> tuple[jnp.ndarray, jnp.ndarray]:
    """For each point and each edge ``a -> b`` of the polygon: the parameter ``t`` ``(P, N)`` of
    the edge's point ``q = a + t (b - a)`` closest to it, and ``p - q`` ``(P, N, 2)``."""
    a = verts
    ab = jnp.roll(verts, -1, axis=0) - a  # (N, 2)
    ap = points[:, None, :] - a[None, :, :]  # (P, N, 2)
    len2 = jnp.sum(ab * ab, axis=-1)  # (N,)
    safe = jnp.where(len2 > 0, len2, 1.0)
    t = jnp.clip(jnp.sum(ap * ab[None], axis=-1) / safe, 0.0, 1.0)
    return t, ap - t[..., None] * ab[None]


def _inside(points: jnp.ndarray, verts: jnp.ndarray) -> jnp.ndarray:
    """Whether each point is inside the polygon: the even-odd crossing rule, half-open in y."""
    a = verts
    b = jnp.roll(verts, -1, axis=0)
    py = points[:, 1:2]
    px = points[:, 0:1]
    ay, by = a[None, :, 1], b[None, :, 1]
    straddle = (ay <= py) != (by <= py)
    dy = jnp.where(by != ay, by - ay, 1.0)
    xint = a[None, :, 0] + (py - ay) * (b[None, :, 0] - a[None, :, 0]) / dy
    crossings = jnp.sum(straddle & (px < xint), axis=1)
    return (crossings % 2) == 1


def soft_inside(points: jnp.ndarray, verts: jnp.ndarray, tau: float) -> jnp.ndarray:
    """Inside probability ``(P,)`` of each point: ``sigmoid(signed distance / tau)``."""
    return jax.nn.sigmoid(signed_distance(points, verts) / tau)


def soft_dice(verts, points, target, weight, tau) -> jnp.ndarray:
    """Soft Dice of the polygon against the 0/1 ``target`` over weighted ``points``."""
    p = soft_inside(points, verts, tau)
    tp = jnp.sum(weight * target * p)
    return 2.0 * tp / (jnp.sum(weight * p) + jnp.sum(weight * target))


def hard_dice_points(verts, points, target, weight) -> jnp.ndarray:
    inside = (signed_distance(points, verts) > 0).astype(points.dtype)
    tp = jnp.sum(weight * target * inside)
    return 2.0 * tp / (jnp.sum(weight * inside) + jnp.sum(weight * target))


def _vertices(params, n):
    idx = jnp.minimum(jnp.arange(params.shape[0]), n - 1)
    return params[idx]


def _block_sums(verts, pts, coef, tau):
    """``coef @ p`` ``(3,)`` for one block of points ``(S, 2)``, the rows of ``coef`` ``(3, S)`` being
    ``w t``, ``w`` and ``w f`` (weight, target, forbidden), and its Jacobian ``(3, N, 2)`` in the
    vertices.

    The Jacobian is written out: a point's signed distance moves only with the two vertices of
    its nearest edge, ``d|p - q| / da = -u (1 - t)`` and ``d|p - q| / db = -u t`` for the closest
    point ``q = a + t (b - a)`` and the unit vector ``u`` from ``q`` to ``p`` (the derivative
    through ``t`` vanishes: ``t`` is optimal, or clipped and constant). It is what reverse-mode
    differentiation of :func:`signed_distance` gives (a test checks), at the cost of one pass."""
    t, closest = _closest_on_edges(pts, verts)  # (S, N), (S, N, 2)
    d2 = jnp.sum(closest * closest, axis=-1)
    nearest = jnp.argmin(d2, axis=1)
    onehot = (jnp.arange(verts.shape[0])[None, :] == nearest[:, None]).astype(pts.dtype)  # (S, N)
    dist = jnp.sqrt(jnp.min(d2, axis=1) + 1e-12)
    sign = jnp.where(_inside(pts, verts), 1.0, -1.0).astype(pts.dtype)
    p = jax.nn.sigmoid(sign * dist / tau)
    g = coef * (sign * p * (1.0 - p) / tau)[None, :]  # (3, S): d(sum)/d(dist) per point
    te = jnp.sum(onehot * t, axis=1)
    u = jnp.einsum("sn,snd->sd", onehot, closest) / dist[:, None]
    ga = jnp.einsum("ks,sn,sd->knd", g, onehot, -u * (1.0 - te)[:, None])
    gb = jnp.einsum("ks,sn,sd->knd", g, onehot, -u * te[:, None])
    return coef @ p, ga + jnp.roll(gb, 1, axis=1)


def _pool_sums_and_jacobian(verts, pool_pts, pool_coef, off, nblk, tau, block):
    """The band sums of one brick whose points are the ``nblk`` blocks of ``block`` points from
    ``off`` in the pool, with their Jacobian in the vertices: a loop over blocks, so that one
    compiled program serves any brick size (its cost follows the brick's points, not the pool's)."""

    def body(carry):
        i, s, j = carry
        start = off + i * block
        pts = jax.lax.dynamic_slice_in_dim(pool_pts, start, block, 0)
        coef = jax.lax.dynamic_slice_in_dim(pool_coef, start, block, 1)
        v, g = _block_sums(verts, pts, coef, tau)
        return i + 1, s + v, j + g

    init = (jnp.zeros((), nblk.dtype), jnp.zeros(3, pool_pts.dtype), jnp.zeros((3, *verts.shape), pool_pts.dtype))
    _, s, j = jax.lax.while_loop(lambda c: c[0] < nblk, body, init)
    return s, j


@partial(jax.custom_jvp, nondiff_argnums=(6,))
def _pool_sums(verts, pool_pts, pool_coef, off, nblk, tau, block):
    """``(sum w t p, sum w p, sum w f p)`` over the brick's band, ``p`` the soft inside
    probability. Its derivative is the Jacobian the block loop accumulates (a loop has no reverse
    derivative of its own); only the vertices are differentiated."""
    return _pool_sums_and_jacobian(verts, pool_pts, pool_coef, off, nblk, tau, block)[0]


@_pool_sums.defjvp
def _pool_sums_jvp(block, primals, tangents):
    s, jac = _pool_sums_and_jacobian(*primals, block)
    return s, jnp.tensordot(jac, tangents[0].astype(jac.dtype), axes=2)


def _loss(params, args):
    n, pool_pts, pool_coef, off, nblk, m, const, box, tau, penalty, block = args
    verts = _vertices(params, n)
    wtp, wp, wfp = _pool_sums(verts, pool_pts, pool_coef, off, nblk, tau, block)
    dice = 2.0 * (wtp + const) / (wp + const + m)
    # a barrier keeps every vertex inside the crop, where the pixels that judge it are
    outside = jnp.maximum(jnp.abs(verts) - box, 0.0)
    return m * (1.0 - dice) + penalty * wfp + 100.0 * penalty * jnp.sum(outside**2)


def _refine_batch(
    params0, n, pool_pts, pool_coef, off, nblk, m, const, box, penalty, taus, *, max_steps, rtol, atol, block
):
    """Every brick of a batch through the temperatures ``taus``, ``max_steps`` BFGS steps each
    (vmap over bricks of a scan over temperatures). Brick ``b``'s band is the ``nblk[b]`` blocks of
    ``block`` points from ``off[b]`` in the pool shared by the batch: ``pool_pts`` ``(L, 2)`` and
    ``pool_coef`` ``(3, L)`` (weight x target, weight, weight x forbidden); ``m`` is the brick's
    region in pixels and ``const`` the pixels inside both it and the polygon that the band leaves
    out. Called through :func:`_batch_solver`."""
    import optimistix as optx

    def one(p0, n_, o, nb, m_, c, bx):
        def stage(y, tau):
            sol = optx.minimise(
                _loss,
                optx.BFGS(rtol=rtol, atol=atol),
                y,
                args=(n_, pool_pts, pool_coef, o, nb, m_, c, bx, tau, penalty, block),
                max_steps=max_steps,
                throw=False,
            )
            finite = jnp.all(jnp.isfinite(sol.value))
            # 0 converged, 1 step limit, 2 non-finite (the stage's start is kept)
            code = jnp.where(finite, jnp.where(sol.result == optx.RESULTS.successful, 0, 1), 2)
            return jnp.where(finite, sol.value, y), code

        y, codes = jax.lax.scan(stage, p0, taus)
        return _vertices(y, n_), codes[-1]

    return jax.vmap(one)(params0, n, off, nblk, m, const, box)


@cache
def _batch_solver(n_max: int, n_taus: int, max_steps: int, rtol: float, atol: float, dtype: str, block: int):
    """:func:`_refine_batch` for these settings, exported once for any batch and pool size (JAX
    shape polymorphism), kept on disk beside the compilation cache and in memory
    (:func:`calib_masonry._jax.exported`).

    Why: tracing it (vmap of a scan of optimistix's BFGS) takes about a second, far more than
    most solves; exported, it is traced once per settings and machine. The refinement calls it
    with one batch size and one pool size (:func:`_run_jobs`), so a process compiles it once per
    schedule, or finds it in the persistent compilation cache. Its results are bit for bit those
    of the jitted function. Returned jitted, for jit's fast dispatch: a wall makes a call per
    brick."""
    from jax import export

    from .._jax import exported

    b, length = export.symbolic_shape("b, L", constraints=[f"L >= {block}"])
    dt = jnp.dtype(dtype)

    def spec(*shape, t=dt):
        return jax.ShapeDtypeStruct(shape, t)

    i32 = jnp.int32
    args = (spec(b, n_max, 2), spec(b, t=i32), spec(length, 2), spec(3, length), spec(b, t=i32), spec(b, t=i32))
    args += (spec(b), spec(b), spec(b, 2), spec(), spec(n_taus))
    return jax.jit(
        exported(
            "refine",
            partial(_refine_batch, max_steps=max_steps, rtol=rtol, atol=atol, block=block),
            args,
            sources=[__file__],
            settings=(n_max, n_taus, max_steps, rtol, atol, dtype, block),
        ).call
    )


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
    temps = tuple(config.temperatures)
    k = config.coarse_stages if 0 < config.coarse_stages < len(temps) else 0
    easy_schedule = (tuple(config.easy_temperatures), config.easy_steps)
    first = [easy_schedule if e else (temps[:k] if k else temps, config.max_steps) for _, _, e in jobs]
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
            [(temps[k:], config.max_steps)] * len(hard),
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
    its solver's status at the last temperature.

    Every call of the batch solver has the same shapes: ``config.chunk`` bricks (unused lanes have
    no points) and a pool of ``config.pool_points`` points (more only for a brick larger than
    that), each brick's band padded to whole blocks of ``config.block`` points. So one compiled
    program per schedule serves every wall, whatever its bricks' sizes."""
    n_max = 4 * math.ceil(max(len(s) for s in starts) / 4)  # few vertex-count shapes to compile
    results: list[np.ndarray | None] = [None] * len(bricks)
    statuses: list[FitStatus] = [FitStatus.DIVERGED] * len(bricks)
    groups: dict[tuple[tuple[float, ...], int], list[int]] = {}
    for i in range(len(bricks)):
        groups.setdefault(schedules[i], []).append(i)
    dt = jnp.dtype(config.dtype)
    f = dt.type  # numpy arrays of the solver's dtype: no conversion on the way in
    blk, lanes = config.block, config.chunk
    sizes = [blk * math.ceil(len(b.points) / blk) for b in bricks]
    bar = _progress(total=len(bricks), desc=desc, unit="brick")
    pending = []
    for (taus, steps), members in sorted(groups.items()):
        solver = _batch_solver(n_max, len(taus), steps, config.rtol, config.atol, dt.name, blk)
        penalty, taus_arr = np.asarray(config.penalty, dt), np.asarray(taus, dt)
        for run in _chunks([sizes[i] for i in members], lanes, config.pool_points):
            chunk = [members[r] for r in run]
            total = sum(sizes[i] for i in chunk)
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
            for r, i in enumerate(chunk):
                b = bricks[i]
                k = len(b.points)
                w = np.ones(k) if b.weight is None else b.weight
                pool_pts[at : at + k] = b.points
                pool_coef[:, at : at + k] = w * b.target, w, w * b.forbid
                off[r], nblk[r] = at, sizes[i] // blk
                at += sizes[i]
                m[r] = float(np.sum(w * b.target)) + b.const
                const[r] = b.const
                box[r] = b.centre - 0.5  # half the crop, less half a pixel
                s = starts[i] - b.origin - b.centre
                p0[r, : len(s)] = s
                p0[r, len(s) :] = s[-1]
                n[r] = len(s)
            out = solver(p0, n, pool_pts, pool_coef, off, nblk, m, const, box, penalty, taus_arr)
            pending.append((chunk, out))
    for chunk, out in pending:  # dispatched above, asynchronously: collected as they finish
        out, codes = (np.asarray(a) for a in out)
        for r, i in enumerate(chunk):
            results[i] = out[r, : len(starts[i])] + bricks[i].centre + bricks[i].origin
            statuses[i] = _SOLVER_STATUS[int(codes[r])]
        bar.update(len(chunk))
    bar.close()
    return results, statuses


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

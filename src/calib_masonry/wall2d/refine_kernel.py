"""The soft-Dice refinement's JAX side (:mod:`calib_masonry.wall2d.refine` has the method, its
data preparation and its driver): the soft rasteriser, the loss summed block by block with its
Jacobian written out, and the batch solver (optimistix's BFGS over a temperature schedule),
exported and compiled ahead of time (:func:`_batch_solver`).

Kept apart so that the driver's numpy work (cropping, banding, checking) imports no JAX: a
command can prepare a wall while another process loads JAX and the solver
(:func:`calib_masonry.wall2d.refine.solver_process`).
"""

from __future__ import annotations

from functools import cache, partial

from .._jax import jax, jnp

__all__ = ["signed_distance", "soft_inside", "soft_dice", "hard_dice_points"]

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
    with one batch size and one pool size (:func:`_run_jobs`), so it needs a program per
    schedule (and per larger pool), compiled once per machine and loaded from disk by each
    process (:class:`calib_masonry._jax.Precompiled`). Its results are bit for bit those of the
    jitted function."""
    from jax import export

    from .._jax import Precompiled

    b, length = export.symbolic_shape("b, L", constraints=[f"L >= {block}"])
    dt = jnp.dtype(dtype)

    def spec(*shape, t=dt):
        return jax.ShapeDtypeStruct(shape, t)

    i32 = jnp.int32
    args = (spec(b, n_max, 2), spec(b, t=i32), spec(length, 2), spec(3, length), spec(b, t=i32), spec(b, t=i32))
    args += (spec(b), spec(b), spec(b, 2), spec(), spec(n_taus))
    return Precompiled(
        "refine",
        partial(_refine_batch, max_steps=max_steps, rtol=rtol, atol=atol, block=block),
        args,
        sources=[__file__],
        settings=(n_max, n_taus, max_steps, rtol, atol, dtype, block),
    )

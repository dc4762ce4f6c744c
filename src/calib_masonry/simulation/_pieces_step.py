"""The freed pieces' explicit step compiled (numba): :meth:`~calib_masonry.simulation.pieces._Pieces.advance`'s
arithmetic, steps at a time, without numpy's per-call overhead.

Why: in numpy a step of a few hundred contact corners costs about 1 ms, almost all of it the
dispatch of some forty small array operations, and a quake whose pieces rock for the whole record
takes tens of thousands of steps (the paper example's 0.3 g record: 34 s of its 219 s; docs/dynamics.md).
Compiled, the same step is the arithmetic alone, and a run of steps between two reads of the state is
one call.

The arithmetic is the numpy step's, term for term and in the same order where the order is numpy's
own (sums of three products, a force summed over the corners in their order), so the motion is the
same to a few units of the last place: the numpy step's matrix products of 3 x 3 blocks (the inertia
turned into the world frame) go through BLAS, which may fuse a multiply and an add, and this does not.
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["advance_steps"]


@njit(cache=True, nogil=True)
def _rotate_exact(R: np.ndarray) -> np.ndarray:
    u, _, vt = np.linalg.svd(R)
    return u @ vt


@njit(cache=True, nogil=True)
def _turned(R: np.ndarray, A: np.ndarray, tmp: np.ndarray, out: np.ndarray) -> None:
    """``out = (R A) R^T`` for 3 x 3 ``R`` and ``A`` (``tmp`` holds ``R A``)."""
    for a in range(3):
        for b in range(3):
            tmp[a, b] = R[a, 0] * A[0, b] + R[a, 1] * A[1, b] + R[a, 2] * A[2, b]
    for a in range(3):
        for b in range(3):
            out[a, b] = tmp[a, 0] * R[b, 0] + tmp[a, 1] * R[b, 1] + tmp[a, 2] * R[b, 2]


@njit(cache=True, nogil=True)
def advance_steps(
    g: np.ndarray,  # (S, 3) the load per unit mass of each step
    dt: float,
    count: int,  # steps made before (every 64th rotation is re-orthonormalised)
    R: np.ndarray,  # (n, 3, 3) per piece, updated
    c: np.ndarray,  # (n, 3)
    d: np.ndarray,  # (n, 3) updated
    v: np.ndarray,  # (n, 3) updated
    w: np.ndarray,  # (n, 3) updated
    M: np.ndarray,  # (n,)
    I0: np.ndarray,  # (n, 3, 3)
    I0inv: np.ndarray,  # (n, 3, 3)
    alive: np.ndarray,  # (n,) bool
    sa: np.ndarray,  # (C,) each corner's sides: a piece, or n for the still ground
    sb: np.ndarray,
    p: np.ndarray,  # (C, 3) the corners' points at the start
    fu: np.ndarray,  # (C, 3) each corner's frame
    fv: np.ndarray,
    fn: np.ndarray,
    k: np.ndarray,  # (C, 3) the corners' stiffness (u, v, n)
    cdamp: np.ndarray,  # (C, 3) their dashpots
    off: np.ndarray,  # (C,) how far each corner started into its normal spring
    slip: np.ndarray,  # (C, 2) the corners' kept slip, updated
    friction: float,
) -> int:
    """``S`` steps of ``dt``; returns the count of steps made (``count + S``)."""
    n = M.shape[0]
    C = sa.shape[0]
    F = np.empty((n, 3))
    T = np.empty((n, 3))
    FB = np.empty((n + 1, 3))
    FA = np.empty((n + 1, 3))
    TB = np.empty((n + 1, 3))
    TA = np.empty((n + 1, 3))
    ra = np.empty(3)
    rb = np.empty(3)
    fb = np.empty(3)
    Iw = np.empty((3, 3))
    Iinv = np.empty((3, 3))
    tmp = np.empty((3, 3))
    for step in range(g.shape[0]):
        for i in range(n):
            for a in range(3):
                F[i, a] = M[i] * g[step, a]
                T[i, a] = 0.0
        if C:
            FB[:] = 0.0
            FA[:] = 0.0
            TB[:] = 0.0
            TA[:] = 0.0
            for q in range(C):
                ia = sa[q]
                ib = sb[q]
                # the corner's lever from each side's centroid, turned with it (the ground: not)
                for a in range(3):
                    if ia < n:
                        ra[a] = R[ia, a, 0] * (p[q, 0] - c[ia, 0]) + R[ia, a, 1] * (p[q, 1] - c[ia, 1])
                        ra[a] = ra[a] + R[ia, a, 2] * (p[q, 2] - c[ia, 2])
                    else:
                        ra[a] = p[q, a]
                    if ib < n:
                        rb[a] = R[ib, a, 0] * (p[q, 0] - c[ib, 0]) + R[ib, a, 1] * (p[q, 1] - c[ib, 1])
                        rb[a] = rb[a] + R[ib, a, 2] * (p[q, 2] - c[ib, 2])
                    else:
                        rb[a] = p[q, a]
                gu = 0.0
                gv = 0.0
                gn = 0.0
                vu = 0.0
                vv = 0.0
                vn = 0.0
                for a in range(3):
                    cda = c[ia, a] + d[ia, a] if ia < n else 0.0
                    cdb = c[ib, a] + d[ib, a] if ib < n else 0.0
                    gap = (rb[a] + cdb) - (ra[a] + cda)
                    # (w x r)[a]
                    a1 = (a + 1) % 3
                    a2 = (a + 2) % 3
                    if ib < n:
                        velb = v[ib, a] + (w[ib, a1] * rb[a2] - w[ib, a2] * rb[a1])
                    else:
                        velb = 0.0 + (0.0 * rb[a2] - 0.0 * rb[a1])
                    if ia < n:
                        vela = v[ia, a] + (w[ia, a1] * ra[a2] - w[ia, a2] * ra[a1])
                    else:
                        vela = 0.0 + (0.0 * ra[a2] - 0.0 * ra[a1])
                    vel = velb - vela
                    if a == 0:
                        gu = gap * fu[q, 0]
                        gv = gap * fv[q, 0]
                        gn = gap * fn[q, 0]
                        vu = vel * fu[q, 0]
                        vv = vel * fv[q, 0]
                        vn = vel * fn[q, 0]
                    else:
                        gu += gap * fu[q, a]
                        gv += gap * fv[q, a]
                        gn += gap * fn[q, a]
                        vu += vel * fu[q, a]
                        vv += vel * fv[q, a]
                        vn += vel * fn[q, a]
                dn = gn - off[q]
                closed = dn < 0.0
                N = -k[q, 2] * dn - cdamp[q, 2] * vn if closed else 0.0
                N = max(N, 0.0)
                s0 = slip[q, 0]
                s1 = slip[q, 1]
                t0 = -k[q, 0] * (gu - s0) - cdamp[q, 0] * vu
                t1 = -k[q, 1] * (gv - s1) - cdamp[q, 1] * vv
                limit = friction * N
                size = np.sqrt(t0 * t0 + t1 * t1)
                if size > limit:
                    scale = limit / max(size, 1e-300)
                    t0 = t0 * scale
                    t1 = t1 * scale
                    s0 = gu + t0 / max(k[q, 0], 1e-300)
                    s1 = gv + t1 / max(k[q, 1], 1e-300)
                if not closed:
                    s0 = gu
                    s1 = gv
                    t0 = 0.0
                    t1 = 0.0
                slip[q, 0] = s0
                slip[q, 1] = s1
                for a in range(3):
                    fb[a] = (fn[q, a] * N + fu[q, a] * t0) + fv[q, a] * t1
                for a in range(3):
                    a1 = (a + 1) % 3
                    a2 = (a + 2) % 3
                    FB[ib, a] += fb[a]
                    FA[ia, a] += fb[a]
                    TB[ib, a] += rb[a1] * fb[a2] - rb[a2] * fb[a1]
                    TA[ia, a] += ra[a1] * fb[a2] - ra[a2] * fb[a1]
            for i in range(n):
                for a in range(3):
                    F[i, a] += FB[i, a] - FA[i, a]
                    T[i, a] += TB[i, a] - TA[i, a]
        count += 1
        exact = count % 64 == 0
        for i in range(n):
            # the inertia in the world frame, its gyroscopic moment and the angular acceleration
            _turned(R[i], I0[i], tmp, Iw)
            _turned(R[i], I0inv[i], tmp, Iinv)
            Lw0 = Iw[0, 0] * w[i, 0] + Iw[0, 1] * w[i, 1] + Iw[0, 2] * w[i, 2]
            Lw1 = Iw[1, 0] * w[i, 0] + Iw[1, 1] * w[i, 1] + Iw[1, 2] * w[i, 2]
            Lw2 = Iw[2, 0] * w[i, 0] + Iw[2, 1] * w[i, 1] + Iw[2, 2] * w[i, 2]
            m0 = T[i, 0] - (w[i, 1] * Lw2 - w[i, 2] * Lw1)
            m1 = T[i, 1] - (w[i, 2] * Lw0 - w[i, 0] * Lw2)
            m2 = T[i, 2] - (w[i, 0] * Lw1 - w[i, 1] * Lw0)
            if not alive[i]:
                continue
            for a in range(3):
                v[i, a] += dt * F[i, a] / M[i]
            dw0 = Iinv[0, 0] * m0 + Iinv[0, 1] * m1 + Iinv[0, 2] * m2
            dw1 = Iinv[1, 0] * m0 + Iinv[1, 1] * m1 + Iinv[1, 2] * m2
            dw2 = Iinv[2, 0] * m0 + Iinv[2, 1] * m1 + Iinv[2, 2] * m2
            w[i, 0] += dt * dw0
            w[i, 1] += dt * dw1
            w[i, 2] += dt * dw2
            for a in range(3):
                d[i, a] += dt * v[i, a]
            # Rodrigues: exp(skew(dt w)) R
            x0 = dt * w[i, 0]
            x1 = dt * w[i, 1]
            x2 = dt * w[i, 2]
            th = np.sqrt(x0 * x0 + x1 * x1 + x2 * x2)
            if th < 1e-12:
                k0 = 0.0
                k1 = 0.0
                k2 = 0.0
            else:
                k0 = x0 / th
                k1 = x1 / th
                k2 = x2 / th
            sn = np.sin(th)
            cs = 1.0 - np.cos(th)
            # K = skew(k), E = I + sin K + (1 - cos) K K
            K = np.array(((0.0, -k2, k1), (k2, 0.0, -k0), (-k1, k0, 0.0)))
            for a in range(3):
                for b in range(3):
                    kk = K[a, 0] * K[0, b] + K[a, 1] * K[1, b] + K[a, 2] * K[2, b]
                    Iw[a, b] = (1.0 if a == b else 0.0) + sn * K[a, b] + cs * kk
            for a in range(3):
                for b in range(3):
                    tmp[a, b] = Iw[a, 0] * R[i, 0, b] + Iw[a, 1] * R[i, 1, b] + Iw[a, 2] * R[i, 2, b]
            if exact:
                tmp = _rotate_exact(tmp.copy())
            for a in range(3):
                for b in range(3):
                    R[i, a, b] = tmp[a, b]
    return count

"""The contact iteration's per-corner arithmetic compiled (numba): the contact law
(:meth:`~calib_masonry.simulation.joints.JointModel._contact_forces`), the corners' tangent blocks
(:func:`~calib_masonry.simulation.joints._corner_blocks`) and their sum into the tangent's pattern
(:meth:`~calib_masonry.simulation.joints._Tangent.values`).

Why: a dry stone wall's every joint is a contact, and its iteration evaluates the law and sums a
12 x 12 block for each of a few thousand contact corners at every residual and Newton step. In
numpy those are dozens of array operations on ``(C,)`` to ``(C, 78)`` arrays: on SW.100.1's 3,064
corners the law took 0.69 ms and the blocks 1.34 ms a call, 40 % of its dry pushover (py-spy);
compiled, 0.25 and 0.34 ms (docs/stone_walls.md, "Where a dry pushover's time goes"). Each is
numpy's arithmetic term for term and in the same order (no multiply-add is fused without
``fastmath``; numpy's vector tanh, which differs from libm's in the last bit, is computed by numpy
and passed in), so every value is the same bit for bit: the crack cascades follow the last digits
(``pytest tests/test_joints.py -k "compiled or bincount or corner_blocks_change_no_bit"``).
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["contact_forces", "corner_blocks", "summed_blocks"]


@njit(cache=True, nogil=True)
def corner_blocks(Lc: np.ndarray, TL: np.ndarray, row: np.ndarray, col: np.ndarray) -> np.ndarray:
    """``(C, P)``: ``Lc[c, 0, row] TL[c, 0, col] + Lc[c, 2, row] TL[c, 2, col] + Lc[c, 1, row] TL[c, 1, col]``
    for ``Lc``, ``TL`` ``(C, 3, 12)`` and the ``P`` entries ``(row, col)``, summed in that order."""
    C = Lc.shape[0]
    P = row.shape[0]
    out = np.empty((C, P))
    for c in range(C):
        for p in range(P):
            r = row[p]
            q = col[p]
            v = Lc[c, 0, r] * TL[c, 0, q]
            v = v + Lc[c, 2, r] * TL[c, 2, q]
            out[c, p] = v + Lc[c, 1, r] * TL[c, 1, q]
    return out


@njit(cache=True, nogil=True)
def _logaddexp0(x: float) -> float:
    """numpy's ``logaddexp(0, x)``, its branches and libm calls (numpy 1.26's ``npy_logaddexp``)."""
    if x == 0.0:
        return 0.6931471805599453  # 0 + ln 2
    tmp = 0.0 - x
    if tmp > 0:
        return 0.0 + np.log1p(np.exp(-tmp))
    if tmp <= 0:
        return x + np.log1p(np.exp(tmp))
    return tmp


@njit(cache=True, nogil=True)
def _smooth_cap(x: float, h: float) -> tuple[float, float]:
    """``f(x)`` and ``f'(x)`` of the contacts' smoothed limit: ``x`` up to ``1 - h``, ``1`` from
    ``1 + h`` and a parabola between (a continuous slope, for Newton's method): Coulomb's friction
    and the masonry's crushing (perfectly plastic, no memory: a monotonic load's toe; under
    reversals the crushed corner recovers, which a laboratory's cyclic test does not) both bound a
    corner's force by it."""
    lo = 1.0 - h
    xc = min(max(x, lo), 1.0 + h)
    if x <= lo:
        return x, 1.0
    w = xc - lo
    return xc - w * w / (4.0 * h), 1.0 - w / (2.0 * h)


@njit(cache=True, nogil=True)
def contact_forces(
    k: np.ndarray,
    slip: np.ndarray,
    gap: np.ndarray,
    tanh_half_x: np.ndarray,
    mu: float,
    d: float,
    h: float,
    cap: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """:meth:`~calib_masonry.simulation.joints.JointModel._contact_forces`' law, corner by corner:
    the forces ``(C, 3)`` and tangents ``(C, 3, 3)`` of the corners of stiffness ``k`` ``(C, 3)``
    and slip ``slip`` ``(C, 2)`` at their gaps ``gap`` ``(C, 3)``; ``tanh_half_x`` ``(C,)`` is
    numpy's ``tanh(-gap_n / (2 d))`` (numpy's vector tanh differs from libm's in the last bit),
    ``cap`` ``(C,)`` the crushing forces (empty: no crushing)."""
    C = gap.shape[0]
    F = np.empty((C, 3))
    T = np.zeros((C, 3, 3))
    crush = cap.shape[0] > 0
    lo = 1.0 - h
    for c in range(C):
        x = -gap[c, 2] / d
        N = k[c, 2] * d * _logaddexp0(x)
        dN = -k[c, 2] * 0.5 * (1.0 + tanh_half_x[c])
        if crush:
            fc, dfc = _smooth_cap(N / cap[c], h)
            N = cap[c] * fc
            dN = dN * dfc
        t0 = k[c, 0] * (gap[c, 0] - slip[c, 0])
        t1 = k[c, 1] * (gap[c, 1] - slip[c, 1])
        L = mu * N
        a = np.sqrt(t0 * t0 + t1 * t1)
        F[c, 2] = -N
        T[c, 2, 2] = -dN
        if not (a > 0.0 or L > 0.0):  # open and unloaded: no force, no stiffness
            F[c, 0] = 0.0 * t0
            F[c, 1] = 0.0 * t1
            continue
        xr = a / L if L > 0.0 else np.inf
        f, df = _smooth_cap(xr, h)
        ratio = 1.0 if xr <= lo else L * f / (a if a > 0.0 else 1.0)
        e0 = t0 / a if a > 0.0 else 0.0
        e1 = t1 / a if a > 0.0 else 0.0
        F[c, 0] = ratio * t0
        F[c, 1] = ratio * t1
        e = (e0, e1)
        for i in range(2):
            for j in range(2):
                ee = e[i] * e[j]
                delta = 1.0 if i == j else 0.0
                T[c, i, j] = (ratio * (delta - ee) + df * ee) * k[c, j]
        dl = f - (xr if df > 0.0 else 0.0) * df
        g = dl * mu * dN
        T[c, 0, 2] = e0 * g
        T[c, 1, 2] = e1 * g
    return F, T


@njit(cache=True, nogil=True)
def summed_blocks(slot: np.ndarray, joints: np.ndarray, blocks: np.ndarray, nnz: int) -> np.ndarray:
    """``(nnz,)``: ``np.bincount(slot[joints].ravel(), weights=blocks.ravel(), minlength=nnz)``, each
    block's entries added in the order bincount adds them (so the same bits), without the gathered
    ``(M, P)`` copy of ``slot``."""
    out = np.zeros(nnz)
    P = blocks.shape[1]
    for m in range(joints.shape[0]):
        row = slot[joints[m]]
        for p in range(P):
            out[row[p]] += blocks[m, p]
    return out

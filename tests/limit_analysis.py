"""Rigid-block limit analysis of a scene's bodies on its joints: a static (lower-bound) linear
programme solved with HiGHS, written here, apart from the joint model it checks.

Every joint (bond) is a dry interface: at each corner of its outline a normal force n >= 0 (no
tension) and a friction force in the joint's plane inside the pyramid |t_u| + |t_v| <= mu n (the
inscribed square of Coulomb's cone: the friction is associative here, and the square is the cone's
safe side, at most sqrt(2) weaker along a diagonal; the in-plane problems below slide along u or v).
A foundation joint (b = -1) bears on the fixed ground. Each body is in equilibrium (forces and
moments about its centroid) under its weight and ``lam`` times its weight along ``direction``;
the programme finds the largest ``lam`` (or whether ``lam = 0``, gravity alone, is possible).
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import linprog
from scipy.sparse import coo_matrix

from calib_masonry.simulation.ground_motion import G
from calib_masonry.simulation.scene import Scene, joint_axes


def _corners(scene: Scene):
    """Every joint corner: (bond index, point (3,), n, u, v) with the frame of each bond."""
    bonds = scene.bonds
    u, v, n = joint_axes(np.array([b.normal for b in bonds]))
    rows = []
    for k, b in enumerate(bonds):
        pts = np.unique(np.round(np.asarray(b.outline), 12), axis=0)
        for cu, cv in pts:
            rows.append((k, b.location + cu * u[k] + cv * v[k], n[k], u[k], v[k]))
    return rows


def limit_load(scene: Scene, mu: float, direction=(1.0, 0.0, 0.0), *, gravity_only: bool = False) -> float | None:
    """The largest lateral load factor (in g) the scene's bodies carry on their joints as dry
    interfaces of friction ``mu``; with ``gravity_only``, 0.0 if they stand under their weight alone
    and None if they cannot."""
    bodies, bonds = scene.bodies, scene.bonds
    corners = _corners(scene)
    nc = len(corners)
    # variables: per corner n, t_u, t_v; then lam
    nv = 3 * nc + 1
    rows, cols, vals = [], [], []
    for c, (k, p, n, u, v) in enumerate(corners):
        a, b = bonds[k].a, bonds[k].b
        for body, sign in ((a, -1.0), (b, 1.0)):  # the force on b is +(n N + u Tu + v Tv); on a the opposite
            if body < 0:
                continue
            r = p - bodies[body].location
            for j, axis in enumerate((n, u, v)):
                f = sign * axis
                m = np.cross(r, f)
                for e in range(3):
                    rows += [6 * body + e, 6 * body + 3 + e]
                    cols += [3 * c + j, 3 * c + j]
                    vals += [f[e], m[e]]
    nb = len(bodies)
    W = np.array([b.mass * G for b in bodies])
    d = np.asarray(direction, dtype=np.float64)
    d = d / np.linalg.norm(d)
    b_eq = np.zeros(6 * nb)
    b_eq[2::6] = W  # the joints hold each weight up: sum of forces + (0, 0, -W) = 0
    if not gravity_only:
        for e in range(3):  # and lam W along d: sum of forces + lam W d = 0
            rows += list(range(e, 6 * nb, 6))
            cols += [nv - 1] * nb
            vals += list(W * d[e])
    A_eq = coo_matrix((vals, (rows, cols)), shape=(6 * nb, nv)).tocsr()
    # friction pyramid: +-t_u +-t_v - mu n <= 0
    ur, uc, uv = [], [], []
    for c in range(nc):
        for q, (su, sv) in enumerate(((1, 1), (1, -1), (-1, 1), (-1, -1))):
            row = 4 * c + q
            ur += [row, row, row]
            uc += [3 * c, 3 * c + 1, 3 * c + 2]
            uv += [-mu, su, sv]
    A_ub = coo_matrix((uv, (ur, uc)), shape=(4 * nc, nv)).tocsr()
    cost = np.zeros(nv)
    cost[-1] = -1.0
    bounds = [(0, None), (None, None), (None, None)] * nc + [(0, 0) if gravity_only else (0, None)]
    res = linprog(cost, A_ub=A_ub, b_ub=np.zeros(4 * nc), A_eq=A_eq, b_eq=b_eq, bounds=bounds, method="highs")
    if res.status == 2:  # infeasible
        return None
    assert res.success, res.message
    return float(res.x[-1])

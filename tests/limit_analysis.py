"""Rigid-block limit analysis of a scene's bodies on its joints: a static linear programme solved
with HiGHS, written here, apart from the joint model it checks.

Every joint (bond) is a dry interface: at each corner of its outline a normal force n >= 0 (no
tension) and a friction force in the joint's plane inside the pyramid |t_u| + |t_v| <= mu n (the
inscribed square of Coulomb's cone, its safe side, at most sqrt(2) weaker along a diagonal; the
in-plane problems below slide along u or v). A foundation joint (b = -1) bears on the fixed ground.
Each body is in equilibrium (forces and moments about its centroid) under its weight and ``lam``
times its weight along ``direction``; the programme finds the largest ``lam`` (or whether
``lam = 0``, gravity alone, is possible).

Two flow rules:

- **associative** (the default): the programme above. Its dual mechanism slides with dilatancy (a
  joint that slides opens by tan(phi) of its slip), which a rigid-block assembly does not do: the
  load it finds bounds Coulomb's (non-associative) collapse load from above.
- **non-associative** (``associative=False``), after Gilbert, Casapulla & Ahmed (2006, "Limit
  analysis of masonry block structures with non-associative frictional joints using linear
  programming", Computers & Structures 84, 873-887): each corner's friction is replaced by a fixed
  shear capacity ``mu n`` taken from the previous solution, so the joint slides without opening
  (zero dilatancy, as the joint model's contacts and Bullet's do), and the programme is solved
  again with the capacities relaxed towards ``mu n`` of each new solution until the load factor
  settles. Its result is a load at which a non-associative mechanism exists with every corner
  inside Coulomb's cone, not a bound (two 0.2 x 1 m blocks side by side at mu 5: 0.40 g, the pair
  tipping as one, where each can tip about its own toe at b/h = 0.2, sliding along the head joint
  without opening, which builds no normal force there: experiments/joint_statics.py); where the
  bodies' forces are statically indeterminate it
  can lie far below the associative load (a stone that can slide out only by dilating: on the
  SWAT wall pushed along -X, 0.054 g against 0.29 g). The programme is solved by HiGHS's interior
  point method without crossover, whose solution lies inside the optimal face (the normal forces
  spread over the corners that can carry them), not on a vertex (a few corners carrying all,
  the rest losing their capacity at the next step).
"""

from __future__ import annotations

import warnings

import numpy as np
from scipy.optimize import OptimizeWarning, linprog
from scipy.sparse import coo_matrix

from calib_masonry.simulation.ground_motion import G
from calib_masonry.simulation.scene import Scene, joint_axes

RELAX = 0.5  # the capacities move half way to mu n of each new solution
SETTLED = 1e-4  # relative change of the load factor ...
WINDOW = 100  # ... over this many steps that ends the non-associative iteration
MAX_STEPS = 1000


def _corners(scene: Scene):
    """Every joint corner: (bond index, point (3,), n, u, v) with the frame of each bond."""
    bonds = scene.bonds
    u, v, n = joint_axes(np.array([b.normal for b in bonds]).reshape(-1, 3))  # (0, 3) for a body alone
    rows = []
    for k, b in enumerate(bonds):
        pts = np.unique(np.round(np.asarray(b.outline), 12), axis=0)
        for cu, cv in pts:
            rows.append((k, b.location + cu * u[k] + cv * v[k], n[k], u[k], v[k]))
    return rows


def _equilibrium(scene: Scene, corners, direction, gravity_only: bool):
    """A_eq, b_eq of every body's six equations; the variables: per corner n, t_u, t_v; then lam."""
    bodies, bonds = scene.bodies, scene.bonds
    nv = 3 * len(corners) + 1
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
    return coo_matrix((vals, (rows, cols)), shape=(6 * nb, nv)).tocsr(), b_eq


def _friction(nc: int, mu: float | None):
    """A_ub of the friction pyramids, four rows a corner: +-t_u +-t_v - mu n <= 0 (b_ub zero), or with
    ``mu`` None +-t_u +-t_v <= b_ub (a fixed capacity per corner, repeated four times)."""
    ur, uc, uv = [], [], []
    for c in range(nc):
        for q, (su, sv) in enumerate(((1, 1), (1, -1), (-1, 1), (-1, -1))):
            row = 4 * c + q
            if mu is not None:
                ur += [row, row, row]
                uc += [3 * c, 3 * c + 1, 3 * c + 2]
                uv += [-mu, su, sv]
            else:
                ur += [row, row]
                uc += [3 * c + 1, 3 * c + 2]
                uv += [su, sv]
    return coo_matrix((uv, (ur, uc)), shape=(4 * nc, 3 * nc + 1)).tocsr()


def _solve(A_eq, b_eq, A_ub, b_ub, nc: int, gravity_only: bool, *, central: bool = False):
    """The solution vector, or None if no equilibrium exists."""
    cost = np.zeros(3 * nc + 1)
    cost[-1] = -1.0
    bounds = [(0, None), (None, None), (None, None)] * nc + [(0, 0) if gravity_only else (0, None)]
    # the interior point method without crossover may stop short of its tolerances on an ill-scaled
    # programme (HiGHS's model status "unknown"): then the same method with crossover, a vertex
    for options in [{"run_crossover": "off"}, {"run_crossover": "on"}] if central else [None]:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", OptimizeWarning)  # run_crossover goes to HiGHS verbatim
            res = linprog(
                cost,
                A_ub=A_ub,
                b_ub=b_ub,
                A_eq=A_eq,
                b_eq=b_eq,
                bounds=bounds,
                method="highs-ipm" if central else "highs",
                options=options or {},
            )
        if res.success or res.status == 2:
            break
    if res.status == 2:  # infeasible
        return None
    assert res.success, res.message
    return res.x


def limit_load(
    scene: Scene,
    mu: float,
    direction=(1.0, 0.0, 0.0),
    *,
    gravity_only: bool = False,
    associative: bool = True,
) -> float | None:
    """The largest lateral load factor (in g) the scene's bodies carry on their joints as dry
    interfaces of friction ``mu``; with ``gravity_only``, 0.0 if they stand under their weight alone
    and None if they cannot. ``associative=False``: the non-associative load (module docstring);
    None if the iteration reaches a capacity that cannot carry the weight alone."""
    corners = _corners(scene)
    nc = len(corners)
    A_eq, b_eq = _equilibrium(scene, corners, direction, gravity_only)
    x = _solve(A_eq, b_eq, _friction(nc, mu), np.zeros(4 * nc), nc, gravity_only)
    if x is None or associative:
        return None if x is None else float(x[-1])
    capacity = mu * x[0::3][:nc]
    A_cap = _friction(nc, None)  # the same rows every step: only the capacities change
    history = []
    for _ in range(MAX_STEPS):
        x = _solve(A_eq, b_eq, A_cap, np.repeat(capacity, 4), nc, gravity_only, central=True)
        if x is None:
            return None
        history.append(float(x[-1]))
        capacity = RELAX * mu * x[0::3][:nc] + (1.0 - RELAX) * capacity
        if len(history) > WINDOW and abs(history[-1] - history[-1 - WINDOW]) <= SETTLED * max(history[-1], 1e-9):
            break
    else:
        raise AssertionError(f"the non-associative load did not settle in {MAX_STEPS} steps: {history[-5:]}")
    return history[-1]

"""The intact structure as an elastic body: mass matrix, natural periods, mode shapes and effective
modal masses.

Why this module exists. The joint model (simulation/joints.py) holds the bricks together with the
joints' stiffness and solves their forces quasi-statically. A real tower is not rigid: it has a
natural period (0.1-0.5 s for masonry towers, in the band where earthquakes carry most energy) and
amplifies the ground's motion near it. This module gives the undamped modes of the structure the
joints hold, from the same stiffness (every joint intact, mortar and units in series, see
:func:`calib_masonry.simulation.joints.joint_stiffness`) and the bricks' rigid-body inertia:

    K phi = omega^2 M phi

on the bodies that a chain of joints ties to the ground (a body no joint holds has no elastic
mode), by a sparse shift-invert Lanczos solve (ARPACK through ``scipy.sparse.linalg.eigsh``) about
a small negative shift, so that ``K + M`` is factorised, positive definite even when some body
is free to move; a dense solve for small structures. Each body has six degrees of freedom, the
translation of its centroid and a small rotation about it (global axes), as in the joint model;
its mass block is ``diag(m, m, m)`` and its inertia tensor about the centroid (from its mesh, the
divergence theorem on signed tetrahedra, scaled to the body's mass).

The modes are mass-normalised (``phi^T M phi = 1``). A direction ``d``'s participation is
``L_d = phi^T M r_d`` (``r_d`` the rigid translation of every body along ``d``) and the mode's
effective modal mass along ``d`` is ``L_d^2``; over all modes they sum to the structure's mass.
EN 1998-1:2004, 4.3.3.3.1(3), asks a modal analysis to take the modes whose effective masses sum
to at least 90 % of the mass in each horizontal direction: ``modes(scene, mass_fraction=0.9)``
computes the lowest modes until they do (at most :data:`MAX_MODES`). A thin-walled structure needs
many: the paper example's lowest 6 carry 30 / 35 % of its mass along x / y, its lowest 100 92 %.

Units: metres, kilograms, seconds, radians.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ..errors import InputError
from .scene import Body, Scene, grounded_bodies

__all__ = [
    "Modes",
    "body_inertia",
    "mass_blocks",
    "mass_matrix",
    "newmark_rhs",
    "newmark_next",
    "l_stable_rhs",
    "l_stable_next",
    "L_STABLE_MATRIX",
    "stiffness_matrix",
    "modes",
    "empirical_tower_periods",
    "modes_json",
    "write_modes",
]

#: The most modes one call computes. Shift-invert Lanczos for k modes costs about k^2 times the
#: unknowns: the paper example (9,522 unknowns) takes 7 s for 200 modes and 23 s for 500, which
#: carry 95 % and 98 % of its horizontal mass; a hundred thousand asked for (9,521 once capped at
#: its unknowns) had not ended after two minutes.
MAX_MODES = 500

#: below this many unknowns the eigenproblem is solved densely (ARPACK needs k < n and is slow on tiny ones)
_DENSE = 600


@dataclass(frozen=True)
class Modes:
    """Natural modes of a structure's intact joints (see the module docstring)."""

    periods_s: np.ndarray  # (n,) ascending
    shapes: np.ndarray  # (n, B, 6) mass-normalised, per body of the whole scene (0 on bodies not held)
    participation: np.ndarray  # (n, 3) L_d along x, y, z, kg^0.5
    effective_mass_kg: np.ndarray  # (n, 3) L_d^2
    total_mass_kg: float  # of the bodies the joints tie to the ground
    bodies: np.ndarray  # (B,) bool: the bodies in the eigenproblem
    mass_fraction: float | None = None  # the share of the horizontal mass asked for (modes(mass_fraction=))
    mass_fraction_met: bool | None = None  # whether the modes' effective masses reach it along x and y

    @property
    def frequencies_hz(self) -> np.ndarray:
        return 1.0 / self.periods_s

    @property
    def effective_mass_fraction(self) -> np.ndarray:
        return self.effective_mass_kg / self.total_mass_kg


def _rotation(q) -> np.ndarray:
    w, x, y, z = (float(c) for c in q)
    n = np.sqrt(w * w + x * x + y * y + z * z) or 1.0
    w, x, y, z = w / n, x / n, y / n, z / n
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def body_inertia(body: Body) -> np.ndarray:
    """The body's inertia tensor (3, 3) about its centroid in global axes, kg m^2: its mesh's, by
    signed tetrahedra from the origin (the canonical second moment ``det(A) / 120 A (1 + I) A^T`` of
    each), shifted to the mesh's centroid and scaled to the body's mass."""
    v = np.asarray(body.vertices, dtype=np.float64)
    f = np.asarray(body.faces, dtype=np.int64)
    A = np.stack([v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]], axis=2)  # (F, 3, 3): columns a, b, c
    det = np.linalg.det(A)
    volume = det.sum() / 6.0
    if not abs(volume) > 1e-15:
        raise InputError(f"body {body.name}: its mesh encloses no volume; it has no inertia")
    first = (det[:, None] * A.sum(axis=2)).sum(axis=0) / 24.0
    S = np.ones((3, 3)) + np.eye(3)
    second = np.einsum("f,fij,jk,flk->il", det / 120.0, A, S, A)
    c = first / volume
    second = second - volume * np.outer(c, c)
    I_body = (np.trace(second) * np.eye(3) - second) * (body.mass / volume)
    R = _rotation(body.rotation)
    return R @ I_body @ R.T


def mass_blocks(mass: np.ndarray, inertia: np.ndarray) -> np.ndarray:
    """``(B, 6, 6)``: each body's ``mass`` (B,) on its translations, its ``inertia`` tensor
    ``(B, 3, 3)`` about its centroid on its rotations."""
    mass = np.asarray(mass, dtype=np.float64)
    out = np.zeros((len(mass), 6, 6))
    out[:, 0, 0] = out[:, 1, 1] = out[:, 2, 2] = mass
    out[:, 3:, 3:] = inertia
    return out


def mass_matrix(scene: Scene) -> sp.csr_matrix:
    """Block-diagonal ``(6 B, 6 B)`` of :func:`mass_blocks`."""
    if not scene.bodies:
        return sp.csr_matrix((0, 0))
    blocks = mass_blocks([b.mass for b in scene.bodies], np.array([body_inertia(b) for b in scene.bodies]))
    return sp.block_diag(list(blocks), format="csr")


def stiffness_matrix(scene: Scene, intact: np.ndarray | None = None, model=None) -> sp.csr_matrix:
    """The stiffness ``(6 B, 6 B)`` of the scene's joints (default every one intact), without the
    joint model's weak springs that hold free bodies (``model``: the scene's JointModel, if made)."""
    from .joints import JointModel

    return (model if model is not None else JointModel(scene)).stiffness_matrix(intact)


def modes(
    scene: Scene,
    n: int = 6,
    *,
    mass_fraction: float | None = None,
    model=None,
    mass: sp.spmatrix | None = None,
    progress: bool | None = False,
) -> Modes:
    """The ``n`` lowest natural modes of the scene's intact structure (see the module docstring);
    with ``mass_fraction`` (0-1), at least ``n`` and as many more as the lowest modes need for their
    effective masses to sum to that fraction of the mass along x and along y (EN 1998-1, 4.3.3.3.1:
    0.9), or :data:`MAX_MODES` (:attr:`Modes.mass_fraction_met` says whether they did). ``model``
    and ``mass``: the scene's JointModel and mass matrix, if made; ``progress``: the Lanczos steps
    shown (a large structure's hundred modes take minutes)."""
    if n < 1:
        raise InputError(f"modes: n = {n}: ask for at least one mode")
    if n > MAX_MODES:
        raise InputError(
            f"modes: n = {n}: at most {MAX_MODES} modes a call (the cost grows with their square); for the modes "
            "that carry a share of the mass, ask for the share (--mass-fraction 0.9, EN 1998-1 4.3.3.3.1)"
        )
    if mass_fraction is not None and not 0.0 < mass_fraction < 1.0:
        raise InputError(
            f"modes: mass fraction {mass_fraction:g}: must lie between 0 and 1 (EN 1998-1 4.3.3.3.1 asks for 0.9)"
        )
    held = grounded_bodies(scene.bonds, len(scene.bodies))
    if not held.any():
        raise InputError(
            "modes: no body is joined to the ground (a structure without a foundation, or without joints) "
            "has no elastic modes; build it with its footing"
        )
    K = stiffness_matrix(scene, model=model)
    M = sp.csr_matrix(mass) if mass is not None else mass_matrix(scene)
    dof = np.flatnonzero(np.repeat(held, 6))
    K, M = K[dof][:, dof], M[dof][:, dof]
    size = len(dof)
    most = size if size <= _DENSE else size - 1
    n = asked = min(n, most)
    r = np.zeros((size, 3))
    for d in range(3):
        r[d::6, d] = 1.0
    total = float(sum(b.mass for b, h in zip(scene.bodies, held) if h))
    met = None
    while True:
        w, V = _lowest_modes(K, M, n, progress=progress)
        if mass_fraction is None:
            break
        # the horizontal effective masses' running sums: the fewest modes (at least the n asked
        # for) whose sums reach the fraction along x and along y
        L = V.T @ (M @ r)
        need = np.cumsum(L[:, :2] ** 2, axis=0).min(axis=1) / total >= mass_fraction - 1e-12
        met = bool(need[-1])
        cap = min(MAX_MODES, most)
        if met or n >= cap:
            if met:
                n = max(int(np.argmax(need)) + 1, asked)
                w, V = w[:n], V[:, :n]
            break
        n = min(2 * n, cap)
    # mass-normalise (eigh and eigsh do, up to rounding) and fix each shape's sign: the largest
    # translation positive
    V = V / np.sqrt(np.einsum("ik,ik->k", V, M @ V))
    trans = V.reshape(-1, 6, n)[:, :3]
    flat = trans.reshape(-1, n)
    sign = np.sign(flat[np.abs(flat).argmax(axis=0), np.arange(n)])
    V = V * np.where(sign == 0, 1.0, sign)
    omega = np.sqrt(np.maximum(w, 0.0))
    periods = np.where(omega > 0, 2 * np.pi / np.where(omega > 0, omega, 1.0), np.inf)
    L = V.T @ (M @ r)  # (n, 3)
    shapes = np.zeros((n, len(scene.bodies), 6))
    shapes[:, held] = V.T.reshape(n, -1, 6)
    return Modes(
        periods_s=periods,
        shapes=shapes,
        participation=L,
        effective_mass_kg=L**2,
        total_mass_kg=total,
        bodies=held,
        mass_fraction=mass_fraction,
        mass_fraction_met=met,
    )


def _lowest_modes(
    K: sp.spmatrix, M: sp.spmatrix, n: int, *, progress: bool | None = False
) -> tuple[np.ndarray, np.ndarray]:
    """The ``n`` lowest eigenvalues (ascending) and vectors of ``K phi = w M phi``; ``progress``:
    ARPACK's steps (each a solve with ``K - sigma M``) counted on a bar or in log lines."""
    from ..progress import progress as _progress

    size = K.shape[0]
    if size <= _DENSE:
        return sla.eigh(K.toarray(), M.toarray(), subset_by_index=[0, n - 1])
    # a fixed start vector: without one scipy (1.17) draws it from fresh entropy, and the modes,
    # the Rayleigh damping made from them and so every crack check of a quake differed in the
    # last digits from run to run; the shift lies below the lowest eigenvalue, so that K - sigma M
    # is positive definite
    v0 = np.random.default_rng(0).uniform(-1.0, 1.0, size)
    sigma = -1.0
    A, B = K.tocsc(), M.tocsc()
    # (K - sigma M)^-1 as eigsh makes it (scipy's SpLuInv: SuperLU of the same matrix, the same
    # options), so that the modes are the same to the last digit; counted here
    lu = spla.splu((A - sigma * B).tocsc())
    bar = _progress(desc=f"modes (the lowest {n})", unit="step", enabled=progress)

    def solve(x: np.ndarray) -> np.ndarray:
        bar.update()
        return lu.solve(np.asarray(x, dtype=np.float64))

    op = spla.LinearOperator((size, size), matvec=solve, dtype=np.float64)
    try:
        w, V = spla.eigsh(A, k=n, M=B, sigma=sigma, which="LM", v0=v0, OPinv=op)
    finally:
        bar.close()
    order = np.argsort(w)
    return w[order], V[:, order]


def empirical_tower_periods(height_m: float) -> dict[str, dict]:
    """The first period of a masonry tower of this height by two empirical formulas, for comparison:

    * EN 1998-1:2004 (Eurocode 8), 4.3.3.2.2, eq. (4.6): ``T1 = C_t H^(3/4)``, ``C_t = 0.05`` for
      structures other than frames (masonry), meant for buildings up to 40 m;
    * the Italian guidelines for the cultural heritage (DPCM 9 February 2011, for masonry towers):
      ``T1 = 0.0187 H^1.17``.
    """
    h = float(height_m)
    return {
        "eurocode_8": {"period_s": 0.05 * h**0.75, "formula": "0.05 H^0.75", "source": "EN 1998-1:2004, eq. (4.6)"},
        "italian_guidelines": {
            "period_s": 0.0187 * h**1.17,
            "formula": "0.0187 H^1.17",
            "source": "Linee Guida per il patrimonio culturale, DPCM 9/2/2011 (masonry towers)",
        },
    }


def modes_json(m: Modes, scene: Scene) -> dict:
    """The modes as a JSON-able dict (modes.json)."""
    bottom = min(float(np.min(np.asarray(b.vertices)[:, 2]) + b.location[2]) for b in scene.bodies)
    top = max(float(np.max(np.asarray(b.vertices)[:, 2]) + b.location[2]) for b in scene.bodies)
    height = top - bottom
    rows = []
    for k in range(len(m.periods_s)):
        frac = m.effective_mass_fraction[k]
        rows.append(
            {
                "mode": k + 1,
                "period_s": float(m.periods_s[k]),
                "frequency_hz": float(m.frequencies_hz[k]),
                "effective_mass_fraction": {"x": float(frac[0]), "y": float(frac[1]), "z": float(frac[2])},
                "participation_kg05": {
                    "x": float(m.participation[k, 0]),
                    "y": float(m.participation[k, 1]),
                    "z": float(m.participation[k, 2]),
                },
            }
        )
    return {
        "modes": rows,
        "total_mass_kg": m.total_mass_kg,
        "bodies_in_modes": int(m.bodies.sum()),
        "bodies": len(scene.bodies),
        "height_m": height,
        "cumulative_effective_mass_fraction": {
            d: float(m.effective_mass_fraction[:, i].sum()) for i, d in enumerate("xyz")
        },
        # per horizontal direction, the mode of the largest effective mass among those computed: the
        # fundamental mode an empirical period (below) describes; the lowest mode can be a wall
        # panel's own, carrying almost no mass (the scale tower's, 0.24 s, against 0.198 s for its sway)
        "fundamental_mode": {
            d: {
                "mode": int(np.argmax(m.effective_mass_fraction[:, i])) + 1,
                "period_s": float(m.periods_s[np.argmax(m.effective_mass_fraction[:, i])]),
                "effective_mass_fraction": float(m.effective_mass_fraction[:, i].max()),
            }
            for i, d in enumerate("xy")
        },
        # the share of the horizontal mass asked for (modes --mass-fraction) and whether the modes reach it
        "mass_fraction_asked": m.mass_fraction,
        "mass_fraction_met": m.mass_fraction_met,
        "empirical_first_period_of_masonry_towers": empirical_tower_periods(height),
        "material": {
            "unit_youngs_modulus_pa": scene.material.unit_youngs_modulus,
            "mortar_youngs_modulus_pa": scene.material.mortar_youngs_modulus,
            "joint_thickness_m": scene.material.joint_thickness_m,
            "masonry_youngs_modulus_pa": scene.material.masonry_youngs_modulus,
            "density_kg_m3": scene.material.density,
        },
        "method": "undamped modes of the intact joints (mortar and units in series, or the masonry's modulus "
        "where given) and the bricks' rigid-body "
        "inertia, sparse shift-invert Lanczos (calib_masonry.simulation.dynamics)",
    }


def write_modes(m: Modes, scene: Scene, out: Path, figure: bool = True) -> dict:
    """modes.json and modes.png (each mode's deformed shape) into the folder ``out``."""
    from ..io import write_json

    doc = modes_json(m, scene)
    write_json(Path(out) / "modes.json", doc)
    if figure:
        _modes_figure(m, scene, Path(out) / "modes.png")
    return doc


#: modes.png draws the lowest this many modes (modes.json lists them all)
FIGURE_MODES = 12


def _modes_figure(m: Modes, scene: Scene, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    x = np.array([b.location for b in scene.bodies], dtype=np.float64).reshape(-1, 3)
    held = m.bodies
    span = float(np.ptp(x[held], axis=0).max()) if held.any() else 1.0
    n = min(len(m.periods_s), FIGURE_MODES)
    cols = min(n, 3)
    rows = -(-n // cols)
    fig = plt.figure(figsize=(4.2 * cols, 4.4 * rows))
    for k in range(n):
        ax = fig.add_subplot(rows, cols, k + 1, projection="3d")
        u = m.shapes[k, :, :3]
        mag = np.linalg.norm(u, axis=1)
        scale = 0.1 * span / max(float(mag.max()), 1e-30)
        p = x + scale * u
        ax.scatter(*x[held].T, s=2, c="0.8", depthshade=False)
        sc = ax.scatter(
            *p[held].T,
            s=4,
            c=mag[held] / max(float(mag.max()), 1e-30),
            cmap="viridis",
            vmin=0,
            vmax=1,
            depthshade=False,
        )
        frac = m.effective_mass_fraction[k]
        ax.set_title(
            f"mode {k + 1}: T = {m.periods_s[k]:.3f} s\nmass x {frac[0]:.0%}, y {frac[1]:.0%}, z {frac[2]:.0%}",
            fontsize=9,
        )
        ax.set_box_aspect(np.maximum(np.ptp(np.vstack([x[held], p[held]]), axis=0), 1e-3))
        ax.set_xticks([])
        ax.set_yticks([])
        ax.set_zlabel("z (m)", fontsize=7)
        ax.tick_params(labelsize=6)
    fig.colorbar(sc, ax=fig.axes, shrink=0.5, label="displacement / largest (shapes scaled to 10 % of the span)")
    if n < len(m.periods_s):
        fig.suptitle(f"the lowest {n} of {len(m.periods_s)} modes (all of them in modes.json)", fontsize=10)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def rayleigh(ratio: float, omega_1: float, omega_2: float) -> tuple[float, float]:
    """Rayleigh damping ``C = alpha M + beta K`` with the damping ``ratio`` at the circular
    frequencies ``omega_1`` and ``omega_2`` (rad/s); equal frequencies give the tangent at that one."""
    w1, w2 = float(omega_1), float(omega_2)
    return 2.0 * ratio * w1 * w2 / (w1 + w2), 2.0 * ratio / (w1 + w2)


def newmark_rhs(f, mass, stiffness, u, v, a, dt: float, alpha: float, beta: float) -> np.ndarray:
    """The right-hand side of a step of Newmark's average acceleration (gamma 1/2, beta 1/4) with
    Rayleigh damping ``C = alpha M + beta K``, from the state ``u, v, a`` under the load ``f`` at
    the step's end: ``f + M (4 u / dt^2 + 4 v / dt + a) + C (2 u / dt + v)``; ``mass`` and
    ``stiffness`` multiply by ``M`` and ``K``. Its matrix is ``K + 4 M / dt^2 + 2 C / dt``."""
    cu = (2.0 / dt) * u + v
    return f + mass((4.0 / dt**2) * u + (4.0 / dt) * v + a) + alpha * mass(cu) + beta * stiffness(cu)


def newmark_next(u, u1, v, a, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """The velocity and acceleration at the end of that step, which moved ``u`` to ``u1``."""
    a1 = (4.0 / dt**2) * (u1 - u) - (4.0 / dt) * v - a
    return v + 0.5 * dt * (a + a1), a1


#: the step matrix of :func:`l_stable_rhs`, ``K + 2 M / dt^2 + 3 C / (2 dt)``: the multiples of ``M``
#: and of ``C`` (times ``1 / dt^2`` and ``1 / dt``)
L_STABLE_MATRIX = (2.0, 1.5)


def l_stable_rhs(f, mass, stiffness, u, v, a, dt: float, alpha: float, beta: float) -> np.ndarray:
    """The right-hand side of a step of the generalised-alpha rule (Chung & Hulbert 1993) with a
    spectral radius of 0 at infinity (alpha_m = -1, alpha_f = 0, gamma = 3/2, beta = 1): second order
    like Newmark's average acceleration, but L-stable, so that a mode far shorter than the step,
    or overdamped with a time constant shorter than it, settles at once instead of ringing.
    ``M (2 a' - a) + C v' + K u' = f`` at the step's end; Rayleigh damping ``C = alpha M + beta K``.
    Its matrix is ``K + 2 M / dt^2 + 3 C / (2 dt)`` (:data:`L_STABLE_MATRIX`).

    Why: Rayleigh damping set at a structure's first two modes is many times critical at a joint's
    own frequency, where average acceleration's amplification tends to -1: a step load on a
    piece's joint overshot its static force by 13 % at checks of 5 ms and 10 % at 2.5 ms (a 0.6 ms
    joint at a tower's damping, 3.9 times critical), this rule's by 1.7 and 2.2 %
    (docs/dynamics.md)."""
    A, B = _l_stable_terms(u, v, a, dt)
    return f + mass(2.0 * A + a) - alpha * mass(B) - beta * stiffness(B)


def l_stable_next(u, u1, v, a, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """The velocity and acceleration at the end of the :func:`l_stable_rhs` step that moved ``u`` to ``u1``."""
    A, B = _l_stable_terms(u, v, a, dt)
    return B + 1.5 * u1 / dt, u1 / dt**2 - A


def _l_stable_terms(u, v, a, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """The step's start-state terms of :func:`l_stable_rhs`: its end acceleration is ``u' / dt^2 - A``
    and its end velocity ``B + 3 u' / (2 dt)`` (Newmark's update with gamma 3/2, beta 1)."""
    A = u / dt**2 + v / dt - 0.5 * a
    return A, v - 0.5 * dt * a - 1.5 * dt * A


def record_load(motion, t: float, g: np.ndarray) -> np.ndarray:
    """The load per unit mass ``t`` seconds after the ground began to move: ``g``'s vertical with
    the ground ``motion``'s acceleration then, reversed (``g`` itself without a motion)."""
    g = np.asarray(g, dtype=np.float64)
    if motion is None:
        return g
    out = g.copy()
    out[:2] = -np.array([np.interp(t, motion.time, motion.acceleration[:, k], left=0.0, right=0.0) for k in range(2)])
    return out


class ElasticResponse:
    """The linear elastic vibration of the part of a structure that intact joints tie to the ground,
    relative to the ground, under the load ``m g(t)`` on every body (``g`` the gravity and the
    ground's inertial acceleration, the joint model's load):

        M u'' + C u' + K u = f(t),     C = alpha M + beta K  (Rayleigh)

    integrated by Newmark's average-acceleration rule (gamma 1/2, beta 1/4: unconditionally stable,
    no numerical damping) with the load linear in time between two calls and substeps no longer
    than ``T1 / substeps_per_period`` of the first period, so that the frame rate does not set the
    accuracy (the period elongation of the rule is about (2 pi dt / T)^2 / 12: 0.2 % at 40 substeps a
    period). ``u`` starts at the static equilibrium of the first load (gravity), at rest.

    ``K`` is the stiffness of the undamaged structure (every joint intact: the joint model's,
    mortar and units in series) and stays so after joints crack: the cracked joints that still
    bear keep most of a joint's stiffness in compression, and the vibration of the structure that
    stands goes on at its undamaged period (the lengthening of the period by cracking is not
    modelled). Vibrating on the intact joints alone instead left the upper part of a tower whose
    base joints had cracked in tension on a few intact patches, nearly a mechanism in the linear
    model, and its drift grew without bound (Stylite, 0.3 g: 8 m in 9 s). The joint model, which
    carries the cracked joints as contacts, takes the vibration's forces as part of each body's
    load; a piece Bullet has set free takes none (the caller masks it). :meth:`inertial_force` is
    ``-M u'' - C u'``, the
    force the vibration adds to each body's load in the joint model's equilibrium."""

    def __init__(
        self,
        model,
        mass: sp.spmatrix,
        *,
        ratio: float = 0.05,
        omega: tuple[float, float],
        substeps_per_period: int = 40,
        motion=None,
        ground_start_s: float = 0.0,
    ) -> None:
        if not 0.0 <= ratio < 1.0:
            raise InputError(f"damping ratio {ratio}: give a fraction of critical damping in [0, 1), e.g. 0.05")
        self.model = model
        # the ground motion itself, sampled at every step (the load between calls is then the
        # record's, not a line between the calls' loads: independent of how often one calls)
        self.motion = motion
        self.ground_start_s = float(ground_start_s)
        self.M = sp.csr_matrix(mass)
        self.ratio = float(ratio)
        self.alpha, self.beta = rayleigh(ratio, *omega)
        self.dt_max = 2.0 * np.pi / float(omega[0]) / substeps_per_period
        # ``until`` is asked every this many steps: 20 times a first period (a peak seen within
        # cos(pi / 20) = 0.988 of itself)
        self.check_every = max(1, substeps_per_period // 20)
        n = 6 * model.nb
        self.u = np.zeros(n)
        self.v = np.zeros(n)
        self.a = np.zeros(n)
        self._g = None
        self._t = None
        self._lu = None
        self._dt = None
        # the undamaged structure: every joint intact, the bodies they tie to the ground
        self.bodies = model.grounded(np.ones(model.nj, dtype=bool))
        self.dof = np.flatnonzero(np.repeat(self.bodies, 6))
        self.K = model.stiffness_matrix()[self.dof][:, self.dof].tocsc()
        self.Md = self.M[self.dof][:, self.dof].tocsc()

    def _factor(self, dt: float):
        if self._lu is None or abs(self._dt - dt) > 1e-9 * dt:  # frame times differ by rounding
            C = self.alpha * self.Md + self.beta * self.K
            self._lu = _cholesky(self.K + (4.0 / dt**2) * self.Md + (2.0 / dt) * C)
            self._dt = dt
        return self._lu

    def _force(self, g: np.ndarray) -> np.ndarray:
        return self.model._load(g)[self.dof]

    def load_at(self, time_s: float, g: np.ndarray) -> np.ndarray:
        """The load per unit mass at ``time_s``: ``g``'s vertical with the record's ground
        acceleration at that time (``g`` itself without a record)."""
        return record_load(self.motion, float(time_s) - self.ground_start_s, g)

    def advance(self, time_s: float, g: np.ndarray, *, until=None) -> float:
        """Integrate from the last call to ``time_s``: under the record's ground acceleration at
        every step if there is one (``g`` then gives the vertical), else under the load linear in
        time from the last call's ``g`` to this one's; the first call sets the static equilibrium
        under ``g``. ``until(u)``, if given, is asked after every ``check_every``-th step and stops
        the integration there when True. Returns the time reached."""
        g = np.asarray(g, dtype=np.float64)
        if self._g is None or not len(self.dof):
            if len(self.dof):
                self.u[self.dof] = spla.spsolve(self.K, self._force(self.load_at(time_s, g)))
            self._g, self._t = g, float(time_s)
            return self._t
        span = float(time_s) - self._t
        if span <= 0:
            self._g = g
            return self._t
        steps = max(1, int(np.ceil(span / self.dt_max - 1e-9)))
        dt = span / steps
        lu = self._factor(dt)
        d = self.dof
        u, v, a = self.u[d], self.v[d], self.a[d]
        M, K = self.Md, self.K
        t_start, g_start = self._t, self._g
        reached = float(time_s)
        for k in range(1, steps + 1):
            tk = t_start + span * (k / steps)
            gk = self.load_at(tk, g) if self.motion is not None else g_start + (g - g_start) * (k / steps)
            f = self._force(gk)
            rhs = newmark_rhs(f, M.__matmul__, K.__matmul__, u, v, a, dt, self.alpha, self.beta)
            u1 = lu(rhs)
            v, a = newmark_next(u, u1, v, a, dt)
            u = u1
            if until is not None and k < steps and k % self.check_every == 0:
                self.u[d] = u
                if until(self.u):
                    reached = tk
                    break
        self.u[d], self.v[d], self.a[d] = u, v, a
        self._g, self._t = (self.load_at(reached, g) if reached < time_s else g), reached
        return reached

    def inertial_force(self) -> np.ndarray:
        """``-M u'' - C u'`` on every body (6 B,): zero on the bodies not in the vibration."""
        out = np.zeros_like(self.u)
        d = self.dof
        v = self.v[d]
        out[d] = -(self.Md @ (self.a[d] + self.alpha * v)) - self.beta * (self.K @ v)
        return out


def _cholesky(A: sp.spmatrix):
    """``b -> A^-1 b`` for a symmetric positive definite ``A``: CHOLMOD's supernodal Cholesky
    (through cvxopt, as the joint model's contact iteration), whose solves on the paper example's
    9,522 unknowns take a third of SuperLU's."""
    from cvxopt import cholmod, matrix, spmatrix

    low = sp.tril(A, format="coo")
    Ac = spmatrix(
        matrix(low.data.astype(np.float64)), matrix(low.row.astype(np.int64)), matrix(low.col.astype(np.int64)), A.shape
    )
    factor = cholmod.symbolic(Ac)
    cholmod.numeric(Ac, factor)

    def solve(b: np.ndarray) -> np.ndarray:
        x = matrix(np.ascontiguousarray(b, dtype=np.float64))
        cholmod.solve(factor, x)
        return np.array(x).ravel()

    return solve

"""Mortar joints as elastic interfaces: converged joint forces and the criterion that cracks them.

Why this module exists. Bullet holds an intact joint's two bricks together with a rigid constraint.
Rigid constraints in a statically indeterminate structure have no unique forces: how the iterative
solver splits a load between them, and so which joint would break at an impulse threshold, changes
with the iteration count and the substep (the Stylite tower stood at 50 iterations and fell at 150
under its own weight). Springs inside Bullet are no way out: Bullet clamps a spring's stiffness to
about ``m / (16 dt^2)`` (a 23 kg brick at a 4 ms step: 90 kN/m, so a mortar joint would open by
centimetres before it carried its tensile strength).

So the two jobs are split. Bullet keeps every intact joint rigid and unbreakable and does what it
is good at: rigid-body motion, contacts, friction, impacts once joints have cracked. (The part of
the structure that the joints Bullet holds tie to the plate is kinematic in Bullet, exactly
still, until the joints let go set a piece of it free: simulation/blender.py.) Whether a joint
cracks is decided here, from the joint forces of an elastic model of the same joints, as the
distinct-element codes UDEC and 3DEC model a mortar interface (Lourenco and Rots 1997; Itasca,
3DEC manual, "joint stiffness"): a zero-thickness interface between rigid bricks. The bricks
being rigid, the joint carries the deformability of the units as well as the mortar's, in series
over the length ``l`` of unit across the joint (from the joint's plane to the centroids of its two
bodies, along its normal, less the joint's mortar, which the two bodies filled out to its middle
share; one body for a joint on the ground: :func:`unit_lengths`):

* normal stiffness per unit area ``1 / k_n = t_j / E_m + l / E_u``   [Pa/m = N/m^3]
* shear stiffness per unit area  ``1 / k_s = t_j / G_m + l / G_u``   [Pa/m]

so that a column of courses of units ``h`` high and joints ``t_j`` thick (their pitch ``h + t_j``)
has the modulus ``(h + t_j) / (h / E_u + t_j / E_m)`` of units and mortar in series (the interface formula ``E_u E_m / (t_j (E_u - E_m))`` of deformable
units made the paper example's brick walls about 3x too stiff: 2.1e10 against 6.8e9 Pa; it
changes periods and drifts, hardly forces, which depend on the ratios of stiffnesses);
``E_u, G_u`` are the unit's and ``E_m, G_m`` the mortar's moduli, ``G = E / (2 (1 + nu))``, ``t_j`` the
joint thickness. A joint patch of area ``A`` with second moments ``I_uu = int u^2 dA``,
``I_vv = int v^2 dA``, ``I_uv = int u v dA`` about its centroid, in its frame (u, v in the joint
plane, n the normal from brick a to brick b), has the 6 x 6 stiffness, acting on the relative
displacement ``d`` (m) and rotation ``r`` (rad) of b against a at the centroid,

    F_u = k_s A d_u,   F_v = k_s A d_v,   F_n = k_n A d_n                         [N]
    [M_u, M_v] = k_n [[I_vv, -I_uv], [-I_uv, I_uu]] [r_u, r_v],  M_n = k_s (I_uu + I_vv) r_n   [N m]

and the normal stress at a point ``(u, v)`` of the patch is ``sigma = k_n (d_n + r_u v - r_v u)``
[Pa], positive in tension (the joint opening). The joint cracks, as a whole, when anywhere on its
outline (the convex hull of the patch, where a linear field takes its extremes)

* tension cut-off:  ``sigma_max > f_t``, and, for a joint under net compression, its compressive
  resultant ``(u_r, v_r) = (-M_v / F_n, M_u / F_n)`` outside the outline: brittle mortar cracks
  where the stress reaches ``f_t``, but under compression that crack stops where the stress
  changes sign, and the joint stands as a no-tension section until the resultant leaves it
  (rocking). Under net tension the first crack runs through (nothing stops it);
* compression cap:  ``-sigma_min > f_c``
* Mohr-Coulomb shear: ``tau > c + mu sigma_c`` with ``tau = |F_uv| / A + |M_n| r_max / (I_uu + I_vv)``
  and ``sigma_c = max(0, -F_n / A)`` the mean compression.

Bending is no separate constant: it is the linear stress distribution over the patch. A joint of
a rectangle ``b x d`` under a compression ``N`` and a moment ``M`` about a principal axis first
reaches ``f_t`` at ``M = f_t S + N d / 6`` (``S = b d^2 / 6``); its resultant leaves the patch at
``M = N d / 2``; so it fails at ``M = max(f_t S + N d / 6, N d / 2)``: by the mortar's tension for
a lightly loaded joint, by rocking for a heavily loaded one. Once cracked, the joint carries what
dry contact carries: compression, rocking about an edge, Coulomb friction (see "Cracked joints").
(A partly cracked joint keeps its full stiffness in this linear model; the stiffness lost by the
cracked part would shift some load to its neighbours.)

The elastic model. Every brick is a rigid body with six degrees of freedom (translation and small
rotation about its centroid). The intact joints (and the foundation joints to the ground) couple
them through the stiffness above.

Cracked joints. A cracked joint couples its bricks at its outline's corners, each corner with a
share ``A / k`` of the patch (``k`` corners) and the springs ``k_n A / k``, ``k_s A / k`` [N/m]
of an elastic-plastic contact: no tension, and a shear force bounded by Coulomb's ``mu N`` beyond
which the corner slides (UDEC's and 3DEC's contact law; the exact law and its smoothing are in
:meth:`JointModel._contact_forces`); where the material gives the masonry's compressive strength
(:attr:`Material.masonry_compressive_strength`), a compression bounded by it over the corner's share
(:func:`._joint_kernels.contact_forces`: a rocking wall's toe spreads inward, resolved to the joints' corners). A corner keeps the slip it has made from one load to the
next (:meth:`JointModel.commit`), so the model follows the load's history as friction does. The
equilibrium of every body under these nonlinear contacts is found by a Newton iteration on the
symmetric part of the tangent (the contacts' stiffness with their friction taken at a fixed normal
force, see :meth:`JointModel._newton_step`), with every step capped and halved until the
out-of-balance force falls (where no halving does, one step on the touching corners' elastic
stiffness instead), to an out-of-balance force of ``tol`` (1e-3) of the heaviest body's load (these
numerical settings are :class:`ContactSettings`); an iteration that has stalled
(ten steps without halving that force or growing the motion tenfold) stops where it is, and
:attr:`JointModel.converged` says so. In a pushover, a shear test and under gravity alone (not
yet under a ground motion: :meth:`CrackTracker.default_settings`) a solve that ends
unconverged asks a static programme on its own joints and contacts whether the load has an
equilibrium at all (:meth:`JointModel.has_equilibrium`, with each contact's friction bounded by
both Coulomb's cone and ``mu N`` of the iteration's least out-of-balance iterate: one step of
Gilbert, Casapulla & Ahmed's non-associative programme, from the model's own state); if it has,
the iteration failed and not the structure, and the solve ends at that iterate instead of where
its last steps threw it (a fallback step is taken whatever it does: on a dry stone wall, WI2.175,
kilometres and 1e11 N out of balance at 0.10 g, read as the collapse, where the programme says
0.23 g; with the check its pushover collapses at 0.232-0.234 g at three load rates and three
tolerances, experiments/dry_pushover_lp.py). If it has none even with Coulomb's cone alone, the
load is beyond the most the joints can carry, and the solve is a mechanism however little its
iterate moved (:attr:`JointModel.no_equilibrium`: the crack rounds end and the cracked joints are
let go; a dry stone wall's 400-iteration solves ended micrometres from their start above its
static programme's load, and it stood to 1.06 times that load, docs/stone_walls.md). A structure
whose cracked joints leave a mechanism has no such equilibrium: the iteration then runs away along
the mechanism (held only by the weak springs below), and the joints that move by more than
``release_m`` (1 mm; an equilibrium moves them by microns) are the ones Bullet lets go (see
:class:`CrackTracker`; a pushover or a shear test, whose load rises slowly from one equilibrium to
the next, lets go at the verdict's run-away displacement and iterates to convergence instead:
under a laboratory precompression an equilibrium moves its joints by a millimetre,
``CrackTracker.default_settings``). Against rigid-block limit analysis (experiments/joint_statics.py, dry
panels with Coulomb friction 0.6) the model finds its mechanism within 6 % below the static
programme's load (Coulomb friction is non-associative, so the real collapse load is at most the
programme's).

The load is each brick's weight in the frame that moves with the ground, ``m (-a_x, -a_y, -g)``,
the same vector Bullet steps with in that frame: the structure Bullet holds is rigid, so it
responds to the ground quasi-statically, and its joint forces are those of this solve (while no
joint has cracked a linear one, direct sparse LU, exact to rounding; after, the contacts' Newton
iteration to its tolerance): they do not depend on any of Bullet's settings. A brick or a group
of bricks that no joint or contact holds (falling) is held by a weak spring ``eps m`` to its place;
under the uniform gravity-like load that spring takes exactly the group's own weight, so it puts
no force on the group's joints (inertia relief), and the group's equilibrium is a rigid
translation by ``g / eps``, where the contact iteration starts it.

Forces depend on the ratios of the stiffnesses (``k_s / k_n``, the joints' lengths of unit and
the patches' geometry), not on their size: scaling both moduli scales every displacement and
leaves every force as it is. The absolute values matter for how far a joint moves and for the
periods of the structure (simulation/dynamics.py): an equilibrium moves the joints by microns with
the default moduli, a mechanism by metres (``g / eps``), and ``release_m`` lies between (a mortar
a thousand times softer than the default would need a larger one).

When a frame's load cracks a joint, the load is re-solved on the structure without it, and the
joints that this overloads crack in the same frame (event by event: those within
``crack_band`` of the worst at each round, 10 % under a ground motion, the worst alone where the
load rises slowly), up to ``max_rounds``. Every round cracks from an equilibrium: once a round's
solve has run away (a mechanism), the rounds end and nothing more cracks in that frame. The
run-away iterate is no state the structure passes through: how far it has gone, and so the
forces in the joints it carries, are set by where the iteration stopped (cracking every joint over
its strength there, as this model did before, made the cascade after a mechanism's onset follow
the solver's tolerance: Stylite at 0.3 g, 907, 727 and 907 joints cracked at tolerances 1e-3, 3e-4
and 1e-4). The run lets the mechanism's moving joints go, Bullet carries the mechanism, and the
next frame's load is solved on what still stands. With this rule the Stylite tower's 0.3 g quake
(seed 0) cracks and lets go the same joints at the same frames at the default settings, at
tolerances 1e-5 and at 30 or 100 iterations (experiments/joint_solver_settings.py); near a
mechanism's threshold a tighter tolerance can still change a cascade by some 5-10 % of its joints
(0.2 g seed 1: 91 against 86; 0.4 g seed 2: 140 against 131 at 1e-4; measured on 384c38f, before the
fixed-pattern factorisation, whose other rounding gives 135 at 0.4 g seed 2 at the default).

Units: metres, newtons, pascals, radians.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ..errors import InputError
from ..process import raise_if_stopped
from .scene import Bond, Material, Scene, footing_patches, joint_axes, plate_linked

__all__ = [
    "ContactSettings",
    "JointStiffness",
    "joint_stiffness",
    "scene_joint_stiffness",
    "unit_lengths",
    "JointModel",
    "JointState",
    "FAILURE_MODES",
]

FAILURE_MODES = ("tension", "compression", "shear")

#: A new solver state this close to the last factorised one is solved by preconditioned CG.
_CG_CHANGES = 4

#: SuperLU options for the joint model's matrices, which are structurally symmetric (and
#: symmetric where no corner slides): an ordering on the pattern of A^T + A with diagonal pivots
#: fills about half as much as SuperLU's default column ordering (a Stylite tangent, 2,016
#: unknowns: 18 against 32 ms a factorisation, relative residual 1e-8 either way).
_LU_OPTIONS = dict(permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.01, options=dict(SymmetricMode=True))


@dataclass(frozen=True)
class ContactSettings:
    """How the joint model finds its equilibrium and decides a run-away (see the module docstring).
    Numerical settings, not material: none was fitted to make a structure stand or fall; an
    outcome that changed with them would be the solver's, as with Bullet's settings."""

    eps_per_s2: float = 1e-2  # weak spring to each body's place: eps m on translations, eps m l^2 on rotations, 1/s^2
    step_m: float = 1e-4  # no Newton step moves anything further than this or 3x the motion so far, m
    smooth_m: float = 1e-10  # the width over which the contacts' no-tension kink is rounded, m
    tol: float = 1e-3  # out-of-balance force at convergence, as a fraction of the heaviest body's load
    # ... or of each body's own load (its moment: times its size), at least a thousandth of the
    # heaviest's: a shear test's loading beam weighs 20-250 stones, and a thousandth of its load is
    # a third of a stone's weight (the dry SW.30.1's peak 14.8 kN at 1e-3 of the beam, 16.0 and 16.1
    # at 1e-4 and 1e-5: experiments/shear_test_convergence.py)
    tol_per_body: bool = False
    max_iter: int = 50  # Newton iterations per solve
    # the friction law's rounding: a contact corner sticks (its shear force is its elastic trial force)
    # up to 1 - slip_band of Coulomb's limit mu N, slides at that limit from 1 + slip_band, and bends
    # smoothly between (so that Newton's method converges on it)
    slip_band: float = 0.05
    stall_iter: int = 10  # a solve stops when this many iterations neither halved the out-of-balance force nor grew the motion tenfold
    max_rounds: int = 40  # crack rounds per load
    # a crack round cracks the intact joints over their strength whose utilisation is within this
    # fraction of the worst (0: the worst alone, event by event); the rest wait for the next round's
    # solve, which the first ones' load may have moved onto others or off them
    crack_band: float = 0.1
    release_m: float = 1e-3  # a joint whose corners move further than this in a solve has run away, m
    # a solve that ends without converging asks a static programme on its own joints and contacts
    # whether any equilibrium of the load exists (:meth:`JointModel.has_equilibrium`): if one does,
    # the iteration failed, not the structure, and the solve ends at its least out-of-balance iterate
    # instead of wherever it stopped (a diverged fallback step was read as a collapse). On where the
    # load rises slowly (CrackTracker.default_settings); under a ground motion not yet measured
    check_equilibrium: bool = False

    def __post_init__(self) -> None:
        for name in (
            "eps_per_s2",
            "step_m",
            "smooth_m",
            "slip_band",
            "tol",
            "max_iter",
            "stall_iter",
            "max_rounds",
            "release_m",
        ):
            if not getattr(self, name) > 0:
                raise InputError(f"contact settings: {name} = {getattr(self, name)} must be > 0")
        if not 0.0 <= self.crack_band < 1.0:
            raise InputError(f"contact settings: crack_band = {self.crack_band} must be in [0, 1)")


@dataclass(frozen=True)
class JointStiffness:
    """Normal and shear stiffness per unit area of each joint, N/m^3 (Pa/m): arrays, one per joint."""

    normal: np.ndarray
    shear: np.ndarray


#: The masonry's shear modulus over its Young's modulus where the masonry's modulus is given
#: (EN 1996-1-1, 3.7.3: "G may be taken as 40 % of E").
MASONRY_SHEAR_RATIO = 0.4


def joint_stiffness(material: Material, unit_length_m) -> JointStiffness:
    """The stiffness per unit area of a joint between rigid units: the mortar and the units' length
    across the joint in series (see the module docstring),
    ``1 / k_n = t_j / E_m + l / E_u`` and ``1 / k_s = t_j / G_m + l / G_u``, with ``l`` the units'
    length across the joint (m; per joint, an array or a number: :func:`unit_lengths`, the
    distance between the two bodies' centroids less the joint's mortar; for a joint on the rigid
    ground, its body's centroid's distance). Where the material gives the masonry's own modulus E
    (:attr:`Material.masonry_youngs_modulus`: a wallet's compression test, or a code's table for the
    typology), ``k_n = E / (l + t_j)`` and ``k_s = 0.4 E / (l + t_j)`` instead: each column of unit
    and joint then has the masonry's modulus (a stone wall's measured 1.2 GPa where its stones'
    20 GPa and a 1 GPa mortar in series give 10)."""
    m = material
    length = np.maximum(np.asarray(unit_length_m, dtype=np.float64), 0.0)
    if m.masonry_youngs_modulus > 0:
        # the masonry's own modulus over the unit's length and the joint: a column of courses
        # (l = h across each bed joint, the pitch h + t_j) has (h + t_j) k_n = E, and 0.4 E in
        # shear (EN 1996-1-1, 3.7.3)
        span = length + m.joint_thickness_m
        e = m.masonry_youngs_modulus
        return JointStiffness(normal=e / span, shear=MASONRY_SHEAR_RATIO * e / span)
    gu = m.unit_youngs_modulus / (2.0 * (1.0 + m.unit_poisson))
    gm = m.mortar_youngs_modulus / (2.0 * (1.0 + m.mortar_poisson))
    kn = 1.0 / (m.joint_thickness_m / m.mortar_youngs_modulus + length / m.unit_youngs_modulus)
    ks = 1.0 / (m.joint_thickness_m / gm + length / gu)
    return JointStiffness(normal=kn, shear=ks)


def unit_lengths(
    x: np.ndarray, a: np.ndarray, b: np.ndarray, centre: np.ndarray, normal: np.ndarray, mortar_m: float = 0.0
) -> np.ndarray:
    """The length of unit across each joint (m): the distances along its normal from its plane
    (through ``centre``) to the centroids ``x`` of its bodies ``a`` and ``b`` (``b < 0``: the rigid
    ground, none), less the joint's thickness of mortar ``mortar_m`` between two bodies.

    `build` fills each unit out to the middle of the mortar around it, so two bodies' centroids
    are a course's pitch apart, unit and joint (0.19 m for the paper example's 0.18 m bricks and
    10 mm joints): counted as unit, that mortar was counted twice, once in ``t_j / E_m`` and once in
    ``l / E_u`` (the paper example's columns 3.6 % too compliant with the default moduli, 5 % with
    the masonry's own modulus; built walls' first periods 4-6 % above the Timoshenko beam's, now
    2-3 %: docs/dynamics.md, "The mortar counted once"). A body on
    the ground meets it with its unit's own face (the mortar bed under the first course is the
    joint's ``t_j`` alone), so its length is the distance as it is."""
    n = normal / np.linalg.norm(normal, axis=1, keepdims=True)
    length = np.abs(((centre - x[a]) * n).sum(axis=1))
    pair = b >= 0
    other = np.abs(((centre - x[np.maximum(b, 0)]) * n).sum(axis=1))
    return np.where(pair, np.maximum(length + other - mortar_m, 0.0), length)


def scene_joint_stiffness(scene: Scene) -> JointStiffness:
    """The stiffness per unit area of each of a scene's joints (:func:`joint_stiffness`)."""
    if not scene.bonds:
        return joint_stiffness(scene.material, np.zeros(0))
    x = np.array([body.location for body in scene.bodies], dtype=np.float64).reshape(-1, 3)
    a = np.array([j.a for j in scene.bonds])
    b = np.array([j.b for j in scene.bonds])
    centre = np.array([j.location for j in scene.bonds], dtype=np.float64)
    normal = np.array([j.normal for j in scene.bonds], dtype=np.float64)
    return joint_stiffness(scene.material, unit_lengths(x, a, b, centre, normal, scene.material.joint_thickness_m))


def _skew(r: np.ndarray) -> np.ndarray:
    """``[r]x`` ``(N, 3, 3)`` of vectors ``(N, 3)``: ``[r]x w = r x w``."""
    z = np.zeros(len(r))
    return np.stack(
        [
            np.stack([z, -r[:, 2], r[:, 1]], -1),
            np.stack([r[:, 2], z, -r[:, 0]], -1),
            np.stack([-r[:, 1], r[:, 0], z], -1),
        ],
        -2,
    )


@dataclass(frozen=True)
class JointState:
    """The joints' condition under one load: per joint its utilisation (the largest of the three
    criteria's stress over strength; >= 1 fails), the criterion that governs, and the forces in
    the joint frame (``F_u, F_v, F_n, M_u, M_v, M_n``; N and N m, ``F_n > 0`` pulls)."""

    utilisation: np.ndarray  # (J,)
    mode: np.ndarray  # (J,) index into FAILURE_MODES
    forces: np.ndarray  # (J, 6)
    relative: np.ndarray  # (J, 6) d_u, d_v, d_n (m), r_u, r_v, r_n (rad) of b against a


def _point_map(ra: np.ndarray, rb: np.ndarray, ground: np.ndarray) -> np.ndarray:
    """``(N, 3, 12)``: the displacement of body b's copy of a point less body a's, from the two
    bodies' (translation, small rotation) about their centroids; ``ra``, ``rb`` ``(N, 3)`` run from
    each centroid to the point. Where ``ground`` (the point's b is the fixed plate), b's columns are 0."""
    eye = np.broadcast_to(np.eye(3), (len(ra), 3, 3))
    B = np.zeros((len(ra), 3, 12))
    B[:, :, 0:3] = -eye
    B[:, :, 3:6] = _skew(ra)
    B[:, :, 6:9] = eye
    B[:, :, 9:12] = -_skew(rb)
    B[ground, :, 6:] = 0.0
    return B


def _scatter(dofs: np.ndarray, blocks: np.ndarray, n: int, drop_zeros: bool = False) -> sp.csc_matrix:
    """The ``n x n`` sum of the 12 x 12 ``blocks`` ``(M, 12, 12)`` placed at ``dofs`` ``(M, 12)``
    (with ``drop_zeros``, entries that are exactly 0 are left out of the sparsity pattern: a contact
    corner on the plate has no b columns)."""
    rows = np.repeat(dofs, 12, axis=1).ravel()
    cols = np.tile(dofs, (1, 12)).ravel()
    vals = blocks.ravel()
    if drop_zeros:
        keep = vals != 0.0
        rows, cols, vals = rows[keep], cols[keep], vals[keep]
    return sp.coo_matrix((vals, (rows, cols)), shape=(n, n)).tocsc()


def _plate_contacts(scene: Scene) -> tuple[Bond, ...]:
    """Contact-only joints for the bodies that stand on the plate without a foundation joint."""
    if not scene.bodies:
        return ()
    founded = {b.a for b in scene.bonds if b.b < 0}
    tol = max(scene.solver.contact_gap_m, 1e-4)
    top = scene.plate.top_z
    if scene.plate.tilt_deg != 0.0:
        return ()  # a tilted plate (tests of sliding) holds no bonded structure
    patches = footing_patches(scene.bodies, tol, bottom=top)
    return tuple(p for p in patches if p.a not in founded)


def _ratio(stress: np.ndarray, strength) -> np.ndarray:
    """Utilisation ``stress / strength``, where a zero strength is met by any positive stress."""
    strength = np.broadcast_to(np.asarray(strength, dtype=np.float64), np.shape(stress))
    out = np.where(stress > 0, np.inf, 0.0)
    np.divide(stress, strength, out=out, where=strength > 0)
    return out


def _outline_edges(outline: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each convex outline's ``(J, K, 2)`` edges ``(J, K, 2)`` (corner k to k + 1) and whether each
    is a real edge ``(J, K)`` (not one between two repeats of the padding)."""
    edge = np.roll(outline, -1, axis=1) - outline
    return edge, np.linalg.norm(edge, axis=2) > 1e-12


def _inside_outline(
    outline: np.ndarray, u: np.ndarray, v: np.ndarray, edges: tuple[np.ndarray, np.ndarray]
) -> np.ndarray:
    """Whether the points ``(u, v)`` (J,) lie inside each joint's convex outline ``(J, K, 2)``
    (corners in order, padded by repeats), whose :func:`_outline_edges` are ``edges``."""
    a = outline
    edge, real = edges
    rel = np.stack([u, v], axis=1)[:, None] - a
    cross = edge[..., 0] * rel[..., 1] - edge[..., 1] * rel[..., 0]
    pos = np.where(real, cross >= -1e-12, True).all(axis=1)
    neg = np.where(real, cross <= 1e-12, True).all(axis=1)
    return pos | neg


def _corner_blocks(Lc: np.ndarray, TL: np.ndarray) -> np.ndarray:
    """``(Lc^T TL)[ROW, COL]`` ``(C, 78)`` (:attr:`_Tangent.ROW`) for the contact corners' maps
    ``Lc`` ``(C, 3, 12)`` and ``TL`` = ``T Lc`` ``(C, 3, 12)``: each corner's 12 x 12 block of the
    tangent, its lower triangle. Summed over the corner's three directions in the order numpy's
    ``einsum("cap,cap->cp")`` took (0, 2, then 1): the same values bit for bit, in 0.7 of its
    time (the contact iteration's steps and cascades follow the last digits); compiled
    (:mod:`._joint_kernels`), the same sum in a fifth of numpy's time again."""
    from ._joint_kernels import corner_blocks

    return corner_blocks(Lc, TL, _Tangent.ROW, _Tangent.COL)


class _Tangent:
    """The contact iteration's matrix ``K0 + P^T T_s P`` (:meth:`JointModel._newton_step`) on one
    sparsity pattern for the model's life, factorised by CHOLMOD's supernodal Cholesky (through
    cvxopt).

    Every term couples the two bodies of one joint: an intact joint's stiffness and its cracked
    corners' contacts alike fill that joint's 12 x 12 block, and the weak springs the diagonal. So
    the lower triangle of the union of all joints' blocks holds every matrix the iteration meets:
    its fill-reducing analysis (AMD) is done once, each block's place in it is kept, and a new
    matrix is its values summed into those places (``np.bincount``), with no sparse-matrix
    arithmetic, sorting or pattern comparison. A block that is zero (a joint let go) costs its
    entries' share of the factorisation, as it did while the joint was intact."""

    #: A symmetric 12 x 12 block is summed by its 78 entries ``(ROW[p], COL[p])``, ``ROW >= COL``.
    ROW, COL = np.tril_indices(12)

    def __init__(self, dofs: np.ndarray, n: int) -> None:
        from cvxopt import cholmod, matrix, spmatrix

        gi, gj = dofs[:, self.ROW].astype(np.int64), dofs[:, self.COL].astype(np.int64)
        rows, cols = np.maximum(gi, gj), np.minimum(gi, gj)  # each entry's place in the lower triangle
        diag = np.arange(n, dtype=np.int64)
        key = np.concatenate([(cols * n + rows).ravel(), diag * n + diag])
        place, slot = np.unique(key, return_inverse=True)  # column-major: CHOLMOD's own order
        self.slot = slot[:-n].reshape(dofs.shape[0], len(self.ROW))  # (J, 78)
        self.diag_slot = slot[-n:]
        self.nnz = place.size
        self.n = n
        self._place = place
        self._csc = None  # scipy's matrix of this pattern (matvec), made when first asked
        self._A = spmatrix(matrix(np.ones(self.nnz)), matrix(place % n), matrix(place // n), (n, n))
        self._symbolic = cholmod.symbolic(self._A)
        self._base: tuple[bytes, np.ndarray] | None = None

    def values(self, joints: np.ndarray, blocks: np.ndarray, diag: np.ndarray | None = None) -> np.ndarray:
        """The lower triangle's values ``(nnz,)`` of the sum of the symmetric 12 x 12 blocks of
        ``joints`` ``(M,)`` (joints may repeat), given by their entries ``blocks`` ``(M, 78)`` at
        ``(ROW, COL)``, and of ``diag`` ``(n,)`` on the diagonal. (A foundation joint's block has its
        b half at a's place, and zero there.)"""
        from ._joint_kernels import summed_blocks

        out = summed_blocks(
            self.slot, np.asarray(joints, dtype=np.int64), np.asarray(blocks, dtype=np.float64), self.nnz
        )
        if diag is not None:
            out[self.diag_slot] += diag
        return out

    def body_values(self, dofs: np.ndarray, blocks: np.ndarray) -> np.ndarray:
        """The lower triangle's values ``(nnz,)`` of block-diagonal 6 x 6 ``blocks`` ``(B, 6, 6)``
        (symmetric) at the unknowns ``dofs`` ``(B, 6)``: a body's own block lies in the pattern when
        one of the joints it was made with joins it."""
        r, c = np.tril_indices(6)
        gi, gj = dofs[:, r].astype(np.int64), dofs[:, c].astype(np.int64)
        key = (np.minimum(gi, gj) * self.n + np.maximum(gi, gj)).ravel()
        slot = np.searchsorted(self._place, key)
        if not (self._place[np.minimum(slot, self.nnz - 1)] == key).all():
            raise ValueError("a body's block is not in the pattern (a body no joint of the pattern joins)")
        return np.bincount(slot, weights=blocks[:, r, c].ravel(), minlength=self.nnz).astype(np.float64, copy=False)

    def matvec(self, values: np.ndarray, x: np.ndarray) -> np.ndarray:
        """``A x`` for the symmetric ``A`` of these lower-triangle ``values``."""
        import scipy.sparse as sp

        if self._csc is None:
            n = self.n
            self._csc = sp.csc_matrix((np.ones(self.nnz), (self._place % n, self._place // n)), shape=(n, n))
            self._csc.sort_indices()
        # the csc's entries are the pattern's, in its order (column-major, rows ascending)
        low = self._csc
        low.data = np.asarray(values, dtype=np.float64)
        return low @ x + low.T @ x - values[self.diag_slot] * x

    def base(self, key: bytes, make) -> np.ndarray:
        """The values of the intact joints' part and the weak springs, kept for the last ``key``
        (``make()`` computes them)."""
        if self._base is None or self._base[0] != key:
            self._base = (key, make())
        return self._base[1]

    def solve(self, values: np.ndarray, b: np.ndarray) -> np.ndarray:
        """``A^-1 b`` for the symmetric positive definite ``A`` of these lower-triangle ``values``.
        Raises ArithmeticError where ``A`` is not positive definite."""
        self.factor(values)
        return self.solve_factored(b)

    def factor(self, values: np.ndarray) -> None:
        """Factorise ``A`` of these lower-triangle ``values`` (kept until the next); ArithmeticError
        where it is not positive definite."""
        from cvxopt import cholmod, matrix

        self._A.V = matrix(values)
        cholmod.numeric(self._A, self._symbolic)

    def solve_factored(self, b: np.ndarray) -> np.ndarray:
        """``A^-1 b`` with the last factorised ``A`` (:meth:`factor`)."""
        from cvxopt import cholmod, matrix

        x = matrix(np.ascontiguousarray(b, dtype=np.float64))
        cholmod.solve(self._symbolic, x)
        return np.array(x).ravel()


def _highs_bounds(lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Bounds in HiGHS's terms: its own infinity for numpy's."""
    import highspy

    inf = highspy.kHighsInf
    return np.where(np.isfinite(lo), lo, -inf), np.where(np.isfinite(hi), hi, inf)


def _feasibility_programme(A: sp.csc_matrix, lo, hi, row_lo, row_hi):
    """A HiGHS model (``highspy.Highs``) of the linear programme ``row_lo <= A x <= row_hi``,
    ``lo <= x <= hi`` with no objective (is there any such ``x``?), quiet and on one thread."""
    import highspy

    lp = highspy.HighsLp()
    lp.num_row_, lp.num_col_ = A.shape
    lp.col_cost_ = np.zeros(A.shape[1])
    lp.col_lower_, lp.col_upper_ = _highs_bounds(lo, hi)
    lp.row_lower_, lp.row_upper_ = _highs_bounds(row_lo, row_hi)
    lp.a_matrix_.format_ = highspy.MatrixFormat.kColwise
    lp.a_matrix_.start_ = A.indptr
    lp.a_matrix_.index_ = A.indices
    lp.a_matrix_.value_ = A.data
    h = highspy.Highs()
    h.setOptionValue("output_flag", False)
    h.setOptionValue("threads", 1)
    h.passModel(lp)
    return h


# the static programme's iterations (:func:`_feasible`): the dual simplex from the last basis; then
# the interior-point solver from scratch; then the primal simplex from scratch, per row and column;
# and each solver's seconds, a net for a solver stuck within its iterations
DUAL_ITERATIONS = 1000
IPM_ITERATIONS = 1000
PRIMAL_ITERATIONS_PER_ROW_AND_COLUMN = 2
SOLVER_SECONDS = 60.0


def _feasible(h) -> bool | None:
    """Whether the HiGHS model ``h`` (:func:`_feasibility_programme`) has a feasible point; None
    where no solver answers.

    HiGHS's dual simplex can run for minutes on these programmes: a dry laboratory wall's shear
    test (SW.250.1) sat in one question for 20 minutes. SW.30.2's question (1,748 rows, 7,000
    columns; tests/data/shear_test_question.mps.xz) slows down after about 3,500 dual iterations:
    highspy 1.15.1 ran 5,000 in 0.9 s and 10,000 in 46 s (then a solve error), 1.16.0 ran 3,507 in
    3 s and 4,374 in more than 30; the interior-point solver finds it infeasible in 16 iterations
    (0.4 s), the primal simplex in 4,172-4,317 (0.7 s). The dual simplex, which a question on the
    same matrix starts from the last answer's basis (0-39 iterations where measured), is given
    :data:`DUAL_ITERATIONS`; a question it leaves open is put again from scratch to the
    interior-point solver with crossover (:data:`IPM_ITERATIONS`), whose basis the next question's
    dual simplex starts from where the answer is yes, then to the primal simplex
    (:data:`PRIMAL_ITERATIONS_PER_ROW_AND_COLUMN`; on SW.200.1's and SW.250.1's shear tests with
    the dry joints crushing at 56.8 MPa the interior point left one question each open, which the
    primal simplex answered). Limits on iterations, so that a question gets the same answer on any
    machine; :data:`SOLVER_SECONDS` is a net for a solver stuck within them, after which the next
    solver answers the same question: each solver gets its own, counted from when it starts."""
    import highspy

    answered = (highspy.HighsModelStatus.kOptimal, highspy.HighsModelStatus.kInfeasible)
    lp = h.getLp()
    h.setOptionValue("simplex_iteration_limit", DUAL_ITERATIONS)
    # HiGHS's time limit is on the model's run time since it was made, over every question and
    # solver (highspy 1.15.1): each solver gets its own seconds from when it starts (set once, the
    # primal simplex's 30 s left the interior point none, and a kept model that had run 30 s in all
    # answered nothing more)
    h.setOptionValue("time_limit", h.getRunTime() + SOLVER_SECONDS)
    h.run()
    status = h.getModelStatus()
    # the interior point with crossover: an answer yes leaves a basis the next question's dual
    # simplex starts from. Before the primal simplex: on a house of 590 bricks (10,684 rows, 35,720
    # columns) the interior point answered in 12-29 s where the primal simplex from scratch had not
    # in 30; on SW.30.2's question 0.4 s against 0.7
    # (the crossover's simplex clean-up is held to the simplex's iteration limit: the dual's 1,000
    # left one of the house's questions open)
    simplex_limit = int(PRIMAL_ITERATIONS_PER_ROW_AND_COLUMN * (lp.num_row_ + lp.num_col_))
    ipm = {
        "solver": "ipm",
        "run_crossover": "on",
        "ipm_iteration_limit": IPM_ITERATIONS,
        "simplex_iteration_limit": simplex_limit,
    }
    primal = {
        "solver": "simplex",
        "simplex_strategy": 4,  # the primal simplex
        "simplex_iteration_limit": simplex_limit,
    }
    for options in (ipm, primal):
        if status in answered:
            break
        h.clearSolver()
        for name, value in options.items():
            h.setOptionValue(name, value)
        h.setOptionValue("time_limit", h.getRunTime() + SOLVER_SECONDS)
        try:
            h.run()
            status = h.getModelStatus()
        finally:
            # the next question's dual simplex (its iteration limit is set above, at every question)
            h.setOptionValue("solver", "choose")
            h.setOptionValue("simplex_strategy", 1)
            if options is ipm and h.getInfo().basis_validity != highspy.BasisValidity.kBasisValidityValid:
                h.clearSolver()  # from scratch, not from an interior point
            # (the primal simplex's basis, or the crossover's, is where the next question's dual
            # simplex starts)
    if status not in answered:
        return None
    return status == highspy.HighsModelStatus.kOptimal


class JointModel:
    """The elastic joint network of a scene's bonds (see the module docstring).

    ``intact`` (per bond) says which joints still act as mortar; the others act as contacts where
    ``closed`` (per bond and outline corner, from Bullet's poses) says they touch. Body ``i`` is
    ``scene.bodies[i]`` at its reference position (the end of the warm-up): the model is linear,
    small-displacement, about that state.
    """

    def __init__(self, scene: Scene, *, settings: ContactSettings | None = None, contact_gap_m: float = 1e-3) -> None:
        self.settings = settings = settings if settings is not None else ContactSettings()
        self.material = scene.material
        self.stiffness = joint_stiffness(self.material, np.zeros(0))
        self.contact_gap_m = float(contact_gap_m)
        bodies = scene.bodies
        bonds = scene.bonds
        self.nb = len(bodies)
        self.nj = len(bonds)  # the mortar joints; self.n_all adds the plate contacts
        self.mass = np.array([b.mass for b in bodies], dtype=np.float64)
        # bodies standing on the plate without a foundation joint bear on it: contact-only joints,
        # after the real ones, never intact
        bonds = tuple(bonds) + _plate_contacts(scene)
        self.x = np.array([b.location for b in bodies], dtype=np.float64).reshape(-1, 3)
        size = np.array([np.cbrt(max(b.volume, 1e-9)) for b in bodies])
        # weak springs to the body's place: eps m on translations, eps m l^2 on rotations
        reg = np.column_stack(
            [
                np.repeat(settings.eps_per_s2 * self.mass[:, None], 3, axis=1),
                np.repeat((settings.eps_per_s2 * self.mass * size**2)[:, None], 3, axis=1),
            ]
        )
        self._reg = sp.diags(reg.ravel())
        self._size = size
        self._lu: dict = {}
        self._joint_part: tuple | None = None
        self._tangent: _Tangent | None = None  # the contact iteration's matrix and its analysis, made at first use
        self._sub_tangents: dict = {}  # the same over the bodies still held, by their set (_tangent_of)
        self._transposed: tuple | None = None  # the contact iteration's corner operator and its transpose (_residual)
        # the equilibrium question's matrix and its two HiGHS models, with friction capped and with
        # Coulomb's cone alone, each kept for its last basis (:meth:`has_equilibrium`)
        self._programme: tuple | None = None
        self.factorisations = 0  # sparse factorisations (LU or Cholesky), over the model's life
        # the crack rounds of the :meth:`crack` under way (or last): its round and the joints it has
        # cracked so far, read by another thread to show what a long check is doing
        self.crack_round = 0
        self.uncracked_utilisation = np.zeros(0)  # (J,) of the last crack() call's first solve
        self.cracked_in_rounds = 0
        self._U: np.ndarray | None = None  # the last committed solve's motion
        self._last: tuple | None = None
        self.newton_iterations = 0  # of the last solve
        self.converged = True  # whether the last solve met ``settings.tol``
        # over the model's life: its solves, those that ended without meeting the tolerance, and the
        # largest out-of-balance force (or moment) one of those ended with, in tolerances
        self.solves = 0
        self.unconverged_solves = 0
        self.worst_unconverged = 0.0
        # of those, the ones whose load the static programme found an equilibrium for (ended at
        # their least out-of-balance iterate: ``settings.check_equilibrium``)
        self.stalled_in_equilibrium = 0
        # and those whose load has no equilibrium on its joints and contacts even with Coulomb's
        # cone alone (beyond the static programme's largest load: a collapse under any flow rule);
        # ``no_equilibrium`` says whether the last solve was one
        self.without_equilibrium = 0
        self.no_equilibrium = False
        # questions to the static programme that none of its solvers answered (taken for no)
        self.unanswered = 0
        self.n_all = len(bonds)
        # each mortar joint's farthest corner from its centroid, and its outline's edges
        # (:func:`_outline_edges`): constants of the outline, made at first use (each check's
        # state read them anew: 2.4 of its 5.8 ms on the paper example's 4,961 joints)
        self._rmax: np.ndarray | None = None
        self._edges: tuple[np.ndarray, np.ndarray] | None = None
        if self.n_all == 0:
            return
        self.a = np.array([b.a for b in bonds], dtype=np.int64)
        self.b = np.array([b.b for b in bonds], dtype=np.int64)
        self.centre = np.array([b.location for b in bonds], dtype=np.float64)
        u, v, n = joint_axes(np.array([b.normal for b in bonds], dtype=np.float64))
        self.R = np.stack([u, v, n], axis=2)  # (J, 3, 3): columns u, v, n
        self.area = np.array([b.area_m2 for b in bonds], dtype=np.float64)
        # the units' length across each joint: its plane to either body's centroid along the normal,
        # less the joint's mortar (the ground is rigid); the joint carries the units' deformability in series with the mortar's
        self.unit_length = unit_lengths(self.x, self.a, self.b, self.centre, n, self.material.joint_thickness_m)
        self.stiffness = joint_stiffness(self.material, self.unit_length)
        mom = np.array([b.moments for b in bonds], dtype=np.float64).reshape(-1, 3)
        self.iuu, self.ivv, self.iuv = mom[:, 0], mom[:, 1], mom[:, 2]
        self.outline = np.array([b.outline for b in bonds], dtype=np.float64)  # (J, K, 2)
        # each joint's tensile strength and cohesion: the material's, none for a dry joint
        wet = np.array([not getattr(b, "dry", False) for b in bonds[: self.nj]], dtype=bool)
        self.tensile_strength = np.where(wet, self.material.tensile_strength, 0.0)
        self.cohesion = np.where(wet, self.material.shear_strength, 0.0)
        kn, ks = self.stiffness.normal, self.stiffness.shear  # (J,)
        D = np.zeros((self.n_all, 6, 6))
        D[:, 0, 0] = D[:, 1, 1] = ks * self.area
        D[:, 2, 2] = kn * self.area
        D[:, 3, 3] = kn * self.ivv
        D[:, 4, 4] = kn * self.iuu
        D[:, 3, 4] = D[:, 4, 3] = -kn * self.iuv
        D[:, 5, 5] = ks * (self.iuu + self.ivv)
        self.D = D
        self.held_rotation = tuple(getattr(scene, "held_rotation", ()))
        if self.held_rotation:
            # a body whose rotation is held (a shear test's beam between fixed ends): a spring on its
            # rotations a thousand times stiffer than the whole joint network's in bending
            span = float(np.ptp(self.x, axis=0).max()) + 1.0
            big = 1e3 * float(kn.max()) * float(self.area.sum()) * span**2
            diag = self._reg.diagonal().copy()
            for k in scene.held_rotation:
                diag[6 * k + 3 : 6 * k + 6] = big
            self._reg = sp.diags(diag)
        # L (J, 6, 12): the joint-frame relative displacement and rotation of b against a, from the
        # two bodies' (translation, rotation) about their centroids
        self.ground = self.b < 0
        self.bb = np.where(self.ground, self.a, self.b)  # b's body, or a's for the plate (its columns are 0)
        B = np.zeros((self.n_all, 6, 12))
        B[:, :3] = _point_map(self.centre - self.x[self.a], self.centre - self.x[self.bb], self.ground)
        B[:, 3:, 3:6] = -np.eye(3)
        B[:, 3:, 9:12] = np.eye(3)
        B[self.ground, 3:, 9:12] = 0.0
        Rt = np.transpose(self.R, (0, 2, 1))
        L = np.zeros_like(B)
        L[:, :3] = Rt @ B[:, :3]
        L[:, 3:] = Rt @ B[:, 3:]
        self.L = L
        self.Kj = np.transpose(L, (0, 2, 1)) @ D @ L  # (J, 12, 12)
        self.dofs = np.concatenate(
            [6 * self.a[:, None] + np.arange(6), 6 * self.bb[:, None] + np.arange(6)], axis=1
        )  # (J, 12); ground columns are zero in L
        # contact corners of each joint: global positions at the reference state and their B rows
        self.corner_mask = self._unique_corners()
        # each corner's share of its patch (J, 1), m^2: its springs', strengths' and crushing's area
        self._corner_share = self.area[:, None] / self.corner_mask.sum(axis=1, keepdims=True)
        self._corner_L, self._corner_k = self._corner_rows()
        # each contact corner's crushing force (N): the masonry's f_c over its share of the patch
        # (inf: none given, contacts carry any compression)
        fc = self.material.masonry_compressive_strength
        self._corner_cap = np.where(self.corner_mask & (fc > 0), fc * self._corner_share, np.inf)
        self.slip = np.zeros(self.outline.shape[:2] + (2,))  # kept slip of every contact corner, m

    # ------------------------------------------------------------------ geometry of the corners
    def _unique_corners(self) -> np.ndarray:
        """(J, K) True for the distinct outline corners (outlines are padded by repeats)."""
        o = self.outline
        keep = np.ones(o.shape[:2], dtype=bool)
        keep[:, 1:] = np.linalg.norm(np.diff(o, axis=1), axis=2) > 1e-9
        return keep

    def corner_points(self) -> np.ndarray:
        """Global positions ``(J, K, 3)`` of every joint's outline corners at the reference state."""
        u, v = self.R[:, :, 0], self.R[:, :, 1]
        return self.centre[:, None] + self.outline[..., :1] * u[:, None] + self.outline[..., 1:] * v[:, None]

    def _corner_rows(self) -> tuple[np.ndarray, np.ndarray]:
        """Per joint and corner the (3, 12) map from the two bodies' motion to the corner's relative
        displacement in the joint frame, and the corner spring's (k_s, k_s, k_n) stiffness."""
        p = self.corner_points()  # (J, K, 3)
        J, K = p.shape[:2]
        ra = (p - self.x[self.a][:, None]).reshape(-1, 3)
        rb = (p - self.x[self.bb][:, None]).reshape(-1, 3)
        B = _point_map(ra, rb, np.repeat(self.ground, K)).reshape(J, K, 3, 12)
        Rt = np.transpose(self.R, (0, 2, 1))
        Lc = np.einsum("jab,jkbc->jkac", Rt, B)
        share = self._corner_share  # each corner carries its share of the patch
        ks, kn = self.stiffness.shear[:, None], self.stiffness.normal[:, None]
        k = np.stack([ks * share, ks * share, kn * share], -1)
        return Lc, k * self.corner_mask[..., None]

    # ------------------------------------------------------------------ assembly and solve
    def _pad(self, intact: np.ndarray) -> np.ndarray:
        """``intact`` over the mortar joints, extended over the plate contacts (never intact)."""
        out = np.zeros(self.n_all, dtype=bool)
        out[: self.nj] = np.asarray(intact, dtype=bool)
        return out

    def stiffness_matrix(self, intact: np.ndarray | None = None) -> sp.csr_matrix:
        """The stiffness ``(6 B, 6 B)`` of the ``intact`` mortar joints (default all of them), without
        the weak springs that hold free bodies."""
        if self.n_all == 0:
            return sp.csr_matrix((6 * self.nb, 6 * self.nb))
        idx = np.flatnonzero(np.ones(self.nj, bool) if intact is None else np.asarray(intact, bool)[: self.n_all])
        return _scatter(self.dofs[idx], self.Kj[idx], 6 * self.nb).tocsr()

    def grounded(self, held: np.ndarray) -> np.ndarray:
        """``(B,)`` True for the bodies that a chain of the ``held`` mortar joints ``(J,)`` ties to the ground."""
        if self.n_all == 0:
            return np.zeros(self.nb, dtype=bool)
        return plate_linked(self.a, self.b, self.nb, self._pad(held))

    def _joint_matrix(self, intact: np.ndarray) -> sp.csc_matrix:
        """The intact joints' part of the stiffness plus the weak springs (kept for the last intact set)."""
        key = intact.tobytes()
        if self._joint_part is not None and self._joint_part[0] == key:
            return self._joint_part[1]
        K = self.stiffness_matrix(intact) + self._reg
        self._joint_part = (key, K.tocsc())
        return self._joint_part[1]

    def _matrix(self, intact: np.ndarray, contacts: np.ndarray) -> sp.csc_matrix:
        K = self._joint_matrix(intact)
        jc, kc = np.nonzero(contacts)
        if jc.size:
            Lc = self._corner_L[jc, kc]  # (C, 3, 12)
            Kc = np.einsum("cai,ca,caj->cij", Lc, self._corner_k[jc, kc], Lc)
            K = (K + _scatter(self.dofs[jc], Kc, 6 * self.nb, drop_zeros=True)).tocsc()
        return K

    def _load(self, g: np.ndarray) -> np.ndarray:
        f = np.zeros((self.nb, 6))
        f[:, :3] = self.mass[:, None] * np.asarray(g, dtype=np.float64)[None]
        return f.ravel()

    def _solve(self, intact: np.ndarray, active: np.ndarray, rhs: np.ndarray) -> np.ndarray:
        """``K^-1 rhs`` for the stiffness with these joints intact and these contact corners active.

        A state solved before reuses its LU factors (the last few are kept). A new one that differs
        from the last by at most ``_CG_CHANGES`` joints or corners is solved by conjugate gradients
        (K is symmetric positive definite) preconditioned by the last factors, to a relative residual
        of 1e-12 (a change of rank r converges in about r + 1 steps); if that does not converge in 8
        steps, or the change is larger, K is factorised anew. (Trying CG on every new state cost 15 %
        of a Stylite quake's joint time and almost never converged: Bullet's contacts change many
        corners from one frame to the next.)"""
        key = (intact.tobytes(), np.packbits(active).tobytes())
        lu = self._lu.get(key)
        if lu is not None:
            self._lu[key] = self._lu.pop(key)  # most recently used last
            return lu.solve(rhs)
        K = self._matrix(intact, active)
        if self._lu and self._changes(key, next(reversed(self._lu))) <= _CG_CHANGES:
            last = self._lu[next(reversed(self._lu))]
            M = spla.LinearOperator(K.shape, matvec=last.solve, dtype=np.float64)
            x, info = spla.cg(K, rhs, x0=last.solve(rhs), M=M, rtol=1e-12, atol=0.0, maxiter=8)
            if info == 0:
                return x
        lu = spla.splu(K, **_LU_OPTIONS)
        self.factorisations += 1
        self._lu[key] = lu
        while len(self._lu) > 8:
            self._lu.pop(next(iter(self._lu)))
        return lu.solve(rhs)

    @staticmethod
    def _changes(key: tuple[bytes, bytes], other: tuple[bytes, bytes]) -> int:
        """How many joints and contact corners two solver states (keys of ``_solve``) differ by."""
        a = np.frombuffer(key[0], dtype=bool) != np.frombuffer(other[0], dtype=bool)
        b = np.unpackbits(np.frombuffer(key[1], np.uint8) ^ np.frombuffer(other[1], np.uint8))
        return int(a.sum() + b.sum())

    def solve(
        self,
        g: np.ndarray,
        intact: np.ndarray,
        closed: np.ndarray | None = None,
        start: np.ndarray | None = None,
        extra: np.ndarray | None = None,
        joints: np.ndarray | None = None,
    ) -> tuple[JointState, np.ndarray]:
        """The joints' state under the load ``m g`` on every body (``g`` (3,) m/s^2), with the joints
        ``intact`` (J,) as mortar and the others as frictional, compression-only contacts at their
        corners where ``closed`` (J', K) (default: every corner of every cracked joint; J' counts the
        plate contacts after the joints, :attr:`n_all`). Returns the state of the mortar joints and
        the contact corners that carry compression.

        The contacts start from the slip each corner has kept since the last :meth:`commit` (see
        the module docstring, "Cracked joints"); a corner opens and closes again within the solve
        as the iteration finds it pulled or pressed. The iteration starts from the motion ``start``
        (6 B,), by default the last committed one; :attr:`converged` says whether it met its
        tolerance. ``extra`` (6 B,) adds forces and moments on the bodies (the inertial and damping
        forces of the elastic vibration, see :class:`~calib_masonry.simulation.dynamics.ElasticResponse`).
        ``joints``: the mortar joints (indices) whose state is computed (default all; the others' zero)."""
        intact = self._pad(intact)
        cand = (~intact)[:, None] & self.corner_mask
        if closed is not None:
            cand &= closed
        rhs = self._load(g) if extra is None else self._load(g) + extra
        jc, kc = np.nonzero(cand)
        U = self._contact_newton(intact, jc, kc, rhs, start)
        self._last = (jc, kc, U)
        active = np.zeros_like(cand)
        if jc.size:
            active[jc, kc] = self._corner_relative(jc, kc, U)[:, 2] < 0.0
        return self.state(U, joints), active

    def _contact_forces(self, jc, kc, gap):
        """Forces ``(C, 3)`` (u, v, n in the joint frame, on b; ``F_n < 0`` presses) of the contact
        corners at their relative displacements ``gap`` (C, 3) and their tangent ``dF / d gap``
        (C, 3, 3).

        Per corner of stiffness ``(k_s, k_s, k_n)`` and kept slip ``s`` (2,), with ``delta`` =
        :attr:`smooth_m`:

        * normal: ``N = k_n delta softplus(-d_n / delta)`` (``F_n = -N``): ``k_n max(-d_n, 0)``, no
          tension, with its kink rounded over ``delta`` (a corner that just touches carries
          ``k_n delta ln 2``: with the default mortar and 1e-10 m, 0.1 N on a corner of a 0.3 x 0.2 m
          bed, under a thousandth of that brick's weight);
        * shear: the trial force ``T* = k_s (d_t - s)`` and ``T = mu N f(|T*| / (mu N)) T* / |T*|``
          with ``f(x) = x`` up to ``1 - h``, ``1`` from ``1 + h`` and a parabola between
          (``h`` = :attr:`ContactSettings.slip_band`): exactly elastic (``T = T*``) while the corner
          sticks, exactly Coulomb's limit ``mu N`` while it slides, and with a continuous slope (so
          that Newton's method converges on it). A corner that sticks keeps its slip at
          :meth:`commit` (``s = d_t - T / k_s`` is unchanged when ``T = T*``). (The law before
          2026-11-28, ``T = mu N T* / sqrt(|T*|^2 + (mu N)^2)``, was below ``T*`` at any load, so
          every commit turned part of a sticking corner's elastic displacement into slip: a
          loaded contact crept by a step at every load step, and the laboratory walls' shear-test
          peaks fell with the load step, 47 -> 36 kN from 25 to 200 checks a second on WI1.175,
          ``experiments/shear_test_convergence.py``.)

        Units: m, N, N/m."""
        k = self._corner_k[jc, kc]
        d = self.settings.smooth_m
        # compiled corner by corner, the numpy expressions' arithmetic in their order
        # (:mod:`._joint_kernels`; numpy's vector tanh, which libm's differs from, is taken here)
        from ._joint_kernels import contact_forces

        th = np.tanh(0.5 * (-gap[:, 2] / d))
        cap = self._corner_cap[jc, kc] if self.material.masonry_compressive_strength > 0 else np.zeros(0)
        return contact_forces(
            k, self.slip[jc, kc], np.ascontiguousarray(gap), th, self.material.friction, d, self.settings.slip_band, cap
        )

    def _corner_relative(self, jc, kc, U: np.ndarray) -> np.ndarray:
        """The relative displacement ``(C, 3)`` (u, v, n in the joint frame; ``d_n > 0`` opens) of
        the corners ``jc, kc`` under the motion ``U`` (6 B,)."""
        return np.einsum("cab,cb->ca", self._corner_L[jc, kc], U[self.dofs[jc]])

    def _corner_operator(self, jc, kc) -> sp.csr_matrix:
        """``P`` ``(3 C, 6 B)``: the map from every body's motion to the relative displacement of the
        contact corners ``jc, kc`` (u, v, n in each joint's frame): the corners' gaps are ``P U``,
        their forces act on the bodies as ``P^T F`` and their tangent adds ``P^T T P``."""
        C = jc.size
        indices = np.repeat(self.dofs[jc], 3, axis=0)  # (3 C, 12): each corner's three rows
        indptr = np.arange(0, 36 * C + 1, 12)
        data = self._corner_L[jc, kc].reshape(3 * C, 12)
        return sp.csr_matrix((data.ravel(), indices.ravel(), indptr), shape=(3 * C, 6 * self.nb))

    def _residual(self, K0, P, jc, kc, U, rhs):
        """Out-of-balance force ``(6 B,)`` at ``U`` and the contact corners' state there."""
        gap = (P @ U).reshape(-1, 3)
        F, T = self._contact_forces(jc, kc, gap)
        if self._transposed is None or self._transposed[0] is not P:
            # P's transpose (a csc view of its arrays) made once a solve, not at every residual
            self._transposed = (P, P.T)
        return K0 @ U - rhs + self._transposed[1] @ F.ravel(), (gap, T)

    def _tangent_of(self, held: np.ndarray | None) -> tuple[_Tangent, np.ndarray, np.ndarray | None]:
        """The contact iteration's matrix for the bodies ``held`` ``(B,)`` (None: all of them), its
        joints' places in it (``(J',)``, -1 for a joint outside) and the motion's entries it holds
        (``(6 B,)`` bool, None for all). Kept for the model's life (all) and the last few sets."""
        if held is None or held.all():
            if self._tangent is None:
                self._tangent = _Tangent(self.dofs, 6 * self.nb)
            return self._tangent, np.arange(self.n_all), None
        key = held.tobytes()
        if key not in self._sub_tangents:
            inside = held[self.a] & (self.ground | held[self.bb])
            local = np.full(self.n_all, -1, dtype=np.int64)
            local[inside] = np.arange(int(inside.sum()))
            keep = np.repeat(held, 6)
            place = np.cumsum(keep) - 1  # each kept entry's place in the smaller motion
            self._sub_tangents[key] = (_Tangent(place[self.dofs[inside]], int(keep.sum())), local, keep)
            while len(self._sub_tangents) > 4:
                self._sub_tangents.pop(next(iter(self._sub_tangents)))
        return self._sub_tangents[key]

    def _newton_step(self, intact, jc, kc, K0, P, T, r, held: np.ndarray | None = None) -> np.ndarray:
        """The step ``-J^-1 r`` for ``J = K0 + P^T T_s P``, with ``T_s`` the corners' tangents ``T``
        ``(C, 3, 3)`` without the friction's dependence on the normal displacement (``T[:, :2, 2]``,
        the only part that is not symmetric).

        ``J`` is then symmetric positive definite (``K0`` is, with the weak springs; each corner's
        normal stiffness and its shear stiffness at a fixed normal force are), so it is factorised
        by a sparse Cholesky factorisation (CHOLMOD's supernodal one, on a pattern fixed for the
        model's life: :class:`_Tangent`) instead of a general LU: on the paper example's 9,522
        unknowns 18 ms against SuperLU's 140 ms. The step is that of a
        quasi-Newton iteration: it converges to the same out-of-balance tolerance (linearly where
        corners slide under a changing normal force), in more but much cheaper steps. On the
        paper example's 0.3 g quake every joint cracks at the same frame in the same mode as with
        the exact tangent (202 joints; the joint model's 278 s -> 76 s). After a mechanism's onset
        the exact tangent's cascade changed with the tolerance; this iteration's, with crack rounds
        only from equilibria (:meth:`crack`), is the same from tolerance 1e-3 to 1e-5 on the
        Stylite tower's 0.3 g quake (experiments/joint_solver_settings.py).

        ``held`` ``(B,)``: the bodies that intact joints and contact corners tie to the ground
        (None: all). The others carry no joint force (each floats where its weak spring puts it,
        :meth:`_contact_newton`), so their step is zero and the matrix is factorised over the held
        bodies alone: once a quake has set a tower free, its few stones still on the ground cost
        a factorisation of their size, not the tower's."""
        tan, local, keep = self._tangent_of(held)

        def base() -> np.ndarray:
            idx = np.flatnonzero(intact & (local >= 0))
            diag = self._reg.diagonal()
            return tan.values(local[idx], self.Kj[idx][:, tan.ROW, tan.COL], diag if keep is None else diag[keep])

        Ts = T.copy()
        Ts[:, :2, 2] = 0.0
        Lc = self._corner_L[jc, kc]  # (C, 3, 12)
        TL = Ts @ Lc
        blocks = _corner_blocks(Lc, TL)  # (Lc^T Ts Lc)[ROW, COL]
        self.factorisations += 1
        try:
            inside = local[jc] >= 0  # contacts between two floating bodies are not in it
            values = tan.base(intact.tobytes(), base) + tan.values(local[jc][inside], blocks[inside])
            if keep is None:
                return -tan.solve(values, r)
            step = np.zeros_like(r)
            if keep.any():
                step[keep] = -tan.solve(values, r[keep])
            return step
        except ArithmeticError:  # not positive definite in floating point (not seen): a general LU
            C = len(T)
            rows = np.repeat(np.arange(3 * C).reshape(C, 3), 3, axis=0).ravel()
            Tm = sp.csr_matrix((Ts.ravel(), rows, np.arange(0, 9 * C + 1, 3)), shape=(3 * C, 3 * C))
            return spla.splu((K0 + P.T @ Tm @ P).tocsc(), **_LU_OPTIONS).solve(-r)

    def _contact_newton(self, intact, jc, kc, rhs, start: np.ndarray | None = None) -> np.ndarray:
        """The motion ``U`` (6 B,) that balances ``rhs`` with the contact corners ``jc, kc``, from
        ``start`` or the last committed motion (see the module docstring, "Cracked joints"). Stops
        without convergence when ``settings.stall_iter`` (ten) iterations have neither halved the
        out-of-balance force nor grown the motion tenfold (a mechanism's run-away)."""
        self.converged = True
        self.no_equilibrium = False
        self.solves += 1
        if jc.size == 0:
            return self._solve(intact, np.zeros((self.n_all, self.outline.shape[1]), bool), rhs)
        if start is not None:
            U = start.copy()
        else:
            U = self._U.copy() if self._U is not None else np.zeros_like(rhs)
        # a group of bodies that nothing in the model ties to the ground stands where its weak
        # springs put it (the uniform load over ``eps m``: a rigid translation that loads none of
        # its joints); starting it there saves the dozen capped steps it would take to get there
        free_bodies = self._free_bodies(intact, jc)
        held = ~free_bodies if free_bodies.any() else None
        free = np.repeat(free_bodies, 6)
        if free.any():
            U[free] = rhs[free] / self._reg.diagonal()[free]
        K0 = self._joint_matrix(intact)
        limit = self._tolerance(rhs)
        P = self._corner_operator(jc, kc)
        r, st = self._residual(K0, P, jc, kc, U, rhs)
        self.newton_iterations = 0
        self.converged = False
        history = []
        check = self.settings.check_equilibrium
        # the least out-of-balance iterate, in tolerances (kept only where a stall may be excused)
        best = (float(np.max(np.abs(r) / limit)), U) if check else None
        stall = self.settings.stall_iter
        for it in range(self.settings.max_iter):
            # a stop (SIGTERM) ends a check at its next iteration: one check of a large tower's
            # crack rounds can take minutes, and the run waits for its thread before it leaves
            raise_if_stopped()
            if np.all(np.abs(r) <= limit):
                self.converged = True
                break
            # the motion of the bodies something holds (a free body's place, g / eps, is a kilometre)
            moved = float(np.abs(U[~free]).max(initial=0.0))
            history.append((np.linalg.norm(r), moved))
            if len(history) > stall:
                (r10, u10), (rn, un) = history[-stall - 1], history[-1]
                if rn > 0.5 * r10 and un < 10.0 * u10:
                    break  # stalled
            gap, T = st
            norm0 = np.linalg.norm(r)
            dU = self._newton_step(intact, jc, kc, K0, P, T, r, held)
            # a step that would move anything by more than ``step_m`` (or three times the largest
            # motion so far) is shortened: a free body's full step is g / eps, metres; then halved
            # while it does not lower the out-of-balance force
            # (over the bodies something holds: measured with a free one the cap let a step throw
            # held stones a kilometre: a shear test whose sliver had just been let go diverged to
            # 1e11 N and let the whole wall go)
            cap = max(self.settings.step_m, 3.0 * moved)
            a = min(1.0, cap / max(float(np.abs(dU).max()), 1e-300))
            for _ in range(6):
                r_new, st_new = self._residual(K0, P, jc, kc, U + a * dU, rhs)
                if np.linalg.norm(r_new) < norm0:
                    break
                a *= 0.5
            else:
                # Newton's step does not lower the out-of-balance force (the contact law bends
                # within a few smoothing widths): a full step on the elastic stiffness of the
                # touching corners instead, the initial-stiffness iteration of plasticity
                Te = np.zeros_like(T)
                touch = gap[:, 2] < 0.0
                Te[touch] = self._corner_k[jc[touch], kc[touch]][:, :, None] * np.eye(3)
                dU = self._newton_step(intact, jc, kc, K0, P, Te, r, held)
                a = min(1.0, cap / max(float(np.abs(dU).max()), 1e-300))
                r_new, st_new = self._residual(K0, P, jc, kc, U + a * dU, rhs)
            U = U + a * dU
            r, st = r_new, st_new
            self.newton_iterations = it + 1
            if check:
                off = float(np.max(np.abs(r) / limit))
                if off < best[0]:
                    best = (off, U)
        if not self.converged:
            self.unconverged_solves += 1
            if check and self.has_equilibrium(
                intact, jc, kc, rhs, free_bodies, self._friction_capacity(jc, kc, P @ best[1])
            ):
                # the load has an equilibrium on these joints and contacts: the iteration stalled
                # short of it, and where its last steps took it (a fallback step is taken whatever
                # it does: kilometres, 1e11 N out of balance on a dry stone wall) is no mechanism
                self.stalled_in_equilibrium += 1
                U = best[1]
                r = self._residual(K0, P, jc, kc, U, rhs)[0]
            elif check and self._definitely_without_equilibrium(intact, jc, kc, rhs, free_bodies):
                # nor with the cone alone: the load is beyond the most the joints and contacts can
                # carry, a collapse whatever the flow rule, though the iterate may have moved by
                # micrometres (a dry stone wall's 400 iterations ended so from 0.129 g, its static
                # programme's load, and nothing was let go until 0.138 g): a mechanism (:meth:`crack`)
                self.no_equilibrium = True
                self.without_equilibrium += 1
            self.worst_unconverged = max(self.worst_unconverged, float(np.max(np.abs(r) / limit)))
        return U

    def _definitely_without_equilibrium(self, intact, jc, kc, rhs, free_bodies) -> bool:
        """Whether :meth:`has_equilibrium`, asked with Coulomb's cone alone, answers no; a question
        none of HiGHS's solvers answered is no collapse (whatever the capped question before it got)."""
        unanswered = self.unanswered
        return not self.has_equilibrium(intact, jc, kc, rhs, free_bodies) and unanswered == self.unanswered

    def _friction_capacity(self, jc, kc, gap: np.ndarray) -> np.ndarray:
        """``(C,)`` Coulomb's ``mu N`` of the contact corners ``jc, kc`` at their gaps ``gap`` (3 C,)."""
        F, _ = self._contact_forces(jc, kc, gap.reshape(-1, 3))
        return self.material.friction * np.maximum(-F[:, 2], 0.0)

    def has_equilibrium(
        self,
        intact: np.ndarray,
        jc: np.ndarray,
        kc: np.ndarray,
        rhs: np.ndarray,
        free_bodies: np.ndarray,
        shear_capacity: np.ndarray | None = None,
    ) -> bool:
        """Whether the load ``rhs`` (6 B,) on the bodies that something ties to the ground (not
        ``free_bodies``) is balanced by some set of forces that the joints ``intact`` (J',) and
        the contact corners ``jc, kc`` can carry: a static (lower-bound) programme, solved by HiGHS.

        A contact corner carries any compression ``N >= 0`` with its shear inside Coulomb's cone
        ``mu N``, taken as the inscribed square ``|F_u| + |F_v| <= mu N`` (exact along the joint's
        u and v axes, sqrt(2) weak along a diagonal: walls in their plane slide along an axis),
        and, given ``shear_capacity`` (C,) N, each of ``|F_u|`` and ``|F_v|`` within it too.

        An intact joint bears at its corners as contacts with its strength, each over its share
        ``A / k`` of the patch: a tension up to ``f_t A / k`` and a shear up to ``c A / k + mu N``
        (a plastic joint: more than the elastic stresses its crack criterion reads, so a load the
        programme refuses would crack it; carrying anything, an intact dry footing let a laboratory
        wall stand in the programme at 1.13 times its sliding load). A body whose rotation is held
        (a shear test's beam between fixed ends) is given any moment. The weak springs hold nothing.

        With the cone alone the programme is associative limit analysis: it finds equilibria the
        contacts, which slide without dilating, cannot reach (a stalled solve excused by it let the
        dry wall WI2.175 stand to its associative load, 0.259 g, on six of nine load rates and
        tolerances, where the non-associative programme gives 0.226 g). With the friction also held
        to ``mu N`` of the iteration's own state (the capacities a step of Gilbert, Casapulla &
        Ahmed's non-associative programme fixes) it excused the stalls below 0.23 g and none
        after: 0.232-0.234 g at all nine."""
        keep_rows = np.repeat(~free_bodies, 6)
        # the corners: the contacts' and every corner of each intact joint, which bears as a contact
        # with the joint's strength: a tension up to f_t and a cohesion c over its share of the patch
        ij, ik = np.nonzero(intact[:, None] & self.corner_mask)
        H = len(self.held_rotation)
        if jc.size + ij.size + H == 0:
            return not np.any(rhs[keep_rows])
        # the programme's matrix holds every corner of every joint and every body's rows, whichever
        # joints are intact, which corners touch and which bodies float: a question differs from
        # the last in its bounds alone, and HiGHS's dual simplex starts from the last answer's
        # basis (0.004-0.015 s against 0.45-0.6 s from scratch on a laboratory wall's 1,400
        # corners). Before, each crack round's joints made a new matrix, asked from scratch: on a
        # house of 590 bricks (10,684 rows, 35,720 columns) 15-39 s a question, where the next
        # round's question from the kept basis took 2.5 s (644 iterations). A corner that is
        # neither intact nor a contact is held at zero, a floating body's rows are free. The
        # questions with friction capped and those with the cone alone each have a model of their
        # own: a stalled solve asks both in turn, and the cone's question from the capped one's
        # answer (no) took the dual simplex's 1,000 iterations and then the interior point, 1.8 s
        # each on SW.100.1's drawing near its sliding load, where from the last cone question's
        # basis it starts next to its answer.
        if self._programme is None:
            aj, ak = np.nonzero(self.corner_mask)
            index = np.full(self.corner_mask.shape, -1, dtype=np.int64)
            index[aj, ak] = np.arange(aj.size)
            self._programme = (index, self._programme_matrix(aj, ak), {})
        index, A, models = self._programme
        kind = "capped" if shear_capacity is not None else "cone"
        if kind not in models:
            zero, free = np.zeros(A.shape[1]), np.full(A.shape[0], np.inf)
            models[kind] = _feasibility_programme(A, zero, zero, -free, free)
        h = models[kind]
        C = int(self.corner_mask.sum())
        ci, ii = index[jc, kc], index[ij, ik]
        # the unknowns: each corner's normal force F_n (in its joint's frame, on b; F_n < 0
        # presses), its shear in four non-negative parts F_u = u+ - u-, F_v = v+ - v-, and a held
        # rotation's moments: [F_n (C), u+ (C), u- (C), v+ (C), v- (C), M (3 H)]
        nvar = 5 * C + 3 * H
        lo, hi = np.zeros(nvar), np.zeros(nvar)
        # F_n <= f_t A_c (0 for a contact: no tension), and F_n >= -f_c A_c where the masonry's
        # crushing strength is given (-inf where not)
        hi[ii] = self.tensile_strength[ij] * self._corner_share[ij, 0]
        lo[ii] = -self._corner_cap[ij, ik]
        lo[ci] = -self._corner_cap[jc, kc]
        cap = np.inf if shear_capacity is None else np.asarray(shear_capacity, np.float64)
        for part in range(1, 5):
            hi[part * C + ii] = np.inf
            # and the contacts' friction within ``shear_capacity`` along u and along v
            hi[part * C + ci] = cap
        lo[5 * C :], hi[5 * C :] = -np.inf, np.inf
        # the bodies' equilibrium, then friction inside the square inscribed in Coulomb's cone,
        # c A_c + mu N, one row a corner (:meth:`_programme_matrix`)
        row_lo = np.concatenate([np.where(keep_rows, rhs, -np.inf), np.full(C, -np.inf)])
        row_hi = np.concatenate([np.where(keep_rows, rhs, np.inf), np.full(C, np.inf)])
        row_hi[6 * self.nb + ii] = self.cohesion[ij] * self._corner_share[ij, 0]
        row_hi[6 * self.nb + ci] = 0.0
        h.changeColsBounds(nvar, np.arange(nvar, dtype=np.int32), *_highs_bounds(lo, hi))
        h.changeRowsBounds(row_lo.size, np.arange(row_lo.size, dtype=np.int32), *_highs_bounds(row_lo, row_hi))
        answer = _feasible(h)
        if answer is None:
            self.unanswered += 1
        return bool(answer)

    def _programme_matrix(self, cj: np.ndarray, ck: np.ndarray) -> sp.csc_matrix:
        """The matrix of :meth:`has_equilibrium`'s programme on the corners ``cj, ck`` (C,): the
        equilibrium rows of every body (6 B; each corner's force on its two bodies,
        ``L^T F``; a held rotation's moments), then one friction row a corner,
        ``u+ + u- + v+ + v- + mu F_n`` (the square inscribed in Coulomb's cone: exact along the
        joint's u and v, sqrt(2) weak along a diagonal; the octagon, 7.6 % weak, made the programme
        1.6 times as slow on a laboratory wall's 1,400 corners). Unknowns as there."""
        C, H = cj.size, len(self.held_rotation)
        nvar = 5 * C + 3 * H
        Lc = self._corner_L[cj, ck]  # (C, 3, 12): each corner's (u, v, n) from its two bodies' motion
        dof = self.dofs[cj]  # (C, 12)
        rows, cols, vals = [], [], []
        for part, (e, sign) in enumerate(((2, 1.0), (0, 1.0), (0, -1.0), (1, 1.0), (1, -1.0))):
            rows.append(dof.ravel())
            cols.append(np.repeat(part * C + np.arange(C), 12))
            vals.append(sign * Lc[:, e, :].ravel())
        for q, k in enumerate(self.held_rotation):  # a held rotation: any moment on that body
            rows.append(6 * k + np.arange(3, 6))
            cols.append(5 * C + 3 * q + np.arange(3))
            vals.append(np.ones(3))
        A_eq = sp.coo_matrix(
            (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(6 * self.nb, nvar)
        ).tocsr()
        A_ub = sp.csr_matrix(
            (
                np.concatenate([np.full(C, self.material.friction), np.ones(4 * C)]),
                (np.tile(np.arange(C), 5), np.arange(5 * C)),
            ),
            shape=(C, nvar),
        )
        return sp.vstack([A_eq, A_ub]).tocsc()

    def _tolerance(self, rhs: np.ndarray) -> np.ndarray | float:
        """The out-of-balance force (and moment) at which the contact iteration has converged:
        ``settings.tol`` of the largest load on every entry (the heaviest body's), or with ``tol_per_body`` of each
        body's own (the largest component of its force; its moments times its size, the cube root of
        its volume), at least a thousandth of the heaviest body's."""
        if not self.settings.tol_per_body:
            return self.settings.tol * max(float(np.abs(rhs).max()), 1e-300)
        f = np.abs(rhs.reshape(-1, 6)[:, :3]).max(axis=1)
        heaviest = max(float(f.max()), 1e-300)
        own = self.settings.tol * np.maximum(f, 1e-3 * heaviest)
        return np.repeat(np.column_stack([own, own * self._size]), 3, axis=1).ravel()

    def _free_bodies(self, intact: np.ndarray, jc: np.ndarray) -> np.ndarray:
        """``(B,)`` True for the bodies that no chain of intact joints and contact corners ``jc``
        (joints may repeat) ties to the ground."""
        linked = intact.copy()
        linked[jc] = True
        return ~plate_linked(self.a, self.b, self.nb, linked)

    def commit(self) -> None:
        """Keep the last solve's slip of every contact corner (and its motion, the next solve's start):
        the end of a load step."""
        if self._last is None:
            return
        jc, kc, U = self._last
        self._U = U
        if jc.size:
            gap = self._corner_relative(jc, kc, U)
            F, _ = self._contact_forces(jc, kc, gap)
            k = self._corner_k[jc, kc]
            self.slip[jc, kc] = gap[:, :2] - F[:, :2] / np.maximum(k[:, :2], 1e-300)

    def state(self, U: np.ndarray, joints: np.ndarray | None = None) -> JointState:
        """Utilisation, governing criterion and forces of every mortar joint for the body motion ``U``
        (6 B,); of the mortar ``joints`` (indices) alone if given, the others' zero."""
        sel = slice(None, self.nj) if joints is None else joints
        part = self.state_from_relative(np.einsum("jab,jb->ja", self.L[sel], U[self.dofs[sel]]), joints)
        if joints is None:
            return part
        out = JointState(
            utilisation=np.zeros(self.nj),
            mode=np.zeros(self.nj, dtype=part.mode.dtype),
            forces=np.zeros((self.nj, 6)),
            relative=np.zeros((self.nj, 6)),
        )
        out.utilisation[joints] = part.utilisation
        out.mode[joints] = part.mode
        out.forces[joints] = part.forces
        out.relative[joints] = part.relative
        return out

    def utilisation_bound(self, U: np.ndarray) -> float:
        """An upper bound of the mortar joints' largest utilisation under the body motion ``U``
        (6 B,), at a third of :meth:`state`'s cost: the tension criterion without the no-tension
        section's relief of a compressed joint (which only lowers it). Below 1, nothing cracks."""
        m = self.material
        n = self.nj
        rel = np.einsum("jab,jb->ja", self.L[:n], U[self.dofs[:n]])
        forces = np.einsum("jab,jb->ja", self.D[:n], rel)
        ou, ov = self.outline[:n, :, 0], self.outline[:n, :, 1]
        sigma = self.stiffness.normal[:n, None] * (rel[:, 2:3] + rel[:, 3:4] * ov - rel[:, 4:5] * ou)
        tension = _ratio(sigma.max(axis=1), self.tensile_strength)
        compression = -sigma.min(axis=1) / m.compressive_strength
        polar = np.maximum(self.iuu[:n] + self.ivv[:n], 1e-30)
        tau = np.hypot(forces[:, 0], forces[:, 1]) / self.area[:n] + np.abs(forces[:, 5]) * self._farthest() / polar
        shear = _ratio(tau, self.cohesion + m.friction * np.maximum(0.0, -forces[:, 2] / self.area[:n]))
        return float(max(tension.max(initial=0.0), compression.max(initial=0.0), shear.max(initial=0.0)))

    def _farthest(self) -> np.ndarray:
        """``(nj,)`` each mortar joint's farthest outline corner from its centroid (m)."""
        if self._rmax is None:
            self._rmax = np.sqrt((self.outline[: self.nj] ** 2).sum(axis=2)).max(axis=1)
        return self._rmax

    def _outline_edges(self) -> tuple[np.ndarray, np.ndarray]:
        """:func:`_outline_edges` of the mortar joints' outlines, kept."""
        if self._edges is None:
            self._edges = _outline_edges(self.outline[: self.nj])
        return self._edges

    def state_from_relative(self, rel: np.ndarray, joints: np.ndarray | slice | None = None) -> JointState:
        """The same from every joint's relative displacement and rotation ``(J, 6)`` (d_u, d_v, d_n,
        r_u, r_v, r_n) in its frame; of the mortar ``joints`` (indices, ``(len(joints), 6)``) if given."""
        m = self.material
        n = slice(None, self.nj) if joints is None else joints
        forces = np.einsum("jab,jb->ja", self.D[n], rel)
        kn = self.stiffness.normal[n, None]
        outline, area, iuu, ivv = self.outline[n], self.area[n], self.iuu[n], self.ivv[n]
        ou, ov = outline[..., 0], outline[..., 1]
        sigma = kn * (rel[:, 2:3] + rel[:, 3:4] * ov - rel[:, 4:5] * ou)  # (J, K), tension positive
        tension = _ratio(sigma.max(axis=1), self.tensile_strength[n])
        # a compressed joint whose tensile corner has cracked stands as a no-tension section while
        # its compressive resultant stays inside the patch: it fails in bending only once the
        # resultant leaves the outline (rocking)
        fn = forces[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            ur = np.where(fn < 0, -forces[:, 4] / fn, 0.0)
            vr = np.where(fn < 0, forces[:, 3] / fn, 0.0)
        edge, real = self._outline_edges()
        inside = _inside_outline(outline, ur, vr, (edge[n], real[n]))
        tension = np.where((fn < 0) & inside, np.minimum(tension, 1.0 - 1e-12), tension)
        compression = -sigma.min(axis=1) / m.compressive_strength
        polar = np.maximum(iuu + ivv, 1e-30)
        rmax = self._farthest()[n]
        tau = np.hypot(forces[:, 0], forces[:, 1]) / area + np.abs(forces[:, 5]) * rmax / polar
        sigma_c = np.maximum(0.0, -forces[:, 2] / area)
        shear = _ratio(tau, self.cohesion[n] + m.friction * sigma_c)
        crit = np.stack([tension, compression, shear], axis=1)
        return JointState(utilisation=crit.max(axis=1), mode=crit.argmax(axis=1), forces=forces, relative=rel)

    def crack(
        self,
        g: np.ndarray,
        intact: np.ndarray,
        closed: np.ndarray | None = None,
        runaway_m: float | None = None,
        extra: np.ndarray | None = None,
        start: np.ndarray | None = None,
    ) -> tuple[np.ndarray, np.ndarray, JointState]:
        """The joints that crack under the load ``m g``, event by event: solve, crack the intact
        joints whose utilisation is over 1 and within ``settings.crack_band`` of the worst (10 % by
        default, the worst alone at 0), solve again on what is
        left, until no intact joint is over 1 (or ``max_rounds``). Once a solve has run away (a
        corner of a cracked joint still in the model, a contact that may touch, moving by more
        than ``runaway_m``: a mechanism), the rounds end and nothing more cracks in this load:
        the run-away iterate is no equilibrium, and its joint forces are set by where the
        iteration stopped. (An intact joint stretched as far is no mechanism but an elastic
        overload, a hundred times its strength: the rounds crack it. Counting such joints as a
        run-away let a vibrating tower, Stylite at 0.3 g, hold intact joints at 80-450 times their
        strength for 9 s, every frame's rounds ended before they cracked anything.) Returns
        the indices cracked (in order), the criterion each failed by, and the state of the last
        solve that was not a run-away (the joints' forces at a run-away iterate are no state the
        structure passes through), of the joints intact in that solve (the others' zero: only
        theirs decide a crack). ``extra``: forces on the bodies besides ``m g``; ``start``: where the
        first solve's iteration starts (see :meth:`solve`)."""
        intact = np.asarray(intact, dtype=bool)[: self.nj].copy()
        closed = None if closed is None else np.asarray(closed, dtype=bool).copy()
        cracked: list[np.ndarray] = []
        modes: list[np.ndarray] = []
        self.crack_round = self.cracked_in_rounds = 0
        state, _ = self.solve(g, intact, closed, start=start, extra=extra, joints=np.flatnonzero(intact))
        # the intact joints' utilisation before this call cracked any (CrackTracker's first check)
        self.uncracked_utilisation = np.where(intact, state.utilisation, 0.0)
        kept = state
        for rounds in range(self.settings.max_rounds + 1):
            if runaway_m is not None and (
                self.no_equilibrium
                or self._motion(self._last[2], np.flatnonzero(self._linked(intact, closed) & ~self._pad(intact))).max(
                    initial=0.0
                )
                > runaway_m
            ):
                break  # a mechanism: no equilibrium to crack more joints from (module docstring)
            kept = state
            util = np.where(intact, state.utilisation, 0.0)
            worst = float(util.max(initial=0.0))
            if worst <= 1.0 or rounds == self.settings.max_rounds:
                break
            new = np.flatnonzero(util >= max(1.0, (1.0 - self.settings.crack_band) * worst))
            intact[new] = False
            if closed is not None:
                closed[new] = True  # a joint that has just cracked still touches
            cracked.append(new)
            modes.append(state.mode[new])
            self.cracked_in_rounds += len(new)
            self.crack_round = rounds + 1  # the solve below is this round's
            # from the last round's motion
            state, _ = self.solve(g, intact, closed, start=self._last[2], extra=extra, joints=np.flatnonzero(intact))
        state = kept
        self.commit()
        if not cracked:
            return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64), state
        return np.concatenate(cracked), np.concatenate(modes), state

    def _linked(self, intact: np.ndarray, closed: np.ndarray | None) -> np.ndarray:
        """``(J',)`` the joints in the model: intact, or cracked with a contact corner that may touch.
        A body whose joints are all let go is held by its weak spring alone and moves by ``g / eps``
        (a kilometre), which says nothing about whether the structure has an equilibrium."""
        linked = self._pad(intact)
        linked |= (closed if closed is not None else self.corner_mask).any(axis=1)
        return linked

    @property
    def motion(self) -> np.ndarray | None:
        """The bodies' displacements and rotations ``(6 B,)`` of the last solve (None before any)."""
        return None if self._last is None else self._last[2]

    def corner_motion(self, joints: np.ndarray | None = None) -> np.ndarray:
        """The largest relative displacement ``(J',)`` (m) of each joint's corners in the last
        committed solve (0 before any); of the ``joints`` (indices) alone if given."""
        if self._U is None or self.n_all == 0:
            return np.zeros(self.n_all if joints is None else len(joints))
        return self._motion(self._U, joints)

    def _motion(self, U: np.ndarray, joints: np.ndarray | None = None) -> np.ndarray:
        """The largest relative displacement ``(J',)`` (m) of each joint's corners under the motion
        ``U``; ``(len(joints),)`` of the ``joints`` (indices) alone if given."""
        if self.n_all == 0:
            return np.zeros(0)
        sel = slice(None) if joints is None else joints
        rel = np.einsum("jkab,jb->jka", self._corner_L[sel], U[self.dofs[sel]])
        return np.linalg.norm(rel, axis=2).max(axis=1, initial=0.0)

    def release_factors(self) -> None:
        """Drop the kept LU factors. Call it on the thread that made them: scipy frees a SuperLU
        factor's memory only on the thread that allocated it, and a factor dropped on another
        thread leaks (scipy issue 15921; about 2 MB a run when the joint model ran ahead on a
        thread of its own and the run ended on the caller's: ``experiments/sim_memory.py``)."""
        self._lu.clear()

    def forget(self, joints: np.ndarray) -> None:
        """Drop the kept motion and the slip of these joints' corners: after a mechanism has run
        away in the model, its motion is no start for the next load."""
        self._U = None
        self.slip[joints] = 0.0

    def corner_gaps(
        self,
        positions: np.ndarray,
        rotations: np.ndarray,
        plate: np.ndarray,
        ref_positions: np.ndarray,
        ref_rotations: np.ndarray,
        plate0: np.ndarray,
    ) -> np.ndarray:
        """How far each joint's outline corners have opened ``(J, K)`` (m, along the joint normal as
        brick a carries it) between the reference poses and these."""
        p = self.corner_points()
        ground, bb = self.ground, self.bb
        Ra0, Rb0 = ref_rotations[self.a], ref_rotations[bb]
        qa = np.einsum("jba,jkb->jka", Ra0, p - ref_positions[self.a][:, None])
        qb = np.einsum("jba,jkb->jka", Rb0, p - ref_positions[bb][:, None])
        pa = np.einsum("jab,jkb->jka", rotations[self.a], qa) + positions[self.a][:, None]
        pb = np.einsum("jab,jkb->jka", rotations[bb], qb) + positions[bb][:, None]
        pb[ground] = p[ground] + (np.asarray(plate, dtype=np.float64) - np.asarray(plate0, dtype=np.float64))
        n = np.einsum("jab,jb->ja", rotations[self.a] @ np.transpose(Ra0, (0, 2, 1)), self.R[:, :, 2])
        return np.einsum("jka,ja->jk", pb - pa, n)

    def __repr__(self) -> str:
        return (
            f"JointModel({self.nb} bodies, {self.nj} joints, median k_n={np.median(self.stiffness.normal):.3g} N/m^3, "
            f"k_s={np.median(self.stiffness.shear):.3g} N/m^3)"
        )

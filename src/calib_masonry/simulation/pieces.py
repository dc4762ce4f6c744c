"""The pieces a ground motion sets free, as rigid bodies on their contacts, integrated to convergence.

Why this module exists. Once the joint model lets go of the cracked joints under a piece of the
structure (simulation/joints.py), Bullet moves the piece: its bodies turn dynamic and the held
joints among them become Bullet's rigid constraints. A piece of hundreds of bricks is then held
together only as far as Bullet's iterative solve converges, and how far it rocks or slides, and so
whether the structure counts as collapsed, changed with the solver's substeps and iterations (the
Stylite tower: a collapse PGA of 0.35 g at the defaults, 0.20 g at twice the substeps or the
iterations; docs/dynamics.md). The joint model never cracks a joint inside a piece once it is free,
so such a piece *is* one rigid body; this module moves it as one (and, if asked, checks its joints:
below).

The model (small strains, finite motion):

* A piece is a connected set of free bodies (no chain of held joints ties them to the ground), the
  held joints between them its internal ones: one rigid body with the summed mass, the inertia
  tensor about its centroid (the bodies' own plus the parallel-axis terms) and a rigid transform
  ``x -> R (x - c) + c + d`` from its place when the run began.
* It bears on the rest of the structure, on the plate and on other pieces at the outline corners of
  the joints the joint model let go (and, for bodies standing on the plate without a joint, of
  their footprint), with the joint model's corner springs (each corner its share of the joint's
  area times the joint's normal and shear stiffness, units and mortar in series): no tension,
  Coulomb friction with the material's coefficient (an elastic-plastic tangential spring whose slip
  is kept), and a dashpot at ``contact_damping`` of critical on each spring against the piece's
  mass (default 1: an impact does not rebound, as in Housner's rocking block, and the energy a
  rocking piece then loses per impact follows mostly from its geometry). It is a physical
  parameter (the impacts' restitution), not an accuracy setting: a verdict near a threshold may
  follow it (Stylite's seed 0 at 0.55 g, the default interval: damaged at 1 and at 0.5 on
  2026-12-03).
* The rest of the structure (held by its joints) is rigid and moves with the ground: its elastic
  vibration is not felt by the pieces resting on it (it is small against the motions that decide a
  collapse: a few millimetres at the roof).
* Loads: gravity and the ground's inertial force ``-m a_g(t)`` (the ground motion's mean
  acceleration over each step). A piece set free starts with the momentum and angular momentum of
  its bodies' elastic vibration at that moment (zero for a quasi-static run).
* Symplectic Euler with a step of ``1 / steps_per_period`` of the shortest period of any piece on
  its contact springs (all closed), so the step follows from the structure, not from Bullet's
  settings. A piece whose any body has moved ``fallen_m`` and that falls whatever the ground does
  from then on (its centroid beyond an edge of its support, moving away, and gravity's moment
  about that edge above what the record's largest acceleration still to come can turn against
  it: ``_Pieces.falls``) has fallen: it is no longer integrated (its bodies count as moved), and
  its contacts with other pieces are dropped.
* A piece still moving when the run ends whose kinetic energy reaches the least work that lifts its
  centroid over an edge of its support *may* overturn (``_Pieces.overturns``: with the ground still
  the contacts only dissipate, so below that bound it comes to rest, at whatever phase of a swing
  it is read); the bound leaves out the energy the next impact takes, so such a piece is played
  out: integrated on with the ground still until it falls (as above, with no acceleration to come)
  or its energy is below the bound, for at most ``play_out_s`` (then the bound answers;
  ``_Pieces.play_out``). Until 2026-12-03 the bound answered alone, and a tower swinging back
  with a little more than its tipping energy when the record ended counted as toppled.

A piece's own joints (``check_joints``; ``simulate --piece-joints``, off by default). Held together
by its joints, a rocking or sliding piece loads them with the forces that keep it rigid; without
this check nothing inside a piece ever cracks, and the paper example's box of 6 m walls stood at
1.5 g (docs/dynamics.md). Every ``scene.solver.check_interval_s`` each moving piece's bodies are
loaded with gravity and the ground's inertial force, the contact forces on them and minus their
share of the piece's rigid acceleration (``m (A + alpha x r + w x (w x r))``, ``I alpha + w x I
w``), all averaged over the interval (so an impact enters by its impulse, not by the penalty's
peak) and balanced per piece; the joint model's joints between them take these loads, intact ones
as mortar (its criteria) and cracked ones as contacts that carry compression alone (found by an
active-set iteration; their shear elastic), with the joint model's weak springs. Intact joints over
their strength crack in rounds as in the joint model (the worst within 10 %, solved again); a
cracked joint whose corners then move more than the joint model's ``release_m`` (a part nothing
holds under its load: metres, against microns) is let go, and the piece splits there, each part
moving on with its parent's velocity field. Under a ground motion (the run's Rayleigh damping
given, ``joint_dynamics``) a piece's joints vibrate: its first check is static (the piece was so
loaded in the structure it left), and each later one is a step over the interval of the L-stable
generalised-alpha rule (:func:`~calib_masonry.simulation.dynamics.l_stable_rhs`: the run's Rayleigh
damping is many times critical at a joint's own frequency, where Newmark's average acceleration
rang 10-13 % past the static force at the default intervals), ``M u'' + C u' + K u = f`` for the
bodies' elastic motion ``u`` relative to the piece's rigid motion, with the run's Rayleigh damping
on the same tangent; a part nothing holds then runs away over a few checks (the window's load
accelerates it) until its joint's corners have moved ``release_m``. A static check takes each
window's load at once, so the joints of a rocking piece took every impact's mean over the interval
as a static load and the verdict changed with the interval (docs/dynamics.md); a step load rings to
1.85 times its static force at 5 % damping, as a damped oscillator does, and rises to it without
ringing at a tower's damping (tests/test_pieces.py). The parts of a split start again from rest,
statically. With the check, a piece starts settled on its new contacts (``_Pieces._preload``,
``_settle_split``): on unloaded penalty springs it would drop onto them in a few milliseconds and
load its joints up to about 10 % above their static forces (tests/test_pieces.py).

The run's verdict reads the bodies in pieces that fell or overturn at the last time asked
(``PieceMotion.toppled``: collapsed from half of the bricks; simulation/results.py ``outcome``),
and reports the displacement of every body's centroid at every frame beside it (bricks moved,
roof drift); Bullet's own motion of the freed pieces is the animation, its count of bricks moved
reported beside the verdict.

Units: metres, kilograms, seconds, radians.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.sparse import coo_matrix, csr_matrix
from scipy.sparse.csgraph import connected_components

from ..errors import InputError
from ..progress import progress as _progress
from .dynamics import L_STABLE_MATRIX, l_stable_next, l_stable_rhs, mass_blocks
from .joints import _skew, _Tangent
from .scene import Scene

__all__ = ["PieceSettings", "PieceMotion", "piece_motion", "rigid_velocity"]


@dataclass(frozen=True)
class PieceSettings:
    """How the freed pieces are integrated (see the module docstring)."""

    steps_per_period: float = 20.0  # explicit steps per shortest contact period
    contact_damping: float = 1.0  # of critical, on every contact spring (1: an impact does not rebound)
    stiffness_factor: float = 1.0  # times the contacts' stiffness (a convergence check doubles it)
    # the contacts' stiffness is at most that which the piece's weight compresses by this fraction of
    # its size: a penalty, stiff enough that rocking and sliding do not feel it (measured: the
    # verdict does not change at a fifth of it, tests/test_pieces.py), and it keeps the explicit
    # step to about a millisecond instead of the joints' ~20 microseconds
    settle_fraction: float = 1e-4
    fallen_m: float = 0.5  # a piece that has moved this far (any body) has fallen
    # a piece still moving when the times asked end whose energy may overturn it (the bound of
    # _Pieces.overturns) is integrated on with the ground still, for at most this long, until it
    # rests or falls (_Pieces.play_out); one still undecided then is judged by the bound; 0: the bound
    play_out_s: float = 20.0
    # check the joints inside every piece against the forces that keep it rigid, once per joint-model
    # check interval (module docstring, "A piece's own joints"); False: a piece never cracks
    check_joints: bool = False
    # with check_joints and the run's Rayleigh damping: a piece's joints vibrate under the window's
    # loads (an L-stable step over each check interval, relative to the piece's rigid
    # motion) instead of taking each window's loads statically; a piece's first check is static
    joint_dynamics: bool = True

    def __post_init__(self) -> None:
        if not self.steps_per_period >= 4.0:
            raise InputError(f"piece steps_per_period {self.steps_per_period}: at least 4 (default 20)")
        if not 0.0 <= self.contact_damping <= 2.0:
            raise InputError(f"piece contact_damping {self.contact_damping}: a ratio of critical in [0, 2] (default 1)")
        if not self.stiffness_factor > 0.0 or not self.fallen_m > 0.0 or not self.settle_fraction > 0.0:
            raise InputError("piece stiffness_factor, settle_fraction and fallen_m must be > 0")
        if not self.play_out_s >= 0.0:
            raise InputError(f"piece play_out_s {self.play_out_s}: seconds, at least 0 (default 20)")


@dataclass(frozen=True)
class PieceMotion:
    """The freed pieces' motion at the asked times: ``displacement_m`` ``(T, B, 3)`` of every body's
    centroid from its place (0 for a body the joints hold; float32), ``pieces`` how many pieces
    there were at the end, ``fallen`` ``(B,)`` the bodies of pieces that fell, ``toppled`` ``(B,)``
    those and the bodies of pieces that overturn from where they are at the last time asked
    (played out on still ground, :meth:`_Pieces.play_out`),
    ``dt_s`` the (last) step, ``steps`` how many were taken and ``seconds`` the wall time."""

    time_s: np.ndarray
    displacement_m: np.ndarray
    pieces: int
    fallen: np.ndarray
    dt_s: float
    steps: int
    seconds: float = 0.0
    # (B,) the bodies of pieces that fell or overturn from their state at the last time asked
    # (played out on still ground, _Pieces.play_out): the verdict's, which does not read where a
    # rocking piece happens to be
    toppled: np.ndarray | None = None
    # (T, B, 3, 3) every body's rotation from its place (the identity for a body the joints hold;
    # float32), if asked for (``piece_motion(..., rotations=True)``): with ``displacement_m`` the
    # bodies' poses, for a run whose frames show the verdict's motion (no Bullet)
    rotation: np.ndarray | None = None
    # (J,) when a piece's own joints cracked and were let go (:meth:`_Pieces.check_joints`; NaN:
    # not in a piece, or never)
    crack_time_s: np.ndarray | None = None
    release_time_s: np.ndarray | None = None
    # (B,) when each body's piece fell (NaN: never), and (B, 6) the body's velocity then (m/s of its
    # centroid, rad/s; NaN rows where it never fell): where an engine takes the fall on from here
    fell_time_s: np.ndarray | None = None
    fell_velocity: np.ndarray | None = None

    def distance_m(self) -> np.ndarray:
        """``(T, B)`` every body's displacement's length."""
        return np.linalg.norm(self.displacement_m.astype(np.float64), axis=2)


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise cross product of ``(n, 3)`` arrays (numpy's ``cross`` costs ten times more on small ones)."""
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    out[:, 0] = a[:, 1] * b[:, 2] - a[:, 2] * b[:, 1]
    out[:, 1] = a[:, 2] * b[:, 0] - a[:, 0] * b[:, 2]
    out[:, 2] = a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]
    return out


def _rotate(R: np.ndarray, w: np.ndarray, exact: bool = True) -> np.ndarray:
    """``exp(skew(w)) R`` per piece (Rodrigues), re-orthonormalised if ``exact``."""
    th = np.linalg.norm(w, axis=1)
    small = th < 1e-12
    k = np.where(small[:, None], 0.0, w / np.where(small, 1.0, th)[:, None])
    K = _skew(k)
    s, c = np.sin(th)[:, None, None], (1.0 - np.cos(th))[:, None, None]
    E = np.eye(3) + s * K + c * (K @ K)
    out = E @ R
    if not exact:
        return out
    u, _, vt = np.linalg.svd(out)
    return u @ vt


def rigid_velocity(mass: np.ndarray, inertia: np.ndarray, x: np.ndarray, velocity: np.ndarray):
    """The velocity ``(v, omega)`` of one rigid body made of bodies of ``mass`` (n,), inertia
    tensors ``(n, 3, 3)`` about centroids ``x`` (n, 3), moving at ``velocity`` (n, 6) (centroid
    velocity, angular velocity): the one with their momentum and angular momentum."""
    M = mass.sum()
    c = (mass[:, None] * x).sum(axis=0) / M
    v = (mass[:, None] * velocity[:, :3]).sum(axis=0) / M
    r = x - c
    rr = (r * r).sum(axis=1)[:, None, None] * np.eye(3) - r[:, :, None] * r[:, None, :]
    inertia_c = inertia.sum(axis=0) + (mass[:, None, None] * rr).sum(axis=0)
    L = np.einsum("nij,nj->i", inertia, velocity[:, 3:]) + (mass[:, None] * np.cross(r, velocity[:, :3] - v)).sum(
        axis=0
    )
    return v, np.linalg.solve(inertia_c, L), c, inertia_c


class _Pieces:
    """The integrator's state: pieces, their contacts and the corners' slip."""

    def __init__(self, scene: Scene, model, inertia: np.ndarray, settings: PieceSettings) -> None:
        self.settings = settings
        self.model = model
        self.mass = model.mass
        self.x = model.x
        self.inertia = inertia
        self.gravity = float(scene.gravity)
        self.friction = float(scene.material.friction)
        self.body_size = np.array([np.cbrt(max(b.volume, 1e-9)) for b in scene.bodies])
        nb = model.nb
        self.piece_of = np.full(nb, -1)
        self.n = 0
        # per piece: reference centroid c, displacement d, rotation R, velocity v, angular velocity w
        self.c = np.zeros((0, 3))
        self.d = np.zeros((0, 3))
        self.R = np.zeros((0, 3, 3))
        self.v = np.zeros((0, 3))
        self.w = np.zeros((0, 3))
        self.M = np.zeros(0)
        self.I0 = np.zeros((0, 3, 3))
        self.alive = np.zeros(0, dtype=bool)
        self.fallen = np.zeros(nb, dtype=bool)
        self.final = np.zeros((nb, 3))  # displacement of the bodies of fallen pieces when they fell
        self.final_R = np.broadcast_to(np.eye(3), (nb, 3, 3)).copy()  # and their rotation
        self.fell_s = np.full(nb, np.nan)  # when each body's piece fell
        self.fell_v = np.full((nb, 6), np.nan)  # and the body's velocity then (centroid m/s, rad/s)
        self.t = 0.0  # the time the state is at (s since the ground began to move)
        # the ground's largest horizontal acceleration from a time on (m/s^2; _peak_after)
        self.ground_peak_after: Callable[[float], float] = _peak_after(scene.motion)
        K = model.outline.shape[1] if model.n_all else 0
        self.slip = np.zeros((model.n_all, K, 2))
        self.points = model.corner_points() if model.n_all else np.zeros((0, K, 3))
        k = model._corner_k * settings.stiffness_factor if model.n_all else np.zeros((0, K, 3))
        self.k = k
        # the joints inside the pieces: which are still mortar, and when they cracked or were let go
        self.intact = np.ones(model.nj, dtype=bool)
        self.held = np.ones(model.nj, dtype=bool)
        self.crack_time_s = np.full(model.nj, np.nan)
        self.release_time_s = np.full(model.nj, np.nan)
        # per group of bodies checked together: (_Tangent, joints' places, kept entries, last factor's key)
        self._solvers: dict[bytes, tuple] = {}
        # the pieces' own vibration (joint_dynamics): Rayleigh's (alpha, beta), None for static checks;
        # every body's elastic displacement, velocity and acceleration (6 B,) relative to its
        # piece's rigid motion, in the piece's frame, and whether a check has started them
        self.damping: tuple[float, float] | None = None
        self.eu = np.zeros(6 * nb)
        self.ev = np.zeros(6 * nb)
        self.ea = np.zeros(6 * nb)
        self.e_on = np.zeros(nb, dtype=bool)
        self.e_t = np.nan  # when the last check was made (s): a vibrating check's step runs from it
        self._open = np.zeros((model.n_all, K), dtype=bool)  # the cracked corners the last check found open
        # with check_joints, a new piece's contacts start loaded (_preload): each corner's offset
        # into its spring (m; the force it carries at zero gap is k times it)
        self.off = np.zeros((model.n_all, K))
        self._split_loads: np.ndarray | None = None
        self.g_now = np.array([0.0, 0.0, -self.gravity])  # the load per unit mass when pieces regroup
        self.new = np.zeros(0, dtype=bool)  # per piece: made of bodies that were not moving
        self._K78: np.ndarray | None = None
        self._window()

    # ---------------------------------------------------------------- pieces
    def regroup(self, free: np.ndarray, held: np.ndarray, velocity: np.ndarray | None) -> None:
        """Make the pieces of the ``free`` bodies (B,) joined by ``held`` joints (nj,): a piece
        splits with its parent's transform; bodies newly free start at rest where they are, with
        the momentum of ``velocity`` (B, 6) if given."""
        m = self.model
        nb = m.nb
        keep = held & free[m.a[: m.nj]] & (m.b[: m.nj] >= 0)
        keep &= free[np.where(m.b[: m.nj] >= 0, m.b[: m.nj], 0)]
        a, b = m.a[: m.nj][keep], m.b[: m.nj][keep]
        graph = coo_matrix((np.ones(len(a)), (a, b)), shape=(nb, nb))
        _, label = connected_components(graph, directed=False)
        ids = np.flatnonzero(free)
        groups = {}
        for j in ids:
            groups.setdefault(int(label[j]), []).append(int(j))
        old = (self.c, self.d, self.R, self.v, self.w, self.alive)
        old_of = self.piece_of.copy()
        c, d, R, v, w, M, I0, alive, size, new = [], [], [], [], [], [], [], [], [], []
        piece_of = np.full(nb, -1)
        for members in groups.values():
            idx = np.array(members)
            if self.fallen[idx].any():
                continue  # a fallen piece stays where it fell (its bodies already counted)
            vel = np.zeros((len(idx), 6)) if velocity is None else velocity[idx]
            vi, wi, ci, Ii = rigid_velocity(self.mass[idx], self.inertia[idx], self.x[idx], vel)
            parents = old_of[idx]
            p = parents[0]
            if p >= 0 and (parents == p).all():
                # a part of a piece already moving: the same transform and velocity field
                pc, pd, pR, pv, pw, _ = (o[p] for o in old)
                di = pR @ (ci - pc) + pc + pd - ci
                vi = pv + np.cross(pw, pR @ (ci - pc))
                wi = pw
                Ri = pR
                new.append(False)
            else:
                di, Ri = np.zeros(3), np.eye(3)
                new.append(True)
            piece_of[idx] = len(c)
            c.append(ci), d.append(di), R.append(Ri), v.append(vi), w.append(wi)
            M.append(self.mass[idx].sum()), I0.append(Ii), alive.append(True)
            size.append(float(np.ptp(self.x[idx], axis=0).max() + self.body_size[idx].mean()))
        self.n = len(c)
        self.piece_of = piece_of
        self.c = np.array(c).reshape(-1, 3)
        self.d = np.array(d).reshape(-1, 3)
        self.R = np.array(R).reshape(-1, 3, 3)
        self.v = np.array(v).reshape(-1, 3)
        self.w = np.array(w).reshape(-1, 3)
        self.M = np.array(M)
        self.I0 = np.array(I0).reshape(-1, 3, 3)
        self.alive = np.array(alive, dtype=bool)
        self.size = np.array(size)
        self.new = np.array(new, dtype=bool)
        self.held = held[: m.nj].copy()
        self._contacts(held)
        self._window()

    def _contacts(self, held: np.ndarray) -> None:
        """The contact corners: of the joints let go (and the plate contacts) between a piece and
        anything else."""
        m = self.model
        if m.n_all == 0 or self.n == 0:
            self.cj = self.ck = np.zeros(0, dtype=int)
            self.pa = self.pb = np.zeros(0, dtype=int)
            return
        let_go = np.ones(m.n_all, dtype=bool)
        let_go[: m.nj] = ~held
        pa = self.piece_of[m.a]
        pb = np.where(m.b >= 0, self.piece_of[np.maximum(m.b, 0)], -1)
        # a fallen piece's bodies (piece -1 now) are no ground to bear on: their contacts are gone
        gone = self.fallen[m.a] | np.where(m.b >= 0, self.fallen[np.maximum(m.b, 0)], False)
        use = let_go & (pa != pb) & ((pa >= 0) | (pb >= 0)) & ~gone
        jc, kc = np.nonzero(use[:, None] & m.corner_mask)
        self.cj, self.ck = jc, kc
        self.pa, self.pb = pa[jc], pb[jc]
        self.frame = m.R[jc]  # (C, 3, 3) columns u, v, n
        self.p = self.points[jc, kc]
        kc_ = self.k[jc, kc]
        # the penalty: no stiffer than the heaviest piece's weight compressing its contacts by
        # settle_fraction of its size, one factor for every contact (a light stone under a heavy
        # piece carries the heavy one's weight: its contacts must be as stiff)
        factor = np.zeros(self.n)
        for i in range(self.n):
            on = (self.pa == i) | (self.pb == i)
            total = float(kc_[on, 2].sum())
            if total > 0:
                cap = self.M[i] * self.gravity / (self.settings.settle_fraction * self.size[i])
                factor[i] = min(1.0, cap / total)
        f = float(factor.max(initial=0.0)) or 1.0
        self.kc = kc_ * f
        if self.settings.check_joints:
            self._preload()
        self._prepare()

    def _preload(self) -> None:
        """Start a new piece's contacts loaded (with ``check_joints``): a piece set free that bore
        on unloaded penalty springs would drop onto them, and their settling would load its joints
        up to ~10 % above their static forces, cracking joints that hold. A piece new from the
        joint model's release is settled statically on its contacts with the rest of the world
        (its load ``M g_now``; the tension-free corners found in a few passes; friction capped at
        ``mu N``; none where that load tips or lifts it) and its corners start with those forces.
        The offsets stay with the corners: a contact that opens closes again a settling short of
        its gap (about ``settle_fraction`` of the piece's size). The parts of a piece its own
        check splits are settled on the contacts between them (:meth:`_settle_split`); the forces
        of the last check that held the joint were tried for them (a solve near a mechanism: tens
        of times the parts' weight, and the Stylite tower fell at 0.1 g) and are not used."""
        cj, ck, kc = self.cj, self.ck, self.kc
        fresh = (self.off[cj, ck] == 0.0) & (self.slip[cj, ck] == 0.0).all(axis=1)
        if self._split_loads is not None:
            self._settle_split(fresh)
            self._split_loads = None
        for i in np.flatnonzero(self.new):
            side_b = self.pb == i
            on = ((self.pa == i) | side_b) & fresh
            other = np.where(side_b, self.pa, self.pb)
            on &= (other < 0) | ~self.new[np.maximum(other, 0)]  # two new pieces' contacts: left unloaded
            idx = np.flatnonzero(on)
            if len(idx) < 3:
                continue
            sgn = np.where(side_b[idx], 1.0, -1.0)
            r = (self.p[idx] - self.c[i]) @ self.R[i].T
            J = [
                np.concatenate([self.frame[idx, :, col], np.cross(r, self.frame[idx, :, col])], axis=1)
                for col in range(3)
            ]
            F = np.concatenate([self.M[i] * self.g_now, np.zeros(3)])
            act = np.ones(len(idx), dtype=bool)
            gap = None
            for _ in range(6):
                K = sum((J[col][act] * kc[idx[act], col][:, None]).T @ J[col][act] for col in range(3))
                try:
                    delta = np.linalg.solve(K, F)
                except np.linalg.LinAlgError:
                    break
                gap = np.stack([sgn * (J[col] @ delta) for col in range(3)], axis=1)  # b against a
                now = gap[:, 2] < 0.0
                if (now == act).all():
                    break
                act, gap = now, None
            if gap is not None:
                self._start_loaded(idx, act, gap, self.M[i] * float(np.linalg.norm(self.g_now)))

    def _settle_split(self, fresh: np.ndarray) -> None:
        """Start the contacts between the parts of a split loaded: each part needs from the others
        what it needed from the rest of its piece to move with it (the sum of its bodies' balanced
        loads of the check that split it); the parts are settled on the new contacts between them
        together (6 unknowns a part, tension-free corners dropped in a few passes, a weak spring
        for the group's own rigid motion), and none where that has no equilibrium (a part that
        falls off: a settle of more than ten times the mean)."""
        use = fresh & (self.pa >= 0) & (self.pb >= 0) & ~self.new[np.maximum(self.pa, 0)]
        use &= ~self.new[np.maximum(self.pb, 0)]
        idx = np.flatnonzero(use)
        if len(idx) < 3:
            return
        parts = np.unique(np.concatenate([self.pa[idx], self.pb[idx]]))
        place = np.full(self.n, -1)
        place[parts] = np.arange(len(parts))
        n6 = 6 * len(parts)
        loads = self._split_loads.reshape(-1, 6)
        F = np.zeros(n6)
        for q, i in enumerate(parts):
            bodies = np.flatnonzero(self.piece_of == i)
            f = loads[bodies, :3].sum(axis=0)
            mom = (np.cross(self.x[bodies] - self.c[i], loads[bodies, :3]) + loads[bodies, 3:]).sum(axis=0)
            F[6 * q : 6 * q + 3] = self.R[i] @ f
            F[6 * q + 3 : 6 * q + 6] = self.R[i] @ mom
        ia, ib = place[self.pa[idx]], place[self.pb[idx]]
        ra = np.einsum("cij,cj->ci", self.R[self.pa[idx]], self.p[idx] - self.c[self.pa[idx]])
        rb = np.einsum("cij,cj->ci", self.R[self.pb[idx]], self.p[idx] - self.c[self.pb[idx]])
        frames = self.frame[idx]  # the springs' directions, as advance() takes them
        kc = self.kc[idx]
        # each corner's gap change (b against a) per direction: rows of a (C, 3, 6 n) operator
        rows, cols, vals = [], [], []
        C = len(idx)
        for col in range(3):
            e = frames[:, :, col]
            for side, r, sgn in ((ib, rb, 1.0), (ia, ra, -1.0)):
                blk = sgn * np.concatenate([e, np.cross(r, e)], axis=1)  # (C, 6)
                rows.append(np.repeat(3 * np.arange(C) + col, 6))
                cols.append((6 * side[:, None] + np.arange(6)).ravel())
                vals.append(blk.ravel())
        G = csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(3 * C, n6))
        weak = 1e-9 * float(kc.max()) * np.ones(n6)
        act = np.ones(C, dtype=bool)
        gap = None
        for _ in range(8):
            k = (kc * act[:, None]).ravel()
            K = (G.T @ G.multiply(k[:, None])).toarray() + np.diag(weak)
            try:
                delta = np.linalg.solve(K, F)
            except np.linalg.LinAlgError:
                return
            gap = (G @ delta).reshape(C, 3)
            now = gap[:, 2] < 0.0
            if (now == act).all():
                break
            act, gap = now, None
        if gap is not None:
            weight = float(np.abs(F[2::6]).sum()) or float(self.M[parts].sum() * self.gravity)
            self._start_loaded(idx, act, gap, weight)

    def _start_loaded(self, idx: np.ndarray, act: np.ndarray, gap: np.ndarray, load_n: float) -> None:
        """Give the contact corners ``idx`` (into the contact set) that a settle left pressed
        (``act``) the forces of its gaps ``gap`` (C, 3; b against a): each an offset into its normal
        spring and a slip carrying its shear, capped at ``mu N``. Nothing where the settle has no
        equilibrium (a load ``load_n`` (N) that tips, lifts or drops a part off: a settle of more
        than ten times the mean one, ``load_n`` over the pressed corners' stiffness): those
        corners start on unloaded springs. (Shared by :meth:`_preload` and :meth:`_settle_split`.)"""
        if not act.any():
            return
        kk = self.kc[idx[act]]
        if float(-gap[act, 2].min()) > 10.0 * (load_n / float(kk[:, 2].sum())):
            return
        j, k = self.cj[idx[act]], self.ck[idx[act]]
        N = -kk[:, 2] * gap[act, 2]
        T = -kk[:, :2] * gap[act, :2]
        size = np.linalg.norm(T, axis=1)
        T = T * np.minimum(1.0, self.friction * N / np.maximum(size, 1e-300))[:, None]
        self.off[j, k] = -gap[act, 2]
        self.slip[j, k] = T / np.maximum(kk[:, :2], 1e-300)

    def step_size(self) -> float:
        """``1 / steps_per_period`` of the shortest period of a piece on its contacts, all closed."""
        shortest = np.inf
        for i in range(self.n):
            on = (self.pa == i) | (self.pb == i)
            if not on.any():
                continue
            r = self.p[on] - (self.c[i] + self.d[i])
            K = np.zeros((6, 6))
            for col in range(3):
                kk = self.kc[on, col]
                e = self.frame[on, :, col]  # (C, 3) the spring's direction
                J = np.concatenate([e, np.cross(r, e)], axis=1)  # (C, 6): d(e . x)/d(d, theta)
                K += (J * kk[:, None]).T @ J
            Mi = np.zeros((6, 6))
            Mi[:3, :3] = self.M[i] * np.eye(3)
            Mi[3:, 3:] = self.R[i] @ self.I0[i] @ self.R[i].T
            L = np.linalg.cholesky(Mi)
            Li = np.linalg.inv(L)
            top = float(np.linalg.eigvalsh(Li @ K @ Li.T).max())
            if top > 0:
                w = np.sqrt(top)
                # the explicit step's stability with stiffness-proportional damping (beta = 2 zeta / omega_0)
                zeta = self.settings.contact_damping * w * np.sqrt(self.M[i] / max(float(self.kc[on, 2].sum()), 1e-30))
                stable = 2.0 / w * (np.sqrt(1.0 + zeta**2) - zeta)
                shortest = min(shortest, 2.0 * np.pi / w / self.settings.steps_per_period, 0.5 * stable)
        return shortest

    # ---------------------------------------------------------------- motion
    def _prepare(self) -> None:
        """Per contact set: the sides as indices into the pieces with the still ground appended
        (index ``n``), the maps summing corner forces onto pieces, each corner's dashpot."""
        n = self.n
        self.sa = np.where(self.pa >= 0, self.pa, n)
        self.sb = np.where(self.pb >= 0, self.pb, n)
        C = len(self.cj)
        cols = np.arange(C)
        self.Sa = csr_matrix((np.ones(C), (self.sa, cols)), shape=(n + 1, C))
        self.Sb = csr_matrix((np.ones(C), (self.sb, cols)), shape=(n + 1, C))
        # the dashpot: contact_damping of critical against the lighter side's translation on all its
        # closed normal springs (stiffness-proportional: c = 2 zeta k sqrt(M / K))
        tot = np.asarray(self.Sa @ self.kc[:, 2] + self.Sb @ self.kc[:, 2]).ravel()[:n]
        Mg = np.concatenate([self.M, [np.inf]])
        lighter = np.where(Mg[self.sa] <= Mg[self.sb], self.sa, self.sb)
        beta = 2.0 * self.settings.contact_damping * np.sqrt(self.M[lighter] / np.maximum(tot[lighter], 1e-30))
        self.cdamp = self.kc * beta[:, None]
        self.fn = self.frame[:, :, 2].copy()
        self.fu = self.frame[:, :, 0].copy()
        self.fv = self.frame[:, :, 1].copy()
        self.I0inv = np.linalg.inv(self.I0) if n else np.zeros((0, 3, 3))
        self._count = 0
        # each corner's force on the bodies of the pieces on either side, and its lever from the
        # body's centroid (in the piece's frame): the loads on a piece's own joints (check_joints)
        self.o = self.off[self.cj, self.ck]
        if self.settings.check_joints:
            m = self.model
            ba, bb = m.a[self.cj], m.b[self.cj]
            on_a, on_b = self.pa >= 0, self.pb >= 0
            self.Ba = csr_matrix((np.ones(int(on_a.sum())), (ba[on_a], cols[on_a])), shape=(m.nb, C))
            self.Bb = csr_matrix((np.ones(int(on_b.sum())), (bb[on_b], cols[on_b])), shape=(m.nb, C))
            self.qa = self.p - self.x[ba]
            self.qb = self.p - self.x[np.maximum(bb, 0)]

    def advance(self, g: np.ndarray, dt: float) -> None:
        """One step of ``dt`` under the load ``g`` (3,) per unit mass."""
        n = self.n
        if n == 0:
            return
        F = self.M[:, None] * g[None, :]
        T = np.zeros((n, 3))
        if len(self.cj):
            z = np.zeros((1, 3))
            R = np.concatenate([self.R, np.eye(3)[None]])
            c = np.concatenate([self.c, z])
            cd = c + np.concatenate([self.d, z])
            v = np.concatenate([self.v, z])
            w = np.concatenate([self.w, z])
            ra = np.einsum("cij,cj->ci", R[self.sa], self.p - c[self.sa])
            rb = np.einsum("cij,cj->ci", R[self.sb], self.p - c[self.sb])
            gap = (rb + cd[self.sb]) - (ra + cd[self.sa])  # b against a
            vel = (v[self.sb] + _cross(w[self.sb], rb)) - (v[self.sa] + _cross(w[self.sa], ra))
            fu, fv, fn = self.fu, self.fv, self.fn
            du = np.stack([(gap * fu).sum(1), (gap * fv).sum(1)], axis=1)
            dn = (gap * fn).sum(1)
            vu = np.stack([(vel * fu).sum(1), (vel * fv).sum(1)], axis=1)
            vn = (vel * fn).sum(1)
            k, cdamp = self.kc, self.cdamp
            dn = dn - self.o  # a corner that started loaded (_preload) is that far into its spring
            closed = dn < 0.0
            N = np.maximum(np.where(closed, -k[:, 2] * dn - cdamp[:, 2] * vn, 0.0), 0.0)
            s = self.slip[self.cj, self.ck]
            # the tangential spring and dashpot, capped at Coulomb's limit mu N; where it is reached,
            # the spring's slip is kept so that it carries that force; an open corner sticks again
            # where it next touches
            trial = -k[:, :2] * (du - s) - cdamp[:, :2] * vu
            limit = self.friction * N
            size = np.sqrt((trial**2).sum(1))
            over = size > limit
            Tt = trial * np.where(over, limit / np.maximum(size, 1e-300), 1.0)[:, None]
            s = np.where(over[:, None], du + Tt / np.maximum(k[:, :2], 1e-300), s)
            s = np.where(closed[:, None], s, du)
            self.slip[self.cj, self.ck] = s
            Tt = Tt * closed[:, None]
            fb = fn * N[:, None] + fu * Tt[:, :1] + fv * Tt[:, 1:]  # on side b; -fb on side a
            F += (self.Sb @ fb - self.Sa @ fb)[:n]
            T += (self.Sb @ _cross(rb, fb) - self.Sa @ _cross(ra, fb))[:n]
            if self.settings.check_joints:
                la = np.einsum("cij,cj->ci", R[self.sa], self.qa)
                lb = np.einsum("cij,cj->ci", R[self.sb], self.qb)
                self.acc_F += dt * (self.Bb @ fb - self.Ba @ fb)
                self.acc_T += dt * (self.Bb @ _cross(lb, fb) - self.Ba @ _cross(la, fb))
        self.acc_g += dt * g
        self.acc_t += dt
        live = self.alive
        Rt = np.transpose(self.R, (0, 2, 1))
        Iw = self.R @ self.I0 @ Rt
        Iinv = self.R @ self.I0inv @ Rt
        gyro = _cross(self.w, np.einsum("nij,nj->ni", Iw, self.w))
        dw = np.einsum("nij,nj->ni", Iinv, T - gyro)
        self.v[live] += dt * F[live] / self.M[live, None]
        self.w[live] += dt * dw[live]
        self.d[live] += dt * self.v[live]
        self._count += 1
        self.R[live] = _rotate(self.R[live], dt * self.w[live], exact=self._count % 64 == 0)

    def advance_many(self, g: np.ndarray, dt: float) -> None:
        """Steps of ``dt`` under the loads ``g`` (S, 3) per unit mass, one after the other: compiled
        (simulation/_pieces_step.py) where no piece's joints are checked, :meth:`advance` each
        otherwise (the check sums the contact forces on each body over the steps)."""
        if self.n == 0 or len(g) == 0:
            return
        if self.settings.check_joints:
            for row in g:
                self.advance(row, dt)
            return
        from ._pieces_step import advance_steps

        jc, kc = self.cj, self.ck
        slip = np.ascontiguousarray(self.slip[jc, kc])
        self._count = advance_steps(
            np.ascontiguousarray(g, dtype=np.float64),
            float(dt),
            self._count,
            self.R,
            self.c,
            self.d,
            self.v,
            self.w,
            self.M,
            self.I0,
            self.I0inv,
            self.alive,
            self.sa,
            self.sb,
            self.p,
            self.fu,
            self.fv,
            self.fn,
            self.kc,
            self.cdamp,
            self.o,
            slip,
            self.friction,
        )
        self.slip[jc, kc] = slip

    # ---------------------------------------------------------------- a piece's own joints
    def _window(self) -> None:
        """Start a new window over which the loads on the pieces' joints are averaged."""
        nb = self.model.nb
        self.acc_F = np.zeros((nb, 3))
        self.acc_T = np.zeros((nb, 3))
        self.acc_g = np.zeros(3)
        self.acc_t = 0.0
        self.v0 = self.v.copy()
        self.w0 = self.w.copy()

    def _internal(self) -> np.ndarray:
        """``(J,)`` the held joints between two bodies of one piece still moving."""
        m = self.model
        nj = m.nj
        if nj == 0 or self.n == 0:
            return np.zeros(nj, dtype=bool)
        b = m.b[:nj]
        pa = self.piece_of[m.a[:nj]]
        pb = np.where(b >= 0, self.piece_of[np.maximum(b, 0)], -1)
        live = np.zeros(nj, dtype=bool)
        on = pa >= 0
        live[on] = self.alive[pa[on]]
        return self.held & (pa == pb) & live

    def _joint_loads(self, bodies: np.ndarray) -> np.ndarray:
        """``(6 B,)`` the forces and moments on the ``bodies`` (B,) of the pieces, averaged over the
        window, in each piece's own frame (where the joint model's joints are): gravity and the
        ground's inertial force, the contacts, less the body's share of its piece's rigid motion
        (``m (A + alpha x r + w x (w x r))`` and ``I alpha + w x I w``). What the averages leave out of
        balance (the piece turns within the window) is taken out as a rigid acceleration of the
        piece, so that each piece's loads balance and strain its joints alone."""
        h = self.acc_t
        out = np.zeros((self.model.nb, 6))
        idx = np.flatnonzero(bodies)
        p = self.piece_of[idx]
        R = self.R[p]
        Rt = np.transpose(R, (0, 2, 1))
        r = np.einsum("nij,nj->ni", R, self.x[idx] - self.c[p])
        A = (self.v - self.v0) / h
        alpha = (self.w - self.w0) / h
        w = self.w[p]
        acc = A[p] + _cross(alpha[p], r) + _cross(w, _cross(w, r))
        F = self.mass[idx, None] * (self.acc_g / h - acc) + self.acc_F[idx] / h
        Iw = R @ self.inertia[idx] @ Rt
        T = self.acc_T[idx] / h - np.einsum("nij,nj->ni", Iw, alpha[p]) - _cross(w, np.einsum("nij,nj->ni", Iw, w))
        Ftot = np.zeros((self.n, 3))
        Mtot = np.zeros((self.n, 3))
        np.add.at(Ftot, p, F)
        np.add.at(Mtot, p, _cross(r, F) + T)
        Ip = self.R @ self.I0 @ np.transpose(self.R, (0, 2, 1))
        dA = Ftot / self.M[:, None]
        dalpha = np.linalg.solve(Ip, Mtot[..., None])[..., 0]
        F -= self.mass[idx, None] * (dA[p] + _cross(dalpha[p], r))
        T -= np.einsum("nij,nj->ni", Iw, dalpha[p])
        out[idx, :3] = np.einsum("nij,nj->ni", Rt, F)
        out[idx, 3:] = np.einsum("nij,nj->ni", Rt, T)
        return out.ravel()

    def _internal_motion(
        self, bodies: np.ndarray, intact: np.ndarray, cracked: np.ndarray, rhs: np.ndarray, step: float | None = None
    ):
        """The bodies' motion ``(6 B,)`` under ``rhs`` on the ``intact`` joints (J,) as mortar and the
        ``cracked`` ones (indices) as contacts that carry compression alone (their corners found by
        an active-set iteration; their shear elastic), with the joint model's weak springs: the
        balanced loads strain the joints, and a part that nothing holds under its load moves by
        ``g / eps`` (metres). With a ``step`` (s), the motion at its end from the bodies' elastic
        state (``eu``, ``ev``, ``ea``) by the L-stable generalised-alpha rule with Rayleigh damping on
        the same tangent: ``(c_k K + c_m M) u = f + M (...) + C (...)``; a part nothing holds then
        moves by its acceleration over the step, and on over the next ones."""
        m = self.model
        key = bodies.tobytes()
        if key not in self._solvers:
            if len(self._solvers) >= 4:
                self._solvers.pop(next(iter(self._solvers)))
            nj = m.nj
            b = m.b[:nj]
            inside = bodies[m.a[:nj]] & (b >= 0) & bodies[np.maximum(b, 0)]
            local = np.full(nj, -1, dtype=np.int64)
            local[inside] = np.arange(int(inside.sum()))
            keep = np.repeat(bodies, 6)
            place = np.cumsum(keep) - 1
            self._solvers[key] = (_Tangent(place[m.dofs[:nj][inside]], int(keep.sum())), local, keep, [None], [None])
        tan, local, keep, last, mass = self._solvers[key]
        corners = m.corner_mask[cracked]
        cj = np.repeat(cracked, corners.sum(axis=1))
        ck = np.nonzero(corners)[1]
        # each crack's corners start as the last check left them (a new crack closed)
        active = ~self._open[cj, ck]
        idx = np.flatnonzero(intact)
        U = np.zeros(6 * m.nb)
        if self._K78 is None:
            self._K78 = m.Kj[:, tan.ROW, tan.COL]  # (J', 78): each joint's block as the tangent sums it

        def base() -> np.ndarray:
            return tan.values(local[idx], self._K78[idx], m._reg.diagonal()[keep])

        blocks = None
        if len(cj):
            Lc = m._corner_L[cj, ck]
            blocks = np.einsum("cai,ca,caj->cij", Lc, m._corner_k[cj, ck], Lc)[:, tan.ROW, tan.COL]
        b_rhs = rhs[keep]
        if step is not None:
            h = float(step)
            alpha, beta = self.damping
            if mass[0] is None:
                ids = np.flatnonzero(bodies)
                blk = mass_blocks(self.mass[ids], self.inertia[ids])
                mass[0] = (tan.body_values(np.arange(6 * len(ids)).reshape(-1, 6), blk), blk)
            mv, blk = mass[0]
            u, v, a = self.eu[keep], self.ev[keep], self.ea[keep]

            def M(x: np.ndarray) -> np.ndarray:
                return np.einsum("nij,nj->ni", blk, x.reshape(-1, 6)).ravel()

            # l_stable_rhs's matrix, K + 2 M / h^2 + 3 C / (2 h), as multiples of the tangent and the mass
            q_m, q_c = L_STABLE_MATRIX
            c_m, c_k = q_m / h**2 + q_c * alpha / h, 1.0 + q_c * beta / h
        for rounds in range(len(cj) + 1):
            fkey = (intact.tobytes(), np.packbits(active).tobytes(), step)
            if last[0] != fkey or step is not None:
                values = tan.base(intact.tobytes(), base)
                if active.any():
                    values = values + tan.values(local[cj[active]], blocks[active])
                if step is not None:
                    stiff = values
                    b_rhs = l_stable_rhs(rhs[keep], M, lambda x: tan.matvec(stiff, x), u, v, a, h, alpha, beta)
                    values = c_k * values + c_m * mv
                if last[0] != fkey:
                    tan.factor(values)
                    last[0] = fkey
            U[keep] = tan.solve_factored(b_rhs)
            if not len(cj):
                break
            closed = m._corner_relative(cj, ck, U)[:, 2] < 0.0
            # the first pass opens and closes; then corners only open (the pulled ones), so that the
            # iteration ends (a no-tension active set can cycle), at most once per corner
            new = closed if rounds == 0 else active & closed
            if (new == active).all():
                break
            active = new
        self._open[cj, ck] = ~active
        return U

    def check_joints(self, t: float) -> np.ndarray:
        """Check the joints inside the moving pieces under the loads that keep each piece rigid,
        averaged since the last check: crack the intact ones over their strength (the joint
        model's criteria, rounds as :meth:`JointModel.crack`'s: the worst within 10 %, solved
        again), and let go the cracked ones whose corners a part that nothing holds moves by more
        than the joint model's ``release_m`` (the piece splits where its joints can no longer hold
        it together). Returns the joints let go (indices)."""
        released = np.zeros(0, dtype=np.int64)
        if not self.settings.check_joints:
            return released  # the default: a piece never cracks, and no window is kept
        internal = self._internal()
        if self.acc_t <= 0.0 or not internal.any():
            self._window()
            return released
        m = self.model
        nj = m.nj
        bodies = np.zeros(m.nb, dtype=bool)
        bodies[m.a[:nj][internal]] = True
        bodies[m.b[:nj][internal]] = True
        rhs = self._joint_loads(bodies)
        if self.damping is None:
            released = self._check_group(bodies, internal, rhs, t, None)
        else:
            # a piece's first check is static (it was loaded so in the structure it left), then
            # it vibrates from there; a piece's bodies are all new or all started
            parts = []
            # the step from the last check (a regroup since then restarts the load's window, not the
            # vibration's clock)
            since = t - self.e_t if np.isfinite(self.e_t) and t > self.e_t else self.acc_t
            for group, step in ((bodies & ~self.e_on, None), (bodies & self.e_on, since)):
                if group.any():
                    inside = internal & group[m.a[:nj]] & group[np.maximum(m.b[:nj], 0)]
                    parts.append(self._check_group(group, inside, rhs, t, step))
            released = np.concatenate(parts) if parts else released
            if released.size:
                # the parts of a split start again from rest, statically (their split is rigid motion)
                split = np.unique(self.piece_of[np.concatenate([m.a[released], m.b[released]])])
                again = np.isin(self.piece_of, split[split >= 0])
                self.e_on[again] = False
                dof = np.repeat(again, 6)
                self.eu[dof] = self.ev[dof] = self.ea[dof] = 0.0
        self.release_time_s[released] = t
        self.e_t = t
        # what each body needs from the rest of its piece to move with it (its balanced load): the
        # parts a split makes need it from the contacts between them (_preload)
        self._split_loads = rhs if released.size else None
        self._window()
        return released

    def _check_group(
        self, bodies: np.ndarray, internal: np.ndarray, rhs: np.ndarray, t: float, step: float | None
    ) -> np.ndarray:
        """:meth:`check_joints` on the ``bodies`` (B,) and their ``internal`` joints (J,):
        statically, or (a ``step``) as the step of their vibration that ends at ``t``, kept as
        their elastic state. Returns the joints let go."""
        m = self.model
        released = np.zeros(0, dtype=np.int64)
        for _ in range(m.settings.max_rounds + 1):
            intact = internal & self.intact
            cracked = np.flatnonzero(internal & ~self.intact)
            U = self._internal_motion(bodies, intact, cracked, rhs, step)
            if cracked.size:
                moved = cracked[m._motion(U, cracked) > m.settings.release_m]
                if moved.size:
                    released = moved
                    break
            idx = np.flatnonzero(intact)
            if not idx.size:
                break
            util = m.state(U, idx).utilisation[idx]
            worst = float(util.max())
            if worst <= 1.0:
                break
            new = idx[util >= max(1.0, 0.9 * worst)]
            self.intact[new] = False
            self.crack_time_s[new] = t
        self._last_U = U  # the last solve's motion (a test reads a static check's forces from it)
        if self.damping is not None:
            dof = np.repeat(bodies, 6)
            if step is None:
                self.ev[dof] = self.ea[dof] = 0.0
            else:
                self.ev[dof], self.ea[dof] = l_stable_next(
                    self.eu[dof], U[dof], self.ev[dof], self.ea[dof], float(step)
                )
            self.eu[dof] = U[dof]
            self.e_on[bodies] = True
        return released

    def rotation(self) -> np.ndarray:
        """(B, 3, 3) every body's rotation from its place: its piece's (a fallen piece's as it fell,
        its state is no longer advanced), the identity for a body the joints hold."""
        out = self.final_R.copy()
        on = self.piece_of >= 0
        out[on] = self.R[self.piece_of[on]]
        return out

    def displacement(self) -> np.ndarray:
        """(B, 3) every body's centroid displacement (fallen ones as they fell)."""
        out = self.final.copy()
        on = self.piece_of >= 0
        if on.any():
            i = self.piece_of[on]
            x = self.x[on]
            out[on] = np.einsum("nij,nj->ni", self.R[i], x - self.c[i]) + self.c[i] + self.d[i] - x
        return out

    def _support(self, i: int):
        """Piece ``i``'s support (the plan hull of its contact corners on bed-like faces, within 45
        degrees of level, below its centroid) where it is now: ``(edges, c)``, each edge ``(p1,
        axis, out)`` (a hull vertex, the unit edge direction and the unit outward normal in plan;
        the vertices run counter-clockwise) and ``c`` the centroid; None where there is no such
        support (fewer than three corners, or all on one line: a knife edge)."""
        from scipy.spatial import ConvexHull, QhullError

        on = (self.pa == i) | (self.pb == i)
        if not on.any():
            return None
        R, c = self.R[i], self.c[i] + self.d[i]
        pts = (self.p[on] - self.c[i]) @ R.T + c  # the corners on this piece, where they are now
        normal_z = (self.fn[on] @ R.T)[:, 2]
        support = pts[(np.abs(normal_z) >= np.sqrt(0.5)) & (pts[:, 2] < c[2])]
        if len(support) < 3:
            return None
        try:
            hull = ConvexHull(support[:, :2])
        except QhullError:  # on one line: a knife edge, no support polygon
            return None
        edges = []
        for q in range(len(hull.vertices)):
            p1 = support[hull.vertices[q]]
            axis = support[hull.vertices[(q + 1) % len(hull.vertices)]] - p1
            if np.linalg.norm(axis) < 1e-12:
                continue
            axis = axis / np.linalg.norm(axis)
            out = np.array([axis[1], -axis[0]])
            edges.append((p1, axis, out / max(float(np.linalg.norm(out)), 1e-300)))
        return edges, c

    def _energy(self, i: int) -> tuple[float, float, float] | None:
        """Piece ``i``'s kinetic energy, the least work that lifts its centroid over an edge of its
        support (:meth:`_support`; zero over an edge the centroid is already beyond) and the
        weight times the contacts' settling (``settle_fraction`` of its size, what the penalty
        springs allow): J each; None where it has no support."""
        found = self._support(i)
        if found is None:
            return None
        edges, c = found
        g = self.gravity
        work = np.inf
        for p1, axis, out in edges:
            d = c - p1
            if float(out @ d[:2]) >= 0.0:
                work = 0.0  # the centroid is beyond this edge: it falls over it
                break
            along = float(d @ axis)
            r = float(np.linalg.norm(d - along * axis))
            top = p1[2] + along * axis[2] + r * np.sqrt(max(0.0, 1.0 - axis[2] ** 2))
            work = min(work, self.M[i] * g * (top - c[2]))
        R = self.R[i]
        Iw = R @ self.I0[i] @ R.T
        kinetic = 0.5 * self.M[i] * float(self.v[i] @ self.v[i]) + 0.5 * float(self.w[i] @ Iw @ self.w[i])
        return kinetic, max(work, 0.0), self.M[i] * g * self.settings.settle_fraction * self.size[i]

    def overturns(self, i: int) -> bool | None:
        """Whether piece ``i`` may overturn from its present state with the ground still: its
        kinetic energy reaches the least work that lifts its centroid over an edge of its support,
        plus the contacts' settling (:meth:`_energy`). Mechanical energy only falls once the ground
        is still (the contacts dissipate), so a piece below that bound comes to rest and one above
        it may overturn (the next impact may take what it has above): the answer does not depend on
        where in its rocking the piece is. While the ground still moves it may put energy in or
        take it out: :meth:`falls` then. None where the piece has no support."""
        found = self._energy(i)
        if found is None:
            return None
        kinetic, work, settle = found
        # a Python bool: numpy's False is not the ``False`` singleton (an ``is not False`` once took
        # every answer for yes)
        return bool(kinetic >= work + settle)

    def falls(self, i: int, ground_peak: float) -> bool | None:
        """Whether piece ``i`` falls whatever the ground does from now on, its acceleration at most
        ``ground_peak`` (m/s^2, horizontal): its centroid is beyond an edge of its support
        (:meth:`_support`), moving away from it, and gravity's moment about that edge exceeds the
        largest the ground's inertial force can turn against it, ``g e > a h`` (``e`` the
        centroid's plan distance beyond the edge, ``h`` its height above it). The piece's angular
        acceleration about the edge then points outward whatever the ground does, and as it turns
        on ``e`` grows and ``h`` shrinks: it cannot come back. With ``ground_peak`` 0: beyond an
        edge and moving away. None where the piece has no support."""
        found = self._support(i)
        if found is None:
            return None
        edges, c = found
        for p1, axis, out in edges:
            d = c - p1
            e = float(out @ d[:2])
            h = float(d[2] - (d @ axis) * axis[2])
            if e > 0.0 and float(out @ self.v[i][:2]) >= 0.0 and self.gravity * e > ground_peak * max(h, 0.0):
                return True
        return False

    def play_out(
        self, pieces: np.ndarray, limit_s: float, stopped: Callable[[], bool] | None = None
    ) -> np.ndarray | None:
        """Whether each of ``pieces`` (indices) topples, integrated on with the ground still from
        where they are: a piece falls once a body has moved ``fallen_m`` and it falls (:meth:`falls`
        with no ground acceleration; by the distance alone where it has no bed support, as
        :meth:`check_fallen`), and rests once its energy is below the bound of :meth:`overturns`
        by the contacts' settling (:meth:`_energy`: it cannot lift its centroid over an edge any
        more, with the ground still the contacts only take energy out). Every piece moves on
        meanwhile (those decided too: a resting one still bears on its neighbours); none is
        stopped, so :attr:`fallen` and the motion read so far are left as they were. A piece that
        neither rests nor falls within ``limit_s``: the bound answers for it. ``stopped()`` asked
        every 64 steps: None at once if it says so."""
        pieces = np.asarray(pieces, dtype=np.int64)
        answer: dict[int, bool] = {}
        dt = self.step_size()
        if pieces.size and np.isfinite(dt) and limit_s > 0.0:
            chunk = 64
            loads = np.repeat(np.array([[0.0, 0.0, -self.gravity]]), chunk, axis=0)
            end = self.t + limit_s
            while len(answer) < pieces.size and self.t < end - 1e-12:
                self.advance_many(loads, dt)
                self.t += chunk * dt
                if stopped is not None and stopped():
                    return None
                dist = np.linalg.norm(self.displacement(), axis=1)
                for i in pieces:
                    i = int(i)
                    if i in answer:
                        continue
                    if dist[self.piece_of == i].max() > self.settings.fallen_m and self.falls(i, 0.0) is not False:
                        answer[i] = True
                        continue
                    energy = self._energy(i)
                    # below the lift by the settling's margin (a piece left at its apex's energy by
                    # an impact creeps over it or back as the springs' energy decides: played on)
                    if energy is not None and energy[0] + energy[2] < energy[1]:
                        answer[i] = False
        return np.array([answer[int(i)] if int(i) in answer else bool(self.overturns(int(i))) for i in pieces], bool)

    def check_fallen(self) -> bool:
        """Stop the pieces that have fallen; True if any did (their contacts are dropped). A piece has
        fallen once a body has moved ``fallen_m`` and it falls whatever the ground does from now on
        (:meth:`falls`, the ground's largest acceleration to come from ``ground_peak_after``); by
        the distance alone where it has no bed support. The energy bound (:meth:`overturns`) is
        not a stop: it holds on still ground only, and even there says "may": measured on a 2 x 2
        x 8 m column it stopped as fallen swings that, integrated on, came back (tests/test_pieces.py),
        and until 2026-12-03 a numpy ``False`` that is not ``False`` made every piece that had moved
        ``fallen_m`` fall (docs/dynamics.md)."""
        disp = self.displacement()
        dist = np.linalg.norm(disp, axis=1)
        gone = False
        peak = self.ground_peak_after(self.t)  # the largest ground acceleration still to come
        for i in np.flatnonzero(self.alive):
            idx = self.piece_of == i
            if dist[idx].max() <= self.settings.fallen_m:
                continue
            if self.falls(i, peak) is not False:
                self.alive[i] = False
                self.fallen[idx] = True
                self.final[idx] = disp[idx]
                self.final_R[idx] = self.R[i]
                # each body's velocity as it fell: the piece's field at the body's centroid
                r = self.x[idx] + disp[idx] - (self.c[i] + self.d[i])
                self.fell_v[idx, :3] = self.v[i] + np.cross(self.w[i], r)
                self.fell_v[idx, 3:] = self.w[i]
                self.fell_s[idx] = self.t
                self.v[i] = self.w[i] = 0.0
                gone = True
        if gone:
            keep = ((self.pa < 0) | self.alive[np.maximum(self.pa, 0)]) & (
                (self.pb < 0) | self.alive[np.maximum(self.pb, 0)]
            )
            for name in ("cj", "ck", "pa", "pb", "frame", "p", "kc"):
                setattr(self, name, getattr(self, name)[keep])
            self._prepare()
        return gone


def _peak_after(motion) -> Callable[[float], float]:
    """``t -> `` the largest horizontal acceleration (m/s^2, the two components' resultant) of the
    ground ``motion`` at its samples from the one at or before ``t`` on; 0 after its last sample
    and for no motion."""
    if motion is None or len(motion.acceleration) == 0:
        return lambda t: 0.0
    size = np.linalg.norm(np.asarray(motion.acceleration, dtype=np.float64), axis=1)
    rest = np.maximum.accumulate(size[::-1])[::-1]
    dt = float(motion.dt)

    def peak(t: float) -> float:
        k = max(int(np.floor(t / dt + 1e-9)), 0)
        return float(rest[k]) if k < len(rest) else 0.0

    return peak


def _load_at(gravity: np.ndarray, motion, t: float) -> np.ndarray:
    """The load per unit mass (3,) at ``t``: gravity and the ground's inertial force (its mean
    acceleration over the next millisecond)."""
    g = gravity.copy()
    if motion is not None:
        g[:2] -= motion.mean_acceleration(np.array([t, t + 1e-3]))[0]
    return g


def piece_motion(
    scene: Scene,
    release_time_s: np.ndarray,
    times_s: np.ndarray,
    *,
    velocity: dict[float, np.ndarray] | None = None,
    model=None,
    settings: PieceSettings | None = None,
    progress: bool | None = False,
    stopped: Callable[[], bool] | None = None,
    reached: Callable[[float], None] | None = None,
    rotations: bool = False,
    crack_time_s: np.ndarray | None = None,
    damping: tuple[float, float] | None = None,
) -> PieceMotion | None:
    """The freed pieces' motion (module docstring) at ``times_s`` (T,), seconds since the ground
    began to move, given when the joint model let each joint go (``release_time_s`` (nj,), NaN
    for never; a joint let go at ``t`` is let go before the step from ``t``). ``velocity`` maps
    a release time to every body's elastic velocity (B, 6) at it (None: pieces start from rest).
    ``model``: the run's :class:`~calib_masonry.simulation.joints.JointModel` (else built);
    ``progress`` as :func:`calib_masonry.progress.progress`. ``stopped()``, if given, is asked
    every 64 steps whether the caller has gone (a run stopped while the pieces moved on a thread
    of their own): then None at once. ``reached(t)``, if given, is told every 64 steps how far
    (seconds) the motion has got (a caller waiting for it shows the progress). ``rotations``: also
    record every body's rotation at each time (:attr:`PieceMotion.rotation`). ``crack_time_s``
    (nj,): when the joint model cracked each joint (NaN for never; None: none cracked): a piece's
    cracked joints are contacts in its own joints' check (:meth:`_Pieces.check_joints`), made every
    ``scene.solver.check_interval_s``. ``damping``: the run's Rayleigh ``(alpha, beta)``: with
    ``settings.joint_dynamics`` a piece's joints vibrate between checks (None: each check is
    static)."""
    from .dynamics import body_inertia
    from .joints import JointModel

    settings = settings if settings is not None else PieceSettings()
    if model is None:
        model = JointModel(scene, contact_gap_m=scene.solver.contact_gap_m)
    clock = time.perf_counter()
    times_s = np.asarray(times_s, dtype=np.float64)
    nb = model.nb
    out = np.zeros((len(times_s), nb, 3), dtype=np.float32)
    rot = np.zeros((len(times_s), nb, 3, 3), dtype=np.float32) if rotations else None
    if rot is not None:
        rot[:] = np.eye(3, dtype=np.float32)
    release = np.asarray(release_time_s, dtype=np.float64)

    def still() -> PieceMotion:
        return PieceMotion(
            times_s, out, 0, np.zeros(nb, dtype=bool), np.inf, 0, toppled=np.zeros(nb, dtype=bool), rotation=rot
        )

    if nb == 0 or len(times_s) == 0:
        return still()
    release = np.where(release <= times_s[-1], release, np.nan)  # let go after the last time asked: no matter
    inertia = np.array([body_inertia(b) for b in scene.bodies])
    state = _Pieces(scene, model, inertia, settings)
    if settings.check_joints and settings.joint_dynamics and damping is not None:
        state.damping = (float(damping[0]), float(damping[1]))
    events = np.unique(release[np.isfinite(release)])
    start_free = ~model.grounded(np.ones(model.nj, dtype=bool)) if model.nj else np.ones(nb, dtype=bool)
    if start_free.any():
        events = np.unique(np.concatenate([[0.0], events]))
    if events.size == 0:
        return still()
    gravity = np.array([0.0, 0.0, -scene.gravity])
    motion = scene.motion
    # the steps run from one release to the next (and on to the last time asked), not from one time
    # asked to the next: the motion does not depend on when it is looked at (the frame rate); each
    # time asked reads the state of the first step at or after it (steps are a fraction of a ms)
    ends = np.append(events, max(float(times_s[-1]), float(events[-1])))
    dt = np.inf
    steps = 0
    k_time = 0

    def read(t_now: float) -> None:
        nonlocal k_time
        while k_time < len(times_s) and times_s[k_time] <= t_now + 1e-12:
            out[k_time] = state.displacement()
            if rot is not None:
                rot[k_time] = state.rotation()
            k_time += 1

    cracked = np.asarray(crack_time_s, dtype=np.float64) if crack_time_s is not None else np.full(model.nj, np.nan)
    check_s = float(scene.solver.check_interval_s)
    read(float(events[0]) - 1e-9)  # before the first release nothing has moved
    for e in _progress(range(len(events)), desc="pieces", unit="release", enabled=progress):
        t = float(events[e])
        state.intact &= ~(cracked <= t + 1e-12)
        held = ~(release <= t + 1e-12) & np.isnan(state.release_time_s)
        free = ~model.grounded(held) if model.nj else np.ones(nb, dtype=bool)
        vel = velocity.get(t) if velocity else None
        state.g_now = _load_at(gravity, motion, t)
        state.t = t
        state.regroup(free, held, vel)
        dt = state.step_size()
        read(t)
        t0 = t
        next_check = (np.floor(t0 / check_s + 1e-9) + 1.0) * check_s
        while True:
            span = float(ends[e + 1]) - t0
            if span <= 0 or not state.n or dt == np.inf:
                break
            n = max(1, int(np.ceil(span / dt - 1e-9)))
            grid = t0 + span * np.arange(n + 1) / n
            a = motion.mean_acceleration(grid) if motion is not None else np.zeros((n, 2))
            h = span / n
            split = None
            loads = np.repeat(gravity[None], n, axis=0)
            loads[:, :2] -= a[:n]
            q = 0
            while q < n:
                # the steps up to the next at which the state is looked at: every 64th, a time
                # asked, a check of the pieces' joints; made in one call
                last = min(q | 63, n - 1)
                if k_time < len(times_s):
                    due = times_s[k_time] <= grid[q + 1 : last + 2] + 1e-12
                    if due.any():
                        last = q + int(np.argmax(due))
                if state.settings.check_joints:
                    due = grid[q + 1 : last + 2] >= next_check - 1e-12
                    if due.any():
                        last = q + int(np.argmax(due))
                state.advance_many(loads[q : last + 1], h)
                q = last
                state.t = float(grid[q + 1])
                if (q & 63) == 63:
                    state.check_fallen()
                    if stopped is not None and stopped():
                        return None
                    if reached is not None:
                        reached(float(grid[q + 1]))
                if k_time < len(times_s) and times_s[k_time] <= grid[q + 1] + 1e-12:
                    read(float(grid[q + 1]))
                if grid[q + 1] >= next_check - 1e-12:
                    next_check = (np.floor(grid[q + 1] / check_s + 1e-9) + 1.0) * check_s
                    if state.check_joints(float(grid[q + 1])).size:
                        split = float(grid[q + 1])
                        steps += q + 1
                        break
                q += 1
            if split is None:
                steps += n
                break
            # a piece's own joints let go: it splits, its parts moving on as they were
            state.g_now = _load_at(gravity, motion, split)
            state.regroup(free, held & np.isnan(state.release_time_s), None)
            dt = state.step_size()
            t0 = split
        state.check_fallen()
    read(np.inf)
    toppled = state.fallen.copy()
    # a piece still moving that may overturn (the energy bound) is played out on still ground
    may = np.array([i for i in np.flatnonzero(state.alive) if state.overturns(int(i))], dtype=np.int64)
    if may.size:
        state.t = max(state.t, float(times_s[-1]))
        goes = state.play_out(may, settings.play_out_s, stopped)
        if goes is None:
            return None
        for i in may[goes]:
            toppled[state.piece_of == i] = True
    return PieceMotion(
        times_s,
        out,
        int(state.n),
        state.fallen.copy(),
        float(dt),
        steps,
        time.perf_counter() - clock,
        toppled,
        rot,
        state.crack_time_s.copy(),
        state.release_time_s.copy(),
        state.fell_s.copy(),
        state.fell_v.copy(),
    )

"""The crack tracker: the joint model stepped through a run. Before each step of the engine it
cracks the joints that the step's load cracks, and says which cracked joints the engine must let
go (:class:`CrackTracker`); under a ground motion it carries the intact structure's elastic
vibration (:mod:`~calib_masonry.simulation.dynamics`) and checks on a grid of its own.

The joint model itself (stiffness, contact iteration, failure criteria) is
:mod:`~calib_masonry.simulation.joints`; this module only steps it.
"""

from __future__ import annotations

import time

import numpy as np

from ..errors import InputError
from .dynamics import ElasticResponse, mass_matrix, modes, record_load
from .joints import ContactSettings, JointModel, JointState
from .scene import Scene, runaway_m

__all__ = ["CrackTracker"]


class CrackTracker:
    """The joints of a run, from the end of the warm-up on: before each step, :meth:`step` cracks
    the joints that the step's load (``m g`` on every body) cracks, given which cracked joints
    still touch (from the poses), and says which cracked joints Bullet must let go. Records each
    joint's cracking time, failure mode and release time.

    A cracked joint is not let go at once: it is a frictional, no-tension contact in the joint
    model, and while the model finds an equilibrium with it (every body's motion small, under
    ``release_m``), Bullet keeps holding it with its rigid constraint, as it holds an intact one.
    Bullet's own friction between two moving bodies creeps at a rate set by the time step (a
    block on a block under a steady 0.2 g slides 38 mm in 5 s at the defaults, 5 mm at 4x the
    substeps), so a crack handed to Bullet's contacts at once would let a standing structure
    creep apart at a speed the solver chooses. Without an equilibrium the model's motion runs
    away (the weak inertia-relief springs hold a mechanism at ``g / eps``, metres); the cracked
    joints that then move by more than ``release_m`` are let go, and Bullet's contacts carry the
    mechanism from there. Under a ground motion what the held joints still tie to the ground is
    then solved again under the same load, cracking and letting go until it stands, so that a check
    lets go at once all that its load lets go (one run-away a check made the damage grow as the
    checks came more often); in a pushover the joints go one run-away a check (:attr:`cascade`).

    While no joint has cracked (and no body merely stands on the plate), the joint forces are
    linear in ``g``: the three unit-load solutions are computed once and combined, so a structure
    that stands costs one factorisation."""

    def __init__(
        self,
        scene: Scene,
        positions: np.ndarray,
        rotations: np.ndarray,
        plate: np.ndarray,
        time_s: float,
        *,
        settings: ContactSettings | None = None,
        record_vibration: bool = False,
    ) -> None:
        # the sparse Cholesky (cvxopt's CHOLMOD) is imported here, on the thread that builds the
        # tracker, not first where its steps may run (a thread of their own beside Bullet's): two
        # threads importing modules of one package at once can hang in CPython 3.11 (gh-83065)
        from ..preload import preload

        preload("joint_solver")

        if settings is None:
            settings = self.default_settings(scene)
        self.model = JointModel(scene, settings=settings, contact_gap_m=scene.solver.contact_gap_m)
        n = self.model.nj
        self.t0 = float(time_s)
        self.release_m = self.model.settings.release_m
        self.ref = (
            np.asarray(positions, dtype=np.float64).copy(),
            np.asarray(rotations, dtype=np.float64).copy(),
            np.asarray(plate, dtype=np.float64).copy(),
        )
        self.intact = np.ones(n, dtype=bool)
        self.held = np.ones(n, dtype=bool)  # Bullet's constraint still on
        self.break_time_s = np.full(n, np.nan)
        self.break_mode = np.full(n, -1, dtype=np.int64)
        self.release_time_s = np.full(n, np.nan)
        self.max_utilisation = 0.0
        # the intact joints' largest utilisation at the first check and how many are over 1, before
        # anything cracks: under the weight alone where the ground starts at rest or a push at zero
        self.first_check: tuple[float, int] | None = None
        self.seconds = 0.0
        self._unit = None
        # each body's elastic velocity (B, 6) when joints were let go, by release time since t0: the
        # pieces set free then start with it (simulation/pieces.py)
        self.free_velocity: dict[float, np.ndarray] = {}
        # the elastic vibration of what the intact joints hold, under a ground motion (dynamics.py)
        self.elastic = None
        # under a ground motion the joints are checked on a grid common to all frame rates (step)
        self.ground_motion = scene.motion
        self.check_interval_s = float(scene.solver.check_interval_s)
        self._next_check = 0
        self.checking_s: float | None = None  # the record's time of the check under way (or last)
        self._cracked_before = 0  # the joints cracked before the crack rounds under way
        # whether a check lets go at once all that its load lets go (see _check): under a ground
        # motion, whose verdict moves the freed pieces itself; in a pushover or a shear test the
        # peak is read where Bullet's poses run away, and a piece freed whole at once stood on
        # Bullet's contacts past the load the joint model found no equilibrium at (the laboratory
        # wall WI1.175: 74.8 kN against 47.4 kN, above the rigid cantilever's rocking bound of
        # 68.9 kN), so there the joints go one run-away a check, as Bullet moves them
        self.cascade = scene.motion is not None
        self.history: dict[str, list[float]] = {"time_s": [], "roof_drift_m": [], "base_shear_n": [], "first_mode": []}
        # every body's elastic displacement (B, 6: m, rad) about the weight's equilibrium at the end
        # of each step (a frame), and its time since t0: what an engine's held bricks may follow
        # (recorded where asked: only Bullet's pass after the verdict's reads it)
        self.record_vibration = record_vibration
        # a shear test's loading beam (its body index): its displacement and rotation (6,) in the
        # joint model at the last check of a pushover, where that check's motion is known (the
        # unit-load solutions' sum while nothing has cracked, else a converged solve): the force-drift
        # curve's drift up to the peak, along the run's own path (its cracks and the contacts' slip)
        self.beam_body = scene.notes.get("shear_test", {}).get("beam") if scene.motion is None else None
        self.beam_motion: np.ndarray | None = None
        self._unit_motion: list[np.ndarray] = []
        self._linear_g: np.ndarray | None = None
        self.frame_u: list[tuple[float, np.ndarray]] = []
        self._u_static: np.ndarray | None = None
        if scene.motion is not None and scene.solver.dynamics and n:
            mass = mass_matrix(scene)
            try:
                first = modes(scene, 2, model=self.model, mass=mass)
            except InputError:
                first = None  # nothing joined to the ground: nothing vibrates
            if first is not None and np.isfinite(first.periods_s).all():
                omega = 2 * np.pi / first.periods_s
                self.elastic = ElasticResponse(
                    self.model,
                    mass,
                    ratio=scene.solver.damping_ratio,
                    omega=(omega[0], omega[-1]),
                    motion=scene.motion,
                    ground_start_s=0.0,  # its times are the checks', from the ground's start (step)
                )
                self.first_period_s = float(first.periods_s[0])
                self._phi1 = mass @ first.shapes[0].ravel()  # q_1 = phi_1^T M u
                z = self.model.x[:, 2]
                self._top = np.flatnonzero(z >= z.max() - 0.05 * max(float(np.ptp(z)), 1e-9))

    @staticmethod
    def default_settings(scene: Scene) -> ContactSettings:
        """The joint model's settings for a run of ``scene``: :class:`ContactSettings`'s defaults under
        a ground motion; without one (a pushover or a shear test, whose load rises slowly, each check
        from the last one's equilibrium; gravity alone) a contact iteration that runs on until it converges or runs away
        (``max_iter`` 400, no stall window) and a release displacement of the run-away the verdict
        reads (:func:`~calib_masonry.simulation.scene.runaway_m`: the moved threshold, or 1 % of
        the height if more). Under a laboratory precompression (0.9-1.3 MPa) an equilibrium's elastic
        and frictional motions reach a millimetre, and a stalled iteration is often no mechanism: at
        1 mm and 10 stalled iterations the laboratory walls' peaks moved by 15-70 % with the load step
        and the release displacement; with these, WI1.175's is 65.2 kN at 25, 50 and 100 checks a
        second (docs/stone_walls.md, experiments/shear_test_convergence.py). A solve of a pushover
        or a shear test that ends unconverged asks whether the load has an equilibrium at all
        (:attr:`ContactSettings.check_equilibrium`): a dry laboratory wall (SW.30.2) stalls in most
        crack rounds of its frames from 35 s of its ramp, and each question (a linear programme
        on 1,400 corners) costs HiGHS 0.45-0.6 s from scratch, 0.004-0.015 s from its last answer
        (:meth:`JointModel.has_equilibrium`). And a crack round cracks the worst joint alone
        (``crack_band`` 0, event by event): cracking every joint within 10 % of the worst at once
        made a mortared laboratory wall's peak follow the load step (WI1.175: 57.6, 66.6 and 60.7
        kN at 25, 50 and 100 checks a second; 66.5 kN at all three with the worst alone)."""
        if scene.motion is not None:
            return ContactSettings()
        return ContactSettings(
            max_iter=400,
            stall_iter=400,
            release_m=max(ContactSettings.release_m, runaway_m(scene)),
            check_equilibrium=True,
            crack_band=0.0,
        )

    def release_factors(self) -> None:
        """The joint model's :meth:`JointModel.release_factors`: on the thread that stepped it."""
        self.model.release_factors()

    def _record(self, time_s: float, g: np.ndarray, extra: np.ndarray, held_bodies: np.ndarray | None) -> None:
        """The vibration's roof drift (the mean horizontal displacement of the top 5 % of the
        height), base shear (the horizontal resultant of the loads, inertial forces included, on
        the bodies that held joints tie to the ground: what their footing carries) and first modal
        coordinate at this step. ``held_bodies``: those bodies, None while every joint is held."""
        u = self.elastic.u.reshape(-1, 6)
        h = self.history
        h["time_s"].append(float(time_s))
        h["roof_drift_m"].append(float(np.hypot(*u[self._top, :2].mean(axis=0))))
        on = self.model._load(g).reshape(-1, 6)[:, :2] + extra.reshape(-1, 6)[:, :2]
        if held_bodies is not None:
            on = on[held_bodies]
        h["base_shear_n"].append(float(np.hypot(*on.sum(axis=0))))
        h["first_mode"].append(float(self._phi1 @ self.elastic.u))

    @property
    def reads_poses(self) -> bool:
        """Whether :meth:`step` reads the poses: only for bodies that bear on the plate without a
        foundation joint (where they touch it is Bullet's). Otherwise a step's outcome follows from
        the load and the tracker's own state alone."""
        return self.model.n_all > self.model.nj

    def _unit_states(self) -> list[JointState]:
        if self._unit is None:
            eye = np.eye(3)
            self._unit, self._unit_motion = [], []
            for k in range(3):
                self._unit.append(self.model.solve(eye[k], self.intact)[0])
                self._unit_motion.append(self.model.motion.copy())
        return self._unit

    def step(
        self,
        time_s: float,
        g: np.ndarray,
        positions: np.ndarray,
        rotations: np.ndarray,
        plate: np.ndarray,
        through_s: float | None = None,
    ) -> np.ndarray:
        """The joints that Bullet must let go before the coming step's load ``g`` (3,), given the
        current poses; returns their indices (joints that crack are recorded, and let go only
        once the model has no equilibrium with them).

        Under a ground motion the joints are checked on a grid of ``check_interval_s`` from the
        ground's start, not at the frames: every grid point up to ``time_s`` not checked yet is
        checked, at the record's acceleration then (``g`` gives the vertical), so that the cracks,
        the releases and their times are the same at any frame rate (wherever no pose is read).
        ``through_s`` (the run's last step: its end) checks the grid on to that time as well, so
        that the record's last frame is checked too (0.04 s at 25 frames a second, 0.02 s at 50:
        a crack there had been seen at one frame rate only). Without a ground motion (a pushover)
        the frame's ``g`` is checked at ``time_s``."""
        t = time.perf_counter()
        try:
            if self.model.nj == 0:
                return np.zeros(0, dtype=np.int64)
            g = np.asarray(g, dtype=np.float64)
            if self.ground_motion is None:
                self.checking_s = float(time_s) - self.t0
                self._linear_g = None
                release = self._check(self.checking_s, g, positions, rotations, plate)
                if self.beam_body is not None:
                    self.beam_motion = self._beam_motion()
                return release
            h = self.check_interval_s
            out: list[np.ndarray] = []
            peak = None
            for until in (time_s,) if through_s is None else (time_s, through_s):
                last = int(np.floor((float(until) - self.t0) / h + 1e-6))
                checked = False
                while self._next_check <= last:
                    # the check's time from the ground's start, the same number at any frame rate:
                    # an absolute time (t0 + k h) is rounded by t0, which the frame rate sets (the
                    # warm-up's whole frames: 0.48 s at 25 fps, 0.50 s at 50), and the vibration's
                    # steps and the record's samples read at it differed in their last bits: one
                    # joint of Stylite's (seed 2, 0.95 g) cracked at 25 fps and not at 50, and the
                    # tower fell at one only
                    tk = self._next_check * h
                    self.checking_s = tk
                    out.append(self._check(tk, record_load(self.ground_motion, tk, g), positions, rotations, plate))
                    peak = self.max_utilisation if peak is None else max(peak, self.max_utilisation)
                    self._next_check += 1
                    checked = True
                if self.elastic is not None and checked and self.record_vibration:
                    if self._u_static is None:  # the first check: the equilibrium under the weight
                        self._u_static = self.elastic.u.copy()
                    u = (self.elastic.u - self._u_static).reshape(-1, 6).astype(np.float32)
                    self.frame_u.append((float(until) - self.t0, u))
            if peak is not None:
                self.max_utilisation = peak  # the largest of this frame's checks
            return np.concatenate(out) if out else np.zeros(0, dtype=np.int64)
        finally:
            self.seconds += time.perf_counter() - t

    def activity(self) -> str:
        """What the check under way is doing, for the progress line of a run that waits for it (a
        crack cascade on a large structure can take minutes a check): the time it checks (from
        the ground motion's or the pushover's start), and its crack round with the joints cracked
        so far. Read from another thread than the check's."""
        if self.checking_s is None:
            return ""
        text = f"checking the joints at {self.checking_s:.3f} s"
        rounds = self.model.crack_round
        if rounds:
            n = self._cracked_before + self.model.cracked_in_rounds
            text += f": crack round {rounds}, {n} joint{'' if n == 1 else 's'} cracked"
        return text

    def _beam_motion(self) -> np.ndarray | None:
        """The loading beam's (6,) displacement and rotation at the check just made: the unit-load
        solutions' sum where nothing had cracked, the last solve's where it converged, else None."""
        b = 6 * self.beam_body
        if self._linear_g is not None:
            return sum(self._linear_g[k] * self._unit_motion[k][b : b + 6] for k in range(3))
        if self.model.converged and self.model.motion is not None:
            return self.model.motion[b : b + 6].copy()
        return None

    def _frozen(self, held_bodies: np.ndarray | None) -> np.ndarray:
        """``(nj,)`` the held joints of the pieces already set free (no held joint ties their bodies
        to the ground): the verdict moves each such piece as one rigid body (simulation/pieces.py)
        and never cracks it again, so the checks leave them out (on the Stylite tower, set free at
        1.5 s of a 0.3 g quake, each check of the rest of the run cost 50 ms with them)."""
        nj = self.model.nj
        if self.held.all():
            return np.zeros(nj, dtype=bool)
        grounded = held_bodies if held_bodies is not None else self.model.grounded(self.held)
        return self.held & ~grounded[self.model.a[:nj]]

    def _check(
        self, time_s: float, g: np.ndarray, positions: np.ndarray, rotations: np.ndarray, plate: np.ndarray
    ) -> np.ndarray:
        """One check of the joints at ``time_s`` (from the ground's or the push's start, t0) under
        the load ``g``: :meth:`step`'s."""
        closed = None
        extra = None
        start = None
        held_bodies = None  # the bodies held joints tie to the ground, once some joint is let go
        crack_time_s = float(time_s)
        if self.elastic is not None:
            before = self.elastic.u.copy()
            until = None
            if self.intact.all() and self.model.n_all == self.model.nj:
                # while every joint is intact their forces are K u: checked 20 times a first
                # period of the vibration, so that a peak between two checks cracks where it
                # happens (the unseen tower's 0.07 s period is 14 check intervals of 0.005 s)
                def until(u: np.ndarray) -> bool:
                    return self.model.utilisation_bound(u) > 1.0 and bool(self.model.state(u).utilisation.max() > 1.0)

            crack_time_s = self.elastic.advance(time_s, g, until=until)
            # the load at the instant checked: the record's ground acceleration then
            g = self.elastic.load_at(crack_time_s, g)
            extra = self.elastic.inertial_force()
            if self.model.motion is not None:
                # the vibration moved the structure it holds: start the contact iteration there
                start = self.model.motion + (self.elastic.u - before)
            if not self.held.all():
                # a piece Bullet has set free moves as Bullet says: no vibration's forces on it
                held_bodies = self.model.grounded(self.held)
                extra.reshape(-1, 6)[~held_bodies] = 0.0
        if self.elastic is not None and self.intact.all() and self.model.n_all == self.model.nj:
            # while nothing has cracked the joints' forces are the vibration's: K u
            state = self.model.state(self.elastic.u)
            self._record(crack_time_s, g, extra, held_bodies)
            self.max_utilisation = float(state.utilisation.max())
            self._first(state.utilisation)
            if self.max_utilisation <= 1.0:
                return np.zeros(0, dtype=np.int64)
        elif self.intact.all() and self.model.n_all == self.model.nj:
            # forces are linear in g while nothing has cracked: combine the unit-load solutions
            unit = self._unit_states()
            state = self.model.state_from_relative(sum(g[k] * unit[k].relative for k in range(3)))
            self.max_utilisation = float(state.utilisation.max())
            self._first(state.utilisation)
            if self.max_utilisation <= 1.0:
                self._linear_g = g
                return np.zeros(0, dtype=np.int64)
        else:
            # the cracked joints Bullet holds are contacts in the model; those it has let go
            # are Bullet's alone; bodies standing on the plate bear where Bullet says they touch
            closed = self._held_corners()
            if self.model.n_all > self.model.nj:
                gaps = self.model.corner_gaps(positions, rotations, plate, *self.ref)
                closed[self.model.nj :] = gaps[self.model.nj :] < self.model.contact_gap_m
        released: list[np.ndarray] = []
        for _ in range(self.model.nj + 1):
            # under a ground motion a check cracks and lets go until what held joints still tie to
            # the ground has an equilibrium (or nothing more lets go): the joints a run-away lets
            # go leave the model, and what is left is solved again under the same load. Letting go
            # one run-away a check made a cascade over checks, whose damage grew as the checks came
            # more often (Stylite, 0.3 g: 7.0 / 9.4 / 12.9 / 14.9 % of the bonds broken at 5 / 2.5
            # / 1.25 / 0.625 ms)
            frozen = self._frozen(held_bodies)
            intact = self.intact & ~frozen
            if frozen.any() and closed is not None:
                closed[: self.model.nj][frozen] = False
            self.model.cracked_in_rounds = 0
            self._cracked_before = int((~self.intact).sum())
            new, modes, state = self.model.crack(g, intact, closed, runaway_m=self.release_m, extra=extra, start=start)
            self._first(self.model.uncracked_utilisation)
            self.intact[new] = False
            self.break_time_s[new] = crack_time_s
            self.break_mode[new] = modes
            self.max_utilisation = float(np.where(intact & self.intact, state.utilisation, 0.0).max(initial=0.0))
            candidates = np.flatnonzero(~self.intact & self.held & ~frozen)
            if self.model.no_equilibrium:
                # the load has no equilibrium even with every contact at Coulomb's cone: the cracked
                # joints cannot hold what they hold, whatever the iterate's small motion says
                release = candidates
            else:
                release = candidates[self.model.corner_motion(candidates) > self.release_m]
            if not release.size:
                break
            released.append(release)
            self.held[release] = False
            self.release_time_s[release] = float(time_s)
            self.model.forget(release)
            if not self.cascade:
                break
            start = None
            if closed is None:
                closed = self._held_corners()
            closed[release] = False
            if extra is not None:
                held_bodies = self.model.grounded(self.held)
                extra.reshape(-1, 6)[~held_bodies] = 0.0
        if self.elastic is not None:
            if released:
                self.free_velocity[float(time_s)] = self.elastic.v.reshape(-1, 6).copy()
            self._record(crack_time_s, g, extra, held_bodies)
        return np.concatenate(released) if released else np.zeros(0, dtype=np.int64)

    def _first(self, utilisation: np.ndarray) -> None:
        """Keep the first check's utilisation of the intact joints (:attr:`first_check`)."""
        if self.first_check is None:
            self.first_check = (float(utilisation.max(initial=0.0)), int((utilisation > 1.0).sum()))

    def _held_corners(self) -> np.ndarray:
        """``(J', K)`` the contact corners of the joints Bullet still holds (every corner of each):
        those the model may let touch; the plate contacts' rows are the caller's to fill."""
        return np.repeat(self.model._pad(self.held)[:, None], self.model.outline.shape[1], axis=1)

"""The simulation's stepping loop, free of any physics engine: the load history, the warm-up, the
joint model's checks (on a thread of their own, ahead of the engine), the joints let go, the
parts set free, and the verdict's rigid pieces after the run.

The engine (Blender's Bullet: :class:`~calib_masonry.simulation.blender.BlenderEngine`) is driven
through a small interface, :class:`Engine`: step to a frame, read the poses, switch damping off,
switch joints off, set bodies free, save. Nothing here imports Blender; a test can drive the loop
with an engine of its own.
"""

from __future__ import annotations

import queue
import threading
import time
from collections.abc import Callable, Generator, Iterator, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Protocol, TypeVar

import numpy as np

from ..errors import InputError
from ..progress import progress as _progress
from .pieces import PieceSettings, _rotate, piece_motion
from .scene import Scene, grounded_bodies, quaternions_from_matrices, rotations
from .tracker import CrackTracker

__all__ = ["Engine", "RunOutput", "StillEngine", "drain", "gravity_per_frame", "run", "steps"]

T = TypeVar("T")


#: what a run's frames show (:attr:`RunOutput.frames_of`, summary.json ``engine``): Bullet's poses,
#: the verdict's pieces (no Bullet), or the verdict's pieces on kinematic bricks until a piece
#: falls and Bullet's after (:func:`_follow`)
BULLET_FRAMES, PIECES_FRAMES, PIECES_THEN_BULLET_FRAMES = "bullet", "pieces", "pieces, then bullet"


@dataclass(frozen=True)
class RunOutput:
    """Poses at every frame (frame 0 is the initial state), in the frame that moves with the ground:
    ``positions`` ``(F, B, 3)``, ``quaternions`` ``(F, B, 4)`` (w, x, y, z), ``plate`` ``(F, 3)``,
    ``time`` ``(F,)`` seconds from the start of the warm-up; ``seconds_stepping`` is the wall time
    of the stepping loop."""

    time: np.ndarray
    positions: np.ndarray
    quaternions: np.ndarray
    plate: np.ndarray
    seconds_build: float
    seconds_stepping: float
    bond_break_time_s: np.ndarray | None = None  # cracking time of each bond after the warm-up, if watched
    bond_break_mode: np.ndarray | None = None  # per bond: index into joints.FAILURE_MODES, -1 if intact
    bond_release_time_s: np.ndarray | None = None  # when Bullet let each cracked bond go, NaN if never
    max_utilisation: np.ndarray | None = None  # (F,) the intact joints' largest utilisation at each frame
    seconds_joints: float = 0.0  # wall time spent in the joint model
    # the intact joints' largest utilisation at the joint model's first check, before anything
    # cracked, and how many were over 1 (the weight alone where the ground starts at rest: a model
    # over 1 there cannot carry its own weight as built); None where not computed
    first_check: tuple[float, int] | None = None
    # the joint model's contact solves: how many, how many ended without meeting their tolerance,
    # and the largest out-of-balance one of those ended with, in tolerances (None without it)
    contact_solves: dict | None = None
    # the elastic vibration of the structure the intact joints hold (simulation/dynamics.py), per
    # joint-model step after the warm-up: time_s, roof_drift_m, base_shear_n, first_mode (arrays),
    # first_period_s and damping_ratio; None for a quasi-static run
    elastic: dict | None = None
    # the pieces the joint model set free, moved as rigid bodies to convergence (simulation/pieces.py):
    # the verdict's motion; None where no ground motion ran with the joint model
    pieces: object | None = None
    # what the poses are: Bullet's ("bullet"), the verdict's pieces' in a run without it ("pieces"),
    # or those on kinematic bricks until a piece falls and Bullet's then ("pieces, then bullet": _follow)
    frames_of: str = BULLET_FRAMES
    # the velocities (B, 6) the engine set each body free with (the vibration's), NaN rows for a body
    # set free from rest or never
    freed_velocity: np.ndarray | None = None
    # the vibration's displacement of every body about the weight's equilibrium at each frame the
    # joint model stepped: (times since the ground started (K,), (K, B, 6) m and rad, float32);
    # None without a vibration (a quasi-static run)
    vibration: tuple[np.ndarray, np.ndarray] | None = None
    # a shear test's loading beam in the joint model at each frame's check (F, 6: m and rad), NaN
    # where the check's motion is not known (before the checks, an unconverged solve, the run-away)
    beam_motion: np.ndarray | None = None


class Engine(Protocol):
    """What the loop asks of a physics engine. Frame ``f`` of the run is the state after ``f``
    steps (frame 0: the initial state); bodies are numbered as in ``scene.bodies``, joints as in
    ``scene.bonds``."""

    def step_to(self, frame: int) -> None:
        """Advance to ``frame`` (frame 0: set up the initial state)."""

    def read_poses(self, out: np.ndarray) -> np.ndarray:
        """Write every body's world matrix into ``out`` ``(B, 4, 4)`` (row-major) and return the
        plate's position ``(3,)``."""

    def end_warmup(self) -> None:
        """Take the warm-up's damping off every body."""

    def switch_off(self, bonds: Sequence[int]) -> None:
        """Let the joints ``bonds`` go (their bodies bear on each other from now on)."""

    def set_free(self, bodies: np.ndarray, bonds: np.ndarray, velocity: np.ndarray | None = None) -> None:
        """Turn the bodies held fixed ``bodies`` dynamic and switch the held joints ``bonds`` among
        them on: from rest, or with ``velocity`` ``(len(bodies), 6)`` (translation m/s and rotation
        rad/s about each centroid, in the engine's frame)."""

    def place(self, bodies: np.ndarray, locations: np.ndarray, quaternions: np.ndarray) -> None:
        """Move the kinematic ``bodies`` to ``locations`` ``(n, 3)`` and ``quaternions`` ``(n, 4)``
        (w, x, y, z) over the coming step (a motion computed elsewhere: the verdict's pieces')."""

    def save(self, path: Path, frames: int, freed_at: np.ndarray) -> None:
        """Save the run's first ``frames`` frames, the bodies set free keyed at ``freed_at``."""


class StillEngine:
    """An engine that moves nothing: every body stays where the scene puts it, the plate at the
    origin. For a run without Bullet (:func:`steps` with ``bullet=False``): under a ground motion
    the joint model decides every check from the load and its own state (where no body bears on
    the plate without a joint), the verdict moves the pieces it sets free, and the run's frames
    are those pieces' poses, put in once the run is done."""

    def __init__(self, scene: Scene, fixed: np.ndarray, gravity: np.ndarray) -> None:
        nb = len(scene.bodies)
        self.mats = np.zeros((nb, 4, 4), dtype=np.float32)
        if nb:
            self.mats[:, :3, :3] = rotations(np.array([b.rotation for b in scene.bodies]))
            self.mats[:, :3, 3] = [b.location for b in scene.bodies]
        self.mats[:, 3, 3] = 1.0

    def step_to(self, frame: int) -> None:
        pass

    def read_poses(self, out: np.ndarray) -> np.ndarray:
        out[:] = self.mats
        return np.zeros(3)

    def end_warmup(self) -> None:
        pass

    def switch_off(self, bonds: Sequence[int]) -> None:
        pass

    def set_free(self, bodies: np.ndarray, bonds: np.ndarray, velocity: np.ndarray | None = None) -> None:
        pass

    def place(self, bodies: np.ndarray, locations: np.ndarray, quaternions: np.ndarray) -> None:
        pass

    def save(self, path: Path, frames: int, freed_at: np.ndarray) -> None:
        pass


def _poses_from_pieces(mats: np.ndarray, warm: int, pieces, centroids: np.ndarray) -> None:
    """Put the verdict's pieces' motion into the frames ``mats`` ``(F, B, 4, 4)`` from frame ``warm``
    on (frame ``warm + k`` is the pieces' time ``k``): each body turned by its piece's rotation
    about its centroid ``centroids`` (B, 3) and moved by the centroid's displacement."""
    n = min(len(mats) - warm, len(pieces.time_s))
    if n <= 0:
        return
    R0 = mats[warm, :, :3, :3].astype(np.float64)
    L0 = mats[warm, :, :3, 3].astype(np.float64)
    R = pieces.rotation[:n].astype(np.float64)  # (n, B, 3, 3)
    d = pieces.displacement_m[:n].astype(np.float64)
    mats[warm : warm + n, :, :3, :3] = R @ R0
    mats[warm : warm + n, :, :3, 3] = centroids + d + np.einsum("tbij,bj->tbi", R, L0 - centroids)


def gravity_per_frame(scene: Scene) -> np.ndarray:
    """The gravity vector Bullet steps into each frame with, ``(frames + 1, 3)``; row k drives the
    step from frame k - 1 to k (row 0: the initial state).

    * Warm-up: gravity rises smoothly from 0 to g over ``gravity_ramp_s`` and then holds, so the
      bonded structure takes its weight quasi-statically instead of ringing after a sudden load.
    * Ground motion: applied as the inertial force it puts on every body in the ground's frame,
      gravity ``(-a_x, -a_y, -g)`` with ``a`` the ground's mean acceleration over the frame, so the
      velocities are exact at every frame. A kinematic plate keyed per frame would instead change
      its velocity within one substep at every frame boundary: an acceleration spike of substeps x
      a, which rocked a block at 0.9 g b / h (measured).
    * Pushover: a uniform lateral acceleration ``lambda g`` along the pushover's direction, with
      ``lambda`` rising linearly from 0 at the end of the warm-up (mean over each frame).
    """
    s = scene.solver
    frames = scene.frames
    warm = s.warmup_frames
    t = (np.arange(frames + 1) - warm) / s.fps  # time since the ground started moving
    g = np.zeros((frames + 1, 3))
    g[:, 2] = -scene.gravity
    ramp = min(s.gravity_ramp_s, s.warmup_s)
    if ramp > 0:
        x = np.clip((t + s.warmup_s) / ramp, 0.0, 1.0)
        g[:, 2] *= x * x * (3.0 - 2.0 * x)
    if scene.motion is not None:
        g[1:, :2] = -scene.motion.mean_acceleration(t)
    if scene.pushover is not None:
        p = scene.pushover
        lam = 0.5 * (p.lateral_g(t[:-1]) + p.lateral_g(t[1:]))  # the mean over each frame (linear ramp)
        d = np.radians(p.direction_deg)
        g[1:, 0] = lam * scene.gravity * np.cos(d)
        g[1:, 1] = lam * scene.gravity * np.sin(d)
    return g


def _ahead(
    fn: Callable[[int], T],
    items: range,
    release: Callable[[], None],
    then: Callable[[Callable[[], bool]], object] | None = None,
    waiting: Callable[[bool], None] | None = None,
) -> Iterator:
    """``fn(k)`` for each of ``items``, computed in order on a thread of its own as far ahead as it
    gets, yielded in order; then, if given, ``then(stopped)`` on the same thread, yielded last
    (``stopped()`` says whether the consumer has left: a long ``then`` checks it). ``release()``
    runs on that thread as it ends (the joint model's LU factors are freed there, on the thread
    that made them: see :meth:`~calib_masonry.simulation.joints.JointModel.release_factors`).
    Leaving early (an error, a stop, ``close()``) stops the thread after the item it is on and
    waits for it, so nothing runs on after the run; an error of ``fn`` is raised here, in its
    item's turn. ``waiting(last)``, if given, is called about every 0.25 s while the consumer
    waits for an item (``last``: ``then``'s), to show that the work goes on; an exception it
    raises (a stop) ends the wait."""
    results: queue.SimpleQueue = queue.SimpleQueue()
    stop = threading.Event()

    def work() -> None:
        try:
            for k in items:
                if stop.is_set():
                    return
                results.put((True, fn(k)))
            if then is not None and not stop.is_set():
                results.put((True, then(stop.is_set)))
        except BaseException as exc:  # noqa: BLE001 - raised by the consumer in its turn
            results.put((False, exc))
        finally:
            release()

    thread = threading.Thread(target=work, name="calib-masonry-joints", daemon=True)
    thread.start()
    try:
        for i in range(len(items) + (then is not None)):
            while True:
                try:
                    ok, value = results.get(timeout=None if waiting is None else 0.25)
                    break
                except queue.Empty:
                    waiting(i == len(items))  # type: ignore[misc]
            if not ok:
                raise value
            yield value
    finally:
        stop.set()
        thread.join()


def run(scene: Scene, **options) -> RunOutput:
    """Simulate ``scene`` in one pass: :func:`steps` with the same options, run to its end."""
    return drain(steps(scene, **options))


def drain(gen: Generator[int, None, T]) -> T:
    """The value a generator of :func:`steps` (or a function built on it) returns, run to its end."""
    while True:
        try:
            next(gen)
        except StopIteration as end:
            return end.value


def _blender_engine(scene: Scene, fixed: np.ndarray, gravity: np.ndarray) -> Engine:
    from .blender import BlenderEngine

    return BlenderEngine(scene, fixed, gravity)


def steps(
    scene: Scene,
    *,
    progress: bool | None = None,
    blend_path: Path | None = None,
    record: bool = True,
    switch_off_s: np.ndarray | None = None,
    freed_velocity: np.ndarray | None = None,
    stop=None,
    joints_ahead: bool = True,
    engine: Callable[[Scene, np.ndarray, np.ndarray], Engine] = _blender_engine,
    bullet: bool = True,
    vibration: bool = False,
) -> Generator[int, None, RunOutput]:
    """Simulate ``scene`` in one pass, yielding each frame's number once it is stepped, and return
    the :class:`RunOutput` (a caller that drives it from an event loop lets the loop run between
    frames: :func:`calib_masonry.simulation.run.simulate_async`). Closing the generator early
    stops the joint model's thread as an error would. ``joints_ahead=False`` runs the joint model
    on this thread, one check before each step, instead of ahead on a thread of its own (the same
    run, bit for bit): for a process whose cores are busy anyway (a study's workers).

    The pass: the warm-up under (ramped) gravity with every joint intact
    and the bodies damped, then the ground motion (or the pushover's ramp) with no damping, the
    joint model cracking joints before each step (:class:`~calib_masonry.simulation.tracker.CrackTracker`).

    The bodies a chain of joints ties to the plate are held fixed by the engine, their joints off
    there, until the joints let go set a part of the structure free (see
    :mod:`~calib_masonry.simulation.blender` for why). With ``record=False`` only the stepping is
    done (the bare-engine baseline): no poses are read and no joint model runs; ``switch_off_s``
    (per bond, seconds after the warm-up, NaN for never; the ``bond_release_time_s`` of a recorded
    run) then replays that run's joint switches on a schedule fixed in advance, and
    ``freed_velocity`` (its :attr:`RunOutput.freed_velocity`) the velocities its bodies were set
    free with, so the baseline does the same engine work. ``stop(frame, positions (B, 3), plate
    (3,))``, if given, is asked after every recorded frame whether the run may end there (a pushover ends once it has run
    away); the output then holds the frames up to that one. ``engine(scene, held fixed (B,),
    gravity per frame)`` builds the engine (default: Blender's).

    ``bullet=False`` (a ground motion only) steps no engine (:class:`StillEngine`): the joint model
    and the verdict's rigid pieces run as they do beside Bullet, and the frames are the pieces'
    poses (the structure the joints hold stays in place): the same verdict, cracks and releases
    bit for bit, without Bullet's animation of the freed pieces (most of a quake's time once a
    tower is free). A structure with bodies that bear on the plate without a joint needs Bullet's
    poses for them, and is refused. ``vibration``: record every body's vibration at each frame
    (:attr:`RunOutput.vibration`, what Bullet's pass plays on the held bricks; only that pass reads
    it, and it is 10 MB on the paper example's quake, about 50 MB on a tower of 8,000 bricks).
    """
    if (
        bullet
        and record
        and engine is _blender_engine
        and scene.motion is not None
        and scene.pushover is None
        and scene.solver.bullet_moves == "fallen"
        and scene.bonds
    ):
        # Bullet plays the verdict's pieces and takes over those that fell (_follow): the verdict's
        # pass first, without Bullet; a structure whose checks read Bullet's poses runs as before
        try:
            first = yield from steps(scene, progress=progress, joints_ahead=joints_ahead, bullet=False, vibration=True)
        except _NeedsPoses:
            pass
        else:
            return (yield from _follow(scene, first, blend_path, progress))
    if not bullet:
        if scene.motion is None or scene.pushover is not None or not record:
            raise InputError(
                "--no-bullet: only for a ground motion (a pushover or a shear test ends where Bullet's poses "
                "run away, and gravity alone moves no piece); run it with Bullet"
            )
        engine = StillEngine
    t0 = time.perf_counter()
    nb = len(scene.bodies)
    fixed = grounded_bodies(scene.bonds, nb)
    gravity = gravity_per_frame(scene)
    eng = engine(scene, fixed.copy(), gravity)
    seconds_build = time.perf_counter() - t0
    s = scene.solver
    frames = scene.frames
    warm = min(s.warmup_frames, frames)
    n = frames + 1 if record else 1
    plate_pos = np.zeros((n, 3))
    mats = np.zeros((n, nb, 4, 4), dtype=np.float32)
    utilisation = np.zeros(n)
    beam_motion = np.full((n, 6), np.nan)  # a shear test's beam in the joint model (tracker.beam_motion)

    def grab(i: int) -> None:
        plate_pos[i] = eng.read_poses(mats[i])

    tracker: CrackTracker | None = None

    def end_warmup(i: int) -> None:
        nonlocal tracker
        if warm > 0:
            eng.end_warmup()
        if record and scene.bonds:
            tracker = CrackTracker(
                scene, mats[i, :, :3, 3], mats[i, :, :3, :3], plate_pos[i], (i) / s.fps, record_vibration=vibration
            )
            if not bullet and tracker.reads_poses:
                raise _NeedsPoses(
                    "--no-bullet: some bricks stand on the plate without a joint (a model without its footing, "
                    "--no-foundation): where they touch it is Bullet's to say; run it with Bullet"
                )

    schedule: dict[int, list[int]] = {}
    if not record and switch_off_s is not None:
        for k in np.flatnonzero(np.isfinite(switch_off_s)):
            schedule.setdefault(warm + int(round(float(switch_off_s[k]) * s.fps)), []).append(int(k))

    held = np.ones(len(scene.bonds), dtype=bool)  # the joints the engine holds
    bond_a = np.array([b.a for b in scene.bonds], dtype=np.int64)
    freed_at = np.full(nb, -1)  # the frame at which each body held fixed was set free
    started = np.full((nb, 6), np.nan)  # the velocities they were set free with (NaN: from rest)
    # the joint model's contact solves up to the last check the run used (a check thread running
    # ahead of the engine may have solved frames past the run's end: counted, they made the summary
    # follow the machine's load, 56-949 solves for one block's pushover)
    solves_used: list[dict | None] = [None]

    def switch_off(bonds, frame: int, velocity: np.ndarray | None = None) -> None:
        eng.switch_off(bonds)
        held[list(bonds)] = False
        # the part of the structure that no held joint ties to the plate any more is set free:
        # its bodies turn dynamic, with the elastic vibration's velocities they had (``velocity``
        # (B, 6), the last release's of the step; from rest without one), and the held joints
        # among them act in the engine
        free = np.flatnonzero(fixed & ~grounded_bodies(scene.bonds, nb, held))
        if free.size == 0:
            return
        fixed[free] = False
        freed_at[free] = frame
        v = _start_velocity(None if velocity is None else velocity[free])
        if v is not None:
            started[free] = v
        eng.set_free(free, np.flatnonzero(held & np.isin(bond_a, free)), v)

    def check(f: int, p: int):
        # the joints that step f's load cracks and the engine must let go, given the poses of
        # frame p (read only for bodies that bear on the plate without a joint)
        assert tracker is not None
        # the last step's checks run on to its end, the record's last frame checked as well
        release = tracker.step(
            (f - 1) / s.fps,
            gravity[f],
            mats[p, :, :3, 3].astype(np.float64),
            mats[p, :, :3, :3].astype(np.float64),
            plate_pos[p].copy(),
            through_s=f / s.fps if f == frames else None,
        )
        # the vibration's velocities at the step's last release (its pieces start with them)
        velocity = tracker.free_velocity[max(tracker.free_velocity)] if len(release) and tracker.free_velocity else None
        beam = None if tracker.beam_motion is None else tracker.beam_motion.copy()
        return release, tracker.max_utilisation, velocity, _contact_solves(tracker), beam

    # A tracker that reads no pose (no body bears on the plate without a joint) decides every step
    # from the load history and its own state alone, so it runs ahead on the other core, frame
    # after frame in order, while the engine steps (Blender's frame_set releases the GIL): the
    # joints cracked and let go are those of one check before each step, and the run takes the
    # longer of the two.
    ahead = None
    ahead_pieces = False  # whether the thread ahead moves the verdict's pieces once its checks are done
    pieces = None
    times = (np.arange(warm, frames + 1) - warm) / s.fps  # the recorded frames' times since the ground started

    def move_pieces(stopped=None, progress=False, reached=None):
        # the verdict's motion of what the joints set free: rigid pieces, converged (not the engine's)
        assert tracker is not None
        return piece_motion(
            scene,
            tracker.release_time_s,
            times,
            velocity=tracker.free_velocity,
            crack_time_s=tracker.break_time_s,
            model=tracker.model,
            settings=PieceSettings(check_joints=scene.solver.piece_joints),
            progress=progress if np.isfinite(tracker.release_time_s).any() else False,
            stopped=stopped,
            reached=reached,
            rotations=not bullet,
            damping=(tracker.elastic.alpha, tracker.elastic.beta) if tracker.elastic is not None else None,
        )

    # where the pieces' motion on the thread ahead has got, and its progress shown while this
    # thread waits for it once the engine is done (the pieces can take longer than Bullet)
    pieces_at = [0.0]
    wait_bar: list = []
    waited = [False]  # the frames' line shows a long check's activity (cleared once it is done)

    def pieces_reached(t: float) -> None:
        pieces_at[0] = t

    def waiting(for_pieces: bool) -> None:
        # a check of the joint model can take minutes (a crack cascade on a large structure): the
        # frames' progress goes on showing (a line every 10 s in a log) and a stop ends the wait
        if not for_pieces:
            if tracker is not None:
                frames_bar.set_postfix_str(tracker.activity())
                waited[0] = True
            frames_bar.update(0)
            return
        if not wait_bar:
            wait_bar[:] = [_progress(total=len(times), desc="pieces", unit="frame", enabled=progress), 0]
        k = int(np.searchsorted(times, pieces_at[0], side="right"))
        if k > wait_bar[1]:
            wait_bar[0].update(k - wait_bar[1])
            wait_bar[1] = k
        else:
            wait_bar[0].update(0)  # a stop requested while waiting ends the wait

    t1 = time.perf_counter()
    eng.step_to(0)
    if record:
        grab(0)
    if warm == 0:
        end_warmup(0)
    try:
        frames_bar = _progress(range(1, frames + 1), desc="simulate", unit="frame", enabled=progress)
        for f in frames_bar:
            i = f if record else 0
            if tracker is not None:
                if joints_ahead and ahead is None and not tracker.reads_poses:
                    # under a ground motion the same thread then moves the pieces, while the engine
                    # is still stepping: they need the checks' releases alone
                    ahead_pieces = record and scene.motion is not None
                    ahead = _ahead(
                        lambda k, w=i - 1: check(k, w),
                        range(f, frames + 1),
                        tracker.release_factors,
                        then=(lambda stopped: move_pieces(stopped, reached=pieces_reached)) if ahead_pieces else None,
                        waiting=waiting,
                    )
                p = i - 1
                release, utilisation[p], velocity, solves_used[0], beam = (
                    next(ahead) if ahead is not None else check(f, p)
                )
                if beam is not None:
                    beam_motion[i] = beam  # the check of step f is frame f's load
                if waited[0]:
                    frames_bar.set_postfix_str("")
                    waited[0] = False
                if len(release):
                    switch_off(release, f, velocity)
            elif f - 1 in schedule:
                # the recorded run's velocities where it set these bodies free with some
                switch_off(schedule[f - 1], f, freed_velocity)
            eng.step_to(f)
            if record:
                grab(i)
            if f == warm:
                end_warmup(i)
            if record and stop is not None and f > warm and stop(f, mats[i, :, :3, 3], plate_pos[i]):
                n = f + 1
                break
            yield f
        else:
            if ahead_pieces:
                pieces = next(ahead)  # the thread's last item
                if wait_bar:
                    wait_bar[0].update(len(times) - wait_bar[1])
                    wait_bar[1] = len(times)
    finally:
        if ahead is not None:
            ahead.close()  # a pushover that has run away, an error, a signal: no check runs on after the run
        if wait_bar:
            wait_bar[0].close()
    seconds_stepping = time.perf_counter() - t1
    mats, plate_pos, utilisation, beam_motion = mats[:n], plate_pos[:n], utilisation[:n], beam_motion[:n]
    if record and tracker is not None and scene.motion is not None and (pieces is None or n < frames + 1):
        times = times[: n - warm]
        pieces = move_pieces(progress=progress)
    if not bullet and pieces is not None and tracker is not None:
        _poses_from_pieces(mats, warm, pieces, tracker.model.x)
    if not record:
        grab(0)  # the final state only
    if blend_path is not None:
        eng.save(blend_path, len(mats), freed_at)
    return RunOutput(
        time=np.arange(n) / s.fps,
        positions=mats[:, :, :3, 3].astype(np.float64),
        quaternions=quaternions_from_matrices(mats[:, :, :3, :3].astype(np.float64)),
        plate=plate_pos,
        seconds_build=seconds_build,
        seconds_stepping=seconds_stepping,
        bond_break_time_s=tracker.break_time_s if tracker is not None else None,
        bond_break_mode=tracker.break_mode if tracker is not None else None,
        bond_release_time_s=tracker.release_time_s if tracker is not None else None,
        max_utilisation=utilisation if record else None,
        beam_motion=beam_motion if record and tracker is not None and tracker.beam_body is not None else None,
        seconds_joints=tracker.seconds if tracker is not None else 0.0,
        first_check=tracker.first_check if tracker is not None else None,
        contact_solves=solves_used[0] if solves_used[0] is not None else _contact_solves(tracker),
        elastic=_elastic_history(tracker, float(n - 1) / s.fps),
        vibration=_vibration(tracker),
        pieces=pieces,
        frames_of=BULLET_FRAMES if bullet else PIECES_FRAMES,
        freed_velocity=started,
    )


def _contact_solves(tracker) -> dict | None:
    """The joint model's contact solves over the run (:class:`RunOutput`'s ``contact_solves``)."""
    if tracker is None:
        return None
    m = tracker.model
    return {
        "solves": int(m.solves),
        "unconverged": int(m.unconverged_solves),
        "worst_unconverged_in_tolerances": round(float(m.worst_unconverged), 3) if m.unconverged_solves else None,
        "stalled_in_equilibrium": int(m.stalled_in_equilibrium),
        "without_equilibrium": int(m.without_equilibrium),
        "equilibrium_questions_unanswered": int(m.unanswered),
    }


def _start_velocity(velocity: np.ndarray | None) -> np.ndarray | None:
    """The velocities ``(n, 6)`` to set bodies free with (NaN rows: from rest), or None to set them
    free at once from rest (none given, or all at rest: a velocity costs the engine a frame)."""
    if velocity is None or np.isnan(velocity).all():
        return None
    v = np.nan_to_num(velocity)
    return v if v.any() else None


class _NeedsPoses(InputError):
    """A run without Bullet of a structure whose joint checks read Bullet's poses."""


def _follow(scene: Scene, first: RunOutput, blend_path: Path | None, progress: bool | None):
    """Bullet's pass after the verdict's (``first``: a run without Bullet, its frames the verdict's
    pieces' poses): every body kinematic, the verdict's motion played on them frame by frame (the
    held structure stands, the freed pieces rock and slide as the verdict moves them), and the
    bodies of a piece that fell (:attr:`PieceMotion.fell_time_s`) set dynamic at the first frame
    at or after its fall, with the velocities it fell with, its held joints Bullet's constraints and
    the joints let go around it bearing as contacts: Bullet animates the fall onto the ground and
    the debris. The verdict, cracks and releases are ``first``'s; the frames are Bullet's (the
    verdict's pieces exactly until they fall). Bullet is stepped only from three frames before
    the first fall: until then every body is kinematic and its frames are the poses put, keyed in
    the saved .blend (a structure that stands: three steps, where stepping every frame of the
    paper example's quake took 18 s). Bullet's debris then differs from a pass stepped from the
    first frame by its contact caches' history (the verdict does not read it). Yields each frame;
    returns ``first`` with Bullet's poses.

    Why: a freed piece set dynamic on its joints is held together only as far as Bullet's
    iterative solve converges, its motion is not the verdict's, and solving its hundreds of
    constraints was most of a quake's time (docs/dynamics.md)."""
    from .blender import BlenderEngine

    t0 = time.perf_counter()
    s = scene.solver
    nb = len(scene.bodies)
    frames = len(first.time) - 1
    warm = min(s.warmup_frames, frames)
    p = first.pieces
    fell = p.fell_time_s if p is not None and p.fell_time_s is not None else np.full(nb, np.nan)
    fell_v = p.fell_velocity if p is not None and p.fell_velocity is not None else np.full((nb, 6), np.nan)
    hand = np.full(nb, -1)  # the frame each body turns dynamic at (-1: never)
    ok = np.isfinite(fell)
    hand[ok] = np.maximum(warm + np.ceil(fell[ok] * s.fps - 1e-9).astype(int), warm + 1)
    hand[hand > frames] = -1
    # Until the first body turns dynamic every body is kinematic: Bullet has nothing to solve, and
    # its frames are the poses put on the bodies. Its simulation starts three frames before: at
    # the step after the start Blender builds the live bodies from the objects as they stand (an
    # object written at that step has no mesh yet to build a body of: Blender's "no vertices to
    # define Convex Hull"), so that step writes nothing, and the next moves the kinematic bodies
    # from where Bullet has them, before the first dynamic step (its bodies' velocities are those
    # of their last kinematic step). The frames before the start are those poses, keyed in the
    # saved file, not stepped (a structure that stands steps three frames).
    start = max(min(int(hand[hand > 0].min()) if (hand > 0).any() else frames, frames) - 3, 0)
    bond_a = np.array([b.a for b in scene.bonds], dtype=np.int64)
    bond_b = np.array([b.b for b in scene.bonds], dtype=np.int64)

    def ends_in(group: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Per bond, whether both its bodies are in ``group`` (B,) (the plate is in none), and
        whether one is."""
        a, b = group[bond_a], (bond_b >= 0) & group[np.maximum(bond_b, 0)]
        return a & b, a | b

    # Bullet's constraints only for the joints of the bodies that turn dynamic (the others join
    # kinematic bodies, where a constraint is off and does nothing: 1.3 of the 2.0 s it took to
    # build the paper example's scene in Blender)
    eng = BlenderEngine(
        scene,
        np.ones(nb, dtype=bool),
        gravity_per_frame(scene),
        start=start,
        joints=np.flatnonzero(ends_in(hand >= 0)[1]),
    )
    seconds_build = time.perf_counter() - t0
    # when each joint was let go: by the joint model, or inside a piece (--piece-joints)
    release = np.full(len(bond_a), np.nan) if first.bond_release_time_s is None else first.bond_release_time_s
    if p is not None and p.release_time_s is not None:
        release = np.fmin(release, p.release_time_s)
    pos, quat = _with_vibration(scene, first, warm)
    for f in range(1, len(quat)):  # one sign from frame to frame (the keys interpolate linearly)
        quat[f] *= np.where((quat[f] * quat[f - 1]).sum(axis=1) < 0.0, -1.0, 1.0)[:, None]
    placed_pos, placed_quat = pos[0].copy(), quat[0].copy()  # where each kinematic body was put last
    mats = np.zeros((frames + 1, nb, 4, 4), dtype=np.float32)
    plate = np.zeros((frames + 1, 3))
    freed_at = np.full(nb, -1)
    t1 = time.perf_counter()
    eng.step_to(0)
    plate[0] = eng.read_poses(mats[0])
    if warm == 0:
        eng.end_warmup()
    keyed = np.zeros(nb, dtype=bool)  # the bodies moved only in the keys so far (frames not stepped)
    for f in _progress(range(1, frames + 1), desc="bullet", unit="frame", enabled=progress):
        go = np.flatnonzero(hand == f)
        if go.size:
            group = np.zeros(nb, dtype=bool)
            group[go] = True
            inner, touching = ends_in(group)
            gone = release <= (f - warm) / s.fps + 1e-9
            eng.switch_off(np.flatnonzero(touching & gone))  # those joints' bricks bear on each other
            eng.set_free(go, np.flatnonzero(inner & ~gone), _start_velocity(fell_v[go]))
            freed_at[go] = f
        # the kinematic bodies that move by more than a micrometre (or a microradian) from where
        # they were put last
        moves = (np.abs(pos[f] - placed_pos).max(axis=1) > 1e-6) | (np.abs(quat[f] - placed_quat).max(axis=1) > 5e-7)
        drive = np.flatnonzero(moves & ((hand < 0) | (hand > f)))
        if drive.size:
            placed_pos[drive], placed_quat[drive] = pos[f, drive], quat[f, drive]
        if f < start or (f == start + 1 and not go.size):  # keyed only (above)
            if drive.size:
                eng.place(drive, pos[f, drive], quat[f, drive], write=False)
                keyed[drive] = True
            if f < start:
                eng.skip_to(f)
                plate[f] = plate[0]
                mats[f] = _matrices(placed_pos, placed_quat)
            else:
                eng.step_to(f)
                plate[f] = eng.read_poses(mats[f])
                mats[f, keyed] = _matrices(placed_pos[keyed], placed_quat[keyed])
        else:
            if keyed.any():  # the bodies put in the keys alone so far, written where they are now
                drive = np.union1d(drive, np.flatnonzero(keyed))
                keyed[:] = False
            if drive.size:
                eng.place(drive, placed_pos[drive], placed_quat[drive])
            eng.step_to(f)
            plate[f] = eng.read_poses(mats[f])
        if f == max(warm, start + 1):  # with the live bodies (after the start)
            eng.end_warmup()
        yield f
    seconds = time.perf_counter() - t1
    if blend_path is not None:
        eng.save(blend_path, len(mats), freed_at)
    return replace(
        first,
        positions=mats[:, :, :3, 3].astype(np.float64),
        quaternions=quaternions_from_matrices(mats[:, :, :3, :3].astype(np.float64)),
        plate=plate,
        seconds_build=first.seconds_build + seconds_build,
        seconds_stepping=first.seconds_stepping + seconds,
        frames_of=PIECES_THEN_BULLET_FRAMES,
    )


def _matrices(positions: np.ndarray, quaternions: np.ndarray) -> np.ndarray:
    """World matrices ``(B, 4, 4)`` (float32, as an engine's frames) of poses ``(B, 3)``, ``(B, 4)``."""
    out = np.zeros((len(positions), 4, 4), dtype=np.float32)
    out[:, :3, :3] = rotations(quaternions)
    out[:, :3, 3] = positions
    out[:, 3, 3] = 1.0
    return out


def _with_vibration(scene: Scene, first: RunOutput, warm: int) -> tuple[np.ndarray, np.ndarray]:
    """Every body's pose at every frame for Bullet's pass (:func:`_follow`): the verdict's pieces'
    (``first``'s frames) for the bodies set free, and for those that held joints still tie to the
    ground their place moved by the vibration at that frame (:attr:`RunOutput.vibration`: the last
    one recorded at or before it; translation of the centroid, rotation about it). Returns
    positions ``(F, B, 3)`` and quaternions ``(F, B, 4)`` (float64)."""
    pos = first.positions.copy()
    quat = first.quaternions.copy()
    if first.vibration is None:
        return pos, quat
    times, u = first.vibration
    s = scene.solver
    nb = len(scene.bodies)
    release = first.bond_release_time_s if first.bond_release_time_s is not None else np.full(len(scene.bonds), np.nan)
    events = np.unique(release[np.isfinite(release)])
    x0, q0 = first.positions[warm], first.quaternions[warm]
    R0 = rotations(q0)
    held_at, idx = -1, np.zeros(0, dtype=np.int64)
    for f in range(warm + 1, len(pos)):
        t = (f - warm) / s.fps
        k = int(np.searchsorted(times, t + 1e-9, side="right")) - 1
        if k < 0:
            continue
        gone = int(np.searchsorted(events, t + 1e-9, side="right"))
        if gone != held_at:
            held_at = gone
            held = grounded_bodies(scene.bonds, nb, ~(release <= t + 1e-9))
            idx = np.flatnonzero(held)
        if not idx.size:
            continue
        du = u[k, idx].astype(np.float64)
        pos[f, idx] = x0[idx] + du[:, :3]
        quat[f, idx] = quaternions_from_matrices(_rotate(R0[idx], du[:, 3:], exact=False))
    return pos, quat


def _vibration(tracker) -> tuple[np.ndarray, np.ndarray] | None:
    """The tracker's record of every body's vibration at each frame (:attr:`RunOutput.vibration`)."""
    if tracker is None or not tracker.frame_u:
        return None
    return np.array([t for t, _ in tracker.frame_u]), np.stack([u for _, u in tracker.frame_u])


def _elastic_history(tracker, end_s: float) -> dict | None:
    """The tracker's record of the elastic vibration up to the run's last frame (a tracker running
    ahead of Bullet may have stepped further)."""
    if tracker is None or tracker.elastic is None:
        return None
    h = {k: np.asarray(v, dtype=np.float64) for k, v in tracker.history.items()}
    keep = h["time_s"] + tracker.t0 <= end_s + 1e-9
    out = {k: v[keep] for k, v in h.items()}
    out["first_period_s"] = tracker.first_period_s
    out["damping_ratio"] = tracker.elastic.ratio
    return out

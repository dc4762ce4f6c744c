"""The Blender (bpy) adapter: realise a :class:`~calib_masonry.simulation.scene.Scene` in Bullet and step it.

This is the only module that imports ``bpy``, lazily, so everything else works without Blender.
Facts it relies on (measured with bpy 5.0.1, see ../shared/ARCHITECTURE.md):

* bodies and constraints are added by linking objects into the rigid-body world's collections
  (no operators besides ``rigidbody.world_add``); each mesh is built around its centroid;
* convex hulls use ``use_margin = True`` with ``collision_margin = 0`` (a positive margin rounds
  the corners and blocks rock over early); the ground plate uses the BOX shape;
* the world is stepped with ``scene.frame_set(f)`` frame by frame, the point cache covering the run;
* every intact mortar joint is one FIXED constraint that never breaks in Bullet: the joint model
  (:class:`~calib_masonry.simulation.joints.JointModel`) decides, before every step after the
  warm-up, which joints the coming step's load cracks, and the run switches those off;
* the bodies that a chain of joints Bullet holds ties to the plate are *kinematic* (Blender's
  "Animated"): they stand exactly where they are, and the joints among them are off in Bullet
  (nothing for its solver to do), until the joints the run lets go set a part of the structure
  free; that part's bodies then turn dynamic (written on the evaluated objects, as the joints'
  switches are; they start from rest) and its joints act. Why: Bullet holds a joint rigid only
  as far as its iterative solver converges, and a tall structure under its own weight then
  sways by its solver's settings (a 20 m tower of 557 stones: 100 mm at 10 substeps x 50
  iterations, 34 mm at 20 x 100, with no joint let go), while the structure the joint model
  holds is rigid by its own account (its joints move by microns);
  ``rigid_body_constraint.enabled = False`` is written on the *evaluated* object between
  frames: it reaches the live Bullet constraint at once; writing the original object instead
  tags the depsgraph and crashed Blender in about half the trials;
* a bond's constraints disable collisions between its two bricks, and Bullet keeps ignoring that
  pair's contacts after a constraint is merely disabled (a block fell through its support,
  measured); writing ``disable_collisions = False`` on the evaluated constraint as well restores
  them (the block then came to rest on the support).
"""

from __future__ import annotations

import contextlib
import queue
import re
import signal
import sys
import threading
import time
from collections.abc import Callable, Generator, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import TypeVar

import numpy as np

from ..errors import BackendMissing, signals_deferred
from ..progress import progress as _progress
from .joints import CrackTracker
from .pieces import piece_motion
from .scene import Scene, grounded_bodies, joint_axes
from .scene import box_mesh as _box  # the tests build their blocks with it

__all__ = ["RunOutput", "drain", "run", "require_bpy", "steps", "write_model_blend"]

T = TypeVar("T")


# a path Blender puts on sys.path when it starts: <...>/5.0/scripts/modules and the like
_BLENDER_SCRIPTS = re.compile(r"[/\\]\d+\.\d+[/\\]scripts([/\\]|$)")


def require_bpy():
    if "bpy" not in sys.modules:
        # a process spawned by one that ran Blender (a dask worker of a study started after a
        # simulation) inherits Blender's script folders on sys.path, and `import bpy` would then
        # find bpy's Python half (scripts/modules/bpy) before the module: "No module named '_bpy'"
        sys.path[:] = [p for p in sys.path if not _BLENDER_SCRIPTS.search(p)]
    try:
        with _signals_held(), _one_cpu():
            import bpy  # noqa: PLC0415 - the one place bpy is imported
    except ImportError as exc:
        raise BackendMissing(
            "simulate: Blender's bpy module is not installed; install it with "
            "pip install -c constraints.txt 'bpy==5.0.*' (Python 3.11 only)"
        ) from exc
    return bpy


@contextlib.contextmanager
def _one_cpu():
    """Let Blender start its task scheduler (TBB) with one thread: TBB sizes it from the CPUs the
    process may use when bpy is first imported. With a pool of threads, allocations made in
    parallel land in an order that depends on timing, and Bullet's broad phase (ordered by
    address) then steps the same scene differently when the machine is busy: 2 of 6 runs of one
    Stylite job differed under load, 0 of 13 with this (measured). The CPUs are given back after
    the import; the scheduler keeps its single thread."""
    import os

    if "bpy" in sys.modules or not hasattr(os, "sched_setaffinity"):
        yield
        return
    cpus = os.sched_getaffinity(0)
    os.sched_setaffinity(0, {min(cpus)})
    try:
        yield
    finally:
        os.sched_setaffinity(0, cpus)


@contextlib.contextmanager
def _signals_held():
    """Hold SIGTERM and Ctrl-C back while Blender runs Python of its own (start-up, factory
    settings, saving, baking): an exception raised by the CLI's signal handler inside it crashes
    Blender with SIGSEGV. A signal that came meanwhile is handled on the way out. The mask keeps
    the signal from this thread; the deferral covers the signal delivered to another thread."""
    held = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGTERM, signal.SIGINT})
    try:
        with signals_deferred():
            yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, held)


@contextlib.contextmanager
def _stdout_quiet():
    """Blender's own lines to stdout (``Info: Saved as "model.blend"``) go nowhere: the command's
    stdout is its result lines. The file descriptor is redirected (Blender writes from C), and C's
    buffer flushed before it is restored."""
    import ctypes
    import os

    try:
        sys.stdout.flush()
        fd = sys.stdout.fileno()
    except (AttributeError, OSError, ValueError):  # no real stdout (a notebook, a worker): nothing to hide
        yield
        return
    saved = os.dup(fd)
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, fd)
    try:
        yield
    finally:
        try:
            ctypes.CDLL(None).fflush(None)
        except (OSError, AttributeError):
            pass
        os.dup2(saved, fd)
        os.close(saved)
        os.close(devnull)


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
    # the elastic vibration of the structure the intact joints hold (simulation/dynamics.py), per
    # joint-model step after the warm-up: time_s, roof_drift_m, base_shear_n, first_mode (arrays),
    # first_period_s and damping_ratio; None for a quasi-static run
    elastic: dict | None = None
    # the pieces the joint model set free, moved as rigid bodies to convergence (simulation/pieces.py):
    # the verdict's motion; None where no ground motion ran with the joint model
    pieces: object | None = None


def _reset(bpy) -> None:
    with _signals_held():
        bpy.ops.wm.read_factory_settings(use_empty=True)


def _mesh_object(bpy, name: str, vertices: np.ndarray, faces: np.ndarray, location, collection):
    me = bpy.data.meshes.new(name)
    me.from_pydata([tuple(v) for v in vertices.tolist()], [], [tuple(f) for f in faces.tolist()])
    me.validate(clean_customdata=False)
    me.update()
    ob = bpy.data.objects.new(name, me)
    ob.location = tuple(float(x) for x in location)
    collection.objects.link(ob)
    return ob


def write_model_blend(walls, path: str | Path) -> None:
    """Save a built model as a .blend file: one collection per wall, one mesh object per brick
    (its origin at the brick's vertex mean, so it rotates about itself), coloured by wall.

    ``walls``: a sequence of ``(wall name, rgba, bricks)``, each brick ``(name, vertices (V, 3) in
    global metres, triangles (T, 3))``. Blender's state is reset before and after.
    """
    bpy = require_bpy()
    _reset(bpy)
    sc = bpy.context.scene
    for name, rgba, bricks in walls:
        col = bpy.data.collections.new(name)
        sc.collection.children.link(col)
        mat = bpy.data.materials.new(f"{name}_material")
        mat.diffuse_color = tuple(float(x) for x in rgba)
        for brick_name, vertices, faces in bricks:
            centre = np.asarray(vertices, dtype=np.float64).mean(axis=0)
            ob = _mesh_object(bpy, brick_name, np.asarray(vertices) - centre, np.asarray(faces), centre, col)
            ob.data.materials.append(mat)
            ob.color = tuple(float(x) for x in rgba)  # the viewport's object colour
    with _signals_held(), _stdout_quiet():
        bpy.ops.wm.save_as_mainfile(filepath=str(path), check_existing=False, compress=True)
    _reset(bpy)


def _quaternions(r: np.ndarray) -> np.ndarray:
    """Unit quaternions (w, x, y, z) ``(..., 4)`` of rotation matrices ``(..., 3, 3)``, w >= 0
    (scipy's Rotation; Blender's float32 matrices are taken to the nearest rotation)."""
    from scipy.spatial.transform import Rotation

    m = np.asarray(r, dtype=np.float64)
    flat = m.reshape(-1, 3, 3)
    if len(flat) == 0:
        return np.zeros((*m.shape[:-2], 4))
    q = Rotation.from_matrix(flat).as_quat(scalar_first=True)
    q *= np.where(q[:, :1] < 0, -1.0, 1.0)
    return q.reshape(*m.shape[:-2], 4)


def _frame_quaternion(normal: np.ndarray) -> tuple[float, float, float, float]:
    """Quaternion (w, x, y, z) of the joint frame (:func:`~calib_masonry.simulation.scene.joint_axes`)
    whose z axis is ``normal``."""
    x, y, z = (a[0] for a in joint_axes(np.asarray(normal, dtype=np.float64)[None]))
    return tuple(float(v) for v in _quaternions(np.column_stack([x, y, z])))


def _gravity_per_frame(scene: Scene) -> np.ndarray:
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


def _key_gravity(bpy, scene: Scene) -> None:
    sc = bpy.context.scene
    g = _gravity_per_frame(scene)
    if np.all(g == g[-1]):
        sc.gravity = tuple(float(x) for x in g[-1])
        return
    prefs = bpy.context.preferences.edit
    old = prefs.keyframe_new_interpolation_type
    prefs.keyframe_new_interpolation_type = "CONSTANT"
    try:
        for k in range(len(g)):
            sc.gravity = tuple(float(x) for x in g[k])
            sc.keyframe_insert("gravity", frame=k + 1)  # our frame k is Blender's frame k + 1
    finally:
        prefs.keyframe_new_interpolation_type = old


def build_scene(scene: Scene):
    """Create the Blender scene; returns (bpy, body objects, plate object, constraint objects: one
    rigid, unbreakable FIXED constraint per mortar joint, the bodies held fixed (B,): kinematic,
    their joints off in Bullet until they are set free)."""
    bpy = require_bpy()
    _reset(bpy)
    sc = bpy.context.scene
    s = scene.solver
    frames = scene.frames
    sc.render.fps = s.fps
    sc.render.fps_base = 1.0
    sc.frame_start = 1
    sc.frame_end = frames + 1
    sc.gravity = (0.0, 0.0, -scene.gravity)
    sc.use_gravity = True
    with _signals_held():
        bpy.ops.rigidbody.world_add()
    rw = sc.rigidbody_world
    rw.substeps_per_frame = s.substeps
    rw.solver_iterations = s.iterations
    rw.use_split_impulse = scene.solver.split_impulse
    rw.point_cache.frame_start = 1
    rw.point_cache.frame_end = frames + 1
    bodies_col = bpy.data.collections.new("Bricks")
    sc.collection.children.link(bodies_col)
    rb_col = bpy.data.collections.new("RigidBodyWorld")
    rw.collection = rb_col

    # ground plate: a passive BOX that stays put (the ground motion is applied as an inertial force)
    pv, pf = _box(scene.plate.size)
    plate_loc = (scene.plate.centre[0], scene.plate.centre[1], scene.plate.top_z - scene.plate.size[2] / 2)
    plate = _mesh_object(bpy, "ground_plate", pv, pf, plate_loc, sc.collection)
    plate.rotation_euler = (0.0, np.radians(scene.plate.tilt_deg), 0.0)
    rb_col.objects.link(plate)
    prb = plate.rigid_body
    prb.type = "PASSIVE"
    prb.collision_shape = "BOX"
    prb.friction = scene.plate.friction
    prb.restitution = 0.0
    prb.use_margin = True
    prb.collision_margin = 0.0
    _key_gravity(bpy, scene)

    warm = s.warmup_frames
    fixed = grounded_bodies(scene.bonds, len(scene.bodies))
    objects = []
    for b, held_fixed in zip(scene.bodies, fixed):
        ob = _mesh_object(bpy, b.name, b.vertices, b.faces, b.location, bodies_col)
        ob.rotation_mode = "QUATERNION"
        ob.rotation_quaternion = tuple(float(x) for x in b.rotation)
        rb_col.objects.link(ob)
        rb = ob.rigid_body
        rb.type = "ACTIVE"
        rb.collision_shape = b.shape
        rb.use_margin = True
        rb.collision_margin = s.collision_margin_m
        rb.mass = float(b.mass)
        rb.friction = float(b.friction)
        rb.restitution = float(b.restitution)
        rb.linear_damping = rb.angular_damping = s.warmup_damping if warm > 0 else 0.0
        rb.use_deactivation = False
        rb.kinematic = bool(held_fixed)
        objects.append(ob)

    constraints = []
    if scene.bonds:
        ccol = bpy.data.collections.new("RigidBodyConstraints")
        sc.collection.children.link(ccol)
        rw.constraints = ccol
        for k, bond in enumerate(scene.bonds):
            e = bpy.data.objects.new(f"bond_{k:05d}", None)
            e.location = tuple(float(x) for x in bond.location)
            e.rotation_mode = "QUATERNION"
            e.rotation_quaternion = _frame_quaternion(bond.normal)
            e.empty_display_size = 0.02
            ccol.objects.link(e)
            c = e.rigid_body_constraint
            c.type = "FIXED"
            c.object1 = objects[bond.a]
            c.object2 = plate if bond.b < 0 else objects[bond.b]
            c.disable_collisions = True  # an intact joint's bricks do not touch: the joint carries the load
            c.use_breaking = False  # the joint model decides when a joint cracks (see joints.py)
            c.enabled = not fixed[bond.a]  # a joint of the part held fixed acts once that part is set free
            constraints.append(e)
    for k in scene.held_rotation:
        # its rotation locked to the ground, its translations free (a generic constraint with angular
        # limits only): it acts once the body is set free
        e = bpy.data.objects.new(f"held_rotation_{k:05d}", None)
        e.location = tuple(float(x) for x in scene.bodies[k].location)
        if rw.constraints is None:
            ccol = bpy.data.collections.new("RigidBodyConstraints")
            sc.collection.children.link(ccol)
            rw.constraints = ccol
        rw.constraints.objects.link(e)
        c = e.rigid_body_constraint
        c.type = "GENERIC"
        c.object1 = plate
        c.object2 = objects[k]
        for axis in "xyz":
            setattr(c, f"use_limit_ang_{axis}", True)
            setattr(c, f"limit_ang_{axis}_lower", 0.0)
            setattr(c, f"limit_ang_{axis}_upper", 0.0)
    return bpy, objects, plate, constraints, fixed


def _ahead(fn: Callable[[int], T], items: range, release: Callable[[], None]) -> Iterator[T]:
    """``fn(k)`` for each of ``items``, computed in order on a thread of its own as far ahead as it
    gets, yielded in order; ``release()`` runs on that thread as it ends (the joint model's LU
    factors are freed there, on the thread that made them: see
    :meth:`~calib_masonry.simulation.joints.JointModel.release_factors`). Leaving early (an
    error, a stop, ``close()``) stops the thread after the item it is on and waits for it, so
    nothing runs on after the run; an error of ``fn`` is raised here, in its item's turn."""
    results: queue.SimpleQueue = queue.SimpleQueue()
    stop = threading.Event()

    def work() -> None:
        try:
            for k in items:
                if stop.is_set():
                    return
                results.put((True, fn(k)))
        except BaseException as exc:  # noqa: BLE001 - raised by the consumer in its turn
            results.put((False, exc))
        finally:
            release()

    thread = threading.Thread(target=work, name="calib-masonry-joints", daemon=True)
    thread.start()
    try:
        for _ in items:
            ok, value = results.get()
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


def steps(
    scene: Scene,
    *,
    progress: bool | None = None,
    blend_path: Path | None = None,
    record: bool = True,
    switch_off_s: np.ndarray | None = None,
    stop=None,
    joints_ahead: bool = True,
) -> Generator[int, None, RunOutput]:
    """Simulate ``scene`` in one pass, yielding each frame's number once it is stepped, and return
    the :class:`RunOutput` (a caller that drives it from an event loop lets the loop run between
    frames: :func:`calib_masonry.simulation.run.simulate_async`). Closing the generator early
    stops the joint model's thread as an error would. ``joints_ahead=False`` runs the joint model
    on this thread, one check before each step, instead of ahead on a thread of its own (the same
    run, bit for bit): for a process whose cores are busy anyway (a study's workers).

    The pass: the warm-up under (ramped) gravity with every joint intact
    and the bodies damped, then the ground motion (or the pushover's ramp) with no damping, the
    joint model cracking joints before each step (:class:`~calib_masonry.simulation.joints.CrackTracker`).

    Damping is switched, cracked joints switched off and bodies set free (kinematic -> dynamic,
    with the held joints among them switched on) on the evaluated copies of the objects, which
    hold the live Bullet bodies and constraints (writing the originals tags the depsgraph and
    crashed Blender in about half the trials). With ``record=False`` only the stepping is done
    (the bare-Bullet baseline): no poses are read and no joint model runs; ``switch_off_s`` (per
    bond, seconds after the warm-up, NaN for never; the ``bond_release_time_s`` of a recorded run)
    then replays that run's joint switches on a schedule fixed in advance, so the baseline does the
    same Bullet work. ``stop(frame, positions (B, 3), plate (3,))``, if given, is asked after every
    recorded frame whether the run may end there (a pushover ends once it has run away); the
    output then holds the frames up to that one.
    """
    t0 = time.perf_counter()
    bpy, objects, plate, constraints, fixed = build_scene(scene)
    sc = bpy.context.scene
    seconds_build = time.perf_counter() - t0
    s = scene.solver
    frames = scene.frames
    warm = min(s.warmup_frames, frames)
    nb = len(objects)
    n = frames + 1 if record else 1
    plate_pos = np.zeros((n, 3))
    bodies_col = bpy.data.collections["Bricks"]
    position = {ob.name: j for j, ob in enumerate(objects)}
    order = np.array([position[ob.name] for ob in bodies_col.objects], dtype=int)
    buf = np.zeros(nb * 16, dtype=np.float32)
    mats = np.zeros((n, nb, 4, 4), dtype=np.float32)
    gravity = _gravity_per_frame(scene)
    utilisation = np.zeros(n)

    def grab(i: int) -> None:
        # one bulk read of every brick's world matrix (column-major 4x4)
        bodies_col.objects.foreach_get("matrix_world", buf)
        mats[i, order] = buf.reshape(nb, 4, 4).transpose(0, 2, 1)
        plate_pos[i] = plate.matrix_world.translation

    depsgraph = bpy.context.evaluated_depsgraph_get()
    tracker: CrackTracker | None = None

    def end_warmup(i: int) -> None:
        nonlocal tracker
        if warm > 0:
            for ob in objects:
                rb = ob.evaluated_get(depsgraph).rigid_body
                rb.linear_damping = rb.angular_damping = 0.0
        if record and scene.bonds:
            tracker = CrackTracker(scene, mats[i, :, :3, 3], mats[i, :, :3, :3], plate_pos[i], (i) / s.fps)

    schedule: dict[int, list[int]] = {}
    if not record and switch_off_s is not None:
        for k in np.flatnonzero(np.isfinite(switch_off_s)):
            schedule.setdefault(warm + int(round(float(switch_off_s[k]) * s.fps)), []).append(int(k))

    held = np.ones(len(scene.bonds), dtype=bool)  # the joints Bullet holds
    bond_a = np.array([b.a for b in scene.bonds], dtype=np.int64)
    freed_at = np.full(nb, -1)  # the frame at which each body held fixed was set free

    def switch_off(bonds, frame: int) -> None:
        for k in bonds:
            live = constraints[k].evaluated_get(depsgraph).rigid_body_constraint
            live.enabled = False
            live.disable_collisions = False  # the cracked joint's bricks bear on each other
        held[list(bonds)] = False
        # the part of the structure that no held joint ties to the plate any more is set free:
        # its bodies turn dynamic (from rest) and the held joints among them act in Bullet
        free = np.flatnonzero(fixed & ~grounded_bodies(scene.bonds, nb, held))
        if free.size == 0:
            return
        fixed[free] = False
        freed_at[free] = frame
        for j in free:
            objects[j].evaluated_get(depsgraph).rigid_body.kinematic = False
        for k in np.flatnonzero(held & np.isin(bond_a, free)):
            constraints[k].evaluated_get(depsgraph).rigid_body_constraint.enabled = True

    def check(f: int, p: int):
        # the joints that step f's load cracks and Bullet must let go, given the poses of frame p
        # (read only for bodies that bear on the plate without a joint)
        assert tracker is not None
        release = tracker.step(
            (f - 1) / s.fps,
            gravity[f],
            mats[p, :, :3, 3].astype(np.float64),
            mats[p, :, :3, :3].astype(np.float64),
            plate_pos[p].copy(),
        )
        return release, tracker.max_utilisation

    # A tracker that reads no pose (no body bears on the plate without a joint) decides every step
    # from the load history and its own state alone, so it runs ahead on the other core, frame
    # after frame in order, while Bullet steps (frame_set releases the GIL): the joints cracked and
    # let go are those of one check before each step, and the run takes the longer of the two.
    ahead = None
    t1 = time.perf_counter()
    sc.frame_set(1)
    if record:
        grab(0)
    if warm == 0:
        end_warmup(0)
    try:
        for f in _progress(range(1, frames + 1), desc="simulate", unit="frame", enabled=progress):
            i = f if record else 0
            if tracker is not None:
                if joints_ahead and ahead is None and not tracker.reads_poses:
                    ahead = _ahead(lambda k, w=i - 1: check(k, w), range(f, frames + 1), tracker.release_factors)
                p = i - 1
                release, utilisation[p] = next(ahead) if ahead is not None else check(f, p)
                if len(release):
                    switch_off(release, f)
            elif f - 1 in schedule:
                switch_off(schedule[f - 1], f)
            sc.frame_set(f + 1)  # our frame f is Blender's frame f + 1
            if record:
                grab(i)
            if f == warm:
                end_warmup(i)
            if record and stop is not None and f > warm and stop(f, mats[i, :, :3, 3], plate_pos[i]):
                n = f + 1
                break
            yield f
    finally:
        if ahead is not None:
            ahead.close()  # a pushover that has run away, an error, a signal: no check runs on after the run
    seconds_stepping = time.perf_counter() - t1
    mats, plate_pos, utilisation = mats[:n], plate_pos[:n], utilisation[:n]
    pieces = None
    if record and tracker is not None and scene.motion is not None:
        # the verdict's motion of what the joints set free: rigid pieces, converged (not Bullet's)
        pieces = piece_motion(
            scene,
            tracker.release_time_s,
            (np.arange(warm, n) - warm) / s.fps,
            velocity=tracker.free_velocity,
            model=tracker.model,
            progress=progress if np.isfinite(tracker.release_time_s).any() else False,
        )
    if not record:
        grab(0)  # the final state only
    if blend_path is not None:
        # keep the run in the file: the point cache holds every frame just stepped (with the joint
        # model's cracks in it); marked as baked, it is saved and replayed instead of re-simulated
        rw = sc.rigidbody_world
        rw.point_cache.frame_end = len(mats)  # a pushover may have stopped early
        with bpy.context.temp_override(scene=sc, point_cache=rw.point_cache), _signals_held():
            bpy.ops.ptcache.bake_from_cache()
        # a body held fixed plays its own (still) place, a dynamic one the cache: the bodies set
        # free in the run are keyed from fixed to dynamic at the frame they were set free
        for j in np.flatnonzero(freed_at >= 0):
            rb = objects[j].rigid_body
            rb.keyframe_insert("kinematic", frame=1)
            rb.kinematic = False
            rb.keyframe_insert("kinematic", frame=int(freed_at[j]) + 1)  # our frame f is Blender's f + 1
        sc.frame_end = len(mats)
        sc.frame_set(1)
        with _signals_held(), _stdout_quiet():
            bpy.ops.wm.save_as_mainfile(filepath=str(blend_path), check_existing=False, compress=True)
    return RunOutput(
        time=np.arange(n) / s.fps,
        positions=mats[:, :, :3, 3].astype(np.float64),
        quaternions=_quaternions(mats[:, :, :3, :3].astype(np.float64)),
        plate=plate_pos,
        seconds_build=seconds_build,
        seconds_stepping=seconds_stepping,
        bond_break_time_s=tracker.break_time_s if tracker is not None else None,
        bond_break_mode=tracker.break_mode if tracker is not None else None,
        bond_release_time_s=tracker.release_time_s if tracker is not None else None,
        max_utilisation=utilisation if record else None,
        seconds_joints=tracker.seconds if tracker is not None else 0.0,
        elastic=_elastic_history(tracker, float(n - 1) / s.fps),
        pieces=pieces,
    )


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

"""The Blender (bpy) adapter: realise a :class:`~calib_masonry.simulation.scene.Scene` in Bullet and step it.

This is the only module that imports ``bpy``, lazily, so everything else works without Blender.
Facts it relies on (measured with bpy 5.0.1, see ../shared/ARCHITECTURE.md):

* bodies and constraints are added by linking objects into the rigid-body world's collections
  (no operators besides ``rigidbody.world_add``); each mesh is built around its centroid;
* convex hulls use ``use_margin = True`` with ``collision_margin = 0`` (a positive margin rounds
  the corners and blocks rock over early); the ground plate uses the BOX shape;
* the world is stepped with ``scene.frame_set(f)`` frame by frame, the point cache covering the run
  from its start (a later start, ``BlenderEngine(start=...)``, skips frames where every body is
  kinematic: Blender builds the live bodies at the step after the start from the objects as they
  stand, and an object written at that very step has no mesh yet, "no vertices to define Convex
  Hull", so nothing is written there);
* every intact mortar joint is one FIXED constraint that never breaks in Bullet: the joint model
  (:class:`~calib_masonry.simulation.joints.JointModel`) decides, before every step after the
  warm-up, which joints the coming step's load cracks, and the run switches those off;
* the bodies that a chain of joints Bullet holds ties to the plate are *kinematic* (Blender's
  "Animated"): they stand exactly where they are, and the joints among them are off in Bullet
  (nothing for its solver to do), until the joints the run lets go set a part of the structure
  free; that part's bodies then turn dynamic (written on the evaluated objects, as the joints'
  switches are) and its joints act. Bullet gives a kinematic body that turns dynamic the
  velocity its last kinematic step moved it with (measured: a body keyed at 1 m/s goes on at
  1 m/s), so a part set free with the structure's elastic velocities is first moved by them over
  one frame, kinematic (its *original* objects' location and rotation written, which Blender
  re-evaluates into the live body), and turns dynamic a frame later: Bullet's pieces start with
  the velocities the vibration gave them, as the verdict's pieces do (one frame late). Why the
  held structure is kinematic: Bullet holds a joint rigid only as far as its iterative solver
  converges, and a tall structure under its own weight then sways by its solver's settings (a
  20 m tower of 557 stones: 100 mm at 10 substeps x 50 iterations, 34 mm at 20 x 100, with no
  joint let go), while the structure the joint model holds is rigid by its own account (its
  joints move by microns);
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
import re
import signal
import sys
from pathlib import Path

import numpy as np

from ..errors import BackendMissing
from ..process import signals_deferred
from .scene import Scene, box_mesh, joint_axes, quaternions_from_matrices

__all__ = ["BlenderEngine", "require_bpy", "write_model_blend"]


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


def _reset(bpy) -> None:
    with _signals_held():
        bpy.ops.wm.read_factory_settings(use_empty=True)


def _save(bpy, path) -> None:
    """Save Blender's scene as ``path`` (compressed), the signals held and Blender's own line quiet."""
    with _signals_held(), _stdout_quiet():
        bpy.ops.wm.save_as_mainfile(filepath=str(path), check_existing=False, compress=True)


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
    _save(bpy, path)
    _reset(bpy)


def write_animation_blend(scene: Scene, positions: np.ndarray, quaternions: np.ndarray, fps: int, path) -> None:
    """Save a run's frames as a .blend without physics: one mesh object per body, its location and
    rotation keyed at every frame (``positions`` ``(F, B, 3)``, ``quaternions`` ``(F, B, 4)`` w, x,
    y, z; our frame f is Blender's f + 1, linear in between), played at ``fps``. For a run without
    Bullet, whose frames are the verdict's pieces (open it in Blender and press play). Blender's
    state is reset before and after."""
    bpy = require_bpy()
    _reset(bpy)
    sc = bpy.context.scene
    col = bpy.data.collections.new("Bricks")  # as in a run's scene.blend with Bullet
    sc.collection.children.link(col)
    n = len(positions)
    frames = np.arange(1, n + 1)
    for j, b in enumerate(scene.bodies):
        ob = _mesh_object(bpy, b.name or f"body_{j}", np.asarray(b.vertices), np.asarray(b.faces), b.location, col)
        ob.rotation_mode = "QUATERNION"
        _key_transform(bpy, ob, frames, np.concatenate([positions[:, j], quaternions[:, j]], axis=1))
    sc.render.fps = int(fps)
    sc.frame_start, sc.frame_end = 1, n
    sc.frame_set(1)
    _save(bpy, path)
    _reset(bpy)


def _key_transform(bpy, ob, frames: np.ndarray, values: np.ndarray) -> None:
    """Key ``ob``'s location and rotation quaternion at the Blender ``frames`` (n,) to ``values``
    ``(n, 7)`` (x, y, z, w, qx, qy, qz), linear in between, in one write per curve (into the
    object's action where it has one: a rigid body's keyed ``kinematic`` switch)."""
    from bpy_extras import anim_utils

    if ob.animation_data is None:
        ob.animation_data_create()
    if ob.animation_data.action is None:
        action = bpy.data.actions.new(ob.name)
        ob.animation_data.action = action
        ob.animation_data.action_slot = action.slots.new(id_type="OBJECT", name=ob.name)
    bag = anim_utils.action_ensure_channelbag_for_slot(ob.animation_data.action, ob.animation_data.action_slot)
    linear = bpy.types.Keyframe.bl_rna.properties["interpolation"].enum_items["LINEAR"].value
    co = np.empty(2 * len(frames))
    co[0::2] = frames
    interpolation = np.full(len(frames), linear, np.int32)
    for path, first, width in (("location", 0, 3), ("rotation_quaternion", 3, 4)):
        for i in range(width):
            fc = bag.fcurves.find(path, index=i) or bag.fcurves.new(path, index=i)
            fc.keyframe_points.clear()
            fc.keyframe_points.add(len(frames))
            co[1::2] = values[:, first + i]
            fc.keyframe_points.foreach_set("co", co)
            fc.keyframe_points.foreach_set("interpolation", interpolation)
            fc.update()


def _key_poses(bpy, objects: list, moves: dict[int, tuple[np.ndarray, np.ndarray]]) -> None:
    """Key each object ``objects[j]``'s moves ``moves[j]`` (Blender frames (k,), poses (k, 7):
    location, quaternion): :func:`_key_transform`, its place set to the first."""
    for j, (frames, values) in moves.items():
        ob = objects[j]
        ob.location, ob.rotation_quaternion = values[0, :3].tolist(), values[0, 3:].tolist()  # where it stood first
        _key_transform(bpy, ob, frames, values)


def _frame_quaternion(normal: np.ndarray) -> tuple[float, float, float, float]:
    """Quaternion (w, x, y, z) of the joint frame (:func:`~calib_masonry.simulation.scene.joint_axes`)
    whose z axis is ``normal``."""
    x, y, z = (a[0] for a in joint_axes(np.asarray(normal, dtype=np.float64)[None]))
    return tuple(float(v) for v in quaternions_from_matrices(np.column_stack([x, y, z])))


def _key_gravity(bpy, g: np.ndarray) -> None:
    """Key the scene's gravity at every frame: ``g`` ``(frames + 1, 3)``, row k driving the step
    into frame k (:func:`~calib_masonry.simulation.loop.gravity_per_frame`)."""
    sc = bpy.context.scene
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


def _world(bpy, scene: Scene, start: int = 0):
    """Reset Blender and set up the scene's rigid-body world (frames, substeps, iterations), its
    simulation starting at our frame ``start``."""
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
    rw.point_cache.frame_start = start + 1  # our frame f is Blender's frame f + 1
    rw.point_cache.frame_end = frames + 1
    bodies_col = bpy.data.collections.new("Bricks")
    sc.collection.children.link(bodies_col)
    rb_col = bpy.data.collections.new("RigidBodyWorld")
    rw.collection = rb_col
    return sc, rw, bodies_col, rb_col


def _add_plate(bpy, scene: Scene, sc, rb_col):
    """The ground plate: a passive BOX that stays put (the ground motion is applied as an
    inertial force)."""
    pv, pf = box_mesh(scene.plate.size)
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
    return plate


def _add_bodies(bpy, scene: Scene, fixed: np.ndarray, bodies_col, rb_col) -> list:
    """One active convex body per brick, damped during a warm-up, kinematic where held fixed."""
    s = scene.solver
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
        rb.linear_damping = rb.angular_damping = s.warmup_damping if s.warmup_frames > 0 else 0.0
        rb.use_deactivation = False
        rb.kinematic = bool(held_fixed)
        objects.append(ob)
    return objects


def _constraint_collection(bpy, sc, rw):
    if rw.constraints is None:
        ccol = bpy.data.collections.new("RigidBodyConstraints")
        sc.collection.children.link(ccol)
        rw.constraints = ccol
    return rw.constraints


def _add_joints(bpy, scene: Scene, fixed: np.ndarray, objects: list, plate, sc, rw, joints=None) -> dict:
    """One rigid, unbreakable FIXED constraint per mortar joint (off where its part is held
    fixed), for the ``joints`` given (bond indices; None: every one), by bond index; and the
    rotation locks of ``scene.held_rotation``."""
    constraints = {}
    which = range(len(scene.bonds)) if joints is None else [int(k) for k in joints]
    if len(which):
        ccol = _constraint_collection(bpy, sc, rw)
        for k in which:
            bond = scene.bonds[k]
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
            constraints[k] = e
    for k in scene.held_rotation:
        # its rotation locked to the ground, its translations free (a generic constraint with angular
        # limits only): it acts once the body is set free
        e = bpy.data.objects.new(f"held_rotation_{k:05d}", None)
        e.location = tuple(float(x) for x in scene.bodies[k].location)
        _constraint_collection(bpy, sc, rw).objects.link(e)
        c = e.rigid_body_constraint
        c.type = "GENERIC"
        c.object1 = plate
        c.object2 = objects[k]
        for axis in "xyz":
            setattr(c, f"use_limit_ang_{axis}", True)
            setattr(c, f"limit_ang_{axis}_lower", 0.0)
            setattr(c, f"limit_ang_{axis}_upper", 0.0)
    return constraints


class BlenderEngine:
    """A :class:`~calib_masonry.simulation.scene.Scene` realised in Blender's Bullet, driven by
    :func:`calib_masonry.simulation.loop.steps` (the :class:`~calib_masonry.simulation.loop.Engine`
    interface). ``fixed`` ``(B,)``: the bodies held fixed (kinematic, their joints off) until set
    free; ``gravity`` ``(frames + 1, 3)``: the gravity keyed at each frame.

    Damping is switched, joints switched off and bodies set free on the *evaluated* copies of the
    objects, which hold the live Bullet bodies and constraints (writing the originals tags the
    depsgraph and crashed Blender in about half the trials)."""

    def __init__(self, scene: Scene, fixed: np.ndarray, gravity: np.ndarray, start: int = 0, joints=None) -> None:
        bpy = require_bpy()
        sc, rw, bodies_col, rb_col = _world(bpy, scene, start)
        self.plate = _add_plate(bpy, scene, sc, rb_col)
        _key_gravity(bpy, gravity)
        self.objects = _add_bodies(bpy, scene, fixed, bodies_col, rb_col)
        # the joints' constraints by bond index: every joint's, or those of ``joints`` alone (a
        # pass that switches no other: loop._follow); asking for another is a KeyError
        self.constraints = _add_joints(bpy, scene, fixed, self.objects, self.plate, sc, rw, joints)
        self.bpy, self.sc, self.bodies_col = bpy, sc, bodies_col
        position = {ob.name: j for j, ob in enumerate(self.objects)}
        self.order = np.array([position[ob.name] for ob in bodies_col.objects], dtype=int)
        self.buf = np.zeros(len(self.objects) * 16, dtype=np.float32)
        self.depsgraph = bpy.context.evaluated_depsgraph_get()
        self.dt = 1.0 / float(scene.solver.fps)
        self.warm = False  # whether the warm-up's damping is off
        # bodies moved over one kinematic step, to turn dynamic at the next: (last frame stepped, bodies)
        self.pending: list[tuple[int, np.ndarray]] = []
        self.kicked: set[int] = set()  # bodies moved a frame kinematic before turning dynamic
        # the moves written on kinematic bodies, keyed in the saved file: a body's place before its
        # first move (body -> (Blender frame, pose)), and every move as arrays (Blender frame, bodies
        # (n,), poses (n, 7)): a dict of tuples for every held brick at every frame of the paper
        # example's quake (the vibration played) was hundreds of MB of Python objects
        self.rest: dict[int, tuple[int, tuple]] = {}
        self.placed: list[tuple[int, np.ndarray, np.ndarray]] = []
        self.frame = 0

    def step_to(self, frame: int) -> None:
        for _, bodies in [p for p in self.pending if frame >= p[0] + 2]:
            for j in bodies:
                self._dynamic(int(j))
        self.pending = [p for p in self.pending if frame < p[0] + 2]
        self.frame = frame
        self.sc.frame_set(frame + 1)  # our frame f is Blender's frame f + 1

    def skip_to(self, frame: int) -> None:
        """Pass our ``frame`` without evaluating it: a frame before the simulation's start (the
        ``start`` the engine was built with), where every body is kinematic and Bullet has nothing
        to do; the moves :meth:`place` keys there are played from the saved file's keys."""
        self.frame = frame

    def _dynamic(self, j: int) -> None:
        rb = self.objects[j].evaluated_get(self.depsgraph).rigid_body
        rb.kinematic = False
        if self.warm:  # a moved body's live settings were copied again from its original
            rb.linear_damping = rb.angular_damping = 0.0

    def read_poses(self, out: np.ndarray) -> np.ndarray:
        # one bulk read of every brick's world matrix (column-major 4x4)
        self.bodies_col.objects.foreach_get("matrix_world", self.buf)
        out[self.order] = self.buf.reshape(len(self.objects), 4, 4).transpose(0, 2, 1)
        return np.array(self.plate.matrix_world.translation)

    def end_warmup(self) -> None:
        self.warm = True
        for ob in self.objects:
            rb = ob.evaluated_get(self.depsgraph).rigid_body
            rb.linear_damping = rb.angular_damping = 0.0

    def switch_off(self, bonds) -> None:
        for k in bonds:
            live = self.constraints[k].evaluated_get(self.depsgraph).rigid_body_constraint
            live.enabled = False
            live.disable_collisions = False  # the cracked joint's bricks bear on each other

    def _rest(self, j: int) -> None:
        """Record where body ``j`` stood until now, before its first move."""
        if j not in self.rest:
            ob = self.objects[j]
            self.rest[j] = (self.frame + 1, (*ob.location, *ob.rotation_quaternion))

    def place(self, bodies: np.ndarray, locations: np.ndarray, quaternions: np.ndarray, write: bool = True) -> None:
        """Move the kinematic ``bodies`` to ``locations`` ``(n, 3)`` and ``quaternions`` ``(n, 4)``
        (w, x, y, z) over the coming step (a motion computed elsewhere, played by Bullet): their
        *original* objects written, which Blender re-evaluates into the live bodies (and Bullet
        moves them at the velocity of that step); the moves are keyed in the saved file.
        ``write=False`` only keys them (a frame before the simulation's start, :meth:`skip_to`)."""
        bodies = np.asarray(bodies, dtype=np.int64)
        poses = np.concatenate([np.asarray(locations, np.float64), np.asarray(quaternions, np.float64)], axis=1)
        for j, pose in zip(bodies.tolist(), poses.tolist()):
            self._rest(j)
            if write:
                ob = self.objects[j]
                ob.location = pose[:3]
                ob.rotation_quaternion = pose[3:]
        self.placed.append((self.frame + 2, bodies, poses))  # our frame + 1

    def set_free(self, bodies: np.ndarray, bonds: np.ndarray, velocity: np.ndarray | None = None) -> None:
        if velocity is None:
            for j in bodies:
                self._dynamic(int(j))
        else:
            # one frame kinematic at the velocity, then dynamic (the module docstring)
            from mathutils import Quaternion, Vector

            locations, quaternions = [], []
            for j, v in zip(bodies, np.asarray(velocity, dtype=np.float64)):
                ob = self.objects[j]
                self.kicked.add(int(j))
                locations.append(tuple(Vector(tuple(ob.location)) + Vector(tuple(v[:3] * self.dt))))
                q = Quaternion(tuple(ob.rotation_quaternion))
                turn = v[3:] * self.dt
                angle = float(np.linalg.norm(turn))
                if angle > 0.0:
                    q = (Quaternion(tuple(turn / angle), angle) @ q).normalized()
                quaternions.append(tuple(q))
            self.place(np.asarray(bodies), np.array(locations, np.float64), np.array(quaternions, np.float64))
            self.pending.append((self.frame, np.asarray(bodies)))
        for k in bonds:
            self.constraints[k].evaluated_get(self.depsgraph).rigid_body_constraint.enabled = True

    def _moves(self) -> dict[int, tuple[np.ndarray, np.ndarray]]:
        """Every moved body's keys: body -> (Blender frames (k,), poses (k, 7)), in frame order
        (its rest, then its moves; a later record of a frame wins)."""
        frames, bodies, poses = [], [], []
        for j, (f, pose) in self.rest.items():
            frames.append([f]), bodies.append([j]), poses.append([pose])
        for f, b, p in self.placed:
            frames.append(np.full(len(b), f)), bodies.append(b), poses.append(p)
        if not frames:
            return {}
        f = np.concatenate([np.asarray(x, dtype=np.int64) for x in frames])
        b = np.concatenate([np.asarray(x, dtype=np.int64) for x in bodies])
        p = np.concatenate([np.asarray(x, dtype=np.float64).reshape(-1, 7) for x in poses])
        order = np.lexsort((np.arange(len(f)), f, b))  # by body, then frame, then record order
        f, b, p = f[order], b[order], p[order]
        last = np.r_[(b[1:] != b[:-1]) | (f[1:] != f[:-1]), True]  # of equal (body, frame), the last
        f, b, p = f[last], b[last], p[last]
        cuts = np.flatnonzero(np.r_[True, b[1:] != b[:-1], True])
        return {int(b[s]): (f[s:e], p[s:e]) for s, e in zip(cuts[:-1], cuts[1:])}

    def save(self, path: Path, frames: int, freed_at: np.ndarray) -> None:
        """Keep the run in the file: the point cache holds every frame just stepped (with the joint
        model's cracks in it); marked as baked, it is saved and replayed instead of re-simulated. A
        body held fixed plays its own (still) place, a dynamic one the cache: the bodies set free
        in the run are keyed from fixed to dynamic at the frame they were set free."""
        bpy, sc = self.bpy, self.sc
        rw = sc.rigidbody_world
        rw.point_cache.frame_end = frames  # a pushover may have stopped early
        with bpy.context.temp_override(scene=sc, point_cache=rw.point_cache), _signals_held():
            bpy.ops.ptcache.bake_from_cache()
        for j in np.flatnonzero(freed_at >= 0):
            rb = self.objects[j].rigid_body
            rb.keyframe_insert("kinematic", frame=1)
            rb.kinematic = False
            late = int(j) in self.kicked  # moved a frame kinematic first, dynamic a frame later
            rb.keyframe_insert("kinematic", frame=int(freed_at[j]) + 1 + late)  # our frame f is Blender's f + 1
        # the moves written on kinematic bodies: their place until then, each frame's move after
        _key_poses(bpy, self.objects, self._moves())
        sc.frame_end = frames
        sc.frame_set(1)
        _save(bpy, path)

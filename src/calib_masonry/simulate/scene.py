"""The simulation scene as plain data: bodies, mortar bonds, the ground plate and solver settings.

Nothing here imports Blender: :mod:`calib_masonry.simulate.blender` realises a :class:`Scene` in
Bullet through ``bpy``, and any other engine could read the same description.

Mortar model (re-derived from the Bullet Constraints Builder's masonry preset). The mortar joints
are folded into the bricks: each brick's body is its share of the wall, up to the middle of each
joint around it (:func:`calib_masonry.simulate.mortar.mortar_cells`), so neighbours touch and,
once a joint has cracked, bear on each other with Coulomb friction. Bricks whose filled bodies
would overlap a brick they are not bonded to (at corners, where walls meet) keep their exact
shape. The mortar's mass is left out: a body weighs as much as its brick. Each contact patch of
area ``A`` between two bricks' facing faces (any orientation) becomes four constraints at the
patch centroid, in a frame whose z axis is the patch normal:

* compression: one-sided, keeps b from approaching a along the normal, fails at ``f_c A``;
* tension: one-sided, keeps b from leaving a along the normal, fails at ``f_t A``;
* shear: locks sliding in the joint plane, fails at ``f_s A``;
* bending: locks the three rotations, fails at the moment that opens the joint,
  ``M = f_t S + N d / 2 = (f_t + 3 sigma_0) S`` with ``S = A d / 6`` (``d`` the patch's narrower
  width), ``N = sigma_0 A`` the dead load across the joint and ``sigma_0 = rho g h n_z^2`` (``h``
  the height of masonry above the patch: the highest brick top within 0.25 m of it in plan;
  ``n_z`` the normal's vertical part, 0 for head joints). ``N d / 2`` is the moment that rocks a
  joint under compression about its edge; ``f_t S`` is what the mortar's tension adds.

While a joint is intact its two bricks do not collide with each other (the constraints'
``disable_collisions``): the four constraints alone carry the joint's load, each up to its own
strength. With contacts on, a brick turning about its compressed edge lifts the patch centroid,
so the central tension lock carried bending up to ``(f_t A + N) d / 2`` on top of the rotation
lock, and nothing saw the rotation lock break. Once the joint has cracked, the run switches its
constraints off and the pair's contacts back on: a cracked joint carries compression, rocking and
Coulomb friction, and nothing else. Both halves of the bending threshold are needed (measured):
with the elastic ``(f_t + sigma_0) S`` the Stylite tower's eccentrically loaded stone joints
cracked as soon as the warm-up ended and the tower fell under its own weight; with
``(f_t + 3 sigma_0) S`` it stood.

A cracked joint fails as a whole: the run switches its remaining constraints off (see
:mod:`calib_masonry.simulate.monitor`).

Bullet compares each constraint row's impulse with the constraint's threshold, and the rows of a
rotation lock carry angular impulses (N m s): that is why bending is a constraint of its own, with
the threshold ``M dt_sub``.

Bullet breaks a constraint when the impulse it applies within one solver substep exceeds its
threshold, so a joint component that fails at the force ``F = f A`` gets the threshold

    ``J = f A dt_sub``,  with  ``dt_sub = 1 / (fps x substeps)``

in N s (A in m^2, f in Pa); for bending ``M dt_sub`` in N m s. Defaults as the add-on's masonry preset: f_c = 10, f_t = 0.2,
f_s = 0.5 N/mm^2, density 1800 kg/m^3.
"""

from __future__ import annotations

import math
from pathlib import Path
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np
import shapely

from ..build3d.assemble import Brick, brick_solid
from ..build3d.contacts import ContactPatch, contact_patches
from ..build3d.extrude import Polyhedron
from ..build3d.place import Corner, WallFrame
from ..errors import InputError
from .ground_motion import GroundMotion
from .mortar import mortar_cells

__all__ = ["Material", "SolverSettings", "Body", "Bond", "Plate", "Scene", "SceneGeometry", "scene_geometry",
           "scene_from_geometry", "scene_from_bricks", "save_geometry", "load_geometry", "MASONRY",
           "dead_load_precompression", "joint_axes"]


@dataclass(frozen=True)
class Material:
    """Masonry defaults as in the Bullet Constraints Builder preset (strengths in Pa)."""

    density: float = 1800.0
    friction: float = 0.6  # brick-on-brick Coulomb friction (Bullet multiplies the two bodies' values)
    restitution: float = 0.0
    compressive_strength: float = 10e6
    tensile_strength: float = 0.2e6
    shear_strength: float = 0.5e6


MASONRY = Material()


@dataclass(frozen=True)
class SolverSettings:
    """Bullet settings, set explicitly: tall bonded walls need far more iterations than Blender's 10.

    The defaults are the settings the analytic tests pass at (tests/test_simulate.py). Ten substeps
    (a 4 ms step) rather than five: at 5 the paper example jitters by up to 6 mm under gravity
    alone (bonded bricks and their contacts fight at zero margin) and a block at rest on a plane
    sticks up to 10 % past atan(mu); at 10 both are within the tests' tolerances."""

    fps: int = 25
    substeps: int = 10
    iterations: int = 50
    split_impulse: bool = False
    warmup_s: float = 0.5  # gravity only, bonds unbreakable
    gravity_ramp_s: float = 0.3  # within the warm-up, gravity rises smoothly from 0 to g over this time
    # Bullet's linear and angular damping of every body during the warm-up only (velocities x
    # (1 - d) per second): a tall bonded structure otherwise rings at its ~2 Hz sway mode for
    # seconds after taking its weight (about 1 mm at the paper example's wall tops)
    warmup_damping: float = 0.99
    drift_break_m: float = 0.002  # a joint whose faces move apart this far anywhere on its patch has cracked
    crack_whole_joints: bool = True  # switch a cracked joint's remaining constraints off during the run
    moved_threshold_m: float = 0.05  # a brick displaced this far (beyond the plate) counts as moved

    def __post_init__(self) -> None:
        if self.fps <= 0 or self.substeps <= 0 or self.iterations <= 0:
            raise InputError(f"solver settings: fps, substeps and iterations must be > 0 (got {self.fps}, "
                             f"{self.substeps}, {self.iterations})")

    @property
    def warmup_frames(self) -> int:
        return int(round(self.warmup_s * self.fps))

    @property
    def dt_substep(self) -> float:
        return 1.0 / (self.fps * self.substeps)


@dataclass(frozen=True)
class Body:
    name: str
    vertices: np.ndarray  # (V, 3) around the centroid (body frame)
    faces: np.ndarray  # (F, 3)
    location: np.ndarray  # (3,) centroid, global
    mass: float
    friction: float
    restitution: float = 0.0
    volume: float = 0.0
    hull_volume_change: float = 0.0  # relative change from taking the convex hull
    rotation: tuple[float, float, float, float] = (1.0, 0.0, 0.0, 0.0)  # initial orientation (w, x, y, z)


@dataclass(frozen=True)
class Bond:
    """A mortar joint: four constraints at the patch centroid, each breaking at its own impulse per
    substep: compression and tension (one-sided, along ``normal``, a -> b), shear (in the joint
    plane) in N s, and bending (the rotations) in N m s."""

    a: int  # body indices; b = -1 is the ground plate (a foundation bond)
    b: int
    location: np.ndarray  # (3,) patch centroid
    normal: np.ndarray
    area_m2: float
    compression_ns: float
    tension_ns: float
    shear_ns: float
    bending_nms: float = math.inf  # angular impulse per substep (N m s) that opens the joint in bending

    @property
    def thresholds(self) -> tuple[float, float, float, float]:
        """The four constraints' thresholds in the order a joint's constraints are built: compression,
        tension, shear, bending."""
        return (self.compression_ns, self.tension_ns, self.shear_ns, self.bending_nms)


@dataclass(frozen=True)
class Plate:
    """The ground: a passive box that stays put (the ground motion acts as an inertial force).
    ``tilt_deg`` about global Y (for tests)."""

    size: tuple[float, float, float] = (20.0, 20.0, 0.5)
    centre: tuple[float, float] = (0.0, 0.0)
    top_z: float = 0.0
    friction: float = 0.6
    tilt_deg: float = 0.0


@dataclass(frozen=True)
class Scene:
    bodies: tuple[Body, ...]
    bonds: tuple[Bond, ...] = ()
    plate: Plate = Plate()
    motion: GroundMotion | None = None
    duration_s: float = 1.0
    solver: SolverSettings = SolverSettings()
    gravity: float = 9.80665
    notes: dict = field(default_factory=dict)

    @property
    def frames(self) -> int:
        return int(round((self.solver.warmup_s + self.duration_s) * self.solver.fps))


def _body(name: str, vertices: np.ndarray, faces: np.ndarray, location: np.ndarray, volume: float,
          material: Material, hull_volume_change: float = 0.0) -> Body:
    """A body of ``volume`` m^3 of ``material``: the one place a body's mass, friction and
    restitution come from (Bullet multiplies the two bodies' frictions, hence the square root)."""
    return Body(name=name, vertices=vertices, faces=faces, location=location, mass=material.density * volume,
                friction=math.sqrt(material.friction), restitution=material.restitution, volume=float(volume),
                hull_volume_change=float(hull_volume_change))


def body_from_polyhedron(name: str, solid: Polyhedron, material: Material, *, mass_volume: float | None = None,
                         hull_volume_change: float = 0.0) -> Body:
    c = solid.centroid
    return _body(name, solid.vertices - c, solid.faces, c, solid.volume if mass_volume is None else mass_volume,
                 material, hull_volume_change)


def _cell_solid(brick: Brick, outline: np.ndarray | None, frames: list[WallFrame], corners: list[Corner]
                ) -> tuple[Polyhedron, float]:
    """The prism of ``outline`` (the brick's mortar cell in wall 2D, or its convex hull if None),
    extruded and cut at corners; and the relative area change from taking the brick's hull."""
    poly = shapely.Polygon(brick.polygon_m)
    hull = poly.convex_hull
    change = hull.area / poly.area - 1.0 if poly.area > 0 else 0.0
    xy = np.asarray(hull.exterior.coords)[:-1] if outline is None else outline
    solid = brick_solid(xy, brick.wall, frames, corners)
    return (solid if solid is not None else brick.solid), change


def _hull_overlap_depth(ha: np.ndarray, hb: np.ndarray) -> float:
    """The radius of the largest ball inside two convex hulls given by their facet equations
    ``(k, 4)`` (``n . x + d <= 0`` inside; 0 if they do not overlap)."""
    from scipy.optimize import linprog

    h = np.vstack([ha, hb])
    norm = np.linalg.norm(h[:, :3], axis=1)
    res = linprog([0.0, 0.0, 0.0, -1.0], A_ub=np.column_stack([h[:, :3], norm]), b_ub=-h[:, 3],
                  bounds=[(None, None)] * 3 + [(0.0, None)], method="highs")
    return float(res.x[3]) if res.success else 0.0


def _overlapping_unbonded(bodies: Sequence[Body], bonded: set[tuple[int, int]], tol_m: float = 1e-4) -> set[int]:
    """Bodies, not bonded to each other, whose hulls overlap by more than ``tol_m`` (grown bricks
    that meet only along an edge, as two walls' end bricks at a re-entrant corner do, or stones
    whose corners nearly touch, overlap once grown)."""
    lo = np.array([b.location + b.vertices.min(axis=0) for b in bodies])
    hi = np.array([b.location + b.vertices.max(axis=0) for b in bodies])
    from scipy.spatial import cKDTree

    from scipy.spatial import ConvexHull

    centre, half = (lo + hi) / 2, (hi - lo) / 2
    tree = cKDTree(centre)
    facets: dict[int, np.ndarray] = {}  # each body's hull, computed once however many pairs it is in

    def hull(k: int) -> np.ndarray:
        if k not in facets:
            facets[k] = ConvexHull(bodies[k].vertices + bodies[k].location).equations
        return facets[k]

    out: set[int] = set()
    for i, j in tree.query_pairs(2.0 * float(half.max()) * math.sqrt(3.0)):
        if (min(i, j), max(i, j)) in bonded:
            continue
        if np.any(np.abs(centre[i] - centre[j]) >= half[i] + half[j] - tol_m):
            continue
        if _hull_overlap_depth(hull(i), hull(j)) > tol_m:
            out.update((i, j))
    return out


def mortar_bond(a: int, b: int, location: np.ndarray, normal: np.ndarray, area_m2: float, width_m: float,
                sigma0_pa: float, material: Material, dt: float) -> Bond:
    """A mortar joint's four thresholds (see the module docstring): ``f A dt`` for compression,
    tension and shear, ``(f_t + 3 sigma_0) S dt`` with ``S = A d / 6`` for bending."""
    return Bond(a=a, b=b, location=location, normal=normal, area_m2=area_m2,
                compression_ns=material.compressive_strength * area_m2 * dt,
                tension_ns=material.tensile_strength * area_m2 * dt,
                shear_ns=material.shear_strength * area_m2 * dt,
                bending_nms=(material.tensile_strength + 3.0 * sigma0_pa) * area_m2 * width_m / 6.0 * dt)


def joint_axes(normals: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each joint's frame from its normal ``(N, 3)``: in-plane axes ``u, v`` and the unit normal ``n``
    (right-handed, ``u = h x n / |h x n|`` with the helper ``h`` = X, or Y where the normal is nearly
    along X, and ``v = n x u``). The Bullet constraints and the joint monitor share this frame."""
    n = np.asarray(normals, dtype=np.float64)
    n = n / np.linalg.norm(n, axis=1, keepdims=True)
    helper = np.where(np.abs(n[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    u = np.cross(helper, n)
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    return u, np.cross(n, u), n


def dead_load_precompression(bodies: Sequence[Body], points: np.ndarray, normals: np.ndarray, material: Material,
                             radius_m: float = 0.25) -> np.ndarray:
    """Dead-load compression (Pa) across joints at ``points`` ``(N, 3)`` with unit ``normals``:
    ``rho g h n_z^2``, ``h`` from the point up to the highest brick top within ``radius_m`` in plan."""
    from scipy.spatial import cKDTree

    if len(points) == 0:
        return np.zeros(0)
    centres = np.array([b.location[:2] for b in bodies])
    tops = np.array([b.location[2] + b.vertices[:, 2].max() for b in bodies])
    tree = cKDTree(centres)
    near = tree.query_ball_point(points[:, :2], r=radius_m)
    h = np.array([max(0.0, float(tops[i].max()) - z) if i else 0.0 for i, z in zip(near, points[:, 2])])
    nz = np.asarray(normals, dtype=np.float64)[:, 2] / np.linalg.norm(normals, axis=1)
    return material.density * 9.80665 * h * nz**2


def _foundation_bonds(bodies: list[Body], material: Material, dt: float, tol_m: float) -> tuple[Bond, ...]:
    """Bonds between the plate and every body whose bottom lies within a joint's width ``tol_m`` of
    the structure's lowest level: the bed joint on the footing, as thick as it needs to be under an
    irregular stone. Its patch is the body's footprint within ``tol_m`` of its own bottom."""
    bottom = min(float(b.location[2] + b.vertices[:, 2].min()) for b in bodies)
    beds = []  # (body, centroid, area, width) of each footing patch
    for i, b in enumerate(bodies):
        v = b.vertices + b.location
        own = float(v[:, 2].min())
        if own > bottom + tol_m:
            continue
        base = v[v[:, 2] <= own + tol_m]
        hull = shapely.MultiPoint(base[:, :2]).convex_hull
        if hull.area <= 1e-6:
            continue
        c = np.array([hull.centroid.x, hull.centroid.y, bottom])
        rect = hull.minimum_rotated_rectangle
        xy = np.asarray(rect.exterior.coords)[:4] if rect.geom_type == "Polygon" else base[:, :2]
        width = float(min(np.linalg.norm(xy[1] - xy[0]), np.linalg.norm(xy[2] - xy[1]))) if len(xy) >= 3 else 0.0
        beds.append((i, c, float(hull.area), width))
    if not beds:
        return ()
    up = np.array([0.0, 0.0, 1.0])
    s0 = dead_load_precompression(bodies, np.array([c for _, c, _, _ in beds]), np.tile(up, (len(beds), 1)), material)
    return tuple(mortar_bond(i, -1, c, -up, area, width, float(s), material, dt)
                 for (i, c, area, width), s in zip(beds, s0))


@dataclass(frozen=True)
class SceneGeometry:
    """The part of a scene that depends on the built bricks alone, not on materials, solver or
    ground motion: every body's shape (its mortar cell, or its brick where a cell would overlap a
    brick it is not bonded to) and the contact patches between bricks. ``build`` computes it once
    and stores it in the model folder (:func:`save_geometry`), so that every simulation of a model
    (an uncertainty study runs many) starts from it instead of recomputing it (about 2 s on the
    Stylite tower). Body ``i`` is brick ``i`` of the model, in order."""

    names: tuple[str, ...]
    vertices: tuple[np.ndarray, ...]  # each (V, 3) around the body's centroid
    faces: tuple[np.ndarray, ...]  # each (F, 3)
    locations: np.ndarray  # (N, 3) centroids, global
    brick_volumes: np.ndarray  # (N,) the bricks' own volumes (a body weighs as much as its brick)
    hull_volume_change: np.ndarray  # (N,) relative area change from taking the brick's convex hull
    patch_pairs: np.ndarray  # (P, 2) body indices a, b of each contact patch
    patch_centroids: np.ndarray  # (P, 3)
    patch_normals: np.ndarray  # (P, 3), from a to b
    patch_areas: np.ndarray  # (P,) m^2
    patch_widths: np.ndarray  # (P,) the patch's narrower extent, m
    mortar_fill_volume: float  # the mortar given to the bodies, as a fraction of the bricks' volume
    bricks_without_fill: int
    max_gap_m: float
    mortar_fill: bool


def scene_geometry(bricks: Sequence[Brick], frames: list[WallFrame], corners: list[Corner], *,
                   mortar_fill: bool = True, max_gap_m: float = 0.06) -> SceneGeometry:
    """Bodies and contact patches of a built structure (see the module docstring for the mortar model)."""
    if not bricks:
        raise InputError("model: it has no bricks; build it first with `calib-masonry build`")
    patches: list[ContactPatch] = contact_patches(bricks, max_gap_m=max_gap_m, angle_deg=15.0)
    index = {b.id: i for i, b in enumerate(bricks)}
    outlines: list[np.ndarray | None] = [None] * len(bricks)
    if mortar_fill:
        for w in sorted({b.wall for b in bricks}):
            members = [i for i, b in enumerate(bricks) if b.wall == w]
            for i, cell in zip(members, mortar_cells([bricks[i].polygon_m for i in members], 0.5 * max_gap_m)):
                outlines[i] = cell

    def make_body(i: int, outline: np.ndarray | None) -> Body:
        solid, change = _cell_solid(bricks[i], outline, frames, corners)
        return body_from_polyhedron(f"brick_{bricks[i].id:05d}", solid, MASONRY, mass_volume=bricks[i].volume,
                                    hull_volume_change=change)

    bodies = [make_body(i, o) for i, o in enumerate(outlines)]
    pairs = np.array([(index[p.a], index[p.b]) for p in patches], dtype=np.int64).reshape(-1, 2)
    ungrown: set[int] = set()
    if mortar_fill:
        ungrown = _overlapping_unbonded(bodies, {(int(min(a, b)), int(max(a, b))) for a, b in pairs})
        for i in ungrown:
            bodies[i] = make_body(i, None)
    from scipy.spatial import ConvexHull

    fill = sum(ConvexHull(bd.vertices).volume for bd in bodies) / max(1e-12, sum(b.volume for b in bricks)) - 1.0
    return SceneGeometry(
        names=tuple(bd.name for bd in bodies), vertices=tuple(bd.vertices for bd in bodies),
        faces=tuple(np.asarray(bd.faces, dtype=np.int64) for bd in bodies),
        locations=np.array([bd.location for bd in bodies], dtype=np.float64).reshape(-1, 3),
        brick_volumes=np.array([b.volume for b in bricks], dtype=np.float64),
        hull_volume_change=np.array([bd.hull_volume_change for bd in bodies], dtype=np.float64),
        patch_pairs=pairs, patch_centroids=np.array([p.centroid for p in patches], dtype=np.float64).reshape(-1, 3),
        patch_normals=np.array([p.normal for p in patches], dtype=np.float64).reshape(-1, 3),
        patch_areas=np.array([p.area_m2 for p in patches], dtype=np.float64),
        patch_widths=np.array([p.min_width_m for p in patches], dtype=np.float64),
        mortar_fill_volume=float(fill), bricks_without_fill=len(ungrown), max_gap_m=float(max_gap_m),
        mortar_fill=bool(mortar_fill))


def _geometry_code_version() -> str:
    """A hash of the source of every module the geometry is computed by, so that a stored copy
    computed by other code (after any edit to them) is never taken for this code's result."""
    import hashlib
    import sys

    from ..build3d import assemble, contacts, extrude, place
    from . import mortar

    h = hashlib.sha256()
    for module in (sys.modules[__name__], mortar, contacts, assemble, extrude, place):
        h.update(Path(module.__file__).read_bytes())
    return h.hexdigest()[:16]


def save_geometry(geometry: SceneGeometry, path: Path, key: str) -> None:
    """Store ``geometry`` as an npz file; ``key`` names the inputs it was computed from (see
    :func:`load_geometry`)."""
    g = geometry
    nv = np.array([len(v) for v in g.vertices], dtype=np.int64)
    nf = np.array([len(f) for f in g.faces], dtype=np.int64)
    with open(path, "wb") as fh:
        np.savez(fh, key=np.array(f"{_geometry_code_version()}:{key}"), names=np.array(g.names),
                 vertex_counts=nv, vertices=np.concatenate(g.vertices).reshape(-1, 3),
                 face_counts=nf, faces=np.concatenate(g.faces).reshape(-1, 3),
                 locations=g.locations, brick_volumes=g.brick_volumes, hull_volume_change=g.hull_volume_change,
                 patch_pairs=g.patch_pairs, patch_centroids=g.patch_centroids, patch_normals=g.patch_normals,
                 patch_areas=g.patch_areas, patch_widths=g.patch_widths,
                 scalars=np.array([g.mortar_fill_volume, g.bricks_without_fill, g.max_gap_m, float(g.mortar_fill)]))


def load_geometry(path: Path, key: str) -> SceneGeometry | None:
    """The geometry stored at ``path`` if it was computed from the inputs ``key`` names by this
    version of the code (the source of the modules that compute it, hashed); None otherwise (no
    file, another key, other code, an unreadable file)."""
    try:
        with np.load(path, allow_pickle=False) as z:
            if str(z["key"]) != f"{_geometry_code_version()}:{key}":
                return None
            d = {k: z[k] for k in z.files}
    except (OSError, ValueError, KeyError, EOFError):
        return None
    fill, without, gap, filled = (float(x) for x in d["scalars"])
    return SceneGeometry(
        names=tuple(str(n) for n in d["names"]),
        vertices=tuple(np.split(d["vertices"], np.cumsum(d["vertex_counts"])[:-1])),
        faces=tuple(np.split(d["faces"], np.cumsum(d["face_counts"])[:-1])),
        locations=d["locations"], brick_volumes=d["brick_volumes"], hull_volume_change=d["hull_volume_change"],
        patch_pairs=d["patch_pairs"], patch_centroids=d["patch_centroids"], patch_normals=d["patch_normals"],
        patch_areas=d["patch_areas"], patch_widths=d["patch_widths"], mortar_fill_volume=fill,
        bricks_without_fill=int(without), max_gap_m=gap, mortar_fill=bool(filled))


def scene_from_geometry(geometry: SceneGeometry, *, motion: GroundMotion | None, duration_s: float,
                        material: Material = MASONRY, solver: SolverSettings = SolverSettings(),
                        foundation: bool = False) -> Scene:
    """The scene of a structure's geometry under ``material``, ``solver`` and ``motion``: masses,
    frictions and the bonds' thresholds (see the module docstring).

    With ``foundation`` every brick of the bottom course is also bonded to the ground plate by a
    mortar bed of the same strengths over its bottom face: a wall stands on a footing, and without
    it the ground moves the structure only through friction (0.6 g at most)."""
    g = geometry
    bodies = [_body(n, v, f, c, vol, material, h) for n, v, f, c, vol, h in zip(
        g.names, g.vertices, g.faces, g.locations, g.brick_volumes, g.hull_volume_change)]
    dt = solver.dt_substep
    sigma0 = dead_load_precompression(bodies, g.patch_centroids, g.patch_normals, material)
    bonds = tuple(mortar_bond(int(a), int(b), c, n, float(area), float(w), float(s0), material, dt)
                  for (a, b), c, n, area, w, s0 in zip(g.patch_pairs, g.patch_centroids, g.patch_normals,
                                                      g.patch_areas, g.patch_widths, sigma0))
    if foundation:
        bonds = bonds + _foundation_bonds(bodies, material, dt, g.max_gap_m)
    lo = np.min([b.location + b.vertices.min(axis=0) for b in bodies], axis=0)
    hi = np.max([b.location + b.vertices.max(axis=0) for b in bodies], axis=0)
    span = float(max(hi[0] - lo[0], hi[1] - lo[1]))
    plate = Plate(size=(span + 40.0, span + 40.0, 0.5), centre=(float((lo[0] + hi[0]) / 2), float((lo[1] + hi[1]) / 2)),
                  top_z=float(lo[2]), friction=math.sqrt(material.friction))
    notes = {"mortar_fill_volume": g.mortar_fill_volume, "bricks_without_fill": g.bricks_without_fill,
             "bonds": len(bonds), "foundation_bonds": sum(bd.b < 0 for bd in bonds),
             "max_hull_volume_change": float(g.hull_volume_change.max(initial=0.0)),
             "strengths_pa": {"compression": material.compressive_strength, "tension": material.tensile_strength,
                              "shear": material.shear_strength}}
    return Scene(bodies=tuple(bodies), bonds=bonds, plate=plate, motion=motion, duration_s=duration_s,
                 solver=solver, notes=notes)


def scene_from_bricks(bricks: Sequence[Brick], frames: list[WallFrame], corners: list[Corner], *,
                      motion: GroundMotion | None, duration_s: float, material: Material = MASONRY,
                      solver: SolverSettings = SolverSettings(), mortar_fill: bool = True,
                      max_gap_m: float = 0.06, foundation: bool = False) -> Scene:
    """:func:`scene_geometry` and :func:`scene_from_geometry` in one call."""
    return scene_from_geometry(scene_geometry(bricks, frames, corners, mortar_fill=mortar_fill, max_gap_m=max_gap_m),
                               motion=motion, duration_s=duration_s, material=material, solver=solver,
                               foundation=foundation)

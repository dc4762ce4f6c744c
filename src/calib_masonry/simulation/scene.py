"""The simulation scene as plain data: bodies, mortar bonds, the ground plate and solver settings.

Nothing here imports Blender: :mod:`calib_masonry.simulation.blender` realises a :class:`Scene` in
Bullet through ``bpy``, and any other engine could read the same description.

Mortar model. The mortar joints are folded into the bricks: each brick's body is its share of the
wall, up to the middle of each joint around it (:func:`calib_masonry.simulation.mortar.mortar_cells`),
so neighbours touch and, once a joint has cracked, bear on each other with Coulomb friction. Bricks
whose filled bodies would overlap a brick they are not bonded to (at corners, where walls meet) keep
their exact shape. The mortar's mass is left out: a body weighs as much as its brick.

Each contact patch between two bricks' facing faces (any orientation) is a mortar joint
(:class:`Bond`): its centroid, normal, area, second moments and outline. In Bullet an intact joint
is one rigid, unbreakable constraint and its two bricks do not collide; whether and when it cracks
is decided by the elastic joint model (:mod:`calib_masonry.simulation.joints`, where every formula
is), not by Bullet's impulses, whose split between the constraints of a statically indeterminate
structure depends on the solver settings. A cracked joint's constraint is switched off and its
bricks' contacts come back: it then carries compression, rocking and Coulomb friction only.

With ``foundation`` the bottom course is bonded to the ground plate by joints of the same mortar
over each brick's footprint (a footing).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
import shapely

from ..build3d.assemble import MAX_GAP_M, Brick, brick_solid
from ..build3d.bond import corner_roles
from ..build3d.contacts import (
    OUTLINE_POINTS,
    ContactPatch,
    box_pairs,
    contact_patches,
    joint_axes,
    patch_section,
    patch_sections,
)
from ..build3d.extrude import Polyhedron
from ..build3d.place import Corner, WallFrame
from ..errors import InputError
from ..process import raise_if_stopped
from .ground_motion import G, GroundMotion
from .mortar import mortar_cells, nearest_labels, shared_boundary_lengths, wall_joints

__all__ = [
    "ONSET_DRIFT",
    "runaway_m",
    "structure_height",
    "Material",
    "SolverSettings",
    "Body",
    "Bond",
    "Plate",
    "Pushover",
    "ShearTest",
    "shear_test_scene",
    "Scene",
    "SceneGeometry",
    "scene_geometry",
    "scene_from_geometry",
    "MASONRY",
    "MATERIAL_KEYS",
    "MAX_GAP_M",
    "material_from_table",
    "material_table",
    "read_material",
    "joint_axes",
    "footing_patches",
    "grounded_bodies",
    "plate_linked",
    "quaternions_from_matrices",
    "rotations",
    "box_mesh",
]


@dataclass(frozen=True)
class Material:
    """Masonry: the bricks' density and the mortar joints' stiffness and strength (SI units).

    Sources of the defaults: strengths (f_c 10, f_t 0.2 N/mm^2) as in the Bullet Constraints
    Builder's masonry preset; cohesion ``shear_strength`` c = 0.3 N/mm^2 = 1.5 f_t and friction
    0.6, the ratios Lourenco (1996, "Computational strategies for masonry structures", Table 4.2)
    recommends for unit-mortar interfaces; moduli for a lime-cement mortar (E_m 1 GPa, nu 0.2) and
    clay units or stone (E_u 10 GPa, nu 0.15), a 10 mm joint. Only ratios of the stiffnesses
    affect the joint forces (see :mod:`calib_masonry.simulation.joints`)."""

    density: float = 1800.0  # kg/m^3
    friction: float = 0.6  # mu: Coulomb friction of brick on brick and of a cracked joint
    restitution: float = 0.0
    compressive_strength: float = 10e6  # f_c, Pa
    tensile_strength: float = 0.2e6  # f_t, Pa
    shear_strength: float = 0.3e6  # cohesion c of the Mohr-Coulomb criterion tau <= c + mu sigma, Pa
    mortar_youngs_modulus: float = 1.0e9  # E_m, Pa
    mortar_poisson: float = 0.2
    unit_youngs_modulus: float = 10.0e9  # E_u, Pa
    unit_poisson: float = 0.15
    joint_thickness_m: float = 0.01  # t_j
    # E of the masonry as a whole (Pa; a wall's or wallet's compression test, a code's table for its
    # typology), where known: the joints then give each column of units and joint that modulus and
    # 0.4 of it in shear (EN 1996-1-1, 3.7.3) in place of the mortar's and the units' moduli in
    # series (:func:`calib_masonry.simulation.joints.joint_stiffness`); 0: not given
    masonry_youngs_modulus: float = 0.0
    # f_c of the masonry as a whole (Pa; a wall's or wallet's compression test), where known: a
    # cracked joint's contact then crushes at it, each corner carrying at most f_c over its share of
    # the patch, so a rocking wall's toe spreads over N / (f_c t) (the toe crushing of EN 1998-3
    # C.4.2.1's flexural capacity); 0: contacts carry any compression (rigid units; the joints'
    # own criterion, ``compressive_strength``, still cracks an intact joint)
    masonry_compressive_strength: float = 0.0

    def __post_init__(self) -> None:
        for name in (
            "density",
            "compressive_strength",
            "mortar_youngs_modulus",
            "unit_youngs_modulus",
            "joint_thickness_m",
        ):
            if not getattr(self, name) > 0:
                raise InputError(f"material {name} = {getattr(self, name)}: must be > 0")
        for name in (
            "friction",
            "restitution",
            "tensile_strength",
            "shear_strength",
            "masonry_youngs_modulus",
            "masonry_compressive_strength",
        ):
            if not getattr(self, name) >= 0:
                raise InputError(f"material {name} = {getattr(self, name)}: must be >= 0")
        for name in ("mortar_poisson", "unit_poisson"):
            if not 0 <= getattr(self, name) < 0.5:
                raise InputError(f"material {name} = {getattr(self, name)}: must be in [0, 0.5)")


MASONRY = Material()

#: The [material] table of structure.toml and of ``simulate --material FILE``: each key (its unit in
#: its name) and the :class:`Material` field it sets, with the factor from the key's unit to SI.
MATERIAL_KEYS: dict[str, tuple[str, float]] = {
    "density_kg_m3": ("density", 1.0),
    "friction": ("friction", 1.0),
    "restitution": ("restitution", 1.0),
    "compressive_strength_mpa": ("compressive_strength", 1e6),
    "tensile_strength_mpa": ("tensile_strength", 1e6),
    "cohesion_mpa": ("shear_strength", 1e6),
    "mortar_youngs_modulus_mpa": ("mortar_youngs_modulus", 1e6),
    "mortar_poisson": ("mortar_poisson", 1.0),
    "unit_youngs_modulus_mpa": ("unit_youngs_modulus", 1e6),
    "unit_poisson": ("unit_poisson", 1.0),
    "joint_thickness_m": ("joint_thickness_m", 1.0),
    "masonry_youngs_modulus_mpa": ("masonry_youngs_modulus", 1e6),
    "masonry_compressive_strength_mpa": ("masonry_compressive_strength", 1e6),
}
_MATERIAL_KEY_OF = {name: key for key, (name, _) in MATERIAL_KEYS.items()}

#: The largest (and, for the density, smallest) value a [material] table may give, in the key's
#: unit, and what a value beyond it usually is: far outside masonry (units 400-3000 kg/m^3, friction
#: 0.3-1.0, strengths to about 300 MPa in compression and 20 MPa in tension, moduli to about 100 GPa,
#: joints to a few centimetres), so a value beyond is a unit error. :class:`Material` itself (the
#: API) takes any value its physics allows: a test may hold a joint rigid or unbreakable.
MATERIAL_PLAUSIBLE: dict[str, tuple[float, float, str]] = {
    "density_kg_m3": (100.0, 30000.0, "kg/m^3: brick about 1800, stone 2000-2700 (a value in t/m^3 or g/cm^3 x 1000)"),
    "friction": (0.0, 2.0, "a coefficient: masonry 0.3-1.0"),
    "restitution": (0.0, 1.0, "a coefficient in [0, 1]"),
    "compressive_strength_mpa": (0.0, 500.0, "MPa: masonry 1-30, stone units up to about 300 (a value in kPa or Pa?)"),
    "tensile_strength_mpa": (0.0, 50.0, "MPa: mortar joints 0-1 (a value in kPa or Pa?)"),
    "cohesion_mpa": (0.0, 50.0, "MPa: mortar joints 0-1.5 (a value in kPa or Pa?)"),
    "mortar_youngs_modulus_mpa": (0.0, 1e6, "MPa: mortar 100-20,000 (a value in kPa or Pa?)"),
    "unit_youngs_modulus_mpa": (0.0, 1e6, "MPa: brick and stone 2,000-100,000 (a value in kPa or Pa?)"),
    "joint_thickness_m": (0.0, 0.2, "metres: about 0.01 (a value in millimetres?)"),
    "masonry_youngs_modulus_mpa": (
        0.0,
        1e5,
        "MPa: stone and brick masonry 500-20,000, 0 for none (a value in kPa or Pa?)",
    ),
    "masonry_compressive_strength_mpa": (
        0.0,
        300.0,
        "MPa: stone and brick masonry 1-80, 0 for none (a value in kPa or Pa?)",
    ),
}


def material_from_table(table, where: str, base: Material = MASONRY) -> Material:
    """The material a [material] table gives (:data:`MATERIAL_KEYS`; a key left out keeps
    ``base``'s value). Bad input (an unknown key, a value that is no number or out of range) ends in
    an :class:`InputError` that names ``where`` and the key."""
    import difflib

    if not isinstance(table, dict):
        raise InputError(f"{where}: [material] must be a table of numbers ({', '.join(MATERIAL_KEYS)})")
    changes = {}
    for key, value in table.items():
        if key not in MATERIAL_KEYS:
            close = difflib.get_close_matches(str(key), list(MATERIAL_KEYS), n=1, cutoff=0.6)
            hint = f"did you mean {close[0]}?" if close else f"valid keys are {', '.join(MATERIAL_KEYS)}"
            raise InputError(f"{where}: [material] has no key {key!r}; {hint}")
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise InputError(f"{where}: [material] {key} = {value!r}: give a finite number")
        lo, hi, hint = MATERIAL_PLAUSIBLE.get(key, (-math.inf, math.inf, ""))
        if value > hi or (value > 0 and value < lo):
            raise InputError(f"{where}: [material] {key} = {value:g}: outside {lo:g}..{hi:g} {hint}")
        name, scale = MATERIAL_KEYS[key]
        changes[name] = float(value) * scale
    try:
        return replace(base, **changes)
    except InputError as exc:  # Material's own checks name its fields: say them as the table's keys
        message = str(exc)
        for name, key in _MATERIAL_KEY_OF.items():
            scale = MATERIAL_KEYS[key][1]
            if f"material {name} = " in message:
                value = getattr(base, name) if name not in changes else changes[name]
                message = message.replace(f"material {name} = {value}", f"{key} = {value / scale:g}")
        raise InputError(f"{where}: [material] {message}") from None


def material_table(material: Material) -> dict[str, float]:
    """``material`` as a [material] table (:data:`MATERIAL_KEYS`): what summary.json echoes."""
    return {key: float(getattr(material, name)) / scale for key, (name, scale) in MATERIAL_KEYS.items()}


def read_material(path: str | Path, base: Material = MASONRY) -> Material:
    """The material of a TOML file: its [material] table, or its keys at the top level."""
    from ..io import read_toml

    data = read_toml(Path(path), "material file")
    table = data.get("material", data) if isinstance(data, dict) else data
    if isinstance(data, dict) and "material" in data and len(data) > 1:
        others = sorted(k for k in data if k != "material")
        raise InputError(f"{path}: a material file holds a [material] table only; remove {others}")
    return material_from_table(table, str(path), base)


#: Upper limits of the solver settings: far beyond what changes a result (the convergence study
#: doubles the defaults), low enough that a typo does not start a run of days.
MAX_FPS = 1000
MAX_SUBSTEPS = 1000
MAX_ITERATIONS = 10_000


@dataclass(frozen=True)
class SolverSettings:
    """Bullet settings, set explicitly: tall bonded walls need far more iterations than Blender's 10.

    The defaults are the settings the analytic tests pass at (tests/test_simulate.py). Ten substeps
    (a 4 ms step) rather than five: at 5 the paper example jitters by up to 6 mm under gravity
    alone (bonded bricks and their contacts fight at zero margin) and a block at rest on a plane
    sticks up to 10 % past atan(mu); at 10 both are within the tests' tolerances.

    150 iterations rather than 50: the structure that held joints tie to the plate is kinematic
    (still, no work for the solver), so iterations matter only once joints have been let go, for
    the pieces set free. A freed piece of hundreds of bricks is held together by Bullet's rigid
    constraints only as far as the iterative solve converges, and a soft piece rocks where a rigid
    one topples: the Stylite tower (seed 2, 0.15 g), freed above a cracked joint near its base,
    moved 0.3 % of its stones at 50 iterations, 21 % at 2x substeps and 36 % at 100 iterations,
    so that its collapse PGA was 0.25, 0.35 and 0.20 g; at 150 iterations 41 %, and 66 % and
    68 % at 2x substeps and at 300 iterations: collapse PGAs 0.20, 0.15 and 0.15 g
    (experiments/sim_convergence.py; the table is in docs/measurements.md)."""

    fps: int = 25
    substeps: int = 10
    iterations: int = 150
    split_impulse: bool = False
    warmup_s: float = 0.5  # gravity only, bonds unbreakable
    gravity_ramp_s: float = 0.3  # within the warm-up, gravity rises smoothly from 0 to g over this time
    # Bullet's linear and angular damping of every body during the warm-up only (velocities x
    # (1 - d) per second): a tall bonded structure otherwise rings at its ~2 Hz sway mode for
    # seconds after taking its weight (about 1 mm at the paper example's wall tops)
    warmup_damping: float = 0.99
    # a cracked joint's corner is a contact of the joint model (compression only: it is dropped if it
    # would pull) until the joint has opened this far: the statics decide which corners bear; this
    # only lets bodies that have fallen away go (at 1 mm, stones that rocked a little in Bullet lost
    # their support and the Stylite tower cracked 548 joints in 3 s under gravity; at 5 cm, 106)
    contact_gap_m: float = 0.05
    # Bullet's collision margin of the bricks (the plate's is 0): a positive margin rounds a hull's
    # corners by that radius (the rocking threshold of a block of half-width b drops by about
    # margin / b)
    collision_margin_m: float = 0.0
    moved_threshold_m: float = 0.05  # a brick displaced this far (beyond the plate) counts as moved
    # under a ground motion, the joints' forces include the elastic vibration of the structure the
    # intact joints hold (simulation/dynamics.py: Newmark, Rayleigh damping at this ratio of critical
    # at the first two modes); False: quasi-static, the structure rigid (a pushover always is)
    dynamics: bool = True
    damping_ratio: float = 0.05
    # under a ground motion the joint model checks the joints every this many seconds of the record,
    # on a grid from the ground's start that is the same at every frame rate (between frames too),
    # at the record's acceleration at that instant: its cracks, releases and the verdict then do not
    # depend on the frame rate. 0.005 s is the synthetic record's own sampling (200 Hz): every sample
    # is checked. Halving it is the accuracy check (experiments/sim_convergence.py): on the Stylite
    # tower's three records 0.01 -> 0.005 s moved the collapse PGA by 0.00-0.10 g, 0.005 -> 0.0025 s
    # by 0.05-0.10 g, as much as the freed pieces' own settings move it (docs/dynamics.md)
    check_interval_s: float = 0.005
    # under a ground motion, check the joints inside the pieces the joint model sets free against the
    # forces that keep each piece rigid, at the same interval, and split a piece where they let go
    # (simulation/pieces.py, _Pieces.check_joints); off by default until the README's tables are
    # re-run with it (docs/dynamics.md, "A freed piece's own joints")
    piece_joints: bool = False
    # under a ground motion, what Bullet moves: "fallen" (default) plays the verdict's rigid pieces
    # (simulation/pieces.py) on kinematic bodies and takes over a piece's bodies once it has fallen,
    # with their velocities then (its held joints Bullet's constraints); "freed" sets every freed
    # piece's bodies dynamic in Bullet on its joints as it is freed (before 2026-11-29: Bullet's
    # iterative solve of hundreds of constraints, most of a quake's time). The verdict is the pieces'
    # either way (simulation/loop.py, _follow)
    bullet_moves: str = "fallen"

    def __post_init__(self) -> None:
        for flag, value, most in (
            ("--fps", self.fps, MAX_FPS),
            ("--substeps", self.substeps, MAX_SUBSTEPS),
            ("--iterations", self.iterations, MAX_ITERATIONS),
        ):
            if not value > 0:
                raise InputError(
                    f"{flag} {value}: must be > 0 (defaults 25 frames a second, 10 substeps, 150 iterations)"
                )
            if value > most:
                raise InputError(
                    f"{flag} {value}: at most {most}; the defaults already pass the analytic tests, and "
                    "doubling them is the accuracy check"
                )

        if not 0.0 < self.check_interval_s <= 0.1:
            raise InputError(
                f"--check-interval {self.check_interval_s}: the joints' check interval must be in (0, 0.1] s "
                "(default 0.005: every sample of a 200 Hz record)"
            )
        if self.bullet_moves not in ("fallen", "freed"):
            raise InputError(
                f"--bullet-moves {self.bullet_moves!r}: 'fallen' (Bullet takes over the pieces that fell) or "
                "'freed' (Bullet moves every freed piece on its joints)"
            )
        if not 0.0 <= self.damping_ratio < 1.0:
            raise InputError(
                f"--damping {self.damping_ratio}: the ratio of critical damping must be in [0, 1) (masonry: about 0.05)"
            )

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
    shape: str = "CONVEX_HULL"  # Bullet's collision shape: the hull of the vertices, or "BOX" for a box's


@dataclass(frozen=True)
class Bond:
    """A mortar joint between bodies ``a`` and ``b`` (``b = -1``: the ground plate, a foundation
    joint): the patch's centroid, its normal from a to b, area, second moments
    ``(I_uu, I_vv, I_uv)`` about the centroid in the joint frame (:func:`joint_axes`) and its
    outline's corners ``(K, 2)`` in (u, v) about the centroid. A ``dry`` joint has no tensile
    strength and no cohesion whatever the material (a structure set on the ground without a footing
    bears on it through such joints: they hold by friction and compression alone)."""

    a: int
    b: int
    location: np.ndarray  # (3,)
    normal: np.ndarray  # (3,)
    area_m2: float
    moments: np.ndarray  # (3,) m^4
    outline: np.ndarray  # (K, 2) m
    dry: bool = False

    @classmethod
    def rectangle(cls, a: int, b: int, location, normal, along, length: float, width: float) -> "Bond":
        """A ``length x width`` rectangular patch centred on ``location``, its ``length`` along the
        global direction ``along`` (in the joint's plane) and its ``width`` across it."""
        n = np.asarray(normal, dtype=np.float64)
        n = n / np.linalg.norm(n)
        e1 = np.asarray(along, dtype=np.float64)
        e1 = e1 - (e1 @ n) * n
        e1 /= np.linalg.norm(e1)
        basis = np.vstack([e1, np.cross(n, e1)])
        _, moments, outline, area = patch_section(shapely.box(-length / 2, -width / 2, length / 2, width / 2), basis, n)
        return cls(
            a=a,
            b=b,
            location=np.asarray(location, dtype=np.float64),
            normal=n,
            area_m2=area,
            moments=moments,
            outline=outline,
        )


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
class Pushover:
    """A quasi-static collapse analysis: after the warm-up, a uniform lateral acceleration rises
    from 0 at ``rate_g_per_s`` (in g per second) along ``direction_deg`` (from global X), up to
    ``max_g``. The collapse multiplier is the lateral acceleration (in g) at which the structure's
    displacement runs away (see :func:`calib_masonry.simulation.results.collapse_multiplier`)."""

    rate_g_per_s: float = 0.01
    direction_deg: float = 0.0
    max_g: float = 5.0  # mortar walls need 3-4.5 g (a ramp that reaches it says so in summary.json)

    def __post_init__(self) -> None:
        if not (self.rate_g_per_s > 0 and math.isfinite(self.rate_g_per_s)):
            raise InputError(f"--pushover-rate {self.rate_g_per_s}: must be > 0 g per second")
        if not (self.max_g > 0 and math.isfinite(self.max_g)):
            raise InputError(
                f"--pushover-max {self.max_g}: must be > 0 g (the largest lateral acceleration of the ramp)"
            )
        if not math.isfinite(self.direction_deg):
            raise InputError(f"--direction {self.direction_deg}: must be a finite angle in degrees")

    @property
    def duration_s(self) -> float:
        return self.max_g / self.rate_g_per_s

    def lateral_g(self, t: np.ndarray) -> np.ndarray:
        """The lateral acceleration (g) at times ``t`` since the ramp started (0 before)."""
        return np.clip(np.asarray(t, dtype=np.float64) * self.rate_g_per_s, 0.0, self.max_g)


BOUNDARIES = ("cantilever", "double-fixed")


@dataclass(frozen=True)
class ShearTest:
    """The laboratory shear-compression test of a wall: a rigid loading beam on its top carries the
    vertical load ``precompression_pa`` times the wall's section (length x thickness) and is pushed
    along the wall by a slowly rising lateral load, ``rate_per_s`` of that vertical load per second
    (force-controlled, up to ``max_ratio`` of it), its rotation free (``cantilever``: the lateral
    load acts at the beam's centroid, ``shear_span_ratio`` H0 / L above the wall's foot, default the
    wall's height plus 0.1 m) or held (``double-fixed``: H0 = H / 2). The wall stands on a footing
    of its own mortar, the beam on its top course through joints of the same mortar."""

    precompression_pa: float
    boundary: str = "cantilever"
    shear_span_ratio: float | None = None
    rate_per_s: float = 0.01
    max_ratio: float = 2.0

    def __post_init__(self) -> None:
        if not (math.isfinite(self.precompression_pa) and self.precompression_pa > 0):
            raise InputError(
                f"--precompression-mpa {self.precompression_pa / 1e6:g}: must be > 0 MPa (the vertical stress the "
                "loading beam puts on the wall's section)"
            )
        if self.precompression_pa > 50e6:
            raise InputError(
                f"--precompression-mpa {self.precompression_pa / 1e6:g}: above 50 MPa, more than any masonry carries; "
                "give the stress in MPa"
            )
        if self.boundary not in BOUNDARIES:
            raise InputError(f"--boundary {self.boundary!r}: choose one of {', '.join(BOUNDARIES)}")
        if self.shear_span_ratio is not None:
            if self.boundary != "cantilever":
                raise InputError(
                    "--shear-span-ratio: a double-fixed wall's shear span is half its height; drop the flag "
                    "or test a cantilever"
                )
            if not (math.isfinite(self.shear_span_ratio) and self.shear_span_ratio > 0):
                raise InputError(f"--shear-span-ratio {self.shear_span_ratio:g}: must be > 0 (H0 / L)")
        for name in ("rate_per_s", "max_ratio"):
            if not (math.isfinite(getattr(self, name)) and getattr(self, name) > 0):
                raise InputError(f"shear test {name} = {getattr(self, name)}: must be > 0")

    @property
    def duration_s(self) -> float:
        return self.max_ratio / self.rate_per_s


@dataclass(frozen=True)
class Scene:
    bodies: tuple[Body, ...]
    bonds: tuple[Bond, ...] = ()
    plate: Plate = Plate()
    motion: GroundMotion | None = None
    pushover: Pushover | None = None
    material: Material = MASONRY
    duration_s: float = 1.0
    solver: SolverSettings = SolverSettings()
    gravity: float = G
    # bodies whose rotation is held (a shear test's loading beam between fixed ends): Bullet locks it
    # with a constraint to the ground, the joint model with a stiff spring on its rotations
    held_rotation: tuple[int, ...] = ()
    notes: dict = field(default_factory=dict)

    @property
    def frames(self) -> int:
        return int(round((self.solver.warmup_s + self.duration_s) * self.solver.fps))


def plate_linked(a: np.ndarray, b: np.ndarray, n_bodies: int, linked: np.ndarray) -> np.ndarray:
    """``(B,)`` True for the bodies that a chain of the ``linked`` joints (of bodies ``a`` and ``b``,
    ``b < 0`` the ground plate; joints may repeat) ties to the plate."""
    import scipy.sparse as sp
    import scipy.sparse.csgraph as csgraph

    linked = np.asarray(linked, dtype=bool)
    b = np.where(b < 0, n_bodies, b)  # the plate is node n_bodies
    graph = sp.csr_matrix((np.ones(int(linked.sum())), (a[linked], b[linked])), shape=(n_bodies + 1,) * 2)
    _, label = csgraph.connected_components(graph, directed=False)
    return label[:n_bodies] == label[n_bodies]


def grounded_bodies(bonds: Sequence[Bond], n_bodies: int, held: np.ndarray | None = None) -> np.ndarray:
    """``(B,)`` True for the bodies that a chain of ``held`` joints (default: all) ties to the
    ground plate (a foundation joint, ``b < 0``, at its end). Bullet holds such a body fixed: the
    structure it belongs to is rigid and stands on the plate (see simulation/blender.py)."""
    if not bonds or n_bodies == 0:
        return np.zeros(n_bodies, dtype=bool)
    held = np.ones(len(bonds), dtype=bool) if held is None else held
    a = np.array([bd.a for bd in bonds], dtype=np.int64)
    b = np.array([bd.b for bd in bonds], dtype=np.int64)
    return plate_linked(a, b, n_bodies, held)


def _body(
    name: str,
    vertices: np.ndarray,
    faces: np.ndarray,
    location: np.ndarray,
    volume: float,
    material: Material,
    hull_volume_change: float = 0.0,
) -> Body:
    """A body of ``volume`` m^3 of ``material``: the one place a body's mass, friction and
    restitution come from (Bullet multiplies the two bodies' frictions, hence the square root)."""
    return Body(
        name=name,
        vertices=vertices,
        faces=faces,
        location=location,
        mass=material.density * volume,
        friction=math.sqrt(material.friction),
        restitution=material.restitution,
        volume=float(volume),
        hull_volume_change=float(hull_volume_change),
    )


def body_from_polyhedron(
    name: str,
    solid: Polyhedron,
    material: Material,
    *,
    mass_volume: float | None = None,
    hull_volume_change: float = 0.0,
) -> Body:
    c = solid.centroid
    return _body(
        name,
        solid.vertices - c,
        solid.faces,
        c,
        solid.volume if mass_volume is None else mass_volume,
        material,
        hull_volume_change,
    )


def _cell_solid(
    brick: Brick,
    outline: np.ndarray | None,
    frames: list[WallFrame],
    corners: list[Corner],
    ends: tuple[str | None, str | None] = (None, None),
) -> tuple[Polyhedron, float]:
    """The prism of ``outline`` (the brick's mortar cell in wall 2D, or its convex hull if None),
    extruded and cut at corners (``ends``: the brick's place in its course there, as in the
    build, :func:`~calib_masonry.build3d.bond.course_ends`); and the relative area change from
    taking the brick's hull."""
    poly = shapely.Polygon(brick.polygon_m)
    hull = poly.convex_hull
    change = hull.area / poly.area - 1.0 if poly.area > 0 else 0.0
    xy = np.asarray(hull.exterior.coords)[:-1] if outline is None else outline
    solid = brick_solid(xy, brick.wall, frames, corners, ends)
    return (solid if solid is not None else brick.solid), change


def _hull_overlap_depth(ha: np.ndarray, hb: np.ndarray) -> float:
    """The radius of the largest ball inside two convex hulls given by their facet equations
    ``(k, 4)`` (``n . x + d <= 0`` inside; 0 if they do not overlap)."""
    from scipy.optimize import linprog

    h = np.vstack([ha, hb])
    norm = np.linalg.norm(h[:, :3], axis=1)
    res = linprog(
        [0.0, 0.0, 0.0, -1.0],
        A_ub=np.column_stack([h[:, :3], norm]),
        b_ub=-h[:, 3],
        bounds=[(None, None)] * 3 + [(0.0, None)],
        method="highs",
    )
    return float(res.x[3]) if res.success else 0.0


def _overlapping_unbonded(bodies: Sequence[Body], bonded: set[tuple[int, int]], tol_m: float = 1e-4) -> set[int]:
    """Bodies, not bonded to each other, whose hulls overlap by more than ``tol_m`` (grown bricks
    that meet only along an edge, as two walls' end bricks at a re-entrant corner do, or stones
    whose corners nearly touch, overlap once grown)."""
    from scipy.spatial import ConvexHull

    lo = np.array([b.location + b.vertices.min(axis=0) for b in bodies])
    hi = np.array([b.location + b.vertices.max(axis=0) for b in bodies])
    hulls: dict[int, tuple[np.ndarray, np.ndarray]] = {}  # each body's hull, once however many pairs it is in

    def hull(k: int) -> tuple[np.ndarray, np.ndarray]:
        if k not in hulls:
            h = ConvexHull(bodies[k].vertices + bodies[k].location)
            hulls[k] = h.equations, h.points[h.vertices]
        return hulls[k]

    def apart(facets: np.ndarray, corners: np.ndarray) -> bool:
        # a facet plane with all the other hull's corners within tol_m of its outer side: a ball
        # inside both hulls would have its centre there, so its radius is at most tol_m
        return bool(np.any((corners @ facets[:, :3].T + facets[:, 3]).min(axis=0) >= -tol_m))

    out: set[int] = set()
    for i, j in box_pairs(lo, hi, tol_m):
        if (i, j) in bonded:
            continue
        (fi, ci), (fj, cj) = hull(i), hull(j)
        if apart(fi, cj) or apart(fj, ci):  # most neighbours across a joint: no linear programme needed
            continue
        if _hull_overlap_depth(fi, fj) > tol_m:
            out.update((i, j))
    return out


def _level_patches(bodies: Sequence[Body], level: float, tol_m: float, sign: float, other: int) -> tuple[Bond, ...]:
    """Joints between body ``other`` (-1: the plate) and every body whose bottom (``sign`` -1) or top
    (``sign`` +1) lies within ``tol_m`` of ``level``: the body's face within ``tol_m`` of its own
    bottom or top, at ``level``, its normal ``(0, 0, sign)`` from the body to ``other``."""
    basis = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    normal = np.array([0.0, 0.0, sign])
    out = []
    for i, b in enumerate(bodies):
        z = sign * (b.vertices[:, 2] + b.location[2])  # heights, the face's side up
        own = float(z.max())
        if own < sign * level - tol_m:
            continue
        face = (b.vertices + b.location)[z >= own - tol_m]
        hull = shapely.MultiPoint(face[:, :2]).convex_hull
        if hull.area <= 1e-6:
            continue
        c2, moments, outline, area = patch_section(hull, basis, normal)
        out.append(
            Bond(
                a=i,
                b=other,
                location=np.array([c2[0], c2[1], level]),
                normal=normal,
                area_m2=area,
                moments=moments,
                outline=outline,
            )
        )
    return tuple(out)


def footing_patches(bodies: Sequence[Body], tol_m: float, bottom: float | None = None) -> tuple[Bond, ...]:
    """Joints between the plate and every body whose bottom lies within a joint's width ``tol_m`` of
    ``bottom`` (default: the structure's lowest level): the bed joint on the footing, as thick as it
    needs to be under an irregular stone. Its patch is the body's footprint within ``tol_m`` of its
    own bottom; its normal points down, from the body to the ground."""
    if bottom is None:
        bottom = min(float(b.location[2] + b.vertices[:, 2].min()) for b in bodies)
    return _level_patches(bodies, bottom, tol_m, -1.0, -1)


@dataclass(frozen=True)
class _Solid:
    """A body's solid under an id, as :func:`~calib_masonry.build3d.contacts.contact_patches` reads bricks."""

    id: int
    solid: Polyhedron


@dataclass(frozen=True)
class SceneGeometry:
    """The part of a scene that depends on the built bricks alone, not on materials, solver or
    ground motion: every body's shape (its mortar cell, or its brick where a cell would overlap a
    brick it is not bonded to) and the contact patches between bricks. ``build`` computes it once
    and stores it in the model folder (:func:`calib_masonry.build_folder.store_geometry`), so that every simulation of a model
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
    patch_moments: np.ndarray  # (P, 3) second moments (I_uu, I_vv, I_uv) in the joint frame, m^4
    patch_outlines: np.ndarray  # (P, OUTLINE_POINTS, 2) the outline's corners in (u, v), m
    mortar_fill_volume: float  # the mortar given to the bodies, as a fraction of the bricks' volume
    bricks_without_fill: int
    max_gap_m: float
    mortar_fill: bool
    # joint area over the area of the boundary neighbouring bricks of a wall share (within the
    # reach): median and 10th percentile over the pairs, the total, the pairs, those without a joint
    coverage: np.ndarray = field(default_factory=lambda: np.full(5, np.nan))

    def coverage_summary(self) -> dict:
        """The coverage as summary.json reports it (see :func:`joint_coverage`), with the units
        that have no joint beneath them (:meth:`without_bed_joint`, by name)."""
        median, p10, total, pairs, missing = (float(x) for x in self.coverage)
        clean = lambda x: None if not np.isfinite(x) else round(x, 4)  # noqa: E731
        return {
            "median": clean(median),
            "p10": clean(p10),
            "total": clean(total),
            "pairs": int(pairs) if np.isfinite(pairs) else 0,
            "pairs_without_joint": int(missing) if np.isfinite(missing) else 0,
            "reach_m": round(0.5 * self.max_gap_m, 6),
            "units_without_bed_joint": [self.names[i] for i in self.without_bed_joint()],
        }

    def without_bed_joint(self) -> np.ndarray:
        """The bodies above the lowest course with no joint beneath them (none whose normal is
        within 60 degrees of vertical, with the body on its upper side): the bed under them is
        wider than the joint reach (``max_gap_m``: a wide mortar bed, or a unit traced smaller
        than it is) or a void, and they hang from their side joints. Indices, ascending."""
        n = len(self.names)
        if n == 0:
            return np.zeros(0, dtype=np.int64)
        nz = self.patch_normals[:, 2] if len(self.patch_normals) else np.zeros(0)
        bedded = np.zeros(n, dtype=bool)
        pairs = self.patch_pairs.reshape(-1, 2)
        bedded[pairs[nz > 0.5, 1]] = True  # a's normal points up at b: b rests on a
        bedded[pairs[nz < -0.5, 0]] = True
        bottom = np.array([float(v[:, 2].min()) + float(x[2]) for v, x in zip(self.vertices, self.locations)])
        on_ground = bottom <= bottom.min() + self.max_gap_m
        return np.flatnonzero(~bedded & ~on_ground)


#: Pairs sharing less boundary than this (m) touch at a corner: left out of the coverage's median.
MIN_SHARED_M = 0.01


def _walls_on_threads(fn, walls: list) -> list:
    """``[fn(w) for w in walls]``, two walls at a time: Qhull's Voronoi, the distance transform
    and the rasters' array work let the other thread run (the geometry of an 8,190-brick tower:
    43 s one wall after the other, 33 s so). What the threads use is imported here first (no
    module is imported for the first time on a thread: tests/test_thread_imports.py)."""
    import scipy.ndimage  # noqa: F401
    import scipy.spatial  # noqa: F401
    import shapely.ops  # noqa: F401

    from .._threads import thread_map
    from ..wall2d import dice  # noqa: F401

    return thread_map(fn, walls, workers=2)


def wall_segments(bricks: Sequence[Brick], reach: float) -> list[tuple]:
    """The straight pieces of every wall's joints (:func:`~calib_masonry.simulation.mortar.wall_joints`)
    as ``(a, b, P0, P1, n, wall)``: brick indices a < b, the piece's ends in wall metres (x, z)
    and its unit normal there, from a toward b."""
    rows = []
    walls = sorted({b.wall for b in bricks})
    member_lists = [[i for i, b in enumerate(bricks) if b.wall == w] for w in walls]
    joints = _walls_on_threads(lambda m: wall_joints([bricks[i].polygon_m for i in m], reach), member_lists)
    for w, members, found in zip(walls, member_lists, joints):
        polys = [bricks[i].polygon_m for i in members]
        if not found:
            continue
        seg = np.concatenate([sg for _, _, sg in found])
        ij = np.repeat(np.array([(i, j) for i, j, _ in found]), [len(sg) for _, _, sg in found], axis=0)
        mid = seg.mean(axis=1)
        d = seg[:, 1] - seg[:, 0]
        n = np.stack([-d[:, 1], d[:, 0]], axis=1) / np.linalg.norm(d, axis=1, keepdims=True)
        shapes = np.array([shapely.Polygon(p) for p in polys], dtype=object)
        far = shapes[ij[:, 1]]
        eps = 1e-4  # the normal points to b: a step along it nears b
        toward = shapely.distance(shapely.points(mid + eps * n), far) <= shapely.distance(
            shapely.points(mid - eps * n), far
        )
        n = np.where(toward[:, None], n, -n)
        rows += [(members[i], members[j], s0, s1, nn, w) for (i, j), (s0, s1), nn in zip(ij.tolist(), seg, n)]
    return rows


def wall_patches(
    bricks: Sequence[Brick], bodies: Sequence[Body], frames: Sequence[WallFrame], reach: float, segments=None
) -> list[ContactPatch]:
    """The joints between the bricks of each wall over their whole shared boundary
    (:func:`~calib_masonry.simulation.mortar.wall_joints`: the middle of the mortar, no farther than
    ``reach`` from either brick), one planar patch per straight piece, through the wall's thickness
    and within both bodies (their outlines seen along the joint's normal: a body cut at a corner
    carries no joint beyond its cut). ``a``, ``b`` are body indices (a < b), the normal from a to b.
    ``segments``: :func:`wall_segments` of the bricks, if already found."""
    rows = wall_segments(bricks, reach) if segments is None else segments
    if not rows:
        return []
    a_idx = np.array([r[0] for r in rows])
    b_idx = np.array([r[1] for r in rows])
    p0 = np.array([r[2] for r in rows])
    p1 = np.array([r[3] for r in rows])
    n2 = np.array([r[4] for r in rows])
    wall = np.array([r[5] for r in rows])
    along = np.array([[*frames[w].direction, 0.0] for w in range(len(frames))])[wall]
    inward = np.array([[*frames[w].inward, 0.0] for w in range(len(frames))])[wall]
    origin = np.array([[*frames[w].origin_xy, 0.0] for w in range(len(frames))])[wall]
    thick = np.array([frames[w].thickness_m for w in range(len(frames))])[wall]
    up = np.array([0.0, 0.0, 1.0])
    d = (p1 - p0) / np.linalg.norm(p1 - p0, axis=1, keepdims=True)
    e_s = d[:, :1] * along + d[:, 1:] * up
    normals_a = n2[:, :1] * along + n2[:, 1:] * up
    bases_a = np.stack([e_s, inward], axis=1)  # (R, 2, 3): along the piece, through the wall
    # the piece's rectangle through the thickness, global, and in its plane's 2D basis
    ends = [origin + q[:, :1] * along + q[:, 1:] * up for q in (p0, p1)]
    corners = np.stack([ends[0], ends[1], ends[1] + thick[:, None] * inward, ends[0] + thick[:, None] * inward], axis=1)
    patch = shapely.polygons(np.einsum("rck,rjk->rcj", corners, bases_a))
    # cut to both bodies as seen along the normal (convex: the hull of their corners)
    counts = np.array([len(bd.vertices) for bd in bodies])
    starts = np.r_[0, np.cumsum(counts)]
    every = np.concatenate([bd.vertices + bd.location for bd in bodies])
    for idx in (a_idx, b_idx):
        cnt = counts[idx]
        row = np.repeat(np.arange(len(idx)), cnt)
        vid = np.repeat(starts[idx], cnt) + np.arange(cnt.sum()) - np.repeat(np.cumsum(cnt) - cnt, cnt)
        seen = np.einsum("vk,vjk->vj", every[vid], bases_a[row])
        patch = shapely.intersection(patch, shapely.convex_hull(shapely.multipoints(seen, indices=row)))
    offsets = np.einsum("rk,rk->r", corners[:, 0], normals_a)
    keep = list(zip(a_idx.tolist(), b_idx.tolist()))
    c2, moments, outlines, areas, widths = patch_sections(patch, bases_a, normals_a)
    centroids = np.einsum("pj,pjk->pk", c2, bases_a) + offsets[:, None] * normals_a
    return [
        ContactPatch(
            a=a,
            b=b,
            normal=normals_a[k],
            centroid=centroids[k],
            area_m2=float(areas[k]),
            gap_m=0.0,
            min_width_m=float(widths[k]),
            moments=moments[k],
            outline=outlines[k],
        )
        for k, (a, b) in enumerate(keep)
        if areas[k] >= 1e-4
    ]


def joint_coverage(
    bricks: Sequence[Brick],
    frames: Sequence[WallFrame],
    patches: Sequence[ContactPatch],
    reach: float,
    pixel: float = 0.005,
    labels: dict | None = None,
) -> np.ndarray:
    """The joints' area over the boundary neighbouring bricks of one wall share, per pair: the
    shared boundary measured on a raster (:func:`~calib_masonry.simulation.mortar.shared_boundary_lengths`,
    within ``reach`` less one pixel: a boundary at the reach's very edge is not counted on either
    side) times the wall's thickness. ``patches`` name bricks by index. Returns (median, 10th
    percentile, total, pairs, pairs without any joint) over the pairs sharing at least
    :data:`MIN_SHARED_M`. ``labels``: each wall's :func:`~calib_masonry.simulation.mortar.nearest_labels`
    at this reach and pixel, if already found."""
    area: dict[tuple[int, int], float] = {}
    for p in patches:
        key = (min(p.a, p.b), max(p.a, p.b))
        area[key] = area.get(key, 0.0) + p.area_m2
    ratios, shared_total, joint_total = [], 0.0, 0.0
    for w in sorted({b.wall for b in bricks}):
        members = [i for i, b in enumerate(bricks) if b.wall == w]
        t = frames[w].thickness_m
        polys = [bricks[i].polygon_m for i in members]
        lengths = shared_boundary_lengths(polys, reach, pixel=pixel, labels=(labels or {}).get(w))
        for (i, j), length in lengths.items():
            if length < MIN_SHARED_M:
                continue
            a = area.get((members[i], members[j]), 0.0)
            ratios.append(a / (length * t))
            shared_total += length * t
            joint_total += a
    if not ratios:
        return np.array([np.nan, np.nan, np.nan, 0.0, 0.0])
    r = np.array(ratios)
    return np.array([np.median(r), np.percentile(r, 10), joint_total / shared_total, len(r), float(np.sum(r == 0))])


def scene_geometry(
    bricks: Sequence[Brick],
    frames: list[WallFrame],
    corners: list[Corner],
    *,
    mortar_fill: bool = True,
    max_gap_m: float = MAX_GAP_M,
) -> SceneGeometry:
    """Bodies and contact patches of a built structure (see the module docstring for the mortar model)."""
    if not bricks:
        raise InputError("model: it has no bricks; build it first with `calib-masonry build`")
    reach = 0.5 * max_gap_m
    index = {b.id: i for i, b in enumerate(bricks)}
    wall_of = np.array([b.wall for b in bricks])

    def across(found: list[ContactPatch], ids: bool) -> list[ContactPatch]:
        """The patches between bricks of different walls (corners), named by body index."""
        out = []
        for p in found:
            a, b = (index[p.a], index[p.b]) if ids else (p.a, p.b)
            if wall_of[a] != wall_of[b]:
                out.append(replace(p, a=a, b=b))
        return out

    # within a wall, the joints are the middle of the mortar between neighbours, whole
    # (:func:`wall_patches`); where walls meet, the bricks' facing faces
    segments = wall_segments(bricks, reach)
    raise_if_stopped()
    several_walls = len(set(wall_of.tolist())) > 1  # a single wall has no corner joints to look for
    corner_patches = (
        across(contact_patches(bricks, max_gap_m=max_gap_m, angle_deg=15.0, groups=wall_of), ids=True)
        if several_walls
        else []
    )
    bonded = {(int(r[0]), int(r[1])) for r in segments} | {(min(p.a, p.b), max(p.a, p.b)) for p in corner_patches}
    outlines: list[np.ndarray | None] = [None] * len(bricks)
    labels = {}  # each wall's nearest-brick raster: the mortar cells' and the coverage's

    def wall_cells(w: int) -> tuple[list[int], tuple | None, list | None]:
        raise_if_stopped()  # a stop request (SIGTERM) ends the work here, wall by wall and brick by brick
        members = [i for i, b in enumerate(bricks) if b.wall == w]
        polys = [bricks[i].polygon_m for i in members]
        if len(polys) < 2:
            return members, None, None
        found = nearest_labels(polys, reach, 0.005)
        return members, found, mortar_cells(polys, reach, pixel=0.005, labels=found) if mortar_fill else None

    walls = sorted({b.wall for b in bricks})
    for w, (members, found, cells) in zip(walls, _walls_on_threads(wall_cells, walls)):
        if found is not None:
            labels[w] = found
        for i, cell in zip(members, cells or []):
            outlines[i] = cell

    ends: list[tuple[str | None, str | None]] = [(None, None)] * len(bricks)
    members = [[i for i, b in enumerate(bricks) if b.wall == w] for w in range(len(frames))]
    roles = corner_roles([[bricks[i].polygon_m for i in m] for m in members], frames, corners)
    for m, r in zip(members, roles):
        for i, e in zip(m, r):
            ends[i] = e

    def make_body(i: int, outline: np.ndarray | None) -> Body:
        raise_if_stopped()
        solid, change = _cell_solid(bricks[i], outline, frames, corners, ends[i])
        return body_from_polyhedron(
            f"brick_{bricks[i].id:05d}", solid, MASONRY, mass_volume=bricks[i].volume, hull_volume_change=change
        )

    bodies = [make_body(i, o) for i, o in enumerate(outlines)]
    ungrown: set[int] = set()
    if mortar_fill:
        ungrown = _overlapping_unbonded(bodies, bonded)
        for i in ungrown:
            bodies[i] = make_body(i, None)
        if several_walls:
            # where walls meet, the joints are the faces the filled bodies share (the hulls of two
            # neighbouring cells overlap where a cell is not convex: their shared face is a joint even
            # so, overlap up to a joint's reach)
            cells = [_Solid(id=i, solid=Polyhedron(bd.vertices + bd.location, bd.faces)) for i, bd in enumerate(bodies)]
            corner_patches = across(
                contact_patches(cells, max_gap_m=reach, angle_deg=10.0, min_gap_m=-max_gap_m, groups=wall_of),
                ids=False,
            )
            if ungrown:
                # a stone left bare (its cell's hull would overlap a neighbour) faces its neighbours
                # across its whole mortar joint, not half of it, and its faces are the stone's own
                have = {(p.a, p.b) for p in corner_patches}
                near = sorted(ungrown | {j for i, j in bonded if i in ungrown} | {i for i, j in bonded if j in ungrown})
                extra = contact_patches(
                    [cells[k] for k in near],
                    max_gap_m=max_gap_m,
                    angle_deg=15.0,
                    min_gap_m=-max_gap_m,
                    progress=False,
                    groups=wall_of[near],
                )
                corner_patches += [
                    p for p in across(extra, ids=False) if (p.a in ungrown or p.b in ungrown) and (p.a, p.b) not in have
                ]
    raise_if_stopped()
    within = wall_patches(bricks, bodies, frames, reach, segments=segments)
    patches = sorted(within + corner_patches, key=lambda c: (c.a, c.b))
    coverage = joint_coverage(bricks, frames, within, reach, pixel=0.005, labels=labels)
    pairs = np.array([(p.a, p.b) for p in patches], dtype=np.int64).reshape(-1, 2)
    from scipy.spatial import ConvexHull

    fill = sum(ConvexHull(bd.vertices).volume for bd in bodies) / max(1e-12, sum(b.volume for b in bricks)) - 1.0
    return SceneGeometry(
        names=tuple(bd.name for bd in bodies),
        vertices=tuple(bd.vertices for bd in bodies),
        faces=tuple(np.asarray(bd.faces, dtype=np.int64) for bd in bodies),
        locations=np.array([bd.location for bd in bodies], dtype=np.float64).reshape(-1, 3),
        brick_volumes=np.array([b.volume for b in bricks], dtype=np.float64),
        hull_volume_change=np.array([bd.hull_volume_change for bd in bodies], dtype=np.float64),
        patch_pairs=pairs,
        patch_centroids=np.array([p.centroid for p in patches], dtype=np.float64).reshape(-1, 3),
        patch_normals=np.array([p.normal for p in patches], dtype=np.float64).reshape(-1, 3),
        patch_areas=np.array([p.area_m2 for p in patches], dtype=np.float64),
        patch_widths=np.array([p.min_width_m for p in patches], dtype=np.float64),
        patch_moments=np.array([p.moments for p in patches], dtype=np.float64).reshape(-1, 3),
        patch_outlines=np.array([p.outline for p in patches], dtype=np.float64).reshape(-1, OUTLINE_POINTS, 2),
        mortar_fill_volume=float(fill),
        bricks_without_fill=len(ungrown),
        max_gap_m=float(max_gap_m),
        mortar_fill=bool(mortar_fill),
        coverage=coverage,
    )


def scene_from_geometry(
    geometry: SceneGeometry,
    *,
    motion: GroundMotion | None = None,
    duration_s: float,
    material: Material = MASONRY,
    solver: SolverSettings = SolverSettings(),
    foundation: bool = False,
    pushover: Pushover | None = None,
) -> Scene:
    """The scene of a structure's geometry under ``material``, ``solver`` and a ground ``motion`` or
    a ``pushover``: masses, frictions and the mortar joints.

    With ``foundation`` every brick of the bottom course is also bonded to the ground plate by a
    mortar bed over its bottom face: a wall stands on a footing, and without it the ground moves
    the structure only through friction (0.6 g at most)."""
    g = geometry
    bodies = [
        _body(n, v, f, c, vol, material, h)
        for n, v, f, c, vol, h in zip(g.names, g.vertices, g.faces, g.locations, g.brick_volumes, g.hull_volume_change)
    ]
    bonds = tuple(
        Bond(a=int(a), b=int(b), location=c, normal=n, area_m2=float(area), moments=mom, outline=out)
        for (a, b), c, n, area, mom, out in zip(
            g.patch_pairs, g.patch_centroids, g.patch_normals, g.patch_areas, g.patch_moments, g.patch_outlines
        )
    )
    # the bottom course bears on the ground through joints: of mortar on a footing (``foundation``),
    # else dry (friction and compression alone): the joint model decides when they open or slide, as
    # for every other joint, rather than Bullet's friction letting the whole structure creep
    bonds = bonds + tuple(b if foundation else replace(b, dry=True) for b in footing_patches(bodies, g.max_gap_m))
    lo = np.min([b.location + b.vertices.min(axis=0) for b in bodies], axis=0)
    hi = np.max([b.location + b.vertices.max(axis=0) for b in bodies], axis=0)
    span = float(max(hi[0] - lo[0], hi[1] - lo[1]))
    plate = Plate(
        size=(span + 40.0, span + 40.0, 0.5),
        centre=(float((lo[0] + hi[0]) / 2), float((lo[1] + hi[1]) / 2)),
        top_z=float(lo[2]),
        friction=math.sqrt(material.friction),
    )
    notes = {
        "mortar_fill_volume": g.mortar_fill_volume,
        "bricks_without_fill": g.bricks_without_fill,
        "bonds": len(bonds),
        "foundation_bonds": sum(bd.b < 0 and not bd.dry for bd in bonds),
        "ground_contacts": sum(bd.b < 0 and bd.dry for bd in bonds),
        "max_hull_volume_change": float(g.hull_volume_change.max(initial=0.0)),
        "joint_coverage": g.coverage_summary(),
    }
    return Scene(
        bodies=tuple(bodies),
        bonds=bonds,
        plate=plate,
        motion=motion,
        pushover=pushover,
        duration_s=duration_s,
        solver=solver,
        material=material,
        notes=notes,
    )


def quaternions_from_matrices(r: np.ndarray) -> np.ndarray:
    """Unit quaternions (w, x, y, z) ``(..., 4)`` of rotation matrices ``(..., 3, 3)``, w >= 0
    (scipy's Rotation; an engine's float32 matrices are taken to the nearest rotation)."""
    from scipy.spatial.transform import Rotation

    m = np.asarray(r, dtype=np.float64)
    flat = m.reshape(-1, 3, 3)
    if len(flat) == 0:
        return np.zeros((*m.shape[:-2], 4))
    q = Rotation.from_matrix(flat).as_quat(scalar_first=True)
    q *= np.where(q[:, :1] < 0, -1.0, 1.0)
    return q.reshape(*m.shape[:-2], 4)


def rotations(q: np.ndarray) -> np.ndarray:
    """Rotation matrices ``(..., 3, 3)`` of unit quaternions ``(..., 4)`` (w, x, y, z) (scipy's
    Rotation): :func:`quaternions_from_matrices`' inverse."""
    from scipy.spatial.transform import Rotation

    q = np.asarray(q, dtype=np.float64)
    flat = q.reshape(-1, 4)
    if len(flat) == 0:
        return np.zeros((*q.shape[:-1], 3, 3))
    return Rotation.from_quat(flat, scalar_first=True).as_matrix().reshape(*q.shape[:-1], 3, 3)


def box_mesh(size) -> tuple[np.ndarray, np.ndarray]:
    """A box ``size`` (x, y, z) centred on the origin: its corners ``(8, 3)`` and triangles ``(12, 3)``."""
    sx, sy, sz = (s / 2 for s in size)
    v = np.array(
        [
            (-sx, -sy, -sz),
            (sx, -sy, -sz),
            (sx, sy, -sz),
            (-sx, sy, -sz),
            (-sx, -sy, sz),
            (sx, -sy, sz),
            (sx, sy, sz),
            (-sx, sy, sz),
        ]
    )
    f = np.array(
        [
            (0, 3, 2),
            (0, 2, 1),
            (4, 5, 6),
            (4, 6, 7),
            (0, 1, 5),
            (0, 5, 4),
            (1, 2, 6),
            (1, 6, 5),
            (2, 3, 7),
            (2, 7, 6),
            (3, 0, 4),
            (3, 4, 7),
        ]
    )
    return v, f


def _box_body(name: str, size, centre, mass: float, material: Material) -> Body:
    """A rectangular box ``size`` (x, y, z) centred on ``centre``, of ``mass`` kg."""
    v, f = box_mesh(size)
    return Body(
        name=name,
        vertices=v,
        faces=f,
        location=np.asarray(centre, dtype=np.float64),
        mass=float(mass),
        friction=math.sqrt(material.friction),
        restitution=material.restitution,
        volume=float(np.prod(size)),
        shape="BOX",
    )


def capping_patches(bodies: Sequence[Body], beam: int, tol_m: float, top: float) -> tuple[Bond, ...]:
    """Joints between every body whose top lies within ``tol_m`` of ``top`` and the loading beam
    (body ``beam``) resting there: :func:`footing_patches` upside down (each body's top face within
    ``tol_m`` of its own top; the normal points up, from the body to the beam)."""
    return _level_patches(bodies, top, tol_m, 1.0, beam)


def shear_test_scene(
    geometry: SceneGeometry, test: ShearTest, *, material: Material = MASONRY, solver: SolverSettings = SolverSettings()
) -> Scene:
    """The scene of :class:`ShearTest` on a single wall's geometry: the wall on its footing, a rigid
    loading beam on its top (as long and thick as the wall, weighing the vertical load N =
    precompression x L x t, so that gravity puts N on the wall), bonded to the top course, and a
    lateral load rising along the wall: a uniform lateral acceleration ``lambda g`` (a pushover),
    which puts ``lambda N`` on the beam and ``lambda W`` on the wall's own weight W (a few per cent of
    N in laboratory tests; the reported force is the top force with the same overturning moment,
    ``lambda (N + W H / (2 H0))``). The notes carry N, W, L, t, H, H0 and the beam's index."""
    base = scene_from_geometry(geometry, duration_s=test.duration_s, material=material, solver=solver, foundation=True)
    lo = np.min([b.location + b.vertices.min(axis=0) for b in base.bodies], axis=0)
    hi = np.max([b.location + b.vertices.max(axis=0) for b in base.bodies], axis=0)
    along_x = (hi[0] - lo[0]) >= (hi[1] - lo[1])
    length = float((hi - lo)[0 if along_x else 1])
    thick = float((hi - lo)[1 if along_x else 0])
    height = float(hi[2] - lo[2])
    if thick > 0.5 * length:
        raise InputError(
            f"shear test: the model is {length:.3g} x {thick:.3g} m in plan, not a single wall; build one wall "
            "(one [[wall]] table) to test it"
        )
    if test.boundary == "double-fixed":
        beam_h, h0 = 0.2, 0.5 * height
    else:
        h0 = test.shear_span_ratio * length if test.shear_span_ratio is not None else height + 0.1
        if h0 <= height:
            raise InputError(
                f"--shear-span-ratio {h0 / length:g}: puts the load {h0:.3g} m above the foot, inside the wall "
                f"({height:.3g} m high); give at least {height / length:.3g}"
            )
        beam_h = 2.0 * (h0 - height)
    n = test.precompression_pa * length * thick
    w = float(sum(b.mass for b in base.bodies)) * base.gravity
    beam = _box_body(
        "loading_beam",
        (length, thick, beam_h) if along_x else (thick, length, beam_h),
        ((lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, hi[2] + beam_h / 2),
        n / base.gravity,
        material,
    )
    k = len(base.bodies)
    caps = capping_patches(base.bodies, k, geometry.max_gap_m, float(hi[2]))
    if not caps:
        raise InputError("shear test: no stone reaches the wall's top to carry the loading beam")
    pushover = Pushover(rate_g_per_s=test.rate_per_s, direction_deg=0.0 if along_x else 90.0, max_g=test.max_ratio)
    notes = dict(base.notes)
    notes["shear_test"] = {
        "boundary": test.boundary,
        "precompression_mpa": test.precompression_pa / 1e6,
        "vertical_load_kn": n / 1e3,
        "wall_weight_kn": w / 1e3,
        "length_m": length,
        "thickness_m": thick,
        "height_m": height,
        "shear_span_m": h0,
        "shear_span_ratio": h0 / length,
        "beam": k,
        "cap_bonds": len(caps),
        "force_per_g_kn": (n + w * height / (2 * h0)) / 1e3,
    }
    return replace(
        base,
        bodies=base.bodies + (beam,),
        bonds=base.bonds + caps,
        pushover=pushover,
        duration_s=test.duration_s,
        held_rotation=(k,) if test.boundary == "double-fixed" else (),
        notes=notes,
    )


#: a pushover's onset of collapse: a brick moves faster than this fraction of the height per second
#: (simulation/results.py)
ONSET_DRIFT = 1e-3


def structure_height(scene: Scene) -> float:
    z = np.concatenate([b.vertices[:, 2] + b.location[2] for b in scene.bodies])
    return float(z.max() - z.min())


def runaway_m(scene: Scene) -> float:
    """A displacement that only a mechanism reaches: the moved threshold, or ten times the onset
    drift of the structure's height if that is more."""
    return max(scene.solver.moved_threshold_m, 10 * ONSET_DRIFT * structure_height(scene))

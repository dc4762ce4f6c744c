"""``simulate``: a built model + a ground motion or a pushover -> a Bullet run -> a result in memory.

:func:`simulate` is the library call: it takes a :class:`~calib_masonry.build3d.assemble.Structure3D`
(or its :class:`~calib_masonry.simulation.scene.SceneGeometry`, or a ``build`` output folder) and a
load (a :class:`~calib_masonry.simulation.ground_motion.GroundMotion` or a
:class:`~calib_masonry.simulation.scene.Pushover`) and returns a :class:`SimulationResult`; it writes
no file unless ``blend_path`` is given. :func:`write_simulation` writes a result at the edge, and
:func:`simulate_to_folder` is what the command line calls.

Determinism: two :func:`simulate` calls with the same inputs give bit-identical poses, in one
process or in two (tested): every Blender scene is built from an empty file in the order of the
model's bricks and joints, and nothing in it depends on Python's string hashing.
"""

from __future__ import annotations

import math
import threading
import time
import warnings
from collections.abc import Generator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .._json import jsonable
from ..build3d.assemble import MAX_GAP_M, Structure3D
from ..build_folder import checked_model_dir, geometry_for_model, simulation_geometry
from ..errors import InputError
from ..io import check_output, staged_output, write_json
from .ground_motion import (
    MAX_PGA_G,
    RECORD_UNITS,
    G,
    GroundMotion,
    check_record_dt,
    read_accelerogram,
    synthetic_motion,
)
from .joints import scene_joint_stiffness
from .scene import (
    MASONRY,
    Material,
    Pushover,
    Scene,
    SceneGeometry,
    ShearTest,
    SolverSettings,
    material_table,
    scene_from_geometry,
    shear_test_scene,
)

__all__ = [
    "Pushover",
    "SimulationConfig",
    "SimulationResult",
    "simulate",
    "simulate_async",
    "simulate_scene",
    "write_simulation",
    "simulate_to_folder",
    "scene_for",
    "scene_for_model",
    "motion_for",
]


DEFAULT_PGA_G = 0.3  # of a synthetic motion when no PGA is given
MAX_FRAMES = 100_000  # about an hour of simulated time at 25 fps: far beyond any record or pushover
MAX_FRAMES_PNG = 1000


@dataclass(frozen=True)
class SimulationConfig:
    """What ``calib-masonry simulate`` is asked for, checked on construction: a synthetic ground
    motion (``pga_g``, ``duration_s``, ``seed``, ``components``), a recorded one (``accelerogram``)
    or a ``pushover``; the solver, the material and the outputs."""

    # the peak ground acceleration in g: of the synthetic motion (None: 0.3), or, with an
    # accelerogram, the peak the record is scaled to (None: the record as recorded)
    pga_g: float | None = None
    duration_s: float = 10.0
    seed: int = 0
    accelerogram: Path | None = None
    # a second file of the same record, its other horizontal component (along Y): PEER and ESM
    # give one file a component
    accelerogram_y: Path | None = None
    record_units: str | None = None  # of a CSV record: "g" (default), "m/s2" or "cm/s2"; .AT2 and ESM files name theirs
    # a record of accelerations alone (no time column): its time step (s); .AT2 and ESM files give theirs
    record_dt_s: float | None = None
    # two independent horizontal components, as a real earthquake has: with one, along X, the walls
    # parallel to X are loaded only in their plane and stand, so at most the other walls fall (the
    # paper example at 0.6 g, seed 0: 43 % of bricks moved with one component, 71-77 % with two)
    components: int = 2
    direction_deg: float = 0.0  # of a one-component motion, from global X
    solver: SolverSettings = SolverSettings()
    # None: the model folder's material.toml (its structure's [material]) or, without one, MASONRY
    material: Material | None = None
    frames_png: int = 6
    gif_frames: int = 24  # views in collapse.gif (0: none)
    figures: bool = True
    # bond the bottom course to the ground (a footing): without it the ground moves the structure
    # through friction alone, and the whole structure creeps on the plate (a slow turn of ~1 mrad
    # in 10 s under gravity alone on the paper example, measured)
    foundation: bool = True
    # a quasi-static collapse analysis instead of a ground motion (then pga, duration, seed,
    # accelerogram and components are not used)
    pushover: Pushover | None = None
    shear_test: ShearTest | None = None  # the laboratory shear-compression test instead of a load
    # False: no Bullet (a ground motion only): the verdict as with it, the frames the verdict's
    # rigid pieces (scene.blend keyed from them)
    bullet: bool = True

    def __post_init__(self) -> None:
        if self.pga_g is None and self.accelerogram is None:
            object.__setattr__(self, "pga_g", DEFAULT_PGA_G)
        if self.pga_g is not None and not (math.isfinite(self.pga_g) and 0 <= self.pga_g <= MAX_PGA_G):
            raise InputError(
                f"--pga {self.pga_g}: the peak ground acceleration must lie in 0..{MAX_PGA_G:g} g "
                "(the strongest records reach about 3 g)"
            )
        if self.accelerogram_y is not None and self.accelerogram is None:
            raise InputError(
                f"--accelerogram-y {self.accelerogram_y}: the record's Y component alone; add --accelerogram with its X component"
            )
        if self.record_units is not None and self.record_units not in RECORD_UNITS:
            raise InputError(f"--units {self.record_units!r}: choose {', '.join(RECORD_UNITS)}")
        check_record_dt(self.record_dt_s)
        if not (math.isfinite(self.duration_s) and self.duration_s > 0):
            raise InputError(f"--duration {self.duration_s}: must be > 0 seconds")
        if self.components not in (1, 2):
            raise InputError(f"--components {self.components}: give 1 (along --direction) or 2 horizontal components")
        if not math.isfinite(self.direction_deg):
            raise InputError(f"--direction {self.direction_deg}: give the motion's direction in degrees from global X")
        quake = self.pushover is None and self.shear_test is None
        if self.direction_deg and quake and self.accelerogram is None and self.components == 2:
            raise InputError(
                f"--direction {self.direction_deg:g}: the synthetic motion has two horizontal components; a direction "
                "turns one: add --components 1"
            )
        if self.direction_deg and self.accelerogram_y is not None:
            raise InputError(
                f"--direction {self.direction_deg:g}: --accelerogram-y gives the record's Y component; a direction turns "
                "a record of one: drop one of them"
            )
        if self.frames_png < 0:
            raise InputError(f"--frames {self.frames_png}: must be >= 0 (collapse frames to render)")
        if not 0 <= self.seed < 2**63:
            raise InputError(f"--seed {self.seed}: must be a whole number >= 0")
        seconds = self.pushover.duration_s if self.pushover is not None else self.duration_s
        frames = seconds * self.solver.fps
        if frames > MAX_FRAMES:
            what = (
                f"--pushover-max {self.pushover.max_g:g} at --pushover-rate {self.pushover.rate_g_per_s:g}"
                if self.pushover is not None
                else f"--duration {self.duration_s:g}"
            )
            raise InputError(
                f"{what}: {seconds:.4g} s at {self.solver.fps} fps is {frames:.3g} frames, above {MAX_FRAMES:,}; "
                "give a shorter run (a quake's strong motion lasts seconds; a pushover ramp of 0.01 g/s to 1 g "
                "is 100 s)"
            )
        if not 0 <= self.gif_frames <= MAX_FRAMES_PNG:
            raise InputError(f"--gif-frames {self.gif_frames}: must lie in 0..{MAX_FRAMES_PNG}")
        if self.frames_png > MAX_FRAMES_PNG:
            raise InputError(f"--frames {self.frames_png}: at most {MAX_FRAMES_PNG} collapse frames are rendered")
        if not self.bullet and (self.pushover is not None or self.shear_test is not None):
            raise InputError(
                "--no-bullet: only for a ground motion (a pushover or a shear test ends where Bullet's poses run "
                "away); run it with Bullet"
            )
        if not self.bullet and not self.foundation:
            raise InputError(
                "--no-bullet with --no-foundation: the bricks stand on the plate without a joint, and where they "
                "touch it is Bullet's to say; keep the footing or run it with Bullet"
            )


@dataclass(frozen=True)
class SimulationResult:
    """One run: the scene it simulated, the poses at every frame (:class:`~calib_masonry.simulation.loop.RunOutput`),
    the metrics read from them, the pushover curve (collapse multiplier in g or None, lateral
    acceleration in g and roof displacement in m per frame; None for a ground motion) and the
    summary (what ``summary.json`` holds)."""

    scene: Scene
    output: object  # loop.RunOutput
    metrics: object  # results.Metrics
    curve: tuple | None
    summary: dict
    shear: dict | None = None  # a shear test's force-drift curve (results.shear_curve), None otherwise

    @property
    def collapse_multiplier_g(self) -> float | None:
        return None if self.curve is None else self.curve[0]


def motion_for(config: SimulationConfig) -> GroundMotion:
    """The ground motion of a run. A synthetic record is scaled so that its samples (200 Hz) peak
    at the PGA, the same record at every frame rate: the joint model reads the record itself (its
    vibration at every Newmark step, its checks of the joints on a grid common to all frame rates),
    and the verdict with it. Bullet's animation applies the mean over each frame, which peaks
    10-20 % lower for a broadband record at 25 fps (0.49-0.54 g for 0.6 g records, seeds 0-2,
    measured: ``ground_motion.bullet_applied_peak_g`` in summary.json). Until 2026-11-27 the record
    was scaled so that the frame means peaked at the PGA instead, a record 7 % stronger at 25 fps
    than at 50 fps (Stylite, seed 0, 0.5 g: 0.56 against 0.52 g at its samples), which moved the
    collapse PGA with the frame rate. A recorded accelerogram is applied as recorded, or, with
    ``pga_g``, scaled the same way so that its peak is the PGA."""
    if config.accelerogram is not None:
        record = read_accelerogram(
            config.accelerogram, units=config.record_units, path_y=config.accelerogram_y, dt=config.record_dt_s
        )
        if config.direction_deg:
            record = record.along(config.direction_deg)
        if config.pga_g is not None and config.pga_g > 0 and record.pga <= 0:
            # (it ran the still record and reported the structure standing under "0.3 g")
            raise InputError(
                f"--accelerogram {config.accelerogram}: every acceleration in it is 0, so --pga {config.pga_g:g} "
                "cannot scale it; give the record with its motion"
            )
        return record if config.pga_g is None else record.at_pga(config.pga_g)
    motion = synthetic_motion(
        config.pga_g,
        config.duration_s,
        seed=config.seed,
        components=config.components,
        direction_deg=config.direction_deg,
    )
    if motion.pga <= 0:
        return motion
    return motion.scaled(config.pga_g * G / motion.pga)


def scene_for(
    model: Structure3D | SceneGeometry,
    load: GroundMotion | Pushover | None,
    *,
    solver: SolverSettings = SolverSettings(),
    material: Material = MASONRY,
    foundation: bool = True,
    duration_s: float | None = None,
) -> Scene:
    """The Bullet scene of a model under a ground motion, a pushover or (``load`` None, for
    ``duration_s``) gravity alone."""
    geometry = simulation_geometry(model)
    motion = load if isinstance(load, GroundMotion) else None
    pushover = load if isinstance(load, Pushover) else None
    if load is not None and motion is None and pushover is None:
        raise InputError(f"simulate: the load must be a GroundMotion or a Pushover, got {type(load).__name__}")
    if pushover is not None:
        duration = pushover.duration_s
    elif motion is not None:
        duration = motion.duration
    elif duration_s is not None and duration_s > 0:
        duration = duration_s
    else:
        raise InputError("simulate: without a ground motion or a pushover, give duration_s > 0 (gravity alone)")
    return scene_from_geometry(
        geometry,
        motion=motion,
        pushover=pushover,
        duration_s=duration,
        material=material,
        solver=solver,
        foundation=foundation,
    )


def scene_for_model(model_dir: str | Path, config: SimulationConfig) -> Scene:
    """The scene ``simulate_to_folder`` runs for a model folder and a configuration."""
    geometry, stored = geometry_for_model(model_dir)
    material, source = model_material(model_dir, config.material)
    if config.shear_test is not None:
        scene = shear_test_scene(geometry, config.shear_test, material=material, solver=config.solver)
    else:
        load = config.pushover if config.pushover is not None else motion_for(config)
        scene = scene_for(geometry, load, solver=config.solver, material=material, foundation=config.foundation)
    scene.notes["geometry_stored"] = stored
    scene.notes["material_source"] = source
    return scene


def model_material(model_dir: str | Path, given: Material | None = None) -> tuple[Material, str]:
    """The material a run of the model uses and where it comes from: ``given`` (``--material``),
    else the model folder's material.toml (its structure's [material] table), else the defaults."""
    from ..build_folder import MATERIAL_FILE
    from .scene import read_material

    if given is not None:
        return given, "given"
    path = Path(model_dir) / MATERIAL_FILE
    if path.is_file():
        return read_material(path), str(path)
    return MASONRY, "defaults (calib_masonry.simulation.scene.Material)"


def _pieces_summary(scene: Scene, out) -> dict | None:
    """How the freed pieces were moved for the verdict (simulation/pieces.py), and how many bricks
    Bullet's animation moved beside it."""
    p = out.pieces
    if p is None:
        return None
    from .results import metrics

    bullet = metrics(scene, out, bullet=True)
    return {
        "motion": "rigid pieces on their contacts, explicit step 1/20 of the shortest contact period",
        "count": int(p.pieces),
        "fallen_fraction": float(p.fallen.mean()) if len(p.fallen) else 0.0,
        "step_s": float(p.dt_s) if np.isfinite(p.dt_s) else None,
        "steps": int(p.steps),
        "seconds": round(float(p.seconds), 3),
        # the joints inside the pieces, checked against the forces that keep each piece rigid
        "joints_cracked_in_pieces": _count_finite(p.crack_time_s),
        "joints_let_go_in_pieces": _count_finite(p.release_time_s),
        "bullet_moved_fraction_final": float(bullet.moved_fraction[-1]),
    }


def _count_finite(times: np.ndarray | None) -> int:
    return 0 if times is None else int(np.isfinite(times).sum())


def _dynamics_summary(scene: Scene, out) -> dict:
    """The elastic vibration of a run (see simulation/dynamics.py), or why there was none."""
    el = out.elastic
    if el is None:
        why = (
            "quasi-static: a pushover or shear test ramps its load slowly"
            if scene.motion is None
            else "quasi-static (--quasi-static), or no body is joined to the ground"
        )
        return {"elastic": False, "note": why, "first_period_s": _first_period(scene)}
    from .loop import PIECES_THEN_BULLET_FRAMES

    drift, shear = el["roof_drift_m"], el["base_shear_n"]
    return {
        "elastic": True,
        "method": "Newmark average acceleration on the intact joints and the bricks' rigid-body inertia, Rayleigh "
        "damping at the first two modes, on the undamaged stiffness; its joints crack on the vibration's forces",
        # whether the frames show it: Bullet's held bricks follow the vibration where Bullet plays
        # the verdict's pieces (loop._follow); otherwise Bullet holds them rigid
        "frames": "the held bricks follow the vibration (about the weight's equilibrium)"
        if out.frames_of == PIECES_THEN_BULLET_FRAMES
        else "the held bricks stand rigid: the drift below is the vibration's, not the poses'",
        "first_period_s": el["first_period_s"],
        "damping_ratio": el["damping_ratio"],
        "max_roof_drift_m": float(drift.max()) if drift.size else 0.0,
        "max_base_shear_kn": float(shear.max()) / 1000 if shear.size else 0.0,
        "max_first_mode_kg05_m": float(np.abs(el["first_mode"]).max()) if el["first_mode"].size else 0.0,
    }


def _grounded_at_end(scene: Scene, out) -> np.ndarray | None:
    """``(B,)`` the bodies that the bonds Bullet still held at the end tie to the ground (None: there
    are no bonds, or the run kept no release times)."""
    from .scene import grounded_bodies

    if not scene.bonds or out.bond_release_time_s is None:
        return None
    return grounded_bodies(scene.bonds, len(scene.bodies), ~np.isfinite(out.bond_release_time_s))


def _set_free_fraction(scene: Scene, out) -> float:
    grounded = _grounded_at_end(scene, out)
    return 0.0 if grounded is None else float(1.0 - grounded.mean())


def _unchecked_bonds(scene: Scene, out) -> int | None:
    """How many bonds never cracked lie inside the pieces set free (no held bond ties their bodies to
    the ground): their piece moved as one rigid body, its own bonds not checked again (None where
    ``piece_joints`` checked them)."""
    if scene.solver.piece_joints:
        return None
    grounded = _grounded_at_end(scene, out)
    if grounded is None or out.bond_break_time_s is None:
        return 0
    a = np.array([b.a for b in scene.bonds])
    return int((~np.isfinite(out.bond_break_time_s) & ~grounded[a]).sum())


def _first_period(scene: Scene) -> float | None:
    """The first natural period of the scene's intact structure (None if nothing is joined to the ground)."""
    from .dynamics import modes

    try:
        return float(modes(scene, 1).periods_s[0])
    except InputError:
        return None


def _spread(values: np.ndarray) -> dict | None:
    """The median and range of per-joint values, for summary.json."""
    if not len(values):
        return None
    return {"median": float(np.median(values)), "min": float(values.min()), "max": float(values.max())}


def _summary(scene: Scene, out, m, curve, name: str, shear: dict | None = None) -> dict:
    from .results import AT_START_S, ONSET_DRIFT, failure_mode_counts, mechanism, ran_away_first

    s = scene.solver
    k = scene_joint_stiffness(scene)
    mat = scene.material
    summary = {
        "model": name,
        "bricks": len(scene.bodies),
        "bonds": len(scene.bonds),
        # pga_g: the peak of the motion's samples (what the joint model and the verdict read);
        # bullet_applied_peak_g: of the frame means Bullet's animation applies; record_peak_g: a
        # record's own peak as recorded (for a synthetic motion, its samples'), before it was
        # started from rest and high-passed
        "ground_motion": {
            "source": scene.motion.source if scene.motion else None,
            "pga_g": scene.motion.pga / G if scene.motion else 0.0,
            "bullet_applied_peak_g": scene.motion.applied_peak(s.fps) / G if scene.motion else 0.0,
            "record_peak_g": (
                (scene.motion.pga if scene.motion.recorded_peak is None else scene.motion.recorded_peak) / G
                if scene.motion
                else 0.0
            ),
            "duration_s": scene.motion.duration if scene.motion else 0.0,
        },
        "solver": {
            "fps": s.fps,
            "substeps": s.substeps,
            "iterations": s.iterations,
            "warmup_s": s.warmup_s,
            "gravity_ramp_s": s.gravity_ramp_s,
            "warmup_damping": s.warmup_damping,
            "contact_gap_m": s.contact_gap_m,
            "check_interval_s": s.check_interval_s,
            "piece_joints": s.piece_joints,
            "bullet_moves": s.bullet_moves,
        },
        "joints": {
            "model": "elastic interfaces (UDEC/3DEC convention) between rigid bricks, cracked ones as "
            "frictional no-tension contacts; Bullet keeps joints rigid until the joint model has no "
            "equilibrium with them (calib_masonry.simulation.joints)",
            # per unit area, mortar and units in series: the median over the joints and their range
            "normal_stiffness_n_per_m3": _spread(k.normal),
            "shear_stiffness_n_per_m3": _spread(k.shear),
            "tensile_strength_pa": mat.tensile_strength,
            "compressive_strength_pa": mat.compressive_strength,
            "cohesion_pa": mat.shear_strength,
            "friction": mat.friction,
            "cracked_by": failure_mode_counts(out),
            # the intact joints at the first check, before anything cracks (the weight alone where the
            # ground starts at rest); where not computed, those left intact after it
            "max_utilisation_at_end_of_warmup": out.first_check[0]
            if out.first_check is not None
            else (
                float(out.max_utilisation[min(s.warmup_frames, len(out.time) - 1)])
                if out.max_utilisation is not None and len(out.time)
                else None
            ),
            "joints_over_strength_at_end_of_warmup": out.first_check[1] if out.first_check is not None else None,
            "seconds": round(out.seconds_joints, 3),
            # solves that end without meeting the tolerance: a pushover's or shear test's collapse
            # is read where one runs away, which a stalled iteration may do where an equilibrium
            # exists (docs/stone_walls.md, "The database's walls, dry")
            "contact_solves": out.contact_solves,
        },
        # the material of the run, as a [material] table (its units in its keys), and where it came from
        "material": {**material_table(mat), "source": scene.notes.get("material_source", "given")},
        "frame": "ground: the plate stays put and the ground motion acts on every brick as an inertial force",
        "foundation_bonds": int(scene.notes.get("foundation_bonds", 0)),
        # without a footing (--no-foundation), the bottom course bears on the ground through dry joints
        "ground_contacts": int(scene.notes.get("ground_contacts", 0)),
        # the bodies and contact patches: read from the model folder's sim_geometry.npz (stored
        # by build) or, for a model built without it or edited since, computed in this run
        "geometry_stored_by_build": bool(scene.notes.get("geometry_stored", False)),
        "mortar": {
            "fill_volume_fraction": scene.notes.get("mortar_fill_volume"),
            "max_hull_volume_change": scene.notes.get("max_hull_volume_change"),
            "bricks_without_fill": scene.notes.get("bricks_without_fill", 0),
        },
        "joint_coverage": scene.notes.get("joint_coverage"),
        "dynamics": _dynamics_summary(scene, out),
        "moved_fraction_final": float(m.moved_fraction[-1]),
        "moved_threshold_m": s.moved_threshold_m,
        "max_roof_drift_m": float(m.roof_drift_m.max()),
        "collapse_time_s": m.collapse_time_s,
        "bonds_broken": int(np.isfinite(m.bond_break_time_s).sum()),
        "bonds_broken_fraction": float(np.isfinite(m.bond_break_time_s).mean()) if len(m.bond_break_time_s) else 0.0,
        # cracked joints Bullet let go: the rest of the cracked ones it held while they had an equilibrium
        "bonds_released": int(np.isfinite(out.bond_release_time_s).sum()) if out.bond_release_time_s is not None else 0,
        "max_brick_displacement_m": float(m.max_displacement_m.max()),
        "outcome": m.outcome,
        # the bricks in freed pieces that fell or overturn from their state at the end (the verdict
        # under a ground motion: collapsed from half); None where Bullet's motion is read
        "toppled_fraction": m.toppled_fraction,
        # the bricks the joint model cut off from the ground (no joint Bullet still holds ties them
        # to the plate): its decision, the same whatever Bullet's settings; how far they then move
        # (moved_fraction_final, outcome) is the rigid pieces' motion ("pieces" below), Bullet's
        # only without a ground motion
        "set_free_fraction": _set_free_fraction(scene, out),
        # the bonds inside the pieces set free that had not cracked when their piece was: not checked
        # again, unless --piece-joints (None then), so that a larger PGA, which frees a piece sooner,
        # can report fewer bonds broken
        "bonds_unchecked": _unchecked_bonds(scene, out),
        "pieces": _pieces_summary(scene, out),
        # rocking, sliding or stepped (diagonal) cracking, from the joints' motion where the
        # collapse began (None: nothing ran away); see calib_masonry.simulation.results.mechanism
        "mechanism": mechanism(scene, out, m),
        "seconds": {
            "blender_build": round(out.seconds_build, 3),
            "stepping": round(out.seconds_stepping, 3),
            "per_frame": round(out.seconds_stepping / max(1, len(out.time) - 1), 4),
        },
    }
    if curve is not None:
        summary["pushover"] = {
            "rate_g_per_s": scene.pushover.rate_g_per_s,
            "direction_deg": scene.pushover.direction_deg,
            "max_g": scene.pushover.max_g,
            "onset_drift": ONSET_DRIFT,
            # the ramp reached its largest acceleration and the structure still stood: no multiplier
            "reached_max": curve[0] is None,
        }
        if curve[0] is None:
            summary["pushover"]["note"] = (
                f"no collapse up to {scene.pushover.max_g:g} g: the collapse multiplier is above it; "
                "raise --pushover-max to find it"
            )
        elif curve[0] <= scene.pushover.rate_g_per_s * AT_START_S and "shear_test" not in scene.notes:
            first = ran_away_first(scene, out, m)
            summary["pushover"]["ran_away_first"] = first
            summary["pushover"]["note"] = (
                f"it ran away in the ramp's first {AT_START_S:g} s, under its own weight rather than the load"
                + (f": {', '.join(first)} moved first" if first else "")
                + " (a unit over an opening with no lintel, or stones that cannot "
                "bear on one another as traced: see build's notes and joints.max_utilisation_at_end_of_warmup)"
            )
        summary["collapse_multiplier_g"] = curve[0]
        summary["ground_motion"] = None
        if shear is not None:
            summary["shear_test"] = {
                **scene.notes["shear_test"],
                "peak_lateral_force_kn": shear["peak_lateral_force_kn"],
                "drift_at_peak_percent": None if shear["drift_at_peak"] is None else 100 * shear["drift_at_peak"],
                "drift_at_95_percent_of_peak_percent": (
                    None if shear["drift_at_95_percent_of_peak"] is None else 100 * shear["drift_at_95_percent_of_peak"]
                ),
                # the joint model's drift is known up to this force: above it, the run's cracks solved
                # again at one load had no converged equilibrium (the curve leaves those loads out)
                "drift_known_to_kn": shear["drift_known_to_kn"],
                "drift_levels_converged": shear["drift_levels_converged"],
                "drift_levels": shear["drift_levels"],
                "reached_max": shear["peak_lateral_force_kn"] is None,
                "mechanism": (summary["mechanism"] or {}).get("mechanism"),
            }
    return summary


def simulate_scene(
    scene: Scene,
    name: str = "scene",
    *,
    progress: bool | None = None,
    blend_path: Path | None = None,
    joints_ahead: bool = True,
    bullet: bool = True,
) -> SimulationResult:
    """Simulate a :class:`~calib_masonry.simulation.scene.Scene` as it is (one made by
    :func:`scene_for`, :func:`scene_for_model` or by hand: a wall without some stones, a scene
    with its own material), as :func:`simulate` does a model's: one BLAS thread for the joint
    model, a pushover stopped after its collapse, the metrics, the pushover's multiplier and the
    shear test's curve in the result; ``name`` is the summary's model name."""
    from .loop import drain

    return drain(
        _scene_steps(scene, name, progress=progress, blend_path=blend_path, joints_ahead=joints_ahead, bullet=bullet)
    )


def _scene_steps(
    scene: Scene,
    name: str,
    *,
    progress: bool | None,
    blend_path: Path | None,
    joints_ahead: bool = True,
    bullet: bool = True,
) -> Generator[int, None, SimulationResult]:
    """The run of ``scene``, yielding after every frame (:func:`calib_masonry.simulation.loop.steps`),
    returning its :class:`SimulationResult`."""
    from threadpoolctl import threadpool_limits

    from .blender import require_bpy
    from .loop import steps
    from .results import collapse_multiplier, metrics, pushover_stop, shear_curve

    if bullet and threading.current_thread() is not threading.main_thread():
        warnings.warn(
            "simulate: called from a thread other than the main one; Blender driven so, beside other "
            "busy Python threads, gave other poses from the same inputs and crashed at times "
            "(experiments/sim_determinism.py --thread); call it from the main thread (a dask task: "
            "simulate_async, which runs on the worker's event loop, its main thread)",
            RuntimeWarning,
            stacklevel=5,
        )
    if bullet:
        require_bpy()
    stop = pushover_stop(scene) if scene.pushover is not None else None
    # one BLAS thread for the joint model's solves, whatever the process's setting (a dask worker,
    # a notebook): a threaded BLAS splits a sum by its thread count, and so rounds it another way
    with threadpool_limits(limits=1, user_api="blas"):
        out = yield from steps(
            scene,
            progress=progress,
            blend_path=blend_path if bullet else None,
            stop=stop,
            joints_ahead=joints_ahead,
            bullet=bullet,
        )
    m = metrics(scene, out)
    curve = collapse_multiplier(scene, out, m) if scene.pushover is not None else None
    shear = shear_curve(scene, out, m, curve) if "shear_test" in scene.notes and curve is not None else None
    summary = _summary(scene, out, m, curve, name, shear)
    _warn_first_check(scene, out)
    # what moved the freed pieces in the frames: Bullet, the verdict's rigid pieces (--no-bullet), or
    # these until they fall and Bullet then (--bullet-moves fallen, the default under a ground motion)
    summary["engine"] = out.frames_of
    if not bullet and isinstance(summary.get("pieces"), dict):
        summary["pieces"]["bullet_moved_fraction_final"] = None  # no Bullet ran
    return SimulationResult(scene=scene, output=out, metrics=m, curve=curve, summary=summary, shear=shear)


def _warn_first_check(scene: Scene, out) -> None:
    """A warning where the intact model's joints are over their strength at the joint model's first
    check, before any ground motion or push: under its own weight (and a shear test's precompression)
    the model as built cracks at once, whatever the load asked for (not said of dry or no-tension
    joints, which open under it by design). Seen on a stone structure traced to four vertices a
    stone: stones traced smaller than they are stand in mortar wider than the joint reach and hang
    from their neighbours on slivers of joint."""
    if out.first_check is None or out.first_check[0] <= 1.0:
        return
    if scene.material.tensile_strength <= 0.0 or scene.material.shear_strength <= 0.0:
        return  # dry or no-tension joints open and slide under the weight by design
    worst, over = out.first_check
    load = "its own weight and the precompression" if "shear_test" in scene.notes else "its own weight"
    warnings.warn(
        f"simulate: under {load} alone {over} joint{'s' if over != 1 else ''} of the intact model "
        f"{'are' if over != 1 else 'is'} over {'their' if over != 1 else 'its'} strength (the worst "
        f"{worst:.3g} times) and {'crack' if over != 1 else 'cracks'} at the start, whatever the load: the "
        "model as built cannot carry itself with this material. Look for bricks hanging from their "
        "neighbours on small joints (build's walls.png and summary.json's units_without_bed_joint: outlines "
        "traced smaller than the stones, or mortar beds wider than the joints reach); trace the walls with "
        "more vertices (`vertices = 8` or `target_dice = 0.98` in structure.toml), or for wide mortar raise "
        f"`max_joint_m` (default {MAX_GAP_M:g} m) in its [structure], and build again",
        RuntimeWarning,
        stacklevel=2,
    )


def _scene(model, load, settings, material, foundation, duration_s) -> tuple[Scene, str]:
    """The scene of a :func:`simulate` call, and the model's name."""
    stored = None
    if hasattr(model, "structure") and isinstance(model.structure, Structure3D):  # a BuildResult
        model = model.structure
    if isinstance(model, (str, Path)):
        name = str(model)
        model, stored = geometry_for_model(model)
    else:
        name = model.name if isinstance(model, Structure3D) else "model"
    scene = scene_for(model, load, solver=settings, material=material, foundation=foundation, duration_s=duration_s)
    if stored is not None:
        scene.notes["geometry_stored"] = stored
    return scene, name


def simulate(
    model,
    load: GroundMotion | Pushover | None = None,
    settings: SolverSettings = SolverSettings(),
    *,
    material: Material = MASONRY,
    foundation: bool = True,
    duration_s: float | None = None,
    progress: bool | None = None,
    blend_path: Path | None = None,
    joints_ahead: bool = True,
    bullet: bool = True,
) -> SimulationResult:
    """Simulate a built model in Bullet under a ground motion, a pushover or (``load`` None, for
    ``duration_s`` seconds) gravity alone; in memory (writes ``blend_path`` only if given).

    ``model`` is a :class:`~calib_masonry.build3d.assemble.Structure3D` or the BuildResult
    :func:`calib_masonry.build` returns, its :class:`~calib_masonry.simulation.scene.SceneGeometry`,
    or a ``build`` output folder.

    Call it from the process's main thread (it warns otherwise): Blender driven from another
    thread, beside busy Python threads (a dask worker's task thread), gave other poses from the
    same inputs and crashed at times. In a dask task, await :func:`simulate_async` instead.

    ``joints_ahead`` (where no brick bears on the plate without a joint) runs the joint model ahead
    of Bullet on a thread of its own, on the second core; ``False`` runs it before each step on
    this thread, with the same poses bit for bit, for a process whose cores are busy anyway (a
    study's workers).

    ``bullet=False`` (a ground motion only): no Bullet and no Blender; the same verdict, cracks and
    releases bit for bit, the frames showing the verdict's rigid pieces instead of Bullet's
    animation of them (:func:`calib_masonry.simulation.loop.steps`)."""
    scene, name = _scene(model, load, settings, material, foundation, duration_s)
    return simulate_scene(
        scene, name, progress=progress, blend_path=blend_path, joints_ahead=joints_ahead, bullet=bullet
    )


async def simulate_async(
    model,
    load: GroundMotion | Pushover | None = None,
    settings: SolverSettings = SolverSettings(),
    *,
    material: Material = MASONRY,
    foundation: bool = True,
    duration_s: float | None = None,
    progress: bool | None = None,
    bullet: bool = True,
) -> SimulationResult:
    """:func:`simulate` on the running event loop's thread, handing the loop back between frames.

    For a dask task (``client.submit`` of a coroutine function runs it on the worker's event loop,
    which is the worker process's main thread): Blender then runs on the main thread, where its runs
    are reproducible, and the worker still answers its scheduler between frames (the loop waits
    one frame at most: Bullet's step and the joint model's check). The scene is prepared on a
    thread of the loop's executor. The same poses as :func:`simulate`, bit for bit; cancelling the task stops the run at
    the next frame. The joint model runs on the loop's thread, before each step (``simulate(...,
    joints_ahead=False)``): a worker runs many simulations, and its cores are busy with workers."""
    import asyncio

    from .._threads import loop_lock

    scene, name = await asyncio.to_thread(_scene, model, load, settings, material, foundation, duration_s)
    # one Blender per process: two runs on one loop (a dask worker with two threads) take turns, whole
    async with loop_lock("blender"):
        gen = _scene_steps(scene, name, progress=progress, blend_path=None, joints_ahead=False, bullet=bullet)
        try:
            while True:
                try:
                    next(gen)
                except StopIteration as end:
                    return end.value
                await asyncio.sleep(0)
        finally:
            gen.close()


def write_simulation(
    result: SimulationResult,
    out: Path,
    *,
    figures: bool = True,
    frames_png: int = 6,
    gif_frames: int = 24,
    progress: bool | None = None,
) -> dict:
    """Write a result into the folder ``out`` (it must exist): summary.json, poses.npz and the figures
    (ground_motion.png or pushover.png, histories.png, frames/, collapse.gif). Returns the summary
    as written (:func:`calib_masonry._json.jsonable`)."""
    from .results import plot_ground_motion, plot_histories, plot_pushover, render_frames, write_collapse_gif

    scene, r, m = result.scene, result.output, result.metrics
    np.savez_compressed(
        out / "poses.npz",
        time=r.time,
        positions=r.positions.astype(np.float32),
        quaternions=r.quaternions.astype(np.float32),
        plate=r.plate.astype(np.float32),
        bond_break_time_s=m.bond_break_time_s,
        bond_release_time_s=(
            r.bond_release_time_s if r.bond_release_time_s is not None else np.full(len(scene.bonds), np.nan)
        ),
        **({"freed_velocity": r.freed_velocity.astype(np.float32)} if r.freed_velocity is not None else {}),
        **(
            {f"elastic_{k}": v for k, v in r.elastic.items() if isinstance(v, np.ndarray)}
            if r.elastic is not None
            else {}
        ),
    )
    t1 = time.perf_counter()
    if result.shear is not None:
        from .results import write_shear_curve

        write_shear_curve(scene, result.shear, out, figures=figures)
    if figures:
        if scene.pushover is not None:
            plot_pushover(scene, result.curve, out / "pushover.png")
        else:
            plot_ground_motion(scene, out / "ground_motion.png")
        plot_histories(scene, r, m, out / "histories.png")
        render_frames(scene, r, out / "frames", count=frames_png)
        if gif_frames:
            write_collapse_gif(scene, r, out / "collapse.gif", count=gif_frames, progress=progress)
    summary = dict(result.summary)
    summary["seconds"] = {**summary["seconds"], "figures": round(time.perf_counter() - t1, 3)}
    summary = jsonable(summary)  # as written (write_json of it writes the same bytes)
    write_json(out / "summary.json", summary)
    return summary


def _out_beside_model(out: str | Path, model_dir: str | Path) -> None:
    model = Path(model_dir).resolve()
    if Path(out).resolve() == model or Path(out).resolve() in model.parents:
        raise InputError(
            f"--out {out}: holds the model folder {model_dir}, which a run would replace; give another folder"
        )


def simulate_to_folder(
    model_dir: str | Path,
    out: str | Path,
    config: SimulationConfig = SimulationConfig(),
    *,
    progress: bool | None = None,
    overwrite: bool = False,
) -> dict:
    """Run the simulation ``config`` asks for on a model folder and write summary.json, poses.npz,
    scene.blend, figures and frames/ into ``out`` (all or nothing, replacing ``out`` as a whole)."""
    from .blender import require_bpy

    if config.bullet:
        require_bpy()
    check_output(out, command="simulate", overwrite=overwrite)
    _out_beside_model(out, model_dir)
    t0 = time.perf_counter()
    scene = scene_for_model(model_dir, config)
    t_scene = time.perf_counter() - t0
    with staged_output(
        out, "simulate", overwrite=overwrite, keep=[config.accelerogram, config.accelerogram_y]
    ) as stage:
        result = simulate_scene(
            scene,
            str(model_dir),
            progress=progress,
            blend_path=stage / "scene.blend" if config.bullet else None,
            bullet=config.bullet,
        )
        result.summary["seconds"]["scene"] = round(t_scene, 3)
        if not config.bullet:
            _write_pieces_blend(result, stage / "scene.blend")
        summary = write_simulation(
            result,
            stage,
            figures=config.figures,
            frames_png=config.frames_png,
            gif_frames=config.gif_frames,
            progress=progress,
        )
    return summary


def _write_pieces_blend(result: SimulationResult, path: Path) -> None:
    """scene.blend of a run without Bullet: every brick keyed at every frame where the verdict's
    pieces put it, when Blender's bpy is installed (the run itself needs none)."""
    from ..errors import BackendMissing
    from .blender import require_bpy, write_animation_blend

    try:
        require_bpy()
    except BackendMissing:
        return
    r = result.output
    write_animation_blend(result.scene, r.positions, r.quaternions, result.scene.solver.fps, path)


def model_modes(
    model_dir: str | Path,
    n: int = 6,
    material: Material | None = None,
    mass_fraction: float | None = None,
    progress: bool | None = False,
):
    """The ``n`` lowest natural modes of a model folder's intact structure (with ``mass_fraction``,
    as many more as carry that share of the horizontal mass: :func:`~.dynamics.modes`), with the
    scene they are of (its material: ``material``, else the model's material.toml, else the defaults)."""
    from .dynamics import modes

    geometry, _ = geometry_for_model(model_dir)
    mat, source = model_material(model_dir, material)
    scene = scene_for(geometry, None, material=mat, duration_s=1.0)
    scene.notes["material_source"] = source
    return modes(scene, n, mass_fraction=mass_fraction, progress=progress), scene


def modes_to_folder(
    model_dir: str | Path,
    out: str | Path,
    *,
    n: int = 6,
    material: Material | None = None,
    mass_fraction: float | None = None,
    figures: bool = True,
    overwrite: bool = False,
    progress: bool | None = None,
) -> dict:
    """modes.json (periods, effective modal masses, the empirical periods of masonry towers of the
    model's height) and modes.png (the lowest modes' shapes) of a model folder into ``out``, all or
    nothing; ``n`` and ``mass_fraction``: :func:`model_modes`; ``progress``: the eigen-solve's steps
    shown (a bar on a terminal, a line every 10 s in a log)."""
    from .dynamics import write_modes

    check_output(out, command="modes", overwrite=overwrite)
    checked_model_dir(model_dir)
    _out_beside_model(out, model_dir)
    m, scene = model_modes(model_dir, n, material, mass_fraction, progress)
    with staged_output(out, "modes", overwrite=overwrite) as stage:
        doc = write_modes(m, scene, stage, figure=figures)
        doc["model"] = str(model_dir)
        doc["material"]["source"] = scene.notes.get("material_source")
        write_json(stage / "modes.json", doc)
    return doc

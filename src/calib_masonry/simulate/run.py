"""``simulate``: a built model folder + ground motion -> Bullet run -> results folder."""

from __future__ import annotations

import json
import math
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..build3d.export import bricks_from_json
from ..build3d.place import corners, wall_frames
from ..errors import InputError
from ..io import read_json, staged_output, write_json
from ..spec import StructureSpec, WallSpec
from .ground_motion import G, GroundMotion, read_accelerogram, synthetic_motion
from .joints import joint_stiffness
from .scene import (MASONRY, Material, Pushover, Scene, SceneGeometry, SolverSettings, load_geometry, save_geometry,
                    scene_from_geometry, scene_geometry)

__all__ = ["Pushover", "SimulationConfig", "load_model", "model_from_json", "geometry_for_model", "store_geometry",
           "scene_for_model", "simulate_to_folder", "rerun_with_fixed_hash_seed"]


def rerun_with_fixed_hash_seed(python_args: list[str]) -> int | None:
    """Run ``python PYTHON_ARGS`` in a child with ``PYTHONHASHSEED=0`` and return its exit code, or
    None when this process already has that seed (then the caller does the work itself).

    Bullet in Blender repeats a run bit for bit only when the process's memory layout repeats, and
    Python's string-hash seed changes it: two processes with random seeds diverged from the second
    frame on the Stylite model, processes with PYTHONHASHSEED=0 matched exactly (measured; also
    with a different --out path). The first run after a source change still differs (Python writes
    its bytecode caches then), which is why scripts/setup.sh compiles them."""
    import os
    import subprocess
    import sys

    if os.environ.get("PYTHONHASHSEED") == "0":
        return None
    env = {**os.environ, "PYTHONHASHSEED": "0"}
    return subprocess.run([sys.executable, *python_args], env=env).returncode


@dataclass(frozen=True)
class SimulationConfig:
    pga_g: float = 0.3
    duration_s: float = 10.0
    seed: int = 0
    accelerogram: Path | None = None
    # two independent horizontal components, as a real earthquake has: with one, along X, the walls
    # parallel to X are loaded only in their plane and stand, so at most the other walls fall (the
    # paper example at 0.6 g, seed 0: 43 % of bricks moved with one component, 71-77 % with two)
    components: int = 2
    direction_deg: float = 0.0  # of a one-component motion, from global X
    solver: SolverSettings = SolverSettings()
    material: Material = MASONRY
    frames_png: int = 6
    figures: bool = True
    # bond the bottom course to the ground (a footing): without it the ground moves the structure
    # through friction alone, and the whole structure creeps on the plate (a slow turn of ~1 mrad
    # in 10 s under gravity alone on the paper example, measured)
    foundation: bool = True
    # a quasi-static collapse analysis instead of a ground motion (then pga, duration, seed,
    # accelerogram and components are not used)
    pushover: Pushover | None = None


GEOMETRY_FILE = "sim_geometry.npz"  # the simulation's bodies and contact patches, stored by `build`


def _checked_model_dir(model_dir: str | Path) -> Path:
    model_dir = Path(model_dir)
    if not model_dir.is_dir():
        raise InputError(f"MODEL_DIR {model_dir}: not a folder; give the --out folder of `calib-masonry build`")
    if not (model_dir / "bricks.json").is_file():
        raise InputError(f"MODEL_DIR {model_dir}: has no bricks.json; run `calib-masonry build STRUCTURE.toml --out {model_dir}` first")
    return model_dir


def _closed_footprint(model_dir: Path):
    if (model_dir / "summary.json").is_file():
        return read_json(model_dir / "summary.json").get("closed_footprint")
    return None


def model_from_json(data: dict, closed, source: str | Path):
    """Bricks, wall frames, corners and spec of a ``build`` output's bricks.json contents ``data``
    (``closed``: the build summary's closed_footprint)."""
    try:
        bricks = bricks_from_json(data)
        walls = tuple(WallSpec(name=w["name"], width_m=w["width_m"], height_m=w["height_m"],
                               theta_rad=math.radians(w["theta_deg"]), thickness_m=w["thickness_m"])
                      for w in data["walls"])
    except (KeyError, TypeError, ValueError) as exc:
        raise InputError(f"MODEL_DIR {source}: bricks.json is not a build output ({exc}); re-run build") from None
    if not bricks:
        raise InputError(f"MODEL_DIR {source}: bricks.json holds no bricks; nothing to simulate")
    spec = StructureSpec(name=data.get("structure", Path(source).name), walls=walls, thickness_m=walls[0].thickness_m,
                         closed=closed)
    return bricks, wall_frames(spec), corners(spec), spec


def load_model(model_dir: str | Path):
    """Bricks, wall frames, corners and spec of a ``build`` output folder."""
    model_dir = _checked_model_dir(model_dir)
    data = read_json(model_dir / "bricks.json", field="MODEL_DIR bricks.json")
    return model_from_json(data, _closed_footprint(model_dir), model_dir)


def _geometry_key(bricks_json: bytes, closed, max_gap_m: float, mortar_fill: bool) -> str:
    """What a model's simulation geometry is computed from: the bricks.json bytes, whether the
    footprint is closed, the joint reach and the mortar fill."""
    import hashlib

    h = hashlib.sha256(bricks_json)
    h.update(repr((closed, float(max_gap_m), bool(mortar_fill))).encode())
    return h.hexdigest()


def _computed_geometry(data: dict, closed, source: Path, max_gap_m: float, mortar_fill: bool) -> SceneGeometry:
    bricks, frames, cs, _ = model_from_json(data, closed, source)
    return scene_geometry(bricks, frames, cs, mortar_fill=mortar_fill, max_gap_m=max_gap_m)


def store_geometry(model_dir: str | Path, closed, *, max_gap_m: float = 0.06, mortar_fill: bool = True) -> SceneGeometry:
    """Compute the simulation geometry of the bricks.json in ``model_dir`` (a ``build`` stage, whose
    summary says whether the footprint is ``closed``) and store it there as sim_geometry.npz."""
    model_dir = Path(model_dir)
    raw = (model_dir / "bricks.json").read_bytes()
    geometry = _computed_geometry(json.loads(raw), closed, model_dir, max_gap_m, mortar_fill)  # the file build just wrote
    save_geometry(geometry, model_dir / GEOMETRY_FILE, _geometry_key(raw, closed, max_gap_m, mortar_fill))
    return geometry


def geometry_for_model(model_dir: str | Path, *, max_gap_m: float = 0.06, mortar_fill: bool = True
                       ) -> tuple[SceneGeometry, bool]:
    """The simulation geometry of a model folder and whether it came from the folder's
    sim_geometry.npz. The stored copy is used only if it was computed from this bricks.json (its
    hash), footprint and settings by this version of the code; otherwise (a model built before it
    was stored, an edited bricks.json) the geometry is computed here, as :func:`store_geometry` would."""
    model_dir = _checked_model_dir(model_dir)
    raw = (model_dir / "bricks.json").read_bytes()
    closed = _closed_footprint(model_dir)
    stored = load_geometry(model_dir / GEOMETRY_FILE, _geometry_key(raw, closed, max_gap_m, mortar_fill))
    if stored is not None:
        return stored, True
    data = read_json(model_dir / "bricks.json", field="MODEL_DIR bricks.json")
    return _computed_geometry(data, closed, model_dir, max_gap_m, mortar_fill), False


def motion_for(config: SimulationConfig) -> GroundMotion:
    """The ground motion of a run. A synthetic record is scaled so that the acceleration the run
    applies (its mean over each frame) peaks at the PGA: the Kanai-Tajimi record is broadband, and
    at 25 fps its frame means peak 10-20 % below the peak of the 200 Hz samples (0.49-0.54 g for
    0.6 g records, seeds 0-2, measured), so scaling the samples would shake the model less than
    asked. A recorded accelerogram is applied as it is."""
    if config.accelerogram is not None:
        return read_accelerogram(config.accelerogram)
    motion = synthetic_motion(config.pga_g, config.duration_s, seed=config.seed, components=config.components,
                              direction_deg=config.direction_deg)
    applied = motion.applied_peak(config.solver.fps)
    if applied <= 0:
        return motion
    return motion.scaled(config.pga_g * G / applied,
                         source=f"{motion.source} as applied at {config.solver.fps} fps")


def scene_for_model(model_dir: str | Path, config: SimulationConfig) -> Scene:
    if config.pga_g < 0 or not math.isfinite(config.pga_g):
        raise InputError(f"--pga {config.pga_g}: the peak ground acceleration must be >= 0 (in g)")
    if config.duration_s <= 0:
        raise InputError(f"--duration {config.duration_s}: must be > 0 seconds")
    geometry, stored = geometry_for_model(model_dir)
    motion = motion_for(config) if config.pushover is None else None
    duration = config.pushover.duration_s if config.pushover is not None else motion.duration
    scene = scene_from_geometry(geometry, motion=motion, pushover=config.pushover, duration_s=duration,
                                material=config.material, solver=config.solver, foundation=config.foundation)
    scene.notes["geometry_stored"] = stored
    return scene


def simulate_to_folder(model_dir: str | Path, out: str | Path, config: SimulationConfig = SimulationConfig(), *,
                       progress: bool | None = None) -> dict:
    """Run the simulation and write summary.json, poses.npz, scene.blend, figures and frames/."""
    from .blender import require_bpy, run
    from .results import (ONSET_DRIFT, collapse_multiplier, failure_mode_counts, metrics, outcome, plot_ground_motion,
                          plot_histories, plot_pushover, pushover_stop, render_frames)

    require_bpy()
    t0 = time.perf_counter()
    scene = scene_for_model(model_dir, config)
    t_scene = time.perf_counter() - t0
    with staged_output(out) as stage:
        stop = pushover_stop(scene) if scene.pushover is not None else None
        result = run(scene, progress=progress, blend_path=stage / "scene.blend", stop=stop)
        m = metrics(scene, result)
        curve = collapse_multiplier(scene, result, m) if scene.pushover is not None else None
        np.savez_compressed(stage / "poses.npz", time=result.time, positions=result.positions.astype(np.float32),
                            quaternions=result.quaternions.astype(np.float32), plate=result.plate.astype(np.float32),
                            bond_break_time_s=m.bond_break_time_s)
        t1 = time.perf_counter()
        if config.figures:
            if scene.pushover is not None:
                plot_pushover(scene, curve, stage / "pushover.png")
            else:
                plot_ground_motion(scene, stage / "ground_motion.png")
            plot_histories(scene, result, m, stage / "histories.png")
            render_frames(scene, result, stage / "frames", count=config.frames_png)
        t_fig = time.perf_counter() - t1
        s = scene.solver
        k = joint_stiffness(scene.material)
        mat = scene.material
        summary = {
            "model": str(model_dir), "bricks": len(scene.bodies), "bonds": len(scene.bonds),
            # pga_g: the peak of the acceleration the run applies (frame means); record_peak_g: of the samples
            "ground_motion": {"source": scene.motion.source if scene.motion else None,
                              "pga_g": scene.motion.applied_peak(s.fps) / G if scene.motion else 0.0,
                              "record_peak_g": scene.motion.pga / G if scene.motion else 0.0,
                              "duration_s": scene.motion.duration if scene.motion else 0.0},
            "solver": {"fps": s.fps, "substeps": s.substeps, "iterations": s.iterations, "warmup_s": s.warmup_s,
                       "gravity_ramp_s": s.gravity_ramp_s, "warmup_damping": s.warmup_damping,
                       "contact_gap_m": s.contact_gap_m},
            "joints": {"model": "elastic interfaces (UDEC/3DEC convention) between rigid bricks; Bullet keeps intact "
                                "joints rigid, the joint model cracks them (calib_masonry.simulate.joints)",
                       "normal_stiffness_n_per_m3": k.normal, "shear_stiffness_n_per_m3": k.shear,
                       "tensile_strength_pa": mat.tensile_strength, "compressive_strength_pa": mat.compressive_strength,
                       "cohesion_pa": mat.shear_strength, "friction": mat.friction,
                       "cracked_by": failure_mode_counts(result),
                       "max_utilisation_at_end_of_warmup": float(result.max_utilisation[min(s.warmup_frames, len(result.time) - 1)])
                       if result.max_utilisation is not None and len(result.time) else None,
                       "seconds": round(result.seconds_joints, 3)},
            "frame": "ground: the plate stays put and the ground motion acts on every brick as an inertial force",
            "foundation_bonds": int(scene.notes.get("foundation_bonds", 0)),
            # the bodies and contact patches: read from the model folder's sim_geometry.npz (stored
            # by build) or, for a model built without it or edited since, computed in this run
            "geometry_stored_by_build": bool(scene.notes.get("geometry_stored", False)),
            "mortar": {"fill_volume_fraction": scene.notes.get("mortar_fill_volume"),
                       "max_hull_volume_change": scene.notes.get("max_hull_volume_change"),
                       "bricks_without_fill": scene.notes.get("bricks_without_fill", 0)},
            "moved_fraction_final": float(m.moved_fraction[-1]),
            "moved_threshold_m": s.moved_threshold_m,
            "max_roof_drift_m": float(m.roof_drift_m.max()),
            "collapse_time_s": m.collapse_time_s,
            "bonds_broken": int(np.isfinite(m.bond_break_time_s).sum()),
            "bonds_broken_fraction": float(np.isfinite(m.bond_break_time_s).mean()) if len(m.bond_break_time_s) else 0.0,
            "max_brick_displacement_m": float(m.max_displacement_m.max()),
            "outcome": outcome(float(m.moved_fraction[-1])),
            "seconds": {"scene": round(t_scene, 3), "blender_build": round(result.seconds_build, 3),
                        "stepping": round(result.seconds_stepping, 3), "figures": round(t_fig, 3),
                        "per_frame": round(result.seconds_stepping / max(1, len(result.time) - 1), 4)},
        }
        if curve is not None:
            summary["pushover"] = {"rate_g_per_s": scene.pushover.rate_g_per_s,
                                   "direction_deg": scene.pushover.direction_deg, "max_g": scene.pushover.max_g,
                                   "onset_drift": ONSET_DRIFT}
            summary["collapse_multiplier_g"] = curve[0]
            summary["ground_motion"] = None
        write_json(stage / "summary.json", summary)
    return summary

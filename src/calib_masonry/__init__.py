"""calib_masonry: photos of single-wythe masonry walls to a calibrated 3D brick model and its simulation.

The public API, re-exported explicitly. Every stage is a plain function on objects and writes no
file; the ``write_*`` / ``read_*`` functions and the ``*_to_folder`` / ``*_to_file`` calls behind
each command of the CLI are the edge::

    photo --calibrate_photo--> PhotoCalibration --rectify--> orthophoto --segment--> mask
    mask --trace--> TraceResult --refine--> TraceResult
    StructureSpec (+ traces) --build--> BuildResult (.structure: Structure3D)
    Structure3D + GroundMotion | Pushover --simulate--> SimulationResult
    Structure3D + truth Structure3D --compare--> metrics
    Study (load_study) --run_study--> rows, summary   (on Dask; study_to_folder resumes)

Names are imported lazily on first use (PEP 562), so ``import calib_masonry`` and the command line
start fast and load JAX, torch or bpy only for the stages that need them.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING

__version__ = "0.1.0"

# public name -> (module, attribute)
_API = {
    "demo": (".cli", "demo"),
    "compare_to_file": (".comparison", "compare_to_file"),
    "synth_to_folder": (".synthetic.truth", "synth_to_folder"),
    "trace_to_file": (".wall2d.trace", "trace_to_file"),
    "footprint_to_folder": (".calibrate.footprint", "footprint_to_folder"),
    "rectify_to_folder": (".calibrate.rectify", "rectify_to_folder"),
    "Brick": (".build3d.assemble", "Brick"),
    "Structure3D": (".build3d.assemble", "Structure3D"),
    "WallPolygons": (".build3d.assemble", "WallPolygons"),
    "assemble": (".build3d.assemble", "assemble"),
    "Interpenetration": (".build3d.contacts", "Interpenetration"),
    "max_interpenetration": (".build3d.contacts", "max_interpenetration"),
    "Corner": (".build3d.place", "Corner"),
    "Footprint": (".build3d.place", "Footprint"),
    "WallFrame": (".build3d.place", "WallFrame"),
    "WallGeometry": (".build3d.place", "WallGeometry"),
    "closure_gap": (".build3d.place", "closure_gap"),
    "corners": (".build3d.place", "corners"),
    "wall_frames": (".build3d.place", "wall_frames"),
    "image_from_wall": (".build3d.scale", "image_from_wall"),
    "wall_from_image": (".build3d.scale", "wall_from_image"),
    "calibrate_corner_photo": (".calibrate.corner", "calibrate_corner_photo"),
    "FitResult": (".calibrate.fitresult", "FitResult"),
    "FitStatus": (".calibrate.fitresult", "FitStatus"),
    "fit_footprint": (".calibrate.footprint", "fit_footprint"),
    "CalibrateConfig": (".calibrate.rectify", "CalibrateConfig"),
    "PhotoCalibration": (".calibrate.rectify", "PhotoCalibration"),
    "calibrate_photo": (".calibrate.rectify", "calibrate_photo"),
    "rectify": (".calibrate.rectify", "rectify"),
    "BackendMissing": (".errors", "BackendMissing"),
    "CalibMasonryError": (".errors", "CalibMasonryError"),
    "FitFailed": (".errors", "FitFailed"),
    "InputError": (".errors", "InputError"),
    "Photo": (".io", "Photo"),
    "read_mask": (".io", "read_mask"),
    "read_photo": (".io", "read_photo"),
    "write_mask": (".io", "write_mask"),
    "BuildResult": (".pipeline", "BuildResult"),
    "build": (".pipeline", "build"),
    "build_to_folder": (".build_folder", "build_to_folder"),
    "read_build": (".build_folder", "read_build"),
    "write_build": (".build_folder", "write_build"),
    "GroundMotion": (".simulation.ground_motion", "GroundMotion"),
    "read_accelerogram": (".simulation.ground_motion", "read_accelerogram"),
    "synthetic_motion": (".simulation.ground_motion", "synthetic_motion"),
    "SimulationConfig": (".simulation.run", "SimulationConfig"),
    "SimulationResult": (".simulation.run", "SimulationResult"),
    "simulate": (".simulation.run", "simulate"),
    "simulate_async": (".simulation.run", "simulate_async"),
    "simulate_scene": (".simulation.run", "simulate_scene"),
    "simulate_to_folder": (".simulation.run", "simulate_to_folder"),
    "write_simulation": (".simulation.run", "write_simulation"),
    "Material": (".simulation.scene", "Material"),
    "Pushover": (".simulation.scene", "Pushover"),
    "SolverSettings": (".simulation.scene", "SolverSettings"),
    "StructureSpec": (".spec", "StructureSpec"),
    "SyntheticSpec": (".spec", "SyntheticSpec"),
    "WallSpec": (".spec", "WallSpec"),
    "load_structure": (".spec", "load_structure"),
    "structure_to_toml": (".spec", "structure_to_toml"),
    "compare": (".comparison", "compare"),
    "Study": (".study.design", "Study"),
    "load_study": (".study.design", "load_study"),
    "run_study": (".study.run", "run_study"),
    "study_to_folder": (".study.run", "study_to_folder"),
    "compare_dirs": (".comparison", "compare_dirs"),
    "synthesize": (".synthetic.truth", "synthesize"),
    "Synthesis": (".synthetic.truth", "Synthesis"),
    "truth_structure": (".synthetic.truth", "truth_structure"),
    "RefineConfig": (".wall2d.refine", "RefineConfig"),
    "PhotoSegmentConfig": (".wall2d.segment", "PhotoSegmentConfig"),
    "segment": (".wall2d.segment", "segment_photo"),
    "TraceConfig": (".wall2d.trace", "TraceConfig"),
    "TracedBrick": (".wall2d.trace", "TracedBrick"),
    "TraceResult": (".wall2d.trace", "TraceResult"),
    "refine": (".wall2d.trace", "refine_trace"),
    "trace": (".wall2d.trace", "trace_mask"),
}

__all__ = sorted(_API)


def __getattr__(name: str):
    try:
        module, attr = _API[name]
    except KeyError:
        raise AttributeError(f"module 'calib_masonry' has no attribute {name!r}") from None
    value = getattr(importlib.import_module(module, __name__), attr)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted([*globals(), *_API])


if TYPE_CHECKING:  # the same names, for type checkers and IDEs
    from .build3d.assemble import Brick as Brick
    from .build3d.assemble import Structure3D as Structure3D
    from .build3d.assemble import WallPolygons as WallPolygons
    from .build3d.assemble import assemble as assemble
    from .build3d.contacts import Interpenetration as Interpenetration
    from .build3d.contacts import max_interpenetration as max_interpenetration
    from .build3d.place import Corner as Corner
    from .build3d.place import Footprint as Footprint
    from .build3d.place import WallFrame as WallFrame
    from .build3d.place import WallGeometry as WallGeometry
    from .build3d.place import closure_gap as closure_gap
    from .build3d.place import corners as corners
    from .build3d.place import wall_frames as wall_frames
    from .build3d.scale import image_from_wall as image_from_wall
    from .build3d.scale import wall_from_image as wall_from_image
    from .build_folder import build_to_folder as build_to_folder
    from .build_folder import read_build as read_build
    from .build_folder import write_build as write_build
    from .calibrate.corner import calibrate_corner_photo as calibrate_corner_photo
    from .calibrate.fitresult import FitResult as FitResult
    from .calibrate.fitresult import FitStatus as FitStatus
    from .calibrate.footprint import fit_footprint as fit_footprint
    from .calibrate.footprint import footprint_to_folder as footprint_to_folder
    from .calibrate.rectify import CalibrateConfig as CalibrateConfig
    from .calibrate.rectify import PhotoCalibration as PhotoCalibration
    from .calibrate.rectify import calibrate_photo as calibrate_photo
    from .calibrate.rectify import rectify as rectify
    from .calibrate.rectify import rectify_to_folder as rectify_to_folder
    from .cli import demo as demo
    from .comparison import compare as compare
    from .comparison import compare_dirs as compare_dirs
    from .comparison import compare_to_file as compare_to_file
    from .errors import BackendMissing as BackendMissing
    from .errors import CalibMasonryError as CalibMasonryError
    from .errors import FitFailed as FitFailed
    from .errors import InputError as InputError
    from .io import Photo as Photo
    from .io import read_mask as read_mask
    from .io import read_photo as read_photo
    from .io import write_mask as write_mask
    from .pipeline import BuildResult as BuildResult
    from .pipeline import build as build
    from .simulation.ground_motion import GroundMotion as GroundMotion
    from .simulation.ground_motion import read_accelerogram as read_accelerogram
    from .simulation.ground_motion import synthetic_motion as synthetic_motion
    from .simulation.run import SimulationConfig as SimulationConfig
    from .simulation.run import SimulationResult as SimulationResult
    from .simulation.run import simulate as simulate
    from .simulation.run import simulate_async as simulate_async
    from .simulation.run import simulate_scene as simulate_scene
    from .simulation.run import simulate_to_folder as simulate_to_folder
    from .simulation.run import write_simulation as write_simulation
    from .simulation.scene import Material as Material
    from .simulation.scene import Pushover as Pushover
    from .simulation.scene import SolverSettings as SolverSettings
    from .spec import StructureSpec as StructureSpec
    from .spec import SyntheticSpec as SyntheticSpec
    from .spec import WallSpec as WallSpec
    from .spec import load_structure as load_structure
    from .spec import structure_to_toml as structure_to_toml
    from .study.design import Study as Study
    from .study.design import load_study as load_study
    from .study.run import run_study as run_study
    from .study.run import study_to_folder as study_to_folder
    from .synthetic.truth import Synthesis as Synthesis
    from .synthetic.truth import synth_to_folder as synth_to_folder
    from .synthetic.truth import synthesize as synthesize
    from .synthetic.truth import truth_structure as truth_structure
    from .wall2d.refine import RefineConfig as RefineConfig
    from .wall2d.segment import PhotoSegmentConfig as PhotoSegmentConfig
    from .wall2d.segment import segment_photo as segment
    from .wall2d.trace import TraceConfig as TraceConfig
    from .wall2d.trace import TracedBrick as TracedBrick
    from .wall2d.trace import TraceResult as TraceResult
    from .wall2d.trace import refine_trace as refine
    from .wall2d.trace import trace_mask as trace
    from .wall2d.trace import trace_to_file as trace_to_file

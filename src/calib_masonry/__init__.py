"""calib_masonry: photos of single-wythe masonry walls to a calibrated 3D brick model.

The public API, re-exported explicitly.
"""

from .build3d.assemble import Brick, Structure3D, WallPolygons, assemble
from .build3d.contacts import Interpenetration, max_interpenetration
from .build3d.place import Corner, WallFrame, closure_gap, corners, wall_frames
from .build3d.scale import image_from_wall, wall_from_image
from .errors import BackendMissing, CalibMasonryError, FitFailed, InputError
from .pipeline import BuildResult, build_to_folder, model_from_masks
from .spec import StructureSpec, SyntheticSpec, WallSpec, load_structure, structure_to_toml
from .study.compare import compare_dirs
from .synthetic.truth import synthesize, truth_structure
from .wall2d.trace import TraceConfig, TracedBrick, TraceResult, trace_mask

__version__ = "0.1.0"

__all__ = [
    "Brick", "Structure3D", "WallPolygons", "assemble",
    "Interpenetration", "max_interpenetration",
    "Corner", "WallFrame", "closure_gap", "corners", "wall_frames",
    "image_from_wall", "wall_from_image",
    "BackendMissing", "CalibMasonryError", "FitFailed", "InputError",
    "BuildResult", "build_to_folder", "model_from_masks",
    "StructureSpec", "SyntheticSpec", "WallSpec", "load_structure", "structure_to_toml",
    "compare_dirs", "synthesize", "truth_structure",
    "TraceConfig", "TracedBrick", "TraceResult", "trace_mask",
]

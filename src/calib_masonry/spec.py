"""Structure descriptions: frozen dataclasses, read from and written to TOML.

A structure file has one ``[structure]`` table and one ``[[wall]]`` table per photo or mask, in the
order the walls follow the footprint (each wall starts where the previous one ends)::

    [structure]
    name = "paper_example"
    thickness_m = 0.18        # default brick thickness t of every wall
    vertices = 5              # default target number of polygon vertices (or target_dice = 0.98)
    max_joint_m = 0.06        # optional: the widest mortar joint two units are joined across

    [[wall]]
    name = "wall1"
    mask = "masks/wall1.png"  # relative to this file
    width_m = 5.73
    height_m = 6.07
    theta_deg = 0.0           # counter-clockwise from global X

Units are SI inside; degrees appear only in the file (``theta_deg``). A scenario file for
``calib-masonry synth`` has the same tables plus a ``[synthetic]`` table (see
:class:`SyntheticSpec`) and needs no mask paths.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import tomli_w

from .errors import InputError
from .io import read_toml

#: polygon vertices per unit of a mask wall (and of ``trace``) when neither the wall nor
#: [structure] gives ``vertices`` or ``target_dice``
DEFAULT_VERTICES = 5
#: the most corners a stone of synth's ``stones`` layout has (four, each chamfered or not): a
#: stones scenario that gives neither ``vertices`` nor ``target_dice`` traces its masks to this
#: many (at five, a tower's stones came out at mean Dice 0.965 against 0.993, and their beds up
#: to 2 cm wider than drawn)
STONE_VERTICES = 8
#: a photo wall's pieces, and a LabelMe file's (its pieces as rectify wrote them or an engineer
#: drew them), likewise traced to the fewest vertices reaching this Dice: a photo's pieces are
#: whatever its masonry is, and irregular stones in five vertices were a tangle of overlapping
#: triangles (a laboratory stone wall: mean Dice 0.84, 7e-4 m^3 of overlap; traced to 0.95: 0.95
#: and 7e-5 m^3), where a brick's rectangle takes four or five either way
PHOTO_TARGET_DICE = 0.95

__all__ = [
    "WallSpec",
    "SyntheticSpec",
    "StructureSpec",
    "load_structure",
    "structure_to_toml",
    "LAYOUTS",
    "CornerSpec",
    "PhotoSpec",
]

LAYOUTS = ("stretcher", "stones")


#: the largest mask a synth run draws per wall (pixels): 8 bytes a pixel to trace it, 1.6 GB
MAX_SYNTH_PIXELS = 2e8
#: the largest wall dimension accepted (m): above any masonry wall; a value beyond it is a unit error
MAX_WALL_M = 1000.0
#: the thinnest wall accepted (m): below any masonry unit's depth (a brick on edge is about 0.05 m);
#: a thickness under it is a unit error (millimetres or centimetres divided once too often)
MIN_THICKNESS_M = 0.01


@dataclass(frozen=True)
class WallSpec:
    """One wall: its photo or mask and the method's input row (W, H, theta, t, N)."""

    name: str
    width_m: float
    height_m: float
    theta_rad: float
    thickness_m: float
    mask: Path | None = None
    image: Path | None = None
    vertices: int | None = None
    target_dice: float | None = None
    refine: bool = False  # soft-Dice vertex refinement after splitting
    # photo walls (``image``): what the calibration is told; W or H may be NaN = take the fitted value
    camera_height_m: float | None = None
    corners_px: tuple[float, ...] | None = None
    focal_px: float | None = None
    occluders: Path | None = None  # a LabelMe JSON or a JSON list of polygons in the photo's pixels
    # the scale, where neither W nor H is given: two photo points and their measured distance
    # (x1, y1, x2, y2, metres), or the masonry's mean course height (metres)
    known_length: tuple[float, float, float, float, float] | None = None
    course_height_m: float | None = None

    def __post_init__(self) -> None:
        where = f"wall '{self.name}'"
        if not isinstance(self.name, str) or not self.name:
            raise InputError(f"wall name {self.name!r}: give every wall a non-empty name")
        for key in ("width_m", "height_m"):
            value = getattr(self, key)
            if not (value > 0 or (math.isnan(value) and self.image is not None)):
                raise InputError(
                    f"{where}: {key} = {value:.6g} must be > 0 (metres); leave it out only for a photo wall"
                )
            if value > MAX_WALL_M:
                raise InputError(
                    f"{where}: {key} = {value:.6g} m is larger than any masonry wall (at most {MAX_WALL_M:g} m); "
                    "give it in metres"
                )
        if not (math.isfinite(self.thickness_m) and MIN_THICKNESS_M <= self.thickness_m <= MAX_WALL_M):
            raise InputError(
                f"{where}: thickness_m = {self.thickness_m:.6g} must lie in {MIN_THICKNESS_M:g}..{MAX_WALL_M:g} "
                "(metres: the units' depth, about 0.1-0.6 m for brick and stone)"
            )
        if not math.isfinite(self.theta_rad):
            raise InputError(f"{where}: theta = {self.theta_rad} must be a finite angle")
        if self.vertices is not None and (
            isinstance(self.vertices, bool) or not isinstance(self.vertices, int) or self.vertices < 3
        ):
            raise InputError(f"{where}: vertices = {self.vertices!r} must be a whole number >= 3")
        if self.target_dice is not None and not 0 < self.target_dice < 1:
            raise InputError(f"{where}: target_dice = {self.target_dice} must lie between 0 and 1")
        if self.camera_height_m is not None and not 0 < self.camera_height_m < 100:
            raise InputError(f"{where}: camera_height_m = {self.camera_height_m} must be the eye height in metres")
        if self.focal_px is not None and not self.focal_px > 0:
            raise InputError(f"{where}: focal_px = {self.focal_px} must be > 0 (pixels)")
        if self.corners_px is not None and len(self.corners_px) != 8:
            raise InputError(f"{where}: corners_px must be 8 numbers [x1, y1, ..., x4, y4] (pixels)")

    @property
    def size_from_photo(self) -> bool:
        return math.isnan(self.width_m) or math.isnan(self.height_m)

    @property
    def theta_deg(self) -> float:
        return math.degrees(self.theta_rad)


@dataclass(frozen=True)
class SyntheticSpec:
    """How ``synth`` lays out and rasterises the walls of a scenario.

    ``layout`` is ``"stretcher"`` (rectangular bricks of ``brick_length_m`` x ``brick_height_m``
    in stretcher bond) or ``"stones"`` (irregular, roughly rectangular stones in courses whose
    heights and lengths are drawn from the given ranges; ``irregularity`` in [0, 1] scales how far
    corners are chamfered and edges tilted). ``edge_blur_px`` and ``edge_noise`` roughen the mask
    edges (a Gaussian blur of that sigma plus that much uniform noise before thresholding).
    """

    layout: str = "stretcher"
    px_per_m: float = 200.0
    seed: int = 0
    mortar_m: float = 0.01
    brick_length_m: float = 0.40
    brick_height_m: float = 0.18
    stone_length_m: tuple[float, float] = (0.5, 0.9)
    stone_height_m: tuple[float, float] = (0.35, 0.55)
    irregularity: float = 0.5
    edge_blur_px: float = 0.0
    edge_noise: float = 0.0

    @property
    def lowest_unit_m(self) -> float:
        """The lowest unit's height (m): the bricks', or the stones' smallest."""
        return self.brick_height_m if self.layout == "stretcher" else self.stone_height_m[0]

    def __post_init__(self) -> None:
        # here rather than where the file is read: a study's sweep makes its specs by ``replace``
        for key in ("px_per_m", "mortar_m", "brick_length_m", "brick_height_m"):
            if getattr(self, key) <= 0:
                raise InputError(f"'{key}' must be > 0, got {getattr(self, key)}")
        stones = self.layout != "stretcher"
        # the shortest unit along the course as well as the lowest (stones of 0.1 mm between joints
        # of 25 mm were laid, 8,468 of them on the Stylite tower)
        for key, unit in (
            ("stone_height_m" if stones else "brick_height_m", self.lowest_unit_m),
            (
                "stone_length_m" if stones else "brick_length_m",
                self.stone_length_m[0] if stones else self.brick_length_m,
            ),
        ):
            if self.mortar_m >= unit:
                raise InputError(
                    f"mortar_m = {self.mortar_m:g} is not thinner than the units ({key} "
                    f"{unit:g} m); give the joint's thickness in metres (about 0.01 m for brick, "
                    "0.02-0.04 m for stone)"
                )


@dataclass(frozen=True)
class PhotoSpec:
    """How ``synth`` takes perspective photos (the ``[photos]`` table of a scenario file).

    Ranges are ``[min, max]``; each photo draws its camera from them (see synthetic.photo)."""

    long_side_px: int = 3000
    short_side_px: int = 2000
    focal_35mm: tuple[float, float] = (24.0, 32.0)
    eye_height_m: tuple[float, float] = (1.5, 1.8)
    distance_m: tuple[float, float] = (3.0, 30.0)
    max_yaw_deg: float = 35.0
    yaw_deg: float | None = None  # a fixed yaw (a truth sweep's value) instead of a draw within max_yaw_deg
    max_roll_deg: float = 2.0
    # the lens's radial distortion (OpenCV's k1, k2; drawn only when a range is not [0, 0], so
    # that photos without it are the same as before it existed)
    k1: tuple[float, float] = (0.0, 0.0)
    k2: tuple[float, float] = (0.0, 0.0)
    blur_px: tuple[float, float] = (0.4, 0.9)
    noise: float = 0.012
    jpeg_quality: int = 90
    heading_sigma_deg: float = 0.25
    margin: float = 0.04  # fraction of the image kept free around the wall


@dataclass(frozen=True)
class CornerSpec:
    """A photo of the corner where wall ``walls[0]`` ends and ``walls[1]`` starts (``[[corner]]``)."""

    photo: Path
    walls: tuple[str, str]
    focal_px: float | None = None


@dataclass(frozen=True)
class StructureSpec:
    """A whole structure: walls in footprint order plus defaults and tolerances."""

    name: str
    walls: tuple[WallSpec, ...]
    thickness_m: float
    vertices: int | None = 5
    target_dice: float | None = None
    closed: bool | None = None
    aspect_tolerance: float = 0.03
    refine: bool = False
    photo_px_per_m: float = 300.0  # orthophoto resolution for segmenting photo walls
    synthetic: SyntheticSpec | None = None
    photos: PhotoSpec | None = None
    corners: tuple[CornerSpec, ...] = ()
    # the widest mortar joint (m) two units are joined across, where it is not the default 0.06
    max_joint_m: float | None = None
    # the [material] table as given (key, value) (calib_masonry.simulation.scene.MATERIAL_KEYS):
    # build stores it in the model folder (material.toml), where simulate reads it
    material: tuple[tuple[str, float], ...] = ()
    source: Path | None = field(default=None, compare=False)

    def __post_init__(self) -> None:
        if not self.walls:
            raise InputError(f"structure '{self.name}': it has no walls; give at least one")
        names = [w.name for w in self.walls]
        if len(set(names)) != len(names):
            raise InputError(f"structure '{self.name}': wall names {names} repeat; give every wall its own name")
        for key in ("thickness_m", "aspect_tolerance", "photo_px_per_m"):
            value = getattr(self, key)
            if not (math.isfinite(value) and value > 0):
                raise InputError(f"structure '{self.name}': {key} = {value} must be > 0")
        j = self.max_joint_m
        if j is not None and not (math.isfinite(j) and MIN_JOINT_M <= j <= MAX_JOINT_M):
            raise InputError(
                f"structure '{self.name}': max_joint_m = {j:g} must lie in {MIN_JOINT_M:g}..{MAX_JOINT_M:g} "
                "(metres: the widest mortar joint two units are joined across; default 0.06)"
            )
        if self.synthetic is not None:  # here, not where the file is read: a sweep uses ``replace``
            course = self.synthetic.mortar_m + self.synthetic.lowest_unit_m
            for w in self.walls:  # a wall lower than one course holds no unit whole: a size in the wrong unit
                if w.height_m < course:
                    raise InputError(
                        f"[synthetic]: one course ({course:g} m: a unit and its mortar) is taller than wall "
                        f"'{w.name}' (height_m = {w.height_m:g}); give the units' sizes in metres"
                    )

    def with_walls(self, walls: tuple[WallSpec, ...]) -> "StructureSpec":
        return replace(self, walls=walls)

    @property
    def footprint(self):
        """The walls' W, H, theta and t and the declared closure: what build3d places and extrudes
        (a :class:`~calib_masonry.build3d.place.Footprint`)."""
        from .build3d.place import Footprint, WallGeometry

        return Footprint(
            walls=tuple(WallGeometry(w.width_m, w.height_m, w.theta_rad, w.thickness_m, w.name) for w in self.walls),
            closed=self.closed,
        )


# ----------------------------------------------------------------------------------------------
# reading


def _where(path: Path | None, table: str) -> str:
    return f"{path.name if path else '<structure>'}: {table}"


def _num(tbl: dict, key: str, where: str, *, default: Any = None, required: bool = False) -> Any:
    if key not in tbl:
        if required:
            raise InputError(f"{where}: field '{key}' is missing; add it (a number)")
        return default
    value = tbl[key]
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise InputError(f"{where}: field '{key}' must be a number, got {value!r}")
    if not math.isfinite(value):
        raise InputError(f"{where}: field '{key}' must be finite, got {value!r}")
    return value


def _flag(tbl: dict, key: str, where: str, default: bool) -> bool:
    value = tbl.get(key, default)
    if not isinstance(value, bool):
        raise InputError(f"{where}: '{key}' must be true or false, got {value!r}")
    return value


def _vertices_or_dice(tbl: dict, where: str, default_n: int | None, default_d: float | None):
    n = tbl.get("vertices", None)
    d = tbl.get("target_dice", None)
    if n is not None:
        if isinstance(n, bool) or not isinstance(n, int):
            raise InputError(f"{where}: 'vertices' must be a whole number, got {n!r}")
        if n < 3:
            raise InputError(f"{where}: 'vertices' = {n} is too few; a polygon needs at least 3")
    if d is not None:
        d = _num(tbl, "target_dice", where)
        if not 0.0 < d < 1.0:
            raise InputError(f"{where}: 'target_dice' = {d} must lie between 0 and 1 (e.g. 0.98)")
    if n is None and d is None:
        return default_n, default_d
    return n, d


def _only_fields_of(cls, tbl: dict, where: str) -> None:
    _check_keys(tbl, tuple(cls.__dataclass_fields__), where)


def _synthetic_from(tbl: dict, where: str) -> SyntheticSpec:
    _only_fields_of(SyntheticSpec, tbl, where)
    kwargs: dict[str, Any] = {}
    for key, value in tbl.items():
        if key == "layout":
            if value not in LAYOUTS:
                raise InputError(f"{where}: layout = {value!r}; choose one of {list(LAYOUTS)}")
            kwargs[key] = value
        elif key == "seed":
            if isinstance(value, bool) or not isinstance(value, int):
                raise InputError(f"{where}: 'seed' must be a whole number, got {value!r}")
            kwargs[key] = value
        elif key in ("stone_length_m", "stone_height_m"):
            if (
                not isinstance(value, list)
                or len(value) != 2
                or not all(isinstance(v, (int, float)) for v in value)
                or not 0 < value[0] <= value[1]
            ):
                raise InputError(f"{where}: '{key}' must be [min, max] in metres with 0 < min <= max, got {value!r}")
            kwargs[key] = (float(value[0]), float(value[1]))
        else:
            kwargs[key] = float(_num(tbl, key, where))
    try:
        spec = SyntheticSpec(**kwargs)
    except InputError as e:
        raise InputError(f"{where}: {e}") from None
    if not 0.0 <= spec.irregularity <= 1.0:
        raise InputError(f"{where}: 'irregularity' must lie in [0, 1], got {spec.irregularity}")
    mortar_px = spec.mortar_m * spec.px_per_m
    if mortar_px < 2.0:
        raise InputError(
            f"{where}: the mortar joint ({spec.mortar_m} m) is only {mortar_px:.1f} px at "
            f"px_per_m = {spec.px_per_m:g}; bricks would merge. Raise px_per_m to at least "
            f"{math.ceil(2.0 / spec.mortar_m)} or widen mortar_m"
        )
    return spec


def _photos_from(tbl: dict, where: str) -> PhotoSpec:
    if not isinstance(tbl, dict):
        raise InputError(f"{where}: must be a table of photo settings")
    _only_fields_of(PhotoSpec, tbl, where)
    kwargs: dict[str, Any] = {}
    for key, value in tbl.items():
        default = getattr(PhotoSpec, key)
        if isinstance(default, tuple):
            if (
                not isinstance(value, list)
                or len(value) != 2
                or not all(isinstance(v, (int, float)) for v in value)
                or value[0] > value[1]
            ):
                raise InputError(f"{where}: '{key}' must be [min, max] with min <= max, got {value!r}")
            kwargs[key] = (float(value[0]), float(value[1]))
        elif isinstance(default, int):
            if isinstance(value, bool) or not isinstance(value, int) or value <= 0:
                raise InputError(f"{where}: '{key}' must be a positive whole number, got {value!r}")
            kwargs[key] = value
        else:
            kwargs[key] = float(_num(tbl, key, where))
    spec = PhotoSpec(**kwargs)
    if spec.short_side_px > spec.long_side_px or spec.short_side_px < 64:
        raise InputError(f"{where}: short_side_px must be >= 64 and <= long_side_px")
    if spec.distance_m[0] <= 0 or spec.eye_height_m[0] <= 0 or spec.focal_35mm[0] <= 0:
        raise InputError(f"{where}: distance_m, eye_height_m and focal_35mm must be positive")
    if not 1 <= spec.jpeg_quality <= 100:
        raise InputError(f"{where}: jpeg_quality must lie in 1..100, got {spec.jpeg_quality}")
    if not (-0.5 <= spec.k1[0] and spec.k1[1] <= 0.5 and -0.5 <= spec.k2[0] and spec.k2[1] <= 0.5):
        raise InputError(f"{where}: k1 and k2 must lie within [-0.5, 0.5] (OpenCV's radial distortion)")
    return spec


#: The range of ``max_joint_m``: a joint narrower than half a centimetre leaves hairline gaps
#: unjoined, and a gap wider than 30 cm is a void, not a joint.
MIN_JOINT_M, MAX_JOINT_M = 0.005, 0.3

STRUCTURE_KEYS = (
    "name",
    "thickness_m",
    "vertices",
    "target_dice",
    "closed",
    "refine",
    "photo_px_per_m",
    "aspect_tolerance",
    "max_joint_m",
)
WALL_KEYS = (
    "name",
    "mask",
    "image",
    "photo",
    "width_m",
    "height_m",
    "theta_deg",
    "thickness_m",
    "vertices",
    "target_dice",
    "refine",
    "camera_height_m",
    "focal_px",
    "corners_px",
    "known_length",
    "course_height_m",
    "occluders",
)
CORNER_KEYS = ("photo", "walls", "focal_px")
TABLES = ("structure", "wall", "corner", "synthetic", "photos", "material")


def _check_keys(tbl: dict, allowed, where: str, what: str = "field") -> None:
    """An unknown key is an error naming the closest valid one ("widht_m: did you mean width_m?")."""
    import difflib

    for key in tbl:
        if key not in allowed:
            close = difflib.get_close_matches(key, list(allowed), n=1, cutoff=0.6)
            hint = f"did you mean {close[0]}?" if close else f"valid {what}s are {', '.join(sorted(allowed))}"
            raise InputError(f"{where}: unknown {what} '{key}'; {hint}")


def _structure_defaults(st, path: Path) -> dict:
    """The [structure] table: the name and the defaults every wall inherits."""
    where = _where(path, "[structure]")
    if not isinstance(st, dict):
        raise InputError(f"{path}: the [structure] table is missing; add one with name and thickness_m")
    _check_keys(st, STRUCTURE_KEYS, where)
    t_default = _num(st, "thickness_m", where, default=None)
    if t_default is not None and t_default <= 0:
        raise InputError(f"{where}: 'thickness_m' must be > 0, got {t_default}")
    n_default, d_default = _vertices_or_dice(st, where, None, None)  # None: each wall's own default
    closed = st.get("closed", None)
    if closed is not None and not isinstance(closed, bool):
        raise InputError(f"{where}: 'closed' must be true or false, got {closed!r}")
    photo_ppm = float(_num(st, "photo_px_per_m", where, default=300.0))
    if photo_ppm <= 0:
        raise InputError(f"{where}: 'photo_px_per_m' must be > 0, got {photo_ppm}")
    aspect_tol = float(_num(st, "aspect_tolerance", where, default=0.03))
    if aspect_tol <= 0:
        raise InputError(f"{where}: 'aspect_tolerance' must be > 0, got {aspect_tol}")
    max_joint = _num(st, "max_joint_m", where, default=None)
    return {
        "name": str(st.get("name", path.parent.name)),
        "max_joint_m": None if max_joint is None else float(max_joint),
        "thickness_m": t_default,
        "vertices": n_default,
        "target_dice": d_default,
        "closed": closed,
        "refine": _flag(st, "refine", where, False),
        "photo_px_per_m": photo_ppm,
        "aspect_tolerance": aspect_tol,
    }


def _numbers(value, count: int) -> bool:
    """Whether a TOML value is a list of ``count`` numbers (not booleans)."""
    return (
        isinstance(value, list)
        and len(value) == count
        and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value)
    )


def _named(path: Path, make, **kwargs):
    """``make(**kwargs)``, its InputError prefixed with the file's name."""
    try:
        return make(**kwargs)
    except InputError as e:
        raise InputError(f"{path.name}: {e}") from None


def _wall_from(w, where: str, wname: str, defaults: dict, path: Path, require_sources: bool) -> WallSpec:
    """One [[wall]] table."""
    if not isinstance(w, dict):
        raise InputError(f"{where}: must be a table of wall fields")
    _check_keys(w, WALL_KEYS, where)
    base = path.parent
    t_default, n_default, d_default = defaults["thickness_m"], defaults["vertices"], defaults["target_dice"]
    refine_default = defaults["refine"]
    has_photo = "image" in w or "photo" in w
    width = _num(w, "width_m", where, required=not has_photo, default=math.nan)
    height = _num(w, "height_m", where, required=not has_photo, default=math.nan)
    theta_deg = _num(w, "theta_deg", where, default=0.0)
    t = _num(w, "thickness_m", where, default=t_default)
    if width <= 0:
        raise InputError(f"{where}: width_m = {width:.6g} must be > 0 (metres)")
    if height <= 0:
        raise InputError(f"{where}: height_m = {height:.6g} must be > 0 (metres)")
    if t is None:
        raise InputError(f"{where}: no thickness; set thickness_m here or in [structure]")
    if t <= 0:
        raise InputError(f"{where}: thickness_m = {t:.6g} must be > 0 (metres)")
    if t < MIN_THICKNESS_M:
        raise InputError(
            f"{where}: thickness_m = {t:.6g} is thinner than any masonry unit (at least {MIN_THICKNESS_M:g} m); "
            "give the units' depth in metres"
        )
    if t >= width and not math.isnan(width):
        raise InputError(f"{where}: thickness_m = {t:.6g} is not smaller than width_m = {width:.6g}; check both")
    n, d = _vertices_or_dice(w, where, n_default, d_default)
    mask = image = None
    if "photo" in w and "image" not in w:
        w = {**w, "image": w["photo"]}
    for key in ("mask", "image"):
        if key in w:
            if not isinstance(w[key], str):
                raise InputError(f"{where}: '{key}' must be a path string, got {w[key]!r}")
            p = Path(w[key])
            p = p if p.is_absolute() else base / p
            if require_sources and not p.is_file():
                raise InputError(f"{where}: {key} file {p} not found; fix the path (relative to {path.name})")
            if key == "mask":
                mask = p
            else:
                image = p
    if require_sources and mask is None and image is None:
        raise InputError(f"{where}: neither 'mask' nor 'image' (photo) is given; name the wall's mask or photo file")
    if n is None and d is None:  # given neither here nor in [structure]
        drawn = image is not None or (mask is not None and mask.suffix.lower() == ".json")
        n, d = (None, PHOTO_TARGET_DICE) if drawn else (DEFAULT_VERTICES, None)
    if mask is None and image is None and (math.isnan(width) or math.isnan(height)):
        raise InputError(f"{where}: width_m and height_m are missing; give them (metres) or a photo to fit them from")
    occluders = None
    if "occluders" in w:
        if not isinstance(w["occluders"], str):
            raise InputError(f"{where}: 'occluders' must be a path string (a LabelMe .json), got {w['occluders']!r}")
        occluders = Path(w["occluders"])
        occluders = occluders if occluders.is_absolute() else base / occluders
        if require_sources and not occluders.is_file():
            raise InputError(f"{where}: occluders file {occluders} not found; fix the path (relative to {path.name})")
    cam_h = _num(w, "camera_height_m", where, default=None)
    if cam_h is not None and not 0.0 < cam_h < 100.0:
        raise InputError(
            f"{where}: camera_height_m = {cam_h} must be the eye height above the wall's base in metres (e.g. 1.6)"
        )
    focal = _num(w, "focal_px", where, default=None)
    if focal is not None and focal <= 0:
        raise InputError(f"{where}: focal_px = {focal} must be > 0 (pixels)")
    corners = w.get("corners_px")
    if corners is not None:
        if not _numbers(corners, 8):
            raise InputError(f"{where}: corners_px must be 8 numbers [x1, y1, ..., x4, y4] (pixels), got {corners!r}")
        corners = tuple(float(v) for v in corners)
    known_length = w.get("known_length")
    if known_length is not None and not (_numbers(known_length, 5) and known_length[4] > 0):
        raise InputError(
            f"{where}: known_length must be [x1, y1, x2, y2, metres] (two photo points and their measured distance "
            f"> 0), got {known_length!r}"
        )
    course = _num(w, "course_height_m", where, default=None)
    if course is not None and not 0.0 < course < 10.0:
        raise InputError(f"{where}: course_height_m = {course} must be the mean course height in metres (e.g. 0.075)")
    scales = [k for k, v in (("known_length", known_length), ("course_height_m", course)) if v is not None]
    if scales and image is None:
        raise InputError(f"{where}: {scales[0]} scales a photo; this wall has no image (its mask is drawn to W x H)")
    given = [k for k in ("width_m", "height_m") if k in w]
    if len(scales) + bool(given) > 1:
        raise InputError(
            f"{where}: {' and '.join(given + scales)} each set the scale; give one (leave width_m and height_m out "
            "to take them from the photo)"
        )
    return WallSpec(
        name=wname,
        width_m=float(width),
        height_m=float(height),
        theta_rad=math.radians(theta_deg),
        thickness_m=float(t),
        mask=mask,
        image=image,
        vertices=n,
        target_dice=d,
        refine=_flag(w, "refine", where, refine_default),
        camera_height_m=None if cam_h is None else float(cam_h),
        corners_px=corners,
        focal_px=None if focal is None else float(focal),
        occluders=occluders,
        known_length=None if known_length is None else tuple(float(v) for v in known_length),
        course_height_m=None if course is None else float(course),
    )


def _corner_from(c, i: int, names, path: Path, require_sources: bool) -> CornerSpec:
    """One [[corner]] table."""
    base = path.parent
    where = _where(path, f"[[corner]] {i}")
    if isinstance(c, dict):
        _check_keys(c, CORNER_KEYS, where)
    if not isinstance(c, dict) or not isinstance(c.get("photo"), str):
        raise InputError(f"{where}: needs photo = 'PATH' and walls = ['A', 'B']")
    pair = c.get("walls")
    if not (isinstance(pair, list) and len(pair) == 2 and all(p in names for p in pair) and pair[0] != pair[1]):
        raise InputError(
            f"{where}: walls = {pair!r} must name two different walls of this file, the left one "
            "(as seen from outside) first"
        )
    p = Path(c["photo"])
    p = p if p.is_absolute() else base / p
    if require_sources and not p.is_file():
        raise InputError(f"{where}: photo file {p} not found; fix the path (relative to {path.name})")
    focal = _num(c, "focal_px", where, default=None)
    return CornerSpec(photo=p, walls=(pair[0], pair[1]), focal_px=None if focal is None else float(focal))


def load_structure(path: str | Path, *, require_sources: bool = True) -> StructureSpec:
    """Read and validate a structure (or scenario) TOML file, table by table.

    Parameters
    ----------
    path : path of the TOML file; mask and image paths inside it are relative to its folder.
    require_sources : if True every wall must name a ``mask`` (or ``image``) that exists.
    """
    path = Path(path)
    data = read_toml(path, "structure file")
    _check_keys(data, TABLES, str(path), "table")
    defaults = _structure_defaults(data.get("structure"), path)
    synthetic = _synthetic_from(data["synthetic"], _where(path, "[synthetic]")) if "synthetic" in data else None
    if synthetic is not None and synthetic.layout == "stones" and defaults["vertices"] is None:
        if defaults["target_dice"] is None:  # the masks synth draws of its stones: traced to their own corners
            defaults["vertices"] = STONE_VERTICES
    photos = _photos_from(data["photos"], _where(path, "[photos]")) if "photos" in data else None
    walls_tbl = data.get("wall")
    if not isinstance(walls_tbl, list) or not walls_tbl:
        raise InputError(f"{path}: no [[wall]] tables; add one per wall photo or mask")
    walls: list[WallSpec] = []
    names: set[str] = set()
    for i, w in enumerate(walls_tbl, start=1):
        wname = str(w.get("name", f"wall{i}")) if isinstance(w, dict) else f"wall{i}"
        where = _where(path, f"[[wall]] {i} ({wname})")
        if wname in names:
            raise InputError(f"{where}: duplicate wall name; give every wall its own name")
        names.add(wname)
        walls.append(_wall_from(w, where, wname, defaults, path, require_sources))
    if synthetic is not None:
        for w in walls:  # the masks a synth run would draw, bounded before any work (1e6 px/m ran out of memory)
            pixels = w.width_m * w.height_m * synthetic.px_per_m**2
            if pixels > MAX_SYNTH_PIXELS:
                most = math.sqrt(MAX_SYNTH_PIXELS / (w.width_m * w.height_m))
                raise InputError(
                    f"{_where(path, '[synthetic]')}: px_per_m = {synthetic.px_per_m:.6g} makes wall '{w.name}' a "
                    f"{w.width_m * synthetic.px_per_m:.3g} x {w.height_m * synthetic.px_per_m:.3g} px mask, above "
                    f"{MAX_SYNTH_PIXELS:.0e} px; lower px_per_m to at most {math.floor(most)}"
                )
    corners = [
        _corner_from(c, i, names, path, require_sources) for i, c in enumerate(data.get("corner", []) or [], start=1)
    ]
    material: tuple[tuple[str, float], ...] = ()
    if "material" in data:
        from .simulation.scene import material_from_table

        material_from_table(data["material"], str(path))  # checked here, before any work
        material = tuple((str(k), float(v)) for k, v in data["material"].items())
    t_default = defaults["thickness_m"]
    spec = _named(
        path,
        StructureSpec,
        name=defaults["name"],
        walls=tuple(walls),
        thickness_m=float(t_default if t_default is not None else walls[0].thickness_m),
        # neither given in [structure]: each wall took its own default; the structure says five
        vertices=DEFAULT_VERTICES
        if defaults["vertices"] is None and defaults["target_dice"] is None
        else defaults["vertices"],
        target_dice=defaults["target_dice"],
        closed=defaults["closed"],
        aspect_tolerance=defaults["aspect_tolerance"],
        refine=defaults["refine"],
        photo_px_per_m=defaults["photo_px_per_m"],
        max_joint_m=defaults["max_joint_m"],
        synthetic=synthetic,
        photos=photos,
        corners=tuple(corners),
        material=material,
        source=path,
    )
    if not any(w.size_from_photo for w in walls):  # the corners' room, before any work (else at the build)
        from .build3d.place import corners as footprint_corners

        _named(path, footprint_corners, footprint=spec)
    return spec


# ----------------------------------------------------------------------------------------------
# writing


def _clean(value: float) -> float:
    return float(round(value, 12))


def structure_to_toml(spec: StructureSpec, *, relative_to: Path | None = None, include_synthetic: bool = False) -> str:
    """TOML text of ``spec``; paths are written relative to ``relative_to`` when given."""
    st: dict[str, Any] = {"name": spec.name, "thickness_m": _clean(spec.thickness_m)}
    if spec.vertices is not None:
        st["vertices"] = spec.vertices
    if spec.target_dice is not None:
        st["target_dice"] = spec.target_dice
    if spec.closed is not None:
        st["closed"] = spec.closed
    st["aspect_tolerance"] = spec.aspect_tolerance
    if spec.photo_px_per_m != 300.0:
        st["photo_px_per_m"] = spec.photo_px_per_m
    if spec.refine:
        st["refine"] = True
    if spec.max_joint_m is not None:
        st["max_joint_m"] = _clean(spec.max_joint_m)
    doc: dict[str, Any] = {"structure": st}
    if include_synthetic and spec.synthetic is not None:
        syn = {k: (list(v) if isinstance(v, tuple) else v) for k, v in spec.synthetic.__dict__.items()}
        doc["synthetic"] = syn
    walls = []
    for w in spec.walls:
        row: dict[str, Any] = {"name": w.name}
        for key in ("mask", "image", "occluders"):
            p = getattr(w, key)
            if p is not None:
                row[key] = Path(p).relative_to(relative_to).as_posix() if relative_to else Path(p).as_posix()
        if not math.isnan(w.width_m):
            row["width_m"] = _clean(w.width_m)
        if not math.isnan(w.height_m):
            row["height_m"] = _clean(w.height_m)
        row.update(theta_deg=_clean(w.theta_deg), thickness_m=_clean(w.thickness_m))
        for key in ("camera_height_m", "focal_px"):
            if getattr(w, key) is not None:
                row[key] = _clean(getattr(w, key))
        if w.corners_px is not None:
            row["corners_px"] = [_clean(v) for v in w.corners_px]
        if w.known_length is not None:
            row["known_length"] = [_clean(v) for v in w.known_length]
        if w.course_height_m is not None:
            row["course_height_m"] = _clean(w.course_height_m)
        if w.vertices is not None and w.vertices != spec.vertices:
            row["vertices"] = w.vertices
        if w.target_dice is not None and w.target_dice != spec.target_dice:
            row["target_dice"] = w.target_dice
        if w.refine != spec.refine:
            row["refine"] = w.refine
        walls.append(row)
    doc["wall"] = walls
    if spec.corners:
        doc["corner"] = [
            {
                "photo": (
                    Path(c.photo).relative_to(relative_to).as_posix() if relative_to else Path(c.photo).as_posix()
                ),
                "walls": list(c.walls),
                **({"focal_px": c.focal_px} if c.focal_px else {}),
            }
            for c in spec.corners
        ]
    if spec.material:
        doc["material"] = dict(spec.material)
    return tomli_w.dumps(doc)

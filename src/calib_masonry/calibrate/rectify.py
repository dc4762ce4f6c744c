"""One photo to a calibrated wall: detect or take the corners, fit, check, resample to an orthophoto.

``calibrate_photo`` is the library call behind ``calib-masonry rectify`` and behind ``build`` on
structure files that name photos. ``rectify_image`` resamples the photo by the fitted homography
(bilinear, scipy; a Gaussian pre-blur when the wall is shrunk, so the orthophoto does not alias).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from .._threads import background, thread_map
from ..errors import FitFailed, InputError
from ..io import (
    MIN_IMAGE_PX,
    Photo,
    check_output,
    read_photo,
    staged_output,
    write_json,
    write_mask,
    write_rgb,
)
from ..preload import preload_in_background
from .camera import (
    CORNERS_FLAG,
    FILLS_PHOTO_ADVICE,
    FOCAL_PRIOR_35MM,
    FOCAL_PRIOR_LOG_SIGMA,
    focal_prior_px,
    order_corners,
    px_per_m,
)
from .lines import (
    DetectConfig,
    Detection,
    carry_soft_sides,
    detect_wall,
    joint_segments,
    refine_quad,
    segments_in_quad,
)
from .veil import without_veil

if TYPE_CHECKING:
    from .fit import CalibrationResult

__all__ = [
    "wall_stretch",
    "CalibrateConfig",
    "PhotoCalibration",
    "calibrate_photo",
    "native_px_per_m",
    "parse_corners",
    "rect_from_wall",
    "rectify",
    "rectify_image",
    "rectify_to_folder",
]


#: Without a measured camera height, the eye height above the wall's base is this prior: a
#: standing photographer's eye (1.5-1.75 m), a ground that is not level with the wall's base, a
#: step, a tripod at the wall's mid-height in a laboratory (0.45 m measured on the laboratory
#: photos). Its spread makes the scale it gives uncertain by about a third, which
#: :data:`MAX_RELATIVE_SIGMA` refuses: the prior alone never passes as a measurement.
EYE_HEIGHT_PRIOR_M = 1.6
EYE_HEIGHT_PRIOR_SIGMA_M = 0.5
#: a measured camera height's default sigma (tape or laser to the wall's base)
MEASURED_HEIGHT_SIGMA_M = 0.02
#: a fit whose W or H is less certain than this (1 sigma, relative) is refused without --force
MAX_RELATIVE_SIGMA = 0.25
#: corners further than this many of their sigmas (RMS) from the outline the joints fit are refused
MAX_CORNER_SIGMAS = 3.0
#: the lens is kept fitted when the photo narrows k1's sigma below this share of its prior's, and
#: undoing it takes the long joints' RMS distance from straight lines below this share of what it
#: was (a quarter less squared distance): a lens bends every straight joint alike, and undoing it
#: straightens them (0.39 -> 0.27 px on a synthetic brick wall at k1 = -0.05, 2-5 times at
#: 0.1-0.2, down to the segments' own noise), where irregular stone courses, whose joints no lens
#: made crooked, gain little (0.59 -> 0.58 px) and gave a spurious k1 of 0.1 +- 0.026
LENS_DETERMINED = 0.5
LENS_STRAIGHTENS = 0.85
#: a clicked corner's sigma where no edge pins it (px)
CLICKED_SIGMA_PX = 2.0
#: a course height's default relative sigma (the mean course of a brick wall: units to 2-3 %,
#: joints to a couple of millimetres)
COURSE_HEIGHT_RELATIVE_SIGMA = 0.03

#: the flags that pin the scale, best first (named by every message about the scale)
SCALE_FLAGS = "--known-width, --known-height or --known-length x1,y1,x2,y2,M (a tape measurement), --course-height M, or a measured --camera-height"


class ScaleSource:
    """Where a calibration's scale (metres per wall unit) comes from, best first."""

    KNOWN_WIDTH = "known width"
    KNOWN_HEIGHT = "known height"
    KNOWN_LENGTH = "known length"
    COURSE_HEIGHT = "course height"
    CAMERA_HEIGHT = "measured camera height"
    EYE_HEIGHT_PRIOR = "eye-height prior"


def parse_numbers(text: str, flag: str, count: int | tuple[int, ...], what: str) -> tuple[float, ...]:
    """A comma-separated list of numbers for ``flag`` (negative ones included), of ``count`` items."""
    counts = (count,) if isinstance(count, int) else count
    try:
        values = tuple(float(v) for v in str(text).replace(" ", "").split(","))
    except ValueError:
        raise InputError(f"{flag} {text!r}: not a list of numbers; give {what}") from None
    if len(values) not in counts or not all(math.isfinite(v) for v in values):
        raise InputError(f"{flag}: got {len(values)} numbers ({text!r}); give {what}")
    return values


@dataclass(frozen=True)
class CalibrateConfig:
    """What the user tells the calibration (the flags of ``rectify``).

    Scale, best first: ``known_width_m`` / ``known_height_m`` / ``known_length`` (``(x1, y1, x2, y2,
    metres)``, two photo points on the wall), ``course_height_m`` (the masonry's mean course
    height, with ``course_height_sigma_m``; the number of courses is found from the bed joints'
    spacing), a measured ``camera_height_m`` (eye height above the wall's base; sigma
    ``camera_height_sigma_m``, default :data:`MEASURED_HEIGHT_SIGMA_M`), else the eye-height prior
    (:data:`EYE_HEIGHT_PRIOR_M` +- :data:`EYE_HEIGHT_PRIOR_SIGMA_M`). A fit whose W or H sigma
    exceeds ``max_relative_sigma`` is refused unless ``force``.

    ``corner_sigma_px``: default from each corner's edge evidence (detected or snapped), else
    :data:`CLICKED_SIGMA_PX`. ``snap_tolerance_px``: how far a clicked corner may move onto the
    outline (default 1 % of the photo's diagonal, at least 3 px). ``max_rms_px``: the largest RMS
    residual kept (default 3 px per 1500 px of the photo's long side, at least 3). ``occluders``:
    polygons ``((x, y), ...)`` in photo pixels (a rig, a beam, scaffolding, vegetation, people) left
    out of the detection, the fit and the segmentation. ``lens_profile``: take k1, k2's prior from
    lensfun when the EXIF names a known camera and lens."""

    corners_px: tuple[float, ...] | None = None  # 8 numbers x1, y1, ..., x4, y4 in any order; None = automatic
    camera_height_m: float | None = None
    camera_height_sigma_m: float | None = None
    focal_px: float | None = None  # overrides EXIF
    focal_sigma_px: float | None = None
    focal_prior_log_sigma: float = FOCAL_PRIOR_LOG_SIGMA  # without EXIF or focal_px: the prior's log sigma
    known_width_m: float | None = None
    known_height_m: float | None = None
    known_length: tuple[float, float, float, float, float] | None = None
    known_sigma_m: float = 0.005
    course_height_m: float | None = None
    course_height_sigma_m: float | None = None
    corner_sigma_px: float | None = None
    line_sigma_px: float = 1.0
    max_effective_segments: int = 16
    use_lines: bool = True
    snap_corners: bool = True  # refine clicked corners onto the wall's outline edges
    snap_tolerance_px: float | None = None
    max_rms_px: float | None = None
    max_relative_sigma: float = MAX_RELATIVE_SIGMA
    force: bool = False
    occluders: tuple = ()
    # (width, height) px of the image the corners or occluders were drawn on (a LabelMe file's
    # imageWidth, imageHeight), checked against the photo's
    annotation_size: tuple[int, int] | None = None
    fit_distortion: bool = True
    lens_profile: bool = True
    detect: DetectConfig = field(default_factory=DetectConfig)

    def __post_init__(self) -> None:
        if not (math.isfinite(self.focal_prior_log_sigma) and self.focal_prior_log_sigma > 0):
            raise InputError(f"focal_prior_log_sigma {self.focal_prior_log_sigma}: must be > 0")
        # bounds past which the fit's Jacobian was singular (a height of 1e-6 m, a sigma of 1e-9 or
        # 1e9 m, a length of 1e9 m): each named here rather than as "too few constraints"
        if self.camera_height_m is not None and not (
            math.isfinite(self.camera_height_m) and 0.01 <= self.camera_height_m < 100
        ):
            raise InputError(
                f"--camera-height {self.camera_height_m}: give the eye height above the wall's base in metres "
                "(0.01-100)"
            )
        if self.camera_height_sigma_m is not None and not (
            math.isfinite(self.camera_height_sigma_m) and 0.001 <= self.camera_height_sigma_m <= 100
        ):
            raise InputError(
                f"--camera-height-sigma {self.camera_height_sigma_m}: give its uncertainty in metres (0.001-100)"
            )
        if self.focal_px is not None and not (math.isfinite(self.focal_px) and self.focal_px > 0):
            raise InputError(f"--focal-px {self.focal_px}: must be > 0 (pixels)")
        for flag, value, top in (
            ("--known-width", self.known_width_m, 1000.0),
            ("--known-height", self.known_height_m, 1000.0),
            ("--course-height", self.course_height_m, 5.0),
        ):
            if value is not None and not (math.isfinite(value) and 0.01 <= value <= top):
                raise InputError(f"{flag} {value}: give a length in metres (0.01-{top:g})")
        if self.course_height_sigma_m is not None and not (
            math.isfinite(self.course_height_sigma_m) and 0 < self.course_height_sigma_m <= 5.0
        ):
            raise InputError(
                f"--course-height: its sigma {self.course_height_sigma_m} must be a length in metres (above 0, to 5)"
            )
        given = [
            f
            for f, v in (
                ("--known-width", self.known_width_m),
                ("--known-height", self.known_height_m),
                ("--known-length", self.known_length),
                ("--course-height", self.course_height_m),
            )
            if v is not None
        ]
        if len(given) > 1:
            raise InputError(f"rectify: give one measured length, not {' and '.join(given)}")
        if self.known_length is not None:
            kl = tuple(self.known_length)
            if len(kl) != 5 or not all(math.isfinite(v) for v in kl):
                raise InputError("--known-length: give x1,y1,x2,y2,METRES (two photo points and their distance)")
            if not 0.01 <= kl[4] <= 1000:
                raise InputError(f"--known-length: the distance {kl[4]} must be a length in metres (0.01-1000)")
            if math.hypot(kl[2] - kl[0], kl[3] - kl[1]) < 5:
                raise InputError("--known-length: the two points are less than 5 px apart; click two points far apart")
        if not (math.isfinite(self.known_sigma_m) and self.known_sigma_m > 0):
            raise InputError(f"known_sigma_m = {self.known_sigma_m}: must be > 0 (metres)")
        for flag, value in (("--max-rms", self.max_rms_px), ("--snap-tolerance", self.snap_tolerance_px)):
            if value is not None and not (math.isfinite(value) and value > 0):
                raise InputError(f"{flag} {value}: must be > 0 (pixels)")
        # (a snap tolerance is checked against the photo's size in calibrate_photo)
        if not (math.isfinite(self.max_relative_sigma) and self.max_relative_sigma > 0):
            raise InputError(f"max_relative_sigma = {self.max_relative_sigma}: must be > 0")
        if self.corner_sigma_px is not None and not (math.isfinite(self.corner_sigma_px) and self.corner_sigma_px > 0):
            raise InputError(f"corner_sigma_px = {self.corner_sigma_px}: must be > 0 (pixels)")
        if self.corners_px is not None and len(self.corners_px) != 8:
            raise InputError(f"--corners: got {len(self.corners_px)} numbers; give exactly 8 (x1,y1,...,x4,y4)")
        for i, poly in enumerate(self.occluders):
            pts = np.asarray(poly, dtype=np.float64)
            if pts.ndim != 2 or pts.shape[1] != 2 or len(pts) < 3 or not np.all(np.isfinite(pts)):
                raise InputError(f"occluder {i + 1}: give a polygon of at least 3 points (x, y) in photo pixels")

    @property
    def scale_source(self) -> str:
        if self.known_width_m is not None:
            return ScaleSource.KNOWN_WIDTH
        if self.known_height_m is not None:
            return ScaleSource.KNOWN_HEIGHT
        if self.known_length is not None:
            return ScaleSource.KNOWN_LENGTH
        if self.course_height_m is not None:
            return ScaleSource.COURSE_HEIGHT
        if self.camera_height_m is not None:
            return ScaleSource.CAMERA_HEIGHT
        return ScaleSource.EYE_HEIGHT_PRIOR

    def eye_height(self) -> tuple[float, float]:
        """The camera height's value and sigma the fit uses (measured or the prior)."""
        if self.camera_height_m is None:
            return EYE_HEIGHT_PRIOR_M, self.camera_height_sigma_m or EYE_HEIGHT_PRIOR_SIGMA_M
        return self.camera_height_m, self.camera_height_sigma_m or MEASURED_HEIGHT_SIGMA_M


#: above this relative 1-sigma uncertainty of W or H a calibration says how to pin the scale
SCALE_ADVICE_RELATIVE_SIGMA = 0.02


@dataclass(frozen=True)
class PhotoCalibration:
    photo: Photo
    result: CalibrationResult
    detection: Detection | None
    mode: str  # "clicked", "clicked, snapped to the outline" or "automatic"
    focal_source: str
    scale_source: str = ScaleSource.EYE_HEIGHT_PRIOR
    scale_detail: str = ""  # the prior's or the measurement's value, for the printed line
    lens_source: str = "fitted (no profile)"
    corner_sigma_px: tuple[float, ...] = ()
    corner_snap_px: tuple[float, ...] | None = None  # clicked -> snapped, per corner
    occluders: tuple = ()
    courses: dict | None = None  # the course-height scale's measurement
    joints_left_out: int = 0  # joint segments found but left out: they did not fit the clicked corners' plane

    def relative_sigma(self) -> float:
        return max(
            self.result.sigma("width_m") / self.result.width_m, self.result.sigma("height_m") / self.result.height_m
        )

    def advice(self) -> str:
        """What to add when the photo fixes W and H only loosely ("" when both are known to within
        :data:`SCALE_ADVICE_RELATIVE_SIGMA`)."""
        rel = self.relative_sigma()
        if not rel > SCALE_ADVICE_RELATIVE_SIGMA:
            return ""
        measured = (
            ScaleSource.KNOWN_WIDTH,
            ScaleSource.KNOWN_HEIGHT,
            ScaleSource.KNOWN_LENGTH,
            ScaleSource.COURSE_HEIGHT,
        )
        if self.scale_source in measured:
            # the scale is measured: what is loose is the other side, from where the corners are (the
            # laboratory photos' H at +-3 % with the width given were told to add --known-width)
            loose = [
                name
                for name, key in (("W", "width_m"), ("H", "height_m"))
                if self.result.sigma(key) / self.result.value(key) > SCALE_ADVICE_RELATIVE_SIGMA
            ]
            return (
                f"{' and '.join(loose)} {'is' if len(loose) == 1 else 'are'} known only to +-{rel:.1%} (1 sigma) from "
                f"this photo: the scale is the {self.scale_source}, the rest rests on where its corners are; click "
                f"them with {CORNERS_FLAG} (or correct the outline in photo.json and pass it with --labelme)"
            )
        return (
            f"W and H are known only to +-{rel:.1%} (1 sigma) from this photo (scale from the {self.scale_source}); "
            f"pin the scale with {SCALE_FLAGS}"
        )

    def to_json(self) -> dict:
        doc = self.result.to_json()
        doc.update(
            photo=str(self.photo.path),
            mode=self.mode,
            focal_source=self.focal_source,
            scale_source=self.scale_source,
            scale_detail=self.scale_detail,
            lens_source=self.lens_source,
            corner_sigma_px=list(self.corner_sigma_px),
        )
        if self.corner_snap_px is not None:
            doc["corner_snap_px"] = list(self.corner_snap_px)
        if self.joints_left_out:
            doc["joints_left_out"] = self.joints_left_out
        if self.occluders:
            doc["occluders_px"] = [np.asarray(p, dtype=float).tolist() for p in self.occluders]
        if self.courses is not None:
            doc["courses"] = self.courses
        advice = self.advice()
        if advice:
            doc["advice"] = advice
        if self.photo.heading_deg is not None:
            doc["exif_heading_deg"] = self.photo.heading_deg
            from .camera import theta_from_heading

            doc["theta_from_heading_deg"] = math.degrees(
                theta_from_heading(math.radians(self.photo.heading_deg), self.result.value("yaw_rad"))
            )
        return doc


def parse_corners(text: str) -> tuple[float, ...]:
    return parse_numbers(text, "--corners", 8, "exactly 8 numbers x1,y1,...,x4,y4 in pixels")


def _refine_clicked(rgb: np.ndarray, corners: np.ndarray, tolerance: float):
    """Snap clicked corners onto the wall's outline edges within ``tolerance`` px: (corners, sigma per
    corner, snapped?)."""
    snapped, sigma = refine_quad(rgb, corners, (tolerance, max(2.0, tolerance / 3)), with_sigma=True, curved=True)
    if np.array_equal(snapped, corners):
        return corners, np.full(4, CLICKED_SIGMA_PX), False
    moved = np.linalg.norm(snapped - corners, axis=1)
    if np.max(moved) > tolerance:
        return corners, np.full(4, CLICKED_SIGMA_PX), False
    return snapped, np.maximum(sigma, 0.5), True


def wall_config(wall, base: CalibrateConfig | None = None) -> CalibrateConfig:
    """What a photo wall's [[wall]] table (a :class:`~calib_masonry.spec.WallSpec`) tells its
    calibration, on top of ``base`` (a command's flags; default none): its scale where ``base``
    gives none (its W, else its H, else ``known_length``, else ``course_height_m``), its camera
    height (sigma 2 cm), clicked corners, focal length and occluders (and the size they were drawn
    on). build and footprint each calibrate a photo wall so."""
    cfg = base or CalibrateConfig()
    if all(v is None for v in (cfg.known_width_m, cfg.known_height_m, cfg.known_length, cfg.course_height_m)):
        if not math.isnan(wall.width_m):
            cfg = replace(cfg, known_width_m=wall.width_m)
        elif not math.isnan(wall.height_m):
            cfg = replace(cfg, known_height_m=wall.height_m)
        elif wall.known_length is not None:
            cfg = replace(cfg, known_length=wall.known_length)
        elif wall.course_height_m is not None:
            cfg = replace(cfg, course_height_m=wall.course_height_m)
    if wall.camera_height_m is not None:
        cfg = replace(cfg, camera_height_m=wall.camera_height_m, camera_height_sigma_m=0.02)
    if wall.corners_px is not None:
        cfg = replace(cfg, corners_px=wall.corners_px)
    if wall.focal_px is not None:
        cfg = replace(cfg, focal_px=wall.focal_px)
    if wall.occluders is not None:
        from ..labelme import annotation_size, read_occluders

        cfg = replace(
            cfg,
            occluders=tuple(cfg.occluders) + tuple(read_occluders(wall.occluders)),
            annotation_size=annotation_size(wall.occluders),
        )
    return cfg


def _inside_photo(points: np.ndarray, w: int, h: int) -> np.ndarray:
    """``(n,)`` True for each point ``(n, 2)`` on a ``w`` x ``h`` photo (pixel centres, edges to +-0.5)."""
    return (points[:, 0] >= -0.5) & (points[:, 0] <= w - 0.5) & (points[:, 1] >= -0.5) & (points[:, 1] <= h - 0.5)


def calibrate_photo(photo: Photo | str | Path, config: CalibrateConfig = CalibrateConfig()) -> PhotoCalibration:
    """Fit the camera, the lens and the wall to one photo; refuse a fit whose residual is above
    ``max_rms_px`` or whose W or H sigma is above ``max_relative_sigma`` (unless ``force``)."""
    if not isinstance(photo, Photo):
        photo = read_photo(photo)
    photo = without_veil(photo)
    w, h = photo.size
    diag = math.hypot(w, h)
    if config.annotation_size is not None and tuple(int(v) for v in config.annotation_size) != (w, h):
        aw, ah = (int(v) for v in config.annotation_size)
        raise InputError(
            f"{photo.path}: the LabelMe annotation was drawn on a {aw} x {ah} px image, but this photo is {w} x {h} px "
            "(a resized or rotated copy?); draw the outline and occluders on this photo itself"
        )
    focal, focal_source = config.focal_px, "--focal-px"
    # an EXIF whose two focal lengths disagree gives the prior's centre and spread, not the focal length
    prior_px, prior_log_sigma = None, config.focal_prior_log_sigma
    if focal is None and photo.focal_px is not None:
        if photo.focal_log_sigma is None:
            focal, focal_source = photo.focal_px, f"EXIF: {photo.focal_note}" if photo.focal_note else "EXIF"
        else:
            prior_px, prior_log_sigma = photo.focal_px, photo.focal_log_sigma
    prior_note = photo.focal_note
    if focal is None and prior_px is None:
        # FocalLength alone (no focal plane resolution, no 35 mm equivalent): the camera's crop
        # factor from lensfun makes it a 35 mm equivalent, a prior (the photo may cover less of the
        # sensor than its diagonal) that the vanishing points settle
        from .lens import CROP_FACTOR_LOG_SIGMA, crop_factor_focal

        found = crop_factor_focal(photo.lens, (w, h))
        if found is not None:
            (prior_px, prior_note), prior_log_sigma = found, CROP_FACTOR_LOG_SIGMA
    if focal is not None and not 0.1 * max(w, h) < focal < 20 * max(w, h):
        raise InputError(
            f"{photo.path}: focal length {focal:.0f} px is implausible for a {w} x {h} photo; "
            "pass --focal-px with the right value"
        )
    if config.known_length is not None:
        if not _inside_photo(np.asarray(config.known_length[:4], dtype=np.float64).reshape(2, 2), w, h).all():
            raise InputError(
                f"--known-length: a point lies outside the {w} x {h} photo {photo.path.name}; give two points on the wall"
            )
    if config.snap_tolerance_px is not None and config.snap_tolerance_px > 0.1 * diag:
        # (a tolerance of 1e9 px allocated a search of 4e9 samples a side)
        raise InputError(
            f"--snap-tolerance {config.snap_tolerance_px:g}: more than a tenth of the photo's diagonal "
            f"({diag:.0f} px); give a few pixels (the default is 1 % of the diagonal, {max(3.0, 0.01 * diag):.0f} px)"
        )
    for i, poly in enumerate(config.occluders):
        pts = np.asarray(poly, dtype=np.float64)
        if not _inside_photo(pts, w, h).any():
            raise InputError(f"occluder {i + 1}: it lies wholly outside the {w} x {h} photo {photo.path.name}")
    detection = None
    snap = None
    if config.corners_px is not None:
        corners = order_corners(np.array(config.corners_px).reshape(4, 2))
        if not _inside_photo(corners, w, h).all():
            raise InputError(
                f"--corners: a corner lies outside the {w} x {h} photo {photo.path.name}; click inside the image"
            )
        mode = "clicked"
        sigma = np.full(4, config.corner_sigma_px or CLICKED_SIGMA_PX)
        if config.snap_corners:
            tol = config.snap_tolerance_px or max(3.0, 0.01 * diag)
            snapped, snap_sigma, moved = _refine_clicked(photo.rgb, corners, tol)
            if moved:
                snap = tuple(float(v) for v in np.linalg.norm(snapped - corners, axis=1))
                corners, mode = snapped, "clicked, snapped to the outline"
                sigma = snap_sigma if config.corner_sigma_px is None else np.full(4, config.corner_sigma_px)
        bed = head = np.zeros((0, 4))
        if config.use_lines:
            from .outline import occluded_mask, segments_outside

            seg = joint_segments(photo.rgb, config.detect)
            seg = segments_outside(seg, occluded_mask((h, w), config.occluders))
            seg = segments_in_quad(seg, corners)
            ang = np.degrees(np.arctan2(seg[:, 3] - seg[:, 1], seg[:, 2] - seg[:, 0])) % 180.0
            from_h = np.minimum(ang, 180.0 - ang)
            bed = seg[from_h < config.detect.horizontal_max_deg]
            head = seg[np.abs(ang - 90.0) < config.detect.vertical_max_deg]
    else:
        try:
            detection = detect_wall(photo.rgb, config.detect, occluders=config.occluders)
        except FitFailed as exc:
            raise FitFailed(f"{photo.path}: {exc}") from None
        if detection.n_segments < MIN_WALL_JOINTS:
            raise FitFailed(
                f"{photo.path}: automatic mode: the outline found holds {detection.n_segments} joint segment(s), too "
                "few for a masonry wall (one unit of a wall that fills the photo, or a wall whose joints do not show); "
                f"click the wall's corners with {CORNERS_FLAG} {FILLS_PHOTO_ADVICE}"
            )
        corners, bed, head = detection.corners_px, detection.bed_segments, detection.head_segments
        if not config.use_lines:
            bed = head = np.zeros((0, 4))
        mode = "automatic"
        if config.corner_sigma_px is not None:
            sigma = np.full(4, config.corner_sigma_px)
        elif detection.corner_sigma_px is not None:
            sigma = np.asarray(detection.corner_sigma_px, dtype=np.float64)
        else:
            sigma = np.full(4, 1.0)
    from .fit import CalibrationInput, calibrate  # JAX loads here (or on preload's thread)

    lens = None
    lens_source = "fitted (no profile)" if config.fit_distortion else "none (held at 0)"
    if config.lens_profile and photo.lens and config.fit_distortion:
        from .lens import lensfun_profile

        lens = lensfun_profile(photo.lens, (w, h), focal or prior_px or focal_prior_px((w, h)))
        if lens is not None:
            lens_source = lens.source
    height_m, height_sigma = config.eye_height()
    known_length = tuple(config.known_length) if config.known_length is not None else None
    # the first fit's corners were found along straight sides, which a lens bows: looser (by 0.3 %
    # of the photo's diagonal) until the lens is known and they are found again through it
    first_sigma = np.sqrt(np.asarray(sigma, dtype=np.float64) ** 2 + (0.003 * diag) ** 2)
    if not (config.fit_distortion and (config.snap_corners or config.corners_px is None)):
        first_sigma = np.asarray(sigma, dtype=np.float64)
    plumb = scene_plumb(photo.rgb, corners, config.occluders) if config.fit_distortion else {}
    inp = CalibrationInput(
        image_size=(w, h),
        corners_px=corners,
        **plumb,
        corner_sigma_px=tuple(float(v) for v in first_sigma),
        bed_segments=bed,
        head_segments=head,
        line_sigma_px=config.line_sigma_px,
        max_effective_segments=config.max_effective_segments,
        camera_height_m=height_m,
        camera_height_sigma_m=height_sigma,
        focal_px=focal,
        focal_sigma_px=config.focal_sigma_px,
        known_width_m=config.known_width_m,
        known_height_m=config.known_height_m,
        known_sigma_m=config.known_sigma_m,
        known_length=known_length,
        known_length_sigma_m=config.known_sigma_m,
        fit_distortion=config.fit_distortion,
        focal_prior_px=prior_px,
        focal_prior_log_sigma=prior_log_sigma,
        **(
            {"k1_prior": lens.k1, "k1_sigma": lens.k1_sigma, "k2_prior": lens.k2, "k2_sigma": lens.k2_sigma}
            if lens is not None
            else {}
        ),
    )
    try:
        result = calibrate(inp)
    except FitFailed as exc:
        raise FitFailed(f"{photo.path}: {exc}") from None
    # the lens only where the photo tells it: a fit that narrows k1 to less than half its prior
    # sigma keeps it; otherwise the lens is held at the prior (0, or the profile's), as crooked
    # stone joints and cracks moved k1 by 0.1-0.3 (on the laboratory photos) without knowing it
    before, after = result.plumb_rms_px
    straightened = result.plumb_lines >= 2 and after <= LENS_STRAIGHTENS * before
    if inp.fit_distortion and (result.sigma("k1") > LENS_DETERMINED * inp.k1_sigma or not straightened):
        lines = (
            f"straightening {result.plumb_lines} long joints from {before:.2f} to {after:.2f} px RMS"
            if result.plumb_lines
            else "no long straight joint or line to straighten"  # its RMS is NaN: "from nan to nan" was printed
        )
        lens_source = (
            f"held at {'the profile' if lens is not None else '0'}: this photo's joints do not determine it "
            f"(k1 {result.value('k1'):+.3f} +- {result.sigma('k1'):.3f} when fitted, {lines})"
        )
        inp = replace(inp, fit_distortion=False)
        try:  # on the segments and plumb lines the first fit kept (choosing them again cost 2 solves)
            result = calibrate(
                replace(result.used, fit_distortion=False),
                start=np.r_[result.params[:9], inp.k1_prior, inp.k2_prior],
                reject_outliers=False,
            )
        except FitFailed as exc:
            raise FitFailed(f"{photo.path}: {exc}") from None
    # the outline again with the first fit's lens: each side snapped along a line straight in the
    # ideal image (a barrel lens bows a wall's base by tens of pixels, and a straight side through
    # the bow put the corners 10-40 px off, measured), then a soft side carried across its ramp
    if config.snap_corners or config.corners_px is None:
        straight = detection.straight if detection is not None and config.corner_sigma_px is None else None
        corners, sigma, again = _outline_through_lens(
            photo, result, corners, sigma, first_sigma, config, mode, straight=straight
        )
        if again:
            inp = replace(inp, corners_px=corners, corner_sigma_px=tuple(float(v) for v in sigma))
            if detection is not None:
                detection = replace(detection, corners_px=corners, corner_sigma_px=np.asarray(sigma))
            try:  # on the segments and plumb lines the first fit kept
                result = calibrate(
                    replace(result.used, corners_px=corners, corner_sigma_px=inp.corner_sigma_px),
                    start=result.params,
                    reject_outliers=False,
                )
            except FitFailed as exc:
                raise FitFailed(f"{photo.path}: {exc}") from None
    # a wall's end face (its thickness, seen at a yaw) taken into the outline: the sides moved in
    # to the front face's crease, found from the end face's own courses. Not from a fit whose
    # corners its joints contradict (which _check refuses): the crease is mapped through that
    # fit's camera, and the corners moved to its projections made a fit that agreed with itself
    # (Blender wall 12325: corners 24 px RMS from the joints' outline, 43 times their sigmas, then
    # 1.7 px once moved; W -62 %, H -67 %, passed as converged)
    max_rms = config.max_rms_px or default_max_rms_px(photo.size)
    if (
        detection is not None
        and detection.segments is not None
        and config.corners_px is None
        and not _corners_contradict(result, max_rms)
    ):
        found = front_face_ends(result, detection.segments, photo.rgb)
        if found is not None:
            corners = found[0]
            detection = replace(detection, corners_px=corners)
            try:
                result = calibrate(
                    replace(result.used, corners_px=corners, corner_sigma_px=tuple(float(v) for v in sigma)),
                    start=result.params,
                    reject_outliers=False,
                )
            except FitFailed as exc:
                raise FitFailed(f"{photo.path}: {exc}") from None
    courses = None
    if config.course_height_m is not None:
        from .courses import course_scale

        c = float(config.course_height_m)
        try:
            courses = course_scale(
                _course_ortho(photo, result), c, config.course_height_sigma_m or COURSE_HEIGHT_RELATIVE_SIGMA * c
            )
        except FitFailed as exc:
            raise FitFailed(
                f"{photo.path}: --course-height: {exc}; the module cannot give the scale of this wall: use "
                f"{SCALE_FLAGS.split(', --course-height M')[0]} or a measured --camera-height"
            ) from None
        inp = replace(inp, known_height_m=courses["height_m"], known_height_sigma_m=courses["height_sigma_m"])
        result = calibrate(inp, start=result.params)
    # clicked corners with joints that fit no wall plane, with the corners or without them (their own
    # RMS over the limit: a motion blur's streaks, grain or speckle taken for joints): the wall rests
    # on the clicks and the joints are left out (the lens with them), rather than refused with
    # advice to click the corners the user clicked (laboratory photo SC4 blurred 8 px along a
    # diagonal: 368 "joints" 4.3 px RMS from their lines, pulling the corners 90 px off). A corner
    # clicked on something else is still refused: there the joints fit their lines
    # (:func:`_corners_contradict`); max_rms as set for the end faces above
    left_out = 0
    used = result.used
    if (
        config.corners_px is not None
        and len(used.bed_segments) + len(used.head_segments)
        and result.rms_residual_px > max_rms
        and result.rms_line_px > max_rms
    ):
        left_out = len(used.bed_segments) + len(used.head_segments)
        try:
            result = calibrate(
                replace(
                    used,
                    bed_segments=np.zeros((0, 4)),
                    head_segments=np.zeros((0, 4)),
                    plumb_points=np.zeros((0, 2)),
                    plumb_cluster=np.zeros(0, dtype=np.int64),
                    plumb_family=np.zeros(0),
                    fit_distortion=False,
                ),
                start=np.r_[result.params[:9], used.k1_prior, used.k2_prior],
                reject_outliers=False,
            )
        except FitFailed as exc:
            raise FitFailed(f"{photo.path}: {exc}") from None
        lens_source = "held at 0: the joints were left out"
    if focal is None:
        prior = prior_px or focal_prior_px((w, h))
        rel = result.sigma("focal_px") / result.value("focal_px")
        centre = f"EXIF: {prior_note}" if prior_px else f"{FOCAL_PRIOR_35MM:g} mm equivalent"
        focal_source = (
            "vanishing points"
            if rel < 0.5 * inp.focal_prior_log_sigma
            else f"prior ({centre}, {prior:.0f} px, x/: {math.exp(inp.focal_prior_log_sigma):.2f})"
        )
    scale_source = config.scale_source
    if scale_source == ScaleSource.KNOWN_WIDTH:
        detail = f"W = {config.known_width_m:g} m"
    elif scale_source == ScaleSource.KNOWN_HEIGHT:
        detail = f"H = {config.known_height_m:g} m"
    elif scale_source == ScaleSource.KNOWN_LENGTH:
        detail = f"{known_length[4]:g} m between two points"
    elif scale_source == ScaleSource.COURSE_HEIGHT:
        detail = f"{courses['courses']:.2f} courses of {config.course_height_m:g} m"
    elif scale_source == ScaleSource.CAMERA_HEIGHT:
        detail = f"{height_m:g} +- {height_sigma:g} m"
    else:
        detail = f"prior: eye {height_m:g} +- {height_sigma:g} m above the wall's base, not measured"
    cal = PhotoCalibration(
        photo=photo,
        result=result,
        detection=detection,
        mode=mode,
        focal_source=focal_source,
        scale_source=scale_source,
        scale_detail=detail,
        lens_source=lens_source,
        corner_sigma_px=tuple(float(v) for v in sigma),
        corner_snap_px=snap,
        occluders=tuple(np.asarray(p, dtype=float) for p in config.occluders),
        courses=courses,
        joints_left_out=left_out,
    )
    if not config.force:
        _check(cal, config)
    return cal


#: an end face is looked for within this fraction of W of each end, and must hold this many of
#: its courses' segments (over at least END_FACE_SPAN of the height)
END_FACE_REACH = 0.3
END_FACE_SEGMENTS = 4
END_FACE_SPAN = 0.3


def front_face_ends(result, segments: np.ndarray, rgb: np.ndarray | None = None) -> tuple[np.ndarray, list[str]] | None:
    """The corners moved in to the front face's ends where the outline took a wall's end face (its
    thickness, seen at a yaw) into the wall: the end face's courses are segments pointing at the
    vanishing point of the wall's normal (not at the bed or head joints'), only at an end the camera
    stands beyond, and their inner ends lie on the crease between the two faces, on the wall's plane, so the fitted camera maps them to the
    crease's x exactly. ``segments`` ``(n, 4)``: the photo's segments inside the outline. Where an
    end face is too narrow for its courses to be found (a few pixels at a yaw of 10-20 degrees) and
    the photo ``rgb`` is given, the crease is found by its shading instead
    (:func:`crease_by_shading`), or, shaded as the front face, by the slope of its courses on the
    fitted plane (:func:`crease_by_slope`). Returns the four corners (photo pixels) and the ends moved
    (``"left"``, ``"right"``), or None.

    Measured on tall walls rendered by Blender as 0.4 m thick boxes: W came out 2.3-7.9 % wide
    with the end face in the outline (experiments/bench_tall_walls_blender.py)."""
    seg = np.asarray(segments, dtype=np.float64).reshape(-1, 4)
    w, ht = result.width_m, result.height_m
    x_new = [0.0, w]
    moved: list[str] = []
    courses = _ends_by_courses(result, seg) if len(seg) >= END_FACE_SEGMENTS else {}
    for side, sign in (("left", 1.0), ("right", -1.0)):
        crease = courses.get(side)
        if crease is None and rgb is not None:
            crease = crease_by_shading(rgb, result, sign)
        if crease is None and rgb is not None:
            crease = crease_by_slope(rgb, result, sign)
        if crease is None:
            continue
        x_new[0 if sign > 0 else 1] = crease if sign > 0 else w - crease
        moved.append(side)
    x0, x1 = x_new
    corners = result.photo_from_wall(np.array([[x0, 0.0], [x1, 0.0], [x1, ht], [x0, ht]]))
    if rgb is not None:
        from .lines import _intersect

        cx = float(result.params[4])
        for side, sign in (("left", 1.0), ("right", -1.0)):
            if side in moved or (sign > 0 and cx >= 0.0) or (sign < 0 and cx <= w):
                continue
            line = sliver_crease(rgb, corners, sign)
            if line is None:
                continue
            base, top = (corners[0], corners[1] - corners[0]), (corners[2], corners[3] - corners[2])
            lower, upper = (0, 3) if sign > 0 else (1, 2)
            corners[lower], corners[upper] = _intersect(base, line), _intersect(top, line)
            moved.append(side)
    if not moved:
        return None
    return _front_face_quad(rgb, result, corners, moved), moved


#: the front face's base and top are found again between the corners moved in to its creases,
#: within this many pixels of them
FRONT_FACE_REFIT_PX = 2.0
#: and the new corners kept only within this many pixels of the ones moved in on the first fit
FRONT_FACE_MAX_SHIFT_PX = 4.0


def _front_face_quad(rgb, result, corners: np.ndarray, moved: list[str]) -> np.ndarray:
    """The front face's corners (LL, LR, UR, UL, photo pixels) once its ``moved`` ends have been
    moved in to the creases, ``corners``, from the outline the first fit ``result`` was given
    (``result.used.corners_px``). That fit, made with an end face in the outline, runs the base on
    along the end face's foot (which slopes to another vanishing point) and maps the corners at
    the crease a pixel or two off along it. So the base and the top are found again over the
    front face alone (:func:`~.lines._refine_side` between the moved corners, the outermost strong
    edge within :data:`FRONT_FACE_REFIT_PX`); a side not moved stays the outline's (the fit's
    projection of it is a compromise with the end face), a moved one where the crease put it; the
    four corners are where these lines meet.
    The lines are straight in the ideal image of the fit's lens (the photo sampled where the lens
    puts them), as the outline's sides are (:func:`_outline_through_lens`). Where anything fails,
    or a corner would move more than :data:`FRONT_FACE_MAX_SHIFT_PX`, ``corners`` as they are.

    Measured on tall walls rendered by Blender at yaws of 9-35 degrees
    (experiments/bench_tall_walls_blender.py; 12029, 12049, 12103, 12108, 12159): the corners at
    the crease came 1.0-2.1 px out along the end face's foot, and W 2.0-6.5 % wide. (The moved
    side snapped as well to the strongest edge within 2.5 px of it, in the photo: 251 of 280 walls
    within 2 % instead of 254, four failing that pass without it and one passing that fails.)"""
    if rgb is None:
        return corners
    from .lines import _intersect, _refine_side

    outline = np.asarray(result.used.corners_px, dtype=np.float64)
    ideal, lens = _through_lens(result, corners)
    if lens is not None:
        outline = result.undistort(outline)
    else:
        ideal = corners  # no lens: the photo's own pixels, as the corners were found
    lines = {}
    for side, sign in (("left", 1.0), ("right", -1.0)):
        a, b = _side_ends(ideal if side in moved else outline, sign)
        lines[side] = (a, b - a)
    for name, i, j in (("base", 0, 1), ("top", 2, 3)):
        line = _refine_side(rgb, ideal[i], ideal[j], FRONT_FACE_REFIT_PX, to_photo=lens)
        lines[name] = line if line is not None else (ideal[i], ideal[j] - ideal[i])
    try:
        new = np.array(
            [
                _intersect(lines["base"], lines["left"]),
                _intersect(lines["base"], lines["right"]),
                _intersect(lines["top"], lines["right"]),
                _intersect(lines["top"], lines["left"]),
            ]
        )
    except np.linalg.LinAlgError:
        return corners
    if lens is not None:
        new = lens(new)
    if not np.all(np.isfinite(new)) or np.abs(new - corners).max() > FRONT_FACE_MAX_SHIFT_PX:
        return corners
    return new


#: an end face narrower than :func:`crease_by_shading` looks for (under 4.5 px: a small yaw, or a
#: far wall) is a band of its own colour along the outline's side; its crease is sought up to this
#: far in from the side
SLIVER_REACH_PX = 5.0
#: the band's colour differs from the front face's (and the background's) by this much, and by
#: SLIVER_CONTRAST times the face's texture
SLIVER_MIN_STEP = 0.04
SLIVER_CONTRAST = 3.0


def _side_ends(corners: np.ndarray, sign: float) -> tuple[np.ndarray, np.ndarray]:
    """The ends of the outline's left (``sign`` 1) or right (-1) side, in the order the sides run
    (LL, LR, UR, UL), so that the side's normal points out of the wall."""
    return (corners[3], corners[0]) if sign > 0 else (corners[1], corners[2])


def _sliver(rgb: np.ndarray, corners: np.ndarray, sign: float) -> dict | None:
    """The band between the left (``sign`` 1) or right (-1) side of ``corners`` and a second step
    of colour up to :data:`SLIVER_REACH_PX` in from it (:func:`~.lines.inner_step`), where it is
    at least a pixel and a half wide on ten or more of the profiles: the crease's line, the band's
    colour, and its differences from the face inside it, the face's texture and the background."""
    from .lines import _blurred_samples, across, inner_step, side_normal

    a, b = _side_ends(corners, sign)
    found = inner_step(rgb, a, b, SLIVER_REACH_PX)
    if found is None:
        return None
    outer, inner = found
    n = side_normal(a, b)
    p = a[None] + np.linspace(0.05, 0.95, 60)[:, None] * (b - a)[None]
    so, si = across(outer, p, n), across(inner, p, n)
    gap = so - si
    wide = gap >= 1.5
    if gap.min() < -0.5 or wide.sum() < 10:
        return None

    def colour(at: np.ndarray) -> np.ndarray:
        q = p[wide] + at[wide, None] * n
        return _blurred_samples(rgb, q[:, 1], q[:, 0])

    band, face, deeper, background = colour((so + si) / 2), colour(si - 2.0), colour(si - 4.0), colour(so + 2.5)
    return {
        "line": inner,
        "colour": np.median(band, axis=0),
        "to_face": float(np.median(np.linalg.norm(band - face, axis=1))),
        "texture": float(np.median(np.linalg.norm(face - deeper, axis=1))),
        "to_background": float(np.median(np.linalg.norm(band - background, axis=1))),
    }


def sliver_crease(rgb: np.ndarray, corners: np.ndarray, sign: float):
    """The crease (a line: point, direction) of an end face only a few pixels wide along the left
    (``sign`` 1) or right (-1) side of the outline ``corners`` (photo pixels, LL, LR, UR, UL), or
    None. The side snaps to the outermost strong edge (:func:`~.lines._refine_side`), which for
    such an end face is its far edge: W and the camera came out 2-7 % off on Blender walls seen
    at a small yaw (12089, 12096: their right corners 2.6-4.4 px out). A band of its own is an end
    face where its colour differs from the front face's by :data:`SLIVER_MIN_STEP` and
    :data:`SLIVER_CONTRAST` times the face's texture, and from the background's; and not where the
    other end shows a band of the same colour (a strip of mortar along both of a wall's ends, which
    the outline rightly takes in). Only for an end the camera stands beyond (the caller's)."""
    mine = _sliver(rgb, corners, sign)
    if mine is None:
        return None
    step = max(SLIVER_MIN_STEP, SLIVER_CONTRAST * mine["texture"])
    if not (mine["to_face"] > step and mine["to_background"] > SLIVER_MIN_STEP):
        return None
    other = _sliver(rgb, corners, -sign)
    if other is not None and float(np.linalg.norm(other["colour"] - mine["colour"])) < 0.5 * mine["to_face"]:
        return None
    return mine["line"]


def _ends_by_courses(result, seg: np.ndarray) -> dict[str, float]:
    """``front_face_ends``'s first cue: per end the camera stands beyond, the crease's distance in
    from that end (m) where the end face's courses give it."""
    from .camera import intrinsics, principal_point, wall_from_camera_rotation
    from .segments import dist_to_vp

    ideal = result.undistort(seg.reshape(-1, 2)).reshape(-1, 4)
    length = np.hypot(ideal[:, 2] - ideal[:, 0], ideal[:, 3] - ideal[:, 1])
    p = result.params
    rot = wall_from_camera_rotation(p[1], p[2], p[3]).T  # camera from wall
    k = intrinsics(p[0], principal_point(result.image_size))
    vp_normal = k @ rot[:, 1]
    h = result.image_from_wall
    tol = 1.5
    course = (
        (length >= 12.0)
        & (dist_to_vp(ideal, vp_normal) < tol)
        & (dist_to_vp(ideal, h[:, 0]) > 3 * tol)
        & (dist_to_vp(ideal, h[:, 1]) > tol)
    )
    if course.sum() < END_FACE_SEGMENTS:
        return {}
    inv = np.linalg.inv(h)
    ends = ideal[course].reshape(-1, 2)
    q = np.c_[ends, np.ones(len(ends))] @ inv.T
    xz = (q[:, :2] / q[:, 2:3]).reshape(-1, 2, 2)  # (segments, 2 ends, x z)
    w, ht = result.width_m, result.height_m
    found = {}
    cx = float(p[4])  # the camera's x along the wall: an end face shows only to a camera beyond that end
    for side, sign in (("left", 1.0), ("right", -1.0)):
        if (sign > 0 and cx >= 0.0) or (sign < 0 and cx <= w):
            continue
        near = xz
        x = near[..., 0] if sign > 0 else w - near[..., 0]  # distance in from this end
        mine = np.all((x > -0.02 * w) & (x < END_FACE_REACH * w), axis=1)
        if mine.sum() < END_FACE_SEGMENTS:
            continue
        inner = x[mine].max(axis=1)  # each course's end at the crease
        z = near[mine][..., 1]
        if np.ptp(z) < END_FACE_SPAN * ht:
            continue
        crease = float(np.median(inner))
        spread = float(np.median(np.abs(inner - crease)))
        if crease < 0.015 * w or spread > 0.02 * w:
            continue
        found[side] = crease
    return found


#: the thickest end face looked for by its shading (m): a single-wythe wall's is under a metre
END_FACE_MAX_THICKNESS_M = 1.0
#: the crease must stand out of the band's texture by this factor (its step of colour against the
#: band's median step), and hold in this many of the eight height slabs
CREASE_CONTRAST = 3.0
CREASE_SLABS = 6
#: and step by at least this much (the colour's step, RGB of 1): faces lit from different
#: directions stepped by 0.063-0.27 on the Blender walls; a brick wall's half-bats in every other
#: course, seen through a barrel lens, by 0.018 (a false crease, W 4.5 % short)
CREASE_MIN_STEP = 0.04
#: a weaker step, down to CREASE_WEAK_STEP, is a crease where it stands out of the texture by
#: CREASE_WEAK_CONTRAST: faces whose light differs little stepped by 0.027-0.038 at 6.4-6.6 times
#: the face's texture (Blender walls 12143, 12163, 12170: W +2.8 to +8.8 % with the end face in);
#: false creases of the project's own flat walls stepped by 0.023-0.029 at 3.3-4.1 times (a wall's
#: bond seen past a lens's edge, the coverage run's seeds 11714 and 708)
CREASE_WEAK_STEP = 0.02
CREASE_WEAK_CONTRAST = 5.0
#: the slabs agree on the crease within 1.5 px, or this fraction of its distance in from the side
#: (a fit made with the end face inside the outline maps the crease a little aslant: 33-36 px in
#: from the side over the height of 12163's 39-px end face)
CREASE_AGREE_FRACTION = 0.1


def _end_face_band(result, sign: float, min_px: float) -> tuple[float, float, float] | None:
    """The band an end face can take along the left (``sign`` 1) or right (-1) end of the fitted
    outline: the end's x (m), the band's width (m) and the photo's pixels per metre across it; None
    where the camera does not stand beyond that end (no end face shows). An end face takes at most
    ``b t / (|y| + t)`` of the wall's plane (``b`` how far beyond the end the camera stands, ``y``
    its distance from the wall's plane, ``t`` up to :data:`END_FACE_MAX_THICKNESS_M`), and no more
    than :data:`END_FACE_REACH` of W. None too where that band is under ``min_px`` pixels wide."""
    p = result.params
    w, ht = float(result.width_m), float(result.height_m)
    cx, cy = float(p[4]), float(p[5])
    beyond = -cx if sign > 0 else cx - w
    if beyond <= 0.0:
        return None
    t = END_FACE_MAX_THICKNESS_M
    reach = min(END_FACE_REACH * w, beyond * t / (abs(cy) + t))
    x_end = 0.0 if sign > 0 else w
    a, b = result.photo_from_wall(np.array([[x_end, 0.5 * ht], [x_end + sign * reach, 0.5 * ht]]))
    ppm = float(np.linalg.norm(b - a)) / reach  # photo pixels per metre across the side
    if not np.isfinite(ppm) or reach * ppm < min_px:
        return None
    return x_end, reach, ppm


def crease_by_shading(rgb: np.ndarray, result, sign: float) -> float | None:
    """The crease between a wall's front face and its end face, found by its shading: its distance
    (m, on the wall's plane) in from the left (``sign`` 1) or right (-1) end of the fitted outline,
    or None. (A crease let slant across the outline's side was tried: it took a texture edge for
    a crease on one wall in twenty.)

    An end face shows only to a camera beyond that end; on the wall's plane it takes at most
    ``b t / (|y| + t)`` of the outline (``b`` how far beyond the end the camera stands, ``y`` its
    distance from the wall's plane, ``t`` up to :data:`END_FACE_MAX_THICKNESS_M`). Over that band
    the photo is sampled along the wall's x in eight slabs of its height (each the mean of 32
    rows); in each slab the crease is the largest step of colour (2 px either side) in the band, at
    least 4.5 px in from the outline's side (clear of its own edge and blur). Faces lit from
    different directions step where they meet, at the same x all the way up; the front face's
    texture (head joints, stones' ends) steps at other x in each slab. The crease is taken where at
    least :data:`CREASE_SLABS` slabs agree within 1.5 px (or :data:`CREASE_AGREE_FRACTION` of its
    distance from the side), its step is :data:`CREASE_CONTRAST` times the median step of the face
    beside it (sampled to twice the band, or 16 px, in from the side; more than 4 px from the
    crease) and at least :data:`CREASE_MIN_STEP` (or :data:`CREASE_WEAK_CONTRAST` times and at
    least :data:`CREASE_WEAK_STEP`), and the band's level
    differs from the face's beyond by three quarters of that step (a perpend of a regular bond is
    a line at the same x in every other course: it steps in and out), and as much from the
    background 3 px outside the side (the band is a face of its own); and where what lies 3 px
    outside the side differs as much from what lies beyond the widest end face, the side is on a
    crease already (the end face outside it), and None."""
    from .lines import _blurred_samples

    w, ht = float(result.width_m), float(result.height_m)
    band = _end_face_band(result, sign, 8.0)
    if band is None:
        return None
    x_end, reach, ppm = band
    # sampled twice as far in, or 16 px: the front face's texture beyond the band is the contrast
    # the crease must stand out of
    span = min(END_FACE_REACH * w, max(2.0 * reach, reach + 16.0 / ppm))
    n = int(2.0 * span * ppm) + 1  # two samples a pixel
    d = np.linspace(0.0, span, n)
    z = np.linspace(0.1, 0.9, 256) * ht
    xx, zz = np.meshgrid(x_end + sign * d, z)
    pts = result.photo_from_wall(np.c_[xx.ravel(), zz.ravel()])
    vals = _blurred_samples(rgb, pts[:, 1], pts[:, 0]).reshape(8, 32, n, 3).mean(axis=1)
    k = 4  # 2 px
    c = np.concatenate([np.zeros((8, 1, 3)), np.cumsum(vals, axis=1)], axis=1)
    i = np.arange(k, n - k + 1)
    left = (c[:, i] - c[:, i - k]) / k
    right = (c[:, i + k] - c[:, i]) / k
    step = np.linalg.norm(left - right, axis=-1)  # (8, len(i)): the step at d[i]
    di = d[i]
    inner = di >= 4.5 / ppm  # the 2-px windows clear of the side's own edge and its blur
    valid = inner & (di <= reach)
    if valid.sum() < 3:
        return None
    at = np.argmax(np.where(valid, step, -1.0), axis=1)
    ds = di[at]
    crease = float(np.median(ds))
    agree = np.abs(ds - crease) <= max(1.5 / ppm, CREASE_AGREE_FRACTION * crease)
    if agree.sum() < CREASE_SLABS:
        return None
    texture = inner & (np.abs(di - crease) > 4.0 / ppm)
    if texture.sum() < 3:
        return None
    strength = float(np.median(step[np.arange(8), at][agree]))
    face = float(np.median(step[:, texture]))
    if not (
        strength > max(CREASE_MIN_STEP, CREASE_CONTRAST * face)
        or strength > max(CREASE_WEAK_STEP, CREASE_WEAK_CONTRAST * face)
    ):
        return None
    # a step between two faces, not a line on one (a perpend of a regular bond, at the same x in
    # every course of its kind, steps in and out again): the band's level differs from the face's
    # (at half the step, the perpends 0.30 m in from a brick wall's end passed: W 11 % short)
    band = (d >= 1.5 / ppm) & (d <= crease - 1.0 / ppm)
    beside = (d >= crease + 1.0 / ppm) & (d <= crease + max(crease, 4.0 / ppm))
    if not band.any() or not beside.any():
        return None
    level = np.linalg.norm(vals[:, band].mean(axis=1) - vals[:, beside].mean(axis=1), axis=-1)
    if not float(np.median(level[agree])) >= 0.75 * strength:
        return None

    # and a face of its own, not the background: beyond the side (3 px out) the band's level
    # differs as much (a side that a lens left a few pixels off the wall's edge has the background
    # in its band, which steps to the face as a crease would: a planar wall through k1 -0.1)
    def outside(out_m: float) -> np.ndarray:  # (8, 3): each slab's colour ``out_m`` beyond the side
        po = result.photo_from_wall(np.c_[np.full(256, x_end - sign * out_m), z])
        return _blurred_samples(rgb, po[:, 1], po[:, 0]).reshape(8, 32, 3).mean(axis=1)

    near = outside(3.0 / ppm)
    apart = np.linalg.norm(vals[:, band].mean(axis=1) - near, axis=-1)
    if not float(np.median(apart[agree])) >= 0.75 * strength:
        return None
    # and the outline's side is not a crease already: where the outline left the end face out,
    # the end face lies beyond its side, unlike the background beyond the widest end face (on a
    # Blender wall the outline stood on the crease, and the search in from it took a bond's
    # perpends 0.35 m in for another crease: W 11 % short)
    far = outside(reach + 3.0 / ppm)
    if float(np.median(np.linalg.norm(near - far, axis=-1)[agree])) >= 0.75 * strength:
        return None
    return crease


#: :func:`crease_by_slope`: a height slab is read where an end face's courses drop or rise by at
#: least this many pixels a pixel across (their slope on the wall's plane, ``(z_eye - z) / (x_eye -
#: x_end)``: none at eye height), and the crease is taken where at least this many slabs agree
CREASE_SLOPE_MIN = 0.5
CREASE_SLOPE_SLABS = 4
#: and where, over the slabs that agree, the sloped courses explain the band (the pairs' relative
#: gain, -1 to 1) by at least this much, and the level ones the front face beyond it as much
CREASE_SLOPE_GAIN = 0.3
#: each slab is read along at most this many rows (a row a pixel where it is lower): the pairs'
#: gains are means over the rows, and every pixel's row of a 3000 x 2000 photo's wall cost 30 ms a
#: call, 5 % of its fit (bench_calibrate.py)
CREASE_SLOPE_ROWS = 64


def crease_by_slope(rgb: np.ndarray, result, sign: float) -> float | None:
    """The crease between a wall's front face and its end face, found by the slope of the end
    face's courses: its distance (m, on the wall's plane) in from the left (``sign`` 1) or right
    (-1) end of the fitted outline, or None.

    A course is level in the world on both faces. On the front face (the fitted plane) it is level
    on the fitted wall; the end face's courses run to the vanishing point of the wall's normal, and
    on the fitted plane (which the end face is not on) a course at height ``z`` drops or rises
    outward at ``(z_eye - z) / (x_eye - x_end)`` (``x_eye, z_eye``: the fitted camera's place): steep
    on a tall wall far above the eye, whatever the end face's shading. So across the band an end
    face can take (:func:`crease_by_shading`'s, for a thickness up to
    :data:`END_FACE_MAX_THICKNESS_M`), each pair of columns a pixel apart is compared twice in
    eight slabs of the height: the two columns level (``e_level``, the mean squared difference of
    their grey) and the outer one shifted along that slope (``e_slope``); the pair's gain
    ``(e_level - e_slope) / (e_level + e_slope)`` is near 1 on the end face, near -1 on the front
    face's joints. Each slab's crease is the change point (the sloped pairs outside, the level
    inside), at least 1.5 px in (clear of the side's own edge); it is taken where
    :data:`CREASE_SLOPE_SLABS` slabs steep enough to tell (:data:`CREASE_SLOPE_MIN`) agree within
    a pixel (or :data:`CREASE_AGREE_FRACTION` of the crease's distance) and both sides of it hold
    (:data:`CREASE_SLOPE_GAIN`).

    Measured on a wall rendered by Blender at a yaw of 18.5 degrees, seed 12291 of
    experiments/bench_tall_walls_blender.py: an end face 8.7 px wide, lit like the front face
    (its step of shading 0.031, which :func:`crease_by_shading` does not take), left in the
    outline with W 3.1 % wide; the slabs above 5 m gave gains of 0.54-0.74 outside and under
    -0.9 inside, and the crease 0.3 px inside Blender's."""
    from .lines import _blurred_samples

    w, ht = float(result.width_m), float(result.height_m)
    band = _end_face_band(result, sign, 3.0)
    if band is None:
        return None
    x_end, reach, ppm = band
    cx, cz = float(result.params[4]), float(result.params[6])  # the camera's x and height on the wall's axes
    span = min(END_FACE_REACH * w, max(2.0 * reach, reach + 8.0 / ppm))
    n = int(2.0 * span * ppm) + 1  # two samples a pixel
    d = np.linspace(0.0, span, n)
    x = x_end + sign * d
    k = 2  # the pairs' columns a pixel apart
    dx = x[k:] - x[:-k]
    pair = d[:-k]
    usable = pair >= 1.5 / ppm
    if usable.sum() < 4:
        return None
    # the slabs steep enough to tell, each sampled level and along its slope (one call each)
    rows = min(max(int(0.1125 * ht * ppm), 8), CREASE_SLOPE_ROWS)
    slabs = []
    for s in range(8):
        z = np.linspace((0.05 + 0.1125 * s) * ht, (0.05 + 0.1125 * (s + 1)) * ht, rows)
        slope = (cz - float(z.mean())) / (cx - x_end)  # dz / dx of an end face's course on the plane
        if abs(slope) >= CREASE_SLOPE_MIN:
            slabs.append((z, slope))
    if len(slabs) < CREASE_SLOPE_SLABS:
        return None
    level, sloped = [], []
    for z, slope in slabs:
        xx, zz = np.meshgrid(x, z)
        level.append(np.c_[xx.ravel(), zz.ravel()])
        sloped.append(np.c_[xx[:, k:].ravel(), (zz[:, k:] + slope * dx[None, :]).ravel()])

    def grey(xz: list[np.ndarray]) -> list[np.ndarray]:
        pts = result.photo_from_wall(np.concatenate(xz))
        g = _blurred_samples(rgb, pts[:, 1], pts[:, 0], gray=True)
        return np.split(g, np.cumsum([len(q) for q in xz])[:-1])

    found = []  # (crease, gain outside, gain inside) per slab
    for (z, _), g, shifted in zip(slabs, grey(level), grey(sloped)):
        g = g.reshape(len(z), n)
        shifted = shifted.reshape(len(z), n - k)
        e_level = np.mean((g[:, :-k] - g[:, k:]) ** 2, axis=0)
        e_slope = np.mean((g[:, :-k] - shifted) ** 2, axis=0)
        gain = (e_level - e_slope) / np.maximum(e_level + e_slope, 1e-12)
        r = np.where(usable, gain, 0.0)
        cs = np.cumsum(r)
        i = int(np.argmax(2.0 * cs - cs[-1]))  # the last pair of the sloped band
        crease = float(pair[i]) + 0.75 / ppm  # the pair's middle, half a sample on
        outside = usable & (pair <= pair[i])
        inside = usable & (pair > pair[i]) & (pair <= pair[i] + max(crease, 4.0 / ppm))
        if not outside.any() or not inside.any() or crease > reach:
            continue
        found.append((crease, float(gain[outside].mean()), float(gain[inside].mean())))
    if len(found) < CREASE_SLOPE_SLABS:
        return None
    c = np.array(found)
    crease = float(np.median(c[:, 0]))
    agree = np.abs(c[:, 0] - crease) <= max(1.0 / ppm, CREASE_AGREE_FRACTION * crease)
    if agree.sum() < CREASE_SLOPE_SLABS or crease < 2.0 / ppm:
        return None
    if not (np.median(c[agree, 1]) >= CREASE_SLOPE_GAIN and np.median(c[agree, 2]) <= -CREASE_SLOPE_GAIN):
        return None
    return crease


def scene_plumb(rgb: np.ndarray, corners: np.ndarray, occluders=()) -> dict:
    """The photo's long straight lines off the wall (:func:`~calib_masonry.calibrate.lines.straight_lines`:
    a beam's edges, a frame, a building's edge; those mostly within the outline are joints, which
    the fit's own plumb lines already hold, or the wall's own sides) as plumb lines of any
    direction (family 2) for
    :class:`~calib_masonry.calibrate.fit.CalibrationInput`; none where they cross an occluder."""
    from .lines import _in_convex, straight_lines
    from .outline import occluded_mask

    occ = occluded_mask(rgb.shape[:2], occluders)
    c = corners.mean(axis=0)
    # off the wall: not mostly within its outline grown by 2.5 % (the joints, and the wall's own
    # sides, whose edge jumps between a course's half units and its mortar: biased as plumb lines)
    outer = c + (corners - c) * 1.05
    pts, cl, fam = [], [], []
    for line in straight_lines(rgb):
        if _in_convex(line, outer).mean() > 0.5:
            continue
        if occ is not None:
            r = np.clip(np.round(line[:, 1]).astype(int), 0, occ.shape[0] - 1)
            q = np.clip(np.round(line[:, 0]).astype(int), 0, occ.shape[1] - 1)
            if occ[r, q].any():
                continue
        pts.append(line)
        cl.append(np.full(len(line), len(cl), dtype=np.int64))
        fam.append(np.full(len(line), 2.0))
    if not pts:
        return {}
    return {
        "plumb_points": np.concatenate(pts),
        "plumb_cluster": np.concatenate(cl),
        "plumb_family": np.concatenate(fam),
    }


def _through_lens(result, corners: np.ndarray):
    """``corners`` (photo pixels) in the ideal image of the fit ``result``'s lens, and the lens
    (ideal -> photo) to sample the photo through, None where it moves no corner by a twentieth of
    a pixel (the photo's pixels are the ideal image's then)."""
    ideal = result.undistort(corners)
    return ideal, (result.distort if np.max(np.linalg.norm(ideal - corners, axis=1)) > 0.05 else None)


def _outline_through_lens(photo, result, corners, sigma, first_sigma, config, mode, *, straight=None):
    """Corners snapped again (and soft sides carried, :func:`carry_soft_sides`) along sides
    straight in the ideal image of a first fit's lens; returns the corners, their sigmas and
    whether they changed. A corner that moves more than twice its first sigma from where the
    first fit put it has snapped onto another edge (seen under a strong lens: a brick's edge
    34 px off): the first fit's corner is kept there, with that sigma.

    Where the fit found no lens, ``straight`` (the detection's corners and sigmas of straight
    sides, :attr:`~calib_masonry.calibrate.lines.Detection.straight`) replaces corners put on a
    bowed side's tangents: with no lens to bow it, the side's bow was its edge's own (a cast
    shadow's edge along part of a Blender wall's base: the tangent put the far corner 4 px low,
    W 2.4 % short, where the straight side is within half a pixel)."""
    w, h = photo.size
    s = min(1.0, config.detect.work_long_side_px / max(w, h))
    ideal, lens = _through_lens(result, corners)
    if lens is not None:
        snapped, snap_sigma = refine_quad(
            photo.rgb, ideal, (6.0 / s, 2.5 / s), with_sigma=True, to_photo=lens, curved=True
        )
    elif straight is not None:
        snapped, snap_sigma = np.asarray(straight[0], dtype=np.float64), np.asarray(straight[1], dtype=np.float64)
    else:
        snapped, snap_sigma = ideal, np.asarray(sigma, dtype=np.float64)
    if mode == "automatic":
        snapped, snap_sigma = _base_through_fit(photo.rgb, result, snapped, snap_sigma, s, lens, first_sigma)
    else:  # a click's own uncertainty stays the floor
        snap_sigma = np.maximum(snap_sigma, sigma)
    carried, shift = carry_soft_sides(photo.rgb, snapped, to_photo=lens)
    new = result.distort(carried) if lens is not None else carried
    if np.array_equal(new, corners):
        return corners, sigma, False
    new_sigma = np.sqrt(np.asarray(snap_sigma) ** 2 + shift**2)
    # straight sides are the detection's own corners, not a re-snap that may have jumped: they
    # are checked against themselves (the carry's shift allowed), not against the first fit's
    predicted = snapped if lens is None and straight is not None else result.corners_px()
    astray = np.linalg.norm(new - predicted, axis=1) > 2.0 * np.asarray(first_sigma) + shift
    new = np.where(astray[:, None], predicted, new)
    new_sigma = np.where(astray, first_sigma, new_sigma)
    if config.corner_sigma_px is not None:
        new_sigma = np.full(4, config.corner_sigma_px)
    return new, new_sigma, True


def _base_through_fit(rgb, result, quad, sigma, scale, lens, first_sigma):
    """An automatic outline's base (``quad`` in the ideal image, corner sigmas ``sigma``) sought
    again through the first fit's bed vanishing point where it turns from it by more than
    :data:`~.lines.SIDE_TURN_RAD` while the top runs to it (:func:`~.lines.base_in_pencil`): the
    fitted camera's point rests on the top, the ends and the focal length, which no shadow at the
    foot moves. The base found is kept where its corners lie within twice the first fit's corner
    sigmas ``first_sigma`` of where that fit puts them (not a bed joint further in). ``scale``: the
    detection's working scale (its half-widths are in its pixels)."""
    from .camera import project
    from .lines import (
        SIDE_MOVE_FRACTION,
        SIDE_TURN_RAD,
        _corner_sigma,
        _side_sigma,
        base_in_pencil,
        side_turn,
    )

    quad = np.asarray(quad, dtype=np.float64)
    vp = result.image_from_wall[:, 0]
    if side_turn(quad[0], quad[1], vp) <= SIDE_TURN_RAD or side_turn(quad[3], quad[2], vp) > SIDE_TURN_RAD / 2:
        return quad, sigma
    ends = 0.5 * float(np.linalg.norm(quad[3] - quad[0]) + np.linalg.norm(quad[2] - quad[1]))
    found = base_in_pencil(rgb, quad, vp, reach_in=SIDE_MOVE_FRACTION * ends, reach_out=2.5 / scale, to_photo=lens)
    if found is None:
        return quad, sigma
    new, edge, line = found
    predicted = project(result.image_from_wall, np.array([[0.0, 0.0], [result.width_m, 0.0]]))
    allowed = 2.0 * np.broadcast_to(np.asarray(first_sigma, dtype=np.float64), (4,))[:2]
    if np.any(np.linalg.norm(new[:2] - predicted, axis=1) > allowed):
        return quad, sigma
    base = _side_sigma(edge, line, float(np.linalg.norm(new[1] - new[0])))
    sigma = np.array(sigma, dtype=np.float64)
    sigma[:2] = [_corner_sigma(float(v), base) for v in sigma[:2]]
    return new, sigma


#: the fewest joint segments an automatic outline holds for calibrate_photo to take it for a
#: masonry wall (detect_wall itself outlines a plain one): a close-up that a brick wall fills gave
#: its middle brick as the wall (4 segments, its own joints' ends); the laboratory photos hold
#: 60-72, 27-104 under the 41 lighting and camera changes of experiments/photo_conditions.py, the
#: Blender renders 203 or more
MIN_WALL_JOINTS = 8


def default_max_rms_px(image_size: tuple[int, int]) -> float:
    """The largest RMS residual a fit keeps without --force: 3 px per 1500 px of the long side, at
    least 3 px (a clicked corner off by 3.2 px on a 6000 px photo is a good click)."""
    return max(3.0, 3.0 * max(image_size) / 1500.0)


def _corners_contradict(result: CalibrationResult, max_rms: float) -> bool:
    """Whether the fit's corners lie further from the outline its joints fit than ``max_rms`` px
    (RMS) and :data:`MAX_CORNER_SIGMAS` times their sigmas: a corner on something else."""
    return result.rms_corner_px > max_rms and result.rms_corner_sigma > MAX_CORNER_SIGMAS


def _check(cal: PhotoCalibration, config: CalibrateConfig) -> None:
    """Refuse what should not pass without --force, in one line that says what to do."""
    result, photo = cal.result, cal.photo
    max_rms = config.max_rms_px or default_max_rms_px(photo.size)
    if not result.fit.ok:
        raise FitFailed(f"{photo.path}: the calibration {result.status.message}; or use --force to keep it anyway")
    if result.rms_residual_px > max_rms:
        # corners the user clicked: telling them to click the corners was no help (a blurred
        # laboratory photo's clicks were refused so, its streaks taken for joints)
        what = (
            "check each click on the photo (on the wall's corner, not a shadow, a stone or the rig)"
            if cal.mode.startswith("clicked")
            else "click the corners with --corners"
        )
        raise FitFailed(
            f"{photo.path}: RMS residual {result.rms_residual_px:.2f} px exceeds {max_rms:g} px "
            f"(corners or joints do not fit one wall plane); {what}, or use --force to keep it anyway"
        )
    if _corners_contradict(result, max_rms):
        # the joints' lines contradict the corners: a corner found (or clicked) on something else
        raise FitFailed(
            f"{photo.path}: the corners are {result.rms_corner_px:.1f} px (RMS) from the outline the mortar "
            f"joints fit (more than {max_rms:g} px and {result.rms_corner_sigma:.1f} times their sigmas), so one "
            f"is not on the wall's corner; click the wall's corners with {CORNERS_FLAG}, or use --force to keep it anyway"
        )
    if not (0.05 < result.width_m < 500 and 0.05 < result.height_m < 500):
        raise FitFailed(
            f"{photo.path}: fitted wall {result.width_m:.2f} x {result.height_m:.2f} m is implausible; "
            f"pin the scale with {SCALE_FLAGS}, or check the corners"
        )
    rel = cal.relative_sigma()
    if rel > config.max_relative_sigma:
        raise FitFailed(
            f"{photo.path}: W = {result.width_m:.3g} m and H = {result.height_m:.3g} m are uncertain by "
            f"+-{rel:.0%} (1 sigma; more than {config.max_relative_sigma:.0%}), the scale resting on the "
            f"{cal.scale_source} ({cal.scale_detail}); pin it with {SCALE_FLAGS}, or use --force to keep it anyway"
        )


def rectify(
    calibration: PhotoCalibration,
    *,
    px_per_m: float | None = None,
    width_m: float | None = None,
    height_m: float | None = None,
    anchored: bool = False,
) -> np.ndarray:
    """The metric orthophoto ``(rows, cols, 3)`` of a calibrated photo's wall, at ``px_per_m``
    (default: the photo's own finest resolution on the wall). ``width_m`` / ``height_m`` stretch the
    fitted wall onto a measured size (the photo's outline then maps onto the W x H given);
    ``anchored``: the height is not stretched but kept at the photo's own scale from the wall's
    base, the orthophoto ``height_m`` high (above the fitted top it shows what the photo shows
    there; below it, the outline's top is cut off), see :func:`wall_stretch`."""
    res = calibration.result
    width = res.width_m if width_m is None else float(width_m)
    height = res.height_m if height_m is None else float(height_m)
    for name, v in (("width_m", width), ("height_m", height)):
        if not (math.isfinite(v) and v > 0):
            raise InputError(f"rectify: {name} = {v} must be a length > 0 (metres)")
    ppm = native_px_per_m(res) if px_per_m is None else float(px_per_m)
    if not (math.isfinite(ppm) and ppm > 0):
        raise InputError(f"rectify: px_per_m = {ppm} must be > 0")
    stretch = wall_stretch(res, width, height, anchored)
    return rectify_image(calibration.photo.rgb, stretch @ res.wall_from_image, width, height, ppm, lens=lens_of(res))


def wall_stretch(res, width_m: float, height_m: float, anchored: bool = False) -> np.ndarray:
    """3x3 map of the fitted wall's metres onto an orthophoto ``width_m`` x ``height_m``: each axis
    stretched by the given size over the fitted one, or with ``anchored`` the height at the photo's
    own scale (the base where the outline's base is). A wall whose typed W scales the photo and
    whose typed H lies beyond the fitted H's noise (an outline that left out a band of mortar at
    the top, or took in one below the eaves) is anchored by :func:`calib_masonry.pipeline.photo_wall`:
    stretched, every course would be moved by its share of the difference."""
    return np.diag([width_m / res.width_m, 1.0 if anchored else height_m / res.height_m, 1.0])


def ortho_from_photo(
    calibration: PhotoCalibration,
    points: np.ndarray,
    shape: tuple[int, int],
    *,
    width_m=None,
    height_m=None,
    anchored: bool = False,
) -> np.ndarray:
    """Photo pixels ``(n, 2)`` -> the pixels of the orthophoto :func:`rectify` makes of shape
    ``shape`` (rows, cols) (lens undone, stretched onto ``width_m`` x ``height_m`` or ``anchored``
    as there)."""
    from .camera import project

    res = calibration.result
    width = res.width_m if width_m is None else float(width_m)
    height = res.height_m if height_m is None else float(height_m)
    stretch = wall_stretch(res, width, height, anchored)
    ideal = res.undistort(np.asarray(points, dtype=np.float64).reshape(-1, 2))
    return project(rect_from_wall(width, height, shape) @ stretch @ res.wall_from_image, ideal)


def valid_ortho(
    calibration: PhotoCalibration, px_per_m: float, *, width_m=None, height_m=None, anchored: bool = False
) -> np.ndarray:
    """``(rows, cols)`` True where :func:`rectify`'s orthophoto (same arguments) shows the wall:
    inside the photo and outside every occluder the calibration was given (and, ``anchored``,
    not above the fitted outline's top: what the photo shows there was not taken for wall)."""
    from .outline import polygon_mask

    res = calibration.result
    width = res.width_m if width_m is None else float(width_m)
    height = res.height_m if height_m is None else float(height_m)
    stretch = wall_stretch(res, width, height, anchored)
    rows, cols = calibration.photo.rgb.shape[:2]
    wall_from_image = stretch @ res.wall_from_image
    lens = lens_of(res)
    shape = (max(2, round(height * px_per_m)), max(2, round(width * px_per_m)))
    if _ortho_inside_photo(wall_from_image, width, height, shape, lens, (cols, rows)):
        valid = np.ones(shape, dtype=bool)
    else:
        ones = np.ones((rows, cols), dtype=np.float32)
        valid = rectify_image(ones, wall_from_image, width, height, px_per_m, nearest=True, lens=lens) > 0.5
    for poly in calibration.occluders:
        valid &= ~polygon_mask(
            valid.shape,
            ortho_from_photo(calibration, poly, valid.shape, width_m=width, height_m=height, anchored=anchored),
        )
    if anchored and height > res.height_m:
        # the rows whose centres lie above the fitted top (z = res.height_m; row r's centre is at
        # z = (rows - 0.5 - r) height / rows)
        rows_out = valid.shape[0]
        above = int(np.clip(round(rows_out * (1.0 - res.height_m / height)), 0, rows_out))
        valid[:above] = False
    return valid


def _ortho_inside_photo(wall_from_image, width_m, height_m, shape, lens, size) -> bool:
    """Whether every pixel of :func:`rectify_image`'s orthophoto ``shape`` samples the photo of
    ``size`` (cols, rows) at least a pixel inside its edges, found from its outermost pixels
    alone: the homography maps the orthophoto's rectangle onto a convex quadrilateral, a lens that
    does not fold the image (its radial map increasing out to the quadrilateral's farthest corner)
    maps that onto the region its boundary encloses, and a region whose boundary lies inside the
    photo's (convex) rectangle lies inside it. (:func:`valid_ortho` rectified a photo of ones for
    this: 0.2 s of a rectify's segmentation, measured; the answer is the same where this holds.)"""
    rows, cols = shape
    image_from_ortho = np.linalg.inv(rect_from_wall(width_m, height_m, shape) @ wall_from_image)
    xs, ys = np.arange(cols, dtype=np.float64), np.arange(rows, dtype=np.float64)
    edge = np.concatenate(
        [
            np.stack([xs, np.zeros(cols)], -1),
            np.stack([xs, np.full(cols, rows - 1.0)], -1),
            np.stack([np.zeros(rows), ys], -1),
            np.stack([np.full(rows, cols - 1.0), ys], -1),
        ]
    )
    q = image_from_ortho @ np.c_[edge, np.ones(len(edge))].T
    if np.any(q[2] <= 0):
        return False
    xy = np.stack([q[0] / q[2], q[1] / q[2]], axis=-1)
    if lens is not None:
        from .camera import distort

        focal, pp, k1, k2 = lens
        r_max = float(np.max(np.linalg.norm((xy - np.asarray(pp)) / focal, axis=1)))
        r2 = np.linspace(0.0, r_max, 257) ** 2
        if np.any(1.0 + 3.0 * k1 * r2 + 5.0 * k2 * r2 * r2 <= 0.0):  # the lens folds the image there
            return False
        xy = distort(xy, focal, pp, k1, k2)
    w, h = size
    return bool(np.all((xy[:, 0] >= 1.0) & (xy[:, 0] <= w - 2.0) & (xy[:, 1] >= 1.0) & (xy[:, 1] <= h - 2.0)))


def _course_ortho(photo, result) -> np.ndarray:
    """The first fit's orthophoto of the wall in grey, 1200 rows high (at most 3000 columns wide),
    for the course count (:func:`~calib_masonry.calibrate.courses.course_scale`)."""
    w, h = result.width_m, result.height_m
    ppm = 1200 / h
    if w * ppm > 3000:
        ppm = 3000 / w
    gray = np.asarray(photo.rgb, dtype=np.float32).mean(axis=-1)
    return rectify_image(gray, result.wall_from_image, w, h, ppm, lens=lens_of(result))


def lens_of(res: CalibrationResult) -> tuple[float, tuple[float, float], float, float] | None:
    """``(focal_px, principal point, k1, k2)`` of a calibration, for :func:`rectify_image`; None
    when the lens is a pinhole (k1 = k2 = 0)."""
    from .camera import principal_point

    k1, k2 = res.distortion
    if k1 == 0.0 and k2 == 0.0:
        return None
    return res.value("focal_px"), principal_point(res.image_size), k1, k2


def rect_from_wall(width_m: float, height_m: float, shape: tuple[int, int]) -> np.ndarray:
    """3x3 map of wall metres (x, z, 1) to orthophoto pixels, the Eq. 1 convention of build3d.scale."""
    rows, cols = shape
    return np.array([[cols / width_m, 0.0, -0.5], [0.0, -rows / height_m, rows - 0.5], [0.0, 0.0, 1.0]])


def rectify_image(
    image: np.ndarray,
    wall_from_image: np.ndarray,
    width_m: float,
    height_m: float,
    px_per_m: float,
    *,
    nearest: bool = False,
    lens: tuple[float, tuple[float, float], float, float] | None = None,
) -> np.ndarray:
    """Resample a photo ``(rows, cols[, C])`` into the wall's orthophoto ``(R, C'[, C])`` at
    ``px_per_m`` (``R = round(H px_per_m)``, ``C' = round(W px_per_m)``), in float32.

    Convention: pixel centres at integers, (x = column, y = row); the orthophoto's pixel ``(x, y)``
    shows the photo at ``image_from_ortho @ (x, y, 1)``, interpolated bilinearly (or, with
    ``nearest``, from the nearest pixel), zero beyond the photo's edges (and blended with zero
    within half a pixel of them, as kornia's ``warp_perspective`` with zero padding does). Where
    the wall is shrunk by more than 1.25 photo pixels per orthophoto pixel, the photo is first
    blurred by a Gaussian of 0.45 times that factor (truncated at 3 sigma, mirrored at the
    edges), so the orthophoto does not alias. ``lens``: ``(focal_px, principal point, k1, k2)``;
    the ideal point the homography gives is then moved where the lens put it
    (:func:`~calib_masonry.calibrate.camera.distort`), so the orthophoto is undistorted.

    This is the bilinear homography warp of kornia's ``warp_perspective`` (which this function
    used until it was measured: importing torch took 1 s of every 3-7 s ``rectify``, and torch's
    separable blur of a photo 0.75 s) done by OpenCV's ``remap`` (scipy's ``map_coordinates`` for
    ``nearest``, and for a photo over 32,000 px a side), in row strips (on every core) so the
    coordinate arrays stay small."""
    from scipy import ndimage

    shape = (max(2, round(height_m * px_per_m)), max(2, round(width_m * px_per_m)))
    ortho_from_image = rect_from_wall(width_m, height_m, shape) @ wall_from_image
    image_from_ortho = np.linalg.inv(ortho_from_image)
    img = np.asarray(image, dtype=np.float32)
    chans = img[..., None] if img.ndim == 2 else img
    s = 1.0
    if not nearest:
        # photo pixels per orthophoto pixel at the wall's corners: blur when the wall is shrunk
        corners = np.array([[0, 0], [width_m, 0], [width_m, height_m], [0, height_m]])
        image_from_wall = np.linalg.inv(wall_from_image)
        shrink = []
        for c in corners:
            p = image_from_wall @ np.r_[c, 1]
            q = image_from_wall @ np.r_[c + [1.0 / px_per_m, 0], 1]
            shrink.append(np.linalg.norm(p[:2] / p[2] - q[:2] / q[2]))
        s = float(np.median(shrink))
    # OpenCV's bilinear remap where the photo fits its fixed-point coordinates (under 32,767 px a
    # side): 0.03 s against scipy's 0.4 s for a 2.6 MP orthophoto, the same values to 0.007 (its
    # weights come in steps of 1/32 px; mean difference 0.0002); it takes the channels together,
    # so a photo is split into planes only to be blurred
    by_cv2 = not nearest and max(img.shape[:2]) < 32000
    blur = not nearest and s > 1.25
    planes = [np.ascontiguousarray(chans[..., c]) for c in range(chans.shape[2])] if blur or not by_cv2 else []
    if blur:
        sigma = 0.45 * s
        radius = math.ceil(3 * sigma)
        planes = thread_map(lambda p: ndimage.gaussian_filter(p, sigma, mode="mirror", radius=radius), planes)
    n_chan = chans.shape[2]
    out = np.empty(shape + (n_chan,), np.float32)
    xs = np.arange(shape[1], dtype=np.float64)
    h = image_from_ortho
    if by_cv2:
        import cv2

        whole = np.stack(planes, axis=-1) if blur else np.ascontiguousarray(img)  # the blurred planes, or the photo

    def strip(r0: int) -> None:
        ys = np.arange(r0, min(shape[0], r0 + rows_per_strip), dtype=np.float64)[:, None]
        # the homography by broadcasting: each pixel's x, y and w from a row and a column term
        w = h[2, 0] * xs + (h[2, 1] * ys + h[2, 2])
        x = (h[0, 0] * xs + (h[0, 1] * ys + h[0, 2])) / w
        y = (h[1, 0] * xs + (h[1, 1] * ys + h[1, 2])) / w
        if lens is not None:
            from .camera import distort

            xy = distort(np.stack([x, y], axis=-1), lens[0], lens[1], lens[2], lens[3])
            x, y = xy[..., 0], xy[..., 1]
        rows = slice(r0, r0 + len(ys))
        if by_cv2:
            mx, my = (np.ascontiguousarray(c, dtype=np.float32) for c in (x, y))
            got = cv2.remap(whole, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
            out[rows] = got.reshape(len(ys), len(xs), n_chan)
            return
        coords = np.stack([y.ravel(), x.ravel()])
        for c, plane in enumerate(planes):
            out[rows, :, c] = ndimage.map_coordinates(
                plane, coords, order=0 if nearest else 1, mode="grid-constant", cval=0.0
            ).reshape(len(ys), len(xs))

    # strips of about 2^18 pixels, on every core (scipy's interpolation and OpenCV release the GIL)
    rows_per_strip = max(1, (1 << 18) // shape[1])
    thread_map(strip, range(0, shape[0], rows_per_strip))
    return out[..., 0] if img.ndim == 2 else out


def rectify_to_folder(
    photo_path: str | Path,
    out: str | Path,
    config: CalibrateConfig = CalibrateConfig(),
    *,
    px_per_m: float | None = None,
    mask_path: str | Path | None = None,
    figure: bool = True,
    overwrite: bool = False,
    pieces: bool = True,
) -> dict:
    """``calib-masonry rectify``: calibration.json, rectified.png (and rectified_mask.png),
    overlay.png; with ``pieces``, the masonry units segmented (pieces_mask.png) and the LabelMe
    files rectified.json (outline, occluders, pieces over rectified.png) and photo.json (the fitted
    outline and the occluders over the photo)."""

    from .figures import plot_calibration

    check_output(out, command="rectify", overwrite=overwrite)
    if px_per_m is not None and not (math.isfinite(px_per_m) and px_per_m > 0):
        raise InputError(f"--px-per-m {px_per_m}: give the orthophoto's resolution in pixels a metre (> 0)")
    # JAX with the camera fit (0.3 s) and its compiled code (0.6 s), and Pillow's drawing, load on a
    # second thread while this one reads and searches the photo (mostly in scipy, which releases the GIL)
    preload_in_background("camera_fit", *(("figure_font",) if figure else ()), first=("detection",))
    cal = calibrate_photo(photo_path, config)
    res = cal.result
    if px_per_m is None:  # the photo's own resolution at the wall's centre, rounded
        px_per_m = native_px_per_m(res)
    size = f"the orthophoto would be {res.width_m * px_per_m:.0f} x {res.height_m * px_per_m:.0f} px"
    if min(res.width_m, res.height_m) * px_per_m < MIN_IMAGE_PX:  # the least photo, as the least orthophoto
        least = math.ceil(MIN_IMAGE_PX / min(res.width_m, res.height_m))
        raise InputError(f"--px-per-m {px_per_m:g}: {size}; choose a larger value (at least {least})")
    if res.width_m * px_per_m * res.height_m * px_per_m > 1.2e8:
        raise InputError(f"--px-per-m {px_per_m:g}: {size}; choose a smaller value")
    mask = None
    if mask_path is not None:
        from ..io import read_mask

        mask = read_mask(mask_path, field="--mask")
        if mask.shape[::-1] != cal.photo.size:
            raise InputError(
                f"--mask {mask_path}: {mask.shape[1]} x {mask.shape[0]} px, but the photo is "
                f"{cal.photo.size[0]} x {cal.photo.size[1]}; give the mask of this photo"
            )
    doc = cal.to_json()
    doc["px_per_m"] = px_per_m
    with staged_output(out, "rectify", overwrite=overwrite, keep=[photo_path, mask_path]) as stage:
        # resampling (scipy), then the segmentation of the pieces (mostly scipy and numpy, which
        # release the GIL), run on the other core while this one draws the overlay and encodes the
        # PNGs; the segmentation starts as soon as the orthophoto is there
        jobs = []

        def orthophoto() -> np.ndarray:
            rect = rectify(cal, px_per_m=px_per_m)
            if pieces:
                jobs.append(background(segment_orthophoto, cal, rect, px_per_m))
            return rect

        try:
            with background(orthophoto) as job:  # waited for on the way out of an error too
                if figure:
                    plot_calibration(cal, job.result, stage / "overlay.png")
                if mask is not None:
                    rm = rectify_image(
                        mask.astype(np.float32),
                        res.wall_from_image,
                        res.width_m,
                        res.height_m,
                        px_per_m,
                        lens=lens_of(res),
                    )
                    write_mask(stage / "rectified_mask.png", rm >= 0.5)
                rect = job.result()
                write_rgb(stage / "rectified.png", rect)
            doc["rectified_shape"] = list(rect.shape[:2])
            if pieces:
                seg, polygons, occ, openings = jobs[0].result()
                doc["pieces"] = seg.summary()
                from ..labelme import write_labelme_pair

                write_labelme_pair(
                    stage, cal, rect.shape[:2], pieces=polygons, occluders_ortho=occ, openings_ortho=openings
                )
                write_mask(stage / "pieces_mask.png", _upsampled_mask(seg.mask, rect.shape[:2]))
        finally:  # nothing runs on after this function, however it ends
            for j in jobs:
                j.wait()
        write_json(stage / "calibration.json", doc)
    return doc


#: the orthophoto's resolution the pieces are segmented at, at most (px per metre of wall)
SEGMENT_PX_PER_M = 300.0


def segment_orthophoto(cal: PhotoCalibration, rect: np.ndarray, px_per_m: float):
    """The masonry units of a calibrated photo's orthophoto ``rect`` (at ``px_per_m``), segmented at
    no more than :data:`SEGMENT_PX_PER_M` (a finer orthophoto is shrunk first): the
    :class:`~calib_masonry.wall2d.segment.Segmentation`, the pieces' polygons, the occluders and the
    openings it left out (windows, doors) in ``rect``'s pixels."""
    from ..wall2d.segment import segment_wall
    from .segments import shrink

    f = min(1.0, SEGMENT_PX_PER_M / px_per_m)
    small = rect if f >= 1.0 else shrink(rect, f)  # OpenCV shrinks the three channels at once
    ppm = px_per_m * small.shape[1] / rect.shape[1]
    # the shrunk orthophoto's rows are rounded on their own, so the mask at its column scale can be a
    # row longer or shorter (a square close-up of bricks, 304 against 303): cut, or the edge repeated
    valid = valid_ortho(cal, ppm)[: small.shape[0], : small.shape[1]]
    valid = np.pad(valid, [(0, small.shape[0] - valid.shape[0]), (0, small.shape[1] - valid.shape[1])], mode="edge")
    seg = segment_wall(small, ppm, valid=valid if not valid.all() else None)
    polygons = piece_polygons(seg.labels, tolerance_px=1.5)
    up = np.array([rect.shape[1] / small.shape[1], rect.shape[0] / small.shape[0]])
    polygons = [(p + 0.5) * up - 0.5 for p in polygons]
    occluders = [ortho_from_photo(cal, poly, rect.shape[:2]) for poly in cal.occluders]
    openings = [(p + 0.5) * up - 0.5 for p in opening_polygons(seg)]
    return seg, polygons, occluders, openings


def opening_polygons(seg) -> list[np.ndarray]:
    """The openings a :class:`~calib_masonry.wall2d.segment.Segmentation` left out (windows,
    doors), one polygon each in its pixels, as :func:`piece_polygons` draws pieces."""
    if seg.openings is None:
        return []
    from scipy import ndimage

    return piece_polygons(ndimage.label(seg.openings)[0].astype(np.int32), tolerance_px=1.5)


def piece_polygons(labels: np.ndarray, *, tolerance_px: float = 1.5) -> list[np.ndarray]:
    """Each labelled piece ``(rows, cols)`` (0 mortar) as a polygon for a LabelMe file: the traced
    outline of its largest part (along pixel edges,
    :func:`~calib_masonry.wall2d.trace.trace_outline`) simplified to within ``tolerance_px``
    (Douglas-Peucker), so that an engineer drags a few vertices, not hundreds."""
    import cv2
    from scipy import ndimage
    from skimage.measure import label

    from ..wall2d.trace import trace_outline, trace_outlines

    # how many 4-connected parts each piece has, from one labelling of the whole image (labelling
    # each piece's crop took 0.08 s of a wall's 326 pieces, measured): only pieces in parts are
    # labelled again, to keep their largest
    parts_of = label(labels, connectivity=1, background=0)
    first = np.zeros(int(parts_of.max()) + 1, dtype=labels.dtype)
    first[parts_of.ravel()] = labels.ravel()
    n_parts = np.bincount(first[1:], minlength=int(labels.max()) + 1)
    slices = ndimage.find_objects(labels)
    # the pieces in one part traced all at once (one by one they took 0.15-0.2 s of a wall's 463)
    whole = [k for k, sl in enumerate(slices, start=1) if sl is not None and n_parts[k] == 1]
    outlines = dict(zip(whole, trace_outlines(labels, whole, slices)))
    out = []
    for k, sl in enumerate(slices, start=1):
        if sl is None:
            continue
        if n_parts[k] > 1:
            parts, _ = ndimage.label(labels[sl] == k)
            outline = trace_outline(parts == 1 + int(np.argmax(np.bincount(parts.ravel())[1:])))
        else:
            outline = outlines[k]
        # OpenCV's Douglas-Peucker on the closed outline (scikit-image's took 2 ms a piece)
        poly = cv2.approxPolyDP(outline.astype(np.float32).reshape(-1, 1, 2), tolerance_px, True)
        poly = poly.reshape(-1, 2).astype(np.float64)
        if len(poly) >= 3:
            out.append(poly + [sl[1].start, sl[0].start])
    return out


def _upsampled_mask(mask: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    if mask.shape == tuple(shape):
        return mask
    rows = np.minimum((np.arange(shape[0]) + 0.5) * mask.shape[0] / shape[0], mask.shape[0] - 1).astype(int)
    cols = np.minimum((np.arange(shape[1]) + 0.5) * mask.shape[1] / shape[1], mask.shape[1] - 1).astype(int)
    return mask[np.ix_(rows, cols)]


def native_px_per_m(res: CalibrationResult) -> float:
    """Photo pixels per wall metre at the wall's centre (rounded to 10), a natural orthophoto scale."""
    scale = float(px_per_m(res.image_from_wall, [res.width_m / 2, res.height_m / 2], eps=0.01)[0])
    return float(max(10.0, round(scale / 10.0) * 10.0))

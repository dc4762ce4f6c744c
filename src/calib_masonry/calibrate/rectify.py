"""One photo to a calibrated wall: detect or take the corners, fit, check, resample to an orthophoto.

``calibrate_photo`` is the library call behind ``calib-masonry rectify`` and behind ``build`` on
structure files that name photos. ``rectify_image`` resamples the photo by the fitted homography
(bilinear, scipy; a Gaussian pre-blur when the wall is shrunk, so the orthophoto does not alias).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from .._threads import background, thread_map
from ..errors import FitFailed, InputError
from ..io import Photo, check_output, read_photo, staged_output, write_json, write_mask, write_rgb
from .camera import CORNERS_FLAG, order_corners, px_per_m
from .lines import DetectConfig, Detection, detect_wall, refine_quad, segments_in_quad

if TYPE_CHECKING:
    from .fit import CalibrationResult

__all__ = [
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


@dataclass(frozen=True)
class CalibrateConfig:
    """What the user tells the calibration (the flags of ``rectify``)."""

    corners_px: tuple[float, ...] | None = None  # 8 numbers x1, y1, ..., x4, y4 in any order; None = automatic
    camera_height_m: float = 1.6
    camera_height_sigma_m: float = 0.1
    focal_px: float | None = None  # overrides EXIF
    focal_sigma_px: float | None = None
    known_width_m: float | None = None
    known_height_m: float | None = None
    corner_sigma_px: float | None = None  # default 1.5 clicked, 1.0 detected
    line_sigma_px: float = 1.0
    max_effective_segments: int = 16
    use_lines: bool = True
    snap_corners: bool = True  # refine clicked corners onto the wall's outline edges
    max_rms_px: float = 3.0
    force: bool = False
    detect: DetectConfig = field(default_factory=DetectConfig)

    def __post_init__(self) -> None:
        if not (math.isfinite(self.camera_height_m) and 0 < self.camera_height_m < 100):
            raise InputError(
                f"--camera-height {self.camera_height_m}: give the eye height above the wall's base in metres"
            )
        if not (math.isfinite(self.camera_height_sigma_m) and self.camera_height_sigma_m > 0):
            raise InputError(f"--camera-height-sigma {self.camera_height_sigma_m}: must be > 0 (metres)")
        if self.focal_px is not None and not (math.isfinite(self.focal_px) and self.focal_px > 0):
            raise InputError(f"--focal-px {self.focal_px}: must be > 0 (pixels)")
        for flag, value in (("--known-width", self.known_width_m), ("--known-height", self.known_height_m)):
            if value is not None and not (math.isfinite(value) and value > 0):
                raise InputError(f"{flag} {value}: must be > 0 (metres)")
        if self.known_width_m is not None and self.known_height_m is not None:
            raise InputError("rectify: give --known-width or --known-height, not both")
        if not (math.isfinite(self.max_rms_px) and self.max_rms_px > 0):
            raise InputError(f"--max-rms {self.max_rms_px}: must be > 0 (pixels)")
        if self.corners_px is not None and len(self.corners_px) != 8:
            raise InputError(f"--corners: got {len(self.corners_px)} numbers; give exactly 8 (x1,y1,...,x4,y4)")


#: above this relative 1-sigma uncertainty of W or H a calibration says how to pin the scale
SCALE_ADVICE_RELATIVE_SIGMA = 0.02


@dataclass(frozen=True)
class PhotoCalibration:
    photo: Photo
    result: CalibrationResult
    detection: Detection | None
    mode: str  # "clicked" or "automatic"
    focal_source: str

    def advice(self) -> str:
        """What to add when the photo fixes W and H only loosely ("" when both are known to within
        :data:`SCALE_ADVICE_RELATIVE_SIGMA`): the scale rests on the camera height and the wall's
        convergence, and for a tall wall seen from its foot one pixel on a corner moves it by
        2-6 % (measured, experiments/bench_tall_walls.py)."""
        rel = max(
            self.result.sigma("width_m") / self.result.width_m, self.result.sigma("height_m") / self.result.height_m
        )
        if not rel > SCALE_ADVICE_RELATIVE_SIGMA:
            return ""
        return (
            f"W and H are known only to +-{rel:.1%} (1 sigma) from this photo; measure one side and pass "
            "--known-width or --known-height, or measure your eye height above the wall's base for --camera-height"
        )

    def to_json(self) -> dict:
        doc = self.result.to_json()
        doc.update(photo=str(self.photo.path), mode=self.mode, focal_source=self.focal_source)
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
    try:
        values = tuple(float(v) for v in text.replace(" ", "").split(","))
    except ValueError:
        raise InputError(f"--corners {text!r}: not a list of numbers; give x1,y1,x2,y2,x3,y3,x4,y4 in pixels") from None
    if len(values) != 8:
        raise InputError(f"--corners: got {len(values)} numbers; give exactly 8 (x1,y1,...,x4,y4)")
    return values


def calibrate_photo(photo: Photo | str | Path, config: CalibrateConfig = CalibrateConfig()) -> PhotoCalibration:
    """Fit the camera and the wall to one photo; refuse a fit whose residual is above ``max_rms_px``."""
    if not isinstance(photo, Photo):
        photo = read_photo(photo)
    w, h = photo.size
    focal, focal_source = config.focal_px, "--focal-px"
    if focal is None and photo.focal_px is not None:
        focal, focal_source = photo.focal_px, "EXIF"
    if focal is None:
        focal_source = "fitted"
    if focal is not None and not 0.1 * max(w, h) < focal < 20 * max(w, h):
        raise InputError(
            f"{photo.path}: focal length {focal:.0f} px is implausible for a {w} x {h} photo; "
            "pass --focal-px with the right value"
        )
    detection = None
    if config.corners_px is not None:
        corners = order_corners(np.array(config.corners_px).reshape(4, 2))
        if np.any(corners < -0.5) or np.any(corners[:, 0] > w - 0.5) or np.any(corners[:, 1] > h - 0.5):
            raise InputError(
                f"--corners: a corner lies outside the {w} x {h} photo {photo.path.name}; click inside the image"
            )
        mode = "clicked"
        sigma = config.corner_sigma_px or 1.5
        if config.snap_corners:
            snapped = refine_quad(photo.rgb, corners, (3.0 * sigma + 1.0, 2.0))
            if not np.array_equal(snapped, corners):
                corners, sigma, mode = snapped, min(sigma, 0.5), "clicked, snapped to the outline"
        bed = head = np.zeros((0, 4))
        if config.use_lines:
            try:
                found = detect_wall(photo.rgb, config.detect)
                bed = segments_in_quad(found.bed_segments, corners)
                head = segments_in_quad(found.head_segments, corners)
            except FitFailed:
                pass  # no joint lines: the corners alone (plus priors) still determine the fit
    else:
        try:
            detection = detect_wall(photo.rgb, config.detect)
        except FitFailed as exc:
            raise FitFailed(f"{photo.path}: {exc}") from None
        corners, bed, head = detection.corners_px, detection.bed_segments, detection.head_segments
        if not config.use_lines:
            bed = head = np.zeros((0, 4))
        mode = "automatic"
        sigma = config.corner_sigma_px or 1.0
    from .fit import CalibrationInput, calibrate  # JAX loads here (or on import_early's thread)

    inp = CalibrationInput(
        image_size=(w, h),
        corners_px=corners,
        corner_sigma_px=sigma,
        bed_segments=bed,
        head_segments=head,
        line_sigma_px=config.line_sigma_px,
        max_effective_segments=config.max_effective_segments,
        camera_height_m=config.camera_height_m,
        camera_height_sigma_m=config.camera_height_sigma_m,
        focal_px=focal,
        focal_sigma_px=config.focal_sigma_px,
        known_width_m=config.known_width_m,
        known_height_m=config.known_height_m,
    )
    try:
        result = calibrate(inp)
    except FitFailed as exc:
        raise FitFailed(f"{photo.path}: {exc}") from None
    if focal is None and result.sigma("focal_px") > 0.2 * result.value("focal_px"):
        raise FitFailed(
            f"{photo.path}: no focal length in EXIF and too few constraints to fit one "
            f"(+-{result.sigma('focal_px'):.0f} px); pass --focal-px F"
        )
    if not config.force:
        if not result.fit.ok:
            raise FitFailed(f"{photo.path}: the calibration {result.status.message}; or use --force to keep it anyway")
        if result.rms_residual_px > config.max_rms_px:
            raise FitFailed(
                f"{photo.path}: RMS residual {result.rms_residual_px:.2f} px exceeds {config.max_rms_px:g} px "
                "(corners or joints do not fit one wall plane); click the corners with --corners, "
                "or use --force to keep it anyway"
            )
        if result.rms_corner_px > config.max_rms_px:
            # the joints' lines contradict the corners: a corner found (or clicked) on something
            # else. The RMS over all residuals hides it among hundreds of joint segments (tall wall
            # seed 9143: a base corner 70 px up the wall, corners' RMS 20 px, all residuals' 2.1 px,
            # W 60 % short)
            raise FitFailed(
                f"{photo.path}: the corners are {result.rms_corner_px:.1f} px (RMS) from the outline the mortar "
                f"joints fit (more than {config.max_rms_px:g} px), so one is not on the wall's corner; click the "
                f"wall's corners with {CORNERS_FLAG}, or use --force to keep it anyway"
            )
        if not (0.2 < result.width_m < 500 and 0.2 < result.height_m < 500):
            raise FitFailed(
                f"{photo.path}: fitted wall {result.width_m:.2f} x {result.height_m:.2f} m is implausible; "
                "check --camera-height and the corners"
            )
    return PhotoCalibration(photo=photo, result=result, detection=detection, mode=mode, focal_source=focal_source)


def rectify(
    calibration: PhotoCalibration,
    *,
    px_per_m: float | None = None,
    width_m: float | None = None,
    height_m: float | None = None,
) -> np.ndarray:
    """The metric orthophoto ``(rows, cols, 3)`` of a calibrated photo's wall, at ``px_per_m``
    (default: the photo's own finest resolution on the wall). ``width_m`` / ``height_m`` stretch the
    fitted wall onto a measured size (the photo's outline then maps onto the W x H given)."""
    res = calibration.result
    width = res.width_m if width_m is None else float(width_m)
    height = res.height_m if height_m is None else float(height_m)
    for name, v in (("width_m", width), ("height_m", height)):
        if not (math.isfinite(v) and v > 0):
            raise InputError(f"rectify: {name} = {v} must be a length > 0 (metres)")
    ppm = native_px_per_m(res) if px_per_m is None else float(px_per_m)
    if not (math.isfinite(ppm) and ppm > 0):
        raise InputError(f"rectify: px_per_m = {ppm} must be > 0")
    stretch = np.diag([width / res.width_m, height / res.height_m, 1.0])
    return rectify_image(calibration.photo.rgb, stretch @ res.wall_from_image, width, height, ppm)


def rect_from_wall(width_m: float, height_m: float, shape: tuple[int, int]) -> np.ndarray:
    """3x3 map of wall metres (x, z, 1) to orthophoto pixels, the Eq. 1 convention of build3d.scale."""
    rows, cols = shape
    return np.array([[cols / width_m, 0.0, -0.5], [0.0, -rows / height_m, rows - 0.5], [0.0, 0.0, 1.0]])


def import_detection() -> None:
    """Import the modules the automatic detection imports on first use, in this thread: two
    threads importing one package at once can see it half initialised (seen with matplotlib)."""
    import encodings.ascii  # noqa: F401 - EXIF text

    import scipy.spatial  # noqa: F401
    from PIL import Image, ImageOps, TiffImagePlugin  # noqa: F401 - the photo's reader and its EXIF

    # scikit-image loads a submodule when one of its names is first asked for (lazy_loader):
    # the names the detection asks for, asked for here
    from skimage.feature import canny, hessian_matrix, hessian_matrix_eigvals  # noqa: F401
    from skimage.measure import label  # noqa: F401
    from skimage.transform import probabilistic_hough_line  # noqa: F401

    Image.preinit()  # Pillow's common formats' plugins (JPEG, PNG, ...), loaded on the first open


def import_early(figures: bool = True) -> None:
    """Start importing JAX with the camera fit (0.3 s) and, with ``figures``, Pillow's drawing on a
    second thread, so that it runs while this one reads and searches the photo (mostly in scipy,
    which releases the GIL). numpy and scipy, which both sides import, are loaded before the
    thread starts, and so are the detection's modules (:func:`import_detection`); an import that
    fails there fails again, with its message, where it is needed."""
    import threading

    import_detection()

    def load() -> None:
        try:
            from . import fit  # noqa: F401

            if figures:
                from .. import _raster

                _raster.font(12)  # the font file is read once, here
        except Exception:  # noqa: BLE001 - reported by the import where it is needed
            pass

    threading.Thread(target=load, name="calib-masonry-imports", daemon=True).start()


def rectify_image(
    image: np.ndarray,
    wall_from_image: np.ndarray,
    width_m: float,
    height_m: float,
    px_per_m: float,
    *,
    nearest: bool = False,
) -> np.ndarray:
    """Resample a photo ``(rows, cols[, C])`` into the wall's orthophoto ``(R, C'[, C])`` at
    ``px_per_m`` (``R = round(H px_per_m)``, ``C' = round(W px_per_m)``), in float32.

    Convention: pixel centres at integers, (x = column, y = row); the orthophoto's pixel ``(x, y)``
    shows the photo at ``image_from_ortho @ (x, y, 1)``, interpolated bilinearly (or, with
    ``nearest``, from the nearest pixel), zero beyond the photo's edges (and blended with zero
    within half a pixel of them, as kornia's ``warp_perspective`` with zero padding does). Where
    the wall is shrunk by more than 1.25 photo pixels per orthophoto pixel, the photo is first
    blurred by a Gaussian of 0.45 times that factor (truncated at 3 sigma, mirrored at the
    edges), so the orthophoto does not alias.

    This is the bilinear homography warp of kornia's ``warp_perspective`` (which this function
    used until it was measured: importing torch took 1 s of every 3-7 s ``rectify``, and torch's
    separable blur of a photo 0.75 s) done by scipy's ``map_coordinates``, in row strips (on every
    core) so the coordinate arrays stay small."""
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
    planes = [np.ascontiguousarray(chans[..., c]) for c in range(chans.shape[2])]
    if not nearest and s > 1.25:
        sigma = 0.45 * s
        radius = math.ceil(3 * sigma)
        planes = thread_map(lambda p: ndimage.gaussian_filter(p, sigma, mode="mirror", radius=radius), planes)
    out = np.empty(shape + (len(planes),), np.float32)
    xs = np.arange(shape[1], dtype=np.float64)

    def strip(r0: int) -> None:
        ys = np.arange(r0, min(shape[0], r0 + rows_per_strip), dtype=np.float64)
        q = image_from_ortho @ np.stack(
            [
                np.broadcast_to(xs, (len(ys), len(xs))),
                np.broadcast_to(ys[:, None], (len(ys), len(xs))),
                np.ones((len(ys), len(xs))),
            ]
        ).reshape(3, -1)
        coords = np.stack([q[1] / q[2], q[0] / q[2]])
        for c, plane in enumerate(planes):
            out[r0 : r0 + len(ys), :, c] = ndimage.map_coordinates(
                plane, coords, order=0 if nearest else 1, mode="grid-constant", cval=0.0
            ).reshape(len(ys), len(xs))

    # strips of about 2^18 pixels, on every core (scipy's interpolation releases the GIL)
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
) -> dict:
    """``calib-masonry rectify``: calibration.json, rectified.png (and rectified_mask.png), overlay.png."""

    from .figures import plot_calibration

    check_output(out, command="rectify", overwrite=overwrite)
    import_early(figures=figure)
    cal = calibrate_photo(photo_path, config)
    res = cal.result
    if px_per_m is None:  # the photo's own resolution at the wall's centre, rounded
        px_per_m = native_px_per_m(res)
    if px_per_m <= 0 or res.width_m * px_per_m * res.height_m * px_per_m > 1.2e8:
        raise InputError(
            f"--px-per-m {px_per_m:g}: the orthophoto would be "
            f"{res.width_m * px_per_m:.0f} x {res.height_m * px_per_m:.0f} px; choose a smaller value"
        )
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
        # resampling (scipy) and the PNG's encoding (zlib) release the GIL: they run on the other
        # core while the overlay draws
        def orthophoto() -> np.ndarray:
            rect = rectify(cal, px_per_m=px_per_m)
            write_rgb(stage / "rectified.png", rect)
            return rect

        with background(orthophoto) as job:  # waited for on the way out of an error too
            if figure:
                plot_calibration(cal, job.result, stage / "overlay.png")
            if mask is not None:
                rm = rectify_image(mask.astype(np.float32), res.wall_from_image, res.width_m, res.height_m, px_per_m)
                write_mask(stage / "rectified_mask.png", rm >= 0.5)
        rect = job.result()
        doc["rectified_shape"] = list(rect.shape[:2])
        write_json(stage / "calibration.json", doc)
    return doc


def native_px_per_m(res: CalibrationResult) -> float:
    """Photo pixels per wall metre at the wall's centre (rounded to 10), a natural orthophoto scale."""
    scale = float(px_per_m(res.image_from_wall, [res.width_m / 2, res.height_m / 2], eps=0.01)[0])
    return float(max(10.0, round(scale / 10.0) * 10.0))

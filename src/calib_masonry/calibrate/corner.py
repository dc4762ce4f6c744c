"""A corner photo: one camera, two walls meeting at a vertical edge, the angle between them.

Seen from outside, wall n is on the left of the corner and wall n+1 on the right. In wall n's frame
(x along it, z up, y into the building) the next wall runs along ``(cos phi, sin phi, 0)``: phi is
the turn from wall n to wall n+1, counter-clockwise positive, so theta_{n+1} = theta_n + phi (a
convex corner of a counter-clockwise footprint turns +90 degrees).

Only directions matter, so the fit is rotation-only: focal length, the camera's yaw, pitch and roll
against wall n, and phi. Residuals: every bed-joint segment of wall n must point at the image of
wall n's x axis, every bed joint of wall n+1 at the image of its own x axis, and every head joint
of either wall at the image of the vertical; a focal prior from EXIF. Segments are found and split
between the walls automatically (two horizontal vanishing points by sequential RANSAC; the left
one in the image is wall n). Levenberg-Marquardt in JAX (optimistix), covariance from the Jacobian.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from .._jax import jax, jnp
from ..errors import FitFailed, InputError
from ..io import Photo, read_photo
from .camera import angles_from_rotation, intrinsics, principal_point, wall_from_camera_rotation
from .fit import _line_distances, _pad_segments
from .fitresult import FitResult, FitStatus, HasFit, fit_result
from .lines import DetectConfig, _hough_segments
from .lm import least_squares
from .segments import vanishing_point
from .veil import without_veil

__all__ = [
    "CORNER_DETECT",
    "CornerDetect",
    "CornerResult",
    "calibrate_corner_photo",
    "corner_vanishing_points",
    "fit_corner",
]

_SCALE = np.array([1000.0, 0.1, 0.1, 0.1, 0.1])  # f, yaw, pitch, roll, phi
CORNER_PARAMS = ("focal_px", "yaw_rad", "pitch_rad", "roll_rad", "turn_rad")


@dataclass(frozen=True)
class CornerResult(HasFit):
    """The fit of a corner photo: its :class:`~calib_masonry.calibrate.fitresult.FitResult` (focal,
    yaw, pitch, roll, turn) and the segments it used."""

    fit: FitResult
    rms_line_px: float
    n_segments: tuple[int, int, int]  # bed of wall n, bed of wall n+1, head
    segments: tuple = ()  # (bed of wall n, bed of wall n+1) in full-size pixels, for figures

    @property
    def turn_rad(self) -> float:
        return float(self.params[4])

    @property
    def turn_sigma_rad(self) -> float:
        return self.fit.sigma("turn_rad")

    def to_json(self) -> dict:
        return {
            "turn_deg": math.degrees(self.turn_rad),
            "turn_sigma_deg": math.degrees(self.turn_sigma_rad),
            "focal_px": float(self.params[0]),
            "yaw_deg": math.degrees(self.params[1]),
            "pitch_deg": math.degrees(self.params[2]),
            "roll_deg": math.degrees(self.params[3]),
            "rms_line_px": self.rms_line_px,
            "segments": {"bed_left": self.n_segments[0], "bed_right": self.n_segments[1], "head": self.n_segments[2]},
            **self.fit.to_json(),
        }


def _vps(p, pp):
    k = intrinsics(p[0], pp, jnp)
    cam_from_wall = wall_from_camera_rotation(p[1], p[2], p[3], jnp).T
    along_b = jnp.stack([jnp.cos(p[4]), jnp.sin(p[4]), jnp.zeros(())])
    return k @ cam_from_wall[:, 0], k @ (cam_from_wall @ along_b), k @ cam_from_wall[:, 2]


def _residuals(u, data):
    p = u * _SCALE
    vp_a, vp_b, vp_z = _vps(p, data["pp"])
    return jnp.concatenate(
        [
            _line_distances(vp_a, data["bed_a"]) * data["w_a"],
            _line_distances(vp_b, data["bed_b"]) * data["w_b"],
            _line_distances(vp_z, data["head"]) * data["w_h"],
            jnp.atleast_1d((p[0] - data["prior"][0]) * data["prior"][1]),
        ]
    )


@jax.jit
def _solve(u0, data):
    return least_squares(_residuals, u0, data)


@dataclass(frozen=True)
class CornerDetect:
    """Joint centre lines (Hessian ridges) split the segments into the walls' families robustly:
    the horizon and the walls' outlines are steps, not ridges. The fit then uses long edge
    segments (``edges``) consistent with those families: short segments carry a direction bias of
    up to a degree (pixel staircase, joints thinning with distance) that the vanishing points
    would inherit."""

    ridges: DetectConfig = DetectConfig(ridge_sigma_px=1.5)
    edges: DetectConfig = DetectConfig(min_length_px=40)
    assign_px: float = 1.0  # working px: an edge segment joins a family within this distance
    with_ridges: bool = True  # fit on the ridge segments of each family too


CORNER_DETECT = CornerDetect()


def _families(seg, config: DetectConfig, tol, norm, rng):
    ang = np.degrees(np.arctan2(seg[:, 3] - seg[:, 1], seg[:, 2] - seg[:, 0])) % 180.0
    horiz = seg[np.minimum(ang, 180 - ang) < config.horizontal_max_deg]
    vert = seg[np.abs(ang - 90.0) < config.vertical_max_deg]
    vp1, in1 = vanishing_point(norm(horiz), tol, config.ransac_iterations, rng)
    rest = horiz[~in1]
    if len(rest) < 10:
        raise FitFailed("corner photo: only one wall's bed joints found; frame the corner so both walls show")
    vp2, in2 = vanishing_point(norm(rest), tol, config.ransac_iterations, rng)
    vpz, _ = vanishing_point(norm(vert), tol, config.ransac_iterations, rng)
    fam1, fam2 = horiz[in1], rest[in2]
    if len(fam2) < 5:
        raise FitFailed("corner photo: the second wall's bed joints are too few; frame the corner so both walls show")
    if np.median((fam1[:, 0] + fam1[:, 2]) / 2) < np.median((fam2[:, 0] + fam2[:, 2]) / 2):
        return vp1, vp2, vpz
    return vp2, vp1, vpz


def corner_vanishing_points(rgb: np.ndarray, config: CornerDetect = CORNER_DETECT):
    """Segments of a corner photo split into (bed of the left wall, bed of the right wall, head), in
    full-size pixels, with their vanishing points (homogeneous, full-size pixels)."""
    from .lines import working_gray
    from .segments import dist_to_vp

    rows, cols = rgb.shape[:2]
    small, s = working_gray(rgb, config.ridges.work_long_side_px)
    ridge = (_hough_segments(small, config.ridges, ridges=True) + 0.5) / s - 0.5
    edge = (_hough_segments(small, config.edges) + 0.5) / s - 0.5
    if len(ridge) < 20:
        raise FitFailed("corner photo: almost no mortar joints found; is the corner of two brick walls in view?")
    centre = np.array([cols - 1, rows - 1]) / 2.0
    scale = float(max(rows, cols))
    norm = lambda sg: np.c_[(sg[:, :2] - centre) / scale, (sg[:, 2:] - centre) / scale]  # noqa: E731
    rng = np.random.default_rng(config.ridges.seed)
    va, vb, vz = _families(ridge, config.ridges, config.ridges.vp_inlier_px / s / scale, norm, rng)
    tol = config.assign_px / s / scale
    en = norm(edge)
    da, db, dz = (dist_to_vp(en, v) for v in (va, vb, vz))
    fam_a = edge[(da < tol) & (db >= tol) & (dz >= tol)]
    fam_b = edge[(db < tol) & (da >= tol) & (dz >= tol)]
    fam_z = edge[(dz < tol) & (da >= tol) & (db >= tol)]
    if config.with_ridges:
        rn = norm(ridge)
        ra, rb = (dist_to_vp(rn, v) for v in (va, vb))
        rtol = config.ridges.vp_inlier_px / s / scale
        fam_a = np.concatenate([fam_a, ridge[(ra < rtol) & (rb >= rtol)]])
        fam_b = np.concatenate([fam_b, ridge[(rb < rtol) & (ra >= rtol)]])
    unscale = np.array([[scale, 0, centre[0]], [0, scale, centre[1]], [0, 0, 1.0]])
    if len(fam_a) < 5 or len(fam_b) < 5:
        raise FitFailed("corner photo: too few long joint lines on one of the walls; frame the corner closer")
    return fam_a, fam_b, fam_z, unscale @ va, unscale @ vb, unscale @ vz


def _direction(k_inv, vp, positive_axis, sign):
    d = k_inv @ vp
    d = d / np.linalg.norm(d)
    return d if d[positive_axis] * sign >= 0 else -d


def fit_corner(
    image_size,
    bed_a,
    bed_b,
    head,
    *,
    focal_px: float | None,
    focal_sigma_px: float | None = None,
    line_sigma_px: float = 1.0,
    max_effective_segments: int = 64,
    start=None,
) -> CornerResult:
    """Fit focal, orientation and the turn angle to the three segment families of a corner photo."""
    pp = principal_point(image_size)
    if start is None:
        raise InputError("fit_corner: a start (from corner_vanishing_points) is needed")
    ba, wa = _pad_segments(bed_a, line_sigma_px, max_effective_segments)
    bb, wb = _pad_segments(bed_b, line_sigma_px, max_effective_segments)
    hd, wh = _pad_segments(head, line_sigma_px, max_effective_segments)
    f_sigma = focal_sigma_px or (0.002 * focal_px if focal_px else None)
    data = {
        "pp": jnp.asarray(pp),
        "bed_a": jnp.asarray(ba),
        "w_a": jnp.asarray(wa),
        "bed_b": jnp.asarray(bb),
        "w_b": jnp.asarray(wb),
        "head": jnp.asarray(hd),
        "w_h": jnp.asarray(wh),
        "prior": jnp.asarray([focal_px or 0.0, 1.0 / f_sigma if focal_px else 0.0]),
    }
    u, ok, steps, jac, r = _solve(jnp.asarray(np.asarray(start) / _SCALE), data)
    fit = fit_result(u, ok, steps, jac, r, CORNER_PARAMS, _SCALE)
    if fit.status in (FitStatus.SINGULAR, FitStatus.DIVERGED):
        raise FitFailed(f"corner photo: the joint lines do not determine the corner angle ({fit.status.message})")
    r = np.asarray(r)
    n = (min(len(bed_a), 1024), min(len(bed_b), 1024), min(len(head), 1024))
    weights = np.concatenate([wa, wb, wh])
    used = weights > 0
    dist = r[:-1][used] / weights[used]  # endpoint distances in px
    return CornerResult(fit=fit, rms_line_px=float(np.sqrt(np.mean(dist**2))) if len(dist) else 0.0, n_segments=n)


def calibrate_corner_photo(
    photo: Photo | str | Path, *, focal_px: float | None = None, config: CornerDetect = CORNER_DETECT
) -> CornerResult:
    """The turn angle between the two walls of a corner photo (wall n on the left)."""
    if not isinstance(photo, Photo):
        photo = read_photo(photo)
    photo = without_veil(photo)
    f = focal_px or photo.focal_px
    if f is None:
        raise InputError(f"{photo.path}: a corner photo needs the focal length (no EXIF); pass --focal-px F")
    try:
        bed_a, bed_b, head, va, vb, vz = corner_vanishing_points(photo.rgb, config)
    except FitFailed as exc:
        raise FitFailed(f"{photo.path}: {exc}") from None
    pp = principal_point(photo.size)
    k_inv = np.linalg.inv(intrinsics(f, pp))
    ex_a = _direction(k_inv, va, 0, +1)
    ez = _direction(k_inv, vz, 1, -1)
    ex_b = _direction(k_inv, vb, 0, +1)
    ez = ez - ex_a * (ez @ ex_a)
    ez /= np.linalg.norm(ez)
    ey_a = np.cross(ez, ex_a)
    cam_from_wall = np.stack([ex_a, ey_a, ez], axis=1)
    u, _, vt = np.linalg.svd(cam_from_wall)
    yaw, pitch, roll = angles_from_rotation((u @ vt).T)
    phi = math.atan2(ex_b @ ey_a, ex_b @ ex_a)
    # head joints are short and their centre lines bend into the bed joints at both ends, which
    # biases the vertical vanishing point towards the image's vertical; with the focal length
    # known the two walls' bed joints fix the vertical anyway (it is normal to both), so the head
    # joints only seed the start
    res = fit_corner(photo.size, bed_a, bed_b, np.zeros((0, 4)), focal_px=f, start=np.array([f, yaw, pitch, roll, phi]))
    res = replace(res, segments=(bed_a, bed_b))
    if not res.fit.ok:
        raise FitFailed(
            f"{photo.path}: the corner fit {res.status.message}; check that the photo shows two brick walls "
            "meeting at a vertical edge"
        )
    return res

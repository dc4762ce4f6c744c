"""Fit the camera and the wall's size to one photo: JAX residuals, optimistix Levenberg-Marquardt.

Unknowns (:data:`~calib_masonry.calibrate.camera.PARAM_NAMES`): focal length, yaw, pitch, roll,
camera centre (wall frame) and the wall's W and H. Residuals, each divided by its noise:

- the four wall corners ``(0, 0), (W, 0), (W, H), (0, H)`` reprojected against the clicked or
  detected ones (``corner_sigma_px``);
- every mortar-joint segment against the line through its midpoint and its vanishing point: bed
  joints are horizontal in the wall (vanishing point = image of +x), head joints vertical (image of
  +z); one residual per segment, its endpoint distance to that line (``line_sigma_px`` per endpoint);
- the camera height above the wall's base (a prior, ``camera_height_m`` +- sigma);
- the focal length when known (EXIF or ``--focal-px``) and any known width or height.

The solve is exported once (``jax.export``, kept on disk, so a new process does not trace it) and
runs on inputs padded to a few fixed sizes, so photos with different numbers of segments reuse one
compilation. The covariance of the parameters is ``(J^T J)^-1`` at
the solution (residuals are already in units of their noise).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from functools import cache

import numpy as np

from .._jax import jax, jnp
from ..errors import FitFailed, InputError
from .camera import (
    CORNERS_FLAG,
    DISTORTION_MODEL,
    FOCAL_PRIOR_LOG_SIGMA,
    PARAM_NAMES,
    angles_from_rotation,
    distort,
    focal_prior_px,
    image_from_wall_homography,
    order_corners,
    principal_point,
    project,
    undistort,
)
from .fitresult import FitResult, FitStatus, HasFit, fit_result
from .lm import least_squares

__all__ = [
    "CalibrationInput",
    "CalibrationResult",
    "calibrate",
    "homography_dlt",
    "initial_params",
    "order_corners",
    "pack",
    "residual_vector",
]

# Parameter scales: the solver works on params / SCALE so every unknown is of order one.
SCALE = np.array([1000.0, 0.1, 0.1, 0.1, 1.0, 1.0, 1.0, 1.0, 1.0, 0.1, 0.1])

#: The lens's radial distortion without a profile: k1 ~ N(0, 0.15), k2 ~ N(0, 0.05) (OpenCV's
#: convention; consumer lenses lie within about -0.3..0.15, and most JPEGs are corrected in the
#: camera; k2 is nearly the same curve as k1 over a photo's radii, so its prior keeps the pair apart)
K1_PRIOR_SIGMA = 0.15
K2_PRIOR_SIGMA = 0.05
# every fit pads its bed and head segments to MAX_SEGMENTS and its plumb points to
# MAX_PLUMB_POINTS (padding has weight 0: exact zeros in every sum), so that the exported fit has
# one shape: each further shape cost a process 0.6 s of lowering and 0.8 s of loading its compiled
# code; the largest segments' count a photo gives (about 800 a family on a 6 m brick wall) costs
# 9 ms a Levenberg-Marquardt step, so the longest 512 are kept, which count as
# ``max_effective_segments`` all the same
MAX_SEGMENTS = 512


@dataclass(frozen=True)
class CalibrationInput:
    """What one photo offers the fit. Segments are ``(n, 4)`` arrays of ``x1, y1, x2, y2`` pixels.

    ``corner_sigma_px``: one value for all four corners or four (LL, LR, UR, UL). Without
    ``focal_px`` the focal length has a log-normal prior (``focal_prior_px``, default a 35 mm
    equivalent of :data:`FOCAL_PRIOR_35MM`, log sigma :data:`FOCAL_PRIOR_LOG_SIGMA`). The lens's k1,
    k2 are fitted about ``k1_prior``, ``k2_prior`` (a lens profile's, or 0) with their sigmas
    (``fit_distortion=False`` holds them at the prior). ``known_length``: ``(x1, y1, x2, y2, metres)``,
    the distance on the wall between two photo points."""

    image_size: tuple[int, int]  # (width, height) in pixels
    corners_px: np.ndarray  # (4, 2), lower-left, lower-right, upper-right, upper-left
    corner_sigma_px: float | tuple[float, float, float, float] = 1.5
    bed_segments: np.ndarray = field(default_factory=lambda: np.zeros((0, 4)))
    head_segments: np.ndarray = field(default_factory=lambda: np.zeros((0, 4)))
    line_sigma_px: float = 1.0
    # Joint segments share errors (one brick's edge feeds several segments, texture biases a whole
    # course), so each family counts as at most this many independent observations.
    max_effective_segments: int = 64
    camera_height_m: float = 1.6
    camera_height_sigma_m: float = 0.1
    focal_px: float | None = None
    focal_sigma_px: float | None = None
    focal_prior_px: float | None = None
    focal_prior_log_sigma: float = FOCAL_PRIOR_LOG_SIGMA
    known_width_m: float | None = None
    known_height_m: float | None = None
    known_sigma_m: float = 0.005
    known_height_sigma_m: float | None = None  # default known_sigma_m (a course-height scale sets its own)
    known_length: tuple[float, float, float, float, float] | None = None
    known_length_sigma_m: float = 0.005
    fit_distortion: bool = True
    # long straight lines, each a cluster of points that must lie on one straight line once the
    # lens is undone (the plumb-line constraint): points (n, 2), their cluster (n,) and family
    # (n,: 0 a bed joint, 1 a head joint, 2 a straight line of the scene; for the record); see
    # plumb_lines() and calibrate.lines.straight_lines()
    plumb_points: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    plumb_cluster: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    plumb_family: np.ndarray = field(default_factory=lambda: np.zeros(0))
    plumb_sigma_px: float = 1.0
    k1_prior: float = 0.0
    k1_sigma: float = K1_PRIOR_SIGMA
    k2_prior: float = 0.0
    k2_sigma: float = K2_PRIOR_SIGMA

    def corner_sigmas(self) -> np.ndarray:
        sig = np.broadcast_to(np.asarray(self.corner_sigma_px, dtype=np.float64), (4,)).copy()
        if not (np.all(np.isfinite(sig)) and np.all(sig > 0)):
            raise InputError(f"calibration: corner sigmas {sig.tolist()} must be > 0 (pixels)")
        return sig


@dataclass(frozen=True)
class CalibrationResult(HasFit):
    """The camera fit of one photo: its :class:`~calib_masonry.calibrate.fitresult.FitResult` (unknowns
    in PARAM_NAMES order) and what the photo's geometry makes of it."""

    fit: FitResult
    rms_residual_px: float  # over corners and joint-line endpoints
    rms_corner_px: float
    rms_corner_sigma: float  # the corners' residuals in units of their sigmas (RMS)
    rms_line_px: float
    image_size: tuple[int, int]
    n_bed: int
    n_head: int
    plumb_lines: int = 0  # long joints the lens was straightened on
    plumb_rms_px: tuple[float, float] = (float("nan"), float("nan"))  # their RMS from straight: photo, lens undone
    # what the last solve used (the inlier segments and the plumb lines), for a refit that changes
    # one thing (the corners, the lens held) without choosing them again
    used: CalibrationInput | None = field(default=None, repr=False, compare=False)

    def value(self, name: str) -> float:
        return self.fit[name]

    def sigma(self, name: str) -> float:
        return self.fit.sigma(name)

    @property
    def width_m(self) -> float:
        return self.value("width_m")

    @property
    def height_m(self) -> float:
        return self.value("height_m")

    @property
    def image_from_wall(self) -> np.ndarray:
        return image_from_wall_homography(self.params, principal_point(self.image_size))

    @property
    def wall_from_image(self) -> np.ndarray:
        h = np.linalg.inv(self.image_from_wall)
        return h / h[2, 2]

    @property
    def distortion(self) -> tuple[float, float]:
        """The lens's (k1, k2), :data:`~calib_masonry.calibrate.camera.DISTORTION_MODEL`."""
        return self.value("k1"), self.value("k2")

    def distort(self, points: np.ndarray) -> np.ndarray:
        """Ideal image points ``(..., 2)`` (the homography's) -> the photo's pixels (the lens's)."""
        k1, k2 = self.distortion
        return distort(
            np.asarray(points, dtype=np.float64), self.value("focal_px"), principal_point(self.image_size), k1, k2
        )

    def undistort(self, points: np.ndarray) -> np.ndarray:
        """The photo's pixels ``(..., 2)`` -> ideal image points (the homography's)."""
        k1, k2 = self.distortion
        return undistort(
            np.asarray(points, dtype=np.float64), self.value("focal_px"), principal_point(self.image_size), k1, k2
        )

    def photo_from_wall(self, xz: np.ndarray) -> np.ndarray:
        """Wall points ``(..., 2)`` (metres) -> the photo's pixels, lens included."""
        return self.distort(project(self.image_from_wall, np.asarray(xz, dtype=np.float64)))

    def corners_px(self) -> np.ndarray:
        w, h = self.width_m, self.height_m
        return self.photo_from_wall(np.array([[0, 0], [w, 0], [w, h], [0, h]], dtype=np.float64))

    def camera_json(self) -> dict:
        return {
            "focal_px": self.value("focal_px"),
            "center_m": [self.value("cx_m"), self.value("cy_m"), self.value("cz_m")],
            "yaw_deg": math.degrees(self.value("yaw_rad")),
            "pitch_deg": math.degrees(self.value("pitch_rad")),
            "roll_deg": math.degrees(self.value("roll_rad")),
            "principal_point_px": list(principal_point(self.image_size)),
        }

    def to_json(self) -> dict:
        return {
            "width_m": self.width_m,
            "height_m": self.height_m,
            "width_sigma_m": self.sigma("width_m"),
            "height_sigma_m": self.sigma("height_m"),
            "image_to_wall": self.wall_from_image.tolist(),
            "camera": self.camera_json(),
            "rms_residual_px": self.rms_residual_px,
            "rms_corner_px": self.rms_corner_px,
            "rms_corner_sigma": self.rms_corner_sigma,
            "rms_line_px": self.rms_line_px,
            **self.fit.to_json(),
            "image_size": list(self.image_size),
            "corners_px": self.corners_px().tolist(),
            "joint_segments": {"bed": self.n_bed, "head": self.n_head},
            "plumb_lines": {
                "count": self.plumb_lines,
                "rms_from_straight_px": self.plumb_rms_px[0],
                "rms_from_straight_undistorted_px": self.plumb_rms_px[1],
            },
            "covariance_units": "px, rad, m, -",
            "distortion": {
                "model": DISTORTION_MODEL,
                "k1": self.value("k1"),
                "k2": self.value("k2"),
                "k1_sigma": self.sigma("k1"),
                "k2_sigma": self.sigma("k2"),
            },
        }


# ----------------------------------------------------------------------------------------------
# corners and the closed-form start


def homography_dlt(src: np.ndarray, dst: np.ndarray) -> np.ndarray:
    """Normalised DLT: the 3x3 ``H`` with ``dst ~ H src`` from >= 4 point pairs (least squares)."""
    src = np.asarray(src, dtype=np.float64)
    dst = np.asarray(dst, dtype=np.float64)

    def norm(p):
        c = p.mean(axis=0)
        s = math.sqrt(2) / max(np.mean(np.linalg.norm(p - c, axis=1)), 1e-12)
        return np.array([[s, 0, -s * c[0]], [0, s, -s * c[1]], [0, 0, 1.0]])

    ts, td = norm(src), norm(dst)
    a = np.c_[src, np.ones(len(src))] @ ts.T
    b = np.c_[dst, np.ones(len(dst))] @ td.T
    rows = []
    for (x, y, w), (u, v, s) in zip(a, b):
        rows.append([0, 0, 0, -s * x, -s * y, -s * w, v * x, v * y, v * w])
        rows.append([s * x, s * y, s * w, 0, 0, 0, -u * x, -u * y, -u * w])
    _, _, vt = np.linalg.svd(np.asarray(rows))
    h = np.linalg.inv(td) @ vt[-1].reshape(3, 3) @ ts
    return h / h[2, 2]


def _focal_guess(inp: CalibrationInput) -> float:
    return inp.focal_px or inp.focal_prior_px or focal_prior_px(inp.image_size)


def initial_params(inp: CalibrationInput) -> np.ndarray:
    """Closed-form start from the four corners: homography, focal from the right angle, pose, scale."""
    pp = np.array(principal_point(inp.image_size))
    unit = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], dtype=np.float64)
    g = homography_dlt(
        unit, undistort(np.asarray(inp.corners_px, np.float64), _focal_guess(inp), pp, inp.k1_prior, inp.k2_prior) - pp
    )
    f = inp.focal_px
    if f is None:
        den = g[2, 0] * g[2, 1]
        f2 = -(g[0, 0] * g[0, 1] + g[1, 0] * g[1, 1]) / den if abs(den) > 1e-15 else -1.0
        f = math.sqrt(f2) if f2 > 0 else 1.2 * max(inp.image_size)
        f = float(np.clip(f, 0.3 * max(inp.image_size), 6.0 * max(inp.image_size)))
    m = np.diag([1 / f, 1 / f, 1.0]) @ g
    if m[2, 2] < 0:
        m = -m
    a, b = np.linalg.norm(m[:, 0]), np.linalg.norm(m[:, 1])
    r1, r2 = m[:, 0] / a, m[:, 1] / b
    cam_from_wall = np.stack([r1, np.cross(r2, r1), r2], axis=1)
    u, _, vt = np.linalg.svd(cam_from_wall)
    cam_from_wall = u @ vt
    if np.linalg.det(cam_from_wall) < 0:
        cam_from_wall = u @ np.diag([1, 1, -1]) @ vt
    wall_from_cam = cam_from_wall.T
    centre_u = -wall_from_cam @ m[:, 2]
    if inp.known_width_m:
        lam = a / inp.known_width_m
    elif inp.known_height_m:
        lam = b / inp.known_height_m
    elif inp.known_length is not None:
        m_inv = np.linalg.inv(np.diag([1 / f, 1 / f, 1.0]) @ g)  # photo (centred) -> unit wall
        ends = np.c_[np.asarray(inp.known_length[:4]).reshape(2, 2) - pp, np.ones(2)] @ m_inv.T
        ends = ends[:, :2] / ends[:, 2:3]
        unit_len = math.hypot(a * (ends[1, 0] - ends[0, 0]), b * (ends[1, 1] - ends[0, 1]))
        lam = unit_len / inp.known_length[4] if unit_len > 1e-12 else a / 5.0
    else:
        lam = abs(centre_u[2]) / inp.camera_height_m if abs(centre_u[2]) > 1e-9 else a / 5.0
    yaw, pitch, roll = angles_from_rotation(wall_from_cam)
    c = centre_u / lam
    return np.array([f, yaw, pitch, roll, c[0], c[1], c[2], a / lam, b / lam, inp.k1_prior, inp.k2_prior])


# ----------------------------------------------------------------------------------------------
# residuals (JAX)


def _capped(seg) -> np.ndarray:
    """At most MAX_SEGMENTS segments, the longest."""
    seg = np.asarray(seg, dtype=np.float64).reshape(-1, 4)
    if len(seg) > MAX_SEGMENTS:
        length = np.hypot(seg[:, 2] - seg[:, 0], seg[:, 3] - seg[:, 1])
        seg = seg[np.argsort(-length)[:MAX_SEGMENTS]]
    return seg


def _pad_segments(seg: np.ndarray, sigma: float, n_eff: int) -> tuple[np.ndarray, np.ndarray]:
    seg = _capped(seg)
    n = MAX_SEGMENTS
    out = np.zeros((n, 4))
    w = np.zeros(n)
    out[: len(seg)] = seg
    w[: len(seg)] = math.sqrt(2.0) / sigma * math.sqrt(min(1.0, n_eff / max(len(seg), 1)))
    return out, w


#: plumb-line clusters: at most this many long joints, each of at most PLUMB_POINTS_PER_LINE points
#: (evenly spaced: a line's straightness needs no more) counting as at most PLUMB_EFFECTIVE points
MAX_PLUMB_LINES = 96
PLUMB_EFFECTIVE = 12
PLUMB_POINTS_PER_LINE = 16
MAX_PLUMB_POINTS = MAX_PLUMB_LINES * PLUMB_POINTS_PER_LINE


#: how straight a straight line of a real scene is, as a sagitta over its length: a loaded beam may
#: bow by L/250-L/500 (the serviceability limits of EN 1993-1-1 and EN 1995-1-1), a member by
#: L/750-L/1000 as made (EN 1090-2), a masonry joint by more. Each plumb line's points get
#: sigma = hypot(plumb_sigma_px, PLUMB_STRAIGHTNESS * its length): with the 12 points a line counts
#: as, that is about the sigma of its sagitta. Without it a line's pixel noise was the only doubt,
#: so the same photo with more pixels straightened the same beam more surely: the laboratory
#: photo SC4 at 2, 4 and 8 times its pixels kept a lens (k1 -0.084, -0.054, -0.036) from its
#: loading beam's two edges and gave H 8 % short at 4 sigma (at its own size the lens was held).
PLUMB_STRAIGHTNESS = 1 / 500


def _spans(pts: np.ndarray, cl: np.ndarray) -> np.ndarray:
    """Each cluster's length (px): the largest distance of its points from one another, by cluster
    index (0 where a cluster has no points)."""
    out = np.zeros(int(cl.max()) + 1 if len(cl) else 0)
    for k in np.unique(cl):
        p = pts[cl == k]
        out[k] = float(np.max(np.linalg.norm(p[:, None, :] - p[None, :, :], axis=-1)))
    return out


def _pad_plumb(inp: CalibrationInput):
    """The plumb-line points padded to :data:`MAX_PLUMB_POINTS`: points (n, 2), weights (n,)
    (1 / sigma, shrunk so that a cluster counts as at most :data:`PLUMB_EFFECTIVE` points; 0 =
    padding), cluster index (n,) as float (JAX's segment sums take it cast) and family (n,)."""
    pts = np.asarray(inp.plumb_points, dtype=np.float64).reshape(-1, 2)
    cl = np.asarray(inp.plumb_cluster, dtype=np.int64).ravel()
    fam = np.asarray(inp.plumb_family, dtype=np.float64).ravel()
    keep = cl < MAX_PLUMB_LINES
    for k in np.unique(cl[keep]):  # each cluster thinned to PLUMB_POINTS_PER_LINE, evenly
        idx = np.flatnonzero(cl == k)
        if len(idx) > PLUMB_POINTS_PER_LINE:
            chosen = idx[np.round(np.linspace(0, len(idx) - 1, PLUMB_POINTS_PER_LINE)).astype(int)]
            keep[np.setdiff1d(idx, chosen)] = False
    pts, cl, fam = pts[keep], cl[keep], fam[keep]
    n = MAX_PLUMB_POINTS
    pts, cl, fam = pts[:n], cl[:n], fam[:n]
    out = np.zeros((n, 2))
    w = np.zeros(n)
    c = np.full(n, float(MAX_PLUMB_LINES - 1))
    f = np.zeros(n)
    out[: len(pts)] = pts
    if len(pts):
        counts = np.bincount(cl, minlength=MAX_PLUMB_LINES).astype(np.float64)
        sigma = np.hypot(inp.plumb_sigma_px, PLUMB_STRAIGHTNESS * _spans(pts, cl)[cl])
        w[: len(pts)] = np.sqrt(np.minimum(1.0, PLUMB_EFFECTIVE / counts[cl])) / sigma
        c[: len(pts)] = cl
        f[: len(pts)] = fam
    return out, w, c, f


def pack(inp: CalibrationInput) -> dict:
    """The fit's data as fixed-shape float64 arrays (weights = 1 / sigma, 0 = absent)."""
    if inp.corners_px is None or np.shape(inp.corners_px) != (4, 2):
        raise InputError("calibration: four wall corners are needed (clicked with --corners or detected)")
    bed, bed_w = _pad_segments(inp.bed_segments, inp.line_sigma_px, inp.max_effective_segments)
    head, head_w = _pad_segments(inp.head_segments, inp.line_sigma_px, inp.max_effective_segments)
    f0 = inp.focal_px or 0.0
    f_sigma = inp.focal_sigma_px if inp.focal_sigma_px else (0.002 * f0 if f0 else None)
    f_prior = inp.focal_prior_px or focal_prior_px(inp.image_size)
    # held: a sigma of 1e-3 (a tighter one made J^T J singular by its condition number)
    k_w = (1.0 / inp.k1_sigma, 1.0 / inp.k2_sigma) if inp.fit_distortion else (1e3, 1e3)
    length = inp.known_length
    h_sigma = inp.known_height_sigma_m or inp.known_sigma_m
    prior = np.array(
        [
            inp.camera_height_m,
            1.0 / inp.camera_height_sigma_m,
            f0,
            1.0 / f_sigma if inp.focal_px else 0.0,
            inp.known_width_m or 0.0,
            1.0 / inp.known_sigma_m if inp.known_width_m else 0.0,
            inp.known_height_m or 0.0,
            1.0 / h_sigma if inp.known_height_m else 0.0,
            math.log(f_prior),
            0.0 if inp.focal_px else 1.0 / inp.focal_prior_log_sigma,
            inp.k1_prior,
            k_w[0],
            inp.k2_prior,
            k_w[1],
            length[4] if length is not None else 0.0,
            1.0 / inp.known_length_sigma_m if length is not None else 0.0,
        ]
    )
    plumb, plumb_w, plumb_c, plumb_f = _pad_plumb(inp)
    return {
        "pp": np.array(principal_point(inp.image_size)),
        "corners": np.asarray(inp.corners_px, dtype=np.float64),
        "corner_w": 1.0 / inp.corner_sigmas(),
        "plumb": plumb,
        "plumb_w": plumb_w,
        "plumb_cluster": plumb_c,
        "plumb_family": plumb_f,
        "bed": bed,
        "bed_w": bed_w,
        "head": head,
        "head_w": head_w,
        "prior": prior,
        "length_px": np.asarray(length[:4] if length is not None else (0.0, 0.0, 1.0, 0.0), dtype=np.float64),
    }


def _line_distances(vp, seg, xp=jnp):
    """Signed distance of each segment's first endpoint from the line through its midpoint and ``vp``
    (``xp``: jax.numpy inside the fit, numpy outside it, where eager JAX would compile every call)."""
    p1 = xp.concatenate([seg[:, :2], xp.ones((seg.shape[0], 1))], axis=1)
    mid = xp.concatenate([(seg[:, :2] + seg[:, 2:]) / 2, xp.ones((seg.shape[0], 1))], axis=1)
    line = xp.cross(mid, xp.broadcast_to(vp, mid.shape))
    norm = xp.sqrt(line[:, 0] ** 2 + line[:, 1] ** 2 + 1e-300)
    return xp.sum(line * p1, axis=1) / norm


def _ideal_points(params, data):
    """Every observed photo point the fit uses -> ideal pinhole points, by the fitted lens (k1,
    k2), in one call (one lens model in the fit's code, not six): the corners ``(4, 2)``, the bed
    and head segments ``(n, 4)`` and the known length's two ends ``(2, 2)``."""
    nb, nh = data["bed"].shape[0], data["head"].shape[0]
    pts = jnp.concatenate(
        [
            data["corners"],
            data["bed"][:, :2],
            data["bed"][:, 2:],
            data["head"][:, :2],
            data["head"][:, 2:],
            data["length_px"].reshape(2, 2),
            data["plumb"],
        ]
    )
    ideal = undistort(pts, params[0], data["pp"], params[9], params[10], jnp)
    corners, ideal = ideal[:4], ideal[4:]
    bed = jnp.concatenate([ideal[:nb], ideal[nb : 2 * nb]], axis=1)
    ideal = ideal[2 * nb :]
    head = jnp.concatenate([ideal[:nh], ideal[nh : 2 * nh]], axis=1)
    ideal = ideal[2 * nh :]
    return corners, bed, head, ideal[:2], ideal[2:]


def _plumb_residuals(params, data, ideal):
    """Each plumb-line point's distance (px, times its weight) from the straight line fitted to its
    cluster (through the weighted centroid along the principal axis), all in ideal (lens undone)
    coordinates: a long joint's or a beam's curvature in the photo is what k1, k2 must explain.
    Only straightness: the direction is each line's own, so that the clusters, made of the same
    joints as the segments, do not count the vanishing points a second time (lines forced through
    them pulled a tall wall's fit to a camera 33 km away, measured)."""
    w = data["plumb_w"]
    cl = data["plumb_cluster"].astype(jnp.int32)
    tot = jax.ops.segment_sum(w, cl, num_segments=MAX_PLUMB_LINES)
    cen = jax.ops.segment_sum(ideal * w[:, None], cl, num_segments=MAX_PLUMB_LINES) / jnp.maximum(tot, 1e-12)[:, None]
    d = ideal - cen[cl]
    sxx = jax.ops.segment_sum(w * d[:, 0] ** 2, cl, num_segments=MAX_PLUMB_LINES)
    syy = jax.ops.segment_sum(w * d[:, 1] ** 2, cl, num_segments=MAX_PLUMB_LINES)
    sxy = jax.ops.segment_sum(w * d[:, 0] * d[:, 1], cl, num_segments=MAX_PLUMB_LINES)
    # an empty cluster (the padding's) gets a fixed direction, so that no 0/0 reaches a derivative
    used = tot > 0
    angle = 0.5 * jnp.arctan2(jnp.where(used, 2.0 * sxy, 0.0), jnp.where(used, sxx - syy, 1.0))
    return (-d[:, 0] * jnp.sin(angle)[cl] + d[:, 1] * jnp.cos(angle)[cl]) * w


def _parts(params, data, ideal=None):
    corners_obs, bed_obs, head_obs, _, _ = _ideal_points(params, data) if ideal is None else ideal
    h = image_from_wall_homography(params, data["pp"], jnp)
    w, ht = params[7], params[8]
    zero = jnp.zeros(())
    corners = jnp.stack([jnp.stack([zero, zero]), jnp.stack([w, zero]), jnp.stack([w, ht]), jnp.stack([zero, ht])])
    corner_px = project(h, corners, jnp) - corners_obs
    bed = _line_distances(h[:, 0], bed_obs)
    head = _line_distances(h[:, 1], head_obs)
    return corner_px, bed, head


def _known_length(params, data, ends):
    """The wall distance between the two (ideal) photo points ``ends`` ``(2, 2)`` (metres)."""
    h = image_from_wall_homography(params, data["pp"], jnp)
    # the inverse map up to scale: the adjugate (elementwise, so the exported and the jitted
    # fit compile it alike, where a LAPACK inverse did not, to 1e-10)
    adj = jnp.stack([jnp.cross(h[:, 1], h[:, 2]), jnp.cross(h[:, 2], h[:, 0]), jnp.cross(h[:, 0], h[:, 1])])
    wall = project(adj, ends, jnp)
    return jnp.sqrt(jnp.sum((wall[1] - wall[0]) ** 2) + 1e-30)


#: the joint segments' residuals count by Cauchy's loss beyond this many sigmas: a stone's slanted
#: edge, a crack or a beam's edge taken for a joint weighs little instead of bending the camera
#: (on the laboratory photos, irregular joints and cracks drove the focal length to 200 px)
ROBUST_SCALE = 2.0


def _cauchy(r, c=ROBUST_SCALE):
    """Residuals ``r`` (in sigmas) mapped so that their squares sum to Cauchy's loss
    ``c^2 log(1 + (r / c)^2)``: ``r`` itself near zero, growing as ``sqrt(log)`` far out; smooth at
    zero (a padded segment's exact zero too)."""
    q = (r / c) ** 2
    small = q < 1e-8
    safe = jnp.where(small, 1.0, q)
    ratio = jnp.where(small, 1.0 - 0.5 * q, jnp.log1p(safe) / safe)
    return r * jnp.sqrt(ratio)


def residual_vector(u, data):
    """All residuals, in units of their noise, at scaled parameters ``u = params / SCALE`` (the joint
    segments' through :func:`_cauchy`)."""
    params = u * SCALE
    ideal = _ideal_points(params, data)
    corner_px, bed, head = _parts(params, data, ideal)
    pr = data["prior"]
    priors = jnp.stack(
        [
            (params[6] - pr[0]) * pr[1],
            (params[0] - pr[2]) * pr[3],
            (params[7] - pr[4]) * pr[5],
            (params[8] - pr[6]) * pr[7],
            (jnp.log(jnp.maximum(params[0], 1.0)) - pr[8]) * pr[9],
            (params[9] - pr[10]) * pr[11],
            (params[10] - pr[12]) * pr[13],
            (_known_length(params, data, ideal[3]) - pr[14]) * pr[15],
        ]
    )
    return jnp.concatenate(
        [
            (corner_px * data["corner_w"][:, None]).ravel(),
            _cauchy(bed * data["bed_w"]),
            _cauchy(head * data["head_w"]),
            _cauchy(_plumb_residuals(params, data, ideal[4])),
            priors,
        ]
    )


def _solve_fn(u0, data):
    u, ok, steps, jac, r = least_squares(residual_vector, u0, data)
    corner_px, bed, head = _parts(u * SCALE, data)
    return u, ok, steps, jac, r, corner_px, bed, head


@cache
def _solver():
    """:func:`_solve_fn` exported once for the padded shapes and kept on disk
    (:func:`calib_masonry._jax.exported`): tracing optimistix's Levenberg-Marquardt and its
    Jacobian took 1-2 s of every process that fitted a photo (the solve itself takes
    milliseconds). It returns the jitted function's parameters, status and Jacobian bit for bit,
    and its residuals to rounding (test)."""
    from pathlib import Path

    from .. import _jax
    from . import camera, lm

    nb = nh = MAX_SEGMENTS
    npl = MAX_PLUMB_POINTS

    def spec(*shape):
        return jax.ShapeDtypeStruct(shape, jnp.float64)

    data = {
        "pp": spec(2),
        "corners": spec(4, 2),
        "corner_w": spec(4),
        "bed": spec(nb, 4),
        "bed_w": spec(nb),
        "head": spec(nh, 4),
        "head_w": spec(nh),
        "prior": spec(16),
        "length_px": spec(4),
        "plumb": spec(npl, 2),
        "plumb_w": spec(npl),
        "plumb_cluster": spec(npl),
        "plumb_family": spec(npl),
    }
    sources = [Path(__file__), Path(camera.__file__), Path(lm.__file__)]
    return _jax.exported("camera-fit", _solve_fn, (spec(len(SCALE)), data), sources=sources)


def _solve(u0, data):
    return _solver().call(u0, data)


def _inliers(seg: np.ndarray, dist: np.ndarray) -> np.ndarray:
    """Segments whose endpoint distance is within 3 robust sigmas (and 3 px) of the fitted line."""
    if len(seg) == 0:
        return seg
    d = np.abs(dist[: len(seg)])
    cut = max(3.0, 3.0 * 1.4826 * float(np.median(d)))
    return seg[d <= cut]


def _singular_advice(inp: CalibrationInput) -> str:
    """What to add when the fit is singular: the focal length if it was not given, else what pins
    the wall (a measured side, or corners clicked where the wall's outline is unclear); telling a
    user who gave the focal length and the eye height to give them was no help (tall wall seed
    10209: a base corner found 20 px off made the fit singular; --known-width fitted it)."""
    if inp.focal_px is None:
        return "pass --focal-px (and --camera-height), or give a photo with visible mortar joints"
    return f"pass --known-width or --known-height, or click the wall's corners with {CORNERS_FLAG}"


def _wiggle(points: np.ndarray) -> float:
    """RMS distance (px) of points ``(n, 2)`` from the parabola fitted along their principal
    direction: a lens bends a straight joint into (nearly) a parabola, an irregular course wiggles."""
    d = points - points.mean(axis=0)
    _, _, vt = np.linalg.svd(d, full_matrices=False)
    t, y = d @ vt[0], d @ vt[1]
    if len(t) < 4:
        return 0.0
    a = np.c_[np.ones_like(t), t, t * t]
    coef, *_ = np.linalg.lstsq(a, y, rcond=None)
    return float(np.sqrt(np.mean((y - a @ coef) ** 2)))


def plumb_lines(
    first: "CalibrationResult",
    bed: np.ndarray,
    head: np.ndarray,
    *,
    tol_px: float = 4.0,
    min_span: float = 0.3,
    max_wiggle_px: float = 1.5,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Long joints for the plumb-line constraint: the bed segments (``(n, 4)`` photo pixels) that lie
    on one course's joint (their middles within ``tol_px`` of each other across the wall, in the
    wall's frame of a first fit ``first``) and together span ``min_span`` of the wall's width, and
    the head segments likewise along its height; a cluster that wiggles more than
    ``max_wiggle_px`` about a parabola (:func:`_wiggle`: irregular stones, a crack) is left out.
    Returns the points (each segment's ends and middle, photo pixels), their cluster and family
    (0 bed, 1 head)."""
    from .camera import px_per_m as local_px_per_m

    pts_out, cl_out, fam_out = [], [], []
    k = 0
    wall_from_image = first.wall_from_image
    span_of = (first.width_m, first.height_m)
    for fam, seg in ((0, bed), (1, head)):
        seg = np.asarray(seg, dtype=np.float64).reshape(-1, 4)
        if len(seg) < 3:
            continue
        ends = first.undistort(seg.reshape(-1, 2))
        xz = project(wall_from_image, ends).reshape(-1, 2, 2)
        across = xz[:, :, 1 - fam].mean(axis=1)  # z of a bed joint, x of a head joint
        along = xz[:, :, fam]
        scale = local_px_per_m(first.image_from_wall, xz.mean(axis=1))
        tol = tol_px / np.maximum(scale, 1e-9)
        # a joint's pieces chain: two segments are of one joint when they lie side by side along
        # it (their gap within a tenth of the wall) and within tol_px of each other across it, so
        # a joint a lens bows (20 px and more from end to end) still forms one chain
        lo, hi = along.min(axis=1), along.max(axis=1)
        gap = np.maximum(lo[:, None], lo[None, :]) - np.minimum(hi[:, None], hi[None, :])
        # and only edges of one polarity (LSD keeps the dark side on one hand of a segment's
        # direction): the two edges of a thin joint, a few pixels apart, stay two lines
        run = seg[:, 2 + fam] - seg[:, fam]  # along x for a bed segment, y for a head one
        polarity = np.sign(run)
        near = (
            (np.abs(across[:, None] - across[None, :]) <= np.maximum(tol[:, None], tol[None, :]))
            & (gap <= 0.1 * span_of[fam])
            & (polarity[:, None] == polarity[None, :])
        )
        from scipy.sparse.csgraph import connected_components

        _, label = connected_components(near, directed=False)
        groups = [np.nonzero(label == c)[0] for c in range(label.max() + 1)]
        for g in groups:
            g = np.array(g)
            extent = float(along[g].max() - along[g].min())
            if len(g) < 3 or extent < min_span * span_of[fam] or k >= MAX_PLUMB_LINES - 1:
                continue
            s_ = seg[g]
            mids = (s_[:, :2] + s_[:, 2:]) / 2
            p = np.concatenate([s_[:, :2], mids, s_[:, 2:]])
            if _wiggle(p) > max_wiggle_px:
                continue  # an irregular stone course or a crack: not a straight joint
            pts_out.append(p)
            cl_out.append(np.full(len(p), k))
            fam_out.append(np.full(len(p), float(fam)))
            k += 1
    if not pts_out:
        return np.zeros((0, 2)), np.zeros(0, dtype=np.int64), np.zeros(0)
    return np.concatenate(pts_out), np.concatenate(cl_out), np.concatenate(fam_out)


def straightness_rms(points: np.ndarray, cluster: np.ndarray) -> float:
    """The RMS distance (px) of ``points`` from the straight line fitted (total least squares) to
    each of their ``cluster``'s points: how far the long joints are from straight lines."""
    sq, n = 0.0, 0
    for c in np.unique(cluster):
        p = points[cluster == c]
        if len(p) < 3:
            continue
        d = p - p.mean(axis=0)
        _, sv, _ = np.linalg.svd(d, full_matrices=False)
        sq += float(sv[-1] ** 2)
        n += len(p)
    return math.sqrt(sq / n) if n else float("nan")


def warm_up() -> None:
    """Load the exported fit and run it once on a made-up photo (a square wall seen head-on), so
    that its one-off cost (0.6 s of loading its compiled code, measured) is paid here, on a thread
    that runs while the photo is searched, not by the first fit."""
    inp = CalibrationInput(
        image_size=(400, 300),
        corners_px=np.array([[150.0, 250.0], [250.0, 250.0], [250.0, 150.0], [150.0, 150.0]]),
        camera_height_m=1.0,
        focal_px=400.0,
    )
    data = pack(inp)
    out = _solve(jnp.asarray(initial_params(inp) / SCALE), {k: jnp.asarray(v) for k, v in data.items()})
    jax.block_until_ready(out)


def calibrate(
    inp: CalibrationInput, *, start: np.ndarray | None = None, reject_outliers: bool = True
) -> CalibrationResult:
    """Fit one photo. Raises FitFailed when the data cannot determine the camera.

    With ``reject_outliers`` the fit runs twice: joint segments more than three robust sigmas
    from their vanishing point after the first fit (a stone's slanted edge, a crack, a segment of
    the background) are dropped before the second."""
    if reject_outliers and (len(inp.bed_segments) or len(inp.head_segments)):
        first = calibrate(inp, start=start, reject_outliers=False)
        bed, head = _capped(inp.bed_segments), _capped(inp.head_segments)
        own_plumb = inp.fit_distortion
        given = (inp.plumb_points, inp.plumb_cluster, inp.plumb_family)
        # with the lens fitted, twice: a strong lens bends the far joints off the first fit's
        # vanishing lines, so the first cut drops what tells the lens; the second, from a fit that
        # has straightened the long joints, keeps them
        for last in (False, True) if own_plumb else (True,):
            h = first.image_from_wall

            def ideal(seg, fit=first):
                return fit.undistort(seg.reshape(-1, 2)).reshape(-1, 4)

            d_bed = _line_distances(h[:, 0], ideal(bed), np) if len(bed) else np.zeros(0)
            d_head = _line_distances(h[:, 1], ideal(head), np) if len(head) else np.zeros(0)
            step = replace(inp, bed_segments=_inliers(bed, d_bed), head_segments=_inliers(head, d_head))
            if own_plumb:
                pts, cl, fam = plumb_lines(first, step.bed_segments, step.head_segments)
                base = int(np.max(given[1])) + 1 if len(given[1]) else 0
                step = replace(
                    step,
                    plumb_points=np.concatenate([np.reshape(given[0], (-1, 2)), pts]),
                    plumb_cluster=np.concatenate([np.asarray(given[1], dtype=np.int64), cl + base]),
                    plumb_family=np.concatenate([np.asarray(given[2], dtype=np.float64), fam]),
                )
            if last:
                inp = step
                break
            first = calibrate(step, start=first.params, reject_outliers=False)
        start = first.params
    data = pack(inp)
    p0 = initial_params(inp) if start is None else np.asarray(start, dtype=np.float64)
    u, ok, steps, jac, residuals, corner_px, bed, head = _solve(
        jnp.asarray(p0 / SCALE), {k: jnp.asarray(v) for k, v in data.items()}
    )
    fit = fit_result(u, ok, steps, jac, residuals, PARAM_NAMES, SCALE)
    if fit.status is FitStatus.DIVERGED:
        raise FitFailed(
            f"calibration: the fit {fit.status.message}; check the corners and pass --focal-px or --camera-height"
        )
    if fit.status is FitStatus.SINGULAR:
        raise FitFailed(
            f"calibration: too few constraints to fit the camera (singular Jacobian); {_singular_advice(inp)}"
        )
    nb, nh = min(len(inp.bed_segments), MAX_SEGMENTS), min(len(inp.head_segments), MAX_SEGMENTS)
    corner_px = np.asarray(corner_px)
    # each segment's endpoint distance, both endpoints
    lines = np.concatenate([np.asarray(bed)[:nb], np.asarray(head)[:nh]])
    sq = np.concatenate([np.sum(corner_px**2, axis=1), np.repeat(lines**2, 2)])
    rms_line = float(np.sqrt(np.mean(lines**2))) if len(lines) else 0.0
    result = CalibrationResult(
        fit=fit,
        rms_residual_px=float(np.sqrt(np.mean(sq))),
        rms_corner_px=float(np.sqrt(np.mean(np.sum(corner_px**2, axis=1)))),
        rms_corner_sigma=float(np.sqrt(np.mean(np.sum(corner_px**2, axis=1) / inp.corner_sigmas() ** 2 / 2))),
        rms_line_px=rms_line,
        image_size=tuple(int(v) for v in inp.image_size),
        n_bed=nb,
        n_head=nh,
        used=inp,
    )
    if len(inp.plumb_points):
        pts, cl = np.asarray(inp.plumb_points), np.asarray(inp.plumb_cluster)
        result = replace(
            result,
            plumb_lines=int(len(np.unique(cl))),
            plumb_rms_px=(straightness_rms(pts, cl), straightness_rms(result.undistort(pts), cl)),
        )
    return result

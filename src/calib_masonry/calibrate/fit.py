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
    PARAM_NAMES,
    angles_from_rotation,
    image_from_wall_homography,
    order_corners,
    principal_point,
    project,
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
SCALE = np.array([1000.0, 0.1, 0.1, 0.1, 1.0, 1.0, 1.0, 1.0, 1.0])
# padded segment counts: each is one compilation of the exported fit (a photo with no segments
# pads to the first; padding has weight 0, so it adds exact zeros to every sum)
_BUCKETS = (16, 64, 256, 1024)
MAX_SEGMENTS = _BUCKETS[-1]


@dataclass(frozen=True)
class CalibrationInput:
    """What one photo offers the fit. Segments are ``(n, 4)`` arrays of ``x1, y1, x2, y2`` pixels."""

    image_size: tuple[int, int]  # (width, height) in pixels
    corners_px: np.ndarray  # (4, 2), lower-left, lower-right, upper-right, upper-left
    corner_sigma_px: float = 1.5
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
    known_width_m: float | None = None
    known_height_m: float | None = None
    known_sigma_m: float = 0.005


@dataclass(frozen=True)
class CalibrationResult(HasFit):
    """The camera fit of one photo: its :class:`~calib_masonry.calibrate.fitresult.FitResult` (unknowns
    in PARAM_NAMES order) and what the photo's geometry makes of it."""

    fit: FitResult
    rms_residual_px: float  # over corners and joint-line endpoints
    rms_corner_px: float
    rms_line_px: float
    image_size: tuple[int, int]
    n_bed: int
    n_head: int

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

    def corners_px(self) -> np.ndarray:
        w, h = self.width_m, self.height_m
        return project(self.image_from_wall, np.array([[0, 0], [w, 0], [w, h], [0, h]], dtype=np.float64))

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
            "rms_line_px": self.rms_line_px,
            **self.fit.to_json(),
            "image_size": list(self.image_size),
            "corners_px": self.corners_px().tolist(),
            "joint_segments": {"bed": self.n_bed, "head": self.n_head},
            "covariance_units": "px, rad, m",
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


def initial_params(inp: CalibrationInput) -> np.ndarray:
    """Closed-form start from the four corners: homography, focal from the right angle, pose, scale."""
    pp = np.array(principal_point(inp.image_size))
    unit = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], dtype=np.float64)
    g = homography_dlt(unit, inp.corners_px - pp)
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
    else:
        lam = abs(centre_u[2]) / inp.camera_height_m if abs(centre_u[2]) > 1e-9 else a / 5.0
    yaw, pitch, roll = angles_from_rotation(wall_from_cam)
    c = centre_u / lam
    return np.array([f, yaw, pitch, roll, c[0], c[1], c[2], a / lam, b / lam])


# ----------------------------------------------------------------------------------------------
# residuals (JAX)


def _bucket(n: int) -> int:
    for b in _BUCKETS:
        if n <= b:
            return b
    return _BUCKETS[-1]


def _capped(seg) -> np.ndarray:
    """At most MAX_SEGMENTS segments, the longest."""
    seg = np.asarray(seg, dtype=np.float64).reshape(-1, 4)
    if len(seg) > MAX_SEGMENTS:
        length = np.hypot(seg[:, 2] - seg[:, 0], seg[:, 3] - seg[:, 1])
        seg = seg[np.argsort(-length)[:MAX_SEGMENTS]]
    return seg


def _pad_segments(seg: np.ndarray, sigma: float, n_eff: int) -> tuple[np.ndarray, np.ndarray]:
    seg = _capped(seg)
    n = _bucket(len(seg))
    out = np.zeros((n, 4))
    w = np.zeros(n)
    out[: len(seg)] = seg
    w[: len(seg)] = math.sqrt(2.0) / sigma * math.sqrt(min(1.0, n_eff / max(len(seg), 1)))
    return out, w


def pack(inp: CalibrationInput) -> dict:
    """The fit's data as fixed-shape float64 arrays (weights = 1 / sigma, 0 = absent)."""
    if inp.corners_px is None or np.shape(inp.corners_px) != (4, 2):
        raise InputError("calibration: four wall corners are needed (clicked with --corners or detected)")
    bed, bed_w = _pad_segments(inp.bed_segments, inp.line_sigma_px, inp.max_effective_segments)
    head, head_w = _pad_segments(inp.head_segments, inp.line_sigma_px, inp.max_effective_segments)
    f0 = inp.focal_px or 0.0
    f_sigma = inp.focal_sigma_px if inp.focal_sigma_px else (0.002 * f0 if f0 else None)
    prior = np.array(
        [
            inp.camera_height_m,
            1.0 / inp.camera_height_sigma_m,
            f0,
            1.0 / f_sigma if inp.focal_px else 0.0,
            inp.known_width_m or 0.0,
            1.0 / inp.known_sigma_m if inp.known_width_m else 0.0,
            inp.known_height_m or 0.0,
            1.0 / inp.known_sigma_m if inp.known_height_m else 0.0,
        ]
    )
    return {
        "pp": np.array(principal_point(inp.image_size)),
        "corners": np.asarray(inp.corners_px, dtype=np.float64),
        "corner_w": np.full(4, 1.0 / inp.corner_sigma_px),
        "bed": bed,
        "bed_w": bed_w,
        "head": head,
        "head_w": head_w,
        "prior": prior,
    }


def _line_distances(vp, seg, xp=jnp):
    """Signed distance of each segment's first endpoint from the line through its midpoint and ``vp``
    (``xp``: jax.numpy inside the fit, numpy outside it, where eager JAX would compile every call)."""
    p1 = xp.concatenate([seg[:, :2], xp.ones((seg.shape[0], 1))], axis=1)
    mid = xp.concatenate([(seg[:, :2] + seg[:, 2:]) / 2, xp.ones((seg.shape[0], 1))], axis=1)
    line = xp.cross(mid, xp.broadcast_to(vp, mid.shape))
    norm = xp.sqrt(line[:, 0] ** 2 + line[:, 1] ** 2 + 1e-300)
    return xp.sum(line * p1, axis=1) / norm


def _parts(params, data):
    h = image_from_wall_homography(params, data["pp"], jnp)
    w, ht = params[7], params[8]
    zero = jnp.zeros(())
    corners = jnp.stack([jnp.stack([zero, zero]), jnp.stack([w, zero]), jnp.stack([w, ht]), jnp.stack([zero, ht])])
    corner_px = project(h, corners, jnp) - data["corners"]
    bed = _line_distances(h[:, 0], data["bed"])
    head = _line_distances(h[:, 1], data["head"])
    return corner_px, bed, head


def residual_vector(u, data):
    """All residuals, in units of their noise, at scaled parameters ``u = params / SCALE``."""
    params = u * SCALE
    corner_px, bed, head = _parts(params, data)
    pr = data["prior"]
    priors = jnp.stack(
        [
            (params[6] - pr[0]) * pr[1],
            (params[0] - pr[2]) * pr[3],
            (params[7] - pr[4]) * pr[5],
            (params[8] - pr[6]) * pr[7],
        ]
    )
    return jnp.concatenate(
        [(corner_px * data["corner_w"][:, None]).ravel(), bed * data["bed_w"], head * data["head_w"], priors]
    )


def _solve_fn(u0, data):
    u, ok, steps, jac, r = least_squares(residual_vector, u0, data)
    corner_px, bed, head = _parts(u * SCALE, data)
    return u, ok, steps, jac, r, corner_px, bed, head


@cache
def _solver():
    """:func:`_solve_fn` exported once for any number of bed and head segments and kept on disk
    (:func:`calib_masonry._jax.exported`): tracing optimistix's Levenberg-Marquardt and its
    Jacobian took 1-2 s of every process that fitted a photo (the solve itself takes
    milliseconds). It returns the jitted function's parameters, status and Jacobian bit for bit,
    and its residuals to rounding (test)."""
    from pathlib import Path

    from jax import export

    from .. import _jax
    from . import camera, lm

    nb, nh = export.symbolic_shape("nb, nh")

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
        "prior": spec(8),
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


def calibrate(
    inp: CalibrationInput, *, start: np.ndarray | None = None, reject_outliers: bool = True
) -> CalibrationResult:
    """Fit one photo. Raises FitFailed when the data cannot determine the camera.

    With ``reject_outliers`` the fit runs twice: joint segments more than three robust sigmas
    from their vanishing point after the first fit (a stone's slanted edge, a crack, a segment of
    the background) are dropped before the second."""
    if reject_outliers and (len(inp.bed_segments) or len(inp.head_segments)):
        first = calibrate(inp, start=start, reject_outliers=False)
        h = first.image_from_wall
        bed, head = _capped(inp.bed_segments), _capped(inp.head_segments)
        d_bed = _line_distances(h[:, 0], bed, np) if len(bed) else np.zeros(0)
        d_head = _line_distances(h[:, 1], head, np) if len(head) else np.zeros(0)
        inp = replace(inp, bed_segments=_inliers(bed, d_bed), head_segments=_inliers(head, d_head))
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
    return CalibrationResult(
        fit=fit,
        rms_residual_px=float(np.sqrt(np.mean(sq))),
        rms_corner_px=float(np.sqrt(np.mean(np.sum(corner_px**2, axis=1)))),
        rms_line_px=rms_line,
        image_size=tuple(int(v) for v in inp.image_size),
        n_bed=nb,
        n_head=nh,
    )

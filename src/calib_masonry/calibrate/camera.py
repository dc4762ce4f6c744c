"""A pinhole camera looking at a wall: rotations, the image-from-wall homography and its pieces.

Frames. Wall: x along the wall from its lower-left corner (seen from outside), z up, y into the
wall, so the outer face is the plane y = 0 and a camera outside has y < 0. Camera (OpenCV): x
right, y down, z forward. Image: (x = column, y = row) pixels, origin top-left, pixel centres at
integers. The principal point is the image centre ``((w - 1) / 2, (h - 1) / 2)``.

Angles (radians inside, degrees only in files): at yaw = pitch = roll = 0 the camera looks
straight at the wall along +y with its image rows horizontal. ``yaw`` turns the view towards +x
(the camera's forward direction is ``(sin yaw cos pitch, cos yaw cos pitch, sin pitch)`` in the
wall frame), ``pitch`` tilts it up, ``roll`` turns the image about the optical axis.

Every function takes ``xp`` (numpy or jax.numpy) so the same formulas serve the synthetic renderer
(numpy) and the differentiable fit (JAX).
"""

from __future__ import annotations

import math

import numpy as np

from ..errors import InputError

__all__ = [
    "DISTORTION_MODEL",
    "PARAM_NAMES",
    "angles_from_rotation",
    "distort",
    "focal_px_from_35mm",
    "focal_prior_px",
    "FOCAL_PRIOR_35MM",
    "FOCAL_PRIOR_LOG_SIGMA",
    "heading_from_theta",
    "image_from_wall_homography",
    "intrinsics",
    "normalise_homography",
    "order_corners",
    "principal_point",
    "project",
    "theta_from_heading",
    "undistort",
    "wall_from_camera_rotation",
]

#: The calibration parameter vector, in this order (SI and radians; k1, k2 without units).
PARAM_NAMES = (
    "focal_px",
    "yaw_rad",
    "pitch_rad",
    "roll_rad",
    "cx_m",
    "cy_m",
    "cz_m",
    "width_m",
    "height_m",
    "k1",
    "k2",
)

#: The lens model, as written to calibration.json.
DISTORTION_MODEL = (
    "radial (Brown-Conrady, OpenCV's k1, k2): x_d = x_u (1 + k1 r^2 + k2 r^4), x = (pixel - principal point) / focal_px, "
    "r^2 = x_u . x_u"
)


def principal_point(image_size: tuple[int, int]) -> tuple[float, float]:
    """Image centre of an image ``(width, height)`` in pixels."""
    w, h = image_size
    return (w - 1) / 2.0, (h - 1) / 2.0


def intrinsics(focal_px, pp, xp=np):
    return xp.array([[focal_px, 0.0, pp[0]], [0.0, focal_px, pp[1]], [0.0, 0.0, 1.0]])


def _rz(a, xp):
    c, s = xp.cos(a), xp.sin(a)
    return xp.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _rx(a, xp):
    c, s = xp.cos(a), xp.sin(a)
    return xp.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


# Columns: the camera's x, y, z axes in the wall frame when it looks straight at the wall.
_WALL_FROM_CAMERA_0 = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])


def wall_from_camera_rotation(yaw, pitch, roll, xp=np):
    """Rotation whose columns are the camera axes in the wall frame (``X_wall = R X_cam + C``)."""
    return _rz(-yaw, xp) @ _rx(pitch, xp) @ xp.asarray(_WALL_FROM_CAMERA_0) @ _rz(roll, xp)


def image_from_wall_homography(params, pp, xp=np):
    """3x3 map of homogeneous wall points ``(x, z, 1)`` (metres) to homogeneous pixels.

    ``params`` follows :data:`PARAM_NAMES`; W and H are not used (they size the wall, not the map).
    """
    f, yaw, pitch, roll = params[0], params[1], params[2], params[3]
    centre = xp.stack([params[4], params[5], params[6]])
    camera_from_wall = wall_from_camera_rotation(yaw, pitch, roll, xp).T
    k = intrinsics(f, pp, xp)
    cols = xp.stack([camera_from_wall[:, 0], camera_from_wall[:, 2], -camera_from_wall @ centre], axis=1)
    return k @ cols


def distort(points, focal_px, pp, k1, k2, xp=np):
    """Ideal (pinhole) image points ``(..., 2)`` -> where the lens puts them: radial distortion
    (:data:`DISTORTION_MODEL`) about the principal point ``pp``."""
    c = xp.asarray(pp)
    x = (points - c) / focal_px
    r2 = xp.sum(x * x, axis=-1, keepdims=True)
    return c + focal_px * x * (1.0 + k1 * r2 + k2 * r2 * r2)


def _ideal_radius(rd, k1, k2, xp=np, iterations: int = 4):
    """The ideal radius r with ``r (1 + k1 r^2 + k2 r^4) = rd``: the series inverse to second
    order, then ``iterations`` Newton steps (four reach 1e-10 px for |k1| <= 0.3, |k2| <= 0.2 out
    to r = 1, a 3000 px photo's corner at a focal length of 1800 px)."""
    rd2 = rd * rd
    r = rd * (1.0 - k1 * rd2 + (3.0 * k1 * k1 - k2) * rd2 * rd2)
    for _ in range(iterations):
        r2 = r * r
        r = r - (r * (1.0 + k1 * r2 + k2 * r2 * r2) - rd) / (1.0 + 3.0 * k1 * r2 + 5.0 * k2 * r2 * r2)
    return r


_JAX_IDEAL_RADIUS = None


def _jax_ideal_radius():
    """:func:`_ideal_radius` for JAX with its derivative by the implicit function theorem, so that
    a fit differentiates a closed form instead of the unrolled Newton steps (which made the camera
    fit's compiled code three times larger and its first call in a process 3 s longer, measured)."""
    global _JAX_IDEAL_RADIUS
    if _JAX_IDEAL_RADIUS is None:
        import jax
        import jax.numpy as jnp

        @jax.custom_jvp
        def radius(rd, k1, k2):
            return _ideal_radius(rd, k1, k2, jnp)

        @radius.defjvp
        def _(primals, tangents):
            rd, k1, k2 = primals
            drd, dk1, dk2 = tangents
            r = radius(rd, k1, k2)
            r2 = r * r
            dr = (drd - r * r2 * dk1 - r * r2 * r2 * dk2) / (1.0 + 3.0 * k1 * r2 + 5.0 * k2 * r2 * r2)
            return r, dr

        _JAX_IDEAL_RADIUS = radius
    return _JAX_IDEAL_RADIUS


def undistort(points, focal_px, pp, k1, k2, xp=np):
    """The inverse of :func:`distort`: observed image points ``(..., 2)`` -> ideal pinhole points."""
    c = xp.asarray(pp)
    x = (points - c) / focal_px
    rd = xp.sqrt(xp.sum(x * x, axis=-1, keepdims=True) + 1e-30)
    if xp is np:
        r = _ideal_radius(rd, k1, k2)
    else:
        r = _jax_ideal_radius()(rd, k1 + xp.zeros_like(rd), k2 + xp.zeros_like(rd))
    return c + focal_px * x * (r / rd)


def project(h, xz, xp=np):
    """Apply a 3x3 homography to points ``(..., 2)``."""
    pts = xp.concatenate([xz, xp.ones(xz.shape[:-1] + (1,))], axis=-1) @ h.T
    return pts[..., :2] / pts[..., 2:3]


def px_per_m(image_from_wall: np.ndarray, xz: np.ndarray, eps: float = 1e-3) -> np.ndarray:
    """Photo pixels per wall metre at wall points ``(M, 2)``: the square root of the homography's
    local area scale, from steps of ``eps`` metres along x and z."""
    xz = np.atleast_2d(np.asarray(xz, dtype=np.float64))
    p0 = project(image_from_wall, xz)
    dx = project(image_from_wall, xz + [eps, 0.0]) - p0
    dz = project(image_from_wall, xz + [0.0, eps]) - p0
    return np.sqrt(np.abs(dx[:, 0] * dz[:, 1] - dx[:, 1] * dz[:, 0])) / eps


def normalise_homography(h: np.ndarray) -> np.ndarray:
    """Scale a homography to unit Frobenius norm with a positive (2, 2) entry (for comparisons)."""
    h = np.asarray(h, dtype=np.float64)
    h = h / np.linalg.norm(h)
    return h if h[2, 2] >= 0 else -h


def angles_from_rotation(r_wall_from_camera: np.ndarray) -> tuple[float, float, float]:
    """(yaw, pitch, roll) in radians of a wall-from-camera rotation (inverse of the constructor)."""
    fwd = r_wall_from_camera[:, 2]
    pitch = math.asin(float(np.clip(fwd[2], -1.0, 1.0)))
    yaw = math.atan2(float(fwd[0]), float(fwd[1]))
    no_roll = wall_from_camera_rotation(yaw, pitch, 0.0)
    rz = no_roll.T @ r_wall_from_camera
    roll = math.atan2(float(rz[1, 0]), float(rz[0, 0]))
    return yaw, pitch, roll


def heading_from_theta(theta_rad: float, yaw_rad: float) -> float:
    """Compass heading (radians clockwise from north = global +Y) of a camera with this yaw in front
    of a wall whose x axis points ``theta`` counter-clockwise from global X."""
    return (yaw_rad - theta_rad) % (2 * math.pi)


def theta_from_heading(heading_rad: float, yaw_rad: float) -> float:
    """The wall's theta (radians, in [0, 2 pi)) from a camera heading and the fitted yaw."""
    return (yaw_rad - heading_rad) % (2 * math.pi)


def focal_px_from_35mm(focal_35mm: float, image_size: tuple[int, int]) -> float:
    """Focal length in pixels from a 35 mm-equivalent focal length (diagonal convention)."""
    w, h = image_size
    return focal_35mm * math.hypot(w, h) / math.hypot(36.0, 24.0)


#: Without EXIF or --focal-px, the focal length's prior: log-normal about a 35 mm-equivalent of
#: 35 mm, sigma 1.0 in log (x/: 2.7; 13-95 mm at one sigma, 5-260 mm at two). Weak on purpose: a
#: photo without EXIF may come from a phone (24-50 mm) or from a laboratory's or a surveyor's
#: camera with a standard or a longer lens. The shipped laboratory photos were taken at 75-100 mm
#: (1800-2500 px on 891 px), +2.5 to +3.5 sigmas out on the 0.3 of before, whose H then followed the
#: prior (-2.4 and -4.1 % with the width given; within 2 % at 1.0), and on synthetic walls shot
#: at 60-100 mm the 0.3 put the truth within 2 sigma in 23 of 26 fits (26 of 26 at 1.0):
#: experiments/focal_prior.py, docs/photo_path.md "the focal length's prior"
FOCAL_PRIOR_35MM = 35.0
FOCAL_PRIOR_LOG_SIGMA = 1.0


def focal_prior_px(image_size: tuple[int, int]) -> float:
    """The focal length's prior median in pixels (:data:`FOCAL_PRIOR_35MM`) for a photo of ``image_size``."""
    return focal_px_from_35mm(FOCAL_PRIOR_35MM, image_size)


#: the flag that gives the wall's corners by hand, named by every message of a failed detection
CORNERS_FLAG = "--corners x1,y1,...,x4,y4"
#: what follows it where the automatic outline found no wall, or one too small: a close-up has no
#: corners to click
FILLS_PHOTO_ADVICE = (
    f"(a wall that fills the photo has none in it: click four joint crossings that make a rectangle on it with "
    f"{CORNERS_FLAG} and give its width with --known-width, or step back)"
)


def order_corners(points: np.ndarray, *, where: str = "--corners") -> np.ndarray:
    """Four image points in any order -> lower-left, lower-right, upper-right, upper-left.

    Raises InputError for repeated, collinear or non-convex (self-crossing) quadrilaterals.
    """
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    if pts.shape != (4, 2) or not np.all(np.isfinite(pts)):
        raise InputError(f"{where}: need exactly 4 finite corners x1,y1,...,x4,y4, got {pts.size} numbers")
    centre = pts.mean(axis=0)
    ang = np.arctan2(-(pts[:, 1] - centre[1]), pts[:, 0] - centre[0])  # counter-clockwise as seen (y up)
    ccw = pts[np.argsort(ang)]
    span = float(np.max(np.ptp(pts, axis=0)))
    q = ccw * np.array([1.0, -1.0])  # y up, so the order is counter-clockwise
    edges = np.roll(q, -1, axis=0) - q
    nxt = np.roll(edges, -1, axis=0)
    cross = edges[:, 0] * nxt[:, 1] - edges[:, 1] * nxt[:, 0]
    if span < 4.0 or np.min(np.abs(cross)) < 1e-3 * span**2:
        raise InputError(
            f"{where}: the corners are repeated or three of them are collinear; click the wall's four corners "
            f"with {CORNERS_FLAG}"
        )
    if not (np.all(cross > 0) or np.all(cross < 0)):
        raise InputError(
            f"{where}: the corners do not form a convex quadrilateral (self-crossing or dented); "
            f"click the wall's four outer corners with {CORNERS_FLAG}"
        )
    # start from the lower-left: of the two lowest points in the image (largest y), the left one
    low = np.argsort(-ccw[:, 1])[:2]
    start = low[np.argmin(ccw[low, 0])]
    return np.roll(ccw, -start, axis=0)

"""Synthetic perspective photos of synthetic walls, with the exact camera as truth.

Each wall is textured (a colour and brightness per brick, mortar colour, low-frequency weathering,
vertical streaks, grain) into an orthophoto, then photographed by a pinhole camera at standing
height: eye 1.5-1.8 m above the wall's base, yawed up to +-35 degrees, slightly rolled and pitched
up so the whole wall is in frame, 3-30 m away. The wall is warped into the photo with kornia's
``warp_perspective`` over a sky and a ground plane rendered by casting the photo's rays; then
optical blur, sensor noise and JPEG compression. The JPEG carries EXIF focal length (with the focal
plane resolution, so the focal length in pixels is exact) and a compass heading (GPSImgDirection,
with ``heading_sigma_deg`` of noise).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from scipy import ndimage

from ..build3d.scale import image_from_wall
from ..calibrate.camera import (
    distort,
    focal_px_from_35mm,
    heading_from_theta,
    image_from_wall_homography,
    intrinsics,
    principal_point,
    project,
    wall_from_camera_rotation,
)
from ..calibrate.camera import (
    px_per_m as photo_px_per_m,
)
from ..errors import InputError
from ..process import raise_if_stopped
from ..spec import PhotoSpec, WallSpec
from ..wall2d.dice import polygon_pixels
from .layouts import Piece
from .render import mask_shape

__all__ = [
    "corner_homographies",
    "photograph_corner",
    "photograph_wall",
    "render_photo",
    "sample_camera",
    "save_jpeg",
    "wall_texture",
]


def wall_texture(wall: WallSpec, pieces: list[Piece], px_per_m: float, rng: np.random.Generator) -> np.ndarray:
    """An RGB orthophoto (rows, cols, 3) in [0, 1] of the wall's outer face."""
    shape = mask_shape(wall, px_per_m)
    labels = np.zeros(shape, dtype=np.int32)
    for i, piece in enumerate(pieces, start=1):
        xy = image_from_wall(piece.polygon_m, shape, wall.width_m, wall.height_m)
        rr, cc = polygon_pixels(xy[:, 1], xy[:, 0], shape)
        labels[rr, cc] = i
    base = np.array([0.56, 0.27, 0.19]) * rng.uniform(0.85, 1.15)
    colours = base * rng.uniform(0.72, 1.18, size=(len(pieces) + 1, 1)) + rng.normal(0, 0.025, (len(pieces) + 1, 3))
    colours[0] = np.array([0.74, 0.71, 0.65]) * rng.uniform(0.93, 1.05)
    img = colours.astype(np.float32)[labels]  # float32 from here: a float64 texture was 360 MB
    small = (max(2, shape[0] // 16), max(2, shape[1] // 16))
    weather = ndimage.zoom(
        ndimage.gaussian_filter(rng.normal(size=small), 2.0), (shape[0] / small[0], shape[1] / small[1]), order=1
    )[: shape[0], : shape[1]]
    weather = np.pad(weather, ((0, shape[0] - weather.shape[0]), (0, shape[1] - weather.shape[1])), mode="edge")
    streaks = (
        ndimage.gaussian_filter1d(rng.normal(size=shape[1]), 3.0)[None, :] * np.linspace(1.0, 0.2, shape[0])[:, None]
    )
    shade = 1.0 + 0.5 * weather / max(np.std(weather), 1e-9) * 0.1 - 0.03 * streaks / max(np.std(streaks), 1e-9)
    img *= shade.astype(np.float32)[..., None]
    grain = ndimage.gaussian_filter(rng.normal(0.0, 0.05, shape), 0.8).astype(np.float32)
    grain[labels == 0] = 0.0
    img *= 1.0 + grain[..., None]
    return np.clip(img, 0.0, 1.0, out=img)


def _corners_m(wall: WallSpec) -> np.ndarray:
    w, h = wall.width_m, wall.height_m
    return np.array([[0, 0], [w, 0], [w, h], [0, h]], dtype=np.float64)


def _in_frame(params, size, wall, margin) -> bool:
    pp = principal_point(size)
    h = image_from_wall_homography(params, pp)
    pts = np.c_[_corners_m(wall), np.ones(4)] @ h.T
    if np.any(pts[:, 2] <= 0):
        return False
    xy = pts[:, :2] / pts[:, 2:]
    w, hh = size
    return bool(
        np.all(xy[:, 0] > margin * w)
        and np.all(xy[:, 0] < (1 - margin) * w)
        and np.all(xy[:, 1] > margin * hh)
        and np.all(xy[:, 1] < (1 - margin) * hh)
    )


def _aimed(wall: WallSpec, aim: tuple, d: float) -> np.ndarray:
    """Camera parameters at horizontal distance ``d`` from the aim point, pitched to it."""
    f, yaw, roll, eye, xt, zt, pitch_jitter = aim
    c = (xt - d * math.sin(yaw), -d * math.cos(yaw), eye)
    pitch = math.atan2(zt - eye, d) + pitch_jitter
    return np.array([f, yaw, pitch, roll, *c, wall.width_m, wall.height_m])


def sample_camera(wall: WallSpec, spec: PhotoSpec, rng: np.random.Generator) -> dict:
    """A standing-height camera that sees the whole wall: parameters (PARAM_NAMES order) and size."""
    portrait = wall.height_m > wall.width_m
    size = (spec.short_side_px, spec.long_side_px) if portrait else (spec.long_side_px, spec.short_side_px)
    for _ in range(50):
        f35 = rng.uniform(*spec.focal_35mm)
        f = focal_px_from_35mm(f35, size)
        eye = rng.uniform(*spec.eye_height_m)
        yaw = math.radians(rng.uniform(-spec.max_yaw_deg, spec.max_yaw_deg))
        if spec.yaw_deg is not None:  # drawn all the same, so the other draws do not change with it
            yaw = math.radians(spec.yaw_deg)
        roll = math.radians(rng.uniform(-spec.max_roll_deg, spec.max_roll_deg))
        xt, zt = wall.width_m * rng.uniform(0.4, 0.6), wall.height_m * rng.uniform(0.45, 0.55)
        pitch_jitter = math.radians(rng.uniform(-2.0, 2.0))

        aim = (f, yaw, roll, eye, xt, zt, pitch_jitter)
        d_fit = None
        for d in np.geomspace(spec.distance_m[0], spec.distance_m[1], 80):
            if _in_frame(_aimed(wall, aim, d), size, wall, spec.margin):
                d_fit = float(d)
                break
        if d_fit is None:
            continue
        d = min(spec.distance_m[1], d_fit * rng.uniform(1.0, 1.3))
        params = _aimed(wall, aim, d)
        if not _in_frame(params, size, wall, spec.margin):
            d, params = d_fit, _aimed(wall, aim, d_fit)
        k1 = float(rng.uniform(*spec.k1)) if spec.k1 != (0.0, 0.0) else 0.0
        k2 = float(rng.uniform(*spec.k2)) if spec.k2 != (0.0, 0.0) else 0.0
        return {
            "params": params,
            "image_size": size,
            "focal_35mm": f35,
            "distance_m": d,
            "eye_height_m": eye,
            "k1": k1,
            "k2": k2,
        }
    raise InputError(
        f"wall '{wall.name}': no standing-height camera {spec.distance_m[0]:g}-{spec.distance_m[1]:g} m "
        f"away frames a {wall.width_m:g} x {wall.height_m:g} m wall; widen [photos] distance_m or focal_35mm"
    )


def _scale_of(h: np.ndarray, wall: WallSpec) -> np.ndarray:
    """Photo pixels per wall metre at the wall's four corners (the homography's local scale)."""
    return photo_px_per_m(h, _corners_m(wall))


def _scale_px_per_m(params, size, wall) -> np.ndarray:
    return _scale_of(image_from_wall_homography(params, principal_point(size)), wall)


def _ideal_grid(params, size, lens) -> tuple[np.ndarray, np.ndarray]:
    """Each photo pixel's ideal (pinhole) position, ``(h, w)`` x and y: the lens ``(k1, k2)`` undone."""
    from ..calibrate.camera import undistort

    w, h = size
    xs, ys = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
    ideal = undistort(np.stack([xs, ys], -1), params[0], principal_point(size), lens[0], lens[1])
    return ideal[..., 0], ideal[..., 1]


def _background(params, size, rng, ideal=None) -> np.ndarray:
    """Sky above the horizon, a ground plane (z = 0) below it, by casting each pixel's ray. The
    sky in float32; the ground's rays in float64 (near the horizon a ray's height is a difference
    of nearly equal terms, and where it meets the ground is far), but only below the horizon.
    ``ideal``: each pixel's ideal position (a lens with distortion), else the pixel itself."""
    w, h = size
    m = wall_from_camera_rotation(params[1], params[2], params[3]) @ np.linalg.inv(
        intrinsics(params[0], principal_point(size))
    )
    if ideal is not None:
        return _background_ideal(m, params, ideal, rng)
    xs, ys = np.arange(w, dtype=np.float64)[None, :], np.arange(h, dtype=np.float64)[:, None]
    rz = m[2, 0] * xs + m[2, 1] * ys + m[2, 2]
    m32 = m.astype(np.float32)
    xs32, ys32 = xs.astype(np.float32), ys.astype(np.float32)
    rx, ry = (m32[k, 0] * xs32 + m32[k, 1] * ys32 + m32[k, 2] for k in range(2))
    elev = (rz / np.sqrt(rx * rx + ry * ry + rz * rz)).astype(np.float32)
    sky_top, horizon = np.array([0.30, 0.48, 0.82], np.float32), np.array([0.62, 0.74, 0.90], np.float32)
    img = horizon + np.clip(elev, 0, 1)[..., None] * (sky_top - horizon)
    below = np.nonzero(elev < -1e-6)
    # the ground: where each ray below the horizon meets z = 0
    px, py = xs[0, below[1]], ys[below[0], 0]
    r = [m[k, 0] * px + m[k, 1] * py + m[k, 2] for k in range(2)] + [rz[below]]
    norm = np.sqrt(r[0] ** 2 + r[1] ** 2 + r[2] ** 2)
    t = -params[6] / np.minimum(r[2] / norm, -1e-6)
    gx = params[4] + t * (r[0] / norm)
    gy = params[5] + t * (r[1] / norm)
    pattern = 0.5 + 0.25 * np.sin(2.3 * gx) * np.sin(1.7 * gy) + 0.25 * np.sin(7.1 * gx + 3.3 * gy)
    ground = np.array([0.36, 0.37, 0.26], np.float32) * (0.8 + 0.3 * pattern.astype(np.float32))[:, None]
    haze = np.clip(t / 200.0, 0, 0.6).astype(np.float32)[:, None]
    img[below] = ground * (1 - haze) + haze * horizon
    img += rng.normal(0, 0.01, img.shape)
    return img


def _background_ideal(m, params, ideal, rng) -> np.ndarray:
    """:func:`_background` at given ideal pixel positions ``(xs, ys)`` ``(h, w)`` each (float64 throughout)."""
    xs, ys = ideal
    r = [m[k, 0] * xs + m[k, 1] * ys + m[k, 2] for k in range(3)]
    norm = np.sqrt(r[0] ** 2 + r[1] ** 2 + r[2] ** 2)
    elev = (r[2] / norm).astype(np.float32)
    sky_top, horizon = np.array([0.30, 0.48, 0.82], np.float32), np.array([0.62, 0.74, 0.90], np.float32)
    img = horizon + np.clip(elev, 0, 1)[..., None] * (sky_top - horizon)
    below = elev < -1e-6
    t = -params[6] / np.minimum(r[2][below] / norm[below], -1e-6)
    gx = params[4] + t * (r[0][below] / norm[below])
    gy = params[5] + t * (r[1][below] / norm[below])
    pattern = 0.5 + 0.25 * np.sin(2.3 * gx) * np.sin(1.7 * gy) + 0.25 * np.sin(7.1 * gx + 3.3 * gy)
    ground = np.array([0.36, 0.37, 0.26], np.float32) * (0.8 + 0.3 * pattern.astype(np.float32))[:, None]
    haze = np.clip(t / 200.0, 0, 0.6).astype(np.float32)[:, None]
    img[below] = ground * (1 - haze) + haze * horizon
    img += rng.normal(0, 0.01, img.shape)
    return img


def _warp_layer_ideal(texture, wall, image_from_wall, ideal):
    """:func:`_warp_layer` through a lens: each photo pixel samples the texture where its ideal
    position ``ideal`` ``(xs, ys)`` falls (bilinear, zero outside, antialiased as there)."""
    rows, cols = texture.shape[:2]
    wall_from_tex = np.array(
        [
            [wall.width_m / cols, 0, 0.5 * wall.width_m / cols],
            [0, -wall.height_m / rows, wall.height_m - 0.5 * wall.height_m / rows],
            [0, 0, 1.0],
        ]
    )
    tex_from_photo = np.linalg.inv(image_from_wall @ wall_from_tex)
    src = np.concatenate([texture, np.ones((rows, cols, 1), np.float32)], axis=-1)
    tex_per_photo = (cols / wall.width_m) / float(np.min(_scale_of(image_from_wall, wall)))
    if tex_per_photo > 1.2:
        s = 0.45 * tex_per_photo
        src = ndimage.gaussian_filter(src, (s, s, 0), mode="mirror", truncate=math.ceil(3 * s) / s)
    xs, ys = ideal
    q = [tex_from_photo[k, 0] * xs + tex_from_photo[k, 1] * ys + tex_from_photo[k, 2] for k in range(3)]
    u, v = q[0] / q[2], q[1] / q[2]
    out = np.stack(
        [ndimage.map_coordinates(src[..., c], [v, u], order=1, mode="constant", cval=0.0) for c in range(4)], -1
    ).astype(np.float32)
    return out[..., :3], np.clip(out[..., 3:4], 0, 1)


def _warp_layer(texture: np.ndarray, wall: WallSpec, image_from_wall: np.ndarray, size: tuple[int, int]):
    """A wall's texture warped into the photo: (rgb premultiplied by alpha, alpha)."""
    import torch
    from kornia.geometry.transform import warp_perspective

    rows, cols = texture.shape[:2]
    # texture pixel (u, v) -> wall metres (Eq. 1 convention) -> photo pixel
    wall_from_tex = np.array(
        [
            [wall.width_m / cols, 0, 0.5 * wall.width_m / cols],
            [0, -wall.height_m / rows, wall.height_m - 0.5 * wall.height_m / rows],
            [0, 0, 1.0],
        ]
    )
    photo_from_tex = image_from_wall @ wall_from_tex
    src = np.concatenate([texture, np.ones((rows, cols, 1), np.float32)], axis=-1)
    tex_per_photo = (cols / wall.width_m) / float(np.min(_scale_of(image_from_wall, wall)))
    if tex_per_photo > 1.2:  # antialias: the texture is shrunk
        # a Gaussian of sigma s cut at ceil(3 s), mirrored at the edges (kornia's gaussian_blur2d
        # of that kernel, to 2e-7, in a sixth of its time)
        s = 0.45 * tex_per_photo
        src = ndimage.gaussian_filter(src, (s, s, 0), mode="mirror", truncate=math.ceil(3 * s) / s)
    w, h = size
    # float32 is ample for the sampling (positions to ~1e-3 px) and twice as fast as float64
    warped = (
        warp_perspective(
            torch.from_numpy(src).permute(2, 0, 1)[None],
            torch.from_numpy(photo_from_tex.astype(np.float32))[None],
            (h, w),
            mode="bilinear",
            align_corners=True,
        )[0]
        .permute(1, 2, 0)
        .numpy()
    )
    return warped[..., :3], np.clip(warped[..., 3:4], 0, 1)


def render_photo(
    layers: list[tuple[np.ndarray, WallSpec, np.ndarray]],
    params: np.ndarray,
    size: tuple[int, int],
    spec: PhotoSpec,
    rng: np.random.Generator,
    lens: tuple[float, float] | None = None,
) -> np.ndarray:
    """The photo (h, w, 3) uint8 of textured walls ``(texture, wall, image_from_wall)`` seen by the
    camera ``params`` (which also places the sky and the ground), through a lens of radial
    distortion ``(k1, k2)`` (OpenCV's; None or zeros: a pinhole), with blur and noise."""
    ideal = _ideal_grid(params, size, lens) if lens is not None and any(lens) else None
    img = _background(params, size, rng, ideal)
    for texture, wall, h in layers:
        raise_if_stopped()  # photos render on worker threads: a stop request ends them here
        if ideal is None:
            rgb, alpha = _warp_layer(texture, wall, h, size)
        else:
            rgb, alpha = _warp_layer_ideal(texture, wall, h, ideal)
        img = rgb + (1 - alpha) * img
    blur = rng.uniform(*spec.blur_px)
    img = ndimage.gaussian_filter(img, (blur, blur, 0))
    # sensor noise, a constant and a shot-noise part, in place (two full-size float64 arrays)
    out = rng.normal(0, spec.noise, img.shape)
    out += img
    shot = rng.normal(0, 1, img.shape)
    shot *= spec.noise
    shot *= np.sqrt(np.clip(img, 0, 1))
    out += shot
    del shot
    np.clip(out, 0, 1, out=out)
    out *= 255
    out += 0.5
    return out.astype(np.uint8)


def save_jpeg(path, img: np.ndarray, *, focal_35mm: float | None, heading_deg: float | None, quality: int = 90) -> None:
    """Write a JPEG with EXIF focal length (35 mm equivalent and focal plane resolution) and heading."""
    Path(path).write_bytes(jpeg_bytes(img, focal_35mm=focal_35mm, heading_deg=heading_deg, quality=quality))


def jpeg_bytes(img: np.ndarray, *, focal_35mm: float | None, heading_deg: float | None, quality: int = 90) -> bytes:
    """The bytes of a JPEG of ``img`` with EXIF focal length (35 mm equivalent and focal plane
    resolution) and heading: a photo as a camera writes it, made in memory."""
    import io
    from fractions import Fraction

    from PIL import Image
    from PIL.TiffImagePlugin import IFDRational

    def rational(v: float) -> IFDRational:
        q = Fraction(v).limit_denominator(100000)
        return IFDRational(q.numerator, q.denominator)

    pil = Image.fromarray(img)
    exif = Image.Exif()
    exif[0x010F] = "calib_masonry"
    exif[0x0110] = "synthetic pinhole"
    if focal_35mm is not None:
        sub = exif.get_ifd(0x8769)
        sub[0x920A] = rational(focal_35mm)  # FocalLength, mm (full-frame scale)
        sub[0xA405] = round(focal_35mm)  # FocalLengthIn35mmFilm
        w, h = pil.size
        # pixels per mm of a full-frame sensor with this image's diagonal: FocalLength x this = f in px
        sub[0xA20E] = rational(math.hypot(w, h) / math.hypot(36.0, 24.0))
        sub[0xA20F] = sub[0xA20E]
        sub[0xA210] = 4  # unit: mm
    if heading_deg is not None:
        gps = exif.get_ifd(0x8825)
        gps[16] = "T"
        gps[17] = rational(heading_deg % 360.0)
    buf = io.BytesIO()
    pil.save(buf, format="JPEG", quality=quality, exif=exif)
    return buf.getvalue()


def photograph_wall(wall: WallSpec, pieces: list[Piece], spec: PhotoSpec, rng: np.random.Generator) -> dict:
    """Sample a camera, texture and photograph one wall. Returns the image and its truth."""
    cam = sample_camera(wall, spec, rng)
    params, size = cam["params"], cam["image_size"]
    tex_res = float(np.clip(1.25 * np.max(_scale_px_per_m(params, size, wall)), 100.0, 700.0))
    texture = wall_texture(wall, pieces, tex_res, rng)
    h = image_from_wall_homography(params, principal_point(size))
    lens = (cam["k1"], cam["k2"])
    img = render_photo([(texture, wall, h)], params, size, spec, rng, lens)
    true_heading = math.degrees(heading_from_theta(wall.theta_rad, params[1]))
    exif_heading = (true_heading + rng.normal(0, spec.heading_sigma_deg)) % 360.0
    return {
        "image": img,
        "truth": {
            "image_size": list(size),
            "params": dict(
                zip(
                    ("focal_px", "yaw_rad", "pitch_rad", "roll_rad", "cx_m", "cy_m", "cz_m", "width_m", "height_m"),
                    map(float, params),
                )
            ),
            "yaw_deg": math.degrees(params[1]),
            "pitch_deg": math.degrees(params[2]),
            "roll_deg": math.degrees(params[3]),
            "focal_35mm": cam["focal_35mm"],
            "distance_m": cam["distance_m"],
            "eye_height_m": cam["eye_height_m"],
            "image_from_wall": (h / h[2, 2]).tolist(),
            "image_to_wall": (np.linalg.inv(h) / np.linalg.inv(h)[2, 2]).tolist(),
            "corners_px": (
                distort(project(h, _corners_m(wall)), params[0], principal_point(size), *lens)
                if any(lens)
                else project(h, _corners_m(wall))
            ).tolist(),
            "k1": lens[0],
            "k2": lens[1],
            "width_m": wall.width_m,
            "height_m": wall.height_m,
            "theta_deg": wall.theta_deg,
            "heading_deg": true_heading,
            "exif_heading_deg": exif_heading,
            "texture_px_per_m": tex_res,
        },
    }


def corner_homographies(params: np.ndarray, pp, wall_a: WallSpec, turn_rad: float) -> tuple[np.ndarray, np.ndarray]:
    """image_from_wall of wall n (camera params in its frame) and of wall n+1, which starts at wall
    n's end and runs along (cos turn, sin turn, 0) in wall n's frame."""
    h_a = image_from_wall_homography(params, pp)
    k = intrinsics(params[0], pp)
    cam_from_wall = wall_from_camera_rotation(params[1], params[2], params[3]).T
    along = np.array([math.cos(turn_rad), math.sin(turn_rad), 0.0])
    origin_b = np.array([wall_a.width_m, 0.0, 0.0])
    h_b = k @ np.stack([cam_from_wall @ along, cam_from_wall[:, 2], cam_from_wall @ (origin_b - params[4:7])], axis=1)
    return h_a, h_b


def photograph_corner(
    wall_a: WallSpec,
    pieces_a: list[Piece],
    wall_b: WallSpec,
    pieces_b: list[Piece],
    spec: PhotoSpec,
    rng: np.random.Generator,
) -> dict:
    """A photo of the corner where wall_a ends and wall_b starts, taken from outside along the
    corner's bisector (+-8 degrees), the corner edge in frame. Truth: the turn angle and the camera."""
    turn = (wall_b.theta_rad - wall_a.theta_rad + math.pi) % (2 * math.pi) - math.pi
    n_a = np.array([0.0, -1.0])
    n_b = np.array([math.sin(turn), -math.cos(turn)])
    bis = n_a + n_b
    if np.linalg.norm(bis) < 1e-6:
        raise InputError(f"walls '{wall_a.name}' and '{wall_b.name}' are parallel; no corner to photograph")
    bis /= np.linalg.norm(bis)
    size = (spec.long_side_px, spec.short_side_px)
    pp = principal_point(size)
    for _ in range(50):
        f = focal_px_from_35mm(rng.uniform(*spec.focal_35mm), size)
        eye = rng.uniform(*spec.eye_height_m)
        jitter = math.radians(rng.uniform(-8.0, 8.0))
        fwd = -np.array(
            [
                bis[0] * math.cos(jitter) - bis[1] * math.sin(jitter),
                bis[0] * math.sin(jitter) + bis[1] * math.cos(jitter),
            ]
        )
        yaw = math.atan2(fwd[0], fwd[1])
        roll = math.radians(rng.uniform(-spec.max_roll_deg, spec.max_roll_deg))
        z_top = min(wall_a.height_m, wall_b.height_m)
        edge = np.array([[wall_a.width_m, 0.0, 0.0], [wall_a.width_m, 0.0, z_top]])
        for d in np.geomspace(spec.distance_m[0], spec.distance_m[1], 60):
            c = np.array([wall_a.width_m - d * fwd[0], -d * fwd[1], eye])
            pitch = math.atan2(z_top / 2 - eye, d)
            params = np.array([f, yaw, pitch, roll, *c, wall_a.width_m, wall_a.height_m])
            k = intrinsics(f, pp)
            cam = (wall_from_camera_rotation(yaw, pitch, roll).T @ (edge - c).T).T
            if np.any(cam[:, 2] <= 0):
                continue
            px = (cam @ k.T)[:, :2] / cam[:, 2:3]
            w, h = size
            m = spec.margin
            if np.all((px[:, 0] > m * w) & (px[:, 0] < (1 - m) * w) & (px[:, 1] > m * h) & (px[:, 1] < (1 - m) * h)):
                break
        else:
            continue
        h_a, h_b = corner_homographies(params, pp, wall_a, turn)
        res = float(np.clip(1.25 * max(np.max(_scale_of(h_a, wall_a)), np.max(_scale_of(h_b, wall_b))), 100.0, 700.0))
        tex_a = wall_texture(wall_a, pieces_a, res, rng)
        tex_b = wall_texture(wall_b, pieces_b, res, rng)
        img = render_photo([(tex_b, wall_b, h_b), (tex_a, wall_a, h_a)], params, size, spec, rng)
        return {
            "image": img,
            "truth": {
                "walls": [wall_a.name, wall_b.name],
                "turn_deg": math.degrees(turn),
                "image_size": list(size),
                "focal_px": float(f),
                "eye_height_m": eye,
                "yaw_deg": math.degrees(yaw),
                "pitch_deg": math.degrees(pitch),
                "roll_deg": math.degrees(roll),
                "distance_m": float(d),
                "focal_35mm": float(f * math.hypot(36, 24) / math.hypot(*size)),
            },
        }
    raise InputError(
        f"corner {wall_a.name}/{wall_b.name}: no camera {spec.distance_m[0]:g}-{spec.distance_m[1]:g} m "
        "away frames it; widen [photos] distance_m"
    )

"""The lens: radial distortion profiles from the lensfun database (``lensfunpy``) for a photo whose
EXIF names its camera and lens.

The fit's lens model is OpenCV's radial one (:data:`~calib_masonry.calibrate.camera.DISTORTION_MODEL`:
``x_d = x_u (1 + k1 r^2 + k2 r^4)`` on coordinates divided by the focal length in pixels). lensfun
keeps its own models (ptlens, poly3, poly5) on its own normalisation; rather than translate each,
:func:`lensfun_profile` asks lensfun where each point of a corrected image lies in the photo (its
``Modifier.apply_geometry_distortion``) on a grid of the photo's shape, and fits (k1, k2) to that map
by linear least squares. The corrected image of lensfun may be scaled about the centre; that scale
is taken out (it is a change of focal length, which the camera fit owns). The profile then centres
the fit's prior on k1 and k2 with the sigma of that least-squares fit (at least
:data:`PROFILE_SIGMA`): the profile is a strong, not a hard, constraint.
"""

from __future__ import annotations

import functools
import math
import threading
from dataclasses import dataclass

import numpy as np

from .camera import focal_px_from_35mm

__all__ = ["LensProfile", "PROFILE_SIGMA", "lensfun_profile", "profile_from_map"]

#: the least sigma of a profile's k1 and k2 (a lens's copy and focus differ from the profiled one)
PROFILE_SIGMA = 0.01


@dataclass(frozen=True)
class LensProfile:
    """k1, k2 (OpenCV's radial model, focal-normalised), their sigmas and where they come from."""

    k1: float
    k2: float
    k1_sigma: float
    k2_sigma: float
    source: str

    def to_json(self) -> dict:
        return {
            "k1": self.k1,
            "k2": self.k2,
            "k1_sigma": self.k1_sigma,
            "k2_sigma": self.k2_sigma,
            "source": self.source,
        }


def profile_from_map(ideal: np.ndarray, distorted: np.ndarray, pp, focal_px: float, source: str) -> LensProfile:
    """Fit (k1, k2) to pairs of ideal and distorted points ``(n, 2)`` (pixels about ``pp``): the
    radial map ``|x_d| = s |x_u| (1 + a |x_u|^2 + b |x_u|^4)``, linear in (s, s a, s b); then in the
    scaled ideal coordinates ``s x_u`` the fit's k1 = a / s^2 and k2 = b / s^4."""
    c = np.asarray(pp, dtype=np.float64)
    xu = (np.asarray(ideal, np.float64) - c) / focal_px
    xd = (np.asarray(distorted, np.float64) - c) / focal_px
    ru, rd = np.linalg.norm(xu, axis=1), np.linalg.norm(xd, axis=1)
    keep = ru > 1e-6
    ru, rd = ru[keep], rd[keep]
    a = np.c_[ru, ru**3, ru**5]
    coef, *_ = np.linalg.lstsq(a, rd, rcond=None)
    s, sa, sb = coef
    k1, k2 = sa / s / s**2, sb / s / s**4
    resid = rd - a @ coef
    dof = max(1, len(rd) - 3)
    cov = np.linalg.pinv(a.T @ a) * float(resid @ resid) / dof
    # the sigmas of k1, k2 through their (near-linear) dependence on s a and s b
    k1_sigma = math.sqrt(max(cov[1, 1], 0.0)) / s**3
    k2_sigma = math.sqrt(max(cov[2, 2], 0.0)) / s**5
    return LensProfile(
        k1=float(k1),
        k2=float(k2),
        k1_sigma=max(PROFILE_SIGMA, float(k1_sigma)),
        k2_sigma=max(PROFILE_SIGMA, float(k2_sigma)),
        source=source,
    )


def lensfun_profile(exif: dict | None, image_size: tuple[int, int], focal_px: float) -> LensProfile | None:
    """The lens profile of a photo whose EXIF (:func:`calib_masonry.io.read_photo`'s ``lens``) names
    a camera and a lens that lensfun knows, at the EXIF focal length; None otherwise (no EXIF, no
    lensfunpy, an unknown camera or lens, or a lens model other than a rectilinear one)."""
    if not exif or not exif.get("model") or not exif.get("focal_mm"):
        return None
    try:
        import lensfunpy
    except ImportError:  # an optional part of the calibration: without it, no profile
        return None
    with _DATABASE_LOCK:  # one thread at a time in lensfun's database (its thread safety is not documented)
        return _profile(lensfunpy, _database(), exif, image_size, focal_px)


#: how far a focal length from FocalLength and the camera's crop factor may be off (log sigma): the
#: crop factor is the sensor's diagonal, and a photo taken in another aspect than the sensor's (16:9 on
#: a 4:3 sensor: 9 %) or cropped since covers less of it
CROP_FACTOR_LOG_SIGMA = math.log1p(0.10)


def crop_factor_focal(exif: dict | None, image_size: tuple[int, int]) -> tuple[float, str] | None:
    """The focal length in pixels of a photo whose EXIF (:func:`calib_masonry.io.read_photo`'s
    ``lens``) gives FocalLength in mm but neither the focal plane's resolution nor the 35 mm
    equivalent, from the crop factor lensfun's database holds for its camera (FocalLength x crop
    factor is the 35 mm equivalent, over the 43.3 mm diagonal of 36 x 24 mm, times the photo's
    diagonal in pixels), with a note naming the camera; None where lensfun does not know the
    camera (or is not installed). A prior's centre, with :data:`CROP_FACTOR_LOG_SIGMA`."""
    if not exif or not exif.get("model") or not exif.get("focal_mm"):
        return None
    try:
        with _DATABASE_LOCK:
            cams = _database().find_cameras(exif.get("make") or None, exif["model"], loose_search=False)
    except ImportError:  # no lensfunpy: no crop factor
        return None
    crop = float(cams[0].crop_factor) if cams else 0.0
    focal_mm = float(exif["focal_mm"])
    if not (math.isfinite(crop) and crop > 0 and math.isfinite(focal_mm) and focal_mm > 0):
        return None
    px = focal_px_from_35mm(focal_mm * crop, image_size)
    name = (
        cams[0].model if cams[0].model.lower().startswith(cams[0].maker.lower()) else f"{cams[0].maker} {cams[0].model}"
    )
    return px, f"FocalLength ({focal_mm:g} mm) x the crop factor {crop:.3g} of a {name} (lensfun)"


_DATABASE_LOCK = threading.Lock()


@functools.cache
def _database():
    """lensfun's database, read once a process (its XML files took 0.06-0.09 s of every photo's
    calibration whose EXIF names a camera: six times in a build from six photos, once a sample in
    a study of a photo wall)."""
    import lensfunpy

    return lensfunpy.Database()


def _profile(lensfunpy, db, exif: dict, image_size: tuple[int, int], focal_px: float) -> LensProfile | None:
    cams = db.find_cameras(exif.get("make") or None, exif["model"], loose_search=False)
    if not cams:
        return None
    cam = cams[0]
    lens_name = exif.get("lens_model") or ""
    if not lens_name:
        return None
    lenses = db.find_lenses(cam, exif.get("lens_make") or None, lens_name, loose_search=False)
    if not lenses:
        return None
    lens = lenses[0]
    if lens.type != lensfunpy.LensType.RECTILINEAR:
        return None
    w, h = image_size
    scale = min(1.0, 600.0 / max(w, h))  # lensfun's map depends on the shape, not the size
    ws, hs = max(8, round(w * scale)), max(8, round(h * scale))
    mod = lensfunpy.Modifier(lens, cam.crop_factor, ws, hs)
    mod.initialize(float(exif["focal_mm"]), float(exif.get("f_number") or 8.0), 10.0)
    coords = mod.apply_geometry_distortion()  # (hs, ws, 2): where each corrected pixel is in the photo
    if coords is None:
        return None
    step = max(1, min(ws, hs) // 24)
    ys, xs = np.mgrid[0:hs:step, 0:ws:step]
    ideal = np.c_[xs.ravel(), ys.ravel()].astype(np.float64)
    distorted = coords[ys.ravel(), xs.ravel()].astype(np.float64)
    pp = ((ws - 1) / 2.0, (hs - 1) / 2.0)
    return profile_from_map(
        ideal, distorted, pp, focal_px * ws / w, f"lensfun: {cam.maker} {cam.model}, {lens.maker} {lens.model}"
    )

"""A photo's veil of light (mist, flare, a lifted black), taken off before anything is read from it
(:func:`without_veil`; docs/photo_path.md, 2026-12-04)."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from ..io import Photo

__all__ = [
    "VEIL_GRID",
    "VEIL_PERCENTILE",
    "VEIL_PLANE_SHARE",
    "VEIL_PLANE_SPREAD",
    "VEIL_SHADOW_SHARE",
    "linear_light",
    "srgb_from_linear",
    "veil_plane",
    "without_veil",
]

#: the share of a photo's pixels (%) whose light is taken as its black: what lies under them is
#: veiling light (mist, flare, a lifted black), taken off before anything is read from the photo
VEIL_PERCENTILE = 0.5
#: ... where that light is above this share of its white (the lightest as many pixels); below it
#: the darkest pixels are taken for the scene's own shade under the sky's light, no veil. Measured:
#: Blender-rendered walls and facades 3-8 %, the project's generated photos 7-13 %, the laboratory
#: photos 0.2 %; the same under an even veil of an eighth to a fifth of the light 17-31 %
VEIL_SHADOW_SHARE = 0.15
#: a veil graded across the frame (flare from a corner or the sky): the photo is cut into
#: ``VEIL_GRID`` x ``VEIL_GRID`` tiles and each tile's black (its darkest :data:`VEIL_PERCENTILE` %)
#: is read ...
VEIL_GRID = 4
#: ... and where a plane through those blacks misses none by more than this share of the photo's
#: white, and rises above :data:`VEIL_PLANE_SHARE` of it, the plane is the veil, graded or even.
#: A scene's own blacks do not lie on one plane: sky, a bright ground or a lit wall fill whole
#: tiles (measured: 54 Blender-rendered tall walls 0.51-0.62 of the white off the plane at the
#: worst tile, 28 facades 0.29-0.62, 60 of the project's generated tall walls 0.31-0.49; 20
#: close-up photos filled by their wall 0.018-0.43, the four under 0.1 with their plane at most
#: 0.18 of the white); the laboratory photos 0.001-0.010, under a flare graded across them
#: 0.003-0.012. So a graded veil over a frame with sky in it is not found (the even rule above
#: takes its least off)
VEIL_PLANE_SPREAD = 0.04
#: ... the share of the white a veil whose blacks lie on one plane must rise above: a photo whose
#: every tile has the same lifted black is veiled at less than a scene's shade needs (the
#: laboratory photos' plane 0.2-0.3 %, under an even veil of 0.06: 9-11 %); of the photos above,
#: one generated close-up lies on its plane and above 0.05 (0.129, taken off: a contrast stretch)
VEIL_PLANE_SHARE = 0.05


def linear_light(rgb: np.ndarray) -> np.ndarray:
    """sRGB values in [0, 1] to linear light (the sRGB curve undone)."""
    rgb = np.asarray(rgb, dtype=np.float32)
    return np.where(rgb <= 0.04045, rgb / np.float32(12.92), ((rgb + np.float32(0.055)) / np.float32(1.055)) ** 2.4)


def srgb_from_linear(lin: np.ndarray) -> np.ndarray:
    """Linear light (clipped to [0, 1]) to sRGB values in [0, 1]."""
    lin = np.clip(np.asarray(lin, dtype=np.float32), 0.0, 1.0)
    return np.where(lin <= 0.0031308, lin * np.float32(12.92), np.float32(1.055) * lin ** (1 / 2.4) - np.float32(0.055))


def _sample(rgb: np.ndarray) -> np.ndarray:
    """The photo's light (the mean of its channels, linear light) on about a million pixels."""
    step = max(1, int(math.sqrt(rgb.shape[0] * rgb.shape[1] / 1.0e6)))
    return linear_light(rgb[::step, ::step, :3]).mean(axis=-1)


def _plane_on(coef: np.ndarray, rows: int, cols: int) -> np.ndarray:
    """The plane ``a + b u + c v`` on the pixels of a ``rows`` x ``cols`` image, ``(u, v)`` their
    centres in the frame's unit square (u across)."""
    u = (np.arange(cols) + 0.5) / cols
    v = (np.arange(rows) + 0.5) / rows
    return coef[0] + coef[1] * u[None, :] + coef[2] * v[:, None]


def veil_plane(light: np.ndarray) -> tuple[np.ndarray, float, float] | None:
    """The plane ``(a, b, c)`` (:func:`_plane_on`) through the blacks of a light image's
    :data:`VEIL_GRID` x :data:`VEIL_GRID` tiles, the image's white (its lightest
    :data:`VEIL_PERCENTILE` %) and the largest miss of a tile's black from the plane; None for an
    image with fewer pixels than tiles. Two passes: a tile's darkest pixels lie where a graded veil
    is least in it, so the first plane lies low; the second reads the tiles with it taken off."""
    rows, cols = light.shape
    n = VEIL_GRID
    if rows < n or cols < n:
        return None
    design = np.array([(1.0, (j + 0.5) / n, (i + 0.5) / n) for i in range(n) for j in range(n)])
    coef = np.zeros(3)
    for _ in range(2):
        rest = light - _plane_on(coef, rows, cols)
        blacks = np.array(
            [
                np.percentile(
                    rest[i * rows // n : (i + 1) * rows // n, j * cols // n : (j + 1) * cols // n], VEIL_PERCENTILE
                )
                for i in range(n)
                for j in range(n)
            ]
        )
        step, *_ = np.linalg.lstsq(design, blacks, rcond=None)
        coef = coef + step
    white = float(np.percentile(light, 100.0 - VEIL_PERCENTILE))
    return coef, white, float(np.max(np.abs(design @ step - blacks)))


def _without_graded_veil(photo: Photo, light: np.ndarray) -> Photo:
    """The photo with a veil on one plane taken off, graded across it or even but faint
    (:data:`VEIL_PLANE_SPREAD`, :data:`VEIL_PLANE_SHARE`), or the same object where its tiles'
    blacks do not say one."""
    found = veil_plane(light)
    if found is None:
        return photo
    coef, white, miss = found
    corners = coef[0] + np.array([0.0, coef[1], coef[2], coef[1] + coef[2]])
    if not (miss < VEIL_PLANE_SPREAD * white and corners.max() > VEIL_PLANE_SHARE * white):
        return photo
    rgb = np.asarray(photo.rgb)
    plane = np.maximum(_plane_on(coef, *rgb.shape[:2]), 0.0).astype(np.float32)
    least = float(max(corners.min(), 0.0))  # the scene kept at its own exposure where the veil is least
    out = srgb_from_linear((linear_light(rgb[..., :3]) - plane[..., None]) / np.float32(1.0 - least))
    return replace(photo, rgb=out.astype(np.float32))


def without_veil(photo: Photo) -> Photo:
    """The photo with its veiling light taken off: the light of its darkest :data:`VEIL_PERCENTILE`
    % of pixels (the mean of the three channels, in linear light) is taken as black, subtracted
    from every channel and the rest scaled back to [0, 1]. Mist, flare and a lifted black add
    light evenly (linear light ``a x + b``) and flatten the photo towards a grey where the
    outline's appearance model, GrabCut and the soft sides read the wall's darker courses as
    surroundings (laboratory photos under a veil of an eighth: H 14-35 % short, at 7-27
    sigmas, measured by experiments/photo_conditions.py); with the veil off they read as
    without it. A photo whose darkest light is at most :data:`VEIL_SHADOW_SHARE` of its lightest
    (its own shade, no veil), or that is of one lightness, comes back as it is (the same object),
    unless its tiles' blacks lie on one plane above :data:`VEIL_PLANE_SHARE` of it (a veil graded
    across the frame, as flare is, or an even one too faint for the first rule:
    :data:`VEIL_PLANE_SPREAD`), when that plane is subtracted and the rest scaled as far as the
    veil's least."""
    rgb = np.asarray(photo.rgb)
    sample = _sample(rgb)
    dark, light = (float(v) for v in np.percentile(sample, [VEIL_PERCENTILE, 100.0 - VEIL_PERCENTILE]))
    if dark >= light:  # a flat photo: nothing to restore
        return photo
    if dark <= VEIL_SHADOW_SHARE * light:  # no veil a scene's shade could not be; perhaps one on a plane
        return _without_graded_veil(photo, sample)
    out = srgb_from_linear((linear_light(rgb[..., :3]) - np.float32(dark)) / np.float32(1.0 - dark))
    return replace(photo, rgb=out.astype(np.float32))

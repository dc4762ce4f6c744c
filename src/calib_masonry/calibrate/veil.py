"""A photo's veil of light (mist, flare, a lifted black), taken off before anything is read from it
(:func:`without_veil`; docs/photo_path.md, 2026-12-04)."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from ..io import Photo

__all__ = ["VEIL_PERCENTILE", "VEIL_SHADOW_SHARE", "linear_light", "srgb_from_linear", "without_veil"]

#: the share of a photo's pixels (%) whose light is taken as its black: what lies under them is
#: veiling light (mist, flare, a lifted black), taken off before anything is read from the photo
VEIL_PERCENTILE = 0.5
#: ... where that light is above this share of its white (the lightest as many pixels); below it
#: the darkest pixels are taken for the scene's own shade under the sky's light, no veil. Measured:
#: Blender-rendered walls and facades 3-8 %, the project's generated photos 7-13 %, the laboratory
#: photos 0.2 %; the same under an even veil of an eighth to a fifth of the light 17-31 %
VEIL_SHADOW_SHARE = 0.15


def linear_light(rgb: np.ndarray) -> np.ndarray:
    """sRGB values in [0, 1] to linear light (the sRGB curve undone)."""
    rgb = np.asarray(rgb, dtype=np.float32)
    return np.where(rgb <= 0.04045, rgb / np.float32(12.92), ((rgb + np.float32(0.055)) / np.float32(1.055)) ** 2.4)


def srgb_from_linear(lin: np.ndarray) -> np.ndarray:
    """Linear light (clipped to [0, 1]) to sRGB values in [0, 1]."""
    lin = np.clip(np.asarray(lin, dtype=np.float32), 0.0, 1.0)
    return np.where(lin <= 0.0031308, lin * np.float32(12.92), np.float32(1.055) * lin ** (1 / 2.4) - np.float32(0.055))


def without_veil(photo: Photo) -> Photo:
    """The photo with its veiling light taken off: the light of its darkest :data:`VEIL_PERCENTILE`
    % of pixels (the mean of the three channels, in linear light) is taken as black, subtracted
    from every channel and the rest scaled back to [0, 1]. Mist, flare and a lifted black add
    light evenly (linear light ``a x + b``) and flatten the photo towards a grey where the
    outline's appearance model, GrabCut and the soft sides read the wall's darker courses as
    surroundings (laboratory photos under a veil of an eighth: H 14-35 % short, at 7-27
    sigmas, measured by experiments/photo_conditions.py); with the veil off they read as
    without it. A photo whose darkest light is at most :data:`VEIL_SHADOW_SHARE` of its lightest
    (its own shade, no veil), or that is of one lightness, comes back as it is (the same object)."""
    rgb = np.asarray(photo.rgb)
    step = max(1, int(math.sqrt(rgb.shape[0] * rgb.shape[1] / 1.0e6)))  # about a million pixels suffice
    sample = linear_light(rgb[::step, ::step, :3]).mean(axis=-1)
    dark, light = (float(v) for v in np.percentile(sample, [VEIL_PERCENTILE, 100.0 - VEIL_PERCENTILE]))
    if not VEIL_SHADOW_SHARE * light < dark < light:  # no veil; or a flat photo, nothing to restore
        return photo
    out = srgb_from_linear((linear_light(rgb[..., :3]) - np.float32(dark)) / np.float32(1.0 - dark))
    return replace(photo, rgb=out.astype(np.float32))

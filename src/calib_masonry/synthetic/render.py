"""Rasterising synthetic walls to binary masks.

A pixel is brick when its centre lies inside a piece's polygon (scikit-image's polygon rule, by
:func:`~calib_masonry.wall2d.dice.polygon_pixels`), so a mask edge is within half a pixel of the
true edge. ``edge_blur_px`` / ``edge_noise`` roughen the
edges: the mask is blurred with that Gaussian sigma, uniform noise of that amplitude is added, and
the result is thresholded at one half.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from ..build3d.scale import image_from_wall
from ..spec import SyntheticSpec, WallSpec
from ..wall2d.dice import polygon_pixels
from .layouts import Piece

__all__ = ["mask_shape", "rasterise_wall"]


def mask_shape(wall: WallSpec, px_per_m: float) -> tuple[int, int]:
    return (max(2, int(round(wall.height_m * px_per_m))), max(2, int(round(wall.width_m * px_per_m))))


def rasterise_wall(
    wall: WallSpec, pieces: list[Piece], syn: SyntheticSpec, rng: np.random.Generator
) -> tuple[np.ndarray, list[np.ndarray]]:
    """Mask ``(rows, cols)`` of a wall and each piece's polygon in image pixels (x, y)."""
    shape = mask_shape(wall, syn.px_per_m)
    mask = np.zeros(shape, dtype=bool)
    polys_px = []
    for piece in pieces:
        xy = image_from_wall(piece.polygon_m, shape, wall.width_m, wall.height_m)
        polys_px.append(xy)
        rr, cc = polygon_pixels(xy[:, 1], xy[:, 0], shape)
        mask[rr, cc] = True
    if syn.edge_blur_px > 0 or syn.edge_noise > 0:
        f = mask.astype(np.float64)
        if syn.edge_blur_px > 0:
            f = ndimage.gaussian_filter(f, syn.edge_blur_px, mode="nearest")
        if syn.edge_noise > 0:
            f = f + rng.uniform(-syn.edge_noise, syn.edge_noise, size=shape)
        mask = f > 0.5
    return mask, polys_px

"""Scaling between mask pixels and wall metres (the method's Eq. 1).

Convention: a mask of shape ``(rows, cols)`` covers the whole outer face of a wall ``W`` wide and
``H`` high. Pixel centres sit at integer image coordinates ``(x, y)`` (x = column, y = row, origin
top-left), so pixel ``c`` spans ``[c - 0.5, c + 0.5]`` and the wall's left edge is at ``x = -0.5``.
Wall coordinates ``(x, z)`` have their origin at the wall's lower-left corner, z up.
"""

from __future__ import annotations

import numpy as np

__all__ = ["wall_from_image", "image_from_wall", "aspect_mismatch"]


def wall_from_image(xy: np.ndarray, shape: tuple[int, int], width_m: float, height_m: float) -> np.ndarray:
    """Image points ``(M, 2)`` (x, y) in pixels to wall points ``(M, 2)`` (x, z) in metres."""
    rows, cols = shape
    xy = np.asarray(xy, dtype=np.float64)
    x = (xy[..., 0] + 0.5) * (width_m / cols)
    z = height_m - (xy[..., 1] + 0.5) * (height_m / rows)
    return np.stack([x, z], axis=-1)


def image_from_wall(xz: np.ndarray, shape: tuple[int, int], width_m: float, height_m: float) -> np.ndarray:
    """Inverse of :func:`wall_from_image`."""
    rows, cols = shape
    xz = np.asarray(xz, dtype=np.float64)
    x = xz[..., 0] * (cols / width_m) - 0.5
    y = (height_m - xz[..., 1]) * (rows / height_m) - 0.5
    return np.stack([x, y], axis=-1)


def aspect_mismatch(shape: tuple[int, int], width_m: float, height_m: float) -> float:
    """Relative disagreement between the mask's aspect ratio (cols/rows) and W/H."""
    rows, cols = shape
    return abs((cols / rows) / (width_m / height_m) - 1.0)

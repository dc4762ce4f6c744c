"""Binary mask to labelled bricks (scikit-image / scipy labelling).

Specks (components far smaller than a typical brick) are dropped and small holes inside bricks
are filled; bricks touching the image border are kept. Labels are 4-connected, so two bricks
that touch only diagonally stay apart.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

__all__ = ["SegmentConfig", "label_bricks"]

_FOUR = ndimage.generate_binary_structure(2, 1)


@dataclass(frozen=True)
class SegmentConfig:
    """``speck_fraction``: components smaller than this fraction of the median brick area (and
    never fewer than ``min_speck_px`` pixels) are dropped. ``hole_fraction``: enclosed mortar
    holes smaller than this fraction of the median brick area are filled."""

    speck_fraction: float = 0.02
    min_speck_px: int = 6
    hole_fraction: float = 0.05


def _component_areas(labels: np.ndarray, n: int) -> np.ndarray:
    return np.bincount(labels.ravel(), minlength=n + 1)[1:]


def label_bricks(mask: np.ndarray, config: SegmentConfig = SegmentConfig()) -> np.ndarray:
    """Label bricks of a boolean mask ``(rows, cols)``; returns int32 labels ``(rows, cols)``, 0 = mortar.

    Labels are numbered 1..K in raster order of each brick's first pixel.
    """
    mask = np.asarray(mask, dtype=bool)
    labels, n = ndimage.label(mask, structure=_FOUR)
    if n == 0:
        return labels.astype(np.int32)
    areas = _component_areas(labels, n)
    big = areas[areas >= config.min_speck_px]
    median = float(np.median(big)) if big.size else float(np.median(areas))
    speck = max(config.min_speck_px, config.speck_fraction * median)
    keep = np.concatenate([[False], areas >= speck])
    clean = keep[labels]
    # fill small enclosed holes (background components not touching the border)
    holes, nh = ndimage.label(~clean, structure=_FOUR)
    if nh:
        hole_areas = _component_areas(holes, nh)
        border = np.unique(np.concatenate([holes[0], holes[-1], holes[:, 0], holes[:, -1]]))
        small = hole_areas < config.hole_fraction * median
        small[border[border > 0] - 1] = False
        fill = np.concatenate([[False], small])
        clean |= fill[holes]
    labels, _ = ndimage.label(clean, structure=_FOUR)
    return labels.astype(np.int32)

"""Figures of the 2D stage: fitted polygons drawn over the mask."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from .trace import TraceResult

__all__ = ["plot_trace"]


def plot_trace(mask: np.ndarray, result: TraceResult, path: Path, *, title: str = "") -> None:
    """The mask in grey with every brick's polygon and vertices, coloured by its Dice."""
    from matplotlib.collections import PolyCollection

    from .. import _figure as plt

    rows, cols = mask.shape
    scale = 9.0 / max(rows, cols)
    fig, ax = plt.subplots(figsize=(max(3.0, cols * scale) + 1.2, max(3.0, rows * scale)))
    # the figure shows about 1,000 px across: a mask of many megapixels is shown decimated (a view,
    # no copy), since matplotlib would otherwise make 32-byte RGBA floats of every pixel
    step = max(1, max(rows, cols) // 2000)
    ax.imshow(
        mask[::step, ::step],
        cmap="gray",
        vmin=-0.6,
        vmax=1.3,
        interpolation="nearest",
        extent=(-0.5, -0.5 + step * len(range(0, cols, step)), -0.5 + step * len(range(0, rows, step)), -0.5),
    )
    cmap = plt.get_cmap("plasma")
    dice = np.array([b.dice for b in result.bricks])
    coll = PolyCollection(
        [b.vertices_xy for b in result.bricks],
        facecolors="none",
        edgecolors=[cmap(np.clip((d - 0.9) / 0.1, 0, 1)) for d in dice],
        linewidths=1.0,
    )
    ax.add_collection(coll)
    if result.refined:
        ax.add_collection(
            PolyCollection(
                [b.splitting_xy for b in result.bricks if b.splitting_xy is not None],
                facecolors="none",
                edgecolors="c",
                linewidths=0.6,
                linestyles="--",
            )
        )
        title = (f"{title}  splitting (dashed) mean Dice {result.mean_dice_splitting:.4f} -> refined (solid)").strip()
    pts = np.concatenate([b.vertices_xy for b in result.bricks])
    ax.plot(pts[:, 0], pts[:, 1], ".", ms=2, color="c")
    from matplotlib.cm import ScalarMappable
    from matplotlib.colors import Normalize

    sm = ScalarMappable(cmap=cmap, norm=Normalize(0.9, 1.0))
    fig.colorbar(sm, ax=ax, fraction=0.046, pad=0.02, label="Dice")
    ax.set_xlim(-0.5, cols - 0.5)
    ax.set_ylim(rows - 0.5, -0.5)
    # wrapped to the figure's width (about 8 characters of 9 pt text an inch): a refined trace's
    # title ran out of a narrow mask's figure on both sides
    import textwrap

    width_chars = max(20, int(fig.get_size_inches()[0] * 8))
    text = f"{title}  {len(result.bricks)} bricks, mean Dice {result.mean_dice:.4f}".strip()
    ax.set_title("\n".join(textwrap.wrap(text, width_chars)), fontsize=9)
    fig.tight_layout()
    plt.save(fig, path, dpi=110)
    plt.close(fig)

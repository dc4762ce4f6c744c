"""Figures of the calibration: the photo with the fitted outline and joint lines, and the orthophoto."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from .camera import project

__all__ = ["plot_calibration", "plot_corner", "plot_footprint"]


def plot_calibration(cal, rect, path: Path, *, photo_size: tuple[int, int] | None = None) -> None:
    """Left: the photo, the fitted wall outline (green), the clicked or detected corners (red),
    bed (orange) and head (cyan) joint segments used by the fit, the vanishing directions.
    Right: the rectified orthophoto with a 1 m grid.

    ``rect`` is the orthophoto ``(rows, cols, 3)``, or a callable that returns it: the photo's
    panel is drawn while it runs (``rectify`` resamples on other threads meanwhile).
    ``photo_size`` ``(width, height)``: the photo's size in pixels when ``cal.photo.rgb`` is a
    reduced copy of it (a build keeps only a preview of each photo, not the photo)."""
    from matplotlib.collections import LineCollection

    from .. import _figure as plt

    res = cal.result
    rgb = cal.photo.rgb
    width, height = photo_size if photo_size is not None else (rgb.shape[1], rgb.shape[0])
    # each panel is about 800 px wide at the saved size: a finer image only costs resampling time
    step = max(1, math.ceil(max(rgb.shape[:2]) / 900))
    fig, (a, b) = plt.subplots(1, 2, figsize=(14, 7.5), gridspec_kw={"width_ratios": [1, 1]})
    a.imshow(rgb[::step, ::step], extent=(-0.5, width - 0.5, height - 0.5, -0.5))
    h = res.image_from_wall
    w_m, h_m = res.width_m, res.height_m
    # fitted outline, and 1 m grid lines of the wall drawn through the camera
    t = np.linspace(0, 1, 50)
    edge = np.concatenate(
        [
            np.c_[t * w_m, 0 * t],
            np.c_[w_m + 0 * t, t * h_m],
            np.c_[(1 - t) * w_m, h_m + 0 * t],
            np.c_[0 * t, (1 - t) * h_m],
        ]
    )
    e = project(h, edge)
    a.plot(e[:, 0], e[:, 1], "-", color="lime", lw=1.2, label="fitted outline")
    grid = [project(h, np.array([[x, 0], [x, h_m]])) for x in np.arange(1.0, w_m, 1.0)]
    grid += [project(h, np.array([[0, z], [w_m, z]])) for z in np.arange(1.0, h_m, 1.0)]
    a.add_collection(LineCollection(grid, colors="white", linewidths=0.5, alpha=0.7, label="fitted 1 m grid"))
    if cal.detection is not None:
        c = cal.detection.corners_px
        lab = "detected corners"
    else:
        c = res.corners_px()
        lab = "clicked corners (fitted)"
    a.plot(c[:, 0], c[:, 1], "o", mfc="none", mec="red", ms=9, label=lab)
    det = cal.detection
    if det is not None:
        for seg, col, name in ((det.bed_segments, "orange", "bed joints"), (det.head_segments, "cyan", "head joints")):
            if len(seg):
                a.add_collection(
                    LineCollection(seg.reshape(-1, 2, 2), colors=col, linewidths=0.6, label=f"{name} ({len(seg)})")
                )
    a.set_xlim(-0.5, width - 0.5)
    a.set_ylim(height - 0.5, -0.5)
    a.legend(loc="lower left", fontsize=7, framealpha=0.8)
    cam = res.camera_json()
    a.set_title(
        f"{cal.photo.path.name}: {cal.mode}, f = {cam['focal_px']:.0f} px ({cal.focal_source}), "
        f"yaw {cam['yaw_deg']:.1f}, pitch {cam['pitch_deg']:.1f}, roll {cam['roll_deg']:.1f} deg\n"
        f"RMS residual {res.rms_residual_px:.2f} px, {res.status.value}",
        fontsize=9,
    )
    if callable(rect):
        rect = rect()
    rows, cols = rect.shape[:2]
    rstep = max(1, math.ceil(max(rows, cols) / 900))
    b.imshow(np.clip(rect[::rstep, ::rstep], 0, 1), extent=(0, w_m, 0, h_m))
    for x in np.arange(1.0, w_m, 1.0):
        b.axvline(x, color="white", lw=0.5, alpha=0.7)
    for z in np.arange(1.0, h_m, 1.0):
        b.axhline(z, color="white", lw=0.5, alpha=0.7)
    b.set_xlabel("x along the wall [m]")
    b.set_ylabel("z [m]")
    b.set_title(
        f"orthophoto {cols} x {rows} px: W = {w_m:.3f} +- {res.sigma('width_m'):.3f} m, "
        f"H = {h_m:.3f} +- {res.sigma('height_m'):.3f} m",
        fontsize=9,
    )
    # fixed margins for this fixed layout: matplotlib's tight_layout measured every text to find
    # them (0.11 s of the figure's 0.45 s)
    fig.subplots_adjust(left=0.045, right=0.99, bottom=0.07, top=0.92, wspace=0.12)
    plt.save(fig, path, dpi=110)
    plt.close(fig)


def plot_footprint(widths, thetas, adjusted_w, adjusted_t, names, path: Path, *, title: str = "") -> None:
    """Plan view of the footprint from the per-wall estimates (dashed, not closing) and after the
    closure-constrained fit (solid)."""
    from .. import _figure as plt

    def walk(w, t):
        steps = np.c_[np.cos(t) * w, np.sin(t) * w]
        return np.vstack([[0.0, 0.0], np.cumsum(steps, axis=0)])

    fig, ax = plt.subplots(figsize=(6.5, 6.5))
    p0, p1 = walk(np.asarray(widths), np.asarray(thetas)), walk(np.asarray(adjusted_w), np.asarray(adjusted_t))
    ax.plot(p0[:, 0], p0[:, 1], "--o", color="tab:red", ms=3, label="per-wall estimates")
    ax.plot(p1[:, 0], p1[:, 1], "-o", color="tab:blue", ms=3, label="closure fit")
    for i, n in enumerate(names):
        m = (p1[i] + p1[i + 1]) / 2
        ax.annotate(n, m, fontsize=8, ha="center")
    gap = np.linalg.norm(p0[-1] - p0[0])
    ax.set_aspect("equal")
    ax.legend(fontsize=8)
    ax.set_xlabel("X [m]")
    ax.set_ylabel("Y [m]")
    ax.set_title(f"{title}\nestimates leave a {gap * 1000:.0f} mm gap; the fit closes it".strip(), fontsize=9)
    fig.tight_layout()
    plt.save(fig, path, dpi=110)
    plt.close(fig)


def plot_corner(rgb: np.ndarray, result, path: Path, *, names=("wall n", "wall n+1"), title: str = "") -> None:
    """A corner photo with the bed-joint segments of the left (orange) and right (cyan) wall that
    fixed the turn angle between them."""
    from matplotlib.collections import LineCollection

    from .. import _figure as plt

    step = max(1, int(math.ceil(max(rgb.shape[:2]) / 1600)))
    fig, ax = plt.subplots(figsize=(10, 10 * rgb.shape[0] / rgb.shape[1] + 0.6))
    ax.imshow(rgb[::step, ::step], extent=(-0.5, rgb.shape[1] - 0.5, rgb.shape[0] - 0.5, -0.5))
    for seg, col, name in zip(result.segments, ("orange", "cyan"), names):
        if len(seg):
            ax.add_collection(
                LineCollection(
                    seg.reshape(-1, 2, 2), colors=col, linewidths=0.8, label=f"{name}: {len(seg)} bed-joint segments"
                )
            )
    ax.set_xlim(-0.5, rgb.shape[1] - 0.5)
    ax.set_ylim(rgb.shape[0] - 0.5, -0.5)
    ax.legend(loc="lower left", fontsize=8)
    ax.set_title(
        f"{title} turn {math.degrees(result.turn_rad):.2f} +- {math.degrees(result.turn_sigma_rad):.2f} deg, "
        f"RMS {result.rms_line_px:.2f} px".strip(),
        fontsize=9,
    )
    fig.tight_layout()
    plt.save(fig, path, dpi=100)
    plt.close(fig)

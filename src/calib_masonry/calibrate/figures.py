"""Figures of the calibration: the photo with the fitted outline and joint lines, and the orthophoto."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

__all__ = ["plot_calibration", "plot_corner", "plot_footprint"]


def plot_calibration(
    cal, rect, path: Path, *, photo_size: tuple[int, int] | None = None, ortho_m: tuple[float, float] | None = None
) -> None:
    """Left: the photo, the fitted wall outline (green) and its 1 m grid drawn through the camera
    (white), the clicked or detected corners (red), the bed (orange) and head (cyan) joint segments
    used by the fit. Right: the rectified orthophoto with a 1 m grid and metre ticks.

    ``rect`` is the orthophoto ``(rows, cols, 3)``, or a callable that returns it: the photo's
    panel is drawn while it runs (``rectify`` resamples on other threads meanwhile).
    ``photo_size`` ``(width, height)``: the photo's size in pixels when ``cal.photo.rgb`` is a
    reduced copy of it (a build keeps only a preview of each photo, not the photo). ``ortho_m``
    ``(W, H)``: the orthophoto's size in metres where it is not the fitted wall's (a build's typed
    W and H).

    Drawn with Pillow (:mod:`calib_masonry._raster`), not matplotlib: importing and drawing a
    matplotlib figure was a quarter of ``rectify``'s time."""
    from .._raster import Canvas, nice_step, text_width

    res = cal.result
    rgb = cal.photo.rgb
    width, height = photo_size if photo_size is not None else (rgb.shape[1], rgb.shape[0])
    w_m, h_m = res.width_m, res.height_m
    ow, oh = ortho_m if ortho_m is not None else (w_m, h_m)
    side, top, bottom, margin, gap = 760, 64, 48, 12, 78  # px: panel images at most side x side
    k = side / max(width, height)
    photo_wh = (max(1, round(width * k)), max(1, round(height * k)))
    kr = side / max(ow, oh)
    ortho_wh = (max(1, round(ow * kr)), max(1, round(oh * kr)))
    cam = res.camera_json()
    k1, k2 = res.distortion
    left_title = (
        f"{cal.photo.path.name} ({width} x {height} px): {cal.mode}, f = {cam['focal_px']:.0f} px "
        f"({cal.focal_source})\nyaw {cam['yaw_deg']:.1f}, pitch {cam['pitch_deg']:.1f}, roll "
        f"{cam['roll_deg']:.1f} deg, lens k1 {k1:+.3f}, k2 {k2:+.3f}\nscale from the {cal.scale_source}; "
        f"RMS residual {res.rms_residual_px:.2f} px, {res.status.value}"
    )
    sizes = f"W = {w_m:.3f} +- {res.sigma('width_m'):.3f} m, H = {h_m:.3f} +- {res.sigma('height_m'):.3f} m"
    # each column as wide as its panel or its title (a tall narrow wall's orthophoto is narrow)
    left_w = max(photo_wh[0], text_width(left_title))
    right_w = max(ortho_wh[0], text_width(f"orthophoto 99999 x 99999 px\n{sizes}"), text_width("x along the wall [m]"))
    x0 = margin + left_w + gap
    canvas = Canvas(x0 + right_w + margin, top + max(photo_wh[1], ortho_wh[1]) + bottom)
    a = canvas.image_panel(rgb, margin, top, photo_wh, (-0.5, -0.5, width - 0.5, height - 0.5))

    def through_lens(ends):  # a straight wall line, drawn through the camera and its lens (curved)
        t = np.linspace(0.0, 1.0, 33)[:, None]
        return res.photo_from_wall(ends[0] + t * (ends[1] - ends[0]))

    # the fitted 1 m grid and outline of the wall, drawn through the camera
    step_m = nice_step(max(w_m, h_m), 360.0)  # at most eight lines along the longer side (1, 2, 5 x 10^k m)
    for x in np.arange(step_m, w_m - 1e-9, step_m):
        canvas.polyline(a, through_lens(np.array([[x, 0], [x, h_m]])), "white", alpha=0.7)
    for z in np.arange(step_m, h_m - 1e-9, step_m):
        canvas.polyline(a, through_lens(np.array([[0, z], [w_m, z]])), "white", alpha=0.7)
    corners_m = np.array([[0, 0], [w_m, 0], [w_m, h_m], [0, h_m], [0, 0]], dtype=np.float64)
    outline = np.concatenate([through_lens(corners_m[i : i + 2])[:-1] for i in range(4)])
    canvas.polyline(a, outline, "lime", width=2, closed=True)
    for poly in cal.occluders:
        canvas.polyline(a, np.asarray(poly, dtype=float), "magenta", width=2, closed=True)
    det = cal.detection
    entries = [("line", "lime", "fitted outline"), ("line", "white", f"fitted {step_m:g} m grid")]
    if len(cal.occluders):
        entries.append(("line", "magenta", f"occluders left out ({len(cal.occluders)})"))
    if det is not None:
        for seg, col, name in ((det.bed_segments, "orange", "bed joints"), (det.head_segments, "cyan", "head joints")):
            if len(seg):
                canvas.segments(a, np.asarray(seg).reshape(-1, 4), col)
                entries.append(("line", col, f"{name} ({len(seg)})"))
        c, label = det.corners_px, "detected corners"
    else:
        c, label = res.corners_px(), "clicked corners (fitted)"
    canvas.rings(a, c, "red")
    entries.append(("ring", "red", label))
    canvas.legend(a, entries)
    canvas.text((margin, 8), left_title)
    if callable(rect):
        rect = rect()
    rows, cols = rect.shape[:2]
    b = canvas.image_panel(rect, x0, top, ortho_wh, (0.0, 0.0, ow, oh), flip=True)
    for x in np.arange(step_m, ow - 1e-9, step_m):
        canvas.polyline(b, [[x, 0], [x, oh]], "white", alpha=0.7)
    for z in np.arange(step_m, oh - 1e-9, step_m):
        canvas.polyline(b, [[0, z], [ow, z]], "white", alpha=0.7)
    # metre ticks: every 1, 2 or 5 x 10^k m, at least 45 px apart
    for x in np.arange(0.0, ow + 1e-9, nice_step(ow, ortho_wh[0])):
        ((px, py),) = b.xy([[x, 0.0]])
        canvas.draw.line([(px, py), (px, py + 4)], fill=(0, 0, 0, 255))
        canvas.text((px, py + 6), f"{x:g}", size=11, anchor="ma")
    for z in np.arange(0.0, oh + 1e-9, nice_step(oh, ortho_wh[1])):
        ((px, py),) = b.xy([[0.0, z]])
        canvas.draw.line([(px - 4, py), (px, py)], fill=(0, 0, 0, 255))
        canvas.text((px - 6, py), f"{z:g}", size=11, anchor="rm")
    canvas.text((x0 + ortho_wh[0] / 2, top + ortho_wh[1] + 24), "x along the wall [m]", size=12, anchor="ma")
    canvas.text((x0 - 6, top - 4), "z [m]", size=12, anchor="rd")
    canvas.text((x0, 8), f"orthophoto {cols} x {rows} px\n{sizes}")
    canvas.save(path)


def plot_footprint(
    widths, thetas, adjusted_w, adjusted_t, names, path: Path, *, title: str = "", closed: bool = True
) -> None:
    """Plan view of the footprint from the per-wall estimates (dashed, not closing) and after the
    closure-constrained fit (solid; an open footprint's: the fit to its corner photos' turns)."""
    from .. import _figure as plt

    def walk(w, t):
        steps = np.c_[np.cos(t) * w, np.sin(t) * w]
        return np.vstack([[0.0, 0.0], np.cumsum(steps, axis=0)])

    fig, ax = plt.subplots(figsize=(6.5, 6.5))
    p0, p1 = walk(np.asarray(widths), np.asarray(thetas)), walk(np.asarray(adjusted_w), np.asarray(adjusted_t))
    ax.plot(p0[:, 0], p0[:, 1], "--o", color="tab:red", ms=3, label="per-wall estimates")
    ax.plot(p1[:, 0], p1[:, 1], "-o", color="tab:blue", ms=3, label="closure fit" if closed else "fit to the turns")
    for i, n in enumerate(names):
        m = (p1[i] + p1[i + 1]) / 2
        ax.annotate(n, m, fontsize=8, ha="center")
    gap = np.linalg.norm(p0[-1] - p0[0])
    ax.set_aspect("equal")
    ax.legend(fontsize=8)
    ax.set_xlabel("X [m]")
    ax.set_ylabel("Y [m]")
    say = f"estimates leave a {gap * 1000:.0f} mm gap; the fit closes it" if closed else "open footprint: no closure"
    ax.set_title(f"{title}\n{say}".strip(), fontsize=9)
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

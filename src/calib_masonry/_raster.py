"""Figures drawn straight into pixels with Pillow: an image panel with lines, markers, a legend and
a title. For the figures that are a photo with lines on it (the calibration overlay): importing
matplotlib's Figure took 0.42 s and drawing the overlay 0.35-0.6 s of a 3.5 s ``rectify``; Pillow
is imported anyway to read the photo, and draws the same overlay in a few hundredths of a second.

A :class:`Panel` maps a source frame (photo pixels, or wall metres) linearly onto its rectangle of
the canvas; everything drawn on it is given in the source frame."""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cache

import numpy as np

from .io import to_uint8

__all__ = ["Canvas", "Panel", "font", "nice_step", "preview_uint8", "text_width"]

#: colours by name, as the matplotlib figures name them
COLOURS = {
    "lime": (0, 255, 0),
    "red": (255, 0, 0),
    "orange": (255, 165, 0),
    "cyan": (0, 255, 255),
    "magenta": (255, 0, 255),
    "white": (255, 255, 255),
    "black": (0, 0, 0),
    "grey": (110, 110, 110),
}


@cache
def font(size: int):
    """Pillow's built-in scalable font (Pillow >= 10.1) at ``size`` px."""
    from PIL import ImageFont

    return ImageFont.load_default(size=size)


def text_width(text: str, size: int = 12) -> int:
    """The width in px of ``text``'s widest line in :func:`font` ``(size)``."""
    return max(math.ceil(font(size).getlength(line)) for line in text.split("\n"))


def preview_uint8(img: np.ndarray, max_side: int) -> np.ndarray:
    """An image in [0, 1] (rows, cols[, 3]), taken every ``step`` pixels so that its larger side is
    at most twice ``max_side`` (the panel's resize smooths the rest), as RGB uint8. (The step was
    rounded down until 2026-11-30, so that a 3000 px photo in an 870 px panel was converted whole:
    0.1-0.4 s of a ``rectify``'s figure, with the segmentation's threads on both cores.)"""
    step = max(1, math.ceil(max(img.shape[:2]) / (2 * max_side)))
    sub = to_uint8(img[::step, ::step])
    return np.repeat(sub[..., None], 3, axis=-1) if sub.ndim == 2 else sub


def nice_step(span: float, length_px: float, min_px: float = 45.0) -> float:
    """The smallest of 1, 2, 5 x 10^k whose ticks are at least ``min_px`` apart on a ``span`` drawn
    ``length_px`` long."""
    per_unit = length_px / max(span, 1e-12)
    k = math.floor(math.log10(max(min_px / per_unit, 1e-12)))
    for m in (1, 2, 5, 10):
        if m * 10.0**k * per_unit >= min_px:
            return m * 10.0**k
    return 10.0 ** (k + 1)  # pragma: no cover - the loop ends at 10


@dataclass(frozen=True)
class Panel:
    """The rectangle ``(x0, y0)``-``(x0 + w, y0 + h)`` of a canvas showing the source box
    ``(u0, v0)``-``(u1, v1)``; ``flip`` when the source's v axis points up (wall metres)."""

    x0: float
    y0: float
    w: float
    h: float
    u0: float
    v0: float
    u1: float
    v1: float
    flip: bool = False

    def xy(self, pts) -> list[tuple[float, float]]:
        """Canvas positions of source points ``(n, 2)``."""
        p = np.asarray(pts, dtype=np.float64).reshape(-1, 2)
        x = self.x0 + (p[:, 0] - self.u0) * (self.w / (self.u1 - self.u0))
        t = (p[:, 1] - self.v0) / (self.v1 - self.v0)
        y = self.y0 + (1.0 - t if self.flip else t) * self.h
        return list(zip(x.tolist(), y.tolist()))


class Canvas:
    """A white RGB canvas. Each image panel is drawn on its own layer, so that lines running past
    its edges (an outline partly outside the photo) are clipped to it; :meth:`save` pastes the
    layers in. Colours may carry an alpha (blended)."""

    def __init__(self, width: int, height: int):
        from PIL import Image, ImageDraw

        self.image = Image.new("RGB", (int(width), int(height)), COLOURS["white"])
        self.draw = ImageDraw.Draw(self.image, "RGBA")
        self._layers: dict[Panel, tuple] = {}

    def image_panel(self, img: np.ndarray, x0: int, y0: int, size: tuple[int, int], box, *, flip=False) -> Panel:
        """A panel showing ``img`` (rows, cols[, 3]) in [0, 1] resized to ``size`` (w, h) at
        ``(x0, y0)``; ``box`` ``(u0, v0, u1, v1)`` is the source frame's extent it shows."""
        from PIL import Image, ImageDraw

        layer = Image.fromarray(preview_uint8(img, max(size))).resize(size, Image.Resampling.BILINEAR)
        panel = Panel(x0, y0, size[0], size[1], *box, flip=flip)
        self._layers[panel] = (layer, ImageDraw.Draw(layer, "RGBA"))
        return panel

    def _on(self, panel: Panel, pts) -> tuple:
        """The panel's drawer and ``pts`` in its layer's pixels."""
        return self._layers[panel][1], [(x - panel.x0, y - panel.y0) for x, y in panel.xy(pts)]

    def polyline(self, panel: Panel, pts, colour, width: int = 1, alpha: float = 1.0, closed=False) -> None:
        draw, xy = self._on(panel, pts)
        if closed:
            xy = xy + xy[:1]
        draw.line(xy, fill=_rgba(colour, alpha), width=width)

    def segments(self, panel: Panel, segs: np.ndarray, colour, width: int = 1, alpha: float = 1.0) -> None:
        """Segments ``(n, 4)``: x0, y0, x1, y1 in the source frame."""
        fill = _rgba(colour, alpha)
        draw, xy = self._on(panel, np.asarray(segs, dtype=np.float64).reshape(-1, 2))
        for a, b in zip(xy[0::2], xy[1::2]):
            draw.line([a, b], fill=fill, width=width)

    def rings(self, panel: Panel, pts, colour, radius: float = 6.0, width: int = 2) -> None:
        draw, xy = self._on(panel, pts)
        for x, y in xy:
            draw.ellipse([x - radius, y - radius, x + radius, y + radius], outline=_rgba(colour), width=width)

    def text(self, xy, text: str, size: int = 12, colour="black", anchor: str = "la") -> None:
        """Text on the canvas (outside the panels), at canvas pixels ``xy``."""
        self.draw.multiline_text(xy, text, fill=_rgba(colour), font=font(size), anchor=anchor, spacing=3)

    def legend(self, panel: Panel, entries: list[tuple[str, str, str]], size: int = 11) -> None:
        """A box in the panel's lower left corner: ``(kind, colour, label)``, kind ``"line"`` or
        ``"ring"``."""
        draw = self._layers[panel][1]
        f = font(size)
        pad, swatch, row = 6, 22, size + 6
        width = pad * 3 + swatch + max(int(draw.textlength(lab, font=f)) for _, _, lab in entries)
        height = pad * 2 + row * len(entries)
        x0, y1 = 8, panel.h - 8
        y0 = y1 - height
        draw.rectangle([x0, y0, x0 + width, y1], fill=(255, 255, 255, 205), outline=COLOURS["grey"])
        for i, (kind, colour, label) in enumerate(entries):
            yc = y0 + pad + row * i + row / 2
            if kind == "ring":
                xc = x0 + pad + swatch / 2
                draw.ellipse([xc - 4, yc - 4, xc + 4, yc + 4], outline=_rgba(colour), width=2)
            else:  # a grey rim, so that a white line shows on the white box
                draw.line([(x0 + pad - 1, yc), (x0 + pad + swatch + 1, yc)], fill=_rgba("grey"), width=5)
                draw.line([(x0 + pad, yc), (x0 + pad + swatch, yc)], fill=_rgba(colour), width=3)
            draw.text((x0 + 2 * pad + swatch, yc), label, fill=_rgba("black"), font=f, anchor="lm")

    def save(self, path) -> None:
        """The panels pasted in, framed, and the canvas written as a PNG at zlib level 1 (as
        :func:`calib_masonry._figure.save`)."""
        for panel, (layer, _) in self._layers.items():
            self.image.paste(layer, (int(panel.x0), int(panel.y0)))
            box = [panel.x0 - 1, panel.y0 - 1, panel.x0 + panel.w, panel.y0 + panel.h]
            self.draw.rectangle(box, outline=COLOURS["grey"])
        self.image.save(path, compress_level=1)


def _rgba(colour, alpha: float = 1.0) -> tuple[int, int, int, int]:
    r, g, b = COLOURS[colour] if isinstance(colour, str) else colour
    return (r, g, b, round(255 * alpha))

"""Synthetic ground truth: every wall's bricks laid out in wall metres.

Courses are shared by all walls of a structure (the same z levels), so corners interlock: at a
convex corner between walls a and b, course i belongs to one of them (alternating with i). The
owner's brick runs through the corner; the other wall's photo shows the owner's end face there, a
piece ``t / sin(turn)`` wide (``t`` for a right angle), as a real photo would. Those pieces are
flagged ``end_face`` and are not bricks of the wall they appear on.

Layouts: ``stretcher`` (rectangular bricks in stretcher bond) and ``stones`` (irregular, roughly
rectangular stones in courses of varying height). Deterministic for a given seed.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..build3d.place import Corner, corners
from ..spec import StructureSpec, SyntheticSpec

__all__ = ["Piece", "Course", "layout_structure", "course_levels"]

#: A top course lower than this fraction of its nominal height is left out (the wall top is mortar).
MIN_TOP_COURSE_FRACTION = 0.4


@dataclass(frozen=True)
class Course:
    index: int
    z0: float
    z1: float


@dataclass(frozen=True)
class Piece:
    """One visible piece of a wall's outer face: a brick or stone, or another wall's end face."""

    wall: int
    course: int
    polygon_m: np.ndarray  # (k, 2) wall metres (x along, z up), counter-clockwise
    end_face: bool = False


def course_levels(spec: StructureSpec, rng: np.random.Generator) -> list[Course]:
    """z ranges of all courses up to the tallest wall."""
    syn = spec.synthetic or SyntheticSpec()
    top = max(w.height_m for w in spec.walls)
    levels, z, i = [], 0.0, 0
    while z < top:
        if syn.layout == "stones":
            h = float(rng.uniform(*syn.stone_height_m))
        else:
            h = syn.brick_height_m
        levels.append(Course(i, z, z + h))
        z += h + syn.mortar_m
        i += 1
    return levels


def _owner(corner_index: int, course: int, a_has: bool, b_has: bool, corner: Corner) -> int | None:
    if not corner.convex:
        return None
    if not a_has:
        return corner.b
    if not b_has:
        return corner.a
    return corner.a if (course + corner_index) % 2 == 0 else corner.b


def _lengths(
    span: float, syn: SyntheticSpec, rng: np.random.Generator, *, half_first: bool, avoid: float
) -> list[float]:
    """Piece lengths filling ``span`` with mortar joints between them.

    The last piece is never a sliver: a leftover shorter than half a unit is merged with the piece
    before it (or the two share the length equally). Pieces within 35 % of ``avoid`` (the corner
    end-face width) are avoided next to corners so the corner pieces stay recognisable.
    """
    m = syn.mortar_m
    unit_lo, unit_hi = (syn.brick_length_m, syn.brick_length_m) if syn.layout == "stretcher" else syn.stone_length_m
    lengths: list[float] = []
    pos = 0.0
    first = True
    while True:
        unit = float(rng.uniform(unit_lo, unit_hi)) if unit_hi > unit_lo else unit_lo
        if first and half_first:
            unit = max((unit - m) / 2.0, 0.5 * unit_lo)
        first = False
        if pos + unit > span - 1e-9:
            break
        lengths.append(unit)
        pos += unit + m
    left = span - pos
    if left <= 1e-9:
        # exact fill: the last joint is not needed
        if lengths:
            lengths[-1] += left + m
        return lengths
    too_short = left < 0.5 * unit_lo or (avoid > 0 and abs(left - avoid) < 0.35 * avoid)
    if not lengths:
        return [span]
    if too_short:
        last = lengths.pop()
        total = last + m + left
        if left < 0.25 * unit_lo:
            lengths.append(total)
        else:
            lengths.extend([(total - m) / 2.0] * 2)
    else:
        lengths.append(left)
    return lengths


def _stone(
    x0: float,
    x1: float,
    z0: float,
    z1: float,
    irr: float,
    rng: np.random.Generator,
    *,
    flush_start: bool = False,
    flush_end: bool = False,
    flush_base: bool = False,
) -> np.ndarray:
    """An irregular stone inside the cell [x0, x1] x [z0, z1]: chamfered, tilted, at most 8 vertices.

    ``flush_start`` / ``flush_end``: the stone ends a wall (a jamb stone), so its face on that end
    lies on the cell's side x0 / x1, plumb, as a mason sets it; ``flush_base``: the stone is of the
    first course, bedded on the footing, so its bottom face lies on z0. Its corners may still be
    chamfered, the notches mortared to the wall's outline as bed joints are. The random draws are
    the same either way, so the rest of a layout does not change with it."""
    w, h = x1 - x0, z1 - z0
    s = min(w, h)

    # inward shifts of the four corners tilt the edges slightly
    def shift(keep: bool = True) -> float:
        d = float(rng.uniform(0.0, 0.06 * irr * s))
        return d if keep else 0.0

    corners_xy = [
        (x0 + shift(not flush_start), z0 + shift(not flush_base)),
        (x1 - shift(not flush_end), z0 + shift(not flush_base)),
        (x1 - shift(not flush_end), z1 - shift()),
        (x0 + shift(not flush_start), z1 - shift()),
    ]
    pts: list[tuple[float, float]] = []
    for k, (cx, cz) in enumerate(corners_xy):
        prev_pt = np.array(corners_xy[k - 1])
        next_pt = np.array(corners_xy[(k + 1) % 4])
        here = np.array([cx, cz])
        if rng.uniform() < 0.35 + 0.6 * irr:
            c1 = float(rng.uniform(0.05, 0.3) * irr * s)
            c2 = float(rng.uniform(0.05, 0.3) * irr * s)
            a = here + (prev_pt - here) / np.linalg.norm(prev_pt - here) * c1
            b = here + (next_pt - here) / np.linalg.norm(next_pt - here) * c2
            pts.extend([tuple(a), tuple(b)])
        else:
            pts.append((cx, cz))
    return np.asarray(pts, dtype=np.float64)


def _rect(x0: float, x1: float, z0: float, z1: float) -> np.ndarray:
    return np.array([[x0, z0], [x1, z0], [x1, z1], [x0, z1]], dtype=np.float64)


def layout_structure(spec: StructureSpec) -> list[list[Piece]]:
    """Every wall's pieces (bricks and corner end faces), wall by wall, course by course."""
    syn = spec.synthetic or SyntheticSpec()
    rng = np.random.default_rng(syn.seed)
    courses = course_levels(spec, rng)
    cs = corners(spec)
    start_corner = {c.b: (k, c) for k, c in enumerate(cs)}
    end_corner = {c.a: (k, c) for k, c in enumerate(cs)}
    nominal_h = syn.brick_height_m if syn.layout == "stretcher" else syn.stone_height_m[0]

    def has_course(wall: int, course: Course) -> bool:
        return course.z0 + MIN_TOP_COURSE_FRACTION * min(nominal_h, course.z1 - course.z0) <= spec.walls[wall].height_m

    out: list[list[Piece]] = []
    for n, wall in enumerate(spec.walls):
        pieces: list[Piece] = []
        for course in courses:
            if not has_course(n, course):
                continue
            z0, z1 = course.z0, min(course.z1, wall.height_m)
            a, b = 0.0, wall.width_m
            avoid_start = avoid_end = 0.0
            open_start = True
            if n in start_corner:
                k, c = start_corner[n]
                owner = _owner(k, course.index, has_course(c.a, course), True, c)
                if owner is not None:
                    open_start = False
                    w_end = c.end_width_on(spec.walls[c.a].thickness_m)
                    if owner == c.a:
                        zt = min(z1, spec.walls[c.a].height_m)
                        pieces.append(Piece(n, course.index, _rect(0.0, w_end, z0, zt), True))
                        a = w_end + syn.mortar_m
                    else:
                        avoid_start = w_end
            if n in end_corner:
                k, c = end_corner[n]
                owner = _owner(k, course.index, True, has_course(c.b, course), c)
                if owner is not None:
                    w_end = c.end_width_on(spec.walls[c.b].thickness_m)
                    if owner == c.b:
                        zt = min(z1, spec.walls[c.b].height_m)
                        pieces.append(Piece(n, course.index, _rect(wall.width_m - w_end, wall.width_m, z0, zt), True))
                        b = wall.width_m - w_end - syn.mortar_m
                    else:
                        avoid_end = w_end
            half_first = open_start and course.index % 2 == 1
            lengths = _lengths(b - a, syn, rng, half_first=half_first, avoid=max(avoid_start, avoid_end))
            x = a
            for k, length in enumerate(lengths):
                x1 = min(x + length, b)
                if syn.layout == "stones":
                    # a wall's free end (no corner there) is a jamb: its stones' faces are set to
                    # the end's plumb line, as the corner's end faces are, so the wall ends where
                    # its stones do (a strip of mortar beyond them, 0-1.5 cm, was not a wall's end a
                    # mason builds, and no photo shows it against a pale sky); and the first
                    # course is bedded on the footing, its stones' bottoms on the base line (a
                    # wedge of mortar below them, 0-1.5 cm, blurred into the stones' edge in a
                    # photo and tilted the detected base: the tall walls' scale 2-5 % off)
                    poly = _stone(
                        x,
                        x1,
                        z0,
                        z1,
                        syn.irregularity,
                        rng,
                        flush_start=k == 0 and n not in start_corner,
                        flush_end=k == len(lengths) - 1 and n not in end_corner,
                        flush_base=course.index == 0,
                    )
                else:
                    poly = _rect(x, x1, z0, z1)
                pieces.append(Piece(n, course.index, poly, False))
                x = x1 + syn.mortar_m
        out.append(pieces)
    return out

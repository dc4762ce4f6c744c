"""Stretcher-bond interlocking at corners (the threshold method, made pairwise).

At a convex corner between wall a (ending) and wall b (starting), each course belongs to one of
the two walls: the owner's brick runs through the corner and the other wall's photo shows the
owner's end face there, a piece ``w = t_owner / sin(turn)`` wide. Those end-face pieces are not
bricks of the wall they appear on and are removed before extrusion.

The method's test: a polygon whose centre lies within ``w / 2`` of the wall end and whose area is
about ``A_th = w x course height`` is a corner piece. Pixel rounding and half bricks of nearly the
same width make that test ambiguous on its own, so it only nominates candidates (centre within
``CENTRE_TOL x w`` of the end, width within ``WIDTH_TOL`` of ``w``); where both walls nominate a
piece in the same course, the one whose width is closer to its expected ``w`` is the end face.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .place import Corner, WallFrame

__all__ = ["CornerTolerances", "find_end_faces", "corner_clip_planes"]


@dataclass(frozen=True)
class CornerTolerances:
    centre: float = 0.65  # candidate if its centre is within centre x w of the wall end
    width_lo: float = 0.6  # and its width is between width_lo x w ...
    width_hi: float = 1.4  # ... and width_hi x w
    z_overlap: float = 0.5  # pieces of the two walls share a course if their z ranges overlap this much


def _extent(poly: np.ndarray) -> tuple[float, float, float, float, float]:
    x, z = poly[:, 0], poly[:, 1]
    return float(x.min()), float(x.max()), float(z.min()), float(z.max()), float(x.mean())


def _z_shared(e1, e2, frac: float) -> bool:
    lo, hi = max(e1[2], e2[2]), min(e1[3], e2[3])
    return hi - lo >= frac * min(e1[3] - e1[2], e2[3] - e2[2])


#: two rival end-face candidates whose widths match their end widths within this (a fraction) of
#: each other are told apart by their walls' unit lengths (:func:`_module_length`)
TIE = 0.1


def _module_length(ext: list, width_m: float) -> float | None:
    """The length (m) of a bond's units: the median width of a wall's pieces that touch neither of
    its ends, where the middle half of them lie within 5 % of it (bricks); None for units of many
    lengths (stones) or fewer than three."""
    inner = [e[1] - e[0] for e in ext if e[0] > 0.02 * width_m and e[1] < 0.98 * width_m]
    if len(inner) < 3:
        return None
    q1, med, q3 = np.percentile(inner, [25, 50, 75])
    return float(med) if q3 - q1 <= 0.1 * med else None


def find_end_faces(
    polygons: list[list[np.ndarray]],
    frames: list[WallFrame],
    corners: list[Corner],
    tol: CornerTolerances = CornerTolerances(),
) -> list[set[int]]:
    """Indices (into ``polygons[n]``) of the end-face pieces to remove from each wall.

    ``polygons[n]`` are wall ``n``'s outer-face polygons in wall metres ``(k, 2)``.
    """
    remove: list[set[int]] = [set() for _ in polygons]
    ext = [[_extent(p) for p in polys] for polys in polygons]
    module = [_module_length(e, f.width_m) for e, f in zip(ext, frames)]
    for c in corners:
        if not c.convex:
            continue
        fa, fb = frames[c.a], frames[c.b]
        w_a = c.end_width_on(fb.thickness_m)  # b's end faces seen on a
        w_b = c.end_width_on(fa.thickness_m)  # a's end faces seen on b
        edge_a = 0.25 * w_a
        edge_b = 0.25 * w_b

        def cand_a(e) -> bool:
            width = e[1] - e[0]
            return (
                e[1] >= fa.width_m - edge_a
                and fa.width_m - 0.5 * (e[0] + e[1]) <= tol.centre * w_a
                and tol.width_lo * w_a <= width <= tol.width_hi * w_a
            )

        def cand_b(e) -> bool:
            width = e[1] - e[0]
            return (
                e[0] <= edge_b
                and 0.5 * (e[0] + e[1]) <= tol.centre * w_b
                and tol.width_lo * w_b <= width <= tol.width_hi * w_b
            )

        at_end_a = [i for i, e in enumerate(ext[c.a]) if e[1] >= fa.width_m - edge_a]
        at_start_b = [i for i, e in enumerate(ext[c.b]) if e[0] <= edge_b]
        for i in at_end_a:
            ea = ext[c.a][i]
            if not cand_a(ea):
                continue
            partners = [j for j in at_start_b if _z_shared(ea, ext[c.b][j], tol.z_overlap)]
            if not partners:
                continue  # nothing of wall b in this course: a's piece is its own brick
            rival = [j for j in partners if cand_b(ext[c.b][j])]
            if not rival:
                remove[c.a].add(i)
                continue
            j = rival[0]
            eb = ext[c.b][j]
            da = abs((ea[1] - ea[0]) / w_a - 1.0)
            db = abs((eb[1] - eb[0]) / w_b - 1.0)
            if abs(da - db) <= TIE and module[c.a] and module[c.b]:
                # both as wide as an end face (a unit as long as the other wall is thick): the one
                # that is no unit of its own wall's length is the end face
                da -= abs((ea[1] - ea[0]) / module[c.a] - 1.0)
                db -= abs((eb[1] - eb[0]) / module[c.b] - 1.0)
            if da <= db:
                remove[c.a].add(i)
            else:
                remove[c.b].add(j)
        for j in at_start_b:
            eb = ext[c.b][j]
            if j in remove[c.b] or not cand_b(eb):
                continue
            partners = [i for i in at_end_a if _z_shared(eb, ext[c.a][i], tol.z_overlap)]
            if partners and not any(cand_a(ext[c.a][i]) for i in partners):
                remove[c.b].add(j)
    return remove


def corner_clip_planes(
    poly: np.ndarray, wall: int, frames: list[WallFrame], corners: list[Corner]
) -> tuple[np.ndarray, list[tuple[np.ndarray, np.ndarray]]]:
    """The polygon, extended where it runs through a corner, and the vertical planes that cut it.

    A brick that reaches a corner (it owns that course) is extended past the wall end and cut by
    the other wall's outer face; a brick that stops short of the corner is cut by the other wall's
    inner face. At a right angle neither changes anything. Planes are ``(point_xy, normal_xy)``
    keeping the side the normal points to.
    """
    fr = frames[wall]
    planes: list[tuple[np.ndarray, np.ndarray]] = []
    poly = np.asarray(poly, dtype=np.float64)
    for c in corners:
        if not c.convex or wall not in (c.a, c.b):
            continue
        if c.a == c.b:
            continue
        other = frames[c.b if wall == c.a else c.a]
        w = c.end_width_on(other.thickness_m)
        reach = 2.0 * (w + fr.thickness_m + other.thickness_m)
        right_angle = abs(np.cos(c.turn_rad)) < 1e-9
        if wall == c.a:
            xmax = poly[:, 0].max()
            if xmax < fr.width_m - w - reach:
                continue
            owner = xmax >= fr.width_m - 0.5 * w
            if owner and not right_angle:
                poly = poly.copy()
                ends = poly[:, 0] >= xmax - 1e-9
                poly[ends, 0] = fr.width_m + reach
        else:
            xmin = poly[:, 0].min()
            if xmin > w + reach:
                continue
            owner = xmin <= 0.5 * w
            if owner and not right_angle:
                poly = poly.copy()
                ends = poly[:, 0] <= xmin + 1e-9
                poly[ends, 0] = -reach
        normal = other.inward
        point = other.origin_xy if owner else other.origin_xy + other.thickness_m * other.inward
        planes.append((point, normal))
    return poly, planes

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
import shapely

from .place import Corner, WallFrame

__all__ = [
    "CornerTolerances",
    "LAST",
    "SHELTERED",
    "find_end_faces",
    "course_ends",
    "corner_roles",
    "corner_clip_planes",
]


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
#: rivals told apart by less than this, after that, are a guess (:func:`find_end_faces`'s ``guesses``)
GUESS = 0.05


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
    guesses: list[int] | None = None,
) -> list[set[int]]:
    """Indices (into ``polygons[n]``) of the end-face pieces to remove from each wall.

    ``polygons[n]`` are wall ``n``'s outer-face polygons in wall metres ``(k, 2)``. ``guesses``
    (a list, filled): per corner, in the order of ``corners``, the courses where the two walls'
    candidates were told apart by less than :data:`GUESS` (an end face about as wide as the units
    on both sides: which wall runs through there is a guess).
    """
    remove: list[set[int]] = [set() for _ in polygons]
    ext = [[_extent(p) for p in polys] for polys in polygons]
    module = [_module_length(e, f.width_m) for e, f in zip(ext, frames)]
    for c in corners:
        if guesses is not None:
            guesses.append(0)
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
            if guesses is not None and abs(da - db) <= GUESS:
                guesses[-1] += 1
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


#: a non-owner's brick whose end lies within this many end-face widths of its wall's end is the
#: one next to the other wall's end face (the joint between them, mortar and a stone's irregular
#: edge, is far narrower); it reaches back to the owner's inner face
NEXT_TO_END_FACE = 1.5


def _end_band(poly: np.ndarray, at_start: bool) -> tuple[float, float, float, float] | None:
    """Where ``poly`` ``(k, 2)`` ends at its wall's start (``at_start``) or end: its outermost x,
    the band ``d`` inward from it that is squared off when it is carried on (a quarter of its height,
    at most half its width), and that band's z-span (None if the band holds nothing of it)."""
    x, z = poly[:, 0], poly[:, 1]
    d = min(0.5 * float(x.max() - x.min()), max(0.25 * float(z.max() - z.min()), 1e-3))
    end = float(x.min() if at_start else x.max())
    lo, hi = (end, end + d) if at_start else (end - d, end)
    part = shapely.Polygon(poly).intersection(shapely.box(lo, float(z.min()), hi, float(z.max())))
    if part.is_empty:
        return None
    _, zlo, _, zhi = part.bounds
    return end, d, zlo, zhi


def _carried_past(poly: np.ndarray, at_start: bool, to_x: float) -> np.ndarray:
    """``poly`` ``(k, 2)`` with its end at the wall's start (``at_start``) or end carried on to
    ``x = to_x``: the union with a rectangle over the z-span of its end band (:func:`_end_band`), so
    an irregular stone's end runs on whole (before 2026-12-06 only its one outermost vertex was
    moved, a sliver). A rectangle's end stays as it is, moved."""
    band = _end_band(poly, at_start)
    if band is None:
        return poly
    end, d, zlo, zhi = band
    rect = shapely.box(to_x, zlo, end + d, zhi) if at_start else shapely.box(end - d, zlo, to_x, zhi)
    u = shapely.Polygon(poly).union(rect)
    if not isinstance(u, shapely.Polygon):
        return poly
    u = shapely.geometry.polygon.orient(u.simplify(0.0), 1.0)  # counter-clockwise, no collinear points
    return np.asarray(u.exterior.coords, dtype=np.float64)[:-1]


#: a piece's place in its course at a corner (:func:`course_ends`): it ends the course there
LAST = "last"
#: a piece of its own wall lies beyond it and reaches the corner: the corner is its wall's in
#: this course, and nothing of the other wall comes near it
SHELTERED = "sheltered"


def _reaches_corner(poly: np.ndarray, at_start: bool, width_m: float, w: float) -> bool:
    """Whether a piece (wall metres) reaches its wall's start (``at_start``) or end within half the
    other wall's end-face width ``w``: it owns the corner in its course."""
    return float(poly[:, 0].min()) <= 0.5 * w if at_start else float(poly[:, 0].max()) >= width_m - 0.5 * w


def course_ends(
    polys: list[np.ndarray], wall: int, frames: list[WallFrame], corners: list[Corner]
) -> list[tuple[str | None, str | None]]:
    """Per polygon of wall ``wall`` (its kept pieces, end faces removed), its place in its course at
    the wall's start and at its end: :data:`LAST` where nothing of the wall lies between it and the
    wall's end in the way it would be carried past the corner (its end band's z-span,
    :func:`_end_band`; another piece counts where 2 % of its area lies there), :data:`SHELTERED`
    where a piece in that way reaches the corner (within half the end face's width of it), else
    None. Only the last piece of a course may run past a corner: by distance alone a piece before
    the corner's own could not be told from the one next to the other wall's end face where the end
    face is about as wide as a unit (a hexagonal tower of 0.35 m walls and 0.40 m bricks). Pieces
    far from any corner, or at a right angle (where nothing is carried on), get None there."""
    fr = frames[wall]
    w_at = [None, None]  # the end faces' width at the wall's start and end (a re-entrant corner's: its depth)
    for c in corners:
        if ((c.convex and not c.right_angle) or c.reentrant) and wall in (c.a, c.b) and c.a != c.b:
            w = abs(c.end_width_on(frames[c.b if wall == c.a else c.a].thickness_m))
            w_at[0 if wall == c.b else 1] = w
    out: list[tuple[str | None, str | None]] = [(None, None)] * len(polys)
    if w_at == [None, None]:
        return out
    shapes = [shapely.Polygon(p) for p in polys]
    tree = shapely.STRtree(shapes)
    lo = np.array([p[:, 0].min() for p in polys])
    hi = np.array([p[:, 0].max() for p in polys])
    for i, p in enumerate(polys):
        roles: list[str | None] = []
        for at_start, w in zip((True, False), w_at):
            near = w is not None and (
                lo[i] <= (NEXT_TO_END_FACE + 1.0) * w
                if at_start
                else hi[i] >= fr.width_m - (NEXT_TO_END_FACE + 1.0) * w
            )
            band = _end_band(p, at_start) if near else None
            if band is None:
                roles.append(None)
                continue
            end, d, zlo, zhi = band
            way = shapely.box(-1.0, zlo, end + d, zhi) if at_start else shapely.box(end - d, zlo, fr.width_m + 1.0, zhi)
            hit = [
                int(j) for j in tree.query(way) if j != i and shapes[j].intersection(way).area > 0.02 * shapes[j].area
            ]
            if not hit:
                roles.append(LAST)
            elif any(_reaches_corner(polys[j], at_start, fr.width_m, w) for j in hit):
                roles.append(SHELTERED)
            else:
                roles.append(None)
        out[i] = (roles[0], roles[1])
    return out


def corner_roles(
    polys: list[list[np.ndarray]], frames: list[WallFrame], corners: list[Corner]
) -> list[list[tuple[str | None, str | None]]]:
    """:func:`course_ends` of every wall's kept pieces (``polys[wall]``), less the claims two walls
    make on one corner in one course: where the last piece of each reaches the corner (both seem to
    own it, as where the end face is about as wide as a unit and the end faces were told apart
    wrongly), neither is carried past it (each keeps its cut at the other wall's outer face, as
    before 2026-12-06), since both would fill the corner and overlap there."""
    roles = [course_ends(p, w, frames, corners) for w, p in enumerate(polys)]
    for c in corners:
        if not c.convex or c.right_angle or c.a == c.b:
            continue
        fa, fb = frames[c.a], frames[c.b]
        wa, wb = c.end_width_on(fb.thickness_m), c.end_width_on(fa.thickness_m)
        own_a = [
            i
            for i, p in enumerate(polys[c.a])
            if roles[c.a][i][1] == LAST and _reaches_corner(p, False, fa.width_m, wa)
        ]
        own_b = [
            j for j, p in enumerate(polys[c.b]) if roles[c.b][j][0] == LAST and _reaches_corner(p, True, fb.width_m, wb)
        ]
        for i in own_a:
            za = polys[c.a][i][:, 1]
            for j in own_b:
                zb = polys[c.b][j][:, 1]
                if min(za.max(), zb.max()) - max(za.min(), zb.min()) > 1e-3:
                    roles[c.a][i] = (roles[c.a][i][0], None)
                    roles[c.b][j] = (None, roles[c.b][j][1])
    return roles


def corner_clip_planes(
    poly: np.ndarray,
    wall: int,
    frames: list[WallFrame],
    corners: list[Corner],
    ends: tuple[str | None, str | None] = (None, None),
) -> tuple[np.ndarray, list[tuple[np.ndarray, np.ndarray]]]:
    """The polygon, extended where it runs through a corner, and the vertical planes that cut it.

    A brick that reaches a corner (it owns that course) is carried past the wall end and cut by
    the other wall's outer face. The brick next to the other wall's end face (the corner is the
    other wall's in this course) is carried past the wall end too and cut by a plane parallel to
    the other wall's inner face, through its own end on the outer face (the joint keeps the width
    the photo shows; never nearer the corner than the inner face itself): at a corner that is not a
    right angle the two walls' bands then meet without a hole (before 2026-12-06 that brick
    stopped square at its end, and a triangle ``t^2 cot(turn) / 2`` stayed open at every corner of
    every course: 7 % of a hexagonal tower's ring, 11 % of an octagonal one's). Any other brick
    near a corner is cut by the other wall's inner face, unless a piece of its own wall beyond it
    owns the corner in its course (before 2026-12-06 it was cut even then: a triangle of it was
    lost wherever the owner's piece is shorter than the end face is wide). At a right angle none of
    this changes anything. Planes are ``(point_xy, normal_xy)`` keeping the side the normal points
    to.

    ``ends``: the piece's place in its course at the wall's start and end (:func:`course_ends`);
    only the last piece is carried on (one that reaches the corner but does not end its course,
    where pieces overlap in a traced photo, keeps the other wall's outer face as its cut, as
    before).
    """
    fr = frames[wall]
    planes: list[tuple[np.ndarray, np.ndarray]] = []
    poly = np.asarray(poly, dtype=np.float64)
    for c in corners:
        if c.reentrant and wall in (c.a, c.b) and c.a != c.b:
            poly, cuts = _reentrant(poly, wall, frames, c, ends)
            planes += cuts
            continue
        if not c.convex or wall not in (c.a, c.b):
            continue
        if c.a == c.b:
            continue
        other = frames[c.b if wall == c.a else c.a]
        w = c.end_width_on(other.thickness_m)
        reach = 2.0 * (w + fr.thickness_m + other.thickness_m)
        at_start = wall == c.b
        if at_start:
            end = float(poly[:, 0].min())
            gone = end > w + reach
            last, sheltered = ends[0] == LAST, ends[0] == SHELTERED
            owner = _reaches_corner(poly, True, fr.width_m, w)
            beside = last and not owner and end <= NEXT_TO_END_FACE * w  # next to the other's end face
            past, face_x = -reach, max(end, w)
        else:
            end = float(poly[:, 0].max())
            gone = end < fr.width_m - w - reach
            last, sheltered = ends[1] == LAST, ends[1] == SHELTERED
            owner = _reaches_corner(poly, False, fr.width_m, w)
            beside = last and not owner and end >= fr.width_m - NEXT_TO_END_FACE * w
            past, face_x = fr.width_m + reach, min(end, fr.width_m - w)
        if c.right_angle:  # as before 2026-12-06, to the bit: a right angle needs none of this
            sheltered = beside = last = False
        if gone or (sheltered and not owner):
            continue
        if last and (owner or beside):
            poly = _carried_past(poly, at_start, past)
        normal = other.inward
        if owner:
            point = other.origin_xy
        elif beside:
            point = fr.origin_xy + face_x * fr.direction  # on this wall's outer face
        else:
            point = other.origin_xy + other.thickness_m * other.inward
        planes.append((point, normal))
    return poly, planes


def _reentrant(
    poly: np.ndarray, wall: int, frames: list[WallFrame], c: Corner, ends: tuple[str | None, str | None]
) -> tuple[np.ndarray, list[tuple[np.ndarray, np.ndarray]]]:
    """A piece at a re-entrant corner (an L or T plan's inner corner, :attr:`Corner.reentrant`): the
    last of its course, where it reaches the corner's edge (within half the other wall's depth
    there), is carried past its wall's end into the masonry that neither photo shows, between the
    two walls' bands, up to the other wall's inner face and to the mitre through the corner's edge
    and the inner faces' meeting point, so the two walls meet over that mitre (which wall's units
    run through in which course is hidden in both photos). Before 2026-12-06 that masonry was left
    out: a void of t x t at a right angle, the two walls touching along the corner's edge alone, with
    no joint between them (the paper example's walls 3 and 4)."""
    fr = frames[wall]
    at_start = wall == c.b
    other = frames[c.a if at_start else c.b]
    w = abs(c.end_width_on(other.thickness_m))
    end = float(poly[:, 0].min() if at_start else poly[:, 0].max())
    reaches = end <= 0.5 * w if at_start else end >= fr.width_m - 0.5 * w
    if ends[0 if at_start else 1] != LAST or not reaches:
        return poly, []
    reach = 2.0 * (w + fr.thickness_m + other.thickness_m)
    poly = _carried_past(poly, at_start, -reach if at_start else fr.width_m + reach)
    edge = fr.origin_xy if at_start else fr.origin_xy + fr.width_m * fr.direction  # the corner's edge
    # where the two inner faces meet: edge + t_a n_a + s d_a = edge + t_b n_b + u d_b
    a, b = (other, fr) if at_start else (fr, other)
    m = np.column_stack([a.direction, -b.direction])
    s, _ = np.linalg.solve(m, b.thickness_m * b.inward - a.thickness_m * a.inward)
    inner = edge + a.thickness_m * a.inward + s * a.direction
    along = inner - edge
    normal = np.array([-along[1], along[0]])
    own = edge + 0.5 * fr.thickness_m * fr.inward + (0.01 if at_start else -0.01) * fr.direction  # inside this band
    if np.dot(own - edge, normal) < 0:
        normal = -normal
    # the other wall's inner face: keep the side of its outer face
    return poly, [(other.origin_xy + other.thickness_m * other.inward, -other.inward), (edge, normal)]

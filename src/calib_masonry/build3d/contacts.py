"""Overlaps between bricks: the largest interpenetration volume of a built structure.

Pairs are found cheaply first (bricks of one wall: their outer-face polygons intersect, shapely;
bricks of different walls: their global bounding boxes overlap) and only those are intersected
exactly as solids (manifold3d).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import manifold3d
import numpy as np
import shapely

from .assemble import Brick
from .extrude import Polyhedron

__all__ = [
    "Interpenetration",
    "max_interpenetration",
    "intersection_volume",
    "ContactPatch",
    "contact_patches",
    "joint_axes",
    "patch_section",
    "OUTLINE_POINTS",
    "box_pairs",
]

OUTLINE_POINTS = 16  # a patch's outline (its convex hull) is stored with this many corners, padded by repeats


@dataclass(frozen=True)
class Interpenetration:
    max_volume_m3: float
    pair: tuple[int, int] | None  # global brick ids of the worst pair
    pairs_checked: int


def _manifold(p: Polyhedron, origin: np.ndarray) -> manifold3d.Manifold:
    mesh = manifold3d.Mesh(
        vert_properties=np.ascontiguousarray(p.vertices - origin, dtype=np.float32),
        tri_verts=np.ascontiguousarray(p.faces, dtype=np.uint32),
    )
    return manifold3d.Manifold(mesh=mesh)


def intersection_volume(p: Polyhedron, q: Polyhedron) -> float:
    """Volume of the intersection of two closed polyhedra (m^3)."""
    origin = 0.5 * (p.vertices.mean(axis=0) + q.vertices.mean(axis=0))
    inter = _manifold(p, origin) ^ _manifold(q, origin)
    return float(inter.volume()) if not inter.is_empty() else 0.0


def box_pairs(lo: np.ndarray, hi: np.ndarray, min_overlap: float):
    """Pairs ``(i, j)``, i < j, of boxes ``[lo, hi]`` ``(N, 3)`` overlapping by more than
    ``min_overlap`` along every axis (sweep and prune along x, each box's candidates tested at once):
    the package's one broad phase."""
    order = np.argsort(lo[:, 0], kind="stable")
    lo_s, hi_s = lo[order], hi[order]
    # the candidates of the box at sorted position p are those after it whose lo_x is below its hi_x
    ends = np.searchsorted(lo_s[:, 0], hi_s[:, 0] - min_overlap, side="left")
    for p in range(len(order)):
        q = np.arange(p + 1, max(p + 1, ends[p]))
        if q.size == 0:
            continue
        ok = np.all(np.minimum(hi_s[p], hi_s[q]) - np.maximum(lo_s[p], lo_s[q]) > min_overlap, axis=1)
        i = order[p]
        for j in order[q[ok]]:
            yield (int(i), int(j)) if i < j else (int(j), int(i))


def _candidate_pairs(bricks: Sequence[Brick], eps: float) -> set[tuple[int, int]]:
    pairs: set[tuple[int, int]] = set()
    index = {b.id: k for k, b in enumerate(bricks)}
    # within a wall: outer-face polygons that overlap in area
    for w in sorted({b.wall for b in bricks}):
        own = [b for b in bricks if b.wall == w]
        geoms = [shapely.Polygon(b.polygon_m) for b in own]
        tree = shapely.STRtree(geoms)
        left, right = tree.query(geoms, predicate="intersects")
        for i, j in zip(left.tolist(), right.tolist()):
            if i < j and geoms[i].intersection(geoms[j]).area > eps:
                pairs.add((index[own[i].id], index[own[j].id]))
    # across walls: global boxes that overlap by more than eps in every axis
    lo = np.array([b.solid.vertices.min(axis=0) for b in bricks])
    hi = np.array([b.solid.vertices.max(axis=0) for b in bricks])
    pairs.update((i, j) for i, j in box_pairs(lo, hi, eps) if bricks[i].wall != bricks[j].wall)
    return pairs


def max_interpenetration(bricks: Sequence[Brick], eps: float = 1e-9) -> Interpenetration:
    """The largest volume shared by any two of ``bricks`` (pair reported by brick ids)."""
    worst, worst_pair = 0.0, None
    pairs = sorted(_candidate_pairs(bricks, eps))
    for i, j in pairs:
        v = intersection_volume(bricks[i].solid, bricks[j].solid)
        if v > worst:
            worst, worst_pair = v, (bricks[i].id, bricks[j].id)
    return Interpenetration(max_volume_m3=worst, pair=worst_pair, pairs_checked=len(pairs))


# ----------------------------------------------------------------------------------------------
# contact patches between neighbouring bricks (for mortar bonds)


@dataclass(frozen=True)
class ContactPatch:
    """Two facing faces of bricks ``a`` and ``b`` (global ids) across a joint ``gap_m`` wide.

    ``normal`` points from a to b; ``centroid`` is the middle of the joint over the overlap of the
    two faces projected on a's face plane; ``area_m2`` is that overlap's area.
    """

    a: int
    b: int
    normal: np.ndarray
    centroid: np.ndarray
    area_m2: float
    gap_m: float
    min_width_m: float = 0.0  # the patch's narrower principal extent (the lever arm in bending)
    # second moments (int u^2 dA, int v^2 dA, int u v dA) about the centroid in the joint frame
    # (:func:`joint_axes`), m^4, and the outline's corners (OUTLINE_POINTS, 2) in (u, v), m
    moments: np.ndarray = field(default_factory=lambda: np.zeros(3))
    outline: np.ndarray = field(default_factory=lambda: np.zeros((OUTLINE_POINTS, 2)))


def joint_axes(normals: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each joint's frame from its normal ``(N, 3)``: in-plane axes ``u, v`` and the unit normal ``n``
    (right-handed, ``u = h x n / |h x n|`` with the helper ``h`` = X, or Y where the normal is nearly
    along X, and ``v = n x u``). The Bullet constraints, the joint model and the patches' second
    moments share this frame."""
    n = np.asarray(normals, dtype=np.float64)
    n = n / np.linalg.norm(n, axis=1, keepdims=True)
    helper = np.where(np.abs(n[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    u = _cross(helper, n)
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    return u, _cross(n, u), n


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``np.cross`` of rows ``(N, 3)``, the same products and differences (so the same bits),
    without its axis handling, which cost 50 us a call: a tenth of the contact search, which
    calls it for one normal at a time."""
    return np.stack(
        [
            a[:, 1] * b[:, 2] - a[:, 2] * b[:, 1],
            a[:, 2] * b[:, 0] - a[:, 0] * b[:, 2],
            a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0],
        ],
        axis=1,
    )


def _ring_moments(xy: np.ndarray) -> np.ndarray:
    """(A, int x dA, int y dA, int x^2 dA, int y^2 dA, int x y dA) of a closed ring ``(k + 1, 2)``,
    signed by its orientation (Green's theorem)."""
    x0, y0, x1, y1 = xy[:-1, 0], xy[:-1, 1], xy[1:, 0], xy[1:, 1]
    c = x0 * y1 - x1 * y0
    return np.array(
        [
            c.sum() / 2,
            (c * (x0 + x1)).sum() / 6,
            (c * (y0 + y1)).sum() / 6,
            (c * (x0**2 + x0 * x1 + x1**2)).sum() / 12,
            (c * (y0**2 + y0 * y1 + y1**2)).sum() / 12,
            (c * (x0 * y1 + 2 * x0 * y0 + 2 * x1 * y1 + x1 * y0)).sum() / 24,
        ]
    )


def patch_section(
    poly: shapely.Geometry, basis: np.ndarray, normal: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """A joint patch's section in its joint frame: the patch ``poly`` is in the 2D coordinates of
    ``basis`` ``(2, 3)`` (rows: the plane's axes in 3D); returns its centroid's offset in those
    2D coordinates ``(2,)``, the second moments ``(I_uu, I_vv, I_uv)`` about the centroid in the
    frame of :func:`joint_axes` of ``normal``, its outline's corners ``(OUTLINE_POINTS, 2)`` in
    (u, v) about the centroid (the convex hull, padded by repeats), and its area."""
    parts = [g for g in getattr(poly, "geoms", [poly]) if isinstance(g, shapely.Polygon) and g.area > 0]
    m = np.zeros(6)
    for g in parts:
        g = shapely.geometry.polygon.orient(g, 1.0)
        m += _ring_moments(np.asarray(g.exterior.coords))
        for hole in g.interiors:
            m += _ring_moments(np.asarray(hole.coords))
    area = m[0]
    if area <= 0:
        return np.zeros(2), np.zeros(3), np.zeros((OUTLINE_POINTS, 2)), 0.0
    cx, cy = m[1] / area, m[2] / area
    jxx = m[3] - area * cx * cx
    jyy = m[4] - area * cy * cy
    jxy = m[5] - area * cx * cy
    u, v, _ = (a[0] for a in joint_axes(np.asarray(normal, dtype=np.float64)[None]))
    rot = np.array([[u @ basis[0], u @ basis[1]], [v @ basis[0], v @ basis[1]]])  # (x, y) -> (u, v)
    J = rot @ np.array([[jxx, jxy], [jxy, jyy]]) @ rot.T
    hull = shapely.union_all(parts).convex_hull
    pts = np.asarray(hull.exterior.coords)[:-1] if isinstance(hull, shapely.Polygon) else np.array([[cx, cy]])
    if len(pts) > OUTLINE_POINTS:  # keep the corners farthest apart: evenly along the hull
        pts = pts[np.linspace(0, len(pts), OUTLINE_POINTS, endpoint=False).astype(int)]
    outline = (pts - [cx, cy]) @ rot.T
    outline = np.vstack([outline, np.repeat(outline[-1:], OUTLINE_POINTS - len(outline), axis=0)])
    return np.array([cx, cy]), np.array([J[0, 0], J[1, 1], J[0, 1]]), outline, float(area)


def _planar_faces(
    p: Polyhedron, angle_tol: float = 1e-3
) -> list[tuple[np.ndarray, float, shapely.Geometry, np.ndarray]]:
    """Planar faces of a polyhedron: (unit normal, offset n.x, polygon in the plane's 2D basis, basis)."""
    v = p.vertices[p.faces]
    n = _cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
    area2 = np.linalg.norm(n, axis=1)
    ok = area2 > 1e-15
    n = n[ok] / area2[ok, None]
    v = v[ok]
    d = np.einsum("ij,ij->i", n, v[:, 0])
    groups: dict[tuple, list[int]] = {}
    for i, (ni, di) in enumerate(zip(n, d)):
        key = (round(ni[0] / angle_tol), round(ni[1] / angle_tol), round(ni[2] / angle_tol), round(di * 1e5))
        groups.setdefault(key, []).append(i)
    out = []
    for idx in groups.values():
        normal = n[idx].mean(axis=0)
        normal /= np.linalg.norm(normal)
        offset = float(np.mean(d[idx]))
        basis = _plane_basis(normal)
        tris = shapely.polygons(v[idx] @ basis.T)  # all of the face's triangles at once
        poly = shapely.union_all(tris[shapely.area(tris) > 0])
        out.append((normal, offset, poly, basis))
    return out


def _plane_basis(normal: np.ndarray) -> np.ndarray:
    """Two orthonormal vectors ``(2, 3)`` spanning the plane with this normal."""
    nx, ny, nz = (float(x) for x in normal)
    # normal x helper, with the helper Z, or X where the normal is nearly along Z (written out:
    # np.cross on single vectors was a tenth of the build's time)
    u = np.array([ny, -nx, 0.0]) if abs(nz) < 0.9 else np.array([0.0, nz, -ny])
    u /= np.linalg.norm(u)
    ux, uy, uz = u
    w = np.array([ny * uz - nz * uy, nz * ux - nx * uz, nx * uy - ny * ux])
    return np.vstack([u, w])


def _min_width(poly: shapely.Geometry) -> float:
    """The narrower extent of a patch along its principal axes."""
    hull = poly.convex_hull
    if not isinstance(hull, shapely.Polygon):
        return 0.0
    pts = np.asarray(hull.exterior.coords)[:-1]
    centred = pts - pts.mean(axis=0)
    _, _, vt = np.linalg.svd(centred, full_matrices=False)
    return float(np.ptp(centred @ vt[1]))


def contact_patches(
    bricks: Sequence[Brick],
    *,
    max_gap_m: float = 0.03,
    min_area_m2: float = 1e-4,
    angle_deg: float = 10.0,
    min_gap_m: float = -1e-4,
    progress: bool | None = None,
) -> list[ContactPatch]:
    """Patches where two bricks' faces face each other across at most ``max_gap_m``.

    Any orientation: faces are matched by anti-parallel normals (within ``angle_deg``) and plane
    distance, and the patch is the exact overlap of the two faces projected on a common plane.
    Faces that overlap by more than ``-min_gap_m`` are not a joint. ``progress``: see
    :func:`calib_masonry.progress.progress` (None: a bar on a terminal, log lines otherwise, for a
    step that can take tens of seconds on a large structure).
    """
    from ..progress import progress as _progress

    faces = [_planar_faces(b.solid) for b in _progress(bricks, desc="joint faces", unit="brick", enabled=progress)]
    lo = np.array([b.solid.vertices.min(axis=0) for b in bricks]) - max_gap_m
    hi = np.array([b.solid.vertices.max(axis=0) for b in bricks]) + max_gap_m
    cos_tol = np.cos(np.radians(angle_deg))
    out: list[ContactPatch] = []
    for a, b in _progress(box_pairs(lo, hi, -1e-12), desc="joint patches", unit="pair", enabled=progress):
        best = None
        for na, da, pa, basis in faces[a]:
            for nb, db, pb, basis_b in faces[b]:
                if float(na @ nb) > -cos_tol:
                    continue
                gap = -db - da  # distance from a's plane to b's plane along na (nb ~ -na)
                if gap < min_gap_m or gap > max_gap_m:
                    continue
                # b's face in 3D, projected on a's plane basis
                inter = pa.intersection(shapely.transform(pb, lambda xy: (xy @ basis_b + db * nb) @ basis.T))
                if inter.area < min_area_m2:
                    continue
                if best is None or inter.area > best[0]:
                    best = (inter.area, na, da, gap, inter, basis)
        if best is not None:
            area, normal, da, gap, inter, basis = best
            c2, moments, outline, _ = patch_section(inter, basis, normal)
            centroid = c2 @ basis + (da + 0.5 * gap) * normal
            out.append(
                ContactPatch(
                    a=bricks[a].id,
                    b=bricks[b].id,
                    normal=normal,
                    centroid=centroid,
                    area_m2=float(area),
                    gap_m=float(gap),
                    min_width_m=_min_width(inter),
                    moments=moments,
                    outline=outline,
                )
            )
    out.sort(key=lambda c: (c.a, c.b))
    return out

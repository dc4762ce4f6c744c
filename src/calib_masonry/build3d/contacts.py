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
from .extrude import Polyhedron, _cross

#: the grid (metres) an overlay is snap-rounded to where GEOS cannot node it in floating point
#: ("TopologyException: Ring edge missing", first seen with shapely 2.2 / GEOS 3.14 on a refined
#: wall of the Stylite tower): a nanometre, far below every tolerance here
SNAP_M = 1e-9


def _overlay(op, *args):
    """``op(*args)`` (a shapely overlay: union_all, difference, intersection, elementwise over
    arrays), and where GEOS fails on an element, that element again from valid inputs
    (``make_valid``: a face projected on a plane at a steep angle can come out self-touching) and,
    failing that, on the :data:`SNAP_M` grid (snap-rounding); the others are left as they were."""
    try:
        return op(*args)
    except shapely.errors.GEOSException:
        if op is shapely.union_all or all(np.ndim(a) == 0 for a in args):
            valid = [shapely.make_valid(a) for a in args]
            try:
                return op(*valid)
            except shapely.errors.GEOSException:
                return op(*valid, grid_size=SNAP_M)
    parts = np.broadcast_arrays(*[np.asarray(a, dtype=object) for a in args])
    out = np.empty(parts[0].shape, dtype=object)
    for i in np.ndindex(out.shape):
        out[i] = _overlay(op, *(p[i] for p in parts))
    return out


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
    "narrowest_beds",
    "widest_bed",
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
    min_width_m: float = 0.0  # the patch's least width: across its narrowest direction (its convex hull's)
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


def _ring_moments(xy: np.ndarray, ring: np.ndarray, count: int) -> np.ndarray:
    """(A, int x dA, int y dA, int x^2 dA, int y^2 dA, int x y dA) ``(count, 6)`` of closed rings
    whose corners ``xy`` ``(K, 2)`` (each ring closed, rings one after the other) belong to ring
    ``ring`` ``(K,)``, signed by each ring's orientation (Green's theorem)."""
    same = ring[:-1] == ring[1:]  # the edges: consecutive corners of one ring
    x0, y0, x1, y1 = xy[:-1, 0][same], xy[:-1, 1][same], xy[1:, 0][same], xy[1:, 1][same]
    c = x0 * y1 - x1 * y0
    terms = (
        c / 2,
        c * (x0 + x1) / 6,
        c * (y0 + y1) / 6,
        c * (x0**2 + x0 * x1 + x1**2) / 12,
        c * (y0**2 + y0 * y1 + y1**2) / 12,
        c * (x0 * y1 + 2 * x0 * y0 + 2 * x1 * y1 + x1 * y0) / 24,
    )
    edge_ring = ring[:-1][same]
    return np.stack([np.bincount(edge_ring, t, minlength=count) for t in terms], axis=1)


def patch_sections(
    polys: np.ndarray, bases: np.ndarray, normals: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """:func:`patch_section` of many patches at once: ``polys`` ``(P,)`` shapely geometries,
    ``bases`` ``(P, 2, 3)``, ``normals`` ``(P, 3)``; returns centroids ``(P, 2)``, moments
    ``(P, 3)``, outlines ``(P, OUTLINE_POINTS, 2)``, areas ``(P,)`` and least widths ``(P,)``
    (:func:`_least_widths` of the convex hull)."""
    count = len(polys)
    bases = np.asarray(bases, dtype=np.float64).reshape(count, 2, 3)
    parts, owner = shapely.get_parts(np.asarray(polys, dtype=object), return_index=True)
    keep = (shapely.get_type_id(parts) == 3) & (shapely.area(parts) > 0)  # polygons with an area
    parts, owner = shapely.orient_polygons(parts[keep]), owner[keep]  # exteriors CCW, holes CW
    rings, part_of_ring = shapely.get_rings(parts, return_index=True)
    xy, ring = shapely.get_coordinates(rings, return_index=True)
    per_ring = _ring_moments(xy, ring, len(rings))
    m = np.stack([np.bincount(owner[part_of_ring], per_ring[:, k], minlength=count) for k in range(6)], axis=1)
    area = m[:, 0]
    ok = area > 0
    safe = np.where(ok, area, 1.0)
    cx, cy = m[:, 1] / safe, m[:, 2] / safe
    jxx, jyy, jxy = m[:, 3] - area * cx * cx, m[:, 4] - area * cy * cy, m[:, 5] - area * cx * cy
    u, v, _ = joint_axes(normals)
    rot = np.stack([np.einsum("pk,pjk->pj", u, bases), np.einsum("pk,pjk->pj", v, bases)], axis=1)  # (x, y) -> (u, v)
    J = rot @ np.stack([np.stack([jxx, jxy], -1), np.stack([jxy, jyy], -1)], axis=1) @ np.transpose(rot, (0, 2, 1))
    moments = np.where(ok[:, None], np.stack([J[:, 0, 0], J[:, 1, 1], J[:, 0, 1]], axis=1), 0.0)
    centroids = np.where(ok[:, None], np.stack([cx, cy], axis=1), 0.0)
    # the outline: the convex hull of the polygon parts' corners, about the centroid, in (u, v)
    outer, at = shapely.get_coordinates(shapely.get_exterior_ring(parts), return_index=True)
    with_parts, rank = np.unique(owner[at], return_inverse=True)  # indices must run 0, 1, 2, ...
    hulls = shapely.convex_hull(shapely.multipoints(outer, indices=rank.ravel()))
    hulls = shapely.simplify(hulls, 1e-9)  # GEOS keeps some corners that lie on an edge: not corners
    outlines = np.zeros((count, OUTLINE_POINTS, 2))
    widths = np.zeros(count)
    polygon = (shapely.get_type_id(hulls) == 3) & ok[with_parts]
    corners, at = shapely.get_coordinates(shapely.get_exterior_ring(hulls[polygon]), return_index=True)
    patch = with_parts[polygon]
    start = np.searchsorted(at, np.arange(len(patch) + 1))
    sizes = np.diff(start) - 1  # the rings are closed: the first corner repeated at the end
    for k in np.unique(sizes):  # the hulls with k corners at once
        which = np.flatnonzero(sizes == k)
        pts = corners[start[which][:, None] + np.arange(k)]  # (H, k, 2)
        p = patch[which]
        widths[p] = _least_widths(pts)
        if k > OUTLINE_POINTS:  # keep the corners farthest apart: evenly along the hull
            pts = pts[:, np.linspace(0, k, OUTLINE_POINTS, endpoint=False).astype(int)]
        outline = np.einsum("hkj,hij->hki", pts - centroids[p][:, None], rot[p])
        n = min(k, OUTLINE_POINTS)
        outlines[p, :n] = outline
        outlines[p, n:] = outline[:, -1:]
    # a patch whose hull is a line or a point: its outline is its centroid
    return centroids, moments, outlines, np.where(ok, area, 0.0), widths


def _least_widths(hulls: np.ndarray) -> np.ndarray:
    """The least widths of convex polygons ``(H, k, 2)`` (corners in order): the smallest extent
    across any direction, which is across one of the polygon's edges (rotating calipers)."""
    edges = np.roll(hulls, -1, axis=1) - hulls
    length = np.linalg.norm(edges, axis=2)
    normals = np.stack([-edges[..., 1], edges[..., 0]], axis=2) / np.where(length > 0, length, 1.0)[..., None]
    across = np.einsum("hkj,hej->hke", hulls, normals)  # every corner along every edge's normal
    least = np.where(length > 0, across.max(axis=1) - across.min(axis=1), np.inf).min(axis=1)
    return np.where(np.isfinite(least), least, 0.0)


def patch_section(
    poly: shapely.Geometry, basis: np.ndarray, normal: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """A joint patch's section in its joint frame: the patch ``poly`` is in the 2D coordinates of
    ``basis`` ``(2, 3)`` (rows: the plane's axes in 3D); returns its centroid's offset in those
    2D coordinates ``(2,)``, the second moments ``(I_uu, I_vv, I_uv)`` about the centroid in the
    frame of :func:`joint_axes` of ``normal``, its outline's corners ``(OUTLINE_POINTS, 2)`` in
    (u, v) about the centroid (the convex hull, padded by repeats), and its area."""
    c, m, outline, area, _ = patch_sections(
        np.array([poly], dtype=object), np.asarray(basis)[None], np.asarray(normal, dtype=np.float64)[None]
    )
    return c[0], m[0], outline[0], float(area[0])


@dataclass(frozen=True)
class _Faces:
    """The planar faces of many polyhedra: ``normal`` ``(F, 3)`` unit, ``offset`` ``(F,)`` (n.x),
    ``poly`` ``(F,)`` the face in its plane's 2D basis ``basis`` ``(F, 2, 3)``; the faces of
    polyhedron i are ``start[i]:start[i + 1]``, in the order their first triangles come."""

    normal: np.ndarray
    offset: np.ndarray
    poly: np.ndarray
    basis: np.ndarray
    start: np.ndarray
    centre: np.ndarray  # (F, 3) each face's centroid
    radius: np.ndarray  # (F,) the largest distance from it to the face's corners


def _planar_faces(solids: Sequence[Polyhedron], angle_tol: float = 1e-3) -> _Faces:
    """The planar faces of ``solids``: each face the union of the triangles whose normals and plane
    offsets agree within ``angle_tol`` and 10 um."""
    v = np.concatenate([p.vertices[p.faces] for p in solids])  # every triangle (T, 3, 3)
    owner = np.repeat(np.arange(len(solids)), [len(p.faces) for p in solids])
    n = _cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
    area2 = np.linalg.norm(n, axis=1)
    ok = area2 > 1e-15
    n, v, owner = n[ok] / area2[ok, None], v[ok], owner[ok]
    d = np.einsum("ij,ij->i", n, v[:, 0])
    key = np.column_stack([owner, np.round(n / angle_tol), np.round(d * 1e5)]).astype(np.int64)
    _, first, group = np.unique(key, axis=0, return_index=True, return_inverse=True)
    group = group.ravel()
    # faces numbered by polyhedron, then by their first triangle (sorting the key would order them by normal)
    order = np.argsort(first, kind="stable")
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    group = rank[group]
    count = len(order)
    sizes = np.bincount(group, minlength=count)
    normal = np.stack([np.bincount(group, n[:, k], minlength=count) for k in range(3)], axis=1) / sizes[:, None]
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    offset = np.bincount(group, d, minlength=count) / sizes
    basis = _plane_bases(normal)
    tri = np.einsum("tck,tjk->tcj", v, basis[group])  # each triangle in its face's 2D basis
    tris = shapely.polygons(tri)
    tri_area = shapely.area(tris)
    face_owner = owner[first[order]]
    # a convex face (the sides of an extruded brick, a cut end) is its corners' convex hull; the
    # others are the union of their triangles
    by_group = np.argsort(group, kind="stable")  # the triangles face by face
    hull = shapely.convex_hull(shapely.multipoints(tri[by_group].reshape(-1, 2), indices=np.repeat(group[by_group], 3)))
    convex = np.isclose(shapely.area(hull), np.bincount(group, tri_area, minlength=count), rtol=1e-9, atol=0.0)
    poly = hull.astype(object)
    bounds = np.concatenate([[0], np.cumsum(sizes)])
    for g in np.flatnonzero(~convex):
        members = by_group[bounds[g] : bounds[g + 1]]
        poly[g] = _overlay(shapely.union_all, tris[members[tri_area[members] > 0]])
    start = np.searchsorted(face_owner, np.arange(len(solids) + 1))
    c2 = shapely.get_coordinates(shapely.centroid(poly))
    centre = np.einsum("ik,ikj->ij", c2, basis) + offset[:, None] * normal
    xy, at = shapely.get_coordinates(poly, return_index=True)
    radius = np.zeros(count)
    np.maximum.at(radius, at, np.linalg.norm(xy - c2[at], axis=1))
    return _Faces(normal=normal, offset=offset, poly=poly, basis=basis, start=start, centre=centre, radius=radius)


def _plane_bases(normal: np.ndarray) -> np.ndarray:
    """Two orthonormal vectors ``(N, 2, 3)`` spanning each plane with the normal ``(N, 3)``: normal
    x helper, with the helper Z, or X where the normal is nearly along Z."""
    nx, ny, nz = normal[:, 0], normal[:, 1], normal[:, 2]
    zero = np.zeros_like(nx)
    along_z = np.abs(nz) >= 0.9
    u = np.where(along_z[:, None], np.stack([zero, nz, -ny], 1), np.stack([ny, -nx, zero], 1))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    return np.stack([u, _cross(normal, u)], axis=1)


def _claim_once(
    order: np.ndarray, pair: np.ndarray, inter: np.ndarray, area: np.ndarray, basis, offset, normal
) -> None:
    """Cut from each candidate patch (``order``: grouped by ``pair``, largest first) what the same
    pair's earlier patches cover, projected on its plane; ``inter`` and ``area`` are updated in
    place. Patches on faces more than 60 degrees apart cannot cover each other: they are kept whole."""
    if len(order) < 2:
        return
    group = pair[order]
    starts = np.flatnonzero(np.r_[True, group[1:] != group[:-1], True])
    for s0, s1 in zip(starts[:-1], starts[1:]):
        if s1 - s0 < 2:
            continue
        kept: list[int] = []
        for k in order[s0:s1]:
            near = [j for j in kept if normal[j] @ normal[k] > 0.5]
            if near:
                covered = []
                for j in near:
                    xy = shapely.get_coordinates(inter[j])
                    p3 = xy @ basis[j] + offset[j] * normal[j]
                    covered.append(shapely.transform(inter[j], lambda _, p3=p3, k=k: p3 @ basis[k].T))
                inter[k] = _overlay(shapely.difference, inter[k], _overlay(shapely.union_all, covered))
                area[k] = shapely.area(inter[k])
            kept.append(k)


def contact_patches(
    bricks: Sequence[Brick],
    *,
    max_gap_m: float = 0.03,
    min_area_m2: float = 1e-4,
    angle_deg: float = 10.0,
    min_gap_m: float = -1e-4,
    progress: bool | None = None,
    groups: Sequence[int] | np.ndarray | None = None,
) -> list[ContactPatch]:
    """Patches where two bricks' faces face each other across at most ``max_gap_m``.

    Any orientation: faces are matched by anti-parallel normals (within ``angle_deg``) and plane
    distance, and a patch is the exact overlap of the two faces projected on a common plane. A pair
    of bricks gets a patch for every pair of their faces that qualifies (a bent joint has several),
    each less what the pair's larger patches already cover, so no area is counted twice. Faces that overlap by
    more than ``-min_gap_m`` are not a joint. ``progress``: see
    :func:`calib_masonry.progress.progress` (None: a bar on a terminal, log lines otherwise).
    ``groups``: a label per brick (its wall, say); if given, only bricks of different groups are
    paired (each pair's patches are the same as without it: a pair's faces are matched on their
    own), and only the bricks in such pairs have their faces found.
    """
    from ..progress import progress as _progress

    if not bricks:
        return []
    bar = _progress(total=3, desc="joint patches", unit="step", enabled=progress)
    lo = np.array([b.solid.vertices.min(axis=0) for b in bricks]) - max_gap_m
    hi = np.array([b.solid.vertices.max(axis=0) for b in bricks]) + max_gap_m
    pairs = np.array(list(box_pairs(lo, hi, -1e-12)), dtype=np.int64).reshape(-1, 2)
    if groups is not None:
        g = np.asarray(groups)
        pairs = pairs[g[pairs[:, 0]] != g[pairs[:, 1]]]
        # the bricks in such pairs, in their order (so a pair's a and b keep their sides)
        used = np.unique(pairs)
        bricks = [bricks[k] for k in used.tolist()]
        pairs = np.searchsorted(used, pairs)
        if not bricks:
            bar.close()
            return []
    f = _planar_faces([b.solid for b in bricks])
    bar.update()
    # every face of a against every face of b, pair by pair (a's faces outer)
    na = np.diff(f.start)[pairs[:, 0]]
    nb = np.diff(f.start)[pairs[:, 1]]
    combos = na * nb
    pair = np.repeat(np.arange(len(pairs)), combos)
    k = np.arange(combos.sum()) - np.repeat(np.cumsum(combos) - combos, combos)
    fa = f.start[pairs[pair, 0]] + k // nb[pair]
    fb = f.start[pairs[pair, 1]] + k % nb[pair]
    # the distance from a's plane to b's plane along a's normal: for anti-parallel faces the offsets'
    # sum; where the normals differ by ``s = n_a + n_b`` the planes' distance changes across the
    # faces by ``s`` per metre, so it is read at the faces (their centroids here, at the patch
    # below): the offsets alone, measured from the origin, put two stones 2 cm apart at a corner
    # 2 m from it with beds 2 degrees apart 10 cm apart, and gave them no joint
    gap = -f.offset[fb] - f.offset[fa]
    s = f.normal[fa] + f.normal[fb]
    tilted = np.abs(s).max(axis=1) > 1e-9
    gap[tilted] += 0.5 * np.einsum("ij,ij->i", s[tilted], f.centre[fa[tilted]] + f.centre[fb[tilted]])
    # how far the distance can change between the centroids and any point of the faces
    slack = np.linalg.norm(s, axis=1) * (f.radius[fa] + f.radius[fb])
    facing = np.einsum("ij,ij->i", f.normal[fa], f.normal[fb]) <= -np.cos(np.radians(angle_deg))
    near = (gap >= min_gap_m - slack) & (gap <= max_gap_m + slack)
    cand = np.flatnonzero(facing & near)
    pair, fa, fb, gap, tilted = pair[cand], fa[cand], fb[cand], gap[cand], tilted[cand]
    # b's face in 3D, projected on a's plane basis, and its overlap with a's face
    xy, at = shapely.get_coordinates(f.poly[fb], return_index=True)
    p3 = xy[:, :1] * f.basis[fb[at], 0] + xy[:, 1:] * f.basis[fb[at], 1] + (f.offset[fb, None] * f.normal[fb])[at]
    projected = shapely.transform(f.poly[fb], lambda _: np.einsum("ik,ijk->ij", p3, f.basis[fa[at]]))
    inter = _overlay(shapely.intersection, f.poly[fa], projected)
    area = shapely.area(inter)
    # tilted faces: the planes' distance along a's normal at the overlap's centroid, which must be
    # within the bounds itself
    t = np.flatnonzero(tilted & (area > 0.0))
    if t.size:
        c2 = shapely.get_coordinates(shapely.centroid(inter[t]))
        p3 = np.einsum("ik,ikj->ij", c2, f.basis[fa[t]]) + f.offset[fa[t], None] * f.normal[fa[t]]
        na, nb = f.normal[fa[t]], f.normal[fb[t]]
        gap[t] = (f.offset[fb[t]] - np.einsum("ij,ij->i", nb, p3)) / np.einsum("ij,ij->i", nb, na)
        area[t] = np.where((gap[t] >= min_gap_m) & (gap[t] <= max_gap_m), area[t], 0.0)
    bar.update()
    # per pair, every face pair whose overlap is at least min_area_m2 (a stone's joint with its
    # neighbour bends: its faces meet several of the neighbour's), largest first, each less what the
    # pair's larger patches already cover
    big = np.flatnonzero(area >= min_area_m2)
    best = big[np.lexsort((big, -area[big], pair[big]))]
    inter, area = inter.copy(), area.copy()
    _claim_once(best, pair, inter, area, f.basis[fa], f.offset[fa], f.normal[fa])
    best = best[area[best] >= min_area_m2]
    normal, basis = f.normal[fa[best]], f.basis[fa[best]]
    c2, moments, outlines, _, widths = patch_sections(inter[best], basis, normal)
    centroid = np.einsum("pj,pjk->pk", c2, basis) + (f.offset[fa[best]] + 0.5 * gap[best])[:, None] * normal
    bar.update()
    bar.close()
    out = [
        ContactPatch(
            a=bricks[pairs[pair[i], 0]].id,
            b=bricks[pairs[pair[i], 1]].id,
            normal=normal[j],
            centroid=centroid[j],
            area_m2=float(area[i]),
            gap_m=float(gap[i]),
            min_width_m=float(widths[j]),
            moments=moments[j],
            outline=outlines[j],
        )
        for j, i in enumerate(best)
    ]
    out.sort(key=lambda c: (c.a, c.b))
    return out


def narrowest_beds(
    bricks: Sequence[Brick], *, search_m: float, ground_m: float, only: Sequence[int] | None = None
) -> np.ndarray:
    """Each brick's narrowest bed (m): the least gap of the :func:`contact_patches` (searched to
    ``search_m``) beneath it, whose normal lies within 60 degrees of vertical, as the simulation
    geometry's ``without_bed_joint`` reads a bed. NaN for a brick within ``ground_m`` of the lowest
    brick's bottom (it stands on the footing), inf for one with no bed within ``search_m``. The
    joint reach a structure needs for none of its units to hang is the largest finite value.
    ``only``: the indices of the bricks to measure (the patches are then found among them and the
    bricks within ``search_m`` of them alone); the others are inf."""
    beds = np.full(len(bricks), np.inf)
    if not bricks:
        return beds
    bottom = np.array([float(b.solid.vertices[:, 2].min()) for b in bricks])
    near = np.arange(len(bricks))
    if only is not None:
        only = np.asarray(only, dtype=np.int64)
        lo = np.array([b.solid.vertices.min(axis=0) for b in bricks])
        hi = np.array([b.solid.vertices.max(axis=0) for b in bricks])
        touch = np.zeros(len(bricks), dtype=bool)
        for k in only.tolist():  # the bricks whose boxes come within search_m of a measured one's
            touch |= ((lo <= hi[k] + search_m) & (hi >= lo[k] - search_m)).all(axis=1)
        near = np.flatnonzero(touch)
    row = {bricks[k].id: k for k in near.tolist()}
    for p in contact_patches([bricks[k] for k in near.tolist()], max_gap_m=search_m, progress=False):
        if abs(p.normal[2]) > 0.5:  # a's normal points up at b: b rests on a (or the other way round)
            k = row[p.b] if p.normal[2] > 0 else row[p.a]
            beds[k] = min(beds[k], p.gap_m)
    if only is not None:
        measured = np.zeros(len(bricks), dtype=bool)
        measured[only] = True
        beds[~measured] = np.inf
    beds[bottom <= bottom.min() + ground_m] = np.nan
    return beds


def widest_bed(
    bricks: Sequence[Brick], *, search_m: float, ground_m: float, only: Sequence[int] | None = None
) -> float | None:
    """The largest finite :func:`narrowest_beds` (of the bricks ``only``, where given): the joint
    reach above which every such brick rests on a brick beneath it. None where none has a bed
    within ``search_m``."""
    beds = narrowest_beds(bricks, search_m=search_m, ground_m=ground_m, only=only)
    if only is not None:
        beds = beds[np.asarray(only, dtype=np.int64)]
    beds = beds[np.isfinite(beds)]
    return float(beds.max()) if beds.size else None

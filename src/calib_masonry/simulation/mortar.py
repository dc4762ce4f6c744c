"""Each brick's share of the mortar: the wall's joints split along their middle.

A stone wall's joints are uneven: the Stylite tower has bed joints up to 60 mm wide, and 42 of its
336 stones have no stone within reach below them. Rigid bodies cut to the stones alone leave those
gaps empty, so a cracked joint drops its stones until they land (the tower settled 0.36 m under its
own weight, measured). In the wall, the joints are full of mortar that carries compression.

:func:`mortar_cells` gives every brick the part of the wall nearer to it than to any other brick
(a Voronoi cell of the outlines, found on a raster), no farther than
``reach`` from it and inside the wall's extent. Cells tile the joints, so neighbours touch along
the middle of each joint. Bullet needs convex bodies: a cell's convex hull can cross into a
neighbour's cell where a joint bends, and the hulls of such pairs are cut apart along the line
that separates the two bricks widest.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import shapely

__all__ = ["mortar_cells", "nearest_labels", "shared_boundary_lengths", "wall_joints"]


def _half_plane(c: np.ndarray, n: np.ndarray, size: float) -> shapely.Polygon:
    """The half-plane ``n . (x - c) <= 0`` within ``size`` of ``c``."""
    t = np.array([-n[1], n[0]])
    return shapely.Polygon([c + size * t, c - size * t, c - size * t - size * n, c + size * t - size * n])


def _separate(
    a: shapely.Polygon, b: shapely.Polygon, ha: shapely.Polygon, hb: shapely.Polygon
) -> tuple[shapely.Polygon, shapely.Polygon]:
    """Cut two overlapping convex cells apart along the line that separates their bricks' hulls
    ``ha`` and ``hb`` widest: the perpendicular bisector of the two hulls' closest points (two
    disjoint convex polygons always lie on either side of it). Hulls that touch are cut square to
    the line between the cells' centroids, through the cells' overlap."""
    from shapely.ops import nearest_points

    pa, pb = (np.array(q.coords[0]) for q in nearest_points(ha, hb))
    n = pb - pa
    if np.linalg.norm(n) > 1e-9:
        c = (pa + pb) / 2
    else:
        n = np.array(b.centroid.coords[0]) - np.array(a.centroid.coords[0])
        c = np.array(a.intersection(b).centroid.coords[0])
        if not np.any(n):
            return a, b
    n = n / np.linalg.norm(n)
    size = 10.0 * (np.sqrt(a.area) + np.sqrt(b.area)) + 1.0
    return a.intersection(_half_plane(c, n, size)), b.intersection(_half_plane(c, -n, size))


def mortar_cells(
    polygons: Sequence[np.ndarray], reach: float, *, pixel: float = 0.005, labels: tuple | None = None
) -> list[np.ndarray]:
    """Convex outlines ``(k, 2)`` of each polygon's share of the wall (see the module docstring).

    ``polygons`` are one wall's outer-face outlines in wall metres; ``reach`` bounds how far a cell
    extends from its polygon (half the widest joint that counts as a joint). The split is found on
    a raster of ``pixel`` metres (a distance transform to the nearest outline), so the cells' edges
    lie within half a pixel of the joints' middles. A polygon whose cell would lose part of the
    polygon itself keeps its convex hull. ``labels``: :func:`nearest_labels` of the polygons at this
    reach and pixel, if already found."""
    from scipy.spatial import ConvexHull

    hulls = [shapely.Polygon(p).convex_hull for p in polygons]
    if len(hulls) <= 1 or reach <= 0:
        return [np.asarray(h.exterior.coords)[:-1] for h in hulls]
    hull_xy = [np.asarray(h.exterior.coords)[:-1] for h in hulls]
    nearest, (x0, y0) = nearest_labels(polygons, reach, pixel) if labels is None else labels
    ny = nearest.shape[0]
    allxy = np.vstack(hull_xy)
    extent = shapely.box(*allxy.min(axis=0), *allxy.max(axis=0))
    # each cell's hull is the hull of its rows' end pixels: per (label, row), the first and last column
    r, c = np.nonzero(nearest)
    lab = nearest[r, c]
    key = lab.astype(np.int64) * ny + r
    order = np.argsort(key, kind="stable")
    key, c = key[order], c[order]
    start = np.flatnonzero(np.r_[True, key[1:] != key[:-1]])
    cmin, cmax = np.minimum.reduceat(c, start), np.maximum.reduceat(c, start)
    klab, krow = np.divmod(key[start], ny)
    ends = np.concatenate(
        [
            np.column_stack([cmin, krow]),
            np.column_stack([cmin, krow + 1]),
            np.column_stack([cmax + 1, krow]),
            np.column_stack([cmax + 1, krow + 1]),
        ]
    ) * pixel + [x0, y0]
    ends_lab = np.tile(klab, 4)
    by_label = np.argsort(ends_lab, kind="stable")  # each cell's ends in one slice, in their order
    ends, bounds = ends[by_label], np.searchsorted(ends_lab[by_label], np.arange(len(hulls) + 2))
    cells = []
    for i, h in enumerate(hulls):
        own = np.vstack([np.asarray(h.exterior.coords), ends[bounds[i + 1] : bounds[i + 2]]])
        cell = shapely.Polygon(own[ConvexHull(own).vertices]).intersection(extent)
        cells.append(cell if cell.geom_type == "Polygon" else h)
    tree = shapely.STRtree(cells)
    for i, j in np.array(tree.query(cells, predicate="intersects")).T:
        if i < j and cells[i].intersection(cells[j]).area > 1e-9:
            cells[i], cells[j] = _separate(cells[i], cells[j], hulls[i], hulls[j])
    out = []
    for h, c in zip(hulls, cells):
        if c.is_empty or c.geom_type != "Polygon" or h.difference(c).area > 1e-3 * h.area:
            c = h
        out.append(np.asarray(c.exterior.coords)[:-1])
    return out


def nearest_labels(polygons: Sequence[np.ndarray], reach: float, pixel: float) -> tuple[np.ndarray, np.ndarray]:
    """Each pixel's nearest polygon (1-based label; 0 beyond ``reach`` of every polygon) on a raster of
    ``pixel`` metres over the polygons' extent; returns the labels and the raster's origin (x0, y0)."""
    from scipy.ndimage import distance_transform_edt

    from ..wall2d.dice import polygon_pixels

    allxy = np.vstack([np.asarray(p, dtype=np.float64) for p in polygons])
    x0, y0 = allxy.min(axis=0) - pixel
    x1, y1 = allxy.max(axis=0) + pixel
    nx, ny = int(np.ceil((x1 - x0) / pixel)), int(np.ceil((y1 - y0) / pixel))
    label = np.zeros((ny, nx), dtype=np.int32)
    for i, p in enumerate(polygons):
        xy = np.asarray(p, dtype=np.float64)
        rr, cc = polygon_pixels((xy[:, 1] - y0) / pixel - 0.5, (xy[:, 0] - x0) / pixel - 0.5, label.shape)
        label[rr, cc] = i + 1
    dist, (ri, ci) = distance_transform_edt(label == 0, return_indices=True)
    nearest = label[ri, ci]
    nearest[dist * pixel > reach] = 0
    # the margin of a pixel around the extent is there for the distance transform: not the wall
    lo, hi = allxy.min(axis=0), allxy.max(axis=0)
    cx, cy = x0 + (np.arange(nx) + 0.5) * pixel, y0 + (np.arange(ny) + 0.5) * pixel
    nearest[:, (cx < lo[0]) | (cx > hi[0])] = 0
    nearest[(cy < lo[1]) | (cy > hi[1]), :] = 0
    return nearest, np.array([x0, y0])


def shared_boundary_lengths(
    polygons: Sequence[np.ndarray], reach: float, *, pixel: float = 0.005, labels: tuple | None = None
) -> dict:
    """The length (m) of the boundary each pair of polygons shares: where the parts of the wall
    nearest to each (no farther than ``reach``) meet, measured on a raster of ``pixel`` metres
    (independent of :func:`wall_joints`, which finds the same boundary from a Voronoi diagram of
    the outlines). Keys ``(i, j)``, i < j. A straight boundary crossing ``n_h`` rows and ``n_v``
    columns of pixel edges is ``pixel * hypot(n_h, n_v)`` long (a bent one a little more than
    that: the figure errs short). ``labels``: :func:`nearest_labels` at this reach and pixel, if
    already found."""
    if len(polygons) < 2:
        return {}
    nearest, _ = nearest_labels(polygons, reach, pixel) if labels is None else labels
    counts: dict[tuple[int, int], list[int]] = {}
    for axis in (0, 1):
        a, b = (nearest[:-1], nearest[1:]) if axis == 0 else (nearest[:, :-1], nearest[:, 1:])
        m = (a != b) & (a > 0) & (b > 0)
        lo, hi = np.minimum(a[m], b[m]) - 1, np.maximum(a[m], b[m]) - 1
        keys, n = np.unique(lo.astype(np.int64) * len(polygons) + hi, return_counts=True)
        for k, c in zip(keys.tolist(), n.tolist()):
            counts.setdefault(divmod(k, len(polygons)), [0, 0])[axis] = c
    return {k: pixel * float(np.hypot(*c)) for k, c in counts.items()}


def wall_joints(
    polygons: Sequence[np.ndarray], reach: float, *, step: float | None = None, tolerance: float | None = None
) -> list[tuple[int, int, np.ndarray]]:
    """The joints between the polygons of one wall (outer-face outlines in wall metres): the whole
    boundary each pair of neighbours shares, as straight segments.

    The boundary is the middle of the joint: the Voronoi diagram of the outlines (sampled every
    ``step`` metres; default the smaller of reach/3 and 1 cm), where the parts of the wall nearer
    to one polygon than to any other meet, no farther than ``reach`` from either polygon (so two
    polygons more than twice the reach apart share none) and inside the polygons' extent. Each
    pair's boundary is merged into lines and simplified to within ``tolerance`` (default step/2).
    Returns ``(i, j, segments)`` with i < j and segments ``(k, 2, 2)`` (start and end points)."""
    from scipy.spatial import QhullError, Voronoi

    if len(polygons) < 2 or reach <= 0:
        return []
    step = min(reach / 3, 0.01) if step is None else step
    tolerance = step / 2 if tolerance is None else tolerance
    points, owner = [], []
    for i, p in enumerate(polygons):
        ring = np.vstack([np.asarray(p, dtype=np.float64), np.asarray(p, dtype=np.float64)[:1]])
        for a, b in zip(ring[:-1], ring[1:]):
            n = max(1, int(np.ceil(np.linalg.norm(b - a) / step)))
            points.append(a + (b - a) * (np.arange(n) / n)[:, None])
            owner.append(np.full(n, i))
    xy, owner = np.vstack(points), np.concatenate(owner)
    xy, first = np.unique(np.round(xy, 9), axis=0, return_index=True)  # a corner two outlines share: once
    owner = owner[first]
    if len(np.unique(owner)) < 2:
        return []
    try:
        vor = Voronoi(xy)
    except QhullError:  # every sample on one line: no area to split
        return []
    ridge = np.asarray(vor.ridge_points)
    verts = np.asarray(vor.ridge_vertices)
    keep = (owner[ridge[:, 0]] != owner[ridge[:, 1]]) & np.all(verts >= 0, axis=1)
    ridge, verts = ridge[keep], verts[keep]
    p0, p1 = vor.vertices[verts[:, 0]], vor.vertices[verts[:, 1]]
    # each ridge clipped to the disc of radius reach about its generating point (every point of a
    # ridge is equidistant from the two) and to the outlines' extent
    c = xy[ridge[:, 0]]
    d = p1 - p0
    a2 = np.einsum("ij,ij->i", d, d)
    f = p0 - c
    b2 = np.einsum("ij,ij->i", f, d)
    c2 = np.einsum("ij,ij->i", f, f) - reach**2
    disc = b2**2 - a2 * c2
    ok = (disc > 0) & (a2 > 0)
    root = np.sqrt(np.where(ok, disc, 0.0))
    safe = np.where(a2 > 0, a2, 1.0)
    t0 = np.clip((-b2 - root) / safe, 0.0, 1.0)
    t1 = np.clip((-b2 + root) / safe, 0.0, 1.0)
    ok &= t1 > t0
    q0, q1 = p0 + t0[:, None] * d, p0 + t1[:, None] * d
    lo, hi = xy.min(axis=0), xy.max(axis=0)
    pairs = np.sort(owner[ridge], axis=1)
    order = np.lexsort((pairs[:, 1], pairs[:, 0]))
    order = order[ok[order]]
    if order.size == 0:
        return []
    key = pairs[order]
    group = np.r_[0, np.cumsum(np.any(key[1:] != key[:-1], axis=1))]  # 0, 1, ... a pair each
    first = np.flatnonzero(np.r_[True, group[1:] != group[:-1]])
    # every pair's ridges at once: joined where they meet (snapped to 1 nm: Qhull gives the
    # cocircular corners of evenly sampled parallel edges as separate, nearly equal vertices), cut
    # to the extent, simplified
    lines = shapely.linestrings(
        np.stack([q0[order], q1[order]], axis=1).reshape(-1, 2), indices=np.repeat(np.arange(len(order)), 2)
    )
    multi = shapely.multilinestrings(lines, indices=group)
    merged = shapely.line_merge(shapely.set_precision(multi, 1e-9))
    merged = shapely.simplify(shapely.intersection(merged, shapely.box(*lo, *hi)), tolerance)
    parts, of = shapely.get_parts(merged, return_index=True)
    is_line = shapely.get_type_id(parts) == 1
    parts, of = parts[is_line], of[is_line]
    coords, at = shapely.get_coordinates(parts, return_index=True)
    same = at[1:] == at[:-1]  # consecutive corners of one line: a segment
    seg = np.stack([coords[:-1][same], coords[1:][same]], axis=1)
    seg_of = of[at[:-1][same]]
    long = np.linalg.norm(seg[:, 1] - seg[:, 0], axis=1) > 1e-9
    seg, seg_of = seg[long], seg_of[long]
    out = []
    bounds = np.searchsorted(seg_of, np.arange(len(first) + 1))
    for g, f0 in enumerate(first):
        if bounds[g + 1] > bounds[g]:
            out.append((int(key[f0, 0]), int(key[f0, 1]), seg[bounds[g] : bounds[g + 1]]))
    return out

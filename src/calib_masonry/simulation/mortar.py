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

__all__ = ["mortar_cells"]


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


def mortar_cells(polygons: Sequence[np.ndarray], reach: float, *, pixel: float = 0.005) -> list[np.ndarray]:
    """Convex outlines ``(k, 2)`` of each polygon's share of the wall (see the module docstring).

    ``polygons`` are one wall's outer-face outlines in wall metres; ``reach`` bounds how far a cell
    extends from its polygon (half the widest joint that counts as a joint). The split is found on
    a raster of ``pixel`` metres (a distance transform to the nearest outline), so the cells' edges
    lie within half a pixel of the joints' middles. A polygon whose cell would lose part of the
    polygon itself keeps its convex hull."""
    from scipy.ndimage import distance_transform_edt
    from scipy.spatial import ConvexHull

    from ..wall2d.dice import polygon_pixels

    hulls = [shapely.Polygon(p).convex_hull for p in polygons]
    if len(hulls) <= 1 or reach <= 0:
        return [np.asarray(h.exterior.coords)[:-1] for h in hulls]
    allxy = np.vstack([np.asarray(h.exterior.coords) for h in hulls])
    x0, y0 = allxy.min(axis=0)
    x1, y1 = allxy.max(axis=0)
    nx, ny = int(np.ceil((x1 - x0) / pixel)), int(np.ceil((y1 - y0) / pixel))
    label = np.zeros((ny, nx), dtype=np.int32)
    for i, h in enumerate(hulls):
        xy = np.asarray(h.exterior.coords)
        rr, cc = polygon_pixels((xy[:, 1] - y0) / pixel - 0.5, (xy[:, 0] - x0) / pixel - 0.5, label.shape)
        label[rr, cc] = i + 1
    dist, (ri, ci) = distance_transform_edt(label == 0, return_indices=True)
    nearest = label[ri, ci]
    nearest[dist * pixel > reach] = 0
    extent = shapely.box(x0, y0, x1, y1)
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

"""Overlaps between bricks: the largest interpenetration volume of a built structure.

Pairs are found cheaply first (bricks of one wall: their outer-face polygons intersect, shapely;
bricks of different walls: their global bounding boxes overlap) and only those are intersected
exactly as solids (manifold3d).
"""

from __future__ import annotations

from dataclasses import dataclass

import manifold3d
import numpy as np
import shapely

from typing import Sequence

from .assemble import Brick
from .extrude import Polyhedron

__all__ = ["Interpenetration", "max_interpenetration", "intersection_volume"]


@dataclass(frozen=True)
class Interpenetration:
    max_volume_m3: float
    pair: tuple[int, int] | None  # global brick ids of the worst pair
    pairs_checked: int


def _manifold(p: Polyhedron, origin: np.ndarray) -> manifold3d.Manifold:
    mesh = manifold3d.Mesh(vert_properties=np.ascontiguousarray(p.vertices - origin, dtype=np.float32),
                           tri_verts=np.ascontiguousarray(p.faces, dtype=np.uint32))
    return manifold3d.Manifold(mesh=mesh)


def intersection_volume(p: Polyhedron, q: Polyhedron) -> float:
    """Volume of the intersection of two closed polyhedra (m^3)."""
    origin = 0.5 * (p.vertices.mean(axis=0) + q.vertices.mean(axis=0))
    inter = _manifold(p, origin) ^ _manifold(q, origin)
    return float(inter.volume()) if not inter.is_empty() else 0.0


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
    wall = np.array([b.wall for b in bricks])
    order = np.argsort(lo[:, 0], kind="stable")
    for pos, i in enumerate(order):
        for j in order[pos + 1:]:
            if lo[j, 0] >= hi[i, 0] - eps:
                break
            if wall[i] == wall[j]:
                continue
            if np.all(np.minimum(hi[i], hi[j]) - np.maximum(lo[i], lo[j]) > eps):
                pairs.add((int(min(i, j)), int(max(i, j))))
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

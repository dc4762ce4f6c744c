"""Extrusion of outer-face polygons into closed brick polyhedra (the method's Eq. 4).

A brick whose outer face is the polygon ``(x_i, z_i)`` of wall ``n`` becomes the prism between
``y = 0`` (outer face) and ``y = t`` (inner face), mapped to the global frame by the wall's frame.
Faces are triangles oriented outward (positive signed volume). At a corner that is not a right
angle, bricks are cut by vertical planes (see :func:`clip_plan`), so walls meet without overlap.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import mapbox_earcut
import numpy as np
import trimesh

from .place import WallFrame

__all__ = ["Polyhedron", "prism", "clip_plan", "signed_volume", "polygon_area"]


@dataclass(frozen=True)
class Polyhedron:
    """A closed triangle mesh: ``vertices`` ``(V, 3)`` global metres, ``faces`` ``(F, 3)`` indices."""

    vertices: np.ndarray
    faces: np.ndarray

    @functools.cached_property
    def volume(self) -> float:
        """The enclosed volume (m^3), computed once (a solid's arrays are never changed in place:
        the simulation geometry asked each brick's three times, 1.6 s of an 8,190-brick tower's)."""
        return signed_volume(self.vertices, self.faces)

    @property
    def centroid(self) -> np.ndarray:
        return _centroid(self.vertices, self.faces)

    def to_trimesh(self) -> trimesh.Trimesh:
        return trimesh.Trimesh(self.vertices, self.faces, process=False)


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``np.cross`` of rows ``(N, 3)``, the same products and differences (so the same bits),
    without its axis handling, which cost 50 us a call: a tenth of the contact search
    and of every small solid's volume and centroid."""
    return np.stack(
        [
            a[:, 1] * b[:, 2] - a[:, 2] * b[:, 1],
            a[:, 2] * b[:, 0] - a[:, 0] * b[:, 2],
            a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0],
        ],
        axis=1,
    )


def polygon_area(poly: np.ndarray) -> float:
    """Signed shoelace area of ``poly`` ``(k, 2)`` (positive when counter-clockwise)."""
    x, y = poly[:, 0], poly[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y))


def signed_volume(vertices: np.ndarray, faces: np.ndarray) -> float:
    a, b, c = (vertices[faces[:, k]] for k in range(3))
    return float(np.einsum("ij,ij->i", a, _cross(b, c)).sum() / 6.0)


def _centroid(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    a, b, c = (vertices[faces[:, k]] for k in range(3))
    v = np.einsum("ij,ij->i", a, _cross(b, c)) / 6.0
    total = v.sum()
    if abs(total) < 1e-300:
        return vertices.mean(axis=0)
    return ((a + b + c) / 4.0 * v[:, None]).sum(axis=0) / total


def _triangulate(poly: np.ndarray) -> np.ndarray:
    """Triangles ``(T, 3)`` of a simple counter-clockwise polygon, each counter-clockwise."""
    tris = mapbox_earcut.triangulate_float64(poly, np.array([len(poly)], dtype=np.uint32))
    tris = np.asarray(tris, dtype=np.int64).reshape(-1, 3)
    a, b, c = poly[tris[:, 0]], poly[tris[:, 1]], poly[tris[:, 2]]
    cross = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
    flip = cross < 0
    tris[flip] = tris[flip][:, ::-1]
    return tris


def prism(poly_xz: np.ndarray, frame: WallFrame, depth: float | None = None) -> Polyhedron:
    """The brick with outer face ``poly_xz`` ``(k, 2)`` (wall metres) extruded by the wall thickness."""
    poly = np.asarray(poly_xz, dtype=np.float64)
    if polygon_area(poly) < 0:
        poly = poly[::-1]
    t = frame.thickness_m if depth is None else depth
    k = len(poly)
    tris = _triangulate(poly)
    outer = np.column_stack([poly[:, 0], np.zeros(k), poly[:, 1]])
    inner = np.column_stack([poly[:, 0], np.full(k, t), poly[:, 1]])
    verts = frame.global_from_wall(np.vstack([outer, inner]))
    i = np.arange(k)
    j = (i + 1) % k
    # outer cap: counter-clockwise in (x, z) points to -y (outward); inner cap reversed
    sides = np.concatenate([np.column_stack([i, i + k, j + k]), np.column_stack([i, j + k, j])])
    faces = np.concatenate([tris, tris[:, ::-1] + k, sides]).astype(np.int64)
    return Polyhedron(verts, faces)


def clip_plan(poly: Polyhedron, point_xy: np.ndarray, normal_xy: np.ndarray) -> Polyhedron | None:
    """Keep the part of ``poly`` on the side of the vertical plane through ``point_xy`` that
    ``normal_xy`` points to. Returns None when nothing is left."""
    normal = np.array([normal_xy[0], normal_xy[1], 0.0])
    origin = np.array([point_xy[0], point_xy[1], 0.0])
    side = (poly.vertices - origin) @ normal
    if side.min() >= -1e-12:
        return poly
    if side.max() <= 1e-12:
        return None
    mesh = trimesh.intersections.slice_mesh_plane(poly.to_trimesh(), normal, origin, cap=True)
    if mesh is None or len(mesh.faces) == 0:
        return None
    mesh.merge_vertices()
    faces = np.asarray(mesh.faces, dtype=np.int64)
    verts = np.asarray(mesh.vertices, dtype=np.float64)
    if signed_volume(verts, faces) < 0:
        faces = faces[:, ::-1]
    return Polyhedron(verts, faces)

"""Assembly: wall polygons in metres -> placed, bonded, extruded bricks (a Structure3D)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import shapely

from ..errors import InputError
from .bond import CornerTolerances, corner_clip_planes, corner_roles, find_end_faces
from .extrude import Polyhedron, clip_plan, polygon_area, prism
from .place import Corner, Footprint, WallFrame, _footprint, closure_gap, corners, wall_frames

__all__ = [
    "MAX_GAP_M",
    "joint_width",
    "reach_over",
    "WallPolygons",
    "Brick",
    "Structure3D",
    "assemble",
    "simple_polygon",
    "brick_solid",
]


#: The widest mortar joint (m) two units are joined across by default (a structure file's
#: ``max_joint_m`` sets its own): a gap wider than this between two neighbours is no joint. The
#: default of every function that computes or looks up a model's simulation geometry, and of the
#: build's checks that units reach their wall's ends and base.
MAX_GAP_M = 0.06


def joint_width(model) -> float:
    """The widest mortar joint (m) two units of ``model`` (a Structure3D, a StructureSpec, or
    None) are joined across: its own ``max_joint_m`` (the structure file's), else the default
    :data:`MAX_GAP_M`."""
    value = getattr(model, "max_joint_m", None)
    return MAX_GAP_M if value is None else float(value)


def reach_over(width_m: float) -> float:
    """The joint reach (m) that joins units across a joint ``width_m`` wide: the next whole
    centimetre above it (what ``max_joint_m`` is best given in)."""
    return (np.floor(width_m * 100 + 1e-9) + 1) / 100


@dataclass(frozen=True)
class WallPolygons:
    """One wall's outer-face polygons in wall metres, with per-polygon labels and scores."""

    wall: int
    ids: tuple[int, ...]
    polygons_m: tuple[np.ndarray, ...]
    dice: tuple[float, ...] = ()
    traced_vertices: tuple[int, ...] = ()


@dataclass(frozen=True)
class Brick:
    id: int  # global, 0-based, in wall order
    wall: int
    label: int  # the brick's id within its wall (mask label or truth index)
    polygon_m: np.ndarray  # (k, 2) outer face, wall metres (x, z), counter-clockwise
    solid: Polyhedron
    dice: float = float("nan")
    traced_vertices: int = 0

    @property
    def volume(self) -> float:
        return self.solid.volume


@dataclass(frozen=True)
class Structure3D:
    """A built structure: every brick's polyhedron, placed on the footprint, in global metres."""

    name: str
    footprint: Footprint
    frames: tuple[WallFrame, ...]
    corners: tuple[Corner, ...]
    bricks: tuple[Brick, ...]
    removed: tuple[tuple[int, ...], ...]  # per wall: labels of corner end-face pieces removed
    closure_gap_xy: np.ndarray = field(default_factory=lambda: np.zeros(2))
    # the widest mortar joint (m) two units are joined across (the structure file's max_joint_m);
    # None: the default, MAX_GAP_M
    max_joint_m: float | None = None
    # per corner (in ``corners``' order): the courses where which wall runs through was a guess
    # (the end faces found, not given, and about as wide as the units: find_end_faces)
    corner_guesses: tuple[int, ...] = ()

    @property
    def closure_error_m(self) -> float | None:
        """How far the last wall's end lies from the first wall's start (m); None for an open
        footprint (an L or a single wall), whose ends are apart by design."""
        if not self.footprint.is_closed:
            return None
        return float(np.linalg.norm(self.closure_gap_xy))

    def bricks_of(self, wall: int) -> list[Brick]:
        return [b for b in self.bricks if b.wall == wall]


def simple_polygon(poly: np.ndarray) -> np.ndarray:
    """``poly`` ``(k, 2)`` made simple and counter-clockwise (largest part if it self-crosses)."""
    poly = np.asarray(poly, dtype=np.float64)
    g = shapely.Polygon(poly)
    if not g.is_valid:
        fixed = shapely.make_valid(g)
        parts = [p for p in getattr(fixed, "geoms", [fixed]) if isinstance(p, shapely.Polygon)]
        if parts:
            g = max(parts, key=lambda p: p.area)
            poly = np.asarray(g.exterior.coords)[:-1]
    if polygon_area(poly) < 0:
        poly = poly[::-1]
    return poly


def brick_solid(
    poly: np.ndarray,
    wall: int,
    frames: list[WallFrame],
    corners: list[Corner],
    ends: tuple[str | None, str | None] = (None, None),
) -> Polyhedron | None:
    """The prism of an outer-face polygon of wall ``wall``, extended and cut where it meets a corner
    (``ends``: its place in its course at the wall's start and end, :func:`~.bond.course_ends`)."""
    ext_poly, planes = corner_clip_planes(poly, wall, frames, corners, ends)
    solid: Polyhedron | None = prism(ext_poly, frames[wall])
    for point, normal in planes:
        solid = clip_plan(solid, point, normal)
        if solid is None:
            break
    return solid


def assemble(
    footprint: Footprint,
    walls: list[WallPolygons],
    *,
    name: str = "structure",
    end_faces: list[set[int]] | None = None,
    tolerances: CornerTolerances = CornerTolerances(),
) -> Structure3D:
    """Remove corner end faces, extrude every brick by its wall's thickness and place it.

    ``footprint``: the walls' W, H, theta, t (a :class:`~calib_masonry.build3d.place.Footprint`, or
    an object with a ``footprint``, such as a StructureSpec). ``end_faces`` (indices into each
    wall's polygons) overrides the detection, e.g. for truth.
    """
    footprint = _footprint(footprint)
    frames = wall_frames(footprint)
    cs = corners(footprint)
    polys = [[simple_polygon(p) for p in w.polygons_m] for w in walls]
    guesses: list[int] = []
    if end_faces is None:
        end_faces = find_end_faces(polys, frames, cs, tolerances, guesses)
    bricks: list[Brick] = []
    removed = []
    kept = [
        [i for i, poly in enumerate(polys[w]) if i not in end_faces[w] and abs(polygon_area(poly)) > 0]
        for w in range(len(walls))
    ]
    roles = corner_roles([[polys[w][i] for i in k] for w, k in enumerate(kept)], frames, cs)
    for w, wp in enumerate(walls):
        removed.append(tuple(wp.ids[i] for i in sorted(end_faces[w])))
        ends = dict(zip(kept[w], roles[w]))
        for i in kept[w]:
            poly = polys[w][i]
            solid = brick_solid(poly, w, frames, cs, ends[i])
            if solid is None:
                continue
            bricks.append(
                Brick(
                    id=len(bricks),
                    wall=w,
                    label=int(wp.ids[i]),
                    polygon_m=poly,
                    solid=solid,
                    dice=float(wp.dice[i]) if wp.dice else float("nan"),
                    traced_vertices=int(wp.traced_vertices[i]) if wp.traced_vertices else 0,
                )
            )
    built = {b.wall for b in bricks}
    for w in range(len(walls)):
        if w not in built and len(polys[w]):
            wall = footprint.walls[w]
            raise InputError(
                f"wall '{wall.name or w}': none of its {len(polys[w])} pieces made a brick "
                f"({len(end_faces[w])} taken for corner end faces, the rest empty where its corners cut it); "
                "check its width_m, thickness_m and theta_deg against its neighbours'"
            )
    return Structure3D(
        name=name,
        footprint=footprint,
        frames=tuple(frames),
        corners=tuple(cs),
        bricks=tuple(bricks),
        removed=tuple(removed),
        closure_gap_xy=closure_gap(footprint),
        corner_guesses=tuple(guesses),
    )

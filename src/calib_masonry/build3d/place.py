"""Placement of walls on the footprint (the method's Eqs. 2-3) and the corners between them.

Convention: wall ``n`` starts at the plan point ``P_n = sum_{k<n} W_k (cos theta_k, sin theta_k)``
and runs along ``d_n = (cos theta_n, sin theta_n)``. Its outer face lies on that line; its brick
thickness extends to the left of ``d_n`` (inward for a footprint walked counter-clockwise), along
``n_n = (-sin theta_n, cos theta_n)``. Wall coordinates ``(x, y, z)``: x along the wall from its
lower-left corner as seen from outside, y into the wall (0 on the outer face), z up. The frame
``(d_n, n_n, up)`` is right-handed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import InputError

__all__ = [
    "WallGeometry",
    "Footprint",
    "WallFrame",
    "Corner",
    "wall_frames",
    "closure_gap",
    "footprint_is_closed",
    "ring_closes",
    "corners",
    "MIN_CORNER_TURN_RAD",
]

#: Turns smaller than this (in either sense) are treated as collinear walls that just abut.
MIN_CORNER_TURN_RAD = math.radians(10.0)


@dataclass(frozen=True)
class WallGeometry:
    """What placing and extruding one wall needs: its width W, height H, orientation theta
    (counter-clockwise from global X) and thickness t, in SI units; checked on construction."""

    width_m: float
    height_m: float
    theta_rad: float
    thickness_m: float
    name: str = ""

    def __post_init__(self) -> None:
        where = f"wall '{self.name}'" if self.name else "wall"
        for key in ("width_m", "height_m", "thickness_m"):
            value = getattr(self, key)
            if not (math.isfinite(value) and value > 0):
                raise InputError(f"{where}: {key} = {value} must be a finite length > 0 (metres)")
        if not math.isfinite(self.theta_rad):
            raise InputError(f"{where}: theta = {self.theta_rad} must be a finite angle")

    @property
    def theta_deg(self) -> float:
        return math.degrees(self.theta_rad)


@dataclass(frozen=True)
class Footprint:
    """The walls in footprint order (each starts where the previous one ends) and whether the
    footprint is declared closed (None: decided from the closure gap, see :func:`footprint_is_closed`)."""

    walls: tuple[WallGeometry, ...]
    closed: bool | None = None

    def __post_init__(self) -> None:
        if not self.walls:
            raise InputError("footprint: it has no walls; give at least one")
        object.__setattr__(self, "walls", tuple(self.walls))

    @property
    def is_closed(self) -> bool:
        return footprint_is_closed(self)


def _footprint(obj) -> Footprint:
    """A Footprint, or the ``footprint`` of an object that has one (a StructureSpec)."""
    return obj if isinstance(obj, Footprint) else obj.footprint


@dataclass(frozen=True)
class WallFrame:
    """Where one wall sits in the global frame."""

    index: int
    origin_xy: np.ndarray  # (2,) P_n, global plan metres
    theta_rad: float
    width_m: float
    height_m: float
    thickness_m: float

    @property
    def direction(self) -> np.ndarray:
        return np.array([math.cos(self.theta_rad), math.sin(self.theta_rad)])

    @property
    def inward(self) -> np.ndarray:
        return np.array([-math.sin(self.theta_rad), math.cos(self.theta_rad)])

    def global_from_wall(self, xyz: np.ndarray) -> np.ndarray:
        """Wall points ``(..., 3)`` as (x along, y inward, z up) to global ``(..., 3)`` (X, Y, Z)."""
        xyz = np.asarray(xyz, dtype=np.float64)
        plan = self.origin_xy + xyz[..., :1] * self.direction + xyz[..., 1:2] * self.inward
        return np.concatenate([plan, xyz[..., 2:3]], axis=-1)


@dataclass(frozen=True)
class Corner:
    """The junction where wall ``a`` ends and wall ``b`` starts.

    ``turn_rad`` is the signed turn from ``a``'s direction to ``b``'s, in (-pi, pi]. A convex corner
    (a left turn, seen from outside) is where the walls interlock: in alternate courses the photo
    of one wall shows the end face of the other wall's brick, ``end_width_on_a`` wide on wall a
    (at its end) and ``end_width_on_b`` wide on wall b (at its start).
    """

    a: int
    b: int
    turn_rad: float

    @property
    def convex(self) -> bool:
        return MIN_CORNER_TURN_RAD < self.turn_rad < math.pi - MIN_CORNER_TURN_RAD

    @property
    def right_angle(self) -> bool:
        """A convex corner of 90 degrees: the owner's brick already fills it, so no brick is carried
        past it (:func:`~calib_masonry.build3d.bond.corner_clip_planes`)."""
        return abs(math.cos(self.turn_rad)) < 1e-9

    @property
    def reentrant(self) -> bool:
        """A right turn seen from above (an L or T plan's inner corner): the photos of both walls
        end at the corner's edge, and the masonry between their bands is hidden in both."""
        return -math.pi + MIN_CORNER_TURN_RAD < self.turn_rad < -MIN_CORNER_TURN_RAD

    def end_width_on(self, thickness_other: float) -> float:
        return thickness_other / math.sin(self.turn_rad)


def wall_frames(footprint: Footprint) -> list[WallFrame]:
    """Frames of all walls, each starting at the previous walls' cumulative width (Eqs. 2-3)."""
    spec = _footprint(footprint)
    frames = []
    origin = np.zeros(2)
    for i, w in enumerate(spec.walls):
        frames.append(WallFrame(i, origin.copy(), w.theta_rad, w.width_m, w.height_m, w.thickness_m))
        origin = origin + w.width_m * np.array([math.cos(w.theta_rad), math.sin(w.theta_rad)])
    return frames


def _gap(widths, thetas) -> np.ndarray:
    """``sum_n W_n (cos theta_n, sin theta_n)`` of walls in footprint order."""
    return sum((float(w) * np.array([math.cos(t), math.sin(t)]) for w, t in zip(widths, thetas)), start=np.zeros(2))


def closure_gap(footprint: Footprint) -> np.ndarray:
    """``sum_n W_n (cos theta_n, sin theta_n)``: zero for a footprint that closes."""
    spec = _footprint(footprint)
    return _gap([w.width_m for w in spec.walls], [w.theta_rad for w in spec.walls])


def ring_closes(widths, thetas) -> bool:
    """Whether walls of these widths and directions (footprint order) close into a ring: three or
    more, their gap under 5 % of the perimeter (a footprint's ``closed`` when the file says none)."""
    if len(widths) < 3:
        return False
    return float(np.linalg.norm(_gap(widths, thetas))) <= 0.05 * sum(float(w) for w in widths)


def footprint_is_closed(footprint: Footprint) -> bool:
    """Declared by ``closed`` in the file, else :func:`ring_closes` of its walls."""
    spec = _footprint(footprint)
    if spec.closed is not None:
        return spec.closed
    return ring_closes([w.width_m for w in spec.walls], [w.theta_rad for w in spec.walls])


def _wrap(angle: float) -> float:
    a = (angle + math.pi) % (2 * math.pi) - math.pi
    return math.pi if a == -math.pi else a


def corners(footprint: Footprint) -> list[Corner]:
    """All junctions between consecutive walls (and last-to-first when the footprint is closed)."""
    spec = _footprint(footprint)
    n = len(spec.walls)
    pairs = [(i, i + 1) for i in range(n - 1)]
    if footprint_is_closed(spec) and n >= 3:
        pairs.append((n - 1, 0))
    found = [Corner(a, b, _wrap(spec.walls[b].theta_rad - spec.walls[a].theta_rad)) for a, b in pairs]
    for c in found:
        # between walls as listed; the closing corner of a ring that does not close is warned of
        # (its gap) where the footprint is built, as before
        if c.b == c.a + 1 and abs(c.turn_rad) > math.pi - MIN_CORNER_TURN_RAD:
            # (east at theta 0 instead of 90 on a ring of four: south then ran back over east, and
            # north and west were built with no bricks at all, a traceback after the model was written)
            wa, wb = spec.walls[c.a], spec.walls[c.b]
            raise InputError(
                f"walls '{wa.name or c.a}' and '{wb.name or c.b}': theta_deg {math.degrees(wa.theta_rad):.6g} and "
                f"{math.degrees(wb.theta_rad):.6g} turn the second back over the first (a turn of "
                f"{abs(math.degrees(c.turn_rad)):.0f} degrees); check theta_deg (each wall's direction, in the "
                "order the walls are listed)"
            )
    _check_turning_counterclockwise(spec, found)
    _check_end_widths(spec, found)
    return found


def _check_turning_counterclockwise(spec: Footprint, found: list[Corner]) -> None:
    """Refuse a closed footprint that turns clockwise. Each wall is seen from outside, its x axis
    from the photo's left to its right, and its thickness lies to that axis's left (inward): walls
    listed in order around a building turn counterclockwise seen from above, their turns summing
    to +360 degrees. At -360 (compass bearings, clockwise from north, given as theta_deg; or the
    walls listed the other way round) every wall's thickness lies outside the footprint, every
    corner is built as a re-entrant one and the bricks the photos show at the corners overlap
    (the paper example so: 5.8 litres of overlap, 131 more bricks, corners not interlocked)."""
    if not found or found[-1].b != 0 or len(found) < 3:  # open: no closing corner
        return
    total = sum(c.turn_rad for c in found)
    if total > -math.pi:
        return
    raise InputError(
        f"footprint: its walls turn clockwise (their turns sum to {math.degrees(total):.0f} degrees), which puts "
        "every wall's thickness outside it and leaves its corners open; theta_deg is each wall's direction "
        "counterclockwise from +x, seen from outside from its left end to its right, the walls listed in that "
        "order around the building (counterclockwise from above): from the compass bearing b of that direction, "
        "theta_deg = 90 - b (of a facade facing bearing f, 180 - f)"
    )


def _check_end_widths(spec: Footprint, found: list[Corner]) -> None:
    """Refuse walls whose convex corners take their whole width: at a corner the other wall's
    bricks cover ``t_other / sin(turn)`` of this wall's end (the end faces its photo shows), so a
    wall needs ``W`` larger than the two ends' sum; else its inner faces cross the neighbours' and
    the bricks overlap (a thickness in centimetres read as metres builds a 4.5 m thick wall)."""
    taken = [0.0] * len(spec.walls)
    by: list[list[str]] = [[] for _ in spec.walls]
    for c in found:
        if not c.convex:
            continue
        for this, other in ((c.a, c.b), (c.b, c.a)):
            t = spec.walls[other].thickness_m
            taken[this] += c.end_width_on(t)
            by[this].append(f"'{spec.walls[other].name or other}' (thickness_m = {t:.6g})")
    for i, w in enumerate(spec.walls):
        if taken[i] >= w.width_m:
            raise InputError(
                f"wall '{w.name or i}': width_m = {w.width_m:.6g} is not more than the {taken[i]:.6g} m its "
                f"corners with {' and '.join(by[i])} take of it; a wall's thickness is its units' depth "
                "in metres: check thickness_m and the widths"
            )

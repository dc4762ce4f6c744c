"""Which mortar joints have cracked, seen from the bricks' poses (no Blender here).

Bullet never tells Python that a constraint broke, and it breaks each of a joint's constraints on
its own (compression, tension, shear and bending separately). A cracked joint should lose all of
its cohesion at once and carry only contact and Coulomb friction afterwards, so the run watches
every joint frame by frame and switches the rest of a cracked joint's constraints off.

A joint counts as cracked at the first frame where its two faces have moved apart anywhere on the
patch by more than ``drift_break_m``: each brick carries its own copy of the patch centroid and of
the patch's rim (a circle of radius ``sqrt(A / pi)`` in the joint plane), and the largest distance
between the two copies is the joint's opening. An intact joint keeps that below the solver's error
(a few hundredths of a millimetre); a tension or shear break moves the centroids apart, a bending
break turns one face against the other, which the rim sees. For a foundation bond (``b = -1``) the
second copy is carried by the ground plate, which only translates.
"""

from __future__ import annotations

import numpy as np

from .scene import Scene, joint_axes

__all__ = ["JointMonitor"]


class JointMonitor:
    """Track every bond of ``scene`` from a reference frame; :meth:`update` returns the new cracks."""

    def __init__(self, scene: Scene, positions: np.ndarray, rotations: np.ndarray, plate: np.ndarray,
                 time_s: float) -> None:
        bonds = scene.bonds
        self.threshold = scene.solver.drift_break_m
        self.a = np.array([b.a for b in bonds], dtype=int)
        b = np.array([b.b for b in bonds], dtype=int)
        self.ground = b < 0
        self.b = np.where(self.ground, self.a, b)
        self.t0 = float(time_s)
        self.plate0 = np.asarray(plate, dtype=np.float64).copy()
        n = len(bonds)
        self.break_time_s = np.full(n, np.nan)
        if n == 0:
            return
        c = np.array([bd.location for bd in bonds], dtype=np.float64)
        u, v, _ = joint_axes(np.array([bd.normal for bd in bonds], dtype=np.float64))
        r = np.sqrt(np.array([bd.area_m2 for bd in bonds]) / np.pi)[:, None]
        # probe points per bond: centroid and four rim points in the joint plane -> (n, 5, 3)
        self.points = np.stack([c, c + r * u, c - r * u, c + r * v, c - r * v], axis=1)
        p = np.asarray(positions, dtype=np.float64)
        R = np.asarray(rotations, dtype=np.float64)
        # each probe point in brick a's and brick b's body frames
        self.qa = np.einsum("nji,nkj->nki", R[self.a], self.points - p[self.a][:, None])
        self.qb = np.einsum("nji,nkj->nki", R[self.b], self.points - p[self.b][:, None])

    @property
    def intact(self) -> np.ndarray:
        return np.isnan(self.break_time_s)

    def opening(self, positions: np.ndarray, rotations: np.ndarray, plate: np.ndarray,
                which: np.ndarray | None = None) -> np.ndarray:
        """The largest distance between the two faces' copies of the probe points, per bond."""
        idx = np.arange(len(self.a)) if which is None else which
        p = np.asarray(positions, dtype=np.float64)
        R = np.asarray(rotations, dtype=np.float64)
        a, b = self.a[idx], self.b[idx]
        pa = np.einsum("nij,nkj->nki", R[a], self.qa[idx]) + p[a][:, None]
        pb = np.einsum("nij,nkj->nki", R[b], self.qb[idx]) + p[b][:, None]
        g = self.ground[idx]
        pb[g] = self.points[idx][g] + (np.asarray(plate, dtype=np.float64) - self.plate0)
        return np.linalg.norm(pa - pb, axis=2).max(axis=1)

    def update(self, time_s: float, positions: np.ndarray, rotations: np.ndarray, plate: np.ndarray) -> np.ndarray:
        """Record the bonds that have cracked by now; returns their indices."""
        idx = np.flatnonzero(self.intact)
        if idx.size == 0:
            return idx
        new = idx[self.opening(positions, rotations, plate, idx) > self.threshold]
        self.break_time_s[new] = float(time_s) - self.t0
        return new

"""Results of a simulation: collapse metrics, bond breaks, figures and the output folder.

Displacements are measured relative to the ground plate (a brick carried rigidly by the ground has
not moved) and from the end of the gravity warm-up. A bond counts as broken at the frame where the
joint model cracked it (:mod:`calib_masonry.simulation.joints`).

Pushover: the collapse multiplier is the lateral acceleration (in g) at the last frame where every
brick still moved slower than ``ONSET_DRIFT`` (0.1 %) of the structure's height per second (its
speed over the last ``ONSET_WINDOW_S``), provided the displacement then runs away (past
``moved_threshold_m`` and ten times 0.1 % of the height). Speed, not displacement: an intact
structure is rigid in Bullet but for the constraints' steady-state error, which grows with the
load (0.8 mm at the top of a 0.8 m bonded wall at 0.23 g, measured) and only slowly; a mechanism
accelerates. A rigid block under a ramp ``r`` (g/s) lifts off at ``b / h`` and its speed then
grows as the square of the time since, so the reading lags by a little (about 1 % of ``b / h`` at
0.01 g/s for a 1 m block, measured in the tests).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .ground_motion import G
from .joints import FAILURE_MODES
from .loop import BULLET_FRAMES, PIECES_FRAMES, RunOutput
from .scene import ONSET_DRIFT, Scene, grounded_bodies, rotations, runaway_m, structure_height

ONSET_WINDOW_S = 0.2  # ... measured over this window

__all__ = [
    "Metrics",
    "rotations",
    "metrics",
    "outcome",
    "plot_histories",
    "plot_ground_motion",
    "render_frames",
    "structure_height",
    "pushover_stop",
    "collapse_multiplier",
    "ran_away_first",
    "AT_START_S",
    "plot_pushover",
    "ONSET_DRIFT",
    "runaway_m",
    "ONSET_WINDOW_S",
    "failure_mode_counts",
]


@dataclass(frozen=True)
class Metrics:
    start_frame: int  # end of the warm-up: displacements are measured from here
    moved_fraction: np.ndarray  # (F,)
    roof_drift_m: np.ndarray  # (F,) mean horizontal displacement of the top bricks
    max_displacement_m: np.ndarray  # (B,) over the whole run
    bond_break_time_s: np.ndarray  # (n_bonds,) NaN where intact
    broken_fraction: np.ndarray  # (F,)
    collapse_time_s: float | None  # when the run collapsed (None: the run ends not collapsed)
    # under a ground motion, the bricks in freed pieces that fell or overturn from their state at
    # the end (simulation/pieces.py: PieceMotion.toppled); None where Bullet's motion is read
    toppled_fraction: float | None = None

    @property
    def outcome(self) -> str:
        """The run's verdict: :func:`outcome` of the final fraction moved and the toppled one."""
        return outcome(float(self.moved_fraction[-1]) if len(self.moved_fraction) else 0.0, self.toppled_fraction)


def outcome(moved_fraction: float, toppled_fraction: float | None = None) -> str:
    """The run's verdict. Under a ground motion (``toppled_fraction`` given): "collapsed" when at
    least half of the bricks are in pieces that fell or overturn (not where a rocking piece happens
    to be at the last frame: a freed tower rocking on its base moves most of its stones 5 cm at
    the top of each swing and none in between), "damaged" when more than 1 % toppled or moved,
    else "standing". Otherwise from the final fraction of bricks moved: "collapsed" when at least
    half moved, "damaged" when more than 1 % did, else "standing"."""
    if toppled_fraction is not None:
        if toppled_fraction >= 0.5:
            return "collapsed"
        return "damaged" if max(moved_fraction, toppled_fraction) > 0.01 else "standing"
    return "collapsed" if moved_fraction >= 0.5 else "damaged" if moved_fraction > 0.01 else "standing"


def _motion(out: RunOutput, start: int, *, bullet: bool = False) -> np.ndarray:
    """``(F, B, 3)`` every brick's displacement from frame ``start`` (zero before it): the verdict's
    pieces' (``out.pieces``) where a ground motion ran with the joint model, else (or with
    ``bullet``) the frames' poses relative to the plate."""
    if getattr(out, "pieces", None) is not None and not bullet:
        rel = np.zeros(out.positions.shape)
        rel[start:] = out.pieces.displacement_m[: len(out.time) - start]
        return rel
    return out.positions - out.positions[start] - (out.plate - out.plate[start])[:, None, :]


def metrics(scene: Scene, out: RunOutput, *, bullet: bool = False) -> Metrics:
    """The run's metrics from the bricks' motion: under a ground motion with the joint model, the
    motion of the pieces it set free moved as rigid bodies to convergence (``out.pieces``,
    simulation/pieces.py), not Bullet's, whose freed pieces move as far as its iterative solve of
    their joints converges; ``bullet=True`` reads Bullet's (the animation's) instead."""
    s = scene.solver
    start = min(s.warmup_frames, len(out.time) - 1)
    rel = _motion(out, start, bullet=bullet)
    dist = np.linalg.norm(rel, axis=2)
    dist[:start] = 0.0
    moved = (dist > s.moved_threshold_m).mean(axis=1)
    z0 = out.positions[start, :, 2]
    top = z0 >= z0.min() + 0.9 * (z0.max() - z0.min())
    drift = np.linalg.norm(rel[:, top, :2].mean(axis=1), axis=1)
    breaks = out.bond_break_time_s if out.bond_break_time_s is not None else np.full(len(scene.bonds), np.nan)
    t_rel = out.time - out.time[start]
    broken = (
        (np.array([(breaks <= t).sum() for t in t_rel]) / max(1, len(breaks))) if len(breaks) else np.zeros(len(t_rel))
    )
    # the time from which half the bricks stay moved to the end: None unless the run ends collapsed,
    # so that it agrees with the verdict (the first frame with half moved gave 2.24 s to a run whose
    # bricks came back to rest within the threshold: outcome "standing")
    toppled = None
    if getattr(out, "pieces", None) is not None and not bullet and out.pieces.toppled is not None:
        toppled = float(out.pieces.toppled.mean()) if len(out.pieces.toppled) else 0.0
    collapse = None
    if len(moved) and outcome(float(moved[-1]), toppled) == "collapsed":
        # from when half the bricks stay moved; where the toppled pieces decided it but fewer than
        # half had moved 5 cm by the end, the end of the run
        below = np.flatnonzero(moved < 0.5)
        collapse = (
            float(t_rel[-1]) if moved[-1] < 0.5 else float(t_rel[below[-1] + 1]) if below.size else float(t_rel[0])
        )
    return Metrics(
        start_frame=start,
        moved_fraction=moved,
        roof_drift_m=drift,
        max_displacement_m=dist.max(axis=0),
        bond_break_time_s=breaks,
        broken_fraction=broken,
        collapse_time_s=collapse,
        toppled_fraction=toppled,
    )


def failure_mode_counts(out: RunOutput) -> dict:
    """How many joints cracked by each criterion (tension, compression, shear)."""
    modes = out.bond_break_mode if out.bond_break_mode is not None else np.zeros(0, dtype=int)
    return {name: int((modes == k).sum()) for k, name in enumerate(FAILURE_MODES)}


def _watched(scene: Scene) -> slice:
    """The bodies whose running away is the collapse: every brick, or a shear test's loading beam
    alone (the force acts there; a loose stone falling out of the wall is no peak of that force)."""
    if "shear_test" in scene.notes:
        k = scene.notes["shear_test"]["beam"]
        return slice(k, k + 1)
    return slice(None)


def _moved(scene: Scene, out: RunOutput, m: Metrics) -> np.ndarray:
    """``(F, W, 3)`` the watched bricks' (:func:`_watched`) displacements relative to the ground
    plate, from the end of the warm-up."""
    start, watched = m.start_frame, _watched(scene)
    return (
        out.positions[start:, watched]
        - out.positions[start, watched]
        - (out.plate[start:] - out.plate[start])[:, None, :]
    )


def pushover_stop(scene: Scene, settle_s: float = 1.0):
    """A ``stop`` for :func:`~calib_masonry.simulation.loop.run`: true ``settle_s`` after the largest
    brick displacement (from the end of the warm-up, relative to the plate; a shear test's beam's)
    has run away."""
    s = scene.solver
    limit = runaway_m(scene)
    state = {"ref": None, "since": None}
    watched = _watched(scene)

    def stop(frame: int, positions: np.ndarray, plate: np.ndarray) -> bool:
        if state["ref"] is None:
            state["ref"] = (positions.astype(np.float64).copy(), np.asarray(plate, dtype=np.float64).copy())
            return False
        p0, q0 = state["ref"]
        d = np.linalg.norm(positions[watched] - p0[watched] - (plate - q0), axis=1).max()
        if state["since"] is None and d > limit:
            state["since"] = frame
        return state["since"] is not None and frame - state["since"] >= settle_s * s.fps

    return stop


def collapse_multiplier(scene: Scene, out: RunOutput, m: Metrics) -> tuple[float | None, np.ndarray, np.ndarray]:
    """The pushover's collapse multiplier (g), or None if the structure (a shear test's loading beam)
    did not run away within the ramp; and the lateral acceleration (g) and roof displacement (m) at every frame from the
    end of the warm-up (the pushover curve). The multiplier is at most the last load before the
    joint model set a brick (a shear test's beam) free (:func:`_set_free`)."""
    p = scene.pushover
    start = m.start_frame
    t = out.time[start:] - out.time[start]
    lam = p.lateral_g(t)
    rel = _moved(scene, out, m)
    dmax = np.linalg.norm(rel, axis=2).max(axis=1)
    height = structure_height(scene)
    limit = runaway_m(scene)
    w = max(1, int(round(ONSET_WINDOW_S * scene.solver.fps)))
    speed = np.zeros(len(rel))
    speed[w:] = np.linalg.norm(rel[w:] - rel[:-w], axis=2).max(axis=1) / (w / scene.solver.fps)
    run_away = np.flatnonzero(dmax > limit)
    value = None
    if run_away.size:
        calm = np.flatnonzero(speed[: run_away[0]] <= ONSET_DRIFT * height)
        value = float(lam[calm[-1]]) if calm.size else 0.0
    # a shear test's beam carries the load only while a held joint ties it to the ground: the
    # joint model then found no equilibrium of what carries it. Set free on the stones below it
    # that still hold (fixed in Bullet), it would slide on them at mu instead of falling with the
    # wall (WI1.175: 107.7 kN, the rigid rocking bound 68.9 kN). Likewise any brick of a pushover:
    # set free, it moves on Bullet's contacts, whose finite motion can jam it (a dry stone wall
    # pushed along -X: let go at 0.366 g where the non-associative programme gives 0.362 g, it
    # moved 7 mm, stopped, and ran away at 0.502 g, or 0.534 g at twice Bullet's substeps and
    # iterations): the mechanism is the joint model's, read where it has no equilibrium
    free = _set_free(scene, out)
    if free is not None:
        before = np.flatnonzero(t < free)
        at_free = float(lam[before[-1]]) if before.size else 0.0
        value = at_free if value is None else min(value, at_free)
    return value, lam, m.roof_drift_m[start:]


#: A pushover whose collapse is read within this much of its ramp (s) ran away under its own weight:
#: 0.005 g at the default 0.01 g/s, which only a wall some 200 times as tall as thick would not carry
#: (units falling from over a door were read at 0.0008-0.0012 g, measured)
AT_START_S = 0.5


def ran_away_first(scene: Scene, out: RunOutput, m: Metrics, at_most: int = 5) -> list[str]:
    """The names of the (at most ``at_most``) bricks that had moved furthest when the pushover's
    displacement first ran away (:func:`runaway_m`), furthest first; empty if nothing ran away."""
    dist = np.linalg.norm(_moved(scene, out, m), axis=2)
    limit = runaway_m(scene)
    frames = np.flatnonzero(dist.max(axis=1) > limit)
    if not frames.size:
        return []
    names = [b.name for b in scene.bodies][_watched(scene)]
    d = dist[frames[0]]
    order = np.argsort(-d, kind="stable")
    return [names[k] for k in order[:at_most] if d[k] > limit]


def _set_free(scene: Scene, out: RunOutput) -> float | None:
    """When (s, from the end of the warm-up) the joint model first let go joints that left a watched
    body (:func:`_watched`: every brick, a shear test's beam), tied to the ground by held joints
    before, tied by none: it found no equilibrium with them. None if it never did (or nothing was
    tied: a structure on dry contacts alone)."""
    released = out.bond_release_time_s
    if released is None or not scene.bonds:
        return None
    watched = np.zeros(len(scene.bodies), dtype=bool)
    watched[_watched(scene)] = True
    tied = grounded_bodies(scene.bonds, len(scene.bodies)) & watched
    if not tied.any():
        return None
    for t in np.unique(released[np.isfinite(released)]):
        if (tied & ~grounded_bodies(scene.bonds, len(scene.bodies), ~(released <= t))).any():
            return float(t)
    return None


#: Joints whose relative motion at the onset is at least this fraction of the largest take part in
#: the mechanism (and at least 1 mm).
MECHANISM_SHARE = 0.25


def mechanism(scene: Scene, out: RunOutput, m: Metrics) -> dict | None:
    """How the structure failed, from the joints that let go where the collapse has begun: the
    first frame after the warm-up at which a brick has moved by the run-away displacement
    (:func:`runaway_m`; under a ground motion in the verdict's motion of the freed pieces, as the
    metrics read it), or in a pushover where the joint model set a brick free before that
    (:func:`_set_free`). The joints taking part are those Bullet let go by then (the joint model
    found no equilibrium with them); each opened (it cracked in tension) or slid (in shear or
    crushing). Without any (a run the joint model did not watch), they are those whose two sides moved
    apart by at least :data:`MECHANISM_SHARE` of the largest such motion (and 1 mm), opened where
    that motion is mostly along the normal. Each is a bed joint (normal within 45 degrees of
    vertical, footings included) or a head joint. "stepped (diagonal) cracking": at least a third
    of them are head joints and the bed joints among them lie at two levels or more; otherwise
    "rocking" where most opened, "sliding" where most slid. None if nothing ran away."""
    if not scene.bonds:
        return None
    start = m.start_frame
    w = _watched(scene)
    # the verdict's motion where it has one (a ground motion: the rigid pieces), not the animation's
    rel = _motion(out, start)[start:, w]
    moved = np.flatnonzero(np.linalg.norm(rel, axis=2).max(axis=1) > runaway_m(scene))
    if moved.size == 0:
        return None
    f = start + int(moved[0])
    t_f = float(out.time[f] - out.time[start])
    if scene.pushover is not None:
        # where the joint model let a brick go, as the multiplier is read (:func:`collapse_multiplier`):
        # a freed stone that jams in Bullet runs away later by as much as its settings say
        free = _set_free(scene, out)
        t_f = t_f if free is None else min(t_f, free)
    p = np.array([bd.location for bd in scene.bonds])
    n = np.array([bd.normal for bd in scene.bonds])
    released = out.bond_release_time_s
    active = np.zeros(len(scene.bonds), dtype=bool)
    if released is not None and out.bond_break_mode is not None:
        active = np.isfinite(released) & (released <= t_f)
    if active.any():
        # the joints Bullet let go by then, as the joint model cracked them: what the mechanism
        # needed (Bullet's motion after the peak, a rocking block sliding off its toe, is no guide)
        opened = active & (out.bond_break_mode == FAILURE_MODES.index("tension"))
    else:  # nothing let go (a run without the joint model's watch): the joints' relative motion
        R = rotations(out.quaternions[[start, f]])  # (2, B, 3, 3)
        turn = R[1] @ np.transpose(R[0], (0, 2, 1))  # each body's rotation since the start

        def moved_to(body: np.ndarray) -> np.ndarray:
            plate = p + (out.plate[f] - out.plate[start])
            k = np.maximum(body, 0)
            here = out.positions[f][k] + np.einsum("kij,kj->ki", turn[k], p - out.positions[start][k])
            return np.where((body < 0)[:, None], plate, here)

        d = moved_to(np.array([bd.b for bd in scene.bonds])) - moved_to(np.array([bd.a for bd in scene.bonds]))
        opening = np.einsum("ki,ki->k", d, n)
        slip = np.linalg.norm(d - opening[:, None] * n, axis=1)
        size = np.linalg.norm(d, axis=1)
        active = size >= max(1e-3, MECHANISM_SHARE * float(size.max()))
        if not active.any():
            return None
        opened = active & (opening > slip)
    bed = np.abs(n[:, 2]) >= math.cos(math.radians(45.0))
    head = active & ~bed
    levels = np.unique(np.round(p[active & bed, 2] / 0.05)).size  # bed joints 5 cm apart in height
    if head.sum() >= active.sum() / 3 and levels >= 2:
        kind = "stepped (diagonal) cracking"
    elif opened.sum() >= active.sum() / 2:
        kind = "rocking"
    else:
        kind = "sliding"
    return {
        "mechanism": kind,
        "at_time_s": t_f,
        "joints": int(active.sum()),
        "opened": int(opened.sum()),
        "slid": int((active & ~opened).sum()),
        "head_joints": int(head.sum()),
        "bed_joint_levels": int(levels),
    }


def plot_ground_motion(scene: Scene, path: Path) -> None:
    from .. import _figure as plt

    m = scene.motion
    fig, ax = plt.subplots(2, 1, figsize=(8, 5), sharex=True)
    if m is not None:
        ax[0].plot(m.time, m.acceleration[:, 0] / G, lw=0.7, label="X")
        ax[0].plot(m.time, m.acceleration[:, 1] / G, lw=0.7, label="Y")
        fps = scene.solver.fps
        tf, applied = m.frame_means(fps)
        applied = applied / G
        for k, name in enumerate("XY"):
            if np.any(applied[:, k]):
                ax[0].step(
                    tf,
                    applied[:, k],
                    where="post",
                    lw=0.9,
                    color="k" if k == 0 else "0.4",
                    label=f"{name} as Bullet applies it (mean over each frame)",
                )
        ax[1].plot(m.time, m.displacement[:, 0] * 1000, lw=0.9, label="X")
        ax[1].plot(m.time, m.displacement[:, 1] * 1000, lw=0.9, label="Y")
        ax[0].set_title(
            f"ground motion: {m.source}\npeak {m.pga / G:.3f} g (the joint model's and the verdict's); "
            f"Bullet's frame means {m.applied_peak(fps) / G:.3f} g at {fps} fps",
            fontsize=9,
        )
    ax[0].set_ylabel("acceleration (g)")
    ax[1].set_ylabel("plate displacement (mm)")
    ax[1].set_xlabel("time (s)")
    ax[0].legend(fontsize=7)
    fig.tight_layout()
    plt.save(fig, path, dpi=110)
    plt.close(fig)


def plot_histories(scene: Scene, out: RunOutput, m: Metrics, path: Path) -> None:
    from .. import _figure as plt

    t = out.time - out.time[m.start_frame]
    el = getattr(out, "elastic", None)
    rows = 3 if el is None else 4
    fig, ax = plt.subplots(rows, 1, figsize=(8, 7 if el is None else 9), sharex=True)
    if el is not None:
        # the elastic vibration of what the intact joints hold (sub-millimetre: Bullet keeps it rigid)
        te = el["time_s"]  # from the end of the warm-up, as t
        ax[3].plot(te, el["roof_drift_m"] * 1000, color="C4", lw=0.8)
        ax[3].set_ylabel("elastic roof drift (mm)")
        twin = ax[3].twinx()
        twin.plot(te, el["base_shear_n"] / 1000, color="C1", lw=0.6, alpha=0.7)
        twin.set_ylabel("base shear (kN)", color="C1")
        ax[3].set_title(
            f"elastic vibration: T1 = {el['first_period_s']:.3f} s, {el['damping_ratio']:.0%} damping", fontsize=9
        )
        ax[3].set_xlabel("time since the ground started moving (s)")
    ax[0].plot(t, m.roof_drift_m * 1000, color="C3")
    ax[0].set_ylabel("roof drift (mm)")
    ax[1].plot(t, m.moved_fraction * 100, color="C0")
    ax[1].set_ylabel(f"bricks moved > {scene.solver.moved_threshold_m * 100:g} cm (%)")
    ax[2].plot(t, m.broken_fraction * 100, color="C2")
    ax[2].set_ylabel("bonds broken (%)")
    if el is None:
        ax[2].set_xlabel("time since the ground started moving (s)")
    # a flat history on its own autoscaled axis (+-0.04 %) looked like motion: each panel spans at
    # least a floor (1 mm, 1 %), and one that stays at zero says so
    for a, values, floor in (
        (ax[0], m.roof_drift_m * 1000, 1.0),
        (ax[1], m.moved_fraction * 100, 1.0),
        (ax[2], m.broken_fraction * 100, 1.0),
    ):
        v = np.asarray(values, dtype=np.float64)
        v = v[np.isfinite(v)]
        lo = min(0.0, float(v.min())) if v.size else 0.0
        hi = max(floor, float(v.max()) if v.size else 0.0)
        a.set_ylim(lo, hi * 1.05)
        if not v.size or not np.any(v != 0):
            a.text(0.5, 0.5, "zero throughout the run", transform=a.transAxes, ha="center", va="center", color="0.4")
    for a in ax:
        a.axvline(0.0, color="k", lw=0.5, ls=":")
    fig.tight_layout()
    plt.save(fig, path, dpi=110)
    plt.close(fig)


class _FramePainter:
    """Axonometric views of the bricks at given frames, in one fixed box (shared by the PNG frames
    and the GIF)."""

    def __init__(self, scene: Scene, out: RunOutput) -> None:
        self.scene, self.out = scene, out
        self.R = rotations(out.quaternions)
        allv = np.concatenate([b.vertices + b.location for b in scene.bodies])
        self.lo, self.hi = allv.min(axis=0), allv.max(axis=0)
        self.pad = 0.3 * float((self.hi - self.lo)[:2].max())
        light = np.array([0.4, -0.6, 0.7])
        self.light = light / np.linalg.norm(light)
        self.body_of_tri = np.repeat(np.arange(len(scene.bodies)), [len(b.faces) for b in scene.bodies])
        # frames that show the verdict's pieces (a run without Bullet): a piece that fell is followed
        # no further, so its bricks stay where it fell, drawn grey from that frame on
        self.fallen_at = np.full(len(scene.bodies), np.iinfo(np.int64).max)
        p = getattr(out, "pieces", None)
        if getattr(out, "frames_of", BULLET_FRAMES) == PIECES_FRAMES and p is not None and p.fallen.any():
            start = min(scene.solver.warmup_frames, len(out.time) - 1)
            d = p.displacement_m
            moving = np.any(d != d[-1], axis=2)  # (T, B): not yet where it ends
            last = np.where(moving.any(axis=0), len(d) - np.argmax(moving[::-1], axis=0), 0)
            self.fallen_at[p.fallen] = start + last[p.fallen]

    def figure(self, f: int, size_in: float = 6.0):
        from mpl_toolkits.mplot3d.art3d import Poly3DCollection

        from .. import _figure as plt

        scene, out, lo, hi, pad = self.scene, self.out, self.lo, self.hi, self.pad
        fig = plt.figure(figsize=(size_in, size_in))
        ax = fig.add_subplot(projection="3d")
        # the cracked joints (red) over the bricks, wherever they are: mplot3d's own depth sort put
        # every joint (inside the wall's thickness) behind its bricks' faces, and a frame that said
        # "166 joints cracked (red)" showed none
        ax.computed_zorder = False
        tri = np.concatenate(
            [(b.vertices @ self.R[f, j].T + out.positions[f, j])[b.faces] for j, b in enumerate(scene.bodies)]
        )
        n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)
        sh = 0.35 + 0.6 * np.clip(n @ self.light, 0, 1)
        fell = (self.fallen_at <= f)[self.body_of_tri]
        base = np.where(fell[:, None], [0.55, 0.55, 0.58], [0.75, 0.45, 0.32])
        ax.add_collection3d(
            Poly3DCollection(tri, facecolors=np.column_stack([base * sh[:, None], np.ones_like(sh)]), linewidths=0)
        )
        # the joints cracked by this frame, red, where they have moved with their first body
        start = min(scene.solver.warmup_frames, len(out.time) - 1)
        since = out.time[f] - out.time[start]
        cracked = 0
        if out.bond_break_time_s is not None and len(scene.bonds):
            k = np.flatnonzero(np.asarray(out.bond_break_time_s) <= since + 1e-9)
            cracked = len(k)
            if cracked:
                a = np.array([scene.bonds[j].a for j in k])
                loc = np.array([scene.bonds[j].location for j in k], dtype=np.float64)
                x0 = np.array([scene.bodies[i].location for i in a], dtype=np.float64)
                p = np.einsum("kij,kj->ki", self.R[f, a], loc - x0) + out.positions[f, a]
                ax.scatter(*p.T, s=4, c="red", depthshade=False, zorder=5)
        ax.set_xlim(lo[0] - pad, hi[0] + pad)
        ax.set_ylim(lo[1] - pad, hi[1] + pad)
        ax.set_zlim(min(lo[2], 0.0), hi[2])
        ax.set_box_aspect((hi[0] - lo[0] + 2 * pad, hi[1] - lo[1] + 2 * pad, hi[2] - min(lo[2], 0.0)))
        ax.view_init(elev=20, azim=-60)
        ax.tick_params(labelsize=7)
        # the time origin of histories.png: the end of the warm-up, when the ground starts moving
        fallen = int((self.fallen_at <= f).sum())
        ax.set_title(
            f"t = {since:.2f} s since the ground started moving; {cracked} joint{'' if cracked == 1 else 's'} "
            "cracked (red)"
            + (f"\n{fallen} bricks in pieces that fell (grey, shown where they were judged fallen)" if fallen else ""),
            fontsize=9,
        )
        fig.tight_layout()
        return fig


def _frames(out: RunOutput, count: int) -> np.ndarray:
    return np.unique(np.linspace(0, len(out.time) - 1, count).round().astype(int))


def render_frames(scene: Scene, out: RunOutput, folder: Path, count: int = 6) -> list[Path]:
    """The collapse sequence: ``count`` axonometric views of the bricks at evenly spaced times."""
    from .. import _figure as plt

    folder.mkdir(parents=True, exist_ok=True)
    painter = _FramePainter(scene, out)
    paths = []
    for k, f in enumerate(_frames(out, count)):
        fig = painter.figure(f)
        p = folder / f"frame_{k:03d}.png"
        plt.save(fig, p, dpi=90)
        plt.close(fig)
        paths.append(p)
    return paths


def write_collapse_gif(
    scene: Scene, out: RunOutput, path: Path, count: int = 24, *, progress: bool | None = None
) -> None:
    """The run as an animated GIF: ``count`` views at evenly spaced times, played in real time."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from PIL import Image

    from .. import _figure as plt
    from ..progress import progress as _progress

    painter = _FramePainter(scene, out)
    frames = _frames(out, count)
    images = []
    for f in _progress(frames, desc="collapse.gif", unit="frame", enabled=progress):
        fig = painter.figure(f, size_in=4.5)
        canvas = FigureCanvasAgg(fig)
        canvas.draw()
        rgba = np.asarray(canvas.buffer_rgba())
        images.append(Image.fromarray(rgba[..., :3].copy()).quantize(colors=128, dither=Image.Dither.NONE))
        plt.close(fig)
    if not images:
        return
    dt = np.diff(out.time[frames]) if len(frames) > 1 else np.array([1.0])
    durations = [int(max(40, round(1000 * d))) for d in dt] + [2000]  # hold the last frame
    images[0].save(path, save_all=True, append_images=images[1:], duration=durations[: len(images)], loop=0)


def plot_pushover(scene: Scene, curve: tuple[float | None, np.ndarray, np.ndarray], path: Path) -> None:
    """Roof displacement against lateral acceleration, with the collapse multiplier marked;
    ``curve`` is :func:`collapse_multiplier`'s answer."""
    from .. import _figure as plt

    value, lam, roof = curve
    fig, ax = plt.subplots(figsize=(6.5, 4.5))
    ax.plot(lam, roof * 1000, color="C3", lw=1.2)
    if value is not None:
        ax.axvline(value, color="k", lw=0.8, ls="--")
        ax.text(value, ax.get_ylim()[1] * 0.9, f"collapse multiplier {value:.3f} g  ", fontsize=8, ha="right")
    ax.set_xlabel(f"lateral acceleration (g), along {scene.pushover.direction_deg:g} deg from X")
    ax.set_ylabel("roof displacement (mm)")
    ax.set_title(f"pushover at {scene.pushover.rate_g_per_s:g} g/s", fontsize=9)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    plt.save(fig, path, dpi=110)
    plt.close(fig)


def _elastic_drift(scene: Scene, out: RunOutput, lam: np.ndarray, along: np.ndarray) -> np.ndarray:
    """The beam's displacement along the push (m) at lateral loads ``lam`` (g) before the peak, from
    the joint model (Bullet holds the intact structure rigid, so its poses show no drift before a
    mechanism): each load solved with the joints that had cracked by then, less the displacement under
    gravity alone. NaN where that solve did not converge: near the peak the run's cracks, solved
    again at one load without the contacts' slip history, may have no static equilibrium, and the
    contact iteration's last iterate is then no displacement at all (the rubble wall WR2.250's
    shear test read -1826 % at 95 % of its peak, its out-of-balance force 5e9 tolerances)."""
    from .joints import JointModel

    jm = JointModel(scene)
    beam = scene.notes["shear_test"]["beam"]
    broke = out.bond_break_time_s if out.bond_break_time_s is not None else np.full(len(scene.bonds), np.nan)
    rate = scene.pushover.rate_g_per_s
    drift = np.zeros(len(lam))
    ref = None
    for i, x in enumerate(np.concatenate([[0.0], lam])):
        intact = ~(broke <= x / rate)  # NaN: never cracked
        jm.solve(np.array([x * G * along[0], x * G * along[1], -G]), intact)
        if jm.motion is None:
            d = 0.0
        else:
            d = float(jm.motion[6 * beam : 6 * beam + 3] @ along) if jm.converged else np.nan
        if i == 0:
            ref = d
        else:
            drift[i - 1] = d - ref
    return drift


def shear_curve(scene: Scene, out: RunOutput, m: Metrics, curve, levels: int = 40) -> dict:
    """A shear test's force-drift curve and its peak (see
    :func:`~calib_masonry.simulation.scene.shear_test_scene`): the lateral force at the top (kN:
    ``lambda`` times the notes' ``force_per_g_kn``) against the drift (the beam's displacement along
    the push over the wall's height). Up to the peak the drift is the joint model's: the run's own
    at each frame's check (``out.beam_motion``: the unit-load solutions while nothing has cracked,
    then each converged solve, along the run's path of cracks and contact slip), or, for a run
    without it, each of ``levels`` loads solved again with the joints cracked by then
    (:func:`_elastic_drift`); a load whose motion is not known is left out. After the peak, the last
    known drift plus the beam's motion in Bullet. The peak force is the force at the collapse multiplier (the last
    load before the joint model set the beam free, or before the beam ran away in Bullet if that
    came first: :func:`collapse_multiplier`), None if the ramp ended first."""
    st = scene.notes["shear_test"]
    value, lam, _ = curve
    start = m.start_frame
    d = np.radians(scene.pushover.direction_deg)
    along = np.array([np.cos(d), np.sin(d), 0.0])
    top = float(value) if value is not None else float(lam.max())
    run = getattr(out, "beam_motion", None)
    run = None if run is None else run[start:, :3] @ along
    if run is not None and len(run) == len(lam) and np.isfinite(run).any():
        # the run's own joint model at each frame's check, from its first (the weight alone, the
        # ramp at zero): its path, with the cracks and the contacts' slip as they came
        ref = run[np.flatnonzero(np.isfinite(run))[0]]
        up = (lam <= top) & (lam > 0.0)
        pre, pre_drift = lam[up], (run[up] - ref) / st["height_m"]
    else:  # each of ``levels`` loads solved again with the joints cracked by then
        pre = np.linspace(0.0, top, levels + 1)[1:]
        pre_drift = _elastic_drift(scene, out, pre, along) / st["height_m"]
    # the loads whose motion is known: the curve leaves the others out (see _elastic_drift)
    known = np.isfinite(pre_drift)
    last = float(pre_drift[known][-1]) if known.any() else 0.0
    beam = st["beam"]
    rel = out.positions[start:, beam] - out.positions[start, beam] - (out.plate[start:] - out.plate[start])
    after = lam > top
    post_drift = last + (rel[after] @ along) / st["height_m"]
    peak = None if value is None else float(value * st["force_per_g_kn"])
    # the joint model's geometry is linear: its drift at the last load before a mechanism grows
    # without bound as the mechanism forms (a rocking wall's 21 % on a laboratory wall whose force
    # was within 3 % of the peak from 0.5 %), so the drift where the force reaches 95 % of the
    # peak is reported beside it (interpolated on the curve up to the peak, where a converged
    # load at or above it brackets it)
    f = np.concatenate([[0.0], pre[known]])
    dr = np.concatenate([[0.0], pre_drift[known]])
    at95 = float(np.interp(0.95 * top, f, dr)) if value is not None and f[-1] >= 0.95 * top else None
    return {
        "force_kn": np.concatenate([[0.0], pre[known], lam[after]]) * st["force_per_g_kn"],
        "drift": np.concatenate([[0.0], pre_drift[known], post_drift]),
        "peak_lateral_force_kn": peak,
        "drift_at_peak": None if value is None or not known[-1] else float(pre_drift[-1]),
        "drift_at_95_percent_of_peak": at95,
        # how far up the curve the joint model's drift goes: the largest force whose solve converged
        "drift_known_to_kn": float(f[-1] * st["force_per_g_kn"]),
        "drift_levels_converged": int(known.sum()),
        "drift_levels": len(pre),
    }


def write_shear_curve(scene: Scene, shear: dict, folder: Path, figures: bool = True) -> None:
    """force_drift.csv (drift in per cent, force in kN, per frame) and force_drift.png."""
    rows = np.column_stack([shear["drift"] * 100, shear["force_kn"]])
    np.savetxt(
        folder / "force_drift.csv",
        rows,
        delimiter=",",
        header="drift_percent,lateral_force_kn",
        comments="",
        fmt="%.6g",
    )
    if not figures:
        return
    from .. import _figure as plt

    st = scene.notes["shear_test"]
    fig, ax = plt.subplots(figsize=(6.5, 4.5))
    drift, force = shear["drift"] * 100, shear["force_kn"]
    peak = shear["peak_lateral_force_kn"]
    pre = force <= (peak if peak is not None else np.inf) + 1e-9
    known = shear.get("drift_known_to_kn")
    short = peak is not None and known is not None and known < peak - 1e-9
    ax.plot(
        drift[pre], force[pre], color="C0", lw=1.2,
        label=f"up to {known:.1f} kN (joint model; above it no load's solve converged)" if short
        else "up to the peak (joint model)",
    )  # fmt: skip
    if (~pre).any():
        ax.plot(drift[~pre], force[~pre], color="C0", lw=1.0, ls="--", label="after it: the wall runs away (Bullet)")
    # the drifts a laboratory test reaches (a few per cent), not the joint model's drift at the
    # peak itself, which grows without bound as a mechanism forms (its geometry is linear)
    top = max(3.0, 3 * 100 * (shear.get("drift_at_95_percent_of_peak") or shear["drift_at_peak"] or 0.0))
    if drift.max() > top:
        ax.set_xlim(0, top)
    ax.legend(fontsize=8, loc="lower right")
    if shear["peak_lateral_force_kn"] is not None:
        ax.axhline(shear["peak_lateral_force_kn"], color="k", lw=0.8, ls="--")
        at95 = shear.get("drift_at_95_percent_of_peak")
        ax.text(
            ax.get_xlim()[1], shear["peak_lateral_force_kn"], f"peak {shear['peak_lateral_force_kn']:.1f} kN"
            + (f" (95 % of it at {100 * at95:.2f} % drift) " if at95 is not None else " "),
            fontsize=8, ha="right", va="bottom",
        )  # fmt: skip
    ax.set_xlabel("drift (%)")
    ax.set_ylabel("lateral force (kN)")
    ax.set_title(
        f"shear test, {st['boundary']}, {st['precompression_mpa']:g} MPa ({st['vertical_load_kn']:.1f} kN), "
        f"H0/L = {st['shear_span_ratio']:.2f}",
        fontsize=9,
    )
    ax.grid(alpha=0.3)
    fig.tight_layout()
    plt.save(fig, folder / "force_drift.png", dpi=110)
    plt.close(fig)

"""The footprint: adjust every wall's W and theta so the walls close into a ring (or, for an open
footprint, an L or a row of walls, so that they agree with the corner photos' turns alone).

Each wall brings an estimate of its width (from its photo's calibration, with its sigma) and of
its orientation theta (from the photo's EXIF compass heading plus the fitted yaw, or typed in);
each corner photo (``[[corner]]`` in the structure file, see calibrate.corner) the turn between
two walls, a residual ``wrap(theta_j - theta_i - turn) / sigma``.
We solve, with optimistix's Levenberg-Marquardt,

    minimise  sum_n ((W_n - W^_n) / sW_n)^2 + (wrap(theta_n - theta^_n) / s_theta_n)^2
    subject to  sum_n W_n (cos theta_n, sin theta_n) = 0,

the constraint as two residuals scaled by ``closure_sigma_m`` (1 micrometre: the ring closes to
far below a millimetre). The covariance of the adjusted values is ``(J^T J)^-1`` of that system,
which is the constrained covariance to first order. The first wall's theta is the reference of a
rotation that the closure cannot see, so its prior is what fixes the ring's orientation. An open
footprint has no closure: its walls' W are their photos' and their thetas are adjusted to the turns,
so each wall needs a theta of its own or a chain of corner photos to one that has.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from .._jax import jax, jnp
from ..build3d.place import ring_closes
from ..errors import FitFailed, InputError
from .fitresult import FitResult, FitStatus, HasFit, fit_result
from .lm import least_squares

__all__ = ["FootprintResult", "fit_footprint"]


@dataclass(frozen=True)
class FootprintResult(HasFit):
    """The footprint adjustment: its :class:`~calib_masonry.calibrate.fitresult.FitResult` (unknowns
    W_1..W_n, theta_1..theta_n) and the closure gap before and after."""

    fit: FitResult
    closure_gap_m: float | None  # after the fit; None for an open footprint
    closure_gap_before_m: float | None

    @property
    def n(self) -> int:
        return len(self.fit.value) // 2

    @property
    def width_m(self) -> np.ndarray:
        return self.fit.value[: self.n]

    @property
    def theta_rad(self) -> np.ndarray:
        return np.mod(self.fit.value[self.n :], 2 * math.pi)

    @property
    def width_sigma_m(self) -> np.ndarray:
        return self.fit.sigmas[: self.n]

    @property
    def theta_sigma_rad(self) -> np.ndarray:
        return self.fit.sigmas[self.n :]

    def to_json(self, names) -> dict:
        return {
            "walls": [
                {
                    "name": n,
                    "width_m": float(w),
                    "width_sigma_m": float(sw),
                    "theta_deg": math.degrees(t) % 360.0,
                    "theta_sigma_deg": math.degrees(st),
                }
                for n, w, t, sw, st in zip(
                    names, self.width_m, self.theta_rad, self.width_sigma_m, self.theta_sigma_rad
                )
            ],
            "closure_gap_m": self.closure_gap_m,
            "closure_gap_before_m": self.closure_gap_before_m,
            **self.fit.to_json(),
        }


def _gap(w, t, xp=np):
    return xp.stack([xp.sum(w * xp.cos(t)), xp.sum(w * xp.sin(t))])


def _wrap(a):
    return jnp.arctan2(jnp.sin(a), jnp.cos(a))


def _residuals(x, args):
    w_hat, t_hat, sw, st_inv, sc, turn_i, turn_j, turn, turn_inv = args
    n = w_hat.shape[0]
    w, t = x[:n], x[n:]
    dturn = _wrap(t[turn_j] - t[turn_i] - turn) * turn_inv
    return jnp.concatenate([(w - w_hat) / sw, _wrap(t - t_hat) * st_inv, _gap(w, t, jnp) / sc, dturn])


@jax.jit
def _solve(x0, args):
    return least_squares(_residuals, x0, args, max_steps=500, tol=1e-12)


def fit_footprint(
    width_m,
    width_sigma_m,
    theta_rad,
    theta_sigma_rad,
    *,
    closure_sigma_m: float = 1e-6,
    names=None,
    turns=(),
    closed: bool = True,
) -> FootprintResult:
    """Adjust per-wall (W, theta) estimates with their sigmas so the footprint closes (``closed``;
    else so that they agree with the turns alone: an open footprint, one wall or more).

    ``theta_sigma_rad`` may be ``inf`` for a wall with no own orientation estimate. ``turns`` are
    corner-photo measurements ``(i, j, turn_rad, sigma_rad)``: theta_j - theta_i = turn."""
    w_hat = np.asarray(width_m, dtype=np.float64)
    t_hat = np.asarray(theta_rad, dtype=np.float64)
    sw = np.asarray(width_sigma_m, dtype=np.float64) * np.ones_like(w_hat)
    st = np.asarray(theta_sigma_rad, dtype=np.float64) * np.ones_like(w_hat)
    names = names or [f"wall{i + 1}" for i in range(len(w_hat))]
    if len(t_hat) != len(w_hat) or len(w_hat) < (3 if closed else 1):
        raise InputError(
            f"footprint: {len(w_hat)} walls; a closed footprint needs at least 3 with W and theta each "
            "(an L or a row of walls: closed = false in the structure file)"
        )
    for i, n in enumerate(names):
        if not (w_hat[i] > 0 and sw[i] > 0 and st[i] > 0 and (np.isfinite(t_hat[i]) or np.isinf(st[i]))):
            raise InputError(
                f"footprint: wall '{n}' needs width_m > 0, a width sigma > 0, a theta and a theta "
                "sigma > 0; check its calibration.json or the structure file"
            )
    turns = list(turns)
    ti = np.array([t[0] for t in turns], dtype=np.int64)
    tj = np.array([t[1] for t in turns], dtype=np.int64)
    tv = np.array([t[2] for t in turns], dtype=np.float64)
    ts = np.array([t[3] for t in turns], dtype=np.float64)
    if np.any(ts <= 0) or np.any((ti < 0) | (ti >= len(w_hat)) | (tj < 0) | (tj >= len(w_hat))):
        raise InputError("footprint: a corner measurement names a wall that is not there or has sigma <= 0")
    st_inv = np.where(np.isinf(st), 0.0, 1.0 / st)
    if not np.any(st_inv > 0):
        raise InputError(
            "footprint: no wall has an orientation estimate (EXIF heading or theta_deg); give one at least"
        )
    t_start = np.where(np.isinf(st), 0.0, t_hat)
    # walls with no own theta take theirs from a measured turn (in footprint order), for the start
    for i, j, v, _ in sorted(turns, key=lambda q: q[1]):
        if np.isinf(st[j]) and not np.isinf(st[i]):
            t_start[j] = t_start[i] + v
    t_hat = np.where(np.isinf(st), t_start, t_hat)
    if not closed:  # no closure to give a wall its theta: each needs its own or a turn to one that has
        known = ~np.isinf(st)
        for _ in range(len(w_hat)):
            for i, j in zip(ti.tolist(), tj.tolist()):
                known[i] = known[j] = known[i] or known[j]
        if not known.all():
            raise InputError(
                f"footprint: wall '{names[int(np.argmin(known))]}' of an open footprint has no orientation: give "
                "its theta_deg, a photo with an EXIF heading, or a corner photo with a wall that has one"
            )
    before = float(np.linalg.norm(_gap(w_hat, t_hat))) if closed else None
    sc = closure_sigma_m if closed else np.inf  # an open footprint's gap is no residual
    args = tuple(jnp.asarray(a) for a in (w_hat, t_hat, sw, st_inv, sc, ti, tj, tv, 1.0 / ts))
    x, ok, steps, jac, r = _solve(jnp.asarray(np.r_[w_hat, t_start]), args)
    n = len(w_hat)
    fit = fit_result(x, ok, steps, jac, r, [f"width_m:{m}" for m in names] + [f"theta_rad:{m}" for m in names])
    x = fit.value
    # a ring that closes only by shrinking a wall to (almost) nothing is no footprint: the walls'
    # thetas do not go round (three copies of one wall, a wall listed twice, a heading off by 180)
    if closed and fit.status.ok and np.any(x[:n] <= 0.5 * w_hat):
        fit = replace(fit, status=FitStatus.DEGENERATE)
    if not fit.status.ok:
        worst = names[int(np.argmin(x[:n] / w_hat))] if np.all(np.isfinite(x)) else None
        raise FitFailed(
            f"footprint: closure fit: {fit.status.message}"
            + (
                f" (wall '{worst}' would shrink from {w_hat[names.index(worst)]:.3f} m to "
                f"{x[names.index(worst)]:.3f} m)"
                if worst is not None and fit.status is FitStatus.DEGENERATE
                else ""
            )
        )
    gap = float(np.linalg.norm(_gap(x[:n], x[n:]))) if closed else None
    return FootprintResult(fit=fit, closure_gap_m=gap, closure_gap_before_m=before)


def _estimates_from_structure(path, config, heading_sigma_deg, theta_sigma_deg):
    from ..spec import load_structure
    from .camera import theta_from_heading
    from .rectify import calibrate_photo, wall_config

    spec = load_structure(path)
    rows = []
    for wall in spec.walls:
        if wall.image is None:
            if wall.size_from_photo:
                raise InputError(f"{path}: wall '{wall.name}' has neither a photo nor width_m; give one")
            rows.append((wall.name, wall.width_m, 0.005, wall.theta_rad, math.radians(theta_sigma_deg), "typed"))
            continue
        # the wall's own scale where the command gives none (its typed W or H, as build's: on the
        # eye-height prior alone every photo of the README's example was refused, W +-31 %), its
        # camera height, corners, focal length and occluders
        cfg = wall_config(wall, config)
        cal = calibrate_photo(wall.image, cfg)
        res = cal.result
        if cal.photo.heading_deg is not None:
            theta = theta_from_heading(math.radians(cal.photo.heading_deg), res.value("yaw_rad"))
            t_sigma = math.hypot(math.radians(heading_sigma_deg), res.sigma("yaw_rad"))
            source = "EXIF heading + fitted yaw"
        else:
            theta, t_sigma, source = wall.theta_rad, math.radians(theta_sigma_deg), "typed (no EXIF heading)"
        rows.append((wall.name, res.width_m, res.sigma("width_m"), theta, t_sigma, source))
    return spec, rows


def _turns_from_structure(spec, names):
    from .corner import calibrate_corner_photo

    turns, docs = [], []
    for c in spec.corners:
        res = calibrate_corner_photo(c.photo, focal_px=c.focal_px)
        turns.append((names.index(c.walls[0]), names.index(c.walls[1]), res.turn_rad, res.turn_sigma_rad))
        docs.append({"photo": str(c.photo), "walls": list(c.walls), **res.to_json(), "_result": res})
    return turns, docs


def _estimates_from_json(paths, heading_sigma_deg):
    from ..io import read_json

    rows = []
    for p in paths:
        doc = read_json(p, field="calibration")
        if "theta_from_heading_deg" not in doc:
            raise InputError(f"{p}: no EXIF heading in this calibration; pass a structure TOML with theta_deg instead")
        try:
            yaw_sigma = math.sqrt(doc["covariance"]["matrix"][1][1])
            rows.append(
                (
                    str(p),
                    float(doc["width_m"]),
                    float(doc["width_sigma_m"]),
                    math.radians(doc["theta_from_heading_deg"]),
                    math.hypot(math.radians(heading_sigma_deg), yaw_sigma),
                    "EXIF heading + fitted yaw",
                )
            )
        except (KeyError, TypeError, IndexError, ValueError):
            raise InputError(f"{p}: not a calibration.json written by `calib-masonry rectify`") from None
    return None, rows


def _is_closed(spec, width_m: np.ndarray, theta_rad: np.ndarray) -> bool:
    """Whether the walls are to close into a ring: as the structure file declares (``closed``), else
    as :func:`~calib_masonry.build3d.place.ring_closes` decides from the estimates (a ring of three or
    more with a wall that has no theta yet is closed: the closure places that wall). Calibrations
    alone (no structure file): a ring of three or more; one or two walls are open (an L: no ring
    has two sides)."""
    if spec is None:
        return len(width_m) >= 3
    if spec.closed is not None:
        return bool(spec.closed)
    if len(width_m) >= 3 and not (np.all(np.isfinite(width_m)) and np.all(np.isfinite(theta_rad))):
        return True
    return ring_closes(width_m, theta_rad)


def footprint_to_folder(
    inputs,
    out,
    *,
    config=None,
    heading_sigma_deg: float = 2.0,
    theta_sigma_deg: float = 1.0,
    figure: bool = True,
    overwrite: bool = False,
) -> dict:
    """``calib-masonry footprint``: footprint.json, structure.toml with the adjusted W and theta, a plan figure."""
    from pathlib import Path

    from ..io import check_output, staged_output, write_json
    from ..spec import structure_to_toml
    from .figures import plot_footprint
    from .rectify import CalibrateConfig

    check_output(out, command="footprint", overwrite=overwrite)
    config = config or CalibrateConfig()
    if heading_sigma_deg <= 0 or theta_sigma_deg <= 0:
        raise InputError("footprint: --heading-sigma and --theta-sigma must be > 0 (degrees)")
    paths = [Path(p) for p in inputs]
    if len(paths) == 1 and paths[0].suffix == ".toml":
        spec, rows = _estimates_from_structure(paths[0], config, heading_sigma_deg, theta_sigma_deg)
    elif all(p.suffix == ".json" for p in paths):
        spec, rows = _estimates_from_json(paths, heading_sigma_deg)
    else:
        raise InputError("footprint: give one structure .toml, or calibration .json files in footprint order")
    names = [r[0] for r in rows]
    turns, corner_docs = _turns_from_structure(spec, names) if spec is not None else ([], [])
    w, sw, t, st = (np.array([r[i] for r in rows]) for i in (1, 2, 3, 4))
    closed = _is_closed(spec, w, t)
    res = fit_footprint(w, sw, t, st, names=names, turns=turns, closed=closed)
    doc = res.to_json(names)
    doc["corners"] = [{k: v for k, v in d.items() if k != "_result"} for d in corner_docs]
    for row, est in zip(doc["walls"], rows):
        row.update(
            estimate_width_m=est[1],
            estimate_width_sigma_m=est[2],
            estimate_theta_deg=math.degrees(est[3]) % 360,
            estimate_theta_sigma_deg=math.degrees(est[4]),
            theta_source=est[5],
        )
    with staged_output(out, "footprint", overwrite=overwrite, keep=paths) as stage:
        write_json(stage / "footprint.json", doc)
        if spec is not None:
            walls = tuple(
                replace(
                    wall,
                    width_m=float(res.width_m[i]),
                    theta_rad=float(res.theta_rad[i]),
                    image=wall.image.resolve() if wall.image else None,
                    mask=wall.mask.resolve() if wall.mask else None,
                )
                for i, wall in enumerate(spec.walls)
            )
            # every path absolute, the corner photos' too (written as given, relative to where the
            # command ran, they were looked for beside the new file and the build of it failed)
            corners = tuple(replace(c, photo=c.photo.resolve()) for c in spec.corners)
            (stage / "structure.toml").write_text(
                (
                    "# Written by `calib-masonry footprint`: W and theta adjusted so the footprint closes.\n"
                    if closed
                    else "# Written by `calib-masonry footprint`: W from the photos, theta adjusted to the corner photos.\n"
                )
                + structure_to_toml(replace(spec, walls=walls, corners=corners, closed=closed), relative_to=None),
                encoding="utf-8",
            )
        if figure and corner_docs:
            from ..io import read_photo
            from .figures import plot_corner

            (stage / "corners").mkdir()
            for d in corner_docs:
                a, b = d["walls"]
                plot_corner(
                    read_photo(d["photo"]).rgb,
                    d["_result"],
                    stage / "corners" / f"{a}_{b}.png",
                    names=(a, b),
                    title=f"corner {a} / {b}:",
                )
        if figure:
            plot_footprint(
                w,
                t,
                res.width_m,
                res.theta_rad,
                names,
                stage / "footprint.png",
                title=f"footprint of {len(names)} walls",
                closed=closed,
            )
    return doc

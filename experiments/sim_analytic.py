"""The simulation's analytic checks at the default solver settings, with the measured numbers.

Free fall (landing time vs sqrt(2 h / g)), a block on a plane tilted 0.95 / 1.05 / 1.6 x atan(mu)
(distance slid in 1 s, fitted vs theoretical acceleration), and Housner's rocking block on a plate
accelerating at 0.9 to 1.05 x g b / h (largest tilt). tests/test_simulate.py asserts the same
cases; this prints the figures. About 30 s.

    .venv/bin/python experiments/sim_analytic.py
"""

from __future__ import annotations

import math

import numpy as np

from calib_masonry.simulation.ground_motion import G, constant_acceleration
from calib_masonry.simulation.loop import run
from calib_masonry.simulation.scene import Body, Plate, Scene, SolverSettings, box_mesh


def block(size, loc, mu=0.6, rotation=(1.0, 0.0, 0.0, 0.0)) -> Body:
    v, f = box_mesh(size)
    vol = float(np.prod(size))
    return Body("block", v, f, np.asarray(loc, float), 1800 * vol, math.sqrt(mu), 0.0, vol, rotation=rotation)


def main() -> None:
    s = SolverSettings()
    print(f"solver: {s.fps} fps x {s.substeps} substeps x {s.iterations} iterations (one frame = {1 / s.fps:.3f} s)")
    for h in (1.0, 3.0):
        out = run(
            Scene(bodies=(block((0.2, 0.2, 0.2), (0, 0, h + 0.1)),), duration_s=1.2, solver=SolverSettings(warmup_s=0)),
            progress=False,
        )
        landed = int(np.argmax(out.positions[:, 0, 2] <= 0.11))
        print(f"free fall from {h:g} m: lands at {out.time[landed]:.3f} s, sqrt(2h/g) = {math.sqrt(2 * h / G):.3f} s")
    mu = 0.5
    for factor in (0.95, 1.05, 1.6):
        tilt = factor * math.degrees(math.atan(mu))
        th = math.radians(tilt)
        plate = Plate(size=(6.0, 2.0, 0.2), top_z=0.0, friction=math.sqrt(mu), tilt_deg=tilt)
        top = np.array([0.0, 0.0, -0.1]) + 0.1 * np.array([math.sin(th), 0.0, math.cos(th)])
        normal = np.array([math.sin(th), 0.0, math.cos(th)])
        b = block((0.3, 0.3, 0.2), top + 0.1 * normal, mu=mu, rotation=(math.cos(th / 2), 0.0, math.sin(th / 2), 0.0))
        out = run(Scene(bodies=(b,), plate=plate, duration_s=1.0, solver=SolverSettings(warmup_s=0)), progress=False)
        path = np.linalg.norm(out.positions[:, 0] - out.positions[0, 0], axis=1)
        keep = out.time >= 0.3
        a_fit = 2 * np.polyfit(out.time[keep], path[keep], 2)[0]
        a = G * (math.sin(th) - mu * math.cos(th))
        print(
            f"plane at {tilt:.2f} deg ({factor:g} x atan(mu)): slid {path[-1] * 1000:.1f} mm in 1 s; "
            f"acceleration fitted {a_fit:.3f}, theory {max(a, 0.0):.3f} m/s^2"
        )
    b_, h_ = 0.1, 0.5
    for factor in (0.9, 0.97, 1.03, 1.05):
        a = factor * G * b_ / h_
        out = run(
            Scene(
                bodies=(block((2 * b_, 0.6, 2 * h_), (0, 0, h_), mu=0.8),),
                plate=Plate(friction=math.sqrt(0.8)),
                motion=constant_acceleration(a, 1.5, dt=0.001),
                duration_s=1.5,
                solver=SolverSettings(warmup_s=0.1),
            ),
            progress=False,
        )
        w = np.abs(out.quaternions[:, 0, 0]).clip(0, 1)
        print(f"rocking block, plate at {factor:g} x g b/h: largest tilt {np.degrees(2 * np.arccos(w)).max():.2f} deg")


if __name__ == "__main__":
    main()

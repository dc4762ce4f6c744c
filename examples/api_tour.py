"""A tour of the library, in memory: photo -> calibration -> orthophoto -> mask -> polygons ->
refined polygons -> model -> comparison with truth -> simulation. It writes no file.

    .venv/bin/python examples/api_tour.py

The photo is rendered here from a synthetic wall (wall1 of the paper example, whose exact bricks
are known), so the tour can also say how close each stage came to the truth.
"""

from __future__ import annotations

import math
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

import calib_masonry as cm
from calib_masonry.spec import PhotoSpec
from calib_masonry.synthetic.photo import photograph_wall

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    t0 = time.perf_counter()
    # the scenario: one wall of the paper example, and its exact bricks
    scenario = cm.load_structure(ROOT / "data_synthetic" / "paper_example" / "scenario.toml", require_sources=False)
    scenario = replace(scenario, walls=scenario.walls[:1], closed=False)
    wall = scenario.walls[0]
    pieces, truth = cm.truth_structure(scenario)

    # a perspective photo of it from standing height (an array, with the focal length EXIF would give)
    shot = photograph_wall(
        wall, pieces[0], PhotoSpec(distance_m=(6.0, 9.0), max_yaw_deg=20.0), np.random.default_rng(7)
    )
    photo = cm.Photo(
        path=Path(f"{wall.name} (rendered in memory)"),
        rgb=shot["image"],
        focal_px=shot["truth"]["params"]["focal_px"],
        heading_deg=None,
    )

    # 1. calibrate: camera and wall size, with their covariance (the eye height measured to +- 2 cm)
    eye = shot["truth"]["eye_height_m"]
    cal = cm.calibrate_photo(photo, cm.CalibrateConfig(camera_height_m=eye, camera_height_sigma_m=0.02))
    res = cal.result
    print(
        f"calibrate_photo: W = {res.width_m:.3f} +- {res.sigma('width_m'):.3f} m (true {wall.width_m:.3f}), "
        f"H = {res.height_m:.3f} +- {res.sigma('height_m'):.3f} m (true {wall.height_m:.3f}), "
        f"yaw {math.degrees(res.value('yaw_rad')):.1f} deg, {res.status.value} in {res.steps} steps"
    )

    # 2. rectify and segment: the metric orthophoto and its brick mask
    ortho = cm.rectify(cal, px_per_m=300.0)
    mask = cm.segment(ortho, cm.PhotoSegmentConfig(window_px=150))
    print(f"rectify + segment: {ortho.shape[1]} x {ortho.shape[0]} px orthophoto, {mask.mean():.1%} brick")

    # 3. trace and refine: one polygon per brick, with its Dice against the mask
    traced = cm.trace(mask, cm.TraceConfig(vertices=5))
    refined = cm.refine(mask, traced)
    print(f"trace: {len(traced.bricks)} bricks, mean Dice {traced.mean_dice:.4f}; refine: {refined.mean_dice:.4f}")

    # 4. build: the wall's measured size and the polygons -> 3D bricks
    spec = cm.StructureSpec(
        name="tour",
        thickness_m=wall.thickness_m,
        closed=False,
        walls=(
            cm.WallSpec(
                name=wall.name, width_m=res.width_m, height_m=res.height_m, theta_rad=0.0, thickness_m=wall.thickness_m
            ),
        ),
    )
    built = cm.build(spec, traces={wall.name: refined}, progress=False)
    metrics = cm.compare(built.structure, truth)
    print(
        f"build: {len(built.structure.bricks)} bricks; compare with truth: precision {metrics['precision']:.3f}, "
        f"recall {metrics['recall']:.3f}, median Dice {metrics['dice']['median']:.4f}, "
        f"centroid error {metrics['centroid_error_mm']['mean']:.1f} mm"
    )

    # 5. simulate: two seconds of a 0.3 g synthetic quake (Bullet through bpy)
    motion = cm.synthetic_motion(0.3, 2.0, seed=0)
    result = cm.simulate(built.structure, motion, progress=False)
    s = result.summary
    print(
        f"simulate: {s['outcome']}, {s['moved_fraction_final']:.1%} of bricks moved, "
        f"{s['bonds_broken']} of {s['bonds']} joints cracked, max roof drift {s['max_roof_drift_m'] * 1000:.1f} mm"
    )
    print(f"tour: {time.perf_counter() - t0:.1f} s, nothing written")


if __name__ == "__main__":
    main()

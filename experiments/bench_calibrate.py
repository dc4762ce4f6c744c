"""Benchmark: camera calibration on synthetic standing-height photos of the paper example's walls.

Photos come from `synth` with seeds the tests and the tuning never used (default 101-105; the
tuning used the data set's own seed 20261122 and seed 1). For every photo:

- clicked mode: the true wall corners plus N(0, 1.5 px) noise, camera height and focal length
  known; ours (corners + joint lines + priors, LM) against the Photoshop-like baseline, kornia's
  4-point DLT from the same clicks onto the true W x H rectangle. Error of every true brick
  vertex after rectification (mm, RMS per photo) and of W and H (ours; the DLT is given them);
- automatic mode: no clicks, camera height known; success rate and W, H errors;
- fit time per photo after compilation (the LM solve alone, and detection separately);
- the footprint: per-wall W from the automatic fits and theta from each photo's EXIF heading plus
  the fitted yaw, closed by `fit_footprint`, without and with the six corner photos' turn angles.

    .venv/bin/python experiments/bench_calibrate.py [--seeds 101 102 103 104 105] [--size 3000 2000]
"""

from __future__ import annotations

import argparse
import math
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from calib_masonry.calibrate.camera import project, theta_from_heading
from calib_masonry.calibrate.corner import calibrate_corner_photo
from calib_masonry.calibrate.fit import CalibrationInput, calibrate, order_corners
from calib_masonry.calibrate.footprint import fit_footprint
from calib_masonry.calibrate.lines import detect_wall, refine_quad, segments_in_quad
from calib_masonry.calibrate.rectify import CalibrateConfig, calibrate_photo
from calib_masonry.errors import CalibMasonryError
from calib_masonry.io import read_photo
from calib_masonry.spec import PhotoSpec, load_structure
from calib_masonry.synthetic.truth import synthesize_to_folder

ROOT = Path(__file__).resolve().parents[1]


def kornia_dlt(clicked: np.ndarray, width: float, height: float) -> np.ndarray:
    """wall_from_image by kornia's DLT from the 4 clicks onto the true rectangle."""
    import torch
    from kornia.geometry.homography import find_homography_dlt

    rect = np.array([[0, 0], [width, 0], [width, height], [0, height]], dtype=np.float64)
    h = find_homography_dlt(torch.from_numpy(clicked)[None], torch.from_numpy(rect)[None])[0].numpy()
    return h / h[2, 2]


def vertex_rms_mm(wall_from_image: np.ndarray, image_from_wall_true: np.ndarray, vertices_m: np.ndarray) -> float:
    img = project(image_from_wall_true, vertices_m)
    back = project(wall_from_image, img)
    return float(np.sqrt(np.mean(np.sum((back - vertices_m) ** 2, axis=1)))) * 1000


def run(seeds, size, noise_px, heading_sigmas) -> None:
    base = load_structure(ROOT / "data_synthetic" / "paper_example" / "scenario.toml", require_sources=False)
    photos = replace(PhotoSpec(), long_side_px=max(size), short_side_px=min(size))
    rows, auto_rows, fit_times, detect_times, footprints = [], [], [], [], []
    with tempfile.TemporaryDirectory() as tmp:
        for seed in seeds:
            spec = replace(base, synthetic=replace(base.synthetic, seed=seed))
            out = Path(tmp) / f"s{seed}"
            t0 = time.perf_counter()
            truth = synthesize_to_folder(spec, out, figures=False, photos=photos, progress=False)
            print(f"seed {seed}: {len(truth['photos'])} photos in {time.perf_counter() - t0:.0f} s", flush=True)
            rng = np.random.default_rng([seed, 99])
            fp_w, fp_sw, fp_t, fp_true = [], [], [], []
            for wall_t, photo_t in zip(truth["walls"], truth["photos"]):
                photo = read_photo(out / photo_t["photo"])
                w_true, h_true = wall_t["width_m"], wall_t["height_m"]
                h_true_img = np.array(photo_t["image_from_wall"])
                verts = np.concatenate([np.asarray(p["polygon_m"]) for p in wall_t["pieces"]])
                clicked = np.asarray(photo_t["corners_px"]) + rng.normal(0, noise_px, (4, 2))
                # ours, clicked
                t0 = time.perf_counter()
                det = detect_wall(photo.rgb)
                detect_times.append(time.perf_counter() - t0)
                quad_clicked = order_corners(clicked)
                quad = refine_quad(photo.rgb, quad_clicked, (3.0 * noise_px + 1.0, 2.0))
                snap_ok = not np.array_equal(quad, quad_clicked)
                inp = CalibrationInput(
                    photo.size,
                    quad,
                    corner_sigma_px=0.5 if snap_ok else noise_px,
                    bed_segments=segments_in_quad(det.bed_segments, quad),
                    head_segments=segments_in_quad(det.head_segments, quad),
                    max_effective_segments=16,
                    camera_height_m=photo_t["eye_height_m"],
                    camera_height_sigma_m=0.01,
                    focal_px=photo_t["params"]["focal_px"],
                )
                res = calibrate(inp)
                t0 = time.perf_counter()
                calibrate(inp)
                fit_times.append(time.perf_counter() - t0)
                res_nolines = calibrate(replace(inp, bed_segments=np.zeros((0, 4)), head_segments=np.zeros((0, 4))))
                res_raw = calibrate(replace(inp, corners_px=quad_clicked, corner_sigma_px=noise_px))
                known = dict(known_width_m=w_true, known_height_m=h_true, known_sigma_m=0.001)
                res_raw_known = calibrate(replace(inp, corners_px=quad_clicked, corner_sigma_px=noise_px, **known))
                res_raw_known_nl = calibrate(
                    replace(
                        inp,
                        corners_px=quad_clicked,
                        corner_sigma_px=noise_px,
                        bed_segments=np.zeros((0, 4)),
                        head_segments=np.zeros((0, 4)),
                        **known,
                    )
                )
                dlt = kornia_dlt(quad_clicked, w_true, h_true)
                rows.append(
                    {
                        "w_err": abs(res.width_m / w_true - 1),
                        "h_err": abs(res.height_m / h_true - 1),
                        "ours_mm": vertex_rms_mm(res.wall_from_image, h_true_img, verts),
                        "corners_only_mm": vertex_rms_mm(res_nolines.wall_from_image, h_true_img, verts),
                        "raw_mm": vertex_rms_mm(res_raw.wall_from_image, h_true_img, verts),
                        "raw_w_err": abs(res_raw.width_m / w_true - 1),
                        "raw_h_err": abs(res_raw.height_m / h_true - 1),
                        "snapped": snap_ok,
                        "raw_known_mm": vertex_rms_mm(res_raw_known.wall_from_image, h_true_img, verts),
                        "raw_known_nolines_mm": vertex_rms_mm(res_raw_known_nl.wall_from_image, h_true_img, verts),
                        "dlt_mm": vertex_rms_mm(dlt, h_true_img, verts),
                    }
                )
                # automatic
                try:
                    cal = calibrate_photo(
                        photo, CalibrateConfig(camera_height_m=photo_t["eye_height_m"], camera_height_sigma_m=0.01)
                    )
                    r = cal.result
                    auto_rows.append(
                        {"ok": True, "w_err": abs(r.width_m / w_true - 1), "h_err": abs(r.height_m / h_true - 1)}
                    )
                    fp_w.append(r.width_m)
                    fp_sw.append(r.sigma("width_m"))
                    fp_t.append((photo_t["heading_deg"], r.value("yaw_rad"), r.sigma("yaw_rad")))
                    fp_true.append((w_true, math.radians(wall_t["theta_deg"])))
                except CalibMasonryError as exc:
                    auto_rows.append({"ok": False, "message": str(exc)})
                    print(f"  auto failed: {exc}")
            if len(fp_w) == len(truth["walls"]):
                names = [w["name"] for w in truth["walls"]]
                turns, turn_err = [], []
                for c in truth["corner_photos"]:
                    r = calibrate_corner_photo(out / c["photo"])
                    turns.append((names.index(c["walls"][0]), names.index(c["walls"][1]), r.turn_rad, r.turn_sigma_rad))
                    turn_err.append(abs(math.degrees(r.turn_rad) - c["turn_deg"]))
                tw, tt = np.array(fp_true).T
                for hs in heading_sigmas:
                    # compass headings: the truth plus N(0, hs); theta = yaw - heading
                    noisy = [theta_from_heading(math.radians(h + rng.normal(0, hs)), yaw) for h, yaw, _ in fp_t]
                    th_sig = [math.hypot(math.radians(hs), sy) for _, _, sy in fp_t]
                    dtheta0 = np.degrees(np.abs(np.angle(np.exp(1j * (np.array(noisy) - tt)))))
                    for label, tr in ((f"heading +-{hs:g} deg only", []), (f"heading +-{hs:g} deg + corners", turns)):
                        fp = fit_footprint(fp_w, fp_sw, noisy, th_sig, turns=tr)
                        dtheta = np.degrees(np.abs(np.angle(np.exp(1j * (fp.theta_rad - tt)))))
                        footprints.append(
                            {
                                "seed": seed,
                                "label": label,
                                "gap_before_mm": fp.closure_gap_before_m * 1000,
                                "gap_mm": fp.closure_gap_m * 1000,
                                "max_dtheta_deg": float(dtheta.max()),
                                "max_dtheta_before_deg": float(dtheta0.max()),
                                "max_turn_err_deg": float(max(turn_err)) if tr else float("nan"),
                                "max_w_err": float(np.max(np.abs(fp.width_m / tw - 1))),
                            }
                        )

    def med(key, rs):
        return float(np.median([r[key] for r in rs]))

    n = len(rows)
    print(f"\nclicked corners (N(0, {noise_px} px)), camera height and focal known, {n} photos, seeds {list(seeds)}:")
    print(f"  {'method':<34} {'median W err':>12} {'median H err':>12} {'vertex RMS mm (median)':>23} {'(max)':>8}")
    print(f"  clicks snapped to the outline in {sum(r['snapped'] for r in rows)}/{n} photos")
    print(
        f"  {'ours: snapped corners + lines':<34} {med('w_err', rows):>12.3%} {med('h_err', rows):>12.3%} "
        f"{med('ours_mm', rows):>23.2f} {max(r['ours_mm'] for r in rows):>8.2f}"
    )
    print(
        f"  {'ours: raw clicks (no snap) + lines':<34} {med('raw_w_err', rows):>12.3%} {med('raw_h_err', rows):>12.3%} "
        f"{med('raw_mm', rows):>23.2f} {max(r['raw_mm'] for r in rows):>8.2f}"
    )
    print(
        f"  {'ours: snapped corners, no lines':<34} {'':>12} {'':>12} {med('corners_only_mm', rows):>23.2f} "
        f"{max(r['corners_only_mm'] for r in rows):>8.2f}"
    )
    print(
        f"  {'ours: raw clicks + lines, true W, H':<34} {'(given)':>12} {'(given)':>12} "
        f"{med('raw_known_mm', rows):>23.2f} {max(r['raw_known_mm'] for r in rows):>8.2f}"
    )
    print(
        f"  {'ours: raw clicks, no lines, true W,H':<34} {'(given)':>12} {'(given)':>12} "
        f"{med('raw_known_nolines_mm', rows):>23.2f} {max(r['raw_known_nolines_mm'] for r in rows):>8.2f}"
    )
    print(
        f"  {'kornia 4-point DLT, true W and H':<34} {'(given)':>12} {'(given)':>12} {med('dlt_mm', rows):>23.2f} "
        f"{max(r['dlt_mm'] for r in rows):>8.2f}"
    )
    all_ours = math.sqrt(np.mean([r["ours_mm"] ** 2 for r in rows]))
    all_dlt = math.sqrt(np.mean([r["dlt_mm"] ** 2 for r in rows]))
    print(
        f"  vertex RMS over all photos: ours {all_ours:.2f} mm, DLT {all_dlt:.2f} mm, ratio DLT / ours = "
        f"{all_dlt / all_ours:.2f}; photos where ours beats DLT: {sum(r['ours_mm'] < r['dlt_mm'] for r in rows)}/{n}"
    )
    rk = math.sqrt(np.mean([r["raw_known_mm"] ** 2 for r in rows]))
    rkn = math.sqrt(np.mean([r["raw_known_nolines_mm"] ** 2 for r in rows]))
    print(
        f"  same clicks and true W, H for all three: joint lines {rk:.2f} mm, corners only {rkn:.2f} mm, DLT "
        f"{all_dlt:.2f} mm; ratio DLT / (ours with joint lines) = {all_dlt / rk:.2f}"
    )
    ok = [r for r in auto_rows if r["ok"]]
    print(
        f"\nautomatic mode (no clicks), camera height known: {len(ok)}/{len(auto_rows)} succeed "
        f"({len(ok) / len(auto_rows):.0%}); median W err {med('w_err', ok):.3%}, median H err {med('h_err', ok):.3%}, "
        f"max W err {max(r['w_err'] for r in ok):.3%}, max H err {max(r['h_err'] for r in ok):.3%}"
    )
    print(
        f"\nfit time per photo after compilation (LM solve, 2 cores): median {np.median(fit_times) * 1000:.1f} ms, "
        f"max {np.max(fit_times) * 1000:.1f} ms; detection (outline + joints) median {np.median(detect_times):.2f} s"
    )
    if footprints:
        print(
            "\nfootprint (per-wall W from the automatic fits, theta from a compass heading with the stated noise plus "
            "the fitted yaw):"
        )
        for f in footprints:
            turn = (
                ""
                if math.isnan(f["max_turn_err_deg"])
                else f", max corner-photo turn error {f['max_turn_err_deg']:.3f} deg"
            )
            print(
                f"  seed {f['seed']} {f['label']:<32}: gap {f['gap_before_mm']:.1f} mm -> {f['gap_mm']:.2e} mm, "
                f"max |theta error| {f['max_dtheta_before_deg']:.3f} -> {f['max_dtheta_deg']:.3f} deg, "
                f"max W error {f['max_w_err']:.3%}{turn}"
            )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[101, 102, 103, 104, 105])
    ap.add_argument("--size", type=int, nargs=2, default=[3000, 2000])
    ap.add_argument("--noise-px", type=float, default=1.5)
    ap.add_argument("--heading-sigma", type=float, nargs="+", default=[0.25, 2.0])
    a = ap.parse_args()
    run(a.seeds, a.size, a.noise_px, a.heading_sigma)


if __name__ == "__main__":
    main()

"""``calib-masonry``: a thin command line over the library.

Every sub-command parses its flags into the library's dataclasses and calls one library function.
A user's mistake ends in one line ``error: ...`` and exit code 2, never a traceback.
"""

from __future__ import annotations

import argparse
import re
import signal
import sys
import time
import warnings
from pathlib import Path
from typing import NoReturn

from .errors import CalibMasonryError, InputError, Terminated
from .process import on_signal, print_warning, stop_requested

__all__ = ["main"]


def _cmd_synth(args) -> int:
    from .synthetic.truth import synth_to_folder

    spec, truth = synth_to_folder(
        args.scenario,
        args.out,
        figures=not args.no_figures,
        photos=args.photos,
        photo_size=args.photo_size,
        overwrite=args.overwrite,
    )
    print(
        f"synth: {spec.name}: {len(truth['walls'])} walls, {truth['bricks']} bricks, "
        f"{truth['end_faces']} corner end faces -> {args.out}"
    )
    return 0


def _cmd_trace(args) -> int:
    import contextlib

    refine, solver = None, contextlib.nullcontext()
    if args.refine:
        from .wall2d.refine import RefineConfig, solver_process

        refine = RefineConfig()
        solver = solver_process(refine, args.vertices)  # JAX loads there while this process traces
    with solver:
        from .wall2d.trace import TraceConfig, trace_to_file

        config = TraceConfig(vertices=args.vertices, target_dice=args.target_dice, refine=refine)
        result, seconds, _ = trace_to_file(args.mask, args.out, config, figure=args.figure, figures=not args.no_figures)
    out = Path(args.out)
    before = f"splitting {result.mean_dice_splitting:.4f} -> refined " if result.refined else ""
    print(
        f"trace: {len(result.bricks)} bricks, mean Dice {before}{result.mean_dice:.4f}, "
        f"mean vertices {sum(len(b.vertices_xy) for b in result.bricks) / len(result.bricks):.2f}, "
        f"{seconds:.2f} s -> {out}"
    )
    return 0


def _cmd_build(args) -> int:
    from dataclasses import replace

    from .build_folder import build_to_folder
    from .spec import load_structure

    spec = load_structure(args.structure)
    if args.refine:
        spec = replace(spec, refine=True, walls=tuple(replace(w, refine=True) for w in spec.walls))
    summary = build_to_folder(spec, args.out, figures=not args.no_figures, overwrite=args.overwrite, processes=True)
    _print_build(summary, args.out)
    return 0


#: a build whose worst pair of bricks shares this much of the smaller one's volume says so
OVERLAP_NOTE_SHARE = 0.1


def _print_build(summary: dict, out) -> None:
    print(
        f"build: {summary['structure']}: {summary['bricks']} bricks "
        f"({summary['corner_pieces_removed']} corner pieces removed), mean Dice {summary['mean_dice']:.4f}, "
        + (  # an open footprint's ends are apart by design: no closure to report
            f"closure error {summary['closure_error_m'] * 1000:.2f} mm, "
            if summary.get("closed_footprint", True)
            else "open footprint, "
        )
        + f"max interpenetration {summary['max_interpenetration_m3']:.2e} m^3 -> {out}"
    )
    for w in summary["walls"]:
        ref = f" (splitting {w['mean_dice_splitting']:.4f})" if "mean_dice_splitting" in w else ""
        if w["mean_dice"] is None:  # no brick (a traceback formatting None)
            what = "no bricks"
        elif "photo" in w:  # the Dice of a photo wall is against its own segmentation: say so
            what = f"polygon fit to the segmentation {w['mean_dice']:.4f}{ref}"
        else:
            what = f"mean Dice {w['mean_dice']:.4f}{ref}"
        print(f"  {w['name']:>10}: {w['bricks']:5d} bricks, {what}, {w['corner_pieces_removed']} corner pieces removed")
        if "pieces" in w:
            print(f"  {'':>10}  scale from the {w['scale_source']}; {_pieces_line(w['pieces'])}")
            if w.get("height_anchored"):
                print(f"  {'':>10}  {w['height_anchored']}")
    guessed = summary.get("corner_guesses") or []
    if guessed:
        n = sum(c["courses"] for c in guessed)
        where = ", ".join(f"{c['walls'][0]}/{c['walls'][1]} {c['courses']}" for c in guessed)
        print(
            f"  note: which wall runs through a corner was a guess in {n} course{'s' if n > 1 else ''} ({where}): "
            "the end face the other wall shows there is about as wide as the units (summary.json corner_guesses); "
            "the solids are nearly the same either way, but those bricks may be counted on the wrong wall: check "
            "the corners on walls.png"
        )
    share = summary.get("worst_pair_share")
    if share is not None and share >= OVERLAP_NOTE_SHARE:
        a, b = summary["worst_pair"]
        walls = " and ".join(dict.fromkeys(summary.get("worst_pair_walls") or []))
        print(
            f"  note: brick_{a:05d} and brick_{b:05d} (wall {walls}) overlap by {share:.0%} of the smaller "
            f"({summary['max_interpenetration_m3']:.2e} m^3): their traced outlines cross, as where a piece was "
            "traced across a joint; the model's solids overlap there (the simulation's bodies do not: each is its "
            "cell of the wall); check the wall's overlay, and for a photo wall fix its pieces in the LabelMe file "
            'beside its orthophoto and build from that (mask = "<file>.json")'
        )
    coverage = summary.get("joint_coverage") or {}
    over = coverage.get("units_over_opening") or []
    hanging = [name for name in coverage.get("units_without_bed_joint") or [] if name not in set(over)]
    from .spec import MAX_JOINT_M

    if hanging:
        from .build3d.assemble import reach_over

        n = len(hanging)
        reach = summary["max_joint_m"]  # build writes it since it became a setting
        width, bed = coverage.get("mortar_width_p95_m"), coverage.get("widest_bed_m")
        said = []
        if bed is not None:
            said.append(
                f"max_joint_m = {reach_over(bed):g} joins each of them to a unit beneath, their beds being at most "
                f"{bed * 100:.1f} cm wide"
            )
        if width is not None and width > reach:
            advice = bed is None and reach_over(width) <= MAX_JOINT_M
            said.append(
                f"95 % of the length of the masks' mortar joints is narrower than {width * 100:.1f} cm"
                + (f": max_joint_m = {reach_over(width):g} would reach across them" if advice else "")
            )
        measured = f" ({'; '.join(said)})" if said else ""
        print(
            f"  note: {n} unit{'s' if n > 1 else ''} above the lowest course {'have' if n > 1 else 'has'} no joint "
            f"beneath (a bed wider than max_joint_m = {reach:g} m) and "
            f"{'hang' if n > 1 else 'hangs'} from side joints: {_names(hanging)} "
            f"(summary.json joint_coverage); for wide mortar beds raise max_joint_m in [structure]{measured}, for "
            "units traced too small trace with more vertices"
        )
    if over:
        n = len(over)
        print(
            f"  note: {n} unit{'s' if n > 1 else ''} {'have' if n > 1 else 'has'} nothing beneath within "
            f"{MAX_JOINT_M:g} m (the widest joint a structure file allows): {'they span' if n > 1 else 'it spans'} "
            f"an opening (a window, a door, a void in the mask) and {'hang' if n > 1 else 'hangs'} from side "
            f"joints: {_names(over)} (summary.json joint_coverage units_over_opening); the model has no lintel "
            "or arch: the joints' tension holds them, dry or once cracked they fall. Draw a lintel as a unit in "
            "the mask where the wall has one"
        )


def _names(names: list[str], shown: int = 5) -> str:
    """The first ``shown`` of ``names``, comma-separated, with an ellipsis if there are more."""
    return ", ".join(names[:shown]) + (", ..." if len(names) > shown else "")


def _cmd_compare(args) -> int:
    from .comparison import compare_to_file

    metrics, out = compare_to_file(args.run_dir, args.truth_dir, args.out)
    _print_compare(metrics, out)
    return 0


def _print_compare(m: dict, out) -> None:
    print(
        f"compare: precision {m['precision']:.4f}, recall {m['recall']:.4f}, "
        f"Dice vs truth min {m['dice']['min']:.4f} / median {m['dice']['median']:.4f}, "
        f"centroid error mean {m['centroid_error_mm']['mean']:.2f} mm (max {m['centroid_error_mm']['max']:.2f}), "
        f"volume error {m['total_volume_m3']['relative_error']:+.2%}, "
        f"max interpenetration {m['max_interpenetration_m3']:.2e} m^3 -> {out}"
    )


def _cmd_study(args) -> int:
    from .study.design import load_study
    from .study.run import study_to_folder

    study = load_study(args.study_file)
    t0 = time.perf_counter()
    rows, summary, ran = study_to_folder(
        study,
        args.out,
        scheduler=args.scheduler,
        workers=args.workers,
        overwrite=args.overwrite,
        figures=not args.no_figures,
    )
    print(
        f"study: {study.name}: {summary['samples']} samples ({ran} run now, {summary['samples'] - ran} kept from "
        f"before), {summary['failed']} failed, {time.perf_counter() - t0:.1f} s -> {args.out}"
    )
    # the outputs that vary first (a geometry study's constant outputs said nothing), at most eight
    stats = [(k, st) for k, st in summary["outputs"].items() if st.get("n")]
    varying = [(k, st) for k, st in stats if st.get("std")]
    for key, st in varying[:8]:
        print(f"  {key:>28}: mean {st['mean']:.6g}, std {st['std']:.3g}, 5-95 % {st['p5']:.6g} .. {st['p95']:.6g}")
    rest = len(varying) - 8 if len(varying) > 8 else 0
    if rest or len(stats) > len(varying):
        print(
            f"  ({rest} more outputs vary and {len(stats) - len(varying)} are the same in every sample: "
            "see summary.json)"
        )
    frag = summary.get("fragility")
    if frag and frag.get("median_g"):
        print(f"  fragility: median {frag['median_g']:.3f} g, beta {frag['beta']:.3f}")
    if frag and frag.get("caveat"):
        print(f"  caveat: {frag['caveat']}")
    return 0


def find_demo_data(explicit: str | Path | None = None) -> Path:
    """The paper example's data folder: ``explicit``, else data_synthetic/paper_example under the
    working folder or the project."""
    candidates = (
        [Path(explicit)]
        if explicit
        else [
            Path.cwd() / "data_synthetic" / "paper_example",
            Path(__file__).resolve().parents[2] / "data_synthetic" / "paper_example",
        ]
    )
    for c in candidates:
        if (c / "structure.toml").is_file():
            return c
    raise InputError(
        "demo: data_synthetic/paper_example/structure.toml not found; run from the project folder "
        "or give --data DIR (re-create it with `calib-masonry synth data_synthetic/paper_example/scenario.toml "
        "--out data_synthetic/paper_example`)"
    )


def demo(out: str | Path, data: str | Path | None = None, *, overwrite: bool = False) -> tuple[dict, dict, dict, Path]:
    """``calib-masonry demo``: build the paper example from its masks into ``out``, compare it with
    its truth (compare.json) and check the build against what the method promises. Returns the
    build summary, the metrics, the checks (name -> passed) and the data folder."""
    from .build_folder import build_to_folder
    from .comparison import compare_dirs
    from .io import check_output, write_json
    from .spec import load_structure

    data = find_demo_data(data)
    check_output(out, command="build", overwrite=overwrite)
    summary = build_to_folder(
        load_structure(data / "structure.toml"), out, figures=True, overwrite=overwrite, processes=True
    )
    metrics = compare_dirs(out, data / "truth")
    write_json(Path(out) / "compare.json", metrics)
    checks = {
        "precision == 1": metrics["precision"] == 1.0,
        "recall == 1": metrics["recall"] == 1.0,
        "every brick's Dice vs truth >= 0.98": (metrics["dice"]["min"] or 0) >= 0.98,
        "closure error < 1 mm": summary["closure_error_m"] < 1e-3,
        "max interpenetration <= 1e-6 m^3": metrics["max_interpenetration_m3"] <= 1e-6,
    }
    return summary, metrics, checks, data


def _cmd_demo(args) -> int:
    t0 = time.perf_counter()
    summary, metrics, checks, data = demo(args.out, args.data, overwrite=args.overwrite)
    _print_build(summary, args.out)
    _print_compare(metrics, Path(args.out) / "compare.json")
    for name, ok in checks.items():
        print(f"  [{'ok' if ok else 'FAIL'}] {name}")
    print(
        f"demo: {time.perf_counter() - t0:.1f} s; model in {Path(args.out) / 'model.stl'}, "
        f"figures {Path(args.out) / 'walls.png'} and {Path(args.out) / 'model.png'}"
    )
    return 0 if all(checks.values()) else 1


def _calibrate_config(args):
    from .calibrate.rectify import CalibrateConfig, parse_corners, parse_numbers

    kwargs = {}
    if args.camera_height is not None:
        kwargs["camera_height_m"] = args.camera_height
    if args.camera_height_sigma is not None:
        kwargs["camera_height_sigma_m"] = args.camera_height_sigma
    if args.focal_px is not None:
        kwargs["focal_px"] = args.focal_px
    for flag, key in (("known_width", "known_width_m"), ("known_height", "known_height_m")):
        if getattr(args, flag, None) is not None:
            kwargs[key] = getattr(args, flag)
    if getattr(args, "known_length", None):
        kwargs["known_length"] = parse_numbers(
            args.known_length,
            "--known-length",
            5,
            "x1,y1,x2,y2,METRES: two photo points on the wall and their distance",
        )
    if getattr(args, "course_height", None):
        ch = parse_numbers(
            args.course_height, "--course-height", (1, 2), "M or M,SIGMA in metres (the mean course height)"
        )
        kwargs["course_height_m"] = ch[0]
        if len(ch) == 2:
            kwargs["course_height_sigma_m"] = ch[1]
    corners = getattr(args, "corners", None)
    occluders = ()
    if getattr(args, "labelme", None):
        from .labelme import read_photo_annotation

        ann = read_photo_annotation(args.labelme)
        if ann.outline is not None and not corners:
            kwargs["corners_px"] = tuple(float(v) for v in ann.outline.ravel())
        occluders = ann.not_masonry
        kwargs["annotation_size"] = (ann.shape[1], ann.shape[0])
    if corners:
        kwargs["corners_px"] = parse_corners(corners)
    if getattr(args, "occluders", None):
        from .labelme import annotation_size, read_occluders

        occluders = tuple(occluders) + tuple(read_occluders(args.occluders))
        size = annotation_size(args.occluders)
        if size is not None and kwargs.setdefault("annotation_size", size) != size:
            raise InputError(
                f"--occluders {args.occluders}: drawn on a {size[0]} x {size[1]} px image, --labelme on a "
                f"{kwargs['annotation_size'][0]} x {kwargs['annotation_size'][1]} px one; draw both on the photo"
            )
    if occluders:
        kwargs["occluders"] = tuple(occluders)
    if getattr(args, "snap_tolerance", None) is not None:
        kwargs["snap_tolerance_px"] = args.snap_tolerance
    if getattr(args, "no_distortion", False):
        kwargs["fit_distortion"] = False
    return CalibrateConfig(max_rms_px=args.max_rms, force=args.force, **kwargs)


def _cmd_rectify(args) -> int:
    from .calibrate.rectify import rectify_to_folder

    doc = rectify_to_folder(
        args.photo,
        args.out,
        _calibrate_config(args),
        px_per_m=args.px_per_m,
        mask_path=args.mask,
        figure=not args.no_figures,
        overwrite=args.overwrite,
    )
    cam = doc["camera"]
    snap = ""
    if doc.get("corner_snap_px"):
        snap = ", corners snapped by " + "/".join(f"{v:.1f}" for v in doc["corner_snap_px"]) + " px"
    print(
        f"rectify: {doc['mode']} corners{snap}, W = {doc['width_m']:.3f} +- {doc['width_sigma_m']:.3f} m, "
        f"H = {doc['height_m']:.3f} +- {doc['height_sigma_m']:.3f} m (scale from the {doc['scale_source']}: "
        f"{doc['scale_detail']}), f = {cam['focal_px']:.0f} px ({doc['focal_source']}), "
        f"lens k1 {doc['distortion']['k1']:+.3f}, yaw {cam['yaw_deg']:.1f} deg, RMS {doc['rms_residual_px']:.2f} px, "
        f"{doc['status']} -> {args.out}"
    )
    if "pieces" in doc:
        print(f"  {_pieces_line(doc['pieces'])}")
    if doc.get("joints_left_out"):
        print(
            f"note: the {doc['joints_left_out']} joint segments found do not fit one wall plane with the clicked "
            "corners (blur, grain or speckle taken for joints): left out, the wall rests on the corners"
        )
    if doc.get("advice"):
        print(f"note: {doc['advice']}")
    return 0


def _pieces_line(p: dict) -> str:
    return (
        f"segmentation: {p['count']} pieces, median {p['median_area_m2'] * 1e4:.0f} cm^2 "
        f"(largest {p['max_area_m2'] * 1e4:.0f} cm^2), module {p['module_m'][0] * 100:.1f} cm high x {p['module_m'][1] * 100:.1f} cm long"
        + (
            f"; {p['openings']} opening{'s' if p['openings'] > 1 else ''} left out ({p['openings_m2']:.2f} m^2: windows, "
            "doors; 'opening' polygons in its rectified.json)"
            if p.get("openings")
            else ""
        )
        + (f"; warning: {p['warning']}" if p.get("warning") else "")
    )


def _cmd_footprint(args) -> int:
    from .calibrate.footprint import footprint_to_folder

    doc = footprint_to_folder(
        args.inputs,
        args.out,
        config=_calibrate_config(args),
        heading_sigma_deg=args.heading_sigma,
        theta_sigma_deg=args.theta_sigma,
        figure=not args.no_figures,
        overwrite=args.overwrite,
    )
    gap = (
        f"gap {doc['closure_gap_before_m'] * 1000:.1f} mm before, {doc['closure_gap_m'] * 1000:.3g} mm after"
        if doc["closure_gap_m"] is not None
        else "open footprint (no closure)"
    )
    print(f"footprint: {len(doc['walls'])} walls, {gap} -> {args.out}")
    for w in doc["walls"]:
        print(
            f"  {w['name']:>10}: W = {w['width_m']:.3f} +- {w['width_sigma_m']:.3f} m, "
            f"theta = {w['theta_deg']:.2f} +- {w['theta_sigma_deg']:.2f} deg"
        )
    return 0


def _shear_drifts(st: dict) -> str:
    """The shear test's drifts for the printed line: at 95 % of the peak and at the peak itself,
    or how far up the curve the joint model's drift is known where its solves did not converge."""
    at95, at_peak = st["drift_at_95_percent_of_peak_percent"], st["drift_at_peak_percent"]
    if at95 is None:
        return (
            f"the drift near it not known: the joint model's drift is known up to {st['drift_known_to_kn']:.1f} kN "
            f"({st['drift_levels_converged']} of {st['drift_levels']} loads converged)"
        )
    return f"95 % of it at {at95:.2f} % drift; the joint model's drift at the peak itself " + (
        f"{at_peak:.2f} %, a mechanism forming" if at_peak is not None else "not known (its solve did not converge)"
    )


def _cmd_simulate(args) -> int:
    from dataclasses import replace

    from .simulation.run import SimulationConfig, simulate_to_folder
    from .simulation.scene import Pushover, ShearTest, SolverSettings

    if args.shear_test:
        given = [
            f
            for f, v in (
                ("--pushover", args.pushover),
                ("--accelerogram", args.accelerogram),
                ("--accelerogram-y", args.accelerogram_y),
                ("--pga", args.pga),
            )
            if v
        ]
        if given:
            raise InputError(
                f"--shear-test with {', '.join(given)}: the shear test pushes the wall's loading beam and applies no "
                f"other load; drop {', '.join(given)}"
            )
        if args.precompression_mpa is None:
            raise InputError("--shear-test: give --precompression-mpa S, the vertical stress on the wall (MPa)")
    elif args.precompression_mpa is not None or args.shear_span_ratio is not None:
        raise InputError("--precompression-mpa and --shear-span-ratio belong to --shear-test; add --shear-test")
    if args.pushover and (args.accelerogram or args.accelerogram_y or args.pga is not None):
        given = "--accelerogram" if args.accelerogram else "--accelerogram-y" if args.accelerogram_y else "--pga"
        raise InputError(
            f"--pushover with {given}: a pushover ramps its own lateral acceleration (--pushover-rate, "
            f"--pushover-max) and applies no ground motion; drop {given}, or drop --pushover for a quake"
        )
    d = SolverSettings()
    solver = replace(
        d,
        **{
            k: v
            for k, v in (
                ("fps", args.fps),
                ("substeps", args.substeps),
                ("iterations", args.iterations),
                ("damping_ratio", args.damping),
                ("check_interval_s", args.check_interval),
            )
            if v is not None
        },
        dynamics=not args.quasi_static,
        piece_joints=args.piece_joints,
        bullet_moves=args.bullet_moves,
    )
    material = None
    if args.material:
        from .simulation.scene import read_material

        material = read_material(args.material)
    config = SimulationConfig(
        material=material,
        pga_g=args.pga,
        duration_s=args.duration,
        seed=args.seed,
        accelerogram=Path(args.accelerogram) if args.accelerogram else None,
        accelerogram_y=Path(args.accelerogram_y) if args.accelerogram_y else None,
        record_units=args.units,
        record_dt_s=args.dt,
        components=args.components or SimulationConfig.components,
        direction_deg=0.0 if args.pushover else args.direction,
        solver=solver,
        frames_png=args.frames,
        gif_frames=args.gif_frames,
        figures=not args.no_figures,
        foundation=args.foundation,
        bullet=not args.no_bullet,
        pushover=Pushover(rate_g_per_s=args.pushover_rate, direction_deg=args.direction, max_g=args.pushover_max)
        if args.pushover
        else None,
        shear_test=ShearTest(
            precompression_pa=args.precompression_mpa * 1e6,
            boundary=args.boundary,
            shear_span_ratio=args.shear_span_ratio,
        )
        if args.shear_test
        else None,
    )
    s = simulate_to_folder(args.model_dir, args.out, config, overwrite=args.overwrite)
    if args.shear_test:
        st = s["shear_test"]
        peak = st["peak_lateral_force_kn"]
        print(
            f"shear test: {s['bricks'] - 1} stones, {st['boundary']}, {st['precompression_mpa']:g} MPa "
            f"({st['vertical_load_kn']:.1f} kN), H0/L = {st['shear_span_ratio']:.2f}: peak lateral force "
            + (
                f"{peak:.1f} kN ({_shear_drifts(st)}), {st['mechanism']}"
                if peak is not None
                else "not reached (the ramp ended first)"
            )
            + f" -> {args.out}"
        )
        return 0
    if args.pushover:
        value = s["collapse_multiplier_g"]
        print(
            f"pushover: {s['bricks']} bricks, {s['bonds']} bonds, along {args.direction:g} deg: collapse multiplier "
            + (f"{value:.3f} g" if value is not None else f"above {args.pushover_max:g} g (no collapse)")
            + f"; {s['bonds_broken_fraction']:.1%} of bonds broken; stepping {s['seconds']['stepping']:.1f} s -> {args.out}"
        )
        if "ran_away_first" in s["pushover"]:
            print(f"  note: {s['pushover']['note']}")
        return 0
    print(_quake_line(s, args.out))
    return 0


def _quake_line(s: dict, out) -> str:
    """simulate's last line under a ground motion, from its summary ``s``. The roof drift of the
    frames is the freed pieces' motion too (a top piece that rocks and comes back moves no brick by
    the end); the held structure's vibration, millimetres, is printed beside it."""
    vibration = (s.get("dynamics") or {}).get("max_roof_drift_m")
    return (
        f"simulate: {s['bricks']} bricks, {s['bonds']} bonds, {s['ground_motion']['source']}: {s['outcome']}; "
        + (f"{s['toppled_fraction']:.1%} of bricks toppled, " if s.get("toppled_fraction") is not None else "")
        + f"moved {s['moved_fraction_final']:.1%} of bricks at the end, {s['bonds_broken_fraction']:.1%} of bonds "
        "broken"
        + (
            f" and {s['bonds_unchecked'] / s['bonds']:.1%} not checked since their piece was set free (--piece-joints)"
            if s.get("bonds_unchecked") and s["bonds"]
            else ""
        )
        + f", max roof drift {s['max_roof_drift_m'] * 1000:.0f} mm"
        + (f" (the held structure's vibration {vibration * 1000:.1f} mm)" if vibration is not None else "")
        + f"; stepping {s['seconds']['stepping']:.1f} s -> {out}"
    )


def _cmd_modes(args) -> int:
    from .simulation.dynamics import FIGURE_MODES  # the modes printed in full, as modes.png draws them
    from .simulation.run import modes_to_folder

    material = None
    if args.material:
        from .simulation.scene import read_material

        material = read_material(args.material)
    doc = modes_to_folder(
        args.model_dir,
        args.out,
        n=args.n,
        material=material,
        mass_fraction=args.mass_fraction,
        figures=not args.no_figures,
        overwrite=args.overwrite,
    )
    print(
        f"modes: {doc['bodies_in_modes']} of {doc['bodies']} bodies held by joints, {doc['total_mass_kg']:.0f} kg, "
        f"height {doc['height_m']:.2f} m -> {args.out}"
    )
    rows = doc["modes"]
    for row in rows:
        f = row["effective_mass_fraction"]
        # past the lowest few, only the modes that carry more than 5 % of the mass along x or y
        # (those EN 1998-1 4.3.3.3.1 names); every one is in modes.json
        if row["mode"] <= FIGURE_MODES or max(f["x"], f["y"]) > 0.05:
            print(
                f"  mode {row['mode']}: T = {row['period_s']:.4f} s ({row['frequency_hz']:.2f} Hz), effective mass "
                f"x {f['x']:.1%}, y {f['y']:.1%}, z {f['z']:.1%}"
            )
    if len(rows) > FIGURE_MODES:
        print(f"  ({len(rows)} modes in modes.json; past mode {FIGURE_MODES} those above 5 % of the mass are shown)")
    c = doc["cumulative_effective_mass_fraction"]
    line = f"  the {len(rows)} modes carry x {c['x']:.1%}, y {c['y']:.1%}, z {c['z']:.1%} of the mass"
    asked = doc["mass_fraction_asked"]
    if asked is not None and not doc["mass_fraction_met"]:
        line += f"; {asked:.0%} along x and y not reached within {len(rows)} modes (the most a call computes)"
    elif asked is None and min(c["x"], c["y"]) < 0.9:
        line += " (EN 1998-1 4.3.3.3.1 takes the modes that carry 90 %: --mass-fraction 0.9)"
    print(line)
    fund = doc["fundamental_mode"]
    print(
        "  fundamental mode (the largest effective mass): "
        + "; ".join(
            f"{d} mode {f['mode']}, T = {f['period_s']:.4f} s ({f['effective_mass_fraction']:.1%})"
            for d, f in fund.items()
        )
    )
    emp = doc["empirical_first_period_of_masonry_towers"]
    print(
        "  empirical first period of masonry towers of this height: "
        + "; ".join(f"{e['formula']} = {e['period_s']:.3f} s ({e['source']})" for e in emp.values())
    )
    return 0


def _overwrite_flag(q) -> None:
    q.add_argument(
        "--overwrite",
        action="store_true",
        help="replace --out even if it is not an earlier output of this command (it is replaced as a whole)",
    )


class _Parser(argparse.ArgumentParser):
    """argparse with one-line errors (``error: ...``, exit 2, like every other mistake) and numbers
    such as ``-1e+16``, ``-inf`` or the list ``-12,40,...`` read as values rather than as unknown
    options."""

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        if hasattr(self, "_negative_number_matcher"):
            self._negative_number_matcher = _NEGATIVE_NUMBER

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"error: {self.prog}: {message}; see `{self.prog} --help`\n")


_NUMBER = r"(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?"
# a negative number, or a comma-separated list that starts with one (--corners -12,40,...)
_NEGATIVE_NUMBER = re.compile(rf"^-{_NUMBER}(\s*,\s*[-+]?{_NUMBER})*$|^-(inf|infinity|nan)$", re.IGNORECASE)


def _parser() -> argparse.ArgumentParser:
    p = _Parser(
        prog="calib-masonry",
        description="Photos of masonry walls -> calibrated 3D model of every brick -> earthquake simulation. "
        "Each command below has its own --help.",
    )
    p.add_argument(
        "--trust-large-images",
        action="store_true",
        help="read images above 179 megapixels (Pillow's decompression-bomb limit) for files you trust",
    )
    sub = p.add_subparsers(dest="command", required=True, parser_class=_Parser)

    s = sub.add_parser("synth", help="make masks and exact truth from a scenario TOML")
    s.add_argument("scenario")
    s.add_argument("--out", required=True)
    s.add_argument("--no-figures", action="store_true")
    s.add_argument("--photos", action="store_true", help="also take perspective photos (settings: [photos] table)")
    s.add_argument("--photo-size", type=int, nargs=2, default=None, metavar=("W", "H"), help="photo size in px")
    _overwrite_flag(s)
    s.set_defaults(func=_cmd_synth)

    def calib_flags(q, *, corners: bool) -> None:
        if corners:
            q.add_argument(
                "--corners",
                default=None,
                help="x1,y1,...,x4,y4: the wall's corners in pixels, any order (default: find them automatically)",
            )
        q.add_argument(
            "--camera-height",
            type=float,
            default=None,
            help="measured eye height above the wall's base in m (default: a prior of 1.6 +- 0.5 m, which "
            "alone never pins the scale)",
        )
        q.add_argument(
            "--camera-height-sigma", type=float, default=None, help="its uncertainty in m (default 0.02 if given)"
        )
        q.add_argument(
            "--focal-px",
            type=float,
            default=None,
            help="focal length in pixels (default: EXIF, else fitted from the vanishing points with a weak "
            "prior about a 35 mm equivalent, x/: 2.7)",
        )
        q.add_argument(
            "--max-rms",
            type=float,
            default=None,
            help="refuse a fit above this RMS residual in px (default 3 px per 1500 px of the photo's long side, "
            "at least 3)",
        )
        q.add_argument(
            "--force",
            action="store_true",
            help="keep a fit above --max-rms, not converged or with W or H +-25 %% or worse",
        )
        q.add_argument(
            "--occluders",
            default=None,
            help="a LabelMe JSON (shapes labelled 'occluder') or a JSON list of polygons [[x, y], ...] in photo "
            "pixels: a rig, a beam, scaffolding, vegetation or people to leave out",
        )
        q.add_argument("--no-distortion", action="store_true", help="hold the lens's k1, k2 at 0 (a pinhole)")
        q.add_argument("--no-figures", action="store_true")

    r = sub.add_parser("rectify", help="photo -> calibrated camera, wall size and metric orthophoto")
    r.add_argument("photo")
    calib_flags(r, corners=True)
    r.add_argument("--known-width", type=float, default=None, help="the wall's measured width in m")
    r.add_argument("--known-height", type=float, default=None, help="the wall's measured height in m")
    r.add_argument(
        "--known-length",
        default=None,
        metavar="X1,Y1,X2,Y2,M",
        help="two photo points on the wall (px) and their measured distance in m",
    )
    r.add_argument(
        "--course-height",
        default=None,
        metavar="M[,SIGMA]",
        help="the masonry's mean course height in m (sigma default 3 %%): the scale from the courses counted",
    )
    r.add_argument(
        "--labelme",
        default=None,
        help="a LabelMe JSON of the photo (as rectify writes it, corrected): its 'wall' polygon gives the corners, "
        "its 'occluder' shapes the occluders",
    )
    r.add_argument(
        "--snap-tolerance",
        type=float,
        default=None,
        help="how far (px) clicked corners may move onto the outline (default 1 %% of the photo's diagonal)",
    )
    r.add_argument("--px-per-m", type=float, default=None, help="orthophoto resolution (default: the photo's own)")
    r.add_argument("--mask", default=None, help="a brick mask of the photo to rectify along with it")
    r.add_argument("--out", required=True)
    _overwrite_flag(r)
    r.set_defaults(func=_cmd_rectify)

    f = sub.add_parser("footprint", help="close the footprint: adjust every wall's W and theta jointly")
    f.add_argument(
        "inputs", nargs="+", help="a structure TOML naming photos, or calibration.json files in footprint order"
    )
    calib_flags(f, corners=False)
    f.add_argument("--heading-sigma", type=float, default=2.0, help="compass heading uncertainty in deg (default 2)")
    f.add_argument("--theta-sigma", type=float, default=1.0, help="uncertainty of typed theta_deg values in deg")
    f.add_argument("--out", required=True)
    _overwrite_flag(f)
    f.set_defaults(func=_cmd_footprint)

    t = sub.add_parser("trace", help="mask -> brick polygons with Dice (polygons.json)")
    t.add_argument("mask")
    t.add_argument("--vertices", type=int, default=None, help="vertices per brick (default 5)")
    t.add_argument("--target-dice", type=float, default=None, help="fewest vertices reaching this Dice instead")
    t.add_argument("--refine", action="store_true", help="refine the vertices by soft Dice after splitting")
    t.add_argument("--out", default="polygons.json")
    t.add_argument("--figure", default=None, help="overlay PNG (default: beside --out)")
    t.add_argument("--no-figures", action="store_true")
    t.set_defaults(func=_cmd_trace)

    b = sub.add_parser("build", help="structure TOML with masks or photos -> 3D brick model")
    b.add_argument("structure")
    b.add_argument("--out", default="out/build")
    b.add_argument("--no-figures", action="store_true")
    b.add_argument("--refine", action="store_true", help="soft-Dice refinement for every wall (as refine = true)")
    _overwrite_flag(b)
    b.set_defaults(func=_cmd_build)

    c = sub.add_parser("compare", help="metrics of a build against synthetic truth")
    c.add_argument("run_dir")
    c.add_argument("truth_dir")
    c.add_argument("--out", default=None, help="metrics JSON (default RUN_DIR/compare.json)")
    c.set_defaults(func=_cmd_compare)

    m = sub.add_parser("simulate", help="Bullet (bpy) earthquake simulation of a built model")
    m.add_argument("model_dir", help="a folder `calib-masonry build` wrote (bricks.json, sim_geometry.npz)")
    m.add_argument(
        "--pga",
        type=float,
        default=None,
        help="peak ground acceleration in g: of the synthetic motion (default 0.3), or the peak an "
        "--accelerogram is scaled to (default: the record as recorded)",
    )
    m.add_argument("--duration", type=float, default=10.0, help="seconds of ground motion (default 10)")
    m.add_argument("--seed", type=int, default=0, help="the synthetic motion's random seed (default 0)")
    m.add_argument(
        "--components",
        type=int,
        default=None,
        choices=(1, 2),
        help="horizontal components of the synthetic motion (default 2, as in a real earthquake; "
        "1 shakes along X only and spares the walls parallel to it)",
    )
    m.add_argument(
        "--accelerogram",
        default=None,
        help="a recorded motion instead of the synthetic one: CSV of time, acceleration[, acceleration_y], "
        "a PEER NGA .AT2 or an ESM / ITACA ASCII file",
    )
    m.add_argument(
        "--accelerogram-y",
        default=None,
        help="the record's other horizontal component, along Y, where it comes as a file of its own (PEER "
        "and ESM give one file a component); --accelerogram's then shakes along X",
    )
    m.add_argument(
        "--units",
        default=None,
        choices=("g", "m/s2", "cm/s2"),
        help="of a CSV --accelerogram (default g; cm/s2 is gal; .AT2 and ESM name theirs)",
    )
    m.add_argument(
        "--dt",
        type=float,
        default=None,
        metavar="SECONDS",
        help="the time step of an --accelerogram of accelerations alone (one column, or several values a line "
        "in reading order); a file with a time column, .AT2 and ESM give theirs",
    )
    m.add_argument("--fps", type=int, default=None, help="frames per second (default: the tested settings, 25)")
    m.add_argument("--substeps", type=int, default=None, help="Bullet substeps per frame (default 10)")
    m.add_argument("--iterations", type=int, default=None, help="solver iterations per substep (default 150)")
    m.add_argument(
        "--damping",
        type=float,
        default=None,
        help="the structure's viscous damping as a ratio of critical, Rayleigh at its first two modes (default 0.05)",
    )
    m.add_argument(
        "--check-interval",
        type=float,
        default=None,
        help="under a ground motion, seconds between the joint model's checks of the joints, the same at every "
        "frame rate (default 0.005: every sample of a 200 Hz record)",
    )
    m.add_argument(
        "--piece-joints",
        action="store_true",
        help="under a ground motion, also check the joints inside the pieces the joint model sets free, against "
        "the forces that keep each piece rigid (the joints vibrating between checks with the structure's damping; "
        "statically with --quasi-static), and split a piece where they let go (off by default: slower, "
        "and the README's tables are without it)",
    )
    m.add_argument(
        "--bullet-moves",
        choices=("fallen", "freed"),
        default="fallen",
        help="under a ground motion, what Bullet moves: 'fallen' (default) plays the verdict's rigid pieces on "
        "kinematic bricks and takes over a piece once it has fallen (its fall onto the ground and the debris); "
        "'freed' sets every piece the joints let go dynamic in Bullet on its joints (slower; its motion is "
        "Bullet's solve, not the verdict's)",
    )
    m.add_argument(
        "--quasi-static",
        action="store_true",
        help="under a ground motion, hold the intact structure rigid (its joints' forces quasi-static) instead of "
        "letting it vibrate elastically",
    )
    m.add_argument(
        "--pushover",
        action="store_true",
        help="quasi-static collapse analysis: ramp a uniform lateral acceleration until the structure "
        "runs away; writes collapse_multiplier_g and pushover.png",
    )
    m.add_argument(
        "--direction",
        type=float,
        default=0.0,
        help="degrees from global X (default 0) of a pushover, or of a one-component ground motion (a record "
        "of one component, or the synthetic one with --components 1)",
    )
    m.add_argument(
        "--shear-test",
        action="store_true",
        help="the laboratory shear-compression test: a rigid beam on the wall's top carries --precompression-mpa "
        "and is pushed along the wall by a slow force ramp; writes force_drift.csv/png, the peak lateral force (kN), "
        "the drift at the peak and the mechanism (a single wall's model)",
    )
    m.add_argument(
        "--precompression-mpa", type=float, default=None, help="shear test: vertical stress on the wall's section, MPa"
    )
    m.add_argument(
        "--boundary",
        choices=["cantilever", "double-fixed"],
        default="cantilever",
        help="shear test: the beam's rotation free (cantilever, default) or held (double-fixed)",
    )
    m.add_argument(
        "--shear-span-ratio",
        type=float,
        default=None,
        help="shear test, cantilever: H0/L, the lateral load's height over the wall's length (default: the wall's "
        "height plus 0.1 m)",
    )
    m.add_argument(
        "--material",
        default=None,
        metavar="FILE.toml",
        help="the masonry's material: a TOML file with a [material] table (density_kg_m3, friction, "
        "tensile_strength_mpa, cohesion_mpa, ...; see the README). Default: the model's material.toml (its "
        "structure file's [material]), else the built-in mortar",
    )
    m.add_argument("--pushover-rate", type=float, default=0.01, help="pushover ramp in g per second (default 0.01)")
    m.add_argument(
        "--pushover-max",
        type=float,
        default=5.0,
        help="pushover's largest lateral acceleration in g (default 5: walls with mortar need 3-4.5 g; the run "
        "ends once the structure runs away, and summary.json says when the ramp reached this without a collapse)",
    )
    m.add_argument("--frames", type=int, default=6, help="collapse frames to render as PNG (default 6)")
    m.add_argument("--gif-frames", type=int, default=24, help="views in collapse.gif, played in real time (0: none)")
    m.add_argument(
        "--foundation",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="bond the bottom course to the ground, a footing (default; --no-foundation: friction only)",
    )
    m.add_argument(
        "--no-bullet",
        action="store_true",
        help="a ground motion without Blender's Bullet: the same verdict, cracks and releases, the frames showing "
        "the verdict's rigid pieces (scene.blend keyed from them); faster once a tower is set free",
    )
    m.add_argument("--no-figures", action="store_true")
    m.add_argument("--out", default="out/simulate", help="the folder to write (default out/simulate)")
    _overwrite_flag(m)
    m.set_defaults(func=_cmd_simulate)

    st = sub.add_parser(
        "study",
        help="an uncertainty, sensitivity, fragility or truth-sweep study on Dask (resumes where it stopped)",
    )
    st.add_argument("study_file", help="a study .toml (see data_synthetic/studies/)")
    st.add_argument("--out", default="out/study")
    st.add_argument(
        "--scheduler", default=None, help="a running Dask scheduler, tcp://HOST:PORT (default: a local cluster)"
    )
    st.add_argument(
        "--workers",
        type=int,
        default=None,
        help="worker processes of the local cluster (default: one per core; 0: run in this process)",
    )
    st.add_argument("--no-figures", action="store_true")
    _overwrite_flag(st)
    st.set_defaults(func=_cmd_study)

    mo = sub.add_parser("modes", help="natural periods, effective modal masses and mode shapes of a built model")
    mo.add_argument("model_dir", help="a folder `calib-masonry build` wrote")
    mo.add_argument("--n", type=int, default=6, help="how many of the lowest modes (at most 500)")
    mo.add_argument(
        "--mass-fraction",
        type=float,
        default=None,
        help="also as many more as carry this share of the mass along x and along y (EN 1998-1 4.3.3.3.1: 0.9)",
    )
    mo.add_argument("--out", required=True)
    mo.add_argument("--material", default=None, help="a TOML [material] table (as structure.toml's) for this run")
    mo.add_argument("--no-figures", action="store_true")
    _overwrite_flag(mo)
    mo.set_defaults(func=_cmd_modes)

    d = sub.add_parser("demo", help="build the paper example from its masks and compare with its truth")
    d.add_argument("--out", default="out/demo")
    d.add_argument(
        "--data", default=None, help="folder with structure.toml and truth/ (default data_synthetic/paper_example)"
    )
    _overwrite_flag(d)
    d.set_defaults(func=_cmd_demo)
    _fill_help(sub)
    return p


#: help for the arguments many commands share, where a command gives none of its own
_COMMON_HELP = {
    "out": "the folder to write (replaced as a whole; see --overwrite)",
    "no_figures": "write no PNG figures (faster)",
    "scenario": "a scenario TOML (as data_synthetic/*/scenario.toml)",
    "photo": "the wall's photo (JPEG, PNG, TIFF or a phone's HEIC)",
    "mask": "a brick mask (PNG, bricks white on black) or a LabelMe JSON",
    "structure": "a structure TOML (see the README's 'Structure files')",
    "run_dir": "a folder `calib-masonry build` wrote",
    "truth_dir": "a truth folder `calib-masonry synth` wrote (truth.json, bricks.json)",
}


def _fill_help(sub) -> None:
    """Every argument of every command with a help line (trace's --out is a file) that shows its
    default."""
    for name, parser in sub.choices.items():
        for action in parser._actions:
            if action.help is None and action.dest in _COMMON_HELP:
                action.help = _COMMON_HELP[action.dest]
                if name == "trace" and action.dest == "out":
                    action.help = "the polygons JSON to write (its figure beside it, .png)"
            shown = action.default not in (None, False, True, argparse.SUPPRESS)
            if shown and action.help and "default" not in action.help:
                action.help += f" (default {action.default})"


def _tune_malloc(keep_freed: bool = False) -> None:
    """Keep glibc's heaps few: a build from photos works on two threads, and glibc gave each its
    own heap (arena), which kept the photo stage's freed arrays after it ended, where the main
    thread's later stages could not reuse them. One heap for all threads: the paper example from
    its six photos peaked at 0.89-0.91 GB and took 25.7-26.5 s (four runs) against 1.27-1.35 GB
    and 27.2 s with glibc's defaults, and 0.89-0.97 GB in 26.9-28.9 s with the two heaps and 16 MB
    mmap threshold used before (every freed array of 16 MB or more was unmapped, and the next one
    page-faulted in afresh: 6-7 s of system time against 4).

    ``keep_freed`` (``synth --photos``, which renders one 6 MP photo after another on two threads,
    each through the same sizes of float arrays): freed arrays of any size stay in the heap for
    the next photo instead of going back to the kernel: 26.3-28.0 s and 1.9-2.0 GB against
    28.8-32.9 s and 1.7-2.0 GB (system time 3 s against 8-11 s). Settings the user made in the
    environment are left alone; other C libraries are left as they are."""
    import os
    import platform

    if platform.system() != "Linux" or platform.libc_ver()[0] != "glibc":
        return
    if any(k in os.environ for k in ("MALLOC_ARENA_MAX", "MALLOC_MMAP_THRESHOLD_", "GLIBC_TUNABLES")):
        return
    import ctypes

    try:
        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError):  # pragma: no cover - a glibc without mallopt
        return
    m_trim_threshold, m_mmap_threshold, m_arena_max = -1, -3, -8  # from glibc's malloc.h
    mallopt(m_arena_max, 1)
    if keep_freed:
        mallopt(m_mmap_threshold, 1 << 30)
        mallopt(m_trim_threshold, 1 << 30)


def _one_blas_thread(args) -> None:
    """One OpenBLAS thread for the commands whose work is image processing on threads of their
    own (build, rectify, synth, ...): numpy's and scipy's BLAS do only small products there, and
    their idle pool threads spin beside ours. The paper example's six photos, two at a time:
    photo stage 10.1-10.9 s with 2.8-3.0 s of system time, 9.8 s and 1.3 s with one BLAS thread
    (measured). Only in a process that has not loaded numpy yet (the command line, not a caller
    of ``main``), never for ``simulate`` or ``study``, and never over the user's own setting."""
    import os

    if args.func in (_cmd_simulate, _cmd_study) or "numpy" in sys.modules:
        return
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")


def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    _tune_malloc(keep_freed=args.func is _cmd_synth and bool(getattr(args, "photos", False)))
    _one_blas_thread(args)
    warnings.showwarning = print_warning
    if args.trust_large_images:
        from .io import trust_large_images

        trust_large_images()
    # `kill`, `timeout` and schedulers send SIGTERM; both signals may be held back (process.signals_deferred)
    previous = {sig: signal.signal(sig, on_signal) for sig in (signal.SIGTERM, signal.SIGINT)}
    try:
        code = int(args.func(args) or 0)
        sys.stdout.flush()  # here, not at the interpreter's exit, where a closed pipe has no handler
        return code
    except BrokenPipeError:
        # the reader of the output went away (`| head -1`): what the command wrote stands; no
        # traceback, and nothing more written to the closed pipe when the interpreter exits
        import os

        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 1
    except CalibMasonryError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt as exc:
        what = "terminated" if isinstance(exc, Terminated) else "interrupted"
        written = getattr(exc, "written", None)
        if written:  # what was complete when the signal came (a final rename, a study's samples)
            print(f"error: {what}; {written}", file=sys.stderr)
        else:
            print(f"error: {what}; nothing was written", file=sys.stderr)
        return 2
    finally:
        for sig, handler in previous.items():
            # once stopping, a second SIGTERM (``timeout`` signals the command, then its process
            # group) is ignored: with the default restored here, or by the interpreter's
            # finalisation (which resets a Python handler, not SIG_IGN), it killed the command with
            # -15 after its one line
            signal.signal(sig, signal.SIG_IGN if sig == signal.SIGTERM and stop_requested() else handler)
        from .preload import wait_for_background

        wait_for_background()


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())

"""Comparison of a built model with synthetic truth.

Bricks are matched wall by wall on their outer-face polygons in wall metres: a built brick and a
true brick match when their IoU exceeds 0.5 (one-to-one, best IoU first). Precision is matched /
built, recall is matched / true (corner end faces are not bricks of the wall they appear on and
are left out of the truth). For matched pairs: Dice of the polygons, and the distance between the
3D centroids of the solids in mm.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import shapely

from .build3d.assemble import Structure3D
from .build3d.contacts import max_interpenetration
from .errors import InputError
from .io import read_json

__all__ = ["compare", "compare_dirs", "compare_to_file", "match_polygons", "IOU_MATCH"]

IOU_MATCH = 0.5


def match_polygons(
    built: list[np.ndarray], truth: list[np.ndarray], threshold: float = IOU_MATCH
) -> list[tuple[int, int, float, float]]:
    """One-to-one matches ``(built index, truth index, IoU, Dice)`` with IoU > ``threshold``."""
    gb = [shapely.Polygon(p) for p in built]
    gt = [shapely.Polygon(p) for p in truth]
    gb = [g if g.is_valid else shapely.make_valid(g) for g in gb]
    gt = [g if g.is_valid else shapely.make_valid(g) for g in gt]
    if not gb or not gt:
        return []
    tree = shapely.STRtree(gt)
    left, right = tree.query(gb, predicate="intersects")
    cands = []
    for i, j in zip(left.tolist(), right.tolist()):
        inter = gb[i].intersection(gt[j]).area
        union = gb[i].area + gt[j].area - inter
        iou = inter / union if union > 0 else 0.0
        if iou > threshold:
            cands.append((iou, i, j, 2 * inter / (gb[i].area + gt[j].area)))
    cands.sort(key=lambda c: (-c[0], c[1], c[2]))
    used_b, used_t, out = set(), set(), []
    for iou, i, j, dice in cands:
        if i in used_b or j in used_t:
            continue
        used_b.add(i)
        used_t.add(j)
        out.append((i, j, iou, dice))
    return out


def _stats(values: list[float]) -> dict:
    if not values:
        return {"mean": None, "median": None, "min": None, "max": None}
    v = np.asarray(values)
    return {"mean": float(v.mean()), "median": float(np.median(v)), "min": float(v.min()), "max": float(v.max())}


def _angle_diff_deg(a: float, b: float) -> float:
    return (a - b + 180.0) % 360.0 - 180.0


def compare_dirs(run_dir: str | Path, truth_dir: str | Path) -> dict:
    """Metrics of the build in ``run_dir`` against the synthetic truth in ``truth_dir`` (see :func:`compare`)."""
    from .build_folder import read_build

    run_dir, truth_dir = Path(run_dir), Path(truth_dir)
    if not run_dir.is_dir():
        raise InputError(f"RUN_DIR {run_dir}: not a folder; give the --out folder of `calib-masonry build`")
    if not truth_dir.is_dir():
        raise InputError(
            f"TRUTH_DIR {truth_dir}: not a folder; give the truth/ folder written by `calib-masonry synth`"
        )
    if not (truth_dir / "bricks.json").is_file():
        raise InputError(
            f"TRUTH_DIR {truth_dir}: has no bricks.json; give the truth/ folder written by `calib-masonry synth`"
        )
    truth_meta = read_json(truth_dir / "truth.json", field="TRUTH_DIR truth.json")
    metrics = compare(read_build(run_dir), read_build(truth_dir), where=f"RUN_DIR {run_dir}")
    return {
        "run": run_dir.as_posix(),
        "truth": truth_dir.as_posix(),
        **metrics,
        "structure": truth_meta.get("name", metrics["structure"]),
    }


def compare(model: Structure3D, truth: Structure3D, *, where: str = "model") -> dict:
    """Metrics of a built model against the synthetic truth, in memory: brick matching (IoU >=
    :data:`IOU_MATCH`), precision and recall, Dice and centroid errors of the matched bricks, the
    walls' W, H and theta errors, the volume error and the largest interpenetration."""
    built, true = list(model.bricks), list(truth.bricks)
    run_walls = {w.name: (i, w) for i, w in enumerate(model.footprint.walls)}
    truth_walls = {w.name: (i, w) for i, w in enumerate(truth.footprint.walls)}
    missing = sorted(set(truth_walls) - set(run_walls))
    if missing:
        raise InputError(
            f"{where}: walls {missing} of the truth are not in the model; "
            "build the structure file that synth wrote beside the truth"
        )

    per_wall, all_dice, all_centroid = [], [], []
    total_matched = total_built = total_true = 0
    for name, (ti, tw) in truth_walls.items():
        ri, rw = run_walls[name]
        b_list = [b for b in built if b.wall == ri]
        t_list = [b for b in true if b.wall == ti]
        matches = match_polygons([b.polygon_m for b in b_list], [b.polygon_m for b in t_list])
        dice = [m[3] for m in matches]
        cen = [
            1000.0 * float(np.linalg.norm(b_list[i].solid.centroid - t_list[j].solid.centroid))
            for i, j, _, _ in matches
        ]
        all_dice += dice
        all_centroid += cen
        total_matched += len(matches)
        total_built += len(b_list)
        total_true += len(t_list)
        per_wall.append(
            {
                "wall": name,
                "built": len(b_list),
                "true": len(t_list),
                "matched": len(matches),
                "precision": len(matches) / len(b_list) if b_list else 0.0,
                "recall": len(matches) / len(t_list) if t_list else 0.0,
                "dice": _stats(dice),
                "centroid_error_mm": _stats(cen),
                "width_error_m": rw.width_m - tw.width_m,
                "height_error_m": rw.height_m - tw.height_m,
                "theta_error_deg": _angle_diff_deg(rw.theta_deg, tw.theta_deg),
            }
        )
    inter = max_interpenetration(built)
    vol_b = float(sum(b.volume for b in built))
    vol_t = float(sum(b.volume for b in true))
    return {
        "structure": truth.name,
        "precision": total_matched / total_built if total_built else 0.0,
        "recall": total_matched / total_true if total_true else 0.0,
        "built_bricks": total_built,
        "true_bricks": total_true,
        "matched": total_matched,
        "dice": _stats(all_dice),
        "dice_below_0.98": int(sum(d < 0.98 for d in all_dice)),
        "centroid_error_mm": _stats(all_centroid),
        "max_abs_width_error_m": max(abs(w["width_error_m"]) for w in per_wall),
        "max_abs_height_error_m": max(abs(w["height_error_m"]) for w in per_wall),
        "max_abs_theta_error_deg": max(abs(w["theta_error_deg"]) for w in per_wall),
        "total_volume_m3": {
            "built": vol_b,
            "true": vol_t,
            "error": vol_b - vol_t,
            "relative_error": (vol_b - vol_t) / vol_t if vol_t else math.nan,
        },
        "max_interpenetration_m3": inter.max_volume_m3,
        "worst_pair": inter.pair,
        "walls": per_wall,
    }


def compare_to_file(run_dir: str | Path, truth_dir: str | Path, out: str | Path | None = None) -> tuple[dict, Path]:
    """``calib-masonry compare``: :func:`compare_dirs` written to ``out`` (default RUN_DIR/compare.json)."""
    from .io import check_not_input, check_output, staged_file, write_json

    out = check_output(Path(out) if out else Path(run_dir) / "compare.json", folder=False)
    # every file of the truth is an input; of the run's folder, everything but an earlier compare.json
    check_not_input(out, [truth_dir])
    if Path(out).resolve() != (Path(run_dir) / "compare.json").resolve():
        check_not_input(out, [run_dir])
    metrics = compare_dirs(run_dir, truth_dir)
    with staged_file(out) as tmp:
        write_json(tmp, metrics)
    return metrics, out

"""The build folder: the one owner of its format. ``calib-masonry build`` writes it
(:func:`write_build`: model.stl, model.glb, model.blend, bricks.json, summary.json, material.toml,
figures, the photo walls' files and the simulation geometry's cache, sim_geometry.npz); every
later stage reads it back from here (:func:`read_build`, :func:`load_model`,
:func:`geometry_for_model`). The stages themselves (:mod:`calib_masonry.pipeline`,
:mod:`calib_masonry.simulation`) work on objects and write no file.
"""

from __future__ import annotations

import contextlib
import math
import time
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ._threads import background, background_process
from .build3d.assemble import Structure3D, joint_width
from .build3d.contacts import max_interpenetration, narrowest_beds
from .build3d.export import bricks_from_json, bricks_json_bytes, export_mesh, plot_model, plot_walls, write_bricks_json
from .build3d.place import Footprint, WallGeometry, closure_gap, corners, footprint_is_closed, wall_frames
from .build3d.scale import wall_from_image
from .errors import InputError
from .io import check_output, read_json, staged_output, write_json, write_mask, write_rgb
from .labelme import write_labelme_pair
from .simulation.scene import MAX_GAP_M, SceneGeometry, scene_geometry

if TYPE_CHECKING:  # the stages in memory, read only for their types: reading a model loads none of them
    from .pipeline import BuildResult, PhotoWall
    from .spec import StructureSpec
    from .wall2d.trace import TraceResult

__all__ = [
    "GEOMETRY_FILE",
    "GEOMETRY_FORMAT",
    "MATERIAL_FILE",
    "build_to_folder",
    "checked_model_dir",
    "geometry_for_model",
    "load_model",
    "model_from_json",
    "read_build",
    "read_model_json",
    "simulation_geometry",
    "store_geometry",
    "write_build",
]


MATERIAL_FILE = "material.toml"  # a model's [material] (from its structure file), read by `simulate`


def _worst_pair(structure, spec, interpenetration) -> dict:
    """The worst pair's share (its shared volume over the smaller brick's) and walls (None without
    a pair)."""
    pair = [b for i in interpenetration.pair or () for b in structure.bricks if b.id == i]
    if not pair:
        return {"worst_pair_share": None, "worst_pair_walls": None}
    smaller = min(b.volume for b in pair)
    return {
        "worst_pair_share": float(interpenetration.max_volume_m3 / smaller) if smaller > 0 else None,
        "worst_pair_walls": [spec.walls[b.wall].name for b in pair],
    }


def _summary(result: BuildResult, interpenetration) -> dict:
    from .pipeline import anchored_note

    s = result.structure
    spec = result.spec
    walls = []
    for w, (wall, tr) in enumerate(zip(spec.walls, result.traces)):
        own = s.bricks_of(w)
        kept = {x.label for x in own}
        walls.append(
            {
                "name": wall.name,
                "width_m": wall.width_m,
                "height_m": wall.height_m,
                "theta_deg": wall.theta_deg,
                "thickness_m": wall.thickness_m,
                "mask": wall.mask,
                "image_shape": list(tr.image_shape),
                "vertices": wall.vertices,
                "target_dice": wall.target_dice,
                "traced_pieces": len(tr.bricks),
                "bricks": len(own),
                "corner_pieces_removed": len(s.removed[w]),
                "mean_dice": float(np.mean([b.dice for b in own])) if own else None,
                "mean_dice_all_pieces": tr.mean_dice,
                "refine": wall.refine,
                **(
                    {
                        "photo": str(wall.image),
                        "calibration": f"photos/{wall.name}/calibration.json",
                        "fitted_width_m": result.photos[wall.name].calibration.result.width_m,
                        "fitted_height_m": result.photos[wall.name].calibration.result.height_m,
                        "scale_source": result.photos[wall.name].calibration.scale_source,
                        "height_anchored": anchored_note(result.photos[wall.name]),
                        "pieces": result.photos[wall.name].segmentation,
                        "dice_against": "the wall's own segmented mask: how well the polygons fit it, not how "
                        "well the segmentation follows the stones",
                    }
                    if wall.name in result.photos
                    else {}
                ),
                **(
                    {
                        "mean_dice_splitting": float(np.mean([b.dice_splitting for b in tr.bricks if b.id in kept])),
                        "bricks_refined": int(sum(b.refined for b in tr.bricks)),
                    }
                    if tr.refined
                    else {}
                ),
                "mean_vertices": float(np.mean([len(b.polygon_m) for b in own])) if own else None,
            }
        )
    return {
        "structure": spec.name,
        "walls": walls,
        "bricks": len(s.bricks),
        "corner_pieces_removed": int(sum(len(r) for r in s.removed)),
        "mean_dice": float(np.mean([b.dice for b in s.bricks])),
        "total_volume_m3": float(sum(b.volume for b in s.bricks)),
        "closed_footprint": footprint_is_closed(spec),
        "max_joint_m": joint_width(s),
        "closure_error_m": s.closure_error_m,
        "closure_gap_xy_m": s.closure_gap_xy.tolist(),
        "max_interpenetration_m3": interpenetration.max_volume_m3,
        "worst_pair": interpenetration.pair,
        "corner_guesses": [
            {"walls": [spec.walls[c.a].name, spec.walls[c.b].name], "courses": n}
            for c, n in zip(s.corners, s.corner_guesses)
            if n
        ],
        **_worst_pair(s, spec, interpenetration),
        "seconds": {k: round(v, 4) for k, v in result.seconds.items()},
    }


def _write_photo_walls(
    photos: dict[str, PhotoWall], folder: Path, *, figures: bool, traces: dict[str, TraceResult] | None = None
) -> None:
    """Each photo wall's calibration, orthophoto, mask, LabelMe files and overlay figure in
    ``folder/<name>``. The PNGs are encoded on a second thread while this one draws the figures
    (Pillow encodes without the GIL): 3.1 -> 1.85 s for the paper example's six walls."""
    from .calibrate.figures import plot_calibration
    from .pipeline import anchored_note

    def images() -> None:
        for name, pw in photos.items():
            write_rgb(folder / name / "rectified.png", pw.rectified)
            write_mask(folder / name / "mask.png", pw.mask)

    for name, pw in photos.items():
        (folder / name).mkdir(parents=True)
        doc = pw.calibration.to_json()
        doc.update(
            used_width_m=pw.wall.width_m,
            used_height_m=pw.wall.height_m,
            height_anchored=anchored_note(pw),
            rectified_shape=list(pw.mask.shape),
        )
        if pw.segmentation:
            doc["pieces"] = pw.segmentation
        write_json(folder / name / "calibration.json", doc)
        trace = (traces or {}).get(name) or pw.trace
        write_labelme_pair(
            folder / name,
            pw.calibration,
            pw.mask.shape,
            pieces=[b.vertices_xy for b in trace.bricks] if trace is not None else [],
            occluders_ortho=pw.occluders_ortho,
            openings_ortho=pw.openings_ortho,
            photo_size=pw.photo_size,
        )
    with background(images) as job:  # waited for however the figures end
        if figures:
            for name, pw in photos.items():
                plot_calibration(
                    pw.calibration,
                    pw.rectified,
                    folder / name / "overlay.png",
                    photo_size=pw.photo_size,
                    ortho_m=(pw.wall.width_m, pw.wall.height_m),
                )
    job.result()


def build_to_folder(
    spec: StructureSpec,
    out: str | Path,
    *,
    figures: bool = True,
    progress: bool | None = None,
    simulation_geometry: bool = True,
    overwrite: bool = False,
    processes: bool = False,
) -> dict:
    """:func:`build` and :func:`write_build`: what ``calib-masonry build`` calls (``processes``:
    half of the mask walls traced, and the simulation geometry computed, in processes of their
    own: ``trace_process`` of :func:`build`, ``geometry_process`` of :func:`write_build`)."""
    check_output(out, command="build", overwrite=overwrite)  # before the work, not after it
    from .pipeline import build

    return write_build(
        build(spec, progress=progress, trace_process=processes),
        out,
        figures=figures,
        simulation_geometry=simulation_geometry,
        overwrite=overwrite,
        geometry_process=processes,
    )


def read_build(model_dir: str | Path) -> Structure3D:
    """The Structure3D a ``build`` output folder holds (its bricks.json and summary.json)."""
    model_dir = checked_model_dir(model_dir)
    data = read_json(model_dir / "bricks.json", field="MODEL_DIR bricks.json")
    summary = _model_summary(model_dir)  # each file parsed once
    bricks, frames, cs, footprint = model_from_json(data, summary.get("closed_footprint"), model_dir)
    removed = tuple(tuple(w.get("removed_corner_pieces", ())) for w in data["walls"])
    return Structure3D(
        name=str(data.get("structure", Path(model_dir).name)),
        footprint=footprint,
        frames=tuple(frames),
        corners=tuple(cs),
        bricks=tuple(bricks),
        removed=removed,
        closure_gap_xy=closure_gap(footprint),
        max_joint_m=_model_max_joint(model_dir, summary),
    )


def _write_model_blend(structure, path: Path) -> None:
    """model.blend (a collection per wall), when Blender's bpy is installed (the ``sim`` extra)."""
    from .build3d.export import blend_walls
    from .errors import BackendMissing
    from .simulation.blender import require_bpy, write_model_blend

    try:
        require_bpy()
    except BackendMissing:
        return
    write_model_blend(blend_walls(structure), path)


def write_build(
    result: BuildResult,
    out: str | Path,
    *,
    figures: bool = True,
    simulation_geometry: bool = True,
    overwrite: bool = False,
    blend: bool = True,
    geometry_process: bool = False,
) -> dict:
    """Write a build into the folder ``out`` (all or nothing, replacing ``out`` as a whole: an
    existing ``out`` must be an earlier build or empty, unless ``overwrite``; the structure's own
    files inside it are kept): ``model.stl``, ``model.glb``, ``model.blend`` (with bpy; ``blend``), ``bricks.json``,
    ``summary.json``, ``material.toml`` (the structure's [material], if it has one), figures, the
    photo walls' calibrations and (with ``simulation_geometry``) the
    bodies and contact patches ``simulate`` starts from (``sim_geometry.npz``), computed from the
    structure in memory, on a thread while the rest is written, or (``geometry_process``: what the
    command line asks for) in a process of its own (:mod:`calib_masonry._worker`; the same
    geometry, without the GIL between it and the writing: an 8,190-brick tower's build took 49 s
    so, 58 s with the thread, in the same run). Returns the summary."""
    spec = result.spec
    s = result.structure
    inputs = [spec.source, *(w.mask for w in spec.walls), *(w.image for w in spec.walls)]
    want_geometry = simulation_geometry and bool(s.bricks)
    if want_geometry and blend and not geometry_process:
        # the geometry's thread imports nothing: its modules (simulation.scene, mortar) are
        # imported at this module's top, not on that thread while this one imports bpy, trimesh's
        # exporters and matplotlib (two threads importing modules of one package at once can
        # deadlock in CPython 3.11's import locks, gh-83065: a CI run hung in the demo's build,
        # where this was the one place two threads imported at once); and Blender is loaded
        # before that thread starts: loading bpy's libraries (USD's static initialisers take the
        # GIL while the loader's lock is held) beside a thread in numpy (whose temporaries'
        # elision asks the loader, dladdr) deadlocked a build of a 1000 px/m stone wall (both
        # threads' stacks seen in gdb). A process has neither problem (its helper thread here
        # only moves bytes through a pipe).
        from .errors import BackendMissing
        from .simulation.blender import require_bpy

        try:
            require_bpy()
        except BackendMissing:
            pass
    # the simulation's bodies and contact patches, computed once here rather than in every
    # `simulate` run of this model, on a second core while the meshes, model.blend and figures
    # are written (joined, or the process ended, however the block ends)
    job = background_process if geometry_process else background
    with (
        staged_output(out, "build", overwrite=overwrite, keep=inputs) as stage,
        job(_timed_geometry, s) if want_geometry else contextlib.nullcontext() as geometry,
    ):
        t0 = time.perf_counter()
        inter = max_interpenetration(s.bricks)
        result.seconds["interpenetration_check"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        export_mesh(s, stage / "model.stl")
        export_mesh(s, stage / "model.glb")  # one node per brick: opens in Blender, three.js, any glTF viewer
        raw = write_bricks_json(s, stage / "bricks.json")
        if spec.material:  # the structure's [material]: what `simulate` runs the model with
            import tomli_w

            (stage / MATERIAL_FILE).write_text(tomli_w.dumps({"material": dict(spec.material)}))
        result.seconds["export"] = time.perf_counter() - t0
        if blend and s.bricks:
            t0 = time.perf_counter()
            _write_model_blend(s, stage / "model.blend")
            result.seconds["model_blend"] = time.perf_counter() - t0
        if figures:
            t0 = time.perf_counter()
            removed = []
            for w, (wall, tr) in enumerate(zip(spec.walls, result.traces)):
                gone = set(s.removed[w])
                removed.append(
                    [
                        wall_from_image(b.vertices_xy, tr.image_shape, wall.width_m, wall.height_m)
                        for b in tr.bricks
                        if b.id in gone
                    ]
                )
            plot_walls(s, stage / "walls.png", removed_polygons=removed)
            plot_model(s, stage / "model.png")
            result.seconds["figures"] = time.perf_counter() - t0
        if result.photos:
            t0 = time.perf_counter()
            _write_photo_walls(
                result.photos,
                stage / "photos",
                figures=figures,
                traces={w.name: tr for w, tr in zip(spec.walls, result.traces)},
            )
            result.seconds["photo_files"] = time.perf_counter() - t0
        summary = _summary(result, inter)
        if want_geometry:
            t0 = time.perf_counter()
            computed, seconds = geometry.result()
            # its own time on its thread (about 5 s on the Stylite tower, 10 s on the paper
            # example), and how long the build waited for it
            summary["seconds"]["simulation_geometry"] = round(seconds, 4)
            summary["seconds"]["simulation_geometry_wait"] = round(time.perf_counter() - t0, 4)
            store_geometry(s, stage, bricks_json=raw, geometry=computed)
            # joint area over the boundary neighbouring bricks share (simulation/scene.py: joint_coverage)
            summary["joint_coverage"] = computed.coverage_summary()
            if summary["joint_coverage"]["units_without_bed_joint"]:
                width = mortar_width_m(spec, result)
                if width is not None:
                    summary["joint_coverage"]["mortar_width_p95_m"] = round(width, 4)
                bed, over = hanging_beds(s, computed.without_bed_joint())
                if bed is not None:
                    summary["joint_coverage"]["widest_bed_m"] = round(bed, 4)
                if over:
                    summary["joint_coverage"]["units_over_opening"] = [computed.names[k] for k in over]
        write_json(stage / "summary.json", summary)
    return summary


def hanging_beds(structure: Structure3D, hanging) -> tuple[float | None, list[int]]:
    """The widest of the narrowest beds under the units ``hanging`` (indices of
    ``structure.bricks``: the simulation geometry's ``without_bed_joint``), the gap between each
    and the units beneath it (:func:`~calib_masonry.build3d.contacts.narrowest_beds`, searched to
    the structure files' widest reach, :data:`~calib_masonry.spec.MAX_JOINT_M`): a reach above it
    joins each to a unit beneath (None where none has a unit beneath within that search); and
    those of ``hanging`` with no unit beneath within it, which no reach joins: they span an
    opening (a window, a door, a void in the mask)."""
    from .spec import MAX_JOINT_M

    hanging = np.asarray(hanging, dtype=np.int64)
    beds = narrowest_beds(structure.bricks, search_m=MAX_JOINT_M, ground_m=joint_width(structure), only=hanging)
    ours = beds[hanging]
    finite = ours[np.isfinite(ours)]
    return (float(finite.max()) if finite.size else None), hanging[np.isinf(ours)].tolist()


def mortar_width_m(spec, result) -> float | None:
    """The width (m) that 95 % of the mortar joints' length in the walls' masks is narrower than
    (:func:`~calib_masonry.wall2d.trace.mortar_widths`; a photo wall's segmented pieces): what the
    joint reach must span to join the units across their own joints. Gaps wider than the widest
    reach a structure file allows (:data:`~calib_masonry.spec.MAX_JOINT_M`) are openings, not
    joints, and do not count. None where no wall has a mask or pieces to measure (a LabelMe file's
    polygons, traces given)."""
    from .io import read_mask_labels
    from .spec import MAX_JOINT_M
    from .wall2d.trace import mortar_widths

    found = []
    for wall in spec.walls:
        pw = result.photos.get(wall.name)
        if pw is not None:
            mask = pw.mask
        elif wall.mask is not None and Path(wall.mask).suffix.lower() != ".json":
            mask, _ = read_mask_labels(wall.mask, field=f"wall '{wall.name}' mask")
        else:
            continue
        # a gap wider than any reach a structure file allows is an opening, not a joint (a window
        # 1 m wide put the 95th percentile of a 3 x 3 m wall's 1.5 cm joints at 45 cm)
        m_per_px = wall.width_m / mask.shape[1]
        found.append(mortar_widths(mask, max_px=MAX_JOINT_M / m_per_px) * m_per_px)
    widths = np.concatenate(found) if found else np.zeros(0)
    widths = widths[widths <= MAX_JOINT_M]  # and the branches into its corners of that width
    return float(np.percentile(widths, 95)) if widths.size else None


def _timed_geometry(structure: Structure3D):
    """The simulation geometry of ``structure`` and the seconds it took."""
    t0 = time.perf_counter()
    return simulation_geometry(structure), time.perf_counter() - t0


GEOMETRY_FILE = "sim_geometry.npz"  # the simulation's bodies and contact patches, stored by `build`


def checked_model_dir(model_dir: str | Path) -> Path:
    """``model_dir`` as a Path, if it is a folder ``build`` wrote (it holds bricks.json)."""
    model_dir = Path(model_dir)
    if not model_dir.is_dir():
        raise InputError(f"MODEL_DIR {model_dir}: not a folder; give the --out folder of `calib-masonry build`")
    if not (model_dir / "bricks.json").is_file():
        raise InputError(
            f"MODEL_DIR {model_dir}: has no bricks.json; run `calib-masonry build STRUCTURE.toml --out {model_dir}` first"
        )
    return model_dir


def _model_summary(model_dir: Path) -> dict:
    """A model folder's summary.json contents, {} where it has none."""
    return read_json(model_dir / "summary.json") if (model_dir / "summary.json").is_file() else {}


def _model_max_joint(model_dir: Path, summary: dict | None = None) -> float | None:
    """The widest joint a model folder was built with where it is not the default (its summary's
    ``max_joint_m``; ``summary``: that file's contents, where already read), else None."""
    if summary is None:
        summary = _model_summary(model_dir)
    value = summary.get("max_joint_m")
    return float(value) if value is not None and float(value) != MAX_GAP_M else None


def model_from_json(data: dict, closed, source: str | Path):
    """Bricks, wall frames, corners and footprint of a ``build`` output's bricks.json contents
    ``data`` (``closed``: the build summary's closed_footprint)."""
    try:
        bricks = bricks_from_json(data)
        walls = tuple(
            WallGeometry(
                width_m=w["width_m"],
                height_m=w["height_m"],
                theta_rad=math.radians(w["theta_deg"]),
                thickness_m=w["thickness_m"],
                name=w["name"],
            )
            for w in data["walls"]
        )
    except (KeyError, TypeError, ValueError) as exc:
        raise InputError(f"MODEL_DIR {source}: bricks.json is not a build output ({exc}); re-run build") from None
    if not bricks:
        raise InputError(f"MODEL_DIR {source}: bricks.json holds no bricks; nothing to simulate")
    footprint = Footprint(walls=walls, closed=closed)
    return bricks, wall_frames(footprint), corners(footprint), footprint


def read_model_json(model_dir: str | Path) -> tuple[dict, bool | None]:
    """A ``build`` output folder's bricks.json contents and its summary's closed_footprint."""
    model_dir = checked_model_dir(model_dir)
    bricks = read_json(model_dir / "bricks.json", field="MODEL_DIR bricks.json")
    return bricks, _model_summary(model_dir).get("closed_footprint")


def load_model(model_dir: str | Path):
    """Bricks, wall frames, corners and footprint of a ``build`` output folder."""
    return model_from_json(*read_model_json(model_dir), model_dir)


#: The version of sim_geometry.npz: of its layout and of the computation behind it (simulation/
#: scene.py's scene_geometry, mortar.py, build3d's contacts, assemble, extrude, place). Raise it
#: with any change to them that changes a stored value: a stored copy of another version is
#: computed again, never trusted (tests/test_simulate.py -k build_stores checks that it is).
GEOMETRY_FORMAT = 2


def _geometry_key(raw: bytes, closed, max_gap_m: float, mortar_fill: bool) -> str:
    """What a model's simulation geometry is computed from, readable: the format's version, the
    bricks.json bytes (hashed), whether the footprint is closed, the joint reach and the mortar
    fill."""
    import hashlib

    return (
        f"sim_geometry v{GEOMETRY_FORMAT}; bricks.json sha256 {hashlib.sha256(raw).hexdigest()}; "
        f"closed_footprint {closed}; max_gap_m {float(max_gap_m)!r}; mortar_fill {bool(mortar_fill)}"
    )


def _save_geometry(geometry: SceneGeometry, path: Path, key: str) -> None:
    """Store ``geometry`` as an npz file; ``key`` names the inputs it was computed from (see
    :func:`_load_geometry`)."""
    g = geometry
    nv = np.array([len(v) for v in g.vertices], dtype=np.int64)
    nf = np.array([len(f) for f in g.faces], dtype=np.int64)
    with open(path, "wb") as fh:
        np.savez(
            fh,
            key=np.array(key),
            names=np.array(g.names),
            vertex_counts=nv,
            vertices=np.concatenate(g.vertices).reshape(-1, 3),
            face_counts=nf,
            faces=np.concatenate(g.faces).reshape(-1, 3),
            locations=g.locations,
            brick_volumes=g.brick_volumes,
            hull_volume_change=g.hull_volume_change,
            patch_pairs=g.patch_pairs,
            patch_centroids=g.patch_centroids,
            patch_normals=g.patch_normals,
            patch_areas=g.patch_areas,
            patch_widths=g.patch_widths,
            patch_moments=g.patch_moments,
            patch_outlines=g.patch_outlines,
            scalars=np.array([g.mortar_fill_volume, g.bricks_without_fill, g.max_gap_m, float(g.mortar_fill)]),
            coverage=g.coverage,
        )


def _load_geometry(path: Path, key: str) -> SceneGeometry | None:
    """The geometry stored at ``path`` if it was stored under ``key`` (:func:`_geometry_key`: the
    format's version and the inputs); None otherwise (no file, another key, an unreadable file)."""
    try:
        with np.load(path, allow_pickle=False) as z:
            if str(z["key"]) != key:
                return None
            d = {k: z[k] for k in z.files}
    except (OSError, ValueError, KeyError, EOFError):
        return None
    fill, without, gap, filled = (float(x) for x in d["scalars"])
    return SceneGeometry(
        names=tuple(str(n) for n in d["names"]),
        vertices=tuple(np.split(d["vertices"], np.cumsum(d["vertex_counts"])[:-1])),
        faces=tuple(np.split(d["faces"], np.cumsum(d["face_counts"])[:-1])),
        locations=d["locations"],
        brick_volumes=d["brick_volumes"],
        hull_volume_change=d["hull_volume_change"],
        patch_pairs=d["patch_pairs"],
        patch_centroids=d["patch_centroids"],
        patch_normals=d["patch_normals"],
        patch_areas=d["patch_areas"],
        patch_widths=d["patch_widths"],
        patch_moments=d["patch_moments"],
        patch_outlines=d["patch_outlines"],
        mortar_fill_volume=fill,
        bricks_without_fill=int(without),
        max_gap_m=gap,
        mortar_fill=bool(filled),
        coverage=d["coverage"],
    )


def simulation_geometry(
    model: Structure3D | SceneGeometry, *, max_gap_m: float | None = None, mortar_fill: bool = True
) -> SceneGeometry:
    """The bodies and contact patches of a built structure, in memory (``max_gap_m``: the widest
    joint; None: the structure's own, :func:`joint_width`)."""
    if isinstance(model, SceneGeometry):
        return model
    if not isinstance(model, Structure3D):
        raise InputError(
            f"simulate: the model must be a Structure3D (from build), a SceneGeometry or a build "
            f"folder, got {type(model).__name__}"
        )
    gap = joint_width(model) if max_gap_m is None else max_gap_m
    return scene_geometry(model.bricks, list(model.frames), list(model.corners), mortar_fill=mortar_fill, max_gap_m=gap)


def store_geometry(
    structure: Structure3D,
    model_dir: str | Path,
    *,
    max_gap_m: float | None = None,
    mortar_fill: bool = True,
    bricks_json: bytes | None = None,
    geometry: SceneGeometry | None = None,
) -> SceneGeometry:
    """Compute the simulation geometry of ``structure`` in memory (unless the caller has computed
    it already: ``geometry``) and store it in ``model_dir`` (a ``build`` stage) as
    sim_geometry.npz, keyed by the bricks.json that build writes for it (``bricks_json``, its
    bytes, when the caller has them already; else made here) and by the joint reach and mortar
    fill the geometry was computed with."""
    if geometry is None:
        geometry = simulation_geometry(structure, max_gap_m=max_gap_m, mortar_fill=mortar_fill)
    if bricks_json is None:
        bricks_json = bricks_json_bytes(structure)
    key = _geometry_key(bricks_json, structure.footprint.is_closed, geometry.max_gap_m, geometry.mortar_fill)
    _save_geometry(geometry, Path(model_dir) / GEOMETRY_FILE, key)
    return geometry


def geometry_for_model(
    model_dir: str | Path, *, max_gap_m: float | None = None, mortar_fill: bool = True
) -> tuple[SceneGeometry, bool]:
    """The simulation geometry of a model folder and whether it came from the folder's
    sim_geometry.npz. The stored copy is used only if it was computed from this bricks.json (its
    hash), footprint and settings by this version of the code; otherwise (a model built before it
    was stored, an edited bricks.json) the geometry is computed here from bricks.json.
    ``max_gap_m``: the widest joint; None: the one the model was built with (its summary's
    ``max_joint_m``, else the default)."""
    model_dir = checked_model_dir(model_dir)
    raw = (model_dir / "bricks.json").read_bytes()
    summary = _model_summary(model_dir)
    closed = summary.get("closed_footprint")  # as read_model_json's, from the one reading
    if max_gap_m is None:
        max_gap_m = _model_max_joint(model_dir, summary) or MAX_GAP_M
    stored = _load_geometry(model_dir / GEOMETRY_FILE, _geometry_key(raw, closed, max_gap_m, mortar_fill))
    if stored is not None:
        return stored, True
    data = read_json(model_dir / "bricks.json", field="MODEL_DIR bricks.json")
    bricks, frames, cs, _ = model_from_json(data, closed, model_dir)
    return scene_geometry(bricks, frames, cs, mortar_fill=mortar_fill, max_gap_m=max_gap_m), False

"""``synth``: a scenario file to masks, a structure file and the exact truth beside them.

Output folder layout::

    structure.toml        the structure file ``build`` reads (mask paths relative to it; with
                          ``max_joint_m`` where the stones' beds are wider than the default reach,
                          so that every unit is joined to the one beneath it as in the truth)
    masks/<wall>.png      binary masks, bricks white
    truth/truth.json      per wall: W, H, theta, t, image shape, and every piece's polygon in wall
                          metres and in pixels, with ``end_face`` marking corner end faces
    truth/bricks.json     the true 3D bricks (same format as ``build``'s bricks.json)
    truth/walls.png       a picture of the true outer wall surfaces
    photos/<wall>.jpg     (with photos) a standing-height perspective photo of each wall, EXIF focal
                          length and compass heading; truth.json["photos"] holds each camera, the
                          exact image-to-wall homography and the wall's corners in the photo
    photos/corner_<a>_<b>.jpg  (with photos) a photo of each corner, both walls in view;
                          truth.json["corner_photos"] holds the turn angle and the camera
    structure_photos.toml (with photos) the structure file naming the photos instead of masks,
                          and the corner photos as [[corner]] tables
"""

from __future__ import annotations

import contextlib
import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from .._threads import background
from ..build3d.assemble import MAX_GAP_M, Structure3D, WallPolygons, assemble, joint_width, reach_over
from ..build3d.contacts import widest_bed
from ..build3d.export import plot_walls, write_bricks_json
from ..build3d.place import closure_gap, footprint_is_closed
from ..io import Photo, read_photo, staged_output, write_json, write_mask
from ..spec import MAX_JOINT_M, PhotoSpec, StructureSpec, SyntheticSpec, structure_to_toml
from .layouts import layout_structure
from .render import rasterise_wall

__all__ = ["Synthesis", "synthesize", "synthesize_to_folder", "synth_to_folder", "truth_structure", "write_synthesis"]


def truth_structure(spec: StructureSpec):
    """The exact layout and its 3D assembly (corner end faces removed as flagged)."""
    pieces = layout_structure(spec)
    walls = [
        WallPolygons(wall=w, ids=tuple(range(len(p))), polygons_m=tuple(q.polygon_m for q in p))
        for w, p in enumerate(pieces)
    ]
    end_faces = [{i for i, q in enumerate(p) if q.end_face} for p in pieces]
    return pieces, assemble(spec.footprint, walls, name=spec.name, end_faces=end_faces)


def widest_bed_m(structure: Structure3D, syn: SyntheticSpec) -> float:
    """The widest bed (m) under a unit of the true ``structure`` above its lowest course: about the
    joint reach at which every unit gets a joint beneath it (the gap between facing faces at their
    overlap, as the corners' joints are found; a wall's own joints follow the mortar's middle, and
    a traced outline lies up to a pixel inside its stone). A bond's beds are its mortar; irregular stones' beds widen where their edges tilt
    and their corners are chamfered (mortar 4 cm with irregularity 0.8 gives beds of up to 7.2
    cm). A unit with no bed within :data:`~calib_masonry.spec.MAX_JOINT_M` (one resting on a corner
    stone whose face is turned) is left out."""
    if syn.layout != "stones":
        return float(syn.mortar_m)
    widest = widest_bed(structure.bricks, search_m=MAX_JOINT_M, ground_m=MAX_GAP_M)
    return float(syn.mortar_m) if widest is None else widest


def _shots(jobs: list, progress, desc: str):
    """Each job's ``(name, shot)`` in order, rendered two at a time: every photo has its own seeded
    generator, so the order of rendering changes nothing, and NumPy, SciPy and torch release the
    GIL for the heavy work (``synth --photos`` of the paper example 1.7x faster on 2 cores). Two
    at a time because each photo in flight holds a few hundred MB. A stop request ends the work
    at the next photo."""
    from .._threads import thread_imap
    from ..process import raise_if_stopped
    from ..progress import progress as _progress

    def run(job):
        raise_if_stopped()
        name, render = job
        return name, render()

    shots = thread_imap(run, jobs, workers=2, name="photo")
    try:
        yield from _progress(shots, desc=desc, unit="photo", enabled=progress, total=len(jobs))
    finally:
        shots.close()  # the threads end with this generator, not when the progress wrapper goes


def _photograph(spec: StructureSpec, pieces, photos: PhotoSpec, progress):
    """A JPEG of every wall and corner, in memory (name under the data folder -> bytes), the
    structure naming them (paths relative to the data folder) and the cameras' truth."""
    from ..spec import CornerSpec
    from .photo import jpeg_bytes, photograph_corner, photograph_wall

    syn = spec.synthetic or SyntheticSpec()
    n = len(spec.walls)
    closed = spec.closed if spec.closed is not None else footprint_is_closed(spec)
    pairs = [(i, i + 1) for i in range(n - 1)] + ([(n - 1, 0)] if closed else [])
    # no corner between (nearly) collinear walls
    pairs = [
        (i, j)
        for i, j in pairs
        if abs(math.remainder(spec.walls[j].theta_rad - spec.walls[i].theta_rad, 2 * math.pi)) >= math.radians(5)
    ]
    # the walls' photos, then the corners', in one stream: a thread that finishes the last wall
    # early starts on the first corner instead of waiting for the other (each photo has its own
    # seeded generator, so the photos are the same whatever the order)
    jobs = [
        (
            ("wall", w),
            lambda w=w, wall=wall: photograph_wall(wall, pieces[w], photos, np.random.default_rng([syn.seed, 2, w])),
        )
        for w, wall in enumerate(spec.walls)
    ] + [
        (
            ("corner", (i, j)),
            lambda i=i, j=j: photograph_corner(
                spec.walls[i], pieces[i], spec.walls[j], pieces[j], photos, np.random.default_rng([syn.seed, 3, i])
            ),
        )
        for i, j in pairs
    ]
    truths, walls, corner_truths, corners, files = [], [], [], [], {}
    for (kind, key), shot in _shots(jobs, progress, "photograph walls and corners"):
        if kind == "wall":
            wall = spec.walls[key]
            name = f"photos/{wall.name}.jpg"
            heading = shot["truth"]["exif_heading_deg"]
            truths.append({"name": wall.name, "photo": name, **shot["truth"]})
            walls.append(replace(wall, mask=None, image=Path(name)))
        else:  # a corner photo carries no compass heading
            a, b = spec.walls[key[0]], spec.walls[key[1]]
            name = f"photos/corner_{a.name}_{b.name}.jpg"
            heading = None
            corner_truths.append({"photo": name, **shot["truth"]})
            corners.append(CornerSpec(photo=Path(name), walls=(a.name, b.name)))
        files[name] = jpeg_bytes(
            shot["image"], focal_35mm=shot["truth"]["focal_35mm"], heading_deg=heading, quality=photos.jpeg_quality
        )
    photo_spec = replace(spec, walls=tuple(walls), synthetic=None, photos=None, corners=tuple(corners))
    return truths, corner_truths, photo_spec, files


@dataclass(frozen=True)
class Synthesis:
    """A synthetic data set in memory (:func:`synthesize`); :func:`write_synthesis` writes it.

    ``spec``: the structure ``build`` reads, its walls naming ``masks/<wall>.png`` (paths relative
    to the data folder; ``masks`` holds them by wall name); ``photo_spec``, with photos: the same
    walls naming ``photos/<wall>.jpg`` and the corner photos (``photos``: name -> the JPEG's bytes,
    EXIF and all, as a camera writes it); ``truth``: what truth.json holds; ``structure`` and
    ``pieces``: the true bricks and the layout's pieces by wall."""

    spec: StructureSpec
    masks: dict
    truth: dict
    structure: Structure3D
    pieces: list
    photo_spec: StructureSpec | None = None
    photos: dict = field(default_factory=dict)

    def photo(self, name: str | Path) -> Photo:
        """The photo ``name`` (``photos/<wall>.jpg``) as :func:`calib_masonry.read_photo` reads its file."""
        return read_photo(name, data=self.photos[Path(name).as_posix()])


def synthesize(
    spec: StructureSpec,
    *,
    photos: PhotoSpec | None = None,
    progress: bool | None = None,
    beside: Callable[[Structure3D, list], None] | None = None,
) -> Synthesis:
    """Masks and truth for the scenario ``spec``, in memory; with ``photos`` (or a ``[photos]``
    table in the scenario) also perspective photos and their cameras' truth. ``beside(structure,
    pieces)``, if given, runs on a thread of its own while the photos render (a caller's files of
    the true structure: JSON and matplotlib hold the GIL, the photos mostly do not)."""
    photos = photos or spec.photos
    syn = spec.synthetic or SyntheticSpec()
    pieces, structure = truth_structure(spec)
    widest = widest_bed_m(structure, syn)
    if spec.max_joint_m is None and reach_over(widest) > MAX_GAP_M:
        # the structure files written join every unit to the one beneath it, as the truth does
        spec = replace(spec, max_joint_m=min(MAX_JOINT_M, float(reach_over(widest))))
    rng = np.random.default_rng([syn.seed, 1])
    masks, walls_truth, new_walls = {}, [], []
    for w, wall in enumerate(spec.walls):
        mask, polys_px = rasterise_wall(wall, pieces[w], syn, rng)
        name = f"masks/{wall.name}.png"
        masks[wall.name] = mask
        new_walls.append(replace(wall, mask=Path(name), image=None))
        walls_truth.append(
            {
                "name": wall.name,
                "width_m": wall.width_m,
                "height_m": wall.height_m,
                "theta_deg": wall.theta_deg,
                "thickness_m": wall.thickness_m,
                "image_shape": list(mask.shape),
                "mask": name,
                "pieces": [
                    {
                        "id": i,
                        "course": p.course,
                        "end_face": p.end_face,
                        "polygon_m": p.polygon_m,
                        "polygon_px": polys_px[i],
                    }
                    for i, p in enumerate(pieces[w])
                ],
            }
        )
    truth = {
        "name": spec.name,
        "layout": syn.layout,
        "seed": syn.seed,
        "px_per_m": syn.px_per_m,
        "mortar_m": syn.mortar_m,
        "widest_bed_m": round(widest, 5),
        "max_joint_m": joint_width(spec),
        "closure_gap_xy_m": closure_gap(spec),
        "walls": walls_truth,
        "bricks": len(structure.bricks),
        "end_faces": int(sum(p.end_face for ps in pieces for p in ps)),
    }
    photo_spec, files = None, {}
    if photos is None:
        if beside is not None:
            beside(structure, pieces)
    else:
        # what the threads import, imported here first (two threads importing one package at
        # once can hang in CPython 3.11's import locks, gh-83065)
        from ..preload import preload

        preload("renderer")
        with background(beside, structure, pieces) if beside is not None else contextlib.nullcontext() as job:
            truth["photos"], truth["corner_photos"], photo_spec, files = _photograph(spec, pieces, photos, progress)
        if job is not None:
            job.result()
    mask_spec = replace(spec, walls=tuple(new_walls), synthetic=None, photos=None)
    return Synthesis(mask_spec, masks, truth, structure, pieces, photo_spec, files)


def _rooted(spec: StructureSpec, out: Path) -> StructureSpec:
    """``spec`` with its walls' masks and photos and its corner photos under ``out``."""
    walls = tuple(
        replace(w, mask=out / w.mask if w.mask else None, image=out / w.image if w.image else None) for w in spec.walls
    )
    corners = tuple(replace(c, photo=out / c.photo) for c in spec.corners)
    return replace(spec, walls=walls, corners=corners)


def _write_truth_files(structure, pieces, stage: Path, name: str, figures: bool) -> None:
    """truth/bricks.json and (with ``figures``) truth/walls.png."""
    write_bricks_json(structure, stage / "truth" / "bricks.json")
    if figures:
        removed = [[p.polygon_m for p in ps if p.end_face] for ps in pieces]
        plot_walls(
            structure,
            stage / "truth" / "walls.png",
            removed_polygons=removed,
            title=f"{name}: true outer wall surfaces (red hatched: corner end faces)",
        )


def _write_rest(result: Synthesis, stage: Path, out: Path) -> None:
    """Everything of ``result`` but the truth's bricks.json and walls.png, into the stage of ``out``."""
    for wall, mask in result.masks.items():
        write_mask(stage / "masks" / f"{wall}.png", mask)
    if result.photo_spec is not None:
        (stage / "photos").mkdir()
        for name, data in result.photos.items():
            (stage / name).write_bytes(data)
        (stage / "structure_photos.toml").write_text(
            "# Generated by `calib-masonry synth`: the same walls from perspective photos (W, H and theta as the\n"
            "# method's typed input; delete width_m / height_m to fit them from the photos instead).\n"
            + structure_to_toml(_rooted(result.photo_spec, out), relative_to=out),
            encoding="utf-8",
        )
    write_json(stage / "truth" / "truth.json", result.truth)
    syn = result.truth
    (stage / "structure.toml").write_text(
        f"# Generated by `calib-masonry synth` from a scenario ({syn['layout']}, seed {syn['seed']}, "
        f"{syn['px_per_m']:g} px/m); do not edit, re-run synth instead.\n"
        + structure_to_toml(_rooted(result.spec, out), relative_to=out),
        encoding="utf-8",
    )


def write_synthesis(
    result: Synthesis, out: str | Path, *, figures: bool = True, overwrite: bool = False, keep=()
) -> None:
    """Write a :class:`Synthesis` into the folder ``out`` (replacing it as a whole; files among
    ``keep``, a scenario file inside it, are kept): see the module docstring for the layout."""
    out = Path(out)
    with staged_output(out, "synth", overwrite=overwrite, keep=list(keep)) as stage:
        (stage / "masks").mkdir()
        (stage / "truth").mkdir()
        _write_truth_files(result.structure, result.pieces, stage, result.truth["name"], figures)
        _write_rest(result, stage, out)


def synthesize_to_folder(
    spec: StructureSpec,
    out: str | Path,
    *,
    figures: bool = True,
    photos: PhotoSpec | None = None,
    progress: bool | None = None,
    overwrite: bool = False,
) -> dict:
    """:func:`synthesize` the scenario ``spec`` into the folder ``out`` (replacing it as a whole; a
    scenario file inside it is kept), the truth's files written while the photos render. Returns
    the truth (truth.json's contents)."""
    out = Path(out)
    with staged_output(out, "synth", overwrite=overwrite, keep=[spec.source]) as stage:
        (stage / "masks").mkdir()
        (stage / "truth").mkdir()
        if figures and (photos or spec.photos) is not None:
            from ..preload import preload

            preload("figures")  # before the thread that draws starts (see synthesize)
        result = synthesize(
            spec,
            photos=photos,
            progress=progress,
            beside=lambda structure, pieces: _write_truth_files(structure, pieces, stage, spec.name, figures),
        )
        _write_rest(result, stage, out)
    return result.truth


def synth_to_folder(
    scenario: str | Path,
    out: str | Path,
    *,
    figures: bool = True,
    photos: bool = False,
    photo_size: tuple[int, int] | None = None,
    progress: bool | None = None,
    overwrite: bool = False,
):
    """``calib-masonry synth``: read a scenario file and :func:`synthesize_to_folder` it into ``out`` (with
    ``photos``, also perspective photos, ``photo_size`` (W, H) pixels overriding its [photos] table).
    Returns the scenario and the truth summary."""
    from ..errors import InputError
    from ..io import check_output
    from ..spec import load_structure

    check_output(out, command="synth", overwrite=overwrite)
    if photo_size and (min(photo_size) < 64 or max(photo_size) > 20000):
        raise InputError(f"--photo-size {photo_size[0]} {photo_size[1]}: each side must lie in 64..20000 px")
    spec = load_structure(scenario, require_sources=False)
    if spec.synthetic is None:
        raise InputError(f"{scenario}: no [synthetic] table; add one (layout, px_per_m, seed, ...) to make a data set")
    shots = None
    if photos:
        shots = spec.photos or PhotoSpec()
        if photo_size:
            shots = replace(shots, long_side_px=max(photo_size), short_side_px=min(photo_size))
    return spec, synthesize_to_folder(spec, out, figures=figures, photos=shots, progress=progress, overwrite=overwrite)

"""Masks or photos and the parameter table to a 3D brick model, as one call: :func:`build`, in
memory; a build folder is written and read by :mod:`calib_masonry.build_folder` (the edge)."""

from __future__ import annotations

import contextlib
import math
import time
from dataclasses import dataclass, field, replace

import numpy as np

from ._threads import background_process, cpu_count, thread_imap
from .build3d.assemble import Structure3D, WallPolygons, assemble, joint_width
from .build3d.place import footprint_is_closed
from .build3d.scale import aspect_mismatch, wall_from_image
from .errors import InputError
from .io import Photo, read_mask_labels, to_uint8, warn
from .preload import preload
from .progress import progress as _progress
from .spec import StructureSpec, WallSpec
from .wall2d.trace import TraceConfig, TraceResult, check_not_inverted, trace_mask

__all__ = [
    "BuildResult",
    "PhotoWall",
    "trace_wall",
    "build",
    "closure_warning",
]

#: A declared or detected closed footprint whose gap exceeds this gets a warning.
CLOSURE_WARN_M = 1e-3


@dataclass(frozen=True)
class BuildResult:
    """A build in memory: the structure, every wall's trace, the spec with fitted sizes filled in,
    the stage times and the photo walls' calibrations by wall name."""

    structure: Structure3D
    traces: tuple[TraceResult, ...]
    seconds: dict[str, float] = field(default_factory=dict)
    photos: dict = field(default_factory=dict)  # wall name -> PhotoWall
    spec: StructureSpec | None = None


@dataclass(frozen=True)
class PhotoWall:
    """A wall built from a photo: its calibration, orthophoto and segmented mask."""

    calibration: object  # calibrate.rectify.PhotoCalibration, its photo a preview (see photo_size)
    rectified: np.ndarray  # the orthophoto, (rows, cols, 3) uint8 (as rectified.png holds it)
    mask: np.ndarray
    wall: WallSpec  # with W and H resolved (typed values kept, missing ones fitted)
    photo_size: tuple[int, int] | None = None  # (width, height) of the photo the preview shrinks
    trace: TraceResult | None = None  # the mask traced (resolve_photo_walls with trace=True)
    segmentation: dict = field(default_factory=dict)  # the pieces found (wall2d.segment.Segmentation.summary)
    labels: np.ndarray | None = None  # the pieces labelled, where they touch (the joints' partition)
    occluders_ortho: tuple = ()  # the occluders in the orthophoto's pixels
    openings_ortho: tuple = ()  # the openings the segmentation left out (windows, doors), likewise
    # the typed H lay beyond the fitted H's noise: the orthophoto keeps the photo's vertical scale
    # from the base instead of stretching the outline onto H (calibrate.rectify.wall_stretch)
    anchored: bool = False


#: rectify's flags and the [[wall]] keys that say the same in a structure file, for the advice of
#: a photo wall's calibration in build (longest first: a flag's name may begin another's)
_WALL_KEYS = (
    ("--known-length x1,y1,x2,y2,M", "known_length = [x1, y1, x2, y2, M]"),
    ("--corners x1,y1,...,x4,y4", "corners_px = [x1, y1, ..., x4, y4]"),
    ("--course-height M", "course_height_m = M"),
    ("--known-height", "height_m"),
    ("--known-width", "width_m"),
    ("--course-height", "course_height_m"),
    ("--camera-height", "camera_height_m"),
    ("--focal-px", "focal_px"),
    ("--occluders", "occluders"),
    ("--corners", "corners_px"),
)


def as_wall_keys(message: str) -> str:
    """A calibration's advice (rectify's flags) in a structure file's [[wall]] keys; ``--force``,
    which build has not, left out. A build from a photo with no scale advised --known-width and
    --force."""
    import re

    said = re.sub(r",? or use --force to keep it anyway", "", message)
    for flag, key in _WALL_KEYS:
        said = said.replace(flag, key)
    return said if said == message else f"{said} (keys of the wall's [[wall]] table)"


#: a photo wall's typed H this many of the fitted H's sigmas from it (the photo scaled by the typed
#: W) is not stretched onto: the outline's top is then not the wall's (a band of mortar or a
#: capping left out of it: synth's walls end in up to 0.4 of a course of mortar), and stretching
#: moved every course by its share of the difference (a 4 m wall's outline 5 cm short: the top
#: courses 5 cm off, precision against the truth 0.77); the photo's own scale is kept from the base
ANCHOR_SIGMAS = 3.0

#: how far a photo wall's typed H may lie from the H its photo gives when scaled by its typed W
#: (and 5 sigmas of that H): past it, a typing error (a factor of 10, W and H swapped)
TYPED_SIZE_TOLERANCE = 0.10


def photo_wall(wall: WallSpec, spec: StructureSpec, photo: Photo | None = None) -> PhotoWall:
    """Calibrate a wall's photo (``photo``, or read from ``wall.image``), rectify it onto the wall
    (W x H) and segment its masonry units (:func:`calib_masonry.wall2d.segment.segment_wall`),
    leaving out the wall's occluders."""
    from .calibrate.rectify import (
        calibrate_photo,
        opening_polygons,
        ortho_from_photo,
        rectify,
        valid_ortho,
        wall_config,
    )
    from .errors import CalibMasonryError
    from .process import raise_if_stopped
    from .wall2d.segment import segment_wall

    try:
        config = wall_config(wall)
        raise_if_stopped()
        cal = calibrate_photo(photo if photo is not None else wall.image, config)
    except CalibMasonryError as exc:
        raise type(exc)(f"wall '{wall.name}': {as_wall_keys(str(exc))}") from None
    res = cal.result
    width = res.width_m if math.isnan(wall.width_m) else wall.width_m
    height = res.height_m if math.isnan(wall.height_m) else wall.height_m
    anchored = False
    if not math.isnan(wall.width_m) and not math.isnan(wall.height_m) and config.known_width_m == wall.width_m:
        # W and H typed: the photo scaled by W gives its own H; one typed 10 times too large, or the
        # two swapped, stretched the orthophoto onto the typed W x H without a word (1,674 pieces)
        off = abs(res.height_m / wall.height_m - 1.0)
        if off > max(TYPED_SIZE_TOLERANCE, 5.0 * res.sigma("height_m") / res.height_m):
            raise InputError(
                f"wall '{wall.name}': its photo scaled by width_m = {wall.width_m:g} gives H = {res.height_m:.3g} +- "
                f"{res.sigma('height_m'):.2g} m, but height_m = {wall.height_m:g} is typed ({off:.0%} off); check "
                "width_m and height_m (or leave height_m out to take it from the photo)"
            )
        anchored = abs(res.height_m - wall.height_m) > ANCHOR_SIGMAS * res.sigma("height_m")
    raise_if_stopped()
    # the fitted wall's frame stretched onto the typed W x H: the photo's outline maps onto the wall;
    # or, where the typed H is beyond the fitted H's noise, the height kept at the photo's scale
    rect = rectify(cal, px_per_m=spec.photo_px_per_m, width_m=width, height_m=height, anchored=anchored)
    raise_if_stopped()
    valid = valid_ortho(cal, spec.photo_px_per_m, width_m=width, height_m=height, anchored=anchored)
    # anchored under a taller typed H: the rows above the outline's top are no wall the photo showed;
    # the rest is segmented as an orthophoto of its own (its top edge the outline's, where the joints
    # run on to the border), then put back under them with no piece there: segmented with the rows
    # left out as occluded, the top course's head joints stopped a pixel short of them and the course
    # was one piece (five walls of an irregular pentagon, each 5 cm short at the top)
    above = int(np.argmax(valid.any(axis=1))) if anchored and height > res.height_m and valid.any() else 0
    seen = valid[above:]
    seg = segment_wall(rect[above:], spec.photo_px_per_m, valid=seen if not seen.all() else None).padded_top(above)
    # keep a preview of the photo for the overlay figure, not the photo: six 6 MP photos held
    # until the figures are drawn were 430 MB of a build's peak
    step = max(1, math.ceil(max(cal.photo.rgb.shape[:2]) / 900))  # what the figure shows
    preview = replace(cal.photo, rgb=np.ascontiguousarray(cal.photo.rgb[::step, ::step]))
    return PhotoWall(
        calibration=replace(cal, photo=preview),
        # 8-bit, as written: a float orthophoto per wall held until the figures are drawn was 4x
        # the memory (37 MB a paper-example wall) for the same PNG
        rectified=to_uint8(rect),
        mask=seg.mask,
        labels=seg.labels if seg.pieces is not None else None,
        wall=replace(wall, width_m=width, height_m=height),
        photo_size=cal.photo.size,
        segmentation=seg.summary(),
        occluders_ortho=tuple(
            ortho_from_photo(cal, poly, seg.mask.shape, width_m=width, height_m=height, anchored=anchored)
            for poly in cal.occluders
        ),
        openings_ortho=tuple(opening_polygons(seg)),
        anchored=anchored,
    )


def resolve_photo_walls(
    spec: StructureSpec, *, progress: bool | None = None, trace: bool = False, images: dict[str, Photo] | None = None
) -> tuple[StructureSpec, dict]:
    """Calibrate every photo wall; the spec with fitted sizes filled in, and the photo results by wall name.

    The walls are done two at a time on threads (scipy's filters and interpolation, which do most
    of the work, release the GIL): each wall's result depends on its own photo only, so the order
    changes nothing. A stop request ends each wall at its next stage. With ``trace``, each wall's
    mask is also traced on its thread (:func:`trace_wall`, the same result as tracing it after),
    while the other thread works on its photo; walls that refine their outlines are left to the
    caller (their JAX batches and progress bars belong on the main thread). ``images``: photos in
    memory by wall name, read instead of the walls' files."""
    todo = [w for w in spec.walls if w.mask is None and w.image is not None]
    if todo:
        # what the threads import, imported here, not by two threads at once (a half-imported
        # module, seen; tests/test_thread_imports.py checks that they import nothing)
        preload("photo_stage")

    def one(wall: WallSpec) -> PhotoWall:
        pw = photo_wall(wall, spec, (images or {}).get(wall.name))
        if trace and not wall.refine:
            pw = replace(pw, trace=trace_wall(pw.wall, spec, pw.mask, progress=False, labels=pw.labels))
        return pw

    done = thread_imap(one, todo, workers=min(2, cpu_count()), name="photo")
    with contextlib.closing(done):  # an error or a stop ends the other walls here, not when the traceback goes
        bar = _progress(done, total=len(todo), desc="calibrate photos", unit="photo", enabled=progress)
        photos = {wall.name: pw for pw, wall in zip(bar, todo)}  # the bar first: it ends its line
    walls = [photos[w.name].wall if w.name in photos else w for w in spec.walls]
    return spec.with_walls(tuple(walls)), photos


def trace_wall(
    wall: WallSpec,
    spec: StructureSpec,
    mask: np.ndarray | None = None,
    *,
    progress: bool | None = None,
    labels: np.ndarray | None = None,
) -> TraceResult:
    """Read, check and trace one wall's mask (or the mask segmented from its photo; ``labels``,
    its pieces labelled where they touch, when the segmentation made a partition)."""
    if mask is None:
        if wall.mask is None:
            raise InputError(f"wall '{wall.name}': no mask given; add mask = 'PATH' to its [[wall]] table")
        mask, drawn = read_mask_labels(wall.mask, field=f"wall '{wall.name}' mask")
        labels = drawn if labels is None else labels  # a LabelMe file's pieces, each its own
    mismatch = aspect_mismatch(mask.shape, wall.width_m, wall.height_m)
    if mismatch > spec.aspect_tolerance:
        rows, cols = mask.shape
        raise InputError(
            f"wall '{wall.name}' mask {wall.mask}: aspect ratio {cols}/{rows} = {cols / rows:.3f} disagrees with "
            f"width_m/height_m = {wall.width_m:g}/{wall.height_m:g} = {wall.width_m / wall.height_m:.3f} by "
            f"{mismatch:.1%} (tolerance {spec.aspect_tolerance:.0%}); check W and H or crop the mask to the wall"
        )
    refine = None
    if wall.refine:
        from .wall2d.refine import RefineConfig

        refine = RefineConfig()
    config = TraceConfig(
        vertices=wall.vertices, target_dice=wall.target_dice if wall.vertices is None else None, refine=refine
    )
    if labels is not None:
        from .wall2d.trace import trace_labels

        result = trace_labels(labels, config, progress=progress)
    else:
        result = trace_mask(mask, config, progress=progress)
    if not result.bricks:
        raise InputError(
            f"wall '{wall.name}' {_source(wall)}: no bricks found; "
            "bricks must be white on black mortar (or give a mask instead of the photo)"
        )
    if labels is None and wall.mask is not None:
        check_not_inverted(mask, len(result.bricks), f"wall '{wall.name}' mask {wall.mask}")
    return result


#: A wall whose polygons fit its pieces at a mean Dice under this gets a warning: too few vertices.
COARSE_TRACE_DICE = 0.85


def coarse_trace_warning(wall: WallSpec, trace: TraceResult) -> str | None:
    """The warning for a wall traced too coarsely to be a model of its units (None: fine): bricks
    traced to three vertices are triangles (mean Dice 0.67 on a stretcher-bond wall), and a unit
    much smaller than its piece leaves a gap wider than the joints reach beside it."""
    if not trace.bricks or not np.isfinite(trace.mean_dice) or trace.mean_dice >= COARSE_TRACE_DICE:
        return None
    how = f"vertices = {wall.vertices}" if wall.vertices is not None else f"target_dice = {wall.target_dice}"
    return (
        f"wall '{wall.name}': its polygons fit its {len(trace.bricks)} pieces at a mean Dice of "
        f"{trace.mean_dice:.2f} ({how}): too few vertices to model these units; trace with more "
        "(vertices = 8, or target_dice = 0.98, in its [[wall]] or [structure]) and build again"
    )


def unit_margins(polygons_m, width_m: float, height_m: float) -> tuple[float, float, float, float]:
    """How far a wall's units stay from its edges (m): left, right, below (above its base) and
    above (under its top), from its polygons in the wall's frame (x along it, z up)."""
    if not len(polygons_m):  # no unit (traces given in memory): nothing to say
        return 0.0, 0.0, 0.0, 0.0
    pts = np.concatenate([np.asarray(p, dtype=np.float64).reshape(-1, 2) for p in polygons_m])
    (x0, z0), (x1, z1) = pts.min(axis=0), pts.max(axis=0)
    return float(x0), float(width_m - x1), float(z0), float(height_m - z1)


def anchored_note(pw: PhotoWall) -> str:
    """What a photo wall's orthophoto did with a typed H beyond the fitted H's noise ("" where it
    stretched the outline onto the typed H, as the method does)."""
    if not pw.anchored:
        return ""
    res = pw.calibration.result
    h, fit, sigma = pw.wall.height_m, res.height_m, res.sigma("height_m")
    where = (
        f"nothing is built above {fit:.3f} m (what the outline left out there: a band of mortar, a capping)"
        if h > fit
        else f"the outline's top is cut at {h:.3f} m"
    )
    return (
        f"height_m = {h:.3f} m is {abs(h - fit) / max(sigma, 1e-12):.1f} sigma from the outline's {fit:.3f} +- {sigma:.3f} m: "
        f"the orthophoto keeps the photo's scale from the base, not stretched onto it; {where}"
    )


def _source(wall: WallSpec) -> str:
    return f"mask {wall.mask}" if wall.mask is not None else f"photo {wall.image}"


def _crop_advice(wall: WallSpec) -> str:
    if wall.mask is not None:
        return "crop the mask to the wall (its bottom row the wall's base, its first and last columns the wall's ends)"
    return "check its outline and its pieces (the LabelMe file rectify writes beside its orthophoto) and pass them back"


def margin_warning(wall: WallSpec, margins: tuple[float, float, float, float], reach_m: float) -> str | None:
    """The warning for a wall whose units stop short of its ends or of its base by more than the
    joints reach (None: fine): a mask drawn inside a larger canvas builds a smaller wall than
    ``width_m`` x ``height_m``, its ends apart from its neighbours' and its base off the footing.
    The top is not asked: a last course that does not fill the height is common and harmless."""
    left, right, below, above = margins
    if max(left, right, below) <= reach_m:
        return None
    return (
        f"wall '{wall.name}' {_source(wall)}: its units stop {left:.3f} m from its left end, {right:.3f} m from its "
        f"right and {below:.3f} m above its base, beyond the joints' reach ({reach_m:g} m): it is built "
        f"{wall.width_m - left - right:.3f} x {wall.height_m - below - above:.3f} m, not {wall.width_m:g} x "
        f"{wall.height_m:g} m, with its ends or base unjoined; {_crop_advice(wall)}"
    )


def check_units_on_the_footing(walls: tuple[WallSpec, ...], margins: list[tuple], reach_m: float) -> None:
    """Refuse a structure in which a wall's lowest unit lies higher above the footing (the lowest
    unit of all its walls: every wall stands on it) than the joints reach: nothing would carry
    that wall, which would drop onto the footing under gravity alone."""
    below = np.array([m[2] for m in margins])
    k = int(np.argmax(below - below.min()))
    if below[k] - below.min() <= reach_m:
        return
    lowest = walls[int(np.argmin(below))]
    wall = walls[k]
    raise InputError(
        f"wall '{wall.name}' {_source(wall)}: its lowest unit starts {below[k] - below.min():.3f} m above the "
        f"footing (the bottom of wall '{lowest.name}'), beyond the joints' reach of {reach_m:g} m: nothing would "
        f"carry it; {_crop_advice(wall)} (or raise max_joint_m in [structure])"
    )


def closure_warning(spec: StructureSpec, gap_xy: np.ndarray) -> str | None:
    """The warning for a footprint that does not close where it is declared closed or looks meant
    to (None: nothing to say). One or two walls never close a footprint: a laboratory wall or an
    L needs no ``closed = false``."""
    gap = float(np.linalg.norm(gap_xy))
    if spec.closed is False or gap <= CLOSURE_WARN_M or (spec.closed is None and len(spec.walls) < 3):
        return None
    if spec.closed is None and not footprint_is_closed(spec):
        return (
            f"footprint is open: its end is {gap:.3f} m (dx {gap_xy[0]:+.3f}, dy {gap_xy[1]:+.3f}) from its start; "
            "set closed = false in [structure] if that is intended, else check width_m and theta_deg"
        )
    return (
        f"footprint does not close: gap {gap * 1000:.1f} mm (dx {gap_xy[0] * 1000:+.1f}, dy {gap_xy[1] * 1000:+.1f} mm); "
        "check the walls' width_m and theta_deg"
    )


def _trace_walls(walls: tuple[WallSpec, ...], spec: StructureSpec) -> list[TraceResult]:
    """:func:`trace_wall` of each of ``walls`` from its mask file: what :func:`build` sends to a
    process of its own."""
    return [trace_wall(w, spec, None, progress=False) for w in walls]


def build(
    spec: StructureSpec,
    *,
    traces: dict[str, TraceResult] | None = None,
    images: dict[str, Photo] | None = None,
    progress: bool | None = None,
    warn_closure: bool = True,
    trace_process: bool = False,
) -> BuildResult:
    """Calibrate and segment every photo wall, trace every wall's mask, scale to metres (Eq. 1),
    place, bond and extrude (Eqs. 2-4); in memory, writing nothing.

    ``traces`` (by wall name) gives walls already traced in memory (:func:`calib_masonry.trace`);
    their mask or photo is then not read; ``images`` (by wall name) gives photo walls' photos in
    memory (:class:`calib_masonry.Photo`), read instead of their files. ``warn_closure`` False: no warning that the footprint
    does not close (a study's perturbed geometry never closes; its gap is an output there).
    ``trace_process`` (what the command line asks for): half of the walls traced from mask files
    are traced in a process of its own (:func:`calib_masonry._threads.background_process`; the
    same traces)."""
    traces_given = dict(traces or {})
    unknown = sorted(set(traces_given) - {w.name for w in spec.walls})
    if unknown:
        raise InputError(
            f"build: traces given for {unknown}, which are not walls of '{spec.name}'; "
            f"its walls are {[w.name for w in spec.walls]}"
        )
    seconds: dict[str, float] = {}
    t0 = time.perf_counter()
    todo = tuple(w for w in spec.walls if w.name not in traces_given)
    resolved, photos = (
        resolve_photo_walls(spec.with_walls(todo), progress=progress, trace=True, images=images) if todo else (spec, {})
    )
    fitted = {w.name: w for w in resolved.walls if w.name not in traces_given}
    spec = spec.with_walls(tuple(fitted.get(w.name, w) for w in spec.walls))
    if photos:  # calibrated, rectified, segmented and (unless they refine) traced
        seconds["photo_walls"] = time.perf_counter() - t0
    traces_given.update({name: pw.trace for name, pw in photos.items() if pw.trace is not None})
    t0 = time.perf_counter()
    # with ``trace_process``, every second wall traced from its mask file (not refined: JAX stays
    # here) is traced in a process of its own while this one traces the others: the trace holds
    # the GIL (two threads took 14.4 s where one after the other took 10.3 s, four 8 x 20 m walls)
    plain = [w for w in spec.walls if w.name not in traces_given and w.name not in photos and not w.refine]
    aside = plain[1::2] if trace_process else []
    elsewhere = {w.name for w in aside}
    by_name: dict[str, TraceResult] = dict(traces_given)
    with background_process(_trace_walls, tuple(aside), spec) if aside else contextlib.nullcontext() as other:
        bar = _progress(total=len(spec.walls), desc="trace walls", unit="wall", enabled=progress)
        done = 0
        for wall in spec.walls:
            if wall.name in by_name or wall.name in elsewhere:
                continue
            pw = photos.get(wall.name)
            by_name[wall.name] = trace_wall(
                wall, spec, pw.mask if pw else None, labels=pw.labels if pw is not None else None
            )
            bar.update()
            done += 1
        if aside:
            by_name.update(zip([w.name for w in aside], other.result()))
        bar.update(len(spec.walls) - done)  # the walls given, and those traced in the other process
        bar.close()
    traces = [by_name[w.name] for w in spec.walls]
    seconds["trace"] = time.perf_counter() - t0
    for wall, tr in zip(spec.walls, traces):
        message = coarse_trace_warning(wall, tr)
        if message:
            warn(message)

    t0 = time.perf_counter()
    walls = []
    for w, (wall, tr) in enumerate(zip(spec.walls, traces)):
        polys = tuple(wall_from_image(b.vertices_xy, tr.image_shape, wall.width_m, wall.height_m) for b in tr.bricks)
        walls.append(
            WallPolygons(
                wall=w,
                ids=tuple(b.id for b in tr.bricks),
                polygons_m=polys,
                dice=tuple(b.dice for b in tr.bricks),
                traced_vertices=tuple(b.traced_vertices for b in tr.bricks),
            )
        )
    seconds["scale"] = time.perf_counter() - t0
    reach = joint_width(spec)
    margins = [unit_margins(wp.polygons_m, w.width_m, w.height_m) for wp, w in zip(walls, spec.walls)]
    check_units_on_the_footing(spec.walls, margins, reach)
    for wall, m in zip(spec.walls, margins):
        message = margin_warning(wall, m, reach)
        if message:
            warn(message)

    t0 = time.perf_counter()
    structure = assemble(spec.footprint, walls, name=spec.name)
    if spec.max_joint_m is not None:
        structure = replace(structure, max_joint_m=spec.max_joint_m)
    seconds["assemble"] = time.perf_counter() - t0
    message = closure_warning(spec, structure.closure_gap_xy) if warn_closure else None
    if message:
        warn(message)
    return BuildResult(structure=structure, traces=tuple(traces), seconds=seconds, photos=photos, spec=spec)

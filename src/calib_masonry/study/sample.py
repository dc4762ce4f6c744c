"""One sample of a study: a pure function of (study, sample) that calls the library's stages.

:func:`run_sample` varies the structure (walls' W, H, theta, t; the mask; the trace's vertex count
or target Dice), builds it in memory and reads the model's outputs; a truth sweep synthesises its
walls (and photos) with the swept generator parameters and compares the build with the exact truth;
with a ``[simulate]`` table it runs Bullet under the sample's load. What does not change between
samples of a worker (a structure file, a mask's trace, a photo's calibration, the simulation
geometry of an unvaried model) is computed once per worker process and cached.

Blender's runs are reproducible on a process's main thread, and only there: driven from another
thread while another Python thread is busy, as a dask worker runs its tasks beside its event loop,
a collapsing run differed by 13-158 mm between two calls and crashed at times
(``experiments/sim_determinism.py --thread --churn``), and importing bpy on that thread does not
help. A dask worker runs a coroutine task on its event loop, which is its process's main thread
(distributed 2026.8): :func:`run_sample_async`, the task a study submits, builds on a thread of
the loop's executor and simulates on the loop's thread, a frame at a time. The same sample gives
the same row on any worker, in any order (``experiments/sim_determinism.py --dask``, and
``tests/test_study.py``: a LocalCluster and a separate ``dask worker``, bit for bit).
"""

from __future__ import annotations

import contextlib
import functools
import math
import time
import warnings
from collections.abc import Iterator
from dataclasses import replace
from pathlib import Path

import numpy as np

from ..errors import CalibMasonryError, InputError
from .design import Sample, Study

__all__ = ["run_sample", "run_sample_async", "outcome", "build_outputs", "evaluate_sample", "ROW_KEYS"]

ROW_KEYS = ("sample", "point", "status", "error", "warnings", "seconds", "worker")  # the bookkeeping columns


@functools.lru_cache(maxsize=8)
def _structure(path: Path, require_sources: bool = True):
    from ..spec import load_structure

    return load_structure(path, require_sources=require_sources)


@functools.lru_cache(maxsize=64)
def _mask(path: Path, dilate_px: int) -> np.ndarray:
    from ..io import read_mask

    return _dilated(read_mask(path, field=f"mask {path}"), dilate_px)


def _disk(r: int) -> np.ndarray:
    """A disk of radius ``r`` px, the structuring element of a mask input's dilation."""
    y, x = np.mgrid[-r : r + 1, -r : r + 1]
    return x * x + y * y <= r * r


def _dilated(mask: np.ndarray, dilate_px: int) -> np.ndarray:
    """The bricks (True) dilated by ``dilate_px`` pixels (eroded if negative), a disk's reach."""
    if dilate_px == 0:
        return mask
    from .._morphology import binary

    # scipy's binary_dilation / binary_erosion's pixels, by OpenCV (4-23x faster on a wall's mask)
    return binary("dilate" if dilate_px > 0 else "erode", mask.astype(bool), structure=_disk(abs(int(dilate_px))))


def _dilated_labels(labels: np.ndarray, dilate_px: int) -> np.ndarray:
    """Pieces labelled where they touch (a photo's partition, a LabelMe file's), each grown by
    ``dilate_px`` pixels into the unlabelled pixels around it (a disk's reach; the nearest piece
    takes a pixel) or, if negative, shrunk by it (a pixel stays where every pixel within reach is
    its piece's): the pieces stay apart, where a mask's would merge."""
    if dilate_px == 0:
        return labels
    from scipy import ndimage

    r = abs(int(dilate_px))
    if dilate_px < 0:
        disk = _disk(r)
        lo = ndimage.grey_erosion(labels, footprint=disk, mode="constant", cval=0)
        hi = ndimage.grey_dilation(labels, footprint=disk, mode="constant", cval=0)
        return np.where((lo == labels) & (hi == labels), labels, 0).astype(labels.dtype)
    dist, (iy, ix) = ndimage.distance_transform_edt(labels == 0, return_indices=True)
    return np.where((labels > 0) | (dist <= r), labels[iy, ix], 0).astype(labels.dtype)


def _traced(
    mask: np.ndarray | None,
    vertices: int | None,
    target_dice: float | None,
    refine: bool,
    what: str,
    labels: np.ndarray | None = None,
):
    """The trace of a (dilated) mask, or of (dilated) ``labels`` where the pieces are labelled, at a
    sample's trace settings."""
    from ..wall2d.refine import RefineConfig
    from ..wall2d.trace import TraceConfig, trace_labels, trace_mask

    config = TraceConfig(
        vertices=vertices,
        target_dice=target_dice if vertices is None else None,
        refine=RefineConfig() if refine else None,
    )
    result = trace_mask(mask, config) if labels is None else trace_labels(labels, config)
    if not result.bricks:
        raise InputError(f"{what}: no bricks found in the mask; narrow [inputs.mask]")
    return result


@functools.lru_cache(maxsize=256)
def _trace(key: tuple, vertices: int | None, target_dice: float | None, refine: bool):
    """The trace of a wall's mask (``key``: ("mask", path, dilate) or ("photo", structure, wall, dilate)):
    of its pieces as labelled where a LabelMe file or the photo's partition labels them (as build
    traces them: a photo wall's 32 stones were traced from its mask as 16), else of its mask."""
    what = f"{key[1]} (dilated by {key[-1]} px)"
    if key[0] == "mask":
        labels = _labelme_labels(key[1])
        if labels is None:
            return _traced(_mask(key[1], key[2]), vertices, target_dice, refine, what)
    else:
        pw = _photo_wall(key[1], key[2])
        if pw.labels is None:
            return _traced(_dilated(pw.mask, key[3]), vertices, target_dice, refine, what)
        labels = pw.labels
    return _traced(None, vertices, target_dice, refine, what, labels=_dilated_labels(labels, key[-1]))


@functools.lru_cache(maxsize=16)
def _labelme_labels(path: Path) -> np.ndarray | None:
    """A LabelMe mask's pieces, labelled (None for a mask image)."""
    if Path(path).suffix.lower() != ".json":
        return None
    from ..io import read_mask_labels

    return read_mask_labels(path, field=f"mask {path}")[1]


@functools.lru_cache(maxsize=32)
def _photo_wall(structure: Path, wall_name: str):
    """A photo wall calibrated on its own scale (its W or H, a measured length, its courses or a
    camera height; the fitted W and H's covariance is what a calibration input draws from). With
    W and H both set free, a wall whose scale was its measured width rested on the eye-height
    prior, and every sample of a study was refused (W and H uncertain by 39 %)."""
    from ..pipeline import photo_wall

    spec = _structure(structure)
    return photo_wall(next(w for w in spec.walls if w.name == wall_name), spec)


def _calibration(structure: Path, wall_name: str) -> tuple[np.ndarray, np.ndarray]:
    fit = _photo_wall(structure, wall_name).calibration.result.fit
    i = [fit.names.index("width_m"), fit.names.index("height_m")]
    return fit.value[i], fit.covariance[np.ix_(i, i)]


def _varied(spec, study: Study, values: dict, source: Path | None, masks: dict | None = None):
    """The structure with the sample's values, the keys of its walls' traces and the values drawn
    from calibrations (W, H by wall). ``masks``: walls' masks in memory by name (a synthetic
    sweep's), keyed ("memory", wall, dilate)."""
    walls, keys, drawn = [], {}, {}
    vertices = values.get("trace.vertices")
    target = values.get("trace.target_dice")
    dilate = int(values.get("mask.dilate_px", 0))
    for w in spec.walls:
        if masks is not None and w.name in masks:
            key = ("memory", w.name, dilate)
        elif w.mask is not None:
            key = ("mask", Path(w.mask), dilate)
        elif source is not None:
            key = ("photo", source, w.name, dilate)
            base = _photo_wall(source, w.name).wall
            w = replace(
                w,
                width_m=base.width_m if math.isnan(w.width_m) else w.width_m,
                height_m=base.height_m if math.isnan(w.height_m) else w.height_m,
            )
        else:
            raise InputError(f"wall '{w.name}': neither a mask nor a photo")
        pair = values.get(f"{w.name}.width_m+height_m")
        if pair is not None:
            from .design import Input

            width, height = Input("", "calibration").value(np.asarray(pair), _calibration(source, w.name))
            if not (width > 0 and height > 0):
                raise InputError(
                    f"wall '{w.name}': the calibration's draw W = {width:g}, H = {height:g} m is not a wall"
                )
            w = replace(w, width_m=width, height_m=height)
            drawn.update({f"{w.name}.width_m": width, f"{w.name}.height_m": height})
        changes = {}
        for field in ("width_m", "height_m", "thickness_m"):
            v = values.get(f"{w.name}.{field}")
            if v is not None:
                if not v > 0:
                    raise InputError(
                        f"{w.name}.{field} = {v:g}: drawn <= 0 m; give a smaller sigma or a positive range"
                    )
                changes[field] = float(v)
        if f"{w.name}.theta_deg" in values:
            changes["theta_rad"] = math.radians(values[f"{w.name}.theta_deg"])
        if vertices is not None:
            changes.update(vertices=int(vertices), target_dice=None)
        elif target is not None:
            changes.update(vertices=None, target_dice=float(target))
        w = replace(w, **changes)
        walls.append(w)
        keys[w.name] = (key, w.vertices, w.target_dice, bool(w.refine))
    spec = spec.with_walls(tuple(walls))
    if "structure.max_joint_m" in values:
        spec = replace(spec, max_joint_m=float(values["structure.max_joint_m"]))
    return spec, keys, drawn


def build_outputs(result) -> dict:
    """The outputs a sample reads from a built model: volume, mass, centre of mass and the like."""
    from ..simulation.scene import MASONRY

    s = result.structure
    vol = np.array([b.volume for b in s.bricks])
    cen = np.array([b.solid.centroid for b in s.bricks])
    com = (vol[:, None] * cen).sum(axis=0) / vol.sum()
    return {
        "total_volume_m3": float(vol.sum()),
        "mass_kg": float(MASONRY.density * vol.sum()),
        "bricks": len(s.bricks),
        "closure_error_m": s.closure_error_m,  # None for an open footprint: no closure to vary
        "com_x_m": float(com[0]),
        "com_y_m": float(com[1]),
        "com_z_m": float(com[2]),
        "mean_dice": float(np.mean([b.dice for b in s.bricks])),
    }


def _sweep_spec(base, values: dict):
    from ..spec import PhotoSpec, SyntheticSpec

    syn = base.synthetic or SyntheticSpec()
    photos = base.photos or PhotoSpec()
    changes = {}  # made at once: SyntheticSpec checks its sizes together (mortar thinner than the units)
    for name, v in values.items():
        table, _, field = name.partition(".")
        if table == "synthetic":
            cur = getattr(syn, field)
            changes[field] = int(v) if isinstance(cur, int) else float(v)
        elif table == "photos":
            cur = getattr(photos, field)
            if isinstance(cur, tuple):
                v = (float(v), float(v))
            elif isinstance(cur, int):
                v = int(v)
            else:
                v = float(v)
            photos = replace(photos, **{field: v})
    return replace(base, synthetic=replace(syn, **changes), photos=photos)


def _sweep(study: Study, sample: Sample) -> tuple[dict, object]:
    """Synthesise the swept walls (and photos) in memory, build them and compare with the exact
    truth: the outputs and the BuildResult. Nothing is written: the masks and photos are the
    synthesis's own, as their files would read back."""
    from ..comparison import compare
    from ..pipeline import build, trace_wall
    from ..synthetic.truth import synthesize

    spec = _sweep_spec(_structure(study.scenario, False), sample.values)
    syn = synthesize(spec, photos=spec.photos if study.photos else None, progress=False)
    values = {k: v for k, v in sample.values.items() if not k.startswith(("synthetic.", "photos."))}
    images = None
    if study.photos:
        built_spec = syn.photo_spec
        images = {w.name: syn.photo(w.image) for w in built_spec.walls}
        if study.fit_size:
            eye = {p["name"]: p["eye_height_m"] for p in syn.truth["photos"]}
            built_spec = built_spec.with_walls(
                tuple(
                    replace(w, width_m=math.nan, height_m=math.nan, camera_height_m=eye[w.name])
                    for w in built_spec.walls
                )
            )
    else:
        built_spec = syn.spec
    if values:
        built_spec, keys, _ = _varied(built_spec, study, values, None, masks=None if study.photos else syn.masks)
        traces = {
            n: _traced(_dilated(syn.masks[n], k[0][2]), *k[1:], what=f"wall '{n}'")
            if k[0][0] == "memory"
            else _trace(*k)
            for n, k in keys.items()
        }
    elif not study.photos:
        traces = {w.name: trace_wall(w, built_spec, syn.masks[w.name], progress=False) for w in built_spec.walls}
    else:
        traces = None
    result = build(built_spec, traces=traces, images=images, progress=False, warn_closure=False)  # its gap is an output
    m = compare(result.structure, syn.structure)  # the synthesis's own exact truth, not built again
    out = build_outputs(result)
    out.update(
        precision=m["precision"],
        recall=m["recall"],
        dice_mean=m["dice"]["mean"],
        dice_min=m["dice"]["min"],
        centroid_error_mm=m["centroid_error_mm"]["mean"],
        volume_relative_error=m["total_volume_m3"]["relative_error"],
        max_abs_width_error_m=m["max_abs_width_error_m"],
        max_abs_height_error_m=m["max_abs_height_error_m"],
        max_abs_theta_error_deg=m["max_abs_theta_error_deg"],
    )
    for w in m["walls"]:
        out[f"{w['wall']}.width_error_m"] = w["width_error_m"]
        out[f"{w['wall']}.height_error_m"] = w["height_error_m"]
        out[f"{w['wall']}.dice_mean"] = w["dice"]["mean"]
    return out, result


def evaluate_sample(study: Study, sample: Sample) -> tuple[dict, tuple | None]:
    """The sample's build outputs, and the simulation it asks for (model geometry, load) or None."""
    from ..pipeline import build

    if study.scenario is not None:
        outputs, result = _sweep(study, sample)
    else:
        spec, keys, drawn = _varied(_structure(study.structure), study, sample.values, study.structure)
        result = build(spec, traces={n: _trace(*k) for n, k in keys.items()}, progress=False, warn_closure=False)
        outputs = {**drawn, **build_outputs(result)}
    job = _simulation(study, sample, result.structure, result.spec.material) if study.simulate is not None else None
    return outputs, job


_GEOMETRY: dict = {}  # the simulation geometry of an unvaried model, once per worker


def _simulation(study: Study, sample: Sample, structure, material: tuple = ()) -> tuple:
    """The sample's simulation: the model's geometry, the load and the material (the structure's
    [material] ``material``, as its spec holds it, with the sample's drawn values)."""
    from ..build_folder import simulation_geometry
    from ..simulation.ground_motion import synthetic_motion
    from ..simulation.scene import Pushover

    sim = study.simulate
    varied = (
        any(not k.startswith(("synthetic.", "photos.", "material.")) for k in sample.values)
        or study.scenario is not None
    )
    if varied:
        geometry = simulation_geometry(structure)
    else:  # every sample simulates the same model: its contact geometry once per worker
        key = (str(study.structure), study.fingerprint())
        if key not in _GEOMETRY:
            _GEOMETRY.clear()
            _GEOMETRY[key] = simulation_geometry(structure)
        geometry = _GEOMETRY[key]
    if sim.pushover:
        load = Pushover(
            rate_g_per_s=sim.pushover_rate_g_per_s, direction_deg=sim.direction_deg, max_g=sim.pushover_max_g
        )
    elif sim.accelerograms:
        load = _recorded(
            sim.accelerograms[sample.load["record"]],
            sample.load["pga_g"],
            sim.direction_deg,
            sim.record_units,
            sim.record_dt_s,
        )
    else:
        load = synthetic_motion(
            sample.load["pga_g"],
            sim.duration_s,
            seed=study.seed * 1000 + sample.load["record"],
            direction_deg=sim.direction_deg,
        )
    return geometry, load, _material(sample, material)


_RECORDS: dict[tuple, object] = {}  # a worker's records (and units, time step), read once


def _recorded(
    files: tuple[Path, ...],
    pga_g: float,
    direction_deg: float = 0.0,
    units: str | None = None,
    dt: float | None = None,
):
    """The recorded motion of ``files`` (one file, or its X and Y components) scaled so that its peak
    is ``pga_g``, as ``simulate --accelerogram ... --pga`` scales it; a one-component record (one
    file of one component) along ``direction_deg`` from global X, as a study's synthetic motions."""
    from ..simulation.ground_motion import read_accelerogram

    key = (files, units, dt)
    if key not in _RECORDS:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # said once, when the study file was read
            _RECORDS[key] = read_accelerogram(
                files[0], units=units, path_y=files[1] if len(files) == 2 else None, dt=dt
            )
    record = _RECORDS[key]
    if direction_deg and not record.displacement[:, 1].any():
        record = record.along(direction_deg)
    return record.at_pga(pga_g)


def _material(sample: Sample, base: tuple = ()):
    """The sample's material: the structure's [material] ``base`` (or the defaults) with its drawn values."""
    from ..simulation.scene import material_from_table

    drawn = {k.split(".", 1)[1]: float(v) for k, v in sample.values.items() if k.startswith("material.")}
    return material_from_table({**dict(base), **drawn}, f"sample {sample.index}")


def _unchecked_fraction(summary: dict) -> float | None:
    unchecked, bonds = summary.get("bonds_unchecked"), summary.get("bonds") or 0
    return None if unchecked is None else (unchecked / bonds if bonds else 0.0)


def outcome(result) -> dict:
    """What a study keeps of a :class:`~calib_masonry.simulation.run.SimulationResult`."""
    m = result.metrics
    moved = float(m.moved_fraction[-1])
    out = {
        "moved_fraction": moved,
        "toppled_fraction": m.toppled_fraction,
        "cracked_fraction": float(m.broken_fraction[-1]),
        # the joints not checked since their piece was set free (None with --piece-joints): a larger
        # PGA frees a piece sooner, and its cracked_fraction can be the smaller
        "unchecked_fraction": _unchecked_fraction(result.summary),
        "roof_drift_m": float(m.roof_drift_m[-1]),
        "max_displacement_m": float(m.max_displacement_m.max()) if len(m.max_displacement_m) else 0.0,
        "outcome": m.outcome,
        "collapsed": int(m.outcome == "collapsed"),
        "collapse_time_s": m.collapse_time_s,  # None unless the outcome is collapsed
    }
    if result.curve is not None:
        cm = result.collapse_multiplier_g
        out["collapse_multiplier_g"] = None if cm is None else float(cm)
    return out


def warm_worker(simulate: bool = False) -> None:
    """Import the stages a sample calls, once per worker when the study starts, so that the first
    sample of each worker does not pay for them (run on every worker by the study's client, on its
    event loop: the worker's main thread, where Blender is then started if the study simulates).
    A warning outside a sample's row (which records its own) is one line, as the CLI prints them."""
    import warnings

    from ..preload import preload
    from ..process import print_warning

    warnings.showwarning = print_warning
    preload("study")

    if simulate:
        from ..simulation.blender import require_bpy

        require_bpy()


def _worker_name() -> str:
    try:
        from distributed import get_worker

        return str(get_worker().name)
    except (ImportError, ValueError):
        return "local"


@contextlib.contextmanager
def _row(sample: Sample) -> Iterator[dict]:
    """The row of one sample, which the block fills with the sample's outputs: its index, inputs,
    status (``ok``, or ``failed`` with the block's one-line error, which ends the block but is not
    raised, so that a study goes on; an interrupt or a cancellation is raised), the warnings the
    block raised, seconds and worker."""
    t0 = time.perf_counter()
    row: dict = {"sample": sample.index, "point": sample.point}
    row.update(sample.load)
    for k, v in sample.values.items():
        if isinstance(v, tuple):  # a calibration pair's cube coordinates
            continue
        row[k] = v
    caught: list = []
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            yield row
        row.update(status="ok", error="")
    except CalibMasonryError as exc:
        row.update(status="failed", error=str(exc).splitlines()[0] if str(exc) else type(exc).__name__)
    except Exception as exc:  # a bug or a library's error: recorded, the study goes on
        row.update(status="failed", error=f"{type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else ''}")
    row["warnings"] = "; ".join(sorted({str(w.message).splitlines()[0] for w in caught}))
    row["seconds"] = round(time.perf_counter() - t0, 3)
    row["worker"] = _worker_name()


def run_sample(study: Study, sample: Sample) -> dict:
    """The row of one sample (see :func:`_row`), computed on the calling thread: for a study run in
    this process, whose simulations then run on the caller's thread (the main one, from the CLI)."""
    from ..simulation.run import simulate

    with _row(sample) as row:
        outputs, job = evaluate_sample(study, sample)
        if job is not None:
            geometry, load, material = job
            outputs.update(
                outcome(
                    simulate(
                        geometry,
                        load,
                        study.simulate.solver,
                        material=material,
                        progress=False,
                        joints_ahead=False,
                        bullet=study.simulate.bullet,
                    )
                )
            )
        row.update(outputs)
    return row


async def run_sample_async(study: Study, sample: Sample) -> dict:
    """:func:`run_sample` as a dask task runs it: a coroutine, which a dask worker runs on its event
    loop, its process's main thread. The build runs on a thread of the loop's executor; the
    simulation runs on the loop's own thread (:func:`calib_masonry.simulation.run.simulate_async`),
    where Blender's runs are reproducible, handing the loop back between frames, so that the
    worker keeps answering its scheduler. The same row as :func:`run_sample`."""
    import asyncio

    from .._threads import loop_lock
    from ..simulation.run import simulate_async

    # one sample at a time per worker, whatever its threads: a sample's warnings are caught for the
    # process, and two interleaved catches would mix them up
    async with loop_lock("sample"):
        with _row(sample) as row:
            outputs, job = await asyncio.to_thread(evaluate_sample, study, sample)
            if job is not None:
                geometry, load, material = job
                outputs.update(
                    outcome(
                        await simulate_async(
                            geometry,
                            load,
                            study.simulate.solver,
                            material=material,
                            progress=False,
                            bullet=study.simulate.bullet,
                        )
                    )
                )
            row.update(outputs)
    return row

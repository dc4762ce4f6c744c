"""A study file: what varies, how it is sampled, what each sample runs; and its design table.

A study is many independent runs of the same stages. The file (TOML) names a structure (or, for a
truth sweep, a synthetic scenario), the inputs that vary and how, the sampling, and optionally the
simulation every sample runs::

    [study]
    name = "paper_example_geometry"
    structure = "../paper_example/structure.toml"   # or scenario = "...scenario.toml" (a truth sweep)

    [sampling]
    method = "lhs"          # mc | lhs | sobol (Saltelli's scheme; n is its base sample, a power of 2)
    n = 64
    seed = 1

    [inputs.wall1]          # a wall by name; [inputs.every_wall] gives each wall the same law, drawn apart
    width_m = { sigma = 0.02 }             # normal about the structure's value (metres)
    height_m = { range = [6.00, 6.10] }    # uniform
    theta_deg = { sigma = 0.5 }
    # from_calibration = true  # a photo wall: W and H jointly from its calibration's covariance

    [inputs.mask]
    dilate_px = { range = [-2, 2] }        # the segmentation's uncertainty: erode (<0) or dilate (>0) the bricks

    [inputs.trace]
    vertices = { choices = [4, 5, 6, 8] }  # or target_dice = { range = [0.95, 0.99] }

    [inputs.structure]
    max_joint_m = { range = [0.05, 0.08] } # the widest mortar joint two units are joined across

    [inputs.material]       # any key of a [material] table, about the structure's value (or the defaults)
    friction = { range = [0.5, 0.8] }
    tensile_strength_mpa = { sigma = 0.05 }

    [sweep]                 # a truth sweep: generator parameters of `synth`, each a list or {from, to, n}
    "photos.yaw_deg" = [0, 10, 20, 30]
    "synthetic.seed" = [1, 2]

    [simulate]              # optional: every design point is simulated under each load
    pga_g = [0.1, 0.2, 0.3]
    records = 2             # seeded records per PGA (the same records at every PGA, scaled)
    duration_s = 5.0
    # accelerograms = ["RSN766_G02_000.AT2", ["E.ASC", "N.ASC"]]  # instead of records: recorded
    #                        # motions (a file, or its X and Y components), each scaled to every PGA
    #                        # and run for its whole length
    # units = "cm/s2"        # of CSV accelerograms (g by default, "m/s2", "cm/s2")
    # pushover = true        # instead: the collapse multiplier
    # check_interval_s = 0.0025  # the joint model's check interval (default 0.005 s, simulate
    #                        # --check-interval): a fragility's median run again at half of it
    #                        # says whether it has converged

Each input maps one coordinate ``u`` of the unit hypercube to a value (normal: ``mu + sigma
Phi^-1(u)``; uniform: ``a + (b - a) u``; choices: the ``floor(k u)``-th; calibration: ``mu + L
Phi^-1(u1, u2)`` with ``L L^T`` the reported covariance of (W, H)), so Monte Carlo, Latin hypercube
and Sobol' designs all draw in the same cube. A sweep's design is the grid of its lists (times the
inputs' draws, if any). Sample ``k`` is design point ``k // loads`` under load ``k % loads``: a pure
function of (study, k).
"""

from __future__ import annotations

import dataclasses
import difflib
import hashlib
import itertools
import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import InputError

__all__ = [
    "Input",
    "SimulateSpec",
    "Study",
    "Sample",
    "load_study",
    "parse_study",
    "design",
    "samples",
    "WALL_FIELDS",
    "SWEEP_FIELDS",
]

WALL_FIELDS = ("width_m", "height_m", "theta_deg", "thickness_m")
MASK_FIELDS = ("dilate_px",)
TRACE_FIELDS = ("vertices", "target_dice")
STRUCTURE_FIELDS = ("max_joint_m",)  # [inputs.structure]: the model's own settings that may vary
# generator parameters of `synth` a truth sweep may vary: table -> fields
SWEEP_FIELDS = {
    "synthetic": (
        "seed",
        "px_per_m",
        "irregularity",
        "edge_blur_px",
        "edge_noise",
        "mortar_m",
    ),
    "photos": (
        "yaw_deg",
        "distance_m",
        "blur_px",
        "noise",
        "focal_35mm",
        "eye_height_m",
        "long_side_px",
        "short_side_px",
        "jpeg_quality",
    ),
}
METHODS = ("mc", "lhs", "sobol")
MAX_SAMPLES = 1_000_000


@dataclass(frozen=True)
class Input:
    """One varying input: ``name`` ("wall1.width_m", "mask.dilate_px", "trace.vertices", or for a
    calibration pair "wall1.width_m+height_m") and its law: ``normal`` (``sigma`` about ``mean``),
    ``uniform`` (``low``, ``high``), ``choices`` or ``calibration`` (``mean`` and ``cov`` of (W, H),
    filled in when the sample runs the calibration). ``integer`` rounds the value."""

    name: str
    law: str
    mean: float = math.nan
    sigma: float = 0.0
    low: float = math.nan
    high: float = math.nan
    choices: tuple = ()
    integer: bool = False

    @property
    def dims(self) -> int:
        return 2 if self.law == "calibration" else 1

    def value(self, u: np.ndarray, calibration=None):
        """The input's value(s) at unit-cube coordinate(s) ``u`` (a float, or a pair for a calibration)."""
        from scipy.stats import norm

        if self.law == "normal":
            v = self.mean + self.sigma * float(norm.ppf(_open(u[0])))
        elif self.law == "uniform":
            v = self.low + (self.high - self.low) * float(u[0])
        elif self.law == "choices":
            return self.choices[min(int(float(u[0]) * len(self.choices)), len(self.choices) - 1)]
        else:  # calibration: (W, H) jointly
            mean, cov = calibration
            z = norm.ppf(_open(np.asarray(u[:2], dtype=float)))
            w, h = np.asarray(mean, dtype=float) + np.linalg.cholesky(_psd(cov)) @ z
            return float(w), float(h)
        return int(round(v)) if self.integer else v


def _open(u):
    return np.clip(u, 1e-12, 1.0 - 1e-12)  # Phi^-1 of an LHS or Sobol' point on the cube's face


def _psd(cov) -> np.ndarray:
    c = np.asarray(cov, dtype=float)
    return c + np.eye(len(c)) * 1e-18 * max(1.0, float(np.trace(c)))


@dataclass(frozen=True)
class SimulateSpec:
    """What each design point runs in Bullet: every PGA (g) times ``records`` seeded records of
    ``duration_s`` seconds (or times each of ``accelerograms``, recorded motions scaled to the PGA:
    one file, or the X and Y components' two), or (``pushover``) one pushover along
    ``direction_deg``."""

    pga_g: tuple[float, ...] = ()
    records: int = 1
    accelerograms: tuple[tuple[Path, ...], ...] = ()
    record_units: str | None = None  # of CSV accelerograms: "g" (None: the default), "m/s2" or "cm/s2"
    record_dt_s: float | None = None  # of accelerograms of accelerations alone (no time column)
    duration_s: float = 5.0
    pushover: bool = False
    direction_deg: float = 0.0
    pushover_rate_g_per_s: float = 0.05
    pushover_max_g: float = 5.0
    # False: each run without Bullet (simulate's bullet=False): the same outputs, which the verdict's
    # pieces decide, without Bullet's animation of the freed pieces (most of a run's time)
    bullet: bool = True
    # the joint model's check interval (s; SolverSettings.check_interval_s's default, simulate
    # --check-interval)
    check_interval_s: float = 0.005

    @property
    def solver(self):
        """The :class:`~calib_masonry.simulation.scene.SolverSettings` every run of the study uses."""
        from ..simulation.scene import SolverSettings

        return SolverSettings(check_interval_s=self.check_interval_s)

    @property
    def loads(self) -> tuple[dict, ...]:
        if self.pushover:
            return ({"pushover": True},)
        n = len(self.accelerograms) or self.records
        return tuple({"pga_g": p, "record": r} for p in self.pga_g for r in range(n))


@dataclass(frozen=True)
class Study:
    """A parsed study file (see the module docstring); ``source`` is the file it came from."""

    name: str
    structure: Path | None
    scenario: Path | None
    method: str
    n: int
    seed: int
    inputs: tuple[Input, ...]
    sweep: tuple[tuple[str, tuple], ...] = ()
    simulate: SimulateSpec | None = None
    photos: bool = False  # a sweep renders perspective photos and builds from them
    fit_size: bool = True  # a photo sweep fits W and H (camera height given) rather than typing them
    source: Path | None = field(default=None, compare=False)

    @property
    def loads(self) -> tuple[dict, ...]:
        return self.simulate.loads if self.simulate is not None else ({},)

    @property
    def dims(self) -> int:
        return sum(i.dims for i in self.inputs)

    def fingerprint(self) -> str:
        """A hash of everything a sample's result depends on: the study's parsed content and the
        bytes of the structure or scenario file (not of the masks and photos it names)."""
        h = hashlib.sha256()
        h.update(
            repr((self.name, self.method, self.n, self.seed, self.inputs, self.sweep, _lean(self.simulate))).encode()
        )
        h.update(repr((self.photos, self.fit_size)).encode())
        records = [f for r in self.simulate.accelerograms for f in r] if self.simulate is not None else []
        for p in (self.structure, self.scenario, *records):
            if p is not None:
                h.update(Path(p).read_bytes())
        return h.hexdigest()[:16]


#: SimulateSpec's fields added after studies were first run: left out of the fingerprint where at
#: their default, so that a study folder of the code before them resumes
_LATER_FIELDS = ("record_units", "record_dt_s")


def _lean(sim):
    """``repr(sim)`` (a SimulateSpec or None) without the fields of :data:`_LATER_FIELDS` that keep
    their default: the repr the code before them wrote."""
    if sim is None:
        return None
    kept = [
        f"{f.name}={getattr(sim, f.name)!r}"
        for f in dataclasses.fields(sim)
        if f.repr and not (f.name in _LATER_FIELDS and getattr(sim, f.name) == f.default)
    ]
    return _Repr(f"{type(sim).__qualname__}({', '.join(kept)})")


class _Repr(str):
    """A string whose repr is itself (it stands in a tuple's repr for the object it describes)."""

    def __repr__(self) -> str:
        return str(self)


@dataclass(frozen=True)
class Sample:
    """One row of the design: its index, design point, load and input values by name."""

    index: int
    point: int
    load: dict
    values: dict


def _where(path: Path, key: str) -> str:
    return f"{path}: {key}"


def _unknown(path: Path, where: str, keys, valid) -> None:
    """An unknown key names the closest valid one (the structure file's rule)."""
    from ..spec import _check_keys

    _check_keys(dict.fromkeys(keys), valid, f"{path}: {where}", "key")


def _number(path: Path, key: str, value, *, positive=False, nonneg=False, integer=False) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise InputError(f"{_where(path, key)} = {value!r}: give a finite number")
    if integer and int(value) != value:
        raise InputError(f"{_where(path, key)} = {value!r}: give a whole number")
    if positive and not value > 0:
        raise InputError(f"{_where(path, key)} = {value!r}: must be > 0")
    if nonneg and not value >= 0:
        why = " (a spread cannot be negative)" if key.endswith(".sigma") else ""  # not a PGA's, a seed's
        raise InputError(f"{_where(path, key)} = {value!r}: must be >= 0{why}")
    return int(value) if integer else float(value)


def _law(path: Path, name: str, spec, *, mean: float, integer: bool = False) -> Input:
    key = f"[inputs] {name}"
    if not isinstance(spec, dict):
        raise InputError(
            f"{path}: {key} = {spec!r}: give a law, {{ sigma = S }} (normal about the structure's value), "
            "{ range = [LOW, HIGH] } (uniform) or { choices = [...] }"
        )
    _unknown(path, f"[inputs] {name}", spec, ("sigma", "mean", "range", "choices"))
    laws = [k for k in ("sigma", "range", "choices") if k in spec]
    if len(laws) != 1:
        raise InputError(f"{path}: {key}: give exactly one of sigma, range or choices (got {laws or 'none'})")
    if "sigma" in spec:
        sigma = _number(path, f"{key}.sigma", spec["sigma"], nonneg=True)
        if "mean" in spec:
            mu = _number(path, f"{key}.mean", spec["mean"])
        elif math.isnan(mean):  # (checked before the number: "mean = nan: give a finite number" was said)
            raise InputError(f"{path}: {key}: the structure gives no value to vary about; add mean = ...")
        else:
            mu = mean
        return Input(name, "normal", mean=mu, sigma=sigma, integer=integer)
    if "range" in spec:
        r = spec["range"]
        if not (isinstance(r, list) and len(r) == 2):
            raise InputError(f"{path}: {key}.range = {r!r}: give [LOW, HIGH]")
        lo, hi = (_number(path, f"{key}.range", x) for x in r)
        if not hi >= lo:
            raise InputError(f"{path}: {key}.range = {r!r}: LOW must not exceed HIGH")
        if integer:
            return Input(name, "choices", choices=tuple(range(math.ceil(lo), math.floor(hi) + 1)), integer=True)
        return Input(name, "uniform", low=lo, high=hi)
    ch = spec["choices"]
    if not (isinstance(ch, list) and ch):
        raise InputError(f"{path}: {key}.choices = {ch!r}: give a non-empty list")
    return Input(name, "choices", choices=tuple(_number(path, f"{key}.choices", x, integer=integer) for x in ch))


def _sweep_values(path: Path, key: str, spec) -> tuple:
    if isinstance(spec, list) and spec:
        return tuple(_number(path, f"[sweep] {key}", x) for x in spec)
    if isinstance(spec, dict):
        _unknown(path, f"[sweep] {key}", spec, ("from", "to", "n"))
        if set(spec) != {"from", "to", "n"}:
            raise InputError(f"{path}: [sweep] {key}: give a list or {{ from = A, to = B, n = N }}")
        n = _number(path, f"[sweep] {key}.n", spec["n"], positive=True, integer=True)
        a, b = _number(path, f"[sweep] {key}.from", spec["from"]), _number(path, f"[sweep] {key}.to", spec["to"])
        return tuple(float(x) for x in np.linspace(a, b, n))
    raise InputError(f"{path}: [sweep] {key} = {spec!r}: give a non-empty list or {{ from = A, to = B, n = N }}")


def load_study(path: str | Path) -> Study:
    """Read and check a study file; every error names the file and key and says what to do."""
    from ..io import read_toml

    path = Path(path)
    return parse_study(read_toml(path, "study file"), path)


def parse_study(data: dict, path: Path) -> Study:
    """A :class:`Study` from a study file's parsed TOML ``data`` (``path`` names it in messages and
    anchors its relative paths)."""
    from ..spec import load_structure

    _unknown(path, "top level", data, ("study", "sampling", "inputs", "sweep", "simulate"))
    head = data.get("study")
    if not isinstance(head, dict):
        raise InputError(f"{path}: no [study] table; add one with name and structure (or scenario)")
    _unknown(path, "[study]", head, ("name", "structure", "scenario", "photos", "fit_size"))
    name = head.get("name", path.stem)
    if not isinstance(name, str) or not name:
        raise InputError(f"{path}: [study] name = {name!r}: give a non-empty string")
    if ("structure" in head) == ("scenario" in head):
        raise InputError(f"{path}: [study]: give exactly one of structure (a model) or scenario (a truth sweep)")
    key = "structure" if "structure" in head else "scenario"
    src = (path.parent / str(head[key])).resolve()
    if not src.is_file():
        raise InputError(
            f"{path}: [study] {key} = {head[key]!r}: no such file ({src}); give a path relative to the study file"
        )
    spec = load_structure(src, require_sources=(key == "structure"))
    if key == "scenario" and spec.synthetic is None:
        raise InputError(
            f"{path}: [study] scenario {src}: it has no [synthetic] table; give a scenario file of `synth`"
        )
    walls = {w.name: w for w in spec.walls}

    samp = data.get("sampling", {})
    if not isinstance(samp, dict):
        raise InputError(f"{path}: [sampling] must be a table (method, n, seed)")
    _unknown(path, "[sampling]", samp, ("method", "n", "seed"))
    method = samp.get("method", "mc" if "sweep" not in data else "grid")
    inputs_table = data.get("inputs", {})
    if not isinstance(inputs_table, dict):
        raise InputError(f"{path}: [inputs] must be a table of tables ([inputs.WALL], [inputs.mask], ...)")
    inputs: list[Input] = []
    for group, table in inputs_table.items():
        if not isinstance(table, dict):
            raise InputError(f"{path}: [inputs] {group} = {table!r}: give a table [inputs.{group}]")
        if group == "mask":
            _unknown(path, "[inputs.mask]", table, MASK_FIELDS)
            inputs += [_law(path, f"mask.{k}", v, mean=0.0, integer=True) for k, v in table.items()]
        elif group == "material":
            from ..simulation.scene import MATERIAL_KEYS, material_from_table, material_table

            _unknown(path, "[inputs.material]", table, tuple(MATERIAL_KEYS))
            base = material_table(material_from_table(dict(spec.material), str(src)))
            for k, v in table.items():
                # the masonry's modulus at 0 is "not given" (the mortar and the units in series), no
                # value to vary about: a normal about it drew negative moduli for half the samples
                given = not (k in ("masonry_youngs_modulus_mpa", "masonry_compressive_strength_mpa") and base[k] == 0)
                inp = _law(path, f"material.{k}", v, mean=base[k] if given else math.nan)
                for x in inp.choices or (inp.low, inp.high):  # the bounds a draw can take, checked now
                    if isinstance(x, (int, float)) and math.isfinite(x):
                        material_from_table({**dict(spec.material), k: x}, f"{path}: [inputs.material] {k}")
                inputs.append(inp)
        elif group == "structure":
            from ..build3d.assemble import joint_width
            from ..spec import MAX_JOINT_M, MIN_JOINT_M

            _unknown(path, "[inputs.structure]", table, STRUCTURE_FIELDS)
            for k, v in table.items():
                inp = _law(path, f"structure.{k}", v, mean=joint_width(spec))
                bounds = [x for x in (inp.choices or (inp.low, inp.high)) if math.isfinite(x)]
                bad = [x for x in bounds if not MIN_JOINT_M <= x <= MAX_JOINT_M]
                if bad:
                    raise InputError(
                        f"{path}: [inputs.structure] {k}: {bad} out of range ({MIN_JOINT_M:g}..{MAX_JOINT_M:g} m: "
                        "the widest mortar joint two units are joined across)"
                    )
                inputs.append(inp)
        elif group == "trace":
            _unknown(path, "[inputs.trace]", table, TRACE_FIELDS)
            for k, v in table.items():
                default = spec.vertices if k == "vertices" else spec.target_dice
                inp = _law(
                    path, f"trace.{k}", v, mean=math.nan if default is None else default, integer=k == "vertices"
                )
                vals = inp.choices or (inp.low, inp.high)
                bad = [x for x in vals if (k == "vertices" and x < 3) or (k == "target_dice" and not 0 < x <= 1)]
                if bad:
                    raise InputError(
                        f"{path}: [inputs.trace] {k}: {bad} out of range (vertices >= 3, 0 < target_dice <= 1)"
                    )
                inputs.append(inp)
        else:
            targets = list(walls) if group == "every_wall" else [group]
            if group not in walls and group != "every_wall":
                close = difflib.get_close_matches(
                    group, [*walls, "every_wall", "mask", "trace", "material", "structure"], n=1
                )
                raise InputError(
                    f"{path}: [inputs.{group}]: '{spec.name}' has no wall '{group}'"
                    + (f"; did you mean {close[0]}?" if close else f"; its walls are {', '.join(walls)}")
                )
            _unknown(path, f"[inputs.{group}]", table, (*WALL_FIELDS, "from_calibration"))
            for wname in targets:
                wall = walls[wname]
                if table.get("from_calibration", False) is True:
                    if wall.image is None:
                        raise InputError(
                            f"{path}: [inputs.{group}] from_calibration: wall '{wname}' has no photo to calibrate; "
                            "give W and H laws instead"
                        )
                    if "width_m" in table or "height_m" in table:
                        raise InputError(
                            f"{path}: [inputs.{group}]: from_calibration draws W and H; remove width_m and height_m"
                        )
                    inputs.append(Input(f"{wname}.width_m+height_m", "calibration"))
                elif "from_calibration" in table and table["from_calibration"] is not False:
                    raise InputError(
                        f"{path}: [inputs.{group}] from_calibration = {table['from_calibration']!r}: give true or false"
                    )
                for k in WALL_FIELDS:
                    if k in table:
                        inputs.append(_law(path, f"{wname}.{k}", table[k], mean=getattr(wall, k)))

    sweep: list[tuple[str, tuple]] = []
    sw = data.get("sweep", {})
    if not isinstance(sw, dict):
        raise InputError(f"{path}: [sweep] must be a table of generator parameters")
    if sw and key != "scenario":
        raise InputError(f"{path}: [sweep] varies the synthetic generator; name a scenario in [study], not a structure")
    valid = [f"{t}.{f}" for t, fs in SWEEP_FIELDS.items() for f in fs]
    for k, v in sw.items():
        _unknown(path, "[sweep]", [k], valid)
        sweep.append((k, _sweep_values(path, k, v)))
    photos = bool(head.get("photos", any(k.startswith("photos.") for k, _ in sweep)))
    fit_size = head.get("fit_size", True)
    if not isinstance(fit_size, bool):
        raise InputError(f"{path}: [study] fit_size = {fit_size!r}: give true or false")

    if sweep and "method" not in samp:
        method = "grid" if not inputs else "mc"
    if method not in (*METHODS, "grid"):
        close = difflib.get_close_matches(str(method), [*METHODS, "grid"], n=1)
        raise InputError(
            f"{path}: [sampling] method = {method!r}: unknown"
            + (f"; did you mean {close[0]}?" if close else f"; use one of {', '.join(METHODS)}")
        )
    if method == "grid" and inputs:
        raise InputError(f"{path}: [sampling] method = 'grid' takes no [inputs]; use mc, lhs or sobol to draw them")
    n = _number(path, "[sampling] n", samp.get("n", 1), positive=True, integer=True)
    if n > MAX_SAMPLES:  # before the design is drawn (n = 1e9 ran out of memory drawing it)
        raise InputError(f"{path}: [sampling] n = {n:.6g}: at most {MAX_SAMPLES} samples; lower n")
    seed = _number(path, "[sampling] seed", samp.get("seed", 0), nonneg=True, integer=True)
    if method == "sobol":
        if n & (n - 1):
            raise InputError(
                f"{path}: [sampling] n = {n}: Saltelli's scheme needs a power of 2 (say {1 << n.bit_length()})"
            )
        if not inputs:
            raise InputError(f"{path}: [sampling] method = 'sobol': give at least one input in [inputs]")
    if method in METHODS and not inputs and not sweep and "simulate" not in data:
        raise InputError(f"{path}: nothing varies; add [inputs], a [sweep] or a [simulate] table")

    sim = None
    if "simulate" in data:
        s = data["simulate"]
        if not isinstance(s, dict):
            raise InputError(f"{path}: [simulate] must be a table (pga_g, records, duration_s or pushover)")
        _unknown(
            path,
            "simulate",
            s,
            (
                "pga_g",
                "records",
                "accelerograms",
                "units",
                "dt_s",
                "duration_s",
                "pushover",
                "direction_deg",
                "rate_g_per_s",
                "max_g",
                "bullet",
                "check_interval_s",
            ),
        )
        pushover = s.get("pushover", False)
        bullet = s.get("bullet", True)
        if not isinstance(bullet, bool):
            raise InputError(f"{path}: [simulate] bullet = {bullet!r}: give true or false")
        if pushover and not bullet:
            raise InputError(
                f"{path}: [simulate] bullet = false: only for ground motions (a pushover ends where Bullet's "
                "poses run away); drop it or run the pushover with Bullet"
            )
        if not isinstance(pushover, bool):
            raise InputError(f"{path}: [simulate] pushover = {pushover!r}: give true or false")
        pga = s.get("pga_g", [])
        if isinstance(pga, (int, float)):
            pga = [pga]
        if not isinstance(pga, list):
            raise InputError(f"{path}: [simulate] pga_g = {pga!r}: give a list of peak ground accelerations in g")
        pga = tuple(_number(path, "[simulate] pga_g", p, nonneg=True) for p in pga)
        if any(p > 5 for p in pga):
            raise InputError(
                f"{path}: [simulate] pga_g = {list(pga)}: a PGA above 5 g is not an earthquake; give g units"
            )
        if pushover == bool(pga):
            raise InputError(f"{path}: [simulate]: give either pga_g = [...] or pushover = true")
        units, dt = _record_units(path, s)
        accelerograms = _accelerograms(path, s, units, dt)
        if accelerograms and pushover:
            raise InputError(f"{path}: [simulate]: give either accelerograms = [...] or pushover = true")
        records = _number(path, "[simulate] records", s.get("records", 1), positive=True, integer=True)
        if max(1, len(pga)) * records > MAX_SAMPLES:  # before the loads are listed (1e9 records ran out of memory)
            raise InputError(
                f"{path}: [simulate] records = {records:.6g}: {max(1, len(pga))} PGA(s) x {records:.6g} records is "
                f"more than {MAX_SAMPLES} runs; lower records"
            )
        sim = SimulateSpec(
            pga_g=pga,
            records=records,
            accelerograms=accelerograms,
            record_units=units,
            record_dt_s=dt,
            duration_s=_number(path, "[simulate] duration_s", s.get("duration_s", 5.0), positive=True),
            pushover=pushover,
            direction_deg=_number(path, "[simulate] direction_deg", s.get("direction_deg", 0.0)),
            pushover_rate_g_per_s=_number(path, "[simulate] rate_g_per_s", s.get("rate_g_per_s", 0.05), positive=True),
            pushover_max_g=_number(path, "[simulate] max_g", s.get("max_g", 5.0), positive=True),
            bullet=bullet,
            check_interval_s=_number(
                path,
                "[simulate] check_interval_s",
                s.get("check_interval_s", SimulateSpec.check_interval_s),
                positive=True,
            ),
        )
        if sim.check_interval_s > 0.1:
            raise InputError(
                f"{path}: [simulate] check_interval_s = {sim.check_interval_s:g}: the joints' check interval must be "
                f"in (0, 0.1] s (default {SimulateSpec.check_interval_s:g})"
            )
        if sim.duration_s > 600:
            raise InputError(f"{path}: [simulate] duration_s = {sim.duration_s:g}: at most 600 s per run")
    study = Study(
        name=name,
        structure=src if key == "structure" else None,
        scenario=src if key == "scenario" else None,
        method=method,
        n=n,
        seed=seed,
        inputs=tuple(inputs),
        sweep=tuple(sweep),
        simulate=sim,
        photos=photos,
        fit_size=fit_size,
        source=path,
    )
    total = len(design(study)) * len(study.loads)
    if total > MAX_SAMPLES:
        raise InputError(f"{path}: the study has {total} samples; at most {MAX_SAMPLES}: lower n or the sweep's lists")
    return study


def design(study: Study) -> np.ndarray:
    """The design's unit-cube points ``(P, dims)`` (P rows, with a sweep: per grid point); for
    ``sobol`` in Saltelli's order (SALib: N (D + 2) rows, no second-order terms)."""
    d = study.dims
    grid = max(1, math.prod(len(v) for _, v in study.sweep))
    if d == 0:
        return np.zeros((grid * (study.n if study.method != "grid" else 1), 0))
    if study.method == "mc":
        u = np.random.default_rng([study.seed, 11]).random((study.n, d))
    elif study.method == "lhs":
        from scipy.stats import qmc

        u = qmc.LatinHypercube(d=d, seed=np.random.default_rng([study.seed, 12])).random(study.n)
    else:  # sobol
        from SALib.sample import sobol as saltelli

        problem = {"num_vars": d, "names": [f"u{i}" for i in range(d)], "bounds": [[0.0, 1.0]] * d}
        u = saltelli.sample(problem, study.n, calc_second_order=False, seed=study.seed)
    return np.tile(u, (grid, 1))


def sweep_points(study: Study) -> list[dict]:
    """The sweep's grid: one dict of generator parameters per grid point (one empty dict if none)."""
    keys = [k for k, _ in study.sweep]
    return [dict(zip(keys, combo)) for combo in itertools.product(*(v for _, v in study.sweep))] or [{}]


def samples(study: Study) -> list[Sample]:
    """Every sample of the study, in index order (values of calibration inputs are drawn when the
    sample runs, since they need the photo's calibration: here they are the cube coordinates)."""
    u = design(study)
    grid = sweep_points(study)
    per_grid = len(u) // len(grid)
    loads = study.loads
    out = []
    for p in range(len(u)):
        values = dict(grid[p // per_grid]) if per_grid else {}
        col = 0
        for inp in study.inputs:
            if inp.law == "calibration":
                values[inp.name] = tuple(float(x) for x in u[p, col : col + 2])  # cube coordinates
            else:
                values[inp.name] = inp.value(u[p, col : col + 1])
            col += inp.dims
        for j, load in enumerate(loads):
            out.append(Sample(index=p * len(loads) + j, point=p, load=load, values=values))
    return out


def _record_units(path: Path, s: dict) -> tuple[str | None, float | None]:
    """``[simulate] units``: of CSV accelerograms (simulate's ``--units``; .AT2 and ESM files name
    theirs), None where not given (g); and ``dt_s``: their time step where they hold
    accelerations alone (simulate's ``--dt``), None where not given (a time column)."""
    from ..simulation.ground_motion import RECORD_UNITS, check_record_dt

    units = s.get("units")
    if units is not None and units not in RECORD_UNITS:
        raise InputError(
            f"{path}: [simulate] units = {units!r}: the units of CSV accelerograms; choose {', '.join(RECORD_UNITS)}"
        )
    dt = s.get("dt_s")
    if dt is not None:
        dt = _number(path, "[simulate] dt_s", dt, positive=True)
        try:
            check_record_dt(dt)
        except InputError as exc:
            raise InputError(f"{path}: [simulate] dt_s{str(exc).removeprefix('--dt')}") from None
    for key, value in (("units", units), ("dt_s", dt)):
        if value is not None and not s.get("accelerograms"):
            raise InputError(f"{path}: [simulate] {key} = {value!r} without accelerograms: give both, or drop {key}")
    return units, dt


def _accelerograms(
    path: Path, s: dict, units: str | None = None, dt: float | None = None
) -> tuple[tuple[Path, ...], ...]:
    """``[simulate] accelerograms``: each entry a file, or a list of two (the X and Y components),
    relative to the study file, in ``units`` where they are CSV files (sampled every ``dt`` s where
    they hold accelerations alone); every record read once here, so that a bad one is refused
    before any sample runs."""
    from ..simulation.ground_motion import read_accelerogram

    given = s.get("accelerograms", [])
    if not isinstance(given, list):
        raise InputError(
            f"{path}: [simulate] accelerograms = {given!r}: give a list of record files (a file, or [X, Y] "
            "for the two components of one record)"
        )
    if given and "records" in s:
        raise InputError(
            f"{path}: [simulate]: records (seeded synthetic motions) and accelerograms (recorded ones) both "
            "given; keep one"
        )
    out = []
    for entry in given:
        files = entry if isinstance(entry, list) else [entry]
        if not (1 <= len(files) <= 2) or not all(isinstance(f, str) for f in files):
            raise InputError(
                f"{path}: [simulate] accelerograms: {entry!r}: give a file name, or [X, Y]: the two horizontal "
                "components of one record"
            )
        paths = tuple((path.parent / f).resolve() for f in files)
        try:
            read_accelerogram(paths[0], units=units, path_y=paths[1] if len(paths) == 2 else None, dt=dt)
        except InputError as exc:
            raise InputError(f"{path}: [simulate] accelerograms: {exc}") from None
        out.append(paths)
    return tuple(out)


def study_json(study: Study) -> dict:
    """What ``study.json`` in the output folder records: the study as parsed, and its fingerprint."""
    return json.loads(
        json.dumps(
            {
                "name": study.name,
                "source": str(study.source),
                "structure": str(study.structure) if study.structure else None,
                "scenario": str(study.scenario) if study.scenario else None,
                "method": study.method,
                "n": study.n,
                "seed": study.seed,
                "inputs": [i.__dict__ for i in study.inputs],
                "sweep": [[k, list(v)] for k, v in study.sweep],
                "simulate": study.simulate.__dict__ if study.simulate else None,
                "loads": list(study.loads),
                "fingerprint": study.fingerprint(),
            },
            default=lambda o: list(o) if isinstance(o, tuple) else str(o),
        )
    )

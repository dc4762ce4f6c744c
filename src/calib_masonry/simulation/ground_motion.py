"""Ground motion: synthetic accelerograms (Kanai-Tajimi) or recorded ones, and the plate's motion.

A synthetic record is white noise filtered by the Kanai-Tajimi soil filter
``H(w) = (wg^2 + 2 i zg wg w) / (wg^2 - w^2 + 2 i zg wg w)``, shaped by a trapezoid-exponential
envelope (rise, strong phase, exponential decay), high-passed (fourth-order, ``highpass_hz``) so
that velocity and displacement return to rest, and scaled so that its peak equals the PGA. The
displacement is the record integrated twice in the frequency domain, and the acceleration is
recomputed from the sampled displacement, so the two always agree. The simulation applies the
motion as the inertial force it puts on every brick in the ground's frame (see
:meth:`GroundMotion.mean_acceleration` and :mod:`calib_masonry.simulation.blender`).

Units: seconds, metres, m/s^2; ``pga_g`` is in g at the edges only.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from ..errors import InputError

__all__ = [
    "G",
    "GroundMotion",
    "KanaiTajimi",
    "synthetic_motion",
    "read_accelerogram",
    "constant_acceleration",
    "motion_from_acceleration",
    "start_from_rest",
    "TAPER_S",
]

G = 9.80665


@dataclass(frozen=True)
class KanaiTajimi:
    """Firm-soil defaults: ``wg`` = 5 pi rad/s (2.5 Hz), ``zg`` = 0.6."""

    omega_g: float = 5.0 * math.pi
    zeta_g: float = 0.6
    rise_s: float = 1.5
    strong_s: float = 4.0
    decay_per_s: float = 0.5
    highpass_hz: float = 0.15


@dataclass(frozen=True)
class GroundMotion:
    """The plate's motion sampled every ``dt`` seconds: ``displacement`` ``(T, 2)`` (X, Y) in m and
    the matching ``acceleration`` ``(T, 2)`` in m/s^2 (second differences of the displacement)."""

    dt: float
    displacement: np.ndarray
    acceleration: np.ndarray
    source: str = "synthetic"
    # a record's own peak (m/s^2) as recorded, before integration from rest and high-pass; None
    # for a synthetic motion, whose samples are the motion itself
    recorded_peak: float | None = None

    @property
    def time(self) -> np.ndarray:
        return np.arange(len(self.displacement)) * self.dt

    @property
    def duration(self) -> float:
        return (len(self.displacement) - 1) * self.dt

    @property
    def pga(self) -> float:
        return float(np.abs(self.acceleration).max())

    def mean_acceleration(self, t: np.ndarray) -> np.ndarray:
        """The ground's mean acceleration over each interval ``[t_k, t_k+1]`` of ``t`` ``(K,)`` ->
        ``(K - 1, 2)``: its velocity change over the interval divided by the interval, so a run
        that holds it constant within each frame gives the ground's velocity exactly at every frame.
        The ground is at rest before the record and keeps its last velocity after it."""
        v_mid = np.diff(self.displacement, axis=0) / self.dt
        tk = np.concatenate([[0.0], (np.arange(len(v_mid)) + 0.5) * self.dt, [self.duration]])
        t = np.asarray(t, dtype=np.float64)
        v_end = 1.5 * v_mid[-1] - 0.5 * v_mid[-2] if len(v_mid) > 1 else v_mid[-1]
        v = np.column_stack(
            [np.interp(t, tk, np.concatenate([[0.0], v_mid[:, k], [v_end[k]]]), left=0.0) for k in range(2)]
        )
        return np.diff(v, axis=0) / np.diff(t)[:, None]

    def frame_means(self, fps: float) -> tuple[np.ndarray, np.ndarray]:
        """Frame start times ``(K,)`` over the record and the acceleration a run at ``fps`` frames per
        second applies in each frame, :meth:`mean_acceleration` ``(K, 2)``."""
        t = np.arange(int(math.ceil(self.duration * fps)) + 1) / fps
        return t[:-1], self.mean_acceleration(t)

    def applied_peak(self, fps: float) -> float:
        """The peak of the acceleration a run at ``fps`` frames per second applies (m/s^2): the largest
        of :meth:`frame_means`. Content above the frame rate averages out, so it is below
        :attr:`pga` for a broadband record."""
        a = self.frame_means(fps)[1]
        return float(np.abs(a).max()) if a.size else 0.0

    def scaled(self, factor: float, source: str | None = None) -> "GroundMotion":
        return GroundMotion(
            dt=self.dt,
            displacement=self.displacement * factor,
            acceleration=self.acceleration * factor,
            source=self.source if source is None else source,
            recorded_peak=None if self.recorded_peak is None else self.recorded_peak * factor,
        )

    def at_pga(self, pga_g: float) -> "GroundMotion":
        """The motion scaled so that its peak ground acceleration is ``pga_g`` (g), its source naming
        the scale (`simulate --accelerogram --pga`, a study's records); one without a peak as it is."""
        if self.pga <= 0:
            return self
        return self.scaled(pga_g * G / self.pga, source=f"{self.source} scaled to {pga_g:g} g")

    def along(self, direction_deg: float) -> "GroundMotion":
        """A one-component motion (along X, nothing along Y) turned to ``direction_deg`` from global X;
        a motion of two components is refused (``--direction``: nothing to turn)."""
        if self.displacement[:, 1].any():
            raise InputError(
                f"--direction {direction_deg:g}: {self.source} has two horizontal components (X and Y); a direction "
                "turns a record of one; drop --direction"
            )
        d = math.radians(direction_deg)
        turn = np.array([math.cos(d), math.sin(d)])
        return replace(
            self,
            displacement=self.displacement[:, :1] * turn,
            acceleration=self.acceleration[:, :1] * turn,
            source=f"{self.source} along {direction_deg:g} deg",
        )

    def displacement_at(self, t: np.ndarray) -> np.ndarray:
        """Linear interpolation of the displacement at times ``t`` ``(K,)`` -> ``(K, 2)``."""
        tt = self.time
        return np.column_stack([np.interp(t, tt, self.displacement[:, k]) for k in range(2)])


def _second_difference(x: np.ndarray, dt: float) -> np.ndarray:
    a = np.zeros_like(x)
    a[1:-1] = (x[2:] - 2 * x[1:-1] + x[:-2]) / dt**2
    return a


TAPER_S = 0.5  # the ground starts from rest: a cosine taper over this long on the displacement


def start_from_rest(disp: np.ndarray, dt: float, taper_s: float = TAPER_S) -> np.ndarray:
    """The displacement ``(T, 2)`` multiplied by ``w(t) = (1 - cos(pi t / taper_s)) / 2`` for
    ``t < taper_s`` (1 after): ``w``, ``w'`` and ``w''`` are 0, 0 and finite at t = 0, so the tapered
    displacement, velocity and acceleration all start at zero and the first frame does not jolt
    the structure (the integrated record alone has a velocity at t = 0 after high-passing)."""
    t = np.arange(len(disp)) * dt
    w = np.where(t < taper_s, 0.5 * (1.0 - np.cos(np.pi * np.minimum(t, taper_s) / taper_s)), 1.0)
    return disp * w[:, None]


def motion_from_acceleration(acc: np.ndarray, dt: float, *, highpass_hz: float = 0.0, source: str = "") -> GroundMotion:
    """Integrate an acceleration record ``(T,)`` or ``(T, 2)`` twice (frequency domain, zero padded),
    starting from rest (:func:`start_from_rest`)."""
    acc = np.asarray(acc, dtype=np.float64)
    if acc.ndim == 1:
        acc = np.column_stack([acc, np.zeros_like(acc)])
    n = len(acc)
    pad = 1 << int(math.ceil(math.log2(4 * n)))
    f = np.fft.rfftfreq(pad, dt)
    w = 2 * math.pi * f
    spec = np.fft.rfft(acc, n=pad, axis=0)
    if highpass_hz > 0:
        r = (f / highpass_hz) ** 4
        spec *= (r / (1 + r))[:, None]
    with np.errstate(divide="ignore", invalid="ignore"):
        disp_spec = np.where(w[:, None] > 0, -spec / (w[:, None] ** 2), 0.0)
    disp = np.fft.irfft(disp_spec, n=pad, axis=0)[:n]
    disp = start_from_rest(disp - disp[0], dt)
    return GroundMotion(dt=dt, displacement=disp, acceleration=_second_difference(disp, dt), source=source)


def synthetic_motion(
    pga_g: float,
    duration_s: float,
    *,
    seed: int,
    dt: float = 0.005,
    components: int = 1,
    model: KanaiTajimi = KanaiTajimi(),
    direction_deg: float = 0.0,
) -> GroundMotion:
    """A seeded Kanai-Tajimi accelerogram scaled to ``pga_g`` (one or two horizontal components).

    With one component the motion is along ``direction_deg`` (from global X).
    """
    if not pga_g >= 0:
        raise InputError(f"--pga {pga_g}: the peak ground acceleration must be >= 0 (in g)")
    if not duration_s > 0:
        raise InputError(f"--duration {duration_s}: must be > 0 seconds")
    if components not in (1, 2):
        raise InputError(f"components = {components}: choose 1 or 2 horizontal components")
    n = int(round(duration_s / dt)) + 1
    rng = np.random.default_rng(seed)
    t = np.arange(n) * dt
    env = np.where(
        t < model.rise_s,
        (t / model.rise_s) ** 2,
        np.where(
            t < model.rise_s + model.strong_s, 1.0, np.exp(-model.decay_per_s * (t - model.rise_s - model.strong_s))
        ),
    )
    f = np.fft.rfftfreq(n, dt)
    w = 2 * math.pi * f
    h = (model.omega_g**2 + 2j * model.zeta_g * model.omega_g * w) / (
        model.omega_g**2 - w**2 + 2j * model.zeta_g * model.omega_g * w
    )
    comps = []
    for _ in range(components):
        noise = rng.standard_normal(n)
        filtered = np.fft.irfft(np.fft.rfft(noise) * h, n=n)
        comps.append(filtered * env)
    acc = np.column_stack(comps)
    if components == 1:
        d = math.radians(direction_deg)
        acc = np.column_stack([acc[:, 0] * math.cos(d), acc[:, 0] * math.sin(d)])
    motion = motion_from_acceleration(acc, dt, highpass_hz=model.highpass_hz, source="Kanai-Tajimi")
    peak = motion.pga
    scale = 0.0 if peak == 0 else pga_g * G / peak
    return GroundMotion(
        dt=dt,
        displacement=motion.displacement * scale,
        acceleration=motion.acceleration * scale,
        source=f"Kanai-Tajimi seed {seed}, {'two components' if components == 2 else 'one component'}, PGA {pga_g:g} g",
    )


def constant_acceleration(
    a: float, duration_s: float, *, dt: float = 0.001, direction_deg: float = 0.0, ramp_s: float = 0.0
) -> GroundMotion:
    """The plate accelerates at a constant ``a`` (m/s^2) from rest: ``x = a t^2 / 2``."""
    n = int(round(duration_s / dt)) + 1
    t = np.arange(n) * dt
    if ramp_s > 0:
        # jerk-limited start: acceleration rises linearly over ramp_s
        acc = a * np.minimum(t / ramp_s, 1.0)
        vel = np.concatenate([[0.0], np.cumsum(0.5 * (acc[1:] + acc[:-1]) * dt)])
        x = np.concatenate([[0.0], np.cumsum(0.5 * (vel[1:] + vel[:-1]) * dt)])
    else:
        x = 0.5 * a * t**2
    d = math.radians(direction_deg)
    disp = np.column_stack([x * math.cos(d), x * math.sin(d)])
    return GroundMotion(
        dt=dt, displacement=disp, acceleration=_second_difference(disp, dt), source=f"constant {a:.4g} m/s^2"
    )


def _record_error(path: Path, message: str) -> InputError:
    return InputError(f"--accelerogram {path}: {message}")


def _values(path: Path, lines: list[str], first: int) -> list[float]:
    """The accelerations after a header: every number from line ``first`` (0-based) on, several a
    line or one; anything else is refused with its line."""
    values: list[float] = []
    for number, line in enumerate(lines[first:], start=first + 1):
        for token in line.replace(",", " ").split():
            try:
                v = float(token)
            except ValueError:
                raise _record_error(path, f"line {number}: {token!r} is not a number") from None
            if not math.isfinite(v):
                raise _record_error(path, f"line {number}: {token} is not a finite acceleration")
            values.append(v)
    return values


def _parse_at2(path: Path, lines: list[str]) -> tuple[np.ndarray, float, str]:
    """A PEER NGA ``.AT2`` record: four header lines (the third names the units, the fourth NPTS and
    DT, as ``NPTS=  5590, DT=   .0050 SEC`` or the older ``5590   .0050   NPTS, DT``), then the
    accelerations, several per line."""
    import re

    if len(lines) < 5:
        raise _record_error(path, "a PEER .AT2 file needs 4 header lines and the values; this one is shorter")
    units = "m/s2" if re.search(r"CM/S|M/S|GAL", lines[2].upper()) else "g"
    if re.search(r"CM/S|GAL", lines[2].upper()):
        units = "cm/s2"
    head = lines[3].upper()
    m = re.search(r"NPTS\s*=\s*(\d+)\s*,?\s*DT\s*=\s*([0-9.Ee+-]+)", head)
    if m is None:
        m = re.search(r"^\s*(\d+)\s+([0-9.Ee+-]+)\s+NPTS", head)
    if m is None:
        raise _record_error(path, f"line 4 ({lines[3].strip()!r}) does not give NPTS and DT; is this a PEER .AT2 file?")
    npts, dt = int(m.group(1)), float(m.group(2))
    values = _values(path, lines, 4)
    if len(values) != npts:
        raise _record_error(path, f"the header says NPTS = {npts} but the file holds {len(values)} values")
    if not (math.isfinite(dt) and dt > 0):
        raise _record_error(path, f"line 4: DT = {dt} must be > 0 seconds")
    return np.asarray(values)[:, None], dt, units


#: the first keys of an ESM (Engineering Strong Motion database, ORFEUS) or ITACA ASCII record,
#: which with SAMPLING_INTERVAL_S tell one: its header is ``KEY: value`` lines (64 in the DYNA 1.2
#: format), then one acceleration a line
_ESM_KEYS = ("EVENT_NAME:", "EVENT_ID:")
_ESM_UNITS = {
    "CM/S^2": "cm/s2",
    "CM/S2": "cm/s2",
    "CM/S**2": "cm/s2",
    "GAL": "cm/s2",
    "M/S^2": "m/s2",
    "M/S2": "m/s2",
    "G": "g",
}


def _is_esm(lines: list[str]) -> bool:
    """Whether the text is an ESM / ITACA ASCII record (its header's keys)."""
    head = [line.strip().upper() for line in lines[:80]]
    return any(h.startswith("SAMPLING_INTERVAL_S:") for h in head) and any(h.startswith(_ESM_KEYS) for h in head)


def _parse_esm(path: Path, lines: list[str]) -> tuple[np.ndarray, float, str]:
    """An ESM / ITACA ASCII record as the databases give it (one file per component, e.g.
    ``IT.AMT..HNE.D.EMSC-20160824_0000006.ACC.MP.ASC``): ``KEY: value`` header lines, of which
    ``SAMPLING_INTERVAL_S``, ``UNITS`` (cm/s^2 as downloaded), ``DATA_TYPE`` (ACCELERATION) and
    ``NDATA`` are read, then the values, one (or several) a line."""
    header: dict[str, str] = {}
    first = len(lines)
    for number, line in enumerate(lines):
        text = line.strip()
        if not text:
            continue
        key, colon, value = text.partition(":")
        if colon and key and not _is_number(key):
            header[key.strip().upper()] = value.strip()
            continue
        first = number
        break
    kind = header.get("DATA_TYPE", "ACCELERATION").upper()
    if "ACCELERATION" not in kind:
        raise _record_error(
            path, f"DATA_TYPE is {header['DATA_TYPE']!r}; give the record's acceleration file (its .ACC. file)"
        )
    try:
        dt = float(header.get("SAMPLING_INTERVAL_S", "nan"))
    except ValueError:
        dt = float("nan")
    if not (math.isfinite(dt) and dt > 0):
        raise _record_error(
            path, f"SAMPLING_INTERVAL_S is {header.get('SAMPLING_INTERVAL_S', 'missing')!r}; it must be > 0 seconds"
        )
    written = header.get("UNITS", "").replace(" ", "").upper()
    if written not in _ESM_UNITS:
        raise _record_error(
            path, f"UNITS is {header.get('UNITS', 'missing')!r}; an acceleration in cm/s^2, m/s^2 or g is read"
        )
    values = _values(path, lines, first)
    n = header.get("NDATA", "")
    if n.strip().isdigit() and int(n) != len(values):
        raise _record_error(path, f"the header says NDATA = {int(n)} but the file holds {len(values)} values")
    if len(values) < 3:
        raise _record_error(path, f"{len(values)} values after the header; the record is empty or cut short")
    return np.asarray(values)[:, None], dt, _ESM_UNITS[written]


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def _fields(line: str) -> tuple[str, list[str]]:
    """A CSV line's fields (comma, semicolon, tab or spaces between them), and the line as read:
    where semicolons part the columns, a comma is the decimal mark (a European spreadsheet's CSV)."""
    if ";" in line:
        line = line.replace(",", ".")
    return line, [p for p in line.replace(";", ",").replace("\t", ",").replace(" ", ",").split(",") if p.strip()]


def _numeric_rows(path: Path, lines: list[str], what: str):
    """Each line's numbers with its line number, after any header lines (text before the first
    line of numbers); text after it, NaN or inf are refused naming the line (``what``: what the
    numbers should be)."""
    seen = False
    for number, line in enumerate(lines, start=1):
        line, parts = _fields(line)
        if not parts:
            continue
        try:
            values = [float(p) for p in parts]
        except ValueError:
            if seen:
                raise _record_error(path, f"line {number}: {line.strip()!r} is not numbers; give {what}") from None
            continue  # a header line
        if not all(math.isfinite(v) for v in values):
            raise _record_error(path, f"line {number}: {line.strip()!r} holds NaN or inf; give finite numbers")
        seen = True
        yield number, values


def _parse_csv(path: Path, lines: list[str], dt: float | None = None) -> tuple[np.ndarray, float]:
    """``time, acceleration[, acceleration_y]`` per line (comma, semicolon, tab or spaces; where
    semicolons part the columns, a comma is the decimal mark, as a spreadsheet in a European locale
    writes ``0,01;-0,0123``), header lines allowed before the numbers; every problem names its line.
    With ``dt`` (s) the file holds one component's accelerations alone, sampled every ``dt``: one a
    line, or several a line read in order (as fixed-width agency files hold them)."""
    if dt is not None:
        return _parse_samples(path, lines, dt)
    rows: list[list[float]] = []
    numbers: list[int] = []
    for number, values in _numeric_rows(path, lines, "time, acceleration"):
        if len(values) == 1:
            raise _record_error(
                path,
                f"line {number}: one column, accelerations without their times; give the time step "
                "(--dt SECONDS, or dt_s in a study's [simulate]) or a column of times before them",
            )
        if len(values) > 3:
            raise _record_error(
                path, f"line {number}: {len(values)} columns; give time, acceleration[, acceleration_y]"
            )
        if rows and len(values) != len(rows[0]):
            raise _record_error(
                path, f"line {number}: {len(values)} columns where line {numbers[0]} has {len(rows[0])}"
            )
        rows.append(values)
        numbers.append(number)
    if len(rows) < 3:
        raise _record_error(path, "expected at least 3 rows of 'time, acceleration[, acceleration_y]'")
    data = np.asarray(rows)
    t = data[:, 0]
    dts = np.diff(t)
    bad = np.flatnonzero(dts <= 0)
    if bad.size:
        k = int(bad[0]) + 1
        raise _record_error(
            path,
            f"line {numbers[k]}: time {t[k]:g} s does not increase (line {numbers[k - 1]}: "
            f"{t[k - 1]:g} s); sort the record by time",
        )
    dt = float(np.median(dts))
    off = np.flatnonzero(np.abs(dts - dt) > 1e-6 + 1e-3 * dt)
    if off.size:
        k = int(off[0]) + 1
        raise _record_error(
            path,
            f"line {numbers[k]}: time step {dts[k - 1]:g} s where the record's step is "
            f"{dt:g} s; resample the record to a regular time step",
        )
    # the mean step over the record, to the time column's own digits: "0.01, 0.02, ..." steps by
    # 0.01 s, where the median of the differences kept their rounding (0.010000000000000009)
    return data[:, 1:], float(f"{(t[-1] - t[0]) / (len(t) - 1):.10g}")


def _parse_samples(path: Path, lines: list[str], dt: float) -> tuple[np.ndarray, float]:
    """One component's accelerations sampled every ``dt`` s, in reading order, after any header
    lines (see :func:`_parse_csv`). A file whose first column steps evenly upwards is a time
    column: refused, since its times would be read as accelerations."""
    values: list[float] = []
    first: list[float] = []
    for _, row in _numeric_rows(path, lines, "accelerations"):
        values.extend(row)
        if len(row) > 1:
            first.append(row[0])
    if len(values) < 3:
        raise _record_error(path, "expected at least 3 accelerations")
    steps = np.diff(first)
    if len(first) >= 3 and steps.min() > 0 and np.ptp(steps) <= 1e-6 + 1e-3 * steps.mean():
        raise _record_error(
            path,
            f"its first column steps evenly from {first[0]:g} by {float(np.median(steps)):g}: a time column; "
            "leave out --dt (dt_s), the file gives the times",
        )
    return np.asarray(values)[:, None], float(dt)


RECORD_UNITS = {"g": G, "m/s2": 1.0, "cm/s2": 0.01}


#: a record whose processing changes its peak by more than this fraction is warned about
PEAK_CHANGE_WARN = 0.05
#: the largest peak ground acceleration a run accepts (g): above any recorded ground motion (the
#: strongest reach about 3 g)
MAX_PGA_G = 5.0
#: the coarsest time step a record may have (s): strong-motion records are sampled at 0.005-0.02 s;
#: at 0.05 s a record holds nothing above 10 Hz, and a masonry structure's periods are 0.05-0.5 s
MAX_RECORD_DT_S = 0.05


def check_record_dt(dt: float | None) -> None:
    """A record's given time step (s), refused with a one-line error where it is not one."""
    if dt is not None and not (math.isfinite(dt) and 0 < dt <= MAX_RECORD_DT_S):
        raise InputError(
            f"--dt {dt:g}: the record's time step must lie in 0..{MAX_RECORD_DT_S:g} s (strong-motion records "
            "are sampled every 0.005-0.02 s)" + ("; give it in seconds" if 1.0 <= dt <= 1000 * MAX_RECORD_DT_S else "")
        )


def _read_record(path: Path, units: str | None, dt: float | None = None) -> tuple[np.ndarray, float, str]:
    """One file's accelerations ``(n, 1 or 2)``, time step and units (see :func:`read_accelerogram`)."""
    if not path.is_file():
        raise _record_error(
            path, "file not found; give a CSV of time, acceleration, a PEER .AT2 or an ESM / ITACA ASCII file"
        )
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise _record_error(path, f"unreadable ({exc}); give a text file of numbers") from None
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        if b"\0" in raw:  # a binary file
            raise _record_error(path, f"unreadable ({exc}); give a text file of numbers") from None
        # a header in a Windows code page (a station's name, a degree sign): the numbers are ASCII
        text = raw.decode("latin-1")
    lines = text.splitlines()
    if path.suffix.upper() == ".AT2" or _is_esm(lines):
        acc, own, file_units = (_parse_at2 if path.suffix.upper() == ".AT2" else _parse_esm)(path, lines)
        if dt is not None and abs(dt - own) > 1e-9 + 1e-6 * own:
            raise _record_error(path, f"its header gives its time step, {own:g} s, not {dt:g}; leave out --dt (dt_s)")
        return acc, own, units or file_units
    acc, dt = _parse_csv(path, lines, dt)
    return acc, dt, units or "g"


def read_accelerogram(
    path: str | Path,
    *,
    units: str | None = None,
    highpass_hz: float = 0.1,
    path_y: str | Path | None = None,
    dt: float | None = None,
) -> GroundMotion:
    """A recorded ground motion: a CSV of ``time, acceleration[, acceleration_y]`` (a header allowed;
    ``units`` "g" by default, "m/s2" or "cm/s2"), a PEER NGA ``.AT2`` file or an ESM / ITACA ASCII file
    (units from their headers). ``dt`` (s): the file (and ``path_y``) holds accelerations alone,
    sampled every ``dt``, one component, one or several values a line in reading order (a .AT2 or
    ESM file gives its own, which ``dt`` must equal). ``path_y``: a second file of one component, the motion along Y
    (the other horizontal component of the same record: PEER and ESM give one file each); its time
    step must be the first's, and the record ends with the shorter. NaN, inf, a time that does not
    increase or an irregular time step is refused with its line number. The record is applied as
    recorded (see :func:`calib_masonry.simulation.run.motion_for` for scaling it to a PGA)."""
    path = Path(path)
    if units is not None and units not in RECORD_UNITS:
        raise InputError(f"--units {units!r}: choose {', '.join(RECORD_UNITS)}")
    check_record_dt(dt)
    given, given_dt = units, dt
    acc, dt, units = _read_record(path, given, given_dt)
    if dt > MAX_RECORD_DT_S:
        raise _record_error(
            path,
            f"its time step {dt:g} s is coarser than any strong-motion record's (at most {MAX_RECORD_DT_S:g} s: "
            "a masonry structure's periods are 0.05-0.5 s); "
            + (
                f"if its time column is in milliseconds ({dt:g} ms), give it in seconds"
                if 1.0 <= dt <= 1000 * MAX_RECORD_DT_S
                else "give the record as sampled (0.005-0.02 s) or resample it finer"
            ),
        )
    acc = acc * RECORD_UNITS[units]
    name = path.name
    if path_y is not None:
        path_y = Path(path_y)
        if acc.shape[1] != 1:
            raise _record_error(
                path, "holds two components already; give a second file only beside a one-component one"
            )
        acc_y, dt_y, units_y = _read_record(path_y, given, given_dt)
        if acc_y.shape[1] != 1:
            raise _record_error(path_y, "holds two components; the second file must hold the Y component alone")
        if abs(dt_y - dt) > 1e-9 + 1e-6 * dt:
            raise _record_error(
                path_y,
                f"its time step {dt_y:g} s differs from {path.name}'s {dt:g} s; give two components of one record",
            )
        n = min(len(acc), len(acc_y))
        acc = np.column_stack([acc[:n, 0], acc_y[:n, 0] * RECORD_UNITS[units_y]])
        name = f"{path.name} + {path_y.name}"
    peak_g = float(np.max(np.abs(acc))) / G
    if peak_g > MAX_PGA_G:
        other = " or ".join(f"--units {u}" for u in RECORD_UNITS if RECORD_UNITS[u] < RECORD_UNITS[units])
        raise _record_error(
            path_y if path_y is not None and np.abs(acc[:, 1]).max() > np.abs(acc[:, 0]).max() else path,
            f"its peak is {peak_g:.3g} g read in {units}, above any recorded ground motion (the bound is "
            f"{MAX_PGA_G:g} g); if the record is in smaller units, pass {other}, or remove the row that is out "
            "of range",
        )
    if acc.shape[1] == 1:  # one horizontal component, along X
        acc = np.column_stack([acc[:, 0], np.zeros(len(acc))])
    motion = motion_from_acceleration(acc, dt, highpass_hz=highpass_hz, source=name)
    recorded = float(np.abs(acc).max())
    processed = motion.pga
    if recorded > 0 and abs(processed / recorded - 1.0) > PEAK_CHANGE_WARN:
        import warnings

        warnings.warn(
            f"{name}: starting the record from rest and high-passing it at {highpass_hz:g} Hz changes its "
            f"peak from {recorded / G:.3g} g to {processed / G:.3g} g ({processed / recorded - 1.0:+.0%}): the "
            "record does not start and end at rest (a velocity or displacement left at its ends); summary.json "
            "gives both, record_peak_g as recorded",
            stacklevel=2,
        )
    return replace(motion, recorded_peak=recorded)

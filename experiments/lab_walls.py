"""The laboratory shear-compression walls of ../shared/data/external/stone_masonry_db against the
model: each wall's drawn stone layout turned into a stone mask, built at its real size, tested in
shear at its precompression and boundary, and its peak lateral force compared with the measured one.

Why: the joint model and the contacts are checked against limit analysis in the tests; this is the
check against real walls. Two single-leaf series of the Stone Masonry Database (Vanin et al. 2017):

- SW.* (Lourenco, Oliveira, Roca & Orduna 2005): dry joints, sawn granite blocks, monotonic,
  cantilever, H0/H = 1.11. Dry: f_t = c = 0. Friction: mu = 0.6 (the unit-joint value of Lourenco
  1996, "Computational strategies for masonry structures", Table 4.2, already the package's default;
  the paper's own direct shear tests were not at hand here).
- WI* (Vasconcelos & Lourenco 2009): irregular granite stones in hydraulic lime mortar, cyclic,
  cantilever, H0/H = 1.104. The package's default mortar (f_t 0.2, c 0.3 MPa = 1.5 f_t, mu 0.6:
  the Bullet Constraints Builder's masonry preset and Lourenco 1996's ratios), the database's mortar
  compressive strength f_c,m (3.8 MPa) and the units' density of granite, 2650 kg/m^3.

Any other single-leaf wall of the database is run the same way (``--db DIR``: a folder with the
database's tests.csv and crackmaps/), its inputs read from its own row, never from its name:

- material: ``Joints`` "Dry" -> f_t = c = 0, mu 0.6, crushing at the row's masonry f_c (56.8 MPa for
  SW, from its wallets; until 2026-12-01 the package's mortar default of 10 MPa, because at 56.8
  SW.200.1's shear test sat in one frame for 25 minutes: one question HiGHS's dual simplex did not
  finish, since limited);
  any mortar -> the package's default mortar with the row's f_c,m (a row without one: the mean of
  its reference's rows, else the package default) and E_m where given; the masonry's modulus
  from its compression tests (Ecompr) where given, which sets the joints' stiffness (each column of
  unit and joint has it: ``masonry_youngs_modulus_mpa``; else the units' and the mortar's moduli in
  series, whose 10 GPa made the WI walls 4-8 times stiffer than tested); the masonry's
  compressive strength (the row's f_c) where given, at which the cracked joints' contacts crush
  (``masonry_compressive_strength_mpa``: a rocking wall's toe); the units' modulus E_b
  where given (else the package's 10 GPa); the stones' density 2650 kg/m^3 (granite; the database
  gives none) and mu 0.6 for every wall;
- boundary from ``H0/H``: at most 0.55 -> double-fixed (H0 = H / 2); above 1 -> cantilever with the
  load H0 above the foot (``--shear-span-ratio H0/L``); from 0.95 to 1 -> cantilever with the load
  5 cm above the wall's top (the beam's centroid; noted); between -> not run (a partly restrained
  top, which the shear test does not model), said so;
- the joint reach: the package's default (6 cm) or, where a stone would hang at it (a drawing's
  joint wider than that, as rubble walls have), the least whole centimetre above at which none
  does (:func:`build_wall`; WI2.175 and WI3.175 at 0.07 m, a wedge between two stones each);
- the statistics are per reference (a series), from the test's own ``Reference`` field;
- not run, each with its reason printed: more than one leaf (the model is single-wythe), no
  drawing, no precompression, no Vmax or no H0. A drawing is ``crackmaps/crackmap_<unit, letters and
  digits only>_D<drift>_<ref>.png``: the one at the smallest drift (D0p00, before the test) is
  used; a later one's crack lines would be taken for joints (noted).

No value is fitted to the measured Vmax. Each drawing (crackmaps/crackmap_<unit>_D0p00_<ref>.png:
the stone outlines in grey, the wall's outline in black, the damage after the test in red and
yellow) becomes a mask by :func:`stone_mask`: the outline's four corners map to the wall's L x H
(the drawings are slightly skewed), the regions the grey lines close are the stones (red crack lines
run along the joints and count as joints, the yellow hatching of crushed zones is ignored), and the
mortar between stones of a mortared wall, one network of low solidity, is dropped.

    .venv/bin/python experiments/lab_walls.py [--out DIR] [--only SW.30.1 WI1.100] [--db DIR] [--reuse]

The beam carries the row's sigma0,tot less the database's own 20 kN/m^3 of wall above the base
(``DB_UNIT_WEIGHT_N_M3``): the model's stones add their weight themselves.

prints per test: sigma0 (the database's), the beam's stress, measured Vmax (the larger of the two
directions), predicted, ratio, the bound of the wall rocking whole as a rigid body, N L / (2 H0)
with N = sigma0 L t (the test's own scale: a measured peak far above it says the rig held the beam,
far below it that the units or the mortar gave way first), mechanism (model) and failure type
(test; a wall whose drawing cannot be read or whose build or run is refused is printed as failed, with
the last line of its error, and the others run on); under each wall the model's drift where its force first reaches half the measured Vmax
beside the measured envelope's (envelopes/envelope_<unit>_<ref>.csv: the walls' stiffness), at the
test's cracking onset Vcr beside its dcr, and at 95 % of the model's peak beside the test's drift
at its peak; then per series the mean and the coefficient of variation of the ratios. With
``--out``, DIR/lab_walls.png: predicted against measured, each wall's rocking bound beside its
marker, the +-30 % band; DIR/lab_walls_curves.png: each wall's force-drift curve on its measured
envelope. ``--reuse`` reads the shear tests already in ``--out`` instead of running them again. Measured on 2026-11-26, 11-27 and 11-28 (the last after the contacts' friction law
stopped creeping at every load step) and 2026-12-01 (the shear test's stalled solves asking whether
the load has an equilibrium; then the beam's load without the wall's weight, and a crack round
cracking the worst joint alone): see docs/stone_walls.md. Whether a wall's peak is converged in the
joint model's settings: experiments/shear_test_convergence.py.
"""

from __future__ import annotations

import argparse
import csv
import io
import json
import re
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
DB = ROOT.parent / "shared" / "data" / "external" / "stone_masonry_db"
PX_PER_M = 1000
STONE = {"friction": 0.6, "density_kg_m3": 2650.0}  # every wall: mu (Lourenco 1996), granite's density
# the unit weight the database adds to the applied stress in its sigma0,tot, N/m^3 ("total vertical
# stress at the base of the wall, deriving from the applied load and the self weight (rho = 20
# kN/m3)", fields_definition.csv): the beam's load is sigma0,tot - 20 kN/m^3 H, the model's stones
# add their own weight
DB_UNIT_WEIGHT_N_M3 = 20e3
DRY = {"tensile_strength_mpa": 0.0, "cohesion_mpa": 0.0}


# a crackmap's name: crackmap_<unit>_D<drift>_<ref>.png, the drift written 0p93, 0.93 or -0p17 (a
# cyclic test's negative excursion), or crackmap_<unit>_<ref>.png with none; the unit may hold
# underscores, pluses or dots (PS_1, IR4++), so the first "_D<number>_" ends it
_CRACKMAP = re.compile(r"^crackmap_(?P<unit>.+?)(?:_D(?P<drift>-?\d+(?:[p.]\d+)?))?_(?P<ref>[^_]+)\.png$", re.I)


def _drift(path: Path) -> float:
    """The drift of a crackmap's name in per cent, its size (``..._D0p93_...``, ``_D0.93_`` and
    ``_D-0p93_`` -> 0.93), inf if it has none."""
    m = _CRACKMAP.match(path.name)
    if not m or m.group("drift") is None:
        return float("inf")
    return abs(float(m.group("drift").replace("p", ".")))


def _unit_key(unit: str) -> str:
    """A test unit's name as the database writes it in file names: dots, spaces and hyphens left out
    (SW.100.1 -> SW1001, WI1.100 -> WI1100, test 1 -> test1), every other character kept (IR4++ is
    not IR4)."""
    return re.sub(r"[.\s-]", "", unit).lower()


def _surname(reference: str) -> str:
    """The first author's surname of a reference, letters only and without accents ("Lourenço et al.
    (2005)" -> "lourenco"), "" if it has none."""
    import unicodedata

    word = (reference or "").split(" ")[0].split(",")[0]
    folded = unicodedata.normalize("NFKD", word).encode("ascii", "ignore").decode()
    return re.sub(r"[^a-z]", "", folded.lower())


class OnlyAnotherReference(FileNotFoundError):
    """The unit has drawings, but only of another reference's wall of the same name."""


def _files_of(folder: Path, glob: str, pattern: re.Pattern, unit: str) -> list[tuple[Path, str]]:
    """The files ``glob`` of ``folder`` whose name ``pattern`` matches with a unit (its ``unit``
    group) that is ``unit`` as the database writes names (:func:`_unit_key`), each with its
    reference (``ref``)."""
    key, found = _unit_key(unit), []
    for path in sorted(folder.glob(glob)) if folder.is_dir() else []:
        m = pattern.match(path.name)
        if m and _unit_key(m.group("unit")) == key:
            found.append((path, m.group("ref")))
    return found


def _by_author(found: list[tuple[Path, str]], reference: str) -> list[Path]:
    """Those of ``found`` (path, its reference) of ``reference``'s first author (all where it is "")."""
    author = _surname(reference)
    return [p for p, ref in found if not author or author in _surname(ref)]


_ENVELOPE = re.compile(r"^envelope_(?P<unit>.+)_(?P<ref>[^_]+)\.csv$", re.I)


def drawing_of(unit: str, db: Path = DB, reference: str = "") -> Path:
    """The crackmap of a test unit (SW.100.1 -> SW1001, WI1.100 -> WI1100, IR4++ -> IR4++), the one
    at the smallest drift (D0p00: the layout before the test). Where ``reference`` is given, only a
    drawing of the same first author counts (R5 is a wall of Almeida et al. 2014 and another of
    Mazzon 2010; the year may differ, Vasconcelos 2005 for Vasconcelos and Lourenço 2009)."""
    folder = Path(db) / "crackmaps"
    found = _files_of(folder, "crackmap_*.png", _CRACKMAP, unit)
    if not found:
        raise FileNotFoundError(f"no crackmap for {unit} ({_unit_key(unit)}) in {folder}")
    own = _by_author(found, reference)
    if not own:
        raise OnlyAnotherReference(
            f"no crackmap of {reference} for {unit} in {folder} (only of another reference: "
            f"{', '.join(p.name for p, _ in found)})"
        )
    return min(own, key=lambda p: (_drift(p), p.name))


def envelope_of(unit: str, db: Path = DB, reference: str = "") -> tuple[np.ndarray, np.ndarray] | None:
    """The measured force-drift envelope of a test (envelopes/envelope_<unit>_<ref>.csv, named as the
    drawings are; only the row's first author's counts), as drift (%) and force (kN) from the origin
    to the branch's end, on the side whose force reaches the larger magnitude (a cyclic test has two),
    both positive; None where the database has none."""
    for path in _by_author(_files_of(Path(db) / "envelopes", "envelope_*.csv", _ENVELOPE, unit), reference):
        rows = []
        for line in path.read_text(encoding="utf-8", errors="replace").splitlines():
            parts = line.split(",")
            try:
                rows.append((float(parts[2]), float(parts[1])))  # drift %, force kN
            except (IndexError, ValueError):
                continue  # the header lines
        if not rows:
            return None
        a = np.array(rows)
        pos, neg = a[a[:, 0] >= 0], a[a[:, 0] <= 0]
        side = pos if pos[:, 1].max(initial=0.0) >= -neg[:, 1].min(initial=0.0) else neg
        side = np.abs(side[np.argsort(np.abs(side[:, 0]), kind="stable")])
        if side[0, 0] > 0:  # from the origin (a cyclic test's envelope may start at its first peak)
            side = np.vstack([[0.0, 0.0], side])
        return side[:, 0], side[:, 1]
    return None


def first_drift_at(drift: np.ndarray, force: np.ndarray, level_kn: float) -> float | None:
    """The drift (%) where a curve's force first reaches ``level_kn`` (interpolated), None if never."""
    up = np.flatnonzero(force >= level_kn)
    if up.size == 0:
        return None
    k = up[0]
    if k == 0:
        return float(drift[0])
    return float(np.interp(level_kn, [force[k - 1], force[k]], [drift[k - 1], drift[k]]))


def boundary_of(h0_over_h: float) -> tuple[str | None, str]:
    """The shear test's boundary for the database's H0/H, or None and why it is not run."""
    if h0_over_h <= 0.55:
        return "double-fixed", ""
    if h0_over_h >= 0.95:
        return "cantilever", ""
    return None, f"H0/H = {h0_over_h:.2f}: a partly restrained top, which the shear test does not model"


def stone_mask(
    png: Path, length_m: float, height_m: float, px_per_m: int = PX_PER_M, mortar: bool = False
) -> np.ndarray:
    """The stones of a drawing as a binary mask (stones 255, joints 0) of the wall's L x H."""
    import cv2
    from PIL import Image
    from scipy import ndimage

    rgb = np.asarray(Image.open(png).convert("RGB")).astype(np.int32)
    r, g, b = rgb[..., 0], rgb[..., 1], rgb[..., 2]
    white = (r > 200) & (g > 200) & (b > 150)  # white, and the light tints of the hatching's edges
    # crushed zones' hatching (yellow, orange): drawn over stones and joints alike, not a joint
    yellow = (r > 170) & (g > 165) & (b < r - 30)  # (orange and red crack lines run along joints)
    line = ~(white | yellow)
    ys, xs = np.nonzero(line)
    s, d = xs + ys, xs - ys
    quad = np.array(
        [
            [xs[s.argmin()], ys[s.argmin()]],
            [xs[d.argmax()], ys[d.argmax()]],
            [xs[s.argmax()], ys[s.argmax()]],
            [xs[d.argmin()], ys[d.argmin()]],
        ],
        dtype=np.float32,
    )  # top-left, top-right, bottom-right, bottom-left
    w, h = int(round(length_m * px_per_m)), int(round(height_m * px_per_m))
    target = np.array([[0, 0], [w - 1, 0], [w - 1, h - 1], [0, h - 1]], dtype=np.float32)
    label, count = ndimage.label(~line)
    label = cv2.warpPerspective(
        label.astype(np.float32), cv2.getPerspectiveTransform(quad, target), (w, h), flags=cv2.INTER_NEAREST
    ).astype(np.int64)
    label[:2], label[-2:], label[:, :2], label[:, -2:] = 0, 0, 0, 0  # the wall's outline
    keep = np.zeros(count + 1, dtype=bool)
    for k, sl in enumerate(ndimage.find_objects(label), start=1):
        if sl is None:
            continue
        own = label[sl] == k
        area = own.sum() / px_per_m**2
        if area < 2e-4:  # a speck between lines
            continue
        if mortar:  # the mortar network: large, far from convex
            ys_, xs_ = np.nonzero(own)
            hull = cv2.convexHull(np.column_stack([xs_, ys_]).astype(np.int32))
            if own.sum() / max(cv2.contourArea(hull), 1.0) < 0.7:
                continue
        keep[k] = True
    stones = keep[label] & (label > 0)
    # neighbouring stones separated by one pixel of joint at least
    edge = np.zeros_like(stones)
    for axis in (0, 1):
        diff = np.diff(label, axis=axis) != 0
        if axis == 0:
            edge[1:] |= diff
            edge[:-1] |= diff
        else:
            edge[:, 1:] |= diff
            edge[:, :-1] |= diff
    final, _ = ndimage.label(stones & ~edge)
    size = np.bincount(final.ravel())
    size[0] = 0
    return np.where(size[final] >= 2e-4 * px_per_m**2, 255, 0).astype(np.uint8)  # no specks of aliasing


def _field(row: dict, name: str) -> str:
    """A field of a tests.csv row by its name with spaces and line breaks ignored (the database's
    headers break lines inside a name: "fc\\nm  [MPa]" is "fc,m [MPa]")."""
    want = _header_key(name)
    for key, value in row.items():
        if key is not None and _header_key(key) == want:
            return (value or "").strip()
    return ""


def _header_key(name: str) -> str:
    """A column's name compared without spaces, line breaks, commas or anything outside ASCII: a
    copy of the table saved in another encoding writes "σ0,tot [MPa]" as "?0,tot [MPa]"."""
    return re.sub(r"[\s,?]", "", name.encode("ascii", "ignore").decode())


def _num(row: dict, name: str) -> float | None:
    try:
        return float(_field(row, name))
    except ValueError:
        return None


def _dmax(row: dict) -> float | None:
    """The drift (%) at the row's measured peak, of the direction whose Vmax is the larger."""
    pairs = [(_num(row, f"Vmax,{d} [kN]"), _num(row, f"dmax,{d} [%]")) for d in "+-"]
    pairs = [(v, abs(x)) for v, x in pairs if v is not None and x is not None]
    return max(pairs)[1] if pairs else None


def _sigma0(row: dict, L: float | None, t: float | None) -> float | None:
    """The row's total vertical stress at the base, MPa: its sigma0,tot, else its Ntot (kN) over
    L t (mm)."""
    if (s := _num(row, "σ0,tot [MPa]")) is not None:
        return s
    n = _num(row, "Ntot [kN]")
    return n * 1e3 / (L * t) if n is not None and L and t else None


def tests(db: Path = DB) -> list[dict]:
    """Every row of the database's tests.csv with what the shear test needs, read from the row:
    ``skip`` says why a row is not run ("" if it is)."""
    raw = (Path(db) / "tests.csv").read_bytes()
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError:  # a copy saved by a spreadsheet in its own code page (Lourenço, "?0,tot")
        text = raw.decode("cp1252", errors="replace")
    # rows without a unit's name (a spreadsheet's empty lines of commas) are no tests
    rows = [r for r in csv.DictReader(io.StringIO(text, newline="")) if _field(r, "Test unit name")]
    fcm: dict[str, list[float]] = {}
    for row in rows:
        if (v := _num(row, "fc,m [MPa]")) is not None and v > 0:
            fcm.setdefault(_field(row, "Reference"), []).append(v)
    out = []
    for row in rows:
        unit = _field(row, "Test unit name")
        ref = _field(row, "Reference") or "?"
        H, L, t, H0 = (_num(row, k) for k in ("H [mm]", "L [mm]", "t [mm]", "H0 [mm]"))
        vmax = [v for v in (_num(row, "Vmax,+ [kN]"), _num(row, "Vmax,- [kN]")) if v is not None]
        dry = "dry" in _field(row, "Joints").lower()
        test = {
            "unit": unit,
            "series": ref,
            "mortar": not dry,
            "H": H / 1000 if H else None,
            "L": L / 1000 if L else None,
            "t": t / 1000 if t else None,
            "H0": H0 / 1000 if H0 else None,
            "sigma0": _sigma0(row, L, t),
            "applied": None,
            "vmax": max(vmax) if vmax else None,
            "failure": _field(row, "From test report: Failure type") or "?",
            # the test's cracking onset and its drift at the peak (of the larger direction), % and kN
            "vcr": _num(row, "Vcr [kN]"),
            "dcr": _num(row, "dcr [%]"),
            "dmax": _dmax(row),
            "skip": "",
            "note": "",
        }
        material = dict(STONE)
        # the units' modulus (joints' stiffness: units and mortar in series), and the mortar's, where given
        if (eb := _num(row, "Eb [MPa]")) is not None and eb > 0:
            material["unit_youngs_modulus_mpa"] = eb
        if not dry and (em := _num(row, "Em [MPa]")) is not None and em > 0:
            material["mortar_youngs_modulus_mpa"] = em
        # the masonry's own modulus from its compression tests, where given, sets the joints'
        # stiffness (the row's measured wall, not a mortar prism; for a dry wall its contacts')
        if (ec := _num(row, "Ecompr [MPa]")) is not None and ec > 0:
            material["masonry_youngs_modulus_mpa"] = ec
        # and its compressive strength, where given, crushes the cracked joints' contacts: a rocking
        # wall's toe (EN 1998-3's flexural capacity; the rubble walls' 5 MPa is a quarter of their
        # stress block at 1.27 MPa)
        if (fcw := _num(row, "fc [MPa]")) is not None and fcw > 0:
            material["masonry_compressive_strength_mpa"] = fcw
        if dry:
            material.update(DRY)
            # a dry joint crushes at the masonry's strength (the row's f_c, from its wallets), not
            # at the package's mortar default of 10 MPa
            if fcw is not None and fcw > 0:
                material["compressive_strength_mpa"] = fcw
        else:
            own = _num(row, "fc,m [MPa]")
            if own is not None and own > 0:
                material["compressive_strength_mpa"] = own
            elif fcm.get(ref):
                material["compressive_strength_mpa"] = round(float(np.mean(fcm[ref])), 3)
                test["note"] = f"f_c,m {material['compressive_strength_mpa']} MPa: the mean of its reference's rows"
        test["material"] = material
        leaves = _num(row, "Leaves")
        # the beam's stress, MPa: sigma0,tot less the database's wall above the base (H in mm)
        beam = test["sigma0"] - DB_UNIT_WEIGHT_N_M3 * H / 1e9 if test["sigma0"] and H else None
        if not (H and L and t):
            test["skip"] = "no H, L or t"
        elif leaves is not None and leaves != 1:
            test["skip"] = f"{leaves:g} leaves: the model is a single wythe"
        elif beam is None or beam <= 0:
            test["skip"] = "no precompression beyond the wall's own weight"
        elif test["vmax"] is None:
            test["skip"] = "no measured Vmax"
        elif not H0:
            test["skip"] = "no H0: the boundary is not known"
        else:
            test["boundary"], test["skip"] = boundary_of(H0 / H)
            if test["boundary"] == "cantilever" and test["H0"] <= test["H"]:
                test["H0"] = test["H"] + 0.05
                test["note"] = (test["note"] + "; " if test["note"] else "") + "H0 <= H: the load 5 cm above the top"
        if not test["skip"]:
            test["applied"] = round(beam, 6)
            test["envelope"] = envelope_of(unit, db, ref if ref != "?" else "")
            try:
                test["drawing"] = drawing_of(unit, db, ref if ref != "?" else "")
            except FileNotFoundError as e:
                test["skip"] = "no drawing in crackmaps/" + (
                    " of this reference" if isinstance(e, OnlyAnotherReference) else ""
                )
            else:
                if _drift(test["drawing"]) > 0:
                    test["note"] = (test["note"] + "; " if test["note"] else "") + (
                        "drawn after the test: its cracks count as joints"
                    )
        out.append(test)
    return out


def model_curve(shear_folder: Path) -> np.ndarray | None:
    """A shear test's force_drift.csv as ``(n, 2)`` drift (%) and force (kN), None if there is none."""
    path = shear_folder / "force_drift.csv"
    return np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2) if path.is_file() else None


def drift_at_force(curve: np.ndarray | None, force_kn: float | None, summary: dict) -> float | None:
    """The model's drift (%) where its lateral force first reaches ``force_kn`` on the joint model's
    ``curve`` up to the peak (:func:`model_curve`), None where the curve's known part ends below it."""
    st = summary["shear_test"]
    if curve is None or force_kn is None or st.get("drift_known_to_kn") is None or force_kn > st["drift_known_to_kn"]:
        return None
    return first_drift_at(curve[:, 0], curve[:, 1], force_kn)


def rocking_bound_kn(test: dict) -> float:
    """The lateral force at which the wall would rock whole about its toe as one rigid body, kN:
    N L / (2 H0), N the base's total load sigma0,tot L t (the wall's weight in it), H0 the shear span
    (H / 2 for a double-fixed wall)."""
    n_kn = test["sigma0"] * test["L"] * test["t"] * 1e3
    span = test["H"] / 2 if test.get("boundary") == "double-fixed" else test["H0"]
    return n_kn * test["L"] / (2 * span)


def write_wall(test: dict, folder: Path, material: bool = True, max_joint_m: float | None = None) -> Path:
    """The mask (from the row's ``drawing``) and structure file of one wall in ``folder``, with the
    row's ``[material]`` table unless ``material`` is False and the joint reach ``max_joint_m``
    where given (else the package's default); the structure file."""
    from PIL import Image

    folder.mkdir(parents=True, exist_ok=True)
    mask = stone_mask(test["drawing"], test["L"], test["H"], mortar=test["mortar"])
    Image.fromarray(mask).save(folder / "mask.png")
    table = "\n".join(f"{k} = {v}" for k, v in test["material"].items())
    reach = "" if max_joint_m is None else f"max_joint_m = {max_joint_m:g}\n"
    (folder / "structure.toml").write_text(
        f'[structure]\nname = "{test["unit"]}"\nthickness_m = {test["t"]}\nvertices = 8\nclosed = false\n{reach}\n'
        f'[[wall]]\nname = "w"\nmask = "mask.png"\nwidth_m = {test["L"]}\nheight_m = {test["H"]}\ntheta_deg = 0\n'
        + (f"\n[material]\n{table}\n" if material else "")
    )
    return folder / "structure.toml"


#: the widest joint reach a wall is built with (m): the structure files' own bound
MAX_REACH_M = 0.3


def build_wall(test: dict, folder: Path) -> Path:
    """Mask (from the row's ``drawing``), structure and build of one wall in ``folder``; the model
    folder. The joint reach is the package's default or, where a stone would hang at it (no joint
    beneath it: a joint of the drawing wider than the reach, as rubble walls have), the least whole
    centimetre above it at which none does (up to :data:`MAX_REACH_M`): the wall stood before its
    test, each stone on others. Its summary.json's ``max_joint_m`` says which; nothing is fitted
    to Vmax."""
    reach = None
    while True:
        structure = write_wall(test, folder, max_joint_m=reach)
        call([*CLI, "build", str(structure), "--out", str(folder / "model"), "--overwrite"])
        built = json.loads((folder / "model" / "summary.json").read_text())
        if not built["joint_coverage"]["units_without_bed_joint"] or built["max_joint_m"] >= MAX_REACH_M:
            return folder / "model"
        reach = round(built["max_joint_m"] + 0.01, 2)


CLI = [sys.executable, "-m", "calib_masonry"]


def call(args: list[str]) -> None:
    r = subprocess.run(args, capture_output=True, text=True)
    if r.returncode != 0:
        raise RuntimeError(f"{' '.join(args[2:5])}: exit {r.returncode}: {r.stderr.strip()[-2000:]}")


def run(test: dict, folder: Path, boundary: str | None = None) -> dict:
    """Mask, structure, build and shear test of one wall in ``folder`` (``boundary``: the row's by
    default); the simulate summary."""
    boundary = boundary or test["boundary"]
    build_wall(test, folder)
    call(
        [*CLI, "simulate", str(folder / "model"), "--shear-test", "--precompression-mpa", str(test["applied"])]
        + ["--boundary", boundary]
        + (["--shear-span-ratio", str(test["H0"] / test["L"])] if boundary == "cantilever" else [])
        + ["--out", str(folder / "shear"), "--overwrite", "--gif-frames", "0"]
    )
    return json.loads((folder / "shear" / "summary.json").read_text())


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument(
        "--out", default=None, help="keep each wall's mask, model and run here (default: a temporary folder)"
    )
    ap.add_argument("--only", nargs="*", default=None, help="test units to run (default: all)")
    ap.add_argument(
        "--boundary",
        default=None,
        choices=["cantilever", "double-fixed"],
        help="the beam's rotation for every wall (default: each row's, from its H0/H)",
    )
    ap.add_argument("--db", type=Path, default=DB, help=f"the database folder: tests.csv and crackmaps/ (default {DB})")
    ap.add_argument(
        "--reuse",
        action="store_true",
        help="a wall whose shear test is already in --out is read, not run again (to print and draw again)",
    )
    args = ap.parse_args()
    if not (args.db / "tests.csv").is_file():
        print(f"error: --db {args.db}: no tests.csv there; give the database folder (tests.csv and crackmaps/)")
        raise SystemExit(2)
    base = Path(args.out) if args.out else Path(tempfile.mkdtemp(prefix="lab_walls_"))
    ratios: dict[str, list[float]] = {}
    failed: dict[str, list[str]] = {}
    points: list[tuple] = []
    curves: list[tuple] = []
    print(
        f"{'test':>10} {'sigma0':>7} {'beam':>6} {'Vmax':>7} {'model':>7} {'ratio':>6} {'rigid':>6}"
        "  mechanism (model) / failure (test)"
    )
    for t in tests(args.db):
        if args.only and t["unit"] not in args.only:
            continue
        if t["skip"]:
            print(f"{t['unit']:>10}  not run: {t['skip']}", flush=True)
            continue
        folder = base / re.sub(r"[^A-Za-z0-9._-]", "_", t["unit"])
        done = folder / "shear" / "summary.json"
        try:
            s = json.loads(done.read_text()) if args.reuse and done.is_file() else run(t, folder, args.boundary)
        except (RuntimeError, OSError, ValueError) as exc:  # one wall's failure does not stop the others
            failed.setdefault(t["series"], []).append(t["unit"])
            print(f"{t['unit']:>10}  failed: {str(exc).splitlines()[-1][:300]}", flush=True)
            continue
        st = s["shear_test"]
        peak = st["peak_lateral_force_kn"]
        curve = model_curve(folder / "shear")
        curves.append((t, curve, peak))
        ratio = peak / t["vmax"] if peak is not None else float("nan")
        ratios.setdefault(t["series"], []).append(ratio)
        bound = rocking_bound_kn(t)
        points.append((t["series"], t["unit"], t["vmax"], peak, bound))
        print(
            f"{t['unit']:>10} {t['sigma0']:7.3f} {t['applied']:6.3f} {t['vmax']:7.1f} {peak if peak is not None else float('nan'):7.1f} "
            f"{ratio:6.2f} {bound:6.1f}  {st['mechanism']} / {t['failure']}  ({st['boundary']}, coverage "
            f"{s['joint_coverage']['median']}{_reach_note(folder)}{'; ' + t['note'] if t['note'] else ''})",
            flush=True,
        )
        print(f"{'':>10}  {stiffness_line(t, s, curve)}", flush=True)
    for series in {**ratios, **failed}:
        r = np.array(ratios.get(series, []))
        stats = f"mean ratio {np.nanmean(r):.3f}, CoV {np.nanstd(r) / np.nanmean(r):.3f}, " if r.size else ""
        lost = failed.get(series, [])
        print(f"{series}: {stats}n = {len(r)}" + (f"; failed {len(lost)}: {' '.join(lost)}" if lost else ""))
    if points:
        plot_walls(points, base / "lab_walls.png")
        plot_curves(curves, base / "lab_walls_curves.png")
        print(f"figures: {base / 'lab_walls.png'}, {base / 'lab_walls_curves.png'}")


def _reach_note(folder: Path) -> str:
    """ ", joint reach X m" where the wall in ``folder`` was built with more than the default reach
    (:func:`build_wall`), else nothing."""
    built = folder / "model" / "summary.json"
    reach = json.loads(built.read_text()).get("max_joint_m") if built.is_file() else None
    from calib_masonry.build3d.assemble import MAX_GAP_M

    return f", joint reach {reach:g} m" if reach is not None and reach > MAX_GAP_M + 1e-9 else ""


def stiffness_line(test: dict, summary: dict, curve: np.ndarray | None) -> str:
    """The model's drifts beside the test's: at the test's cracking onset Vcr (its dcr) and, against
    the test's drift at its peak, the model's where its force reaches 95 % of its own peak (its drift
    at the peak itself grows without bound as the mechanism forms); with the joints' modulus."""
    pct = lambda x: "?" if x is None else f"{x:.3f} %"  # noqa: E731
    at_vcr = drift_at_force(curve, test["vcr"], summary)
    st = summary["shear_test"]
    em = test["material"].get("masonry_youngs_modulus_mpa")
    env = test.get("envelope")
    half = ""
    if env is not None:
        # the drift where the force first reaches half the measured peak: the walls' stiffness
        # before most cracking, on the measured envelope and on the model's curve
        level = 0.5 * test["vmax"]
        half = (
            f"drift at half the measured Vmax ({level:.1f} kN): model {pct(drift_at_force(curve, level, summary))}, "
            f"envelope {pct(first_drift_at(env[0], env[1], level))}; "
        )
    return half + (
        (f"drift at Vcr {test['vcr']:.1f} kN: model {pct(at_vcr)}, test {pct(test['dcr'])}; " if test["vcr"] else "")
        + f"drift at 95 % of the peak (model) {pct(st.get('drift_at_95_percent_of_peak_percent'))}, "
        f"at the peak (test) {pct(test['dmax'])}; masonry's E {'not given (mortar and units in series)' if em is None else f'{em:g} MPa (Ecompr)'}"
    )


def plot_curves(curves: list[tuple], path: Path) -> None:
    """One panel per wall: the model's force-drift curve (its force_drift.csv: the joint model's up
    to the peak, then Bullet's) against the measured envelope (the side of its larger peak) and the
    measured Vmax (``curves``: the test's row, its :func:`model_curve`, the model's peak kN or None)."""
    from matplotlib.figure import Figure

    cols = min(4, len(curves))
    rows = -(-len(curves) // cols)
    fig = Figure(figsize=(3.2 * cols, 2.6 * rows))
    axes = np.atleast_1d(fig.subplots(rows, cols, squeeze=False)).ravel()
    for ax, (t, c, peak) in zip(axes, curves):
        top = 3.0
        if t.get("envelope") is not None:
            ax.plot(*t["envelope"], color="k", lw=1.0, label="test (envelope)")
            top = max(top, 1.05 * float(t["envelope"][0].max()))
        ax.axhline(t["vmax"], color="k", lw=0.6, ls=":")
        if c is not None:
            up = c[:, 1] <= (peak if peak is not None else np.inf) + 1e-9
            ax.plot(c[up, 0], c[up, 1], color="C3", lw=1.2, label="model")
        ax.set_xlim(0, top)
        ax.set_ylim(0, 1.3 * max(t["vmax"], peak or 0.0))
        ax.set_title(f"{t['unit']} ({t['sigma0']:.2f} MPa)", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.grid(alpha=0.3)
    for ax in axes[len(curves) :]:
        ax.set_visible(False)
    axes[0].legend(fontsize=6, loc="lower right")
    fig.supxlabel("drift (%)", fontsize=8)
    fig.supylabel("lateral force (kN)", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=100)


def plot_walls(points: list[tuple], path: Path) -> None:
    """Predicted against measured peak force, one marker per wall and series, with the +-30 %
    band and, open, each wall's rigid rocking bound N L / (2 H0) (``points``: series, unit,
    measured kN, model kN or None, bound kN)."""
    from matplotlib.figure import Figure  # no pyplot: no backend to select

    fig = Figure(figsize=(6.0, 5.5))
    ax = fig.subplots()
    top = 1.15 * max(max(p[2], p[3] or 0.0, p[4]) for p in points)
    x = np.array([0.0, top])
    ax.plot(x, x, color="k", lw=0.8)
    ax.fill_between(x, 0.7 * x, 1.3 * x, color="0.9", label="within +-30 %")
    for k, series in enumerate(dict.fromkeys(p[0] for p in points)):
        own = [p for p in points if p[0] == series]
        color = f"C{k}"
        ax.scatter([p[2] for p in own], [p[4] for p in own], facecolors="none", edgecolors=color, s=40,
                   label=f"{series}: rigid rocking bound")  # fmt: skip
        run = [p for p in own if p[3] is not None]
        ax.scatter([p[2] for p in run], [p[3] for p in run], color=color, s=22, label=f"{series}: model")
        for p in run:
            ax.annotate(p[1], (p[2], p[3]), fontsize=6, xytext=(3, 2), textcoords="offset points")
    ax.set_xlim(0, top)
    ax.set_ylim(0, top)
    ax.set_xlabel("measured peak lateral force (kN)")
    ax.set_ylabel("predicted (kN)")
    ax.set_title("laboratory shear-compression walls (Stone Masonry Database)", fontsize=9)
    ax.legend(fontsize=7, loc="upper left")
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


if __name__ == "__main__":
    main()

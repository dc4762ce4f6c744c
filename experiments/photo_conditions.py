"""Experiment: does the automatic calibration give the same wall under another light or framing?

The laboratory photos of data_external/real_photos were taken under one light, framed one way. A
user's photo of the same wall may be darker or lighter, flatter (haze, flare), shaded across, or
framed tighter or looser. Each real photo is changed as such a photo would differ (exposure in
linear light: -2, -1, +1 stops; a lens's vignetting, 60 % at the corners; light falling to 35 %
down or across the frame; the contrast halved about mid-grey; a tone curve of gamma 1.6; cropped
to 4 % of the width and 15/10 % of the height around the wall, or only the top tenth cut), saved
as a JPEG of quality 95 and calibrated automatically with its width given. Printed per photo and
change: H, its sigma, the error, the error in sigmas (z) and whether the truth lies within 2
sigma (`ok`), or the one-line refusal; then the counts.

    .venv/bin/python experiments/photo_conditions.py [--second | --third | --fourth | --all] [--write DIR] [--changes ev-2 crop_tight ...] [--truth data_external/real_photos/truth.json]

``--second``: ten other changes of the same kinds (-1.5, -3, +0.5 stops; light falling to 50 % or
20 % towards the foot, to 35 % towards the top, or across the diagonal; contrast 0.7; gamma 1.3 and
0.7), made after the rules of 2026-12-04 were measured on the first ten, to check them on changes
they were not tuned on. ``--third``: eight more (contrast 0.4, 0.6, 0.8; mist or flare as veiling light;
the black lifted; flatter and a stop darker; an S-curve of more contrast), made after the rule of
the fifty-fourth session was set. ``--fourth``: six veils made after the veil's rule. ``--all``: the four sets. ``--write DIR``: only write the changed
photos and a truth.json listing them, for ``bench_real_photos.py --truth DIR/truth.json`` (the
segmentation and the calibration without a length on them).

Measured 2026-12-04 on 5e69001 (docs/photo_path.md, "a photo under another light"): the truth
within 2 sigma in 20 of 30, outside in 10, none refused. The 10: SC4 cropped tighter, shaded from
the top or from a side, darker by 2 stops, flatter (contrast halved) or through gamma 1.6 (H -20
to -35 %, 6.7-8.7 sigma off: the shaded lowest course not taken for wall, the base a course high);
SC1 2 stops darker (-15.6 %, 4.3 sigma); SC2 2 stops darker, flatter or through gamma 1.6 (-5.6
to -17.8 %, 2.5-3.3 sigma). Tried and not kept: the outline's fine contrast taken over its mean
(shading-invariant, as its coarse one is): 8 outside and 2 refused here, 4 outside and 3
refused when the changed photos were truncated to 8 bits instead of rounded; SC1 one stop darker
went from -1.2 % to -19.2 % (8.9 sigma). The outline's lowest course is on a knife's edge on these
photos; the same change of light by half a grey level moves it a course.

Measured again on the fifty-third session's code (the base found again below a shaded bottom
course by its head joints, `calibrate.lines.base_below_heads`): 22 of 30 within 2 sigma. SC4
shaded from a side and cropped tighter now within (-4.5, -4.7 %); darker by 2 stops, shaded from
the top and flatter -6.8, -7.8, -9.1 % (2.9-4.2 sigma; were -24 to -25 %); gamma 1.6 -35.5 % as
before; SC1 and SC2 as before. Then with a soft rim's least fall in proportion to its lightness
(`lines.SOFT_LIGHT`): 26 of 30; two stops darker SC1 -3.2 %, SC2 -3.2 %, SC4 -3.7 %, SC4 shaded
from the top -3.5 %; outside: SC2 and SC4 with the contrast halved (-5.7, -9.1 %) and through
gamma 1.6 (-17.8, -35.5 %).

Measured again on the fifty-fourth session's code (a soft rim's least fall also at most a quarter
of the wall's spread of lightness, `lines.SOFT_SPREAD_SHARE`), against cd67f0b: 28 of 30 (26; the
three halved contrasts within now), `--second` 28 of 30 (27; SC4 contrast 0.7 -8.5 -> -4.7 %), and
`--third`, made after that rule was set, 17 of 24 (10), 5 outside (12), 2 refused (2). Outside: SC2
and SC4 through gamma 1.6, SC4 with its light to a fifth at the foot, and mist or flare (haze0.25,
haze0.4) on SC1 (+19 and +20 %, at 20-27 sigma), SC4 (-34, -35 %) and SC2 (haze0.4, -9 %).

Measured again on the fifty-fifth session's code (a veil taken off a photo whose darkest light is
above 0.15 of its lightest, `calibrate.veil.without_veil`): `--all` on the three sets 78 of 84
within 2 sigma (73), 3 outside (SC2 and SC4 gamma 1.6, SC4 shade_down20), 3 refused; ``--fourth``
(``FOURTH``, veils made after the rule) 9 of 18 within 2 sigma against 1 of 18 with the rule off:
the graded veils (flare_corner, flare_top) and the faint one (mist0.06) still fail.

Measured again on the fifty-sixth session's code (a veil graded across the frame found by a plane
through the blacks of the photo's 4 x 4 tiles, `calibrate.veil.VEIL_PLANE_SPREAD`): ``--fourth``
15 of 18 within 2 sigma (9), the six graded veils within 1.2 sigma (-1.2 to -4.8 %); the three
sets before unchanged (the graded rule acts on none of their photos). Then with that plane taken
off from 0.05 of the white (`VEIL_PLANE_SHARE`; 0.15 before): ``--all`` 95 of 102 (93), the faint
veil mist0.06 within 2 sigma on all three photos, 3 outside (SC2 and SC4 gamma 1.6, SC4
shade_down20), 4 refused.

``--fifth`` (``FIFTH``, 2026-12-05, fifty-seventh session): what the camera does rather than the
light (defocus of 1.5 and 3 px, a diagonal motion blur of 8 px, shot and read noise at a high ISO
and pushed two stops, a phone's sharpening, JPEG at quality 30, and a phone's chain of noise,
denoising, sharpening and JPEG 60). With the focal prior of before (log sigma 0.3): 21 of 24
within 2 sigma, SC4 phone outside (+5.3 %, its top on the loading beam's top), the motion blur
refused on SC1 and SC4 (the speckle's streaks taken for bed joints: 78 of them at 30-40 degrees on
SC4, yaw 48.9 degrees). With the prior at log sigma 1.0 (the package's since then): 21 of 24, SC4
noise_iso outside (-6.9 %, z -3.2; +1.2, +3.7, -2.8 % at log sigmas 0.3, 0.5, 0.7: its outline
follows the first fit), the same two refused. ``--all`` (the five sets, 126 photos): 116 within 2
sigma, 4 outside, 6 refused at 0.3; 117, 3 and 6 at 1.0; H within 2 % in 46 and 72 of the 120 fits.
"""

from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "data_external" / "real_photos"


def _linear(a: np.ndarray) -> np.ndarray:
    return np.where(a <= 0.04045, a / 12.92, ((a + 0.055) / 1.055) ** 2.4)


def _srgb(lin: np.ndarray) -> np.ndarray:
    lin = np.clip(lin, 0.0, 1.0)
    return np.where(lin <= 0.0031308, 12.92 * lin, 1.055 * lin ** (1 / 2.4) - 0.055)


def changed(rgb: np.ndarray, change: str) -> np.ndarray:
    """The photo ``rgb`` (rows, cols, 3) in [0, 1] as it would look under ``change``."""
    h, w = rgb.shape[:2]
    yy, xx = np.mgrid[0:h, 0:w]
    light = {
        "ev-2": 0.25,
        "ev-1": 0.5,
        "ev+1": 2.0,
        "vignette": (1 - 0.6 * ((xx - w / 2) ** 2 + (yy - h / 2) ** 2) / (0.5 * np.hypot(w, h)) ** 2)[..., None],
        "shade_down": np.linspace(1.0, 0.35, h)[:, None, None],
        "shade_side": np.linspace(0.35, 1.0, w)[None, :, None],
        # the second set (--second): changes of the same kinds at other strengths and directions
        "ev-1.5": 2**-1.5,
        "ev-3": 2**-3,
        "ev+0.5": 2**0.5,
        "shade_down50": np.linspace(1.0, 0.5, h)[:, None, None],
        "shade_down20": np.linspace(1.0, 0.2, h)[:, None, None],
        "shade_up35": np.linspace(0.35, 1.0, h)[:, None, None],
        "shade_diag": (0.3 + 0.7 * (1 - (yy / h + xx / w) / 2))[..., None],
    }
    if change in light:
        return _srgb(_linear(rgb) * light[change])
    flat = {  # the contrast scaled about mid-grey, or the black lifted (white kept)
        "contrast0.5": (0.5, 0.25),
        "contrast0.7": (0.7, 0.15),
        "contrast0.4": (0.4, 0.3),
        "contrast0.6": (0.6, 0.2),
        "contrast0.8": (0.8, 0.1),
        "lift0.2": (0.8, 0.2),
    }
    if change in flat:
        return flat[change][0] * rgb + flat[change][1]
    veil = {  # mist or flare: the scene's light dimmed, veiling light added
        "haze0.25": (0.75, 0.125),
        "haze0.4": (0.6, 0.14),
        # the fourth set: veils made after the veil's rule (calibrate.veil.without_veil)
        "mist0.06": (0.9, 0.06),
        "mist0.2": (0.7, 0.2),
        "mist_dark": (0.5, 0.1),
        "flare_blue": (0.8, np.array([0.06, 0.1, 0.16])),
        "flare_corner": (0.8, (0.03 + 0.22 * (1 - (yy / h + xx / w) / 2))[..., None]),
        "flare_top": (0.8, np.linspace(0.3, 0.05, h)[:, None, None]),
    }
    if change in veil:  # dimmed, and veiling light added (linear light): even, coloured or graded
        return _srgb(veil[change][0] * _linear(rgb) + veil[change][1])
    if change == "flat_dark":  # flatter and a stop darker
        return _srgb(0.5 * _linear(0.6 * rgb + 0.2))
    if change == "scurve":  # more contrast
        return np.clip(0.5 + 1.3 * (rgb - 0.5), 0.0, 1.0)
    if change.startswith("gamma"):
        return rgb ** float(change[len("gamma") :])
    if change in FIFTH:
        return _through_camera(rgb, change)
    if change == "crop_tight":
        return rgb[int(0.15 * h) : int(0.9 * h), int(0.04 * w) : int(0.96 * w)]
    if change == "crop_loose":
        return rgb[int(0.1 * h) :]
    raise ValueError(f"unknown change {change!r}")


CHANGES = (
    "ev-2",
    "ev-1",
    "ev+1",
    "vignette",
    "shade_down",
    "shade_side",
    "contrast0.5",
    "gamma1.6",
    "crop_tight",
    "crop_loose",
)
#: a second set, made after the rules of 2026-12-04 were measured on the first, to check them on
#: changes they were not tuned on
SECOND = (
    "ev-1.5",
    "ev-3",
    "ev+0.5",
    "shade_down50",
    "shade_down20",
    "shade_up35",
    "shade_diag",
    "contrast0.7",
    "gamma1.3",
    "gamma0.7",
)

#: a third set, made after the soft rim's least fall was set against the wall's spread of
#: lightness (lines.SOFT_SPREAD_SHARE, on contrast0.5 and contrast0.7 above), to check it on
#: flatter, hazier and harder photos it was not set on
THIRD = ("contrast0.4", "contrast0.6", "contrast0.8", "haze0.25", "haze0.4", "lift0.2", "flat_dark", "scurve")

#: a fourth set, made after the veil was taken off photos whose darkest light is over 0.15 of
#: their lightest (calibrate.veil.without_veil, set on haze0.25 and haze0.4 above): veils of
#: other strengths (one at the rule's edge), coloured, and graded across the frame as flare is
FOURTH = ("mist0.06", "mist0.2", "mist_dark", "flare_blue", "flare_corner", "flare_top")


#: a fifth set, made after the fourth's rules, of what the camera itself does to a photo rather
#: than the light: defocus and motion blur, sensor noise (shot and read noise in linear light,
#: luminance and colour), a phone's sharpening halo, heavy JPEG compression, and a phone's chain
#: of all three
FIFTH = ("defocus1.5", "defocus3", "motion8", "noise_iso", "noise_dark", "sharpen", "jpeg30", "phone")


def _through_camera(rgb: np.ndarray, change: str) -> np.ndarray:
    """The photo ``rgb`` as a camera's optics, sensor or processing would have spoilt it
    (deterministic: the noise's seed is fixed)."""
    from io import BytesIO

    from PIL import Image
    from scipy import ndimage

    rng = np.random.default_rng(7)

    def noisy(a: np.ndarray, gain: float, read: float) -> np.ndarray:
        lin = _linear(a)  # shot noise with variance gain * signal, read noise of sigma read
        sigma = np.sqrt(gain * lin + read**2)
        return _srgb(lin + sigma * rng.standard_normal(lin.shape))

    def sharpened(a: np.ndarray, amount: float, radius: float) -> np.ndarray:
        soft = ndimage.gaussian_filter(a, (radius, radius, 0))
        return np.clip(a + amount * (a - soft), 0.0, 1.0)

    def jpeg(a: np.ndarray, quality: int) -> np.ndarray:
        buf = BytesIO()
        Image.fromarray(np.round(255 * np.clip(a, 0, 1)).astype(np.uint8)).save(buf, "JPEG", quality=quality)
        buf.seek(0)
        with Image.open(buf) as im:
            return np.asarray(im.convert("RGB"), dtype=np.float64) / 255.0

    if change.startswith("defocus"):  # a lens focused off the wall: a disc's blur, near a Gaussian
        s = float(change[len("defocus") :])
        return ndimage.gaussian_filter(rgb, (s, s, 0))
    if change == "motion8":  # the camera moved 8 px along a diagonal while the shutter was open
        kernel = np.eye(8) / 8.0
        return np.stack([ndimage.convolve(rgb[..., c], kernel, mode="nearest") for c in range(3)], axis=-1)
    if change == "noise_iso":  # a high ISO: shot noise and read noise, per channel (colour noise)
        return noisy(rgb, 0.004, 0.006)
    if change == "noise_dark":  # two stops under, pushed back up in the camera: the noise pushed too
        return _srgb(4.0 * _linear(noisy(_srgb(0.25 * _linear(rgb)), 0.002, 0.004)))
    if change == "sharpen":  # a phone's unsharp mask: halos along every edge
        return sharpened(rgb, 1.0, 1.5)
    if change == "jpeg30":  # saved once at quality 30 (8 x 8 blocks, ringing)
        return jpeg(rgb, 30)
    if change == "phone":  # noise, then denoised, sharpened and compressed as a phone does
        return jpeg(sharpened(ndimage.gaussian_filter(noisy(rgb, 0.003, 0.005), (0.8, 0.8, 0)), 0.8, 1.2), 60)
    raise ValueError(f"unknown change {change!r}")


def changed_photos(photos: list[dict], folder: Path, changes: list[str], out: Path):
    """Each photo of ``photos`` (truth.json's entries, their files in ``folder``) under each of
    ``changes``, rounded to 8 bits and saved as a JPEG of quality 95 in ``out``: yields the entry,
    the change and the JPEG's path, photo by photo."""
    from PIL import Image

    for t in photos:
        with Image.open(folder / t["photo"]) as im:
            rgb = np.asarray(im.convert("RGB"), dtype=np.float64) / 255.0
        for change in changes:
            path = out / f"{t['wall']}_{change}.jpg"
            Image.fromarray(np.round(255 * np.clip(changed(rgb, change), 0, 1)).astype(np.uint8)).save(path, quality=95)
            yield t, change, path


def write(photos: list[dict], folder: Path, changes: list[str], out: Path) -> None:
    """The changed photos (:func:`changed_photos`) in ``out``, with a truth.json that lists them
    (the photos' own truths)."""
    out.mkdir(parents=True, exist_ok=True)
    listed = [{**t, "photo": path.name, "change": c} for t, c, path in changed_photos(photos, folder, changes, out)]
    (out / "truth.json").write_text(json.dumps({"photos": listed}, indent=1))
    print(f"{len(listed)} photos and truth.json written to {out}")


def main() -> None:
    import calib_masonry as cm
    from calib_masonry.errors import CalibMasonryError

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--changes", nargs="+", default=None, choices=CHANGES + SECOND + THIRD + FOURTH + FIFTH)
    ap.add_argument("--second", action="store_true", help="the second set of changes (SECOND) instead of the first")
    ap.add_argument("--third", action="store_true", help="the third set of changes (THIRD) instead of the first")
    ap.add_argument("--fourth", action="store_true", help="the fourth set of changes (FOURTH) instead of the first")
    ap.add_argument("--fifth", action="store_true", help="the fifth set of changes (FIFTH) instead of the first")
    ap.add_argument("--all", action="store_true", help="the five sets of changes")
    ap.add_argument("--truth", default=str(DATA / "truth.json"))
    ap.add_argument(
        "--write",
        metavar="DIR",
        help="only write the changed photos and their truth.json into DIR (for bench_real_photos.py --truth)",
    )
    a = ap.parse_args()
    chosen = (
        CHANGES + SECOND + THIRD + FOURTH + FIFTH
        if a.all
        else FIFTH
        if a.fifth
        else FOURTH
        if a.fourth
        else THIRD
        if a.third
        else SECOND
        if a.second
        else CHANGES
    )
    a.changes = a.changes or list(chosen)
    truth_path = Path(a.truth)
    photos = json.loads(truth_path.read_text())["photos"]
    if a.write:
        if (Path(a.write) / "truth.json").resolve() == truth_path.resolve():
            ap.error(f"--write {a.write}: that folder holds the truth it reads ({truth_path}); write elsewhere")
        write(photos, truth_path.parent, a.changes, Path(a.write))
        return
    print(f"{'photo':>6} {'change':>12} {'H m':>6} {'+-':>6} {'err':>7} {'z':>5}")
    ok = out = refused = 0
    with tempfile.TemporaryDirectory() as tmp:
        for t, change, path in changed_photos(photos, truth_path.parent, a.changes, Path(tmp)):
            try:
                cal = cm.calibrate_photo(path, cm.CalibrateConfig(known_width_m=t["width_m"]))
            except CalibMasonryError as exc:
                refused += 1
                print(f"{t['wall']:>6} {change:>12} refused: {exc}", flush=True)
                continue
            res = cal.result
            err = res.height_m - t["height_m"]
            within = abs(err) <= 2.0 * res.sigma("height_m")
            ok, out = ok + within, out + (not within)
            print(
                f"{t['wall']:>6} {change:>12} {res.height_m:6.3f} {res.sigma('height_m'):6.3f} "
                f"{100 * err / t['height_m']:+6.2f}% {err / res.sigma('height_m'):+5.1f}  {'ok' if within else 'OUT'}",
                flush=True,
            )
    print(f"truth within 2 sigma {ok}, outside {out}, refused {refused} (of {ok + out + refused})")


if __name__ == "__main__":
    main()

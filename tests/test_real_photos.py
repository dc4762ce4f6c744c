"""The photo path on real photographs and the features real photos need: scale sources, lens,
occluders, LabelMe, the joints' segmentation (issue 36).

The real photos are the laboratory stone walls of data_external/real_photos (W = H = 0.900 m,
30-40 stones); experiments/bench_real_photos.py measures the same on them and on views of them
this code was never tuned on.
"""

from __future__ import annotations

import json
import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

import calib_masonry as cm
from calib_masonry.errors import FitFailed, InputError

ROOT = Path(__file__).resolve().parents[1]
REAL = ROOT / "data_external" / "real_photos"
TRUTH = json.loads((REAL / "truth.json").read_text())["photos"]


@pytest.fixture(scope="module")
def real_calibrations():
    return {
        t["wall"]: cm.calibrate_photo(REAL / t["photo"], cm.CalibrateConfig(known_width_m=t["width_m"])) for t in TRUTH
    }


@pytest.mark.parametrize("wall", [t["wall"] for t in TRUTH])
def test_real_photo_outline_with_a_known_width_gives_the_height_within_its_sigma(real_calibrations, wall):
    """The automatic outline takes neither the loading beam, the sign, the rig nor the photo's
    border: with the width given, H comes within 2 % of the database's 0.900 m on SC1 and SC4
    (-1.2 and -1.8 % measured; -4.1 % on SC4 while the focal length's prior was a phone's, x/:
    1.35, against this laboratory camera's 75-100 mm), within 4 % on SC2 (-3.6 %: the next test),
    and the truth lies within 2 sigma of it."""
    t = next(t for t in TRUTH if t["wall"] == wall)
    cal = real_calibrations[wall]
    res = cal.result
    assert cal.mode == "automatic" and res.fit.ok and cal.scale_source == "known width"
    assert res.height_m == pytest.approx(t["height_m"], rel=0.04 if wall == "SC2" else 0.02)
    assert abs(res.height_m - t["height_m"]) <= 2.0 * res.sigma("height_m")
    rows, cols = cal.photo.rgb.shape[:2]
    quad = cal.detection.corners_px
    assert quad[:, 0].min() > 0.02 * cols and quad[:, 0].max() < 0.98 * cols  # not the photo's sides
    assert quad[:, 1].min() > 0.15 * rows  # not the beam's or the sign's top (y < 0.2 of the photo)


@pytest.mark.xfail(strict=True, reason="issue 36, not met: SC2's H with the width is -3.6 %, not within 2 %")
def test_real_photo_sc2_height_within_the_issues_two_percent(real_calibrations):
    """SC2's height within the issue's 2 % with the width given: not met. Its +0.2 % of before
    rested on a bed "vanishing point" of eight short segments, seven of them along the loading
    beam: the photo zoomed out by 0.95-0.75 gave -2.2 to -4.9 %, and at 0.85 an outline out of
    the photo (f 155 px). Without that point (outline.MIN_VP_SPREAD) it is -3.6 % at its own size
    and -2.2 to -4.9 % zoomed, within 1 sigma (4 %): the outline is a trapezoid, its right end 40
    px shorter than its left, whether the wall's top or the camera's yaw makes it."""
    t = next(t for t in TRUTH if t["wall"] == "SC2")
    assert real_calibrations["SC2"].result.height_m == pytest.approx(t["height_m"], rel=0.02)


@pytest.mark.slow
def test_a_real_photo_with_three_times_the_pixels_gives_the_same_height(real_calibrations, tmp_path):
    """The laboratory photo SC1 resampled to three times its pixels (2673 x 1782, Lanczos), as
    a camera with a finer sensor would have taken it: the outline's shaded base is carried as at
    its own size, so H is the same within 1.5 % and the truth lies within 2 sigma. Before the
    soft sides' noise floor (lines.SOFT_NOISE) it came out at 0.853 m with a sigma of 1.7 %
    (-5.3 %, 2.8 sigma) against 0.889 m at its own size."""
    from PIL import Image

    t = next(t for t in TRUTH if t["wall"] == "SC1")
    with Image.open(REAL / t["photo"]) as im:
        big = im.resize((3 * im.width, 3 * im.height), Image.LANCZOS)
    big.save(tmp_path / "sc1_x3.jpg", quality=92)
    cal = cm.calibrate_photo(tmp_path / "sc1_x3.jpg", cm.CalibrateConfig(known_width_m=t["width_m"]))
    assert "nan" not in cal.lens_source  # no long line found at this size: said in words
    own = real_calibrations["SC1"].result.height_m
    assert cal.result.height_m == pytest.approx(own, rel=0.015)
    assert abs(cal.result.height_m - t["height_m"]) <= 2.0 * cal.result.sigma("height_m")


@pytest.mark.slow
def test_a_real_photo_with_twice_the_pixels_does_not_take_its_beams_bow_for_a_lens(real_calibrations, tmp_path):
    """The laboratory photo SC4 at twice its pixels (1782 x 1188): its only long straight lines
    are the loading beam's two edges, which bow by about a pixel; with a line's pixel noise as its
    only doubt the fit kept a lens from them (k1 -0.084 +- 0.055) and gave H 0.831 m, 3.6 sigma
    short, where at its own size the lens was held (H 0.863 m). A scene's straight line is
    straight to L/500 (fit.PLUMB_STRAIGHTNESS): the lens is held at both sizes and H agrees."""
    from PIL import Image

    t = next(t for t in TRUTH if t["wall"] == "SC4")
    with Image.open(REAL / t["photo"]) as im:
        big = im.resize((2 * im.width, 2 * im.height), Image.LANCZOS)
    big.save(tmp_path / "sc4_x2.jpg", quality=92)
    cal = cm.calibrate_photo(tmp_path / "sc4_x2.jpg", cm.CalibrateConfig(known_width_m=t["width_m"]))
    own = real_calibrations["SC4"]
    assert own.lens_source.startswith("held") and cal.lens_source.startswith("held")
    assert cal.result.height_m == pytest.approx(own.result.height_m, rel=0.015)
    assert abs(cal.result.height_m - t["height_m"]) <= 2.0 * cal.result.sigma("height_m")


@pytest.mark.parametrize("wall", [t["wall"] for t in TRUTH])
def test_real_photo_without_a_length_is_refused_naming_the_prior_and_the_flags(wall):
    """No EXIF, no measured length: the scale rests on the eye-height prior, whose spread makes W
    and H uncertain by more than 25 % (the photo's camera stood at the wall's mid-height, 0.45 m,
    where the prior says 1.6 m): refused in one line naming the prior and the flags that pin it."""
    t = next(t for t in TRUTH if t["wall"] == wall)
    with pytest.raises(FitFailed) as err:
        cm.calibrate_photo(REAL / t["photo"], cm.CalibrateConfig())
    message = str(err.value)
    assert "eye-height prior" in message and "--known-width" in message and "--course-height" in message
    assert "--force" in message and "\n" not in message
    forced = cm.calibrate_photo(REAL / t["photo"], cm.CalibrateConfig(force=True))
    assert forced.relative_sigma() > 0.25 and forced.focal_source.startswith("prior")


def _relit(rgb: np.ndarray, light) -> np.ndarray:
    """``rgb`` in [0, 1] under ``light`` times the light (a number, or an array that broadcasts
    against it), in linear light (sRGB's curve undone and redone)."""
    lin = np.where(rgb <= 0.04045, rgb / 12.92, ((rgb + 0.055) / 1.055) ** 2.4)
    lin = np.clip(lin * light, 0.0, 1.0)
    return np.where(lin <= 0.0031308, 12.92 * lin, 1.055 * lin ** (1 / 2.4) - 0.055)


def test_a_bottom_course_in_shade_is_found_by_its_head_joints(monkeypatch):
    """SC4 with its light falling to 35 % towards its foot (a lamp high over the rig): the bottom
    course, in the shade, is not taken for wall by its appearance, and the outline's base stopped
    a course high at the left end and tilted (80 px there; H -24 % with the width given). That
    course's head joints run on below such a base (lines.base_below_heads): the base corners come
    within 8 px of those found at the photo's own light. Under the three photos' true bases the
    footing's steel blocks have edges that run on below the foot as head joints do: the strip
    such a base would take in is not masonry's texture, and the base stays."""
    from PIL import Image

    from calib_masonry.calibrate import lines
    from calib_masonry.calibrate.lines import DetectConfig, _work_scale, base_below_heads, detect_wall, joint_segments

    with Image.open(REAL / next(t for t in TRUTH if t["wall"] == "SC4")["photo"]) as im:
        rgb = np.asarray(im.convert("RGB"), dtype=np.float64) / 255.0
    own = detect_wall(rgb).corners_px
    shaded = np.round(255 * _relit(rgb, np.linspace(1.0, 0.35, rgb.shape[0])[:, None, None])) / 255
    found = detect_wall(shaded).corners_px
    assert np.linalg.norm(found[:2] - own[:2], axis=1).max() < 8.0
    moved_without_the_texture = []
    for t in TRUTH:
        with Image.open(REAL / t["photo"]) as im:
            rgb = np.asarray(im.convert("RGB"), dtype=np.float64) / 255.0
        d = detect_wall(rgb)
        args = (rgb, d.corners_px, d.corner_sigma_px, joint_segments(rgb), d.vp_head)
        half = 2.5 / _work_scale(rgb.shape, DetectConfig().work_long_side_px)
        assert np.array_equal(base_below_heads(*args, half)[0], d.corners_px), t["wall"]
        with monkeypatch.context() as m:
            m.setattr(lines, "HEAD_BELOW_TEXTURE", math.inf)
            moved_without_the_texture.append(not np.array_equal(base_below_heads(*args, half)[0], d.corners_px))
    assert any(moved_without_the_texture)  # the footing's edges would have been taken


def test_a_soft_rim_in_less_light_is_carried_as_far():
    """A soft side's ramp of lightness (the laboratory walls' shaded rims: from 0.23 to 0.06 over
    9 px, then the footing) in a quarter of the light (two stops darker, in sRGB about half the
    lightness) ends where it ends at full light: shade scales a ramp's fall with its light, and a
    fall of 0.085 from a rim at 0.12 was not taken for one (lines.SOFT_LIGHT). A rim that falls by
    less than SOFT_MIN_FALL at full light is still no ramp."""
    from calib_masonry.calibrate.lines import SOFT_MIN_FALL, _ramp_end

    offs = np.arange(-4.0, 28.0)
    ramp = np.interp(offs, [-4.0, 0.0, 9.0, 27.0], [0.24, 0.23, 0.06, 0.065])
    at_full = _ramp_end(ramp, offs)
    assert at_full > 0
    assert _ramp_end(0.5 * ramp, offs) == at_full
    shallow = np.interp(offs, [-4.0, 0.0, 9.0, 27.0], [0.24, 0.23, 0.23 - 0.8 * SOFT_MIN_FALL, 0.15])
    assert _ramp_end(shallow, offs) == 0.0


def test_a_soft_rim_on_a_flatter_photo_is_carried_as_far():
    """The same shaded rim on a photo of half the contrast (haze, flare, a flat tone curve: 0.5 x
    + 0.25) falls by half as much, 0.085, from a rim at 0.37: under SOFT_MIN_FALL, and lighter than
    SOFT_LIGHT, so it was not taken for a ramp. The wall's own spread of lightness halves with it:
    measured against a quarter of that (lines.SOFT_SPREAD_SHARE) the ramp ends where it ends at
    full contrast. A fall that is small against the wall's spread is still no ramp."""
    from calib_masonry.calibrate.lines import SOFT_SPREAD_SHARE, _ramp_end

    offs = np.arange(-4.0, 28.0)
    ramp = np.interp(offs, [-4.0, 0.0, 9.0, 27.0], [0.24, 0.23, 0.06, 0.065])
    spread = 0.42  # the laboratory photos' 0.41-0.45 (90th less 10th percentile)
    at_full = _ramp_end(ramp, offs, spread)
    assert at_full > 0
    flat = 0.5 * ramp + 0.25
    assert _ramp_end(flat, offs) == 0.0  # the photo's contrast unknown: no ramp
    assert _ramp_end(flat, offs, 0.5 * spread) == at_full
    fall = 0.8 * SOFT_SPREAD_SHARE * 0.2
    shallow = np.interp(offs, [-4.0, 0.0, 9.0, 27.0], [0.4, 0.39, 0.39 - fall, 0.39 - fall])
    assert _ramp_end(shallow, offs, 0.2) == 0.0
    assert _ramp_end(shallow, offs, 0.5 * 0.2) > 0  # a ramp against a wall of half that spread


@pytest.mark.slow
def test_a_flatter_real_photo_keeps_its_base(real_calibrations, tmp_path):
    """SC4 with its contrast at 0.7 (0.7 x + 0.15, a hazy or flat photo): its shaded base's rim
    fell by 0.07-0.10, under SOFT_MIN_FALL, and was not carried: the base 10 px high, H -8.5 % at
    3.9 sigma. Measured against the wall's own spread of lightness the rim is carried as at the
    photo's own contrast: the base corners within 4 px of those, the truth within 2 sigma."""
    from PIL import Image

    t = next(t for t in TRUTH if t["wall"] == "SC4")
    with Image.open(REAL / t["photo"]) as im:
        rgb = np.asarray(im.convert("RGB"), dtype=np.float64) / 255.0
    Image.fromarray(np.round(255 * (0.7 * rgb + 0.15)).astype(np.uint8)).save(tmp_path / "sc4_flat.jpg", quality=95)
    cal = cm.calibrate_photo(tmp_path / "sc4_flat.jpg", cm.CalibrateConfig(known_width_m=t["width_m"]))
    own = real_calibrations["SC4"].detection.corners_px
    assert np.linalg.norm(cal.detection.corners_px[:2] - own[:2], axis=1).max() < 4.0
    assert abs(cal.result.height_m - t["height_m"]) <= 2.0 * cal.result.sigma("height_m")


@pytest.mark.slow
def test_a_real_photo_two_stops_darker_gives_the_same_height(real_calibrations, tmp_path):
    """SC1 taken with a quarter of the light (two stops, in linear light): its shaded rims, at the
    top under the beam and at the foot, fall by less than at its own light, and were not carried:
    H -15.6 % at 4.3 sigma with the width given. Now within 5 % of H at its own light and the
    truth within 2 sigma."""
    from PIL import Image

    t = next(t for t in TRUTH if t["wall"] == "SC1")
    with Image.open(REAL / t["photo"]) as im:
        rgb = np.asarray(im.convert("RGB"), dtype=np.float64) / 255.0
    Image.fromarray(np.round(255 * _relit(rgb, 0.25)).astype(np.uint8)).save(tmp_path / "sc1_ev-2.jpg", quality=95)
    cal = cm.calibrate_photo(tmp_path / "sc1_ev-2.jpg", cm.CalibrateConfig(known_width_m=t["width_m"]))
    assert cal.result.height_m == pytest.approx(real_calibrations["SC1"].result.height_m, rel=0.05)
    assert abs(cal.result.height_m - t["height_m"]) <= 2.0 * cal.result.sigma("height_m")


def test_a_piece_inside_another_is_merged_into_it():
    """A piece whose one neighbour is another piece goes into it (traced by its outer boundary, the
    encloser covered it: SC1 built two overlapping stones, 9.2e-4 m^3); a piece on the photo's
    edge, or beside unlabelled pixels (an occluder), is not enclosed and stays."""
    from calib_masonry.wall2d.pieces import absorb_islands

    lab = np.ones((30, 40), dtype=np.int32)
    lab[:, 20:] = 2
    lab[10:15, 5:10] = 3  # inside 1
    lab[0:5, 25:30] = 4  # inside 2 but on the photo's edge
    lab[20:28, 25:35] = 0  # an occluder in 2
    lab[22:26, 28:32] = 5  # inside the occluder
    out = absorb_islands(lab)
    assert np.all(out[lab == 3] == out[5, 5]) and out.max() == 4
    assert len(np.unique(out[lab == 4])) == 1 and out[2, 27] != out[2, 22]
    assert np.all(out[lab == 0] == 0) and out[24, 30] not in (0, out[10, 30])
    assert np.array_equal(absorb_islands(out), out)


@pytest.mark.parametrize("wall", [t["wall"] for t in TRUTH])
def test_real_photo_segmentation_finds_the_stones_not_the_speckle(real_calibrations, wall):
    """The painted speckle, the cracks and the plaster are not joints: 25-45 pieces for 30-40
    stones (the top-hat found 1,527), none larger than two of the wall's largest stones (about
    0.05 m^2), and the count and sizes reported."""
    from calib_masonry.calibrate.rectify import rectify
    from calib_masonry.wall2d.segment import segment_wall

    cal = real_calibrations[wall]
    rect = rectify(cal, px_per_m=300.0)
    seg = segment_wall(rect, 300.0)
    s = seg.summary()
    assert seg.method == "joints" and "top-hat" in seg.note and "colour split" in seg.note
    assert 25 <= s["count"] <= 45 and s["max_area_m2"] < 0.1 and s["warning"] == ""
    assert s["piece_aspect"] < 1.0  # stones laid wider than tall


def test_a_laboratory_photo_turned_by_ninety_degrees_is_a_warning(real_calibrations):
    """A photo whose EXIF orientation was lost (a portrait photo stored sideways) rectifies as a
    wall on its side: the known width then measures its height, and nothing had said so. Its stones
    stand taller than wide (1.4-2.1 against 0.7-1.3 upright, at 150-600 px/m), and the summary asks."""
    from calib_masonry.calibrate.rectify import rectify
    from calib_masonry.wall2d.segment import segment_wall

    rect = rectify(real_calibrations["SC1"], px_per_m=300.0)
    upright = segment_wall(rect, 300.0).summary()
    turned = segment_wall(np.ascontiguousarray(np.rot90(rect)), 300.0).summary()
    assert upright["warning"] == "" and upright["piece_aspect"] < 1.0
    assert turned["piece_aspect"] > 1.4 and "turned by 90 degrees" in turned["warning"]


@pytest.mark.parametrize("smooth_px", [0.0, 3.0, 8.0])
def test_a_face_of_texture_alone_is_a_warning_not_a_silent_thousand_pieces(smooth_px):
    """A plastered or rendered wall, or a photo too noisy for its joints: the joints' partition
    measured its module from the texture's own lines and found 160-2,444 pieces that agreed with
    it, with no warning (a 4 x 2.4 m face of grain: "2034 pieces, module 8.6 x 8.7 cm"). Masonry's
    faces are mostly free of lines (the laboratory photos: the test above, no warning); here the
    lines cover the face, and the summary says so and what to do."""
    from scipy import ndimage

    from calib_masonry.wall2d.segment import segment_wall

    rng = np.random.default_rng(11)
    grain = 0.6 + 0.08 * rng.standard_normal((720, 1200))
    face = ndimage.gaussian_filter(grain, smooth_px) if smooth_px else grain
    seg = segment_wall(np.repeat(face[..., None], 3, -1).clip(0, 1).astype(np.float32), 300.0)
    s = seg.summary()
    assert seg.method == "joints" and s["count"] > 1
    assert "line-like evidence covers the whole face" in s["warning"] and "LabelMe" in s["warning"]


@pytest.mark.parametrize("mortar, irregularity, seed", [(0.03, 0.3, 45), (0.05, 0.7, 44)])
def test_a_stone_wall_with_broad_mortar_is_segmented_by_the_mortars_colour(tmp_path, mortar, irregularity, seed):
    """Rubble and stone walls have joints of 2-6 cm, wider than the top-hat's disk: it found their
    edges only, and the joints' partition cut each stone and its mortar along the mortar's grain
    (synth's own stone walls photographed: precision 0.10-0.52 against the truth, 1.4-2.8 times the
    stones). The pale band is taken by its colour; the laboratory photos' speckle is not (their
    segmentation test above: still the joints' partition)."""
    from calib_masonry.build_folder import build_to_folder
    from calib_masonry.comparison import compare_dirs
    from calib_masonry.synthetic.truth import synth_to_folder

    (tmp_path / "s.toml").write_text(
        '[structure]\nname = "rubble"\nthickness_m = 0.4\n[synthetic]\nlayout = "stones"\n'
        f"seed = {seed}\npx_per_m = 100\nmortar_m = {mortar}\nirregularity = {irregularity}\n"
        "stone_length_m = [0.4, 0.8]\nstone_height_m = [0.25, 0.45]\n"
        '[[wall]]\nname = "a"\nwidth_m = 2.8\nheight_m = 2.2\n'
    )
    synth_to_folder(tmp_path / "s.toml", tmp_path / "d", figures=False, photos=True)
    summary = build_to_folder(
        cm.load_structure(tmp_path / "d" / "structure_photos.toml"), tmp_path / "m", figures=False
    )
    assert summary["walls"][0]["pieces"]["method"] == "colour"
    m = compare_dirs(tmp_path / "m", tmp_path / "d" / "truth")
    assert m["precision"] >= 0.95 and m["recall"] >= 0.95 and m["dice"]["median"] >= 0.97


def _drawn_orthophoto(courses, lengths, mortar_m, px_per_m, ground_m, seed):
    """A wall's orthophoto drawn in colour: courses (heights, m, from the top) of units of random
    ``lengths`` (m, a range) in reddish tones with grain, ``mortar_m`` joints of pale grey, the
    lowest course standing on the wall's base and the end units cut by the wall's ends; below the
    base ``ground_m`` of dark ground, as where the fitted outline lies a little below the wall's
    foot. Returns the image and how many units it holds."""
    rng = np.random.default_rng(seed)
    width = 2.0
    rows, cols = int(round(sum(courses) * px_per_m)), int(round(width * px_per_m))
    img = np.empty((rows, cols, 3), np.float32)
    img[:] = (0.80, 0.78, 0.72)
    count, y = 0, 0.0
    for k, ch in enumerate(courses):
        r0 = int((y + mortar_m / 2) * px_per_m)
        r1 = rows if k == len(courses) - 1 else int((y + ch - mortar_m / 2) * px_per_m)
        # the units' ends: the first cut by the wall's end, the last running to the other end
        ends = [0.0, rng.uniform(0.5 * lengths[0], lengths[1])]
        while width - ends[-1] > lengths[1]:
            ends.append(ends[-1] + rng.uniform(*lengths))
        ends[-1] = width
        for x0, x1 in zip(ends[:-1], ends[1:]):
            c0 = 0 if x0 == 0.0 else int((x0 + mortar_m / 2) * px_per_m)
            c1 = cols if x1 == width else int((x1 - mortar_m / 2) * px_per_m)
            tone = np.array([0.58, 0.27, 0.19]) * rng.uniform(0.85, 1.15)
            img[r0:r1, c0:c1] = tone + 0.03 * rng.standard_normal((r1 - r0, c1 - c0, 3))
            count += 1
        y += ch
    ground = np.tile(np.array([0.37, 0.38, 0.28], np.float32), (int(round(ground_m * px_per_m)), cols, 1))
    return np.clip(np.concatenate([img, ground]), 0, 1), count


@pytest.mark.parametrize(
    "kind, courses, lengths, mortar_m, px_per_m, seed",
    [
        ("bricks", [0.075] * 10, (0.2, 0.23), 0.01, 400.0, 3),  # the top-hat's
        # the colour split's (where it splits by lightness: by chroma the grey ground is mortar)
        ("stones", [0.42, 0.38, 0.40], (0.35, 0.6), 0.025, 300.0, 4),
    ],
)
def test_ground_inside_the_outline_does_not_join_the_units_along_the_base(
    kind, courses, lengths, mortar_m, px_per_m, seed
):
    """An outline whose base lies 1.6 cm below the wall's foot (well within H's sigma) takes in a
    strip of ground, which is not mortar: it joined every unit of the lowest course into one piece
    (a stone wall rectified from an 8000 x 5333 px photo: 33 pieces, the largest two stones; these
    drawn walls 82 for 90 bricks and 7 for 10 stones). The joints now run on straight through a 2 cm
    band along the sides."""
    from calib_masonry.wall2d.segment import segment_wall

    for ground_m in (0.0, 0.016):
        rgb, count = _drawn_orthophoto(courses, lengths, mortar_m, px_per_m, ground_m, seed)
        seg = segment_wall(rgb, px_per_m)
        assert seg.method == ("mortar" if kind == "bricks" else "colour")
        assert seg.labels.max() == count, (ground_m, seg.labels.max(), count)


@pytest.mark.parametrize("band_m", [0.0, 0.03, 0.06])
def test_a_band_of_mortar_along_the_top_does_not_join_the_top_course(band_m):
    """A wall ending in a band of mortar (a capping; synth's walls whose height leaves under 0.4 of
    a course) whose outline takes the band in: the band is a plateau the top-hat does not find, and
    the top course's head joints stop a few pixels short of it, so the band joined the course into
    one piece (a 1.9 m wall's top course: one piece of 0.31 m^2). A band along the top or the
    bottom that no joint crosses is not a unit; a wall of long units with few head joints, whose
    thin top course is crossed by them as rarely as its other courses, keeps it."""
    from calib_masonry.wall2d.segment import segment_wall

    px = 400.0
    for courses, lengths, mortar_m, seed in (
        ([0.075] * 10, (0.2, 0.23), 0.01, 3),
        ([0.05] + [0.2] * 3, (0.6, 0.8), 0.01, 5),
    ):
        rgb, count = _drawn_orthophoto(courses, lengths, mortar_m, px, 0.0, seed)
        band = np.tile(np.array([0.80, 0.78, 0.72], np.float32), (int(round(band_m * px)), rgb.shape[1], 1))
        seg = segment_wall(np.concatenate([band, rgb]), px)
        assert seg.method == "mortar" and seg.labels.max() == count, (courses[0], band_m, seg.labels.max(), count)
        # the module is the pieces' median height and length (it was the square root of their
        # median area: 12.3 x 12.3 cm for these 6.5 x 20-23 cm bricks)
        if lengths[1] < 0.5:  # (the long units, two a course, end where the wall ends: no module)
            height, length = seg.summary()["module_m"]
            assert courses[-1] - 2 * mortar_m < height < courses[-1] and lengths[0] - 2 * mortar_m < length < lengths[1]


@pytest.mark.parametrize("courses, buff", [(10, False), (10, True), (40, False)])
def test_a_window_is_left_out_and_the_bricks_around_it_are_found(courses, buff):
    """A brick facade's window (dark glass in a pale frame) joins the bricks around it into one piece
    of the top-hat, 40-70 times the median: the pieces' sizes differed wildly, and the joints'
    partition cut the whole wall into blobs (12 Blender-rendered facades: 40 x 18 cm bricks found
    as pieces of 26-28 x 27-49 cm, 96 % of the windows' area covered by pieces). A region of another
    colour without unit-sized pieces is now an opening, left out as an occluder is, and the
    top-hat's pieces are the wall's bricks. A patch of buff bricks beside it, of another colour but
    with its joints, is no opening. In a wall four times as tall, the top-hat's pieces looked like
    masonry with the window and the bricks around it one piece of them (0.33 m^2): left out too."""
    from calib_masonry.wall2d.segment import segment_wall

    px = 400.0
    rgb, _ = _drawn_orthophoto([0.075] * courses, (0.2, 0.23), 0.01, px, 0.0, 7)
    r0, r1, c0, c1 = int(0.2 * px), int(0.6 * px), int(0.3 * px), int(0.75 * px)  # 0.4 x 0.45 m
    frame = int(0.03 * px)
    rgb[r0:r1, c0:c1] = (0.85, 0.85, 0.82)
    rgb[r0 + frame : r1 - frame, c0 + frame : c1 - frame] = (0.20, 0.24, 0.30)
    b0, b1 = int(1.1 * px), int(1.6 * px)
    if buff:
        patch = rgb[r0:r1, b0:b1]
        brick = patch[..., 0] < 0.7  # not the pale mortar
        patch[brick] = patch[brick][:, [1, 1, 2]] * (1.9, 1.6, 1.3)  # buff bricks, their joints kept
    seg = segment_wall(rgb, px)
    summary = seg.summary()
    assert seg.method == "mortar" and summary["openings"] == 1 and seg.labels[r0:r1, c0:c1].max() == 0
    # the opening is the window with its frame, not the bricks around it
    assert 0.9 < summary["openings_m2"] / ((r1 - r0) * (c1 - c0) / px**2) < 1.4, summary["openings_m2"]
    patch = seg.labels[r0:r1, b0:b1]
    assert len(np.unique(patch[patch > 0])) >= 15 and (patch > 0).mean() > 0.7
    # the bricks are each one piece (the drawn wall's bricks: 6.5 x 20-23 cm)
    height, length = summary["module_m"]
    assert 0.055 < height < 0.075 and 0.18 < length < 0.23
    # the polygon LabelMe gets ('opening', beside the pieces) is the window's, with the 2 cm margin
    # kept clear of pieces and the 1-2 cm the smoothed colour spreads
    from calib_masonry.calibrate.rectify import opening_polygons

    (poly,) = opening_polygons(seg)
    for corner, truth in ((poly.min(axis=0), (c0, r0)), (poly.max(axis=0), (c1, r1))):
        assert np.allclose(corner, truth, atol=0.05 * px), (corner, truth)


def test_with_the_width_measured_the_advice_is_about_the_corners_not_the_scale(real_calibrations):
    """With --known-width the laboratory photos' H is known to +-3 %: the note said "W and H are
    known only to ..." and told the user to pin the scale with --known-width, which was given. It
    names the loose side and what fixes it: the corners (clicked, or the outline corrected)."""
    for cal in real_calibrations.values():
        advice = cal.advice()
        assert advice.startswith("H is known only to") and "--known-width" not in advice
        assert "--corners" in advice and "--labelme" in advice and "known width" in advice


def test_a_segmentation_too_coarse_for_the_joints_says_so(real_calibrations):
    """An orthophoto at 100 px/m (an 8 mm joint 0.8 px): the stones come out as a dozen large
    pieces (12-15 on the laboratory walls, for 30-40), and the summary's warning says the
    resolution is too coarse and what to segment at, where it had been silent."""
    from calib_masonry.calibrate.rectify import rectify
    from calib_masonry.wall2d.segment import segment_wall

    cal = real_calibrations[TRUTH[0]["wall"]]
    s = segment_wall(rectify(cal, px_per_m=100.0), 100.0).summary()
    assert s["count"] < 25 and "too coarse to find the joints" in s["warning"] and "250 px/m" in s["warning"]


def _synthetic_photo(seed, *, k1=0.0, wall_index=0, size=(1500, 1000)):
    from calib_masonry.spec import PhotoSpec
    from calib_masonry.synthetic.photo import photograph_wall

    base = cm.load_structure(ROOT / "data_synthetic" / "paper_example" / "scenario.toml", require_sources=False)
    wall = base.walls[wall_index]
    scenario = replace(base, walls=(wall,), closed=False, synthetic=replace(base.synthetic, seed=seed))
    pieces, _ = cm.truth_structure(scenario)
    spec = replace(PhotoSpec(), long_side_px=max(size), short_side_px=min(size), k1=(k1, k1))
    shot = photograph_wall(wall, pieces[0], spec, np.random.default_rng(seed))
    t = shot["truth"]
    photo = cm.Photo(
        path=Path(f"synthetic{seed}"), rgb=shot["image"], focal_px=t["params"]["focal_px"], heading_deg=None
    )
    return wall, photo, t


@pytest.mark.slow
@pytest.mark.parametrize(("seed", "k1"), [(502, -0.15), (506, 0.05)])
def test_lens_distortion_is_recovered_and_the_wall_with_it(seed, k1):
    """A photo taken through a lens of known k1 (OpenCV's model): the plumb-line fit recovers k1
    within 10 % and W and H within 0.5 %, and the orthophoto is undistorted (its joints straight)."""
    wall, photo, t = _synthetic_photo(seed, k1=k1, wall_index=seed % 6, size=(3000, 2000))
    cal = cm.calibrate_photo(photo, cm.CalibrateConfig(camera_height_m=t["eye_height_m"]))
    res = cal.result
    assert not cal.lens_source.startswith("held")
    assert res.value("k1") == pytest.approx(k1, rel=0.1)
    assert res.width_m == pytest.approx(wall.width_m, rel=0.005)
    assert res.height_m == pytest.approx(wall.height_m, rel=0.005)
    before, after = res.plumb_rms_px
    assert after < 0.6 * before
    doc = cal.to_json()
    assert doc["distortion"]["k1"] == pytest.approx(k1, rel=0.1) and "OpenCV" in doc["distortion"]["model"]


def test_an_undistorted_photo_keeps_a_pinhole_lens():
    """No lens distortion in the photo: the straight joints stay as straight when undone, so the
    lens is held at 0 (a fitted k1 of noise would bend the orthophoto)."""
    wall, photo, t = _synthetic_photo(505, wall_index=0)
    cal = cm.calibrate_photo(photo, cm.CalibrateConfig(camera_height_m=t["eye_height_m"]))
    assert cal.lens_source.startswith("held at 0") and cal.result.value("k1") == pytest.approx(0.0, abs=0.01)


def test_a_lens_profile_map_gives_opencv_coefficients():
    """lensfun's corrected-to-photo map of a lens is turned into OpenCV's k1, k2 exactly when it is
    one (and an overall scale of the map, which is the focal length's, taken out)."""
    from calib_masonry.calibrate.camera import distort
    from calib_masonry.calibrate.lens import profile_from_map

    pp = (1499.5, 999.5)
    ys, xs = np.mgrid[0:2000:50, 0:3000:50]
    ideal = np.c_[xs.ravel(), ys.ravel()].astype(float)
    for k1, k2 in ((-0.12, 0.03), (0.05, 0.0)):
        prof = profile_from_map(ideal, distort(ideal, 2000.0, pp, k1, k2), pp, 2000.0, "test")
        assert prof.k1 == pytest.approx(k1, abs=1e-9) and prof.k2 == pytest.approx(k2, abs=1e-9)
    # lensfun itself, where it is installed: a real camera and lens give a barrel profile at 24 mm
    from calib_masonry.calibrate.lens import lensfun_profile

    exif = {
        "make": "Canon",
        "model": "Canon EOS 5D Mark II",
        "lens_make": "Canon",
        "lens_model": "Canon EF 24-105mm f/4L IS USM",
        "focal_mm": 24.0,
        "f_number": 8.0,
    }
    from calib_masonry.calibrate import lens

    lens._database.cache_clear()
    prof = lensfun_profile(exif, (3000, 2000), 2000.0)
    assert prof is not None and prof.k1 < 0 and "lensfun" in prof.source
    assert lensfun_profile({**exif, "lens_model": "no such lens"}, (3000, 2000), 2000.0) is None
    # the database is read once a process, and gives the same profile again
    assert lensfun_profile(exif, (3000, 2000), 2000.0) == prof
    assert lens._database.cache_info().misses == 1


def test_undistort_inverts_distort():
    from calib_masonry.calibrate.camera import distort, undistort

    pp = np.array((1499.5, 999.5))
    ideal = pp + np.random.default_rng(1).uniform(-1, 1, (500, 2)) * [1500, 1000]
    for k1, k2 in ((-0.3, 0.1), (-0.2, 0.0), (0.1, 0.05)):
        assert np.allclose(undistort(distort(ideal, 1800.0, pp, k1, k2), 1800.0, pp, k1, k2), ideal, atol=1e-6)


def test_known_length_between_two_points_scales_the_wall():
    """Two photo points on the wall and their distance: the base corners, a tape along the base."""
    wall, photo, t = _synthetic_photo(11)
    c = np.array(t["corners_px"])
    cal = cm.calibrate_photo(photo, cm.CalibrateConfig(known_length=(*c[0], *c[1], wall.width_m)))
    assert cal.scale_source == "known length"
    assert cal.result.width_m == pytest.approx(wall.width_m, rel=0.005)
    assert cal.result.height_m == pytest.approx(wall.height_m, rel=0.01)
    with pytest.raises(InputError, match="known-length"):
        cm.CalibrateConfig(known_length=(1.0, 1.0, 2.0, 2.0, 1.0))
    with pytest.raises(InputError, match="one measured length"):
        cm.CalibrateConfig(known_length=(*c[0], *c[1], 1.0), known_width_m=2.0)


def test_course_height_scales_a_brick_wall_from_its_courses():
    """The paper example's bricks lie in courses of 0.19 m (0.18 m and a 10 mm joint): that module
    alone gives the wall's height within 3 % (the sigma it reports covers the truth)."""
    wall, photo, t = _synthetic_photo(12)
    cal = cm.calibrate_photo(photo, cm.CalibrateConfig(course_height_m=0.19))
    assert cal.scale_source == "course height" and cal.courses["autocorrelation"] > 0.25
    assert cal.result.height_m == pytest.approx(wall.height_m, rel=0.03)
    assert abs(cal.result.height_m - wall.height_m) <= 2.0 * cal.result.sigma("height_m")
    assert cal.courses["courses"] == pytest.approx(wall.height_m / 0.19, rel=0.03)


def test_a_course_height_on_a_face_without_courses_is_refused(tmp_path):
    from calib_masonry.calibrate.courses import course_period

    rng = np.random.default_rng(3)
    with pytest.raises(FitFailed, match="repeat"):
        course_period(rng.normal(size=600))
    period, se, peak = course_period(np.sin(np.arange(600) * 2 * math.pi / 37.0) + 0.2 * rng.normal(size=600))
    assert period == pytest.approx(37.0, rel=0.01) and se < 0.5 and peak > 0.5


def test_clicked_corners_snap_within_a_tolerance_that_scales_with_the_photo_and_report_their_offset():
    """Corners clicked 3-5 px off on a 1500 px photo are snapped onto the outline (the offset
    reported per corner, in calibration.json too), and a click 60 px off (three times the tolerance)
    is kept as clicked."""
    wall, photo, t = _synthetic_photo(13)
    truth = np.array(t["corners_px"])
    clicks = truth + np.array([[4.0, -3.0], [-3.5, 3.0], [3.0, 4.0], [-4.0, -3.5]])
    cal = cm.calibrate_photo(photo, cm.CalibrateConfig(corners_px=tuple(clicks.ravel()), known_width_m=wall.width_m))
    assert cal.mode.startswith("clicked, snapped") and all(2.0 < d < 7.0 for d in cal.corner_snap_px)
    assert np.max(np.abs(cal.result.corners_px() - truth)) < 1.5
    assert len(cal.to_json()["corner_snap_px"]) == 4
    far = truth + np.array([[60.0, 0.0], [0.0, 0.0], [0.0, 0.0], [0.0, 0.0]])
    kept = cm.calibrate_photo(
        photo, cm.CalibrateConfig(corners_px=tuple(far.ravel()), known_width_m=wall.width_m, force=True)
    )
    assert kept.mode == "clicked" and kept.corner_snap_px is None


@pytest.mark.slow
def test_clicked_corners_on_a_blurred_photo_leave_out_the_streaks_taken_for_joints(real_calibrations, tmp_path):
    """A laboratory photo blurred 8 px along a diagonal (the camera moved): the speckle's streaks
    are found as hundreds of "joints" that fit no wall plane, and the corners clicked where the
    wall's are were refused with advice to click them (RMS 5.3 px). Now the streaks are left out,
    said in calibration.json, and the wall rests on the clicks: H within 1 % of the same clicks on
    the sharp photo. A sharp photo keeps its joints."""
    from PIL import Image
    from scipy import ndimage

    t = next(t for t in TRUTH if t["wall"] == "SC4")
    with Image.open(REAL / t["photo"]) as im:
        rgb = np.asarray(im.convert("RGB"), dtype=np.float64) / 255.0
    streak = np.eye(8) / 8.0
    blurred = np.stack([ndimage.convolve(rgb[..., c], streak, mode="nearest") for c in range(3)], axis=-1)
    path = tmp_path / "SC4_blurred.jpg"
    Image.fromarray(np.round(255 * blurred).astype(np.uint8)).save(path, quality=95)
    clicks = tuple(float(v) for v in real_calibrations["SC4"].result.corners_px().ravel())
    cfg = cm.CalibrateConfig(known_width_m=t["width_m"], corners_px=clicks)
    sharp = cm.calibrate_photo(REAL / t["photo"], cfg)
    cal = cm.calibrate_photo(path, cfg)
    assert sharp.joints_left_out == 0 and sharp.result.n_bed + sharp.result.n_head > 20
    assert cal.joints_left_out > 100 and cal.to_json()["joints_left_out"] == cal.joints_left_out
    assert cal.result.n_bed + cal.result.n_head == 0 and cal.result.rms_residual_px < 3.0
    assert cal.result.height_m == pytest.approx(sharp.result.height_m, rel=0.01)


def _turned(rgb: np.ndarray, focal_px: float, yaw_deg: float, pitch_deg: float, roll_deg: float, zoom: float):
    """``rgb`` as the same camera (focal length ``focal_px``, principal point at the centre) would
    have taken it turned by the angles and zoomed out by ``zoom``: the homography K' R K^-1, exact
    for any scene; the frame kept, black beyond the photo."""
    from scipy import ndimage

    from calib_masonry.calibrate.camera import wall_from_camera_rotation

    rows, cols = rgb.shape[:2]
    c = [(cols - 1) / 2, (rows - 1) / 2]
    k = np.array([[focal_px, 0, c[0]], [0, focal_px, c[1]], [0, 0, 1.0]])
    k2 = np.array([[focal_px * zoom, 0, c[0]], [0, focal_px * zoom, c[1]], [0, 0, 1.0]])
    rel = wall_from_camera_rotation(*np.radians([yaw_deg, pitch_deg, roll_deg])).T @ wall_from_camera_rotation(0, 0, 0)
    inv = np.linalg.inv(k2 @ rel @ np.linalg.inv(k))
    yy, xx = np.mgrid[0:rows, 0:cols]
    p = inv @ np.stack([xx.ravel(), yy.ravel(), np.ones(xx.size)])
    at = [p[1] / p[2], p[0] / p[2]]
    return np.stack(
        [ndimage.map_coordinates(rgb[..., i], at, order=1, mode="constant").reshape(rows, cols) for i in range(3)], -1
    )


def test_a_turned_laboratory_photo_takes_no_vanishing_point_on_its_wall():
    """SC4 as the laboratory's camera (2000 px) turned by about a degree each way would have taken
    it, zoomed out and brighter: its nine near-horizontal segments lay along the beam's edge, 2 %
    of the photo apart, so they met anywhere along it, and the least squares put the bed joints'
    "vanishing point" 100 px left of the photo. The photo rectified by it gave an outline whose
    base ran 32 degrees from the rows (the fit refused: RMS 3.1 px). On the same view with its
    angles to more digits (experiments/bench_real_photos.py's) the point fell on the wall, the base
    ran 76 degrees from the rows and H came out -25 % at a sigma of 1.5 %. A family whose segments
    lie within 5 % of the photo of one another (the outermost at each end aside) gives no
    vanishing point, nor does a point inside the photo (the axes are taken instead), and an
    outline whose sides are not about the rows and columns is not taken."""
    from calib_masonry.calibrate.outline import detect_outline

    t = next(t for t in TRUTH if t["wall"] == "SC4")
    view = _turned(cm.read_photo(REAL / t["photo"]).rgb, 2000.0, -1.0688, -0.6661, 0.7214, 0.8024)
    view = np.clip(view * 1.1712 + 0.0441, 0, 1).astype(np.float32)
    rows, cols = view.shape[:2]
    outline = detect_outline(view)
    for vp in (outline.vp_bed, outline.vp_head):
        if vp is not None:
            assert not (abs(vp[0] / vp[2] - cols / 2) < cols / 2 and abs(vp[1] / vp[2] - rows / 2) < rows / 2)
    quad = outline.corners_px
    base, top = quad[1] - quad[0], quad[2] - quad[3]
    assert abs(base[1]) < 0.1 * abs(base[0]) and abs(top[1]) < 0.1 * abs(top[0])
    photo = cm.Photo(path=Path("SC4-turned"), rgb=view, focal_px=None, heading_deg=None)
    cal = cm.calibrate_photo(photo, cm.CalibrateConfig(known_width_m=t["width_m"]))
    assert cal.result.height_m == pytest.approx(t["height_m"], rel=0.03)
    assert abs(cal.result.height_m - t["height_m"]) <= 2.0 * cal.result.sigma("height_m")


def test_a_laboratory_photo_zoomed_out_gives_the_outline_at_its_own_size(real_calibrations):
    """SC2 zoomed out by 0.85 about its centre (the frame kept, black around): its seven bed
    segments along the loading beam and one in the wall gave a vanishing point that rectified
    the photo into an outline out of the wall (a corner 110 px off, f 155 px, H with a sigma of
    2.3 %). Zoomed, the corners come back where they are at the photo's own size."""
    t = next(t for t in TRUTH if t["wall"] == "SC2")
    zoom = 0.85
    rgb = cm.read_photo(REAL / t["photo"]).rgb
    view = _turned(rgb, 2000.0, 0.0, 0.0, 0.0, zoom).astype(np.float32)
    photo = cm.Photo(path=Path("SC2-zoomed"), rgb=view, focal_px=None, heading_deg=None)
    cal = cm.calibrate_photo(photo, cm.CalibrateConfig(known_width_m=t["width_m"]))
    own = real_calibrations["SC2"].result
    centre = np.array([rgb.shape[1] - 1, rgb.shape[0] - 1]) / 2.0
    back = (cal.result.corners_px() - centre) / zoom + centre
    assert np.max(np.linalg.norm(back - own.corners_px(), axis=1)) < 8.0
    assert cal.result.height_m == pytest.approx(own.height_m, rel=0.02)


def test_occluders_are_left_out_of_the_outline_and_the_pieces():
    """A person-sized occluder painted over part of a wall: the outline is found all the same, and
    no piece is segmented under it."""
    from calib_masonry.calibrate.rectify import rectify, valid_ortho
    from calib_masonry.wall2d.segment import segment_wall

    wall, photo, t = _synthetic_photo(14)
    c = np.array(t["corners_px"])
    centre = c.mean(axis=0)
    box = np.array([[-60.0, -90.0], [60.0, -90.0], [60.0, 90.0], [-60.0, 90.0]]) + centre
    rgb = photo.rgb.copy()
    x0, y0 = box.min(axis=0).astype(int)
    x1, y1 = box.max(axis=0).astype(int)
    rgb[y0:y1, x0:x1] = [0.1, 0.5, 0.1]  # a green blob where the wall is
    hidden = replace(photo, rgb=rgb)
    cal = cm.calibrate_photo(hidden, cm.CalibrateConfig(known_width_m=wall.width_m, occluders=(box,)))
    assert np.max(np.abs(cal.detection.corners_px - c)) < 2.0
    rect = rectify(cal, px_per_m=200.0)
    valid = valid_ortho(cal, 200.0)
    assert 0.0 < (~valid).mean() < 0.2
    seg = segment_wall(rect, 200.0, valid=valid)
    assert not seg.mask[~valid].any()


def test_an_occluder_over_the_photos_centre_leaves_the_wall_found_around_it():
    """Someone standing in front of the middle of a laboratory wall, given as an occluder (300 x 300
    px of the 594 x 891 photo, painted over): the automatic outline learnt the wall's appearance
    from a square at the photo's centre, all of it under the occluder, and found "no wall". Now the
    square grows until a quarter of it is free and learns from that: the wall's corners within a few
    pixels of the unoccluded photo's at the base (the top may take the beam: H +5.5 % here, at 1.0
    sigma), H within two sigmas. An occluder over nearly the whole wall is
    refused, saying so (it said the centre looked like its surroundings)."""
    from calib_masonry.calibrate.lines import _in_convex
    from calib_masonry.errors import FitFailed

    photo = cm.read_photo(REAL / "photo_SC4_D0p70_Godio2019.jpg")
    free = cm.calibrate_photo(photo, cm.CalibrateConfig(known_width_m=0.9))
    box = np.array([[150.0, 300.0], [450.0, 300.0], [450.0, 600.0], [150.0, 600.0]])
    rgb = photo.rgb.copy()
    rgb[300:600, 150:450] = [0.55, 0.2, 0.2]  # a red coat where the wall is
    hidden = replace(photo, rgb=rgb)
    cal = cm.calibrate_photo(hidden, cm.CalibrateConfig(known_width_m=0.9, occluders=(box,)))
    # the wall around it, not a piece beside it: its base as without the occluder, the occluder inside
    assert np.max(np.abs(cal.detection.corners_px[:2] - free.detection.corners_px[:2])) < 8.0
    assert _in_convex(box, cal.detection.corners_px).all()
    assert abs(cal.result.height_m - 0.9) < 2 * cal.result.sigma("height_m")
    most = np.array([[30.0, 150.0], [560.0, 150.0], [560.0, 700.0], [30.0, 700.0]])
    with pytest.raises(FitFailed, match="occluders cover the middle of the photo"):
        cm.calibrate_photo(photo, cm.CalibrateConfig(known_width_m=0.9, occluders=(most,)))


def test_labelme_round_trip_edits_one_stone_and_builds_it(tmp_path):
    """A LabelMe file of a wall's pieces (as rectify and build write them), one stone's polygon
    edited (made smaller) in it, read back as the wall's mask by build: the model has that stone as
    edited and every other one as before."""
    from calib_masonry.labelme import read_labelme, write_labelme
    from calib_masonry.wall2d.trace import TraceConfig, trace_mask

    mask = np.zeros((200, 300), dtype=bool)
    for r0 in (20, 120):
        for c0 in (0, 155):
            mask[r0 : r0 + 80, c0 : c0 + 145] = True
    traced = trace_mask(mask, TraceConfig(vertices=4))
    pieces = [b.vertices_xy for b in traced.bricks]
    path = tmp_path / "wall1.json"
    write_labelme(path, "rectified.png", mask.shape, pieces=pieces)
    doc = json.loads(path.read_text())
    assert doc["imageHeight"] == 200 and all(s["label"] == "piece" for s in doc["shapes"])
    # the engineer's edit: the first stone's right half removed
    pts = np.array(doc["shapes"][0]["points"])
    pts[:, 0] = np.minimum(pts[:, 0], pts[:, 0].min() + 65.0)
    doc["shapes"][0]["points"] = pts.tolist()
    path.write_text(json.dumps(doc))
    back = read_labelme(path)
    assert len(back.pieces) == 4
    (tmp_path / "structure.toml").write_text(
        '[structure]\nname = "edit"\nthickness_m = 0.2\nvertices = 4\nclosed = false\n'
        '[[wall]]\nname = "wall1"\nmask = "wall1.json"\nwidth_m = 3.0\nheight_m = 2.0\ntheta_deg = 0\n'
    )
    built = cm.build(cm.load_structure(tmp_path / "structure.toml"))
    areas = sorted(b.volume / 0.2 for b in built.structure.bricks)
    assert len(areas) == 4
    # three stones of 1.45 x 0.8 m and the edited one of 0.65 x 0.8 m (to a pixel at 100 px/m)
    assert areas[0] == pytest.approx(0.65 * 0.8, rel=0.05)
    assert all(a == pytest.approx(1.45 * 0.8, rel=0.05) for a in areas[1:])


def test_a_shaded_band_without_visible_joints_is_split_not_the_whole_wall():
    """A brick wall whose top two courses lie in an eave's shade (dark, the joints faint): the
    top-hat sees no joint there, the band is one piece among bricks, and its pieces were refused
    for their sizes; the colour split then took the band for mortar (no unit in it: 108 pieces for
    126 bricks), and on three Blender facades the joints' partition cut the whole wall into blobs.
    Now only the pieces far larger than the rest are split by the joints' partition, with the
    rest's course height and unit length."""
    from calib_masonry.wall2d.segment import segment_wall

    px = 400.0
    rgb, _ = _drawn_orthophoto([0.075] * 14, (0.2, 0.23), 0.01, px, 0.0, 7)
    band = slice(0, int(0.15 * px))
    top = rgb[band]
    mortar = top[..., 0] > 0.7
    top[mortar] *= 0.55
    rgb[band] = top * 0.45
    seg = segment_wall(rgb, px)
    summary = seg.summary()
    assert seg.method == "mortar" and "split by the joints' partition" in seg.note
    inside = seg.labels[band]
    assert len(np.unique(inside[inside > 0])) >= 6 and (inside > 0).mean() > 0.6
    height, length = summary["module_m"]
    assert 0.055 < height < 0.075 and 0.18 < length < 0.23
    assert summary["max_area_m2"] < 4 * 0.065 * 0.215


def test_labelme_openings_are_kept_apart_from_the_pieces(tmp_path):
    """The openings a segmentation left out are written as 'opening' shapes beside the pieces; read
    back (with 'window' and 'door' drawn by hand), they make no piece of the wall's mask, and as a
    photo's occluders they are left out of its fit and segmentation as occluders are."""
    from calib_masonry.labelme import labelme_labels, read_labelme, read_occluders, write_labelme

    square = np.array([[10.0, 10.0], [60.0, 10.0], [60.0, 40.0], [10.0, 40.0]])
    path = tmp_path / "rectified.json"
    write_labelme(path, "rectified.png", (100, 200), pieces=[square], openings=[square + (100.0, 0.0)])
    doc = json.loads(path.read_text())
    assert sorted(sh["label"] for sh in doc["shapes"]) == ["opening", "piece"]
    for label, dx in (("window", 0.0), ("Door", 60.0)):
        doc["shapes"].append({"label": label, "points": (square + (dx, 50.0)).tolist(), "shape_type": "polygon"})
    path.write_text(json.dumps(doc))
    back = read_labelme(path)
    assert len(back.pieces) == 1 and len(back.openings) == 3 and back.occluders == ()
    assert labelme_labels(back).max() == 1
    assert len(read_occluders(path)) == 3


def _mask_shape(label: str, region: np.ndarray) -> dict:
    """A LabelMe mask shape as its AI tools write it: the box's first and last pixel and a base64 PNG
    of the box."""
    import base64
    import io

    from PIL import Image

    rows, cols = np.nonzero(region)
    y1, y2, x1, x2 = rows.min(), rows.max(), cols.min(), cols.max()
    buf = io.BytesIO()
    Image.fromarray(region[y1 : y2 + 1, x1 : x2 + 1].astype(np.uint8)).save(buf, format="PNG")
    return {
        "label": label,
        "points": [[float(x1), float(y1)], [float(x2), float(y2)]],
        "shape_type": "mask",
        "mask": base64.b64encode(buf.getvalue()).decode(),
        "group_id": None,
        "flags": {},
    }


def test_labelme_mask_shapes_are_read_as_the_pieces_they_fill(tmp_path):
    """Stones marked with LabelMe's AI tools are mask shapes (a box and a PNG of it), which were
    refused ("draw ... as polygons or rectangles"): each is read as the outline of its pixels, so
    that the wall built from them has every stone pixel for pixel, irregular ones included."""
    from calib_masonry.labelme import labelme_labels, labelme_mask, read_labelme

    yy, xx = np.mgrid[0:200, 0:300]
    stones = [
        (yy >= 20) & (yy < 100) & (xx < 145),  # a block to the wall's left end
        ((yy - 60) / 38.0) ** 2 + ((xx - 225) / 70.0) ** 2 <= 1.0,  # a rounded stone
        (yy >= 110) & (xx < 150) & (xx + yy > 130),  # a block with a corner cut off
        (yy >= 115) & (xx >= 158) & (xx < 300) & ((xx - 230) ** 2 + (yy - 160) ** 2 > 15**2),  # one with a hole
    ]
    doc = {"version": "5.5.0", "flags": {}, "imagePath": "rectified.png", "imageData": None}
    doc.update(imageHeight=200, imageWidth=300, shapes=[_mask_shape("stone", m) for m in stones])
    path = tmp_path / "wall1.json"
    path.write_text(json.dumps(doc))
    back = read_labelme(path)
    labels = labelme_labels(back)
    hole = (xx - 230) ** 2 + (yy - 160) ** 2 <= 15**2
    for k, m in enumerate([*stones[:3], stones[3] | hole], start=1):  # a piece is its outline: holes filled
        assert np.array_equal(labels == k, m)
    assert np.array_equal(labelme_mask(back), labels > 0)  # drawn apart, they stay as drawn
    (tmp_path / "structure.toml").write_text(
        '[structure]\nname = "ai"\nthickness_m = 0.2\nvertices = 8\nclosed = false\n'
        '[[wall]]\nname = "wall1"\nmask = "wall1.json"\nwidth_m = 3.0\nheight_m = 2.0\ntheta_deg = 0\n'
    )
    built = cm.build(cm.load_structure(tmp_path / "structure.toml"))
    assert len(built.structure.bricks) == 4
    doc["shapes"][0]["mask"] = "not base64!"
    path.write_text(json.dumps(doc))
    with pytest.raises(InputError, match=r"shape 1 \('stone'\): its 'mask' is not a base64 PNG"):
        read_labelme(path)


def test_labelme_files_with_wrong_labels_or_shapes_are_one_line_errors(tmp_path):
    from calib_masonry.labelme import read_labelme, read_occluders

    bad = tmp_path / "bad.json"
    bad.write_text(
        json.dumps(
            {"shapes": [{"label": "tree", "points": [[0, 0], [5, 0], [5, 5]]}], "imageHeight": 10, "imageWidth": 10}
        )
    )
    with pytest.raises(InputError, match="'tree'"):
        read_labelme(bad)
    bad.write_text("{not json")
    with pytest.raises(InputError, match="not readable"):
        read_labelme(bad)
    with pytest.raises(InputError, match="not found"):
        read_occluders(tmp_path / "missing.json")
    (tmp_path / "occ.json").write_text(json.dumps([[[0, 0], [10, 0], [10, 10]]]))
    assert len(read_occluders(tmp_path / "occ.json")) == 1


@pytest.mark.slow
def test_rectify_cli_on_a_real_photo_writes_labelme_and_names_the_scale(tmp_path, capsys):
    from calib_masonry.cli import main

    out = tmp_path / "out"
    photo = REAL / TRUTH[0]["photo"]
    assert main(["rectify", str(photo), "--known-width", "0.9", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "scale from the known width" in printed and "segmentation:" in printed and "pieces" in printed
    doc = json.loads((out / "calibration.json").read_text())
    assert doc["scale_source"] == "known width" and "distortion" in doc and 25 <= doc["pieces"]["count"] <= 45
    ortho = json.loads((out / "rectified.json").read_text())
    labels = {s["label"] for s in ortho["shapes"]}
    assert labels == {"wall", "piece"} and ortho["imagePath"] == "rectified.png"
    photo_doc = json.loads((out / "photo.json").read_text())
    assert [s["label"] for s in photo_doc["shapes"]] == ["wall"] and len(photo_doc["shapes"][0]["points"]) == 4
    # the photo's LabelMe, corrected, goes back to rectify: its outline gives the corners
    assert (
        main(
            [
                "rectify",
                str(photo),
                "--known-width",
                "0.9",
                "--labelme",
                str(out / "photo.json"),
                "--out",
                str(tmp_path / "again"),
            ]
        )
        == 0
    )
    again = json.loads((tmp_path / "again" / "calibration.json").read_text())
    # clicked corners are snapped and their soft sides carried again: the right side goes out 6-7 px
    # onto the lit face's edge, as the left already did (H 0.879 against 0.889 m; 0.892 before
    # lines.SOFT_NOISE, when 2 of that side's 4 quarters read as crisp)
    assert again["mode"].startswith("clicked") and again["height_m"] == pytest.approx(doc["height_m"], rel=0.015)
    # no length: one line, exit 2, nothing written
    assert main(["rectify", str(photo), "--out", str(tmp_path / "refused")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "eye-height prior" in err and not (tmp_path / "refused").exists()


def test_a_coarse_orthophoto_is_segmented_at_its_own_resolution(monkeypatch):
    """A 20 px/m orthophoto of a fit that came out 14 x 75 m was taken to 300 px/m for the joints'
    partition (96 Mpx, 10 GB): the partition is made at the orthophoto's own resolution when that
    is coarser, and on at most MAX_PIECES_PIXELS pixels."""
    from calib_masonry.wall2d import pieces, segment

    seen = []
    real = pieces.segment_pieces

    def spy(rgb, px_per_m, *args, **kwargs):
        seen.append((rgb.shape[:2], px_per_m))
        return real(rgb, px_per_m, *args, **kwargs)

    monkeypatch.setattr(pieces, "segment_pieces", spy)
    monkeypatch.setattr(segment, "mortar_plausible", lambda mask, labels=None, px_per_m=None: "no mortar (forced)")
    rng = np.random.default_rng(0)
    rgb = np.clip(0.5 + 0.1 * rng.standard_normal((300, 60, 3)), 0, 1).astype(np.float32)
    seg = segment.segment_wall(rgb, 20.0)
    assert seg.method == "joints" and seen == [((300, 60), pytest.approx(20.0))]
    assert seg.mask.shape == rgb.shape[:2]


def test_a_real_brick_close_up_with_clicked_corners_writes_its_bricks(tmp_path):
    """A photo not of the laboratory set (scikit-image's close-up of a brick pavement, 512 x 512,
    in the installed package): its corners clicked at the photo's corners, rectify writes the
    pieces. It had ended in a traceback: the orthophoto shrunk for the segmentation (303 x 300
    px at its column scale) was a row longer than its mask of valid pixels. About 13 columns of
    5-7 bricks, partial ones at the border included. Its bricks stand on end, as a wall's do in a
    photo turned by 90 degrees: the summary asks whether it is."""
    from PIL import Image
    from skimage import data

    from calib_masonry.cli import main

    photo = tmp_path / "brick.png"
    Image.fromarray(data.brick()).save(photo)
    out = tmp_path / "out"
    assert (
        main(["rectify", str(photo), "--corners", "0,0,511,0,511,511,0,511", "--known-width", "1.0", "--out", str(out)])
        == 0
    )
    doc = json.loads((out / "calibration.json").read_text())
    pieces = doc["pieces"]
    assert 60 <= pieces["count"] <= 120 and pieces["piece_aspect"] > 2
    assert (
        pieces["warning"].startswith("the pieces are taller than wide") and "turned by 90 degrees" in pieces["warning"]
    )
    assert pieces["max_area_m2"] < 3 * pieces["median_area_m2"]
    ortho = json.loads((out / "rectified.json").read_text())
    assert sum(s["label"] == "piece" for s in ortho["shapes"]) == pieces["count"]


def test_a_stone_wall_built_from_its_photo_is_traced_to_the_stones_shapes(tmp_path):
    """build of a real stone wall from its photo alone (the width measured; nothing said about the
    polygons): its pieces are traced to the fewest vertices reaching Dice 0.95. With the five
    vertices a brick gets, irregular stones were a tangle of overlapping triangles (measured: a
    mean Dice of 0.84 against the segmentation and 7.3e-4 m^3 between two stones; now 0.955 and
    8.6e-5 m^3). A wall given ``vertices`` keeps them; a mask wall keeps five."""
    from calib_masonry.cli import main

    t = TRUTH[0]
    photo = tmp_path / "wall.jpg"
    photo.write_bytes((REAL / t["photo"]).read_bytes())
    (tmp_path / "structure.toml").write_text(
        '[structure]\nname = "lab"\nthickness_m = 0.2\nclosed = false\n'
        f'[[wall]]\nname = "wall"\nimage = "wall.jpg"\nwidth_m = {t["width_m"]}\ntheta_deg = 0\n'
    )
    spec = cm.load_structure(tmp_path / "structure.toml")
    assert spec.walls[0].vertices is None and spec.walls[0].target_dice == pytest.approx(0.95)
    assert main(["build", str(tmp_path / "structure.toml"), "--out", str(tmp_path / "model")]) == 0
    summary = json.loads((tmp_path / "model" / "summary.json").read_text())
    assert 25 <= summary["bricks"] <= 45 and summary["mean_dice"] >= 0.93
    assert summary["max_interpenetration_m3"] < 2.5e-4
    # the scale from a measured length between two photo points instead (the base's two ends)
    c = json.loads((tmp_path / "model" / "photos" / "wall" / "calibration.json").read_text())["corners_px"]
    measured = (
        (tmp_path / "structure.toml")
        .read_text()
        .replace(
            f"width_m = {t['width_m']}", f"known_length = [{c[0][0]}, {c[0][1]}, {c[1][0]}, {c[1][1]}, {t['width_m']}]"
        )
    )
    (tmp_path / "measured.toml").write_text(measured)
    assert main(["build", str(tmp_path / "measured.toml"), "--no-figures", "--out", str(tmp_path / "m2")]) == 0
    wall = json.loads((tmp_path / "m2" / "summary.json").read_text())["walls"][0]
    assert wall["scale_source"] == "known length" and wall["width_m"] == pytest.approx(t["width_m"], rel=0.01)
    given = (tmp_path / "structure.toml").read_text().replace("closed = false", "closed = false\nvertices = 5")
    (tmp_path / "structure.toml").write_text(given)
    assert cm.load_structure(tmp_path / "structure.toml").walls[0].vertices == 5


def test_the_pieces_rectify_writes_as_labelme_build_as_many_stones(tmp_path):
    """The engineer's loop on a real photo: rectify writes rectified.json, and build reads it back as
    the wall's mask (nothing said about the polygons): one stone per piece, traced to Dice 0.95.
    Read as a mask, the one-pixel lines between stones that touch were filled as holes and the
    stones merged (36 pieces built as 24, at a mean Dice of 0.86)."""
    from calib_masonry.cli import main

    t = TRUTH[0]
    out = tmp_path / "rect"
    assert main(["rectify", str(REAL / t["photo"]), "--known-width", "0.9", "--no-figures", "--out", str(out)]) == 0
    doc = json.loads((out / "calibration.json").read_text())
    (tmp_path / "structure.toml").write_text(
        '[structure]\nname = "lab"\nthickness_m = 0.2\nclosed = false\n'
        f'[[wall]]\nname = "wall"\nmask = "rect/rectified.json"\nwidth_m = {doc["width_m"]}\n'
        f"height_m = {doc['height_m']}\ntheta_deg = 0\n"
    )
    assert main(["build", str(tmp_path / "structure.toml"), "--no-figures", "--out", str(tmp_path / "model")]) == 0
    summary = json.loads((tmp_path / "model" / "summary.json").read_text())
    assert summary["bricks"] == doc["pieces"]["count"] and summary["mean_dice"] >= 0.93
    assert summary["max_interpenetration_m3"] < 2.5e-4
    # and trace reads it the same way
    polygons = tmp_path / "polygons.json"
    assert (
        main(["trace", str(out / "rectified.json"), "--target-dice", "0.95", "--no-figures", "--out", str(polygons)])
        == 0
    )
    assert len(json.loads(polygons.read_text())["bricks"]) == doc["pieces"]["count"]


def test_rectify_draws_the_occluders_it_was_given(tmp_path):
    """rectify with --occluders and its figures: the overlay draws them (in magenta). It ended in a
    KeyError while drawing, after the fit, so no command with occluders and figures ever finished."""
    from PIL import Image

    from calib_masonry.cli import main

    occ = tmp_path / "occ.json"
    occ.write_text(json.dumps([[[200, 100], [400, 100], [400, 200], [200, 200]]]))
    out = tmp_path / "out"
    photo = REAL / TRUTH[0]["photo"]
    assert main(["rectify", str(photo), "--known-width", "0.9", "--occluders", str(occ), "--out", str(out)]) == 0
    overlay = np.asarray(Image.open(out / "overlay.png").convert("RGB")).astype(int)
    magenta = (overlay[..., 0] > 200) & (overlay[..., 1] < 60) & (overlay[..., 2] > 200)
    assert magenta.sum() > 300  # the occluder's outline and its legend's line
    assert [s["label"] for s in json.loads((out / "photo.json").read_text())["shapes"]] == ["wall", "occluder"]


def test_a_study_of_a_photo_wall_draws_around_its_measured_width_and_keeps_its_stones(tmp_path):
    """A geometry study of a real stone wall built from its photo, its width measured: every sample
    runs (the study calibrated the photo with W and H set free, on the eye-height prior, and
    refused every sample), and each has the stones build finds (the study traced the photo's mask,
    whose one-pixel lines between stones it filled: 16 stones where build has 32), grown or
    shrunk by the drawn pixel without merging."""
    from calib_masonry.cli import main
    from calib_masonry.study.design import load_study
    from calib_masonry.study.run import run_study

    t = TRUTH[0]
    (tmp_path / "wall.jpg").write_bytes((REAL / t["photo"]).read_bytes())
    (tmp_path / "structure.toml").write_text(
        '[structure]\nname = "lab"\nthickness_m = 0.2\nclosed = false\n'
        f'[[wall]]\nname = "wall"\nimage = "wall.jpg"\nwidth_m = {t["width_m"]}\ntheta_deg = 0\n'
    )
    (tmp_path / "study.toml").write_text(
        '[study]\nname = "lab"\nstructure = "structure.toml"\n[sampling]\nmethod = "lhs"\nn = 3\nseed = 1\n'
        "[inputs.every_wall]\nwidth_m = { sigma = 0.01 }\n[inputs.mask]\ndilate_px = { choices = [-1, 0, 1] }\n"
    )
    assert main(["build", str(tmp_path / "structure.toml"), "--no-figures", "--out", str(tmp_path / "model")]) == 0
    stones = json.loads((tmp_path / "model" / "summary.json").read_text())["bricks"]
    rows, summary = run_study(load_study(tmp_path / "study.toml"), workers=0, progress=False)
    assert summary["failed"] == 0, summary["failures"]
    assert all(r["bricks"] == stones for r in rows)
    vol = {int(r["mask.dilate_px"]): r["total_volume_m3"] / r["wall.width_m"] for r in rows}
    assert sorted(vol) == [-1, 0, 1] and vol[-1] < vol[0] < vol[1]


def test_an_annotation_drawn_on_another_size_of_the_photo_is_refused(tmp_path, capsys):
    """A LabelMe outline drawn on a resized copy of the photo (297 x 446 px for a 594 x 891 px
    photo): its points were read as the photo's pixels, and the fit ran on corners half-way in. It
    is refused in one line naming both sizes, with nothing written."""
    from calib_masonry.cli import main
    from calib_masonry.labelme import write_labelme

    photo = REAL / TRUTH[0]["photo"]
    w, h = cm.read_photo(photo).size
    corners = np.array([[30.0, 95.0], [275.0, 103.0], [276.0, 338.0], [31.0, 350.0]])
    write_labelme(tmp_path / "small.json", photo.name, (h // 2, w // 2), outline=corners)
    out = tmp_path / "out"
    assert (
        main(
            [
                "rectify",
                str(photo),
                "--known-width",
                "0.9",
                "--labelme",
                str(tmp_path / "small.json"),
                "--out",
                str(out),
            ]
        )
        == 2
    )
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"{w // 2} x {h // 2} px image" in err and f"{w} x {h} px" in err
    assert not out.exists()


def test_a_photo_wall_without_a_scale_is_refused_in_the_structure_files_words(tmp_path, capsys):
    """build of a photo wall with no W, H or other scale: refused in one line (exit 2, nothing
    written) that names the [[wall]] keys that pin the scale. It named rectify's flags
    (--known-width, --camera-height) and --force, which a structure file has not."""
    from calib_masonry.cli import main

    (tmp_path / "wall.jpg").write_bytes((REAL / TRUTH[0]["photo"]).read_bytes())
    (tmp_path / "s.toml").write_text(
        '[structure]\nname = "lab"\nthickness_m = 0.2\nclosed = false\n'
        '[[wall]]\nname = "wall"\nimage = "wall.jpg"\ntheta_deg = 0\n'
    )
    assert main(["build", str(tmp_path / "s.toml"), "--out", str(tmp_path / "model")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "eye-height prior" in err and not (tmp_path / "model").exists()
    assert "width_m" in err and "camera_height_m" in err and "known_length = [" in err and "--" not in err


def test_a_veil_is_taken_off_and_an_unveiled_photo_left_as_it_is():
    """calibrate.veil.without_veil: a photo whose darkest light is a scene's shade comes back as
    the same object; one under an even veil (linear light 0.75 x + 0.125) comes back within a
    few grey levels of the photo without it, scaled as the veil dimmed it."""
    from calib_masonry.calibrate.veil import VEIL_SHADOW_SHARE, linear_light, srgb_from_linear, without_veil
    from calib_masonry.io import read_photo

    photo = read_photo(REAL / TRUTH[0]["photo"])
    assert without_veil(photo) is photo  # its darkest pixels are black
    lin = linear_light(photo.rgb)
    veiled = replace(photo, rgb=np.round(255 * srgb_from_linear(0.75 * lin + 0.125)) / 255)
    dark = np.percentile(linear_light(veiled.rgb).mean(axis=-1), 0.5)
    light = np.percentile(linear_light(veiled.rgb).mean(axis=-1), 99.5)
    assert dark > VEIL_SHADOW_SHARE * light  # the rule's own condition holds on this photo
    back = linear_light(without_veil(veiled).rgb)
    scale = 0.75 / (1 - 0.125)  # the veil's dimming, which no black point undoes
    assert np.median(np.abs(back - scale * lin)) < 0.01


@pytest.mark.slow
def test_a_laboratory_photo_in_mist_gives_the_wall_it_gives_without(monkeypatch, tmp_path):
    """SC4 and SC1 under an even veil of an eighth of the light (mist or flare): the outline's
    appearance model and GrabCut took SC4's darker bottom course for surroundings (H -35 %, 9
    sigma) and SC1's foot ran on into the footing (+19 %, 20 sigma). With the veil taken off, H
    comes within 2 % of the photo's own and the truth within 2 sigma; with the rule off it does
    not (the same photos)."""
    from PIL import Image

    import calib_masonry.calibrate.veil as veil_module
    from calib_masonry.calibrate.veil import linear_light, srgb_from_linear

    def veiled(t, tmp):
        with Image.open(REAL / t["photo"]) as im:
            rgb = np.asarray(im.convert("RGB"), dtype=np.float64) / 255.0
        out = np.round(255 * srgb_from_linear(0.75 * linear_light(rgb) + 0.125)).astype(np.uint8)
        path = tmp / f"veiled_{t['photo']}"
        Image.fromarray(out).save(path, quality=95)
        return path

    for t in (x for x in TRUTH if x["wall"] in ("SC1", "SC4")):
        config = cm.CalibrateConfig(known_width_m=t["width_m"])
        own = cm.calibrate_photo(REAL / t["photo"], config).result.height_m
        path = veiled(t, tmp_path)
        res = cm.calibrate_photo(path, config).result
        assert abs(res.height_m / own - 1) < 0.02, t["wall"]
        assert abs(res.height_m - t["height_m"]) < 2 * res.sigma("height_m"), t["wall"]
        with monkeypatch.context() as m:
            m.setattr(veil_module, "VEIL_SHADOW_SHARE", math.inf)
            m.setattr(veil_module, "VEIL_PLANE_SPREAD", 0.0)
            off = cm.calibrate_photo(path, replace(config, force=True)).result
        assert abs(off.height_m - t["height_m"]) > 2 * off.sigma("height_m"), t["wall"]


def _flared(rgb: np.ndarray, how: str) -> np.ndarray:
    """An sRGB photo under a flare graded across the frame (photo_conditions' flare_top and
    flare_corner: the scene dimmed to 0.8 in linear light, the veil added) or a faint even veil
    (mist0.06), rounded to 8 bits."""
    from calib_masonry.calibrate.veil import linear_light, srgb_from_linear

    h, w = rgb.shape[:2]
    yy, xx = np.mgrid[0:h, 0:w]
    if how == "faint":  # photo_conditions' mist0.06: an even veil too faint for the even rule
        return np.round(255 * srgb_from_linear(0.9 * linear_light(rgb) + 0.06)) / 255
    veil = np.linspace(0.3, 0.05, h)[:, None] + 0 * xx if how == "top" else 0.03 + 0.22 * (1 - (yy / h + xx / w) / 2)
    return np.round(255 * srgb_from_linear(0.8 * linear_light(rgb) + veil[..., None])) / 255


def test_a_graded_veil_is_taken_off_and_a_scene_with_sky_left_as_it_is():
    """calibrate.veil: a flare graded across a laboratory photo (0.3 of the light at the top to
    0.05 at the foot), or an even veil of 0.06, is too faint at its least for the even rule, but
    every tile's black lies on one plane: the plane is taken off and the gradient with it (the
    photo back within a hundredth of linear light of the scene at one exposure). A Blender render with sky, whose sky tiles'
    blacks lie far off any plane, and the photo itself come back as the same objects."""
    from calib_masonry.calibrate.veil import VEIL_SHADOW_SHARE, linear_light, without_veil
    from calib_masonry.io import read_photo

    photo = read_photo(REAL / TRUTH[1]["photo"])
    assert without_veil(photo) is photo
    blender = read_photo(sorted((ROOT / "data_external" / "blender_walls").glob("*.jpg"))[0])
    assert without_veil(blender) is blender
    lin = linear_light(photo.rgb)
    for how in ("top", "corner", "faint"):
        flared = replace(photo, rgb=_flared(photo.rgb, how).astype(np.float32))
        light = linear_light(flared.rgb).mean(axis=-1)
        assert np.percentile(light, 0.5) <= VEIL_SHADOW_SHARE * np.percentile(light, 99.5)  # not the even rule's
        back = linear_light(without_veil(flared).rgb)
        k = float(np.sum(back * lin) / np.sum(lin * lin))  # the one exposure the veil's dimming leaves
        off = back - k * lin
        assert np.median(np.abs(off)) < 0.01, how
        rows = off.shape[0]
        assert abs(off[: rows // 4].mean() - off[-rows // 4 :].mean()) < 0.01, how  # no gradient left


@pytest.mark.slow
def test_a_laboratory_photo_under_a_graded_flare_gives_the_wall_it_gives_without(monkeypatch, tmp_path):
    """SC1 under a flare from a corner, SC4 under one from the top and SC1 under a faint even veil
    (photo_conditions' fourth set): with the veil left on, SC1's H came out 25 and 21 % long (30
    and 3.4 sigma) and SC4's 35 % short (17 sigma); with the plane through the tiles' blacks taken
    off, H within 2 % of the photo's own and the truth within 2 sigma; with that rule off, not
    (the same photos)."""
    from PIL import Image

    import calib_masonry.calibrate.veil as veil_module

    for wall, how in (("SC1", "corner"), ("SC4", "top"), ("SC1", "faint")):
        t = next(x for x in TRUTH if x["wall"] == wall)
        with Image.open(REAL / t["photo"]) as im:
            rgb = np.asarray(im.convert("RGB"), dtype=np.float64) / 255.0
        path = tmp_path / f"flare_{how}_{t['photo']}"
        Image.fromarray(np.round(255 * _flared(rgb, how)).astype(np.uint8)).save(path, quality=95)
        config = cm.CalibrateConfig(known_width_m=t["width_m"])
        own = cm.calibrate_photo(REAL / t["photo"], config).result.height_m
        res = cm.calibrate_photo(path, config).result
        assert abs(res.height_m / own - 1) < 0.02, wall
        assert abs(res.height_m - t["height_m"]) < 2 * res.sigma("height_m"), wall
        with monkeypatch.context() as m:
            m.setattr(veil_module, "VEIL_PLANE_SPREAD", 0.0)
            off = cm.calibrate_photo(path, replace(config, force=True)).result
        assert abs(off.height_m - t["height_m"]) > 2 * off.sigma("height_m"), wall


def test_a_blank_photo_is_no_veil(tmp_path, capsys):
    """A photo of one lightness (white, blown out) has no veil to take off: its darkest light is
    its lightest. It ends in the outline's one-line refusal, not in a division by nothing (NaNs
    reported as a float image out of [0, 1])."""
    from PIL import Image

    from calib_masonry.calibrate.veil import without_veil
    from calib_masonry.cli import main
    from calib_masonry.io import read_photo

    path = tmp_path / "white.jpg"
    Image.fromarray(np.full((400, 300, 3), 255, np.uint8)).save(path)
    photo = read_photo(path)
    assert without_veil(photo) is photo
    assert main(["rectify", str(path), "--known-width", "1", "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "no wall found" in err and not (tmp_path / "out").exists()

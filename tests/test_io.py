import numpy as np
import pytest
from PIL import Image

from calib_masonry.errors import InputError
from calib_masonry.io import OUTPUT_MARKER, check_output, output_command, read_mask, staged_output


def test_read_mask_binary(tmp_path):
    a = np.zeros((10, 12), np.uint8)
    a[2:5, 3:9] = 255
    Image.fromarray(a).save(tmp_path / "m.png")
    m = read_mask(tmp_path / "m.png")
    assert m.dtype == bool and m.shape == (10, 12) and m.sum() == 18


def test_read_mask_refuses_grey(tmp_path):
    rng = np.random.default_rng(0)
    Image.fromarray(rng.integers(0, 255, (20, 20), dtype=np.uint8)).save(tmp_path / "g.png")
    with pytest.raises(InputError, match="not a binary-like mask"):
        read_mask(tmp_path / "g.png")


def test_read_mask_refuses_colour_photo(tmp_path):
    rng = np.random.default_rng(0)
    Image.fromarray(rng.integers(0, 255, (20, 20, 3), dtype=np.uint8)).save(tmp_path / "c.png")
    with pytest.raises(InputError, match="colour photo"):
        read_mask(tmp_path / "c.png")


def test_read_mask_corrupt_and_missing(tmp_path):
    (tmp_path / "bad.png").write_bytes(b"\x89PNG not really")
    with pytest.raises(InputError, match="cannot be read"):
        read_mask(tmp_path / "bad.png")
    with pytest.raises(InputError, match="not found"):
        read_mask(tmp_path / "missing.png")


def test_staged_output_all_or_nothing(tmp_path):
    out = tmp_path / "out"
    with pytest.raises(RuntimeError):
        with staged_output(out, "build") as stage:
            (stage / "model.stl").write_text("half")
            raise RuntimeError("boom")
    assert not out.exists()
    assert list(tmp_path.iterdir()) == []
    with staged_output(out, "build") as stage:
        (stage / "a.txt").write_text("1")
    assert (out / "a.txt").read_text() == "1"
    assert [p.name for p in tmp_path.iterdir()] == ["out"]


def test_a_rerun_replaces_its_output_folder_as_a_whole(tmp_path):
    out = tmp_path / "out"
    with staged_output(out, "build") as stage:
        (stage / "compare.json").write_text("old")
        (stage / "model.stl").write_text("old")
    assert output_command(out) == "build"
    with staged_output(out, "build") as stage:
        (stage / "model.stl").write_text("new")
    assert sorted(p.name for p in out.iterdir()) == [OUTPUT_MARKER, "model.stl"]  # no stale compare.json
    assert (out / "model.stl").read_text() == "new"
    assert [p.name for p in tmp_path.iterdir()] == ["out"]  # no staging, no old copy left


def test_a_folder_that_is_not_this_commands_output_is_refused_up_front(tmp_path):
    mine = tmp_path / "notes"
    mine.mkdir()
    (mine / "thesis.tex").write_text("years of work")
    with pytest.raises(InputError, match=r"--out .*notes.*'thesis.tex'.*--overwrite"):
        check_output(mine, command="build")
    with pytest.raises(InputError, match="--overwrite"):
        with staged_output(mine, "build"):
            raise AssertionError("the body must not run")
    assert (mine / "thesis.tex").read_text() == "years of work"
    sim = tmp_path / "sim"
    with staged_output(sim, "simulate") as stage:
        (stage / "summary.json").write_text("{}")
    with pytest.raises(InputError, match="an output of `calib-masonry simulate`"):
        check_output(sim, command="build")
    # an empty folder is fine, and --overwrite replaces a foreign one as a whole
    (tmp_path / "empty").mkdir()
    check_output(tmp_path / "empty", command="build")
    with staged_output(mine, "build", overwrite=True) as stage:
        (stage / "model.stl").write_text("new")
    assert sorted(p.name for p in mine.iterdir()) == [OUTPUT_MARKER, "model.stl"]


def test_the_runs_own_inputs_inside_its_output_folder_are_kept(tmp_path):
    out = tmp_path / "data"
    with staged_output(out, "synth") as stage:
        (stage / "masks").mkdir()
        (stage / "masks" / "old_wall.png").write_text("old")
    (out / "scenario.toml").write_text("the scenario")  # the user's input, kept beside its output
    with staged_output(out, "synth", keep=[out / "scenario.toml", tmp_path / "elsewhere.toml"]) as stage:
        (stage / "masks").mkdir()
        (stage / "masks" / "wall.png").write_text("new")
    assert (out / "scenario.toml").read_text() == "the scenario"
    assert sorted(p.name for p in (out / "masks").iterdir()) == ["wall.png"]


@pytest.mark.parametrize("kind", ["L", "L16", "RGB", "1", "F"])
def test_read_mask_thresholds_half_way_in_every_pixel_format(tmp_path, kind):
    """The mask is `(v - lo) / (hi - lo) >= 1/2` whatever the file's type, computed without float64
    copies of the image."""
    from PIL import Image

    rng = np.random.default_rng(3)
    truth = rng.random((40, 50)) < 0.6
    hi = {"L": 255, "L16": 65535, "RGB": 255, "1": 1, "F": 1.0}[kind]
    values = np.where(truth, hi, 0).astype(np.float64)
    edge = rng.random((40, 50)) < 0.02  # a few anti-aliased pixels either side of one half
    values[edge] = np.where(rng.random(edge.sum()) < 0.5, 0.49, 0.51) * hi
    want = (values - values.min()) / (values.max() - values.min()) >= 0.5
    if kind == "L":
        im = Image.fromarray(values.round().astype(np.uint8))
        want = values.round() >= 128
    elif kind == "L16":
        im = Image.fromarray(values.round().astype(np.uint16))
        want = values.round() >= 32768
    elif kind == "RGB":
        v = values.round().astype(np.uint8)
        im = Image.fromarray(np.stack([v, v, v], axis=-1))
        want = v >= 128
    elif kind == "1":
        im = Image.fromarray(truth)
        want = truth
    else:
        im = Image.fromarray(values.astype(np.float32), mode="F")
    path = tmp_path / ("m.tif" if kind == "F" else "m.png")
    im.save(path)
    np.testing.assert_array_equal(read_mask(path), want)


def test_a_requested_stop_is_never_committed_even_if_its_exception_was_swallowed(tmp_path, monkeypatch):
    # Some third-party imports wrap an optional import in a bare `except:`, which swallows the
    # exception the CLI's SIGTERM handler raises; the stop flag it also sets must still hold.
    import threading

    from calib_masonry import errors, process

    monkeypatch.setattr(process, "_STOP", threading.Event())
    out = tmp_path / "out"
    with pytest.raises(errors.Terminated):
        with staged_output(out, "build") as stage:
            (stage / "model.stl").write_text("whole, but the run was told to stop")
            try:
                process.request_stop()
                raise errors.Terminated()
            except BaseException:  # what such an import does
                pass
    assert list(tmp_path.iterdir()) == []


def test_records_json_reads_back_as_the_indented_exact_json(tmp_path):
    import json
    from pathlib import Path

    from calib_masonry.io import json_bytes, records_json_bytes

    rng = np.random.default_rng(5)
    doc = {
        "name": "w",
        "empty": [],
        "rows": [
            {"xy": rng.normal(size=(3, 2)), "n": np.int64(7), "ok": np.bool_(True), "f": float(rng.normal())},
            {"dice": float("nan"), "where": Path("a/b.png"), "t": (1, 2.5)},  # a NaN: the slow path for this row
        ],
        "scale": 0.1 + 0.2,  # exact, not rounded
    }
    raw = records_json_bytes(doc)
    assert json.loads(raw) == json.loads(json_bytes(doc, exact=True))
    lines = raw.decode().splitlines()
    assert len(lines) == 9 and lines[4].startswith('  {"xy": ')  # a record to a line
    assert json.loads(raw)["rows"][1]["dice"] is None and json.loads(raw)["scale"] == 0.1 + 0.2


def _pattern(rows=60, cols=40):
    """A photo-like grey image that shows which way up it is (a bright top-left block)."""
    yy, xx = np.mgrid[0:rows, 0:cols]
    img = (40 + 2 * xx + yy).astype(np.uint8)
    img[:15, :10] = 250
    return img


def test_read_photo_turns_a_photo_upright_as_its_exif_orientation_says(tmp_path):
    """A phone stores a portrait photo as landscape pixels tagged to be turned (Orientation 6:
    90 degrees clockwise to view); viewers and LabelMe show it upright, and so must the photo
    path (it read the stored pixels, a wall lying on its side)."""
    from calib_masonry.io import read_photo

    upright = _pattern()
    stored = np.rot90(upright)  # turned 90 degrees anticlockwise, as the sensor stored it
    exif = Image.Exif()
    exif[0x0112] = 6
    Image.fromarray(np.repeat(stored[..., None], 3, -1)).save(tmp_path / "p.jpg", exif=exif, quality=100)
    photo = read_photo(tmp_path / "p.jpg")
    assert photo.rgb.shape == (60, 40, 3) and photo.size == (40, 60)
    assert np.abs(photo.rgb[..., 0] * 255 - upright).mean() < 3


def test_read_photo_scales_a_16_bit_grey_image_by_its_range(tmp_path):
    """A 16-bit greyscale PNG (a scanner's, a machine-vision camera's) read as the same photo as
    its 8-bit version: Pillow's conversion to RGB clipped it at 255, a white photo."""
    from calib_masonry.io import read_photo

    grey = _pattern()
    Image.fromarray(grey.astype(np.uint16) * 257).save(tmp_path / "g16.png")
    Image.fromarray(grey).save(tmp_path / "g8.png")
    wide, narrow = read_photo(tmp_path / "g16.png"), read_photo(tmp_path / "g8.png")
    assert wide.rgb.dtype == np.float32 and wide.rgb.shape == narrow.rgb.shape
    assert np.abs(wide.rgb - narrow.rgb).max() < 1e-6


def _exif_photo(path, size, **tags):
    """A grey JPEG of ``size`` (w, h) whose EXIF sub-IFD holds ``tags`` (tag number -> value)."""
    from fractions import Fraction

    from PIL.TiffImagePlugin import IFDRational

    exif = Image.Exif()
    exif[0x010F], exif[0x0110] = "test", "camera"
    sub = exif.get_ifd(0x8769)
    for tag, value in tags.items():
        tag = int(tag[1:], 16)
        if isinstance(value, float):
            q = Fraction(value).limit_denominator(100000)
            value = IFDRational(q.numerator, q.denominator)
        sub[tag] = value
    w, h = size
    Image.fromarray(np.full((h, w, 3), 128, np.uint8)).save(path, exif=exif, quality=90)
    return path


@pytest.mark.parametrize(
    ("unit", "per_unit_mm"),
    [(2, 25.4), (3, 10.0), (4, 1.0)],
    ids=["inch", "cm", "mm"],
)
def test_read_photo_focal_from_the_focal_planes_resolution_in_each_unit(tmp_path, unit, per_unit_mm):
    """FocalPlaneXResolution is pixels per FocalPlaneResolutionUnit (an inch unless told: Canon's
    cameras write inches). A 600 px-wide photo of a 36 mm sensor has 600/36 px a mm; at 50 mm the
    focal length is 833.3 px. The inch was multiplied, not divided (645 times too long: such a
    photo was refused as implausible); only millimetres, the project's own generator's unit, read
    right."""
    from calib_masonry.io import read_photo

    per_mm = 600 / 36.0
    kwargs = {"x920A": 50.0, "xA20E": per_mm * per_unit_mm, "xA20F": per_mm * per_unit_mm, "xA210": unit}
    photo = read_photo(_exif_photo(tmp_path / "p.jpg", (600, 400), **kwargs))
    assert photo.focal_px == pytest.approx(50 * per_mm, rel=1e-4)
    assert photo.focal_note == "FocalLength x FocalPlaneXResolution"
    # without the unit tag: an inch, as EXIF says
    if unit == 2:
        del kwargs["xA210"]
        photo = read_photo(_exif_photo(tmp_path / "q.jpg", (600, 400), **kwargs))
        assert photo.focal_px == pytest.approx(50 * per_mm, rel=1e-4)


def test_read_photo_focal_of_a_photo_resized_or_cropped_since_it_was_taken(tmp_path):
    """The focal plane's resolution is the camera's pixels: a photo halved since (its EXIF kept)
    has half the focal length in pixels. Scaled by its pixels over PixelX/YDimension where those
    are kept; where they are not, the 35 mm equivalent (which scales with the photo's own
    diagonal) is taken when the two disagree; a crop (another shape) keeps the pixels' density."""
    from calib_masonry.io import read_photo

    per_mm = 600 / 36.0
    camera = {"x920A": 50.0, "xA20E": per_mm * 25.4, "xA20F": per_mm * 25.4, "xA210": 2}
    full = 50 * per_mm
    # halved, the camera's pixel dimensions kept
    halved = read_photo(_exif_photo(tmp_path / "a.jpg", (300, 200), **camera, xA002=600, xA003=400))
    assert halved.focal_px == pytest.approx(full / 2, rel=1e-3) and "resized" in halved.focal_note
    # halved, no pixel dimensions, the 35 mm equivalent given (a full-frame sensor: 50 mm): the two
    # disagree (a resize makes the equivalent right, a crop the plane's), so the focal length is a
    # prior between them, each one sigma from it, for the calibration's vanishing points to settle
    eq = read_photo(_exif_photo(tmp_path / "b.jpg", (300, 200), **camera, xA405=50))
    assert eq.focal_px == pytest.approx(full / np.sqrt(2), rel=1e-3) and "disagree" in eq.focal_note
    assert eq.focal_log_sigma == pytest.approx(np.log(2) / 2, rel=1e-3) and halved.focal_log_sigma is None
    # at the camera's own size the two agree and the focal plane's (not rounded to a mm) is taken
    own = read_photo(_exif_photo(tmp_path / "c.jpg", (600, 400), **camera, xA405=50, xA002=600, xA003=400))
    assert own.focal_px == pytest.approx(full, rel=1e-4) and own.focal_note == "FocalLength x FocalPlaneXResolution"
    # a square crop of the camera's 600 x 400: the pixels' density is the camera's, and so is f
    crop = read_photo(_exif_photo(tmp_path / "d.jpg", (400, 400), **camera, xA405=50, xA002=600, xA003=400))
    assert crop.focal_px == pytest.approx(full, rel=1e-4)
    # nothing usable: no focal length, a zero resolution, an unknown unit
    for i, tags in enumerate(
        ({"xA20E": 10.0}, {"x920A": 50.0, "xA20E": 0.0}, {"x920A": 50.0, "xA20E": 9.0, "xA210": 9})
    ):
        assert read_photo(_exif_photo(tmp_path / f"n{i}.jpg", (300, 200), **tags)).focal_px is None


def test_read_photo_reads_a_phones_heic_with_its_exif(tmp_path):
    """A phone's default photo is a HEIC: read (with pillow-heif) as its JPEG would be, its EXIF's
    focal length with it; before, 'cannot be read as an image'."""
    pytest.importorskip("pillow_heif")
    from pillow_heif import from_pillow

    from calib_masonry.io import read_photo

    grey = _pattern()
    rgb = np.repeat(grey[..., None], 3, -1)
    exif = Image.Exif()
    exif[0x010F], exif[0x0110] = "Apple", "iPhone test"
    sub = exif.get_ifd(0x8769)
    sub[0xA405] = 26  # the 35 mm equivalent, as a phone writes it
    heif = from_pillow(Image.fromarray(rgb))
    heif.info["exif"] = exif.tobytes()
    heif.save(tmp_path / "p.heic", quality=-1)  # lossless
    photo = read_photo(tmp_path / "p.heic")
    assert photo.size == (grey.shape[1], grey.shape[0])
    assert np.abs(photo.rgb[..., 0] * 255 - grey).mean() < 3
    assert photo.focal_px == pytest.approx(26 * np.hypot(*grey.shape) / np.hypot(36, 24), rel=1e-6)
    # a copy renamed .jpg is told its real type (as a PNG named .jpg is)
    (tmp_path / "p.jpg").write_bytes((tmp_path / "p.heic").read_bytes())
    with pytest.raises(InputError, match="a HEIF image named .jpg; rename it"):
        read_photo(tmp_path / "p.jpg")


def _touching_pieces() -> np.ndarray:
    """Labels of a 3 x 4 grid of blocks 20 x 30 px that touch their neighbours along every edge,
    inside a black mortar border of 5 px."""
    labels = np.zeros((70, 130), np.int32)
    for r in range(3):
        for c in range(4):
            labels[5 + 20 * r : 25 + 20 * r, 5 + 30 * c : 35 + 30 * c] = 1 + 4 * r + c
    return labels


@pytest.mark.parametrize("kind", ["colour", "ids16", "palette"])
def test_a_label_image_keeps_touching_units_apart(tmp_path, kind):
    # an instance mask, as segmentation and annotation tools export them: each unit a flat colour
    # (or a 16-bit id) of its own on black mortar, units touching; read as twelve pieces, each apart
    from calib_masonry.io import read_mask_labels

    truth = _touching_pieces()
    if kind == "ids16":
        image = Image.fromarray(truth.astype(np.uint16))
    else:
        colours = np.random.default_rng(3).integers(60, 256, (13, 3)).astype(np.uint8)
        colours[0] = 0
        image = Image.fromarray(colours[truth])
        if kind == "palette":
            image = image.convert("P", palette=Image.Palette.ADAPTIVE, colors=16)  # as LabelMe writes them
    image.save(tmp_path / "m.png")
    mask, labels = read_mask_labels(tmp_path / "m.png")
    assert labels is not None and labels.max() == 12
    for k in range(1, 13):  # every unit one label, whole
        (found,) = np.unique(labels[truth == k])
        assert found > 0 and np.array_equal(labels == found, truth == k)
    # the mask keeps them apart: a one-pixel line between every two that touch
    from scipy import ndimage

    assert ndimage.label(mask)[1] == 12 and mask.sum() < (truth > 0).sum()


def test_a_photo_is_not_taken_for_a_label_image(tmp_path):
    # smooth colours and noise with dark lines (few flat regions): still refused, naming both formats
    rng = np.random.default_rng(0)
    y, x = np.mgrid[0:120, 0:160]
    img = np.stack([128 + 100 * np.sin(x / 20), 128 + 100 * np.cos(y / 15), 128 + 60 * np.sin((x + y) / 30)], -1)
    img = img + rng.normal(0, 8, img.shape)
    img[::20] = 5
    Image.fromarray(np.clip(img, 0, 255).astype(np.uint8)).save(tmp_path / "p.png")
    with pytest.raises(InputError, match="colour photo.*label image"):
        read_mask(tmp_path / "p.png")

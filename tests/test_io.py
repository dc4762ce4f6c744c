import numpy as np
import pytest
from PIL import Image

from calib_masonry.errors import InputError
from calib_masonry.io import read_mask, staged_output


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
        with staged_output(out) as stage:
            (stage / "model.stl").write_text("half")
            raise RuntimeError("boom")
    assert not out.exists()
    assert list(tmp_path.iterdir()) == []
    with staged_output(out) as stage:
        (stage / "a.txt").write_text("1")
    assert (out / "a.txt").read_text() == "1"
    assert [p.name for p in tmp_path.iterdir()] == ["out"]

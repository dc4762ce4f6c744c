"""Materials everywhere: the [material] table of structure.toml, ``simulate --material`` and study
inputs that sample any material field (issue 37)."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from calib_masonry.errors import InputError
from calib_masonry.simulation.scene import MASONRY, MATERIAL_KEYS, material_from_table, material_table
from calib_masonry.study.design import load_study, samples

from .conftest import need_bpy, scenario_text


def test_every_material_field_has_a_key_and_the_table_round_trips():
    from dataclasses import fields

    assert {f.name for f in fields(MASONRY)} == {name for name, _ in MATERIAL_KEYS.values()}
    table = material_table(MASONRY)
    assert material_from_table(table, "x") == MASONRY
    m = material_from_table({"tensile_strength_mpa": 0.05, "friction": 0.7}, "x")
    assert m.tensile_strength == pytest.approx(0.05e6) and m.friction == 0.7 and m.density == MASONRY.density


@pytest.mark.parametrize(
    "table, message",
    [
        ({"density_kg_m3": -1}, "density_kg_m3 = -1: must be > 0"),
        ({"fricton": 0.6}, "did you mean friction"),
        ({"cohesion_mpa": "strong"}, "cohesion_mpa = 'strong': give a finite number"),
        ({"mortar_youngs_modulus_mpa": 0}, "mortar_youngs_modulus_mpa = 0: must be > 0"),
        ({"unit_poisson": 0.5}, "unit_poisson = 0.5: must be in [0, 0.5)"),
        # far outside masonry: a unit error, refused with what the key's unit means
        ({"density_kg_m3": 1.8}, "density_kg_m3 = 1.8: outside 100..30000 kg/m^3"),
        ({"friction": 50}, "friction = 50: outside 0..2"),
        ({"tensile_strength_mpa": 200}, "tensile_strength_mpa = 200: outside 0..50 MPa"),
        ({"unit_youngs_modulus_mpa": 1e10}, "unit_youngs_modulus_mpa = 1e+10: outside 0..1e+06 MPa"),
        ({"joint_thickness_m": 10}, "joint_thickness_m = 10: outside 0..0.2 metres"),
    ],
)
def test_bad_material_values_are_one_line_errors_naming_the_key(table, message):
    with pytest.raises(InputError) as e:
        material_from_table(table, "walls.toml")
    assert message in str(e.value) and str(e.value).startswith("walls.toml: [material]")
    assert "\n" not in str(e.value)


def test_a_structure_files_material_is_refused_before_any_work(tmp_path):
    from calib_masonry.spec import load_structure

    p = tmp_path / "s.toml"
    p.write_text(scenario_text([(1.0, 1.0, 0.0)], closed=False) + "\n[material]\ntensile_strength_mpa = -0.1\n")
    with pytest.raises(InputError, match=r"tensile_strength_mpa = -0.1: must be >= 0"):
        load_structure(p, require_sources=False)


@pytest.mark.slow
def test_the_structures_material_reaches_simulate_and_material_flag_overrides_it(tmp_path, make_scenario):
    need_bpy()
    data = make_scenario([(1.0, 0.6, 0.0)], closed=False)
    structure = data / "structure.toml"
    structure.write_text(structure.read_text() + "\n[material]\nfriction = 0.7\ntensile_strength_mpa = 0.05\n")
    run = [sys.executable, "-m", "calib_masonry"]
    subprocess.run([*run, "build", str(structure), "--out", str(tmp_path / "model")], check=True, capture_output=True)
    assert "friction = 0.7" in (tmp_path / "model" / "material.toml").read_text()
    subprocess.run(
        [*run, "simulate", str(tmp_path / "model"), "--duration", "0.5", "--no-figures", "--out", str(tmp_path / "a")],
        check=True,
        capture_output=True,
    )
    echo = json.loads((tmp_path / "a" / "summary.json").read_text())["material"]
    assert echo["friction"] == 0.7 and echo["tensile_strength_mpa"] == pytest.approx(0.05)
    assert echo["source"].endswith("material.toml")
    mine = tmp_path / "mine.toml"
    mine.write_text("[material]\ncohesion_mpa = 0.1\n")
    subprocess.run(
        [*run, "simulate", str(tmp_path / "model"), "--duration", "0.5", "--no-figures", "--material", str(mine)]
        + ["--out", str(tmp_path / "b")],
        check=True,
        capture_output=True,
    )
    echo = json.loads((tmp_path / "b" / "summary.json").read_text())["material"]
    assert (
        echo["cohesion_mpa"] == pytest.approx(0.1) and echo["friction"] == MASONRY.friction
    )  # the file's, not the model's
    mine.write_text("[material]\nfriction = -2\n")
    r = subprocess.run(
        [*run, "simulate", str(tmp_path / "model"), "--duration", "0.5", "--material", str(mine)]
        + ["--out", str(tmp_path / "c")],
        capture_output=True,
        text=True,
    )
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and "friction = -2" in r.stderr and str(mine) in r.stderr
    assert not (tmp_path / "c").exists()


def test_a_study_samples_material_fields_about_the_structures_values(tmp_path, make_scenario):
    data = make_scenario([(1.0, 0.6, 0.0)], closed=False)
    structure = data / "structure.toml"
    structure.write_text(structure.read_text() + "\n[material]\nfriction = 0.7\n")
    study = tmp_path / "s.toml"
    study.write_text(
        f'[study]\nname = "m"\nstructure = "{structure}"\n[sampling]\nmethod = "sobol"\nn = 8\nseed = 2\n'
        "[inputs.material]\nfriction = { sigma = 0.05 }\ntensile_strength_mpa = { range = [0.0, 0.2] }\n"
    )
    s = load_study(study)
    drawn = [x.values for x in samples(s)]
    assert len(drawn) == 8 * (2 + 2)  # Saltelli's scheme: n (d + 2)
    fr = [v["material.friction"] for v in drawn]
    assert abs(sum(fr) / len(fr) - 0.7) < 0.05 and min(fr) != max(fr)  # about the structure's 0.7
    assert all(0.0 <= v["material.tensile_strength_mpa"] <= 0.2 for v in drawn)
    from calib_masonry.spec import load_structure
    from calib_masonry.study.sample import _material

    m = _material(samples(s)[3], load_structure(structure).material)
    assert m.friction == pytest.approx(drawn[3]["material.friction"])
    assert m.tensile_strength == pytest.approx(drawn[3]["material.tensile_strength_mpa"] * 1e6)

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from calib_masonry.build3d.bond import find_end_faces
from calib_masonry.build3d.place import corners, wall_frames
from calib_masonry.build_folder import build_to_folder
from calib_masonry.comparison import compare_dirs
from calib_masonry.io import read_mask
from calib_masonry.spec import load_structure
from calib_masonry.synthetic.layouts import layout_structure
from calib_masonry.synthetic.truth import synthesize_to_folder

from .conftest import DATA, scenario_text


@pytest.mark.parametrize("name", ["paper_example", "stylite"])
def test_shipped_data_is_reproducible(tmp_path, name):
    spec = load_structure(DATA / name / "scenario.toml", require_sources=False)
    synthesize_to_folder(spec, tmp_path / name, figures=False)
    for w in spec.walls:
        a = read_mask(DATA / name / "masks" / f"{w.name}.png")
        b = read_mask(tmp_path / name / "masks" / f"{w.name}.png")
        assert np.array_equal(a, b)
    assert json.loads((DATA / name / "truth" / "truth.json").read_text()) == json.loads(
        (tmp_path / name / "truth" / "truth.json").read_text()
    )
    # and the structure file (its vertices, its joint reach) as shipped: the tables were measured on it
    assert (DATA / name / "structure.toml").read_text() == (tmp_path / name / "structure.toml").read_text()


def test_a_synthesis_in_memory_writes_the_folder_synth_writes(tmp_path):
    """synthesize (in memory) and write_synthesis give, file for file and byte for byte, the folder
    synthesize_to_folder writes (which writes the truth's files while the photos render); the
    photos read from memory are the photos read from their files."""
    from calib_masonry.io import read_photo
    from calib_masonry.spec import PhotoSpec
    from calib_masonry.synthetic.truth import synthesize, write_synthesis

    sc = tmp_path / "scenario.toml"
    sc.write_text(scenario_text([(2.0, 1.2, 0), (1.6, 1.2, 90)], seed=12, closed=False))
    spec = load_structure(sc, require_sources=False)
    photos = PhotoSpec(long_side_px=600, short_side_px=400)
    synthesize_to_folder(spec, tmp_path / "a", figures=False, photos=photos, progress=False)
    result = synthesize(spec, photos=photos, progress=False)
    write_synthesis(result, tmp_path / "b", figures=False)
    files = sorted(p.relative_to(tmp_path / "a") for p in (tmp_path / "a").rglob("*") if p.is_file())
    assert files == sorted(p.relative_to(tmp_path / "b") for p in (tmp_path / "b").rglob("*") if p.is_file())
    assert "photos/w0.jpg" in {f.as_posix() for f in files}
    for f in files:
        assert (tmp_path / "a" / f).read_bytes() == (tmp_path / "b" / f).read_bytes(), f
    on_disk = read_photo(tmp_path / "a" / "photos" / "w0.jpg")
    in_memory = result.photo("photos/w0.jpg")
    assert np.array_equal(on_disk.rgb, in_memory.rgb) and on_disk.focal_px == in_memory.focal_px


@pytest.mark.parametrize(
    "layout, walls",
    [
        (
            "stretcher",
            [(5.73, 6.07, 0), (4.10, 5.88, 90), (3.07, 5.5, 180), (1.23, 5.5, 90), (2.66, 5.5, 180), (5.33, 5.31, 270)],
        ),
        ("stretcher", [(3.3, 2.0, 0), (2.2, 2.5, 90), (3.3, 2.0, 180), (2.2, 2.2, 270)]),
        ("stones", [(2.43, 4.0, 0), (2.48, 4.0, 90), (2.43, 4.0, 180), (2.48, 4.0, 270)]),
    ],
)
@pytest.mark.parametrize("seed", [1, 2])
def test_end_faces_detected_on_true_polygons(tmp_path, layout, walls, seed):
    p = tmp_path / "s.toml"
    p.write_text(scenario_text(walls, layout=layout, seed=seed, t=0.4 if layout == "stones" else 0.18))
    spec = load_structure(p, require_sources=False)
    pieces = layout_structure(spec)
    found = find_end_faces([[q.polygon_m for q in ps] for ps in pieces], wall_frames(spec), corners(spec))
    truth = [{i for i, q in enumerate(ps) if q.end_face} for ps in pieces]
    assert found == truth


@pytest.mark.parametrize("seed", [1, 2])
def test_end_faces_of_walls_of_two_thicknesses_where_a_brick_is_as_long_as_one_is_thick(tmp_path, seed):
    """A tower of 0.45 m and 0.30 m thick walls of 0.30 m long bricks: on a 0.45 m wall's photo the
    other wall's end face is 0.30 wide, and so is a whole brick of its own that reaches the corner.
    The brick was taken for the end face and the real one (0.45 wide on the thinner wall) kept: 14
    pieces of each wall on the wrong side of the corner, the build's precision 0.975."""
    walls = [(4.0, 3.0, 0, 0.45), (3.0, 3.0, 90, 0.3), (4.0, 3.0, 180, 0.45), (3.0, 3.0, 270, 0.3)]
    p = tmp_path / "s.toml"
    p.write_text(
        '[structure]\nname = "mixed"\nthickness_m = 0.3\nclosed = true\n[synthetic]\nlayout = "stretcher"\n'
        f"brick_length_m = 0.30\nbrick_height_m = 0.10\nmortar_m = 0.012\npx_per_m = 200\nseed = {seed}\n"
        + "".join(
            f'[[wall]]\nname = "w{i}"\nwidth_m = {w}\nheight_m = {h}\ntheta_deg = {th}\nthickness_m = {t}\n'
            for i, (w, h, th, t) in enumerate(walls)
        )
    )
    spec = load_structure(p, require_sources=False)
    pieces = layout_structure(spec)
    found = find_end_faces([[q.polygon_m for q in ps] for ps in pieces], wall_frames(spec), corners(spec))
    assert found == [{i for i, q in enumerate(ps) if q.end_face} for ps in pieces]


@pytest.mark.parametrize("seed", [3, 4])
def test_stone_walls_end_where_their_stones_do(tmp_path, monkeypatch, seed):
    """A free end (no corner) is a jamb: its stones' faces lie on the end's plumb line; the first
    course is bedded on the base line. So the wall's true outline is what a photo shows. An end
    at a corner keeps its joint to the corner's end face; the stones off the outline are the same
    as without the rule (the same random draws)."""
    from calib_masonry.synthetic import layouts

    p = tmp_path / "s.toml"
    p.write_text(scenario_text([(2.9, 3.0, 0), (2.2, 3.0, 90)], layout="stones", seed=seed, t=0.4, closed=False))
    spec = load_structure(p, require_sources=False)
    pieces = layout_structure(spec)
    free_start, free_end = 0, 1  # wall 0 starts free, wall 1 ends free; they meet at a corner
    xs = {}
    for n, ps in enumerate(pieces):
        for q in ps:
            xs.setdefault((n, q.course), []).append(q.polygon_m[:, 0])
            if q.course == 0:
                assert q.polygon_m[:, 1].min() == 0.0  # on the base line
    widths = [w.width_m for w in spec.walls]
    for (n, course), pts in xs.items():
        lo, hi = min(float(x.min()) for x in pts), max(float(x.max()) for x in pts)
        if n == free_start:
            assert abs(lo) < 1e-12, (n, course, lo)  # a stone's face on the free end
        if n == free_end:
            assert abs(hi - widths[n]) < 1e-12, (n, course, hi)
    # at the corner end, the courses whose corner piece the other wall owns end in a joint
    inner = [max(float(x.max()) for x in pts) for (n, c), pts in xs.items() if n == free_start]
    assert min(inner) < widths[free_start]
    # without the rule, the same draws: every stone but the jamb stones and the first course's
    # is unchanged
    original = layouts._stone
    monkeypatch.setattr(layouts, "_stone", lambda *args, **flush: original(*args))
    before = layout_structure(spec)
    monkeypatch.undo()
    assert [len(ps) for ps in before] == [len(ps) for ps in pieces]
    changed = [
        (a.course, not np.array_equal(a.polygon_m, b.polygon_m))
        for pa, pb in zip(before, pieces)
        for a, b in zip(pa, pb)
    ]
    above = sum(d for c, d in changed if c > 0)
    courses = len({q.course for q in pieces[0]})
    assert 0 < above <= 2 * (courses - 1)  # above the first course, a jamb stone per free end and course
    assert sum(d for c, d in changed if c == 0) > 0


def test_build_is_deterministic(make_scenario, tmp_path):
    data = make_scenario([(2.0, 1.0, 0), (1.2, 1.0, 90), (2.0, 1.0, 180), (1.2, 1.0, 270)])
    spec = load_structure(data / "structure.toml")
    build_to_folder(spec, tmp_path / "a", figures=False, progress=False)
    # the command line's way: half of the walls traced, and the simulation geometry computed, in
    # processes of their own; the same files
    build_to_folder(spec, tmp_path / "b", figures=False, progress=False, processes=True)
    for f in ("model.stl", "bricks.json", "sim_geometry.npz"):
        assert (tmp_path / "a" / f).read_bytes() == (tmp_path / "b" / f).read_bytes()


def test_a_bad_mask_traced_in_the_other_process_is_named_as_here(make_scenario, tmp_path):
    from calib_masonry.errors import InputError
    from calib_masonry.pipeline import build

    data = make_scenario([(2.0, 1.0, 0), (1.2, 1.0, 90), (2.0, 1.0, 180), (1.2, 1.0, 270)])
    spec = load_structure(data / "structure.toml")
    bad = spec.walls[1]  # the first wall the command line traces in the other process
    Path(bad.mask).write_bytes(b"not an image")
    errors = []
    for flag in (False, True):
        with pytest.raises(InputError) as exc:
            build(spec, progress=False, trace_process=flag)
        errors.append(str(exc.value))
    assert errors[0] == errors[1] and str(bad.mask) in errors[1]


@pytest.mark.parametrize("seed", [11, 12])
def test_unseen_brick_walls_match_truth(make_scenario, tmp_path, seed):
    # off-grid brick sizes, so edges fall anywhere between pixel centres
    data = make_scenario(
        [(3.37, 2.21, 0), (2.13, 2.4, 90), (3.37, 2.3, 180), (2.13, 2.21, 270)],
        seed=seed,
        extra="brick_length_m = 0.3613\nbrick_height_m = 0.1437\nmortar_m = 0.0123",
    )
    spec = load_structure(data / "structure.toml")
    summary = build_to_folder(spec, tmp_path / "run", figures=False, progress=False)
    m = compare_dirs(tmp_path / "run", data / "truth")
    assert m["precision"] == 1.0 and m["recall"] == 1.0
    # every edge is within half a pixel of the truth; for the smallest piece here (a half brick of
    # about 35 x 29 px) that bounds Dice at 2*34*28 / (35*29 + 34*28) = 0.970
    assert m["dice"]["min"] >= 0.97
    assert m["dice"]["median"] >= 0.98  # mean edge error a quarter pixel: about 0.988 for 72 x 29 px bricks
    assert m["max_interpenetration_m3"] < 1e-6
    assert summary["closure_error_m"] < 1e-3
    assert abs(m["total_volume_m3"]["relative_error"]) < 0.01


@pytest.mark.slow
def test_paper_example_against_truth(tmp_path):
    spec = load_structure(DATA / "paper_example" / "structure.toml")
    summary = build_to_folder(spec, tmp_path / "run", figures=True, progress=False)
    m = compare_dirs(tmp_path / "run", DATA / "paper_example" / "truth")
    assert m["precision"] == 1.0 and m["recall"] == 1.0
    assert m["dice"]["min"] >= 0.98
    assert summary["closure_error_m"] < 1e-3
    assert m["max_interpenetration_m3"] <= 1e-6
    for f in ("model.stl", "bricks.json", "summary.json", "walls.png", "model.png"):
        assert (tmp_path / "run" / f).is_file()


def test_stylite_mean_dice(tmp_path):
    spec = load_structure(DATA / "stylite" / "structure.toml")
    summary = build_to_folder(spec, tmp_path / "run", figures=False, progress=False)
    assert all(w["vertices"] == 8 for w in summary["walls"])
    assert summary["mean_dice"] >= 0.98
    m = compare_dirs(tmp_path / "run", DATA / "stylite" / "truth")
    assert m["precision"] >= 0.99 and m["recall"] >= 0.99
    assert m["max_interpenetration_m3"] <= 1e-6


def test_open_footprint_warns_with_gap(make_scenario, tmp_path, recwarn):
    data = make_scenario([(2.0, 1.0, 0), (1.5, 1.0, 90), (1.0, 1.0, 180)], closed=True)
    spec = load_structure(data / "structure.toml")
    build_to_folder(spec, tmp_path / "run", figures=False, progress=False)
    msgs = [str(w.message) for w in recwarn.list]
    assert any("does not close" in m and "mm" in m for m in msgs)


def test_a_single_wall_from_a_label_image_builds_its_touching_units_apart(tmp_path):
    # twelve blocks drawn edge to edge, each a colour of its own on black (an instance mask): twelve
    # bricks, where the same drawing as a black-and-white mask is one piece; a single wall needs no
    # `closed = false` (no warning: the tests turn warnings into errors)
    from PIL import Image

    from .test_io import _touching_pieces

    truth = _touching_pieces()
    colours = np.random.default_rng(5).integers(60, 256, (13, 3)).astype(np.uint8)
    colours[0] = 0
    Image.fromarray(colours[truth]).save(tmp_path / "labels.png")
    Image.fromarray(np.where(truth > 0, 255, 0).astype(np.uint8)).save(tmp_path / "binary.png")
    counts = {}
    for name in ("labels", "binary"):
        (tmp_path / f"{name}.toml").write_text(
            f'[structure]\nname = "{name}"\nthickness_m = 0.1\nvertices = 4\n[[wall]]\nname = "w"\n'
            f'mask = "{name}.png"\nwidth_m = 1.3\nheight_m = 0.7\n'
        )
        summary = build_to_folder(load_structure(tmp_path / f"{name}.toml"), tmp_path / name, figures=False)
        counts[name] = summary["bricks"]
        # a single wall's ends are apart by design: no closure error (it was the wall's width)
        assert summary["closed_footprint"] is False and summary["closure_error_m"] is None
    assert counts == {"labels": 12, "binary": 1}


def _wide_bed_wall(tmp_path: Path, max_joint: float | None) -> Path:
    """Two courses of three bricks 0.39 x 0.18 m, 1 cm head joints, the upper course on a mortar
    bed 8 cm wide (200 px/m; the wall 1.21 x 0.46 m); its structure file, with ``max_joint_m``."""
    from PIL import Image

    px = 200
    mask = np.zeros((int(0.46 * px), int(1.21 * px)), np.uint8)
    rows = mask.shape[0]
    for z0 in (0.0, 0.26):  # the courses' bottoms above the ground
        for x0 in (0.01, 0.41, 0.81):
            r1, r0 = rows - int(round(z0 * px)), rows - int(round((z0 + 0.18) * px))
            mask[r0:r1, int(round(x0 * px)) : int(round((x0 + 0.39) * px))] = 255
    Image.fromarray(mask).save(tmp_path / "wide.png")
    head = '[structure]\nname = "wide"\nthickness_m = 0.2\nvertices = 4\n'
    if max_joint is not None:
        head += f"max_joint_m = {max_joint}\n"
    p = tmp_path / f"wide_{max_joint}.toml"
    p.write_text(head + '[[wall]]\nname = "w"\nmask = "wide.png"\nwidth_m = 1.21\nheight_m = 0.46\n')
    return p


def test_a_mortar_bed_wider_than_the_default_joint_is_joined_where_the_structure_says_so(tmp_path, capsys):
    # an 8 cm bed is wider than the default joint reach (6 cm): the upper course has no joint
    # beneath it, the build says so (summary.json and the command line's note), and nothing ties it
    # to the ground; with max_joint_m = 0.1 in [structure] it is joined, and simulate's geometry
    # (read back from the folder, stored) is the one built with it
    from calib_masonry.build_folder import geometry_for_model
    from calib_masonry.cli import main
    from calib_masonry.simulation.run import SimulationConfig, scene_for_model
    from calib_masonry.simulation.scene import grounded_bodies

    held = {}
    for max_joint in (None, 0.1):
        spec = load_structure(_wide_bed_wall(tmp_path, max_joint))
        assert spec.max_joint_m == max_joint
        out = tmp_path / f"m_{max_joint}"
        summary = build_to_folder(spec, out, figures=False)
        assert summary["max_joint_m"] == (0.06 if max_joint is None else max_joint)
        hanging = summary["joint_coverage"]["units_without_bed_joint"]
        assert len(hanging) == (3 if max_joint is None else 0)
        geometry, stored = geometry_for_model(out)
        assert stored and geometry.max_gap_m == summary["max_joint_m"]
        scene = scene_for_model(out, SimulationConfig(pga_g=0.0, duration_s=1.0, figures=False))
        held[max_joint] = int(grounded_bodies(scene.bonds, len(scene.bodies)).sum())
    assert held == {None: 3, 0.1: 6}
    # the command line names them in one note
    capsys.readouterr()
    r = main(["build", str(_wide_bed_wall(tmp_path, None)), "--out", str(tmp_path / "cli"), "--no-figures"])
    notes = [line for line in capsys.readouterr().out.splitlines() if "note:" in line]
    assert r == 0 and len(notes) == 1 and "3 units" in notes[0] and "max_joint_m = 0.06" in notes[0]
    # the note says what reach the masks' own joints need (their 95th percentile width, 8 cm here,
    # measured along the mortar's medial axis), and that reach joins them
    coverage = json.loads((tmp_path / "cli" / "summary.json").read_text())["joint_coverage"]
    assert coverage["mortar_width_p95_m"] == pytest.approx(0.08, abs=0.006)
    assert "narrower than 8.0 cm" in notes[0]
    # and the reach that joins each hanging unit to a unit beneath: its bed, 8 cm, as built
    assert coverage["widest_bed_m"] == pytest.approx(0.08, abs=1e-6)
    assert "max_joint_m = 0.09 joins each of them to a unit beneath, their beds being at most 8.0 cm" in notes[0]
    suggested = build_to_folder(load_structure(_wide_bed_wall(tmp_path, 0.09)), tmp_path / "m_09", figures=False)
    assert suggested["joint_coverage"]["units_without_bed_joint"] == []
    assert not {"mortar_width_p95_m", "widest_bed_m"} & set(suggested["joint_coverage"])  # only where units hang
    # the value goes through a written structure file (synth writes one from a scenario)
    from calib_masonry.spec import structure_to_toml

    again = tmp_path / "again.toml"
    again.write_text(structure_to_toml(load_structure(_wide_bed_wall(tmp_path, 0.1)), relative_to=tmp_path))
    assert load_structure(again).max_joint_m == 0.1


def test_units_over_an_opening_are_named_as_such_not_as_a_wide_bed(tmp_path, capsys):
    # a running-bond wall (4 courses of bricks 0.39 x 0.18 m, 1 cm joints, 2.01 m wide) with an
    # opening two courses high: the bricks of courses 1 and 2 that reach into x = 0.75-1.25 m are
    # left out, so two bricks of course 3 have nothing beneath within 0.3 m (the widest joint a
    # structure file allows) and no joint reach would join them. The build names them as over an
    # opening and gives no max_joint_m to raise (it said "max_joint_m = 0.46 would reach across
    # them" for a window 1 m wide, past the 0.3 the structure file allows: the 95th percentile of
    # the mortar's widths took the window's for joints'; a gap wider than 0.3 m is no joint now).
    # With the default mortar the wall stands on them, as the note says (dry, the two are a flat
    # arch whose outcome rests on its abutments' friction: not asserted)
    from PIL import Image

    from calib_masonry.cli import main
    from calib_masonry.simulation.joints import Material
    from calib_masonry.simulation.run import SimulationConfig, simulate_to_folder
    from calib_masonry.spec import MAX_JOINT_M

    px = 200
    mask = np.zeros((int(0.77 * px), int(2.01 * px)), np.uint8)
    rows = mask.shape[0]
    for course in range(4):
        edges = [0.01, 0.20] if course % 2 else [0.01]
        while edges[-1] + 0.39 <= 2.0 + 1e-9:
            edges.append(edges[-1] + 0.40)
        edges[-1] = 2.00 if course % 2 else edges[-1]
        for x0, x1 in zip(edges[:-1], edges[1:]):
            x0 = x0 if x0 == 0.01 else x0 + 0.01
            if course in (1, 2) and x0 < 1.25 and x1 > 0.75:
                continue
            z0 = 0.01 + 0.19 * course
            r1, r0 = rows - int(round(z0 * px)), rows - int(round((z0 + 0.18) * px))
            mask[r0:r1, int(round(x0 * px)) : int(round(x1 * px))] = 255
    Image.fromarray(mask).save(tmp_path / "open.png")
    structure = tmp_path / "open.toml"
    structure.write_text(
        '[structure]\nname = "open"\nthickness_m = 0.2\nvertices = 4\n[[wall]]\nname = "w"\n'
        'mask = "open.png"\nwidth_m = 2.01\nheight_m = 0.77\n'
    )
    capsys.readouterr()
    assert main(["build", str(structure), "--out", str(tmp_path / "m"), "--no-figures"]) == 0
    notes = [line for line in capsys.readouterr().out.splitlines() if "note:" in line]
    coverage = json.loads((tmp_path / "m" / "summary.json").read_text())["joint_coverage"]
    assert len(coverage["units_without_bed_joint"]) == 2
    assert coverage["units_over_opening"] == coverage["units_without_bed_joint"]
    assert "widest_bed_m" not in coverage and coverage["mortar_width_p95_m"] <= MAX_JOINT_M
    assert len(notes) == 1 and "an opening" in notes[0] and coverage["units_over_opening"][0] in notes[0]
    assert "max_joint_m =" not in notes[0]
    config = SimulationConfig(pga_g=0.0, duration_s=1.0, material=Material(), figures=False)
    summary = simulate_to_folder(tmp_path / "m", tmp_path / "gravity", config, progress=False)
    assert summary["moved_fraction_final"] == 0.0 and summary["bonds_broken"] == 0


def test_synth_joins_thick_mortar_stones_to_the_ones_beneath_as_its_truth_does(tmp_path):
    # a tower of stones in 5 cm of mortar, irregular at 1.0: their beds are up to about 9 cm wide where their
    # edges tilt and corners are chamfered, wider than the default joint reach (6 cm). A scenario
    # that names neither vertices nor max_joint_m: synth writes the stones' own corner count (8)
    # and the reach its truth's widest bed needs, and the built wall stands under its own weight.
    # With five vertices and the default reach (synth's structure file before) most of its units
    # hang from side joints and gravity alone cracks joints.
    from calib_masonry.build3d.assemble import reach_over
    from calib_masonry.simulation import joints as J
    from calib_masonry.simulation.run import SimulationConfig, scene_for_model
    from calib_masonry.spec import STONE_VERTICES

    text = scenario_text(
        [(2.2, 4.0, a) for a in (0, 90, 180, 270)], layout="stones", seed=11, t=0.5, closed=True, px_per_m=100
    )
    text = text.replace("vertices = 5\n", "").replace("mortar_m = 0.025", "mortar_m = 0.05\nirregularity = 1.0")
    (tmp_path / "s.toml").write_text(text)
    truth = synthesize_to_folder(
        load_structure(tmp_path / "s.toml", require_sources=False), tmp_path / "d", figures=False
    )
    spec = load_structure(tmp_path / "d" / "structure.toml")
    assert truth["widest_bed_m"] > 0.07
    assert spec.max_joint_m == truth["max_joint_m"] == reach_over(truth["widest_bed_m"])
    assert spec.vertices == STONE_VERTICES and all(w.vertices == STONE_VERTICES for w in spec.walls)
    down = np.array([0.0, 0.0, -9.81])
    hanging, cracked = {}, {}
    for name, s in {"synth": spec, "before": replace(spec, max_joint_m=None)}.items():
        if name == "before":
            s = s.with_walls(tuple(replace(w, vertices=5) for w in s.walls))
        summary = build_to_folder(s, tmp_path / name, figures=False)
        hanging[name] = len(summary["joint_coverage"]["units_without_bed_joint"]) / summary["bricks"]
        model = J.JointModel(
            scene_for_model(tmp_path / name, SimulationConfig(pga_g=0.0, duration_s=1.0, figures=False))
        )
        cracked[name] = len(model.crack(down, np.ones(model.nj, bool))[0])
    assert hanging["synth"] <= 0.03 and cracked["synth"] == 0
    assert hanging["before"] > 0.3 and cracked["before"] > 0


def _courses_mask(path: Path, margin_m: float = 0.0, shift_up_m: float = 0.0, px: int = 200) -> None:
    """Two courses of three bricks 0.39 x 0.18 m with 1 cm joints (a wall 1.21 x 0.39 m at 200
    px/m), drawn inside a canvas ``margin_m`` larger on every side, or lifted ``shift_up_m`` off the
    canvas's bottom (its top course cut by as much)."""
    from PIL import Image

    rows, cols = int(round((0.39 + 2 * margin_m) * px)), int(round((1.21 + 2 * margin_m) * px))
    mask = np.zeros((rows, cols), np.uint8)
    for z0 in (0.0, 0.20):
        for x0 in (0.01, 0.41, 0.81):
            r1 = rows - int(round((z0 + margin_m + shift_up_m) * px))
            c0 = int(round((x0 + margin_m) * px))
            mask[max(r1 - int(round(0.18 * px)), 0) : r1, c0 : c0 + int(round(0.39 * px))] = 255
    Image.fromarray(mask).save(path)


def test_a_mask_drawn_inside_a_larger_canvas_is_warned_of(tmp_path):
    # the canvas 0.1 m larger than the wall on every side, width_m and height_m the canvas's: the
    # wall is built 1.2 m wide where 1.41 m was given, its base 0.1 m off the mask's bottom, and
    # the build says so, naming the margins and the size built; drawn to its edges, no word
    import warnings

    from calib_masonry.pipeline import build

    for margin in (0.1, 0.0):
        _courses_mask(tmp_path / f"m{margin}.png", margin_m=margin)
        (tmp_path / f"s{margin}.toml").write_text(
            f'[structure]\nname = "c"\nthickness_m = 0.2\nvertices = 4\n[[wall]]\nname = "w"\nmask = "m{margin}.png"\n'
            f"width_m = {1.21 + 2 * margin:.2f}\nheight_m = {0.39 + 2 * margin:.2f}\n"
        )
        spec = load_structure(tmp_path / f"s{margin}.toml")
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            result = build(spec, progress=False)
        said = [str(w.message) for w in caught if "units stop" in str(w.message)]
        if margin:
            assert len(said) == 1 and "0.100 m above its base" in said[0] and "built 1.190 x 0.380 m" in said[0]
            assert "crop the mask" in said[0] and "\n" not in said[0]
        else:
            assert said == []
        z = np.concatenate([b.solid.vertices[:, 2] for b in result.structure.bricks])
        assert z.min() == pytest.approx(margin, abs=0.006)


def test_a_wall_whose_units_start_above_the_footing_is_refused(tmp_path, capsys):
    # an L of two walls, the second's units lifted 0.1 m off its mask's bottom: nothing joins it
    # to the footing (the first wall's base), and it would drop under gravity alone: exit 2, one
    # line naming the wall, its mask and the reach, nothing written; lifted 3 cm (within the
    # reach of 6 cm), it builds
    from calib_masonry.cli import main

    _courses_mask(tmp_path / "a.png")
    for lift in (0.1, 0.03):
        _courses_mask(tmp_path / "b.png", shift_up_m=lift)
        (tmp_path / "l.toml").write_text(
            '[structure]\nname = "l"\nthickness_m = 0.2\nvertices = 4\nclosed = false\n'
            '[[wall]]\nname = "a"\nmask = "a.png"\nwidth_m = 1.21\nheight_m = 0.39\ntheta_deg = 0\n'
            '[[wall]]\nname = "b"\nmask = "b.png"\nwidth_m = 1.21\nheight_m = 0.39\ntheta_deg = 90\n'
        )
        out = tmp_path / f"out{lift}"
        capsys.readouterr()
        r = main(["build", str(tmp_path / "l.toml"), "--out", str(out), "--no-figures"])
        err = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
        if lift == 0.1:
            assert r == 2 and not out.exists() and len(err) == 1, err
            assert "wall 'b' mask " in err[0] and "b.png" in err[0] and "0.100 m above the footing" in err[0]
            assert "reach of 0.06 m" in err[0] and "max_joint_m" in err[0]
        else:
            assert r == 0 and out.exists(), err


@pytest.mark.parametrize("value", [0.0, 0.5, -0.01])
def test_an_impossible_max_joint_is_refused_naming_the_field(tmp_path, value):
    from calib_masonry.errors import InputError

    with pytest.raises(InputError, match=r"max_joint_m = .* must lie in 0.005..0.3"):
        load_structure(_wide_bed_wall(tmp_path, value))


def test_a_wall_traced_to_triangles_is_said_to_be_too_coarse(tmp_path):
    # bricks traced to three vertices are triangles (half of each brick left out): build warns in one
    # line naming the wall, the Dice and the remedy; four vertices build without a word
    from calib_masonry.pipeline import COARSE_TRACE_DICE

    p = _wide_bed_wall(tmp_path, None)
    p.write_text(p.read_text().replace("vertices = 4", "vertices = 3"))
    with pytest.warns(
        UserWarning, match=r"wall 'w': .* mean Dice of 0\.\d\d \(vertices = 3\): too few vertices"
    ) as got:
        summary = build_to_folder(load_structure(p), tmp_path / "tri", figures=False)
    assert summary["mean_dice"] < COARSE_TRACE_DICE and len(got) == 1
    build_to_folder(load_structure(_wide_bed_wall(tmp_path, None)), tmp_path / "quad", figures=False)


def test_build_says_when_two_bricks_overlap(tmp_path, capsys):
    # a piece traced across a joint around another (a ring of stone around a small one, as a
    # segmentation that leaked through a broken joint leaves it): its outline, traced by its
    # outside, holds the small piece whole, and the model's two solids overlap. The build printed
    # "max interpenetration 8.30e-03 m^3" and nothing else (a hexagonal brick tower's photos).
    from calib_masonry.cli import main
    from calib_masonry.io import write_mask

    mask = np.zeros((120, 200), bool)  # 200 px/m: a wall 1.0 x 0.6 m
    mask[10:110, 10:90] = True
    mask[28:92, 28:72] = False  # the mortar ring inside the large piece
    mask[35:85, 35:65] = True  # the small piece in it
    mask[10:55, 100:190] = True
    mask[65:110, 100:190] = True
    write_mask(tmp_path / "w.png", mask)
    (tmp_path / "s.toml").write_text(
        '[structure]\nname = "ring"\nthickness_m = 0.2\nclosed = false\n\n'
        '[[wall]]\nname = "w"\nmask = "w.png"\nwidth_m = 1.0\nheight_m = 0.6\ntheta_deg = 0\n'
    )
    summary = build_to_folder(load_structure(tmp_path / "s.toml"), tmp_path / "m", figures=False)
    small = 0.15 * 0.25 * 0.2  # the small piece's solid, all of it inside the large one's
    assert summary["worst_pair_share"] == pytest.approx(1.0, abs=0.05)
    assert summary["max_interpenetration_m3"] == pytest.approx(small, rel=0.05)
    assert summary["worst_pair_walls"] == ["w", "w"]
    capsys.readouterr()
    assert main(["build", str(tmp_path / "s.toml"), "--out", str(tmp_path / "cli"), "--no-figures"]) == 0
    notes = [line for line in capsys.readouterr().out.splitlines() if "overlap by" in line]
    assert len(notes) == 1 and "brick_00000 and brick_00002 (wall w) overlap by 100% of the smaller" in notes[0]
    assert "LabelMe" in notes[0]


def test_build_says_where_the_corners_owner_was_a_guess(make_scenario, tmp_path, capsys):
    # a hexagonal tower of 0.35 m walls and 0.40 m bricks: the end face each wall shows of the
    # other's brick, 0.35 / sin 60 = 0.404 m, is as wide as a brick, so in some courses which wall
    # runs through is a guess (built from synth's photos, 13 % of the bricks were counted on the
    # wrong wall, and the build said nothing); a square tower's end faces (0.35 m) are not
    from calib_masonry.cli import main

    extra = "brick_length_m = 0.40\nbrick_height_m = 0.20"
    hexagon = make_scenario([(1.6, 1.0, 60.0 * k) for k in range(6)], name="hex", t=0.35, closed=True, extra=extra)
    square = make_scenario([(1.6, 1.0, 90.0 * k) for k in range(4)], name="sq", t=0.35, closed=True, extra=extra)
    summary = build_to_folder(load_structure(hexagon / "structure.toml"), tmp_path / "h", figures=False)
    assert summary["corner_guesses"] and all(c["courses"] > 0 for c in summary["corner_guesses"])
    assert {tuple(c["walls"]) for c in summary["corner_guesses"]} <= {(f"w{k}", f"w{(k + 1) % 6}") for k in range(6)}
    assert (
        build_to_folder(load_structure(square / "structure.toml"), tmp_path / "s", figures=False)["corner_guesses"]
        == []
    )
    capsys.readouterr()
    assert main(["build", str(hexagon / "structure.toml"), "--out", str(tmp_path / "cli"), "--no-figures"]) == 0
    notes = [line for line in capsys.readouterr().out.splitlines() if "was a guess" in line]
    n = sum(c["courses"] for c in summary["corner_guesses"])
    assert len(notes) == 1 and f"a guess in {n} courses" in notes[0]

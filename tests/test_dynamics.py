"""The intact structure as an elastic body: inertia, natural periods against beam theory, the
Newmark integration against free vibration, and resonance against the first mode's amplification
(no Blender)."""

from dataclasses import replace

import numpy as np
import pytest
import scipy.linalg as sla

from calib_masonry.simulation.dynamics import ElasticResponse, body_inertia, mass_matrix, modes, rayleigh
from calib_masonry.simulation.ground_motion import G, GroundMotion
from calib_masonry.simulation.joints import JointModel
from calib_masonry.simulation.scene import Material
from calib_masonry.simulation.tracker import CrackTracker

from .test_joints import _block, _column


def test_inertia_of_a_box_and_of_a_rotated_one():
    b = _block("b", (0.4, 0.2, 0.3), (1.0, 2.0, 3.0))
    m = b.mass
    assert np.diag(body_inertia(b)) == pytest.approx(
        m / 12 * np.array([0.2**2 + 0.3**2, 0.4**2 + 0.3**2, 0.4**2 + 0.2**2])
    )
    # a quarter turn about z swaps the x and y moments
    c = 2**-0.5
    r = replace(b, rotation=(c, 0.0, 0.0, c))
    assert np.diag(body_inertia(r)) == pytest.approx(
        m / 12 * np.array([0.4**2 + 0.3**2, 0.2**2 + 0.3**2, 0.4**2 + 0.2**2])
    )


def _timoshenko_period(E, G_, rho, A, second_moment, L, kappa=5 / 6, elements=400):
    """First period of a clamped-free Timoshenko beam: finite elements with the exact static
    stiffness of a Timoshenko element (Przemieniecki) and lumped translational and rotary mass."""
    I = second_moment  # noqa: E741
    le = L / elements
    phi = 12 * E * I / (kappa * G_ * A * le**2)
    k = (
        E
        * I
        / ((1 + phi) * le**3)
        * np.array(
            [
                [12, 6 * le, -12, 6 * le],
                [6 * le, (4 + phi) * le**2, -6 * le, (2 - phi) * le**2],
                [-12, -6 * le, 12, -6 * le],
                [6 * le, (2 - phi) * le**2, -6 * le, (4 + phi) * le**2],
            ]
        )
    )
    n = 2 * (elements + 1)
    K, M = np.zeros((n, n)), np.zeros(n)
    for e in range(elements):
        K[2 * e : 2 * e + 4, 2 * e : 2 * e + 4] += k
        M[2 * e : 2 * e + 4] += np.array([rho * A, rho * I, rho * A, rho * I]) * le / 2
    w = sla.eigh(K[2:, 2:], np.diag(M[2:]), eigvals_only=True, subset_by_index=[0, 0])
    return 2 * np.pi / np.sqrt(w[0])


@pytest.mark.parametrize("courses, size", [(20, (0.4, 0.2, 0.3)), (36, (0.25, 0.12, 0.065))])
def test_first_period_of_a_bonded_column_is_the_timoshenko_beams(courses, size):
    mat = Material()
    lx, ly, h = size
    m = modes(_column(courses, size=size, material=mat), 3)
    # the column's effective moduli: units and mortar in series over a course (no mortar mass: the
    # blocks touch in the model, each course's pitch h holds a joint's thickness t of mortar and
    # h - t of unit, as `build`'s bodies filled out to the middle of the mortar do)
    t = mat.joint_thickness_m
    E = h / (t / mat.mortar_youngs_modulus + (h - t) / mat.unit_youngs_modulus)
    gm = mat.mortar_youngs_modulus / (2 * (1 + mat.mortar_poisson))
    gu = mat.unit_youngs_modulus / (2 * (1 + mat.unit_poisson))
    Gs = h / (t / gm + (h - t) / gu)
    L, A = courses * h, lx * ly
    weak = _timoshenko_period(E, Gs, mat.density, A, lx * ly**3 / 12, L)
    strong = _timoshenko_period(E, Gs, mat.density, A, ly * lx**3 / 12, L)
    assert m.periods_s[0] == pytest.approx(weak, rel=0.05)
    assert m.periods_s[1] == pytest.approx(strong, rel=0.05)
    # the weak axis is y: its mode moves the mass along y, about 61 % of it (a uniform cantilever's)
    assert m.effective_mass_fraction[0, 1] == pytest.approx(0.613, abs=0.03)
    assert m.effective_mass_fraction[0, [0, 2]] == pytest.approx([0, 0], abs=1e-6)


def test_a_built_walls_joints_count_its_mortar_once_and_its_first_period_is_the_timoshenko_beams(tmp_path):
    """`build` fills each unit out to the middle of the mortar around it, so two bodies' centroids
    are a course's pitch apart (unit and joint). Counted as unit, that mortar was counted twice (in
    t_j / E_m and again in l / E_u): a bed joint's unit length was the pitch, the masonry's own
    modulus came out (h + t_j) / (h + 2 t_j) of itself, and a built wall's out-of-plane period 4 %
    above the beam's. The beam is computed here from the effective moduli of a course's pitch,
    units and mortar in series."""
    from calib_masonry.build_folder import simulation_geometry
    from calib_masonry.pipeline import build
    from calib_masonry.simulation.scene import scene_from_geometry
    from calib_masonry.spec import load_structure
    from calib_masonry.synthetic.truth import synthesize_to_folder

    from .conftest import scenario_text

    hu, lu, tj, t = 0.14, 0.29, 0.01, 0.2
    (tmp_path / "scenario.toml").write_text(
        scenario_text(
            [(1.2, 3.0, 0.0)],
            closed=False,
            t=t,
            seed=17,
            extra=f"brick_length_m = {lu}\nbrick_height_m = {hu}\nmortar_m = {tj}\n",
        )
    )
    synthesize_to_folder(
        load_structure(tmp_path / "scenario.toml", require_sources=False), tmp_path / "data", figures=False
    )
    g = simulation_geometry(build(load_structure(tmp_path / "data" / "structure.toml"), progress=False).structure)
    mat = Material(joint_thickness_m=tj)
    scene = scene_from_geometry(g, duration_s=1.0, material=mat, foundation=True)
    jm = JointModel(scene)
    bed = (np.abs(jm.R[:, 2, 2]) > 0.99) & (jm.b >= 0)
    assert bed.sum() > 20
    assert np.median(jm.unit_length[bed]) == pytest.approx(hu, abs=0.002)  # the pitch, 0.15, before
    # the masonry's own modulus: each bed joint over its pitch gives it (0.94 of it before)
    e = 2.0e9
    k = JointModel(replace(scene, material=replace(mat, masonry_youngs_modulus=e))).stiffness.normal
    assert np.median(k[bed]) * (hu + tj) == pytest.approx(e, rel=0.01)
    # the wall's first mode (out of its plane) against a Timoshenko cantilever of its effective moduli
    m = modes(scene, 1)
    pitch = hu + tj
    E = pitch / (tj / mat.mortar_youngs_modulus + hu / mat.unit_youngs_modulus)
    gm = mat.mortar_youngs_modulus / (2 * (1 + mat.mortar_poisson))
    gu = mat.unit_youngs_modulus / (2 * (1 + mat.unit_poisson))
    Gs = pitch / (tj / gm + hu / gu)
    lo = np.min([b.location + b.vertices.min(axis=0) for b in scene.bodies], axis=0)
    hi = np.max([b.location + b.vertices.max(axis=0) for b in scene.bodies], axis=0)
    width, height = float(hi[0] - lo[0]), float(hi[2] - lo[2])
    rho = m.total_mass_kg / (width * t * height)  # the units' mass spread over the wall's volume
    beam = _timoshenko_period(E, Gs, rho, width * t, width * t**3 / 12, height)
    assert m.effective_mass_fraction[0, 1] > 0.5  # out of the plane
    assert m.periods_s[0] == pytest.approx(beam, rel=0.05)


def test_effective_masses_sum_to_the_mass():
    sc = _column(3)
    m = modes(sc, 18)
    assert m.effective_mass_kg.sum(axis=0) == pytest.approx([m.total_mass_kg] * 3, rel=1e-9)
    M = mass_matrix(sc).toarray()
    V = m.shapes.reshape(18, -1)
    assert V @ M @ V.T == pytest.approx(np.eye(18), abs=1e-9)


def _tracker_scene(courses=20, material=Material()):
    sc = _column(courses, size=(0.4, 0.2, 0.3), material=material)
    still = GroundMotion(dt=0.01, displacement=np.zeros((3, 2)), acceleration=np.zeros((3, 2)))
    return replace(sc, motion=still)


def test_newmark_free_vibration_has_the_first_period_and_the_damping_ratio():
    sc = _tracker_scene()
    m = modes(sc, 2)
    omega = 2 * np.pi / m.periods_s
    jm = JointModel(sc)
    el = ElasticResponse(jm, mass_matrix(sc), ratio=0.05, omega=(omega[0], omega[1]))
    rate = 200.0
    el.advance(0.0, np.array([0.0, 0.0, -G]))
    el.advance(1 / rate, np.array([0.0, 0.0, -G]))
    # pull along y for a while, then let go: free vibration in the first mode (the pull's shape is
    # close to it; higher modes die out faster)
    for k in range(2, 400):
        el.advance(k / rate, np.array([0.0, 0.05 * G, -G]))
    top = []
    for k in range(400, 1400):
        el.advance(k / rate, np.array([0.0, 0.0, -G]))
        top.append(el.u.reshape(-1, 6)[-1, 1])
    y = np.array(top)
    t = np.arange(len(y)) / rate
    peaks = [i for i in range(1, len(y) - 1) if y[i] > y[i - 1] and y[i] > y[i + 1] and y[i] > 0]
    period = np.diff(t[peaks]).mean()
    assert period == pytest.approx(m.periods_s[0], rel=0.01)
    decrement = np.log(y[peaks[1]] / y[peaks[-1]]) / (len(peaks) - 2)
    assert decrement / (2 * np.pi) == pytest.approx(0.05, rel=0.1)


def test_rayleigh_damping_has_the_ratio_at_both_frequencies():
    a, b = rayleigh(0.05, 10.0, 40.0)
    for w in (10.0, 40.0):
        assert a / (2 * w) + b * w / 2 == pytest.approx(0.05)


def _cracks(sc, amplitude_g, f, rate=50.0):
    """Whether a harmonic base acceleration of this amplitude (along y, a sin^2 ramp then steady)
    cracks a joint of the column."""
    x = np.array([b.location for b in sc.bodies])
    ramp = max(3 / f, 3.0)
    end = ramp + 4 / f + 10.0
    dt = 0.002
    t = np.arange(int(end / dt) + 2) * dt
    a = amplitude_g * G * np.sin(0.5 * np.pi * np.minimum(t / ramp, 1.0)) ** 2 * np.sin(2 * np.pi * f * t)
    vel = np.concatenate([[0.0], np.cumsum(0.5 * (a[1:] + a[:-1]) * dt)])
    disp = np.concatenate([[0.0], np.cumsum(0.5 * (vel[1:] + vel[:-1]) * dt)])
    zero = np.zeros_like(t)
    record = GroundMotion(dt=dt, displacement=np.column_stack([zero, disp]), acceleration=np.column_stack([zero, a]))
    sc = replace(sc, motion=record)
    tr = CrackTracker(sc, x, np.repeat(np.eye(3)[None], len(x), 0), np.zeros(3), 0.0)
    for k in range(int(end * rate) + 1):
        tr.step(k / rate, np.array([0.0, 0.0, -G]), x, None, None)  # the vibration reads the record
        if np.isfinite(tr.break_time_s).any():
            return True
    return False


def _onset(sc, f):
    lo, hi = 1e-3, 1.0
    for _ in range(11):  # to 0.6 % in the amplitude
        mid = np.sqrt(lo * hi)
        lo, hi = (lo, mid) if _cracks(sc, mid, f) else (mid, hi)
    return hi


@pytest.mark.slow
def test_resonance_cracks_at_the_amplitude_the_first_modes_amplification_says():
    sc = _tracker_scene(material=Material(tensile_strength=0.05e6))
    f1 = 1 / modes(sc, 1).periods_s[0]
    at_f1, at_fifth = _onset(sc, f1), _onset(sc, 0.2 * f1)
    zeta, r = 0.05, 0.2
    amplification = 1 / (2 * zeta) / (1 / np.sqrt((1 - r**2) ** 2 + (2 * zeta * r) ** 2))
    assert at_fifth / at_f1 == pytest.approx(amplification, rel=0.15)
    # and quasi-statically (the structure rigid) the frequency would not matter
    rigid = replace(sc, solver=replace(sc.solver, dynamics=False))
    assert _onset(rigid, f1) == pytest.approx(_onset(rigid, 0.2 * f1), rel=0.02)


def test_modes_of_a_large_structure_are_the_same_from_call_to_call():
    # over _DENSE unknowns the modes come from ARPACK, whose start vector scipy 1.17 draws from
    # fresh entropy unless given one: the periods, and with them the Rayleigh damping and every
    # crack check of a quake, then differed in the last digits from run to run
    sc = _column(120)
    a, b = modes(sc, 3), modes(sc, 3)
    assert np.array_equal(a.periods_s, b.periods_s)
    assert np.array_equal(a.shapes, b.shapes)


@pytest.mark.parametrize("courses", [20, 120])  # the dense solve, then ARPACK's (over _DENSE unknowns)
def test_modes_for_a_mass_fraction_are_the_fewest_that_carry_it(courses):
    # EN 1998-1 4.3.3.3.1: the modes whose effective masses sum to 90 % of the mass along each
    # horizontal direction; a cantilever's first bending mode carries about 61 % of it
    sc = _column(courses)
    m = modes(sc, 1, mass_fraction=0.9)
    cum = np.cumsum(m.effective_mass_fraction[:, :2], axis=0)
    k = len(m.periods_s)
    assert m.mass_fraction_met and cum[-1].min() >= 0.9 and cum[-2].min() < 0.9
    assert k > 2
    # the same modes as asking for that many
    assert m.periods_s == pytest.approx(modes(sc, k).periods_s, rel=1e-9)
    # more asked for than the fraction needs: all of them
    assert len(modes(sc, k + 3, mass_fraction=0.9).periods_s) == k + 3


def test_modes_refuses_too_many_and_an_impossible_fraction():
    from calib_masonry.errors import InputError
    from calib_masonry.simulation.dynamics import MAX_MODES

    sc = _column(3)
    for kwargs, msg in (
        (dict(n=MAX_MODES + 1), "at most"),
        (dict(mass_fraction=1.0), "between 0 and 1"),
        (dict(mass_fraction=0.0), "between 0 and 1"),
    ):
        with pytest.raises(InputError, match=msg):
            modes(sc, **kwargs)


def test_modes_count_their_steps_and_are_scipys_to_the_last_digit(monkeypatch, capsys):
    # a large structure's modes take minutes: ARPACK's steps show in log lines (every LOG_EVERY_S,
    # here at each), through an operator that is scipy's own shift-invert to the last digit (the
    # Rayleigh damping of every quake is made from the modes)
    import scipy.sparse.linalg as spla

    from calib_masonry import progress as progress_module
    from calib_masonry.simulation.dynamics import _lowest_modes, stiffness_matrix

    monkeypatch.setattr(progress_module, "LOG_EVERY_S", 0.0)
    sc = _column(120)
    K, M = stiffness_matrix(sc), mass_matrix(sc)
    w, V = _lowest_modes(K, M, 3, progress=None)
    v0 = np.random.default_rng(0).uniform(-1.0, 1.0, K.shape[0])
    w0, V0 = spla.eigsh(K.tocsc(), k=3, M=M.tocsc(), sigma=-1.0, which="LM", v0=v0)
    order = np.argsort(w0)
    assert np.array_equal(w, w0[order]) and np.array_equal(V, V0[:, order])
    lines = [line for line in capsys.readouterr().err.splitlines() if line.startswith("modes (the lowest 3)")]
    assert len(lines) > 3 and lines[-1].endswith("done"), lines

"""The elastic joint model against statics and the analytic failure moments (no Blender)."""

import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp
import shapely

from calib_masonry.build3d.contacts import OUTLINE_POINTS, joint_axes, patch_section
from calib_masonry.errors import InputError
from calib_masonry.simulation.ground_motion import G
from calib_masonry.simulation.joints import FAILURE_MODES, ContactSettings, JointModel, joint_stiffness
from calib_masonry.simulation.results import rotations
from calib_masonry.simulation.scene import Body, Bond, Material, Pushover, Scene, box_mesh, quaternions_from_matrices
from calib_masonry.simulation.tracker import CrackTracker

DOWN = np.array([0.0, 0.0, -1.0])
X = np.array([1.0, 0.0, 0.0])
UP = np.array([0.0, 0.0, 1.0])


def _block(name, size, centre, density=1800.0):
    v, f = box_mesh(size)
    vol = float(np.prod(size))
    return Body(name, v, f, np.asarray(centre, float), density * vol, 0.7, 0.0, vol)


def _column(n, size=(0.4, 0.2, 0.3), material=Material()):
    """``n`` blocks stacked and bonded, the lowest on a foundation joint."""
    lx, ly, h = size
    bodies = tuple(_block(f"b{i}", size, (0, 0, h * (i + 0.5)), material.density) for i in range(n))
    bonds = [Bond.rectangle(0, -1, (0, 0, 0), DOWN, X, lx, ly)]
    bonds += [Bond.rectangle(i, i + 1, (0, 0, h * (i + 1)), UP, X, lx, ly) for i in range(n - 1)]
    return Scene(bodies=bodies, bonds=tuple(bonds), material=material)


def test_patch_section_of_a_rectangle_and_a_rotated_one():
    # a 0.4 x 0.2 rectangle in the plane z = 0 (basis X, Y), normal +Z
    poly = shapely.box(1.0, 2.0, 1.4, 2.2)
    c, mom, outline, area = patch_section(poly, np.array([[1.0, 0, 0], [0, 1.0, 0]]), UP)
    assert area == pytest.approx(0.08)
    assert c == pytest.approx([1.2, 2.1])
    u, v, _ = (a[0] for a in joint_axes(UP[None]))
    # int u^2 dA and int v^2 dA: the widths along u and v
    wu = 0.4 if abs(u[0]) > 0.9 else 0.2
    wv = 0.2 if wu == 0.4 else 0.4
    assert mom[0] == pytest.approx(0.08 * wu**2 / 12)
    assert mom[1] == pytest.approx(0.08 * wv**2 / 12)
    assert mom[2] == pytest.approx(0.0, abs=1e-15)
    assert outline.shape == (OUTLINE_POINTS, 2)
    assert np.abs(outline).max(axis=0) == pytest.approx([wu / 2, wv / 2])
    # rotated by 30 degrees in its plane: the polar moment is invariant, I_uv appears
    rot = shapely.affinity.rotate(poly, 30, origin="centroid")
    _, mom_r, _, _ = patch_section(rot, np.array([[1.0, 0, 0], [0, 1.0, 0]]), UP)
    assert mom_r[0] + mom_r[1] == pytest.approx(mom[0] + mom[1])
    assert abs(mom_r[2]) == pytest.approx(abs(math.sin(math.radians(60)) * (mom[0] - mom[1]) / 2), rel=1e-9)


def test_joint_stiffness_is_mortar_and_units_in_series():
    m = Material(
        mortar_youngs_modulus=2e9,
        unit_youngs_modulus=12e9,
        mortar_poisson=0.25,
        unit_poisson=0.2,
        joint_thickness_m=0.012,
    )
    k = joint_stiffness(m, np.array([0.0, 0.3]))
    gm, gu = 2e9 / 2.5, 12e9 / 2.4
    assert k.normal == pytest.approx([2e9 / 0.012, 1 / (0.012 / 2e9 + 0.3 / 12e9)])
    assert k.shear == pytest.approx([gm / 0.012, 1 / (0.012 / gm + 0.3 / gu)])
    # in a column, a joint between two blocks carries their centroids' distance (a block's height,
    # half of each) less the joint's mortar, which that distance holds (as `build` fills units out
    # to the middle of the mortar: joints.unit_lengths); the foundation joint half a block (the
    # ground is rigid, the bed under it the joint's own): each joint shortens by F (t_j/E_m + l/E_u) / A
    n, h = 4, 0.3
    jm = JointModel(_column(n, material=m))
    assert jm.unit_length == pytest.approx([h / 2] + [h - 0.012] * (n - 1))
    st, _ = jm.solve(np.array([0.0, 0.0, -G]), np.ones(n, bool))
    above = np.array([jm.mass[i:].sum() * G for i in range(n)])
    flexibility = (0.012 / 2e9 + jm.unit_length / 12e9) / (0.4 * 0.2)
    assert st.forces[:, 2] == pytest.approx(-above, rel=1e-6)
    assert st.relative[:, 2] == pytest.approx(-above * flexibility, rel=1e-6)


@pytest.mark.parametrize("lam", [0.0, 0.15])
def test_a_cantilever_column_carries_what_statics_says(lam):
    # statically determinate: each joint carries the load of the blocks above it, and the moment of
    # that load about the joint's centroid
    n = 4
    sc = _column(n)
    jm = JointModel(sc)
    g = np.array([lam * G, 0.0, -G])
    st, _ = jm.solve(g, np.ones(jm.nj, bool))
    per_block = sc.bodies[0].mass * g
    tol = 1e-6 * sc.bodies[0].mass * G
    for j, bond in enumerate(sc.bonds):
        first = 0 if bond.b < 0 else bond.b  # the lowest block above the joint
        above = [sc.bodies[k].location for k in range(first, n)]
        load = per_block * len(above)
        moment = sum(np.cross(x - bond.location, per_block) for x in above)
        # the joint's forces are those b exerts... expressed on a: for the foundation joint a is the
        # block above (it holds the load up), for the others a is the block below (it is pushed)
        on_above = 1.0 if bond.b < 0 else -1.0
        F = jm.R[j] @ st.forces[j, :3]
        M = jm.R[j] @ st.forces[j, 3:]
        assert on_above * F == pytest.approx(-load, abs=tol)
        assert on_above * M == pytest.approx(-moment, abs=tol)


def test_forces_do_not_depend_on_the_size_of_the_stiffness():
    soft = _column(3, material=Material(mortar_youngs_modulus=1e8, unit_youngs_modulus=1e9))
    stiff = _column(3, material=Material(mortar_youngs_modulus=1e10, unit_youngs_modulus=1e11))
    g = np.array([0.2 * G, 0.1 * G, -G])
    a = JointModel(soft).solve(g, np.ones(3, bool))[0].forces
    b = JointModel(stiff).solve(g, np.ones(3, bool))[0].forces
    # equal but for the share of the weak springs that hold free bodies (eps m against k A: 1e-7 here)
    assert a == pytest.approx(b, rel=1e-5, abs=1e-6)


def _first_crack(sc, direction=(1.0, 0.0)):
    """The lateral acceleration (g) at which the model first cracks a joint, by bisection."""
    jm = JointModel(sc)
    lo, hi = 0.0, 5.0
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        g = np.array([mid * G * direction[0], mid * G * direction[1], -G])
        st, _ = jm.solve(g, np.ones(jm.nj, bool))
        lo, hi = (mid, hi) if st.utilisation.max() <= 1.0 else (lo, mid)
    st, _ = jm.solve(np.array([hi * G * direction[0], hi * G * direction[1], -G]), np.ones(jm.nj, bool))
    return hi, FAILURE_MODES[st.mode[int(st.utilisation.argmax())]], int(st.utilisation.argmax())


#: a mortar weak in tension, so that a column's base cracks first and then rocks
WEAK_MORTAR = Material(tensile_strength=0.01e6)


def _past_first_crack(sc, factor):
    """The load ``m g`` at ``factor`` times the lateral acceleration that first cracks ``sc`` (along
    x, with gravity), and the joint that cracks first."""
    lam, _, worst = _first_crack(sc)
    return np.array([factor * lam * G, 0.0, -G]), worst


@pytest.mark.parametrize(
    "height, f_t, governs", [(0.6, 0.2e6, "tension"), (6.0, 0.02e6, "tension"), (3.0, 0.0, "tension")]
)
def test_base_joint_fails_at_max_of_first_crack_and_rocking(height, f_t, governs):
    # one block of thickness t (along X, the push) on a foundation joint: the base moment is
    # lam W H / 2; a no-tension-stopped crack fails at max(f_t S + N t / 6, N t / 2)
    t, L = 0.2, 0.4
    m = Material(tensile_strength=f_t, shear_strength=5e6)  # shear out of the way
    body = _block("wall", (t, L, height), (0, 0, height / 2))
    sc = Scene(bodies=(body,), bonds=(Bond.rectangle(0, -1, (0, 0, 0), DOWN, X, t, L),), material=m)
    W = body.mass * G
    S = L * t**2 / 6
    expected = max(f_t * S + W * t / 6, W * t / 2) / (W * height / 2)
    lam, mode, _ = _first_crack(sc)
    assert mode == governs
    assert lam == pytest.approx(expected, rel=1e-4)


def test_shear_fails_by_mohr_coulomb():
    # a squat block: sliding governs at lam = (c A + mu W) / W
    t, L, h = 1.0, 1.0, 0.1
    m = Material(tensile_strength=1e9, shear_strength=2000.0, friction=0.6)
    body = _block("slab", (t, L, h), (0, 0, h / 2))
    sc = Scene(bodies=(body,), bonds=(Bond.rectangle(0, -1, (0, 0, 0), DOWN, X, t, L),), material=m)
    W = body.mass * G
    lam, mode, _ = _first_crack(sc)
    assert mode == "shear"
    assert lam == pytest.approx((2000.0 * t * L + 0.6 * W) / W, rel=1e-4)


def test_a_group_that_nothing_holds_carries_no_joint_force():
    # two bonded blocks in free fall, 1 m above the plate: the joint between them carries nothing
    from dataclasses import replace

    sc = _column(2)
    lifted = tuple(replace(b, location=b.location + [0.0, 0.0, 1.0]) for b in sc.bodies)
    joint = replace(sc.bonds[1], location=sc.bonds[1].location + [0.0, 0.0, 1.0])
    sc = Scene(bodies=lifted, bonds=(joint,), material=sc.material)
    st, _ = JointModel(sc).solve(np.array([0.3 * G, 0.0, -G]), np.ones(1, bool))
    assert np.abs(st.forces).max() < 1e-6 * sc.bodies[0].mass * G


def test_cracked_joints_carry_compression_only():
    # a column whose foundation joint has cracked: under gravity its contact carries the weight and
    # the joint above carries the top block; pulled upwards, the contact lets go and nothing carries
    sc = _column(2)
    jm = JointModel(sc)
    intact = np.array([False, True])
    st, active = jm.solve(np.array([0.0, 0.0, -G]), intact)
    assert active[0].sum() == 4
    top = sc.bodies[1].mass * G
    assert abs(st.forces[1, 2]) == pytest.approx(top, rel=1e-6)
    st, active = jm.solve(np.array([0.0, 0.0, +G]), intact)
    assert not active.any()
    # (solved iteratively from the last factors: a free body's displacement is large, g / eps, and
    # its joint forces are small differences of it, good to about 1e-6 of the weight)
    assert np.abs(st.forces[1]).max() < 1e-5 * top


def test_cracks_cascade_event_by_event_in_one_load():
    # a column pushed past its base's first crack: the base cracks first, in tension, and the
    # cascade in the same load goes on from there
    sc = _column(3, material=WEAK_MORTAR)
    jm = JointModel(sc)
    g, worst = _past_first_crack(sc, 1.05)
    assert sc.bonds[worst].b < 0  # the base cracks first
    cracked, modes, st = jm.crack(g, np.ones(jm.nj, bool), np.ones((jm.nj, OUTLINE_POINTS), bool))
    assert cracked[0] == worst
    assert FAILURE_MODES[modes[0]] == "tension"


def test_a_crack_round_cracks_the_joints_within_its_band_of_the_worst():
    # crack_band: the joints over their strength within this fraction of the worst crack in one
    # round, the others wait for the next round's solve (0, where the load rises slowly: the worst
    # alone, one event at a time)
    sc = _column(12)
    g = np.array([0.2 * G, 0.0, -G])
    probe = JointModel(sc)
    u = probe.solve(g, np.ones(probe.nj, bool))[0].utilisation
    assert u[0] == u.max() and 0.8 * u[0] <= u[1] < 0.9 * u[0] and u[1] > 1.0 and u[2] < 0.8 * u[0]
    closed = np.ones((probe.nj, OUTLINE_POINTS), bool)
    for band, first_round in ((0.2, {0, 1}), (0.1, {0}), (0.0, {0})):
        jm = JointModel(sc, settings=ContactSettings(crack_band=band, max_rounds=1))
        cracked, _, _ = jm.crack(g, np.ones(jm.nj, bool), closed)
        assert set(cracked.tolist()) == first_round
    with pytest.raises(InputError, match="crack_band"):
        ContactSettings(crack_band=1.0)
    pushed = replace(sc, pushover=Pushover(rate_g_per_s=0.01, max_g=1.0))
    assert CrackTracker.default_settings(pushed).crack_band == 0.0
    assert ContactSettings().crack_band == 0.1  # a ground motion's


@pytest.mark.parametrize("load", [2.0, 3.0])
def test_a_block_let_go_changes_nothing_for_the_rest(load):
    # a column with one more block on top whose joint Bullet has let go (cracked, no corner in the
    # model): that block floats on its weak spring, a kilometre away in the model, and must not
    # make the rest's solve look like a mechanism; the rest cracks as the column without it does
    ref = _column(3, material=WEAK_MORTAR)
    g, _ = _past_first_crack(ref, load)
    expect, expect_modes, _ = JointModel(ref).crack(
        g, np.ones(3, bool), np.ones((3, OUTLINE_POINTS), bool), runaway_m=1e-3
    )
    sc = _column(4, material=WEAK_MORTAR)
    closed = np.ones((4, OUTLINE_POINTS), bool)
    closed[3] = False
    cracked, modes, _ = JointModel(sc).crack(g, np.array([True, True, True, False]), closed, runaway_m=1e-3)
    assert list(cracked) == list(expect)
    assert list(modes) == list(expect_modes)


def test_a_let_go_block_starts_where_its_weak_spring_holds_it():
    # the let-go block is held by its weak spring alone: its equilibrium is the load over eps m (a
    # rigid translation, g / eps); the solve starts it there, so it costs no Newton steps more than
    # the column without it (it used to take a dozen capped steps to float a kilometre away)
    g = np.array([0.3 * G, 0.0, -G])
    intact = np.array([True, True, False])
    ref = JointModel(_column(3, material=WEAK_MORTAR))
    ref.solve(g, intact)
    model = JointModel(_column(4, material=WEAK_MORTAR))
    closed = np.ones((4, OUTLINE_POINTS), bool)
    closed[3] = False
    state, _ = model.solve(g, np.append(intact, False), closed)
    assert model.converged and ref.converged
    assert model.newton_iterations == ref.newton_iterations
    U = model._last[2].reshape(-1, 6)
    assert U[3, :3] == pytest.approx(g / model.settings.eps_per_s2, rel=1e-12)
    assert U[3, 3:] == pytest.approx(np.zeros(3), abs=1e-12)
    assert model._free_bodies(np.zeros(4, bool), np.array([0, 1], dtype=np.int64)).tolist() == [
        False,
        False,
        True,
        True,
    ]


def test_pose_quaternions_give_back_the_matrices():
    from scipy.spatial.transform import Rotation

    rng = np.random.default_rng(3)
    R = Rotation.random(200, random_state=rng).as_matrix()
    q = quaternions_from_matrices(R)
    ref = Rotation.from_matrix(R).as_quat()[:, [3, 0, 1, 2]]
    ref *= np.where(ref[:, :1] < 0, -1.0, 1.0)
    assert q == pytest.approx(ref, abs=1e-12)
    assert rotations(q) == pytest.approx(R, abs=1e-12)


def test_a_block_standing_on_the_plate_bears_on_it():
    # no foundation joint: the plate's contact holds the column up, so its joint carries the top
    sc = _column(2)
    sc = Scene(bodies=sc.bodies, bonds=sc.bonds[1:], material=sc.material)
    st, _ = JointModel(sc).solve(np.array([0.0, 0.0, -G]), np.ones(1, bool))
    assert abs(st.forces[0, 2]) == pytest.approx(sc.bodies[1].mass * G, rel=1e-6)


def _dry_block(size, direction, mu):
    """One block ``size`` (l_x, l_y, h) on a dry footing joint of friction ``mu``, and the lateral
    load factor along ``direction`` (d_x, d_y) at which it tips (its resultant at the footing's edge)."""
    lx, ly, h = size
    dry = Material(tensile_strength=0.0, shear_strength=0.0, friction=mu)
    sc = Scene(
        bodies=(_block("b", size, (0, 0, h / 2)),),
        bonds=(Bond.rectangle(0, -1, (0, 0, 0), DOWN, X, lx, ly),),
        material=dry,
    )
    dx, dy = direction
    return sc, min(lx / (h * abs(dx)) if dx else np.inf, ly / (h * abs(dy)) if dy else np.inf)


@pytest.mark.parametrize(
    "size, direction", [((0.2, 0.3, 0.8), (1.0, 0.0)), ((0.3, 0.2, 1.0), (0.6, 0.8)), ((0.9, 0.6, 0.3), (0.6, 0.8))]
)
def test_a_block_on_a_cracked_joint_tips_or_slides_where_statics_says(size, direction):
    # one block on a dry footing (no tension, no cohesion, friction 0.5), the sideways load ramped
    # in 0.005 g steps: the model keeps an equilibrium up to the smaller of mu (sliding) and the
    # load at which the resultant leaves the footing (tipping: lam h / 2 |d_x| = l_x / 2 or
    # lam h / 2 |d_y| = l_y / 2), and runs away (motion over 1 mm) at the next step; the slender
    # blocks tip, the squat one slides
    mu = 0.5
    sc, tips = _dry_block(size, direction, mu)
    jm = JointModel(sc)
    dx, dy = direction
    expected = min(mu, tips)
    intact = np.ones(1, bool)
    onset = None
    for lam in np.arange(0.005, 1.5, 0.005):
        new, _, _ = jm.crack(np.array([lam * G * dx, lam * G * dy, -G]), intact)
        intact[new] = False
        if jm.corner_motion().max() > 1e-3:
            onset = lam
            break
    assert onset is not None
    assert onset == pytest.approx(expected, abs=0.0101)


@pytest.mark.parametrize("ratio", [0.3, 0.5, 0.7])
def test_a_sticking_contact_does_not_creep_from_one_load_step_to_the_next(ratio):
    # a squat block on a dry footing (tips at 3 g, slides at mu = 0.6) under a steady sideways load
    # below Coulomb's limit, solved and committed 300 times (300 load steps of the same load): each
    # corner sticks, so the block stays where the first solve put it (within the law's rounding,
    # the last 5 % below the limit, a corner slides a little at each step). The friction law before
    # 2026-11-28 carried less than the elastic trial force at any load, and every commit turned the
    # difference into slip: the block crept at every load step (its displacement after the 300
    # steps 14, 40 and 84 times the first at 0.3, 0.5 and 0.7 of the limit), so a pushover's
    # capacity fell with its number of load steps
    mu = 0.6
    size = (1.0, 0.6, 0.3)
    dry = Material(tensile_strength=0.0, shear_strength=0.0, friction=mu)
    sc = Scene(
        bodies=(_block("b", size, (0, 0, size[2] / 2)),),
        bonds=(Bond.rectangle(0, -1, (0, 0, 0), DOWN, X, size[0], size[1]),),
        material=dry,
    )
    jm = JointModel(sc)
    g = np.array([ratio * mu * G, 0.0, -G])
    intact = np.zeros(1, bool)
    jm.solve(g, intact)
    jm.commit()
    first = jm.motion[0]
    assert jm.converged and first > 0
    for _ in range(300):
        jm.solve(g, intact)
        jm.commit()
    assert jm.converged
    assert jm.motion[0] == pytest.approx(first, rel=1e-6, abs=1e-12)


def test_the_contact_laws_tangent_is_its_derivative():
    # the contact corners' forces and the tangent Newton's method uses, against central finite
    # differences, over sticking, sliding, in-between and open corners
    rng = np.random.default_rng(7)
    sc = _column(1, material=Material(tensile_strength=0.0, shear_strength=0.0, friction=0.6))
    jm = JointModel(sc)
    n = 2000
    jc = np.zeros(n, dtype=np.int64)
    kc = rng.choice(np.flatnonzero(jm.corner_mask[0]), n)  # (outlines are padded by repeats)
    jm.slip[0] = rng.normal(0.0, 2e-7, jm.slip[0].shape)
    k = jm._corner_k[jc, kc]
    # normal gaps from open to pressed, shear trials from 0 to 3x Coulomb's limit
    dn = rng.uniform(-2e-6, 5e-10, n)
    gap = np.column_stack([rng.normal(0.0, 1.0, (n, 2)) * (-dn * k[:, 2] * 0.6 / k[:, 0])[:, None], dn])
    gap[:, :2] += jm.slip[jc, kc]
    F, T = jm._contact_forces(jc, kc, gap)
    limit = 0.6 * -F[:, 2]
    assert np.all(np.hypot(F[:, 0], F[:, 1]) <= limit * (1 + 1e-12) + 1e-300)
    for j in range(3):
        h = 1e-13
        up, down = gap.copy(), gap.copy()
        up[:, j] += h
        down[:, j] -= h
        fd = (jm._contact_forces(jc, kc, up)[0] - jm._contact_forces(jc, kc, down)[0]) / (2 * h)
        scale = np.abs(T).max(axis=(1, 2))
        # the law's slope is continuous, its curvature jumps at the band's edges: a central
        # difference there errs by about h / band
        bad = np.abs(fd - T[:, :, j]).max(axis=1) > 1e-5 * scale
        assert bad.mean() < 0.01


@pytest.mark.parametrize("load", [1.5, 3.0])
def test_nothing_cracks_from_a_run_away(load):
    # a column loaded past the lateral load at which its cracked base lets it rock: the base cracks
    # from an equilibrium, the solve on what is left runs away (a mechanism), and nothing else cracks
    # in that load; the state returned is the last equilibrium's, not the run-away iterate's (its
    # forces are set by where the iteration stopped)
    sc = _column(4, material=WEAK_MORTAR)
    g, worst = _past_first_crack(sc, load)
    jm = JointModel(sc)
    closed = np.ones((jm.nj, OUTLINE_POINTS), bool)
    cracked, _, state = jm.crack(g, np.ones(jm.nj, bool), closed, runaway_m=1e-3)
    assert list(cracked) == [worst]
    moved = jm.corner_motion()
    assert moved[worst] > 1e-3  # the base has run away
    assert not np.array_equal(jm.state(jm._U).utilisation, state.utilisation)
    first, _ = JointModel(sc).solve(g, np.ones(jm.nj, bool))
    assert np.array_equal(state.utilisation, first.utilisation)


def test_the_fixed_pattern_cholesky_solve_is_exact_for_any_subset_of_blocks():
    from calib_masonry.simulation.joints import _scatter, _Tangent

    rng = np.random.default_rng(3)
    nb, nj = 40, 90
    a = rng.integers(0, nb, nj)
    b = (a + rng.integers(1, nb, nj)) % nb  # another body
    b[:10] = a[:10]  # foundation joints: b's half at a's place, and zero (as JointModel lays them out)
    dofs = np.concatenate([6 * a[:, None] + np.arange(6), 6 * b[:, None] + np.arange(6)], axis=1)
    n = 6 * nb
    tan = _Tangent(dofs, n)
    G = rng.normal(size=(nj, 12, 12))
    G[:10, 6:] = 0.0
    blocks = G @ np.transpose(G, (0, 2, 1))  # positive semi-definite blocks
    diag = rng.uniform(0.5, 1.0, n)
    rhs = rng.normal(size=n)
    for joints in (np.arange(nj), rng.choice(nj, 25, replace=False), np.array([3, 3, 7, 11, 11, 11, 2])):
        values = tan.values(joints, blocks[joints][:, tan.ROW, tan.COL], diag)
        x = tan.solve(values, rhs)
        A = (_scatter(dofs[joints], blocks[joints], n) + sp.diags(diag)).tocsc()  # the same matrix, summed by scipy
        assert np.linalg.norm(A @ x - rhs) <= 1e-10 * np.linalg.norm(rhs)
        np.testing.assert_array_equal(x, _Tangent(dofs, n).solve(values, rhs))  # a new analysis changes no bit
    with pytest.raises(ArithmeticError):
        tan.solve(tan.values(np.arange(nj), blocks[:, tan.ROW, tan.COL], diag - 1e3), rhs)


def test_a_stop_ends_the_contact_iteration(monkeypatch):
    # SIGTERM sets the process's stop flag; one check of a large tower's crack rounds can take
    # minutes on the joint model's thread, and the run waits for that thread before it leaves
    import threading

    from calib_masonry import process
    from calib_masonry.errors import Terminated

    sc = _column(2)
    intact = np.array([False, True])  # the foundation joint cracked: its contact is iterated
    monkeypatch.setattr(process, "_STOP", threading.Event())
    JointModel(sc).solve(np.array([0.0, 0.0, -G]), intact)
    process.request_stop()
    with pytest.raises(Terminated):
        JointModel(sc).solve(np.array([0.0, 0.0, -G]), intact)


def test_a_per_body_tolerance_balances_a_light_stone_under_a_heavy_beam():
    # a shear test's loading beam weighs tens to hundreds of stones: an out-of-balance force of a
    # thousandth of its load is a third of a stone's weight. With ``tol_per_body`` every body is
    # balanced to a thousandth of its own load (its moments times its size), which the check here
    # recomputes from the solve's motion and contact forces

    mu = 0.6
    dry = Material(tensile_strength=0.0, shear_strength=0.0, friction=mu)
    stone = _block("stone", (0.2, 0.2, 0.1), (0, 0, 0.05))
    beam = _block("beam", (0.2, 0.2, 0.2), (0, 0, 0.2), density=1800.0 * 200)
    sc = Scene(
        bodies=(stone, beam),
        bonds=(
            Bond.rectangle(0, -1, (0, 0, 0), DOWN, X, 0.2, 0.2),
            Bond.rectangle(0, 1, (0, 0, 0.1), UP, X, 0.2, 0.2),
        ),
        material=dry,
    )
    g = np.array([0.3 * mu * G, 0.0, -G])
    intact = np.zeros(2, bool)
    for per_body in (False, True):
        jm = JointModel(sc, settings=ContactSettings(tol_per_body=per_body))
        jm.solve(g, intact)
        jc, kc, U = jm._last
        K0 = jm._joint_matrix(jm._pad(intact))
        rhs = jm._load(g)
        r, _ = jm._residual(K0, jm._corner_operator(jc, kc), jc, kc, U, rhs)
        r = np.abs(r.reshape(2, 6))
        own = np.abs(rhs.reshape(2, 6)[:, :3]).max(axis=1)
        assert jm.converged
        assert r[1, :3].max() <= 1e-3 * own[1]  # the beam, either way
        limit = np.broadcast_to(jm._tolerance(rhs), (12,)).reshape(2, 6)
        # the stone's limit: a thousandth of the beam's load (a fifth of its own weight here), or of its own
        assert limit[0, 0] == pytest.approx(1e-3 * (own[0] if per_body else own[1]))
        if per_body:
            assert r[0, :3].max() <= 1e-3 * own[0]
            assert r[0, 3:].max() <= 1e-3 * own[0] * jm._size[0]


@pytest.mark.parametrize("lateral", [0.59, 0.62])
def test_a_let_go_block_does_not_change_how_far_a_step_may_move_the_others(lateral):
    # a Newton step may move nothing further than step_m or three times the motion so far; a let-go
    # block floats a kilometre away (g / eps) and once counted in "the motion so far" it lifted the
    # cap for every held body: a shear test whose sliver had just been let go then diverged to
    # 1e11 N and let its whole wall go. With it counted out, the held blocks' iteration is the same,
    # step for step, with or without the floating block, below (0.59 g) and past (0.62 g: 142
    # capped steps; 4 uncapped ones before) the top joint's sliding limit mu = 0.6
    g = np.array([lateral * G, 0.0, -G])
    intact = np.array([True, False, False])
    settings = ContactSettings(max_iter=400, stall_iter=400)
    ref = JointModel(_column(3, material=WEAK_MORTAR), settings=settings)
    ref.solve(g, intact)
    model = JointModel(_column(4, material=WEAK_MORTAR), settings=settings)
    closed = np.ones((4, OUTLINE_POINTS), bool)
    closed[3] = False
    model.solve(g, np.append(intact, False), closed)
    assert model.converged and ref.converged
    assert model.newton_iterations == ref.newton_iterations
    U = model._last[2].reshape(-1, 6)
    assert U[:3] == pytest.approx(ref._last[2].reshape(-1, 6), rel=1e-12, abs=1e-15)
    assert U[3, :3] == pytest.approx(g / settings.eps_per_s2, rel=1e-12)


def _contact_forces_in_numpy(k, s, gap, mu, d, h, cap=None):
    """The contact law as numpy wrote it until 2026-12-07 (JointModel._contact_forces), the
    compiled kernel's oracle."""

    def _smooth_cap(x, h):
        lo = 1.0 - h
        xc = np.clip(x, lo, 1.0 + h)
        f = np.where(x <= lo, x, xc - (xc - lo) ** 2 / (4.0 * h))
        df = np.where(x <= lo, 1.0, 1.0 - (xc - lo) / (2.0 * h))
        return f, df

    def _crushed(N, dN, cap, h):
        f, df = _smooth_cap(N / cap, h)
        return cap * f, dN * df

    x = -gap[:, 2] / d
    N = k[:, 2] * d * np.logaddexp(0.0, x)
    dN = -k[:, 2] * 0.5 * (1.0 + np.tanh(0.5 * x))  # dN / d d_n
    if cap is not None:
        N, dN = _crushed(N, dN, cap, h)
    trial = k[:, :2] * (gap[:, :2] - s)
    L = mu * N
    a = np.sqrt((trial**2).sum(axis=1))  # |T*|
    live = (a > 0.0) | (L > 0.0)  # else the corner is open and unloaded: no force, no stiffness
    # the shear force's size L f(a / L): f(x) = x (sticking, T = T* exactly) up to 1 - h, 1
    # (sliding at Coulomb's limit) from 1 + h, a parabola between (continuous slope)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        xr = np.where(L > 0.0, a / np.where(L > 0.0, L, 1.0), np.inf)
    lo = 1.0 - h
    f, df = _smooth_cap(xr, h)
    # f(x) / x: 1 while sticking (and at a = 0)
    ratio = np.where(xr <= lo, 1.0, L * f / np.where(a > 0.0, a, 1.0))
    ratio = np.where(live, ratio, 0.0)
    e = np.where(a[:, None] > 0.0, trial / np.where(a > 0.0, a, 1.0)[:, None], 0.0)  # unit T*
    F = np.empty_like(gap)
    F[:, :2] = ratio[:, None] * trial
    F[:, 2] = -N
    T = np.zeros((len(gap), 3, 3))
    ee = e[:, :, None] * e[:, None, :]
    T[:, :2, :2] = (ratio[:, None, None] * (np.eye(2) - ee) + np.where(live, df, 0.0)[:, None, None] * ee) * k[
        :, None, :2
    ]
    # through L = mu N: d(L f(a / L)) / dL = f - x f' (0 while sticking)
    dl = np.where(live, f - np.where(df > 0.0, xr, 0.0) * df, 0.0)
    T[:, :2, 2] = e * (dl * mu * dN)[:, None]
    T[:, 2, 2] = -dN
    return F, T


def test_the_compiled_contact_law_gives_numpys_values_bit_for_bit():
    # the contact law runs compiled corner by corner (simulation/_joint_kernels.py) for speed
    # only: the cascades follow the last digits, so every force and tangent must be numpy's. Open,
    # touching, sticking, sliding and crushed corners, and corners on the smoothing's kinks
    from calib_masonry.simulation._joint_kernels import contact_forces

    rng = np.random.default_rng(11)
    d, h, mu = 1e-10, 0.05, 0.6
    for C in (1, 5, 300, 4000):
        k = rng.lognormal(20.0, 1.0, size=(C, 3))
        gap = rng.normal(scale=1e-5, size=(C, 3)) * rng.choice([0.0, 1e-6, 1.0], size=(C, 3))
        gap[: C // 3, 2] = rng.normal(scale=3e-10, size=C // 3)  # within the no-tension kink
        s = rng.normal(scale=1e-5, size=(C, 2)) * rng.choice([0.0, 1.0], size=(C, 1))
        s[C // 2 :] = gap[C // 2 :, :2]  # no shear displacement: the corner unloaded in shear
        for cap in (None, rng.lognormal(8.0, 2.0, size=C)):
            want = _contact_forces_in_numpy(k, s, gap, mu, d, h, cap)
            th = np.tanh(0.5 * (-gap[:, 2] / d))
            got = contact_forces(k, s, gap, th, mu, d, h, np.zeros(0) if cap is None else cap)
            for w, g in zip(want, got):
                np.testing.assert_array_equal(g, w)


def test_the_compiled_sum_of_the_blocks_gives_bincounts_values_bit_for_bit():
    # the tangent's values are its joints' blocks summed into their places (simulation/_joint_kernels.py,
    # for speed only): the same bits as numpy's bincount, which adds them in the same order
    from calib_masonry.simulation._joint_kernels import summed_blocks

    rng = np.random.default_rng(3)
    for J, nnz, M in ((1, 5, 1), (40, 300, 0), (40, 300, 200), (900, 20000, 5000)):
        slot = rng.integers(0, nnz, size=(J, 78))
        joints = rng.integers(0, J, size=M)  # joints may repeat
        blocks = rng.normal(size=(M, 78)) * rng.lognormal(0.0, 8.0, size=(M, 1))
        want = np.bincount(slot[joints].ravel(), weights=blocks.ravel(), minlength=nnz).astype(np.float64)
        np.testing.assert_array_equal(summed_blocks(slot, joints, blocks, nnz), want)


def test_the_kept_outline_constants_and_the_corner_blocks_change_no_bit():
    """The joint model keeps each outline's edges and farthest corner instead of computing them at
    every state, and sums the contact corners' blocks itself instead of through ``einsum``: both
    for speed only (the paper example's cascade follows the last digits), so both must give the
    values before bit for bit."""
    from calib_masonry.simulation.joints import _corner_blocks, _Tangent

    rng = np.random.default_rng(5)
    for C in (1, 2, 7, 40, 333, 2500):
        Lc = rng.normal(size=(C + 3, 3, 12))[rng.integers(0, C + 3, C)] * rng.lognormal(size=(C, 1, 1))
        TL = rng.normal(size=(C, 3, 3)) @ Lc
        expected = np.einsum("cap,cap->cp", Lc[:, :, _Tangent.ROW], TL[:, :, _Tangent.COL])
        np.testing.assert_array_equal(_corner_blocks(Lc, TL), expected)

    sc = _column(3)
    m = JointModel(sc)
    U = rng.normal(size=6 * m.nb) * 1e-5
    rel = np.einsum("jab,jb->ja", m.L[: m.nj], U[m.dofs[: m.nj]])
    state = m.state_from_relative(rel)
    for joints in (None, np.array([1]), np.array([2, 0])):
        sel = slice(None) if joints is None else joints
        part = m.state_from_relative(rel[sel], joints)
        np.testing.assert_array_equal(part.utilisation, state.utilisation[sel])
        np.testing.assert_array_equal(part.mode, state.mode[sel])
    # the kept constants are the formulas the state computed at every call before
    outline = m.outline[: m.nj]
    np.testing.assert_array_equal(m._farthest(), np.sqrt((outline**2).sum(axis=2)).max(axis=1))
    edge, real = m._outline_edges()
    np.testing.assert_array_equal(edge, np.roll(outline, -1, axis=1) - outline)
    np.testing.assert_array_equal(real, np.linalg.norm(edge, axis=2) > 1e-12)
    assert real.any(axis=1).all() and not real.all()  # the padding's repeats are not edges


@pytest.mark.parametrize(
    "size, direction", [((0.2, 0.3, 0.8), (1.0, 0.0)), ((0.3, 0.2, 1.0), (0.6, 0.8)), ((0.9, 0.6, 0.3), (0.6, 0.8))]
)
def test_the_static_programme_finds_an_equilibrium_up_to_tipping_or_sliding(size, direction):
    # one block on a cracked (dry) footing joint: its corners bear any compression with friction
    # inside the square inscribed in Coulomb's cone (|t_u| + |t_v| <= mu N: mu / (|d_u| + |d_v|)
    # along d, mu along an axis); the load has an equilibrium below the smaller of that and
    # tipping (lam h / 2 |d| = l / 2), none above the smaller of mu and tipping
    mu = 0.5
    sc, tips = _dry_block(size, direction, mu)
    jm = JointModel(sc)
    dx, dy = direction
    jc, kc = np.nonzero(jm.corner_mask)
    intact = np.zeros(1, bool)
    free = np.zeros(1, bool)

    def stands(lam):
        return jm.has_equilibrium(intact, jc, kc, jm._load(np.array([lam * G * dx, lam * G * dy, -G])), free)

    assert stands(0.0)
    assert stands(0.99 * min(mu / (abs(dx) + abs(dy)), tips))
    assert not stands(1.01 * min(mu, tips))
    # friction held to a fixed capacity as well: none, and only the weight stands
    zero = np.zeros(jc.size)
    assert jm.has_equilibrium(intact, jc, kc, jm._load(np.array([0.0, 0.0, -G])), free, shear_capacity=zero)
    assert not jm.has_equilibrium(
        intact, jc, kc, jm._load(np.array([0.01 * G * dx, 0.01 * G * dy, -G])), free, shear_capacity=zero
    )
    # an intact dry joint bears as the contact does; with a strong mortar it carries far more
    lam = 1.01 * min(mu, tips)
    assert not jm.has_equilibrium(
        np.ones(1, bool), jc[:0], kc[:0], jm._load(np.array([lam * dx, lam * dy, -1]) * G), free
    )
    wet = JointModel(replace(sc, material=Material(tensile_strength=1e6, shear_strength=1.5e6, friction=mu)))
    assert wet.has_equilibrium(np.ones(1, bool), jc[:0], kc[:0], wet._load(np.array([5 * dx, 5 * dy, -1]) * G), free)


def test_a_dry_toe_crushes_at_the_masonrys_strength_and_the_block_tips_sooner():
    # a block 1.0 x 0.2 x 0.5 m on a dry footing of twenty 5 cm patches, pushed along x (friction
    # high enough not to slide): with the masonry's crushing strength f_c each corner bears at most
    # f_c over its share of its patch, so the toe's compression spreads inward and the block tips
    # where its weight's moment about that stress block's resultant is spent: the corners nearest
    # the toe at f_c until they carry W, computed here. That is within 3 % of the rectangular block
    # of EN 1998-3's flexural capacity, lambda = (L - W / (f_c t)) / h; without f_c, L / h
    L, t, h, fc = 1.0, 0.2, 0.5, 0.025e6
    mat = Material(tensile_strength=0.0, shear_strength=0.0, friction=3.0, masonry_compressive_strength=fc)
    body = _block("b", (L, t, h), (0, 0, h / 2), density=2000.0)
    xs = np.linspace(-L / 2 + 0.025, L / 2 - 0.025, 20)
    bonds = tuple(Bond.rectangle(0, -1, (x, 0, 0), DOWN, X, 0.05, t) for x in xs)
    w = body.mass * G
    # the corners' lines from the toe (x = L / 2) inward, each at f_c over its share, until W
    lines = np.sort(np.concatenate([xs - 0.025, xs + 0.025]))[::-1]
    cap = fc * 0.05 * t / 4 * 2  # a patch's two corners on a line
    need, moment = w, 0.0
    for x in lines:
        f = min(cap, need)
        moment, need = moment + f * x, need - f
        if need <= 0:
            break
    tips = moment / w / (h / 2)
    assert tips == pytest.approx((L - w / (fc * t)) / h, rel=0.03)
    assert tips < 0.8 * L / h  # the crushing matters here

    for strength, at in ((fc, tips), (0.0, L / h)):
        jm = JointModel(
            Scene(bodies=(body,), bonds=bonds, material=replace(mat, masonry_compressive_strength=strength))
        )
        jc, kc = np.nonzero(jm.corner_mask)
        nothing, free = np.zeros(len(bonds), bool), np.zeros(1, bool)
        for lam, stands in ((0.97 * at, True), (1.03 * at, False)):
            g = np.array([lam * G, 0.0, -G])
            # the static programme, and the contact iteration on the same corners
            assert jm.has_equilibrium(nothing, jc, kc, jm._load(g), free) == stands
            jm.solve(g, nothing)
            moved = float(np.abs(jm.motion[:3]).max())  # a mechanism runs away, held by the weak springs
            assert (moved < 1e-3) == stands, (strength, lam, moved)


def test_the_static_programme_answers_each_question_as_if_asked_first():
    # the programme is kept between questions (HiGHS starts from its last answer); a dry column of
    # three blocks tips as a whole at lam = b / h = 0.444: loads up and down across it, friction
    # capacities that change, and a change of the intact joints between, each answered as a model
    # asked nothing before answers it
    dry = Material(tensile_strength=0.0, shear_strength=0.0, friction=0.6)
    sc = _column(3, material=dry)
    jc, kc = np.nonzero(JointModel(sc).corner_mask)
    free = np.zeros(3, bool)
    questions = []
    for lam in (0.2, 0.5, 0.3, 0.6, 0.99 * 0.4 / 0.9, 1.01 * 0.4 / 0.9, 0.1):
        questions.append((np.zeros(3, bool), lam, None))
    # a corner's friction capacity, in shares of the footing's shear W / n: half of what 0.1 W needs
    # (no equilibrium), then twice what 0.3 W needs
    share = 3 * 1800 * 0.024 * G / int(JointModel(sc).corner_mask[0].sum())
    for lam, c in ((0.1, 0.05 * share), (0.1, 0.6 * share), (0.3, 0.6 * share), (0.05, 0.02 * share)):
        questions.append((np.zeros(3, bool), lam, c))
    questions.append((np.array([False, True, True]), 0.3, None))
    questions.append((np.zeros(3, bool), 0.3, None))
    kept = JointModel(sc)
    answers, models = [], set()
    for intact, lam, c in questions:
        load = kept._load(np.array([lam * G, 0.0, -G]))
        pick = ~intact[jc]
        caps = None if c is None else np.full(int(pick.sum()), c)
        got = kept.has_equilibrium(intact, jc[pick], kc[pick], load, free, shear_capacity=caps)
        fresh = JointModel(sc).has_equilibrium(intact, jc[pick], kc[pick], load, free, shear_capacity=caps)
        assert got == fresh, (intact, lam, c)
        answers.append(got)
        models.add(id(kept._programme[2]["cone" if c is None else "capped"]))
    assert answers == [True, False, True, False, True, False, True] + [False, True, True, False] + [True, True]
    # two HiGHS models answered them all, one with friction capped and one with the cone alone,
    # the change of the intact joints included (the matrix holds every corner: each question
    # starts from the last basis of its kind)
    assert len(models) == 2


def _block_on_a_dry_footing() -> Scene:
    """A 0.4 x 0.3 x 0.6 m block on a dry footing (friction 0.6), its one joint a rectangle."""
    dry = Material(tensile_strength=0.0, shear_strength=0.0, friction=0.6)
    return Scene(
        bodies=(_block("b", (0.4, 0.3, 0.6), (0, 0, 0.3)),),
        bonds=(Bond.rectangle(0, -1, (0, 0, 0), DOWN, X, 0.4, 0.3),),
        material=dry,
    )


def test_a_stalled_solve_with_an_equilibrium_ends_at_its_least_out_of_balance_iterate():
    # a block on a dry footing under a load it can carry, solved with an iteration cut short (two
    # steps, no convergence): with the check it ends at its best iterate and counts the stall;
    # without, where it stopped
    sc = _block_on_a_dry_footing()
    g = np.array([0.3 * G, 0.0, -G])
    for check in (True, False):
        jm = JointModel(sc, settings=ContactSettings(max_iter=2, check_equilibrium=check))
        jm.solve(g, np.zeros(1, bool))
        assert not jm.converged
        assert jm.unconverged_solves == 1
        assert jm.stalled_in_equilibrium == (1 if check else 0)
    # beyond sliding there is no equilibrium: the stall is not excused
    jm = JointModel(sc, settings=ContactSettings(max_iter=2, check_equilibrium=True))
    jm.solve(np.array([0.8 * G, 0.0, -G]), np.zeros(1, bool))
    assert jm.stalled_in_equilibrium == 0


def test_a_load_without_equilibrium_is_a_mechanism_even_where_the_capped_question_went_unanswered(monkeypatch):
    # a block on a dry footing beyond sliding, solved with an iteration cut short: the capped
    # question (friction within mu N of the iterate) and the cone's both say no, a mechanism. Where
    # no solver answered the capped question, the cone's definite no still is one (the count of
    # unanswered questions taken before the first question hid it); an unanswered cone's is not
    sc = _block_on_a_dry_footing()
    g = np.array([0.8 * G, 0.0, -G])
    real = JointModel.has_equilibrium

    def solve(unanswered_when):
        def ask(self, *args, **kwargs):
            capped = len(args) > 5 or kwargs.get("shear_capacity") is not None
            if unanswered_when(capped):
                self.unanswered += 1
                return False
            return real(self, *args, **kwargs)

        with monkeypatch.context() as m:
            m.setattr(JointModel, "has_equilibrium", ask)
            jm = JointModel(sc, settings=ContactSettings(max_iter=2, check_equilibrium=True))
            jm.solve(g, np.zeros(1, bool))
        assert not jm.converged
        return jm.no_equilibrium, jm.without_equilibrium, jm.unanswered

    assert solve(lambda capped: False) == (True, 1, 0)
    assert solve(lambda capped: capped) == (True, 1, 1)
    assert solve(lambda capped: not capped) == (False, 0, 1)


def test_a_question_the_dual_simplex_leaves_open_is_answered_by_the_interior_point_or_the_primal(monkeypatch):
    # the dual simplex from the last basis can run without end on these programmes (a laboratory
    # wall's shear test sat in one question for 20 minutes): it gets a number of iterations, then
    # the interior-point solver answers from scratch, then the primal simplex; a question none
    # answers is taken for no and counted
    from calib_masonry.simulation import joints

    sc, _ = _dry_block((0.2, 0.3, 0.8), (1.0, 0.0), 0.5)

    def answers():
        jm = JointModel(sc)
        jc, kc = np.nonzero(jm.corner_mask)
        free = np.zeros(1, bool)
        got = [
            jm.has_equilibrium(np.zeros(1, bool), jc, kc, jm._load(np.array([lam * G, 0.0, -G])), free)
            for lam in (0.2, 0.3, 0.1)
        ]
        return got, jm.unanswered

    assert answers() == ([True, False, True], 0)  # sliding at mu = 0.5, tipping at 0.25
    monkeypatch.setattr(joints, "DUAL_ITERATIONS", 0)  # the interior point answers
    assert answers() == ([True, False, True], 0)
    monkeypatch.setattr(joints, "IPM_ITERATIONS", 0)  # the primal simplex
    assert answers() == ([True, False, True], 0)
    monkeypatch.setattr(joints, "PRIMAL_ITERATIONS_PER_ROW_AND_COLUMN", 0)
    got, unanswered = answers()
    assert unanswered >= 2 and not any(got[1:])


def test_every_question_on_a_kept_programme_gets_its_own_seconds(monkeypatch):
    # HiGHS's time limit counts the model's run time over every question asked of it: with the
    # limit set once, a kept programme that had run SOLVER_SECONDS in all answered nothing more
    from calib_masonry.simulation import joints

    monkeypatch.setattr(joints, "SOLVER_SECONDS", 0.003)
    sc, _ = _dry_block((0.2, 0.3, 0.8), (1.0, 0.0), 0.5)
    jm = JointModel(sc)
    jc, kc = np.nonzero(jm.corner_mask)
    free = np.zeros(1, bool)
    got = []
    for _ in range(300):
        for lam in (0.2, 0.3):
            got.append(jm.has_equilibrium(np.zeros(1, bool), jc, kc, jm._load(np.array([lam * G, 0.0, -G])), free))
    assert jm.unanswered == 0
    assert got == [True, False] * 300
    assert jm._programme[2]["cone"].getRunTime() > 2 * joints.SOLVER_SECONDS  # the questions together


def test_the_question_a_dry_walls_shear_test_stuck_in_is_answered(tmp_path):
    # the static programme of SW.30.2's shear test (58 stones; 1,748 rows, 7,000 columns) at 51.56 s
    # of its ramp, written by HiGHS as it was asked: its dual simplex slows down after about 3,500
    # iterations (highspy 1.15.1: 10,000 in 46 s, then a solve error; 1.16.0: 4,374 in more than
    # 30 s), and without a limit sat there for minutes; infeasible (the interior-point and the
    # primal simplex solvers agree)
    import lzma

    import highspy

    from calib_masonry.simulation.joints import _feasible

    mps = tmp_path / "question.mps"
    mps.write_bytes(lzma.decompress((Path(__file__).parent / "data" / "shear_test_question.mps.xz").read_bytes()))
    h = highspy.Highs()
    h.setOptionValue("output_flag", False)
    h.setOptionValue("threads", 1)
    h.readModel(str(mps))
    assert _feasible(h) is False

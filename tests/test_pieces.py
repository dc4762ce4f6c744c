"""The freed pieces as rigid bodies on their contacts (simulation/pieces.py) against the analytic
motion of a sliding and a tipping block, a piece's momentum, and the integrator's own settings
(no Blender)."""

import math

import numpy as np
import pytest

from calib_masonry.simulation.ground_motion import G, constant_acceleration
from calib_masonry.simulation.pieces import PieceSettings, piece_motion, rigid_velocity
from calib_masonry.simulation.scene import Bond, Material, Scene

from .test_joints import DOWN, UP, X, _block

MU = 0.5
DRY = Material(tensile_strength=0.0, shear_strength=0.0, friction=MU)


def _stack(size, n, motion, material=DRY):
    """``n`` blocks of ``size`` stacked on a footing joint, bonded to each other."""
    lx, ly, h = size
    bodies = tuple(_block(f"b{i}", size, (0, 0, h * (i + 0.5))) for i in range(n))
    bonds = [Bond.rectangle(0, -1, (0, 0, 0), DOWN, X, lx, ly)]
    bonds += [Bond.rectangle(i, i + 1, (0, 0, h * (i + 1)), UP, X, lx, ly) for i in range(n - 1)]
    return Scene(bodies=bodies, bonds=tuple(bonds), material=material, motion=motion)


def _let_go_footing(sc, times, **kw):
    """The footing let go when the ground starts to move, the other joints held."""
    release = np.full(len(sc.bonds), np.nan)
    release[0] = 0.0
    settings = PieceSettings(fallen_m=100.0, **kw)
    return piece_motion(sc, release, times, settings=settings)


@pytest.mark.parametrize("n", [1, 3])
def test_a_piece_slides_as_coulomb_says(n):
    # a squat block (or three bonded) on a let-go footing under a steady 0.7 g: it slides against
    # the ground at (0.7 - mu) g, x = (a - mu g) t^2 / 2, every block of the piece alike
    a = 0.7 * G
    t = np.linspace(0.0, 1.0, 6)
    sc = _stack((0.9, 0.6, 0.3), n, constant_acceleration(a, 1.0))
    pm = _let_go_footing(sc, t)
    x = -pm.displacement_m[:, :, 0].astype(float)  # the ground moves +x: the block lags behind
    expected = (a - MU * G) * t**2 / 2
    assert x[-1] == pytest.approx(np.full(n, expected[-1]), rel=0.03)
    assert np.ptp(x[-1]) < 1e-4  # one rigid piece
    assert pm.pieces == 1


def test_a_piece_below_friction_does_not_slide():
    sc = _stack((0.9, 0.6, 0.3), 1, constant_acceleration(0.45 * G, 1.0))
    pm = _let_go_footing(sc, np.linspace(0.0, 1.0, 3))
    assert np.abs(pm.displacement_m[-1, 0, 0]) < 1e-3  # the contacts' own give: well under a millimetre


@pytest.mark.parametrize("factor, tips", [(0.95, False), (1.05, True)])
def test_a_slender_piece_tips_above_b_over_h(factor, tips):
    # a block of half-width b and half-height h on a let-go footing under a steady lam g: it rocks
    # over its toe once lam > b / h (and friction holds: mu = 0.5 > b / h), not below
    lx, ly, hh = 0.2, 0.3, 0.8
    lam = factor * lx / hh
    sc = _stack((lx, ly, hh), 1, constant_acceleration(lam * G, 1.5))
    pm = _let_go_footing(sc, np.linspace(0.0, 1.5, 4))
    moved = float(np.linalg.norm(pm.displacement_m[-1, 0]))
    assert (moved > 0.05) == tips, moved


def test_the_motion_does_not_depend_on_the_penalty_or_the_step():
    # a block tipping over under a ramped 0.36 g (b / h = 1/3): a fifth of the penalty stiffness,
    # twice the steps or half the contact damping change how far it has gone in 1.5 s (0.7 m) by
    # under 5 % (measured: 2.1 % for the stiffness)
    sc = _stack((0.3, 0.3, 0.9), 1, constant_acceleration(0.36 * G, 1.5, ramp_s=0.3))
    t = np.linspace(0.0, 1.5, 4)
    base = _let_go_footing(sc, t).distance_m()[-1, 0]
    assert base > 0.05
    for kw in ({"settle_fraction": 2e-5}, {"steps_per_period": 40}, {"contact_damping": 0.5}):
        other = _let_go_footing(sc, t, **kw).distance_m()[-1, 0]
        assert other == pytest.approx(base, rel=0.05), kw


def test_a_piece_set_free_with_a_velocity_slides_to_rest_where_friction_stops_it():
    # still ground, the block let go moving at 1 m/s: it stops after v^2 / (2 mu g)
    sc = _stack((0.9, 0.6, 0.3), 1, constant_acceleration(0.0, 1.0))
    release = np.array([0.0])
    v = np.zeros((1, 6))
    v[0, 0] = 1.0
    pm = piece_motion(sc, release, np.array([0.0, 1.0]), velocity={0.0: v}, settings=PieceSettings(fallen_m=100.0))
    assert pm.displacement_m[-1, 0, 0] == pytest.approx(1.0 / (2 * MU * G), rel=0.03)


def test_a_piece_takes_its_bodies_momentum_and_angular_momentum():
    rng = np.random.default_rng(3)
    m = rng.uniform(1, 3, 4)
    x = rng.normal(size=(4, 3))
    inertia = np.array([np.diag(rng.uniform(0.1, 0.5, 3)) for _ in range(4)])
    # bodies moving as one rigid body: v_i = v + w x (x_i - c), spinning at w
    v0, w0 = np.array([0.3, -0.2, 0.1]), np.array([0.5, 1.0, -0.7])
    c = (m[:, None] * x).sum(0) / m.sum()
    vel = np.concatenate([v0 + np.cross(w0, x - c), np.repeat(w0[None], 4, 0)], axis=1)
    v, w, c2, _ = rigid_velocity(m, inertia, x, vel)
    assert v == pytest.approx(v0)
    assert w == pytest.approx(w0)
    assert c2 == pytest.approx(c)


def test_no_piece_without_a_joint_let_go():
    sc = _stack((0.9, 0.6, 0.3), 2, constant_acceleration(0.7 * G, 1.0))
    pm = piece_motion(sc, np.full(2, np.nan), np.linspace(0, 1, 3))
    assert pm.pieces == 0 and pm.steps == 0
    assert not pm.displacement_m.any()
    assert math.isinf(pm.dt_s)


def test_a_heavy_piece_on_a_light_one_does_not_sink_into_it():
    # a block ten times denser on a light one, every joint let go on still ground: two pieces, the
    # light one carrying the heavy one's weight to the plate; both settle under 0.2 mm (the
    # penalty must be as stiff as the heaviest piece needs, on every contact)
    size = (0.4, 0.4, 0.3)
    light = _block("light", size, (0, 0, 0.15))
    heavy = _block("heavy", size, (0, 0, 0.45), density=18000.0)
    bonds = (Bond.rectangle(0, -1, (0, 0, 0), DOWN, X, 0.4, 0.4), Bond.rectangle(0, 1, (0, 0, 0.3), UP, X, 0.4, 0.4))
    sc = Scene(bodies=(light, heavy), bonds=bonds, material=DRY, motion=constant_acceleration(0.0, 1.0))
    pm = piece_motion(sc, np.zeros(2), np.array([0.0, 1.0]))
    assert pm.pieces == 2
    assert np.abs(pm.displacement_m[-1]).max() < 2e-4  # a factor per piece: 1.6 mm


def _rocking(factor, times):
    """A slender block (0.3 x 0.3 x 0.9 m) on a let-go footing, still ground, set rocking about its
    +x toe with ``factor`` times the angular velocity whose kinetic energy just lifts its centroid
    over the toe (I_o w^2 / 2 = m g (R - h / 2)); the verdict's pieces at ``times``."""
    lx, ly, hh = 0.3, 0.3, 0.9
    sc = _stack((lx, ly, hh), 1, constant_acceleration(0.0, float(times[-1])))
    m = sc.bodies[0].mass
    r = np.array([-lx / 2, 0.0, hh / 2])  # from the toe to the centroid
    i_o = m * (lx**2 + hh**2) / 12 + m * (r @ r)
    w_crit = math.sqrt(2 * m * G * (np.linalg.norm(r) - hh / 2) / i_o)
    w = np.array([0.0, factor * w_crit, 0.0])
    v = np.zeros((1, 6))
    v[0, :3] = np.cross(w, r)
    v[0, 3:] = w
    return piece_motion(sc, np.array([0.0]), np.asarray(times, dtype=float), velocity={0.0: v})


@pytest.mark.parametrize("factor, falls", [(0.9, False), (1.1, True)])
def test_the_overturn_bound_is_the_rocking_blocks_own(factor, falls):
    # set rocking just below and just above the energy that lifts the centroid over the toe: the
    # verdict's bound, read at once, says which; the integrated motion agrees (it falls, or rocks
    # back and stays)
    at_once = _rocking(factor, [0.0, 1e-3])
    assert bool(at_once.toppled[0]) == falls
    later = _rocking(factor, np.linspace(0.0, 3.0, 301))
    assert bool(later.fallen[0]) == falls
    assert bool(later.toppled[0]) == falls
    if not falls:
        assert later.distance_m()[-1, 0] < 0.05  # back on its base


def test_the_verdict_does_not_read_where_a_rocking_piece_is():
    # the block set rocking below its overturn energy: read at the top of a swing (moved well past
    # 5 cm) or back on its base (not moved), the verdict is the same: it does not overturn
    t = np.linspace(0.0, 3.0, 301)
    dist = _rocking(0.9, t).distance_m()[:, 0]
    swung = int(np.argmax(dist))
    back = swung + int(np.argmax(dist[swung:] < 0.01))
    assert dist[swung] > 0.05 and dist[back] < 0.01
    for k in (swung, back):
        pm = _rocking(0.9, t[: k + 1])
        assert not pm.toppled[0] and not pm.fallen[0]


def _column(factor, motion, times, settings=None):
    """A squat column (2 x 2 x 8 m: its tipping angle 14 degrees, its top 0.5 m out at 3.6) on a
    let-go footing, set rocking about its +x toe with ``factor`` times the angular velocity whose
    energy lifts its centroid over the toe on still ground; the verdict's pieces at ``times``."""
    lx, hh = 2.0, 8.0
    sc = _stack((lx, lx, hh), 1, motion)
    m = sc.bodies[0].mass
    r = np.array([-lx / 2, 0.0, hh / 2])  # from the toe to the centroid
    i_o = m * (lx**2 + hh**2) / 12 + m * (r @ r)
    w = np.array([0.0, factor * math.sqrt(2 * m * G * (np.linalg.norm(r) - hh / 2) / i_o), 0.0])
    v = np.zeros((1, 6))
    v[0, :3] = np.cross(w, r)
    v[0, 3:] = w
    return piece_motion(sc, np.array([0.0]), np.asarray(times, dtype=float), velocity={0.0: v}, settings=settings)


def _push(start_s, for_s, total_s, a=0.2 * G, dt=0.001):
    """A record that pushes the column back (+x, 0.2 g by default) from ``start_s`` for ``for_s``
    seconds, the ground still otherwise, ``total_s`` long."""
    from calib_masonry.simulation.ground_motion import GroundMotion

    tt = np.arange(int(round(total_s / dt)) + 1) * dt
    acc = np.where((tt >= start_s) & (tt < start_s + for_s), a, 0.0)
    vel = np.concatenate([[0.0], np.cumsum(0.5 * (acc[1:] + acc[:-1]) * dt)])
    x = np.concatenate([[0.0], np.cumsum(0.5 * (vel[1:] + vel[:-1]) * dt)])
    return GroundMotion(dt=dt, displacement=np.column_stack([x, 0 * x]), acceleration=np.column_stack([acc, 0 * acc]))


def test_a_piece_that_swings_past_fallen_m_below_its_overturn_energy_swings_back():
    # on still ground, with 0.9 of the energy that tips it, the column's top swings 0.57 m out
    # (past fallen_m) and back: it has not fallen (a numpy False taken for "not False" once made
    # every piece that had moved fallen_m fall)
    pm = _column(0.9, constant_acceleration(0.0, 4.0), np.linspace(0.0, 4.0, 401))
    d = pm.distance_m()[:, 0]
    assert d.max() > PieceSettings().fallen_m
    assert not pm.fallen[0] and not pm.toppled[0]
    assert d[-1] < 0.2 * d.max()


def test_a_piece_the_ground_pushes_back_has_not_fallen():
    # 1.3 times the energy that tips it on still ground (the bound says it overturns, read at
    # once), but from 0.2 s the ground's inertial force pushes it back (0.2 g for 0.5 s): its top
    # passes fallen_m, with the still-ground bound still saying "overturns", and it comes back.
    # Integrated on without a stop (fallen_m 100 m) it does not overturn either: the stop while
    # the ground moves waits until the piece falls whatever the ground does (_Pieces.falls)
    assert _column(1.3, constant_acceleration(0.0, 3.0), [0.0, 1e-3]).toppled[0]
    pm = _column(1.3, _push(0.2, 0.5, 3.0), np.linspace(0.0, 3.0, 301))
    d = pm.distance_m()[:, 0]
    assert d.max() > PieceSettings().fallen_m
    assert not pm.fallen[0] and not pm.toppled[0]


def test_a_piece_still_rocking_when_the_record_ends_is_played_out_on_still_ground():
    # 1.3 times the energy that tips it, pushed back by the ground for 1 s from 0.2 s, the record
    # ending with the push: the column is then 0.67 m out, swinging back, with more energy than
    # lifts it over an edge (the bound, play_out_s = 0, says it overturns), but its next impact
    # takes enough: integrated on, it never tips. Played out on still ground, it rests
    end = 1.2
    times = np.linspace(0.0, end, 121)
    assert _column(1.3, _push(0.2, 1.0, end), times, PieceSettings(play_out_s=0.0)).toppled[0]
    pm = _column(1.3, _push(0.2, 1.0, end), times)
    assert not pm.toppled[0] and not pm.fallen[0]
    on = _column(1.3, _push(0.2, 1.0, 8.0), np.linspace(0.0, 8.0, 801), PieceSettings(fallen_m=100.0))
    d = on.distance_m()[:, 0]
    assert np.allclose(
        d[: len(times)], pm.distance_m()[:, 0], atol=2e-3
    )  # the same motion up to the end (its steps differ)
    assert d.max() < 0.8 and d[-1] < 0.5  # its top tips at 2 m out (8 tan 14 degrees)
    # and one that falls as it is played out: 1.3 times the tipping energy on still ground
    assert _column(1.3, constant_acceleration(0.0, 1e-3), [0.0, 1e-3]).toppled[0]
    assert not _column(0.9, constant_acceleration(0.0, 1e-3), [0.0, 1e-3]).toppled[0]


def _arm_on_a_column(tensile_strength, motion, arm=(0.1, 0.3, 0.4)):
    """A heavy column (0.4 x 0.3 x 1 m) on a let-go footing, and an arm ``arm`` (x, y, z) bonded to
    its +x face near the top by a head joint whose tensile strength is given (its shear strength
    high: the tension criterion governs)."""
    lx, ly, hz = arm
    mat = Material(tensile_strength=tensile_strength, shear_strength=1e7, friction=0.6, compressive_strength=1e9)
    col = _block("col", (0.4, 0.3, 1.0), (0, 0, 0.5), density=5000.0)
    piece = _block("arm", arm, (0.2 + lx / 2, 0, 1.0 - hz / 2))
    bonds = (
        Bond.rectangle(0, -1, (0, 0, 0), DOWN, X, 0.4, 0.3),
        Bond.rectangle(0, 1, (0.2, 0, 1.0 - hz / 2), X, np.array([0.0, 1.0, 0.0]), ly, hz),
    )
    return Scene(bodies=(col, piece), bonds=bonds, material=mat, motion=motion), piece.mass


@pytest.mark.parametrize("target_g, damping", [(0.1, None), (0.3, None), (0.1, (0.5, 2e-4)), (0.3, (0.5, 2e-4))])
def test_a_piece_cracks_its_own_joint_where_statics_says(target_g, damping):
    # the column and its arm, set free as one piece on the plate, under a ground acceleration
    # towards -x ramped from 0 to 0.4 g over 2 s: the inertial force pulls the arm off the column.
    # The head joint's largest tensile stress is m a / A + 6 m g (l / 2) / (b h^2) (the arm's pull
    # and its weight's moment); with the tensile strength set to that at target_g, the piece's own
    # check cracks the joint at target_g (within 2 %; one check interval of the ramp is 0.001 g), the
    # arm falls and the column stays. The same with the joints vibrating between checks (a Rayleigh
    # damping given): the ramp is slow against the joint's period, so statics still says where
    lx, ly, hz = 0.1, 0.3, 0.4
    m = 1800.0 * lx * ly * hz
    strength = m * target_g * G / (ly * hz) + 6 * m * G * (lx / 2) / (ly * hz**2)
    ramp = 2.0
    motion = constant_acceleration(0.4 * G, ramp, ramp_s=ramp, direction_deg=180.0)
    sc, _ = _arm_on_a_column(strength, motion)
    on = PieceSettings(fallen_m=100.0, check_joints=True)
    pm = piece_motion(sc, np.array([0.0, np.nan]), np.linspace(0, ramp, 5), settings=on, damping=damping)
    assert np.isnan(pm.crack_time_s[0])  # the footing is the joint model's (let go at 0)
    a_crack = 0.4 * pm.crack_time_s[1] / ramp
    assert a_crack == pytest.approx(target_g, rel=0.02)
    # no tension left: it falls (vibrating, once its joint's corners have moved release_m, 1 mm:
    # about sqrt(2 mm / g) = 14 ms and a check interval)
    late = 0.02 if damping is None else 0.05
    assert pm.release_time_s[1] == pytest.approx(pm.crack_time_s[1], abs=late)
    d = pm.distance_m()[-1]
    assert d[1] > 0.5 and d[0] < 1e-3
    assert pm.pieces == 2


@pytest.mark.parametrize("factor, falls", [(0.98, False), (1.02, True)])
def test_an_arm_hangs_from_its_piece_until_its_weight_cracks_it(factor, falls):
    # a 0.3 m arm hanging from the column under gravity alone, the two set free at once: its
    # joint's tension is its weight's moment, 6 m g (l / 2) / (b h^2). Within 2 % below its
    # strength it hangs (the piece moves as one), 2 % above the joint cracks and the arm falls:
    # the piece starts settled on its contacts (_Pieces._preload; started on unloaded penalty
    # springs it dropped onto them, and their settling cracked the arm from 0.92 of its strength)
    lx, ly, hz = 0.3, 0.3, 0.2
    m = 1800.0 * lx * ly * hz
    stress = 6 * m * G * (lx / 2) / (ly * hz**2)
    sc, _ = _arm_on_a_column(stress / factor, constant_acceleration(0.0, 1.0), arm=(lx, ly, hz))
    on = PieceSettings(fallen_m=100.0, check_joints=True)
    pm = piece_motion(sc, np.array([0.0, np.nan]), np.linspace(0, 1, 3), settings=on)
    assert np.isfinite(pm.release_time_s[1]) == falls
    assert (pm.distance_m()[-1, 1] > 1.0) == falls
    # without the check (the default) the piece never cracks
    off = piece_motion(sc, np.array([0.0, np.nan]), np.linspace(0, 1, 3), settings=PieceSettings(fallen_m=100.0))
    assert off.distance_m()[-1, 1] < 1e-3 and np.isnan(off.crack_time_s).all()


def test_a_piece_that_checks_its_joints_starts_settled_on_its_contacts():
    # a block let go on still ground: on unloaded penalty springs it drops by its settling (about
    # settle_fraction of its size) and bounces; with check_joints its contacts start carrying its
    # weight and it does not move
    sc = _stack((0.9, 0.6, 0.3), 1, constant_acceleration(0.0, 0.5))
    t = np.linspace(0.0, 0.5, 26)
    release = np.array([0.0])
    dropped = piece_motion(sc, release, t, settings=PieceSettings(fallen_m=100.0))
    settled = piece_motion(sc, release, t, settings=PieceSettings(fallen_m=100.0, check_joints=True))
    assert np.abs(dropped.displacement_m[:, 0, 2]).max() > 1e-5
    assert np.abs(settled.displacement_m[:, 0]).max() < 1e-7


STEP_N = 1000.0  # the step load of the tests below, on body a towards -x: the joint in tension


def _bonded_pair():
    """Two blocks bonded face to face (strong mortar), free as one piece: the scene, the static
    force a step load STEP_N pulling block a away puts on their joint (``F m_2 / (m_1 + m_2)``)
    and the joint's circular frequency ``w^2 = k_n A (1 / m_1 + 1 / m_2)`` (units and mortar in
    series)."""
    mat = Material(tensile_strength=1e9, shear_strength=1e9, compressive_strength=1e12)
    a = _block("a", (0.3, 0.3, 0.3), (0.0, 0.0, 0.5), density=3000.0)
    b = _block("b", (0.2, 0.3, 0.3), (0.25, 0.0, 0.5))
    sc = Scene(bodies=(a, b), bonds=(Bond.rectangle(0, 1, (0.15, 0, 0.5), X, UP, 0.3, 0.3),), material=mat)
    # the centroids 0.25 m apart hold the joint's mortar and 0.25 m - t_j of unit (joints.unit_lengths)
    unit = 0.15 + 0.1 - mat.joint_thickness_m
    kn = 1.0 / (mat.joint_thickness_m / mat.mortar_youngs_modulus + unit / mat.unit_youngs_modulus)
    w = math.sqrt(kn * 0.09 * (1 / a.mass + 1 / b.mass))
    return sc, STEP_N * b.mass / (a.mass + b.mass), w


def _joint_force_under_a_step(sc, damping, h: float, checks: int) -> np.ndarray:
    """The joint's normal force (N, its size) at each of ``checks`` checks ``h`` apart of the pair's
    piece, STEP_N on block a from the second check on (the first, static, unloaded); the joints
    vibrating with Rayleigh's ``damping`` (alpha, beta), or static checks (None)."""
    from calib_masonry.simulation.dynamics import body_inertia
    from calib_masonry.simulation.joints import JointModel
    from calib_masonry.simulation.pieces import _Pieces

    model = JointModel(sc)
    state = _Pieces(sc, model, np.array([body_inertia(x) for x in sc.bodies]), PieceSettings(check_joints=True))
    if damping is not None:
        state.damping = damping
    state.regroup(np.ones(2, dtype=bool), np.ones(1, dtype=bool), None)
    got = []
    for k in range(checks):
        state.acc_t = h
        state.acc_F[0] = [-STEP_N * h if k else 0.0, 0.0, 0.0]
        assert state.check_joints(k * h).size == 0
        got.append(model.state(state.eu if damping is not None else state._last_U, np.array([0])).forces[0, 2])
    return np.abs(np.array(got))


@pytest.mark.parametrize("h", [0.005, 0.0025])
def test_a_pieces_joint_at_a_towers_damping_rises_to_its_static_force_without_ringing(h):
    # the pair below (their joint's period 0.6 ms) with the damping of a tower, 5 % at modes of
    # 0.2 and 0.06 s: 3.9 times critical at the joint, a time constant of 0.7 ms, so a step load
    # takes the joint to its static force within a millisecond or so and no further. Checked at the
    # default interval and its half (steps 7 and 3.5 times that constant): Newmark's average
    # acceleration rang to 1.126 and 1.100 times the static force there (docs/dynamics.md)
    from calib_masonry.simulation.dynamics import rayleigh

    sc, n_s, _ = _bonded_pair()
    damping = rayleigh(0.05, 2 * math.pi / 0.2, 2 * math.pi / 0.06)
    got = _joint_force_under_a_step(sc, damping, h, int(round(0.05 / h)) + 1) / n_s
    assert got.max() < 1.03
    assert got[-1] == pytest.approx(1.0, rel=1e-3)


@pytest.mark.parametrize("dynamic", [True, False])
def test_a_pieces_joint_rings_as_a_damped_oscillator_under_a_step_load(dynamic):
    # two blocks bonded face to face, free as one piece, a force F pulling one of them away along
    # the line through both centroids from t = 0 on (a step): the joint's normal force follows the
    # relative coordinate's damped oscillator, N(t) = N_s (1 - e^(-z w t) (cos w_d t + z / sqrt(1 -
    # z^2) sin w_d t)), N_s = F m_2 / (m_1 + m_2), w^2 = k_n A (1 / m_1 + 1 / m_2) with k_n the units
    # and mortar in series, z the Rayleigh damping at w (5 %); checked every T / 80 (the L-stable
    # rule's own damping and period error are second order: its first peak 1.835 at T / 40, 1.850 at
    # T / 80, against 1.855). A window's mean load is the load at its end,
    # so the step enters as a ramp over the first window: half a window late (t - h / 2 below).
    # Statically each check carries N_s at once.
    from calib_masonry.simulation.dynamics import rayleigh

    sc, n_s, w = _bonded_pair()
    zeta = 0.05
    h = 2 * math.pi / w / 80
    got = _joint_force_under_a_step(sc, rayleigh(zeta, w, 3 * w) if dynamic else None, h, 241)
    if not dynamic:
        assert got[1:] == pytest.approx(n_s, rel=1e-6)
        return
    wd = w * math.sqrt(1 - zeta**2)
    t = np.arange(len(got)) * h - h / 2
    env = np.exp(-zeta * w * t) * (np.cos(wd * t) + zeta / math.sqrt(1 - zeta**2) * np.sin(wd * t))
    want = np.where(np.arange(len(got)) > 0, n_s * (1 - env), 0.0)
    assert np.abs(got - want).max() < 0.03 * n_s
    # the first peak: 1 + e^(-pi z / sqrt(1 - z^2)) times the static force, half a damped period on
    assert got.max() / n_s == pytest.approx(1 + math.exp(-math.pi * zeta / math.sqrt(1 - zeta**2)), rel=0.01)
    assert abs(got.argmax() * h - h / 2 - math.pi / wd) <= h


def test_a_fallen_piece_keeps_its_rotation_and_says_when_and_how_fast_it_fell():
    # a slender block let go at once tips over under a steady 0.5 g (b / h = 1/4) and falls; a squat
    # one 3 m away is let go later, which regroups the pieces: the fallen block keeps the pose it
    # fell in (its rotation too, not only its displacement: the verdict's frames once turned it
    # back upright here), and the motion says when it fell and the velocity field it had then
    # (where an engine takes its fall on: loop._follow)
    bodies = (_block("slender", (0.2, 0.3, 0.8), (0, 0, 0.4)), _block("squat", (0.9, 0.6, 0.3), (3.0, 0, 0.15)))
    bonds = (
        Bond.rectangle(0, -1, (0, 0, 0), DOWN, X, 0.2, 0.3),
        Bond.rectangle(1, -1, (3.0, 0, 0), DOWN, X, 0.9, 0.6),
    )
    sc = Scene(bodies=bodies, bonds=bonds, material=DRY, motion=constant_acceleration(0.5 * G, 3.0))
    t = np.linspace(0.0, 3.0, 61)
    pm = piece_motion(sc, np.array([0.0, 2.5]), t, rotations=True)
    assert pm.fallen[0] and not pm.fallen[1]
    fell = float(pm.fell_time_s[0])
    assert 0.0 < fell < 2.5 and np.isnan(pm.fell_time_s[1])
    after = np.flatnonzero(t > fell + 0.05)
    R = pm.rotation[after, 0].astype(float)
    angle = np.degrees(np.arccos(np.clip((np.trace(R, axis1=1, axis2=2) - 1) / 2, -1, 1)))
    assert angle.min() > 10.0 and np.ptp(angle) < 1e-3  # tipped, and held so after the regroup
    v = pm.fell_velocity[0]
    assert abs(v[4]) > 0.5 and np.allclose(v[[3, 5]], 0.0, atol=1e-6)  # turning about y as it tips
    assert np.isnan(pm.fell_velocity[1]).all()


def test_the_compiled_step_moves_the_pieces_as_the_numpy_step_does(monkeypatch):
    # three slender blocks, each joint let go at another time under a strong two-component quake:
    # pieces that rock, slide and knock on each other and on the ground; the compiled step
    # (simulation/_pieces_step.py, runs of steps in one call) against the numpy step, one by one
    from calib_masonry.simulation import pieces as P
    from calib_masonry.simulation.ground_motion import synthetic_motion

    sc = _stack((0.3, 0.3, 0.5), 3, synthetic_motion(0.8, 3.0, seed=3, components=2))
    release = np.array([0.0, 0.4, 1.1])
    times = np.linspace(0.0, 3.0, 76)
    settings = PieceSettings(fallen_m=100.0)
    fast = piece_motion(sc, release, times, settings=settings, rotations=True)

    def numpy_steps(self, g, dt):
        for row in g:
            self.advance(row, dt)

    monkeypatch.setattr(P._Pieces, "advance_many", numpy_steps)
    slow = piece_motion(sc, release, times, settings=settings, rotations=True)
    assert fast.steps == slow.steps
    moved = float(np.abs(slow.displacement_m).max())
    assert moved > 0.02  # the pieces do move
    assert np.abs(fast.displacement_m - slow.displacement_m).max() < 1e-6 * moved
    assert np.abs(fast.rotation - slow.rotation).max() < 1e-6


@pytest.mark.parametrize("factor, overturns", [(0.98, False), (1.02, True)])
def test_the_rocking_threshold_experiment_s_block_overturns_at_housner_s_pulse_threshold(factor, overturns):
    # experiments/rocking_threshold.py integrates Housner's block: under a rectangular pulse of
    # psi g for t_p (then still ground), the linearised block overturns from psi = alpha / (1 -
    # exp(-p t_p)) (theta = (psi - alpha)(cosh p t - 1) during the pulse, then the free motion's
    # invariant omega^2 / p^2 - (theta - alpha)^2 decides whether it passes alpha). A slender block
    # (alpha 0.05 rad: the linearisation holds to a fraction of a per cent; measured within 0.5 %), p t_p = 1
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "experiments"))
    import rocking_threshold as rt

    alpha, R = 0.05, 2.0
    p2 = 3 * G / (4 * R)
    t_p = 1.0 / math.sqrt(p2)
    psi = factor * alpha / (1.0 - math.exp(-1.0))
    dt = 1e-4
    acc = np.zeros(int(round(t_p / dt)) + 2)
    acc[:-1] = -psi * G  # pushes the block onto its +theta side
    r = 1.0 - 1.5 * math.sin(alpha) ** 2
    assert rt.rock(acc, dt, 0.0, alpha, p2, r, 2.5e-4) is overturns
    # let go on a check grid: at the first check at or after the exact moment, within one interval
    wave = 2.0 * np.sin(np.arange(301) * 0.01)  # 2 sin t sampled every 0.01 s
    exact = rt.release_time(wave, 0.01, 1.5, 0.0)
    assert exact == pytest.approx(math.asin(0.75), abs=1e-4)
    on_grid = rt.release_time(wave, 0.01, 1.5, 0.005)
    assert exact <= on_grid < exact + 0.005

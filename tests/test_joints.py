"""Joint cracking from poses and the dead load across joints (no Blender needed)."""

import math

import numpy as np

from calib_masonry.simulate.blender import _box, _quaternions
from calib_masonry.simulate.monitor import JointMonitor
from calib_masonry.simulate.results import rotations
from calib_masonry.simulate.scene import MASONRY, Body, Bond, Scene, SolverSettings, dead_load_precompression


def _stack(n=10, h=0.2):
    v, f = _box((0.4, 0.2, h))
    return [Body(f"b{i}", v, f, np.array([0.0, 0.0, h / 2 + i * h]), 28.8, 0.77, volume=0.016) for i in range(n)]


def test_dead_load_is_the_weight_above_a_bed_joint_and_none_across_a_head_joint():
    bodies = _stack(10, 0.2)  # top at 2.0 m
    pts = np.array([[0.0, 0.0, 0.2], [0.0, 0.0, 1.2], [0.0, 0.0, 0.6], [5.0, 0.0, 0.2]])
    nrm = np.array([[0, 0, 1.0], [0, 0, -1.0], [1.0, 0, 0], [0, 0, 1.0]])
    s0 = dead_load_precompression(bodies, pts, nrm, MASONRY)
    g = 9.80665 * MASONRY.density
    np.testing.assert_allclose(s0[:2], [g * 1.8, g * 0.8])
    assert s0[2] == 0.0  # head joint: no precompression across it
    assert s0[3] == 0.0  # nothing above a point away from the stack


def _two_bricks_scene(bond_b=1):
    bodies = _stack(2, 0.2)
    bond = Bond(0, bond_b, np.array([0.0, 0.0, 0.2]), np.array([0.0, 0.0, 1.0]), 0.08, 1.0, 1.0, 1.0, 1.0)
    return Scene(bodies=tuple(bodies), bonds=(bond,), solver=SolverSettings(drift_break_m=0.002))


def _rot_y(angle):
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def test_monitor_sees_sliding_opening_and_turning_but_not_rigid_motion():
    sc = _two_bricks_scene()
    p0 = np.array([b.location for b in sc.bodies])
    R0 = np.repeat(np.eye(3)[None], 2, axis=0)
    mon = JointMonitor(sc, p0, R0, np.zeros(3), 0.0)
    # the pair moving and turning together as one body: intact
    R = _rot_y(0.3)
    p = p0 @ R.T + np.array([1.0, 2.0, 0.5])
    assert mon.update(0.1, p, np.stack([R, R]), np.zeros(3)).size == 0
    # the top brick turns 0.02 rad about the joint's centroid: the rim opens by r * 0.02 > 2 mm
    r = math.sqrt(0.08 / math.pi)
    assert r * 0.02 > 0.002
    c = np.array([0.0, 0.0, 0.2])
    Rt = _rot_y(0.02)
    p_turned = p0.copy()
    p_turned[1] = c + Rt @ (p0[1] - c)
    opening = mon.opening(p_turned, np.stack([np.eye(3), Rt]), np.zeros(3))
    assert abs(opening[0] - 2 * r * math.sin(0.01)) < 1e-6  # the rim point across the turn axis
    # sliding by 1 mm is not a crack, by 3 mm it is; the time is recorded once
    slid = p0 + np.array([[0, 0, 0], [0.001, 0, 0]])
    assert mon.update(0.2, slid, R0, np.zeros(3)).size == 0
    slid = p0 + np.array([[0, 0, 0], [0.003, 0, 0]])
    assert list(mon.update(0.3, slid, R0, np.zeros(3))) == [0]
    assert mon.update(0.4, slid, R0, np.zeros(3)).size == 0
    assert mon.break_time_s[0] == 0.3


def test_monitor_follows_the_plate_for_foundation_bonds():
    sc = _two_bricks_scene(bond_b=-1)
    p0 = np.array([b.location for b in sc.bodies])
    R0 = np.repeat(np.eye(3)[None], 2, axis=0)
    mon = JointMonitor(sc, p0, R0, np.zeros(3), 0.0)
    shift = np.array([0.05, 0.0, 0.0])
    assert mon.update(0.1, p0 + shift, R0, shift).size == 0  # carried by the ground
    assert list(mon.update(0.2, p0 + shift, R0, np.zeros(3))) == [0]  # the ground stayed: it slid


def test_rotations_of_quaternions():
    q = np.array([math.cos(0.15), 0.0, math.sin(0.15), 0.0])
    np.testing.assert_allclose(rotations(q), _rot_y(0.3), atol=1e-12)


def test_grown_bricks_that_overlap_an_unbonded_neighbour_are_found():
    from calib_masonry.simulate.scene import _overlapping_unbonded

    v, f = _box((0.4, 0.2, 0.2))
    at = [(0.0, 0.0, 0.1), (0.395, 0.0, 0.1), (0.0, 0.3, 0.1), (0.0, 0.0, 0.3)]
    bodies = [Body(f"b{i}", v, f, np.array(p), 28.8, 0.77) for i, p in enumerate(at)]
    # 0 and 1 overlap by 5 mm and are not bonded: both found; 0-2 apart; 0-3 touch only
    assert _overlapping_unbonded(bodies, set()) == {0, 1}
    assert _overlapping_unbonded(bodies, {(0, 1)}) == set()  # a bonded pair is the joint's business


def test_pose_quaternions_match_scipy_and_give_back_the_matrices():
    from scipy.spatial.transform import Rotation

    rot = Rotation.random(2000, random_state=3)
    m = np.concatenate([rot.as_matrix(), np.eye(3)[None], np.diag([1.0, -1, -1])[None], np.diag([-1.0, 1, -1])[None],
                        np.diag([-1.0, -1, 1])[None]])  # and the turns where w = 0
    q = _quaternions(m)
    assert np.allclose(np.linalg.norm(q, axis=1), 1.0) and np.all(q[:, 0] >= 0)
    back = Rotation.from_quat(np.column_stack([q[:, 1:], q[:, :1]])).as_matrix()
    assert np.abs(back - m).max() < 1e-12
    ref = Rotation.from_matrix(m).as_quat()
    ref = np.column_stack([ref[:, 3], ref[:, :3]])
    assert np.minimum(np.abs(q - ref).max(axis=1), np.abs(q + ref).max(axis=1)).max() < 1e-12
    # batched shapes, and poses read back in float32 as a run reads them
    m32 = m[:2000].astype(np.float32).astype(np.float64).reshape(40, 50, 3, 3)
    q32 = _quaternions(m32)
    assert q32.shape == (40, 50, 4)
    assert np.abs(q32.reshape(-1, 4) - q[:2000]).max() < 1e-6

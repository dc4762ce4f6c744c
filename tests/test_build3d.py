import math

import numpy as np
import pytest

from calib_masonry.build3d.assemble import WallPolygons, assemble
from calib_masonry.build3d.contacts import intersection_volume, max_interpenetration
from calib_masonry.build3d.extrude import polygon_area, prism
from calib_masonry.build3d.place import WallFrame, closure_gap, corners, wall_frames
from calib_masonry.build3d.scale import image_from_wall, wall_from_image
from calib_masonry.errors import InputError
from calib_masonry.spec import load_structure

from .conftest import DATA


def _frame(theta_deg=0.0, t=0.18, origin=(0.0, 0.0)):
    return WallFrame(0, np.array(origin, float), math.radians(theta_deg), 5.0, 3.0, t)


@pytest.mark.parametrize("theta", [0.0, 90.0, 33.0, 217.5])
def test_volume_is_area_times_thickness(theta):
    rng = np.random.default_rng(int(theta * 10))
    for _ in range(20):
        k = rng.integers(3, 10)
        ang = 2 * np.pi * (np.arange(k) + rng.uniform(0, 0.8, k)) / k  # star-shaped, simple
        r = rng.uniform(0.1, 0.3, k)
        poly = np.column_stack([1 + r * np.cos(ang), 1 + r * np.sin(ang)])
        t = rng.uniform(0.1, 0.5)
        solid = prism(poly, _frame(theta, t, origin=(2.0, -1.0)))
        assert math.isclose(solid.volume, abs(polygon_area(poly)) * t, rel_tol=1e-12)
        mesh = solid.to_trimesh()
        assert mesh.is_watertight and mesh.is_winding_consistent and mesh.volume > 0


def test_prism_orientation_outward_for_clockwise_input():
    poly = np.array([[0, 0], [0, 1], [2, 1], [2, 0]], float)  # clockwise
    solid = prism(poly, _frame())
    assert solid.volume > 0
    assert np.allclose(solid.centroid, [1.0, 0.09, 0.5])


def test_scaling_roundtrip_and_corners():
    shape = (120, 300)
    xy = np.array([[-0.5, -0.5], [299.5, 119.5]])
    xz = wall_from_image(xy, shape, 3.0, 1.2)
    assert np.allclose(xz, [[0.0, 1.2], [3.0, 0.0]])
    assert np.allclose(image_from_wall(xz, shape, 3.0, 1.2), xy)


def test_wall_at_90_starts_at_cumulative_width():
    spec = load_structure(DATA / "paper_example" / "structure.toml")
    frames = wall_frames(spec)
    expected = np.zeros(2)
    for f, w in zip(frames, spec.walls):
        assert np.allclose(f.origin_xy, expected)
        expected = expected + w.width_m * np.array([math.cos(w.theta_rad), math.sin(w.theta_rad)])
    # wall2 (theta 90) begins where wall1 (5.73 m along X) ends
    assert np.allclose(frames[1].origin_xy, [5.73, 0.0])
    assert np.allclose(frames[3].origin_xy, [5.73 - 3.07, 4.10])
    assert np.linalg.norm(closure_gap(spec)) < 1e-9


def test_built_bricks_of_wall2_start_at_cumulative_width(make_scenario):
    data = make_scenario([(2.0, 1.2, 0), (1.5, 1.2, 90)], closed=False)
    from calib_masonry.pipeline import build

    s = build(load_structure(data / "structure.toml"), progress=False).structure
    wall2 = np.concatenate([b.solid.vertices for b in s.bricks_of(1)])
    # wall 2 runs along +Y from X = 2.0 with its thickness to -X: its outer face is the plane X = 2.0
    assert math.isclose(wall2[:, 0].max(), 2.0, abs_tol=1e-9)
    assert wall2[:, 1].min() >= -1e-9
    assert math.isclose(wall2[:, 0].min(), 2.0 - 0.18, abs_tol=1e-9)


def test_corner_kinds():
    spec = load_structure(DATA / "paper_example" / "structure.toml")
    cs = corners(spec)
    assert len(cs) == 6  # closed
    assert [c.convex for c in cs] == [True, True, False, True, True, True]


def _rect(x0, x1, z0, z1):
    return np.array([[x0, z0], [x1, z0], [x1, z1], [x0, z1]], float)


def test_interpenetration_detects_overlap():
    f = _frame()
    a = prism(_rect(0, 1, 0, 1), f)
    b = prism(_rect(0.5, 1.5, 0, 1), f)
    assert math.isclose(intersection_volume(a, b), 0.5 * 0.18, rel_tol=1e-5)


@pytest.mark.parametrize("thetas", [(30, 120, 210, 300), (15, 105, 195, 285)])
def test_rotated_footprint_no_interpenetration(make_scenario, thetas):
    data = make_scenario([(2.4, 1.5, thetas[0]), (1.8, 1.5, thetas[1]), (2.4, 1.5, thetas[2]), (1.8, 1.5, thetas[3])])
    from calib_masonry.pipeline import build

    s = build(load_structure(data / "structure.toml"), progress=False).structure
    inter = max_interpenetration(s.bricks)
    assert inter.pairs_checked > 0  # corners really were checked
    assert inter.max_volume_m3 < 1e-6


def test_non_right_angle_corners_no_interpenetration(make_scenario):
    # an equilateral triangle: 120-degree turns at every corner
    data = make_scenario([(3.0, 1.2, 0), (3.0, 1.2, 120), (3.0, 1.2, 240)], t=0.2)
    from calib_masonry.pipeline import build

    s = build(load_structure(data / "structure.toml"), progress=False).structure
    assert max_interpenetration(s.bricks).max_volume_m3 < 1e-6
    for b in s.bricks:
        m = b.solid.to_trimesh()
        assert m.is_watertight and m.volume > 0


def _ring_holes(structure, spec, mortar_m: float) -> float:
    """The largest fraction of the footprint's ring (its walls' bands, mitred at the corners) that
    no brick covers, over horizontal sections at the middle of each course (of wall 0's bricks):
    each brick's section is grown by a joint and 2 mm, so mortar joints (an irregular stone's up to
    twice as wide) close and only holes stay."""
    import shapely

    fp = spec.footprint
    frames = wall_frames(fp)
    outer = shapely.Polygon([f.origin_xy for f in frames])
    ring = outer.difference(outer.buffer(-fp.walls[0].thickness_m, join_style="mitre"))
    meshes = [(b.solid.to_trimesh(), b.solid.vertices[:, 2]) for b in structure.bricks]
    worst = 0.0
    for z in sorted({round(float(b.solid.vertices[:, 2].mean()), 3) for b in structure.bricks if b.wall == 0}):
        parts = []
        for mesh, zs in meshes:  # brick by brick: two solids meeting on a face would be traced as one loop
            if zs.min() < z < zs.max():
                section = mesh.section(plane_origin=[0.0, 0.0, z], plane_normal=[0.0, 0.0, 1.0])
                parts += [shapely.Polygon(p[:, :2]).buffer(mortar_m + 0.002) for p in section.discrete if len(p) >= 3]
        worst = max(worst, ring.difference(shapely.union_all(parts)).area / ring.area)
    return worst


L_PLAN = [(2.4, 1.1, 0.0), (2.4, 1.1, 90.0), (1.2, 1.1, 180.0), (1.2, 1.1, 90.0), (1.2, 1.1, 180.0), (3.6, 1.1, 270.0)]
# a bay: a re-entrant corner of 45 degrees between walls 1 and 2, and a convex one of 45
BAY_PLAN = [
    (3.0, 1.1, 0.0),
    (1.0, 1.1, 90.0),
    (2**0.5, 1.1, 45.0),
    (2**0.5, 1.1, 135.0),
    (3.0, 1.1, 180.0),
    (3.0, 1.1, 270.0),
]
PLANS = {"L": (L_PLAN, (2, 3)), "bay": (BAY_PLAN, (1, 2))}


@pytest.mark.parametrize(
    ("sides", "layout"),
    [(6, "stretcher"), (8, "stones"), (4, "stones"), ("L", "stretcher"), ("L", "stones"), ("bay", "stones")],
    ids=["hexagon", "octagon", "square", "L-bricks", "L-stones", "bay-stones"],
)
def test_polygonal_towers_leave_no_hole_at_their_corners(make_scenario, sides, layout):
    # at a corner that is not a right angle the owner's brick runs past its wall's end, and the
    # other wall's first brick reaches back to the owner's inner face: a hexagonal tower of
    # stretcher bond had a triangle t^2 cot(60)/2 open at every corner of every course (7 % of its
    # ring), an octagonal tower of stones 16 % (an irregular stone's end was carried past the
    # corner by one vertex: a sliver); the truth (the same extrusion) had the same holes. At an L
    # plan's inner (re-entrant) corner the t x t of masonry that neither photo shows was left out:
    # the two walls touched along the corner's edge alone, with no joint between them
    from calib_masonry.pipeline import build

    walls = PLANS[sides][0] if sides in PLANS else [(1.2, 1.1, 360.0 * k / sides) for k in range(sides)]
    data = make_scenario(walls, layout=layout, t=0.3, closed=True, seed=31)
    spec = load_structure(data / "structure.toml")
    s = build(spec, progress=False).structure
    mortar = 0.025 if layout == "stones" else 0.01
    assert _ring_holes(s, spec, mortar) < 0.01
    assert max_interpenetration(s.bricks).max_volume_m3 < 1e-6
    for b in s.bricks:
        m = b.solid.to_trimesh()
        assert m.is_watertight and m.volume > 0
    if sides in PLANS:  # the simulation joins the two walls of the inner corner over their mitre
        from calib_masonry.build_folder import simulation_geometry

        g = simulation_geometry(s)
        wall = np.array([b.wall for b in s.bricks])
        pairs = g.patch_pairs[(g.patch_pairs >= 0).all(axis=1)]
        assert PLANS[sides][1] in {tuple(sorted(int(v) for v in w)) for w in wall[pairs] if w[0] != w[1]}


def test_assemble_removes_given_end_faces():
    spec = load_structure(DATA / "stylite" / "structure.toml")
    walls = [WallPolygons(w, (0, 1), (_rect(0, 0.4, 0, 0.3), _rect(0.5, 1.0, 0, 0.3))) for w in range(4)]
    s = assemble(spec.footprint, walls, name=spec.name, end_faces=[{0}, set(), set(), set()])
    assert len(s.bricks) == 7 and s.removed[0] == (0,)
    # a wall left with no brick is refused by name (the build wrote its model, then its summary's
    # line for the wall was a traceback formatting a mean Dice of None)
    with pytest.raises(InputError, match="wall 'north': none of its 2 pieces made a brick"):
        assemble(spec.footprint, walls, name=spec.name, end_faces=[{0, 1}, set(), set(), set()])


def _solid(xy, x0, x1, rotation, shift):
    """The prism over the polygon ``xy`` in (y, z), from x = x0 to x1, rotated and shifted."""
    from calib_masonry.build3d.assemble import Brick
    from calib_masonry.build3d.extrude import Polyhedron

    frame = WallFrame(0, np.zeros(2), 0.0, 5.0, 3.0, x1 - x0)  # the wall's y is its thickness
    p = prism(np.asarray(xy, float), frame)  # (x, z) outline, extruded along y
    v = p.vertices[:, [1, 0, 2]] + [x0, 0.0, 0.0]  # thickness along x; the outline in (y, z)
    faces = p.faces[:, ::-1]  # swapping two axes mirrors the solid: keep it outward
    return Brick(
        id=0, wall=0, label=0, polygon_m=np.asarray(xy, float), solid=Polyhedron(v @ rotation.T + shift, faces)
    )


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_contact_patch_of_two_facing_prisms_is_their_overlap(seed):
    """Two prisms face each other across 10 mm, one with an L-shaped (non-convex) face, in an
    arbitrary orientation: the patch is the faces' overlap, its section and outline that overlap's."""
    from dataclasses import replace

    import shapely
    from scipy.spatial.transform import Rotation

    from calib_masonry.build3d.contacts import contact_patches, joint_axes

    rng = np.random.default_rng(seed)
    R = Rotation.random(random_state=seed).as_matrix()
    t = rng.normal(size=3)
    rect = [(0.0, 0.0), (0.5, 0.0), (0.5, 0.3), (0.0, 0.3)]
    ell = [(0.1, -0.1), (0.7, -0.1), (0.7, 0.05), (0.3, 0.05), (0.3, 0.4), (0.1, 0.4)]
    a = _solid(rect, 0.0, 1.0, R, t)
    b = replace(_solid(ell, 1.01, 2.0, R, t), id=1)
    far = replace(_solid(rect, 3.0, 4.0, R, t), id=2)  # beyond the reach: no patch
    (patch,) = contact_patches([a, b, far], max_gap_m=0.03, progress=False)
    overlap = shapely.Polygon(rect).intersection(shapely.Polygon(ell))
    assert (patch.a, patch.b) == (0, 1)
    assert np.allclose(patch.normal, R @ [1.0, 0, 0], atol=1e-12) and math.isclose(patch.gap_m, 0.01, rel_tol=1e-9)
    assert math.isclose(patch.area_m2, overlap.area, rel_tol=1e-12)
    c = overlap.centroid
    assert np.allclose(patch.centroid, R @ [1.005, c.x, c.y] + t, atol=1e-12)
    # second moments about the centroid, turned into the joint frame, against shapely's polygon
    yz = np.asarray(overlap.exterior.coords) - [c.x, c.y]
    u, v, _ = (x[0] for x in joint_axes(patch.normal[None]))
    to_uv = np.array([[u @ R[:, 1], u @ R[:, 2]], [v @ R[:, 1], v @ R[:, 2]]])
    x, y = yz[:-1, 0], yz[:-1, 1]
    x1, y1 = yz[1:, 0], yz[1:, 1]
    cr = x * y1 - x1 * y
    sign = np.sign(cr.sum())
    Jyy = sign * (cr * (x**2 + x * x1 + x1**2)).sum() / 12
    Jzz = sign * (cr * (y**2 + y * y1 + y1**2)).sum() / 12
    Jyz = sign * (cr * (x * y1 + 2 * x * y + 2 * x1 * y1 + x1 * y)).sum() / 24
    J = to_uv @ np.array([[Jyy, Jyz], [Jyz, Jzz]]) @ to_uv.T
    assert np.allclose(patch.moments, [J[0, 0], J[1, 1], J[0, 1]], rtol=0, atol=1e-14)
    hull = np.asarray(overlap.convex_hull.exterior.coords)[:-1] - [c.x, c.y]
    corners = {tuple(np.round(p, 9)) for p in patch.outline @ to_uv}  # (u, v) back to (y, z)
    assert corners == {tuple(np.round(p, 9)) for p in hull}
    assert math.isclose(patch.min_width_m, 0.3, rel_tol=1e-9)  # the overlap is 0.4 wide and 0.3 tall


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_contact_patch_between_faces_turned_apart_far_from_the_origin(seed):
    """Two stones 2 cm apart at the middle of their joint, one face turned 2 degrees from the other,
    5 m from the origin (a corner of a tower): one patch, its gap read at the patch. The planes'
    offsets alone (measured from the origin) put them 17 cm apart, beyond the reach: no joint."""
    from dataclasses import replace

    import shapely
    from scipy.spatial.transform import Rotation

    from calib_masonry.build3d.assemble import Brick
    from calib_masonry.build3d.contacts import contact_patches
    from calib_masonry.build3d.extrude import Polyhedron

    R = Rotation.random(random_state=seed).as_matrix()
    t = 5.0 * R @ [0.0, 1.0, 0.0]
    rect = [(0.0, 0.0), (0.5, 0.0), (0.5, 0.3), (0.0, 0.3)]
    big = [(-0.1, -0.1), (0.6, -0.1), (0.6, 0.4), (-0.1, 0.4)]  # covers rect when turned by 2 degrees
    a = _solid(rect, 0.0, 1.0, R, t)
    b0 = _solid(big, 1.02, 2.0, np.eye(3), np.zeros(3))
    # b turned by 2 degrees about the z axis through its face's point facing rect's centroid
    centre = np.array([1.02, 0.25, 0.15])
    turn = Rotation.from_euler("z", 2.0, degrees=True).as_matrix()
    v = (b0.solid.vertices - centre) @ turn.T + centre
    b = Brick(id=1, wall=0, label=0, polygon_m=b0.polygon_m, solid=Polyhedron(v @ R.T + t, b0.solid.faces))
    far = replace(_solid(rect, 3.0, 4.0, R, t), id=2)
    (patch,) = contact_patches([a, b, far], max_gap_m=0.03, angle_deg=10.0, progress=False)
    assert (patch.a, patch.b) == (0, 1)
    # the distance from a's face to b's plane along a's normal, at the patch (rect's centroid)
    assert math.isclose(patch.gap_m, 0.02, rel_tol=1e-9)
    assert math.isclose(patch.area_m2, shapely.Polygon(rect).area, rel_tol=1e-9)
    assert np.allclose(patch.centroid, R @ [1.01, 0.25, 0.15] + t, atol=1e-9)
    # turned the other way round about a point 4 cm further, the gap at the patch is beyond the reach
    v = (b0.solid.vertices - centre) @ turn.T + centre + [0.04, 0.0, 0.0]
    b = Brick(id=1, wall=0, label=0, polygon_m=b0.polygon_m, solid=Polyhedron(v @ R.T + t, b0.solid.faces))
    assert contact_patches([a, b], max_gap_m=0.03, angle_deg=10.0, progress=False) == []


def test_least_width_of_convex_polygons_is_their_narrowest_extent():
    from scipy.optimize import minimize_scalar

    from calib_masonry.build3d.contacts import _least_widths

    rng = np.random.default_rng(5)
    angles = np.linspace(0, np.pi, 20001)
    directions = np.stack([np.cos(angles), np.sin(angles)], axis=1)
    for k in (3, 4, 7, 12):
        hulls = []
        for _ in range(5):
            a = np.sort(rng.uniform(0, 2 * np.pi, k))
            r = rng.uniform(0.5, 1.5, 2)
            hulls.append(np.column_stack([r[0] * np.cos(a), r[1] * np.sin(a)]))  # convex: on an ellipse
        hulls = np.array(hulls)
        across = np.ptp(np.einsum("hkj,aj->hka", hulls, directions), axis=1)  # (H, angles)
        brute = []
        for h, best in zip(hulls, angles[across.argmin(axis=1)]):  # refined between the samples
            width = lambda a, h=h: np.ptp(h @ [np.cos(a), np.sin(a)])  # noqa: E731
            step = angles[1]
            brute.append(minimize_scalar(width, bounds=(best - step, best + step), options={"xatol": 1e-12}).fun)
        least = _least_widths(hulls)
        assert np.all(least <= across.min(axis=1) + 1e-12)  # no direction is narrower
        assert np.allclose(least, brute, rtol=0, atol=1e-7)  # and it is attained (to the search's tolerance)


def test_walls_figure_has_a_colour_bar_for_dice(make_scenario, tmp_path, monkeypatch):
    """walls.png coloured the bricks by Dice without a scale (the colours were unreadable)."""
    import calib_masonry as cm
    from calib_masonry import _figure
    from calib_masonry.build3d.export import plot_walls

    data = make_scenario([(1.6, 0.8, 0), (1.2, 0.8, 90)], closed=False)
    result = cm.build(cm.load_structure(data / "structure.toml"))
    saved = []
    monkeypatch.setattr(_figure, "save", lambda fig, path, dpi=110: saved.append(fig))
    plot_walls(result.structure, tmp_path / "walls.png")
    (fig,) = saved
    labels = [ax.get_ylabel() for ax in fig.axes]
    assert len(fig.axes) == 3 and any(label.startswith("Dice") for label in labels)


def test_an_overlay_geos_cannot_node_is_done_again_from_valid_inputs():
    # a brick's face projected on a neighbour's plane can come out self-touching, and GEOS then
    # raises a TopologyException (seen with shapely 2.2 / GEOS 3.14 building the refined Stylite
    # tower's contacts); the overlay is done again from valid inputs, only where it failed
    import shapely
    from shapely.errors import GEOSException

    from calib_masonry.build3d.contacts import _overlay

    bow = shapely.Polygon([(0, 0), (1, 1), (1, 0), (0, 1)])  # two triangles meeting at (0.5, 0.5), one ring
    sq = shapely.box(0.2, 0.2, 0.8, 0.8)
    with pytest.raises(GEOSException):
        shapely.difference(bow, sq)
    assert _overlay(shapely.difference, bow, sq).area == pytest.approx(0.5 - 0.18)
    assert _overlay(shapely.union_all, [bow, sq]).area == pytest.approx(0.5 + 0.36 - 0.18)
    both = _overlay(shapely.intersection, np.array([bow, sq]), np.array([sq, sq]))
    assert shapely.area(both) == pytest.approx([0.18, 0.36])
    assert shapely.equals_exact(both[1], shapely.intersection(sq, sq))  # the element that did not fail: as it was


def test_two_walls_that_both_claim_a_corner_are_not_carried_past_it():
    # where the end faces were told apart wrongly (an end face about as wide as a unit: a hexagonal
    # tower of 0.35 m walls and 0.40 m bricks, photographed), both walls' last pieces reach the
    # corner in one course; carried past it, each would fill the corner and the two overlap there
    # (the photographed hexagon: 8.0 litres, against 6.0 before they were carried)
    from calib_masonry.build3d.bond import LAST, corner_roles
    from calib_masonry.build3d.place import Footprint, WallGeometry

    fp = Footprint((WallGeometry(1.6, 1.0, 0.0, 0.35), WallGeometry(1.6, 1.0, math.radians(60.0), 0.35)), closed=False)
    frames, cs = wall_frames(fp), corners(fp)
    a = [_rect(0.0, 1.17, 0.0, 0.2), _rect(0.0, 1.57, 0.22, 0.42)]  # course 2: a reaches the corner
    b = [_rect(0.03, 0.8, 0.0, 0.2), _rect(0.45, 0.9, 0.22, 0.42)]  # course 1: b reaches it
    roles = corner_roles([a, b], frames, cs)
    # each course's last pieces are carried: the owner's past the corner, the other's back to it
    assert roles[0][1][1] == LAST and roles[1][1][0] == LAST
    assert roles[0][0][1] == LAST and roles[1][0][0] == LAST
    b[1] = _rect(0.0, 0.9, 0.22, 0.42)
    roles = corner_roles([a, b], frames, cs)
    assert roles[0][1][1] is None and roles[1][1][0] is None  # both claim course 2: neither is carried

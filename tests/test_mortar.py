"""Mortar cells: each brick's share of its wall (no Blender needed)."""

import numpy as np
import shapely

from calib_masonry.simulation.mortar import mortar_cells


def _rect(x0, y0, x1, y1):
    return np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]], dtype=float)


def test_cells_meet_in_the_middle_of_the_joints_and_never_overlap():
    rng = np.random.default_rng(3)
    polys = []
    for row in range(4):  # running bond with uneven joints, 5-25 mm
        x = 0.25 * (row % 2)
        while x < 1.5:
            w = 0.2 + 0.1 * rng.random()
            polys.append(_rect(x, 0.1 * row, x + w, 0.1 * row + 0.08 - 0.01 * rng.random()))
            x += w + 0.005 + 0.02 * rng.random()
    cells = [shapely.Polygon(c) for c in mortar_cells(polys, reach=0.03, pixel=0.0025)]
    for p, c in zip(polys, cells):
        assert c.is_valid and c.buffer(1e-9).contains(shapely.Polygon(p))
    tree = shapely.STRtree(cells)
    for i, j in np.array(tree.query(cells, predicate="intersects")).T:
        if i < j:
            assert cells[i].intersection(cells[j]).area < 1e-9
    # the joints are filled: bricks within a joint's width of each other end up touching, or a
    # sliver apart where a corner's cut (between diagonal neighbours) passes by
    shapes = [shapely.Polygon(p) for p in polys]
    near = [
        (i, j) for i in range(len(polys)) for j in range(i + 1, len(polys)) if shapes[i].distance(shapes[j]) <= 0.04
    ]
    assert len(near) > len(polys)
    for i, j in near:
        assert cells[i].distance(cells[j]) <= max(0.0025, 0.2 * shapes[i].distance(shapes[j]))
    assert np.median([cells[i].distance(cells[j]) for i, j in near]) < 1e-9


def test_two_bricks_across_a_joint_touch_at_its_middle_and_reach_bounds_a_cell():
    a, b = _rect(0.0, 0.0, 0.2, 0.1), _rect(0.22, 0.0, 0.42, 0.1)
    ca, cb = (shapely.Polygon(c) for c in mortar_cells([a, b], reach=0.03, pixel=0.001))
    assert abs(ca.bounds[2] - 0.21) <= 0.001 and abs(cb.bounds[0] - 0.21) <= 0.001
    assert ca.distance(cb) < 1e-9
    far = _rect(1.0, 0.0, 1.2, 0.1)  # 0.58 m from b: each grows by at most the reach towards the other
    cells = [shapely.Polygon(c) for c in mortar_cells([a, b, far], reach=0.03, pixel=0.001)]
    assert cells[1].bounds[2] <= 0.42 + 0.03 + 0.001
    assert cells[2].bounds[0] >= 1.0 - 0.03 - 0.001


def test_irregular_stones_keep_their_hulls_inside_their_cells():
    rng = np.random.default_rng(7)
    polys = []
    for i in range(5):
        for j in range(3):
            c = np.array([0.45 * i, 0.35 * j]) + 0.03 * rng.standard_normal(2)
            ang = np.sort(rng.uniform(0, 2 * np.pi, 7))
            r = 0.14 + 0.03 * rng.random(7)
            polys.append(c + np.column_stack([r * np.cos(ang), 0.8 * r * np.sin(ang)]))
    cells = [shapely.Polygon(c) for c in mortar_cells(polys, reach=0.05)]
    for p, c in zip(polys, cells):
        assert c.buffer(1e-9).contains(shapely.Polygon(p).convex_hull)
    for i in range(len(cells)):
        for j in range(i + 1, len(cells)):
            assert cells[i].intersection(cells[j]).area < 1e-9

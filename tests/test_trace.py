import numpy as np
import pytest

from calib_masonry.io import read_mask
from calib_masonry.wall2d.dice import dice_polygon_region, rasterise_polygon
from calib_masonry.wall2d.segment import label_bricks
from calib_masonry.wall2d.split import farthest_pair, split_outline
from calib_masonry.wall2d.trace import TraceConfig, trace_mask, trace_outline

from .conftest import SWAT


def _rect_mask(shape, r0, r1, c0, c1):
    m = np.zeros(shape, bool)
    m[r0 : r1 + 1, c0 : c1 + 1] = True
    return m


@pytest.mark.parametrize("r0, r1, c0, c1", [(3, 20, 5, 44), (0, 9, 0, 30), (7, 7, 2, 12), (10, 39, 50, 59)])
def test_rectangle_traces_to_its_four_corners(r0, r1, c0, c1):
    m = _rect_mask((40, 60), r0, r1, c0, c1)
    res = trace_mask(m, TraceConfig(vertices=4))
    (b,) = res.bricks
    expected = {(c0 - 0.5, r0 - 0.5), (c1 + 0.5, r0 - 0.5), (c1 + 0.5, r1 + 0.5), (c0 - 0.5, r1 + 0.5)}
    got = {tuple(v) for v in b.vertices_xy}
    assert got == expected  # exact, so certainly within a pixel
    assert b.dice == 1.0
    assert b.traced_vertices == 4


def test_rotated_rectangle_within_a_pixel():
    # a rectangle rotated by 20 degrees, rasterised by pixel centres
    ang = np.radians(20)
    rot = np.array([[np.cos(ang), -np.sin(ang)], [np.sin(ang), np.cos(ang)]])
    corners = (np.array([[-30, -12], [30, -12], [30, 12], [-30, 12]]) @ rot.T) + [50, 40]
    m = rasterise_polygon(corners, (80, 100))
    (b,) = trace_mask(m, TraceConfig(vertices=4)).bricks
    d = np.linalg.norm(b.vertices_xy[:, None, :] - corners[None, :, :], axis=-1)
    assert d.min(axis=0).max() < 1.0
    assert b.dice > 0.97


def test_outline_area_equals_pixel_count():
    rng = np.random.default_rng(3)
    blob = np.zeros((30, 30), bool)
    blob[5:25, 5:25] = True
    blob[rng.integers(5, 25, 40), rng.integers(5, 25, 40)] = False
    labels = label_bricks(blob)
    region = labels == labels[15, 15]
    outline = trace_outline(region)
    x, y = outline[:, 0], outline[:, 1]
    area = 0.5 * abs(np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y))
    assert area == region.sum()
    assert dice_polygon_region(outline, region) == 1.0


def test_border_bricks_kept_specks_dropped_holes_filled():
    m = np.zeros((50, 80), bool)
    m[0:20, 0:30] = True  # touches the top-left border
    m[25:50, 40:80] = True  # touches bottom and right borders
    m[30, 10] = True  # a speck
    m[35:38, 55:57] = False  # a hole inside a brick
    res = trace_mask(m, TraceConfig(vertices=4))
    assert len(res.bricks) == 2
    assert {b.area_px for b in res.bricks} == {600, 1000}
    assert res.mean_dice == 1.0


def test_farthest_pair_exact():
    rng = np.random.default_rng(1)
    pts = rng.normal(size=(200, 2))
    i, j = farthest_pair(pts)
    d = np.linalg.norm(pts[:, None] - pts[None], axis=-1)
    assert np.isclose(np.linalg.norm(pts[i] - pts[j]), d.max())


def test_split_vertices_on_outline_in_order():
    t = np.linspace(0, 2 * np.pi, 300, endpoint=False)
    outline = np.column_stack([40 * np.cos(t), 25 * np.sin(t)])
    idx = split_outline(outline, 8)
    assert len(idx) == 8 and np.all(np.diff(idx) > 0)


def test_target_dice_mode_reaches_target_with_fewest():
    t = np.linspace(0, 2 * np.pi, 12, endpoint=False)
    poly = np.column_stack([60 + 40 * np.cos(t), 50 + 30 * np.sin(t)])
    m = rasterise_polygon(poly, (100, 120))
    res = trace_mask(m, TraceConfig(vertices=None, target_dice=0.97))
    (b,) = res.bricks
    assert b.dice >= 0.97
    n = len(b.vertices_xy)
    fewer = trace_mask(m, TraceConfig(vertices=n - 1)).bricks[0]
    assert fewer.dice < 0.97


def test_swat_real_mask_eight_vertices():
    m = read_mask(SWAT)
    res = trace_mask(m, TraceConfig(vertices=8))
    assert len(res.bricks) == 45
    assert res.mean_dice >= 0.98
    assert all(len(b.vertices_xy) == 8 for b in res.bricks)


def test_polygon_pixels_are_scikit_images_pixel_for_pixel():
    # random polygons, convex and not, partly outside the image, and half of them on the half-pixel
    # grid, so that pixel centres fall on vertices and edges, which scikit-image counts in (a plain
    # even-odd crossing rule misses those: it differed on 496 of 3,000 such polygons)
    from skimage.draw import polygon as skimage_polygon

    from calib_masonry.wall2d.dice import polygon_pixels

    rng = np.random.default_rng(7)
    for i in range(400):
        k = int(rng.integers(3, 10))
        centre, radius = rng.uniform(-15, 75, 2), rng.uniform(0.3, 30)
        angle = rng.uniform(0, 2 * np.pi, k)  # unsorted: self-intersecting outlines too
        r = centre[0] + radius * rng.uniform(0.2, 1, k) * np.sin(angle)
        c = centre[1] + radius * rng.uniform(0.2, 1, k) * np.cos(angle)
        if i % 2:
            r, c = np.round(2 * r) / 2, np.round(2 * c) / 2
        shape = (60, 70) if i % 3 else None
        expect = skimage_polygon(r, c, shape=shape)
        got = polygon_pixels(r, c, shape)
        assert np.array_equal(got[0], expect[0]) and np.array_equal(got[1], expect[1]), (r, c, shape)


@pytest.mark.parametrize("seed", [0, 1])
def test_grey_morphology_is_scipys_erosion_and_dilation(seed):
    from scipy import ndimage
    from skimage.morphology import diamond, disk

    from calib_masonry.wall2d.segment import grey_morphology

    rng = np.random.default_rng(seed)
    # symmetric footprints go to OpenCV (disks, a diamond, a rectangle, a ring), a lopsided one
    # and an even-sided one to scipy; float32 and float64 images, each as scipy filters them
    ring = disk(3)
    ring[2:5, 2:5] = False  # a hollow centre
    lopsided = disk(2)
    lopsided[0, 2] = False
    for fp in [disk(r) for r in range(1, 7)] + [
        diamond(2),
        np.ones((3, 7), bool),
        ring,
        lopsided,
        np.ones((2, 4), bool),
    ]:
        for shape in [(1, 1), (2, 40), (9, 9), (40, 3), (70, 55), (300, 260)]:
            for dtype in (np.float32, np.float64):
                a = rng.random(shape).astype(dtype)
                assert np.array_equal(grey_morphology(a, fp, np.minimum), ndimage.grey_erosion(a, footprint=fp))
                assert np.array_equal(grey_morphology(a, fp, np.maximum), ndimage.grey_dilation(a, footprint=fp))


def test_the_trace_figures_title_stays_inside_the_figure(tmp_path, monkeypatch):
    """The refine figure's title (the splitting and refined Dice beside the counts) was clipped on
    both sides of a narrow mask's figure: it is wrapped to the figure's width."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    from calib_masonry import _figure
    from calib_masonry.wall2d.figures import plot_trace
    from calib_masonry.wall2d.trace import trace_mask

    mask = np.zeros((400, 120), dtype=bool)
    for top in range(10, 390, 60):
        mask[top : top + 50, 10:110] = True
    result = trace_mask(mask)
    saved = []
    monkeypatch.setattr(_figure, "save", lambda fig, path, dpi=110: saved.append(fig))
    plot_trace(mask, result, tmp_path / "t.png", title="a narrow wall's mask, traced and refined: " * 3)
    fig = saved[0]
    FigureCanvasAgg(fig).draw()
    box = fig.axes[0].title.get_window_extent()
    width = fig.get_size_inches()[0] * fig.dpi
    assert box.x0 >= 0 and box.x1 <= width


@pytest.mark.parametrize("block_px", [1 << 21, 60])  # the whole image at once, and bands of a few rows
def test_outlines_all_at_once_are_each_labels_own_value_for_value(block_px, monkeypatch):
    # trace_outlines (every label's marching squares at once, joined by an index) must give what
    # trace_outline gives on each label's crop, point for point and from the same start: on
    # labels that touch, hold holes and other labels, meet at saddles, lie in several parts and
    # run along the image's border
    from scipy import ndimage

    from calib_masonry.wall2d import trace
    from calib_masonry.wall2d.trace import trace_outlines

    monkeypatch.setattr(trace, "_TRACE_BLOCK_PX", block_px)
    rng = np.random.default_rng(7)
    checked = 0
    for t in range(150):
        h, w = (int(v) for v in rng.integers(2, 30, 2))
        n = int(rng.integers(1, 7))
        labels = rng.integers(0, n + 1, (h, w))  # speckle: saddles, parts, holes
        if t % 3 == 0:  # blobs that touch one another
            f = ndimage.gaussian_filter(rng.random((h, w)), 2.0)
            labels = np.digitize(f, np.quantile(f, np.linspace(0, 1, n + 2)[1:-1]))
        if t % 5 == 0:  # each a 4-connected part, as a segmentation's labels are
            labels, _ = ndimage.label(labels > 0)
        slices = ndimage.find_objects(labels)
        ids = [k for k, sl in enumerate(slices, start=1) if sl is not None]
        for k, outline in zip(ids, trace_outlines(labels, ids)):
            expect = trace_outline(labels[slices[k - 1]] == k)
            assert outline.shape == expect.shape and np.array_equal(outline, expect), (t, k)
            checked += 1
    assert checked > 500
    assert trace_outlines(labels, []) == []
    with pytest.raises(ValueError, match="no pixels"):
        trace_outlines(np.zeros((5, 5), int), [1])

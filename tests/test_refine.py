"""Soft-Dice refinement: the soft rasteriser against analytic facts, and the fit's guarantees."""

import json

import numpy as np
import pytest
import shapely

from calib_masonry._jax import jax, jnp
from calib_masonry.io import read_mask
from calib_masonry.wall2d.dice import rasterise_polygon
from calib_masonry.wall2d.refine import RefineConfig
from calib_masonry.wall2d.refine_kernel import hard_dice_points, soft_dice
from calib_masonry.wall2d.segment import label_bricks
from calib_masonry.wall2d.trace import TraceConfig, trace_mask

from .conftest import DATA, SWAT


def _grid(rows, cols):
    yy, xx = np.mgrid[0:rows, 0:cols]
    return jnp.asarray(np.column_stack([xx.ravel(), yy.ravel()]), dtype=jnp.float64)


def test_float64_is_on():
    assert jnp.zeros(1).dtype == jnp.float64


def test_gradient_matches_finite_differences():
    pts = _grid(40, 50)
    target = jnp.asarray(
        rasterise_polygon(np.array([[8.5, 6.5], [40.5, 9.5], [37.5, 33.5], [10.5, 30.5]]), (40, 50)).ravel(),
        dtype=jnp.float64,
    )
    w = jnp.ones(pts.shape[0])
    verts = jnp.asarray([[9.3, 7.1], [39.2, 10.4], [36.1, 32.2], [11.7, 29.3], [9.9, 18.8]])

    def f(v):
        return soft_dice(v, pts, target, w, 1.3)

    g = np.asarray(jax.grad(f)(verts))
    h = 1e-6
    fd = np.zeros_like(g)
    for i in range(verts.shape[0]):
        for j in range(2):
            e = np.zeros(verts.shape)
            e[i, j] = h
            fd[i, j] = (f(verts + e) - f(verts - e)) / (2 * h)
    assert np.abs(g).max() > 1e-4  # a real gradient, not a flat one
    np.testing.assert_allclose(g, fd, rtol=1e-5, atol=1e-9)


def test_exact_polygon_has_near_zero_gradient():
    pts = _grid(40, 60)
    rect = np.array([[9.5, 7.5], [49.5, 7.5], [49.5, 29.5], [9.5, 29.5]])  # crack outline of a pixel rectangle
    target = jnp.asarray(rasterise_polygon(rect, (40, 60)).ravel(), dtype=jnp.float64)
    w = jnp.ones(pts.shape[0])

    def f(v):
        return soft_dice(v, pts, target, w, 0.1)

    g_exact = np.abs(np.asarray(jax.grad(f)(jnp.asarray(rect)))).max()
    g_off = np.abs(np.asarray(jax.grad(f)(jnp.asarray(rect + [[1.3, 0.0], [0, -1.1], [0, 0], [0.7, 0.9]])))).max()
    # at temperature tau the residual slope is about (FP + FN) / (|P| + |M|) of a unit one, with
    # FP + FN ~ perimeter x sigmoid(-0.5 / tau): far below the slope one pixel off
    assert g_exact < 1e-2 * g_off


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_soft_dice_tends_to_hard_dice(seed):
    rng = np.random.default_rng(seed)
    pts = _grid(50, 50)
    t = np.linspace(0, 2 * np.pi, 7, endpoint=False)
    verts = np.column_stack([25 + 15 * np.cos(t), 25 + 12 * np.sin(t)]) + rng.uniform(-2, 2, (7, 2)) + 0.37
    target = jnp.asarray(rasterise_polygon(verts + 1.5, (50, 50)).ravel(), dtype=jnp.float64)
    w = jnp.ones(2500)
    hard = float(hard_dice_points(jnp.asarray(verts), pts, target, w))
    gaps = [
        abs(float(soft_dice(jnp.asarray(verts), pts, target, w, tau)) - hard) for tau in (1.0, 0.1, 0.01, 1e-3, 1e-5)
    ]
    assert gaps[-1] < 1e-4
    assert all(a >= b - 1e-12 for a, b in zip(gaps, gaps[1:]))


@pytest.fixture(scope="module")
def stone_wall():
    m = read_mask(DATA / "stylite" / "masks" / "north.png")
    return m, label_bricks(m)


def test_refined_never_worse_no_overlap(stone_wall):
    m, labels = stone_wall
    res = trace_mask(m, TraceConfig(vertices=5, refine=RefineConfig()))
    assert all(b.dice >= b.dice_splitting for b in res.bricks)
    assert res.mean_dice > res.mean_dice_splitting + 0.005
    # every brick keeps its solver's status (FitStatus values), and it is in polygons.json
    statuses = [b.solver_status for b in res.bricks]
    assert set(statuses) <= {"converged", "step_limit"}  # the annealing stages stop at their step cap
    assert all(row["solver_status"] in statuses for row in res.to_json()["bricks"])
    geoms = [shapely.Polygon(b.vertices_xy) for b in res.bricks]
    assert all(g.is_valid for g in geoms)
    tree = shapely.STRtree(geoms)
    left, right = tree.query(geoms, predicate="intersects")
    worst = max((geoms[i].intersection(geoms[j]).area for i, j in zip(left, right) if i < j), default=0.0)
    assert worst <= 1e-9


def test_refine_stays_in_own_half_of_mortar():
    # two bricks 2 px apart: refinement must not cross the middle of the joint
    m = np.zeros((30, 60), bool)
    m[5:25, 5:29] = True
    m[5:25, 31:55] = True
    res = trace_mask(m, TraceConfig(vertices=4, refine=RefineConfig()))
    left, right = sorted(res.bricks, key=lambda b: b.vertices_xy[:, 0].min())
    assert left.vertices_xy[:, 0].max() <= 30.0 + 1e-6
    assert right.vertices_xy[:, 0].min() >= 30.0 - 1e-6
    assert left.dice == 1.0 and right.dice == 1.0


def test_target_dice_mode_needs_no_more_vertices(stone_wall):
    m, _ = stone_wall
    plain = trace_mask(m, TraceConfig(vertices=None, target_dice=0.99))
    refined = trace_mask(m, TraceConfig(vertices=None, target_dice=0.99, refine=RefineConfig()))
    n_plain = np.mean([len(b.vertices_xy) for b in plain.bricks])
    n_ref = np.mean([len(b.vertices_xy) for b in refined.bricks])
    assert n_ref < n_plain
    assert np.mean([b.dice >= 0.99 for b in refined.bricks]) >= np.mean([b.dice >= 0.99 for b in plain.bricks])


@pytest.mark.slow
def test_swat_refined_targets():
    m = read_mask(SWAT)
    at = {n: trace_mask(m, TraceConfig(vertices=n, refine=RefineConfig())) for n in (5, 6, 8)}
    assert at[8].mean_dice >= 0.99
    assert at[5].mean_dice >= 0.97
    assert at[6].mean_dice >= 0.984  # so the fewest vertices reaching mean Dice 0.984 is at most 6
    for r in at.values():
        assert all(b.dice >= b.dice_splitting for b in r.bricks)


@pytest.mark.slow
def test_stylite_refined_truth_dice_per_wall(tmp_path):
    from dataclasses import replace

    from calib_masonry.build_folder import build_to_folder
    from calib_masonry.comparison import compare_dirs
    from calib_masonry.spec import load_structure

    spec = load_structure(DATA / "stylite" / "structure.toml")
    build_to_folder(spec, tmp_path / "split", figures=False, progress=False)
    ref = replace(spec, refine=True, walls=tuple(replace(w, refine=True) for w in spec.walls))
    build_to_folder(ref, tmp_path / "ref", figures=False, progress=False)
    a = compare_dirs(tmp_path / "split", DATA / "stylite" / "truth")
    b = compare_dirs(tmp_path / "ref", DATA / "stylite" / "truth")
    for wa, wb in zip(a["walls"], b["walls"]):
        assert wb["dice"]["mean"] >= wa["dice"]["mean"]
    assert b["precision"] == 1.0 and b["recall"] == 1.0
    assert b["max_interpenetration_m3"] <= 1e-9


def _pooled(rng, lanes, sizes, block, length):
    """Random bricks (hexagons against rectangles) laid out in a pool as _run_jobs lays them."""
    angle = np.linspace(0, 2 * np.pi, 6, endpoint=False)
    p0 = np.stack([8 * np.cos(angle), 6 * np.sin(angle)], -1)[None] + rng.normal(0, 1, (lanes, 6, 2))
    pool_pts = np.full((length, 2), 1e4)
    pool_coef = np.zeros((3, length))
    off, nblk, m = np.zeros(lanes, np.int32), np.zeros(lanes, np.int32), np.zeros(lanes)
    at = 0
    for r, k in enumerate(sizes):
        pts = rng.uniform(-12, 12, (k, 2))
        t = ((np.abs(pts[:, 0]) < 7) & (np.abs(pts[:, 1]) < 5)).astype(float)
        f = (pts[:, 0] > 10).astype(float)
        pool_pts[at : at + k] = pts
        pool_coef[:, at : at + k] = t, np.ones(k), f
        off[r], nblk[r], m[r] = at, -(-k // block), t.sum()
        at += block * nblk[r]
    return p0, pool_pts, pool_coef, off, nblk, m


def test_pooled_loss_and_gradient_are_the_direct_soft_dice_loss():
    # the block loop (any brick size, one program) and its written-out Jacobian must give the
    # loss of the whole band at once and the gradient reverse-mode differentiation gives
    import calib_masonry.wall2d.refine_kernel as refine

    rng = np.random.default_rng(5)
    p0, pool_pts, pool_coef, off, nblk, m = _pooled(rng, 2, [700, 300], 128, 2048)
    params = jnp.asarray(np.concatenate([p0[1], p0[1][-1:]]))  # a padded (repeated) last vertex
    n, const, box, tau, penalty = 6, 3.0, jnp.asarray([11.0, 11.0]), 0.8, 4.0
    pts = jnp.asarray(pool_pts[off[1] : off[1] + 300])
    wt, w, wf = (jnp.asarray(c) for c in pool_coef[:, off[1] : off[1] + 300])

    def direct(x):
        v = refine._vertices(x, n)
        p = refine.soft_inside(pts, v, tau)
        dice = 2.0 * (wt @ p + const) / (w @ p + const + m[1])
        outside = jnp.maximum(jnp.abs(v) - box, 0.0)
        return m[1] * (1.0 - dice) + penalty * (wf @ p) + 100.0 * penalty * jnp.sum(outside**2)

    args = (n, jnp.asarray(pool_pts), jnp.asarray(pool_coef), off[1], nblk[1], m[1], const, box, tau, penalty, 128)
    assert np.isclose(refine._loss(params, args), direct(params), rtol=1e-12)
    g = jax.grad(refine._loss)(params, args)
    assert np.allclose(g, jax.grad(direct)(params), rtol=1e-9, atol=1e-9)
    assert np.abs(g).max() > 1e-3  # not a trivially flat start


def test_the_precompiled_batch_solver_is_the_jitted_function_bit_for_bit(tmp_path, monkeypatch):
    # the refinement calls its batch solver exported once for any batch and pool size, through
    # programs compiled ahead of time per shape and kept on disk; for two shapes, compiled here
    # and read back from the files (in a fresh solver object), it must give exactly what jit gives
    from functools import partial

    import calib_masonry.wall2d.refine_kernel as refine

    monkeypatch.setenv("CALIB_MASONRY_CACHE", str(tmp_path))
    refine._batch_solver.cache_clear()
    rng = np.random.default_rng(3)
    taus = jnp.asarray([1.5, 0.35])
    direct = jax.jit(partial(refine._refine_batch, max_steps=12, rtol=1e-6, atol=1e-4, block=64))
    shapes = [(2, [96, 150], 512), (3, [160, 40, 0], 1024)]
    for lanes, sizes, length in shapes:
        p0, pool_pts, pool_coef, off, nblk, m = _pooled(rng, lanes, sizes, 64, length)
        args = (
            jnp.asarray(p0),
            jnp.full(lanes, 6, dtype=jnp.int32),
            jnp.asarray(pool_pts),
            jnp.asarray(pool_coef),
            jnp.asarray(off),
            jnp.asarray(nblk),
            jnp.asarray(m),
            jnp.zeros(lanes),
            jnp.full((lanes, 2), 12.0),
            jnp.asarray(1.0),
            taus,
        )
        expect = [np.asarray(a) for a in direct(*args)]
        assert np.abs(expect[0] - p0).max() > 0.1  # the solver moved the vertices
        for fresh in (False, True):
            if fresh:  # from the files written by the first call
                refine._batch_solver.cache_clear()
            solver = refine._batch_solver(6, 2, 12, 1e-6, 1e-4, "float64", 64)
            got = solver(*args)
            assert all(np.array_equal(np.asarray(g), e) for g, e in zip(got, expect))
            assert solver._jitted is None or not fresh  # read from disk: nothing exported or lowered
    assert len(list(tmp_path.glob("refine-*.jaxexport"))) == 1
    programs = sorted(tmp_path.glob("refine-*.xlaexe"))
    assert len(programs) == len(shapes)
    # a broken program file (here: the other shape's program) is compiled anew, and still exact
    blobs = [p.read_bytes() for p in programs]
    programs[0].write_bytes(blobs[1])
    programs[1].write_bytes(blobs[0])
    refine._batch_solver.cache_clear()
    got = refine._batch_solver(6, 2, 12, 1e-6, 1e-4, "float64", 64)(*args)
    assert all(np.array_equal(np.asarray(g), e) for g, e in zip(got, expect))
    now = {p.name: p.read_bytes() for p in programs}
    assert sum(now[p.name] not in blobs for p in programs) == 1  # the one read was compiled anew
    refine._batch_solver.cache_clear()


def test_the_cache_folder_is_kept_under_its_size(tmp_path, monkeypatch):
    # every change to a traced module or a version bump leaves a new export and new programs, and
    # every program compiled leaves an entry in JAX's compilation cache under a key never used
    # again: the folder grew without end (8.5 MB and 12 programs after one session's work). Past
    # its size the files used longest ago go (a file of ours is touched when read), the one just
    # written never; a .tmp an hour old (a process killed while writing) goes at once
    import os
    import time

    from calib_masonry import _jax

    now = time.time()
    ages = {"a.xlaexe": 3000, "b-cache": 2000, "c.jaxexport": 1000, "d.xlaexe": 10, "kept.xlaexe": 9000}
    for name, age in ages.items():
        (tmp_path / name).write_bytes(b"x" * 600_000)
        os.utime(tmp_path / name, (now - age, now - age))
    for name, age in (("old.123.tmp", 7200), ("new.124.tmp", 10)):
        (tmp_path / name).write_bytes(b"")
        os.utime(tmp_path / name, (now - age, now - age))
    # 3.0 MB in five files, a cap of 2.4 MB: down to 1.8 MB, the oldest first, "kept" kept
    assert _jax.tidy(tmp_path, 2.4 / 1.048576, keep=(tmp_path / "kept.xlaexe",)) == 3
    assert sorted(p.name for p in tmp_path.iterdir()) == ["c.jaxexport", "d.xlaexe", "kept.xlaexe", "new.124.tmp"]
    assert _jax.tidy(tmp_path, 100.0) == 0  # under the cap: nothing goes

    # a program read from the folder is marked used (so that tidy keeps it over older ones)
    import calib_masonry.wall2d.refine_kernel as refine

    cache = tmp_path / "cache"
    monkeypatch.setenv("CALIB_MASONRY_CACHE", str(cache))
    refine._batch_solver.cache_clear()
    rng = np.random.default_rng(4)
    p0, pool_pts, pool_coef, off, nblk, m = _pooled(rng, 2, [96, 150], 64, 512)
    args = [p0, np.full(2, 6, dtype=np.int32), pool_pts, pool_coef, off, nblk, m]
    args += [np.zeros(2), np.full((2, 2), 12.0), np.asarray(1.0), np.asarray([1.5, 0.35])]
    refine._batch_solver(6, 2, 12, 1e-6, 1e-4, "float64", 64).load(*args)
    (program,) = cache.glob("refine-*.xlaexe")
    os.utime(program, (now - 86400, now - 86400))
    refine._batch_solver.cache_clear()
    refine._batch_solver(6, 2, 12, 1e-6, 1e-4, "float64", 64).load(*args)
    assert program.stat().st_mtime > now - 60
    refine._batch_solver.cache_clear()


_IN_SOLVER_PROCESS = r"""
import json, sys
from calib_masonry.io import read_mask
from calib_masonry.wall2d import refine
from calib_masonry.wall2d.trace import TraceConfig, trace_mask
with refine.solver_process(refine.RefineConfig(), 5):
    assert refine._HELPER is not None, "no solver process"
    if sys.argv[2] == "killed":  # the solver process dies: the refinement is solved here instead
        refine._HELPER._proc.kill()
    res = trace_mask(read_mask(sys.argv[1]), TraceConfig(vertices=5, refine=refine.RefineConfig()))
    assert ("jax" in sys.modules) == (sys.argv[2] == "killed"), "solved in the wrong process"
print(json.dumps([b.vertices_xy.tolist() for b in res.bricks]))
"""


def test_the_solver_process_gives_the_local_refinement_bit_for_bit(stone_wall):
    # trace --refine forks a process that loads JAX while this one traces and prepares: the
    # polygons must be exactly those of the refinement solved in this process, and if that
    # process dies, the refinement is solved here, with the same polygons
    import subprocess
    import sys

    mask = DATA / "stylite" / "masks" / "north.png"
    here = trace_mask(stone_wall[0], TraceConfig(vertices=5, refine=RefineConfig()))
    for how in ("there", "killed"):
        cmd = [sys.executable, "-c", _IN_SOLVER_PROCESS, str(mask), how]
        r = subprocess.run(cmd, capture_output=True, text=True)
        assert r.returncode == 0, r.stderr
        there = json.loads(r.stdout.splitlines()[-1])
        assert len(there) == len(here.bricks)
        assert all(np.array_equal(np.asarray(v), b.vertices_xy) for v, b in zip(there, here.bricks))


def test_no_solver_process_where_jax_is_loaded_or_threads_run():
    # a fork copies only the calling thread, and JAX's own threads would not survive it
    from calib_masonry.wall2d import refine

    with refine.solver_process():
        assert refine._HELPER is None  # this test process has JAX loaded


def test_a_cache_size_that_is_no_size_is_named_once_and_the_default_used(monkeypatch):
    import warnings

    from calib_masonry import _jax

    monkeypatch.setattr(_jax, "_WARNED_LIMIT", set())
    for raw, want in (("1024", 1024.0), ("0", 0.0), ("", _jax.CACHE_MAX_MB)):
        monkeypatch.setenv("CALIB_MASONRY_CACHE_MB", raw)
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # a good value warns of nothing
            assert _jax.cache_limit_mb() == want
    monkeypatch.delenv("CALIB_MASONRY_CACHE_MB")
    assert _jax.cache_limit_mb() == _jax.CACHE_MAX_MB
    for raw in ("1 GB", "-5", "nan"):
        monkeypatch.setenv("CALIB_MASONRY_CACHE_MB", raw)
        with pytest.warns(RuntimeWarning, match=r"CALIB_MASONRY_CACHE_MB=.* is not a size in megabytes"):
            assert _jax.cache_limit_mb() == _jax.CACHE_MAX_MB
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # named once
            assert _jax.cache_limit_mb() == _jax.CACHE_MAX_MB


def test_target_dice_with_refinement_searches_each_count_in_few_batches(monkeypatch):
    """A target Dice with refinement on round pieces that need many vertices: each piece starts
    at the count whose splitting polygon reaches the target and is bisected down, a few batches in
    all. Counting up from 3 refined every piece once a count (a real stone wall's pieces, up to
    42 vertices: more than 5 minutes); every piece still reaches the target, with no more
    vertices than its splitting polygon needs."""
    from calib_masonry.wall2d import refine

    yy, xx = np.mgrid[0:90, 0:200]
    m = np.hypot(yy - 45, xx - 45) < 38
    m |= np.hypot((yy - 45) / 0.8, xx - 145) < 40
    calls = []
    real = refine.refine_polygons

    def spy(*args, **kwargs):
        calls.append(len(args[1]))
        return real(*args, **kwargs)

    monkeypatch.setattr(refine, "refine_polygons", spy)
    plain = trace_mask(m, TraceConfig(target_dice=0.995))
    refined = trace_mask(m, TraceConfig(target_dice=0.995, refine=RefineConfig()))
    n_plain = [len(b.vertices_xy) for b in plain.bricks]
    assert min(n_plain) >= 12  # round: many vertices
    assert all(b.dice >= 0.995 for b in refined.bricks)
    assert all(len(r.vertices_xy) <= n for r, n in zip(refined.bricks, n_plain))
    assert len(calls) <= 1 + int(np.ceil(np.log2(max(n_plain)))) < max(n_plain) - 3

"""The seams between the stages, read from the source: bpy's adapter holds Blender calls only, the
stepping loop runs without Blender, experiments use public names, and the modules' imports (at
the top or inside a function) form no cycle."""

from __future__ import annotations

import ast
from pathlib import Path

import numpy as np
import pytest

from .conftest import ROOT

SRC = ROOT / "src" / "calib_masonry"


def _module_name(path: Path) -> str:
    parts = path.relative_to(SRC.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


MODULES = {_module_name(p): p for p in SRC.rglob("*.py")}


def _imports(name: str) -> set[str]:
    """The modules of the package that module ``name`` imports anywhere in its source (a lazy
    import inside a function counts: it ties the two modules as much)."""
    path = MODULES[name]
    package = name.split(".") if path.name == "__init__.py" else name.split(".")[:-1]
    out: set[str] = set()
    tree = ast.parse(path.read_text())
    typing_only = {  # imports under `if TYPE_CHECKING:` are for annotations, never run
        id(n)
        for block in ast.walk(tree)
        if isinstance(block, ast.If) and ast.unparse(block.test) in ("TYPE_CHECKING", "typing.TYPE_CHECKING")
        for stmt in block.body
        for n in ast.walk(stmt)
    }
    for node in ast.walk(tree):
        if id(node) in typing_only:
            continue
        if isinstance(node, ast.ImportFrom):
            base = package[: len(package) - node.level + 1] if node.level else []
            stem = ".".join(base + ([node.module] if node.module else []))
            for alias in node.names:
                full = f"{stem}.{alias.name}"
                if full in MODULES:
                    out.add(full)
                elif stem in MODULES:
                    out.add(stem)
        elif isinstance(node, ast.Import):
            out.update(a.name for a in node.names if a.name in MODULES)
    out.discard(name)
    out.discard("calib_masonry")  # the package's own __init__: a re-export list, imported by none of its modules
    return out


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    found: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                found.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


def test_the_cycle_finder_finds_a_cycle():
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert _cycles({"a": {"b"}, "b": set()}) == []


def test_no_import_cycle_in_src():
    graph = {m: _imports(m) for m in MODULES if m != "calib_masonry"}
    assert _cycles(graph) == []


def test_pipeline_imports_nothing_from_simulation():
    assert not {m for m in _imports("calib_masonry.pipeline") if m.startswith("calib_masonry.simulation")}


def test_blender_holds_only_blender_calls():
    name = "calib_masonry.simulation.blender"
    tree = ast.parse(MODULES[name].read_text())
    long = [
        (n.name, n.end_lineno - n.lineno + 1)
        for n in ast.walk(tree)
        if isinstance(n, ast.FunctionDef | ast.AsyncFunctionDef) and n.end_lineno - n.lineno + 1 > 80
    ]
    assert long == []
    loop_logic = {f"calib_masonry.simulation.{m}" for m in ("loop", "joints", "pieces", "dynamics", "run", "results")}
    assert not _imports(name) & loop_logic


def test_an_experiment_run_from_its_folder_shadows_no_module_the_package_imports():
    # a script's folder comes first on sys.path: experiments/coverage.py was imported by numba as
    # the coverage package (its optional tracer), and every experiment that moved pieces failed
    import subprocess
    import sys

    code = (
        "import sys; sys.path.insert(0, sys.argv[1]); import numba, calib_masonry.simulation._pieces_step, "
        "calib_masonry.simulation.run"
    )
    r = subprocess.run([sys.executable, "-c", code, str(ROOT / "experiments")], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr[-2000:]


def test_no_experiment_imports_a_private_name():
    private = []
    for path in sorted((ROOT / "experiments").glob("*.py")) + sorted((ROOT / "examples").glob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("calib_masonry"):
                names = [node.module, *(a.name for a in node.names)]
                private += [
                    f"{path.name}: {node.module}.{a}" for a in names if any(p.startswith("_") for p in a.split("."))
                ]
    assert private == []


class _StillEngine:
    """An engine in which nothing moves: every body stays at its initial pose. It records what the
    loop asks of it."""

    def __init__(self, scene, fixed, gravity):
        self.scene, self.gravity = scene, gravity
        self.calls: list[tuple] = []
        self.velocities: list = []  # set_free's velocity argument, call by call

    def step_to(self, frame):
        self.calls.append(("step", frame))

    def read_poses(self, out):
        out[:] = np.eye(4, dtype=np.float32)
        out[:, :3, 3] = [b.location for b in self.scene.bodies]
        return np.zeros(3)

    def end_warmup(self):
        self.calls.append(("end_warmup",))

    def switch_off(self, bonds):
        self.calls.append(("off", tuple(int(k) for k in bonds)))

    def set_free(self, bodies, bonds, velocity=None):
        self.calls.append(("free", tuple(int(j) for j in bodies), tuple(int(k) for k in bonds)))
        self.velocities.append(velocity)

    def save(self, path, frames, freed_at):
        raise AssertionError("not asked to save")


def _shaken_stack(material):
    from calib_masonry.simulation.ground_motion import G, constant_acceleration
    from calib_masonry.simulation.scene import Body, Bond, Scene, SolverSettings, box_mesh

    size = (0.3, 0.2, 0.15)
    v, f = box_mesh(size)
    vol = float(np.prod(size))
    bodies = tuple(
        Body(f"b{k}", v, f, np.array([0.0, 0.0, 0.075 + 0.15 * k]), 1800 * vol, 0.6**0.5, 0.0, vol) for k in range(4)
    )
    bonds = tuple(Bond.rectangle(k, k - 1, (0, 0, 0.15 * k), (0, 0, 1.0), (1.0, 0, 0), 0.3, 0.2) for k in range(4))
    motion = constant_acceleration(0.4 * G, 0.6, dt=0.001)
    return Scene(
        bodies=bodies,
        bonds=bonds,
        duration_s=0.6,
        solver=SolverSettings(warmup_s=0.2),
        motion=motion,
        material=material,
    )


@pytest.mark.parametrize("weak", [False, True])
def test_the_loop_drives_any_engine(weak):
    # the stepping loop (simulation/loop.py) asks the engine for what the joint model decides, in
    # order, without Blender: a stack shaken below its mortar's strength is never let go; with a
    # weak mortar, every joint the run reports as let go was switched off in the engine at its
    # frame, and the part above it set free there
    from calib_masonry.simulation.loop import drain, steps
    from calib_masonry.simulation.scene import Material

    material = Material(tensile_strength=2e3, shear_strength=2e3) if weak else Material()
    scene = _shaken_stack(material)
    engines: list[_StillEngine] = []

    def build(*args):
        engines.append(_StillEngine(*args))
        return engines[-1]

    out = drain(steps(scene, progress=False, engine=build))
    calls = engines[0].calls
    s = scene.solver
    assert [c[1] for c in calls if c[0] == "step"] == list(range(scene.frames + 1))
    assert calls.count(("end_warmup",)) == 1
    assert engines[0].gravity[-1, 0] == pytest.approx(-0.4 * 9.81, rel=0.02)
    released = np.flatnonzero(np.isfinite(out.bond_release_time_s))
    off = sorted(k for c in calls if c[0] == "off" for k in c[1])
    assert off == sorted(released.tolist())
    if not weak:
        assert released.size == 0 and not any(c[0] == "free" for c in calls)
        return
    assert released.size > 0
    # the frame before which each joint went off: its release time on the frame grid after the warm-up
    step_before = {}
    frame = 0
    for c in calls:
        if c[0] == "step":
            frame = c[1]
        elif c[0] == "off":
            for k in c[1]:
                step_before[k] = frame + 1
    for k in released:
        assert step_before[int(k)] == s.warmup_frames + round(out.bond_release_time_s[k] * s.fps) + 1
    freed = {j for c in calls if c[0] == "free" for j in c[1]}
    lowest = min(scene.bonds[k].a for k in released)
    assert freed == set(range(lowest, len(scene.bodies)))
    # under a ground motion (the default elastic dynamics) the engine sets each part free with the
    # velocities the vibration gave its bodies, the ones the run reports, or from rest (None, NaN
    # in the run's record) where they are zero: the step load cracks the weak stack at once
    frees = [c for c in calls if c[0] == "free"]
    assert len(frees) == len(engines[0].velocities) > 0
    for c, v in zip(frees, engines[0].velocities):
        rows = out.freed_velocity[list(c[1])]
        if v is None:
            assert np.isnan(rows).all()
        else:
            assert v.shape == (len(c[1]), 6) and np.isfinite(v).all() and np.array_equal(rows, v)


def test_a_wait_for_the_pieces_after_the_engine_shows_its_progress(monkeypatch, capsys):
    # under a ground motion the joint model's thread moves the verdict's pieces once its checks are
    # done; when the engine has finished first, the wait for them is a long step like any other: a
    # log line (here at every update) with the frames the pieces have reached, and a last one
    import time

    from calib_masonry import progress as progress_module
    from calib_masonry.simulation import loop
    from calib_masonry.simulation.scene import Material

    monkeypatch.setattr(progress_module, "LOG_EVERY_S", 0.0)
    real = loop.piece_motion

    def slow(scene, release, times, *, reached=None, **kw):  # the real motion, reported slowly
        out = real(scene, release, times, reached=reached, **kw)
        for t in np.linspace(0.0, times[-1], 4):
            reached(float(t))
            time.sleep(0.4)
        return out

    monkeypatch.setattr(loop, "piece_motion", slow)
    scene = _shaken_stack(Material(tensile_strength=2e3, shear_strength=2e3))
    out = loop.drain(loop.steps(scene, progress=None, engine=_StillEngine))
    assert out.pieces is not None and out.pieces.pieces > 0
    lines = [line for line in capsys.readouterr().err.splitlines() if line.startswith("pieces:")]
    frames = len(out.pieces.time_s)
    assert len(lines) >= 3, lines
    assert lines[-1].startswith(f"pieces: {frames}/{frames} frames") and lines[-1].endswith("done"), lines


def test_a_long_check_shows_its_crack_rounds_in_the_progress(monkeypatch, capsys):
    # the scale tower's first cracking frame took 400 s (one of its checks 39 crack rounds) under
    # a line that said only "24/38 frames": the line now says what the check is doing, the record's
    # time it checks, its crack round and the joints cracked so far, and forgets it once it is done
    import re
    import time

    from calib_masonry import progress as progress_module
    from calib_masonry.simulation import loop
    from calib_masonry.simulation.joints import JointModel
    from calib_masonry.simulation.scene import Material

    monkeypatch.setattr(progress_module, "LOG_EVERY_S", 0.0)
    real = JointModel.solve

    def slow(self, *args, **kwargs):
        if self.crack_round:  # a crack round's solve, after the check's first one
            time.sleep(0.6)
        return real(self, *args, **kwargs)

    monkeypatch.setattr(JointModel, "solve", slow)
    scene = _shaken_stack(Material(tensile_strength=2e3, shear_strength=2e3))
    out = loop.drain(loop.steps(scene, progress=None, engine=_StillEngine))
    lines = capsys.readouterr().err.splitlines()
    rounds = [
        (float(m.group(1)), int(m.group(2)), int(m.group(3)))
        for line in lines
        if (m := re.search(r"checking the joints at (\d+\.\d{3}) s: crack round (\d+), (\d+) joints? cracked$", line))
    ]
    assert rounds, lines
    # the frames' pace says nothing of how long the check will take: no time left is made up
    assert all("time left not known;" in line for line in lines if "crack round" in line), lines
    cracked = np.isfinite(out.bond_break_time_s)
    for t, r, n in rounds:
        # the check's time is one at which joints cracked, and no more had cracked by its end
        assert r >= 1 and 1 <= n <= cracked.sum()
        assert np.isclose(out.bond_break_time_s[cracked], t, atol=1e-9).any()
    assert "checking the joints" not in lines[-1]


def test_a_long_check_of_the_joint_model_keeps_the_progress_going(monkeypatch, capsys):
    # one check of the joint model can take minutes (a crack cascade on thousands of joints): the
    # frames' progress goes on showing while the loop waits for it (a line every LOG_EVERY_S in a
    # log, here at every poll), instead of falling silent until the frame is done
    import re
    import time

    from calib_masonry import progress as progress_module
    from calib_masonry.simulation import loop, tracker
    from calib_masonry.simulation.scene import Material

    monkeypatch.setattr(progress_module, "LOG_EVERY_S", 0.0)
    real = tracker.CrackTracker.step
    calls = []

    def slow(self, *args, **kwargs):
        calls.append(1)
        if len(calls) == 3:
            time.sleep(1.0)
        return real(self, *args, **kwargs)

    monkeypatch.setattr(tracker.CrackTracker, "step", slow)
    loop.drain(loop.steps(_shaken_stack(Material()), progress=None, engine=_StillEngine))
    lines = [line for line in capsys.readouterr().err.splitlines() if not line.endswith("done")]
    done = [int(m.group(1)) for line in lines if (m := re.match(r"simulate: (\d+)/\d+ frames", line))]
    assert len(calls) > 3
    assert len(done) > len(set(done)), "no line while a frame waited for its check"

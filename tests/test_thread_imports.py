"""No module is imported for the first time on one of the library's own threads.

Two threads importing modules of one package at once can deadlock or see a module half
initialised in CPython 3.11's import locks (gh-83065; an earlier session saw matplotlib's
``rcParams`` missing). So every place that starts a thread imports, on the calling thread and
before the start, what the thread will import. This runs the commands that use threads (synth
--photos, build from photos with figures, model.blend and the simulation geometry, simulate with
its joint model's thread) in a fresh interpreter that records every import by thread (the
``import`` audit event is raised only for a module not yet in ``sys.modules``).
"""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from .conftest import scenario_text

CHILD = r"""
import json, sys, threading
from calib_masonry.cli import main

log = []

def hook(event, args):
    if event == "import" and threading.current_thread() is not threading.main_thread():
        log.append([threading.current_thread().name, args[0]])

sys.addaudithook(hook)
out = {}
for argv in json.loads(sys.argv[1]):
    del log[:]
    out[argv[0]] = {"rc": main(argv), "off_main": list(log)}
print("RESULT " + json.dumps(out))
"""


@pytest.mark.slow
def test_threads_import_nothing(tmp_path):
    sc = tmp_path / "scenario.toml"
    extra = "\n[photos]\nlong_side_px = 1500\nshort_side_px = 1000\n"
    sc.write_text(scenario_text([(2.4, 2.0, 0.0), (2.0, 2.0, 90.0)], seed=4343, px_per_m=200, extra=extra))
    data, built, sim = tmp_path / "data", tmp_path / "built", tmp_path / "sim"
    commands = [
        ["synth", str(sc), "--photos", "--out", str(data)],
        ["build", str(data / "structure_photos.toml"), "--out", str(built)],
        ["simulate", str(built), "--duration", "0.4", "--out", str(sim)],
    ]
    r = subprocess.run([sys.executable, "-c", CHILD, json.dumps(commands)], capture_output=True, text=True, timeout=900)
    assert r.returncode == 0, r.stderr[-3000:]
    result = json.loads(r.stdout.split("RESULT ", 1)[1])
    for command, got in result.items():
        assert got["rc"] == 0, (command, r.stderr[-3000:])
        assert got["off_main"] == [], f"{command}: imported on a worker thread first: {got['off_main'][:20]}"
    # the command line's build computes the simulation geometry in a process of its own; the
    # library's computes it in this one, its walls on two threads: in a fresh interpreter that
    # does only that, nothing is imported first on those threads either
    r = subprocess.run([sys.executable, "-c", GEOMETRY_CHILD, str(built)], capture_output=True, text=True, timeout=900)
    assert r.returncode == 0, r.stderr[-3000:]
    got = json.loads(r.stdout.split("RESULT ", 1)[1])
    assert got["bodies"] > 0
    assert got["off_main"] == [], f"geometry: imported on a worker thread first: {got['off_main'][:20]}"


GEOMETRY_CHILD = r"""
import json, sys, threading
from calib_masonry.build_folder import read_build, simulation_geometry

structure = read_build(sys.argv[1])
log = []

def hook(event, args):
    if event == "import" and threading.current_thread() is not threading.main_thread():
        log.append([threading.current_thread().name, args[0]])

sys.addaudithook(hook)
g = simulation_geometry(structure)
print("RESULT " + json.dumps({"bodies": len(g.names), "off_main": log}))
"""

"""Shared fixtures: small synthetic scenarios written to temporary folders."""

from __future__ import annotations

from pathlib import Path

import pytest

try:  # float64 for every JAX computation a test makes, not only those after calib_masonry._jax was imported
    import jax

    jax.config.update("jax_enable_x64", True)
except ImportError:  # pragma: no cover - the calibration extra is not installed
    pass


def need_bpy(*, module_level: bool = False):
    """Blender's bpy, imported as the library imports it (its task scheduler with one thread, as
    in every command), or skip the test. ``pytest.importorskip("bpy")`` would import it with a
    thread per core into the test process, and every simulation of the run would inherit that."""
    from calib_masonry.errors import BackendMissing
    from calib_masonry.simulation.blender import require_bpy

    try:
        return require_bpy()
    except BackendMissing:
        pytest.skip("Blender's bpy is not installed", allow_module_level=module_level)


ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "data_synthetic"
SWAT = ROOT.parent / "shared" / "data" / "external" / "swat" / "WR2_250_new.png"


def scenario_text(
    walls: list[tuple[float, float, float]],
    *,
    layout: str = "stretcher",
    t: float = 0.18,
    vertices: int = 5,
    px_per_m: float = 200,
    seed: int = 7,
    closed: bool | None = None,
    extra: str = "",
) -> str:
    lines = ["[structure]", 'name = "test"', f"thickness_m = {t}", f"vertices = {vertices}"]
    if closed is not None:
        lines.append(f"closed = {'true' if closed else 'false'}")
    lines += ["", "[synthetic]", f'layout = "{layout}"', f"px_per_m = {px_per_m}", f"seed = {seed}"]
    if layout == "stones":
        lines += ["mortar_m = 0.025", "stone_length_m = [0.55, 0.95]", "stone_height_m = [0.35, 0.55]"]
    lines.append(extra)
    for i, (w, h, th) in enumerate(walls):
        lines += ["", "[[wall]]", f'name = "w{i}"', f"width_m = {w}", f"height_m = {h}", f"theta_deg = {th}"]
    return "\n".join(lines) + "\n"


@pytest.fixture
def make_scenario(tmp_path):
    """Write a scenario and run synth on it; returns the data folder."""
    from calib_masonry.spec import load_structure
    from calib_masonry.synthetic.truth import synthesize_to_folder

    def make(walls, name="data", **kw) -> Path:
        sc = tmp_path / f"{name}_scenario.toml"
        sc.write_text(scenario_text(walls, **kw))
        out = tmp_path / name
        synthesize_to_folder(load_structure(sc, require_sources=False), out, figures=False)
        return out

    return make

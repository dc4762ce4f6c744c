"""Benchmark: automatic rectification of tall, narrow walls rendered by Blender (Cycles), not by the
project's photo generator.

The walls are those of experiments/bench_tall_walls.py (the same seeds give the same stones, 2.0-3.2 m
wide and 4-6.5 times as high), but nothing of the project's camera, projection, resampling,
lighting, sky or ground takes part in the photo: the stone texture (the project's orthophoto of
the wall's face, 200 px/m) is mapped onto the front of a 0.4 m thick box, lit by a sun and a sky,
standing on a ground plane with a procedural texture, and photographed by a Blender camera
(portrait 1334 x 2000 px, 24-32 mm on a 36 mm sensor, eye 1.5-1.8 m, yaw up to 35 degrees either
side, aimed at the wall's middle, as far back as the whole wall needs, with 6 % of the frame to
spare), rendered by Cycles (path tracing, 16 samples: its noise is the sensor's) and saved as a
JPEG. Blender's own pinhole gives the focal length in pixels; its world coordinates give the eye
height above the wall's base. The wall's side faces show at an angle, as a real wall's do.

A case succeeds, as in bench_tall_walls.py, when the automatic calibration (focal length and eye
height given, as EXIF and a tape would) converges with W and H within 2 % of the truth. Printed: a
row per wall (with the W error in the fit's own sigma, z), then the count (aim: 18 of 20), how many
failures name the flag to add, and how many failures were overconfident (|z| above 2).

    .venv/bin/python experiments/bench_tall_walls_blender.py [--first 12001 --count 20] [--keep DIR]
"""

from __future__ import annotations

import argparse
import math
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
RES = (1334, 2000)  # portrait, px
SENSOR_MM = 36.0  # along the long side
THICKNESS_M = 0.4
TEXTURE_PX_PER_M = 200.0
OVERHEAD_SUN = False  # --overhead-sun


def textured_wall(scenario: str, name: str, width: float, height: float, seed: int, px_per_m: float, rng):
    """The first wall of ``data_synthetic/<scenario>/scenario.toml`` made ``width`` x ``height`` m
    and named ``name``, its units drawn by the project's generator with ``seed``, and its face's
    texture ``(rows, cols, 3)`` at ``px_per_m`` (colours drawn from ``rng``)."""
    import calib_masonry as cm
    from calib_masonry.synthetic.photo import wall_texture

    base = cm.load_structure(ROOT / "data_synthetic" / scenario / "scenario.toml", require_sources=False)
    wall = replace(base.walls[0], name=name, width_m=width, height_m=height)
    pieces, _ = cm.truth_structure(
        replace(base, walls=(wall,), closed=False, synthetic=replace(base.synthetic, seed=seed))
    )
    return wall, wall_texture(wall, pieces[0], px_per_m, rng)


def wall_and_texture(seed: int):
    """The seed's wall (as bench_tall_walls.py draws it) and its face's texture (rows, cols, 3)."""
    rng = np.random.default_rng(seed)
    width = float(rng.uniform(2.0, 3.2))
    height = float(width * rng.uniform(4.0, 6.5))
    return textured_wall("stylite", f"tall{seed}", width, height, seed, TEXTURE_PX_PER_M, rng)


def look_at(eye: np.ndarray, target: np.ndarray) -> np.ndarray:
    """World -> camera rotation (rows: camera x right, y down, z forward) of a camera at ``eye``
    looking at ``target`` with no roll."""
    z = target - eye
    z /= np.linalg.norm(z)
    x = np.cross(z, [0.0, 0.0, 1.0])
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    return np.stack([x, y, z])


def framing(box: np.ndarray, target: np.ndarray, eye_h: float, yaw: float, f_px: float, res, spare: float, near: float):
    """``(eye, distance)``: the camera ``eye_h`` m high, turned ``yaw`` (rad) from square on to the
    wall's plane y = 0, aimed at ``target``, at the smallest distance from ``near`` m (in 0.25 m
    steps, from ``target``'s x) at which every point of ``box`` ``(n, 3)`` lies inside a
    ``res`` px frame with ``spare`` of it to spare on every side."""
    for d in np.arange(near, near + 300.0, 0.25):
        eye = np.array([target[0] + d * math.sin(yaw), -d * math.cos(yaw), eye_h])
        r = look_at(eye, target)
        cam = (box - eye) @ r.T
        if np.any(cam[:, 2] <= 0.1):
            continue
        u = f_px * cam[:, 0] / cam[:, 2] + res[0] / 2
        v = f_px * cam[:, 1] / cam[:, 2] + res[1] / 2
        mx, my = spare * res[0], spare * res[1]
        if u.min() > mx and u.max() < res[0] - mx and v.min() > my and v.max() < res[1] - my:
            return eye, d
    raise RuntimeError("no distance frames the wall")


def camera(width: float, height: float, rng: np.random.Generator) -> dict:
    """Eye, focal length and yaw drawn for a wall; the distance the smallest (in 0.25 m steps) at
    which the whole box lies inside the frame with 6 % to spare."""
    eye_h = float(rng.uniform(1.5, 1.8))
    f_mm = float(rng.uniform(24.0, 32.0))
    yaw = math.radians(float(rng.uniform(-35.0, 35.0)))
    f_px = f_mm / SENSOR_MM * max(RES)
    target = np.array([width / 2, 0.0, height / 2])
    box = np.array(
        [[x, y, z] for x in (0.0, width) for y in (0.0, THICKNESS_M) for z in (0.0, height)], dtype=np.float64
    )
    eye, d = framing(box, target, eye_h, yaw, f_px, RES, 0.06, 2.0)
    return {"eye": eye, "target": target, "f_mm": f_mm, "f_px": f_px, "yaw_deg": math.degrees(yaw), "d": d}


def cycles_scene(res: tuple[int, int], rng: np.random.Generator, out: Path):
    """Blender's scene emptied and set to render by Cycles (16 samples, no denoising: its noise is
    the sensor's; its seed drawn from ``rng``) at ``res`` px to the JPEG ``out``."""
    import bpy

    bpy.ops.wm.read_factory_settings(use_empty=True)
    sc = bpy.context.scene
    sc.render.engine = "CYCLES"
    sc.cycles.device = "CPU"
    sc.cycles.samples = 16
    sc.cycles.use_denoising = False
    sc.cycles.max_bounces = 2
    sc.cycles.seed = int(rng.integers(0, 2**31 - 1))
    sc.render.resolution_x, sc.render.resolution_y = res
    sc.render.resolution_percentage = 100
    sc.view_settings.view_transform = "Standard"
    sc.render.image_settings.file_format = "JPEG"
    sc.render.image_settings.quality = 90
    sc.render.filepath = str(out)
    return sc


def packed_image(name: str, texture: np.ndarray):
    """A texture ``(rows, cols, 3)`` in [0, 1] as a Blender image packed in the scene (Blender's
    rows run bottom first)."""
    import bpy

    rows, cols = texture.shape[:2]
    img = bpy.data.images.new(name, cols, rows, alpha=False)
    rgba = np.concatenate([texture[::-1], np.ones((rows, cols, 1), np.float32)], axis=-1).astype(np.float32)
    img.pixels.foreach_set(rgba.ravel())
    img.update()
    img.pack()
    return img


def material(name: str, colour=None, image=None, noise: bool = False, rough: float = 0.9):
    """A Principled material of one ``colour``, the packed ``image`` or (``noise``) a procedural
    mottle of ``colour`` down to 0.6 of it."""
    import bpy

    m = bpy.data.materials.new(name)
    m.use_nodes = True
    nt = m.node_tree
    bsdf = nt.nodes["Principled BSDF"]
    bsdf.inputs["Roughness"].default_value = rough
    if image is not None:
        tex = nt.nodes.new("ShaderNodeTexImage")
        tex.image = image
        tex.interpolation = "Cubic"
        nt.links.new(tex.outputs["Color"], bsdf.inputs["Base Color"])
    elif noise:
        tex = nt.nodes.new("ShaderNodeTexNoise")
        tex.inputs["Scale"].default_value = 40.0
        ramp = nt.nodes.new("ShaderNodeValToRGB")
        ramp.color_ramp.elements[0].color = (*colour, 1.0)
        ramp.color_ramp.elements[1].color = (*(0.6 * np.array(colour)), 1.0)
        nt.links.new(tex.outputs["Fac"], ramp.inputs["Fac"])
        nt.links.new(ramp.outputs["Color"], bsdf.inputs["Base Color"])
    else:
        bsdf.inputs["Base Color"].default_value = (*colour, 1.0)
    return m


def shoot(sc, cam: dict, res: tuple[int, int]) -> None:
    """Blender's camera at ``cam["eye"]`` aimed at ``cam["target"]`` with no roll (:func:`look_at`),
    ``cam["f_mm"]`` on a :data:`SENSOR_MM` sensor along the ``res`` px frame's long side, and the
    scene ``sc`` rendered through it to its file."""
    import bpy
    from mathutils import Matrix

    cam_data = bpy.data.cameras.new("camera")
    if res[0] >= res[1]:
        cam_data.sensor_fit = "HORIZONTAL"
        cam_data.sensor_width = SENSOR_MM
    else:
        cam_data.sensor_fit = "VERTICAL"
        cam_data.sensor_height = SENSOR_MM
    cam_data.lens = cam["f_mm"]
    cam_data.clip_end = 1000.0
    cam_obj = bpy.data.objects.new("camera", cam_data)
    r = look_at(cam["eye"], cam["target"])  # rows: x right, y down, z forward
    # Blender's camera looks along its -Z with +Y up: its axes in the world are x, -y, -z
    m = np.eye(4)
    m[:3, :3] = np.stack([r[0], -r[1], -r[2]], axis=1)
    m[:3, 3] = cam["eye"]
    cam_obj.matrix_world = Matrix(m.tolist())
    sc.collection.objects.link(cam_obj)
    sc.camera = cam_obj
    bpy.ops.render.render(write_still=True)


def render(width: float, height: float, texture: np.ndarray, cam: dict, rng: np.random.Generator, out: Path) -> None:
    """The scene rendered by Cycles to the JPEG ``out``."""
    import bpy

    sc = cycles_scene(RES, rng, out)
    img = packed_image("stones", texture)  # the wall's face

    # the wall: a box, its front (y = 0) carrying the texture, the other faces a strip of it
    w, t, h = width, THICKNESS_M, height
    verts = [(0, 0, 0), (w, 0, 0), (w, 0, h), (0, 0, h), (0, t, 0), (w, t, 0), (w, t, h), (0, t, h)]
    faces = [(0, 1, 2, 3), (1, 5, 6, 2), (5, 4, 7, 6), (4, 0, 3, 7), (3, 2, 6, 7), (4, 5, 1, 0)]
    mesh = bpy.data.meshes.new("wall")
    mesh.from_pydata(verts, [], faces)
    uv = mesh.uv_layers.new(name="uv")
    for poly in mesh.polygons:
        for k, li in enumerate(poly.loop_indices):
            x, _, z = verts[mesh.loops[li].vertex_index]
            if poly.index == 0:
                uv.data[li].uv = (x / w, z / h)
            else:  # the first stones' column, stretched along the thickness
                uv.data[li].uv = (0.02 * (k in (1, 2)), z / h)
    wall = bpy.data.objects.new("wall", mesh)
    wall.data.materials.append(material("stones", image=img))
    sc.collection.objects.link(wall)

    ground_c = tuple(float(v) for v in np.array([0.33, 0.36, 0.25]) * rng.uniform(0.8, 1.2))
    bpy.ops.mesh.primitive_plane_add(size=600.0, location=(w / 2, 0.0, 0.0))
    bpy.context.object.data.materials.append(material("ground", colour=ground_c, noise=True))

    world = bpy.data.worlds.new("sky")
    sc.world = world
    world.use_nodes = True
    bg = world.node_tree.nodes["Background"]
    bg.inputs["Color"].default_value = (*(np.array([0.35, 0.5, 0.85]) * rng.uniform(0.8, 1.1)), 1.0)
    bg.inputs["Strength"].default_value = 1.0

    sun = bpy.data.lights.new("sun", "SUN")
    sun.energy = float(rng.uniform(2.0, 4.0))
    sun_obj = bpy.data.objects.new("sun", sun)
    # from the camera's side of the wall (its light travels along -z turned by x towards +y)
    sun_obj.rotation_euler = (math.radians(-rng.uniform(30, 60)), 0.0, math.radians(rng.uniform(-60, 60)))
    if OVERHEAD_SUN:  # the sun straight above: no shadow beside the wall's foot
        sun_obj.rotation_euler = (0.0, 0.0, 0.0)
    sc.collection.objects.link(sun_obj)

    shoot(sc, cam, RES)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--first", type=int, default=12001)
    ap.add_argument("--count", type=int, default=20)
    ap.add_argument(
        "--keep", default=None, help="a folder to keep the rendered photos in (photos already there are reused)"
    )
    ap.add_argument("--overhead-sun", action="store_true", help="the sun straight above (no shadow at the foot)")
    a = ap.parse_args()
    global OVERHEAD_SUN
    OVERHEAD_SUN = a.overhead_sun
    seeds = list(range(a.first, a.first + a.count))
    folder = Path(a.keep) if a.keep else Path(tempfile.mkdtemp(prefix="tall-blender-"))
    folder.mkdir(parents=True, exist_ok=True)
    cases = []
    for seed in seeds:  # every photo first: Blender, then JAX, each in its own phase
        wall, texture = wall_and_texture(seed)
        rng = np.random.default_rng(seed + 1_000_000)
        cam = camera(wall.width_m, wall.height_m, rng)
        path = folder / f"tall{seed}.jpg"
        if a.keep and path.is_file():  # rendered before into --keep: the same scene, not drawn again
            print(f"reusing {path}", flush=True)
        else:
            t0 = time.perf_counter()
            render(wall.width_m, wall.height_m, texture, cam, rng, path)
            print(f"rendered {path.name} in {time.perf_counter() - t0:.1f} s", flush=True)
        cases.append((seed, wall, cam, path))

    import calib_masonry as cm
    from calib_masonry.errors import CalibMasonryError
    from calib_masonry.io import read_photo

    print(
        f"{'seed':>5} {'W m':>6} {'H m':>6} {'aspect':>6} {'yaw':>6} {'dist m':>6} {'W err':>7} {'H err':>7} "
        f"{'W z':>5} {'s':>5}  result"
    )
    ok = flagged = overconfident = 0
    for seed, wall, cam, path in cases:
        photo = read_photo(path)
        config = cm.CalibrateConfig(
            camera_height_m=float(cam["eye"][2]), camera_height_sigma_m=0.02, focal_px=cam["f_px"]
        )
        t0 = time.perf_counter()
        try:
            cal = cm.calibrate_photo(photo, config)
            res = cal.result
            ew, eh = res.width_m / wall.width_m - 1, res.height_m / wall.height_m - 1
            good = res.status.value == "converged" and abs(ew) <= 0.02 and abs(eh) <= 0.02
            msg = "ok" if good else f"FAIL ({res.status.value}, W {res.width_m:.3f} H {res.height_m:.3f})"
            if not good and cal.advice():
                msg += f": {cal.advice()}"
            ew_s, eh_s = f"{ew:+.2%}", f"{eh:+.2%}"
            # the W error in the fit's own sigmas: beyond 2 on a failure, the fit was overconfident
            z = (res.width_m - wall.width_m) / res.sigma("width_m")
            z_s = f"{z:+.1f}"
            overconfident += not good and abs(z) > 2.0
        except CalibMasonryError as exc:
            good, msg, ew_s, eh_s, z_s = False, f"FAIL: {exc}", "-", "-", "-"
        ok += good
        flagged += not good and "--" in msg
        print(
            f"{seed:5d} {wall.width_m:6.2f} {wall.height_m:6.2f} {wall.height_m / wall.width_m:6.2f} "
            f"{cam['yaw_deg']:6.1f} {cam['d']:6.1f} {ew_s:>7} {eh_s:>7} {z_s:>5} {time.perf_counter() - t0:5.1f}  {msg}",
            flush=True,
        )
    print(f"automatic mode on Blender-rendered tall walls: {ok} of {len(seeds)} succeeded (aim: 18 of 20)")
    print(f"failures whose message names the flag to add: {flagged} of {len(seeds) - ok}")
    print(f"failures with the true W beyond 2 sigma of the fit (overconfident): {overconfident} of {len(seeds) - ok}")
    print(f"photos: {folder}")


if __name__ == "__main__":
    main()

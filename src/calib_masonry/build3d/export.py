"""Writing a Structure3D: model.stl, bricks.json, and the figures (outer walls, 3D model).

Exporters are chosen from a table by file suffix (``.stl``, ``.glb``, ``.ply``, ``.obj``); the
outputs are deterministic for the same structure (same bytes for the same input).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import trimesh

from ..errors import InputError
from ..io import records_json_bytes
from .assemble import Structure3D

__all__ = [
    "EXPORTERS",
    "export_mesh",
    "bricks_json",
    "bricks_json_bytes",
    "bricks_from_json",
    "write_bricks_json",
    "plot_walls",
    "plot_model",
    "structure_mesh",
]

EXPORTERS = {".stl": "stl", ".glb": "glb", ".ply": "ply", ".obj": "obj"}


def structure_mesh(structure: Structure3D) -> trimesh.Trimesh:
    verts, faces, offset = [], [], 0
    for b in structure.bricks:
        verts.append(b.solid.vertices)
        faces.append(b.solid.faces + offset)
        offset += len(b.solid.vertices)
    return trimesh.Trimesh(np.vstack(verts), np.vstack(faces), process=False)


def export_mesh(structure: Structure3D, path: Path) -> None:
    kind = EXPORTERS.get(Path(path).suffix.lower())
    if kind is None:
        raise InputError(f"{path}: unknown mesh format; use one of {sorted(EXPORTERS)}")
    mesh = structure_mesh(structure)
    if kind == "glb":
        # one node per brick, named by wall and id; one material per wall, named by it and of its
        # colour in model.png (a material per wall, not colours per face: 0.25 s against 0.7 s for
        # the paper example's 1,587 bricks, and a wall's bricks share a material in Blender)
        scene = trimesh.Scene()
        # glTF is Y-up: a root node turns the model's Z-up frame (x, y, z) into (x, z, -y), so that
        # Blender's importer and every glTF viewer show it standing, not lying on its side
        y_up = np.array([[1.0, 0, 0, 0], [0, 0, 1.0, 0], [0, -1.0, 0, 0], [0, 0, 0, 1.0]])
        scene.graph.update(frame_from=scene.graph.base_frame, frame_to="model", matrix=y_up)
        materials = {}
        for wall, name, m in _brick_meshes(structure):
            if wall not in materials:
                materials[wall] = trimesh.visual.material.PBRMaterial(
                    name=structure.footprint.walls[wall].name,
                    baseColorFactor=(wall_colour(wall) * 255).astype(np.uint8),
                    metallicFactor=0.0,
                    roughnessFactor=1.0,
                )
            m.visual = trimesh.visual.TextureVisuals(material=materials[wall])
            scene.add_geometry(m, node_name=name, geom_name=name, parent_node_name="model")
        data = scene.export(file_type="glb")
    else:
        data = mesh.export(file_type=kind)
    Path(path).write_bytes(data if isinstance(data, bytes) else data.encode())


def wall_colour(wall: int) -> np.ndarray:
    """RGBA in [0, 1] of a wall in every model output (model.png, model.glb, model.blend)."""
    import matplotlib

    return np.array(matplotlib.colormaps["tab10"](wall % 10))


def _brick_meshes(structure: Structure3D):
    """Per brick, in order: its wall's index, its node name in every model file (``WALL_brick_LABEL``)
    and its mesh."""
    names = [w.name for w in structure.footprint.walls]
    for b in structure.bricks:
        yield b.wall, f"{names[b.wall]}_brick_{b.label:05d}", b.solid.to_trimesh()


def blend_walls(structure: Structure3D) -> list:
    """The model as :func:`calib_masonry.simulation.blender.write_model_blend` takes it: per wall its
    name, colour and bricks (name, vertices, triangles)."""
    walls = [(w.name, wall_colour(i), []) for i, w in enumerate(structure.footprint.walls)]
    for wall, name, m in _brick_meshes(structure):
        walls[wall][2].append((name, np.asarray(m.vertices), np.asarray(m.faces)))
    return walls


def bricks_json(structure: Structure3D) -> dict:
    """Per brick: wall, id, outer polygon (wall metres), 3D mesh, volume, centroid, Dice."""
    names = [w.name for w in structure.footprint.walls]
    return {
        "structure": structure.name,
        "walls": [
            {
                "name": w.name,
                "width_m": w.width_m,
                "height_m": w.height_m,
                "theta_deg": w.theta_deg,
                "thickness_m": w.thickness_m,
                "origin_xy": f.origin_xy.tolist(),
                "removed_corner_pieces": list(structure.removed[i]),
            }
            for i, (w, f) in enumerate(zip(structure.footprint.walls, structure.frames))
        ],
        "bricks": [
            {
                "id": b.id,
                "wall": names[b.wall],
                "wall_index": b.wall,
                "label": b.label,
                "polygon_wall_m": b.polygon_m.tolist(),
                "vertices": b.solid.vertices.tolist(),
                "faces": b.solid.faces.tolist(),
                "volume_m3": b.volume,
                "centroid": b.solid.centroid.tolist(),
                "dice": None if not np.isfinite(b.dice) else b.dice,
                "traced_vertices": b.traced_vertices,
            }
            for b in structure.bricks
        ],
    }


def bricks_json_bytes(structure: Structure3D) -> bytes:
    """The bytes of bricks.json: exact floats (a model read back is bit for bit the one written),
    a brick to a line (:func:`calib_masonry.io.records_json_bytes`)."""
    return records_json_bytes(bricks_json(structure))


def write_bricks_json(structure: Structure3D, path: Path) -> bytes:
    """Write bricks.json; returns its bytes (the simulation geometry is keyed by them)."""
    data = bricks_json_bytes(structure)
    Path(path).write_bytes(data)
    return data


def plot_walls(
    structure: Structure3D, path: Path, *, removed_polygons: list[list[np.ndarray]] | None = None, title: str = ""
) -> None:
    """The outer wall surfaces side by side (the method's Fig. 8), bricks coloured by Dice."""
    from matplotlib.cm import ScalarMappable
    from matplotlib.collections import PolyCollection
    from matplotlib.colors import Normalize

    from .. import _figure as plt

    spec = structure.footprint
    widths = [w.width_m for w in spec.walls]
    # as wide as the walls drawn 4.6 inches for the tallest (a 10.8 x 7 m facade had 1.6 inches a
    # metre of width: three quarters of its figure empty), with room for the colour bar
    per_m = 4.6 / max(w.height_m for w in spec.walls)
    width_in = min(24.0, max(5.0, 1.8 + per_m * sum(widths) + 0.25 * len(widths)))
    fig = plt.figure(figsize=(width_in, 6), layout="constrained")
    axes = fig.subplots(1, len(spec.walls), gridspec_kw={"width_ratios": widths}, squeeze=False)
    cmap = plt.get_cmap("viridis")
    for w, ax in enumerate(axes[0]):
        own = structure.bricks_of(w)
        dice = np.array([b.dice for b in own])
        colours = cmap(np.where(np.isfinite(dice), np.clip((dice - 0.9) / 0.1, 0, 1), 0.5))  # (n, 4), one call
        ax.add_collection(
            PolyCollection([b.polygon_m for b in own], facecolors=colours, edgecolors="k", linewidths=0.2)
        )
        if removed_polygons:
            ax.add_collection(
                PolyCollection(removed_polygons[w], facecolors="none", edgecolors="r", linewidths=0.6, hatch="///")
            )
        wall = spec.walls[w]
        ax.set_xlim(0, wall.width_m)
        ax.set_ylim(0, wall.height_m)
        ax.set_aspect("equal")
        ax.set_title(f"{wall.name}\n{wall.width_m:g} x {wall.height_m:g} m, {wall.theta_deg:g} deg", fontsize=8)
        ax.tick_params(labelsize=6)
    bar = fig.colorbar(
        ScalarMappable(norm=Normalize(0.9, 1.0), cmap=cmap), ax=axes[0].tolist(), extend="min", shrink=0.8, pad=0.01
    )
    bar.set_label("Dice of each brick's polygon with its mask region (below 0.9: darkest)", fontsize=7)
    bar.ax.tick_params(labelsize=6)
    fig.suptitle(
        title or f"{structure.name}: outer wall surfaces (colour: Dice; red hatched: corner end faces removed)",
        fontsize=9,
    )
    plt.save(fig, path, dpi=110)
    plt.close(fig)


def plot_model(structure: Structure3D, path: Path) -> None:
    """An axonometric view of the 3D brick model."""
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    from .. import _figure as plt

    fig = plt.figure(figsize=(8, 8))
    ax = fig.add_subplot(projection="3d")
    tris = []
    shade = []
    light = np.array([0.4, -0.6, 0.7])
    light /= np.linalg.norm(light)
    for b in structure.bricks:
        v = b.solid.vertices[b.solid.faces]
        n = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
        norm = np.linalg.norm(n, axis=1, keepdims=True)
        n = n / np.where(norm > 0, norm, 1)
        tris.append(v)
        shade.append(0.35 + 0.6 * np.clip(n @ light, 0, 1))
    tris_all = np.concatenate(tris)
    s = np.concatenate(shade)
    colours = np.column_stack([0.75 * s, 0.45 * s, 0.32 * s, np.ones_like(s)])
    ax.add_collection3d(Poly3DCollection(tris_all, facecolors=colours, linewidths=0))
    allv = np.concatenate([b.solid.vertices for b in structure.bricks])
    lo, hi = allv.min(axis=0), allv.max(axis=0)
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_zlim(lo[2], hi[2])
    ax.set_box_aspect(np.maximum(hi - lo, 1e-3))
    # ticks in proportion to each axis's length: a single wall's 0.2 m thickness got as many as its
    # height, printed over one another
    from matplotlib.ticker import MaxNLocator

    extent = np.maximum(hi - lo, 1e-3)
    for axis, e in zip((ax.xaxis, ax.yaxis, ax.zaxis), extent):
        axis.set_major_locator(MaxNLocator(nbins=max(1, int(round(6 * e / extent.max()))), min_n_ticks=2))
    ax.view_init(elev=22, azim=-60)
    ax.set_xlabel("X (m)")
    ax.set_ylabel("Y (m)")
    ax.set_zlabel("Z (m)")
    ax.set_title(f"{structure.name}: {len(structure.bricks)} bricks")
    fig.tight_layout()
    plt.save(fig, path, dpi=110)
    plt.close(fig)


def bricks_from_json(data: dict) -> list:
    """The bricks of a ``bricks.json`` document (as written by :func:`bricks_json`)."""
    from .assemble import Brick
    from .extrude import Polyhedron

    out = []
    for b in data["bricks"]:
        solid = Polyhedron(np.asarray(b["vertices"], dtype=np.float64), np.asarray(b["faces"], dtype=np.int64))
        out.append(
            Brick(
                id=int(b["id"]),
                wall=int(b["wall_index"]),
                label=int(b["label"]),
                polygon_m=np.asarray(b["polygon_wall_m"], dtype=np.float64),
                solid=solid,
                dice=float("nan") if b.get("dice") is None else float(b["dice"]),
                traced_vertices=int(b.get("traced_vertices", 0)),
            )
        )
    return out

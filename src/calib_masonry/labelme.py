"""LabelMe JSON, the annotation format engineers already correct images in: read and write.

``rectify`` and ``build`` write, beside each orthophoto, a LabelMe file whose polygons are the wall
(label ``wall``: the orthophoto's outline), the occluders (``occluder``) and every piece the
segmentation found (``piece``), and the openings it left out (``opening``: windows and doors, no
piece there). Opened in LabelMe, a wrong stone is fixed by dragging its vertices,
a missing one drawn, a false one deleted; ``build`` reads the corrected file as the wall's mask
(``mask = "wall1.json"`` in structure.toml, or any command that takes a mask). Beside each photo it
also writes one whose ``wall`` polygon is the fitted outline and whose ``occluder`` polygons are
those given: corrected, it goes back to ``rectify --labelme``.

The format (LabelMe 5): ``{"version", "flags", "shapes": [{"label", "points": [[x, y], ...],
"group_id", "description", "shape_type", "flags", "mask"}], "imagePath", "imageData",
"imageHeight", "imageWidth"}``; points are pixels, x along a row, y down, LabelMe's pixel-corner
convention (the image spans 0..width): this module converts to and from this project's
pixel-centre convention (x - 0.5). Polygons, rectangles and masks (LabelMe's AI masks: a box and a
base64 PNG of it) are read; labels ``piece``, ``stone``,
``brick`` and ``unit`` are pieces, ``occluder`` occluders, ``opening``, ``window`` and ``door``
openings (no masonry there: left out of a photo's fit and segmentation as occluders are), ``wall``
or ``outline`` the outline; other labels are named in the error. Reading needs no GUI (plain JSON).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .errors import InputError

__all__ = [
    "LabelMe",
    "PIECE_LABELS",
    "labelme_labels",
    "labelme_mask",
    "read_labelme",
    "read_occluders",
    "read_photo_annotation",
    "write_labelme",
]

LABELME_VERSION = "5.4.1"
PIECE_LABELS = ("piece", "stone", "brick", "unit")
OCCLUDER_LABELS = ("occluder",)
OPENING_LABELS = ("opening", "window", "door")
OUTLINE_LABELS = ("wall", "outline")


@dataclass(frozen=True)
class LabelMe:
    """A LabelMe annotation in this project's pixel-centre convention: the image's ``shape``
    ``(rows, cols)``, its path as written, and the polygons ``(n, 2)`` (x, y) by role."""

    shape: tuple[int, int]
    image_path: str
    pieces: tuple[np.ndarray, ...] = ()
    occluders: tuple[np.ndarray, ...] = ()
    outline: np.ndarray | None = None
    source: Path | None = field(default=None, compare=False)
    openings: tuple[np.ndarray, ...] = ()  # windows and doors: no masonry there

    @property
    def not_masonry(self) -> tuple[np.ndarray, ...]:
        """The polygons a photo's fit and segmentation leave out: the occluders and the openings."""
        return self.occluders + self.openings


def _shape(label: str, points: np.ndarray) -> dict:
    return {
        "label": label,
        "points": [[round(float(x) + 0.5, 3), round(float(y) + 0.5, 3)] for x, y in points],
        "group_id": None,
        "description": "",
        "shape_type": "polygon",
        "flags": {},
        "mask": None,
    }


def write_labelme(
    path: str | Path,
    image_path: str,
    shape: tuple[int, int],
    *,
    pieces=(),
    occluders=(),
    outline: np.ndarray | None = None,
    openings=(),
) -> dict:
    """Write a LabelMe file for the image ``image_path`` (relative to the file, as LabelMe wants it)
    of ``shape`` ``(rows, cols)``: the outline, occluders, openings and pieces (polygons ``(n, 2)``
    in pixel-centre coordinates). Returns the document."""
    from ._json import write_json

    shapes = []
    if outline is not None:
        shapes.append(_shape("wall", np.asarray(outline, dtype=float)))
    shapes += [_shape("occluder", np.asarray(p, dtype=float)) for p in occluders]
    shapes += [_shape("opening", np.asarray(p, dtype=float)) for p in openings]
    shapes += [_shape("piece", np.asarray(p, dtype=float)) for p in pieces]
    doc = {
        "version": LABELME_VERSION,
        "flags": {},
        "shapes": shapes,
        "imagePath": str(image_path),
        "imageData": None,
        "imageHeight": int(shape[0]),
        "imageWidth": int(shape[1]),
    }
    write_json(Path(path), doc)
    return doc


def read_labelme(path: str | Path, *, field_name: str = "LabelMe file") -> LabelMe:
    """Read a LabelMe JSON file (InputError naming the file and what is wrong in it)."""
    path = Path(path)
    where = f"{field_name} {path}"
    if not path.is_file():
        raise InputError(f"{where}: not found; give the path of a LabelMe .json file")
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise InputError(f"{where}: not readable as JSON ({exc}); save it again from LabelMe") from None
    if not isinstance(doc, dict) or not isinstance(doc.get("shapes"), list):
        raise InputError(f"{where}: no 'shapes' list; this is not a LabelMe file")
    try:
        rows, cols = int(doc["imageHeight"]), int(doc["imageWidth"])
    except (KeyError, TypeError, ValueError):
        raise InputError(
            f"{where}: 'imageHeight' and 'imageWidth' (pixels) are missing; save it again from LabelMe"
        ) from None
    if not (0 < rows <= 200_000 and 0 < cols <= 200_000):
        raise InputError(f"{where}: image size {cols} x {rows} px is impossible")
    pieces, occluders, openings, outline = [], [], [], None
    for i, sh in enumerate(doc["shapes"]):
        label = str(sh.get("label", "")).strip().lower() if isinstance(sh, dict) else ""
        kind = sh.get("shape_type", "polygon") if isinstance(sh, dict) else None
        try:
            pts = np.asarray(sh["points"], dtype=np.float64).reshape(-1, 2) - 0.5
        except (KeyError, TypeError, ValueError):
            raise InputError(f"{where}: shape {i + 1} ('{label}') has no list of [x, y] points") from None
        if not np.all(np.isfinite(pts)):
            raise InputError(f"{where}: shape {i + 1} ('{label}') has a point that is not a number")
        if kind == "rectangle" and len(pts) == 2:
            (x0, y0), (x1, y1) = pts
            pts = np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]])
        elif kind == "mask":
            pts = _mask_outline(sh, pts + 0.5, (rows, cols), f"{where}: shape {i + 1} ('{label}')")
        elif kind not in ("polygon", None):
            raise InputError(
                f"{where}: shape {i + 1} ('{label}') is a {kind}; draw stones, occluders and the wall as polygons, "
                "rectangles or masks"
            )
        if len(pts) < 3:
            raise InputError(f"{where}: shape {i + 1} ('{label}') has {len(pts)} points; a polygon needs at least 3")
        if label in PIECE_LABELS:
            pieces.append(pts)
        elif label in OCCLUDER_LABELS:
            occluders.append(pts)
        elif label in OPENING_LABELS:
            openings.append(pts)
        elif label in OUTLINE_LABELS:
            if outline is not None:
                raise InputError(f"{where}: more than one '{label}' polygon; keep one outline of the wall")
            outline = pts
        else:
            raise InputError(
                f"{where}: shape {i + 1} has the label '{sh.get('label')}'; use 'piece' (or stone, brick) for "
                "masonry units, 'occluder' for what hides the wall, 'opening' for a window or a door, 'wall' for "
                "its outline"
            )
    return LabelMe(
        shape=(rows, cols),
        image_path=str(doc.get("imagePath", "")),
        pieces=tuple(pieces),
        occluders=tuple(occluders),
        outline=outline,
        source=path,
        openings=tuple(openings),
    )


def _mask_outline(shape: dict, corners: np.ndarray, size: tuple[int, int], where: str) -> np.ndarray:
    """The outline (x, y pixel centres) of a LabelMe mask shape (what its AI tools make from a
    click, a SAM mask): ``points`` the box's first and last pixel ``[[x1, y1], [x2, y2]]`` and
    ``mask`` a base64 PNG of the box, ``image[y1 : y2 + 1, x1 : x2 + 1]`` as LabelMe fills it. The
    outline runs along the pixel edges of its largest connected part, so that it is drawn back
    pixel for pixel."""
    import base64
    import binascii
    import io

    from PIL import Image, UnidentifiedImageError
    from scipy import ndimage
    from skimage.measure import find_contours

    if len(corners) != 2:
        raise InputError(f"{where} is a mask with {len(corners)} points; LabelMe gives its box's two corners")
    (x1, y1), (x2, y2) = np.asarray(corners).astype(int)
    rows, cols = size
    if not (0 <= x1 <= x2 < cols and 0 <= y1 <= y2 < rows):
        raise InputError(f"{where}: its mask's box ({x1}, {y1})-({x2}, {y2}) lies outside the {cols} x {rows} px image")
    try:
        with Image.open(io.BytesIO(base64.b64decode(shape.get("mask") or "", validate=True))) as im:
            if im.width * im.height > (x2 - x1 + 1) * (y2 - y1 + 1):
                raise ValueError("larger than its box")
            box = np.asarray(im.convert("L")) > 0
    except (binascii.Error, UnidentifiedImageError, OSError, ValueError) as exc:
        raise InputError(
            f"{where}: its 'mask' is not a base64 PNG of its box ({exc}); save it again from LabelMe"
        ) from None
    if box.shape != (y2 - y1 + 1, x2 - x1 + 1):
        raise InputError(
            f"{where}: its mask is {box.shape[1]} x {box.shape[0]} px for a box of {x2 - x1 + 1} x {y2 - y1 + 1}; "
            "save it again from LabelMe"
        )
    parts, n = ndimage.label(box)
    if n == 0:
        raise InputError(f"{where}: its mask is empty; delete the shape or draw it again")
    largest = parts == 1 + int(np.argmax(ndimage.sum_labels(box, parts, index=np.arange(1, n + 1))))
    contour = max(find_contours(np.pad(largest.astype(np.float64), 1), 0.5, fully_connected="low"), key=len)[:-1]
    return np.column_stack([contour[:, 1] - 1.0 + x1, contour[:, 0] - 1.0 + y1])


def labelme_labels(doc: LabelMe) -> np.ndarray:
    """An int32 label image ``(rows, cols)`` of the pieces (1..n in the file's order, a later
    polygon over an earlier one where they overlap), 0 elsewhere."""
    from .calibrate.outline import polygon_mask

    labels = np.zeros(doc.shape, dtype=np.int32)
    for k, poly in enumerate(doc.pieces, start=1):
        labels[polygon_mask(doc.shape, poly)] = k
    return labels


def pieces_apart(labels: np.ndarray) -> np.ndarray:
    """The brick mask ``(rows, cols)`` (bricks True) of labelled pieces ``labels`` (0 none): every
    piece's pixels, less those that touch another piece (4-neighbours), so that two pieces drawn
    edge to edge stay two."""
    edge = np.zeros(labels.shape, dtype=bool)
    below, above = labels[1:], labels[:-1]
    edge[1:] |= (below != above) & (below > 0) & (above > 0)  # the lower of two pieces one above the other
    right, left = labels[:, 1:], labels[:, :-1]
    edge[:, 1:] |= (right != left) & (right > 0) & (left > 0)  # the right one of two side by side
    return (labels > 0) & ~edge


def labelme_mask(doc: LabelMe, labels: np.ndarray | None = None) -> np.ndarray:
    """The pieces as a brick mask ``(rows, cols)`` (bricks True): every piece's pixels, less those
    that touch another piece (4-neighbours), so that two pieces drawn edge to edge stay two.
    ``labels``: the document's :func:`labelme_labels`, where they are at hand."""
    return pieces_apart(labelme_labels(doc) if labels is None else labels)


def read_photo_annotation(path: str | Path) -> LabelMe:
    """A LabelMe file of a photo: its ``wall`` polygon must have 4 points (the corners), when given."""
    doc = read_labelme(path, field_name="--labelme")
    if doc.outline is not None and len(doc.outline) != 4:
        raise InputError(
            f"--labelme {path}: the 'wall' polygon has {len(doc.outline)} points; give the wall's four corners"
        )
    return doc


def annotation_size(path: str | Path) -> tuple[int, int] | None:
    """The (width, height) px a LabelMe file was drawn on; None for a plain JSON list of polygons
    (or a file :func:`read_occluders` refuses anyway)."""
    try:
        doc = json.loads(Path(path).read_text(encoding="utf-8"))
        return (int(doc["imageWidth"]), int(doc["imageHeight"])) if isinstance(doc, dict) else None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError, KeyError, TypeError, ValueError):
        return None


def read_occluders(path: str | Path) -> tuple[np.ndarray, ...]:
    """Occluder polygons (photo pixels) from a LabelMe file (its ``occluder`` shapes) or a JSON list
    of polygons ``[[[x, y], ...], ...]`` (pixel centres)."""
    path = Path(path)
    if not path.is_file():
        raise InputError(f"--occluders {path}: not found; give a LabelMe .json or a JSON list of polygons")
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise InputError(f"--occluders {path}: not readable as JSON ({exc})") from None
    if isinstance(doc, dict):
        ann = read_labelme(path, field_name="--occluders")
        if not ann.not_masonry:
            raise InputError(f"--occluders {path}: no shape labelled 'occluder' (or 'opening')")
        return ann.not_masonry
    if not isinstance(doc, list) or not doc:
        raise InputError(f"--occluders {path}: give a list of polygons [[[x, y], ...], ...]")
    out = []
    for i, poly in enumerate(doc):
        try:
            pts = np.asarray(poly, dtype=np.float64).reshape(-1, 2)
        except (TypeError, ValueError):
            raise InputError(f"--occluders {path}: polygon {i + 1} is not a list of [x, y] points") from None
        if len(pts) < 3 or not np.all(np.isfinite(pts)):
            raise InputError(f"--occluders {path}: polygon {i + 1} needs at least 3 finite points")
        out.append(pts)
    return tuple(out)


def write_labelme_pair(
    folder: Path, calibration, ortho_shape, *, pieces, occluders_ortho, photo_size=None, openings_ortho=()
) -> None:
    """Two LabelMe files in ``folder``: ``rectified.json`` (over rectified.png: the wall's outline,
    the occluders, the openings the segmentation left out and every piece, in its pixels) and
    ``photo.json`` (over the photo: the fitted outline as a 'wall' polygon, the occluders);
    corrected in LabelMe, the first is a wall's mask for ``build`` (``mask = ".../rectified.json"``),
    the second goes back to ``rectify --labelme``."""
    import os

    rows, cols = ortho_shape
    outline = np.array([[-0.5, rows - 0.5], [cols - 0.5, rows - 0.5], [cols - 0.5, -0.5], [-0.5, -0.5]])
    write_labelme(
        folder / "rectified.json",
        "rectified.png",
        (rows, cols),
        outline=outline,
        occluders=occluders_ortho,
        pieces=pieces,
        openings=openings_ortho,
    )
    photo = calibration.photo
    size = photo_size or photo.size
    try:
        rel = os.path.relpath(Path(photo.path).resolve(), Path(folder).resolve())
    except ValueError:  # another drive (Windows): the absolute path
        rel = str(Path(photo.path).resolve())
    write_labelme(
        folder / "photo.json",
        rel,
        (size[1], size[0]),
        outline=calibration.result.corners_px(),
        occluders=calibration.occluders,
    )

"""File input and output shared by every stage: masks, JSON, and all-or-nothing output folders.

Convention: images are arrays of shape ``(rows, cols)``; the pixel at ``[r, c]`` has its centre at
image coordinates ``(x, y) = (c, r)``, origin top-left.
"""

from __future__ import annotations

import contextlib
import functools
import io
import json
import math
import os
import shutil
import signal
import tempfile
import tomllib
import warnings
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from PIL import Image, UnidentifiedImageError

from ._json import json_bytes, read_json, records_json_bytes, write_json
from .errors import InputError
from .process import raise_if_stopped

__all__ = [
    "json_bytes",
    "records_json_bytes",
    "Photo",
    "read_json",
    "read_mask",
    "read_photo",
    "check_output",
    "OUTPUT_MARKER",
    "output_command",
    "remove_stale_staging",
    "to_uint8",
    "trust_large_images",
    "staged_file",
    "staged_output",
    "warn",
    "write_json",
    "write_mask",
    "write_rgb",
    "xy_from_rc",
]


def warn(message: str) -> None:
    """A user-facing warning (printed on one line by the CLI)."""
    warnings.warn(message, UserWarning, stacklevel=2)


def xy_from_rc(rc: np.ndarray) -> np.ndarray:
    """scikit-image ``(row, col)`` points, shape ``(M, 2)``, to image ``(x, y)`` = ``(col, row)``."""
    rc = np.asarray(rc, dtype=np.float64)
    return rc[..., ::-1].copy()


#: Images above this many pixels are refused (Pillow's decompression-bomb guard is 179 megapixels).
MAX_IMAGE_PIXELS = 178_956_970
#: Peak bytes per pixel of reading and tracing a mask (measured: 7.5 on a 12,000 x 12,000 mask).
_BYTES_PER_PIXEL = 16
_TRUST_LARGE_IMAGES = False


def trust_large_images(trust: bool = True) -> None:
    """Lift (or restore) the image-size limit, for files you trust (``--trust-large-images``, or
    the environment variable CALIB_MASONRY_TRUST_LARGE_IMAGES=1)."""
    global _TRUST_LARGE_IMAGES
    _TRUST_LARGE_IMAGES = bool(trust)
    Image.MAX_IMAGE_PIXELS = None if trust else MAX_IMAGE_PIXELS


trust_large_images(os.environ.get("CALIB_MASONRY_TRUST_LARGE_IMAGES") == "1")


def _available_bytes() -> int | None:
    """Memory a process can still take: Linux's MemAvailable (free memory plus the page cache it can
    drop; "free" alone is small on a machine that has read many files), else the physical total."""
    try:
        with open("/proc/meminfo", encoding="ascii") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (ValueError, OSError, AttributeError):  # not every platform says
        return None


@contextlib.contextmanager
def _opened_image(path: Path, field: str, hint: str, data: bytes | None = None) -> Iterator[Image.Image]:
    """An image file (or its bytes ``data``, named ``path``), opened and decoded; a missing or
    unreadable file is a one-line InputError."""
    if data is None and not path.is_file():
        raise InputError(f"{field} {path}: file not found; check the path")
    try:
        with warnings.catch_warnings():  # the size is checked below, in one line
            warnings.simplefilter("ignore", Image.DecompressionBombWarning)
            im = Image.open(path if data is None else io.BytesIO(data))
    except Image.DecompressionBombError as exc:
        raise InputError(f"{field} {path}: {exc}; downsample it or add --trust-large-images") from None
    except (UnidentifiedImageError, OSError, SyntaxError, ValueError) as exc:
        raise InputError(f"{field} {path}: cannot be read as an image ({exc}); {hint}") from None
    if im.width * im.height > MAX_IMAGE_PIXELS and not _TRUST_LARGE_IMAGES:
        im.close()
        raise InputError(
            f"{field} {path}: {im.width} x {im.height} px ({im.width * im.height / 1e6:.0f} megapixels) is above "
            f"the {MAX_IMAGE_PIXELS / 1e6:.0f} megapixel limit; downsample it (a brick needs about 30 px "
            "across), or add --trust-large-images (CALIB_MASONRY_TRUST_LARGE_IMAGES=1) for a file you trust"
        )
    free = _available_bytes()
    if free is not None and im.width * im.height * _BYTES_PER_PIXEL > free:
        im.close()
        raise InputError(
            f"{field} {path}: {im.width} x {im.height} px needs about "
            f"{im.width * im.height * _BYTES_PER_PIXEL / 2**30:.1f} GiB to process and this machine has "
            f"{free / 2**30:.1f} GiB free; downsample it (a brick needs about 30 px across)"
        )
    try:
        im.load()
    except (OSError, SyntaxError, ValueError) as exc:
        im.close()
        raise InputError(f"{field} {path}: cannot be read as an image ({exc}); {hint}") from None
    suffix_format = {".png": "PNG", ".jpg": "JPEG", ".jpeg": "JPEG", ".tif": "TIFF", ".tiff": "TIFF"}
    expected = suffix_format.get(path.suffix.lower())
    if expected is not None and im.format is not None and im.format != expected:
        im.close()
        raise InputError(
            f"{field} {path}: the file is a {im.format} image named {path.suffix}; "
            f"rename it to its real type (a mask must be a lossless PNG or TIFF: JPEG blurs the joints)"
        )
    with im:
        yield im


def read_mask_labels(path: str | Path, *, field: str = "mask") -> tuple[np.ndarray, np.ndarray | None]:
    """:func:`read_mask`'s mask and, for a LabelMe ``.json``, its pieces labelled as drawn, each its
    own where two touch (:func:`calib_masonry.labelme.labelme_labels`), from one reading of the file;
    None for a mask image. Traced as a mask, the one-pixel lines between touching pieces were filled
    as holes and the pieces merged (a real wall's 36 as 24)."""
    path = Path(path)
    if path.suffix.lower() != ".json":
        return _read_mask_image(path, field, 0.05)
    from .labelme import labelme_labels, labelme_mask, read_labelme

    doc = read_labelme(path, field_name=field)
    if not doc.pieces:
        raise InputError(
            f"{field} {path}: the LabelMe file has no piece polygons (labels piece, stone or brick); "
            "draw the masonry units"
        )
    labels = labelme_labels(doc)
    return labelme_mask(doc, labels), labels


def read_mask(path: str | Path, *, field: str = "mask", max_gray_fraction: float = 0.05) -> np.ndarray:
    """Read a binary-like mask (bricks white, mortar black) as a boolean array ``(rows, cols)``.

    Grey levels are allowed on edges (anti-aliasing), but if more than ``max_gray_fraction`` of
    the pixels lie between 20 % and 80 % of the intensity range the file is refused as not a mask.
    A ``.json`` file is read as LabelMe: its pieces' polygons, drawn apart
    (:func:`calib_masonry.labelme.labelme_mask`).
    """
    path = Path(path)
    if path.suffix.lower() == ".json":
        return read_mask_labels(path, field=field)[0]
    return _read_mask_image(path, field, max_gray_fraction)[0]


def _labelled(labels: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A label image's brick mask, its units drawn touching kept apart, and the labels."""
    from .labelme import pieces_apart  # here: labelme imports io

    return pieces_apart(labels), labels


def _read_mask_image(path: Path, field: str, max_gray_fraction: float) -> tuple[np.ndarray, np.ndarray | None]:
    """:func:`read_mask` of an image file, and its pieces labelled where it is a label image (each
    unit a flat colour or grey level of its own on black mortar: :func:`label_image`), else None."""
    with _opened_image(path, field, "give a PNG or TIFF mask") as im:
        arr = np.asarray(im.convert("RGB") if im.mode in ("P", "PA") else im)
    # computed in the file's own integer type where possible: a few bytes per pixel, not 8-24 bytes
    # of float64 copies, so that a 12,000 x 12,000 mask fits in memory
    if arr.ndim == 3:
        chans = arr[..., :3]
        spread = chans.max(axis=-1) - chans.min(axis=-1)  # exact in the native type (max >= min)
        if np.mean(spread > 0.2 * max(1.0, float(chans.max()))) > max_gray_fraction:
            del spread
            labels = label_image(chans)
            if labels is None:
                raise InputError(
                    f"{field} {path}: looks like a colour photo, not a mask; give a binary mask (bricks white, "
                    "mortar black) or a label image (each unit a flat colour of its own, mortar black)"
                )
            return _labelled(labels)
        del spread
        if np.issubdtype(chans.dtype, np.integer):
            arr = chans.sum(axis=-1, dtype=np.int32)  # 3 x the mean, exactly
        else:
            arr = chans.mean(axis=-1, dtype=np.float32)
        del chans
    if arr.dtype == bool:
        arr = arr.view(np.uint8)
    if arr.size == 0 or min(arr.shape) < 2:
        raise InputError(f"{field} {path}: image is empty ({arr.shape}); give a real mask")
    lo, hi = arr.min(), arr.max()
    if float(hi) <= float(lo):
        raise InputError(f"{field} {path}: image is a single flat value; it holds no bricks")
    span = float(hi) - float(lo)
    grey = np.count_nonzero((arr > float(lo) + 0.2 * span) & (arr < float(lo) + 0.8 * span)) / arr.size
    if grey > max_gray_fraction:
        labels = label_image(arr) if arr.ndim == 2 and np.issubdtype(arr.dtype, np.integer) else None
        if labels is None:
            raise InputError(
                f"{field} {path}: not a binary-like mask ({grey:.0%} of pixels are mid-grey); "
                "threshold it to black mortar and white bricks first (or give a label image: each unit a "
                "grey level of its own, mortar 0)"
            )
        return _labelled(labels)
    if np.issubdtype(arr.dtype, np.integer):  # (v - lo) / (hi - lo) >= 1/2, in exact integers
        return arr >= int(lo) + (int(hi) - int(lo) + 1) // 2, None
    return arr >= float(lo) + 0.5 * span, None


#: A label image's pieces: a flat region smaller than this (pixels) is an edge's blend, not a unit.
LABEL_MIN_PX = 20


def label_image(image: np.ndarray) -> np.ndarray | None:
    """The units of a label image as labels ``(rows, cols)`` int32 (0 mortar, 1..K), or None where
    ``image`` is not one. A label image (an instance mask: what segmentation and annotation tools
    export) gives each unit a flat colour (``(rows, cols, 3)`` integers) or grey level (``(rows,
    cols)`` integers, 16-bit ids too) and the mortar black (0; a colour within 4 % of black); two
    units may touch. A unit is a connected region of one value (8-neighbours); regions under
    :data:`LABEL_MIN_PX` pixels are taken for mortar. Not a label image: no mortar (under 1 % of the
    pixels), or more than 2 % of the units' pixels in such small regions (a photo's texture), or a
    sample of 200,000 pixels with more than 5,000 values."""
    from skimage.measure import label as connected

    if image.ndim == 3:
        c = image[..., :3]
        top = max(1, int(c.max()))
        dark = (c <= int(0.04 * top)).all(axis=-1)
        # one integer per colour, in 4 bytes a pixel for 8-bit colours (a large mask fits in memory)
        kind = np.int32 if (top + 1) ** 3 < 2**31 - 1 else np.int64
        key = c[..., 0].astype(kind)
        for k in (1, 2):
            key *= top + 1
            key += c[..., k]
    else:
        dark = image == 0
        key = image.astype(np.int64 if image.dtype.itemsize >= 4 else np.int32)
    if dark.mean() < 0.01:
        return None
    flat = key.ravel()
    sample = flat[np.random.default_rng(0).integers(0, flat.size, min(flat.size, 200_000))]
    if np.unique(sample).size > 5000:
        return None
    key += 1
    key[dark] = 0  # 0 the mortar, each other value a unit's
    del dark
    found = connected(key, background=0, connectivity=2)
    del key
    sizes = np.bincount(found.ravel())
    small = sizes < LABEL_MIN_PX
    small[0] = False
    units = sizes[1:].sum()
    if units == 0 or sizes[small].sum() > 0.02 * units:
        return None
    keep = np.flatnonzero(~small[1:]) + 1  # the units, in order
    renumber = np.zeros(sizes.size, dtype=np.int32)
    renumber[keep] = np.arange(1, keep.size + 1, dtype=np.int32)
    return renumber[found]


def to_uint8(img: np.ndarray) -> np.ndarray:
    """An image in [0, 1] as 8-bit values, rounded to the nearest (8-bit values as they are).

    ``clip(img, 0, 1) * 255 + 0.5`` truncated, in the image's own float type and in place in one
    buffer (a 3000 x 2000 photo: 0.06-0.17 s with a temporary for each step, 0.02 s so)."""
    if img.dtype == np.uint8:
        return img
    dtype = img.dtype if img.dtype.kind == "f" else np.dtype(np.float64)
    out = np.multiply(img, dtype.type(255), dtype=dtype)
    np.add(out, dtype.type(0.5), out=out)
    np.clip(out, dtype.type(0.5), dtype.type(255.5), out=out)
    return out.astype(np.uint8)


def write_rgb(path: Path, rgb: np.ndarray) -> None:
    """Write an RGB image in [0, 1] (or 8-bit) as an 8-bit PNG, with zlib's fastest level: a photo-sized
    orthophoto took 0.80 s at the default level and 0.17 s at this one, 18 % larger (measured)."""
    Image.fromarray(to_uint8(rgb)).save(path, compress_level=1)


def read_toml(path: Path, what: str) -> dict:
    """A TOML file's tables; a missing or malformed file is an error naming it."""
    if not path.is_file():
        raise InputError(f"{path}: {what} not found; give the path of a .toml file")
    try:
        return tomllib.loads(path.read_text(encoding="utf-8"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise InputError(f"{path}: not valid TOML ({exc}); fix the syntax") from None


def write_mask(path: Path, mask: np.ndarray) -> None:
    """Write a boolean mask as an 8-bit PNG (255 = brick), at zlib's default level: Pillow's
    ``optimize`` took 0.13 s for a paper-example wall's mask (27 KB) and this 0.03 s (32 KB)."""
    Image.fromarray(np.where(mask, 255, 0).astype(np.uint8), mode="L").save(path, compress_level=6)


#: The file that marks a folder as a command's output, so that a later run may replace it as a whole.
OUTPUT_MARKER = ".calib-masonry-output.json"


def output_command(folder: str | Path) -> str | None:
    """The command whose output ``folder`` is (from its marker file), or None."""
    try:
        return str(json.loads((Path(folder) / OUTPUT_MARKER).read_text(encoding="utf-8"))["command"])
    except (OSError, ValueError, KeyError, TypeError):
        return None


def check_not_input(path: str | Path, inputs, *, flag: str = "--out") -> None:
    """Refuse, before any work, an output ``path`` that is one of the command's ``inputs`` (files,
    or folders whose every file is an input): writing it would destroy what the run reads."""
    target = Path(path).resolve()
    for item in inputs:
        if item is None:
            continue
        src = Path(item).resolve()
        if target == src or (src.is_dir() and src in target.parents and target.exists()):
            raise InputError(
                f"{flag} {path}: it is one of this command's inputs ({item}), which writing it would destroy; "
                "choose another path"
            )


def _check_writable(folder: Path, path: Path, flag: str) -> None:
    """Refuse, before any work, an output under a folder where nothing can be made (a read-only
    file system, /proc, a folder without write permission): a run would fail only when it writes,
    after its work. Tried for real (a folder made and removed), since permissions alone do not tell
    a read-only mount or /proc."""
    import tempfile

    try:
        probe = tempfile.mkdtemp(prefix=".calib-masonry-probe-", dir=folder)
        os.rmdir(probe)
    except OSError as exc:
        reason = exc.strerror or type(exc).__name__
        raise InputError(f"{flag} {path}: nothing can be written in {folder} ({reason}); choose another path") from None


def check_output(
    path: str | Path,
    *,
    folder: bool = True,
    flag: str = "--out",
    command: str | None = None,
    overwrite: bool = False,
) -> Path:
    """Check, before any work, that ``path`` can become an output folder (or file): it is not an
    existing file (folder) or folder (file), and no folder above it is a file.

    With ``command`` (a folder output, which a run replaces as a whole), an existing folder must be
    empty or an earlier output of the same command (its marker file says so), unless ``overwrite``.
    """
    path = Path(path)
    what = "folder" if folder else "file"
    if folder and path.exists() and not path.is_dir():
        raise InputError(f"{flag} {path}: is a file, not a folder; give a folder to write the results into")
    if not folder and path.is_dir():
        raise InputError(f"{flag} {path}: is a folder; give a file name to write to")
    for up in path.resolve().parents:
        if up.exists():
            if not up.is_dir():
                raise InputError(
                    f"{flag} {path}: {up} is a file, so no {what} can be made under it; choose another path"
                )
            _check_writable(up, path, flag)
            break
    if folder and command and path.is_dir():
        entries = sorted(e.name for e in path.iterdir())
        if entries:
            cwd = Path.cwd().resolve()
            if cwd == path.resolve() or path.resolve() in cwd.parents:
                raise InputError(
                    f"{flag} {path}: is the working folder or holds it, and a run replaces its --out as a "
                    "whole; give a new folder"
                )
            earlier = output_command(path)
            if earlier != command and not overwrite:
                whose = f"an output of `calib-masonry {earlier}`" if earlier else "not an earlier calib-masonry output"
                shown = ", ".join(repr(e) for e in entries[:3]) + (", ..." if len(entries) > 3 else "")
                raise InputError(
                    f"{flag} {path}: the folder holds {shown} and is {whose}; a `{command}` run replaces its "
                    "output folder as a whole, so choose a new or empty folder, or add --overwrite to replace "
                    "this one"
                )
    return path


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _staging_prefix(path: Path) -> str:
    return f".{path.name}.partial-"


def remove_stale_staging(path: Path) -> None:
    """Remove staging beside ``path`` that a killed run left (its pid, in the name, is gone)."""
    parent = path.resolve().parent
    if not parent.is_dir():
        return
    prefix = _staging_prefix(path)
    for entry in parent.glob(prefix + "*"):
        pid = entry.name[len(prefix) :].split("-", 1)[0]
        if pid.isdigit() and int(pid) != os.getpid() and not _alive(int(pid)):
            if entry.is_dir() and not entry.is_symlink():
                shutil.rmtree(entry, ignore_errors=True)
            else:
                entry.unlink(missing_ok=True)


def _keep_inputs(out_dir: Path, stage: Path, keep) -> None:
    """Copy the files among ``keep`` (the run's inputs) that lie inside ``out_dir`` into the stage,
    at the same relative place, unless the run wrote that name itself."""
    for f in keep:
        if f is None:
            continue
        f = Path(f).resolve()
        try:
            rel = f.relative_to(out_dir)
        except ValueError:
            continue
        target = stage / rel
        if f.is_file() and not target.exists():
            target.parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(f, target)


@contextlib.contextmanager
def staged_output(
    out_dir: str | Path, command: str, *, overwrite: bool = False, keep: Iterable[str | Path | None] = ()
) -> Iterator[Path]:
    """Yield an empty staging folder; on success it becomes ``out_dir``, replacing it as a whole.

    ``out_dir`` must be new, empty, or an earlier output of the same ``command`` (a marker file in
    it says so; see :func:`check_output`), unless ``overwrite``. Nothing of an earlier run stays
    beside the new results, except files among ``keep`` (the run's own inputs, say a scenario file
    kept inside its output folder), which are carried over. On any exception (SIGTERM and Ctrl-C
    included, see the CLI) the staging folder is removed and ``out_dir`` is untouched, so a failed
    run never leaves half a result. Staging that a killed run left beside ``out_dir`` is removed
    first. The staging folder's name carries this process's id.
    """
    out_dir = check_output(out_dir, command=command, overwrite=overwrite).resolve()
    parent = out_dir.parent
    parent.mkdir(parents=True, exist_ok=True)
    remove_stale_staging(out_dir)
    prefix = f"{_staging_prefix(out_dir)}{os.getpid()}-"
    stage = Path(tempfile.mkdtemp(prefix=prefix, dir=parent))
    try:
        yield stage
        _keep_inputs(out_dir, stage, keep)
        (stage / OUTPUT_MARKER).write_text(json.dumps({"command": command}) + "\n", encoding="utf-8")
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(stage, 0o777 & ~umask)  # mkdtemp makes 0700; give the folder the usual permissions
        old = parent / f"{prefix}old-{os.urandom(4).hex()}"
        blocked = {signal.SIGTERM, signal.SIGINT}
        signal.pthread_sigmask(signal.SIG_BLOCK, blocked)  # the swap is not interrupted half-way
        swapped = False
        try:
            raise_if_stopped()  # a stop whose exception some library swallowed: do not commit
            if out_dir.exists():
                os.replace(out_dir, old)
            try:
                os.replace(stage, out_dir)
            except BaseException:
                if old.exists() and not out_dir.exists():
                    os.replace(old, out_dir)  # put the earlier output back
                raise
            swapped = True
            shutil.rmtree(old, ignore_errors=True)
        finally:
            try:
                signal.pthread_sigmask(signal.SIG_UNBLOCK, blocked)  # a signal held back is handled here
            except KeyboardInterrupt as exc:
                if swapped:
                    exc.written = f"{out_dir} was complete before it; that output is whole"  # the CLI says so
                raise
    finally:
        shutil.rmtree(stage, ignore_errors=True)


@contextlib.contextmanager
def staged_file(path: str | Path) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; rename it onto ``path`` on success only."""
    path = check_output(path, folder=False)
    path.resolve().parent.mkdir(parents=True, exist_ok=True)
    remove_stale_staging(path)
    fd, tmp = tempfile.mkstemp(
        prefix=f"{_staging_prefix(path)}{os.getpid()}-", suffix=path.suffix, dir=path.resolve().parent
    )
    os.close(fd)
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp, 0o666 & ~umask)  # mkstemp makes 0600; give the file the usual permissions
    tmp_path = Path(tmp)
    try:
        yield tmp_path
    except BaseException:
        tmp_path.unlink(missing_ok=True)
        raise
    os.replace(tmp_path, path)


#: the least side of a photo (px), and of an orthophoto made from one
MIN_IMAGE_PX = 32


@dataclass(frozen=True)
class Photo:
    """An RGB photo in [0, 1] with what its EXIF says about the camera."""

    path: Path
    rgb: np.ndarray  # (rows, cols, 3) float32
    focal_px: float | None  # from FocalLength x FocalPlaneXResolution, or the 35 mm equivalent
    heading_deg: float | None  # GPSImgDirection
    lens: dict | None = None  # EXIF Make, Model, LensMake, LensModel, FocalLength (mm), FNumber
    focal_note: str = ""  # which EXIF tags gave focal_px (see :func:`exif_focal_px`)
    # where focal_px is a prior of this log sigma rather than a fact (the EXIF's two focal lengths
    # disagree, or the 35 mm equivalent alone, rounded to a millimetre: :func:`exif_focal_px`)
    focal_log_sigma: float | None = None

    def __post_init__(self) -> None:
        rgb = np.asarray(self.rgb)
        if rgb.ndim != 3 or rgb.shape[2] not in (3, 4) or min(rgb.shape[:2]) < MIN_IMAGE_PX:
            raise InputError(
                f"photo {self.path}: rgb must be an image array (rows, cols, 3) of at least {MIN_IMAGE_PX} x {MIN_IMAGE_PX} px, "
                f"got shape {rgb.shape}"
            )
        if rgb.dtype == np.uint8:  # 8-bit values, as PIL and most readers give them
            rgb = rgb[..., :3].astype(np.float32) / 255.0
        else:
            rgb = np.asarray(rgb[..., :3], dtype=np.float32)
            # NaN makes min and max NaN, and the test false: two passes over a photo, not three
            if not (rgb.min() >= 0.0 and rgb.max() <= 1.0):
                raise InputError(f"photo {self.path}: a float image must hold values in [0, 1] (or give uint8 0-255)")
        object.__setattr__(self, "rgb", rgb)
        if self.focal_px is not None and not (math.isfinite(self.focal_px) and self.focal_px > 0):
            raise InputError(f"photo {self.path}: focal_px = {self.focal_px} must be > 0 (pixels) or None")

    @property
    def size(self) -> tuple[int, int]:
        return int(self.rgb.shape[1]), int(self.rgb.shape[0])


_PLANE_UNIT_MM = {2: 25.4, 3: 10.0, 4: 1.0, 5: 0.001}


# a focal length from the focal plane's resolution further than this from the 35 mm equivalent's
# (both in the photo's EXIF) is taken for a photo resized or cropped since it was taken: a prior
EXIF_FOCAL_AGREE = 0.10
# FocalLengthIn35mmFilm is a whole number of millimetres: half of one is its sigma (2 % at 25 mm),
# a prior the vanishing points may move, not a fact (held at 26 mm for a 24.7 mm equivalent, a
# generator photo's W came out 1.3 % wide with H's sigma unchanged)
EXIF_35MM_ROUNDING_MM = 0.5


def exif_focal_px(sub, size: tuple[int, int]) -> tuple[float | None, str, float | None]:
    """The focal length in pixels of a photo of ``size`` (w, h) from its EXIF sub-IFD ``sub`` (a
    mapping of tag -> value), which tags gave it ('' where none did), and None where it is a fact,
    else the log sigma of a prior at it: where its two focal lengths disagree half the log of their
    ratio (at least :data:`EXIF_FOCAL_AGREE`'s), from the 35 mm equivalent alone its rounding to a
    whole millimetre (:data:`EXIF_35MM_ROUNDING_MM` over it).

    FocalLength (mm) x FocalPlaneXResolution (pixels per FocalPlaneResolutionUnit: inch by
    default, as Canon writes it; cm, mm or um) is the camera's own; it is scaled by the photo's
    pixels over PixelX/YDimension where the camera wrote those and the photo has their shape but
    another size (resized since). Else FocalLengthIn35mmFilm x the photo's diagonal / 43.3 mm,
    which scales with the photo's own pixels. Where both are given and disagree by more than
    :data:`EXIF_FOCAL_AGREE` (a photo resized with its EXIF kept, the pixel dimensions too: the 35 mm
    equivalent is right; or cropped: the plane's is), the focal length is a prior, not a fact: their
    geometric mean, with half the log of their ratio for its log sigma (each one sigma from it);
    unless the photo's shape differs from the camera's, a crop, which keeps the plane's density."""

    def num(tag) -> float:
        try:
            v = float(sub.get(tag) or 0.0)
        except (TypeError, ValueError, ZeroDivisionError):
            return 0.0
        return v if math.isfinite(v) and v > 0 else 0.0

    w, h = size
    fl, res, eq35 = num(0x920A), num(0xA20E), num(0xA405)
    try:
        unit = int(sub.get(0xA210, 2))
    except (TypeError, ValueError):
        unit = 0
    equivalent = eq35 * math.hypot(w, h) / math.hypot(36.0, 24.0) if eq35 else None
    plane, note, cropped = None, "", False
    if fl and res and unit in _PLANE_UNIT_MM:
        plane, note = fl * res / _PLANE_UNIT_MM[unit], "FocalLength x FocalPlaneXResolution"
        ex, ey = num(0xA002), num(0xA003)
        if ex and ey:
            long_ratio = max(w, h) / max(ex, ey)
            if abs(max(w, h) / min(w, h) - max(ex, ey) / min(ex, ey)) > 0.01 * max(ex, ey) / min(ex, ey):
                cropped = True
            elif abs(long_ratio - 1.0) > 1e-3:
                plane *= long_ratio
                note += f" x {long_ratio:.3g} (the photo resized from the camera's {ex:.0f} x {ey:.0f} px)"
    if plane is not None and equivalent is not None and not cropped:
        if abs(math.log(plane / equivalent)) > math.log1p(EXIF_FOCAL_AGREE):
            # a resize makes the 35 mm equivalent right, a crop the plane's: the prior between the two
            # (their geometric mean), each of them one sigma from it
            return (
                math.sqrt(plane * equivalent),
                f"FocalLengthIn35mmFilm ({eq35:g} mm, {equivalent:.0f} px) and FocalLength x "
                f"FocalPlaneXResolution ({plane:.0f} px) disagree: a photo resized or cropped since it was taken",
                max(abs(math.log(plane / equivalent)) / 2.0, math.log1p(EXIF_FOCAL_AGREE)),
            )
    if plane is not None:
        return plane, note, None
    if equivalent is not None:
        return equivalent, f"FocalLengthIn35mmFilm ({eq35:g} mm)", EXIF_35MM_ROUNDING_MM / eq35
    return None, "", None


def _exif_camera(im) -> tuple[float | None, float | None, str, float | None]:
    try:
        exif = im.getexif()
        sub = exif.get_ifd(0x8769)
        gps = exif.get_ifd(0x8825)
    except Exception:  # noqa: BLE001 - a broken EXIF block only means no EXIF
        return None, None, "", None
    focal, note, log_sigma = exif_focal_px(sub, im.size)
    heading = None
    try:
        if 17 in gps:
            heading = float(gps[17]) % 360.0
    except (TypeError, ValueError, ZeroDivisionError):
        heading = None
    return focal, heading, note, log_sigma


def _exif_lens(im) -> dict | None:
    """The camera and lens EXIF names (Make, Model, LensMake, LensModel) and the focal length in
    mm and f-number, as far as the photo has them; None without a camera model."""
    try:
        exif = im.getexif()
        sub = exif.get_ifd(0x8769)
    except Exception:  # noqa: BLE001 - a broken EXIF block only means no EXIF
        return None

    def text(v):
        return str(v).strip("\x00 ").strip() if v else ""

    out = {
        "make": text(exif.get(0x010F)),
        "model": text(exif.get(0x0110)),
        "lens_make": text(sub.get(0xA433)),
        "lens_model": text(sub.get(0xA434)),
    }
    for key, tag in (("focal_mm", 0x920A), ("f_number", 0x829D)):
        try:
            out[key] = float(sub[tag]) if sub.get(tag) else None
        except (TypeError, ValueError, ZeroDivisionError):
            out[key] = None
    return out if out["model"] else None


_EXIF_ORIENTATION = 0x0112
_WIDE_GREY = ("I;16", "I;16B", "I;16L", "I;16N", "I", "F")  # 16-bit, 32-bit and float single-channel


def _photo_rgb(im) -> np.ndarray:
    """A decoded photo as float32 ``(rows, cols, 3)`` in [0, 1], turned upright as its EXIF
    orientation says (a phone stores a portrait photo as landscape pixels tagged to be turned
    90 degrees, as viewers and LabelMe show it). A 16-bit greyscale image is scaled by its own
    range (to 65,535, or its largest value above that): Pillow's conversion to RGB clipped it at
    255, so a 16-bit PNG of a wall read as a white photo."""
    from PIL import ImageOps

    try:
        turned = im.getexif().get(_EXIF_ORIENTATION, 1) in range(2, 9)
    except Exception:  # noqa: BLE001 - a broken EXIF block only means no orientation
        turned = False
    if turned:
        im = ImageOps.exif_transpose(im)
    if im.mode in _WIDE_GREY:
        grey = np.asarray(im, dtype=np.float32)
        top = float(np.nanmax(grey)) if grey.size else 1.0
        scale = 1.0 if im.mode == "F" and top <= 1.0 else 255.0 if top <= 255 else max(65535.0, top)
        grey = np.clip(np.nan_to_num(grey / scale), 0.0, 1.0)
        return np.repeat(grey[..., None], 3, axis=-1)
    rgb = np.asarray(im if im.mode == "RGB" else im.convert("RGB"), dtype=np.float32)
    rgb /= 255.0  # in place: the same values as a division into a new array, one 6 MP copy fewer
    return rgb


_HEIF_SUFFIXES = (".heic", ".heif", ".hif")


def _is_heif(path: Path, data: bytes | None) -> bool:
    """A HEIF file by its name, or by its first box (``ftyp`` and a HEIF brand) whatever its name."""
    if path.suffix.lower() in _HEIF_SUFFIXES:
        return True
    if data is not None:
        head = data[:12]
    else:
        try:
            with path.open("rb") as f:
                head = f.read(12)
        except OSError:
            return False
    return head[4:8] == b"ftyp" and head[8:12] in (
        b"heic",
        b"heix",
        b"heim",
        b"heis",
        b"hevc",
        b"hevx",
        b"mif1",
        b"msf1",
    )


@functools.cache
def _heif_opener() -> bool:
    """Pillow opens HEIC/HEIF photos (a phone's default) once pillow-heif registers them; libheif
    turns them upright as their transforms say and pillow-heif sets their EXIF orientation to 1, so
    they are not turned twice. False where pillow-heif is not installed."""
    try:
        from pillow_heif import register_heif_opener
    except ImportError:
        return False
    register_heif_opener()
    return True


def read_photo(path: str | Path, *, field: str = "PHOTO", data: bytes | None = None) -> Photo:
    """Read a colour photo (JPEG, PNG, TIFF, HEIC) and its EXIF focal length, compass heading and
    lens; from its bytes ``data``, when given (a photo made in memory), named ``path``."""
    path = Path(path)
    if _is_heif(path, data) and not _heif_opener():
        raise InputError(
            f"{field} {path}: a HEIC photo needs pillow-heif (pip install pillow-heif); or save it as a JPEG"
        )
    with _opened_image(path, field, "give a JPEG, PNG, TIFF or HEIC photo", data) as im:
        focal, heading, note, log_sigma = _exif_camera(im)
        lens = _exif_lens(im)
        rgb = _photo_rgb(im)
    if min(rgb.shape[:2]) < MIN_IMAGE_PX:
        raise InputError(f"{field} {path}: image is only {rgb.shape[1]} x {rgb.shape[0]} px; give the full photo")
    return Photo(
        path=path, rgb=rgb, focal_px=focal, heading_deg=heading, lens=lens, focal_note=note, focal_log_sigma=log_sigma
    )

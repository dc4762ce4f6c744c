"""Binary mask to labelled bricks (scikit-image / scipy labelling).

Specks (components far smaller than a typical brick) are dropped and small holes inside bricks
are filled; bricks touching the image border are kept. Labels are 4-connected, so two bricks
that touch only diagonally stay apart.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from functools import cached_property

import numpy as np
from scipy import ndimage

from .._morphology import opening
from .._threads import background, thread_map

__all__ = [
    "PhotoSegmentConfig",
    "SegmentConfig",
    "Segmentation",
    "label_bricks",
    "mortar_plausible",
    "segment_photo",
    "segment_wall",
]

_FOUR = ndimage.generate_binary_structure(2, 1)


@dataclass(frozen=True)
class SegmentConfig:
    """``speck_fraction``: components smaller than this fraction of the median brick area (and
    never fewer than ``min_speck_px`` pixels) are dropped. ``hole_fraction``: enclosed mortar
    holes smaller than this fraction of the median brick area are filled."""

    speck_fraction: float = 0.02
    min_speck_px: int = 6
    hole_fraction: float = 0.05


#: Pixels per chunk where numpy would otherwise make an 8-byte index copy of the whole label image.
_CHUNK_PX = 1 << 22


def _row_chunks(shape: tuple[int, ...], pixels: int = _CHUNK_PX):
    step = max(1, pixels // max(1, shape[1]))
    return (slice(r, r + step) for r in range(0, shape[0], step))


def _component_areas(labels: np.ndarray, n: int) -> np.ndarray:
    areas = np.zeros(n + 1, np.int64)
    for rows in _row_chunks(labels.shape):
        areas += np.bincount(labels[rows].ravel(), minlength=n + 1)
    return areas[1:]


def _lookup(table: np.ndarray, labels: np.ndarray) -> np.ndarray:
    """``table[labels]`` row chunk by row chunk (fancy indexing copies its index as int64)."""
    out = np.empty(labels.shape, table.dtype)
    for rows in _row_chunks(labels.shape):
        out[rows] = table[labels[rows]]
    return out


def label_bricks(mask: np.ndarray, config: SegmentConfig = SegmentConfig()) -> np.ndarray:
    """Label bricks of a boolean mask ``(rows, cols)``; returns int32 labels ``(rows, cols)``, 0 = mortar.

    Labels are numbered 1..K in raster order of each brick's first pixel.
    """
    # int32 labels and boolean temporaries, each freed when done: about 8 bytes per pixel at the
    # peak, so that a 12,000 x 12,000 mask labels in under 1.5 GB
    mask = np.asarray(mask, dtype=bool)
    labels = np.empty(mask.shape, np.int32)
    n = ndimage.label(mask, structure=_FOUR, output=labels)
    if n == 0:
        return labels
    areas = _component_areas(labels, n)
    big = areas[areas >= config.min_speck_px]
    median = float(np.median(big)) if big.size else float(np.median(areas))
    speck = max(config.min_speck_px, config.speck_fraction * median)
    keep = np.concatenate([[False], areas >= speck])
    clean = _lookup(keep, labels)
    # fill small enclosed holes (background components not touching the border)
    nh = ndimage.label(~clean, structure=_FOUR, output=labels)  # the brick labels are done with
    if nh:
        hole_areas = _component_areas(labels, nh)
        border = np.unique(np.concatenate([labels[0], labels[-1], labels[:, 0], labels[:, -1]]))
        small = hole_areas < config.hole_fraction * median
        small[border[border > 0] - 1] = False
        fill = np.concatenate([[False], small])
        clean |= _lookup(fill, labels)
    ndimage.label(clean, structure=_FOUR, output=labels)
    return labels


@dataclass(frozen=True)
class PhotoSegmentConfig:
    """Classical brick-versus-mortar segmentation of a rectified photo (scikit-image morphology).

    Mortar joints are thin lines that differ from the bricks on both sides, whatever each brick's
    colour: a morphological top-hat of radius ``joint_px`` (wider than a joint, narrower than a
    brick) keeps exactly them. Both the white top-hat (light mortar) and the black top-hat (dark
    mortar) are taken on CIELAB lightness and on chroma (grey mortar between coloured bricks); the
    channel whose response is most bimodal wins. A joint's contrast fades where the photo saw the
    wall obliquely or from far away, so the response is divided by its local peak (a maximum
    mean of likely joint pixels in a Gaussian window of ``window_px``, about a brick and a half) and
    cut at one half: each joint is split near half-way between its own mortar and brick levels. Responses
    below ``floor`` of the global 99th percentile are never mortar (brick texture). A final opening
    of ``separate_px`` parts bricks joined by a pixel or two.
    """

    joint_px: int = 4
    smooth_px: float = 0.7
    window_px: int = 151
    floor: float = 0.12
    separate_px: int = 1


def _wide_gaussian(img: np.ndarray, sigma: float) -> np.ndarray:
    """A Gaussian blur of ``img`` ``(rows, cols)`` (edges mirrored, as scipy's default) that is
    wide, ``sigma`` of tens of pixels, computed on a grid ``f = sigma // 6`` times coarser: block
    means of ``f x f`` pixels (their variance, ``f**2 / 12``, taken off the kernel's), the Gaussian
    there, and bilinear interpolation back. The image is mirrored by the kernel's reach first, so
    the edges are blurred as the direct filter blurs them. Within 8e-4 of the direct filter on a
    3 MP field of 0/1 blobs (whose blur spans 0.25), edges included, and 5x faster: the direct
    window of a brick and a half took 0.5 s per filter on a 3 MP orthophoto."""
    f = int(sigma // 6)
    if f < 2:
        return ndimage.gaussian_filter(img, sigma)
    rows, cols = img.shape
    m = f * int(np.ceil(4 * sigma / f))  # the kernel's reach, in whole blocks
    padded = np.pad(img, ((m, m + (-rows % f)), (m, m + (-cols % f))), mode="symmetric")
    blocks = padded.reshape(padded.shape[0] // f, f, padded.shape[1] // f, f).mean(axis=(1, 3), dtype=np.float64)
    coarse = ndimage.gaussian_filter(blocks, np.sqrt(sigma**2 - f**2 / 12.0) / f)
    # pixel i of the image is pixel i + m of the padded one; block k's centre is at k f + (f - 1) / 2
    r = (np.arange(rows) + m - (f - 1) / 2) / f
    c = (np.arange(cols) + m - (f - 1) / 2) / f
    r0, c0 = np.floor(r).astype(int), np.floor(c).astype(int)
    wr, wc = (r - r0)[:, None], (c - c0)[None, :]
    # bilinear is separable: along the columns on the coarse rows, then along the rows, in the
    # image's precision and in place (full-size float64 temporaries were 130 MB a call on 3 MP)
    across = (coarse[:, c0] * (1 - wc) + coarse[:, c0 + 1] * wc).astype(img.dtype)
    out = across[r0]
    out *= (1 - wr).astype(img.dtype)
    lower = across[r0 + 1]
    lower *= wr.astype(img.dtype)
    out += lower
    return out


def grey_morphology(image: np.ndarray, footprint: np.ndarray, op) -> np.ndarray:
    """scipy's ``grey_erosion`` (``op`` np.minimum) or ``grey_dilation`` (np.maximum) of a 2-D
    image by a footprint, mirrored at the edges (scipy's "reflect"): the same values.

    A symmetric footprint of odd sides on an image of a type OpenCV filters goes to OpenCV's
    ``erode`` / ``dilate`` (its ``BORDER_REFLECT`` is scipy's "reflect"; a minimum or maximum
    takes no rounding), about four times faster than the separable sliding windows this used
    before (as unions of centred rectangles; 7 against 27 ms on a 2 MP orthophoto's channel, by
    disk(4)), which were two to five times faster than scipy's filter over the footprint's pixels:
    the segmentation's four top-hats were a third of a photo wall's time. Any other footprint or
    type goes to scipy."""
    fp = np.asarray(footprint, dtype=bool)
    symmetric = fp.shape[0] % 2 == 1 and fp.shape[1] % 2 == 1 and np.array_equal(fp, fp[::-1, ::-1])
    if not symmetric or image.ndim != 2 or image.dtype not in (np.float32, np.float64, np.uint8, np.uint16, np.int16):
        f = ndimage.grey_erosion if op is np.minimum else ndimage.grey_dilation
        return f(image, footprint=fp, mode="reflect")
    import cv2

    f = cv2.erode if op is np.minimum else cv2.dilate
    return f(np.ascontiguousarray(image), fp.astype(np.uint8), borderType=cv2.BORDER_REFLECT)


def _otsu_split(values: np.ndarray) -> tuple[float, float] | None:
    """Otsu's threshold of ``values`` and how well it splits them (the between-class variance over
    the whole variance, in [0, 1]); None where one side is empty."""
    from skimage.filters import threshold_otsu

    t = threshold_otsu(values)
    lo, hi = values[values <= t], values[values > t]
    if len(lo) == 0 or len(hi) == 0:
        return None
    return t, float((hi.mean() - lo.mean()) ** 2 * len(lo) * len(hi) / values.size**2 / max(values.var(), 1e-12))


def _cielab(img: np.ndarray) -> np.ndarray:
    """CIELAB of an RGB image in [0, 1] (float32 in, float32 out). rgb2lab's temporaries are 5x its
    input: a band at a time, the bands on every core (numpy's arithmetic releases the GIL; 0.1 s of
    a 2.6 MP orthophoto on one core)."""
    from skimage.color import rgb2lab

    lab = np.empty_like(img)

    def to_lab(job) -> None:
        src_rgb, dst, rows = job
        dst[rows] = rgb2lab(src_rgb[rows])

    thread_map(to_lab, [(img, lab, rows) for rows in _row_chunks(img.shape, 1 << 18)])
    return lab


def _smoothed(rgb: np.ndarray, sigma: float) -> np.ndarray:
    """``rgb`` ``(rows, cols, 3)`` as float32, each channel Gaussian-smoothed over ``sigma`` px on a
    core of its own (scipy's filters release the GIL; the same values as one filter of the three
    with sigma 0 across them), clipped to [0, 1]. float32, as the orthophoto is: CIELAB of a 5 MP
    orthophoto took 1.5 s in float64 and 0.2 s in float32 (scikit-image keeps the dtype); the paper
    example's six masks came out identical."""
    src = np.asarray(rgb, dtype=np.float32)
    img = np.empty(src.shape[:2] + (3,), dtype=np.float32)

    def smooth(c: int) -> None:
        img[..., c] = ndimage.gaussian_filter(np.ascontiguousarray(src[..., c]), sigma)

    thread_map(smooth, range(3))
    np.clip(img, 0, 1, out=img)
    return img


def segment_photo(rgb: np.ndarray, config: PhotoSegmentConfig = PhotoSegmentConfig()) -> np.ndarray:
    """Boolean brick mask ``(rows, cols)`` of a rectified RGB photo in [0, 1] (bricks True)."""
    import cv2  # noqa: F401 - grey_morphology's, loaded here and not first on the threads below
    from skimage.filters import threshold_otsu
    from skimage.morphology import disk

    img = _smoothed(rgb, config.smooth_px)
    lab = _cielab(img)
    del img
    chroma = np.hypot(lab[..., 1], lab[..., 2])
    fp = disk(config.joint_px)
    chans = (np.ascontiguousarray(lab[..., 0]), chroma)
    del lab

    def top_hat(job):  # white (light mortar) or black (dark mortar) top-hat of a channel
        chan, white = job
        if white:  # scipy's grey_opening and grey_closing, the same values
            return chan - grey_morphology(grey_morphology(chan, fp, np.minimum), fp, np.maximum)
        return grey_morphology(grey_morphology(chan, fp, np.maximum), fp, np.minimum) - chan

    # the four morphological filters on every core (numpy's minimum and maximum release the GIL)
    responses = thread_map(top_hat, [(c, white) for c in chans for white in (True, False)])

    def separation(resp):  # each response's normalised form and how well Otsu's cut splits it
        scale = float(np.percentile(resp, 99))
        if scale <= 1e-9:
            return None, -1.0
        r = np.clip(resp / scale, 0, 1.5)
        split = _otsu_split(r)
        return (None, -1.0) if split is None else (r, split[1])

    best, best_sep = None, -1.0
    for r, sep in thread_map(separation, responses):  # in order: the first of equal ones wins, as before
        if r is not None and sep > best_sep:
            best, best_sep = r, sep
    responses = chans = r = None  # only the chosen response is needed from here
    if best is None:
        return np.ones(rgb.shape[:2], dtype=bool)
    # the local joint level: the mean response of likely-joint pixels (above a low global cut)
    # in a Gaussian window, so faint joints far from the camera get their own threshold
    likely = best > max(config.floor, 0.5 * threshold_otsu(best))
    sigma = max(1.0, config.window_px / 4)
    weight = background(_wide_gaussian, likely.astype(np.float32), sigma)  # the two wide filters at once
    level = _wide_gaussian((best * likely).astype(np.float32), sigma) / np.maximum(weight.result(), 1e-6)
    mortar = (best > 0.5 * level) & (best > config.floor)
    bricks = ~mortar
    if config.separate_px > 0:
        bricks = opening(bricks, disk(config.separate_px))  # scipy's binary_opening's pixels
    return bricks


@dataclass(frozen=True)
class Segmentation:
    """A wall's orthophoto segmented: the brick ``mask`` (rows, cols) for tracing, the method that
    made it, and what it found (:meth:`summary`)."""

    mask: np.ndarray
    method: str  # "mortar" (the top-hat), "colour" (broad mortar by its colour) or "joints" (wall2d.pieces)
    px_per_m: float
    pieces: object | None = None  # wall2d.pieces.Pieces, for the "joints" method
    note: str = ""  # why the method was chosen
    coarse: str = ""  # why the resolution is too coarse for the joints ("" when it is not)
    # the mask's labels where the caller has them (:func:`segment_wall` labels the top-hat's mask
    # to judge it): :attr:`labels` then does not label it again (0.06 s of a rectify)
    known_labels: np.ndarray | None = field(default=None, repr=False, compare=False)
    # the openings left out of the wall (windows, doors: :func:`find_openings`), True there; None: none
    openings: np.ndarray | None = field(default=None, repr=False, compare=False)

    @cached_property
    def labels(self) -> np.ndarray:
        """The pieces labelled ``(rows, cols)`` int32, 0 mortar: each piece its own label even where
        two touch (the joints' partition), for :func:`~calib_masonry.wall2d.trace.trace_labels`.
        Computed once (the LabelMe polygons and the summary both ask), and read-only, as it is
        shared."""
        if self.pieces is not None:
            out = np.where(self.mask, self.pieces.labels, 0).astype(np.int32)
        elif self.known_labels is not None:
            out = self.known_labels
        else:
            out = label_bricks(self.mask)
        out.setflags(write=False)
        return out

    def padded_top(self, rows: int) -> "Segmentation":
        """The same segmentation of an orthophoto ``rows`` rows taller, the rows added on top
        holding no piece (a wall's orthophoto whose top band was not seen as wall and was left
        out of the segmentation: :func:`calib_masonry.pipeline.photo_wall`)."""
        if rows <= 0:
            return self

        def pad(a: np.ndarray | None) -> np.ndarray | None:
            return None if a is None else np.pad(a, ((rows, 0), (0, 0)))

        pieces = self.pieces
        if pieces is not None:
            pieces = replace(pieces, labels=pad(pieces.labels), joints=pad(pieces.joints))
        return Segmentation(
            mask=pad(self.mask),
            method=self.method,
            px_per_m=self.px_per_m,
            pieces=pieces,
            note=self.note,
            coarse=self.coarse,
            known_labels=pad(self.known_labels),
            openings=pad(self.openings),
        )

    def summary(self) -> dict:
        if self.pieces is not None:
            doc = self.pieces.summary()
        else:
            a = np.bincount(self.labels.ravel())[1:]
            a = a[a > 0] / self.px_per_m**2
            n = len(a)
            # (course height, unit length) as the joints' partition gives it: the pieces' median
            # height and length (their square root of area, 18.7 x 18.7 cm, said nothing of 30 x 12
            # cm bricks)
            module = median_box_m(self.labels, self.px_per_m)
            doc = {
                "count": n,
                "median_area_m2": float(np.median(a)) if n else 0.0,
                "max_area_m2": float(a.max()) if n else 0.0,
                "min_area_m2": float(a.min()) if n else 0.0,
                "module_m": [float(module[0]), float(module[1])],
                "module_source": "the pieces' median height and length",
                "warning": "" if n > 1 else "the segmentation found one piece: no joints stand out",
            }
        if self.coarse:
            doc["warning"] = f"{doc['warning']}; {self.coarse}" if doc["warning"] else self.coarse
        aspect = piece_aspect(self.labels)
        doc["piece_aspect"] = aspect
        if aspect is not None and aspect > UPRIGHT_ASPECT:
            turned = (
                f"the pieces are taller than wide (height / width {aspect:.2f} on average), where masonry is laid with "
                "its long side level: if the photo is turned by 90 degrees (its EXIF orientation lost), turn it "
                "upright and rectify again"
            )
            doc["warning"] = f"{doc['warning']}; {turned}" if doc["warning"] else turned
        doc.update(method=self.method, method_note=self.note)
        if self.openings is not None:
            _, n = ndimage.label(self.openings)
            doc.update(openings=int(n), openings_m2=float(self.openings.sum() / self.px_per_m**2))
        return doc


def median_box_m(labels: np.ndarray, px_per_m: float) -> np.ndarray:
    """The median height and length (m) of the pieces' bounding boxes in ``labels`` (0 mortar):
    the course height and unit length they give. Zeros where there is no piece."""
    boxes = [b for b in ndimage.find_objects(labels) if b is not None]
    size = np.array([[b[0].stop - b[0].start, b[1].stop - b[1].start] for b in boxes], dtype=np.float64)
    return np.median(size, axis=0) / px_per_m if len(size) else np.zeros(2)


#: the pieces' mean height / width (:func:`piece_aspect`) above which they stand taller than wide, as
#: the units of a photo turned by 90 degrees do: the laboratory photos rectified at 150-600 px/m
#: 0.70-1.27 upright and 1.42-2.14 turned (the segmentation is coarsest, and least upright, at
#: 150-200 px/m); 49 orthophotos of synth's brick and stone walls photographed 0.45-0.86 upright and
#: 1.36-2.21 turned (docs/photo_path.md)
UPRIGHT_ASPECT = 1.4


def piece_aspect(labels: np.ndarray, *, min_pieces: int = 5, max_px: int = 2_000_000) -> float | None:
    """The pieces' mean height over width in ``labels`` (0 mortar): the area-weighted geometric mean of
    each piece's ratio (the square root of its second moments', rows over columns), on a grid
    thinned to at most ``max_px`` pixels; None for fewer than ``min_pieces`` pieces."""
    step = max(1, math.ceil(math.sqrt(labels.size / max_px)))
    thin = np.asarray(labels)[::step, ::step]
    lab = thin.ravel()
    n = int(lab.max(initial=0)) + 1
    count = np.bincount(lab, minlength=n).astype(np.float64)
    moments = []
    for x in (np.asarray(g, dtype=np.float64).ravel() for g in np.indices(thin.shape)):
        with np.errstate(invalid="ignore", divide="ignore"):
            mean = np.bincount(lab, weights=x, minlength=n) / count
            moments.append(np.bincount(lab, weights=x * x, minlength=n) / count - mean**2)
    keep = (count > 0) & (np.arange(n) > 0) & (moments[0] > 0) & (moments[1] > 0)
    if int(keep.sum()) < min_pieces:
        return None
    log_ratio = 0.5 * np.log(moments[0][keep] / moments[1][keep])
    return float(np.exp(np.average(log_ratio, weights=count[keep])))


#: the least median area (m^2) of a wall's units: a small brick is 40 cm^2 and more on its face; a
#: top-hat's pieces of grain or noise are specks of a square centimetre or two, of one size
MIN_UNIT_AREA_M2 = 10e-4


#: how :func:`mortar_plausible` begins when the pieces' sizes differ wildly
WILD = "the mortar top-hat's pieces differ wildly in size"


def mortar_plausible(mask: np.ndarray, labels: np.ndarray | None = None, px_per_m: float | None = None) -> str:
    """Why a top-hat mortar mask does not look like masonry ("" when it does): bricks of one
    format give pieces of similar size (the median piece within a third of the area-weighted mean,
    measured 0.91-1.08 on the synthetic brick walls); texture taken for mortar gives a few large
    pieces among a crowd of specks (0.01-0.02 on the laboratory photos), a face without joints one,
    and a face of even grain or noise specks all of one size, under :data:`MIN_UNIT_AREA_M2` (with
    ``px_per_m``). ``labels``: the mask's :func:`label_bricks`, where the caller has them."""
    if labels is None:
        labels = label_bricks(mask)
    a = np.bincount(labels.ravel())[1:]
    a = a[a > 0].astype(np.float64)
    if len(a) < 4:
        return f"the mortar top-hat found {len(a)} piece(s)"
    median = float(np.median(a))
    if px_per_m is not None and median / px_per_m**2 < MIN_UNIT_AREA_M2:
        return (
            f"the mortar top-hat's pieces are specks (median {median / px_per_m**2 * 1e4:.1f} cm^2, "
            f"a unit's face is {MIN_UNIT_AREA_M2 * 1e4:.0f} cm^2 or more): grain, not joints"
        )
    weighted = float((a * a).sum() / a.sum())
    ratio = median / weighted
    if ratio < 0.3:
        return f"{WILD} (median {ratio:.2f} of the weighted mean)"
    return ""


def _top_hat_units(
    mortar_mask: np.ndarray, px_per_m: float, valid: np.ndarray | None
) -> tuple[np.ndarray, np.ndarray, str]:
    """The units the mortar top-hat's mask ``mortar_mask`` (True off the joints) gives within
    ``valid``, their labels, and why they do not look like masonry ("" when they do)."""
    if valid is not None:
        mortar_mask = mortar_mask & valid
    # the joints carried on straight to the orthophoto's sides, as the colour split's are: a strip of
    # ground or sky inside the outline joined the units along it (a course of bricks as one piece)
    units = _joints_to_the_border(mortar_mask, int(round(EDGE_BAND_M * px_per_m)))  # only takes units away
    units = _bands_without_joints(units, valid, int(round(JOINTLESS_BAND_M * px_per_m)))  # so does this
    labels = label_bricks(units)
    return units, labels, mortar_plausible(units, labels, px_per_m)


#: the colour split (:func:`segment_by_colour`): the orthophoto is smoothed over this (m) first, and
#: the units opened by it after, so that grain and speckle finer than half a centimetre are neither
MORTAR_SMOOTH_M = 0.005
#: of the mortar side of the colour split, at least this share must be one connected network (the
#: joints between units are; texture on the units' faces is spots)
MORTAR_NETWORK = 0.9
#: the mortar side of the colour split covers at most this share of the wall (the units are most of it)
MORTAR_MOST = 0.5
#: the band along the orthophoto's sides (m) where the top-hat's and the colour split's joints are
#: carried straight on from just inside it: an outline a centimetre or two beyond the wall takes in
#: ground, sky or the next wall, which is not mortar and joined every unit of the course along it
EDGE_BAND_M = 0.02


def _joints_to_the_border(units: np.ndarray, band: int) -> np.ndarray:
    """``units`` ``(rows, cols)`` with the joints that reach each side's band of ``band`` pixels
    run on straight through it to the border (a band pixel is a unit only where the row or column
    just inside it is; the top and bottom first, then the sides over the whole height): nothing in
    the band joins two units that the wall inside it keeps apart, and nothing in it is made a unit.
    Unchanged where the band would take more than a quarter of either side."""
    rows, cols = units.shape
    if band < 1 or 4 * band >= min(rows, cols):
        return units
    out = units.copy()
    out[:band] &= out[band]
    out[rows - band :] &= out[rows - band - 1]
    out[:, :band] &= out[:, band : band + 1]
    out[:, cols - band :] &= out[:, cols - band - 1 : cols - band]
    return out


#: how deep a band along the orthophoto's top or bottom (m) may be that :func:`_bands_without_joints`
#: takes out: a capping or bed of mortar, a sill (a course of masonry is crossed by its head joints)
JOINTLESS_BAND_M = 0.10
#: ... a row whose share of mortar is under this fraction of the median row's
JOINTLESS_SHARE = 0.25


def _bands_without_joints(units: np.ndarray, valid: np.ndarray | None, band: int) -> np.ndarray:
    """``units`` ``(rows, cols)`` without a band along its top and its bottom, at most ``band``
    deep, that holds a row the mortar top-hat found (almost) no joint across: a row through a course
    of masonry crosses its head joints, so such a row is a band of another kind along the wall's
    edge, a capping or bed of mortar wider than the top-hat finds (a plateau, not a line), a beam or
    sill, and as a unit it joined every unit of the course beside it (synth's walls end in up to 0.4
    of a course of mortar: the top course of a wall as one piece; the band's own texture may show
    a few specks of "mortar"). A row with almost no joint has a share of mortar under a quarter of
    the wall's own median row's (its head joints' share, most rows being rows through courses), so
    that a wall of long units, whose rows cross few joints, keeps its courses; everything from the
    edge to the deepest such row that three rows through a course (neither almost jointless nor
    over half mortar, as a bed joint's row is) follow is taken out: the top course's head joints
    stop a few rows short of a band the top-hat does not find, and those rows joined the course.
    Unchanged where the median row crosses no joint."""
    rows = units.shape[0]
    seen = np.ones_like(units) if valid is None else valid
    counted = seen.sum(axis=1)
    share = 1.0 - (units & seen).sum(axis=1) / np.maximum(counted, 1)
    typical = float(np.median(share[counted > 0])) if (counted > 0).any() else 0.0
    if typical <= 0.0:
        return units
    jointless = (counted > 0) & (share < JOINTLESS_SHARE * typical)
    course = (counted > 0) & ~jointless & (share <= 0.5)
    run = np.convolve(course.astype(np.int64), np.ones(3, dtype=np.int64), mode="valid") == 3  # rows k..k+2

    def depth(flags_run: np.ndarray, flags_jointless: np.ndarray) -> int:
        """Rows from this edge to the masonry: to just past the deepest almost jointless row within
        ``band`` that three rows through a course follow (0: none)."""
        for j in np.flatnonzero(flags_jointless[:band])[::-1]:
            if j + 1 < len(flags_run) and flags_run[j + 1]:
                return int(j) + 1
        return 0

    out = units.copy()
    top = depth(run, jointless)
    bottom = depth(run[::-1], jointless[::-1])
    if top:
        out[:top] = False
    if bottom:
        out[rows - bottom :] = False
    return out


def segment_by_colour(
    rgb: np.ndarray, px_per_m: float, valid: np.ndarray | None = None
) -> tuple[np.ndarray | None, str]:
    """Units against broad mortar by colour: the brick mask ``(rows, cols)``, or None and why not.

    Rubble and stone walls have joints of 2-6 cm, wider than the top-hat of :func:`segment_photo`
    keeps whole (a joint wider than its disk is a plateau, not a line), whose pale band the top-hat
    finds only at its edges. Here CIELAB lightness and chroma, smoothed over
    :data:`MORTAR_SMOOTH_M`, are each split at Otsu's threshold, the lighter or the greyer side
    taken for mortar (and the other way round); a split counts only where its mortar side is one
    network (:data:`MORTAR_NETWORK`), at most :data:`MORTAR_MOST` of the wall, and its units look like
    masonry (:func:`mortar_plausible`). Of those, the one whose two sides Otsu separates best. On
    the laboratory photos (painted speckle, tight joints) no split counts. Within
    :data:`EDGE_BAND_M` of the orthophoto's sides the joints run on straight from inside it
    (:func:`_joints_to_the_border`)."""
    from skimage.morphology import disk

    r = max(1, int(round(MORTAR_SMOOTH_M * px_per_m)))
    band = int(round(EDGE_BAND_M * px_per_m))
    img = _smoothed(rgb, MORTAR_SMOOTH_M * px_per_m)
    lab = _cielab(img)
    del img
    inside = np.ones(rgb.shape[:2], dtype=bool) if valid is None else valid
    best, best_sep, why = None, -1.0, "no colour split looks like mortar"
    for chan in (lab[..., 0], np.hypot(lab[..., 1], lab[..., 2])):
        values = chan[inside]
        split = _otsu_split(values)
        if split is None or values.var() <= 1e-12:
            continue
        t, sep = split
        for mortar in (chan > t, chan <= t):
            mortar &= inside
            share = mortar.sum() / max(1, inside.sum())
            if not 0.0 < share <= MORTAR_MOST:
                continue
            parts, n = ndimage.label(mortar)
            if n == 0 or np.bincount(parts.ravel())[1:].max() < MORTAR_NETWORK * mortar.sum():
                continue
            units = _joints_to_the_border(opening(~mortar & inside, disk(r)), band)
            labels = label_bricks(units)
            problem = mortar_plausible(units, labels, px_per_m)
            if problem:
                why = problem.replace("the mortar top-hat", "the colour split")
            elif sep > best_sep:
                best, best_sep = units, sep
    return (best, "") if best is not None else (None, why)


#: the joints' partition is made at this resolution (px per metre of wall), or the orthophoto's
#: own where that is coarser, on at most MAX_PIECES_PIXELS pixels
PIECES_PX_PER_M = 300.0
#: the fewest pixels across a joint (PieceConfig.joint_width_m) the joints' partition is trusted
#: at: the laboratory stone walls' 30-40 stones came out as 19-25 at 200 px/m (1.6 px), 12-15
#: at 100 px/m, against 29-36 from 250 px/m (2.0 px) up
MIN_JOINT_PX = 2.0
MAX_PIECES_PIXELS = 2.0e7


def _resampled(img: np.ndarray, shape: tuple[int, int], *, order: int) -> np.ndarray:
    """``img`` ``(rows, cols[, C])`` resampled to ``shape`` (pixel centres matched: output pixel
    ``o`` samples the input at ``(o + 0.5) n / n_out - 0.5``), linearly or (``order=0``) nearest."""
    rows, cols = img.shape[:2]
    ys = (np.arange(shape[0]) + 0.5) * rows / shape[0] - 0.5
    xs = (np.arange(shape[1]) + 0.5) * cols / shape[1] - 0.5
    if order == 0:
        r = np.clip(np.round(ys).astype(int), 0, rows - 1)
        c = np.clip(np.round(xs).astype(int), 0, cols - 1)
        return img[np.ix_(r, c)]
    grid = np.meshgrid(ys, xs, indexing="ij")
    if img.ndim == 2:
        return ndimage.map_coordinates(img, grid, order=1, mode="nearest")
    return np.stack(
        [ndimage.map_coordinates(img[..., k], grid, order=1, mode="nearest") for k in range(img.shape[2])], -1
    )


#: an opening (a window, a door) differs from the units in colour by this many of the units' own
#: spread (pieces' mean chromaticity, robust): the facades' glass and frames stood at 4-6 in red and
#: blue on red brick, a run of bricks the top-hat joined 0.3-0.7
OPENING_COLOUR_SIGMAS = 6.0
#: the least spread of the units' chromaticity taken (units of one tone, drawn: a red share of 0.06
#: at six of it)
OPENING_SPREAD_FLOOR = 0.01
#: an opening holds a disk this wide (m): the mortar's joints, of the same outlier colour, do not
OPENING_DISK_M = 0.10
#: and is at least this large (m^2: a slit window 0.2 x 0.75 m; a rubble wall's largest stones are
#: under 0.1) and this many median pieces (the facades' windows 20-70)
OPENING_MIN_M2 = 0.15
OPENING_MIN_PIECES = 8.0
#: of an opening, at most this share is pieces of a unit's size: glass, a frame and a door hold
#: none (the top-hat joins them into one piece or takes a pale frame for mortar), a patch of bricks
#: of another colour is mostly its bricks
OPENING_MASONRY_SHARE = 0.1


def _least_opening_px(px_per_m: float, median_px: float) -> float:
    """The least area (pixels) of an opening among pieces of median area ``median_px``."""
    return max(OPENING_MIN_M2 * px_per_m**2, OPENING_MIN_PIECES * median_px)


def _has_giant(labels: np.ndarray, px_per_m: float) -> bool:
    """Whether a piece of ``labels`` is as large as :func:`find_openings` asks of an opening."""
    a = np.bincount(labels.ravel())[1:]
    a = a[a > 0]
    if len(a) < 4:
        return False
    return float(a.max()) >= _least_opening_px(px_per_m, float(np.median(a)))


def find_openings(
    rgb: np.ndarray, labels: np.ndarray, px_per_m: float, valid: np.ndarray | None = None
) -> np.ndarray | None:
    """The openings of a wall's orthophoto (windows and doors, with their frames; True there), from
    the mortar top-hat's pieces ``labels`` whose sizes differ wildly (a window's glass and frame
    join the bricks around it into one piece 40-70 times the median): the regions at least
    :data:`OPENING_MIN_M2` and :data:`OPENING_MIN_PIECES` median pieces large, a disk
    :data:`OPENING_DISK_M` wide within them, whose colour (chromaticity, smoothed over 2 cm) lies
    :data:`OPENING_COLOUR_SIGMAS` of the units' spread from the units' (the pieces of a unit's
    size), with next to no unit-sized piece in them. None where there is none."""
    from skimage.morphology import disk

    a = np.bincount(labels.ravel())
    ids = np.flatnonzero(a[1:]) + 1
    if len(ids) < 4:
        return None
    median = float(np.median(a[ids]))
    units = ids[a[ids] <= 3.0 * median]
    total = np.asarray(rgb, dtype=np.float64).sum(axis=2) + 1e-6
    # red and blue shares (the light left out), smoothed over 2 cm: the units' own with their joints'
    chroma = [ndimage.gaussian_filter(rgb[..., c] / total, 0.02 * px_per_m) for c in (0, 2)]
    means = np.stack([ndimage.mean(c, labels, units) for c in chroma], axis=1)
    centre = np.median(means, axis=0)
    spread = np.maximum(1.4826 * np.median(np.abs(means - centre), axis=0), OPENING_SPREAD_FLOOR)
    z2 = sum(((c - m) / d) ** 2 for c, m, d in zip(chroma, centre, spread))
    other = z2 > OPENING_COLOUR_SIGMAS**2
    if valid is not None:
        other &= valid
    other = opening(other, disk(max(1, int(round(0.5 * OPENING_DISK_M * px_per_m)))))
    regions, n = ndimage.label(other)
    if n == 0:
        return None
    size = np.bincount(regions.ravel(), minlength=n + 1).astype(np.float64)
    masonry = np.bincount(regions.ravel(), weights=np.isin(labels, units).ravel(), minlength=n + 1)
    keep = np.flatnonzero((size >= _least_opening_px(px_per_m, median)) & (masonry <= OPENING_MASONRY_SHARE * size))
    keep = keep[keep > 0]
    return np.isin(regions, keep) if keep.size else None


def _partition(rgb: np.ndarray, px_per_m: float, config, valid: np.ndarray | None):
    """The joints' partition (:func:`~calib_masonry.wall2d.pieces.segment_pieces`) of ``rgb`` at
    one resolution, whatever the orthophoto's (its pieces changed by a third between 300 and 550
    px/m, measured), never finer than the orthophoto (a 20 px/m orthophoto of a 14 x 75 m fit was
    taken to 300 px/m: 96 Mpx, 10 GB, for detail that is not there) and never above
    :data:`MAX_PIECES_PIXELS`, its labels back in the orthophoto's pixels; and the scale it ran at."""
    from .pieces import segment_pieces

    f = min(PIECES_PX_PER_M / px_per_m, 1.0, math.sqrt(MAX_PIECES_PIXELS / max(1, rgb.shape[0] * rgb.shape[1])))
    work, work_valid = rgb, valid
    if abs(f - 1.0) > 0.05:
        shape = (max(8, round(rgb.shape[0] * f)), max(8, round(rgb.shape[1] * f)))
        work = _resampled(np.asarray(rgb, dtype=np.float32), shape, order=1)
        work_valid = None if valid is None else _resampled(valid.astype(np.float32), shape, order=1) > 0.5
    work_ppm = px_per_m * work.shape[1] / rgb.shape[1]
    pieces = segment_pieces(work, work_ppm, config, valid=work_valid)
    if work is not rgb:
        labels = _resampled(pieces.labels, rgb.shape[:2], order=0)
        pieces = replace(pieces, labels=labels.astype(np.int32), px_per_m=float(px_per_m))
    return pieces, work_ppm


#: the top-hat's pieces this many median pieces large or more, at most this share of its pieces'
#: area, are split by the joints' partition where the rest looks like masonry
GIANT_SHARE = 0.25


def _giants_split(rgb, px_per_m, labels, valid, config) -> tuple[np.ndarray, int] | None:
    """The top-hat's ``labels`` with its pieces far larger than the rest (at least
    :data:`OPENING_MIN_PIECES` median pieces: a course whose head joints the top-hat did not see on
    a facade's far side, a band of bricks in an eave's shade) split by the joints' partition, the
    course height and unit length given by the rest's; and how many were split. None where there
    is none, where they hold more than :data:`GIANT_SHARE` of the pieces' area, or where the rest
    does not look like masonry."""
    a = np.bincount(labels.ravel())
    ids = np.flatnonzero(a[1:]) + 1
    if len(ids) < 4:
        return None
    giant_ids = ids[a[ids] >= OPENING_MIN_PIECES * float(np.median(a[ids]))]
    if not giant_ids.size or a[giant_ids].sum() > GIANT_SHARE * a[ids].sum():
        return None
    from .pieces import pieces_mask

    giant = np.isin(labels, giant_ids)
    rest = np.where(giant, 0, labels).astype(np.int32)
    if mortar_plausible(rest > 0, rest, px_per_m):
        return None
    size = median_box_m(rest, px_per_m)
    inside = giant if valid is None else giant & valid
    pieces, _ = _partition(rgb, px_per_m, replace(config, module_m=(float(size[0]), float(size[1]))), inside)
    split = np.where(inside & (pieces.labels > 0), pieces.labels + int(rest.max()), 0)
    # the partition's pieces touch: a pixel's line taken off where two meet, as its own mask has
    joined = replace(pieces, labels=np.where(giant, split, rest).astype(np.int32))
    mask = pieces_mask(joined)
    return np.where(mask, joined.labels, 0).astype(np.int32), int(len(giant_ids))


def segment_wall(
    rgb: np.ndarray,
    px_per_m: float,
    config: PhotoSegmentConfig | None = None,
    *,
    pieces_config=None,
    valid: np.ndarray | None = None,
) -> Segmentation:
    """Segment a wall's orthophoto ``(rows, cols, 3)`` at ``px_per_m`` into masonry units: the
    mortar top-hat (:func:`segment_photo`: exact on brick walls with visible mortar) when its pieces
    look like masonry (:func:`mortar_plausible`), else the mortar by its colour where its joints
    are broad (:func:`segment_by_colour`: rubble and stone walls), else the joints' partition
    (:func:`calib_masonry.wall2d.pieces.segment_pieces`: stones, plaster, speckle, cracks).
    ``valid``: the pixels that are wall (False under an occluder): no piece covers the others."""
    from .pieces import PieceConfig, pieces_mask

    config = config or PhotoSegmentConfig(window_px=int(round(0.5 * px_per_m)))
    pc = pieces_config or PieceConfig()
    mortar_mask = segment_photo(rgb, config)
    units, labels, why = _top_hat_units(mortar_mask, px_per_m, valid)
    holes = None
    # a piece far larger than the rest may be an opening: a facade's windows and doors, each joined
    # with the bricks around it into one piece, made the top-hat's pieces implausible and the
    # joints' partition cut the whole wall into blobs (module 27.6 x 26.6 cm for 40 x 18 cm
    # bricks), or, one window in a large wall, left them plausible with the window a unit; with the
    # openings left out, as occluders are, the top-hat's pieces may be the wall's units, and where
    # they are not (joints too faint on a facade seen at 23 degrees) the other methods run without
    # them
    if (not why or why.startswith(WILD)) and _has_giant(labels, px_per_m):
        holes = find_openings(rgb, labels, px_per_m, valid)
    if holes is not None:
        holes = ndimage.binary_dilation(holes, iterations=max(1, int(round(0.02 * px_per_m))))
        n = ndimage.label(holes)[1]
        left_out = (
            f"{n} opening{'s' if n > 1 else ''} left out (regions of another colour without units, "
            f"{holes.sum() / px_per_m**2:.2f} m^2: windows, doors)"
        )
        seen = ~holes if valid is None else valid & ~holes
        kept, kept_labels, still = _top_hat_units(mortar_mask, px_per_m, seen)
        if not still:
            return Segmentation(
                mask=kept,
                method="mortar",
                px_per_m=float(px_per_m),
                note=f"the mortar top-hat, {left_out}" + (f"; before, {why}" if why else ""),
                known_labels=kept_labels,
                openings=holes,
            )
        if why:
            why, valid = f"{why}; {left_out}, {still}", seen
        else:
            holes = None  # the top-hat's pieces were plausible with them and are not without: keep them
    if not why:
        return Segmentation(
            mask=units, method="mortar", px_per_m=float(px_per_m), note="the mortar top-hat", known_labels=labels
        )
    if why.startswith(WILD):
        # a few pieces of brick the top-hat saw no joints in (faint or shaded), among pieces that
        # look like masonry: those split by the joints' partition, not the whole wall (3 of 35
        # Blender facades became blobs of 25-32 x 28-49 cm for their 18 x 40 cm bricks)
        split = _giants_split(rgb, px_per_m, kept_labels if holes is not None else labels, valid, pc)
        if split is not None:
            joined, n = split
            return Segmentation(
                mask=joined > 0,
                method="mortar",
                px_per_m=float(px_per_m),
                note=f"the mortar top-hat, its {n} piece{'s' if n > 1 else ''} far larger than the rest split by "
                f"the joints' partition ({why})",
                known_labels=joined,
                openings=holes,
            )
    if valid is not None:
        mortar_mask &= valid
    colour, not_colour = segment_by_colour(rgb, px_per_m, valid)
    if colour is not None:  # broad mortar, paler or greyer than the units
        return Segmentation(
            mask=colour, method="colour", px_per_m=float(px_per_m), note=f"{why}: the mortar's colour", openings=holes
        )
    why = f"{why}; {not_colour}"
    pieces, work_ppm = _partition(rgb, px_per_m, pc, valid)
    coarse = ""
    if work_ppm * pc.joint_width_m < MIN_JOINT_PX:
        coarse = (
            f"at {work_ppm:.0f} px/m a {pc.joint_width_m * 1000:.0f} mm joint is {work_ppm * pc.joint_width_m:.1f} px, "
            f"too coarse to find the joints (fewer, larger pieces); segment at "
            f"{math.ceil(MIN_JOINT_PX / pc.joint_width_m)} px/m or more (--px-per-m, photo_px_per_m), from a photo "
            "that holds as many"
        )
    mask = pieces_mask(pieces, mortar=~mortar_mask)
    return Segmentation(
        mask=mask,
        method="joints",
        px_per_m=float(px_per_m),
        pieces=pieces,
        note=f"{why}: the joints' partition",
        coarse=coarse,
        openings=holes,
    )

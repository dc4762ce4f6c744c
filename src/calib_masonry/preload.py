"""Imports paid before they are needed, in one place: what each stage imports on first use, by
name, so that a thread starts with its modules loaded, a Dask worker's first sample does not pay
for them, and a command can load JAX and a compiled fit on a second thread while this one works.

Two threads importing modules of one package at once can hang or see a module half initialised in
CPython 3.11's import locks (gh-83065; seen with matplotlib's ``rcParams``). So a place that starts
a thread calls :func:`preload` first, on its own thread, for what the thread will import
(tests/test_thread_imports.py checks that the library's threads import nothing); and
:func:`preload_in_background` first loads its ``first`` groups on the calling thread, so that the
calling thread, while the background one runs, imports nothing that the background one imports.

A group is a tuple of entries, each a string (so this module imports no stage and adds no edge to
the import graph): ``"pkg.mod"`` imports a module (``".x"`` is ``calib_masonry.x``),
``"pkg.mod:name"`` asks the module for a name (scikit-image loads a submodule when one of its
names is first asked for), ``"pkg.mod:name(args)"`` calls it with literal arguments (a compiled
fit's one-off loading), ``"?..."`` ignores an ImportError (an optional package), ``"@group"``
loads another group.
"""

from __future__ import annotations

import ast
import importlib
import threading

__all__ = ["GROUPS", "preload", "preload_in_background", "wait_for_background"]

GROUPS: dict[str, tuple[str, ...]] = {
    # the photo's automatic detection (calibrate.rectify, its threads in pipeline.resolve_photo_walls)
    "detection": (
        "encodings.ascii",  # EXIF text
        "cv2",  # the line segment detector and GrabCut
        "scipy.spatial",
        "PIL.Image",  # the photo's reader and its EXIF
        "PIL.ImageOps",
        "PIL.TiffImagePlugin",
        "scipy.sparse.csgraph:connected_components",  # plumb-line chains
        "skimage.color:rgb2lab",  # the outline's appearance model
        "skimage.draw:polygon",  # occluders
        "skimage.feature:canny",
        "skimage.measure:label",
        "skimage.transform:probabilistic_hough_line",
        ".labelme",
        ".calibrate.courses",
        ".calibrate.lens",
        ".calibrate.outline",
        "?lensfunpy",  # lens profiles, where installed
        "PIL.Image:preinit()",  # Pillow's common formats' plugins (JPEG, PNG, ...), loaded on the first open
    ),
    # a photo wall from photo to traced pieces, as pipeline.photo_wall does it on two threads
    "photo_stage": (
        "@detection",
        "jax",
        "skimage.filters:frangi",  # the joints' segmentation
        "skimage.filters:threshold_otsu",
        "skimage.measure:approximate_polygon",
        "skimage.measure:find_contours",
        "skimage.morphology:disk",
        "skimage.morphology:h_maxima",
        "skimage.segmentation:watershed",
        ".calibrate.fit",
        ".calibrate.rectify",
        ".wall2d.pieces",
        ".wall2d.segment",
        ".wall2d.trace",
        "jax:devices()",  # JAX's backends are set up on first use, looking for plugins (imports)
        ".calibrate.fit:_solver()",  # the camera fit, read from disk (jax.export)
        "?jaxlib.mlir.dialects.builtin",  # the MLIR dialects its first call lowers to
        "?jaxlib.mlir.dialects.mhlo",
        "?jaxlib.mlir.extras.meta",
    ),
    # the camera fit's one-off cost (JAX 0.3 s, loading its compiled code 0.6 s): rectify's second thread
    "camera_fit": (".calibrate.fit", ".calibrate.fit:warm_up()"),
    "figure_font": ("._raster:font(12)",),  # Pillow's drawing: the font file is read once
    # rendering and saving a synthetic photo (synth --photos renders two at a time)
    "renderer": (
        "fractions",
        "torch",
        "kornia.geometry.transform:warp_perspective",
        "PIL.Image",
        "PIL.TiffImagePlugin",
        "PIL.Image:preinit()",
        ".synthetic.photo",
    ),
    # drawing and saving a figure (matplotlib's Figure, no pyplot)
    "figures": (
        "matplotlib.backends.backend_agg",  # savefig's PNG writer
        "matplotlib.collections",
        "matplotlib.figure",
        "mpl_toolkits.mplot3d",  # the model's 3D view
        "._figure",
    ),
    # the joint model's sparse Cholesky, before the tracker's steps run on a thread of their own
    "joint_solver": ("cvxopt", "cvxopt.cholmod"),
    # what a study's sample calls, once per Dask worker
    "study": (".pipeline", ".build3d.assemble", ".simulation.run", ".wall2d.trace"),
}

_LOADED: set[str] = set()  # groups loaded (on any thread), so a second preload costs nothing
_STARTED: set[str] = set()  # groups handed to a background thread
_THREADS: list[threading.Thread] = []  # the background threads started, until waited for


def preload(*groups: str) -> None:
    """Load ``groups`` (names of :data:`GROUPS`) on this thread. An import that fails raises."""
    for group in groups:
        if group in _LOADED:
            continue
        for entry in GROUPS[group]:
            _load(entry)
        _LOADED.add(group)


def _load(entry: str) -> None:
    if entry.startswith("@"):
        preload(entry[1:])
        return
    optional = entry.startswith("?")
    entry = entry.lstrip("?")
    module, _, name = entry.partition(":")
    try:
        mod = importlib.import_module(module, "calib_masonry")
    except ImportError:
        if optional:
            return
        raise
    if not name:
        return
    attr, paren, args = name.partition("(")
    value = getattr(mod, attr)
    if paren:
        value(*ast.literal_eval(f"({args[:-1]},)") if args[:-1].strip() else ())


def preload_in_background(*groups: str, first: tuple[str, ...] = ()) -> threading.Thread | None:
    """Load ``groups``, one after the other, on a daemon thread (returned; None if there is nothing
    to load), after loading ``first`` on this one (what this thread will import while the other
    runs). A failure on the thread is silent: the import fails again, with its message, where it
    is needed."""
    preload(*first)
    todo = tuple(g for g in groups if g not in _LOADED and g not in _STARTED)
    if not todo:
        return None

    def run() -> None:
        try:
            preload(*todo)
        except Exception:  # noqa: BLE001 - reported by the import where it is needed
            pass

    _STARTED.update(todo)
    thread = threading.Thread(target=run, name="calib-masonry-imports", daemon=True)
    thread.start()
    _THREADS.append(thread)
    return thread


def wait_for_background(timeout_s: float = 30.0) -> None:
    """Wait for the background loads to finish (each up to ``timeout_s``). A process that exits
    while one is inside JAX's native code is aborted at the interpreter's shutdown ("terminate
    called after throwing an instance of ''", exit code 134): a rectify that failed at once on its
    photo did so on 2 runs of 4, where it should say its one line and exit with 2."""
    while _THREADS:
        _THREADS.pop().join(timeout_s)

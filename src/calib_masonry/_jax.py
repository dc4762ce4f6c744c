"""The one place JAX is configured: float64 on (geometry and calibration fits need it)."""

from __future__ import annotations

from functools import cache

from .errors import BackendMissing

try:
    import jax
    import jax.numpy as jnp
except ImportError as exc:  # pragma: no cover - exercised only without the extra
    raise BackendMissing(
        "JAX is not installed; install the calibration extra: pip install -c constraints.txt -e '.[calib]'"
    ) from exc

jax.config.update("jax_enable_x64", True)

__all__ = ["jax", "jnp"]


def cache_dir():
    """The folder of the on-disk caches (``$CALIB_MASONRY_CACHE`` or ~/.cache/calib_masonry/jax),
    created if need be; None where it cannot be."""
    import os
    from pathlib import Path

    path = Path(os.environ.get("CALIB_MASONRY_CACHE", Path.home() / ".cache" / "calib_masonry" / "jax"))
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError:
        return None
    return path


def enable_compilation_cache() -> None:
    """Keep compiled fits on disk (:func:`cache_dir`), so a second run of the same command skips
    XLA compilation."""
    path = cache_dir()
    if path is None:
        return
    jax.config.update("jax_compilation_cache_dir", str(path))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.5)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)


enable_compilation_cache()


def exported(name: str, fn, args, *, sources=(), settings=()):
    """``jax.jit(fn)`` exported (``jax.export``) for the argument specs ``args`` (pytrees of
    ``jax.ShapeDtypeStruct``, symbolic dimensions allowed) and kept on disk beside the compilation
    cache, so that a new process traces nothing: it deserializes the file and calls it
    (``.call(*arrays)``), which costs a lowering and a (cached) compilation per concrete shape.

    Why: tracing an optimistix solve (a vmapped BFGS, a Levenberg-Marquardt with its Jacobian)
    takes 1-12 s of Python per process and shape, far more than the solve. The solutions are bit
    for bit those of the jitted function; quantities computed after a solve may be fused
    differently and differ by rounding (tests). The file's name hashes ``name``, ``settings``,
    the text of the ``sources`` files (the modules whose code is traced) and the versions of JAX,
    equinox and optimistix, so a change to any of them exports anew. A file that cannot be read
    is exported anew and replaced, atomically (workers may export at once); where the cache
    cannot be written the export is kept in memory only."""
    import os

    from jax import export

    folder = cache_dir()
    path = None if folder is None else folder / f"{_export_stem(name, sources, settings)}.jaxexport"
    _initialise_lapack()
    if path is not None and path.is_file():
        try:
            result = export.deserialize(bytearray(path.read_bytes()))
            _used(path)
            return result
        except Exception:  # noqa: BLE001 - a partial or foreign file: export anew and replace it
            pass
    result = export.export(jax.jit(fn))(*args)
    if path is not None:
        try:
            blob = result.serialize()
            tmp = path.with_suffix(f".{os.getpid()}.tmp")
            tmp.write_bytes(blob)
            os.replace(tmp, path)  # whole or not at all
            tidy(folder, keep=(path,))
        except (ImportError, OSError):  # no flatbuffers, or a read-only cache: in memory only
            pass
    return result


# the cache folder's size past which :func:`tidy` deletes the files used longest ago
CACHE_MAX_MB = 512.0


_WARNED_LIMIT: set[str] = set()


def cache_limit_mb() -> float:
    """``$CALIB_MASONRY_CACHE_MB`` (megabytes, 0 or more: 0 keeps only the file just written), or
    :data:`CACHE_MAX_MB` when it is unset; a value that is not such a number is named in a
    warning (once) and the default used."""
    import math
    import os
    import warnings

    raw = os.environ.get("CALIB_MASONRY_CACHE_MB")
    if raw is None or raw.strip() == "":
        return CACHE_MAX_MB
    try:
        value = float(raw)
    except ValueError:
        value = math.nan
    if math.isfinite(value) and value >= 0:
        return value
    if raw not in _WARNED_LIMIT:
        _WARNED_LIMIT.add(raw)
        warnings.warn(
            f"CALIB_MASONRY_CACHE_MB={raw!r} is not a size in megabytes (0 or more); the cache "
            f"folder is kept under {CACHE_MAX_MB:g} MB instead: set it to a number such as 1024, or unset it",
            RuntimeWarning,
            stacklevel=3,
        )
    return CACHE_MAX_MB


def tidy(folder, max_mb: float | None = None, *, keep=()) -> int:
    """Keep the cache ``folder`` under ``max_mb`` megabytes (default ``$CALIB_MASONRY_CACHE_MB`` or
    :data:`CACHE_MAX_MB`): past it, delete the files used longest ago (by modification time: a file
    of ours is touched when it is read) down to three quarters of it, never those in ``keep``; and
    delete a ``.tmp`` file an hour old (a process killed while writing). Called after each new
    export or program is written, so the folder does not grow for ever: every change to a traced
    module or a version bump leaves a new set of files, and each program compiled here leaves an
    entry in JAX's compilation cache under a key never used again. A file deleted that a process
    then looks for is exported or compiled anew. Returns the number of files deleted."""
    import os
    import stat
    import time

    if max_mb is None:
        max_mb = cache_limit_mb()
    now = time.time()
    keep = {str(k) for k in keep}
    files, total, deleted = [], 0, 0
    for path in folder.iterdir():
        try:
            st = path.stat()
            if not stat.S_ISREG(st.st_mode):
                continue
            if path.suffix == ".tmp" and now - st.st_mtime > 3600.0:
                path.unlink()
                deleted += 1
                continue
        except OSError:
            continue
        files.append((st.st_mtime, str(path), st.st_size))
        total += st.st_size
    limit = max_mb * 2**20
    if total <= limit:
        return deleted
    for _, name, size in sorted(files):
        if total <= 0.75 * limit:
            break
        if name in keep:
            continue
        try:
            os.unlink(name)
        except OSError:
            continue
        total -= size
        deleted += 1
    return deleted


def _used(path) -> None:
    """Mark a cache file as just used (its modification time: :func:`tidy` deletes the oldest)."""
    import os

    try:
        os.utime(path)
    except OSError:  # a read-only cache
        pass


def _export_stem(name: str, sources, settings) -> str:
    """``name`` and a hash of what an export of it depends on (:func:`exported`)."""
    import hashlib
    from importlib.metadata import version
    from pathlib import Path

    key = repr((name, tuple(settings), jax.__version__, version("equinox"), version("optimistix")))
    key += "".join(Path(s).read_text(encoding="utf-8") for s in sources)
    return f"{name}-{hashlib.sha256(key.encode()).hexdigest()[:32]}"


@cache
def _machine() -> str:
    """What a compiled CPU program depends on besides its code: jaxlib, the backend and the
    processor (its model and instruction-set flags, where /proc/cpuinfo tells them)."""
    import platform

    import jaxlib

    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as f:
            lines = [ln for ln in f.read().splitlines() if ln.startswith(("model name", "flags", "Features"))]
        cpu += "".join(dict.fromkeys(lines))  # the first of each (every core repeats them)
    except OSError:
        pass
    backend = jax.devices()[0].client
    return repr((jaxlib.__version__, backend.platform, backend.platform_version, cpu))


def _fresh() -> dict:
    """Compiler options that make a compile fresh: a GPU-only option (no effect on a CPU program)
    set to a value never used before, so that the compilation cache's key is new and the program
    is compiled, not loaded from that cache (a loaded one serializes without its code: see
    :class:`Precompiled`)."""
    import uuid

    # (not xla_gpu_cuda_data_dir: JAX leaves that one out of the key)
    return {"xla_gpu_per_fusion_autotune_cache_dir": f"calib-masonry-aot-{uuid.uuid4().hex}"}


class Precompiled:
    """An exported function (:func:`exported`) called through programs compiled ahead of time,
    one per concrete shape of its arguments, kept in memory and on disk
    (``jax.experimental.serialize_executable``) beside the export.

    Why: a new process that calls an export jitted lowers the call and looks its program up in
    JAX's compilation cache, about 0.25 s a shape for the refinement's batch solver (four
    shapes on a stone wall: a second of each ``trace --refine``); loading a serialized program
    takes about 0.05 s and lowers nothing, and the export itself is read only when a program
    must be compiled. The programs are bit for bit the jitted export's (the same lowering and
    options, but a GPU-only one: :func:`_fresh`; test).

    A program is compiled anew, never taken from JAX's compilation cache: an executable that
    came from that cache does not serialize whole with jax 0.6 (the loaded copy fails on its
    first call, "Function ... not found"). It is written atomically, keyed by the export's hash,
    the shapes and :func:`_machine`. A program read from disk is tried once on zeros; one that
    cannot be read or run is compiled anew and replaced. Where the cache cannot be written the
    programs live in memory only. Arguments without a shape and a dtype (Python numbers) go
    through the jitted export."""

    def __init__(self, name: str, fn, args, *, sources=(), settings=()):
        import threading

        self._export_args = (name, fn, args, tuple(sources), tuple(settings))
        self._stem = _export_stem(name, sources, settings)
        self._jitted = None
        self._programs: dict = {}
        self._lock = threading.Lock()

    def jitted(self):
        """The export, jitted (read or exported on first use)."""
        with self._lock:
            if self._jitted is None:
                name, fn, args, sources, settings = self._export_args
                self._jitted = jax.jit(exported(name, fn, args, sources=sources, settings=settings).call)
            return self._jitted

    def __call__(self, *args):
        try:
            shapes = _shapes(args)
        except AttributeError:
            return self.jitted()(*args)
        program = self._programs.get(shapes)
        if program is None:
            program = self._program(shapes)
        return program(*args)

    def load(self, *args) -> None:
        """Load (or compile) the program for the shapes of ``args`` (arrays), without calling it."""
        self._program(_shapes(args))

    def _program(self, shapes):
        import hashlib
        import os
        import pickle

        import numpy as np
        from jax.experimental import serialize_executable as se

        with self._lock:
            if shapes in self._programs:
                return self._programs[shapes]
        folder = cache_dir()
        key = hashlib.sha256(repr((self._stem, shapes, _machine())).encode()).hexdigest()[:32]
        path = None if folder is None else folder / f"{self._stem}-{key}.xlaexe"
        program = None
        _initialise_lapack()
        if path is not None and path.is_file():
            try:
                program = se.deserialize_and_load(*pickle.loads(path.read_bytes()))
                # a trial on zeros: a program that loads but cannot run fails here (its errors
                # surface only when a result is read), not in the caller's solve
                jax.block_until_ready(program(*(np.zeros(s, d) for s, d in shapes)))
                _used(path)
            except Exception:  # noqa: BLE001 - a partial, foreign or broken file: compile anew, replace it
                program = None
        if program is None:
            specs = [jax.ShapeDtypeStruct(s, d) for s, d in shapes]
            lowered = self.jitted().lower(*specs)
            if path is None:
                program = lowered.compile()
            else:
                program = lowered.compile(compiler_options=_fresh())
                try:
                    blob = pickle.dumps(se.serialize(program))
                    tmp = path.with_suffix(f".{os.getpid()}.tmp")
                    tmp.write_bytes(blob)
                    os.replace(tmp, path)  # whole or not at all
                    tidy(folder, keep=(path,))
                except (ValueError, OSError, pickle.PicklingError):  # not serializable, or read-only
                    pass
        with self._lock:
            return self._programs.setdefault(shapes, program)


def _shapes(args) -> tuple:
    """The shapes and dtypes of ``args`` (arrays), a program's key."""
    return tuple((tuple(a.shape), str(a.dtype)) for a in args)


def _initialise_lapack() -> None:
    """Point jaxlib's LAPACK kernels at their routines. JAX does it when it lowers a linear-algebra
    operation; a deserialized export lowers none, and calling one that solves a linear system in a
    process that has not yet lowered one crashes (segmentation fault, measured with jax 0.6)."""
    try:
        from jaxlib import lapack

        lapack._lapack.initialize()
    except (ImportError, AttributeError):  # another jaxlib: it lowers as it always did
        pass

"""The one place JAX is configured: float64 on (geometry and calibration fits need it)."""

from __future__ import annotations

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
    import hashlib
    import os
    from importlib.metadata import version
    from pathlib import Path

    from jax import export

    key = repr((name, tuple(settings), jax.__version__, version("equinox"), version("optimistix")))
    key += "".join(Path(s).read_text(encoding="utf-8") for s in sources)
    folder = cache_dir()
    path = None if folder is None else folder / f"{name}-{hashlib.sha256(key.encode()).hexdigest()[:32]}.jaxexport"
    _initialise_lapack()
    if path is not None and path.is_file():
        try:
            return export.deserialize(bytearray(path.read_bytes()))
        except Exception:  # noqa: BLE001 - a partial or foreign file: export anew and replace it
            pass
    result = export.export(jax.jit(fn))(*args)
    if path is not None:
        try:
            blob = result.serialize()
            tmp = path.with_suffix(f".{os.getpid()}.tmp")
            tmp.write_bytes(blob)
            os.replace(tmp, path)  # whole or not at all
        except (ImportError, OSError):  # no flatbuffers, or a read-only cache: in memory only
            pass
    return result


def _initialise_lapack() -> None:
    """Point jaxlib's LAPACK kernels at their routines. JAX does it when it lowers a linear-algebra
    operation; a deserialized export lowers none, and calling one that solves a linear system in a
    process that has not yet lowered one crashes (segmentation fault, measured with jax 0.6)."""
    try:
        from jaxlib import lapack

        lapack._lapack.initialize()
    except (ImportError, AttributeError):  # another jaxlib: it lowers as it always did
        pass

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

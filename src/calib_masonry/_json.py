"""Deterministic JSON: the one writer and reader of the project's JSON files (re-exported by
:mod:`calib_masonry.io`, the file edge). Imports nothing of the package but its errors, so the
format modules (:mod:`calib_masonry.labelme`) and the file edge both build on it."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from .errors import InputError

__all__ = ["json_bytes", "jsonable", "read_json", "records_json_bytes", "write_json"]


#: the values json's encoder cannot write itself, which :func:`_json_default` converts
_JSON_SCALARS = (np.floating, np.integer, np.bool_, Path)


def _json_default(obj: Any) -> Any:
    """An array or one of :data:`_JSON_SCALARS` as json writes it (``default`` of json.dumps)."""
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, np.floating):
        return float(obj)
    if isinstance(obj, np.bool_):
        return bool(obj)
    if isinstance(obj, Path):
        return obj.as_posix()
    raise TypeError(f"JSON: cannot write a {type(obj).__name__}")


def _jsonable(obj: Any, exact: bool = False) -> Any:
    if isinstance(obj, dict):
        return {str(k): _jsonable(v, exact) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v, exact) for v in obj]
    if isinstance(obj, np.ndarray):
        return _jsonable(obj.tolist(), exact)
    if isinstance(obj, _JSON_SCALARS):  # numpy floats as they are (before the rounding below)
        return _json_default(obj)
    if isinstance(obj, float):
        return (obj if exact else round(obj, 10)) if np.isfinite(obj) else None
    return obj


def jsonable(obj: Any, *, exact: bool = False) -> Any:
    """``obj`` as :func:`write_json` writes it and ``json.load`` reads it back (numpy values as
    numbers, tuples as lists, non-finite floats as None, floats rounded to 1e-10 unless ``exact``),
    without the file."""
    return _jsonable(obj, exact)


def json_bytes(obj: Any, *, exact: bool = False) -> bytes:
    """The bytes :func:`write_json` writes for ``obj``."""
    return (json.dumps(_jsonable(obj, exact), indent=1) + "\n").encode("utf-8")


def records_json_bytes(doc: dict) -> bytes:
    """Exact-float JSON of a document whose lists are records (bricks.json): each list value of
    ``doc`` is written one item to a line. It reads back as the document :func:`json_bytes` with
    ``exact`` writes (non-finite floats as null, numpy values as numbers), but is written by json's
    C encoder, which an indented layout cannot use: the paper example's bricks.json (1,587 bricks)
    took 0.31-0.37 s to convert and indent in Python, 0.05 s this way."""

    def dump(value: Any) -> str:
        try:
            return json.dumps(value, allow_nan=False, default=_json_default)
        except ValueError:  # a NaN or infinity somewhere: written as null, as _jsonable does
            return json.dumps(_jsonable(value, True))

    parts = []
    for key, value in doc.items():
        name = json.dumps(str(key))
        if isinstance(value, (list, tuple)) and value:
            rows = ",\n".join("  " + dump(item) for item in value)
            parts.append(f" {name}: [\n{rows}\n ]")
        else:
            parts.append(f" {name}: {dump(value)}")
    return ("{\n" + ",\n".join(parts) + "\n}\n").encode("utf-8")


def write_json(path: Path, obj: Any, *, exact: bool = False) -> None:
    """Deterministic JSON, one-space indent: floats rounded to 1e-10, or with ``exact`` written in
    full (Python's shortest repr, which reads back to the same float: a model read back from its
    bricks.json is bit for bit the model that was written)."""
    Path(path).write_bytes(json_bytes(obj, exact=exact))


def read_json(path: str | Path, *, field: str = "file") -> Any:
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{field} {path}: not found; check the path")
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise InputError(f"{field} {path}: not valid JSON ({exc}); re-create it") from None

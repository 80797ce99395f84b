"""Every JSON file the tool writes goes through here: schema header, rounded floats, no NaN,
sorted keys, atomic write (a crash never leaves half a file behind)."""

from __future__ import annotations

import json
import math
import os
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from wtcli import __version__
from wtcli.errors import InputError

FLOAT_DIGITS = 6


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


_FILE_MODE = 0o666 & ~_umask()  # mkstemp makes 0600 files; outputs should be ordinary files


def clean(obj: Any, digits: int = FLOAT_DIGITS) -> Any:
    """Convert numpy types to plain Python, round floats, and refuse NaN/inf."""
    if isinstance(obj, dict):
        return {str(k): clean(v, digits) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [clean(v, digits) for v in obj]
    if isinstance(obj, np.ndarray):
        return clean(obj.tolist(), digits)
    if isinstance(obj, (bool, np.bool_)):
        return bool(obj)
    if isinstance(obj, (int, np.integer)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        f = float(obj)
        if not math.isfinite(f):
            raise ValueError(f"refusing to write a non-finite number ({f}) to JSON")
        r = round(f, digits)
        return 0.0 if r == 0 else r  # no "-0.0" in files
    if isinstance(obj, Path):
        return str(obj)
    return obj


def document(schema: str, schema_version: int, body: dict[str, Any]) -> dict[str, Any]:
    """Wrap a result's ``to_dict()`` with the header every file carries."""
    return {"schema": schema, "schema_version": schema_version, "tool": "wtinspect",
            "tool_version": __version__, **body}


def dumps(doc: Any, digits: int = FLOAT_DIGITS, indent: int | None = 1) -> str:
    return json.dumps(clean(doc, digits), sort_keys=True, allow_nan=False, indent=indent)


def atomic_write_text(path: str | Path, text: str) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent)
    try:
        os.fchmod(fd, _FILE_MODE)
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            f.write(text)
            if not text.endswith("\n"):
                f.write("\n")
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path


def atomic_write_bytes(path: str | Path, data: bytes) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent)
    try:
        os.fchmod(fd, _FILE_MODE)
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path


def write_json(path: str | Path, doc: Any, digits: int = FLOAT_DIGITS) -> Path:
    return atomic_write_text(path, dumps(doc, digits))


def read_json(path: str | Path, schema: str | None = None,
              max_version: int | None = None) -> Any:
    """Read a JSON file; with ``schema``, check its header and name the file in any error."""
    path = Path(path)
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise InputError(f"{path}: file not found") from None
    except (OSError, UnicodeDecodeError) as e:
        raise InputError(f"{path}: cannot read ({e.__class__.__name__})") from None
    except json.JSONDecodeError as e:
        raise InputError(f"{path}: not valid JSON (line {e.lineno}, column {e.colno}: {e.msg})") from None
    if schema is not None:
        if not isinstance(doc, dict) or doc.get("schema") != schema:
            got = doc.get("schema") if isinstance(doc, dict) else type(doc).__name__
            raise InputError(f"{path}: expected a '{schema}' file, got schema {got!r}")
        ver = doc.get("schema_version")
        if not isinstance(ver, int) or (max_version is not None and ver > max_version):
            raise InputError(f"{path}: schema_version {ver!r} of '{schema}' is not supported "
                             f"(this wtinspect reads up to {max_version})")
    return doc

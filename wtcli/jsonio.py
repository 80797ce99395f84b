"""Every JSON file the tool writes goes through here: schema header, rounded floats, no NaN,
sorted keys, atomic write (a crash never leaves half a file behind). Every JSON file it reads
goes through ``read_json``: NaN/Infinity refused, ``schema`` and ``schema_version`` checked
(a newer version than this wtinspect knows is refused), errors naming the file. ``shown``
quotes a value in a message, bounded however large the value is."""

from __future__ import annotations

import errno
import json
import math
import os
import re
import reprlib
import tempfile
import textwrap
from pathlib import Path
from typing import Any, Iterable, Iterator

import numpy as np

from wtcli import __version__
from wtcli.errors import InputError, OutputError

FLOAT_DIGITS = 6
SHOWN_CHARS = 80  # the most characters of an input value an error message quotes
# The largest input files read, checked from the size before reading (docs/exit-codes.md,
# "Input sizes"). The largest JSON we write is a flight's instances file: about 145 kB per
# 150 MP photo, 91 MB for the 626 photos of one sample turbine (a 100-turbine plan is
# 15.8 MB); the cap gives that 11x headroom. One cap for every JSON, since `pitch` reads a file before it knows
# its kind. A turbines.yaml is ~0.3 kB per turbine.
MAX_JSON_BYTES = 1_000_000_000
MAX_YAML_BYTES = 16_000_000

_repr = reprlib.Repr()
_repr.maxlevel, _repr.maxlist, _repr.maxtuple, _repr.maxdict = 3, 6, 6, 4
_repr.maxstring, _repr.maxother, _repr.maxlong = SHOWN_CHARS, SHOWN_CHARS, 40


def shown(value: Any) -> str:
    """``repr(value)`` for an error message, bounded: nested or shared structures (a YAML alias
    bomb) are cut at depth 3 and 6 items per level, and the text at 80 characters."""
    text = _repr.repr(value)
    return text if len(text) <= SHOWN_CHARS else text[:SHOWN_CHARS - 3] + "..."


def os_reason(e: OSError) -> str:
    """'No space left on device' rather than '[Errno 28] No space left on device: path'."""
    if e.strerror:
        return e.strerror
    return errno.errorcode.get(e.errno or 0, e.__class__.__name__)


def missing(path: str | Path) -> str:
    """Why an input is not there: a link to nothing says so, as the user would want to know."""
    return "broken symbolic link" if Path(path).is_symlink() else "file not found"


def write_failed(path: str | Path, e: OSError) -> OutputError:
    """The one message for an output that could not be written (exit 3, docs/exit-codes.md)."""
    return OutputError(f"{path}: cannot write ({os_reason(e)})", errno=e.errno)


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


NAME_MAX = 255  # bytes in one file name on the usual file systems (ext4, XFS, APFS)
_TEMP_TAIL = 10  # what a temporary adds to the name: a dot before, a dot and 8 characters after


def temp_prefix(name: str) -> str:
    """The start of the temporary's name that ``atomic_write_bytes`` writes ``name`` through:
    ``.NAME.``, then 8 random characters. A name within 10 bytes of the 255-byte limit is cut
    to fit, its final extension kept (``outputs.remove_temp_files`` knows temporaries by it)."""
    raw = os.fsencode(name)
    room = NAME_MAX - _TEMP_TAIL
    if len(raw) <= room:
        return f".{name}."
    stem, dot, ext = name.rpartition(".")
    keep = os.fsencode(dot + ext) if stem and len(ext) <= 16 else b""
    cut = (os.fsencode(stem) if keep else raw)[:room - len(keep)]
    # Cut on a character, not inside one; any bytes that were not UTF-8 are dropped.
    return "." + (cut + keep).decode("utf-8", "ignore") + "."


def atomic_write_text(path: str | Path, text: str) -> Path:
    return atomic_write_bytes(path, (text if text.endswith("\n") else text + "\n").encode("utf-8"))


def atomic_write_bytes(path: str | Path, data: bytes | Iterable[bytes]) -> Path:
    """Write ``data`` (bytes, or pieces of them made as they are written: a file larger than
    memory should hold) to a temporary ``.NAME.k2x9q0ab`` (8 random characters) beside ``path``
    (``temp_prefix``: a long NAME is cut to fit), then rename it over ``path``: readers see the
    old file or the new one, never half of one. Any OSError (a file in the way, a read-only folder, a full disk)
    becomes OutputError naming ``path``; the temporary file is removed
    (``outputs.remove_temp_files`` clears those a kill left). A symbolic link is written
    through (its target replaced, the link kept); a device, pipe or socket in the way is
    refused rather than replaced by a file."""
    path = Path(path)
    shown = path
    try:
        if path.is_symlink():  # raises for a name over the limit: that is this file's error too
            path = Path(os.path.realpath(path))
        if path.exists() and not (path.is_file() or path.is_dir()):
            raise OutputError(f"{shown}: is not a regular file (a device, pipe or socket); "
                              "write to a file")
        if path.is_dir():
            raise IsADirectoryError(errno.EISDIR, "a folder is in the way")
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=temp_prefix(path.name), dir=path.parent)
    except OSError as e:
        raise write_failed(shown, e) from None
    try:
        os.fchmod(fd, _FILE_MODE)
        with os.fdopen(fd, "wb") as f:
            for piece in (data,) if isinstance(data, (bytes, bytearray, memoryview)) else data:
                f.write(piece)
        os.replace(tmp, path)
    except BaseException as e:
        Path(tmp).unlink(missing_ok=True)
        if isinstance(e, OSError):
            raise write_failed(shown, e) from None
        raise
    return path


def write_json(path: str | Path, doc: Any, digits: int = FLOAT_DIGITS) -> Path:
    return atomic_write_text(path, dumps(doc, digits))


def dumps_streamed(doc: dict[str, Any], key: str, items: Iterable[Any],
                   digits: int = FLOAT_DIGITS) -> Iterator[bytes]:
    """``dumps(doc)`` with the top-level ``doc[key]`` the list of ``items``, and its final
    newline, byte for byte as ``write_json`` writes it, in pieces made one item at a time: a
    file of a whole photo folder need never be in memory at once (give it to
    ``atomic_write_bytes``)."""
    here = f"@@{key}:{os.urandom(8).hex()}@@"  # stands for the list in the document's text
    head, tail = dumps({**doc, key: here}, digits).split(json.dumps(here), 1)
    yield head.encode("utf-8")
    n = 0
    for item in items:
        text = textwrap.indent(dumps(item, digits), "  ")  # as items of a top-level list
        yield (("[\n" if n == 0 else ",\n") + text).encode("utf-8")
        n += 1
    yield (("\n ]" if n else "[]") + tail + "\n").encode("utf-8")


def size_text(n: int) -> str:
    """Bytes for a message: '2.1 GB', '512 MB', '980 kB', '12 bytes' (decimal units)."""
    for unit, scale in (("GB", 1e9), ("MB", 1e6), ("kB", 1e3)):
        if n >= scale:
            v = n / scale
            return f"{v:.1f} {unit}" if v < 10 and v != int(v) else f"{v:.0f} {unit}"
    return f"{n} bytes"


def read_capped(path: str | Path, max_bytes: int, kind: str) -> str:
    """The UTF-8 text of the input file ``path``, which may hold at most ``max_bytes``: a larger
    one is refused from its size before a byte is read (a pipe is read only up to the limit).
    InputError (exit 3) naming the file if it is missing, a folder, unreadable or too large;
    UnicodeDecodeError is left to the caller (a content error, which it names)."""
    path = Path(path)
    too_big = f"over the {size_text(max_bytes)} limit for a {kind} input (docs/exit-codes.md)"
    try:
        size = path.stat().st_size if path.is_file() else None
        if size is not None and size > max_bytes:
            raise InputError(f"{path}: {size_text(size)} is {too_big}")
        with open(path, "rb") as f:
            data = _read_upto(f, max_bytes + 1)
    except FileNotFoundError:
        raise InputError(f"{path}: {missing(path)}") from None
    except IsADirectoryError:
        raise InputError(f"{path}: is a folder, expected a {kind} file") from None
    except OSError as e:
        raise InputError(f"{path}: cannot read ({os_reason(e)})") from None
    if len(data) > max_bytes:  # grew since, or a pipe / device with no size
        raise InputError(f"{path}: more than {size_text(max_bytes)}, the limit for a {kind} input "
                         "(docs/exit-codes.md)")
    return data.decode("utf-8")


def _read_upto(f, limit: int, chunk: int = 1 << 24) -> bytes:
    """At most ``limit`` bytes of ``f``, read in chunks: ``f.read(limit)`` would ask for the
    whole limit (1 GB for JSON) at once, which a memory-capped batch job refuses."""
    parts, n = [], 0
    while n < limit:
        part = f.read(min(chunk, limit - n))
        if not part:
            break
        parts.append(part)
        n += len(part)
    return b"".join(parts)


class _NotANumber(ValueError):
    pass


def _refuse_constant(name: str) -> Any:
    raise _NotANumber(name)


def _finite_float(text: str) -> float:
    f = float(text)
    if not math.isfinite(f):  # 1e400 parses to inf
        raise _NotANumber(text)
    return f


def read_json(path: str | Path, schema: str | None = None,
              max_version: int | None = None, header_required: bool = True,
              max_bytes: int = MAX_JSON_BYTES) -> Any:
    """Read a JSON file, naming the file in any error. A file over ``max_bytes`` is refused
    before it is read; NaN, Infinity and numbers too large for a float are refused (JSON has
    none). With ``schema``, the header is checked
    (``check_header``); ``header_required=False`` also accepts a file without one (a COCO file
    from another tool), but never one with another schema or a newer version."""
    path = Path(path)
    try:
        # A UTF-8 byte-order mark (Windows editors, some exporters) is ignored, as RFC 8259 allows.
        text = read_capped(path, max_bytes, "JSON").removeprefix("\ufeff")
    except UnicodeDecodeError:
        raise InputError(f"{path}: not valid JSON (not UTF-8 text)") from None
    try:
        doc = json.loads(text, parse_constant=_refuse_constant, parse_float=_finite_float)
    except _NotANumber as e:
        raise InputError(f"{path}: not valid JSON ({shown(e.args[0])[1:-1]} is not a finite "
                         "number)") from None
    except json.JSONDecodeError as e:
        raise InputError(f"{path}: not valid JSON (line {e.lineno}, column {e.colno}: {e.msg})") from None
    except RecursionError:
        raise InputError(f"{path}: not valid JSON (nested too deeply)") from None
    if schema is not None:
        check_header(doc, path, schema, max_version, required=header_required)
    return doc


def check_header(doc: Any, path: str | Path, schema: str, max_version: int | None,
                 required: bool = True) -> None:
    """The one check of a file's ``schema`` and ``schema_version``: the schema must be
    ``schema``; the version an integer from 1 to ``max_version`` (a newer file may mean things
    this wtinspect would misread, so it is refused rather than guessed at). With
    ``required=False`` a missing key passes, a present one is still checked."""
    if not isinstance(doc, dict):
        raise InputError(f"{path}: expected a '{schema}' JSON object, got {type(doc).__name__}")
    if required or "schema" in doc:
        if doc.get("schema") != schema:
            raise InputError(f"{path}: expected a '{schema}' file, got schema {shown(doc.get('schema'))}")
    if required or "schema_version" in doc:
        ver = doc.get("schema_version")
        if isinstance(ver, bool) or not isinstance(ver, int) or ver < 1:
            raise InputError(f"{path}: schema_version: expected an integer >= 1, got {shown(ver)}")
        if max_version is not None and ver > max_version:
            raise InputError(f"{path}: schema_version {ver} of '{schema}' is newer than this "
                             f"wtinspect reads (up to {max_version}); update wtinspect")


def number(value: Any, where: str, lo: float | None = None, hi: float | None = None,
           integer: bool = False) -> Any:
    """A number read from a file, checked: finite, of the right kind, within [lo, hi];
    InputError naming ``where`` (``file: images[0].width``) and the value otherwise."""
    kind = "an integer" if integer else "a number"
    ok = (isinstance(value, int) or (isinstance(value, float) and value.is_integer())) \
        if integer else isinstance(value, (int, float))
    if isinstance(value, bool) or not ok or not math.isfinite(value) \
            or (lo is not None and value < lo) or (hi is not None and value > hi):
        rng = (f" in [{lo:g}, {hi:g}]" if lo is not None and hi is not None
               else f" >= {lo:g}" if lo is not None else f" <= {hi:g}" if hi is not None else "")
        raise InputError(f"{where}: expected {kind}{rng}, got {shown(value)}")
    return int(value) if integer else float(value)

"""The one rule for outputs, shared by every command.

- Before the expensive work, ``writable_folder`` / ``writable_file`` prove the output location
  can be written (a folder is created and a probe file written and removed), so a read-only
  ``--out`` fails in a second, not after the model has run.
- Every write goes through ``jsonio.atomic_write_*``: an OSError becomes ``OutputError`` naming
  the file (exit 3, docs/exit-codes.md), and no half-written file is ever visible. A set of
  files that must not mix with an earlier one (``plan``'s mission exports) goes through a
  staging folder instead (``wtcli.plan.exports``).
- ``check_not_inputs`` refuses an output that is one of the command's own inputs (usage,
  exit 2): writing it would replace what the user gave.
- ``remove_temp_files`` clears the temporaries (``.NAME.`` and 8 random characters, e.g.
  ``.plan.json.k2x9q0ab``) a kill between write and rename leaves behind; ``remove_stale``
  drops an aggregate a rerun no longer vouches for.
"""

from __future__ import annotations

import errno
import hashlib
import os
import re
import tempfile
import unicodedata
from pathlib import Path, PurePosixPath
from typing import Iterable

from wtcli.errors import OutputError, UsageError
from wtcli.jsonio import write_failed

# jsonio.atomic_write_bytes names its temporaries tempfile.mkstemp(prefix=".NAME."): a dot,
# the final name, a dot, 8 random characters. Only names of files we write match.
_RANDOM = r"[a-z0-9_]{8}"  # tempfile's random part
_TEMP_NAME = re.compile(
    rf"^\..+\.(json|geojson|png|jpg|pt|ckpt|npz|csv|yaml|kml|kmz|plan|waypoints|txt)\.{_RANDOM}$")


def writable_folder(folder: str | Path, what: str = "--out") -> Path:
    """Prove files can be written in ``folder``: in it if it exists, else in the nearest
    folder above it that does (where it would be created; nothing is created now). OutputError
    (exit 3) naming it otherwise. Call before any expensive work."""
    folder = Path(folder)
    if folder.exists() and not folder.is_dir():
        raise OutputError(f"{folder}: exists and is not a folder; choose another {what}")
    try:
        _probe(folder)
    except OSError as e:
        raise OutputError(f"{folder}: cannot write there ({_reason(e)}); choose another "
                          f"{what}") from None
    return folder


def _probe(folder: Path) -> None:
    """Write and remove a file in ``folder``, or in its nearest existing ancestor."""
    existing = folder
    while not existing.exists() and existing.parent != existing:
        existing = existing.parent
    if not existing.is_dir():
        raise NotADirectoryError(errno.ENOTDIR, f"{existing} is a file, not a folder")
    fd, probe = tempfile.mkstemp(prefix=".wtinspect-probe.", dir=existing)
    os.close(fd)
    os.unlink(probe)


def writable_file(path: str | Path, what: str = "--out") -> Path:
    """Prove ``path`` can be written (its folder is created): nothing in the way, folder
    writable. OutputError (exit 3) naming it otherwise. The file itself is not touched."""
    path = Path(path)
    if path.is_dir():
        raise OutputError(f"{path}: is a folder; {what} needs a file name")
    if path.exists() and not path.is_file():  # /dev/null, a pipe: a rename would replace it
        raise OutputError(f"{path}: is not a regular file (a device, pipe or socket); choose "
                          f"another {what}")
    if path.is_symlink():  # written through: the target's folder is where the file goes
        path = Path(os.path.realpath(path))
    parent = path.parent
    if parent.exists() and not parent.is_dir():
        raise OutputError(f"{path}: cannot be written: {parent} is a file, not a folder")
    try:
        _probe(parent)
    except OSError as e:
        raise OutputError(f"{path}: cannot write ({_reason(e)}); choose another {what}") from None
    return path


def remove_temp_files(folder: str | Path, names: str | None = None) -> list[Path]:
    """Delete the ``.NAME.k2x9q0ab`` temporaries of atomic writes (left by a kill between write
    and rename); returns what was removed. Without ``names``: every one under ``folder``, a
    folder of the command's own. With ``names``, a regular expression: only those of the files
    it matches, in ``folder`` itself (a command's own files in a folder it shares)."""
    folder = Path(folder)
    removed: list[Path] = []
    if not folder.is_dir():
        return removed
    if names is None:
        walk = os.walk(folder)
    else:
        walk = [(str(folder), None, [e.name for e in os.scandir(folder)
                                     if e.is_file(follow_symlinks=False)])]
    pattern = _TEMP_NAME if names is None else re.compile(rf"\.(?:{names})\.{_RANDOM}$")
    for dirpath, _, entries in walk:
        for name in entries:
            if pattern.match(name):
                p = Path(dirpath) / name
                try:
                    p.unlink()
                except FileNotFoundError:
                    continue
                except OSError as e:
                    raise write_failed(p, e) from None
                removed.append(p)
    return removed


def remove_stale(path: str | Path) -> None:
    """Remove an earlier output this run does not replace (a combined file none of this run's
    items went into), so no stale aggregate sits beside a fresh report."""
    path = Path(path)
    try:
        path.unlink(missing_ok=True)
    except OSError as e:
        raise write_failed(path, e) from None


def _reason(e: OSError) -> str:
    if e.errno == errno.ENOTDIR:
        return e.strerror or "not a folder"
    if e.errno in (errno.EACCES, errno.EPERM):
        return "permission denied"
    if e.errno == errno.EROFS:
        return "read-only file system"
    return e.strerror or e.__class__.__name__


def check_outputs(files: Iterable[str | Path | None] = (),
                  folders: Iterable[str | Path | None] = ()) -> None:
    """One call per command, before its expensive work: every output file and folder it was
    given (None: not asked for) can be written. OutputError (exit 3) naming the first that
    cannot. The message names the path, not an option: these come from several options
    (``plan``'s --out, --picture, --export-dir)."""
    for f in files:
        if f is not None:
            writable_file(f, "output file")
    for d in folders:
        if d is not None:
            writable_folder(d, "output folder")


def _identity(path: str | Path) -> tuple:
    """What names one file: device and inode for one that exists (a symbolic or hard link to
    it has the same), else where the path resolves to (an output not written yet)."""
    try:
        st = os.stat(path)
        return ("inode", st.st_dev, st.st_ino)
    except OSError:  # missing or unreadable
        return ("path", os.path.realpath(path))


def same_file(a: str | Path, b: str | Path) -> bool:
    """Whether two paths name one file: the same path, a symbolic link to it or a hard link
    of it."""
    return _identity(a) == _identity(b)


def check_not_inputs(outputs: Iterable[tuple[str, str | Path | None]],
                     inputs: Iterable[tuple[str, str | Path | None]]) -> None:
    """Refuse (UsageError, exit 2) an output that is one of the command's inputs, before any
    work: an atomic write would silently replace the input with the output. ``outputs`` pairs
    the option with the path it writes (``("--out", out)``); ``inputs`` pairs what an input is
    with its path (``("the input turbines file", yaml)``). None: not given. Two outputs that
    are one file (``--out x --picture x``: the second would replace the first) are refused too."""
    given: dict[tuple, tuple[str, str | Path]] = {}
    for what, p in inputs:
        if p is not None:
            given.setdefault(_identity(p), (what, p))
    written: dict[tuple, str] = {}
    for option, out in outputs:
        if out is None:
            continue
        key = _identity(out)
        if key in given:
            what, inp = given[key]
            also = "" if os.path.normpath(str(inp)) == os.path.normpath(str(out)) else f" ({inp})"
            raise UsageError(f"{option} {out}: is {what}{also}; choose another output")
        if key in written:
            raise UsageError(f"{option} {out}: is also {written[key]}'s output; choose another "
                             "output")
        written[key] = option


def _fold(name: str) -> str:
    # How a macOS or Windows disk compares names: without case (and NFC, as macOS stores them).
    return unicodedata.normalize("NFC", name).casefold()


def _clashing(names: list[str]) -> set[int]:
    seen: dict[str, list[int]] = {}
    for k, n in enumerate(names):
        seen.setdefault(_fold(n), []).append(k)
    return {k for ks in seen.values() if len(ks) > 1 for k in ks}


def distinct_names(paths: list[str], suffix: str = "", room: int = 0) -> list[str]:
    """One output name per input file (a relative posix path), so that no two overwrite each
    other: the path without its extension, then ``suffix``; where two would meet (compared
    without case, as macOS and Windows disks do) each keeps its extension (``dup.jpg`` and
    ``dup.png``); names still alike get ``~2``, ``~3`` after all but the first in sorted order.
    Decided from the whole set, not its order (a path given twice: numbered in input order).
    ``segment``'s outputs and ``pitch``'s overlays are named so.

    A file name that would pass the 255-byte limit with ``suffix`` and ``room`` more bytes (an
    extension the caller adds) is cut to fit, ``~`` and 8 hex digits of its path's hash after
    the cut, so a photo whose own name is near the limit still gets its outputs."""
    parts = [PurePosixPath(p) for p in paths]

    def named(k: int, stem: str) -> str:
        return str(parts[k].parent / (stem + suffix)) if str(parts[k].parent) != "." \
            else stem + suffix

    names = [named(k, p.stem or p.name) for k, p in enumerate(parts)]
    for _ in range(2):  # twice: a name given its extension may meet another's stem ("dup.jpg.png")
        for k in _clashing(names):
            names[k] = named(k, parts[k].name)
    clash = _clashing(names)
    taken = {_fold(n) for k, n in enumerate(names) if k not in clash}
    for k in sorted(clash, key=lambda k: (names[k], k)):
        cand, j = names[k], 1
        while _fold(cand) in taken:
            j += 1
            cand = named(k, f"{parts[k].name}~{j}")
        taken.add(_fold(cand))
        names[k] = cand
    return [_fit(n, paths[k], suffix, room) for k, n in enumerate(names)]


def _fit(name: str, path: str, suffix: str, room: int) -> str:
    from wtcli.jsonio import NAME_MAX

    head, _, last = name.rpartition("/")
    if len(os.fsencode(last)) + room <= NAME_MAX:
        return name
    tag = "~" + hashlib.sha1(os.fsencode(path)).hexdigest()[:8]
    body = last[:len(last) - len(suffix)] if suffix and last.endswith(suffix) else last
    keep = NAME_MAX - room - len(os.fsencode(tag + suffix))
    # Cut on a character, not inside one.
    cut = os.fsencode(body)[:max(keep, 1)].decode("utf-8", "ignore")
    return (head + "/" if head else "") + cut + tag + suffix

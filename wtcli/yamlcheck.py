"""Small helpers every YAML reader uses, so every config error reads the same way:
``turbines.yaml: turbines[1].hub_height: expected a number in [10, 250], got -5``.
Unknown keys get a "did you mean" hint. ``yaml.safe_load`` only."""

from __future__ import annotations

import copy
import difflib
import math
from pathlib import Path
from typing import Any, Iterable, Sequence

import yaml

from wtcli.errors import ConfigError

_MISSING = object()


def load_yaml(path: str | Path) -> Any:
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise ConfigError(f"{path}: file not found") from None
    except (OSError, UnicodeDecodeError) as e:
        raise ConfigError(f"{path}: cannot read ({e.__class__.__name__})") from None
    try:
        return yaml.safe_load(text)
    except yaml.YAMLError as e:
        mark = getattr(e, "problem_mark", None)
        at = f" (line {mark.line + 1}, column {mark.column + 1})" if mark else ""
        problem = getattr(e, "problem", None) or str(e).splitlines()[0]
        raise ConfigError(f"{path}: not valid YAML{at}: {problem}") from None


def merge(base: dict, over: dict) -> dict:
    """Deep-merge a user's mapping over packaged defaults (neither input is changed)."""
    out = copy.deepcopy(base)
    for k, v in over.items():
        if isinstance(v, dict) and isinstance(out.get(k), dict):
            out[k] = merge(out[k], v)
        else:
            out[k] = v
    return out


def hint(word: str, choices: Iterable[str]) -> str:
    close = difflib.get_close_matches(str(word), list(choices), n=1, cutoff=0.6)
    return f" (did you mean '{close[0]}'?)" if close else ""


def need_mapping(value: Any, where: str) -> dict:
    if not isinstance(value, dict):
        raise ConfigError(f"{where}: expected a mapping of keys, got {type(value).__name__}")
    return value


def check_keys(mapping: dict, allowed: Iterable[str], where: str,
               required: Sequence[str] = ()) -> None:
    allowed = list(allowed)
    for key in mapping:
        if key not in allowed:
            raise ConfigError(f"{where}: unknown key '{key}'{hint(key, allowed)}; allowed: "
                              f"{', '.join(allowed)}")
    for key in required:
        if key not in mapping:
            raise ConfigError(f"{where}: missing required key '{key}'")


def number(mapping: dict, key: str, where: str, lo: float | None = None, hi: float | None = None,
           default: Any = _MISSING, integer: bool = False, lo_open: bool = False) -> Any:
    if key not in mapping or mapping[key] is None:
        if default is _MISSING:
            raise ConfigError(f"{where}: missing required key '{key}'")
        return default
    v = mapping[key]
    kind = "an integer" if integer else "a number"
    rng = _range_text(lo, hi, lo_open)
    ok = isinstance(v, int) if integer else isinstance(v, (int, float))
    if isinstance(v, bool) or not ok or (not integer and not math.isfinite(v)) \
            or (lo is not None and (v <= lo if lo_open else v < lo)) \
            or (hi is not None and v > hi):
        raise ConfigError(f"{where}.{key}: expected {kind}{rng}, got {v!r}")
    return int(v) if integer else float(v)


def choice(mapping: dict, key: str, where: str, choices: Sequence[str],
           default: Any = _MISSING) -> Any:
    if key not in mapping or mapping[key] is None:
        if default is _MISSING:
            raise ConfigError(f"{where}: missing required key '{key}'")
        return default
    v = mapping[key]
    if v not in choices:
        raise ConfigError(f"{where}.{key}: expected one of {', '.join(map(str, choices))}, "
                          f"got {v!r}{hint(v, map(str, choices))}")
    return v


def string(mapping: dict, key: str, where: str, default: Any = _MISSING) -> Any:
    if key not in mapping or mapping[key] is None:
        if default is _MISSING:
            raise ConfigError(f"{where}: missing required key '{key}'")
        return default
    v = mapping[key]
    if not isinstance(v, (str, int)) or isinstance(v, bool) or str(v) == "":
        raise ConfigError(f"{where}.{key}: expected a non-empty string, got {v!r}")
    return str(v)


def vector(mapping: dict, key: str, where: str, length: int, default: Any = _MISSING) -> Any:
    if key not in mapping or mapping[key] is None:
        if default is _MISSING:
            raise ConfigError(f"{where}: missing required key '{key}'")
        return default
    v = mapping[key]
    if not isinstance(v, (list, tuple)) or len(v) != length or not all(
            isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) for x in v):
        raise ConfigError(f"{where}.{key}: expected a list of {length} numbers, got {v!r}")
    return [float(x) for x in v]


def _range_text(lo: float | None, hi: float | None, lo_open: bool) -> str:
    if lo is not None and hi is not None:
        return f" in {'(' if lo_open else '['}{lo:g}, {hi:g}]"
    if lo is not None:
        return f" {'>' if lo_open else '>='} {lo:g}"
    if hi is not None:
        return f" <= {hi:g}"
    return ""

"""Small helpers every YAML reader uses, so every config error reads the same way:
``turbines.yaml: turbines[1].hub_height: expected a number in [10, 250], got -5``.
Unknown keys get a "did you mean" hint. Safe loading only (no ``!!python`` tags), duplicate
keys refused, aliases limited (``load_yaml``); values quoted in messages are bounded."""

from __future__ import annotations

import copy
import difflib
import math
from pathlib import Path
from typing import Any, Iterable, Sequence

import yaml

from wtcli.errors import ConfigError
from wtcli.jsonio import MAX_YAML_BYTES, read_capped, shown

_MISSING = object()

# The most values a YAML document may hold once its aliases are expanded. A settings file has
# hundreds; ~1 KB of nested aliases (an "alias bomb") expands to billions, which any code
# walking the data (a check, an error message, a deep copy) would take minutes and gigabytes
# over. The document is refused before anything is built from it.
MAX_YAML_VALUES = 100_000


class _Refused(Exception):
    def __init__(self, problem: str, mark: Any = None):
        super().__init__(problem)
        self.problem, self.problem_mark = problem, mark


class _StrictLoader(yaml.SafeLoader):
    """``yaml.SafeLoader`` that refuses a key given twice in one mapping (YAML 1.2 forbids it;
    PyYAML would keep the last one silently, dropping e.g. a first ``turbines:`` block)."""

    def construct_mapping(self, node: yaml.MappingNode, deep: bool = False) -> dict:
        seen: dict[Any, Any] = {}
        for key_node, _ in node.value:
            if isinstance(key_node, yaml.ScalarNode) and key_node.tag != "tag:yaml.org,2002:merge":
                key = (key_node.tag, key_node.value)
                if key in seen:
                    raise _Refused(f"duplicate key {shown(key_node.value)} (first given on line "
                                   f"{seen[key].line + 1})", key_node.start_mark)
                seen[key] = key_node.start_mark
        return super().construct_mapping(node, deep=deep)


def _expanded_size(root: yaml.Node) -> None:
    """Refuse a node graph whose aliases expand past MAX_YAML_VALUES, or refer to themselves.
    Shared nodes are counted once per reference (that is what the data will look like),
    memoised, so the check itself takes time proportional to the text."""
    size: dict[int, int] = {}
    active: set[int] = set()
    stack: list[tuple[yaml.Node, bool]] = [(root, False)]
    while stack:
        node, done = stack.pop()
        key = id(node)
        if done:
            active.discard(key)
            children = _children(node)
            total = 1 + sum(size[id(c)] for c in children)
            if total > MAX_YAML_VALUES:
                raise _Refused(f"holds over {MAX_YAML_VALUES:,} values once its aliases are "
                               "expanded (an alias bomb?); a settings file needs far fewer",
                               node.start_mark)
            size[key] = total
            continue
        if key in size:
            continue
        if key in active:
            raise _Refused("an alias refers to the value it is part of", node.start_mark)
        active.add(key)
        stack.append((node, True))
        for c in _children(node):
            if id(c) in active:
                raise _Refused("an alias refers to the value it is part of", c.start_mark)
            if id(c) not in size:
                stack.append((c, False))


def _children(node: yaml.Node) -> list[yaml.Node]:
    if isinstance(node, yaml.SequenceNode):
        return list(node.value)
    if isinstance(node, yaml.MappingNode):
        return [n for pair in node.value for n in pair]
    return []


def parse_yaml(text: str) -> Any:
    """``text`` -> Python data, safely: no tags beyond YAML's own, no duplicate keys, no alias
    expanding past MAX_YAML_VALUES. Raises yaml.YAMLError or _Refused."""
    loader = _StrictLoader(text)
    try:
        node = loader.get_single_node()
        if node is None:
            return None
        _expanded_size(node)
        return loader.construct_document(node)
    finally:
        loader.dispose()


def load_yaml(path: str | Path) -> Any:
    """Read a YAML settings file safely (``parse_yaml``). A file that is missing, a folder,
    unreadable or over MAX_YAML_BYTES is InputError (exit 3, like any input file); what it says
    (syntax, duplicate keys, alias bombs, not UTF-8) is ConfigError (exit 4)."""
    path = Path(path)
    try:
        text = read_capped(path, MAX_YAML_BYTES, "YAML")
    except UnicodeDecodeError:
        raise ConfigError(f"{path}: not valid YAML (not UTF-8 text)") from None
    try:
        return parse_yaml(text)
    except (yaml.YAMLError, _Refused) as e:
        mark = getattr(e, "problem_mark", None)
        at = f" (line {mark.line + 1}, column {mark.column + 1})" if mark else ""
        problem = getattr(e, "problem", None) or str(e).splitlines()[0]
        raise ConfigError(f"{path}: not valid YAML{at}: {problem}") from None
    except RecursionError:
        raise ConfigError(f"{path}: not valid YAML: nested too deeply") from None


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
    if not isinstance(word, str) or len(word) > 100:
        return ""
    close = difflib.get_close_matches(str(word), list(choices), n=1, cutoff=0.6)
    return f" (did you mean '{close[0]}'?)" if close else ""


def need_mapping(value: Any, where: str) -> dict:
    if not isinstance(value, dict):
        raise ConfigError(f"{where}: expected a mapping of keys, got {shown(value)}")
    return value


def check_keys(mapping: dict, allowed: Iterable[str], where: str,
               required: Sequence[str] = ()) -> None:
    allowed = list(allowed)
    for key in mapping:
        if key not in allowed:
            raise ConfigError(f"{where}: unknown key {shown(key)}{hint(key, allowed)}; allowed: "
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
        raise ConfigError(f"{where}.{key}: expected {kind}{rng}, got {shown(v)}")
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
                          f"got {shown(v)}{hint(v, map(str, choices)) if isinstance(v, str) else ''}")
    return v


def string(mapping: dict, key: str, where: str, default: Any = _MISSING) -> Any:
    if key not in mapping or mapping[key] is None:
        if default is _MISSING:
            raise ConfigError(f"{where}: missing required key '{key}'")
        return default
    v = mapping[key]
    if not isinstance(v, (str, int)) or isinstance(v, bool) or str(v) == "":
        raise ConfigError(f"{where}.{key}: expected a non-empty string, got {shown(v)}")
    return str(v)


def vector(mapping: dict, key: str, where: str, length: int, default: Any = _MISSING) -> Any:
    if key not in mapping or mapping[key] is None:
        if default is _MISSING:
            raise ConfigError(f"{where}: missing required key '{key}'")
        return default
    v = mapping[key]
    if not isinstance(v, (list, tuple)) or len(v) != length or not all(
            isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) for x in v):
        raise ConfigError(f"{where}.{key}: expected a list of {length} numbers, got {shown(v)}")
    return [float(x) for x in v]


def _range_text(lo: float | None, hi: float | None, lo_open: bool) -> str:
    if lo is not None and hi is not None:
        return f" in {'(' if lo_open else '['}{lo:g}, {hi:g}]"
    if lo is not None:
        return f" {'>' if lo_open else '>='} {lo:g}"
    if hi is not None:
        return f" <= {hi:g}"
    return ""

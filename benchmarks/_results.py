"""Where every benchmark writes its figures: ``benchmarks/results/NAME.json``.

A benchmark adopts it with three lines::

    from _results import save             # benchmarks/ is on sys.path when run as a script
    ...
    save("plan_coverage", res)             # at the end of main(): figures + how they were made

The file is the benchmark's figures with the tool's header (``wtcli.jsonio.document``) and a
``measured`` block: the exact command, the date (UTC) and the machine (CPU model, cores, GPU,
Python, torch and numpy versions). ``benchmarks/report.py`` renders ``docs/benchmarks.md``
from these files, so a published figure always names the run that made it.
"""

from __future__ import annotations

import os
import platform
import shlex
import sys
from datetime import datetime, timezone
from importlib import metadata
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results"
SCHEMA_PREFIX = "wtinspect.benchmark."

if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from wtcli.jsonio import document, write_json  # noqa: E402


def _version(package: str) -> str | None:
    try:
        return metadata.version(package)
    except metadata.PackageNotFoundError:
        return None


def _cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine() or "unknown"


def _gpu() -> str | None:
    """The GPU a benchmark could have used: asked of torch only when the benchmark imported it
    (importing torch here would cost a plan benchmark seconds for nothing)."""
    torch = sys.modules.get("torch")
    if torch is None or not torch.cuda.is_available():
        return None
    return torch.cuda.get_device_name(0)


def machine() -> dict[str, Any]:
    """The machine a figure was measured on, and one line that says it for the docs."""
    cores = os.cpu_count() or 0
    cpu = _cpu_model()
    gpu = _gpu()
    return {"summary": f"{cores}-core {platform.machine()} CPU ({cpu}), "
                       + (f"GPU {gpu}" if gpu else "no GPU"),
            "cpu": cpu, "cores": cores, "arch": platform.machine(), "gpu": gpu,
            "python": platform.python_version(), "torch": _version("torch"),
            "numpy": _version("numpy")}


def command(script: str | Path | None = None, argv: list[str] | None = None) -> str:
    """The command that reproduces this run, from the repository root: ``python
    benchmarks/NAME.py ARGS`` (``argv``: the arguments ``main`` parsed, default ``sys.argv[1:]``)."""
    script = Path(script or sys.argv[0]).resolve()
    shown = script.relative_to(ROOT) if script.is_relative_to(ROOT) else script
    args = sys.argv[1:] if argv is None else list(argv)
    return shlex.join(["python", str(shown), *_without_out(args)])


def _without_out(args: list[str]) -> list[str]:
    """``args`` less ``--out PATH`` and ``--log PATH``: where a run wrote its files does not change
    its figures, and a scratch path in the docs would send a reader to a file they do not have."""
    kept, skip = [], False
    for a in args:
        if skip:
            skip = False
        elif a in _OUTPUT_FLAGS:
            skip = True
        elif not a.startswith(tuple(f + "=" for f in _OUTPUT_FLAGS)):
            kept.append(a)
    return kept


_OUTPUT_FLAGS = ("--out", "--log")


def now_utc() -> str:
    return datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M UTC")


def measured(script: str | Path | None = None, argv: list[str] | None = None) -> dict[str, Any]:
    return {"command": command(script, argv), "date": now_utc(), "machine": machine()}


def _script(name: str) -> Path | None:
    own = RESULTS.parent / f"{name}.py"
    return own if own.is_file() else None


def save(name: str, figures: dict[str, Any], *, argv: list[str] | None = None,
         out: str | Path | None = None, script: str | Path | None = None) -> Path:
    """Write ``figures`` as ``benchmarks/results/NAME.json`` (or ``out``), with the command, date
    and machine that made them. Returns the path written."""
    if "measured" in figures:
        raise ValueError("figures must not have a 'measured' key: save() writes it")
    body = {"measured": measured(script or _script(name), argv), **figures}
    path = Path(out) if out is not None else RESULTS / f"{name}.json"
    return write_json(path, document(SCHEMA_PREFIX + name, 1, body))

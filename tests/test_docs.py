"""Every ```console block in docs/*.md runs here, line by line, in a scratch folder holding a
copy of sample_images/ (and models/ linked), so the documented examples cannot rot.

Convention for doc pages: a line ``$ wtinspect ARGS`` is run; a trailing ``# exit N`` states
the expected exit code (default 0); other lines in the block are sample output, not checked.
``# needs shared/PATH`` (alone or after ``exit N,``) marks an example that reads the shared
data beside the repository (``../shared``, linked into the scratch folder as ``shared``): it is
skipped where that is absent.
"""

from __future__ import annotations

import os
import re
import shlex
import shutil
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGES = sorted((ROOT / "docs").glob("*.md"))
BLOCK = re.compile(r"```console\n(.*?)```", re.S)


SHARED = ROOT.parent / "shared"


def commands(page: Path) -> list[tuple[list[str], int, str | None]]:
    out = []
    for block in BLOCK.findall(page.read_text(encoding="utf-8")):
        for line in block.splitlines():
            if not line.startswith("$ "):
                continue
            cmd, _, comment = line[2:].partition(" # ")
            m = re.search(r"exit (\d+)", comment)
            argv = shlex.split(cmd)
            needs = re.search(r"needs (\S+)", comment)
            out.append((argv, int(m.group(1)) if m else 0, needs.group(1) if needs else None))
    return out


@pytest.mark.parametrize("page", PAGES, ids=[p.stem for p in PAGES])
def test_doc_examples_run(page, tmp_path, monkeypatch, runner):
    from wtcli.cli import app

    cmds = commands(page)
    if not cmds:
        pytest.skip(f"{page.name} has no console examples")
    shutil.copytree(ROOT / "sample_images", tmp_path / "sample_images")
    if (ROOT / "models").exists():
        os.symlink(ROOT / "models", tmp_path / "models")
    if SHARED.is_dir() and any(needs for *_, needs in cmds):
        os.symlink(SHARED, tmp_path / "shared")
    monkeypatch.chdir(tmp_path)
    for argv, want, needs in cmds:
        if needs and not (tmp_path / needs).exists():
            continue
        assert argv[0] == "wtinspect", f"{page.name}: examples must start with 'wtinspect': {argv}"
        res = runner.invoke(app, argv[1:])
        assert res.exit_code == want, (f"{page.name}: `{' '.join(argv)}` exited {res.exit_code}, "
                                       f"expected {want}\nstdout:\n{res.stdout}\nstderr:\n"
                                       f"{getattr(res, 'stderr', '')}\n{res.exception!r}")


def test_every_command_has_a_page():
    from typer.main import get_command

    from wtcli.cli import app

    names = set(get_command(app).commands)
    missing = [n for n in names if not (ROOT / "docs" / f"{n}.md").exists()]
    assert not missing, f"commands without a docs page: {missing}"

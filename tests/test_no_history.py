"""The product speaks of itself as it is now: no comment, help text, test or doc numbers the
sessions or runs that made it (that history is in git and CHANGELOG.md). This is the search

    grep -rniE "session [0-9]|run [0-9]+[^a-z]" wtcli docs models tests benchmarks README.md

done in Python over the text files of those paths (binary files, such as weights and images,
are skipped as grep skips them)."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PATHS = ("wtcli", "docs", "models", "tests", "benchmarks", "README.md")
PATTERN = re.compile(r"session [0-9]|run [0-9]+[^a-z]", re.IGNORECASE)


def _is_text(path: Path) -> bool:
    try:
        with path.open("rb") as f:
            return b"\0" not in f.read(8192)
    except OSError:
        return False


def history_lines(root: Path = ROOT, paths: tuple[str, ...] = PATHS) -> list[str]:
    """``file:line: text`` for every line that matches, as grep -rn would list them."""
    files: list[Path] = []
    for name in paths:
        p = root / name
        if p.is_file():
            files.append(p)
        elif p.is_dir():
            files += sorted(f for f in p.rglob("*") if f.is_file() and "__pycache__" not in f.parts)
    hits = []
    for f in files:
        if not _is_text(f):
            continue
        text = f.read_text(encoding="utf-8", errors="replace")
        for n, line in enumerate(text.splitlines(), 1):
            if PATTERN.search(line):
                hits.append(f"{f.relative_to(root)}:{n}: {line.strip()[:120]}")
    return hits


def test_no_session_or_run_numbers_in_the_product():
    hits = history_lines()
    assert not hits, ("say what is true now and why, not which session or run made it:\n"
                      + "\n".join(hits))


def test_the_search_finds_what_it_should(tmp_path):
    # The numbers are formatted in, so that this file does not match its own search.
    (tmp_path / "docs").mkdir()
    (tmp_path / "docs" / "a.md").write_text("ok\nshipped in Session %d\nindices 0, 1, 2\n" % 12)
    (tmp_path / "README.md").write_text("as in RUN %d's figures\na run %d\nrun %drd\n" % (4, 5, 3))
    (tmp_path / "docs" / "w.bin").write_bytes(b"\0session %d" % 3)
    assert history_lines(tmp_path, ("docs", "README.md", "missing")) == [
        "docs/a.md:2: shipped in Session %d" % 12, "README.md:1: as in RUN %d's figures" % 4]

import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))


@pytest.fixture
def runner():
    from typer.testing import CliRunner

    return CliRunner()


@pytest.fixture
def cli(runner):
    """Invoke ``wtinspect ARGS...``; returns click's Result (exit_code, stdout, stderr)."""
    from wtcli.cli import app

    def invoke(*args: str):
        return runner.invoke(app, [str(a) for a in args])

    return invoke

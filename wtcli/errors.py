"""The exception tree and the exit codes. The CLI is the only place that maps one to the other.

Library code raises these (never prints or exits); ``wtcli.cli`` turns them into one red line
on stderr and the exit code below. Documented for users in ``docs/exit-codes.md``.
"""

from __future__ import annotations

from enum import IntEnum


class ExitCode(IntEnum):
    OK = 0
    UNEXPECTED = 1  # a bug: please report it with --debug output
    USAGE = 2  # bad command line (typer/click uses 2 too)
    INPUT = 3  # an input file is missing, unreadable or malformed
    CONFIG = 4  # a YAML/JSON config has a wrong key or value
    PERCEPTION = 5  # nothing usable found in an image (no blade, four blades, ...)
    PLAN = 6  # no safe plan exists for the given turbines/fleet/settings
    MODEL = 7  # model weights missing or corrupt
    SIMULATION = 8  # the flight simulation diverged or violated safety when asked to fail on it
    PARTIAL = 9  # a batch finished but some items failed (see its report)
    INTERRUPTED = 130  # Ctrl-C (128 + SIGINT)
    TERMINATED = 143  # SIGTERM (128 + 15): a batch scheduler's time limit, `timeout`, `kill PID`


class WtError(Exception):
    """Base of all expected errors. ``str(err)`` is the one line shown to the user."""

    exit_code = ExitCode.UNEXPECTED


class UsageError(WtError):
    """The command line does not say enough (e.g. which turbine a photo shows): exit 2, as a
    wrong option."""

    exit_code = ExitCode.USAGE


class InputError(WtError):
    exit_code = ExitCode.INPUT


class OutputError(WtError):
    """An output path cannot be written: a file in the way, a read-only folder, a full disk.
    Same exit code as an unreadable input (docs/exit-codes.md); the message names the path.
    ``errno``: the OSError's, where one caused it (a batch tells a name too long for one item
    from a full disk that stops every item)."""

    exit_code = ExitCode.INPUT

    def __init__(self, message: str, errno: int | None = None) -> None:
        super().__init__(message)
        self.errno = errno


class ConfigError(WtError):
    exit_code = ExitCode.CONFIG


class PerceptionError(WtError):
    exit_code = ExitCode.PERCEPTION


class PlanError(WtError):
    exit_code = ExitCode.PLAN


class ModelError(WtError):
    exit_code = ExitCode.MODEL


class SimulationError(WtError):
    exit_code = ExitCode.SIMULATION


class PartialFailure(WtError):
    """A batch ran to the end but some items failed; their errors are in the batch report."""

    exit_code = ExitCode.PARTIAL

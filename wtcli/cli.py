"""The `wtinspect` command line: global options, command discovery and the one error boundary.

Each subcommand lives in ``wtcli/commands/<name>.py`` and exposes ``register(app)``; this file
never needs editing to add one. Commands parse options, call one library function and print.
"""

from __future__ import annotations

import os
import signal
import sys
from typing import Any, Optional


def _quit_at_once(signum: int, frame: Any) -> None:
    """Ctrl-C or SIGTERM outside the error boundary (while the modules below load, 0.3 s, or
    typer parses the command line): nothing to clean up yet; the one line, not a traceback."""
    try:
        os.write(2, b"interrupted\n")
    except OSError:
        pass
    os._exit(128 + signum)


def _handle_signals(handler: Any) -> dict[int, Any]:
    """Point SIGINT and SIGTERM at ``handler``; returns the handlers replaced (none where this
    is not the main thread, which alone may set them)."""
    saved = {}
    try:
        for sig in (signal.SIGINT, signal.SIGTERM):
            saved[sig] = signal.signal(sig, handler)
    except ValueError:
        pass
    return saved


def _restore_signals(saved: dict[int, Any]) -> None:
    for sig, handler in saved.items():
        if handler is not None:  # None: set outside Python, cannot be put back from here
            signal.signal(sig, handler)


_at_import = _handle_signals(_quit_at_once)

# The imports below take most of the start-up: a Ctrl-C there ends quietly (_quit_at_once).
import gc
import importlib
import pkgutil
import re
import traceback

import typer
from rich.markup import escape
from typer.core import TyperGroup

from wtcli import __version__
from wtcli.console import DataStream, LogStream, err_console, to_devnull
from wtcli.errors import ExitCode, WtError

# torch's OpenMP threads (one per core) spin at every barrier by default: with one of two cores
# busy elsewhere, a forward pass of the segmenter took 1.2-5.8 s instead of 0.4 s. Passive
# threads sleep instead: 0.74 s then, 0.43 s on an idle CPU (benchmarks, docs/benchmarks.md).
# Read when torch loads, so set before any command imports it; a user's setting wins.
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")


def one_line(text: str, limit: int = 400) -> str:
    """An error message as printed: one line (newlines folded), at most ``limit`` characters,
    and markup-escaped, so text in square brackets from an input (``[.nan, 0, 0]``) is shown
    as it is rather than taken for a console style."""
    text = " ".join(str(text).split("\n")).replace("\r", " ")
    if len(text) > limit:
        text = text[:limit - 3] + "..."
    return escape(text)


# typer refuses a path argument it cannot read ("Invalid value for 'IMAGE|FOLDER': path
# 'a.png' is not readable.") with its usage exit 2 and a box of help; an unreadable input is
# exit 3 naming the path (docs/exit-codes.md), as when our own code finds it.
_NOT_READABLE = re.compile(r"'(?P<path>.+)' is not readable\.$")


def _debug(ctx: typer.Context) -> bool:
    obj = ctx.find_root().obj
    return bool(obj and obj.get("debug")) or os.environ.get("WTINSPECT_DEBUG") == "1"


def _interrupted(e: BaseException) -> bool:
    """An exception raised because of a KeyboardInterrupt: compiled code (numba's dispatcher)
    reports "returned a result with an exception set" as a SystemError chained to it."""
    seen = set()
    while e is not None and id(e) not in seen:
        if isinstance(e, KeyboardInterrupt):
            return True
        seen.add(id(e))
        e = e.__cause__ or e.__context__
    return False


# SIGTERM (a batch scheduler's time limit, `timeout`, `kill PID`) is handled as Ctrl-C: the
# same cleanup (a batch's report, a checkpoint of the steps done), then exit 143, not 130.
_main_pid: int | None = None  # the process main() runs in, while it runs; None: as a library
_terminated = False  # a SIGTERM came


def _on_sigterm(signum: int, frame: Any) -> None:
    if os.getpid() != _main_pid:
        # A forked child (a `plan --jobs` worker, a DataLoader worker) is ended by its pool
        # or parent with SIGTERM: it must die of it, not unwind as an interrupted command.
        signal.signal(signal.SIGTERM, signal.SIG_DFL)
        os.kill(os.getpid(), signal.SIGTERM)
        return
    global _terminated
    _terminated = True
    # A scheduler signals the whole process group: our workers die of the same SIGTERM, and
    # torch's DataLoader SIGCHLD handler would raise for each, in the middle of the cleanup
    # (a checkpoint save). Their deaths are expected now. (A handler doing nothing, not
    # SIG_DFL: Python reports a SIGCHLD already pending for a handler taken away.)
    if callable(signal.getsignal(signal.SIGCHLD)):
        signal.signal(signal.SIGCHLD, _expected)
    raise KeyboardInterrupt


def _expected(signum: int, frame: Any) -> None:
    pass


def _sigterm_default_in_child() -> None:
    # At fork already, so a child busy in compiled code dies at once rather than when it
    # next runs Python (where _on_sigterm would end it).
    try:
        if signal.getsignal(signal.SIGTERM) is _on_sigterm:
            signal.signal(signal.SIGTERM, signal.SIG_DFL)
    except ValueError:  # forked off the main thread: _on_sigterm's own check covers it
        pass


def _say_interrupted(ctx: typer.Context) -> None:
    # The console has markup off (console.py): a coloured line asks for it.
    err_console.print("[red]interrupted[/red]" + (" (SIGTERM)" if _terminated else ""),
                      markup=True, soft_wrap=True)
    ctx.exit(ExitCode.TERMINATED if _terminated else ExitCode.INTERRUPTED)


class _Boundary(TyperGroup):
    """Maps our exceptions to one red line on stderr and a documented exit code."""

    def list_commands(self, ctx: typer.Context) -> list[str]:
        # Keep the pipeline order in --help rather than alphabetical.
        order = ["synth", "segment", "contours", "pitch", "site", "plan", "fly", "train",
                 "train-refiner"]
        names = list(self.commands)
        return sorted(names, key=lambda n: (order.index(n) if n in order else len(order), n))

    def invoke(self, ctx: typer.Context) -> Any:
        saved = {}
        if _main_pid == os.getpid():  # run by main(): from here on, the boundary cleans up
            saved = _handle_signals(signal.default_int_handler)
            signal.signal(signal.SIGTERM, _on_sigterm)
        try:
            done = super().invoke(ctx)
            sys.stdout.flush()  # a full disk under stdout fails here, named, not at exit
            return done
        except typer.BadParameter as e:
            m = _NOT_READABLE.search(e.message)
            if m is None:
                raise
            err_console.print(f"[red]error:[/red] {one_line(m.group('path'))}: cannot read "
                              "(permission denied)", markup=True, soft_wrap=True)
            ctx.exit(ExitCode.INPUT)
        except (typer.Exit, typer.Abort, typer.TyperException):
            raise
        except KeyboardInterrupt:
            _say_interrupted(ctx)
        except WtError as e:
            if _debug(ctx):
                err_console.print(traceback.format_exc(), markup=False)
            err_console.print(f"[red]error:[/red] {one_line(str(e))}", markup=True, soft_wrap=True)
            ctx.exit(int(e.exit_code))
        except BrokenPipeError:
            # The reader of stdout went away (``wtinspect ... | head``): nothing left to say.
            # Further writes at exit go to /dev/null instead of raising again.
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
            ctx.exit(ExitCode.OK)
        except OSError as e:
            if e.filename is None:
                self._unexpected(ctx, e)
            # An OSError that names its file is that file's problem, not a bug: a folder
            # without permission, a file vanishing mid-run. Exit 3 with the path.
            if _debug(ctx):
                err_console.print(traceback.format_exc(), markup=False)
            err_console.print(f"[red]error:[/red] {one_line(str(e.filename))}: "
                              f"{one_line(e.strerror or e.__class__.__name__)}",
                              markup=True, soft_wrap=True)
            ctx.exit(ExitCode.INPUT)
        except Exception as e:  # noqa: BLE001 - the one place that catches everything
            if _interrupted(e):  # Ctrl-C inside a numba kernel comes out wrapped in a SystemError
                _say_interrupted(ctx)
            self._unexpected(ctx, e)
        finally:
            if saved:  # the work is over: a signal now just ends the process
                _handle_signals(_quit_at_once)

    @staticmethod
    def _unexpected(ctx: typer.Context, e: BaseException) -> None:
        if _debug(ctx):
            err_console.print(traceback.format_exc(), markup=False)
            ctx.exit(ExitCode.UNEXPECTED)
        err_console.print(f"[red]unexpected error:[/red] {e.__class__.__name__}: {one_line(str(e))} "
                          "(run with --debug for the traceback)", markup=True, soft_wrap=True)
        ctx.exit(ExitCode.UNEXPECTED)


app = typer.Typer(
    cls=_Boundary,
    name="wtinspect",
    help="Drone inspection of wind turbines: segment -> contours -> pitch -> plan -> fly.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    context_settings={"help_option_names": ["-h", "--help"]},
)


def _version(value: bool) -> None:
    if value:
        typer.echo(f"wtinspect {__version__}")
        raise typer.Exit()


@app.callback()
def _root(
    ctx: typer.Context,
    version: Optional[bool] = typer.Option(None, "--version", callback=_version, is_eager=True,
                                           help="Print the version and exit."),
    debug: bool = typer.Option(False, "--debug", help="Show tracebacks on errors."),
) -> None:
    """Drone inspection of wind turbines: segment -> contours -> pitch -> plan -> fly.

    Exit codes: 0 ok, 1 unexpected, 2 usage, 3 input, 4 config, 5 perception, 6 plan,
    7 model, 8 simulation, 9 partial batch failure, 130 interrupted (docs/exit-codes.md).
    """
    ctx.obj = {"debug": debug}
    if not debug:
        # OpenCV logs its own lines on stderr for a corrupt image ("IHDR chunk shall be
        # first"); our one-line error names the file and says the same.
        import cv2

        cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_SILENT)


def _register_commands() -> None:
    import wtcli.commands as pkg

    for info in sorted(pkgutil.iter_modules(pkg.__path__), key=lambda i: i.name):
        if info.name.startswith("_"):
            continue
        module = importlib.import_module(f"wtcli.commands.{info.name}")
        module.register(app)


_register_commands()
_restore_signals(_at_import)  # imported as a library (tests), the signals stay the caller's


def _stdout_gone(before: os.stat_result | None) -> bool:
    """Whether the exit-1 just raised was a write to a stdout whose reader went away
    (``wtinspect --help | head -1``): rich then points stdout at /dev/null before exiting 1,
    click wraps sys.stdout in its PacifyFlushWrapper. Any other exit keeps its code."""
    if type(sys.stdout).__name__ == "PacifyFlushWrapper":
        return True
    try:
        now = os.fstat(sys.__stdout__.fileno())
        return (before is not None and not os.path.samestat(before, now)
                and os.path.samestat(now, os.stat(os.devnull)))
    except (OSError, ValueError, AttributeError):
        return False


def _settle_streams(data: DataStream | None, code: Any) -> Any:
    """Flush stdout and the log before the exit code is final. A stdout that failed where no
    error said so makes a run that would exit 0 exit 3, with the line naming stdout. Whatever
    the log (or stdout) still holds and cannot take is dropped: the interpreter's own flush at
    exit would fail on it again and turn the exit code into 120."""
    if data is not None:
        try:
            data.flush()
        except WtError:
            pass  # data.error says it
        except BrokenPipeError:
            pass  # the reader went away: dropped below
        if data.error is not None and code in (0, None):
            err_console.print(f"[red]error:[/red] {one_line(data.error)}", markup=True,
                              soft_wrap=True)
            code = int(ExitCode.INPUT)
    for stream in (sys.__stdout__, sys.__stderr__):
        try:
            stream.flush()
        except (OSError, ValueError, AttributeError):
            to_devnull(stream)
            try:
                stream.flush()
            except (OSError, ValueError, AttributeError):
                pass
    return code


_fork_hook = False  # os.register_at_fork adds a hook at every call: once is enough


def main(argv: list[str] | None = None) -> None:
    global _main_pid, _fork_hook, _terminated
    _main_pid, _terminated = os.getpid(), False
    # Until the boundary takes over (typer parsing the command line), a signal ends at once.
    outside = _handle_signals(_quit_at_once)
    if not _fork_hook:
        os.register_at_fork(after_in_child=_sigterm_default_in_child)
        _fork_hook = True
    streams = sys.stdout, sys.stderr
    data = DataStream(sys.stdout) if sys.stdout is not None else None
    if data is not None:
        sys.stdout = data
    if sys.stderr is not None:
        sys.stderr = LogStream(sys.stderr)
    try:
        try:
            before = os.fstat(sys.__stdout__.fileno())
        except (OSError, ValueError, AttributeError):
            before = None
        code: Any = 0
        try:
            app(args=argv if argv is not None else sys.argv[1:], prog_name="wtinspect")
        except SystemExit as e:
            code = e.code
            # Output cut short by its reader, as `head` does, is not a failure: exit 0
            # quietly, as standard tools do (help and --version are printed before any
            # command runs, so _Boundary's own BrokenPipeError case does not see them).
            if code == 1 and _stdout_gone(before):
                to_devnull(sys.__stdout__)
                code = int(ExitCode.OK)
        except WtError as e:  # stdout failing under --help or --version, before the boundary
            err_console.print(f"[red]error:[/red] {one_line(str(e))}", markup=True, soft_wrap=True)
            code = int(e.exit_code)
        raise SystemExit(_settle_streams(data, code)) from None
    finally:
        sys.stdout, sys.stderr = streams
        _restore_signals(outside)
        _main_pid = None  # a later in-process use (CliRunner) leaves the signals alone
        # The process ends here: without this, the interpreter's last collections walk every
        # object numba and the planner made (0.2-0.3 s of a 2 s photo -> plan, for nothing).
        gc.freeze()

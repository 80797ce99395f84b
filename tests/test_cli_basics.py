from wtcli import __version__


def test_version(cli):
    r = cli("--version")
    assert r.exit_code == 0 and r.stdout.strip() == f"wtinspect {__version__}"


def test_unknown_command_is_usage_error(cli):
    assert cli("no-such-command").exit_code == 2


def _app_with(fn):
    """A throwaway app with our error boundary and one command that runs ``fn``."""
    import typer

    from wtcli.cli import _Boundary

    app = typer.Typer(cls=_Boundary)

    @app.callback()
    def root(ctx: typer.Context, debug: bool = typer.Option(False, "--debug")):
        ctx.obj = {"debug": debug}

    @app.command()
    def go():
        fn()

    return app


def test_error_boundary_maps_errors_to_one_line_and_exit_code(runner):
    from wtcli.errors import ConfigError, ExitCode

    def fail():
        raise ConfigError("turbines.yaml: turbines[0].hub_height: expected a number > 0, got -1")

    r = runner.invoke(_app_with(fail), ["go"])
    assert r.exit_code == ExitCode.CONFIG
    assert r.stdout == ""
    assert "hub_height" in r.stderr and "Traceback" not in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1


def test_unexpected_errors_exit_1_with_hint_and_traceback_on_debug(runner):
    def boom():
        raise RuntimeError("kaboom")

    r = runner.invoke(_app_with(boom), ["go"])
    assert r.exit_code == 1 and "--debug" in r.stderr and "Traceback" not in r.stderr
    r = runner.invoke(_app_with(boom), ["--debug", "go"])
    assert r.exit_code == 1 and "Traceback" in r.stderr


def test_ctrl_c_exits_130(runner):
    def interrupt():
        raise KeyboardInterrupt

    assert runner.invoke(_app_with(interrupt), ["go"]).exit_code == 130


def _run_into_closed_pipe(*args: str):
    """Run ``wtinspect ARGS`` with stdout a pipe whose reader is already gone (what
    ``wtinspect --help | head -1`` becomes once ``head`` has its line): every write fails."""
    import os
    import subprocess
    import sys

    r, w = os.pipe()
    os.close(r)
    try:
        return subprocess.run([sys.executable, "-m", "wtcli", *args], stdout=w,
                              stderr=subprocess.PIPE, text=True, timeout=120)
    finally:
        os.close(w)


def test_help_into_a_closed_pipe_exits_0_quietly():
    for args in (["--help"], ["plan", "--help"], ["--version"]):
        done = _run_into_closed_pipe(*args)
        assert done.returncode == 0, (args, done.returncode, done.stderr)
        assert done.stderr == "", (args, done.stderr)


def test_a_usage_error_keeps_exit_2_when_stdout_is_a_closed_pipe():
    done = _run_into_closed_pipe("no-such-command")  # the error goes to stderr, still open
    assert done.returncode == 2 and "no-such-command" in done.stderr


def test_ctrl_c_says_interrupted_without_markup_tags(runner):
    def interrupt():
        raise KeyboardInterrupt

    r = runner.invoke(_app_with(interrupt), ["go"])
    assert r.exit_code == 130 and r.stderr == "interrupted\n" and r.stdout == ""


def test_ctrl_c_inside_compiled_code_is_an_interrupt_not_a_bug(runner):
    """numba's dispatcher turns a Ctrl-C in a kernel into "SystemError: ... returned a result
    with an exception set", chained to the KeyboardInterrupt."""
    def kernel():
        try:
            raise KeyboardInterrupt
        except KeyboardInterrupt as e:
            raise SystemError("CPUDispatcher(<function trace>) returned a result with an "
                              "exception set") from e

    r = runner.invoke(_app_with(kernel), ["go"])
    assert r.exit_code == 130 and r.stderr == "interrupted\n"

    def bug():
        raise SystemError("a real one")
    r = runner.invoke(_app_with(bug), ["go"])
    assert r.exit_code == 1 and "unexpected error: SystemError" in r.stderr


def _run_with(args: list[str], **streams):
    import subprocess
    import sys

    return subprocess.run([sys.executable, "-m", "wtcli", *map(str, args)], text=True,
                          timeout=120, **streams)


def test_stdout_that_cannot_be_written_is_exit_3_naming_stdout():
    """`--json > /dev/full` or a full disk: exit 3 and one line naming stdout, not exit 1
    ("unexpected error: OSError") nor 120 (the interpreter's own flush failing at exit)."""
    import os
    import subprocess
    from pathlib import Path

    import pytest

    if not os.path.exists("/dev/full"):
        pytest.skip("no /dev/full here")
    instances = Path(__file__).resolve().parents[1] / "sample_images" / "instances.json"
    # 97 kB of JSON, a short line, the version (printed before any command runs)
    for args in (["contours", instances, "--json"], ["contours", instances], ["--version"]):
        with open("/dev/full", "w") as full:
            done = _run_with(args, stdout=full, stderr=subprocess.PIPE)
        assert done.returncode == 3, (args, done.returncode, done.stderr[-800:])
        assert done.stderr == "error: stdout: cannot write (No space left on device)\n", args


def test_a_log_that_cannot_be_written_keeps_the_exit_code_the_run_earned(tmp_path):
    """stderr on a full disk (a batch job's log): the lines are dropped; a run that succeeds
    still exits 0, a missing input still 3."""
    import os
    import subprocess
    from pathlib import Path

    import pytest

    if not os.path.exists("/dev/full"):
        pytest.skip("no /dev/full here")
    instances = Path(__file__).resolve().parents[1] / "sample_images" / "instances.json"
    with open("/dev/full", "w") as full:
        ok = _run_with(["contours", instances, "--out", tmp_path / "c.json"], stderr=full,
                       stdout=subprocess.PIPE)
        missing = _run_with(["contours", tmp_path / "missing.json"], stderr=full,
                            stdout=subprocess.PIPE)
        debug = _run_with(["--debug", "contours", tmp_path / "missing.json"], stderr=full,
                          stdout=subprocess.PIPE)
    assert ok.returncode == 0 and (tmp_path / "c.json").is_file()
    assert missing.returncode == 3 and debug.returncode == 3

"""Signals, as a batch scheduler, `timeout`, `kill` and Ctrl-C send them: SIGTERM stops a command
as Ctrl-C does (its cleanup runs, the "interrupted" line) and exits 143; forked workers still die
of the SIGTERM their pool sends; a signal during start-up is one line, not a traceback; `plan`'s
worker processes end with the run. Each case runs ``wtinspect`` in its own process (the
handlers are installed by ``wtcli.cli.main``), the signal sent by the process to itself at a
known point, so nothing depends on timing."""

from __future__ import annotations

import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

# A throwaway command on the real app, run through main(): it signals itself, then waits.
WAITS = textwrap.dedent("""
    import os, signal, sys, time
    from pathlib import Path
    from wtcli.cli import app, main

    @app.command("wait-here")
    def wait_here(mark: Path, sig: str):
        try:
            os.kill(os.getpid(), getattr(signal, "SIG" + sig))
            time.sleep(30)
        except KeyboardInterrupt:
            mark.write_text("cleaned up")  # what a command does on Ctrl-C: a report, a checkpoint
            raise

    main(["wait-here", sys.argv[1], sys.argv[2]])
""")


def _python(code: str, *args: str, timeout: float = 120) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", code, *args], capture_output=True, text=True,
                          cwd=ROOT, timeout=timeout)


@pytest.mark.parametrize("sig, code, line", [("TERM", 143, "interrupted (SIGTERM)\n"),
                                              ("INT", 130, "interrupted\n")])
def test_sigterm_runs_the_cleanup_ctrl_c_runs_and_exits_143(tmp_path, sig, code, line):
    mark = tmp_path / "mark"
    done = _python(WAITS, str(mark), sig)
    assert done.returncode == code, (done.returncode, done.stderr[-800:])
    assert done.stderr == line and done.stdout == ""
    assert mark.read_text() == "cleaned up"


def test_a_forked_worker_dies_of_sigterm_rather_than_unwinding():
    """A pool ends its workers with SIGTERM: they must die of it (exit code -15), not raise
    KeyboardInterrupt as the main process does. Both ways a child can be found: the handler
    reset at fork, and a child holding our handler anyway (it checks the process id)."""
    code = textwrap.dedent("""
        import multiprocessing as mp, signal, time
        from wtcli import cli
        from wtcli.cli import app, main

        def rearmed():
            signal.signal(signal.SIGTERM, cli._on_sigterm)
            time.sleep(30)

        @app.command("fork-workers")
        def fork_workers():
            for target, args in ((time.sleep, (30,)), (rearmed, ())):
                p = mp.get_context("fork").Process(target=target, args=args)
                p.start()
                time.sleep(0.5)
                p.terminate()
                p.join(20)
                print(p.exitcode)

        main(["fork-workers"])
    """)
    done = _python(code)
    assert done.returncode == 0, done.stderr[-800:]
    assert done.stdout.split() == ["-15", "-15"], done.stderr[-800:]
    assert "KeyboardInterrupt" not in done.stderr


def test_sigterm_to_the_whole_group_lets_the_cleanup_finish(tmp_path):
    """A scheduler (or `timeout`) signals the process group: the workers die of the SIGTERM
    too, and a SIGCHLD handler that raises for a worker killed by a signal (torch's DataLoader
    has one) must not cut the cleanup short (the checkpoint save)."""
    code = textwrap.dedent("""
        import multiprocessing as mp, os, signal, sys, time
        from pathlib import Path
        from wtcli.cli import app, main

        def worker_killed(signum, frame):  # as torch's: a worker that died of a signal is an error
            raise RuntimeError("DataLoader worker is killed by signal: Terminated.")

        @app.command("group-term")
        def group_term(mark: Path):
            signal.signal(signal.SIGCHLD, worker_killed)
            worker = mp.get_context("fork").Process(target=time.sleep, args=(30,))
            worker.start()
            try:
                os.killpg(0, signal.SIGTERM)
                time.sleep(30)
            except KeyboardInterrupt:
                time.sleep(1)  # the worker's death arrives during the cleanup
                mark.write_text("cleaned up")
                raise

        main(["group-term", sys.argv[1]])
    """)
    mark = tmp_path / "mark"
    done = subprocess.run([sys.executable, "-c", code, str(mark)], capture_output=True, text=True,
                          cwd=ROOT, timeout=120, start_new_session=True)
    assert done.returncode == 143, (done.returncode, done.stderr[-800:])
    assert done.stderr == "interrupted (SIGTERM)\n" and mark.read_text() == "cleaned up"


@pytest.mark.parametrize("sig, code", [("SIGINT", 130), ("SIGTERM", 143)])
def test_a_signal_while_starting_is_one_line(sig, code):
    """The signal lands while wtcli.cli imports its modules (typer, the commands: 0.3 s), before
    the error boundary exists."""
    starts = textwrap.dedent(f"""
        import builtins, os, signal
        real = builtins.__import__

        def imports(name, *args, **kwargs):
            if name == "typer":
                os.kill(os.getpid(), signal.{sig})
            return real(name, *args, **kwargs)

        builtins.__import__ = imports
        from wtcli.cli import main
        main(["--version"])
    """)
    done = _python(starts)
    assert done.returncode == code, (done.returncode, done.stderr[-800:])
    assert done.stderr == "interrupted\n" and done.stdout == ""


def test_plan_workers_end_with_an_interrupted_run():
    """`plan --jobs` workers get no signal of their own when SIGTERM reaches the main process
    alone: the pool must end them rather than wait for their queued jobs (or leave them
    running, holding stdout open)."""
    import multiprocessing as mp

    from wtcli.plan.mission import _map

    def interrupt(signum, frame):
        raise KeyboardInterrupt

    before = signal.signal(signal.SIGALRM, interrupt)
    t0 = time.monotonic()
    try:
        signal.setitimer(signal.ITIMER_REAL, 1.0)
        with pytest.raises(KeyboardInterrupt):
            _map(time.sleep, [20.0] * 4, workers=2)
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, before)
    assert time.monotonic() - t0 < 10  # not the 40 s of the jobs
    deadline = time.monotonic() + 10
    while mp.active_children() and time.monotonic() < deadline:
        time.sleep(0.1)
    assert mp.active_children() == []

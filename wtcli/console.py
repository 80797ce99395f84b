"""stdout is data, stderr is people: the one stderr console and the progress bar factory."""

from __future__ import annotations

import math
import os
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager

from rich.console import Console
from rich.progress import (BarColumn, MofNCompleteColumn, Progress, TextColumn,
                           TimeElapsedColumn, TimeRemainingColumn)

# Markup off: what we print names files and quotes inputs, and "[1]" in a photo's name or
# "[.nan, 0, 0]" in a value must come out as written. A line that wants colour says
# markup=True and escapes what it quotes (rich.markup.escape).
err_console = Console(stderr=True, highlight=False, markup=False)


def to_devnull(stream) -> None:
    """Point ``stream``'s file descriptor at /dev/null (what it still buffers goes there)."""
    try:
        null = os.open(os.devnull, os.O_WRONLY)
        try:
            os.dup2(null, stream.fileno())
        finally:
            os.close(null)
    except (OSError, ValueError, AttributeError):
        pass


class LogStream:
    """``sys.stderr`` while a command runs: a write or flush the log cannot take (a full disk,
    a closed pipe) is dropped, so the log never changes the exit code the run earned."""

    def __init__(self, stream) -> None:
        self.stream = stream

    def write(self, text: str) -> int:
        try:
            return self.stream.write(text)
        except OSError:
            return len(text)

    def writelines(self, lines) -> None:
        for line in lines:
            self.write(line)

    def flush(self) -> None:
        try:
            self.stream.flush()
        except OSError:
            pass

    def __getattr__(self, name: str):
        return getattr(self.stream, name)


class DataStream:
    """``sys.stdout`` while a command runs: a write or flush that fails (``--json >`` a full
    disk) raises OutputError naming stdout (exit 3) instead of an unnamed OSError. A reader
    gone away (BrokenPipeError) passes through: the CLI ends quietly on that."""

    def __init__(self, stream) -> None:
        self.stream = stream
        self.error: str | None = None  # the message, once a write failed

    def _failed(self, e: OSError):
        from wtcli.jsonio import write_failed

        err = write_failed("stdout", e)
        self.error = str(err)
        # What stays buffered can never be written: from now on stdout is /dev/null, so the
        # interpreter's flush at exit does not fail again (exit 120, "Exception ignored").
        to_devnull(self.stream)
        return err

    def write(self, text: str) -> int:
        try:
            return self.stream.write(text)
        except BrokenPipeError:
            raise
        except OSError as e:
            raise self._failed(e) from None

    def writelines(self, lines) -> None:
        for line in lines:
            self.write(line)

    def flush(self) -> None:
        try:
            self.stream.flush()
        except BrokenPipeError:
            raise
        except OSError as e:
            raise self._failed(e) from None

    def __getattr__(self, name: str):
        return getattr(self.stream, name)


def make_progress(transient: bool = False) -> Progress:
    """A progress bar on stderr; use it as a context manager and write results after it closes."""
    return Progress(
        TextColumn("[bold]{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TextColumn("{task.fields[status]}"),
        TimeElapsedColumn(),
        TimeRemainingColumn(),
        console=err_console,
        transient=transient,
    )


@contextmanager
def count_bar(description: str, total: int) -> Iterator[Callable[..., None]]:
    """Progress over ``total`` items (photos, renders); yields ``advance(status="")``, called
    once per item done. On a terminal, a bar. In a log (stderr redirected: a batch server,
    ``nohup``) a bar shows nothing until the end, so a line at every tenth of the way instead
    (none for a single item)."""
    if err_console.is_terminal:
        with make_progress() as bar:
            task = bar.add_task(description, total=total, status="")
            yield lambda status="": bar.update(task, advance=1, status=status)
        return
    t0, done, every = time.monotonic(), 0, max(1, math.ceil(total / 10))
    last = t0

    def advance(status: str = "") -> None:
        nonlocal done, last
        done += 1
        now = time.monotonic()
        # Every tenth, and at least every LOG_EVERY_S: a tenth of 5 000 photos is half an hour.
        if total > 1 and (done % every == 0 or done == total or now - last >= LOG_EVERY_S):
            took, last = now - t0, now
            err_console.print(f"{description}: {done}/{total} ({100 * done / total:.0f} %), "
                              f"{took:.0f} s, {took / done:.2f} s each"
                              + (f", last: {status}" if status else ""), soft_wrap=True)

    yield advance


LOG_EVERY_S = 60.0  # in a log, a progress line at least this often while items finish
LOG_QUIET_S = 10.0  # in a log, a staged computation says nothing until it has run this long
LOG_GAP_S = 5.0  # ... and then at most a line this often


# A long computation in stages reports ``progress(stage, done, total)``: once with done 0 when a
# stage starts, then after each of its jobs. These two helpers are the two ends of that.
StageProgress = Callable[[str, int, int], None]


def stage_ticker(progress: StageProgress | None, stage: str, total: int) -> Callable[[], None]:
    """Report ``stage`` started (0 of ``total``); the returned ``tick()`` reports one more done
    (does nothing without ``progress``)."""
    if progress is None:
        return lambda: None
    progress(stage, 0, total)
    done = 0

    def tick() -> None:
        nonlocal done
        done += 1
        progress(stage, done, total)

    return tick


def _stage_lines(texts: dict[str, str], name: str) -> StageProgress:
    """``stage_bars`` in a log (a batch server, ``nohup``), where a bar shows nothing: once the
    computation has run LOG_QUIET_S (a short one says nothing, as on a terminal its bars
    vanish), a line when a stage passes a tenth or ends, at most one every LOG_GAP_S, and at
    least one every LOG_EVERY_S / 2 while jobs finish."""
    t0 = time.monotonic()
    starts: dict[str, float] = {}
    last = [t0]  # the time of the last line, of any stage

    def progress(stage: str, done: int, total: int) -> None:
        now = time.monotonic()
        start = starts.setdefault(stage, now)
        if done == 0 or now - t0 < LOG_QUIET_S:
            return
        every = max(1, math.ceil(total / 10))
        mark = done % every == 0 or done == total
        if (mark and now - last[0] >= LOG_GAP_S) or now - last[0] >= LOG_EVERY_S / 2:
            last[0] = now
            what = texts.get(stage, stage)
            err_console.print(f"{name}: {'' if what == name else what + ': '}{done}/{total} "
                              f"({100 * done / max(total, 1):.0f} %), {now - start:.0f} s",
                              soft_wrap=True)

    return progress


@contextmanager
def busy(text: str) -> Iterator[None]:
    """A spinner with ``text`` on stderr while a step without a count runs (writing many files);
    nothing in a log, where the step's own line follows it."""
    if not err_console.is_terminal:
        yield
        return
    with err_console.status(text):
        yield


@contextmanager
def stage_bars(texts: dict[str, str], name: str = "wtinspect") -> Iterator[StageProgress]:
    """A transient progress bar per stage on stderr; yields the ``progress`` callback to pass
    on. ``texts``: what each stage is called on screen (else its name). In a log (stderr
    redirected), lines instead once the work has run a while (``_stage_lines``), each starting
    with ``name`` (the command)."""
    if not err_console.is_terminal:
        yield _stage_lines(texts, name)
        return
    with make_progress(transient=True) as bar:
        tasks: dict[str, int] = {}

        def progress(stage: str, done: int, total: int) -> None:
            if stage not in tasks:
                tasks[stage] = bar.add_task(texts.get(stage, stage), total=total, status="")
            bar.update(tasks[stage], completed=done)

        yield progress

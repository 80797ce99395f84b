"""stdout is data, stderr is people: the one stderr console and the progress bar factory."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import contextmanager

from rich.console import Console
from rich.progress import (BarColumn, MofNCompleteColumn, Progress, TextColumn,
                           TimeElapsedColumn, TimeRemainingColumn)

err_console = Console(stderr=True, highlight=False)


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


@contextmanager
def stage_bars(texts: dict[str, str]) -> Iterator[StageProgress]:
    """A transient progress bar per stage on stderr; yields the ``progress`` callback to pass
    on. ``texts``: what each stage is called on screen (else its name). Only on a terminal:
    in a log (stderr redirected) a bar that vanishes leaves just a blank line before the
    result or the one-line error."""
    if not err_console.is_terminal:
        yield lambda stage, done, total: None
        return
    with make_progress(transient=True) as bar:
        tasks: dict[str, int] = {}

        def progress(stage: str, done: int, total: int) -> None:
            if stage not in tasks:
                tasks[stage] = bar.add_task(texts.get(stage, stage), total=total, status="")
            bar.update(tasks[stage], completed=done)

        yield progress

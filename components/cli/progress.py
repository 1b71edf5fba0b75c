"""Progress bars on stderr for the CLI's long jobs (rich): one bar per stage.

The APIs report progress through plain callbacks (``progress(done, total)`` or
``progress(stage, done, total)``); the CLI hands them a :class:`Bars`.  On a terminal the
bars move; in a pipe or a log rich draws them once, when they end, so a log keeps one
line per stage and no carriage-return litter.
"""

from __future__ import annotations

import sys

from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

__all__ = ["Bars"]


class Bars:
    """Bars on ``stream`` (default stderr), created on first use of each stage.

    ``unit``: what ``done``/``total`` count (``"s"`` of twin time, ``"views"``, ...).
    Call it as ``bars(stage, done, total)``, or use :meth:`stage` for an API that reports
    ``(done, total)``.  :meth:`close` (or the ``with`` block's end) finishes every bar.
    """

    def __init__(self, unit: str = "", stream=None):
        self.unit = unit
        console = Console(file=stream or sys.stderr, highlight=False, markup=False, emoji=False)
        count = (TextColumn("{task.completed:.1f} / {task.total:.0f} " + unit) if unit == "s"
                 else MofNCompleteColumn())
        self._progress = Progress(TextColumn("  {task.description:12s}"), BarColumn(bar_width=30), count,
                                  TimeElapsedColumn(), console=console, transient=False)
        self._tasks: dict[str, int] = {}
        self._started = False

    def __call__(self, stage: str, done: float, total: float) -> None:
        if not self._started:
            self._progress.start()
            self._started = True
        if stage not in self._tasks:
            self._tasks[stage] = self._progress.add_task(stage, total=max(float(total), 1e-9))
        self._progress.update(self._tasks[stage], completed=min(float(done), float(total)),
                              total=max(float(total), 1e-9))

    def stage(self, name: str):
        """A ``progress(done, total)`` callback for one stage."""
        return lambda done, total: self(name, done, total)

    def close(self) -> None:
        if self._started:
            self._progress.stop()
            self._started = False

    def __enter__(self) -> Bars:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

"""Progress on stderr for the tools' long jobs: rich bars, one per stage (:class:`Bars`), and
a plain progress line (:class:`LineProgress`).

The APIs report progress through plain callbacks (``progress(done, total)`` or
``progress(stage, done, total)``); the CLI hands them a :class:`Bars`.  On a terminal the
bars move; in a pipe or a log rich draws them once, when they end, so a log keeps one
line per stage and no carriage-return litter.
"""

from __future__ import annotations

import sys
import time

from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

__all__ = ["Bars", "LineProgress", "StepProgress"]


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


class LineProgress:
    """A progress line on stderr: rewritten in place on a terminal, a line per 10 % otherwise.
    Called with stats that have ``messages``, ``total`` (0: unknown) and ``seconds``;
    ``label`` starts the line."""

    def __init__(self, stream=None, enabled: bool = True, label: str = "humanpt view"):
        self.label = label
        self.stream = stream or sys.stderr
        self.enabled = enabled
        self.tty = self.stream.isatty()
        self._last_decile = -1
        self._last_write = 0.0

    def __call__(self, stats) -> None:
        if not self.enabled:
            return
        done = stats.messages
        if stats.total:
            frac = min(1.0, done / stats.total)
            bar = "#" * int(frac * 30)
            text = f"{self.label}: [{bar:30s}] {frac * 100:3.0f} % {done}/{stats.total} messages, {stats.seconds:.1f} s"
            decile = int(frac * 10)
        else:
            text = f"{self.label}: {done} messages, {stats.seconds:.1f} s"
            decile = int(stats.seconds // 5)  # unknown total: a line every 5 s
        if self.tty:
            now = time.monotonic()
            if now - self._last_write >= 0.2 or (stats.total and done >= stats.total):
                self.stream.write("\r" + text)
                self.stream.flush()
                self._last_write = now
        elif decile != self._last_decile:
            self._last_decile = decile
            self.stream.write(text + "\n")
            self.stream.flush()

    def end(self) -> None:
        if self.enabled and self.tty:
            self.stream.write("\n")
            self.stream.flush()


class StepProgress:
    """``progress(done, total)`` for counted steps (images, views): ``label: done/total``
    rewritten in place on a terminal; in a pipe or a log one line per tenth and the last,
    each on its own line (issue 35 item 5: they ran together on one line)."""

    def __init__(self, label: str, stream=None):
        self.label = label
        self.stream = stream or sys.stderr
        self.tty = self.stream.isatty()
        self._last_tenth = -1

    def __call__(self, done: float, total: float) -> None:
        done_i, total_i = int(done), int(total)
        finished = done_i >= total_i
        text = f"{self.label}: {done_i}/{total_i}"
        if self.tty:
            self.stream.write("\r" + text + ("\n" if finished else ""))
        else:
            tenth = 10 if finished else int(10 * done_i / max(total_i, 1))
            if tenth == self._last_tenth:
                return
            self._last_tenth = tenth
            self.stream.write(text + "\n")
        self.stream.flush()

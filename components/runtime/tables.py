"""Text tables whose columns line up, whatever the labels (rich renders them).

Every table humanpt prints (experiments, benches, the demo's report) goes through
:func:`render`, so a long row label never pushes its numbers out from under their header.
The output is plain text (no colour, no box characters, never wrapped: the console is as
wide as the table), so it reads the same on a terminal, in a pipe and in ``table.txt``.
"""

from __future__ import annotations

import io
import math
from collections.abc import Sequence

from rich.console import Console
from rich.table import Table

__all__ = ["render", "number"]


def number(value: float, digits: int = 4) -> str:
    """A float with ``digits`` decimals; ``-`` for NaN or infinity (not a measurement)."""
    return f"{value:.{digits}f}" if math.isfinite(value) else "-"


def render(header: Sequence[str], rows: Sequence[Sequence[object]], *, align: str | None = None,
           title: str | None = None, rule: bool = True, gap: int = 2) -> str:
    """``rows`` under ``header`` as aligned text.

    ``align``: one letter per column, ``l`` (left) or ``r`` (right); by default the first
    column is left-aligned and the others right-aligned (a label, then numbers).  A cell
    that is not a string is formatted with ``str``.  A row may be empty (``()``): it prints
    as a blank line that separates groups.  ``rule``: a line of dashes under the header.
    ``gap``: spaces between columns.  Returns the text without a trailing newline.
    """
    n = len(header)
    align = align or ("l" + "r" * (n - 1))
    if len(align) != n or set(align) - {"l", "r"}:
        raise ValueError(f"align must be {n} letters of l/r, got {align!r}")
    table = Table(box=None, show_edge=False, pad_edge=False,
                  padding=(0, gap // 2, 0, gap - gap // 2), title=title, title_justify="left",
                  show_header=True, header_style="", title_style="")
    for name, a in zip(header, align, strict=True):
        table.add_column(str(name), justify="left" if a == "l" else "right", no_wrap=True)
    for row in rows:
        if len(row) == 0:
            table.add_row(*([""] * n))
            continue
        if len(row) != n:
            raise ValueError(f"a row has {len(row)} cells, the header {n}: {row!r}")
        table.add_row(*(c if isinstance(c, str) else str(c) for c in row))
    console = Console(file=io.StringIO(), width=100_000, color_system=None, force_terminal=False,
                      legacy_windows=False, emoji=False, highlight=False, markup=False)
    # Measure first so the console is exactly as wide as the table (no padding to 100 000).
    width = console.measure(table).maximum
    console = Console(file=io.StringIO(), width=max(width, 1), color_system=None, force_terminal=False,
                      emoji=False, highlight=False, markup=False)
    console.print(table)
    lines = [ln.rstrip() for ln in console.file.getvalue().splitlines()]
    while lines and not lines[0]:
        lines.pop(0)
    if rule:  # dashes, not box characters: the text stays ASCII wherever it is written
        at = 1 + (title is not None)
        lines.insert(at, "-" * max(len(ln) for ln in lines))
    return "\n".join(lines).rstrip("\n")

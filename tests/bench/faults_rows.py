"""The table ``humanpt bench faults`` prints, read back; the bench run in this process as the
verb runs it; the checks of issue 29's link rows shared by the ALTER and RSI tests."""

from __future__ import annotations

import os
import re
from dataclasses import dataclass
from pathlib import Path

import pytest

from humanpt.bench.faults import FaultRow, format_table, run_faults

COLUMNS = ["fault", "verdict", "reaction", "robot held", "recovered", "data lost", "note"]
HELD = re.compile(r"yes \(([\d.]+) / ([\d.]+) mm\)")


def table(stdout: str) -> dict[str, dict[str, str]]:
    """{fault: {column: cell}} of the printed table (cells are separated by 2+ spaces)."""
    lines = stdout.splitlines()
    head = next(i for i, line in enumerate(lines) if line.startswith("fault "))
    assert re.split(r"\s{2,}", lines[head].strip()) == COLUMNS, lines[head]
    rows = {}
    for line in lines[head + 1:]:
        if not line.strip():
            break
        cells = re.split(r"\s{2,}", line.strip())
        assert len(cells) == len(COLUMNS), line
        rows[cells[0]] = dict(zip(COLUMNS, cells, strict=True))
    return rows


def leftovers(run_dir: Path) -> list[str]:
    """Command lines of live processes started for ``run_dir`` (each twin process names its
    config or run directory there)."""
    found = []
    for pid in filter(str.isdigit, os.listdir("/proc")):
        try:
            cmd = Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode()
        except OSError:
            continue
        if str(run_dir) in cmd:
            found.append(f"{pid}: {cmd}")
    return found


@dataclass(frozen=True)
class Bench:
    """One run of the bench, in this process: what ``humanpt bench faults`` would print."""

    rows: list[FaultRow]
    failure: str             # the twin's failure (the verb's exit status 2), "" if none
    table: dict[str, dict[str, str]]  # the printed table, parsed back (table())
    run_dir: Path
    leftovers: list[str]     # twin processes still alive once run_faults returned


def bench_run(run_dir: Path, only: tuple[str, ...] | None, **kw) -> Bench:
    """:func:`run_faults` as the verb calls it, its table as the verb prints it."""
    rows, failure = run_faults(only, run_dir=run_dir, **kw)
    return Bench(rows, failure, table(format_table(rows)), run_dir, leftovers(run_dir))

# issue 29's rows on the robot link (humanpt.bench.link_faults), keyed by --only's names
LINK_ROWS = {
    "kill": "gateway killed mid-motion (40 mm/s)",
    "inject": "<Rob> injection from another UDP port (80)",
    "junk": "junk UDP flood from another port (3 s)",
    "ipoc": "spoofed <Rob>, IPOC +500 cycles",
    "bigseam": "path play of a 1795-point seam",
}


def kill_within_bound(row: dict[str, str], cycle_limit_mm: float) -> None:
    """"robot held": the distance moved after the kill / the bound: 2 cycles at the limit."""
    held = HELD.fullmatch(row["robot held"])
    assert held, row
    assert float(held[2]) == pytest.approx(2 * cycle_limit_mm)
    assert float(held[1]) <= float(held[2]), row
    assert re.search(r"killed at [\d.]+ mm/s", row["note"]), row


def seam_played_or_refused(row: dict[str, str]) -> None:
    note = row["note"]
    assert note.startswith("refused before sending") or re.match(
        r"played \(1795 points, [\d.]+ s\): done; \d+ late/stale-command events", note), row
    assert "FAULT" not in note, row  # the issue: 2 of 3 tries latched the gateway's fault

"""``humanpt bench faults --link ur`` (issue 34 item 5): the UR RTDE link's rows against the
live twin over RTDE (router + seven processes; the simulated UR's RTDE server serving every
client as a UR does, the gateway's client, real TCP on loopback; a CB3's 8 ms), run once in
this process for the file: the gateway killed and frozen mid-motion (the program's watchdog
the last guard: the arm within the lead + 2 cycles at the limit), a second RTDE client
writing humanpt's target registers (refused IN_USE, the arm does not follow), junk on the
robot's RTDE port (the controller drops those clients, the gateway's session goes on), the
robot silent for 0.5 s (no fault latched, robot states again), the robot's program stopped
and played again through its Dashboard server (the arm braked, held, the gateway's link down
and up, no jump). Asserted: the verdicts and what each row says, never rates or times."""

from __future__ import annotations

import re

import pytest

from tests.bench.faults_rows import Bench, bench_run

pytestmark = [pytest.mark.live, pytest.mark.cell]  # the bench's twin, routers, TCP sockets

ROWS = {
    "kill": "gateway killed mid-motion (40 mm/s)",
    "rtde2": "second RTDE client writes the target registers",
    "rtdejunk": "junk on the robot's RTDE port (3 s)",
    "freeze": "gateway frozen 0.5 s mid-motion (late answers)",
    "lost": "robot frozen 0.5 s (its data packages lost)",
    "pstop": "robot program stopped, then played (Dashboard)",
}
HELD = re.compile(r"yes \(([\d.]+) / ([\d.]+) mm\)")


@pytest.fixture(scope="module")
def ur_bench(tmp_path_factory) -> Bench:
    """``humanpt bench faults --link ur --only kill,rtde2,rtdejunk,freeze,lost,pstop``, in this process."""
    return bench_run(tmp_path_factory.mktemp("faults-ur") / "run", tuple(ROWS), link="ur")


def _within_lead_and_two_cycles(row: dict[str, str]) -> None:
    """"robot held": moved / bound, the bound 2 cycles at the limit (100 mm/s x 8 ms) + the 5 mm lead."""
    held = HELD.fullmatch(row["robot held"])
    assert held, row
    assert float(held[2]) == pytest.approx(2 * 100.0 * 0.008 + 5.0)
    assert float(held[1]) <= float(held[2]), row


@pytest.mark.timeout(600)  # bounds a hang
def test_ur_link_rows(ur_bench):
    rows = ur_bench.table
    assert list(rows) == list(ROWS.values()), rows
    assert ur_bench.leftovers == []
    checks = {
        "kill": lambda: _within_lead_and_two_cycles(rows[ROWS["kill"]]),
        "rtde2": lambda: _assert(rows[ROWS["rtde2"]]["note"].startswith("refused (IN_USE)")
                                 and "the arm did not follow; the gateway's session went on" in rows[ROWS["rtde2"]]["note"]),
        "rtdejunk": lambda: _assert("the gateway's session went on" in rows[ROWS["rtdejunk"]]["note"]
                                    and "STOPPED" not in rows[ROWS["rtdejunk"]]["note"]
                                    and re.search(r"the controller: [1-9]\d* bad_rtde", rows[ROWS["rtdejunk"]]["note"])),
        "freeze": lambda: (_within_lead_and_two_cycles(rows[ROWS["freeze"]]),
                           _assert("the program's watchdog stopped the arm" in rows[ROWS["freeze"]]["note"])),
        "lost": lambda: _assert(rows[ROWS["lost"]]["note"].startswith("robot states again; no fault latched")),
        "pstop": lambda: _program_stopped_and_played(rows[ROWS["pstop"]]),
    }
    failed = []
    for key, check in checks.items():
        try:
            check()
            assert rows[ROWS[key]]["verdict"] == "ok"
        except AssertionError:
            failed.append(f"{key}: {rows[ROWS[key]]}")
    assert not failed, "\n".join(failed)
    assert ur_bench.failure == ""


def _assert(ok) -> None:
    assert ok


def _program_stopped_and_played(row: dict[str, str]) -> None:
    """Stop and Play on the robot's Dashboard: UR's answers, the arm braked and held still, the
    gateway's link_down and link_up, after Play at most one cycle at the limit (100 mm/s x 8 ms)
    a cycle."""
    held = HELD.fullmatch(row["robot held"])
    assert held and float(held[2]) == pytest.approx(100.0 * 0.008), row
    assert float(held[1]) <= float(held[2]), row
    note = row["note"]
    assert note.startswith("Dashboard: 'Stopped', 'STOPPED humanpt_ur.urp', 'Starting program'"), row
    assert "the gateway: link_down (program stopped), link_up after Play;" in note, row
    braked = re.search(r"braked ([\d.]+) mm from ([\d.]+) mm/s \(bound v\^2/2a \+ v dt = ([\d.]+) mm\), then "
                       r"([\d.]+) mm in", note)
    assert braked, row
    v = float(braked[2])
    assert float(braked[3]) == pytest.approx(v * v / 2000.0 + v * 0.008, abs=0.01)  # 1 m/s^2, one cycle at v
    assert float(braked[1]) <= float(braked[3]) and float(braked[4]) <= 0.001, row


def test_the_ur_rows_are_skipped_over_another_link_and_start_no_twin(tmp_path, cli_main, capsys):
    assert cli_main(["bench", "faults", "--only", "rtde2,rtdejunk,freeze,lost,pstop", "--run-dir",
                     str(tmp_path / "run")]) == 0
    out = capsys.readouterr().out
    assert out.count("not over ALTER (--link ur)") == 5
    assert not (tmp_path / "run" / "humanpt.toml").exists()

"""The UR link's staleness bound is time (``stale_ms``, default 24 ms), not cycles: at the
e-Series' 2 ms that is 12 cycles (3 cycles, 6 ms, before: too strict on a loaded machine), at
the CB3's 8 ms 3 as before. Both ways: a command up to the bound late still moves the arm, one
later is dropped; and when the controller really stops, the gateway runs the arm on for the
bound only, then holds it (the arm comes to rest, the program's watchdog never needed). A bad
value is one line naming the field. The gateway and the simulated UR in memory (the real
codec both ends)."""

from __future__ import annotations

import numpy as np
import pytest

from humanpt.robot_gateway.links import gateway_config
from humanpt.robot_gateway.links.ur.config import STALE_MS
from tests.conftest import run_cli_here
from tests.robot_gateway import rig as rigmod
from tests.ur.test_ur_link import SimUr

MS = 1_000_000
CYCLE_MS = 2.0  # the e-Series'


def _rig(robot=None, **kw) -> rigmod.Rig:
    cfg = gateway_config("ur", cycle_period_ms=CYCLE_MS, **kw)
    if robot is None:
        return rigmod.Rig(cfg)
    saved = rigmod.ROBOTS["ur"]
    rigmod.ROBOTS["ur"] = robot
    try:
        return rigmod.Rig(cfg)
    finally:
        rigmod.ROBOTS["ur"] = saved


def test_the_bound_is_24_ms_whatever_the_cycle():
    assert STALE_MS == 24.0
    assert gateway_config("ur", cycle_period_ms=2.0).stale_cycles == 12
    assert gateway_config("ur", cycle_period_ms=8.0).stale_cycles == 3  # the CB3's 3 cycles, as before
    assert gateway_config("ur", cycle_period_ms=2.0, stale_ms=7.0).stale_cycles == 3  # whole cycles within it
    # stale_cycles given (as on every link; humanpt param may only lower it) is the bound.
    assert gateway_config("ur", cycle_period_ms=2.0, stale_cycles=2).stale_cycles == 2


# 11 cycles (22 ms) late: it answers the next cycle, k + 12, 24 ms after its own; 13 (26 ms): dropped.
@pytest.mark.parametrize("late_cycles, used", [(11, True), (13, False)])
def test_a_command_up_to_the_bound_late_still_moves_the_arm_one_later_is_dropped(late_cycles, used):
    rig = _rig()
    rig.cycle_with_command(dp_mm=(0.1, 0.0, 0.0))
    k = rig.cycle + 1
    for _ in range(late_cycles + 1):  # the robot's cycles k .. k + late_cycles, no command
        rig.status()
        rig.advance(round(CYCLE_MS * MS), tick_ns=MS // 2)
    outs = rig.command(cycle=k, dp_mm=(0.0, 0.1, 0.0))  # the answer to cycle k, late_cycles x 2 ms late
    assert ("late_command" in rig.codes(outs)) is not used
    assert rig.gw.counters["late_commands"] == (0 if used else 1)
    rig.status()
    rig.advance(round(CYCLE_MS * MS), tick_ns=MS // 2)
    last = rig.gw.sent[-1]
    if used:  # (the freshest command within the bound answers the next cycle)
        assert (last.source, last.command_cycle) == ("reused", k)
    else:
        assert last.source == "stale"


def test_the_old_3_cycle_bound_drops_a_command_20_ms_late():
    """What the bound was (stale_cycles 3 at 2 ms = 6 ms): the same 10-cycle-late answer dropped."""
    rig = _rig(stale_ms=6.0)
    rig.cycle_with_command(dp_mm=(0.1, 0.0, 0.0))
    k = rig.cycle + 1
    for _ in range(11):
        rig.status()
        rig.advance(round(CYCLE_MS * MS), tick_ns=MS // 2)
    assert "late_command" in rig.codes(rig.command(cycle=k, dp_mm=(0.0, 0.1, 0.0)))


def test_when_the_controller_stops_the_arm_runs_on_for_the_bound_then_comes_to_rest():
    rig = _rig(SimUr, tick_ms=0.5)
    sim = rig.robot.sim
    start = sim.base_T_flange_mm[:3, 3].copy()
    cycle_ns, tick_ns = round(CYCLE_MS * MS), MS // 2
    for _ in range(20):
        rig.cycle_with_command(dp_mm=(0.1, 0.0, 0.0))
    # (cycle_with_command advances with the rig's 2 ms tick: the same cycle)
    for _ in range(100):  # the controller falls silent; the robot's cycles go on (200 ms)
        rig.status()
        rig.advance(cycle_ns, tick_ns=tick_ns)
    sources = [s.source for s in rig.gw.sent]
    first = sources.index("fresh")
    assert sources[first:first + 20] == ["fresh"] * 20
    assert sources[first + 20:first + 32] == ["reused"] * 12  # 24 ms of the last step (velocity hold)
    assert set(sources[first + 32:]) == {"stale"}  # then holds, every cycle
    assert "stale_command" in rig.codes()
    # The target went 32 x 0.1 mm (under the 5 mm lead) and the arm came to rest on it: the
    # bound stopped it, with the gateway still answering (the program's watchdog never tripped).
    moved = sim.base_T_flange_mm[:3, 3] - start
    np.testing.assert_allclose(moved, (3.2, 0.0, 0.0), atol=1e-3)
    recent = np.array([T[:3, 3] for _, T in list(sim.trace)[-20:]])
    assert float(np.ptp(recent, axis=0).max()) < 1e-3  # (a first-order lag: within a micrometre)
    assert sim.counters["watchdog_stops"] == 0 and not sim.stopped


@pytest.mark.parametrize("value, says", [
    ("60.0", "stale_ms = 60 is longer than the robot program's watchdog (watchdog_cycles x cycle_period_ms = 50 ms)"),
    ("-2", "stale_ms: -2.0 is outside its range [0, 2000] ms"),
    ('"abc"', "stale_ms: expected a number, got 'abc'"),
])
def test_a_bad_bound_is_one_line_naming_the_field(tmp_path, value, says):
    cfg = tmp_path / "cell.toml"
    cfg.write_text(f'[robot_gateway]\nlink = "ur"\nstale_ms = {value}\n')
    r = run_cli_here("config", "--check", "--config", str(cfg))
    assert r.returncode == 2 and r.stdout == ""
    assert r.stderr.strip().count("\n") == 0 and says in r.stderr and "[robot_gateway]" in r.stderr, r.stderr

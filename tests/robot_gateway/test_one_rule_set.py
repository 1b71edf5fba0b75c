"""One implementation of the safety rules: the same fault sequence through the gateway over
every registered link (``links.LINKS``; a test's own third link too:
tests/robot_gateway/test_third_link.py) gives the same decisions (what is sent, why, from
which command), the same events, and the same steps; the expected steps are worked out by
hand."""

from __future__ import annotations

import numpy as np
import pytest

from humanpt.robot_gateway.links import LINKS
from humanpt.schemas import humanpt_pb2 as pb
from tests.robot_gateway.rig import MS, START_X, Rig

CYCLE_MS = 12.0  # every link at RSI's 12 ms cycle: the same per-cycle limits
# 100 mm/s x 12 ms = 1.2 mm per cycle; the box's +x face 0.8 mm beyond the start.
COMMON = dict(cycle_period_ms=CYCLE_MS, reply_deadline_ms=2.0, tick_ms=2.0, stale_cycles=3,
              fault_after_missed=10, status_timeout_cycles=3, max_speed_mm_s=100.0,
              envelope_max_mm=(float(START_X[0]) + 0.8, 1600.0, 1600.0))
# robot_late_limit 0: a robot that applies zero when late (HOLDON off), as ALTER's does;
# with HOLDON's repeats the envelope cuts earlier (tests/rsi/test_rsi_holdon.py).
# ABB EGM and UR RTDE: a target lead under one step (1.2 mm), so that no lead is added to the envelope's
# margin (links/abb/kind.py late_repeats).
FIELDS = {"rsi": dict(robot_late_limit=0), "abb": dict(max_lead_mm=1.0), "ur": dict(max_lead_mm=1.0)}


def _sequence(rig) -> None:
    cycle_ns = round(CYCLE_MS * MS)

    def cycle(**cmd):
        rig.status()
        if cmd:
            rig.command(**cmd)
        rig.advance(cycle_ns)

    for _ in range(3):
        cycle(dp_mm=(0.5, 0.0, 0.0))  # 1-3: within the limits
    cycle(dp_mm=(3.0, 4.0, 0.0))  # 4: 5 mm, beyond 1.2 mm: clamped
    for _ in range(4):
        cycle()  # 5-7: the last command reused; 8: stale -> zero
    for _ in range(2):
        cycle(dp_mm=(0.0, 0.5, 0.0), rv_deg=(0.0, 0.0, 0.2))  # 9-10: commands again
    rig.liveliness(False)
    for _ in range(2):
        cycle(dp_mm=(0.5, 0.0, 0.0))  # 11-12: the controller's token gone: hold
    rig.liveliness(True)
    cycle(dp_mm=(1.0, 0.0, 0.0))  # 13: would leave the box: cut at its face
    cycle(dp_mm=(0.5, 0.0, 0.0), mode=pb.CONTROL_MODE_HOLD)  # 14: HOLD mode


def run_rule_set(link: str) -> Rig:
    """The fault sequence through a gateway over ``link`` (its robot side from rig.ROBOTS)."""
    rig = Rig(link=link, **COMMON, **FIELDS.get(link, {}))
    _sequence(rig)
    return rig


EXPECTED_SOURCES = (["fresh"] * 4 + ["reused"] * 3 + ["stale"] + ["fresh"] * 2 + ["gone"] * 2
                    + ["fresh", "hold"])


@pytest.fixture(scope="module")
def alter():
    return run_rule_set("alter")


@pytest.fixture(scope="module")
def rsi():
    return run_rule_set("rsi")


def assert_the_rule_set(rig, alter: Rig) -> None:
    """``rig``'s gateway made the decisions, events and steps worked out by hand, and the
    same as over ALTER (the reference: the link's own start-up events aside)."""
    decisions = [(s.cycle, s.source, s.command_cycle) for s in rig.gw.sent]
    assert [d[1] for d in decisions] == EXPECTED_SOURCES
    assert [d[0] for d in decisions] == list(range(1, 15))
    assert decisions == [(s.cycle, s.source, s.command_cycle) for s in alter.gw.sent]
    codes = [c for c in rig.codes() if c != "link_up"]
    assert codes == [c for c in alter.codes() if c != "link_up"]
    assert {"clamped", "stale_command", "command_resumed", "controller_gone", "controller_back",
            "envelope"} <= set(codes)
    for a, r in zip(alter.gw.sent, rig.gw.sent, strict=True):
        assert (a.step is None) == (r.step is None)
        if a.step is not None:
            np.testing.assert_array_equal(a.step[0], r.step[0])
            np.testing.assert_array_equal(a.step[1], r.step[1])
    steps = {s.cycle: s.step for s in rig.gw.sent}
    # 5 mm along (0.6, 0.8) clamped by norm to 1.2 mm; reused as such for cycles 5-7.
    for k in (4, 5, 6, 7):
        np.testing.assert_allclose(steps[k][0], [0.72, 0.96, 0.0], atol=1e-12)
    # The flange (reported at the start) may go 0.8 mm further in +x.
    np.testing.assert_allclose(steps[13][0], [0.8, 0.0, 0.0], atol=1e-9)
    np.testing.assert_allclose(steps[9][1], [0.0, 0.0, np.radians(0.2)], atol=1e-15)
    assert all(steps[k] is None for k in (8, 11, 12, 14))  # stale, gone, gone, HOLD


@pytest.mark.parametrize("link", sorted(LINKS))
def test_every_registered_link_passes_the_same_rule_set(link, alter):
    assert_the_rule_set(alter if link == "alter" else run_rule_set(link), alter)


def test_both_wires_carry_those_steps_to_their_resolution(alter, rsi):
    by_cycle = dict(rsi.corrections)
    for cycle, c in alter.corrections:
        r = by_cycle[cycle]
        np.testing.assert_allclose(r.translation_mm, c.translation_mm, atol=0.005 + 1e-4)
    assert by_cycle[4].rkorr[:3] == (0.72, 0.96, 0.0)
    assert by_cycle[8].rkorr == (0.0,) * 6 and by_cycle[11].rkorr == (0.0,) * 6  # holds
    # RSI's A (about Z) carries the 0.2 deg rotation about the base's z.
    assert by_cycle[9].rkorr[3:] == (0.2, 0.0, 0.0)

"""Issue 29 item 8: crafted datagrams against the RSI parser. Each is refused with one line
(RsiProtocolError), entity-bearing ones before the XML parser sees them (no expansion: the
UTF-16 billion laughs cost ~150-220 ms of expat per 1.5 kB datagram), and the gateway
reports them as a rate-limited, counted ``link_error``, never a traceback; live, an
entity-bearing <Rob> from the robot's own address publishes no robot state."""

from __future__ import annotations

import logging
import socket
import threading

import pytest

from humanpt.robot_gateway.core import GatewayCore
from humanpt.robot_gateway.links.rsi.config import RsiConfig
from humanpt.robot_gateway.links.rsi.protocol import (
    RsiProtocolError,
    check_bytes,
    decode_rob,
    decode_sen,
)
from humanpt.robot_gateway.links.rsi.shell import UdpAdapter
from humanpt.runtime.config import RuntimeConfig
from humanpt.runtime.live import LiveShell
from humanpt.testing.rsi_attacks import CRAFTED, rob
from tests.conftest import wait_for
from tests.robot_gateway.rig import Rig

# Refused by the byte check alone, before any XML parsing (what could expand or decode otherwise).
BEFORE_PARSING = ("superscript_ipoc", "arabic_indic_ipoc", "char_reference_ipoc", "entity_rob_ascii",
                  "entity_rob_utf16", "entity_rob_utf16le", "billion_laughs_utf16",
                  "encoding_declared_utf16_ascii_bytes", "nul_byte", "latin1_byte", "processing_instruction",
                  "comment", "too_long")


@pytest.mark.parametrize("name", sorted(CRAFTED))
def test_each_crafted_datagram_is_refused_with_one_line(name):
    data = CRAFTED[name]
    with pytest.raises(RsiProtocolError) as e:
        decode_rob(data)
    assert "\n" not in str(e.value) and len(str(e.value)) < 200, str(e.value)
    if name in BEFORE_PARSING:
        with pytest.raises(RsiProtocolError):
            check_bytes(data)  # nothing reached expat: no entity expanded, the cost bounded by the length
    # The robot side (the simulated controller's parser of <Sen>) refuses the same bytes.
    with pytest.raises(RsiProtocolError):
        decode_sen(data.replace(b"<Rob", b"<Sen").replace(b"</Rob>", b"</Sen>"))


def test_what_the_issue_saw_each_in_its_words():
    with pytest.raises(RsiProtocolError, match="printable ASCII only"):
        decode_rob(CRAFTED["superscript_ipoc"])  # "²".isdigit() is True; int("²") raised ValueError
    with pytest.raises(RsiProtocolError, match="byte 0xff at offset 0"):
        decode_rob(CRAFTED["entity_rob_utf16"])  # was accepted: IPOC 7 from the entity
    with pytest.raises(RsiProtocolError, match="encoding 'UTF-16' declared"):
        decode_rob(CRAFTED["encoding_declared_utf16_ascii_bytes"])


@pytest.mark.parametrize("decl", [b'<?xml version="1.0"?>', b'<?xml version="1.0" encoding="UTF-8"?>',
                                  b"<?xml version='1.0' encoding='us-ascii' standalone='yes'?>\n"])
def test_an_ascii_or_utf8_declaration_is_still_an_rsi_message(decl):
    assert decode_rob(decl + rob(42)).ipoc == 42


def test_the_gateway_reports_crafted_datagrams_rate_limited_with_a_count_and_answers_none():
    rig = Rig(link="rsi", cycle_period_ms=12.0)  # event_interval_ms 1000: one link_error a second per code
    rig.status()
    n_states, n_answers = len(rig.states()), len(rig.corrections)
    outs = []
    for _ in range(5):
        for data in CRAFTED.values():
            outs += rig.from_robot(data)  # all at the same instant: raises nothing
    n = 5 * len(CRAFTED)
    assert rig.gw.link.counters["malformed"] == n and rig.gw.counters["link_errors"] == n
    assert rig.codes(outs) == ["link_error"]  # one report for the burst
    assert (len(rig.states()), len(rig.corrections)) == (n_states, n_answers)  # no state, no answer
    rig.advance(1_100_000_000)
    outs = rig.from_robot(CRAFTED["superscript_ipoc"])
    [ev] = rig.events(outs)
    assert f"(+{n - 1} more since the last report)" in ev.text and f"({n + 1} malformed so far)" in ev.text
    rig.status()
    assert len(rig.states()) == n_states + 1  # the robot's next datagram is served as ever


def test_live_an_entity_bearing_rob_from_the_robots_address_publishes_no_state(router, caplog):
    """The gateway in the live shell with its UDP adapter; this test is the robot (one real
    socket): a valid <Rob> locks the adapter onto it, then the crafted datagrams from the same
    socket, then a valid one. Only the valid ones are answered and become robot states; the
    log has no traceback."""
    port, _ = router
    core = GatewayCore(RsiConfig(udp_bind="127.0.0.1:0", cycle_period_ms=12.0))
    adapter = UdpAdapter("127.0.0.1:0")
    adapter.open()
    shell = LiveShell(core, RuntimeConfig(cell="test", connect=(f"tcp/127.0.0.1:{port}",), listen=(), record=False),
                      adapters=[adapter])
    worker = threading.Thread(target=shell.run, daemon=True)
    caplog.set_level(logging.WARNING)
    worker.start()
    robot = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    robot.bind(("127.0.0.1", 0))
    robot.settimeout(10.0)
    try:
        assert shell.ready.wait(10)
        robot.sendto(rob(1_000_008), adapter.address)
        assert b"<IPOC>1000008</IPOC>" in robot.recvfrom(65536)[0]  # answered: locked onto this socket
        for data in CRAFTED.values():
            robot.sendto(data, adapter.address)
        robot.sendto(rob(1_000_020), adapter.address)  # the next cycle at 12 ms
        assert b"<IPOC>1000020</IPOC>" in robot.recvfrom(65536)[0]  # the next answer is to it
        wait_for(lambda: core.link.counters["datagrams"] == 2 + len(CRAFTED), 10.0, "every datagram handled")
    finally:
        shell.stop.set()
        worker.join(5)
        robot.close()
    assert core.counters["statuses"] == 2 and core.link.counters["malformed"] == len(CRAFTED)
    assert adapter.datagrams_out == 2
    assert not [r for r in caplog.records if r.exc_info], "a traceback was logged"

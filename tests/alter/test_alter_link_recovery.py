"""The DDCMP link never stays dead (issue 14, item 5).

The attack: one forged STRT frame on the line put one end into start-up while the other kept
running; the running end answered the start-up end's STACKs with ACK(R != 0), which start-up
ignores, and no corrections flowed until a STRT came the other way. Here two pure ends talk
over an in-memory line with a 1 ms delay; the robot end sends one data message per 28 ms
cycle and the host answers each (as the gateway answers each STATUS). After any injected
control frames, a clean line must bring both ends back to RUNNING and data flowing.
"""

from __future__ import annotations

import heapq

from hypothesis import given, settings
from hypothesis import strategies as st

from humanpt.robot_gateway.links.alter.ddcmp import (
    NakReason,
    ack,
    encode_frame,
    nak,
    rep,
    stack,
    strt,
)
from humanpt.robot_gateway.links.alter.ddcmp_link import DdcmpLink, LinkConfig, LinkState
from humanpt.robot_gateway.links.alter.events import DataReceived, LinkDown, LinkUp, Transmit
from tests.alter.alter_testkit import CYCLE_NS, MS

LINE_DELAY_NS = 1 * MS
TICK_NS = 2 * MS


class Line:
    """Two ends, a delayed line between them, a robot that sends every cycle and a host
    that answers every data message it receives."""

    def __init__(self):
        self.robot, self.host = DdcmpLink(LinkConfig()), DdcmpLink(LinkConfig())
        self.t_ns = 0
        self._queue: list[tuple[int, int, str, bytes]] = []  # (due, order, to, bytes)
        self._order = 0
        self.delivered = {"robot": 0, "host": 0}
        self.events: list[tuple[int, str, object]] = []
        self._act("robot", self.robot.start(0))
        self._act("host", self.host.start(0))

    def end(self, name: str) -> DdcmpLink:
        return self.robot if name == "robot" else self.host

    def _act(self, name: str, events) -> None:
        other = "host" if name == "robot" else "robot"
        for e in events:
            self.events.append((self.t_ns, name, e))
            if isinstance(e, Transmit):
                self.put(other, e.data)
            elif isinstance(e, DataReceived):
                self.delivered[name] += 1
                if name == "host" and self.host.can_send:  # the gateway's answer
                    self._act("host", self.host.send(b"correction", self.t_ns))

    def put(self, to: str, data: bytes) -> None:
        heapq.heappush(self._queue, (self.t_ns + LINE_DELAY_NS, self._order, to, data))
        self._order += 1

    def run(self, duration_ns: int) -> None:
        end = self.t_ns + duration_ns
        next_cycle = (self.t_ns // CYCLE_NS + 1) * CYCLE_NS
        while self.t_ns < end:
            self.t_ns += TICK_NS
            while self._queue and self._queue[0][0] <= self.t_ns:
                _, _, to, data = heapq.heappop(self._queue)
                self._act(to, self.end(to).receive(data, self.t_ns))
            for name in ("robot", "host"):
                self._act(name, self.end(name).poll(self.t_ns))
            if self.t_ns >= next_cycle:
                next_cycle += CYCLE_NS
                if self.robot.can_send:
                    self._act("robot", self.robot.send(b"status", self.t_ns))

    def flowing(self, duration_ns: int = 10 * CYCLE_NS) -> bool:
        """Both ends running and data delivered both ways over the next ``duration_ns``."""
        before = dict(self.delivered)
        self.run(duration_ns)
        return (self.robot.is_running and self.host.is_running
                and self.delivered["host"] > before["host"] and self.delivered["robot"] > before["robot"])


def _exchanging() -> Line:
    line = Line()
    line.run(20 * CYCLE_NS)
    assert line.robot.is_running and line.host.is_running
    assert line.delivered["host"] >= 15 and line.delivered["robot"] >= 15
    return line


def test_a_forged_strt_to_the_robot_does_not_deadlock_the_link():
    line = _exchanging()
    line.put("robot", encode_frame(strt()))
    line.run(TICK_NS)
    assert line.robot.state is LinkState.ASTRT  # the robot went into start-up
    # One start-up retry (100 ms) and a handshake later, data flows again.
    assert line.flowing(300 * MS)
    downs = [(who, e.reason) for _, who, e in line.events if isinstance(e, LinkDown)]
    assert ("host", "peer in start-up (STACK while running)") in downs
    assert any(isinstance(e, LinkUp) and who == "host" for _, who, e in line.events[-200:])


def test_a_forged_strt_to_the_host_does_not_deadlock_the_link():
    line = _exchanging()
    line.put("host", encode_frame(strt()))
    assert line.flowing(300 * MS)


def test_an_end_in_start_up_that_only_gets_wrong_acks_starts_over():
    """ASTRT: STACKs answered only by ACK(R != 0) -> after max_reps retries, STRT again."""
    link = DdcmpLink(LinkConfig())
    link.start(0)
    link.receive(encode_frame(strt()), 1 * MS)  # the peer's STRT: we go ASTRT, send STACK
    assert link.state is LinkState.ASTRT
    t = 1 * MS
    sent = []
    for _ in range(LinkConfig().max_reps + 2):
        t += LinkConfig().start_timeout_ns
        link.receive(encode_frame(ack(7)), t)
        sent += [e.data for e in link.poll(t) if isinstance(e, Transmit)]
    assert link.state is LinkState.ISTRT
    assert encode_frame(strt()) in sent


CONTROL = st.sampled_from(["strt", "stack", "ack", "nak", "rep"])


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(st.sampled_from(["robot", "host"]), CONTROL, st.integers(0, 255),
                          st.integers(0, 60)), min_size=1, max_size=6))
def test_after_any_forged_control_frames_a_clean_line_recovers(forged):
    line = _exchanging()
    make = {"strt": lambda n: strt(), "stack": lambda n: stack(), "ack": ack,
            "nak": lambda n: nak(n, NakReason.HEADER_CRC), "rep": rep}
    for to, kind, num, gap_ms in forged:
        line.put(to, encode_frame(make[kind](num)))
        line.run(gap_ms * MS + TICK_NS)
    # The clean line: within a few start-up retries both ends run and data flows both ways.
    assert line.flowing(1500 * MS), [(t, w, e) for t, w, e in line.events[-30:]]

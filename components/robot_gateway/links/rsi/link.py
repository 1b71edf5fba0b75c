"""The gateway's Link over KUKA RSI-style UDP/XML (pure: datagrams and times are given).

Cycle numbers: a ``<Rob>``'s IPOC (ms) divided by the cycle time (4 or 12 ms), modulo
2^32, so that a lost datagram is a gap of one cycle and the gateway's rules (missed
cycles, lost statuses, command-ahead by cycle number) apply unchanged.

Sequence (issue 29): a datagram whose IPOC is the last one + one cycle continues the session
and is answered; the same IPOC again (UDP may duplicate) is dropped. Anything else is *out of
sequence* (back: a replay, a reordering, a late duplicate, a restart at the robot; ahead by
more than a cycle: datagrams lost, a spoof; off the cycle's grid): dropped without an answer
and without counting cycles, and kept as a candidate. The next datagram decides: if it
continues the session, the candidate is forgotten (nothing else happened); if it continues
the candidate (candidate + one cycle), the candidate was real: a gap of at most
``MAX_GAP_CYCLES`` ahead on the session's grid is lost cycles of the same session (the
gateway counts them), anything else (back, further ahead, off the grid) a new RSI session
(``LinkUp``, the gateway starts over). So one datagram, whatever its IPOC, is never lost
cycles nor a restart by itself. ``<Delay>`` growing between two datagrams of a session
means the robot judged the previous answer late: ``correction_missed``.
"""

from __future__ import annotations

from collections import OrderedDict

import numpy as np

from humanpt.robot_gateway.link import CycleReceived, CycleState, LinkError, LinkUp, Transmit
from humanpt.robot_gateway.links.rsi.config import RsiConfig
from humanpt.robot_gateway.links.rsi.protocol import (
    RsiCorrection,
    RsiProtocolError,
    decode_rob,
    encode_sen,
    rsi_correction,
)

# A confirmed jump ahead by at most this many cycles (on the session's grid) is lost cycles
# of the session; further (or back, or off the grid) it is a new session. More than the
# gateway's silence watchdog (status_timeout_cycles, 25) is a link_down and a restart anyway.
MAX_GAP_CYCLES = 25
_CYCLE_MOD = 1 << 32


class RsiLink:
    name = "RSI"
    rx_topic = "udp_rx"
    tx_topic = "udp_tx"
    up_text = "RSI link up (a <Rob> datagram from the robot)"

    def __init__(self, cycle_period_ms: float, correction_frame: str = "base", sen_type: str = "ImFree"):
        self.cycle_ms = int(cycle_period_ms)
        self.tool_mode = correction_frame == "tool"
        self.sen_type = sen_type
        self._running = False
        self._last_ipoc: int | None = None
        self._last_delay: int | None = None
        self._candidate: int | None = None  # an out-of-sequence IPOC awaiting the next datagram
        self._ipocs: OrderedDict[int, int] = OrderedDict()  # cycle -> IPOC, the last few
        self.counters = dict.fromkeys(("datagrams", "malformed", "sessions", "duplicates", "out_of_sequence",
                                       "out_of_sequence_dropped", "confirmed"), 0)

    @classmethod
    def from_config(cls, config: RsiConfig) -> RsiLink:
        return cls(config.cycle_period_ms, config.correction_frame, config.sen_type)

    @property
    def is_running(self) -> bool:
        return self._running

    def start(self, t_ns: int) -> list:
        """(Re)start: wait for the robot's next datagram (RSI has no handshake)."""
        self._running = False
        self._last_ipoc = self._last_delay = self._candidate = None
        self._ipocs.clear()
        return []

    def poll(self, t_ns: int) -> list:
        return []

    def receive(self, data: bytes, t_ns: int) -> list:
        self.counters["datagrams"] += 1
        try:
            rob = decode_rob(data)
        except RsiProtocolError as e:
            self.counters["malformed"] += 1
            return [LinkError(f"RSI link: {e}; datagram dropped, no answer for it "
                              f"({self.counters['malformed']} malformed so far)")]
        if not self._running:
            return self._accept(rob, new_session=True)  # the first datagram of a session
        last = self._last_ipoc
        assert last is not None
        if rob.ipoc == last:
            self.counters["duplicates"] += 1  # UDP may deliver a datagram twice: answered once
            return []
        candidate, self._candidate = self._candidate, None
        if rob.ipoc - last == self.cycle_ms:
            if candidate is not None:
                self.counters["out_of_sequence_dropped"] += 1  # the session went on: it was nothing
            return self._accept(rob)
        if candidate is not None and rob.ipoc - candidate == self.cycle_ms:
            # The candidate is confirmed: a gap of the same session, or a new one.
            self.counters["confirmed"] += 1
            cycles, off_grid = divmod(candidate - last, self.cycle_ms)
            return self._accept(rob, new_session=bool(off_grid) or not 1 < cycles <= MAX_GAP_CYCLES)
        if candidate is not None and rob.ipoc == candidate:
            self._candidate = candidate
            self.counters["duplicates"] += 1
            return []
        self._candidate = rob.ipoc
        self.counters["out_of_sequence"] += 1
        where = "back" if rob.ipoc < last else "ahead"
        return [LinkError(
            f"RSI link: IPOC {rob.ipoc} out of sequence ({abs(rob.ipoc - last)} ms {where} of the last, {last}; "
            f"the cycle is {self.cycle_ms} ms): dropped, no answer; it counts only if the next datagram "
            f"continues it ({self.counters['out_of_sequence']} so far)")]

    def _accept(self, rob, new_session: bool = False) -> list:
        """``rob`` is the session's next datagram (the first of a new one if ``new_session``)."""
        events: list = []
        if new_session:
            self._running = True
            self._last_delay = None
            self._candidate = None
            self._ipocs.clear()
            self.counters["sessions"] += 1
            events.append(LinkUp())
        missed = self._last_delay is not None and rob.delay > self._last_delay
        self._last_ipoc, self._last_delay = rob.ipoc, rob.delay
        cycle = (rob.ipoc // self.cycle_ms) % _CYCLE_MOD
        self._ipocs[cycle] = rob.ipoc
        if len(self._ipocs) > 8:
            self._ipocs.popitem(last=False)
        events.append(CycleReceived(CycleState(
            cycle=cycle,
            base_T_flange_mm=rob.base_T_flange_mm(),
            corrections_on=True,
            tool_mode=self.tool_mode,
            cumulative=True,  # RKorr is relative: it adds to the path
            arm_power=True,
            fault=False,
            correction_missed=missed,
        )))
        return events

    def _ipoc(self, cycle: int) -> int:
        return self._ipocs.get(cycle, cycle * self.cycle_ms)

    def correction(self, cycle: int, dp_mm: np.ndarray, rv_rad: np.ndarray,
                   max_step_mm: float, max_step_deg: float) -> RsiCorrection:
        return rsi_correction(self._ipoc(cycle), dp_mm, rv_rad, max_step_mm, max_step_deg)

    def hold(self, cycle: int, corrections_off: bool) -> RsiCorrection:
        # RSI has no "correction mode off" in the answer: a hold is RKorr zero (the
        # operator stops RSI at the robot; the gateway's latched fault keeps holding).
        return RsiCorrection.hold(self._ipoc(cycle))

    def send(self, correction: RsiCorrection, t_ns: int) -> list:
        return [Transmit(encode_sen(correction, self.sen_type))]

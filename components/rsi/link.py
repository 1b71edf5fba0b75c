"""The gateway's Link over KUKA RSI-style UDP/XML (pure: datagrams and times are given).

Cycle numbers: a ``<Rob>``'s IPOC (ms) divided by the cycle time (4 or 12 ms), modulo
2^32, so that a lost datagram is a gap of one cycle and the gateway's rules (missed
cycles, lost statuses, command-ahead by cycle number) apply unchanged. An IPOC that goes
back or jumps more than ``MAX_IPOC_JUMP_CYCLES`` ahead is a new RSI session (RSI_ON again
at the robot): ``LinkUp``, the gateway starts over; the same IPOC twice (a duplicated
datagram) is dropped. ``<Delay>`` growing between two
datagrams means the robot judged the previous answer late: ``correction_missed``.
"""

from __future__ import annotations

from collections import OrderedDict

import numpy as np

from humanpt.alter import LinkUp, Transmit
from humanpt.robot_gateway.link import CycleReceived, CycleState, LinkError
from humanpt.rsi.protocol import (
    RsiCorrection,
    RsiProtocolError,
    decode_rob,
    encode_sen,
    rsi_correction,
)

MAX_IPOC_JUMP_CYCLES = 1000
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
        self._ipocs: OrderedDict[int, int] = OrderedDict()  # cycle -> IPOC, the last few
        self.counters = {"datagrams": 0, "malformed": 0, "sessions": 0, "duplicates": 0}

    @property
    def is_running(self) -> bool:
        return self._running

    def start(self, t_ns: int) -> list:
        """(Re)start: wait for the robot's next datagram (RSI has no handshake)."""
        self._running = False
        self._last_ipoc = self._last_delay = None
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
            return [LinkError(f"RSI link: {e}; datagram dropped (no answer for it)")]
        events: list = []
        last = self._last_ipoc
        if self._running and rob.ipoc == last:
            self.counters["duplicates"] += 1  # UDP may deliver a datagram twice: answered once
            return events
        jump = None if last is None else (rob.ipoc - last) // self.cycle_ms
        if not self._running or jump is None or jump <= 0 or jump > MAX_IPOC_JUMP_CYCLES:
            # First datagram, or a new RSI session (IPOC back or far ahead).
            self._running = True
            self._last_delay = None
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

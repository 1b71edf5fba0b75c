"""The gateway's ALTER link: the codec's HostEndpoint (DDCMP frames over a serial line,
STATUS in, CORRECTION out) behind the gateway's :class:`~humanpt.robot_gateway.link.Link`."""

from __future__ import annotations

import numpy as np

from humanpt.robot_gateway.link import CycleReceived, CycleState, LinkError
from humanpt.robot_gateway.links.alter.config import AlterConfig
from humanpt.robot_gateway.links.alter.ddcmp import FrameError
from humanpt.robot_gateway.links.alter.ddcmp_link import LinkConfig
from humanpt.robot_gateway.links.alter.endpoint import HostConfig, HostEndpoint
from humanpt.robot_gateway.links.alter.events import MessageRejected, StatusReceived
from humanpt.robot_gateway.links.alter.messages import (
    ControllerStatus,
    Correction,
    CorrectionFlags,
    StatusBits,
)
from humanpt.robot_gateway.links.alter.quantize import quantize

# Status bits as plain ints (IntFlag arithmetic is slow on this hot path).
_ALTER_ACTIVE, _TOOL_MODE, _CUMULATIVE, _ARM_POWER, _FAULT, _MISSED = (
    int(StatusBits.ALTER_ACTIVE),
    int(StatusBits.TOOL_MODE),
    int(StatusBits.CUMULATIVE),
    int(StatusBits.ARM_POWER),
    int(StatusBits.FAULT),
    int(StatusBits.CORRECTION_MISSED),
)


def cycle_state(status: ControllerStatus) -> CycleState:
    """An ALTER STATUS as the gateway's CycleState (pose from the status' fixed point)."""
    b = int(status.bits)
    return CycleState(
        cycle=status.cycle,
        base_T_flange_mm=status.base_T_flange_mm(),
        corrections_on=bool(b & _ALTER_ACTIVE),
        tool_mode=bool(b & _TOOL_MODE),
        cumulative=bool(b & _CUMULATIVE),
        arm_power=bool(b & _ARM_POWER),
        fault=bool(b & _FAULT),
        correction_missed=bool(b & _MISSED),
    )


class AlterLink:
    """The gateway's Link over the ALTER codec's HostEndpoint (DDCMP over a serial line)."""

    name = "ALTER"
    rx_topic = "serial_rx"
    tx_topic = "serial_tx"
    up_text = "ALTER link up (DDCMP start-up done)"

    def __init__(self, cycle_period_ns: int):
        self.host = HostEndpoint(HostConfig(LinkConfig(rep_timeout_ns=3 * cycle_period_ns)))

    @classmethod
    def from_config(cls, config: AlterConfig) -> AlterLink:
        return cls(config.cycle_period_ns)

    @property
    def is_running(self) -> bool:
        return self.host.link.is_running

    @staticmethod
    def _events(events: list) -> list:
        out = []
        for e in events:
            if isinstance(e, StatusReceived):
                out.append(CycleReceived(cycle_state(e.status)))
            elif isinstance(e, FrameError | MessageRejected):
                out.append(LinkError(f"ALTER link: {e}"))
            else:
                out.append(e)
        return out

    def start(self, t_ns: int) -> list:
        return self._events(self.host.start(t_ns))

    def receive(self, data: bytes, t_ns: int) -> list:
        return self._events(self.host.receive(data, t_ns))

    def poll(self, t_ns: int) -> list:
        return self._events(self.host.poll(t_ns))

    def shift_time(self, step_ns: int) -> None:
        """The gateway's clock stepped (runtime/clock.py): DDCMP's timers keep the time left."""
        self.host.shift_time(step_ns)

    def correction(self, cycle: int, dp_mm: np.ndarray, rv_rad: np.ndarray,
                   max_step_mm: float, max_step_deg: float) -> Correction:
        return quantize(cycle, dp_mm, rv_rad, max_step_mm, max_step_deg)

    def hold(self, cycle: int, corrections_off: bool) -> Correction:
        return Correction.hold(cycle, CorrectionFlags.ALTER_OFF if corrections_off else CorrectionFlags(0))

    def send(self, correction: Correction, t_ns: int) -> list:
        return self._events(self.host.send_correction(correction, t_ns))

"""alter_gateway core (pure) over the ALTER link: the host end of the Puma's ALTER serial
line (humanpt.alter: DDCMP frames, STATUS / CORRECTION) under the gateway's safety rules
(humanpt.alter_gateway.gateway.GatewayCore: the rules are there, one implementation for
every link).

Per controller cycle k (the controller sends STATUS k every ``cycle_period_ms``): STATUS k
(``serial_rx``) becomes a CycleState (the status' fixed-point pose and bits); the answer is
a CORRECTION echoing k (quantised to 0.01 mm, 0.01 deg within the limits), or HOLD (with
ALTER_OFF on a latched fault if ``alter_off_on_fault``, or when the command asks ALTER
off). The DDCMP link's events (start-up, link down, frame errors) become the gateway's
``link_up``/``link_down``/``link_error`` events.
"""

from __future__ import annotations

import numpy as np

from humanpt.alter import (
    ControllerStatus,
    Correction,
    CorrectionFlags,
    FrameError,
    HostConfig,
    HostEndpoint,
    LinkConfig,
    MessageRejected,
    StatusBits,
    StatusReceived,
)
from humanpt.alter_gateway.config import AlterGatewayConfig
from humanpt.alter_gateway.gateway import (  # noqa: F401  (re-exported: tests, benches)
    EVENTS,
    MAX_LEAD_CYCLES,
    MAX_SEQ_GAP,
    ROBOT_STATE,
    WATCH,
    Command,
    CycleReceived,
    CycleState,
    GatewayCore,
    LinkError,
    Sent,
    cycles_after,
    gateway_ports,
)
from humanpt.alter_gateway.safety import quantize

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
    """The gateway's Link over humanpt.alter's HostEndpoint (DDCMP over a serial line)."""

    name = "ALTER"
    rx_topic = "serial_rx"
    tx_topic = "serial_tx"
    up_text = "ALTER link up (DDCMP start-up done)"

    def __init__(self, cycle_period_ns: int):
        self.host = HostEndpoint(HostConfig(LinkConfig(rep_timeout_ns=3 * cycle_period_ns)))

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

    def correction(self, cycle: int, dp_mm: np.ndarray, rv_rad: np.ndarray,
                   max_step_mm: float, max_step_deg: float) -> Correction:
        return quantize(cycle, dp_mm, rv_rad, max_step_mm, max_step_deg)

    def hold(self, cycle: int, corrections_off: bool) -> Correction:
        return Correction.hold(cycle, CorrectionFlags.ALTER_OFF if corrections_off else CorrectionFlags(0))

    def send(self, correction: Correction, t_ns: int) -> list:
        return self._events(self.host.send_correction(correction, t_ns))


class AlterGatewayCore(GatewayCore):
    name = "alter_gateway"
    config_type = AlterGatewayConfig
    ports = gateway_ports(AlterLink.rx_topic)
    watch = WATCH

    def tick_period_ns(self) -> int | None:
        return self.config.tick_period_ns

    def make_link(self, config: AlterGatewayConfig) -> AlterLink:
        return AlterLink(config.cycle_period_ns)

    @property
    def _host(self) -> HostEndpoint:  # (tests and benches reach the endpoint by this name)
        return self.link.host

"""Serial byte budget of one ALTER cycle.

Async 8N1 costs 10 bit times per byte (start + 8 data + stop). The line is full duplex,
so each direction has its own budget of ``baud * cycle / 10`` bytes. Worst steady-state
traffic per cycle and direction is one data frame plus one stand-alone ACK (with
piggybacking, the ACK usually rides in the data frame's RESP and costs nothing).
"""

from __future__ import annotations

from dataclasses import dataclass

from humanpt.robot_gateway.links.alter.ddcmp import CONTROL_FRAME_BYTES, data_frame_bytes
from humanpt.robot_gateway.links.alter.ddcmp_link import ALTER_CYCLE_NS
from humanpt.robot_gateway.links.alter.messages import (
    CORRECTION_PAYLOAD_BYTES,
    STATUS_PAYLOAD_BYTES,
)

BITS_PER_BYTE_8N1 = 10
DEFAULT_BAUD = 38_400
SUPPORTED_BAUDS = (19_200, 38_400)
NS_PER_S = 1_000_000_000


def bytes_per_cycle(
    baud: int, cycle_period_ns: int = ALTER_CYCLE_NS, bits_per_byte: int = BITS_PER_BYTE_8N1
) -> int:
    """Whole bytes one direction of the line carries in one cycle (floor)."""
    if baud <= 0 or cycle_period_ns <= 0 or bits_per_byte <= 0:
        raise ValueError("baud, cycle_period_ns and bits_per_byte must be > 0")
    return baud * cycle_period_ns // (bits_per_byte * NS_PER_S)


def byte_time_ns(n_bytes: int, baud: int, bits_per_byte: int = BITS_PER_BYTE_8N1) -> int:
    """Time on the wire of ``n_bytes`` (ns, rounded up)."""
    return -(-n_bytes * bits_per_byte * NS_PER_S // baud)


STATUS_FRAME_BYTES = data_frame_bytes(STATUS_PAYLOAD_BYTES)  # 41
CORRECTION_FRAME_BYTES = data_frame_bytes(CORRECTION_PAYLOAD_BYTES)  # 29
ACK_FRAME_BYTES = CONTROL_FRAME_BYTES  # 8


@dataclass(frozen=True)
class CycleBudget:
    """One cycle's traffic against the line capacity at ``baud``.

    controller_to_host_bytes: STATUS frame + ACK of the host's correction.
    host_to_controller_bytes: CORRECTION frame + ACK of the status.
    turnaround_ns: STATUS then CORRECTION back to back on the wire (host compute
        excluded): the shortest time from the controller starting to send cycle k's
        status to it holding the correction for cycle k.
    """

    baud: int
    cycle_period_ns: int
    budget_bytes: int
    controller_to_host_bytes: int
    host_to_controller_bytes: int
    turnaround_ns: int

    @property
    def fits(self) -> bool:
        """Both directions' traffic fits one cycle (full duplex)."""
        return (
            max(self.controller_to_host_bytes, self.host_to_controller_bytes) <= self.budget_bytes
        )

    @property
    def same_cycle_reply(self) -> bool:
        """Can the correction for cycle k arrive within cycle k? (else: one cycle later)"""
        return self.turnaround_ns < self.cycle_period_ns

    @property
    def host_slack_ns(self) -> int:
        """Time left in the cycle for the host to compute, if it answers in the same cycle."""
        return self.cycle_period_ns - self.turnaround_ns


def cycle_budget(baud: int = DEFAULT_BAUD, cycle_period_ns: int = ALTER_CYCLE_NS) -> CycleBudget:
    return CycleBudget(
        baud=baud,
        cycle_period_ns=cycle_period_ns,
        budget_bytes=bytes_per_cycle(baud, cycle_period_ns),
        controller_to_host_bytes=STATUS_FRAME_BYTES + ACK_FRAME_BYTES,
        host_to_controller_bytes=CORRECTION_FRAME_BYTES + ACK_FRAME_BYTES,
        turnaround_ns=byte_time_ns(STATUS_FRAME_BYTES + CORRECTION_FRAME_BYTES, baud),
    )

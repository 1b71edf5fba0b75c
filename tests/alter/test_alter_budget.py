"""One cycle's traffic against the serial line's byte budget."""

from __future__ import annotations

import pytest

from humanpt.robot_gateway.links.alter import (
    ALTER_CYCLE_NS,
    ControllerEndpoint,
    HostEndpoint,
    bytes_per_cycle,
    cycle_budget,
)
from humanpt.robot_gateway.links.alter.budget import (
    ACK_FRAME_BYTES,
    CORRECTION_FRAME_BYTES,
    STATUS_FRAME_BYTES,
    byte_time_ns,
)
from tests.alter.alter_testkit import CYCLE_NS, correction_for, handshake, status_for, tx_bytes


def test_bytes_per_cycle():
    assert ALTER_CYCLE_NS == 28_000_000
    assert bytes_per_cycle(19_200) == 53  # 53.76 bytes
    assert bytes_per_cycle(38_400) == 107  # 107.52 bytes
    assert bytes_per_cycle(38_400, 4_000_000) == 15
    assert byte_time_ns(1, 38_400) == 260_417  # 10 bits at 38 400 baud, rounded up
    with pytest.raises(ValueError):
        bytes_per_cycle(0)


def measured_cycle_traffic() -> tuple[int, int]:
    """Bytes each end really puts on the line in one steady-state cycle."""
    host, ctrl = HostEndpoint(), ControllerEndpoint()
    handshake(host, ctrl)
    to_host_total = to_ctrl_total = 0
    for k in (1, 2, 3):
        t = k * CYCLE_NS
        to_host = tx_bytes(ctrl.send_status(status_for(k), t))
        to_ctrl = [b for c in to_host for b in tx_bytes(host.receive(c, t))]
        to_ctrl += tx_bytes(host.send_correction(correction_for(k), t))
        back = [b for c in to_ctrl for b in tx_bytes(ctrl.receive(c, t))]
        assert all(not tx_bytes(host.receive(b, t)) for b in back)
        to_host += back
        if k == 3:  # steady state
            to_host_total = sum(map(len, to_host))
            to_ctrl_total = sum(map(len, to_ctrl))
    return to_host_total, to_ctrl_total


@pytest.mark.parametrize("baud", [19_200, 38_400])
def test_one_cycle_of_traffic_fits_both_directions(baud):
    budget = cycle_budget(baud)
    to_host, to_ctrl = measured_cycle_traffic()
    # The model matches what the codec really sends (data frame + stand-alone ACK each way).
    assert to_host == budget.controller_to_host_bytes == STATUS_FRAME_BYTES + ACK_FRAME_BYTES == 49
    assert (
        to_ctrl == budget.host_to_controller_bytes == CORRECTION_FRAME_BYTES + ACK_FRAME_BYTES == 37
    )
    assert budget.fits
    assert max(to_host, to_ctrl) <= bytes_per_cycle(baud)


def test_same_cycle_reply_needs_38400():
    """STATUS (41 B) then CORRECTION (29 B) back to back: 70 bytes of turnaround."""
    slow, fast = cycle_budget(19_200), cycle_budget(38_400)
    assert not slow.same_cycle_reply  # 36.5 ms > 28 ms: the reply lands a cycle late
    assert fast.same_cycle_reply
    assert fast.turnaround_ns == byte_time_ns(70, 38_400)
    assert 9_000_000 < fast.host_slack_ns < 10_000_000  # ~9.8 ms for the host to answer
    # A recovery cycle from the controller (REP, the resent status, this cycle's status,
    # an ACK) still fits at 38 400, not at 19 200.
    recovery = ACK_FRAME_BYTES + 2 * STATUS_FRAME_BYTES + ACK_FRAME_BYTES
    assert recovery <= fast.budget_bytes and recovery > slow.budget_bytes

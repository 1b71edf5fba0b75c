"""Host and controller endpoints: a clean session, and the controller's validation."""

from __future__ import annotations

import pytest

from humanpt.robot_gateway.links.alter import (
    ControllerConfig,
    ControllerEndpoint,
    Correction,
    CorrectionFlags,
    CorrectionReceived,
    HostEndpoint,
    MessageRejected,
    SendRejected,
    StatusReceived,
)
from humanpt.robot_gateway.links.alter.ddcmp import DataFrame, encode_frame
from humanpt.robot_gateway.links.alter.messages import encode_correction, encode_status
from tests.alter.alter_testkit import (
    CYCLE_NS,
    correction_for,
    handshake,
    non_tx,
    record_clean_session,
    replay_controller,
    status_for,
    tx_bytes,
)


def connected(config: ControllerConfig | None = None) -> tuple[HostEndpoint, ControllerEndpoint]:
    host, ctrl = HostEndpoint(), ControllerEndpoint(config)
    handshake(host, ctrl)
    assert host.link.is_running and ctrl.link.is_running
    return host, ctrl


def exchange_cycle(host, ctrl, cycle, correction=None):
    """Controller sends status ``cycle``; host answers ``correction``; returns the
    controller's application events (CorrectionReceived, MessageRejected)."""
    t = cycle * CYCLE_NS
    host_events = [
        e for c in tx_bytes(ctrl.send_status(status_for(cycle), t)) for e in host.receive(c, t)
    ]
    assert StatusReceived(status_for(cycle)) in host_events
    corr = correction if correction is not None else correction_for(cycle)
    ctrl_events = []
    for chunk in tx_bytes(host_events) + tx_bytes(host.send_correction(corr, t)):
        ev = ctrl.receive(chunk, t)
        ctrl_events += [e for e in ev if isinstance(e, CorrectionReceived | MessageRejected)]
        for back in tx_bytes(ev):
            host.receive(back, t)
    return ctrl_events


def test_clean_session_delivers_every_correction_fresh():
    host, ctrl = connected()
    for k in range(1, 40):
        events = exchange_cycle(host, ctrl, k)
        assert events == [CorrectionReceived(correction_for(k), 0)]
    assert host.link.unacked_count == 0 and host.last_status_cycle == 39


def test_recorded_script_replays_exactly():
    script = record_clean_session(20)
    got = []
    replay_controller(
        script,
        script.slots,
        script.start_slot,
        lambda k, ev: got.append(ev) if isinstance(ev, CorrectionReceived) else None,
    )
    assert [e.correction for e in got] == [script.corrections[k] for k in range(1, 21)]


def test_correction_for_unknown_or_old_cycle_is_rejected():
    host, ctrl = connected(ControllerConfig(max_correction_age_cycles=1))
    for k in (1, 2, 3):
        t = k * CYCLE_NS
        for c in tx_bytes(ctrl.send_status(status_for(k), t)):
            host.receive(c, t)

    def feed(correction):
        out = []
        for c in tx_bytes(host.send_correction(correction, 0)):
            out += non_tx(ctrl.receive(c, 0))
        return [e for e in out if isinstance(e, CorrectionReceived | MessageRejected)]

    [r] = feed(correction_for(99))  # never issued
    assert isinstance(r, MessageRejected) and "not a recent cycle" in r.why
    [r] = feed(correction_for(1))  # issued, but 2 cycles old with max age 1
    assert isinstance(r, MessageRejected)
    assert feed(correction_for(2)) == [CorrectionReceived(correction_for(2), 1)]
    [r] = feed(correction_for(2))  # same cycle again: never applied twice
    assert isinstance(r, MessageRejected) and "not newer" in r.why
    assert feed(correction_for(3)) == [CorrectionReceived(correction_for(3), 0)]


def test_controller_limits_reject_big_steps():
    host, ctrl = connected(ControllerConfig(max_translation_10um=280, max_rotation_cdeg=168))
    big = Correction(1, CorrectionFlags(0), 281, 0, 0, 0, 0, 0)
    [r] = exchange_cycle(host, ctrl, 1, big)
    assert isinstance(r, MessageRejected) and "exceeds" in r.why
    spin = Correction(2, CorrectionFlags(0), 0, 0, 0, 0, -169, 0)
    [r] = exchange_cycle(host, ctrl, 2, spin)
    assert isinstance(r, MessageRejected)
    ok = Correction(3, CorrectionFlags(0), 280, -280, 0, 168, -168, 0)
    assert exchange_cycle(host, ctrl, 3, ok) == [CorrectionReceived(ok, 0)]


def test_wrong_message_type_is_rejected_both_ways():
    host, ctrl = connected()
    ctrl.send_status(status_for(1), 0)
    # A STATUS payload sent to the controller, a CORRECTION to the host.
    wire = encode_frame(DataFrame(1, 0, bytes([0x53]) + bytes(30)))
    [r] = [e for e in ctrl.receive(wire, 0) if isinstance(e, MessageRejected)]
    assert "not a CORRECTION" in r.why
    wire = encode_frame(DataFrame(1, 1, encode_correction(correction_for(1))))
    [r] = [e for e in host.receive(wire, 0) if isinstance(e, MessageRejected)]
    assert "not a STATUS" in r.why


def test_host_rejects_status_that_does_not_advance_and_resets_on_restart():
    host, ctrl = connected()
    exchange_cycle(host, ctrl, 5)
    t = 6 * CYCLE_NS
    # A controller bug (or a stale replay) repeating cycle 5 in a new data message:
    repeat = tx_bytes(ctrl.link.send(encode_status(status_for(5)), t))
    [r] = [e for c in repeat for e in host.receive(c, t) if isinstance(e, MessageRejected)]
    assert "not after 5" in r.why
    # After a restart the controller may count from 1 again.
    host2, ctrl2 = HostEndpoint(), ControllerEndpoint()
    handshake(host2, ctrl2)
    exchange_cycle(host2, ctrl2, 1)
    assert host2.last_status_cycle == 1


def test_status_cycles_must_increase_and_count_when_link_down():
    ctrl = ControllerEndpoint()
    assert ctrl.send_status(status_for(1), 0) == [SendRejected("link not running")]
    assert ctrl.last_issued_cycle == 1
    with pytest.raises(ValueError, match="must come after"):
        ctrl.send_status(status_for(1), 0)


def test_config_validation():
    with pytest.raises(ValueError):
        ControllerConfig(max_correction_age_cycles=-1)
    with pytest.raises(ValueError):
        ControllerConfig(max_translation_10um=-5)

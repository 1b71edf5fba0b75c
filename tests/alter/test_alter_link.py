"""DdcmpLink state machine: start-up, acks, NAK/REP recovery, discards, timeouts."""

from __future__ import annotations

import random

import pytest

from humanpt.robot_gateway.links.alter import (
    Acknowledged,
    DataFrame,
    DataReceived,
    DdcmpDecoder,
    DdcmpLink,
    Discarded,
    FrameError,
    FrameErrorReason,
    LinkConfig,
    LinkDown,
    LinkState,
    LinkUp,
    NakReason,
    NakReceived,
    RepSent,
    SendRejected,
    encode_frame,
)
from humanpt.robot_gateway.links.alter.ddcmp import ControlType, ack, rep, strt
from tests.alter.alter_testkit import MS, handshake, tx_bytes


def frames_of(events) -> list:
    decoder = DdcmpDecoder()
    return [f for chunk in tx_bytes(events) for f in decoder.feed(chunk)]


def running_pair(**cfg) -> tuple[DdcmpLink, DdcmpLink]:
    a, b = DdcmpLink(LinkConfig(**cfg)), DdcmpLink(LinkConfig(**cfg))
    a_ev, b_ev = handshake(a, b)
    assert a.is_running and b.is_running
    assert a_ev.count(LinkUp()) == 1 and b_ev.count(LinkUp()) == 1
    return a, b


def test_start_up_sends_strt_and_retries_on_timer():
    link = DdcmpLink()
    out = frames_of(link.start(0))
    assert [f.kind for f in out] == [ControlType.STRT]
    assert link.state is LinkState.ISTRT
    assert link.poll(50 * MS) == []
    assert link.next_deadline_ns == 100 * MS
    assert [f.kind for f in frames_of(link.poll(100 * MS))] == [ControlType.STRT]
    assert link.send(b"x", 0) == [SendRejected("link not running")]


def test_one_sided_start_strt_stack_ack():
    a, b = DdcmpLink(), DdcmpLink()
    b.start(0)
    a_strt = tx_bytes(a.start(0))
    out = b.receive(a_strt[0], 1)  # b in ISTRT gets STRT: answers STACK
    assert [f.kind for f in frames_of(out)] == [ControlType.STACK] and b.state is LinkState.ASTRT
    out = a.receive(tx_bytes(out)[0], 2)  # a in ISTRT gets STACK: ACK(0), running
    assert LinkUp() in out and [f for f in frames_of(out)] == [ack(0)]
    out = b.receive(tx_bytes(out)[0], 3)
    assert out == [LinkUp()] and b.is_running


def test_data_with_resp_zero_completes_start_up():
    a, b = DdcmpLink(), DdcmpLink()
    b.start(0)
    b.receive(tx_bytes(a.start(0))[0], 0)  # b -> ASTRT
    frame = encode_frame(DataFrame(1, 0, b"hello"))
    out = b.receive(frame, 1)
    assert LinkUp() in out and DataReceived(1, b"hello") in out


def test_data_flows_acked_and_sequence_wraps():
    a, b = running_pair(window=4)
    for i in range(300):
        payload = i.to_bytes(2, "little")
        out = a.send(payload, i)
        [frame] = frames_of(out)
        assert frame.num == (i + 1) % 256
        got = b.receive(tx_bytes(out)[0], i)
        assert DataReceived((i + 1) % 256, payload) in got
        [ack_frame] = frames_of(got)
        assert ack_frame == ack((i + 1) % 256)
        acked = a.receive(tx_bytes(got)[0], i)
        assert acked == [Acknowledged((i + 1) % 256, 1)]
    assert a.unacked_count == 0 and a.next_deadline_ns is None


def test_piggybacked_ack_with_ack_delay():
    a, b = running_pair(ack_delay_ns=5 * MS)
    got = b.receive(tx_bytes(a.send(b"one", 0))[0], 1 * MS)
    assert tx_bytes(got) == []  # ACK held back
    assert b.next_deadline_ns == 6 * MS
    [reply] = frames_of(b.send(b"two", 2 * MS))
    assert reply.resp == 1  # rides on the data frame
    assert b.poll(10 * MS) == []  # nothing owed any more
    # Without data to ride on, poll sends the ACK when due.
    b.receive(tx_bytes(a.send(b"three", 20 * MS))[0], 20 * MS)
    assert frames_of(b.poll(24 * MS)) == []
    assert frames_of(b.poll(25 * MS)) == [ack(2)]


def test_window_full_rejects():
    a, _ = running_pair(window=2)
    assert tx_bytes(a.send(b"1", 0)) and tx_bytes(a.send(b"2", 0))
    assert not a.can_send
    assert a.send(b"3", 0) == [SendRejected("window full")]
    with pytest.raises(ValueError):
        a.send(b"", 0)


def test_duplicate_and_out_of_order_are_discarded_not_delivered():
    a, b = running_pair()
    f1 = tx_bytes(a.send(b"m1", 0))[0]
    f2 = tx_bytes(a.send(b"m2", 0))[0]
    f3 = tx_bytes(a.send(b"m3", 0))[0]
    out = b.receive(f2, 1)  # 2 before 1
    assert Discarded("out_of_order", 2) in out and not any(isinstance(e, DataReceived) for e in out)
    assert DataReceived(1, b"m1") in b.receive(f1, 2)
    out = b.receive(f1, 3)  # again
    assert Discarded("duplicate", 1) in out and not any(isinstance(e, DataReceived) for e in out)
    assert frames_of(out) == [ack(1)]  # re-acknowledged so the sender stops resending
    assert Discarded("out_of_order", 3) in b.receive(f3, 4)
    assert b.last_received_num == 1


def test_data_crc_error_naks_once_and_sender_resends():
    a, b = running_pair()
    f1 = bytearray(tx_bytes(a.send(b"payload-1", 0))[0])
    f2 = tx_bytes(a.send(b"payload-2", 0))[0]
    f1[10] ^= 0x04
    out = b.receive(bytes(f1) + f2, 1)
    errors = [e for e in out if isinstance(e, FrameError)]
    assert errors and errors[0].reason is FrameErrorReason.DATA_CRC
    assert Discarded("out_of_order", 2) in out
    naks = [f for f in frames_of(out) if f.kind is ControlType.NAK]
    assert len(naks) == 1 and naks[0].rcvr == 0 and naks[0].nak_reason is NakReason.DATA_CRC
    resent = a.receive(tx_bytes(out)[0], 2)
    assert NakReceived(int(NakReason.DATA_CRC), 0, 2) in resent
    assert [f.num for f in frames_of(resent)] == [1, 2]
    got = b.receive(tx_bytes(resent)[0], 3)
    assert [e for e in got if isinstance(e, DataReceived)] == [
        DataReceived(1, b"payload-1"),
        DataReceived(2, b"payload-2"),
    ]


def test_lost_message_recovered_by_rep():
    a, b = running_pair(rep_timeout_ns=10 * MS)
    a.send(b"lost", 0)  # never delivered
    assert a.next_deadline_ns == 10 * MS
    out = a.poll(10 * MS)
    assert RepSent(1, 1) in out and frames_of(out) == [rep(1)]
    answer = b.receive(tx_bytes(out)[0], 11 * MS)
    [n] = frames_of(answer)
    assert n.kind is ControlType.NAK and n.nak_reason is NakReason.REP_RESPONSE and n.rcvr == 0
    resent = a.receive(tx_bytes(answer)[0], 12 * MS)
    assert DataReceived(1, b"lost") in b.receive(tx_bytes(resent)[0], 13 * MS)


def test_rep_when_all_received_gets_ack():
    a, b = running_pair(rep_timeout_ns=10 * MS)
    b.receive(tx_bytes(a.send(b"x", 0))[0], 1)  # b's ACK is lost
    answer = b.receive(tx_bytes(a.poll(10 * MS))[0], 11 * MS)
    assert frames_of(answer) == [ack(1)]
    assert a.receive(tx_bytes(answer)[0], 12 * MS) == [Acknowledged(1, 1)]


def test_link_down_after_max_reps_then_restarts():
    a, _ = running_pair(rep_timeout_ns=10 * MS, max_reps=2)
    a.send(b"x", 0)
    reps = [e for t in (10, 20) for e in a.poll(t * MS) if isinstance(e, RepSent)]
    assert [r.consecutive for r in reps] == [1, 2]
    out = a.poll(30 * MS)
    assert LinkDown("no answer to REP", 1) in out
    assert [f.kind for f in frames_of(out)] == [ControlType.STRT]
    assert a.state is LinkState.ISTRT and a.unacked_count == 0


def test_peer_restart_is_link_down_and_new_start_up():
    a, b = running_pair()
    a.send(b"x", 0)
    out = a.receive(encode_frame(strt()), 1)
    assert LinkDown("peer restarted (STRT)", 1) in out
    assert [f.kind for f in frames_of(out)] == [ControlType.STACK]
    assert a.state is LinkState.ASTRT and a.last_sent_num == 0


def test_wrong_address_and_halted_are_ignored():
    a, b = running_pair()
    other = encode_frame(DataFrame(1, 0, b"x", addr=7))
    assert b.receive(other, 0) == [Discarded("wrong_address", 1)]
    halted = DdcmpLink()
    assert halted.receive(encode_frame(DataFrame(1, 0, b"x")), 0) == [Discarded("not_running", 1)]
    assert halted.receive(encode_frame(rep(3)), 0) == []
    assert b.stop() == [LinkDown("stopped", 0)] and b.state is LinkState.HALTED


def test_bogus_resp_is_ignored():
    a, b = running_pair()
    a.send(b"x", 0)
    assert a.receive(encode_frame(ack(5)), 0) == []  # 5 was never sent
    assert a.unacked_count == 1


def test_config_validation():
    with pytest.raises(ValueError, match="window"):
        LinkConfig(window=128)
    with pytest.raises(ValueError, match="ack_delay"):
        LinkConfig(ack_delay_ns=100 * MS, rep_timeout_ns=50 * MS)
    with pytest.raises(ValueError):
        LinkConfig(max_reps=0)
    with pytest.raises(ValueError):
        LinkConfig(address=300)


def test_noisy_line_delivers_everything_once_in_order():
    """Both directions corrupt, drop and split bytes (seeded); retransmission recovers."""
    rng = random.Random(1234)
    cfg = {"rep_timeout_ns": 30 * MS, "max_reps": 50, "window": 4}
    a, b = running_pair(**cfg)

    def noisy(chunks: list[bytes]) -> list[bytes]:
        out = []
        for chunk in chunks:
            r = rng.random()
            if r < 0.1:
                continue  # lost
            if r < 0.25:
                ba = bytearray(chunk)
                ba[rng.randrange(len(ba))] ^= 1 << rng.randrange(8)
                chunk = bytes(ba)
            if r > 0.9 and len(chunk) > 1:
                p = rng.randrange(1, len(chunk))
                out += [chunk[:p], chunk[p:]]
            else:
                out.append(chunk)
        return out

    sent = [f"msg-{i}".encode() for i in range(120)]
    delivered, downs, recoveries = [], [], 0
    to_b, to_a, next_i = [], [], 0
    for step in range(4000):
        now = step * MS
        if next_i < len(sent) and a.can_send:
            to_b += tx_bytes(a.send(sent[next_i], now))
            next_i += 1
        ev_a = a.poll(now)
        ev_b = b.poll(now)
        for chunk in noisy(to_b):
            ev_b += b.receive(chunk, now)
        for chunk in noisy(to_a):
            ev_a += a.receive(chunk, now)
        delivered += [e.payload for e in ev_b if isinstance(e, DataReceived)]
        downs += [e for e in ev_a + ev_b if isinstance(e, LinkDown)]
        recoveries += sum(isinstance(e, NakReceived | RepSent) for e in ev_a)
        to_b, to_a = tx_bytes(ev_a), tx_bytes(ev_b)
        if len(delivered) == len(sent) and a.unacked_count == 0:
            break
    assert not downs
    assert delivered == sent
    assert recoveries > 5  # the noise really forced NAK/REP recovery

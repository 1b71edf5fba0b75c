"""Fuzzing the codec: garbage and mutated valid streams never crash it and never yield
a correction that was not sent, twice, out of order, or for a cycle not issued."""

from __future__ import annotations

import random
from functools import cache

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from humanpt.robot_gateway.links.alter import (
    ControllerEndpoint,
    CorrectionReceived,
    DataReceived,
    DdcmpDecoder,
    DdcmpLink,
    FrameError,
    HostEndpoint,
    LinkUp,
    encode_frame,
)
from humanpt.robot_gateway.links.alter.ddcmp import CRC_BYTES, HEADER_BYTES
from tests.alter.alter_testkit import (
    apply_mutations,
    handshake,
    record_clean_session,
    replay_controller,
    reslot,
    status_for,
    tx_bytes,
)

FUZZ = settings(
    max_examples=200,
    deadline=None,
    derandomize=True,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)

unit = st.floats(0, 1, exclude_max=True)
mutation_ops = st.lists(
    st.tuples(
        st.sampled_from(["flip", "truncate", "duplicate", "swap", "garbage", "drop", "splice"]),
        unit,
        unit,
    ),
    min_size=1,
    max_size=12,
)
N_CYCLES = 24


@cache
def clean_script():
    return record_clean_session(N_CYCLES)


@cache
def clean_link_stream() -> tuple[bytes, ...]:
    """Chunks a sender link put on the line: start-up, then 40 numbered messages."""
    sender, receiver = DdcmpLink(), DdcmpLink()
    chunks = list(tx_bytes(sender.start(0)))
    receiver_chunks = tx_bytes(receiver.start(0))
    for _ in range(4):
        replies = [b for c in chunks[-2:] for b in tx_bytes(receiver.receive(c, 0))]
        for c in receiver_chunks + replies:
            chunks += tx_bytes(sender.receive(c, 0))
        receiver_chunks = []
    assert sender.is_running
    for i in range(40):
        out = tx_bytes(sender.send(f"payload-{i:03d}".encode(), i))
        chunks += out
        for c in out:
            for back in tx_bytes(receiver.receive(c, i)):
                sender.receive(back, i)
    return tuple(chunks)


def check_decoded_frames_are_genuine(stream: bytes, max_data_bytes: int = 64) -> None:
    decoder = DdcmpDecoder(max_data_bytes)
    pos = 0
    rng = random.Random(len(stream))
    while pos < len(stream):
        step = rng.randint(1, 17)
        for item in decoder.feed(stream[pos : pos + step]):
            if not isinstance(item, FrameError):
                # Every frame the decoder yields is literally present in the input.
                assert encode_frame(item) in stream
        pos += step
        assert decoder.pending_bytes <= HEADER_BYTES + max_data_bytes + CRC_BYTES


@FUZZ
@given(st.binary(max_size=600))
def test_decoder_survives_random_bytes(data):
    check_decoded_frames_are_genuine(data)


@FUZZ
@given(mutation_ops, st.integers(0, 2**32 - 1))
def test_decoder_on_mutated_streams_only_yields_genuine_frames(ops, seed):
    stream = b"".join(apply_mutations(list(clean_link_stream()), ops, random.Random(seed)))
    check_decoded_frames_are_genuine(stream)


@FUZZ
@given(mutation_ops, st.integers(0, 2**32 - 1))
def test_link_delivers_only_in_sequence(ops, seed):
    """Within one link epoch a fresh receiver delivers payload 0, 1, 2, ... and nothing else."""
    chunks = apply_mutations(list(clean_link_stream()), ops, random.Random(seed))
    receiver = DdcmpLink()
    receiver.start(0)
    epoch: list[int] = []
    for t, chunk in enumerate(chunks):
        for ev in receiver.receive(chunk, t) + receiver.poll(t):
            if isinstance(ev, LinkUp):
                epoch = []
            elif isinstance(ev, DataReceived):
                assert ev.payload.startswith(b"payload-")
                index = int(ev.payload[8:])
                assert index == len(epoch), f"delivered {index} after {epoch}"
                assert ev.num == (index + 1) % 256
                epoch.append(index)


@FUZZ
@given(st.lists(st.binary(min_size=1, max_size=120), max_size=20))
def test_random_bytes_never_yield_a_correction(chunks):
    host, ctrl = HostEndpoint(), ControllerEndpoint()
    handshake(host, ctrl)
    assert ctrl.link.is_running
    for k, chunk in enumerate(chunks, start=1):
        ctrl.send_status(status_for(k), k)
        for ev in ctrl.receive(chunk, k) + ctrl.poll(k * 10**9):
            assert not isinstance(ev, CorrectionReceived)


@FUZZ
@given(mutation_ops, st.integers(0, 2**32 - 1))
def test_mutated_host_stream_never_yields_a_bad_correction(ops, seed):
    script = clean_script()
    rng = random.Random(seed)
    # Mutate the start-up bytes and the cycle traffic as one stream, then put the chunks
    # back on the original schedule (one slot per cycle).
    sizes = [len(script.start_slot)] + [len(s) for s in script.slots]
    flat = script.start_slot + [c for s in script.slots for c in s]
    slots = reslot(apply_mutations(flat, ops, rng), sizes)
    delivered: list[tuple[int, CorrectionReceived]] = []

    def on_event(cycle, ev):
        if isinstance(ev, CorrectionReceived):
            delivered.append((cycle, ev))

    ctrl = replay_controller(script, slots[1:], slots[0], on_event)
    max_age = ctrl.config.max_correction_age_cycles
    echoes = [ev.correction.echo_cycle for _, ev in delivered]
    assert echoes == sorted(set(echoes)), "a correction was applied twice or out of order"
    for cycle, ev in delivered:
        c = ev.correction
        assert c == script.corrections[c.echo_cycle], "a correction nobody sent"
        assert 0 <= cycle - c.echo_cycle <= max_age and ev.age_cycles == cycle - c.echo_cycle


def test_fuzz_baseline_unmutated_stream_delivers_all():
    """Guard for the fuzz test above: with no mutation, every correction arrives."""
    script = clean_script()
    got = []
    replay_controller(
        script,
        script.slots,
        script.start_slot,
        lambda k, ev: (
            got.append(ev.correction.echo_cycle) if isinstance(ev, CorrectionReceived) else None
        ),
    )
    assert got == list(range(1, N_CYCLES + 1))

"""Helpers for the ALTER tests: connect two pure ends in memory, record and mutate streams."""

from __future__ import annotations

import random
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from humanpt.robot_gateway.links.alter import (
    ControllerEndpoint,
    ControllerStatus,
    Correction,
    CorrectionFlags,
    DdcmpLink,
    HostEndpoint,
    StatusBits,
    Transmit,
)
from humanpt.robot_gateway.links.alter.events import Event

CYCLE_NS = 28_000_000
MS = 1_000_000


def tx_bytes(events: list[Event]) -> list[bytes]:
    """The Transmit payloads of an event list, in order."""
    return [e.data for e in events if isinstance(e, Transmit)]


def non_tx(events: list[Event]) -> list[Event]:
    return [e for e in events if not isinstance(e, Transmit)]


Endpoint = DdcmpLink | HostEndpoint | ControllerEndpoint


def handshake(a: Endpoint, b: Endpoint, now_ns: int = 0) -> tuple[list[Event], list[Event]]:
    """Start both ends and exchange bytes until quiet; returns each end's non-Transmit events."""
    a_events, b_events = [], []
    to_b = tx_bytes(a.start(now_ns))
    to_a = tx_bytes(b.start(now_ns))
    for _ in range(10):
        if not to_a and not to_b:
            break
        new_to_a, new_to_b = [], []
        for chunk in to_b:
            ev = b.receive(chunk, now_ns)
            b_events += non_tx(ev)
            new_to_a += tx_bytes(ev)
        for chunk in to_a:
            ev = a.receive(chunk, now_ns)
            a_events += non_tx(ev)
            new_to_b += tx_bytes(ev)
        to_a, to_b = new_to_a, new_to_b
    return a_events, b_events


def status_for(cycle: int) -> ControllerStatus:
    """A deterministic, valid status for ``cycle``."""
    return ControllerStatus(
        cycle,
        StatusBits.ALTER_ACTIVE | StatusBits.ARM_POWER,
        50_000 + cycle,
        -20_000 + 3 * cycle,
        80_000 - cycle,
        (cycle * 7) % 36000 - 18000,
        (cycle * 5) % 18000 - 9000,
        (cycle * 3) % 36000 - 18000,
    )


def correction_for(cycle: int) -> Correction:
    """A deterministic, valid, distinct correction answering ``cycle``."""
    rng = np.random.default_rng(cycle)
    d = rng.integers(-280, 281, size=6)
    return Correction(cycle, CorrectionFlags(0), *(int(v) for v in d))


@dataclass
class ControllerScript:
    """What a controller endpoint was fed in a clean session: per cycle, the cycle's
    ``send_status`` then the host's chunks that arrived in that cycle (slot)."""

    start_slot: list[bytes] = field(default_factory=list)
    slots: list[list[bytes]] = field(default_factory=list)  # slot k-1 belongs to cycle k
    corrections: dict[int, Correction] = field(default_factory=dict)


def record_clean_session(n_cycles: int) -> ControllerScript:
    """Run host and controller in lock step over a clean line; record host->controller chunks."""
    host, ctrl = HostEndpoint(), ControllerEndpoint()
    script = ControllerScript()
    to_host = tx_bytes(ctrl.start(0))
    to_ctrl = tx_bytes(host.start(0))
    # Start-up: everything the host sends before cycle 1 goes in start_slot.
    for _ in range(6):
        script.start_slot += to_ctrl
        new_to_host = [b for c in to_ctrl for b in tx_bytes(ctrl.receive(c, 0))]
        to_ctrl = [b for c in to_host for b in tx_bytes(host.receive(c, 0))]
        to_host = new_to_host
    assert host.link.is_running and ctrl.link.is_running
    for k in range(1, n_cycles + 1):
        t = k * CYCLE_NS
        slot: list[bytes] = []
        to_host = tx_bytes(ctrl.send_status(status_for(k), t))
        for chunk in to_host:
            for ev in host.receive(chunk, t + 11 * MS):
                if isinstance(ev, Transmit):
                    slot.append(ev.data)
                elif type(ev).__name__ == "StatusReceived":
                    corr = correction_for(ev.status.cycle)
                    script.corrections[ev.status.cycle] = corr
                    slot += tx_bytes(host.send_correction(corr, t + 12 * MS))
        for chunk in slot:
            for ack_bytes in tx_bytes(ctrl.receive(chunk, t + 20 * MS)):
                assert not tx_bytes(host.receive(ack_bytes, t + 21 * MS))
        script.slots.append(slot)
    return script


def replay_controller(
    script: ControllerScript, slots: list[list[bytes]], start_slot: list[bytes], on_event: Callable
) -> ControllerEndpoint:
    """Feed a (possibly mutated) host stream to a fresh controller on the same schedule."""
    ctrl = ControllerEndpoint()
    ctrl.start(0)
    for chunk in start_slot:
        for ev in ctrl.receive(chunk, 0):
            on_event(0, ev)
    for k, slot in enumerate(slots, start=1):
        t = k * CYCLE_NS
        for ev in ctrl.send_status(status_for(k), t):
            on_event(k, ev)
        for ev in ctrl.poll(t):
            on_event(k, ev)
        for chunk in slot:
            for ev in ctrl.receive(chunk, t + 20 * MS):
                on_event(k, ev)
    return ctrl


# --- stream mutations --------------------------------------------------------------------


def apply_mutations(chunks: list[bytes], ops: list[tuple], rng: random.Random) -> list[bytes]:
    """Mutate a list of wire chunks. ``ops`` are (name, a, b) with a, b in [0, 1) choosing
    positions; names: flip, truncate, duplicate, swap, garbage, drop, splice."""
    out = list(chunks)
    for name, a, b in ops:
        if not out:
            out.append(rng.randbytes(8))
            continue
        i = int(a * len(out))
        j = int(b * len(out))
        chunk = out[i]
        if name == "flip" and chunk:
            p = int(b * len(chunk) * 8)
            ba = bytearray(chunk)
            ba[p // 8] ^= 1 << (p % 8)
            out[i] = bytes(ba)
        elif name == "truncate":
            out[i] = chunk[: int(b * len(chunk))]
        elif name == "duplicate":
            out.insert(j, chunk)
        elif name == "swap":
            out[i], out[j] = out[j], out[i]
        elif name == "garbage":
            out.insert(j, rng.randbytes(1 + int(a * 40)))
        elif name == "drop":
            del out[i]
        elif name == "splice" and chunk:
            # Split a chunk: bytes arrive in arbitrary pieces.
            p = int(b * len(chunk))
            out[i : i + 1] = [chunk[:p], chunk[p:]]
    return out


def reslot(mutated: list[bytes], slot_sizes: list[int]) -> list[list[bytes]]:
    """Distribute a flat chunk list over slots of the original sizes (extras go last)."""
    slots, pos = [], 0
    for size in slot_sizes:
        slots.append(mutated[pos : pos + size])
        pos += size
    if slots:
        slots[-1] = slots[-1] + mutated[pos:]
    return slots

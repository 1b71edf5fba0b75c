"""The two ends of the ALTER link: a DDCMP link plus the application messages.

``HostEndpoint`` (the gateway's side) turns in-sequence data into ``StatusReceived``
and sends corrections; ``ControllerEndpoint`` (the robot controller's side, simulated
by sim_robot) turns them into ``CorrectionReceived`` and sends status. Both are pure:
every call takes ``now_ns`` and returns ``list[Event]``.

The controller end is where a correction becomes motion, so it validates hardest: a
correction is delivered only if it decodes, names a cycle this controller issued within
the last ``max_correction_age_cycles`` cycles, is newer than every correction delivered
before (so link restarts, replays and duplicates never apply one twice), and is within
the optional per-cycle limits.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field

from humanpt.robot_gateway.links.alter.ddcmp_link import DdcmpLink, LinkConfig
from humanpt.robot_gateway.links.alter.events import (
    CorrectionReceived,
    DataReceived,
    Event,
    LinkUp,
    MessageRejected,
    StatusReceived,
)
from humanpt.robot_gateway.links.alter.messages import (
    UINT32_MAX,
    ControllerStatus,
    Correction,
    MessageError,
    decode_correction,
    decode_status,
    encode_correction,
    encode_status,
)

_CYCLE_MOD = UINT32_MAX + 1
_HALF_CYCLE_RANGE = _CYCLE_MOD // 2


def _cycles_after(a: int, b: int) -> int:
    """a - b in uint32 cycle arithmetic, as a signed int (|result| < 2**31)."""
    d = (a - b) % _CYCLE_MOD
    return d - _CYCLE_MOD if d >= _HALF_CYCLE_RANGE else d


class _Endpoint:
    def __init__(self, link_config: LinkConfig) -> None:
        self.link = DdcmpLink(link_config)

    def start(self, now_ns: int) -> list[Event]:
        return self._filter(self.link.start(now_ns))

    def stop(self) -> list[Event]:
        return self._filter(self.link.stop())

    def poll(self, now_ns: int) -> list[Event]:
        return self._filter(self.link.poll(now_ns))

    def receive(self, data: bytes, now_ns: int) -> list[Event]:
        return self._filter(self.link.receive(data, now_ns))

    @property
    def next_deadline_ns(self) -> int | None:
        return self.link.next_deadline_ns

    def shift_time(self, step_ns: int) -> None:
        self.link.shift_time(step_ns)

    def _filter(self, events: list[Event]) -> list[Event]:
        out: list[Event] = []
        for event in events:
            if isinstance(event, LinkUp):
                self._on_link_up()
                out.append(event)
            elif isinstance(event, DataReceived):
                out.append(self._on_payload(event.payload))
            else:
                out.append(event)
        return out

    def _on_link_up(self) -> None:
        pass

    def _on_payload(self, payload: bytes) -> Event:
        raise NotImplementedError


@dataclass(frozen=True)
class HostConfig:
    link: LinkConfig = field(default_factory=LinkConfig)


class HostEndpoint(_Endpoint):
    """The host (gateway) end: receives STATUS, sends CORRECTION."""

    def __init__(self, config: HostConfig | None = None) -> None:
        self.config = config or HostConfig()
        super().__init__(self.config.link)
        self._last_cycle: int | None = None

    @property
    def last_status_cycle(self) -> int | None:
        return self._last_cycle

    def send_correction(self, correction: Correction, now_ns: int) -> list[Event]:
        return self._filter(self.link.send(encode_correction(correction), now_ns))

    def _on_link_up(self) -> None:
        self._last_cycle = None  # a restarted controller may count from anywhere

    def _on_payload(self, payload: bytes) -> Event:
        try:
            status = decode_status(payload)
        except MessageError as exc:
            return MessageRejected(str(exc))
        if self._last_cycle is not None and _cycles_after(status.cycle, self._last_cycle) <= 0:
            return MessageRejected(f"status cycle {status.cycle} not after {self._last_cycle}")
        self._last_cycle = status.cycle
        return StatusReceived(status)


@dataclass(frozen=True)
class ControllerConfig:
    """Controller end. Limits are per-axis absolute values in wire units (None: off)."""

    link: LinkConfig = field(default_factory=LinkConfig)
    max_correction_age_cycles: int = 2
    max_translation_10um: int | None = None
    max_rotation_cdeg: int | None = None

    def __post_init__(self) -> None:
        if not 0 <= self.max_correction_age_cycles <= 1000:
            raise ValueError(
                f"max_correction_age_cycles must be in [0, 1000], got {self.max_correction_age_cycles}"
            )
        for name in ("max_translation_10um", "max_rotation_cdeg"):
            value = getattr(self, name)
            if value is not None and value < 0:
                raise ValueError(f"{name} must be >= 0 or None, got {value}")


class ControllerEndpoint(_Endpoint):
    """The robot controller end: sends STATUS, receives CORRECTION."""

    def __init__(self, config: ControllerConfig | None = None) -> None:
        self.config = config or ControllerConfig()
        super().__init__(self.config.link)
        # Why a deque of issued cycles: a correction must echo one we really sent.
        self._issued: deque[int] = deque(maxlen=self.config.max_correction_age_cycles + 1)
        self._last_applied: int | None = None

    @property
    def last_issued_cycle(self) -> int | None:
        return self._issued[-1] if self._issued else None

    @property
    def last_delivered_echo_cycle(self) -> int | None:
        return self._last_applied

    def send_status(self, status: ControllerStatus, now_ns: int) -> list[Event]:
        """Send this cycle's status. Cycle numbers must increase (ValueError otherwise).

        The cycle counts as issued even if the link is down (the send is then rejected).
        """
        last = self.last_issued_cycle
        if last is not None and _cycles_after(status.cycle, last) <= 0:
            raise ValueError(f"status cycle {status.cycle} must come after {last}")
        self._issued.append(status.cycle)
        return self._filter(self.link.send(encode_status(status), now_ns))

    def _on_payload(self, payload: bytes) -> Event:
        try:
            c = decode_correction(payload)
        except MessageError as exc:
            return MessageRejected(str(exc))
        if c.echo_cycle not in self._issued:
            return MessageRejected(f"correction echoes cycle {c.echo_cycle}, not a recent cycle")
        if self._last_applied is not None and _cycles_after(c.echo_cycle, self._last_applied) <= 0:
            return MessageRejected(
                f"correction for cycle {c.echo_cycle} is not newer than {self._last_applied}"
            )
        cfg = self.config
        if (
            cfg.max_translation_10um is not None
            and max(map(abs, c.deltas[:3])) > cfg.max_translation_10um
        ):
            return MessageRejected(f"translation {c.deltas[:3]} exceeds {cfg.max_translation_10um}")
        if (
            cfg.max_rotation_cdeg is not None
            and max(map(abs, c.deltas[3:])) > cfg.max_rotation_cdeg
        ):
            return MessageRejected(f"rotation {c.deltas[3:]} exceeds {cfg.max_rotation_cdeg}")
        self._last_applied = c.echo_cycle
        age = _cycles_after(self._issued[-1], c.echo_cycle)
        return CorrectionReceived(c, age)

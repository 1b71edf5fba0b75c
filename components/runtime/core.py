"""The component contract: a pure core with ``step(t_ns, topic, message)``.

A core never reads the wall clock, never draws unseeded random numbers, never starts
threads and never touches Zenoh, files or serial ports.  Timer ticks (topic ``tick``),
parameter changes (topic ``param``) and serial bytes reach it as inputs like any other
message.  A shell (live, replay or lock-step) binds it to the world.

Replaying a core's recorded inputs into a fresh core built from the same config must
reproduce its recorded outputs exactly; every shell relies on that.
"""

from __future__ import annotations

import dataclasses
from collections import defaultdict
from typing import Any, ClassVar

from google.protobuf.message import Message

from humanpt.runtime.config import ConfigError, live_keys, replace_live, to_table
from humanpt.schemas import humanpt_pb2 as pb
from humanpt.schemas.convert import header

Output = tuple[str, Message]


class Core:
    """Base class of every component core.

    Subclasses set ``name`` (the component name, first part of its topics),
    ``config_type`` (a frozen dataclass), ``inputs`` (short topic names it consumes,
    besides ``tick`` and ``param``) and implement :meth:`on_input`.  A core that wants
    timer ticks returns a period from :meth:`tick_period_ns`; one that must know whether
    other components are up names them in ``watch`` and gets ``liveliness`` inputs.
    Outputs on local topics (``serial_tx``) go to the shell's adapters, not the bus.
    """

    name: ClassVar[str] = ""
    config_type: ClassVar[type] = type(None)
    inputs: ClassVar[tuple[str, ...]] = ()
    # Components whose liveliness this core is told about (``liveliness`` inputs).
    watch: ClassVar[tuple[str, ...]] = ()

    def __init__(self, config: Any):
        if not isinstance(config, self.config_type):
            raise TypeError(f"{type(self).__name__} needs a {self.config_type.__name__}, got {type(config).__name__}")
        self.config = config
        # The config the core started with: the hard limit of its ``stricter`` parameters.
        self.start_config = config
        self._seq: dict[str, int] = defaultdict(int)

    # -- what shells call -------------------------------------------------------------
    def tick_period_ns(self) -> int | None:
        """Period of the ``tick`` input this core wants, or None for no ticks."""
        return None

    def step(self, t_ns: int, topic: str, msg: Message) -> list[Output]:
        """Consume one input given at time ``t_ns`` (ns); return the outputs it causes."""
        if topic == "param":
            return self._on_param(t_ns, msg)
        return self.on_input(t_ns, topic, msg)

    def params(self) -> dict[str, Any]:
        """Current values of the live parameters."""
        table = to_table(self.config)
        return {k: table[k] for k in live_keys(self.config)}

    # -- what subclasses implement / use -----------------------------------------------
    def on_input(self, t_ns: int, topic: str, msg: Message) -> list[Output]:
        raise NotImplementedError

    def on_config_changed(self, old: Any, new: Any) -> None:
        """Called after a live parameter changed ``self.config`` from ``old`` to ``new``."""

    def next_header(self, topic: str, stamp_ns: int, frame_id: str = "") -> pb.Header:
        """A header for the next message on ``topic`` (sequence numbers count per topic)."""
        seq = self._seq[topic]
        self._seq[topic] = seq + 1
        return header(stamp_ns, seq, frame_id)

    def event(self, t_ns: int, severity: int, code: str, text: str) -> Output:
        """An event output on ``<name>/events``."""
        topic = f"{self.name}/events"
        return topic, pb.Event(header=self.next_header(topic, t_ns), severity=severity,
                               source=self.name, code=code, text=text)

    # -- parameters ----------------------------------------------------------------------
    def _on_param(self, t_ns: int, msg: pb.ParamSet) -> list[Output]:
        old = self.config
        try:
            new = replace_live(old, msg.key, msg.value_json, hard=self.start_config)
        except ConfigError as e:
            return [self.event(t_ns, pb.SEVERITY_WARNING, "param_rejected", f"{self.name}: {e}")]
        self.config = new
        self.on_config_changed(old, new)
        value = dataclasses.asdict(new)[msg.key]
        return [self.event(t_ns, pb.SEVERITY_INFO, "param_changed", f"{self.name}: {msg.key} = {value!r}")]

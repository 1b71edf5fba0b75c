"""Foxglove bridge core: which bus messages go to the browser, and when.

Pure (DESIGN.md's contract): it reads every bus topic and forwards each message it lets
through on the local topic ``show:<component>.<topic>`` (``humanpt.schemas.topics.
show_topic``, as viz does), which the live shell hands to the bridge's adapter
(:mod:`humanpt.foxglove_bridge.server`: the WebSocket server).  A channel goes out at most
``max_hz`` (camera images ``image_max_hz``), by the input's time (its arrival at the bridge);
what must not be thinned (:data:`WHOLE`) always goes.  The shell's inbox holds one image at
most (latest wins) and drops the oldest of other topics when the bridge lags: the bridge
never holds the bus back.  Its recording replays: its outputs are what the browser was given.
"""

from __future__ import annotations

import functools

from foxglove_schemas_protobuf.RawImage_pb2 import RawImage

from humanpt.foxglove_bridge.config import FoxgloveBridgeConfig
from humanpt.runtime.core import Core, Output, Port
from humanpt.runtime.limiter import EventLimiter
from humanpt.schemas import topics

__all__ = ["FoxgloveBridgeCore", "BRIDGED_TOPICS", "IMAGE_TOPICS", "WHOLE"]

# Every bus topic of the topic table.
BRIDGED_TOPICS: tuple[str, ...] = tuple(topics.TOPICS)
IMAGE_TOPICS: tuple[str, ...] = tuple(t for t in BRIDGED_TOPICS if topics.TOPICS[t].type is RawImage)
# Never thinned: each message counts (events and logs), carries what the next one does not
# (path points, seam strips, the command log), or is already bounded by its producer
# (scene/transforms: several sources on one topic, each at most scene's transforms_max_hz;
# the calibration: every republish_every-th measurement; the whole path: as it grows).
WHOLE: frozenset[str] = frozenset(
    {t for t in BRIDGED_TOPICS if t.endswith("/events")}
    | {"scene/log", "scene/path", "scene/path_points", "scene/entities", "scene/calibration", "scene/transforms",
       "controller/path", "console/command"})


def _period_ns(hz: float) -> int:
    return round(1e9 / hz)


class FoxgloveBridgeCore(Core):
    """Every bus topic in; the messages the browser gets out on ``show:`` topics (module
    docstring)."""

    name = "foxglove_bridge"
    config_type = FoxgloveBridgeConfig
    ports = tuple(Port(t, topics.TOPICS[t].type, "_forward", queue=1 if t in IMAGE_TOPICS else 64)
                  for t in BRIDGED_TOPICS)

    def __init__(self, config: FoxgloveBridgeConfig):
        super().__init__(config)
        self.streams = EventLimiter(_period_ns(config.max_hz))
        self.images = EventLimiter(_period_ns(config.image_max_hz))
        self.forwarded: dict[str, int] = {}
        self.thinned: dict[str, int] = {}

    def on_config_changed(self, old: FoxgloveBridgeConfig, new: FoxgloveBridgeConfig) -> None:
        self.streams.interval_ns = _period_ns(new.max_hz)
        self.images.interval_ns = _period_ns(new.image_max_hz)

    def _bind(self, port: Port):
        if port.handler == "_forward":  # one forwarder per topic: its output names the topic
            return functools.partial(self._forward, port.topic)
        return super()._bind(port)

    def _forward(self, short: str, t_ns: int, msg) -> list[Output]:
        if short not in WHOLE:
            limiter = self.images if short in IMAGE_TOPICS else self.streams
            if limiter.allow(short, t_ns) is None:
                self.thinned[short] = self.thinned.get(short, 0) + 1
                return []
        self.forwarded[short] = self.forwarded.get(short, 0) + 1
        return [(topics.show_topic(short), msg)]

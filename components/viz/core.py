"""viz core: chooses what the live view shows and hands it to the shell's rerun adapter.

The core stays pure: it never touches rerun.  For every input it decides whether the
viewer gets it (every ``image_every``-th camera image; everything else) and outputs a
copy on the *local* topic ``show:<component>.<topic>`` (``humanpt.schemas.topics.
show_topic``).  Local topics are never published; the live shell hands them to the
``ViewerAdapter`` (``humanpt.viz.sink``), which logs them with the :class:`~humanpt.viz.
logger.RerunLogger`.  ``humanpt view`` runs the very same core over a recorded run, so a
recording and the live view show the same thing.

Because the decision is in the core, the viz recording replays like any other: its
outputs are exactly what the viewer was given.
"""

from __future__ import annotations

import functools

from foxglove_schemas_protobuf.RawImage_pb2 import RawImage

from humanpt.runtime.core import Core, Output, Port
from humanpt.schemas import topics
from humanpt.viz.config import VizConfig

__all__ = ["VizCore", "SHOWN_TOPICS"]

# What the view shows (README.md: the blueprint).
SHOWN_TOPICS: tuple[str, ...] = (
    "camera/image",
    "perception/tob",
    "pose_filter/tob_state",
    "controller/command",
    "controller/status",
    "controller/path",
    "robot_gateway/robot_state",
    "operator/truth",
    "sim_robot/truth",
    "sim_camera/truth",
    "console/command",
    *(f"{c}/events" for c in topics.EVENT_PUBLISHERS if c not in ("viz", "pinger", "ponger")),
)


class VizCore(Core):
    name = "viz"
    config_type = VizConfig
    ports = (
        Port("camera/image", RawImage, "_on_image"),
        *(Port(t, topics.message_type(t), "_forward") for t in SHOWN_TOPICS if t != "camera/image"),
    )

    def __init__(self, config: VizConfig):
        super().__init__(config)
        self.images_seen = 0

    def _bind(self, port: Port):
        if port.handler == "_forward":  # one forwarder per topic: its output names the topic
            return functools.partial(self._forward, topics.show_topic(port.topic))
        return super()._bind(port)

    def _forward(self, shown: str, t_ns: int, msg) -> list[Output]:
        return [(shown, msg)]

    def _on_image(self, t_ns: int, msg: RawImage) -> list[Output]:
        self.images_seen += 1
        # Decimate by count (not by stamp) so that the first image is always shown.
        if (self.images_seen - 1) % self.config.image_every:
            return []
        return [(topics.show_topic("camera/image"), msg)]


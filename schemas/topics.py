"""The one topic table: short name -> key expression -> message type -> publisher.

Key expressions are ``humanpt/<cell>/<component>/<topic>``; a *short name* is the
``<component>/<topic>`` part, which is what cores use.  Local inputs that never cross
the network (``tick``, ``param``) have no slash.

Bump :data:`SCHEMA_VERSION` on any change that makes old recordings decode differently
(a renumbered field, a changed meaning); adding fields or topics does not need it.

The same table as data, for clients in other languages: ``schemas/topics.json`` (key
pattern, short name, full protobuf type name, the .proto file that defines it, publisher,
doc; the local topics marked local; the event publishers).  It is generated from this
module; after changing a row regenerate it with ONE command (tests/schemas fail while it
is stale)::

    python -m humanpt.schemas.topics --write      # or --json to print it
"""

from __future__ import annotations

from dataclasses import dataclass

from foxglove_schemas_protobuf.CameraCalibration_pb2 import CameraCalibration
from foxglove_schemas_protobuf.FrameTransforms_pb2 import FrameTransforms
from foxglove_schemas_protobuf.ImageAnnotations_pb2 import ImageAnnotations
from foxglove_schemas_protobuf.Log_pb2 import Log
from foxglove_schemas_protobuf.PointCloud_pb2 import PointCloud
from foxglove_schemas_protobuf.PosesInFrame_pb2 import PosesInFrame
from foxglove_schemas_protobuf.RawImage_pb2 import RawImage
from foxglove_schemas_protobuf.SceneUpdate_pb2 import SceneUpdate
from google.protobuf.message import Message

from humanpt.schemas import humanpt_pb2 as pb

SCHEMA_VERSION = 1
KEY_PREFIX = "humanpt"


@dataclass(frozen=True)
class Topic:
    """One row of the topic table."""

    short: str  # "<component>/<topic>"
    type: type[Message]
    publisher: str
    doc: str

    def key(self, cell: str) -> str:
        """The Zenoh key expression of this topic in ``cell``."""
        return f"{KEY_PREFIX}/{cell}/{self.short}"


_ROWS = [
    Topic("camera/image", RawImage, "camera", "complex image (mono8), stamp = capture"),
    Topic("perception/tob", pb.TobMeasurement, "perception", "2D centres, pairs, 3D points, camera_T_tob"),
    Topic("pose_filter/tob_state", pb.TobState, "pose_filter", "filtered world_T_tob, velocity, covariance"),
    Topic("controller/command", pb.FlangeCommand, "controller", "per-cycle flange correction"),
    Topic("controller/status", pb.ControllerStatus, "controller", "mode, visible sources, error"),
    Topic("controller/path", pb.PathPoint, "controller", "recorded path points"),
    Topic("robot_gateway/robot_state", pb.RobotState, "robot_gateway", "world_T_flange per ALTER cycle"),
    Topic("operator/truth", pb.Truth, "operator", "twin: true world_T_tob (and tip)"),
    Topic("sim_robot/truth", pb.Truth, "sim_robot", "twin: true world_T_flange"),
    Topic("sim_camera/truth", pb.Truth, "sim_camera", "twin: world_T_tob, world_T_flange at each image's capture"),
    Topic("console/command", pb.Command, "console", "operator commands (record, save, hold, ...)"),
    # Foxglove's own types for Foxglove and rerun's MCAP import (humanpt.scene).
    Topic("scene/transforms", FrameTransforms, "scene", "frames world, base, flange, camera, camera_right/left, "
          "desired, flange_desired, tob, tip"),
    Topic("scene/path", PosesInFrame, "scene", "the recorded path (tip, else G) in world"),
    Topic("scene/path_points", PointCloud, "scene", "the same path as points (rerun draws them)"),
    Topic("scene/annotations", ImageAnnotations, "scene", "centres, pairs, labels on the complex image"),
    Topic("scene/calibration", CameraCalibration, "scene", "the camera's K, D, P (rig), now and then"),
    Topic("scene/log", Log, "scene", "every component's events as log lines"),
    Topic("scene/entities", SceneUpdate, "scene", "target triangle, recorded seam, twin: true seam"),
    Topic("pinger/ping", pb.Tick, "pinger", "runtime self-test: a tick per period"),
    Topic("ponger/pong", pb.Event, "ponger", "runtime self-test: an event per ping"),
    Topic("player/clock", pb.Tick, "player",
          "humanpt runs play --clock: the recording's time (header.stamp_ns) every period_ns"),
]
# Every component may publish events on "<component>/events".
EVENT_PUBLISHERS = (
    "camera",
    "perception",
    "pose_filter",
    "controller",
    "robot_gateway",
    "sim_robot",
    "sim_camera",
    "operator",
    "standin_robot",
    "viz",
    "scene",
    "foxglove_bridge",
    "pinger",
    "ponger",
)
_ROWS += [Topic(f"{c}/events", pb.Event, c, "events: safety actions, drops, mode changes") for c in EVENT_PUBLISHERS]
# The router (not a component): attempts its access control refused (security = "mtls",
# report_denied; humanpt.runtime.security.DenialWatch).
_ROWS.append(Topic("router/events", pb.Event, "router", "access control: refused attempts (mTLS)"))

# Local inputs: delivered by a shell to its own core, recorded, never published.
LOCAL_TOPICS: dict[str, type[Message]] = {
    "tick": pb.Tick,
    "param": pb.ParamSet,
    "serial_rx": pb.SerialChunk,  # bytes read from the component's serial port
    "serial_tx": pb.SerialChunk,  # output: bytes the shell writes to the serial port
    "udp_rx": pb.SerialChunk, "udp_tx": pb.SerialChunk,  # datagrams from / to a UDP link (RSI)
    "liveliness": pb.Liveliness,  # a watched component came or went (Core.watch)
    "capture": RawImage,  # a frame grabbed by the camera's capture adapter (stamp = capture)
    "capture_right": RawImage,  # the second camera's frame, a stereo pair's right (camera.source_right)
    "path_file": pb.Event,  # what the controller's path writer did on save (path_saved, save_failed)
    "clock_step": pb.Event,  # the wall clock stepped (text: the step in ns): runtime/clock.py
}

TOPICS: dict[str, Topic] = {t.short: t for t in _ROWS}

# A core may hand a copy of a bus message to its own shell's adapters on the local topic
# "show:<component>.<topic>" (no slash, so never published): viz's core forwards what its
# rerun adapter is to log this way.  Such a topic has the type of the bus topic it copies.
SHOW_PREFIX = "show:"


def show_topic(short: str) -> str:
    """The local topic carrying a copy of bus topic ``short`` to a shell's adapter."""
    return SHOW_PREFIX + short.replace("/", ".")


def shown_short(local: str) -> str:
    """The bus topic a ``show:`` local topic copies (inverse of :func:`show_topic`)."""
    return local[len(SHOW_PREFIX):].replace(".", "/")


# Components that changed their name: old name -> new. A config section, profile entry,
# `humanpt OLD`, `humanpt param OLD`, a console command or a recording under the old name
# still works (issue 22 made the ALTER gateway one gateway for every robot link).
RENAMED_COMPONENTS: dict[str, str] = {"alter_gateway": "robot_gateway"}


# Core classes that changed their name or place (after the renames above): a recording that
# names the old one replays with the new one (issue 30: one GatewayCore for every link).
RENAMED_CORES: dict[str, str] = {
    "humanpt.robot_gateway.core:AlterGatewayCore": "humanpt.robot_gateway.core:GatewayCore",
    "humanpt.rsi.core:RsiGatewayCore": "humanpt.robot_gateway.core:GatewayCore",
}


# Keys a component's config held in an older version and holds no more, per (component, key,
# value): a recorded config with key = value drops them when it is read (issue 30: the gateway
# over RSI recorded ALTER's serial port and baud, which its config then inherited).
RETIRED_CONFIG_KEYS: dict[tuple[str, str, str], tuple[str, ...]] = {
    ("robot_gateway", "link", "rsi"): ("port", "baud"),
}


# Keys added to a component's config since older recordings, per (component, key): the value
# that gives the behaviour those recordings had, taken when a recorded config lacks the key
# (issue 32: the controller records a point every recording_spacing_mm as well; 0 = only
# every recording_delay_cycles, as before).
# (component, key) -> (the old behaviour's value, a key the component's own config has): a
# recording of another core under that component's name (a test's scripted controller) has
# no such key and gets nothing added.
ADDED_CONFIG_KEYS: dict[tuple[str, str], tuple[object, str]] = {
    ("controller", "recording_spacing_mm"): (0.0, "recording_delay_cycles"),
}


def current_config(component: str, table: dict) -> dict:
    """A recorded config of ``component`` as this version reads it (RETIRED_CONFIG_KEYS
    dropped; ADDED_CONFIG_KEYS missing from it set to their old behaviour)."""
    added = {k: v for (name, k), (v, sibling) in ADDED_CONFIG_KEYS.items()
             if name == component and k not in table and sibling in table}
    if added and table:
        table = {**table, **added}
    for (name, key, value), retired in RETIRED_CONFIG_KEYS.items():
        if name == component and table.get(key) == value and any(k in table for k in retired):
            table = {k: v for k, v in table.items() if k not in retired}
    return table


def current_name(component: str) -> str:
    """A component's name now (``alter_gateway`` -> ``robot_gateway``)."""
    return RENAMED_COMPONENTS.get(component, component)


def current_topic(short: str) -> str:
    """A short topic's name now (``alter_gateway/robot_state`` -> ``robot_gateway/robot_state``):
    a renamed component's topics moved with it; others unchanged."""
    component, sep, rest = short.partition("/")
    return current_name(component) + sep + rest if sep else short


class UnknownTopicError(KeyError):
    """A topic that is in neither the topic table nor the local topics."""


def message_type(short: str) -> type[Message]:
    """Message class of a short topic name (table or local)."""
    if short in TOPICS:
        return TOPICS[short].type
    if short in LOCAL_TOPICS:
        return LOCAL_TOPICS[short]
    if short.startswith(SHOW_PREFIX) and shown_short(short) in TOPICS:
        return TOPICS[shown_short(short)].type
    raise UnknownTopicError(f"unknown topic {short!r}; see humanpt topics --table")


def short_from_key(key: str) -> tuple[str, str]:
    """Split a key expression ``humanpt/<cell>/<short>`` into (cell, short)."""
    parts = key.split("/")
    if len(parts) < 4 or parts[0] != KEY_PREFIX:
        raise UnknownTopicError(f"{key!r} is not a humanpt key (humanpt/<cell>/<component>/<topic>)")
    return parts[1], "/".join(parts[2:])


def all_types() -> list[type[Message]]:
    """Every message class that can appear on a topic (for schema registration)."""
    seen: dict[str, type[Message]] = {}
    for cls in [t.type for t in _ROWS] + list(LOCAL_TOPICS.values()):
        seen.setdefault(cls.DESCRIPTOR.full_name, cls)
    return list(seen.values())


TABLE_JSON = "topics.json"  # beside this module: schemas/topics.json


def proto_file(cls: type[Message]) -> str:
    """The .proto file defining ``cls``, relative to schemas/ (``humanpt.proto``,
    ``foxglove/RawImage.proto``)."""
    return cls.DESCRIPTOR.file.name


def table_data() -> dict:
    """The topic table as plain data (what schemas/topics.json holds)."""

    def row(t: Topic) -> dict:
        return {"short": t.short, "key": f"{KEY_PREFIX}/{{cell}}/{t.short}", "type": t.type.DESCRIPTOR.full_name,
                "proto": proto_file(t.type), "publisher": t.publisher, "doc": t.doc, "local": False}

    return {
        "generated_by": "python -m humanpt.schemas.topics --write (from schemas/topics.py; do not edit)",
        "schema_version": SCHEMA_VERSION,
        "key_pattern": f"{KEY_PREFIX}/{{cell}}/{{component}}/{{topic}}",
        "encoding": "application/protobuf;<type> (each Zenoh sample's encoding names its full type)",
        "topics": [row(t) for t in TOPICS.values()],
        "event_publishers": list(EVENT_PUBLISHERS),
        "local_topics": [{"short": name, "type": cls.DESCRIPTOR.full_name, "proto": proto_file(cls),
                          "local": True} for name, cls in LOCAL_TOPICS.items()],
        "show_prefix": SHOW_PREFIX,
    }


def table_json() -> str:
    """:func:`table_data` as the text of schemas/topics.json (stable: sorted nowhere, rows in
    table order, two-space indent, a final newline)."""
    import json

    return json.dumps(table_data(), indent=2) + "\n"


def _main(argv: list[str] | None = None) -> int:
    import argparse
    from pathlib import Path

    ap = argparse.ArgumentParser(prog="python -m humanpt.schemas.topics",
                                 description="The topic table as JSON (schemas/topics.json).")
    g = ap.add_mutually_exclusive_group(required=True)
    g.add_argument("--json", action="store_true", help="print it on stdout")
    g.add_argument("--write", action="store_true", help=f"write schemas/{TABLE_JSON} (beside this module)")
    args = ap.parse_args(argv)
    text = table_json()
    if args.json:
        print(text, end="")
        return 0
    out = Path(__file__).with_name(TABLE_JSON)
    out.write_text(text)
    print(f"wrote {out} ({len(TOPICS)} topics, {len(LOCAL_TOPICS)} local)")
    return 0


if __name__ == "__main__":
    raise SystemExit(_main())

"""The gateway's ALTER link: the serial line to the Puma controller (assumed wire format).

The gateway's side: ``link.AlterLink`` (the gateway's Link), ``config.AlterConfig`` (its
``[robot_gateway]`` table: port, baud), ``shell`` (the serial port), ``kind.KIND`` (its
registry entry). The codec (pure; both ends, the simulated controller uses it too); see
PROTOCOL.md for the byte layout. Layers, each pure (bytes in, events out):

- ``crc``: CRC-16/ARC as used by DDCMP.
- ``ddcmp``: frames, encoders, the resynchronising ``DdcmpDecoder``.
- ``ddcmp_link``: ``DdcmpLink`` state machine (start-up, sequence numbers, ACK/NAK/REP).
- ``messages``: STATUS and CORRECTION payloads (fixed point, little-endian).
- ``endpoint``: ``HostEndpoint`` (gateway) and ``ControllerEndpoint`` (robot side).
- ``budget``: bytes per 28 ms cycle at 19 200 / 38 400 baud.
- ``quantize``: a clamped step as a CORRECTION whose rounded values keep the limits.
"""

from humanpt.robot_gateway.links.alter.budget import CycleBudget, bytes_per_cycle, cycle_budget
from humanpt.robot_gateway.links.alter.crc import crc16
from humanpt.robot_gateway.links.alter.ddcmp import (
    ControlFrame,
    ControlType,
    DataFrame,
    DdcmpDecoder,
    FrameDecodeError,
    FrameError,
    FrameErrorReason,
    NakReason,
    decode_frame,
    encode_frame,
)
from humanpt.robot_gateway.links.alter.ddcmp_link import (
    ALTER_CYCLE_NS,
    DdcmpLink,
    LinkConfig,
    LinkState,
)
from humanpt.robot_gateway.links.alter.endpoint import (
    ControllerConfig,
    ControllerEndpoint,
    HostConfig,
    HostEndpoint,
)
from humanpt.robot_gateway.links.alter.events import (
    Acknowledged,
    CorrectionReceived,
    DataReceived,
    Discarded,
    Event,
    LinkDown,
    LinkUp,
    MessageRejected,
    NakReceived,
    RepSent,
    SendRejected,
    StatusReceived,
    Transmit,
)
from humanpt.robot_gateway.links.alter.messages import (
    ControllerStatus,
    Correction,
    CorrectionFlags,
    MessageError,
    StatusBits,
    decode_correction,
    decode_message,
    decode_status,
    encode_correction,
    encode_status,
)

__all__ = [
    "ALTER_CYCLE_NS",
    "Acknowledged",
    "ControlFrame",
    "ControlType",
    "ControllerConfig",
    "ControllerEndpoint",
    "ControllerStatus",
    "Correction",
    "CorrectionFlags",
    "CorrectionReceived",
    "CycleBudget",
    "DataFrame",
    "DataReceived",
    "DdcmpDecoder",
    "DdcmpLink",
    "Discarded",
    "Event",
    "FrameDecodeError",
    "FrameError",
    "FrameErrorReason",
    "HostConfig",
    "HostEndpoint",
    "LinkConfig",
    "LinkDown",
    "LinkState",
    "LinkUp",
    "MessageError",
    "MessageRejected",
    "NakReason",
    "NakReceived",
    "RepSent",
    "SendRejected",
    "StatusBits",
    "StatusReceived",
    "Transmit",
    "bytes_per_cycle",
    "crc16",
    "cycle_budget",
    "decode_correction",
    "decode_frame",
    "decode_message",
    "decode_status",
    "encode_correction",
    "encode_frame",
    "encode_status",
]

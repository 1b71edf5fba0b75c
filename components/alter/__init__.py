"""ALTER serial link to the Puma controller: pure codec (assumed wire format).

See PROTOCOL.md for the byte layout. Layers, each pure (bytes in, events out):

- ``crc``: CRC-16/ARC as used by DDCMP.
- ``ddcmp``: frames, encoders, the resynchronising ``DdcmpDecoder``.
- ``link``: ``DdcmpLink`` state machine (start-up, sequence numbers, ACK/NAK/REP).
- ``messages``: STATUS and CORRECTION payloads (fixed point, little-endian).
- ``endpoint``: ``HostEndpoint`` (gateway) and ``ControllerEndpoint`` (robot side).
- ``budget``: bytes per 28 ms cycle at 19 200 / 38 400 baud.
- ``limiter``: rate-limited events and the serial-chunk output both link ends' cores share.
"""

from humanpt.alter.budget import CycleBudget, bytes_per_cycle, cycle_budget
from humanpt.alter.crc import crc16
from humanpt.alter.ddcmp import (
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
from humanpt.alter.endpoint import ControllerConfig, ControllerEndpoint, HostConfig, HostEndpoint
from humanpt.alter.events import (
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
from humanpt.alter.link import ALTER_CYCLE_NS, DdcmpLink, LinkConfig, LinkState
from humanpt.alter.messages import (
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

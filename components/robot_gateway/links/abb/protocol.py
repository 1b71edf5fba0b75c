"""ABB EGM messages (UDP datagrams of protobuf), encoded and decoded; pure.

The robot controller sends every EGM cycle (4 ms, or a multiple set by EGMActPose's
``\\SampleRate``) one ``EgmRobot``: ``header`` (``seqno`` +1 per message, ``tm`` ms,
``mtype`` DATA), ``feedBack.cartesian`` (the pose of the tool given to EGMActPose -
``tool0``, the flange, for humanpt - in its correction frame - the robot base for humanpt:
``pos`` mm, ``orient`` a unit quaternion u0 = w, u1..u3 = x, y, z), ``motorState``,
``mciState`` (RUNNING while EGM guides the robot) and ``rapidExecState``. The sensor answers
with an ``EgmSensor``: ``header`` (its own ``seqno``, ``tm``, ``mtype`` CORRECTION) and
``planned.cartesian``: the ABSOLUTE pose the robot is to go to (same frame, same units).

Anything that is not such a message raises :class:`EgmProtocolError` (one line: what was
wrong): longer than :data:`MAX_DATAGRAM`, not protobuf, a message without the header's
``seqno`` or without the feedback pose, a number that is not finite, a quaternion that is
not of unit norm (within :data:`QUAT_TOL`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from google.protobuf.message import DecodeError

from humanpt.geometry.transforms import make_transform
from humanpt.robot_gateway.links.abb import humanpt_egm_pb2 as egm
from humanpt.schemas.convert import quaternion_xyzw, rotation_from_xyzw

MAX_DATAGRAM = 4096  # a real EgmRobot is a few hundred bytes
QUAT_TOL = 1e-3  # |q| within 1 +- this; normalised then


class EgmProtocolError(ValueError):
    """A datagram that is not a usable EGM message."""


@dataclass(frozen=True, slots=True)
class EgmState:
    """One ``EgmRobot``: ``seqno``, ``tm_ms``, the fed-back pose ``pos_mm`` (3,) and
    ``quat_wxyz`` (4,) (unit), ``motors_on``, ``mci_running``, ``rapid_running``."""

    seqno: int
    tm_ms: int
    pos_mm: tuple[float, float, float]
    quat_wxyz: tuple[float, float, float, float]
    motors_on: bool = True
    mci_running: bool = True
    rapid_running: bool = True

    def base_T_flange_mm(self) -> np.ndarray:
        return pose_mm(self.pos_mm, self.quat_wxyz)


@dataclass(frozen=True, slots=True)
class EgmTarget:
    """One ``EgmSensor``: ``seqno`` (the sensor's), ``tm_ms``, ``echo`` (the robot's seqno it
    answers: not on the wire, for the link's bookkeeping), the target ``pos_mm`` and
    ``quat_wxyz``."""

    seqno: int
    tm_ms: int
    pos_mm: tuple[float, float, float]
    quat_wxyz: tuple[float, float, float, float]
    echo: int = 0

    def base_T_target_mm(self) -> np.ndarray:
        return pose_mm(self.pos_mm, self.quat_wxyz)


def pose_mm(pos_mm, quat_wxyz) -> np.ndarray:
    """(4, 4) from a position (mm) and a unit quaternion (w, x, y, z)."""
    w, x, y, z = quat_wxyz
    return make_transform(rotation_from_xyzw(x, y, z, w), np.asarray(pos_mm, float))


def pos_quat(a_T_b_mm: np.ndarray) -> tuple[tuple[float, float, float], tuple[float, float, float, float]]:
    """(position mm, unit quaternion w, x, y, z with w >= 0) of a (4, 4) transform."""
    x, y, z, w = quaternion_xyzw(a_T_b_mm[:3, :3])  # (w >= 0)
    p = a_T_b_mm[:3, 3]
    return (float(p[0]), float(p[1]), float(p[2])), (w, x, y, z)


def _check_size(data: bytes) -> None:
    if len(data) > MAX_DATAGRAM:
        raise EgmProtocolError(f"{len(data)} bytes: longer than an EGM message ({MAX_DATAGRAM} at most)")
    if not data:
        raise EgmProtocolError("an empty datagram")


def _finite(values, what: str) -> tuple[float, ...]:
    out = tuple(float(v) for v in values)
    if not all(math.isfinite(v) for v in out):
        raise EgmProtocolError(f"{what} is not finite: {out}")
    return out


def _pose(p, where: str) -> tuple[tuple[float, float, float], tuple[float, float, float, float]]:
    if not p.HasField("pos") or not p.HasField("orient"):
        raise EgmProtocolError(f"{where} has no position and quaternion")
    pos = _finite((p.pos.x, p.pos.y, p.pos.z), f"{where}.pos")
    q = np.array(_finite((p.orient.u0, p.orient.u1, p.orient.u2, p.orient.u3), f"{where}.orient"))
    n = float(np.linalg.norm(q))
    if abs(n - 1.0) > QUAT_TOL:
        raise EgmProtocolError(f"{where}.orient is not a unit quaternion (norm {n:.6f})")
    q = q / n
    return pos, (float(q[0]), float(q[1]), float(q[2]), float(q[3]))  # type: ignore[return-value]


def decode_robot(data: bytes) -> EgmState:
    _check_size(data)
    m = egm.EgmRobot()
    try:
        m.ParseFromString(data)
    except (DecodeError, RuntimeWarning, ValueError) as e:
        raise EgmProtocolError(f"not an EgmRobot (protobuf: {str(e)[:60]})") from None
    if not m.HasField("header") or not m.header.HasField("seqno"):
        raise EgmProtocolError("an EgmRobot without header.seqno")
    if m.header.mtype not in (egm.EgmHeader.MSGTYPE_DATA, egm.EgmHeader.MSGTYPE_UNDEFINED):
        raise EgmProtocolError(f"header.mtype {m.header.mtype} is not DATA: not the robot's message")
    if not m.HasField("feedBack") or not m.feedBack.HasField("cartesian"):
        raise EgmProtocolError("an EgmRobot without feedBack.cartesian (EGMActPose must stream the pose)")
    pos, quat = _pose(m.feedBack.cartesian, "feedBack.cartesian")
    motors = (not m.HasField("motorState")) or m.motorState.state == egm.EgmMotorState.MOTORS_ON
    mci = (not m.HasField("mciState")) or m.mciState.state == egm.EgmMCIState.MCI_RUNNING
    rapid = (not m.HasField("rapidExecState")) or m.rapidExecState.state == egm.EgmRapidCtrlExecState.RAPID_RUNNING
    return EgmState(int(m.header.seqno), int(m.header.tm), pos, quat, motors, mci, rapid)  # type: ignore[arg-type]


def encode_robot(state: EgmState) -> bytes:
    m = egm.EgmRobot()
    m.header.seqno, m.header.tm, m.header.mtype = state.seqno, state.tm_ms, egm.EgmHeader.MSGTYPE_DATA
    c = m.feedBack.cartesian
    c.pos.x, c.pos.y, c.pos.z = state.pos_mm
    c.orient.u0, c.orient.u1, c.orient.u2, c.orient.u3 = state.quat_wxyz
    m.motorState.state = egm.EgmMotorState.MOTORS_ON if state.motors_on else egm.EgmMotorState.MOTORS_OFF
    m.mciState.state = egm.EgmMCIState.MCI_RUNNING if state.mci_running else egm.EgmMCIState.MCI_STOPPED
    m.rapidExecState.state = (egm.EgmRapidCtrlExecState.RAPID_RUNNING if state.rapid_running
                              else egm.EgmRapidCtrlExecState.RAPID_STOPPED)
    return m.SerializeToString()


def encode_sensor(t: EgmTarget) -> bytes:
    m = egm.EgmSensor()
    m.header.seqno, m.header.tm, m.header.mtype = t.seqno, t.tm_ms, egm.EgmHeader.MSGTYPE_CORRECTION
    c = m.planned.cartesian
    c.pos.x, c.pos.y, c.pos.z = t.pos_mm
    c.orient.u0, c.orient.u1, c.orient.u2, c.orient.u3 = t.quat_wxyz
    return m.SerializeToString()


def decode_sensor(data: bytes) -> EgmTarget:
    _check_size(data)
    m = egm.EgmSensor()
    try:
        m.ParseFromString(data)
    except (DecodeError, RuntimeWarning, ValueError) as e:
        raise EgmProtocolError(f"not an EgmSensor (protobuf: {str(e)[:60]})") from None
    if not m.HasField("planned") or not m.planned.HasField("cartesian"):
        raise EgmProtocolError("an EgmSensor without planned.cartesian")
    pos, quat = _pose(m.planned.cartesian, "planned.cartesian")
    return EgmTarget(int(m.header.seqno), int(m.header.tm), pos, quat)  # type: ignore[arg-type]

"""ALTER application messages (the payload of a DDCMP data frame), assumed layout.

Little-endian, fixed point. Lengths are fixed; the first byte names the message:

STATUS (controller -> host, every cycle), 31 bytes, ``<BIH3i3i``::

    type 0x53 'S' | cycle uint32 | status bits uint16 |
    x, y, z int32 [0.01 mm]  (base_T_flange translation) |
    yaw, pitch, roll int32 [0.01 deg]  (Z-Y-X: base_R_flange = Rz(yaw) Ry(pitch) Rx(roll))

CORRECTION (host -> controller, once per cycle), 19 bytes, ``<BIH3h3h``::

    type 0x43 'C' | echoed cycle uint32 | flags uint16 |
    dx, dy, dz int16 [0.01 mm] | drx, dry, drz int16 [0.01 deg]

The correction's rotation is dR = Rz(drz) Ry(dry) Rx(drx) (the same Z-Y-X convention
as the pose; for the small per-cycle angles the order hardly matters). Whether the
delta is in the world (base) or tool (flange) frame is the controller's ALTER mode,
reported in the TOOL_MODE status bit. int16 is ample: the default per-cycle safety
limit (100 mm/s, 60 deg/s at 28 ms) is 280 units and 168 units, the range is +-32767.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass
from enum import IntFlag
from functools import lru_cache

import numpy as np

from humanpt.geometry.transforms import rotation_from_ypr_deg, ypr_deg_from_rotation

MSG_STATUS = 0x53  # 'S'
MSG_CORRECTION = 0x43  # 'C'

_STATUS = struct.Struct("<BIH3i3i")
_CORRECTION = struct.Struct("<BIH3h3h")
STATUS_PAYLOAD_BYTES = _STATUS.size  # 31
CORRECTION_PAYLOAD_BYTES = _CORRECTION.size  # 19

UINT32_MAX = 0xFFFFFFFF
INT32_MIN, INT32_MAX = -(2**31), 2**31 - 1
INT16_MIN, INT16_MAX = -(2**15), 2**15 - 1
MM_PER_UNIT = 0.01  # position unit: 10 micrometres
DEG_PER_UNIT = 0.01  # angle unit: centidegree


class StatusBits(IntFlag):
    """Controller status word (uint16). Undefined bits must be zero."""

    ALTER_ACTIVE = 0x0001  # ALTER mode on: corrections are being applied
    TOOL_MODE = 0x0002  # corrections are in the tool (flange) frame; clear: world frame
    CUMULATIVE = 0x0004  # corrections accumulate; clear: each is relative to the nominal path
    ARM_POWER = 0x0008  # arm power on
    FAULT = 0x0010  # controller fault (e.g. unreachable correction); ALTER stopped
    CORRECTION_MISSED = 0x0020  # no valid correction arrived in time for the last cycle


class CorrectionFlags(IntFlag):
    """Host flags (uint16). Undefined bits must be zero."""

    ALTER_OFF = 0x0001  # request: leave ALTER mode after this cycle
    HOLD = 0x0002  # the host is holding the robot: every delta must be zero


STATUS_BITS_DEFINED = int(sum(StatusBits))
CORRECTION_FLAGS_DEFINED = int(sum(CorrectionFlags))
NO_FLAGS = CorrectionFlags(0)


class MessageError(ValueError):
    """A payload that is not a valid ALTER application message."""


def _check_int(name: str, value: int, lo: int, hi: int) -> None:
    if type(value) is int and lo <= value <= hi:  # the common case, quickly
        return
    if not isinstance(value, int | np.integer) or isinstance(value, bool) or not lo <= value <= hi:
        raise ValueError(f"{name} must be an int in [{lo}, {hi}], got {value!r}")


def _to_units(value: float, unit: float, name: str, lo: int, hi: int) -> int:
    """Round to the nearest fixed-point unit (ties to even); raise when out of range."""
    value = float(value)
    if not math.isfinite(value):
        raise ValueError(f"{name} must be finite, got {value!r}")
    units = round(value / unit)
    if not lo <= units <= hi:
        raise ValueError(f"{name} = {value!r} is outside the wire range [{lo * unit}, {hi * unit}]")
    return units


@dataclass(frozen=True)
class ControllerStatus:
    """One cycle's controller state: cycle number, status bits, base_T_flange (fixed point).

    Position: flange origin in the robot base (world) frame, 0.01 mm units.
    Orientation: Z-Y-X yaw, pitch, roll of base_R_flange, 0.01 deg units; yaw and roll
    in [-180, 180] deg, pitch in [-90, 90] deg.
    """

    cycle: int
    bits: StatusBits
    x_10um: int
    y_10um: int
    z_10um: int
    yaw_cdeg: int
    pitch_cdeg: int
    roll_cdeg: int

    def __post_init__(self) -> None:
        _check_int("cycle", self.cycle, 0, UINT32_MAX)
        _check_int("bits", int(self.bits), 0, 0xFFFF)
        if int(self.bits) & ~STATUS_BITS_DEFINED:
            raise ValueError(f"undefined status bits set: 0x{int(self.bits):04x}")
        object.__setattr__(self, "bits", StatusBits(int(self.bits)))
        for name in ("x_10um", "y_10um", "z_10um"):
            _check_int(name, getattr(self, name), INT32_MIN, INT32_MAX)
        _check_int("yaw_cdeg", self.yaw_cdeg, -18000, 18000)
        _check_int("pitch_cdeg", self.pitch_cdeg, -9000, 9000)
        _check_int("roll_cdeg", self.roll_cdeg, -18000, 18000)

    @classmethod
    def from_pose(
        cls, cycle: int, bits: StatusBits, base_T_flange_mm: np.ndarray
    ) -> ControllerStatus:
        """Quantise a 4x4 pose (translation in mm) to the wire units."""
        base_T_flange_mm = np.asarray(base_T_flange_mm, dtype=float)
        if base_T_flange_mm.shape != (4, 4):
            raise ValueError(f"base_T_flange_mm must be 4x4, got {base_T_flange_mm.shape}")
        p = base_T_flange_mm[:3, 3].tolist()
        ypr = ypr_deg_from_rotation(base_T_flange_mm[:3, :3]).tolist()
        x, y, z = (
            _to_units(v, MM_PER_UNIT, n, INT32_MIN, INT32_MAX)
            for v, n in zip(p, "xyz", strict=True)
        )
        yaw, pitch, roll = (
            _to_units(v, DEG_PER_UNIT, n, -18000, 18000)
            for v, n in zip(ypr, ("yaw", "pitch", "roll"), strict=True)
        )
        return cls(cycle, bits, x, y, z, yaw, pitch, roll)

    @property
    def position_mm(self) -> np.ndarray:
        """(3,) flange origin in the base frame, mm."""
        return np.array([self.x_10um, self.y_10um, self.z_10um], dtype=float) * MM_PER_UNIT

    @property
    def ypr_deg(self) -> np.ndarray:
        """(3,) yaw, pitch, roll of base_R_flange, degrees (Z-Y-X)."""
        return (
            np.array([self.yaw_cdeg, self.pitch_cdeg, self.roll_cdeg], dtype=float) * DEG_PER_UNIT
        )

    def base_T_flange_mm(self) -> np.ndarray:
        """(4, 4) homogeneous pose of the flange in the base frame, translation in mm."""
        T = np.eye(4)
        T[:3, :3] = _rotation_cdeg(self.yaw_cdeg, self.pitch_cdeg, self.roll_cdeg)
        T[:3, 3] = self.position_mm
        return T


@dataclass(frozen=True)
class Correction:
    """The host's correction for one cycle (fixed point).

    ``echo_cycle``: the cycle number of the status this answers. Deltas: translation in
    0.01 mm, rotation about x, y, z in 0.01 deg (dR = Rz(drz) Ry(dry) Rx(drx)), in the
    frame the controller's ALTER mode names (world or tool).
    """

    echo_cycle: int
    flags: CorrectionFlags
    dx_10um: int
    dy_10um: int
    dz_10um: int
    drx_cdeg: int
    dry_cdeg: int
    drz_cdeg: int

    def __post_init__(self) -> None:
        _check_int("echo_cycle", self.echo_cycle, 0, UINT32_MAX)
        _check_int("flags", int(self.flags), 0, 0xFFFF)
        if int(self.flags) & ~CORRECTION_FLAGS_DEFINED:
            raise ValueError(f"undefined correction flags set: 0x{int(self.flags):04x}")
        object.__setattr__(self, "flags", CorrectionFlags(int(self.flags)))
        for name in self._DELTAS:
            _check_int(name, getattr(self, name), INT16_MIN, INT16_MAX)
        if CorrectionFlags.HOLD in self.flags and any(self.deltas):
            raise ValueError("a HOLD correction must have all deltas zero")

    _DELTAS = ("dx_10um", "dy_10um", "dz_10um", "drx_cdeg", "dry_cdeg", "drz_cdeg")

    @property
    def deltas(self) -> tuple[int, int, int, int, int, int]:
        """(dx, dy, dz [0.01 mm], drx, dry, drz [0.01 deg]) as wire integers."""
        return (
            self.dx_10um,
            self.dy_10um,
            self.dz_10um,
            self.drx_cdeg,
            self.dry_cdeg,
            self.drz_cdeg,
        )

    @classmethod
    def hold(cls, echo_cycle: int, flags: CorrectionFlags = NO_FLAGS) -> Correction:
        """A zero correction flagged HOLD."""
        return cls(echo_cycle, flags | CorrectionFlags.HOLD, 0, 0, 0, 0, 0, 0)

    @classmethod
    def from_mm_deg(
        cls,
        echo_cycle: int,
        d_mm: np.ndarray,
        r_deg: np.ndarray,
        flags: CorrectionFlags = NO_FLAGS,
    ) -> Correction:
        """Quantise (3,) translation [mm] and (3,) rotation about x, y, z [deg].

        Raises ValueError when a value does not fit int16 units; it never clips (clamping
        to the safety limits is the gateway's job, before this).
        """
        d_mm = np.asarray(d_mm, dtype=float).reshape(3).tolist()
        r_deg = np.asarray(r_deg, dtype=float).reshape(3).tolist()
        d = [
            _to_units(v, MM_PER_UNIT, n, INT16_MIN, INT16_MAX)
            for v, n in zip(d_mm, ("dx_mm", "dy_mm", "dz_mm"), strict=True)
        ]
        r = [
            _to_units(v, DEG_PER_UNIT, n, INT16_MIN, INT16_MAX)
            for v, n in zip(r_deg, ("rx_deg", "ry_deg", "rz_deg"), strict=True)
        ]
        return cls(echo_cycle, flags, *d, *r)

    @property
    def translation_mm(self) -> np.ndarray:
        """(3,) dx, dy, dz in mm."""
        return np.array(self.deltas[:3], dtype=float) * MM_PER_UNIT

    @property
    def rotation_deg(self) -> np.ndarray:
        """(3,) rotation about x, y, z in degrees (composed Rz(drz) Ry(dry) Rx(drx))."""
        return np.array(self.deltas[3:], dtype=float) * DEG_PER_UNIT

    def delta_T_mm(self) -> np.ndarray:
        """(4, 4) homogeneous delta: rotation dR, translation in mm."""
        T = np.eye(4)
        T[:3, :3] = _rotation_cdeg(self.drz_cdeg, self.dry_cdeg, self.drx_cdeg)
        T[:3, 3] = self.translation_mm
        return T


@lru_cache(maxsize=4096)
def _rotation_cdeg_cached(z_cdeg: int, y_cdeg: int, x_cdeg: int) -> np.ndarray:
    R = rotation_from_ypr_deg(np.array([z_cdeg, y_cdeg, x_cdeg], dtype=float) * DEG_PER_UNIT)
    R.flags.writeable = False
    return R


def _rotation_cdeg(z_cdeg: int, y_cdeg: int, x_cdeg: int) -> np.ndarray:
    """(3, 3) Rz(z) Ry(y) Rx(x) of wire angles [0.01 deg], as
    ``Rotation.from_euler("ZYX", [z, y, x] * 0.01, degrees=True).as_matrix()``.

    Cached (read-only arrays): a correction's small steps and a slowly turning flange
    repeat the same few wire angles cycle after cycle."""
    return _rotation_cdeg_cached(int(z_cdeg), int(y_cdeg), int(x_cdeg))


# --- wire encoding ----------------------------------------------------------------------


def encode_status(status: ControllerStatus) -> bytes:
    s = status
    return _STATUS.pack(
        MSG_STATUS,
        s.cycle,
        int(s.bits),
        s.x_10um,
        s.y_10um,
        s.z_10um,
        s.yaw_cdeg,
        s.pitch_cdeg,
        s.roll_cdeg,
    )


def encode_correction(correction: Correction) -> bytes:
    c = correction
    return _CORRECTION.pack(MSG_CORRECTION, c.echo_cycle, int(c.flags), *c.deltas)


def decode_status(payload: bytes) -> ControllerStatus:
    """Decode and validate a STATUS payload; raises MessageError."""
    if len(payload) != STATUS_PAYLOAD_BYTES or payload[0] != MSG_STATUS:
        raise MessageError(
            f"not a STATUS message ({len(payload)} bytes, type 0x{payload[:1].hex()})"
        )
    _, cycle, bits, *rest = _STATUS.unpack(payload)
    try:
        return ControllerStatus(cycle, StatusBits(bits), *rest)
    except ValueError as exc:
        raise MessageError(f"invalid STATUS: {exc}") from exc


def decode_correction(payload: bytes) -> Correction:
    """Decode and validate a CORRECTION payload; raises MessageError."""
    if len(payload) != CORRECTION_PAYLOAD_BYTES or payload[0] != MSG_CORRECTION:
        raise MessageError(
            f"not a CORRECTION message ({len(payload)} bytes, type 0x{payload[:1].hex()})"
        )
    _, cycle, flags, *deltas = _CORRECTION.unpack(payload)
    try:
        return Correction(cycle, CorrectionFlags(flags), *deltas)
    except ValueError as exc:
        raise MessageError(f"invalid CORRECTION: {exc}") from exc


def decode_message(payload: bytes) -> ControllerStatus | Correction:
    """Decode either message by its type byte; raises MessageError."""
    if payload[:1] == bytes([MSG_STATUS]):
        return decode_status(payload)
    if payload[:1] == bytes([MSG_CORRECTION]):
        return decode_correction(payload)
    raise MessageError(f"unknown message type 0x{payload[:1].hex()}")

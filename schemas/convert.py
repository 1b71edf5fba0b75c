"""numpy <-> message helpers.

Messages carry metres, radians and unit quaternions (x, y, z, w); these helpers move
4x4 homogeneous transforms, vectors and images in and out of them.  They validate what
they read and raise :class:`MessageError` (a ``ValueError``) with a clear text.
"""

from __future__ import annotations

import math
import re

import numpy as np
from foxglove_schemas_protobuf.RawImage_pb2 import RawImage

from humanpt.schemas import humanpt_pb2 as pb


class MessageError(ValueError):
    """A message that decodes but does not make sense (bad image size, zero quaternion...)."""


def header(stamp_ns: int, seq: int = 0, frame_id: str = "") -> pb.Header:
    """A message header: stamp of the data (ns), per-topic sequence, frame id."""
    return pb.Header(stamp_ns=int(stamp_ns), seq=int(seq), frame_id=frame_id)


def vector3(v) -> pb.Vector3:
    """(3,) array-like -> Vector3 (units as given)."""
    x, y, z = np.asarray(v, dtype=float).reshape(3).tolist()
    return pb.Vector3(x=x, y=y, z=z)


def from_vector3(m: pb.Vector3) -> np.ndarray:
    """Vector3 -> (3,) float array."""
    return np.array([m.x, m.y, m.z], dtype=float)


def _quat_from_rows(m00, m01, m02, m10, m11, m12, m20, m21, m22) -> tuple[float, float, float, float]:
    """A rotation matrix's nine entries (row by row, plain floats) -> unit quaternion
    (x, y, z, w), w >= 0, by Shepperd's method: ``Rotation.from_matrix(R).as_quat(
    canonical=True)`` to rounding (tested), on plain floats because every pose message
    goes through it (scipy's per-call overhead is ten times the arithmetic)."""
    tr = m00 + m11 + m22
    # Divide by the largest of the four candidates for stability.
    if tr >= m00 and tr >= m11 and tr >= m22:
        w = 0.5 * math.sqrt(max(1.0 + tr, 0.0))
        f = 0.25 / w
        x, y, z = (m21 - m12) * f, (m02 - m20) * f, (m10 - m01) * f
    elif m00 >= m11 and m00 >= m22:
        x = 0.5 * math.sqrt(max(1.0 + m00 - m11 - m22, 0.0))
        f = 0.25 / x
        y, z, w = (m01 + m10) * f, (m02 + m20) * f, (m21 - m12) * f
    elif m11 >= m22:
        y = 0.5 * math.sqrt(max(1.0 + m11 - m00 - m22, 0.0))
        f = 0.25 / y
        x, z, w = (m01 + m10) * f, (m12 + m21) * f, (m02 - m20) * f
    else:
        z = 0.5 * math.sqrt(max(1.0 + m22 - m00 - m11, 0.0))
        f = 0.25 / z
        x, y, w = (m02 + m20) * f, (m12 + m21) * f, (m10 - m01) * f
    n = math.sqrt(x * x + y * y + z * z + w * w)
    if w < 0:
        n = -n
    return x / n, y / n, z / n, w / n


def _matrix_rows_from_quat(x: float, y: float, z: float, w: float) -> list[list[float]]:
    n = math.sqrt(x * x + y * y + z * z + w * w)
    if not 0.0 < n < math.inf:
        # Its squares under- or overflow: scale by the largest component first.
        m = max(abs(x), abs(y), abs(z), abs(w))
        if not 0.0 < m < math.inf:  # zero, NaN or infinite: no rotation to be had
            raise MessageError(f"quaternion ({x}, {y}, {z}, {w}) has no usable length")
        x, y, z, w = x / m, y / m, z / m, w / m
        n = math.sqrt(x * x + y * y + z * z + w * w)
    x, y, z, w = x / n, y / n, z / n, w / n
    return [
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ]


def quaternion_xyzw(rotation: np.ndarray) -> tuple[float, float, float, float]:
    """A rotation matrix (3, 3) -> unit quaternion (x, y, z, w), w >= 0 (the one conversion
    of every pose message; no check that it is a rotation: :func:`pose` checks)."""
    return _quat_from_rows(*np.asarray(rotation, dtype=float).reshape(9).tolist())


def rotation_from_xyzw(x: float, y: float, z: float, w: float) -> np.ndarray:
    """A quaternion (x, y, z, w), normalised here -> rotation matrix (3, 3); MessageError when
    it has no usable length (zero, NaN, infinite)."""
    return np.array(_matrix_rows_from_quat(float(x), float(y), float(z), float(w)))


def pose(a_T_b: np.ndarray) -> pb.Pose:
    """4x4 homogeneous transform (translation in metres) -> Pose.

    Raises MessageError when the rotation part is not a rotation (det != 1 or not
    orthonormal to 1e-6).
    """
    T = np.asarray(a_T_b, dtype=float)
    if T.shape != (4, 4):
        raise MessageError(f"a transform must be 4x4, got shape {T.shape}")
    (m00, m01, m02, tx), (m10, m11, m12, ty), (m20, m21, m22, tz), _ = T.tolist()
    # R R^T = I (to 1e-6) and det R > 0, on plain floats (a NaN fails every comparison).
    r0, r1, r2 = (m00, m01, m02), (m10, m11, m12), (m20, m21, m22)
    ok = all(abs(a[0] * b[0] + a[1] * b[1] + a[2] * b[2] - (1.0 if i == j else 0.0)) < 1e-6
             for i, a in enumerate((r0, r1, r2)) for j, b in enumerate((r0, r1, r2)) if j >= i)
    det = m00 * (m11 * m22 - m12 * m21) - m01 * (m10 * m22 - m12 * m20) + m02 * (m10 * m21 - m11 * m20)
    if not ok or not det >= 0:
        raise MessageError("the rotation part of the transform is not a proper rotation")
    qx, qy, qz, qw = _quat_from_rows(m00, m01, m02, m10, m11, m12, m20, m21, m22)
    return pb.Pose(
        translation=pb.Vector3(x=tx, y=ty, z=tz),
        rotation=pb.Quaternion(x=qx, y=qy, z=qz, w=qw),
    )


def pose_from_mm(a_T_b_mm: np.ndarray) -> pb.Pose:
    """:func:`pose` of a transform whose translation is in millimetres (the twin's unit)."""
    T = np.array(a_T_b_mm, dtype=float)
    T[:3, 3] /= 1000.0
    return pose(T)


def from_pose(m: pb.Pose) -> np.ndarray:
    """Pose -> 4x4 homogeneous transform (translation in metres).

    An unset rotation (all zero) is the identity; a non-unit quaternion is normalised;
    a non-finite one raises MessageError.
    """
    r, p = m.rotation, m.translation
    x, y, z, w = r.x, r.y, r.z, r.w
    tx, ty, tz = p.x, p.y, p.z
    if not all(map(math.isfinite, (x, y, z, w, tx, ty, tz))):
        raise MessageError("pose holds a non-finite number")
    if x == 0.0 and y == 0.0 and z == 0.0 and w == 0.0:
        rows = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
    else:
        rows = _matrix_rows_from_quat(x, y, z, w)
    rows[0].append(tx)
    rows[1].append(ty)
    rows[2].append(tz)
    rows.append([0.0, 0.0, 0.0, 1.0])
    return np.array(rows)


_ENCODINGS = {
    "mono8": (1, np.uint8),
    "rgb8": (3, np.uint8),
    "bgr8": (3, np.uint8),
    "mono16": (1, np.uint16),
}


def image(
    pixels: np.ndarray, stamp_ns: int, frame_id: str = "camera", encoding: str | None = None
) -> RawImage:
    """(H, W) or (H, W, 3) array -> foxglove.RawImage (stamp = capture time, ns)."""
    a = np.ascontiguousarray(pixels)
    if encoding is None:
        encoding = {
            (2, np.dtype(np.uint8)): "mono8",
            (3, np.dtype(np.uint8)): "rgb8",
            (2, np.dtype(np.uint16)): "mono16",
        }.get((a.ndim, a.dtype))
        if encoding is None:
            raise MessageError(
                f"no image encoding for an array of shape {a.shape} and dtype {a.dtype}"
            )
    channels, dtype = _ENCODINGS[encoding]
    h, w = a.shape[:2]
    msg = RawImage(
        width=w,
        height=h,
        encoding=encoding,
        step=w * channels * np.dtype(dtype).itemsize,
        data=a.astype(dtype, copy=False).tobytes(),
        frame_id=frame_id,
    )
    msg.timestamp.FromNanoseconds(int(stamp_ns))
    return msg


def from_image(m: RawImage) -> np.ndarray:
    """foxglove.RawImage -> (H, W) or (H, W, C) array (a view on the message bytes).

    Raises MessageError for an unknown encoding, an empty image or a size that does not
    match width x height x step.
    """
    if m.encoding not in _ENCODINGS:
        raise MessageError(f"unsupported image encoding {m.encoding!r} (have {sorted(_ENCODINGS)})")
    channels, dtype = _ENCODINGS[m.encoding]
    itemsize = np.dtype(dtype).itemsize
    if m.width == 0 or m.height == 0:
        raise MessageError("empty image (width or height is 0)")
    row = m.width * channels * itemsize
    data = m.data  # (each read of a bytes field copies it out of the message: read it once)
    if m.step < row or len(data) != m.step * m.height:
        raise MessageError(
            f"image data is {len(data)} bytes; {m.width}x{m.height} {m.encoding} with step {m.step} "
            f"needs {m.step * m.height}"
        )
    a = np.frombuffer(data, dtype=np.uint8).reshape(m.height, m.step)[:, :row]
    a = a.view(dtype) if itemsize > 1 else a
    shape = (m.height, m.width) if channels == 1 else (m.height, m.width, channels)
    return a.reshape(shape)


def image_stamp_ns(m: RawImage) -> int:
    """Capture stamp of a RawImage in ns."""
    return m.timestamp.ToNanoseconds()


def covariance(P: np.ndarray) -> tuple[list[float], int]:
    """(n, n) covariance -> (row-major list, n)."""
    P = np.asarray(P, dtype=float)
    if P.ndim != 2 or P.shape[0] != P.shape[1]:
        raise MessageError(f"covariance must be square, got {P.shape}")
    return P.ravel().tolist(), P.shape[0]


def from_covariance(values, dim: int) -> np.ndarray:
    """Row-major list and dimension -> (dim, dim) array."""
    a = np.asarray(values, dtype=float)
    if a.size != dim * dim:
        raise MessageError(f"covariance has {a.size} values, expected {dim}x{dim}")
    return a.reshape(dim, dim)


_FIELD_PART = re.compile(r"([A-Za-z_][A-Za-z0-9_]*)(?:\[(\d+)\])?")


def message_field(msg, path: str):
    """The value at ``path`` in a protobuf message: dotted field names, a repeated field
    indexed ``name[i]`` (``pairs[0].residual_px``, ``world_T_tob.translation.x``); an enum
    gives its value's name, a message its text form on one line. Raises MessageError naming
    the part that is not there (an unknown field, an index beyond the list)."""
    from google.protobuf import text_format
    from google.protobuf.descriptor import FieldDescriptor

    value, where = msg, msg.DESCRIPTOR.full_name
    for part in path.split("."):
        m = _FIELD_PART.fullmatch(part)
        if m is None or not hasattr(value, "DESCRIPTOR"):
            raise MessageError(f"{path!r}: {part!r} is not a field of {where}")
        name, index = m.group(1), m.group(2)
        fd = value.DESCRIPTOR.fields_by_name.get(name)
        if fd is None:
            known = ", ".join(value.DESCRIPTOR.fields_by_name)
            raise MessageError(f"{path!r}: {where} has no field {name!r} (it has {known})")
        value = getattr(value, name)
        if index is not None:
            if not hasattr(value, "__len__") or isinstance(value, str | bytes):
                raise MessageError(f"{path!r}: {where}.{name} is not a list")
            if int(index) >= len(value):
                raise MessageError(f"{path!r}: {where}.{name} has {len(value)} entries, no [{index}]")
            value = value[int(index)]
        elif fd.type == FieldDescriptor.TYPE_ENUM and isinstance(value, int):
            value = fd.enum_type.values_by_number[value].name if value in fd.enum_type.values_by_number else value
        where = f"{where}.{part}"
    if hasattr(value, "DESCRIPTOR"):
        return text_format.MessageToString(value, as_one_line=True)
    if hasattr(value, "__len__") and not isinstance(value, str | bytes):
        return list(value)
    return value


def message_stamp_ns(msg) -> int | None:
    """A message's stamp (ns): ``header.stamp_ns``, or a Foxglove image's ``timestamp``."""
    fields = msg.DESCRIPTOR.fields_by_name
    if "header" in fields:
        return int(msg.header.stamp_ns)
    if "timestamp" in fields:
        return int(msg.timestamp.ToNanoseconds())
    return None

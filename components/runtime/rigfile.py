"""The rig file: what the pipeline believes about the hardware, one versioned TOML file.

Layout (every table optional; a missing table or key takes the nominal design value of
:class:`humanpt.geometry.rig.Rig`)::

    version = 1
    name = "cell0 rig"
    [psvs]                   # camera intrinsics, distortion, the PSVS (PsvsConfig keys)
    a_u = 1000.0
    [psvs.calibration]       # how [psvs] was obtained
    method = "zhang"
    date = "2026-11-23T10:00:00Z"
    sigma = { a_u = 0.4, a_v = 0.4 }
    [hand_eye]
    flange_T_camera_x = [0.0, 60.0, 100.0, 0.0, 0.0, 0.0]   # or flange_T_camera = 4 rows
    [target]
    leg_mm = 40.0
    [tip]
    tob_t_tip_mm = [0.0, 0.0, 60.0]
    [timing]                 # the camera's stamps on the robot's clock (issue 32; older rigs: 0)
    camera_time_offset_ms = 0.0
    [stereo]                 # an ordinary stereo pair, used when kind = "stereo" (issue 35)
    right_T_left_x = [-100.0, 0.0, 0.0, 0.0, 0.0, 0.0]
    [stereo.left]            # each camera: a_u, a_v, u0, v0, dist_coeffs
    [arm]                    # the playing arm's kinematic errors (issue 32.4; older rigs: none)
    model = "puma762"
    joint_offsets_deg = [0.0, 0.02, -0.03, 0.0, 0.01, 0.0]
    link_length_errors_mm = [0.0, -0.2, 0.3, -0.2, 0.0]

A missing file, bad TOML, an unknown key, a value outside its physical range or a
physically impossible value (focal length or baseline <= 0, a hand-eye rotation that is not
orthonormal, a triangle that does not close) raises :class:`ConfigError` naming the file,
the table and the field.  The rig travels as JSON (:func:`rig_to_json`) on the live
queryable and in every MCAP's metadata (``rig``).
"""

from __future__ import annotations

import json
import os
import tomllib
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from humanpt.geometry.config import PsvsConfig
from humanpt.geometry.rig import (
    RIG_KINDS,
    RIG_VERSION,
    Arm,
    Calibration,
    HandEye,
    Rig,
    Stereo,
    StereoCamera,
    TargetGeometry,
    Timing,
    Tip,
)
from humanpt.geometry.transforms import x_from_transform
from humanpt.runtime.config import ConfigError, build, dumps_toml, read_toml, to_table
from humanpt.runtime.files import write_atomic

__all__ = ["load_rig", "rig_from_table", "rig_to_table", "rig_to_toml", "write_rig", "rig_to_json",
           "rig_from_json", "RIG_METADATA"]

RIG_METADATA = "rig"
"""The key of the rig (JSON) in a recording's ``humanpt.run`` metadata."""

_PARTS: dict[str, type] = {"psvs": PsvsConfig, "hand_eye": HandEye, "target": TargetGeometry, "tip": Tip,
                           "timing": Timing, "stereo": Stereo, "arm": Arm}


def _calibration(table: Mapping[str, Any], source: str, section: str) -> Calibration:
    cal = build(Calibration, table, source=source, section=f"{section}.calibration")
    names = {f for f in _PARTS[section].__dataclass_fields__ if f != "calibration"}
    for key in cal.sigma:
        if key not in names:
            raise ConfigError(f"{source}: [{section}.calibration] sigma: {key!r} is not a field of "
                              f"[{section}] ({', '.join(sorted(names))})")
    return cal


def _hand_eye_table(table: dict[str, Any], source: str) -> dict[str, Any]:
    """Accept the hand-eye as a 4x4 matrix (``flange_T_camera``, what calibration tools
    compute) as well as X; refuse a rotation that is not one."""
    if "flange_T_camera" not in table:
        return table
    if "flange_T_camera_x" in table:
        raise ConfigError(f"{source}: [hand_eye] give flange_T_camera or flange_T_camera_x, not both")
    where = f"{source}: [hand_eye] flange_T_camera"
    try:
        T = np.array(table.pop("flange_T_camera"), dtype=float)
    except (TypeError, ValueError) as e:
        raise ConfigError(f"{where}: not a 4x4 matrix of numbers ({e})") from None
    if T.shape != (4, 4) or not np.all(np.isfinite(T)):
        raise ConfigError(f"{where}: must be 4 rows of 4 finite numbers, got shape {T.shape}")
    R = T[:3, :3]
    err = float(np.abs(R.T @ R - np.eye(3)).max())
    if err > 1e-6 or np.linalg.det(R) < 0:
        raise ConfigError(f"{where}: the rotation part is not orthonormal with det +1 "
                          f"(|R^T R - I| = {err:.2g}, det = {np.linalg.det(R):.6g})")
    if np.abs(T[3] - [0, 0, 0, 1]).max() > 1e-9:
        raise ConfigError(f"{where}: the last row must be [0, 0, 0, 1], got {T[3].tolist()}")
    return {**table, "flange_T_camera_x": [float(v) for v in x_from_transform(T)]}


def rig_from_table(data: Mapping[str, Any], source: str = "<rig>") -> Rig:
    """A parsed rig document (TOML or JSON tables) -> a validated :class:`Rig`."""
    if not isinstance(data, Mapping):
        raise ConfigError(f"{source}: a rig is a table, got {type(data).__name__}")
    known = {"version", "name", "kind", *_PARTS}
    unknown = [k for k in data if k not in known]
    if unknown:
        raise ConfigError(f"{source}: unknown rig key {unknown[0]!r}; known: {', '.join(sorted(known))}")
    if "version" not in data:
        raise ConfigError(f"{source}: version: missing (this humanpt writes version = {RIG_VERSION})")
    version = data["version"]
    if isinstance(version, bool) or version != RIG_VERSION:
        raise ConfigError(f"{source}: version: this humanpt reads rig version {RIG_VERSION}, "
                          f"the file says {version!r}")
    name = data.get("name", "")
    if not isinstance(name, str):
        raise ConfigError(f"{source}: name: expected a string, got {name!r}")
    kind = data.get("kind", "psvs")
    if kind not in RIG_KINDS:
        raise ConfigError(f"{source}: kind: {kind!r} is not a rig kind ({', '.join(RIG_KINDS)})")
    kwargs: dict[str, Any] = {"name": name, "kind": kind}
    for section, cls in _PARTS.items():
        table = data.get(section, {})
        if not isinstance(table, Mapping):
            raise ConfigError(f"{source}: [{section}] must be a table, got {type(table).__name__}")
        table = dict(table)
        cal = _calibration(table.pop("calibration", {}), source, section)
        if section == "hand_eye":
            table = _hand_eye_table(table, source)
        if section == "psvs":
            kwargs["psvs"] = build(PsvsConfig, table, source=source, section=section)
            kwargs["psvs_calibration"] = cal
        elif section == "stereo":
            for side in ("left", "right"):
                cam = table.get(side, {})
                if not isinstance(cam, Mapping):
                    raise ConfigError(f"{source}: [stereo.{side}] must be a table, got {type(cam).__name__}")
                table[side] = build(StereoCamera, dict(cam), source=source, section=f"stereo.{side}")
            kwargs["stereo"] = build(Stereo, {**table, "calibration": cal}, source=source, section=section)
        else:
            kwargs[section] = build(cls, {**table, "calibration": cal}, source=source, section=section)
    try:
        return Rig(**kwargs)
    except (ValueError, TypeError) as e:
        raise ConfigError(f"{source}: {e}") from None


def rig_to_table(rig: Rig) -> dict[str, Any]:
    """The rig as nested plain tables (the file's layout; None values left out)."""
    def clean(v):
        if isinstance(v, dict):
            return {k: clean(x) for k, x in v.items() if x is not None}
        return v

    plain = to_table(rig)
    if not rig.arm.present:  # no calibrated arm: the file (and a recording's rig) as before issue 32.4
        plain.pop("arm", None)
    psvs = plain.pop("psvs")
    psvs["calibration"] = plain.pop("psvs_calibration")
    out = {"version": plain.pop("version"), "name": plain.pop("name"), "kind": plain.pop("kind"), "psvs": psvs,
           **plain}
    return clean(out)


def rig_to_toml(rig: Rig, comment: str = "") -> str:
    head = "# humanpt rig: what the pipeline believes about the hardware (humanpt rig --help)\n"
    if comment:
        head += "".join(f"# {line}\n" for line in comment.splitlines())
    return head + dumps_toml(rig_to_table(rig))


def rig_to_json(rig: Rig) -> str:
    return json.dumps(rig_to_table(rig), sort_keys=True)


def rig_from_json(text: str, source: str = "<rig json>") -> Rig:
    try:
        data = json.loads(text)
    except RecursionError:
        raise ConfigError(f"{source}: the rig is nested too deeply to be read (a damaged or crafted file)") from None
    except ValueError as e:
        raise ConfigError(f"{source}: the rig is not JSON: {e}") from None
    return rig_from_table(data, source)


def load_rig(path: str | Path) -> Rig:
    """Read and validate a rig file (ConfigError naming the file and the field)."""
    data = read_toml(path, "rig", f" (write the nominal one with `humanpt rig init {path}`)")
    return rig_from_table(data, str(Path(path)))


def write_rig(path: str | Path, rig: Rig, comment: str = "", *, overwrite: bool = False) -> Path:
    """Write ``rig`` as TOML, atomically (a crash leaves the old file or the new one, never
    half of one; :func:`humanpt.runtime.files.write_atomic`).  An existing file is kept unless
    ``overwrite``: its previous content is then saved beside it as ``<name>.bak``."""
    p = Path(path)
    text = rig_to_toml(rig, comment)
    rig_from_table(tomllib.loads(text), f"{p} (as written)")  # what we write reads back
    there = os.path.lexists(p)
    if there and not overwrite:
        raise FileExistsError(f"{p} exists (overwrite it with --overwrite; the old one is kept as "
                              f"{p.name}.bak)")
    # A temporary file of a random name, created exclusively; the backup written the same way:
    # a link planted at .bak or at the temporary name is replaced, never written through.
    return write_atomic(p, text, backup=there)

"""The seam file: a fitted seam as JSON (mm, deg), readable by people and by other tools.

Layout (``"format": "humanpt.seam"``, ``"version": 1``)::

    {"format": "humanpt.seam", "version": 1,
     "source": {"path": "...", "point": "tip", "frame": "world", "points": 176},
     "fit": {"tolerance_mm": 0.2, ..., "noise_mm": 0.24, "residual_rms_mm": 0.047},
     "segments": [{"kind": "line", "first": 0, "last": 77, "start_mm": [x, y, z], "end_mm": [...],
                   "start_ypr_deg": [psi, theta, phi], "end_ypr_deg": [...], "length_mm": ...,
                   "residual_rms_mm": ..., "residual_max_mm": ..., "points": 78, "outliers": [],
                   "sigma_mm": ...,
                   # arcs also: "centre_mm", "normal", "radius_mm", "sweep_deg"
                  }, ...],
     "corners": [{"point_mm": [...], "angle_deg": 135.1, "before": 0, "after": 1}],
     "dwells": [{"point_mm": [...], "first": 167, "last": 175, "duration_s": 2.27}],
     "outliers": [...], "corner_cut": [...]}

Angles are Z-Y-X (psi, theta, phi) as everywhere in humanpt; ``first``/``last`` index the
source path's points.  :func:`read` checks every field and names the one that is wrong.
"""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

from humanpt.runtime.files import write_atomic
from humanpt.seam.fit import Corner, Dwell, FitConfig, FitError, Seam, Segment

FORMAT, VERSION = "humanpt.seam", 1

__all__ = ["FORMAT", "VERSION", "SeamFileError", "to_dict", "from_dict", "write", "read"]


class SeamFileError(ValueError):
    """A seam file that cannot be read or written; the message names the file and field."""


def _num(v: float) -> float | None:
    return float(v) if v is not None and math.isfinite(v) else None


def to_dict(seam: Seam) -> dict:
    segs = []
    for s in seam.segments:
        d = {k: v for k, v in dataclasses.asdict(s).items() if v is not None}
        d["outliers"] = list(s.outliers)
        d["sigma_mm"] = _num(s.sigma_mm)
        d["length_mm"] = s.length_mm
        segs.append(d)
    return {
        "format": FORMAT, "version": VERSION,
        "source": {**seam.meta, "points": seam.points},
        "fit": {**dataclasses.asdict(seam.config), "noise_mm": seam.noise_mm,
                "residual_rms_mm": _num(seam.residual_rms_mm)},
        "segments": segs,
        "corners": [dataclasses.asdict(c) for c in seam.corners],
        "dwells": [dataclasses.asdict(d) for d in seam.dwells],
        "outliers": list(seam.outliers),
        "corner_cut": list(seam.corner_cut),
    }


def _vec(d: dict, key: str, where: str, n: int = 3) -> tuple[float, ...]:
    v = d.get(key)
    if not isinstance(v, list) or len(v) != n or not all(isinstance(x, (int, float)) and math.isfinite(x) for x in v):
        raise SeamFileError(f"{where}: {key} must be {n} finite numbers, got {v!r}")
    return tuple(float(x) for x in v)


def from_dict(data: dict, source: str = "seam") -> Seam:
    if not isinstance(data, dict) or data.get("format") != FORMAT:
        raise SeamFileError(f"{source}: not a humanpt seam file (no \"format\": \"{FORMAT}\")")
    if data.get("version") != VERSION:
        raise SeamFileError(f"{source}: seam file version {data.get('version')!r}; this humanpt reads {VERSION}")
    segs = []
    for i, s in enumerate(data.get("segments") or []):
        w = f"{source}: segments[{i}]"
        kind = s.get("kind")
        if kind not in ("line", "arc"):
            raise SeamFileError(f"{w}: kind must be line or arc, got {kind!r}")
        kw = dict(kind=kind, first=int(s.get("first", 0)), last=int(s.get("last", 0)),
                  start_mm=_vec(s, "start_mm", w), end_mm=_vec(s, "end_mm", w),
                  start_ypr_deg=_vec(s, "start_ypr_deg", w), end_ypr_deg=_vec(s, "end_ypr_deg", w),
                  residual_rms_mm=float(s.get("residual_rms_mm", math.nan)),
                  residual_max_mm=float(s.get("residual_max_mm", math.nan)), points=int(s.get("points", 0)),
                  outliers=tuple(int(k) for k in s.get("outliers", ())),
                  sigma_mm=math.nan if s.get("sigma_mm") is None else float(s["sigma_mm"]))
        if kind == "arc":
            r, sw = s.get("radius_mm"), s.get("sweep_deg")
            if not (isinstance(r, (int, float)) and r > 0 and math.isfinite(r)):
                raise SeamFileError(f"{w}: radius_mm must be a positive number, got {r!r}")
            if not (isinstance(sw, (int, float)) and 0 < sw < 360):
                raise SeamFileError(f"{w}: sweep_deg must be in (0, 360), got {sw!r}")
            kw.update(centre_mm=_vec(s, "centre_mm", w), normal=_vec(s, "normal", w), radius_mm=float(r),
                      sweep_deg=float(sw))
        segs.append(Segment(**kw))
    if not segs:
        raise SeamFileError(f"{source}: the seam has no segments")
    corners = tuple(Corner(_vec(c, "point_mm", f"{source}: corners[{i}]"), float(c["angle_deg"]), int(c["before"]),
                           int(c["after"])) for i, c in enumerate(data.get("corners") or []))
    dwells = tuple(Dwell(_vec(d, "point_mm", f"{source}: dwells[{i}]"), int(d["first"]), int(d["last"]),
                         float(d["duration_s"])) for i, d in enumerate(data.get("dwells") or []))
    fit = dict(data.get("fit") or {})
    names = {f.name for f in dataclasses.fields(FitConfig)}
    try:
        cfg = FitConfig(**{k: v for k, v in fit.items() if k in names})
    except (FitError, TypeError) as e:
        raise SeamFileError(f"{source}: fit: {e}") from None
    src = dict(data.get("source") or {})
    points = int(src.pop("points", 0))
    return Seam(tuple(segs), corners, dwells, tuple(int(k) for k in data.get("outliers", ())),
                float(fit.get("noise_mm", math.nan)), cfg, points, src,
                tuple(int(k) for k in data.get("corner_cut", ())))


def write(path: str | Path, seam: Seam, overwrite: bool = False) -> Path:
    """Write the seam as JSON; never replaces an existing file unless ``overwrite`` (then
    atomically: a crash leaves the old file or the new one)."""
    path = Path(path)
    if path.exists() and not overwrite:
        raise SeamFileError(f"{path}: exists; give --overwrite to replace it")
    write_atomic(path, json.dumps(to_dict(seam), indent=1) + "\n")  # never through a planted link
    return path


def read(path: str | Path) -> Seam:
    path = Path(path)
    try:
        data = json.loads(path.read_text())
    except FileNotFoundError:
        raise SeamFileError(f"{path}: no such file") from None
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        raise SeamFileError(f"{path}: not JSON ({e})") from None
    return from_dict(data, str(path))

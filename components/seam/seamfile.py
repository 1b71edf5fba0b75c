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
source path's points.  :func:`read` checks every field and names the one that is wrong:
numbers finite and within :mod:`humanpt.seam.limits` (positions within +-10 m, angles
+-720 deg, dwells 0..3600 s, a feed in (0, 1000] mm/s), arcs with a non-zero normal, a
radius of at least 1 mm and the centre off the start, corners between neighbouring
segments; a retimed seam's ``retime`` (``speed_mm_s``, ``samples`` of ``t_s`` and ``x``) and
a ``feed_mm_s`` are checked the same way (:func:`read_file`).  :func:`write` checks the
same before it writes.
"""

from __future__ import annotations

import dataclasses
import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from humanpt.runtime.files import write_atomic
from humanpt.seam.fit import Corner, Dwell, FitConfig, FitError, Seam, Segment
from humanpt.seam.limits import (
    MAX_ABS_DEG,
    MAX_ABS_MM,
    MAX_DWELL_S,
    MAX_INDEX,
    MAX_TIME_S,
    MIN_ARC_RADIUS_MM,
    SPEED_CEILING_MM_S,
)
from humanpt.seam.sanitise import shown

FORMAT, VERSION = "humanpt.seam", 1

__all__ = ["FORMAT", "VERSION", "MAX_FILE_BYTES", "MAX_SEGMENTS", "SeamFileError", "SeamFile", "to_dict",
           "from_dict", "load_dict", "write", "read", "read_file"]

MAX_FILE_BYTES = 64 << 20  # a seam file, retimed samples and all (a day at 28 ms is about 30 MB)
MAX_SEGMENTS = 100_000


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


_REQUIRED = object()


def _real(d: dict, key: str, where: str, lo: float, hi: float, unit: str = "", default=_REQUIRED,
          lo_open: bool = False) -> float:
    """``d[key]``: a finite number within [lo, hi] (``(lo, hi]`` when ``lo_open``);
    ``default`` when absent or null (required when no default)."""
    v = d.get(key)
    if v is None:
        if default is _REQUIRED:
            raise SeamFileError(f"{where}: {key} is missing")
        return default
    u = f" {unit}" if unit else ""
    ok = isinstance(v, (int, float)) and not isinstance(v, bool)
    try:
        x = float(v) if ok else math.nan
    except OverflowError:
        x = math.inf
    if not (math.isfinite(x) and (lo < x if lo_open else lo <= x) and x <= hi):
        raise SeamFileError(f"{where}: {key} must be a finite number in {'(' if lo_open else '['}{lo:g}, "
                            f"{hi:g}]{u}, got {_short(v)}")
    return x


def _int(d: dict, key: str, where: str, lo: int = 0, hi: int = MAX_INDEX, default=_REQUIRED) -> int:
    v = d.get(key)
    if v is None and default is not _REQUIRED:
        return default
    if isinstance(v, float) and v.is_integer() and lo <= v <= hi:
        v = int(v)
    if not (isinstance(v, int) and not isinstance(v, bool) and lo <= v <= hi):
        raise SeamFileError(f"{where}: {key} must be a whole number in [{lo}, {hi}], got {_short(v)}")
    return v


def _ints(d: dict, key: str, where: str) -> tuple[int, ...]:
    v = d.get(key)
    if v is None:
        return ()
    if not isinstance(v, list):
        raise SeamFileError(f"{where}: {key} must be a list of point indices, got {_short(v)}")
    return tuple(_int({f"{key}[{i}]": k}, f"{key}[{i}]", where) for i, k in enumerate(v))


def _vec(d: dict, key: str, where: str, n: int = 3, bound: float = MAX_ABS_MM, unit: str = "mm"
         ) -> tuple[float, ...]:
    v = d.get(key)
    ok = isinstance(v, list) and len(v) == n and all(isinstance(x, (int, float)) and not isinstance(x, bool)
                                                     for x in v)
    if ok:
        try:
            out = tuple(float(x) for x in v)
        except OverflowError:
            ok = False
        else:
            ok = all(math.isfinite(x) and abs(x) <= bound for x in out)
    if not ok:
        raise SeamFileError(f"{where}: {key} must be {n} finite numbers within +-{bound:g} {unit}, "
                            f"got {_short(v)}")
    return out


def _short(v) -> str:
    """A value from the file for a one-line message: escaped, at most 60 characters."""
    s = shown(repr(v))
    return s if len(s) <= 60 else s[:57] + "..."


def _obj(v, where: str) -> dict:
    if not isinstance(v, dict):
        raise SeamFileError(f"{where}: must be an object ({{...}}), got {_short(v)}")
    return v


def _array(data: dict, key: str, where: str) -> list:
    """``data[key]``: a list (absent or null: empty)."""
    v = data.get(key)
    if v is None:
        return []
    if not isinstance(v, list):
        raise SeamFileError(f"{where}: {key} must be a list ([...]), got {_short(v)}")
    return v


def _segment(s: dict, w: str) -> Segment:
    kind = s.get("kind")
    if kind not in ("line", "arc"):
        raise SeamFileError(f"{w}: kind must be line or arc, got {_short(kind)}")
    sigma = _real(s, "sigma_mm", w, 0.0, MAX_ABS_MM, "mm", default=math.nan)
    kw = dict(kind=kind, first=_int(s, "first", w, default=0), last=_int(s, "last", w, default=0),
              start_mm=_vec(s, "start_mm", w), end_mm=_vec(s, "end_mm", w),
              start_ypr_deg=_vec(s, "start_ypr_deg", w, bound=MAX_ABS_DEG, unit="deg"),
              end_ypr_deg=_vec(s, "end_ypr_deg", w, bound=MAX_ABS_DEG, unit="deg"),
              residual_rms_mm=_real(s, "residual_rms_mm", w, 0.0, MAX_ABS_MM, "mm", default=math.nan),
              residual_max_mm=_real(s, "residual_max_mm", w, 0.0, MAX_ABS_MM, "mm", default=math.nan),
              points=_int(s, "points", w, default=0), outliers=_ints(s, "outliers", w), sigma_mm=sigma)
    doubt = s.get("doubt", "")
    if not isinstance(doubt, str) or len(doubt) > 2000:
        raise SeamFileError(f"{w}: doubt must be a text of at most 2000 characters, got {_short(doubt)}")
    kw["doubt"] = doubt
    if kind == "arc":
        r = _real(s, "radius_mm", w, MIN_ARC_RADIUS_MM, MAX_ABS_MM, "mm (an arc tighter than "
                  f"{MIN_ARC_RADIUS_MM:g} mm is a corner)")
        sw = _real(s, "sweep_deg", w, 0.0, 360.0, "deg", lo_open=True)
        if sw >= 360.0:
            raise SeamFileError(f"{w}: sweep_deg must be below 360, got {sw:g}")
        c = _vec(s, "centre_mm", w)
        normal = _vec(s, "normal", w, bound=MAX_ABS_MM, unit="")
        nn = math.sqrt(sum(x * x for x in normal))
        if nn < 1e-9:
            raise SeamFileError(f"{w}: normal must not be zero (the arc's plane), got {_short(s.get('normal'))}")
        n = tuple(x / nn for x in normal)
        d = [a - b for a, b in zip(kw["start_mm"], c, strict=True)]
        h = sum(a * b for a, b in zip(d, n, strict=True))
        rho = math.sqrt(max(sum(a * a for a in d) - h * h, 0.0))
        if rho < MIN_ARC_RADIUS_MM:
            raise SeamFileError(f"{w}: centre_mm is at start_mm ({rho:.3g} mm apart in the arc's plane; "
                                f"at least {MIN_ARC_RADIUS_MM:g}): the arc has no direction to start in")
        kw.update(centre_mm=c, normal=normal, radius_mm=r, sweep_deg=sw)
    return Segment(**kw)


def _feed(data: dict, source: str) -> float | None:
    """The seam's own feed (mm/s): ``retime.speed_mm_s``, else ``feed_mm_s``, else None."""
    rt = data.get("retime")
    if rt is not None:
        rt = _obj(rt, f"{source}: retime")
        if rt.get("speed_mm_s") is not None:
            return _real(rt, "speed_mm_s", f"{source}: retime", 0.0, SPEED_CEILING_MM_S, "mm/s", lo_open=True)
    if data.get("feed_mm_s") is not None:
        return _real(data, "feed_mm_s", source, 0.0, SPEED_CEILING_MM_S, "mm/s", lo_open=True)
    return None


def _samples(data: dict, source: str) -> tuple[tuple[float, np.ndarray], ...] | None:
    """A retimed seam's samples: ``retime.samples`` = [{"t_s": .., "x": [x, y, z, psi,
    theta, phi]}, ...] (s, mm, deg; times never going back), else None."""
    rt = data.get("retime")
    if not isinstance(rt, dict) or rt.get("samples") is None:
        return None
    out, last = [], -math.inf
    for i, s in enumerate(_array(rt, "samples", f"{source}: retime")):
        w = f"{source}: retime.samples[{i}]"
        s = _obj(s, w)
        t = _real(s, "t_s", w, 0.0, MAX_TIME_S, "s")
        x = _vec(s, "x", w, n=6, bound=MAX_ABS_MM, unit="(mm, deg)")
        if any(abs(a) > MAX_ABS_DEG for a in x[3:]):
            raise SeamFileError(f"{w}: x's angles must be within +-{MAX_ABS_DEG:g} deg, got {_short(list(x[3:]))}")
        if t < last:
            raise SeamFileError(f"{w}: t_s {t:g} goes back (the sample before: {last:g} s)")
        last = t
        out.append((t, np.asarray(x, dtype=float)))
    return tuple(out)


@dataclass(frozen=True)
class SeamFile:
    """A seam file as read: the seam, its own feed (mm/s; ``feed_mm_s`` or
    ``retime.speed_mm_s``, None when it has none) and its timed samples (``retime.samples``:
    (t s, (6,) mm and deg), None when not retimed)."""

    seam: Seam
    feed_mm_s: float | None = None
    samples: tuple[tuple[float, np.ndarray], ...] | None = None


def from_dict(data: dict, source: str = "seam") -> Seam:
    """The seam of a seam file's JSON; :class:`SeamFileError` naming the field (and
    ``source``) for anything out of place (see :func:`read_file`)."""
    return load_dict(data, source).seam


def load_dict(data: dict, source: str = "seam") -> SeamFile:
    source = shown(source)
    if not isinstance(data, dict) or data.get("format") != FORMAT:
        raise SeamFileError(f"{source}: not a humanpt seam file (no \"format\": \"{FORMAT}\")")
    if data.get("version") != VERSION:
        raise SeamFileError(f"{source}: seam file version {_short(data.get('version'))}; this humanpt reads {VERSION}")
    raw = _array(data, "segments", source)
    if len(raw) > MAX_SEGMENTS:
        raise SeamFileError(f"{source}: segments: {len(raw)} segments, at most {MAX_SEGMENTS}")
    segs = tuple(_segment(_obj(s, f"{source}: segments[{i}]"), f"{source}: segments[{i}]")
                 for i, s in enumerate(raw))
    if not segs:
        raise SeamFileError(f"{source}: the seam has no segments")
    corners = []
    for i, c in enumerate(_array(data, "corners", source)):
        w = f"{source}: corners[{i}]"
        c = _obj(c, w)
        if len(segs) < 2:
            raise SeamFileError(f"{w}: a corner joins two segments; the seam has one")
        before = _int(c, "before", w, 0, len(segs) - 2)
        after = _int(c, "after", w, before + 1, before + 1)
        corners.append(Corner(_vec(c, "point_mm", w), _real(c, "angle_deg", w, 0.0, 180.0, "deg"), before, after))
    dwells = []
    for i, d in enumerate(_array(data, "dwells", source)):
        w = f"{source}: dwells[{i}]"
        d = _obj(d, w)
        dwells.append(Dwell(_vec(d, "point_mm", w), _int(d, "first", w), _int(d, "last", w),
                            _real(d, "duration_s", w, 0.0, MAX_DWELL_S, "s")))
    fit = dict(_obj(data.get("fit") or {}, f"{source}: fit"))
    names = {f.name for f in dataclasses.fields(FitConfig)}
    try:
        cfg = FitConfig(**{k: v for k, v in fit.items() if k in names})
    except (FitError, TypeError, ValueError) as e:
        raise SeamFileError(f"{source}: fit: {shown(e)}") from None
    noise = _real(fit, "noise_mm", f"{source}: fit", 0.0, MAX_ABS_MM, "mm", default=math.nan)
    src = dict(_obj(data.get("source") or {}, f"{source}: source"))
    points = _int(src, "points", f"{source}: source", default=0)
    src.pop("points", None)
    if src.get("point") not in (None, "tip", "G"):
        raise SeamFileError(f"{source}: source: point must be tip or G, got {_short(src.get('point'))}")
    if src.get("frame") not in (None, "world"):
        raise SeamFileError(f"{source}: source: frame must be world (humanpt's), got {_short(src.get('frame'))}")
    seam = Seam(segs, tuple(corners), tuple(dwells), _ints(data, "outliers", source), noise, cfg, points, src,
                _ints(data, "corner_cut", source))
    return SeamFile(seam, _feed(data, source), _samples(data, source))


def write(path: str | Path, seam: Seam, overwrite: bool = False) -> Path:
    """Write the seam as JSON; never replaces an existing file unless ``overwrite`` (then
    atomically: a crash leaves the old file or the new one)."""
    path = Path(path)
    if path.exists() and not overwrite:
        raise SeamFileError(f"{shown(path)}: exists; give --overwrite to replace it")
    doc = to_dict(seam)
    load_dict(json.loads(json.dumps(doc)), str(path))  # what is written reads back: checked before writing
    write_atomic(path, json.dumps(doc, indent=1) + "\n")  # never through a planted link
    return path


def read(path: str | Path) -> Seam:
    """The seam of a seam file (:func:`read_file`)."""
    return read_file(path).seam


def read_file(path: str | Path) -> SeamFile:
    """A seam file, every field checked (finite, within :mod:`humanpt.seam.limits`, arcs
    with a plane and a radius, corners between neighbours, dwells, the feed and the
    timed samples); :class:`SeamFileError` naming the file and the field."""
    path = Path(path)
    name = shown(path)
    try:
        size = path.stat().st_size
        if size > MAX_FILE_BYTES:
            raise SeamFileError(f"{name}: {size} bytes; a seam file has at most {MAX_FILE_BYTES}")
        data = json.loads(path.read_text())
    except FileNotFoundError:
        raise SeamFileError(f"{name}: no such file") from None
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        raise SeamFileError(f"{name}: not JSON ({shown(e)})") from None
    except RecursionError:
        raise SeamFileError(f"{name}: not a seam file (JSON nested too deeply)") from None
    except ValueError as e:  # a number too long for Python's int, ...
        raise SeamFileError(f"{name}: not a seam file ({shown(e)})") from None
    except OSError as e:
        raise SeamFileError(f"{name}: cannot read ({shown(e.strerror or e)})") from None
    return load_dict(data, str(path))

"""The controller's live-shell adapter: writes recorded path points to CSV path files.

Every path point is appended (and flushed) to ``<path_dir>/path-<n>.csv`` as it arrives,
so a crash loses nothing; ``record_start`` opens a new file, ``save {"file": NAME}`` copies
the current one to ``<path_dir>/NAME`` (a plain name, checked by the core; an existing file
only with ``"overwrite": true``).  Nothing is ever truncated: a restarted controller in the
same run directory continues the numbering after the files already there.  What a save did
comes back to the core as a ``path_file`` input and goes out as an event (``path_saved`` or
``save_failed``).  The files are in mm and degrees, with each point's held-orientation
flag and covariance (see pathfile.py).
"""

from __future__ import annotations

import csv
import json
import logging
import re
import shutil
from pathlib import Path

import numpy as np

from humanpt.controller import pathfile
from humanpt.geometry.transforms import x_from_transform
from humanpt.schemas import humanpt_pb2 as pb
from humanpt.schemas.convert import from_pose

log = logging.getLogger("humanpt.controller")


def x_mm_deg(p: pb.Pose) -> np.ndarray:
    T = from_pose(p)
    T[:3, 3] *= 1e3
    return x_from_transform(T)


def covariance_mm_deg(msg: pb.PathPoint) -> dict:
    """A path point's held flag and covariances (3, 3) in mm^2 and deg^2 (None: not
    recorded), as :func:`pathfile.row` takes them."""
    def cov(values, scale):
        return np.asarray(values, dtype=float).reshape(3, 3) * scale if len(values) == 9 else None

    return {"orientation_held": msg.orientation_held, "cov_g_mm2": cov(msg.position_covariance_m2, 1e6),
            "cov_r_deg2": cov(msg.rotation_covariance_rad2, np.degrees(1.0) ** 2),
            "cov_tip_mm2": cov(msg.tip_position_covariance_m2, 1e6)}


class PathWriter:
    topics_out = ("controller/path", "controller/events")

    def __init__(self, path_dir: str | Path):
        self.dir = Path(path_dir)
        self.n = 0
        self.current: Path | None = None
        self._f = None
        self._w = None
        self._put = None

    def start(self, put) -> None:
        self._put = put
        self.dir.mkdir(parents=True, exist_ok=True)
        # A restart into the same run: continue after the files already there.
        taken = [int(m.group(1)) for p in self.dir.glob("path-*.csv")
                 if (m := re.fullmatch(r"path-(\d+)\.csv", p.name))]
        self.n = max(taken, default=0)

    def _open(self, with_tip: bool) -> None:
        self.close()
        while True:
            self.n += 1
            self.current = self.dir / f"path-{self.n}.csv"
            try:
                self._f = open(self.current, "x", newline="")  # noqa: SIM115 - closed in close()
                break
            except FileExistsError:  # never truncate a path file
                continue
        self._w = csv.writer(self._f)
        self._w.writerow(pathfile.header(with_tip, with_covariance=True))
        self._f.flush()
        log.info("recording path to %s", self.current)

    def _report(self, severity: int, code: str, text: str) -> None:
        (log.info if severity == pb.SEVERITY_INFO else log.warning)("%s", text)
        if self._put is not None:
            self._put("path_file", pb.Event(severity=severity, source="controller", code=code, text=text))

    def _save(self, request: dict) -> None:
        name, overwrite = str(request.get("file") or ""), bool(request.get("overwrite", False))
        dest = (self.dir / name).resolve()
        if not name or dest.parent != self.dir.resolve() or (self.dir / name).is_symlink():
            self._report(pb.SEVERITY_WARNING, "save_failed", f"save: {name!r} is not a file name in {self.dir}")
        elif self.current is None:
            self._report(pb.SEVERITY_WARNING, "save_failed", "save: no path recorded yet")
        elif dest == self.current.resolve():
            self._report(pb.SEVERITY_WARNING, "save_failed", f"save: {name} is the file being recorded")
        elif dest.exists() and not overwrite:
            self._report(pb.SEVERITY_WARNING, "save_failed",
                         f"save: {dest} exists; give overwrite to replace it")
        else:
            try:
                shutil.copyfile(self.current, dest)
            except OSError as e:
                self._report(pb.SEVERITY_WARNING, "save_failed", f"save: {dest}: {e}")
            else:
                self._report(pb.SEVERITY_INFO, "path_saved", f"path saved to {dest}")

    def write(self, topic: str, msg) -> None:
        if topic == "controller/events":
            if msg.code == "record_started":
                self._open(json.loads(msg.text or "{}").get("has_tip", False))
            elif msg.code == "save":
                self._save(json.loads(msg.text or "{}"))
            return
        if self._w is None:
            self._open(msg.has_tip)
        tip = x_mm_deg(msg.world_T_tip) if msg.has_tip else None
        self._w.writerow(pathfile.row(msg.index, msg.header.stamp_ns, x_mm_deg(msg.world_T_tob), tip,
                                      **covariance_mm_deg(msg)))
        self._f.flush()

    def close(self) -> None:
        if self._f is not None:
            self._f.close()
            self._f = None
            self._w = None


def adapters(config, run_dir=None) -> list:
    """Path files go to ``<run dir>/paths/`` next to the run's recordings."""
    return [PathWriter(Path(run_dir or ".") / "paths")]

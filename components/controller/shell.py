"""The controller's live-shell adapter: writes recorded path points to CSV path files.

Every path point is appended (and flushed) to ``<path_dir>/path-<n>.csv`` as it arrives,
so a crash loses nothing; ``record_start`` opens a new file, ``save {"file": F}`` copies
the current one to F.  The files are in mm and degrees (see pathfile.py).
"""

from __future__ import annotations

import csv
import json
import logging
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


class PathWriter:
    topics_out = ("controller/path", "controller/events")

    def __init__(self, path_dir: str | Path):
        self.dir = Path(path_dir)
        self.n = 0
        self.current: Path | None = None
        self._f = None
        self._w = None

    def start(self, put) -> None:
        self.dir.mkdir(parents=True, exist_ok=True)

    def _open(self, with_tip: bool) -> None:
        self.close()
        self.n += 1
        self.current = self.dir / f"path-{self.n}.csv"
        self._f = open(self.current, "w", newline="")  # noqa: SIM115 - closed in close()
        self._w = csv.writer(self._f)
        self._w.writerow(pathfile.header(with_tip))
        self._f.flush()
        log.info("recording path to %s", self.current)

    def write(self, topic: str, msg) -> None:
        if topic == "controller/events":
            if msg.code == "record_started":
                self._open(json.loads(msg.text or "{}").get("has_tip", False))
            elif msg.code == "save" and self.current is not None:
                dest = json.loads(msg.text or "{}").get("file") or ""
                if dest:
                    shutil.copyfile(self.current, dest)
                    log.info("path saved to %s", dest)
            return
        if self._w is None:
            self._open(msg.has_tip)
        tip = x_mm_deg(msg.world_T_tip) if msg.has_tip else None
        self._w.writerow(pathfile.row(msg.index, msg.header.stamp_ns, x_mm_deg(msg.world_T_tob), tip))
        self._f.flush()

    def close(self) -> None:
        if self._f is not None:
            self._f.close()
            self._f = None
            self._w = None


def adapters(config, run_dir=None) -> list:
    """Path files go to ``<run dir>/paths/`` next to the run's recordings."""
    return [PathWriter(Path(run_dir or ".") / "paths")]

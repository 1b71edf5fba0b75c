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

from humanpt.controller import pathfile
from humanpt.schemas import humanpt_pb2 as pb

log = logging.getLogger("humanpt.controller")


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
        p = pathfile.from_path_points([msg])
        self._w.writerow(pathfile.row(msg.index, msg.header.stamp_ns, p.x_g[0], None if p.x_tip is None else p.x_tip[0],
                                      orientation_held=bool(p.orientation_held[0]), cov_g_mm2=p.cov_g_mm2[0],
                                      cov_r_deg2=p.cov_r_deg2[0],
                                      cov_tip_mm2=None if p.cov_tip_mm2 is None else p.cov_tip_mm2[0]))
        self._f.flush()

    def close(self) -> None:
        if self._f is not None:
            self._f.close()
            self._f = None
            self._w = None


def adapters(config, run_dir=None) -> list:
    """Path files go to ``<run dir>/paths/`` next to the run's recordings."""
    return [PathWriter(Path(run_dir or ".") / "paths")]

"""Writers of user files never write through a planted symlink (issue 29, item 12).

The attack: ``write_rig`` wrote through ``rig.toml.bak`` and ``.rig.toml.tmp`` when they were
symlinks (both targets overwritten, and ``rig.toml`` became a symlink); ``path export`` the
same with ``OUT.tmp``. Here each writer runs with real symlinks planted at the names it used
(and at its output), pointing at victim files: the victims must be untouched, the written file
a regular file with the right content, and no temporary file left behind."""

from __future__ import annotations

import json
import os
import stat
from pathlib import Path

import numpy as np
import pytest

from humanpt.geometry.rig import Rig
from humanpt.runtime.files import atomic_open, write_atomic
from humanpt.runtime.recording import Recorder
from humanpt.runtime.rigfile import load_rig, write_rig
from humanpt.schemas import humanpt_pb2 as pb
from humanpt.schemas.convert import header
from tests.conftest import ROOT, run_cli_here

SEAM_FILE = ROOT / "tests" / "seam" / "data" / "export-seam.json"
VICTIM = b"the victim's own content\n"


def _victims(tmp_path: Path, *names: str) -> dict[str, Path]:
    """A victim file per planted link, outside the directory written to."""
    d = tmp_path / "elsewhere"
    d.mkdir(exist_ok=True)
    out = {}
    for n in names:
        v = d / f"victim-{n.strip('.')}"
        v.write_bytes(VICTIM)
        out[n] = v
    return out


def _plant(directory: Path, victims: dict[str, Path]) -> None:
    for name, victim in victims.items():
        (directory / name).symlink_to(victim)


def _untouched(victims: dict[str, Path]) -> None:
    for name, v in victims.items():
        assert v.read_bytes() == VICTIM, f"the victim of {name} was written to"


def _regular(p: Path) -> None:
    st = os.lstat(p)
    assert stat.S_ISREG(st.st_mode), f"{p} is not a regular file"


def _no_temp_left(d: Path, *keep: str) -> None:
    left = [p.name for p in d.iterdir() if p.name.endswith(".tmp") and p.name not in keep]
    assert not left, left


def test_write_rig_never_writes_through_its_backup_or_temporary_name(tmp_path):
    d = tmp_path / "cell"
    d.mkdir()
    rig_path = d / "rig.toml"
    write_rig(rig_path, Rig(name="old"))
    old = rig_path.read_bytes()
    victims = _victims(tmp_path, "rig.toml.bak", ".rig.toml.tmp")
    _plant(d, victims)
    write_rig(rig_path, Rig(name="new"), overwrite=True)
    _untouched(victims)
    _regular(rig_path)
    assert load_rig(rig_path).name == "new"
    _regular(d / "rig.toml.bak")
    assert (d / "rig.toml.bak").read_bytes() == old  # the previous rig, kept
    _no_temp_left(d, ".rig.toml.tmp")
    assert (d / ".rig.toml.tmp").is_symlink()  # the planted name itself is left alone


def test_write_rig_over_a_rig_that_is_a_link_replaces_the_link(tmp_path):
    """Overwriting ``rig.toml`` that is a link writes a file there, never into its target."""
    d = tmp_path / "cell"
    d.mkdir()
    victims = _victims(tmp_path, "rig.toml")
    _plant(d, victims)
    with pytest.raises(FileExistsError):
        write_rig(d / "rig.toml", Rig(name="new"))
    write_rig(d / "rig.toml", Rig(name="new"), overwrite=True)
    _untouched(victims)
    _regular(d / "rig.toml")
    assert load_rig(d / "rig.toml").name == "new"


@pytest.mark.parametrize("fmt", ["krl", "json"])
def test_path_export_never_writes_through_out_tmp(tmp_path, fmt):
    d = tmp_path / "out"
    d.mkdir()
    out = d / ("seam.src" if fmt == "krl" else "seam.program.json")
    victims = _victims(tmp_path, out.name + ".tmp")
    _plant(d, victims)
    r = run_cli_here("path", "export", str(SEAM_FILE), "--format", fmt, "-o", str(out))
    assert r.returncode == 0, r.stdout + r.stderr
    _untouched(victims)
    _regular(out)
    if fmt == "json":
        assert json.loads(out.read_text())
    else:
        assert "LIN" in out.read_text() or "CIRC" in out.read_text()
    _no_temp_left(d, out.name + ".tmp")


def test_seam_and_retime_writers_never_write_through_their_temporary_names(tmp_path):
    from humanpt.seam import retime, seamfile

    seam = seamfile.read(SEAM_FILE)
    d = tmp_path / "w"
    d.mkdir()
    victims = _victims(tmp_path, "s.json.tmp", "s.timed.csv.tmp")
    _plant(d, victims)
    seamfile.write(d / "s.json", seam)
    timed = retime.retime(seam, retime.RetimeConfig(speed_mm_s=30.0))
    retime.write_csv(d / "s.timed.csv", timed)
    _untouched(victims)
    for name in ("s.json", "s.timed.csv"):
        _regular(d / name)
    assert seamfile.read(d / "s.json").segments == seam.segments
    rows = (d / "s.timed.csv").read_text().splitlines()
    assert rows[0].startswith("index,t_s") and len(rows) == len(timed.t_s) + 1
    _no_temp_left(d, "s.json.tmp", "s.timed.csv.tmp")


def test_path_smooth_and_val_never_write_through_a_link_at_their_output(tmp_path):
    """A dangling link at the output name passes the "exists" check: writing must replace
    it, not create (or fill) what it points at."""
    from humanpt.controller import pathfile

    src = tmp_path / "p.csv"
    t = np.arange(20) * 0.1
    x = np.zeros((20, 6))
    x[:, 0] = 10 * t
    pathfile.write(src, pathfile.Path6(np.arange(20), (t * 1e9).astype(np.int64), x))
    d = tmp_path / "o"
    d.mkdir()
    for verb, name in (("smooth", "s.csv"), ("val", "s.v2")):
        target = tmp_path / f"not-yet-{name}"  # dangling: created only by writing through
        (d / name).symlink_to(target)
        r = run_cli_here("path", verb, str(src), str(d / name))
        assert r.returncode == 0, r.stdout + r.stderr
        assert not target.exists(), f"path {verb} wrote through the link"
        _regular(d / name)
    assert len(pathfile.read(d / "s.csv")) == 20


def test_the_losses_file_never_goes_through_its_temporary_name(tmp_path):
    rec = Recorder(tmp_path / "ponger.mcap", {"component": "ponger"})
    victims = _victims(tmp_path, "ponger.losses.json.tmp")
    _plant(tmp_path, victims)
    for i in range(3):
        rec.write("out", i, "ponger/pong", pb.Event(header=header(i, seq=i), code="pong"))
    rec._fail(OSError(28, "No space left on device"))  # what a full disk makes the writer do
    rec.close()
    _untouched(victims)
    _regular(tmp_path / "ponger.losses.json")
    assert json.loads((tmp_path / "ponger.losses.json").read_text())["lost"] == 3


def test_write_atomic_leaves_the_old_file_when_writing_fails(tmp_path):
    p = tmp_path / "f.txt"
    p.write_text("old\n")
    with pytest.raises(RuntimeError), atomic_open(p) as f:
        f.write("half of the new")
        raise RuntimeError("the writer failed half-way")
    assert p.read_text() == "old\n"
    assert [q.name for q in tmp_path.iterdir()] == ["f.txt"]  # no temporary file left
    write_atomic(p, "new\n", backup=True)
    assert p.read_text() == "new\n" and (tmp_path / "f.txt.bak").read_text() == "old\n"

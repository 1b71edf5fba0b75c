"""Recordings are never truncated and replay never imports what a recording names (issue 14,
items 9 and 11)."""

from __future__ import annotations

import humanpt
from humanpt.runtime.recording import IN, OUT, Recorder, read
from humanpt.runtime.selftest import PongerConfig, PongerCore
from humanpt.schemas import humanpt_pb2 as pb
from humanpt.schemas.convert import header
from tests.conftest import run_cli


def _record(path, core="humanpt.runtime.selftest:PongerCore", n=3):
    rec = Recorder(path, {"component": "ponger", "core": core, "config": {"prefix": "pong"},
                          "version": humanpt.__version__})
    core = PongerCore(PongerConfig())
    for i in range(n):
        ping = pb.Tick(header=header(i, i))
        rec.write(IN, 10 + i, "pinger/ping", ping)
        for topic, msg in core.step(10 + i, "pinger/ping", ping):
            rec.write(OUT, 10 + i, topic, msg)
    rec.close()
    return rec.path


def test_a_restarted_recorder_writes_a_new_segment_and_keeps_the_first(tmp_path):
    first = _record(tmp_path / "ponger.mcap", n=5)
    before = first.read_bytes()
    second = _record(tmp_path / "ponger.mcap", n=2)  # the component restarted into the run
    third = _record(tmp_path / "ponger.mcap", n=1)
    assert first.read_bytes() == before
    assert (second.name, third.name) == ("ponger.1.mcap", "ponger.2.mcap")
    assert [len(read(p).inputs) for p in (first, second, third)] == [5, 2, 1]


def test_replay_never_imports_the_module_a_recording_names(tmp_path):
    """The attack: a recording naming a planted module, replayed next to it, ran its code."""
    marker = tmp_path / "pwned"
    (tmp_path / "planted.py").write_text(f"open({str(marker)!r}, 'w').write('ran')\nclass Core: pass\n")
    rec = _record(tmp_path / "ponger.mcap", core="planted:Core")
    r = run_cli("replay", str(rec), cwd=tmp_path)  # the planted module is importable from here
    assert r.returncode != 0
    assert "not a component of this version" in r.stdout + r.stderr
    assert not marker.exists(), "replay imported and ran the planted module"


def test_replay_of_a_known_component_still_works(tmp_path):
    rec = _record(tmp_path / "ponger.mcap")
    r = run_cli("replay", str(rec))
    assert r.returncode == 0 and "MATCH" in r.stdout, r.stdout + r.stderr

"""Snapshots (issue 30 item 6, DESIGN "State that matters for replay can be snapshotted into
the log"): a core freezes its state into its recording, replay starts from the nearest
snapshot, and a crafted snapshot is refused with one line, nothing in it executed.

The lock-step twin's cores: tests/runtime/test_snapshots_twin.py."""

from __future__ import annotations

import dataclasses
import enum
import json
import math
from collections import OrderedDict, defaultdict, deque
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from humanpt.runtime.config import RecordConfig
from humanpt.runtime.core import Core
from humanpt.runtime.lockstep import Lockstep
from humanpt.runtime.recording import IN, SNAPSHOT, Recorder, RecordingError, SnapshotEntry, read
from humanpt.runtime.registry import COMPONENTS, core_class
from humanpt.runtime.replay import build_core, replay, replay_recording
from humanpt.runtime.selftest import PingerConfig, PingerCore, PongerConfig, PongerCore
from humanpt.runtime.snapshot import FORMAT, SnapshotError, dumps, loads, snapshot_bytes
from humanpt.schemas import humanpt_pb2 as pb

PERIOD_S = 2.0
END_S = 25.0


def _run(run_dir: Path, period_s: float = PERIOD_S, end_s: float = END_S) -> Lockstep:
    """Pinger (20 ms, then 10 ms) and ponger (its prefix changed live: a config change the
    snapshots carry), recorded with a snapshot every ``period_s``."""
    with Lockstep([PingerCore(PingerConfig(period_ms=20)), PongerCore(PongerConfig())], run_dir=run_dir,
                  record=RecordConfig(snapshot_period_s=period_s)) as ls:
        ls.set_param(500_000_000, "ponger", "prefix", '"PONG"')
        ls.set_param(700_000_000, "pinger", "period_ms", "10")
        ls.run_until(int(end_s * 1e9))
    return ls


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("snap")
    _run(d)
    return d


def test_every_recording_holds_a_snapshot_per_period_of_input_time(run_dir):
    for comp in ("pinger", "ponger"):
        rec = read(run_dir / f"{comp}.mcap")
        first_in = rec.inputs[0].t_ns
        # One after the first input at or past each 2 s of input time from the first input:
        # 12 in the 25 s run (2, 4, ... 24 s).
        assert len(rec.snapshots) == math.floor((END_S * 1e9 - first_in) / (PERIOD_S * 1e9)) == 12
        for k, s in enumerate(rec.snapshots, 1):
            assert first_in + k * PERIOD_S * 1e9 <= s.t_ns < first_in + k * PERIOD_S * 1e9 + 20e6
            table = json.loads(s.data)
            assert table["format"] == FORMAT and table["component"] == comp and table["t_ns"] == s.t_ns
            # After the input it follows and that input's outputs, before the next input.
            assert table["inputs"] == sum(1 for e in rec.entries[:s.at] if e.direction == IN)
            assert rec.entries[s.at - 1].t_ns <= s.t_ns and (s.at == len(rec.entries) or
                                                              rec.entries[s.at].direction == IN)
    # The live parameter change is in the ponger's frozen config.
    last = json.loads(read(run_dir / "ponger.mcap").snapshots[-1].data)
    assert last["core"]["config"]["prefix"] == "PONG"


def test_the_last_seconds_replay_from_the_nearest_snapshot_and_match(run_dir):
    for comp in ("pinger", "ponger"):
        full = replay(run_dir / f"{comp}.mcap")
        res = replay(run_dir / f"{comp}.mcap", last_s=3.0)
        assert res.match, res.report()
        # The last input is at 25 s: the snapshot at or before 22 s is the one at 22 s (period 2 s).
        assert "from the snapshot at t_ns=22" in res.report()
        # 3 s of 25 s at a ping per 10 ms: ~300 inputs replayed of ~2400.
        assert 250 < res.inputs < 350 < full.inputs
        assert 250 < res.compared < 350
    # The ponger's counter came from the snapshot: its pongs after it go on counting.
    res = replay(run_dir / "ponger.mcap", start_s=20.0)
    assert res.match and "t_ns=20" in res.report()


def test_the_snapshot_is_what_replay_starts_from_a_fresh_state_diverges(run_dir):
    """Could fail: the outputs after a snapshot depend on the state thawed (the ponger's
    count, the per-topic sequence numbers), so a fresh core's state in its place diverges."""
    rec = read(run_dir / "ponger.mcap")
    snap = rec.snapshots[-1]
    table = json.loads(snap.data)
    fresh = build_core(rec)
    forged = SnapshotEntry(snap.at, snap.t_ns, snapshot_bytes(fresh, snap.t_ns, table["inputs"]))
    recorded, replayed = replay_recording(read(run_dir / "ponger.mcap"), snapshot=forged)
    assert recorded and recorded != replayed
    recorded, replayed = replay_recording(read(run_dir / "ponger.mcap"), snapshot=snap)
    assert recorded == replayed


def test_no_snapshot_replays_from_the_start_and_says_so(tmp_path):
    _run(tmp_path, period_s=0.0, end_s=3.0)
    rec = read(tmp_path / "ponger.mcap")
    assert rec.snapshots == []
    res = replay(tmp_path / "ponger.mcap", last_s=1.0)
    assert res.match and res.inputs == len(rec.inputs)
    assert "no snapshot at or before 1 s before the last input: replayed from the start" in res.report()


def test_readers_of_the_messages_never_see_the_snapshots(run_dir):
    from humanpt.runtime.runinfo import run_info

    rec = read(run_dir / "ponger.mcap")
    assert all(e.direction != SNAPSHOT for e in rec.entries)
    assert rec.truncated is None  # the summary's count includes them: not "n of m messages read"
    info = {f.component: f for f in run_info(run_dir)}["ponger"]
    assert not info.notes and {d for d, _ in info.topics} == {"in", "out"}


def test_the_cli_replays_the_last_seconds(run_dir, cli_main, capsys):
    assert cli_main(["replay", str(run_dir), "--component", "ponger", "--last", "3"]) == 0
    out = capsys.readouterr().out
    assert "from the snapshot at t_ns=22" in out and "MATCH" in out


# -- crafted snapshots ---------------------------------------------------------------------------


def _rewrite(src: Path, dst: Path, craft) -> Path:
    """``src`` copied to ``dst`` with the table of its last snapshot replaced by
    ``craft(table)`` (bytes are written as they are)."""
    rec = read(src)
    meta = dict(rec.metadata)
    with Recorder(dst, meta) as out:
        last = rec.snapshots[-1]
        for s_i, e in enumerate(rec.entries + [None]):
            for s in rec.snapshots:
                if s.at == s_i:
                    data = s.data
                    if s is last:
                        crafted = craft(json.loads(s.data))
                        data = crafted if isinstance(crafted, bytes) else json.dumps(crafted).encode()
                    out.write_snapshot(s.t_ns, data)
            if e is not None:
                out.write(e.direction, e.t_ns, e.topic, e.decode(), e.data)
    return dst


def _set(path: str, value):
    def craft(t):
        node = t
        keys = path.split("/")
        for k in keys[:-1]:
            node = node[k]
        node[keys[-1]] = value
        return t
    return craft


def _delete(path: str):
    def craft(t):
        node = t
        keys = path.split("/")
        for k in keys[:-1]:
            node = node[k]
        del node[keys[-1]]
        return t
    return craft


_DEEP = b'{"format":"' + FORMAT.encode() + b'","t_ns":1,"inputs":1,"core":' + b"[" * 100_000 + b"]" * 100_000 + b"}"

CRAFTED = {
    "wrong type": (_set("core/state/pings", "many"), "ponger.pings: a str where this core holds a number"),
    "huge array": (_set("core/state/pings", {"a": {"dtype": "float64", "shape": [1 << 20, 1 << 20], "data": ""},
                                             "id": 990}), "larger than 16777216 elements"),
    "array data short": (_set("core/state/pings", {"a": {"dtype": "float64", "shape": [4, 4], "data": ""},
                                                   "id": 990}), "0 bytes of data for 16 elements of float64"),
    "object array": (_set("core/state/pings", {"a": {"dtype": "object", "shape": [1], "data": ""}, "id": 990}),
                     "dtype 'object' refused"),
    "unknown field": (_set("core/state/extra", 1), "unknown field 'extra' in the snapshot"),
    "missing field": (_delete("core/state/pings"), "field 'pings' missing from the snapshot"),
    "class not held": (_set("core/state/pings", {"o": {"cls": "Popen", "attrs": {"args": "rm -rf /"}}, "id": 990}),
                       "class 'Popen' is not one this core holds; nothing named by a snapshot is imported"),
    "foreign message": (_set("core/state/pings", {"pb": {"type": "google.protobuf.Any", "data": ""}}),
                        "message type 'google.protobuf.Any' is not one of humanpt's schemas"),
    "unknown tag": (_set("core/state/pings", {"exec": "print(1)"}), "unknown tag 'exec'"),
    "a function": (_set("core/state/pings", {"fn": "os.system"}), "a function (os.system) where this core holds none"),
    "unknown config key": (_set("core/config/extra_key", 1), "the snapshot's config has an unknown key 'extra_key'"),
    "bad live value": (_set("core/config/prefix", 5), "the snapshot's config: prefix"),
    "header field": (_set("shell", "x"), "unknown field 'shell'"),
    "format": (_set("format", "pickle"), "format 'pickle', this version reads"),
    "position": (_set("inputs", 3), "it follows input #3"),
    "other component": (_set("component", "pinger"), "it is of component 'pinger'"),
    "not json": (lambda t: b"\x80\x04\x95 pickle", "not JSON"),
    "nested too deeply": (lambda t: _DEEP, "nested too deeply"),
}


@pytest.mark.parametrize("case", sorted(CRAFTED))
def test_a_crafted_snapshot_is_refused_with_one_line(run_dir, tmp_path, case):
    craft, expected = CRAFTED[case]
    bad = _rewrite(run_dir / "ponger.mcap", tmp_path / "ponger.mcap", craft)
    with pytest.raises(RecordingError) as exc:
        replay(bad, last_s=1.0)
    text = str(exc.value)
    assert "\n" not in text and len(text) < 400, text
    assert text.startswith(f"{bad}: the snapshot at t_ns=") and expected in text, text
    # The snapshots before it are sound: replay from one of them still matches.
    assert replay(bad, start_s=20.0).match


def test_the_cli_refuses_a_crafted_snapshot_in_one_line(run_dir, tmp_path, cli_main, capsys):
    bad = _rewrite(run_dir / "ponger.mcap", tmp_path / "ponger.mcap",
                   _set("core/state/pings", {"o": {"cls": "Popen", "attrs": {}}, "id": 990}))
    assert cli_main(["replay", str(bad), "--last", "1"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err
    assert err.startswith(f"humanpt replay: cannot replay {bad}: {bad}: the snapshot at t_ns=24") and "Popen" in err


# -- the encoding, on a core of every kind of state --------------------------------------------


class Colour(enum.Enum):
    RED = "red"
    BLUE = "blue"


@dataclass(frozen=True)
class Item:
    t_ns: int
    where: np.ndarray
    colour: Colour


@dataclass(frozen=True)
class _Cfg:
    gain: float = 1.0


class _Stateful(Core):
    name = "pinger"
    config_type = _Cfg
    state_types = (Item,)

    def __init__(self, config):
        super().__init__(config)
        self.shared = [1, 2]
        self.again = self.shared  # the same list: stays the same after a thaw
        self.x = np.float64(0.5)
        self.n = np.int32(3)
        self.values = {1: math.nan, (2, "b"): math.inf, "c": -0.0}
        self.counts = defaultdict(int)
        self.q = deque(maxlen=3)
        self.od = OrderedDict(b=1, a=2)
        self.items: deque[Item] = deque()
        self.blob = b"\x00\xff"
        self.buf = bytearray(b"ab")
        self.tags = {"a", "b"}
        self.msg = pb.Tick(period_ns=5)
        self.matrix = np.arange(12, dtype=np.float32).reshape(3, 4)
        self.nones = np.array([[None] * 3]).T  # filterpy's z before the first update
        self.colour = Colour.RED


def test_every_kind_of_state_survives_a_round_trip():
    a = _Stateful(_Cfg())
    a.counts["x"] += 2
    a.q.extend([1, 2, 3, 4])
    a.items.append(Item(7, np.ones(3), Colour.BLUE))
    a.shared.append(3)
    a.x = np.float64(1.25)
    a.colour = Colour.BLUE
    data = dumps(a.freeze())
    b = _Stateful(_Cfg())
    b.thaw(loads(data))
    assert dumps(b.freeze()) == data
    assert b.again is b.shared and b.shared == [1, 2, 3]
    assert type(b.x) is np.float64 and b.x == 1.25 and type(b.n) is np.int32
    assert math.isnan(b.values[1]) and b.values[(2, "b")] == math.inf and math.copysign(1, b.values["c"]) < 0
    assert isinstance(b.counts, defaultdict) and b.counts["x"] == 2 and b.counts["new"] == 0
    assert b.q.maxlen == 3 and list(b.q) == [2, 3, 4]
    assert type(b.od) is OrderedDict and list(b.od) == ["b", "a"]
    assert b.items[0].colour is Colour.BLUE and b.items[0].where.tolist() == [1, 1, 1]
    assert dataclasses.is_dataclass(b.items[0]) and type(b.items[0]) is Item
    assert b.blob == a.blob and b.buf == a.buf and b.tags == a.tags and b.msg == a.msg
    assert b.matrix.dtype == np.float32 and (b.matrix == a.matrix).all() and b.matrix.flags.writeable
    assert b.nones.shape == (3, 1) and b.nones.dtype == object and b.colour is Colour.BLUE


def test_a_state_that_cannot_be_frozen_stops_the_snapshots_not_the_core(tmp_path):
    """A core holding something the encoding does not take (a generator here): the shell
    records no snapshot, says so once, and the run goes on."""
    from humanpt.runtime.snapshot import Snapshotter

    a = _Stateful(_Cfg())
    a.gen = (i for i in range(3))
    with pytest.raises(SnapshotError, match=r"pinger.gen: a builtins.generator cannot be frozen"):
        a.freeze()
    snap = Snapshotter(1.0)
    assert snap.after_input(a, 0) is None and snap.after_input(a, 2_000_000_000) is None
    assert snap.inputs == 2 and snap.written == 0 and "pinger.gen" in snap.error
    assert snap.news() and not snap.news()


def test_an_object_may_not_set_a_dunder_attribute():
    a = _Stateful(_Cfg())
    a.items.append(Item(7, np.ones(3), Colour.BLUE))
    frozen = loads(dumps(a.freeze()))
    item = frozen["state"]["items"]["q"]["items"][0]["o"]
    item["attrs"]["__class__"] = {"ref": 0}
    with pytest.raises(SnapshotError, match=r"^pinger.items\[0\]: attribute name '__class__' refused$"):
        _Stateful(_Cfg()).thaw(frozen)


def test_a_snapshot_may_not_loosen_a_safety_limit_or_change_a_fixed_key():
    """The config a snapshot carries is applied as parameter changes would be: a safety limit
    only stricter than the recorded start value (the gateway's 100 mm/s, cell_limits), a key
    that is not live not at all."""
    cls = core_class("robot_gateway")
    frozen = loads(dumps(cls.create(cls.default_config()).freeze()))
    frozen["config"]["max_speed_mm_s"] = 200.0
    with pytest.raises(SnapshotError, match=r"^robot_gateway: the snapshot's config: max_speed_mm_s: 200.0 is "
                                            r"above the hard limit 100.0"):
        cls.create(cls.default_config()).thaw(frozen)
    frozen["config"]["max_speed_mm_s"] = 50.0
    core = cls.create(cls.default_config())
    core.thaw(frozen)
    assert core.config.max_speed_mm_s == 50.0 and core.start_config.max_speed_mm_s == 100.0
    pinger = loads(dumps(PingerCore(PingerConfig()).freeze()))
    pinger["config"]["payload_note"] = "other"
    with pytest.raises(SnapshotError, match=r"^pinger: the snapshot's config changes 'payload_note', which is not a "
                                            r"live parameter$"):
        PingerCore(PingerConfig()).thaw(pinger)


@pytest.mark.parametrize("name", sorted(COMPONENTS))
def test_every_component_thaws_its_built_state(name):
    """Every registered core (camera and viz too, which the twin's run has not) freezes as
    built, and a fresh one thaws it to the same state; the twin's cores after 60 s:
    test_snapshots_twin.py."""
    cls = core_class(name)
    data = dumps(cls.create(cls.default_config()).freeze())
    core = cls.create(cls.default_config())
    core.thaw(loads(data))
    assert dumps(core.freeze()) == data


class _Cb:
    def __init__(self):
        self.n = 0
        self.on = self.bump  # a method of its own, held: bound to the new object after a thaw

    def bump(self):
        self.n += 1


class _Holder(Core):
    name = "pinger"
    config_type = _Cfg

    def __init__(self, config):
        super().__init__(config)
        self.cb = _Cb()
        self.later: list = []  # a _Cb made later: built from the class the core holds


def test_a_method_an_object_holds_is_bound_to_the_thawed_object():
    a = _Holder(_Cfg())
    a.cb.on()
    a.later.append(_Cb())
    b = _Holder(_Cfg())
    b.thaw(loads(dumps(a.freeze())))
    for cb in (b.cb, b.later[0]):
        n = cb.n
        cb.on()
        assert cb.on.__self__ is cb and cb.n == n + 1
    assert b.cb.n == 2 and b.later[0].n == 1

"""Issue 30 item 2: the link owns the cycle.

The robot link's cycle period ([robot_gateway] cycle_period_ms) is the cell's only cycle: the
gateway puts it in every RobotState, the controller, the pose filter and the viewer take it
from there, the simulated robot from the link's config; the keys that once copied it are a
deprecation note when equal to the link's and an error naming the key when not
(humanpt.runtime.cycle).  Expected values come from the link's config (12 ms, 28 ms) and
hand arithmetic (100 mm/s x 12 ms = 1.2 mm)."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from humanpt.controller.config import ControllerConfig
from humanpt.controller.core import ControllerCore
from humanpt.pose_filter.config import PoseFilterConfig
from humanpt.pose_filter.core import PoseFilterCore
from humanpt.runtime import cycle
from humanpt.runtime.config import ConfigError, from_dict
from humanpt.runtime.recording import read
from humanpt.runtime.registry import config_types
from humanpt.runtime.replay import build_core, fields_newer_than
from humanpt.schemas import humanpt_pb2 as pb
from humanpt.schemas.convert import header, pose
from humanpt.sim_robot.config import SimRobotConfig
from tests.conftest import ROOT, run_cli_here
from tests.robot_gateway.rig import Rig

MS = 1_000_000
RSI_12 = {"robot_gateway": {"link": "rsi", "cycle_period_ms": 12.0, "udp_bind": "127.0.0.1:49152"}}


def _toml(sections: dict) -> str:
    out = []
    for name, table in sections.items():
        out.append(f"[{name}]")
        out += [f"{k} = {v!r}" if not isinstance(v, str) else f'{k} = "{v}"' for k, v in table.items()]
    return "\n".join(out) + "\n"


# -- acceptance: grep and config --check -------------------------------------------------------
def test_only_the_link_config_has_a_cycle_period_ms():
    # `grep -rn "cycle_period_ms" components/*/config.py` finds only the link's
    hits = sorted(str(p.relative_to(ROOT)) for p in (ROOT / "components").glob("*/config.py")
                  if "cycle_period_ms" in p.read_text())
    assert hits == ["components/robot_gateway/config.py"], hits


def test_config_check_of_a_12_ms_rsi_cell_without_sim_robot_is_ok_and_shows_the_one_cycle(tmp_path):
    path = tmp_path / "cell.toml"
    path.write_text(_toml(RSI_12))  # no [sim_robot], no [controller], no [pose_filter]
    r = run_cli_here("config", "--config", str(path), "--check")
    assert r.returncode == 0, r.stderr
    assert f"{path}: OK" in r.stdout and "Traceback" not in r.stderr
    assert "cycle: 12 ms, the robot link's ([robot_gateway] link = 'rsi'" in r.stdout, r.stdout
    # every use of the cycle listed, each at the link's 12 ms (never a default 28)
    for name, _ in cycle.USES:
        assert re.search(rf"^  {name} +12 ms: ", r.stdout, re.M), (name, r.stdout)
    assert "28" not in r.stdout.split("\n", 1)[1], r.stdout


def test_the_resolved_cell_gives_the_simulated_robot_the_links_cycle():
    cfg = from_dict(RSI_12, "cell.toml", config_types())
    assert cfg.cycle_period_ns == 12 * MS and cfg.cycle_link == "rsi"
    assert cfg.component("sim_robot", SimRobotConfig).cycle_period_ns == 12 * MS
    assert from_dict({}, "alter.toml", config_types()).component("sim_robot", SimRobotConfig).cycle_period_ns \
        == 28 * MS  # ALTER, the paper's
    # a [sim_robot] table repeating the link's cycle is fine, changing it is not
    ok = {**RSI_12, "sim_robot": {"cycle_period_ns": 12 * MS}}
    assert from_dict(ok, "c.toml", config_types()).component("sim_robot", SimRobotConfig).cycle_period_ns == 12 * MS
    with pytest.raises(ConfigError, match=r"c.toml: \[sim_robot\] cycle_period_ns = 4000000: the simulated robot "
                                          r"runs the link's cycle, 12 ms"):
        from_dict({**RSI_12, "sim_robot": {"cycle_period_ns": 4 * MS}}, "c.toml", config_types())


# -- old configs -----------------------------------------------------------------------------------
@pytest.mark.parametrize("section,key", sorted(cycle.RETIRED))
def test_an_old_cycle_key_that_differs_from_the_link_is_an_error_naming_it(tmp_path, section, key):
    path = tmp_path / "old.toml"
    path.write_text(_toml({**RSI_12, section: {key: 28.0}}))
    r = run_cli_here("config", "--config", str(path), "--check")
    assert r.returncode != 0 and "Traceback" not in r.stderr, r.stderr
    assert len(r.stderr.strip().splitlines()) == 1, r.stderr
    assert f"{path}: [{section}] {key} = 28 differs from the link's cycle" in r.stderr, r.stderr
    assert "[robot_gateway] cycle_period_ms = 12" in r.stderr and f"remove {key}" in r.stderr, r.stderr


def test_an_old_controller_cycle_equal_to_the_links_is_a_deprecation_note(tmp_path):
    path = tmp_path / "old.toml"
    path.write_text(_toml({**RSI_12, "controller": {"cycle_period_ms": 12.0}, "pose_filter": {"predict_ahead_ms": 12}}))
    r = run_cli_here("config", "--config", str(path), "--check")
    assert r.returncode == 0, r.stderr
    assert f"note: {path}: [controller] cycle_period_ms = 12 is deprecated and ignored" in r.stderr, r.stderr
    assert f"note: {path}: [pose_filter] predict_ahead_ms = 12 is deprecated and ignored" in r.stderr, r.stderr
    cfg = from_dict({**RSI_12, "controller": {"cycle_period_ms": 12.0}}, "old.toml", config_types())
    assert "cycle_period_ms" not in cfg.sections["controller"]  # dropped: the controller builds
    cfg.component("controller", ControllerConfig)


def test_an_old_viz_or_sim_robot_cycle_that_is_not_a_number_is_an_error():
    with pytest.raises(ConfigError, match=r"\[viz\] cycle_period_ms = 'fast': no longer a key"):
        from_dict({"viz": {"cycle_period_ms": "fast"}}, "old.toml", config_types())


def test_the_controller_gains_are_checked_at_the_links_cycle():
    # k dt < 0.5: 20/s x 28 ms = 0.56 is refused over ALTER, 20/s x 12 ms = 0.24 is fine over RSI
    with pytest.raises(ConfigError, match=r"\[controller\] gain_translation_1_s = 20.0 must be < 17.9 at the "
                                          r"link's 28 ms cycle"):
        from_dict({"controller": {"gain_translation_1_s": 20.0}}, "c.toml", config_types())
    from_dict({**RSI_12, "controller": {"gain_translation_1_s": 20.0}}, "c.toml", config_types())


# -- the cycle travels in the robot state --------------------------------------------------------
def _gateway_states(**link) -> list[pb.RobotState]:
    rig = Rig(**link)
    for _ in range(3):
        rig.status()
        rig.advance(rig.cycle_ns)
    return rig.states()


@pytest.mark.parametrize("link,cycle_ns", [({"link": "rsi", "cycle_period_ms": 12.0}, 12 * MS),
                                           ({"link": "rsi", "cycle_period_ms": 4.0}, 4 * MS),
                                           ({"link": "alter"}, 28 * MS)])
def test_the_gateway_puts_its_links_cycle_in_every_robot_state(link, cycle_ns):
    states = _gateway_states(**link)
    assert len(states) >= 3 and {s.cycle_period_ns for s in states} == {cycle_ns}


def _tob_state_after(core: PoseFilterCore, state: pb.RobotState) -> pb.TobState:
    outs = core.step(state.header.stamp_ns, "robot_gateway/robot_state", state)
    return next(m for t, m in outs if t == "pose_filter/tob_state")


def test_the_pose_filters_horizon_follows_a_12_ms_link():
    state = _gateway_states(link="rsi", cycle_period_ms=12.0)[-1]
    core = PoseFilterCore(PoseFilterConfig())
    st = _tob_state_after(core, state)
    assert st.header.stamp_ns - state.header.stamp_ns == 12 * MS  # one 12 ms cycle ahead, not 28
    # the same filter behind an ALTER link: 28 ms
    alter = _gateway_states(link="alter")[-1]
    st = _tob_state_after(PoseFilterCore(PoseFilterConfig()), alter)
    assert st.header.stamp_ns - alter.header.stamp_ns == 28 * MS


def test_a_state_without_a_cycle_falls_back_and_an_absurd_one_is_not_believed():
    core = PoseFilterCore(PoseFilterConfig())
    t = 10**9
    old = pb.RobotState(header=header(t), world_T_flange=pose(np.eye(4)), cycle=1)  # 0: an old recording's
    assert _tob_state_after(core, old).header.stamp_ns - t == cycle.FALLBACK_NS
    core.use_cycle(12 * MS)  # what replay does with an old recording's predict_ahead_ms = 12
    t += 12 * MS
    old2 = pb.RobotState(header=header(t), world_T_flange=pose(np.eye(4)), cycle=2)
    assert _tob_state_after(core, old2).header.stamp_ns - t == 12 * MS
    t += 12 * MS
    forged = pb.RobotState(header=header(t), world_T_flange=pose(np.eye(4)), cycle=3, cycle_period_ns=3600 * 10**9)
    assert _tob_state_after(core, forged).header.stamp_ns - t == 12 * MS  # an hour's cycle: not believed


def test_the_controller_runs_at_the_cycle_of_the_states_it_receives():
    state = _gateway_states(link="rsi", cycle_period_ms=12.0)[-1]
    core = ControllerCore(ControllerConfig())
    core.step(state.header.stamp_ns, "robot_gateway/robot_state", state)
    # 100 mm/s and 60 deg/s over 12 ms: 1.2 mm and 0.72 deg per cycle
    assert core.dt == pytest.approx(0.012) and core.max_step_m == pytest.approx(1.2e-3)
    assert np.degrees(core.max_step_rad) == pytest.approx(0.72)
    st = pb.TobState(header=header(state.header.stamp_ns + 12 * MS), status=pb.TOB_STATUS_LOST, cycle=state.cycle)
    outs = core.step(state.header.stamp_ns + MS, "pose_filter/tob_state", st)
    cmd = next(m for t, m in outs if t == "controller/command")
    # commanded one cycle ahead: the next cycle's stamp is one 12 ms cycle later
    assert cmd.cycle == state.cycle + 1 and cmd.header.stamp_ns - state.header.stamp_ns == 12 * MS


def test_the_viewer_draws_per_cycle_steps_at_the_states_cycle():
    import rerun as rr

    from humanpt.viz.config import VizConfig
    from humanpt.viz.logger import RerunLogger

    rec = rr.RecordingStream("humanpt_test")
    rec.memory_recording()
    lg = RerunLogger(rec, VizConfig())
    assert lg.cycle_period_ns == cycle.FALLBACK_NS
    state = _gateway_states(link="rsi", cycle_period_ms=4.0)[-1]
    lg.log("robot_gateway/robot_state", state, state.header.stamp_ns)
    assert lg.cycle_period_ns == 4 * MS


# -- old recordings ------------------------------------------------------------------------------------
def test_an_old_recording_replays_with_the_cycle_its_config_named():
    # arc_rsi was recorded over RSI at 12 ms, before robot states carried the cycle
    run = ROOT / "recordings" / "arc_rsi"
    pf = read(run / "pose_filter.mcap")
    assert pf.config()["predict_ahead_ms"] == 12.0
    newer = fields_newer_than(read(run / "robot_gateway.mcap"))
    assert newer["humanpt.RobotState"] == ("cycle_period_ns",)
    # (and the fields added since by issue 33.5: left out of a replay's outputs as this one)
    assert newer["humanpt.TobState"] == ("world_T_tob_measured",)
    assert newer["humanpt.PathPoint"] == ("world_T_tob_raw", "world_T_tip_raw")
    assert build_core(pf).horizon_ns == 12 * MS
    assert build_core(read(run / "controller.mcap")).dt == pytest.approx(0.012)
    assert build_core(read(run / "sim_robot.mcap")).config.cycle_period_ns == 12 * MS
    table, ns = cycle.recorded("controller", {"cycle_period_ms": 28.0, "dz_mm": 600.0})
    assert table == {"dz_mm": 600.0} and ns == 28 * MS


def test_a_recording_made_now_has_no_field_newer_than_it(tmp_path):
    from humanpt.runtime.recording import Recorder

    path = tmp_path / "gw.mcap"
    with Recorder(path, {"component": "robot_gateway"}) as r:
        r.write("out", 1, "robot_gateway/robot_state", pb.RobotState(header=header(1), cycle_period_ns=12 * MS))
    assert fields_newer_than(read(Path(path), require_humanpt=False)) == {}


@pytest.mark.parametrize("closed", [True, False])
def test_a_field_the_recordings_schema_lacks_is_found_closed_or_not(tmp_path, closed):
    # A RobotState schema as an older humanpt registered it: without field 7 (cycle_period_ns).
    from types import SimpleNamespace

    from google.protobuf import descriptor_pb2
    from mcap.writer import Writer

    fdp = descriptor_pb2.FileDescriptorProto()
    pb.DESCRIPTOR.CopyToProto(fdp)
    state = next(m for m in fdp.message_type if m.name == "RobotState")
    keep = [f for f in state.field if f.name != "cycle_period_ns"]
    del state.field[:]
    state.field.extend(keep)
    fds = descriptor_pb2.FileDescriptorSet(file=[fdp])
    path = tmp_path / "old.mcap"
    with open(path, "wb") as f:
        w = Writer(f, use_chunking=False)
        w.start()
        sid = w.register_schema("humanpt.RobotState", "protobuf", fds.SerializeToString())
        cid = w.register_channel("robot_gateway/robot_state", "protobuf", sid)
        w.add_message(cid, 1, pb.RobotState(cycle=1).SerializeToString(), 1)
        if closed:
            w.finish()
    assert fields_newer_than(SimpleNamespace(path=path)) == {"humanpt.RobotState": ("cycle_period_ns",)}


def test_a_gain_set_at_run_time_must_be_stable_at_the_cycle_the_robot_runs():
    import json

    def set_gain(core, value):
        (_, ev), = core.step(0, "param", pb.ParamSet(key="gain_translation_1_s", value_json=json.dumps(value)))
        return ev

    core = ControllerCore(ControllerConfig())  # no state yet: ALTER's 28 ms; 20 x 0.028 = 0.56
    ev = set_gain(core, 20.0)
    assert ev.code == "param_rejected" and "must be < 17.9 at the link's 28 ms cycle" in ev.text, ev.text
    assert core.config.gain_translation_1_s == 4.0
    state = _gateway_states(link="rsi", cycle_period_ms=4.0)[-1]
    core.step(state.header.stamp_ns, "robot_gateway/robot_state", state)
    assert set_gain(core, 20.0).code == "param_changed" and core.config.gain_translation_1_s == 20.0  # 0.08

"""The gateway was ``alter_gateway`` before issue 22 made it one gateway for every robot
link (``robot_gateway``). What users have under the old name keeps working: config files,
scripts (``humanpt alter_gateway``, ``up --components``, ``param``) and recordings."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from mcap.reader import make_reader

from humanpt.robot_gateway.config import GatewayConfig
from humanpt.robot_gateway.core import GatewayCore
from humanpt.robot_gateway.links.rsi.config import RsiConfig
from humanpt.runtime.config import ConfigError, from_dict
from humanpt.runtime.recording import IN, OUT, RUN_METADATA, Recorder, read
from humanpt.runtime.registry import adapters_for, config_types, core_class
from humanpt.runtime.replay import replay
from tests.conftest import run_cli_here

ROOT = Path(__file__).resolve().parents[2]


def test_an_old_config_section_configures_the_gateway():
    cfg = from_dict({"alter_gateway": {"max_speed_mm_s": 50.0}}, "old.toml", config_types())
    gw = cfg.component("robot_gateway", GatewayConfig)
    assert gw.max_speed_mm_s == 50.0
    # ... whichever link it names
    one_cycle = {s: {"cycle_period_ms": 12.0} for s in ("controller", "sim_robot", "viz")}
    cfg = from_dict({"alter_gateway": {"link": "rsi", "cycle_period_ms": 12.0}, **one_cycle}, "old.toml",
                    config_types())
    assert isinstance(cfg.component("robot_gateway", GatewayConfig), RsiConfig)


def test_both_names_in_one_file_is_an_error_naming_both():
    with pytest.raises(ConfigError, match=r"both \[alter_gateway\] and \[robot_gateway\]"):
        from_dict({"alter_gateway": {}, "robot_gateway": {}}, "two.toml", config_types())


def test_a_profile_and_the_registry_take_the_old_name():
    cfg = from_dict({"profiles": {"mine": ["alter_gateway", "controller"]}}, "p.toml", config_types())
    assert cfg.profiles["mine"] == ("robot_gateway", "controller")
    assert core_class("alter_gateway") is core_class("robot_gateway") is GatewayCore
    rsi = RsiConfig(udp_bind="127.0.0.1:0")
    (adapter,) = adapters_for("alter_gateway", rsi)
    assert type(adapter).__name__ == "UdpAdapter"


def test_the_old_command_runs_the_gateway():
    p = run_cli_here("alter_gateway", "--help")
    assert p.returncode == 0, p.stderr
    assert "Run the robot_gateway component alone" in p.stdout


def test_a_recording_made_under_the_old_name_reads_and_replays(tmp_path):
    """The reference run's gateway recording, written again as the old version wrote it
    (component, core class and topics under ``alter_gateway``), replays exactly."""
    new = read(ROOT / "recordings" / "static" / "robot_gateway.mcap")
    assert new.metadata["component"] == "robot_gateway"
    meta = dict(new.metadata, component="alter_gateway", core="humanpt.alter_gateway.core:AlterGatewayCore")
    old_path = tmp_path / "alter_gateway.mcap"
    rec = Recorder(old_path, meta)
    for e in new.entries:
        if e.direction in (IN, OUT):
            msg, data = e.decode(), e.data
            if e.topic == "robot_gateway/robot_state" and e.direction == OUT:
                # written with this version's schema, whose robot states carry the link's cycle
                # (issue 30; the reference run predates it): as this version's gateway says
                msg.cycle_period_ns, data = 28_000_000, None
            rec.write(e.direction, e.t_ns, e.topic.replace("robot_gateway/", "alter_gateway/"), msg, data)
    rec.close()
    with open(old_path, "rb") as f:  # the file itself says alter_gateway/...
        on_file = {c.topic for c in make_reader(f).get_summary().channels.values()}
    assert "alter_gateway/robot_state" in on_file and not any(t.startswith("robot_gateway/") for t in on_file)
    old = read(old_path)
    assert "robot_gateway/robot_state" in {e.topic for e in old.entries}
    assert old.metadata["component"] == "robot_gateway"
    assert old.metadata["core"] == "humanpt.robot_gateway.core:GatewayCore"
    result = replay(old_path)
    assert result.divergence is None and result.compared == result.recorded_outputs > 100


def _raw_metadata(path: Path) -> dict:
    with open(path, "rb") as f:
        return dict(next(m for m in make_reader(f).iter_metadata() if m.name == RUN_METADATA).metadata)


@pytest.mark.parametrize("run", ["arc", "arc_rsi"])
def test_a_recording_of_the_gateway_before_issue_30_reads_as_the_one_gateway_core_and_replays(run):
    """Before issue 30 the gateway's core was AlterGatewayCore and its config over RSI carried
    ALTER's port and baud: the reference runs were recorded so, and replay with GatewayCore."""
    path = ROOT / "recordings" / run / "robot_gateway.mcap"
    raw = _raw_metadata(path)
    assert raw["core"] == "humanpt.robot_gateway.core:AlterGatewayCore"
    rec = read(path)
    assert rec.metadata["core"] == "humanpt.robot_gateway.core:GatewayCore"
    if run == "arc_rsi":
        assert {"port", "baud"} <= set(json.loads(raw["config"])) and rec.config()["link"] == "rsi"
        assert not {"port", "baud"} & set(rec.config())
    result = replay(path)
    assert result.divergence is None and result.compared == result.recorded_outputs > 100

"""Bad RSI settings: a clear one-line error, nothing started."""

from __future__ import annotations

import socket
import time

import pytest

from humanpt.robot_gateway.links.rsi.config import RsiConfig
from humanpt.robot_gateway.links.rsi.shell import UdpAdapter
from humanpt.sim_robot.config import SimRobotConfig
from humanpt.sim_robot.core import SimRobotCore
from tests.conftest import run_cli_here


@pytest.mark.parametrize("kw, says", [
    ({"cycle_period_ms": 8.0}, "must be one of (4.0, 12.0)"),
    ({"udp_bind": "localhost"}, "host:port"),
    ({"reply_deadline_ms": 4.0}, "shorter than the cycle"),
    ({"correction_frame": "flange"}, "base or tool"),
])
def test_bad_gateway_settings_are_refused(kw, says):
    with pytest.raises(ValueError, match=says.replace("(", r"\(").replace(")", r"\)")):
        RsiConfig(**kw)


def test_an_rsi_sim_robot_is_not_silently_run_as_an_alter_one():
    with pytest.raises(ValueError, match="humanpt.sim_robot.rsi"):
        SimRobotCore(SimRobotConfig(protocol="rsi", cycle_period_ns=4_000_000))
    with pytest.raises(ValueError, match="4 or 12"):
        SimRobotConfig(protocol="rsi")  # 28 ms is no RSI cycle


def test_a_port_in_use_names_the_address():
    a = UdpAdapter("127.0.0.1:0")
    a.open()
    host, port = a.address
    try:
        with pytest.raises(OSError, match=f"cannot bind UDP 127.0.0.1:{port}"):
            UdpAdapter(f"127.0.0.1:{port}").open()
    finally:
        a.close()


def test_bench_rsi_refuses_a_cycle_rsi_does_not_have():
    r = run_cli_here("bench", "rsi", "--cycles", "5")
    assert r.returncode == 2 and r.stdout == ""
    assert r.stderr.strip().count("\n") == 0 and "4 and/or 12" in r.stderr


def test_datagrams_from_another_sender_than_the_robot_are_dropped():
    received = []
    gw = UdpAdapter("127.0.0.1:0", robot="127.0.0.1:9")  # the robot: port 9 (nobody here)
    gw.start(lambda topic, msg: received.append(msg))
    try:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as rogue:
            rogue.sendto(b"<Rob/>", gw.address)
            deadline = time.monotonic() + 2.0
            while gw.rejected == 0 and time.monotonic() < deadline:
                time.sleep(0.01)  # poll the adapter's counter (no event to wait on)
    finally:
        gw.close()
    assert gw.rejected == 1 and received == []


def test_the_link_key_chooses_the_gateway_and_the_protocol_the_simulated_robot():
    from humanpt.robot_gateway.core import GatewayCore
    from humanpt.robot_gateway.links.alter.config import AlterConfig
    from humanpt.runtime.config import ConfigError, from_dict
    from humanpt.runtime.registry import config_types, core_class
    from humanpt.sim_robot.rsi import RsiSimRobotCore

    sections = {"robot_gateway": {"link": "rsi", "cycle_period_ms": 12.0, "udp_bind": "127.0.0.1:0"},
                "sim_robot": {"protocol": "rsi"}}  # the robot runs the link's cycle
    cfg = from_dict(sections, "cell.toml", config_types())
    made = {}
    for name in ("robot_gateway", "sim_robot"):
        cls = core_class(name)  # the registry's entry, as `humanpt <component>` does
        made[name] = cls.create(cfg.component(name, cls.config_type), cfg.rig())
        # a recording names the registry's class: replay rebuilds the RSI core from it
        assert made[name].recording_metadata("live")["core"] == f"{cls.__module__}:{cls.__qualname__}"
    assert type(made["robot_gateway"]) is GatewayCore and made["robot_gateway"].config.udp_bind == "127.0.0.1:0"
    assert made["robot_gateway"].link.name == "RSI" and made["robot_gateway"].rx_topic == "udp_rx"
    assert type(made["sim_robot"]) is RsiSimRobotCore
    assert type(GatewayCore.create(AlterConfig())) is GatewayCore  # the default: ALTER
    # RSI keys without link = "rsi", and a link that does not exist: one line naming the key
    with pytest.raises(ConfigError, match=r"\[robot_gateway\] unknown key 'udp_bind'"):
        from_dict({"robot_gateway": {"udp_bind": "127.0.0.1:1"}}, "cell.toml", config_types())
    from humanpt.robot_gateway.links import LINKS

    with pytest.raises(ConfigError, match=r"\[robot_gateway\]: link 'can' is not a robot link of this version; "
                                          rf"known links: {', '.join(sorted(LINKS))}$"):
        from_dict({"robot_gateway": {"link": "can"}}, "cell.toml", config_types())
    with pytest.raises(ValueError, match="RsiConfig"):
        AlterConfig(link="rsi")

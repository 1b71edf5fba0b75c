"""Issue 34 item 2: the files an ABB controller needs for humanpt's EGM link, from the cell's
config (`humanpt robot-files`): the UDPUC transmission protocol points at the gateway, the
RAPID module guides tool0 in the configured frame at the link's cycle on that protocol."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from humanpt.robot_gateway.links import gateway_config, link_kind
from humanpt.robot_gateway.links.abb import robot_files as rf
from humanpt.robot_gateway.links.rsi.robot_files import RobotFilesError

CFG = gateway_config("abb", udp_bind="10.0.0.5:6600", cycle_period_ms=8.0, correction_frame="tool")


def test_the_transmission_protocol_points_at_the_gateway():
    line = [ln for ln in rf.sio_cfg(CFG).splitlines() if ln.strip().startswith("-Name")][0]
    fields = dict(re.findall(r'-(\w+) ("[^"]*"|\S+)', line))
    assert fields == {"Name": f'"{rf.DEVICE}"', "Type": '"UDPUC"', "RemoteAddress": '"10.0.0.5"',
                      "RemotePortNumber": "6600"}


def test_the_rapid_module_runs_egm_on_that_protocol_at_the_links_cycle():
    mod = rf.rapid_mod(CFG)
    assert f'EGMSetupUC ROB_1, egm_id, "default", "{rf.DEVICE}" \\Pose;' in mod
    assert "\\Tool:=tool0" in mod and "EGM_FRAME_TOOL" in mod and "\\SampleRate:=8" in mod
    assert f"\\CommTimeout:={rf.COMM_TIMEOUT_S:g}" in mod and mod.count("EGMReset egm_id;") >= 2
    assert mod.startswith("MODULE humanpt_egm") and mod.rstrip().endswith("ENDMODULE")
    assert "EGM_FRAME_BASE" in rf.rapid_mod(gateway_config("abb"))


def test_the_shipped_copies_are_the_reference_configs_files():
    shipped = Path(rf.__file__).parent / "robot"
    for name, text in rf.robot_files(rf.reference_config()).items():
        assert (shipped / name).read_text() == text, name


def test_an_address_the_robot_cannot_send_to_is_refused(tmp_path):
    with pytest.raises(RobotFilesError, match="--sensor-ip"):
        rf.write(gateway_config("abb", udp_bind="0.0.0.0:6510"), tmp_path)
    assert list(tmp_path.iterdir()) == []


def test_the_cli_writes_them_through_the_links_kind(tmp_path, cli_main, capsys):
    assert link_kind("abb").write_robot_files is rf.write
    cfg = tmp_path / "cell.toml"
    cfg.write_text('[robot_gateway]\nlink = "abb"\nudp_bind = "0.0.0.0:6510"\n')
    out = tmp_path / "abb"
    assert cli_main(["robot-files", "-c", str(cfg), "--out", str(out), "--sensor-ip", "192.168.125.10"]) == 0
    assert sorted(p.name for p in out.iterdir()) == sorted([rf.SIO_FILE, rf.RAPID_FILE])
    assert '-RemoteAddress "192.168.125.10"' in (out / rf.SIO_FILE).read_text()

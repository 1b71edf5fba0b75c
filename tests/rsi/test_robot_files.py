"""Issue 34 item 3: the files a KUKA controller needs for humanpt's RSI link, written from the
cell's config. The Ethernet object's elements are checked against the messages humanpt's
simulated controller and gateway put on the wire (protocol.encode_rob / encode_sen), read back
with ElementTree; the layout of the Ethernet XML follows the public one of
ros-industrial/kuka_experimental (krl/KR_C4/ros_rsi_ethernet.xml: CONFIG, SEND, RECEIVE, TAG,
TYPE, INDX, HOLDON), where a DEF_<name> element of SEND is sent as <name .../>."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from humanpt.robot_gateway.links.rsi import robot_files as rf
from humanpt.robot_gateway.links.rsi.config import RsiConfig
from humanpt.robot_gateway.links.rsi.protocol import (
    RobState,
    RsiCorrection,
    decode_rob,
    encode_rob,
    encode_sen,
)

CFG = RsiConfig(udp_bind="192.168.1.20:49152", cycle_period_ms=12.0, robot_late_limit=7, correction_frame="tool")


def _xml() -> ET.Element:
    return ET.fromstring(rf.ethernet_xml(CFG))


def test_the_robot_sends_exactly_what_the_gateway_reads():
    send = _xml().find("SEND/ELEMENTS")
    declared = {e.get("TAG").removeprefix("DEF_") for e in send}
    assert all(e.get("INDX") == "INTERNAL" and e.get("TAG").startswith("DEF_") for e in send)
    rob = encode_rob(RobState(ipoc=1000, rist=(1.0, 2.0, 3.0, 10.0, 20.0, 30.0), aipos=(0.0,) * 6, delay=2))
    on_wire = {child.tag for child in ET.fromstring(rob)} - {"IPOC"}  # IPOC: RSI always sends it
    assert declared == on_wire == {"RIst", "AIPos", "Delay"}
    assert decode_rob(rob).delay == 2


def test_the_robot_takes_exactly_what_the_gateway_writes_with_holdon_off():
    receive = list(_xml().find("RECEIVE/ELEMENTS"))
    sen = ET.fromstring(encode_sen(RsiCorrection(1000, (0.1, 0.2, 0.3, 0.01, 0.02, 0.03)), CFG.sen_type))
    written = {f"{child.tag}.{a}" for child in sen if child.tag != "IPOC" for a in child.attrib}
    assert {e.get("TAG") for e in receive} == written == {f"RKorr.{a}" for a in "XYZABC"}
    assert [e.get("INDX") for e in receive] == [str(i) for i in range(1, 7)]
    # issue 29 item 1: a late answer must never repeat the last relative correction
    assert {e.get("HOLDON") for e in receive} == {"0"}
    assert sen.get("Type") == _xml().findtext("CONFIG/SENTYPE")


def test_the_address_late_limit_and_frame_come_from_the_config():
    cfg = _xml().find("CONFIG")
    assert (cfg.findtext("IP_NUMBER"), cfg.findtext("PORT"), cfg.findtext("ONLYSEND")) == ("192.168.1.20", "49152", "FALSE")
    md = rf.context_md(CFG)
    assert "| ETHERNET | Timeout | 7 |" in md and "TCP (tool)" in md and "12 ms" in md
    src = rf.program_src(CFG)
    assert f'RSI_CREATE("{rf.CONTEXT_NAME}"' in src and "RSI_ON(#RELATIVE)" in src and "RSI_MOVECORR()" in src
    assert "#TCP" in src and "7 late answers in a row" in src


@pytest.mark.parametrize("bind, ip, why", [
    ("127.0.0.1:49152", None, "cannot be the robot's destination"),
    ("0.0.0.0:49152", None, "cannot be the robot's destination"),
    ("192.168.1.20:49152", "10.0.0.300", "not an IPv4 address"),
    ("192.168.1.20:49152", "robot.local", "not an IPv4 address"),
    ("192.168.1.20:0", None, "port 0"),
])
def test_an_address_the_robot_cannot_send_to_is_refused(bind, ip, why, tmp_path):
    with pytest.raises(rf.RobotFilesError, match=why):
        rf.write(RsiConfig(udp_bind=bind), tmp_path, ip)
    assert list(tmp_path.iterdir()) == []  # nothing written


def test_the_shipped_copies_are_the_reference_configs_files():
    shipped = Path(rf.__file__).parent / "robot"
    for name, text in rf.robot_files(rf.reference_config()).items():
        assert (shipped / name).read_text() == text, f"{name}: regenerate with rf.write(rf.reference_config(), ...)"


def test_the_cli_writes_the_files_and_keeps_existing_ones(tmp_path, cli_main, capsys):
    cfg = tmp_path / "cell.toml"
    cfg.write_text('[robot_gateway]\nlink = "rsi"\nudp_bind = "0.0.0.0:49152"\ncycle_period_ms = 12.0\n')
    out = tmp_path / "kuka"
    assert cli_main(["robot-files", "-c", str(cfg), "--out", str(out)]) == 2  # 0.0.0.0: the robot needs an address
    assert "--sensor-ip" in capsys.readouterr().err and not out.exists()
    assert cli_main(["robot-files", "-c", str(cfg), "--out", str(out), "--sensor-ip", "10.1.2.3"]) == 0
    assert sorted(p.name for p in out.iterdir()) == sorted([rf.ETHERNET_FILE, rf.PROGRAM_FILE, rf.CONTEXT_FILE])
    assert ET.parse(out / rf.ETHERNET_FILE).findtext("CONFIG/IP_NUMBER") == "10.1.2.3"
    assert cli_main(["robot-files", "-c", str(cfg), "--out", str(out), "--sensor-ip", "10.1.2.4"]) == 2
    assert "exists" in capsys.readouterr().err
    assert ET.parse(out / rf.ETHERNET_FILE).findtext("CONFIG/IP_NUMBER") == "10.1.2.3"  # kept


def test_the_cli_refuses_a_cell_on_another_link(tmp_path, cli_main, capsys):
    assert cli_main(["robot-files", "--out", str(tmp_path / "x")]) == 2  # the default cell: ALTER
    assert 'link = "rsi"' in capsys.readouterr().err

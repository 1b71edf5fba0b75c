"""Issue 34 items 1 and 5 (UR): the URScript program and the installation settings from the
cell's config (`humanpt robot-files` through the link's kind): the registers the link
writes are the ones the program reads, at the link's cycle, with its watchdog."""

from __future__ import annotations

import math
import re
from pathlib import Path

import pytest

from humanpt.robot_gateway.links import gateway_config, link_kind
from humanpt.robot_gateway.links.rsi.robot_files import RobotFilesError
from humanpt.robot_gateway.links.ur import robot_files as rf
from humanpt.robot_gateway.links.ur.link import input_names, output_names

CFG = gateway_config("ur", rtde_address="10.0.0.7:30004", cycle_period_ms=8.0, register_base=30,
                     watchdog_cycles=12, max_lead_mm=4.0, max_lead_deg=1.5)


def test_the_program_reads_the_registers_the_link_writes_and_writes_those_it_reads():
    script = rf.script(CFG)
    ints = set(re.findall(r"read_input_integer_register\((\d+)\)", script))
    floats = re.findall(r"read_input_float_register\((\d+)\)", script)
    writes = set(re.findall(r"write_output_integer_register\((\d+),", script))
    # the link's inputs: input_int_register_30 (the sequence), input_double_register_30..35 (x..rz)
    assert ints == {"30"} and [int(n) for n in floats] == [30, 31, 32, 33, 34, 35]
    assert input_names(30)[0] == "input_int_register_30" and input_names(30)[-1] == "input_double_register_35"
    assert writes == {"30", "31"} and output_names(30)[5:] == ("output_int_register_30", "output_int_register_31")


def test_the_program_servoes_at_the_links_cycle_with_its_watchdog():
    script = rf.script(CFG)
    assert "CYCLE_S = 0.008" in script and "WATCHDOG_CYCLES = 12" in script
    assert f"MAX_LEAD_M = {0.004:.6g}" in script and f"MAX_LEAD_RAD = {math.radians(1.5):.6g}" in script
    assert "stopl(" in script and "servoj(get_inverse_kin(target" in script
    assert script.rstrip().endswith("humanpt_servo()")
    # every def/if/while has its end (URScript's blocks)
    opens = len(re.findall(r"^\s*(def|if|while)\b", script, re.M))
    assert opens == len(re.findall(r"^\s*end\s*$", script, re.M))


def test_the_installation_names_the_robot_the_tcp_and_the_registers():
    text = rf.installation(CFG)
    assert "10.0.0.7" in text and "125 Hz" in text and "0 0 0 0 0 0" in text
    assert "input_int_register_30" in text and "input_double_register_30..35" in text


def test_the_shipped_copies_are_the_reference_configs_files():
    shipped = Path(rf.__file__).parent / "robot"
    for name, text in rf.robot_files(rf.reference_config()).items():
        assert (shipped / name).read_text() == text, name


@pytest.mark.parametrize("address", ["127.0.0.1:30004", "0.0.0.0:30004", "robot.local:30004"])
def test_an_address_that_is_not_a_robots_is_refused(tmp_path, address):
    with pytest.raises(RobotFilesError, match="rtde_address"):
        rf.write(gateway_config("ur", rtde_address=address), tmp_path)
    assert list(tmp_path.iterdir()) == []


def test_the_links_kind_writes_them(tmp_path):
    write = link_kind("ur").write_robot_files
    assert write is rf.write
    paths = write(CFG, tmp_path / "ur", None, False)
    assert sorted(p.name for p in paths) == sorted([rf.SCRIPT_FILE, rf.INSTALLATION_FILE])
    with pytest.raises(FileExistsError):
        write(CFG, tmp_path / "ur", None, False)

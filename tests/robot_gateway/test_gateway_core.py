"""The gateway core alone, on scripted inputs: every safety rule, its zero correction and its event."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from humanpt.geometry.transforms import transform_from_x
from humanpt.robot_gateway.config import GatewayConfig
from humanpt.robot_gateway.core import GatewayCore
from humanpt.robot_gateway.links.alter import CorrectionFlags, StatusBits
from humanpt.robot_gateway.links.alter.config import AlterConfig
from humanpt.runtime.config import ConfigError, build
from humanpt.schemas import humanpt_pb2 as pb
from humanpt.schemas.convert import from_pose, header
from tests.robot_gateway.oracle import (
    LIMIT_DEG,
    LIMIT_MM,
    assert_wire_correction,
    euler_deg_of_rotvec,
    wire_angle_deg,
    wire_euler_deg,
    wire_translation_mm,
)
from tests.robot_gateway.rig import ACTIVE, CYCLE_NS, MS, START_X, AlterRobot, Rig

HOLD = CorrectionFlags.HOLD


def _rig(**kw) -> Rig:
    rig = Rig(**kw)
    assert rig.gw.link_running and rig.robot.link.is_running
    return rig


# -- link start-up and the robot state ------------------------------------------------------


def test_status_becomes_robot_state_with_receive_stamp_and_world_pose_in_metres():
    rig = _rig(status_delay_ms=1.5)
    rig.advance(10 * MS)
    rig.status()
    (state,) = rig.states()
    assert state.cycle == 1 and state.missed_cycles == 0
    assert state.header.stamp_ns == rig.t_ns - 1_500_000 and state.header.frame_id == "world"
    assert state.status.alter_active and state.status.arm_power and not state.status.fault
    T = from_pose(state.world_T_flange)
    np.testing.assert_allclose(T[:3, 3], START_X[:3] / 1000.0, atol=1e-8)
    np.testing.assert_allclose(T[:3, :3], transform_from_x(START_X)[:3, :3], atol=1e-6)


def test_world_T_base_places_the_robot_state_and_rotates_world_commands_into_the_base():
    rig = _rig(world_T_base_mm_deg=(100.0, -50.0, 700.0, 90.0, 0.0, 0.0))
    rig.status()
    T = from_pose(rig.states()[-1].world_T_flange)
    expected = transform_from_x(np.array([100.0, -50.0, 700.0, 90, 0, 0])) @ transform_from_x(
        START_X
    )
    np.testing.assert_allclose(T[:3, 3] * 1000, expected[:3, 3], atol=1e-5)
    rig.command(dp_mm=(1.0, 0.0, 0.0))  # +x in the world is -y in a base turned 90 deg about z
    np.testing.assert_allclose(rig.last_correction().translation_mm, [0.0, -1.0, 0.0], atol=1e-9)


def test_a_fresh_command_within_limits_is_sent_as_is_to_the_wire_resolution():
    rig = _rig()
    rig.status()
    assert rig.corrections == []  # waits for the command of cycle 1
    rig.command(dp_mm=(1.234, -0.5, 0.25), rv_deg=(0.1, -0.2, 0.3))
    cycle, c = rig.corrections[-1]
    assert cycle == 1 and c.flags == CorrectionFlags(0)
    assert c.deltas[:3] == (123, -50, 25)  # 0.01 mm units, 1.234 rounded to the nearest
    # The rotation vector as the wire's Z-Y-X angles (scipy), rounded to 0.01 deg.
    expected = np.round(euler_deg_of_rotvec(np.radians([0.1, -0.2, 0.3])) * 100).astype(int)
    assert c.deltas[3:] == tuple(expected.tolist())
    assert rig.gw.sent[-1].source == "fresh"
    assert "clamped" not in rig.codes()


def test_clamping_is_by_norm_and_by_angle_keeping_the_direction():
    rig = _rig()
    rig.status()
    rig.command(dp_mm=(30.0, 40.0, 0.0), rv_deg=(0.0, 0.0, 5.0))
    c = rig.last_correction()
    # 2.8 mm along (0.6, 0.8, 0): both axes scaled, not clipped per axis.
    np.testing.assert_allclose(wire_translation_mm(c), [1.68, 2.24, 0.0], atol=0.006)
    assert np.linalg.norm(wire_translation_mm(c)) <= 2.8 + 1e-9
    np.testing.assert_allclose(wire_euler_deg(c), [0.0, 0.0, 1.68], atol=0.006)
    assert rig.codes() == ["clamped"]
    assert "2.800 mm / 1.680 deg" in rig.events()[-1].text
    # An oblique rotation keeps its axis: 1.68 deg about (1, 1, 1) / sqrt(3).
    rig.advance(CYCLE_NS)
    rig.status()
    rig.command(rv_deg=(3.0, 3.0, 3.0))
    c = rig.last_correction()
    assert 1.6 < wire_angle_deg(c) <= 1.68 + 1e-9
    expected = euler_deg_of_rotvec(np.radians(1.68) * np.ones(3) / np.sqrt(3))
    np.testing.assert_allclose(wire_euler_deg(c), expected, atol=0.05)


def test_clamping_follows_live_limit_changes():
    rig = _rig()
    outs = rig.step(
        "param",
        pb.ParamSet(
            header=header(0), component="robot_gateway", key="max_speed_mm_s", value_json="50"
        ),
    )
    assert rig.codes(outs) == ["param_changed"]
    rig.status()
    rig.command(dp_mm=(10.0, 0.0, 0.0))
    np.testing.assert_allclose(rig.last_correction().translation_mm, [1.4, 0, 0])


@settings(max_examples=150, deadline=None)
@given(
    st.lists(st.floats(-50, 50), min_size=3, max_size=3),
    st.lists(st.floats(-3.0, 3.0), min_size=3, max_size=3),
)
def test_any_command_goes_out_clamped_to_the_stated_limits_and_rounded(dp_mm, rv_deg):
    """Whatever the command, the wire correction is the command clamped by norm / angle to
    100 mm/s and 60 deg/s x 28 ms, to the wire's 0.01 mm / 0.01 deg (the limits hold after
    rounding)."""
    rig = _rig()
    rig.status()
    rig.command(dp_mm=dp_mm, rv_deg=rv_deg)
    assert_wire_correction(rig.last_correction(), dp_mm, np.radians(rv_deg), LIMIT_MM, LIMIT_DEG)


@settings(max_examples=100, deadline=None)
@given(
    st.lists(st.floats(-5, 5), min_size=3, max_size=3),
    st.lists(st.floats(-3, 3), min_size=3, max_size=3),
    st.lists(st.floats(-3, 3), min_size=3, max_size=3),
)
def test_a_step_never_leaves_the_envelope_and_a_flange_outside_only_comes_back(dp_mm, lo_off, hi_off):
    """The box [lo, hi] around the flange (which may lie outside it on any axis): per axis the
    target p + step stays within the box widened to include p, and no axis moves more than
    its clamped command (nor in the other direction)."""
    p = START_X[:3]
    lo, hi = p + np.minimum(lo_off, hi_off) - 0.5, p + np.maximum(lo_off, hi_off) + 0.5
    rig = _rig(envelope_min_mm=tuple(lo), envelope_max_mm=tuple(hi))
    rig.status()
    rig.command(dp_mm=dp_mm)
    step = wire_translation_mm(rig.last_correction())
    target = p + step
    half_unit = 0.005 + 1e-9  # the wire's rounding
    assert np.all(target >= np.minimum(lo, p) - half_unit), (target, lo)
    assert np.all(target <= np.maximum(hi, p) + half_unit), (target, hi)
    dp_c = np.asarray(dp_mm) * min(1.0, LIMIT_MM / max(np.linalg.norm(dp_mm), 1e-300))
    assert np.all(np.abs(step) <= np.abs(dp_c) + half_unit) and np.all(step * dp_c >= -1e-12)


def test_envelope_cuts_the_step_and_a_flange_outside_may_only_come_back():
    x, y, z = START_X[:3]
    rig = _rig(
        envelope_min_mm=(-2000.0, -2000.0, -2000.0), envelope_max_mm=(x + 1.0, 2000.0, 2000.0)
    )
    rig.status()
    rig.command(dp_mm=(2.0, 0.5, 0.0))
    np.testing.assert_allclose(rig.last_correction().translation_mm, [1.0, 0.5, 0.0])
    assert rig.codes() == ["envelope"]
    # Now the box lies below the flange (z max under it): moving up is refused, down is fine.
    rig = _rig(
        envelope_min_mm=(-2000.0, -2000.0, -2000.0), envelope_max_mm=(2000.0, 2000.0, z - 10.0)
    )
    rig.status()
    rig.command(dp_mm=(0.5, 0.0, 2.0))
    np.testing.assert_allclose(rig.last_correction().translation_mm, [0.5, 0.0, 0.0])
    rig.advance(CYCLE_NS)
    rig.status()
    rig.command(dp_mm=(0.0, 0.0, -2.0))
    np.testing.assert_allclose(rig.last_correction().translation_mm, [0.0, 0.0, -2.0])


def test_tool_mode_corrections_are_expressed_in_the_flange_frame():
    rig = _rig()
    rig.bits = ACTIVE | StatusBits.TOOL_MODE
    rig.status()
    rig.command(dp_mm=(0.0, 0.0, -1.0), rv_deg=(0.0, 0.0, 1.0))  # world: down, turn about world z
    c = rig.last_correction()
    # The flange points down (z_flange = -z_world, y_flange = -y_world): down is +z_tool.
    np.testing.assert_allclose(c.translation_mm, [0.0, 0.0, 1.0], atol=1e-9)
    np.testing.assert_allclose(c.rotation_deg, [0.0, 0.0, -1.0], atol=1e-9)
    # A tool-frame command passes through unchanged in tool mode.
    rig.advance(CYCLE_NS)
    rig.status()
    rig.command(dp_mm=(0.3, 0.2, 0.1), frame="tool")
    np.testing.assert_allclose(rig.last_correction().translation_mm, [0.3, 0.2, 0.1], atol=1e-9)


# -- holding: stale commands, liveliness, HOLD modes ------------------------------------------


def test_stale_command_is_reused_for_stale_cycles_then_zero_with_one_event():
    rig = _rig()
    for _ in range(3):
        rig.cycle_with_command(dp_mm=(1.0, 0.0, 0.0))
    for _ in range(6):  # the controller falls silent
        rig.status()
        rig.advance(CYCLE_NS)
    sources = [s.source for s in rig.gw.sent]
    assert sources == ["fresh"] * 3 + ["reused"] * 3 + ["stale"] * 3
    assert [cycle for cycle, _ in rig.corrections] == list(range(1, 10))  # all reached the robot
    for _, c in rig.corrections[3:6]:
        np.testing.assert_allclose(c.translation_mm, [1.0, 0, 0])  # velocity hold
    for _, c in rig.corrections[6:]:
        assert c.deltas == (0,) * 6 and HOLD in c.flags
    stale = [e for e in rig.events() if e.code == "stale_command"]
    assert len(stale) == 1 and "no command for cycle 7" in stale[0].text  # rate-limited
    assert rig.codes().count("deadline_missed") == 1  # rate-limited too
    rig.cycle_with_command(dp_mm=(0.5, 0, 0))
    assert rig.codes()[-1] == "command_resumed"
    np.testing.assert_allclose(rig.last_correction().translation_mm, [0.5, 0, 0])


def test_before_any_command_the_gateway_holds_and_never_faults():
    rig = _rig(fault_after_missed=3)
    for _ in range(20):
        rig.status()
        rig.advance(CYCLE_NS)
    assert all(c.deltas == (0,) * 6 for _, c in rig.corrections) and len(rig.corrections) == 20
    assert rig.gw.fault is None and "fault" not in rig.codes()
    assert "no command from the controller yet" in rig.events()[0].text


def test_liveliness_loss_gives_zero_at_once_even_with_commands_and_an_event():
    rig = _rig()
    rig.cycle_with_command(dp_mm=(1.0, 0, 0))
    rig.status()
    outs = rig.liveliness(False)  # the pending cycle is answered at once, with zero
    assert rig.codes(outs) == ["controller_gone"]
    assert rig.last_correction().deltas == (0,) * 6
    for _ in range(15):  # commands from a "gone" controller never move the robot
        rig.cycle_with_command(dp_mm=(1.0, 0, 0))
    assert len(rig.corrections) == 17 and all(c.deltas == (0,) * 6 for _, c in rig.corrections[1:])
    assert {s.source for s in list(rig.gw.sent)[1:]} == {"gone"}
    assert rig.gw.fault is None  # an absent controller is held, not faulted
    assert rig.codes().count("controller_gone") == 1
    rig.liveliness(True)
    rig.cycle_with_command(dp_mm=(1.0, 0, 0))
    assert rig.codes()[-1] == "controller_back"
    np.testing.assert_allclose(rig.last_correction().translation_mm, [1.0, 0, 0])


def test_hold_and_idle_modes_and_alter_off_requests_send_zero():
    rig = _rig()
    rig.cycle_with_command(dp_mm=(1.0, 0, 0), mode=pb.CONTROL_MODE_HOLD)
    rig.cycle_with_command(dp_mm=(1.0, 0, 0), mode=pb.CONTROL_MODE_IDLE)
    rig.cycle_with_command(dp_mm=(1.0, 0, 0), alter_off=True)
    flags = [c.flags for _, c in rig.corrections]
    assert all(c.deltas == (0,) * 6 for _, c in rig.corrections)
    assert flags == [HOLD, HOLD, HOLD | CorrectionFlags.ALTER_OFF]


# -- deadlines, missed cycles, fault ---------------------------------------------------------


def test_a_late_command_misses_the_deadline_and_serves_the_next_cycle():
    rig = _rig()
    rig.cycle_with_command(dp_mm=(1.0, 0, 0))
    rig.status()
    rig.advance(7 * MS)  # past the 6 ms deadline: answered with the previous step
    assert rig.gw.sent[-1].source == "reused" and rig.codes() == ["deadline_missed"]
    rig.command(dp_mm=(2.0, 0, 0))  # the late command for cycle 2 ...
    rig.advance(CYCLE_NS - 7 * MS)
    rig.status()
    rig.advance(7 * MS)  # ... serves cycle 3 (velocity hold of the freshest)
    assert rig.gw.sent[-1].source == "reused" and rig.gw.sent[-1].command_cycle == 2
    np.testing.assert_allclose(rig.last_correction().translation_mm, [2.0, 0, 0])
    assert rig.states()[-1].missed_cycles == 1


def test_consecutive_missed_cycles_raise_a_fault_with_hold_and_alter_off_until_alter_restarts():
    rig = _rig(fault_after_missed=5)
    rig.cycle_with_command(dp_mm=(1.0, 0, 0))
    for _ in range(6):  # commands always 10 ms late: each cycle misses its deadline
        rig.status()
        rig.advance(10 * MS)
        rig.command(dp_mm=(1.0, 0, 0))
        rig.advance(CYCLE_NS - 10 * MS)
    assert [s.missed_cycles for s in rig.states()] == [0, 0, 1, 2, 3, 4, 5]
    assert "fault" in rig.codes() and rig.gw.fault is not None
    fault = next(e for e in rig.events() if e.code == "fault")
    assert fault.severity == pb.SEVERITY_ERROR and "5 consecutive missed cycles" in fault.text
    c = rig.last_correction()
    assert c.deltas == (0,) * 6 and c.flags == HOLD | CorrectionFlags.ALTER_OFF
    for _ in range(3):  # fresh commands do not move a faulted gateway
        rig.cycle_with_command(dp_mm=(1.0, 0, 0))
        assert rig.last_correction().deltas == (0,) * 6
    # The controller leaves ALTER, then the operator restarts it: a new session clears the fault.
    rig.bits = StatusBits.ARM_POWER
    rig.cycle_with_command()
    rig.bits = ACTIVE
    rig.status()
    assert rig.codes()[-1] == "fault_cleared" and rig.gw.fault is None
    rig.command(dp_mm=(1.0, 0, 0))
    np.testing.assert_allclose(rig.last_correction().translation_mm, [1.0, 0, 0])


def test_a_console_reset_clears_a_fault_and_without_alter_off_only_hold_is_sent():
    rig = _rig(fault_after_missed=2, alter_off_on_fault=False)
    rig.cycle_with_command(dp_mm=(1.0, 0, 0))
    for _ in range(3):  # commands keep coming, late: a servo loop that misses, a fault
        rig.status()
        rig.advance(10 * MS)
        rig.command(dp_mm=(1.0, 0, 0))
        rig.advance(CYCLE_NS - 10 * MS)
    assert rig.gw.fault is not None and rig.last_correction().flags == HOLD
    # Only the operator clears a fault, by name (issue 14, item 1): a bare command is refused.
    outs = rig.step("console/command", pb.Command(component="robot_gateway", verb="reset_fault"))
    assert rig.codes(outs) == ["bad_console_command"] and rig.gw.fault is not None
    outs = rig.step("console/command", pb.Command(component="robot_gateway", verb="reset_fault",
                                                  args_json='{"operator": "ann@cell1"}'))
    assert rig.codes(outs) == ["fault_cleared"] and "ann@cell1" in rig.events(outs)[0].text
    outs = rig.step("console/command", pb.Command(component="robot_gateway", verb="reset_fault",
                                                  args_json='{"operator": "ann@cell1"}'))
    assert rig.codes(outs) == ["no_fault"]
    outs = rig.step("console/command", pb.Command(component="robot_gateway", verb="explode"))
    assert rig.codes(outs) == ["bad_console_command"]


def test_the_robot_reporting_missed_corrections_and_lost_statuses_count_as_missed_cycles():
    rig = _rig(fault_after_missed=4)
    rig.cycle_with_command(dp_mm=(1.0, 0, 0))
    rig.bits = ACTIVE | StatusBits.CORRECTION_MISSED
    rig.cycle_with_command(dp_mm=(1.0, 0, 0))
    assert rig.states()[-1].missed_cycles == 1 and "robot_missed" in rig.codes()
    rig.bits = ACTIVE
    rig.status(cycle=rig.cycle + 3)  # two statuses lost on the line
    assert rig.states()[-1].missed_cycles == 3 and "status_lost" in rig.codes()
    rig.command(dp_mm=(1.0, 0, 0))
    rig.advance(CYCLE_NS)
    rig.cycle_with_command(dp_mm=(1.0, 0, 0))
    assert rig.states()[-1].missed_cycles == 0  # an on-time cycle resets the count


def test_a_robot_fault_is_reported_and_held_without_a_gateway_fault():
    rig = _rig(fault_after_missed=2)
    rig.cycle_with_command(dp_mm=(1.0, 0, 0))
    rig.bits = StatusBits.ARM_POWER | StatusBits.FAULT
    for _ in range(5):
        rig.cycle_with_command(dp_mm=(1.0, 0, 0))
    assert rig.codes().count("robot_fault") == 1
    assert len(rig.corrections) == 6 and all(c.deltas == (0,) * 6 for _, c in rig.corrections[1:])
    assert rig.gw.fault is None


# -- the link --------------------------------------------------------------------------------


def test_silence_is_a_link_down_event_and_no_corrections_then_link_back():
    rig = _rig()
    rig.cycle_with_command(dp_mm=(1.0, 0, 0))
    n = len(rig.corrections)
    rig.robot_connected = False
    outs = rig.advance(4 * CYCLE_NS)
    assert rig.codes(outs) == ["link_down"]
    assert "no STATUS" in rig.events(outs)[0].text
    # The gateway restarts the link after the silence (STRT every start_timeout_ns = 100 ms,
    # LinkConfig's default): once the line is back, the link is up within one retry.
    assert "restarting the ALTER link" in rig.events(outs)[0].text
    rig.robot_connected = True
    t_back = rig.t_ns
    while "link_up" not in rig.codes() and rig.t_ns - t_back < 200 * MS:
        rig.advance(2 * MS)
    assert rig.codes()[-1] == "link_up"
    assert rig.t_ns - t_back <= 100 * MS + 2 * MS
    rig.cycle_with_command(dp_mm=(1.0, 0, 0))
    rig.cycle_with_command(dp_mm=(1.0, 0, 0))
    assert len(rig.corrections) > n


def test_a_peer_restart_is_link_down_then_up_with_a_new_session():
    rig = _rig()
    rig.cycle_with_command(dp_mm=(1.0, 0, 0))
    rig.robot = AlterRobot()  # the controller restarts (a fresh link, STRT)
    rig.cycle = 0
    outs = []
    for data in rig.robot.begin(rig.t_ns):
        outs += rig.from_robot(data)
    codes = rig.codes(outs)
    assert codes[0] == "link_down" and "peer restarted" in rig.events(outs)[0].text
    assert codes[-1] == "link_up"
    rig.status(cycle=1)  # a restarted controller may count from 1 again
    rig.command(dp_mm=(0.7, 0, 0))
    np.testing.assert_allclose(rig.last_correction().translation_mm, [0.7, 0, 0])


def test_unanswered_corrections_bring_the_link_down_by_rep_timeouts():
    rig = _rig()
    rig.cycle_with_command(dp_mm=(1.0, 0, 0))
    rig.status()
    rig.robot_connected = False  # the correction goes nowhere, nothing comes back
    rig.command(dp_mm=(1.0, 0, 0))
    outs = rig.advance(20 * CYCLE_NS)
    assert "link_down" in rig.codes(outs)
    assert rig.gw.counters["reps"] >= 1


# -- bad input ---------------------------------------------------------------------------------


@settings(max_examples=100, deadline=None)
@given(st.binary(max_size=200))
def test_garbage_on_the_line_never_raises_nor_moves_the_robot(data):
    rig = _rig()
    rig.status()
    rig.step("serial_rx", pb.SerialChunk(header=header(rig.t_ns), data=data))
    rig.advance(CYCLE_NS)
    assert all(c.deltas == (0,) * 6 for _, c in rig.corrections)


def test_bad_commands_are_dropped_with_an_event():
    rig = _rig()
    rig.status()
    rig.command(dp_mm=(float("nan"), 0, 0))
    rig.command(dp_mm=(1.0, 0, 0), frame="camera")
    rig.command(cycle=rig.cycle + 1000, dp_mm=(1.0, 0, 0))
    # NaN never reaches the gateway's handler (every core's input check: bad_input); the
    # other two are the gateway's drops, one report (rate-limited).
    assert rig.codes() == ["bad_input", "bad_command"]
    assert rig.gw.counters["commands_dropped"] == 2
    rig.advance(CYCLE_NS)
    assert rig.last_correction().deltas == (0,) * 6
    rig.step("liveliness", pb.Liveliness(component="someone_else", alive=False))
    rig.step("console/command", pb.Command(component="sim_robot", verb="alter_on"))


# -- config ----------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "key,value,needle",
    [
        ("baud", 9600, "baud must be one of (19200, 38400)"),
        ("max_speed_mm_s", -1.0, "max_speed_mm_s: -1.0 is outside its range"),
        ("max_speed_mm_s", 20000.0, "max_speed_mm_s: 20000.0 is outside its range [0.001, 250]"),
        ("envelope_min_mm", [2000.0, 0.0, 0.0], "must be below envelope_max_mm"),
        ("reply_deadline_ms", 30.0, "reply_deadline_ms"),
        ("port", "", "port must name"),
        ("world_T_base_mm_deg", [0.0] * 5, "expected 6 values"),
        ("stale_cycles", -1, "stale_cycles"),
    ],
)
def test_config_rejects_bad_values_naming_the_key(key, value, needle):
    with pytest.raises(ConfigError) as e:
        build(GatewayConfig, {key: value}, source="x.toml", section="robot_gateway")
    assert needle in str(e.value)


def test_config_defaults_and_19200_baud():
    cfg = AlterConfig(baud=19_200)
    assert cfg.max_step_mm == pytest.approx(2.8) and cfg.max_step_deg == pytest.approx(1.68)
    assert cfg.cycle_period_ns == CYCLE_NS
    core = GatewayCore(cfg)
    assert core.tick_period_ns() == 2 * MS
    assert dataclasses.asdict(cfg)["envelope_max_mm"] == (1600.0, 1600.0, 1600.0)


def test_a_controller_commanding_ahead_is_not_blamed_for_the_cycle_before_its_first_command():
    """Commanding one cycle ahead, the controller's first command is for the next cycle: the
    current one goes unanswered (held) without a miss; from then on every cycle is judged."""
    rig = _rig()
    rig.status()  # cycle 1: no command for it will come
    rig.command(cycle=2, dp_mm=(1.0, 0, 0))  # the first command, for the next cycle
    rig.advance(7 * MS)
    assert "deadline_missed" not in rig.codes()
    stale = [e for e in rig.events() if e.code == "stale_command"]  # cycle 1 held at start-up:
    assert [e.severity for e in stale] == [pb.SEVERITY_INFO]  # normal, not a warning
    rig.advance(CYCLE_NS - 7 * MS)
    rig.status()  # cycle 2: its command is waiting, answered at once
    assert rig.gw.sent[-1].source == "fresh" and rig.states()[-1].missed_cycles == 0
    rig.advance(CYCLE_NS)
    rig.status()  # cycle 3: nothing for it - a miss now
    rig.advance(7 * MS)
    assert rig.codes().count("deadline_missed") == 1


def test_after_a_peer_restart_the_watchdog_rearms_with_the_new_sessions_first_command():
    """Cycle numbers restart with a new session: misses count again from its first command
    (not from the old session's first commanded cycle, which may lie far ahead)."""
    rig = _rig()
    for _ in range(50):
        rig.status()
        rig.advance(CYCLE_NS)
    for _ in range(5):
        rig.cycle_with_command()  # armed from cycle 51
    rig.robot = AlterRobot()  # the controller restarts, counting from 1 again
    rig.cycle = 0
    for data in rig.robot.begin(rig.t_ns):
        rig.from_robot(data)
    rig.cycle_with_command()  # cycle 1 of the new session: re-arms
    before = rig.codes().count("deadline_missed")
    for _ in range(3):
        rig.status()  # cycles 2-4: nothing commanded
        rig.advance(CYCLE_NS)
    rig.status()  # cycle 5 accounts for cycle 4
    assert rig.codes().count("deadline_missed") > before  # (one event per interval)
    assert rig.states()[-1].missed_cycles == 3


# -- absurd but finite steps (issue 14, item 4) ----------------------------------------------


@pytest.mark.parametrize("frame", ["tool", "world"])
@pytest.mark.parametrize("step_m", [1.7e305, -1e300, 1e8, -3e5, 1e-300])
def test_an_absurd_finite_step_is_clamped_never_raises(frame, step_m):
    """The attack: a tool-frame step of 1.7e305 m overflowed to NaN in the frame change and
    raised inside the gateway, losing cycles. A step beyond 1e9 m is not data (every core's
    input check drops it: bad_input, zero correction); any other finite step is clamped to the
    per-cycle limit (100 mm/s x 28 ms = 2.8 mm; 0.01 mm wire units, PROTOCOL.md); the loop
    goes on either way."""
    rig = _rig()
    rig.cycle_with_command(dp_mm=(0, 0, 0))
    n_states = len(rig.states())
    rig.status()
    rig.command(dp_mm=(step_m * 1000.0, step_m * 1000.0, 0.0), rv_deg=(0, 0, 0), frame=frame)
    rig.advance(CYCLE_NS)
    _, c = rig.corrections[-1]
    norm_mm = math.sqrt(sum((d * 0.01) ** 2 for d in c.deltas[:3]))
    if abs(step_m) > 1e9:
        assert norm_mm == 0.0 and "bad_input" in rig.codes()
    elif abs(step_m) * 1000.0 > 2.8:
        assert 2.8 - 0.02 <= norm_mm <= 2.8 + 0.01  # clamped, not zeroed (quantisation 0.01 mm)
        assert "clamped" in rig.codes()
    else:
        assert norm_mm == 0.0
    for _ in range(3):
        rig.cycle_with_command(dp_mm=(0.5, 0, 0))
    assert len(rig.states()) == n_states + 4  # every cycle still answered and reported


@pytest.mark.parametrize("v", [(1.7e308, 1.7e308, 0.0), (-1e300, 5.0, 1e299), (3.0, 4.0, 0.0)])
def test_clamp_norm_keeps_the_direction_of_any_finite_step(v):
    """The gateway's clamp, even where the squares overflow: direction kept, norm = limit."""
    from humanpt.robot_gateway.safety import clamp_norm

    out, clamped = clamp_norm(np.array(v), 2.8)
    assert clamped and np.all(np.isfinite(out))
    assert math.isclose(math.hypot(*out), 2.8, rel_tol=1e-12)
    big = max(abs(x) for x in v)
    np.testing.assert_allclose(out / 2.8, np.array(v) / big / math.hypot(*(x / big for x in v)), atol=1e-12)


# -- the command stream: session, stamps, late commands, starvation (issue 19, item 3) -------


def test_a_silent_controller_is_held_without_a_fault_and_resumes_by_itself():
    """No command at all (a partition): hold, ALTER stays on, no latched fault; the next
    in-sequence fresh command moves the robot again, and the event says so."""
    rig = _rig(fault_after_missed=5)
    rig.cycle_with_command(dp_mm=(1.0, 0, 0))
    for _ in range(40):  # 1.1 s without a command
        rig.status()
        rig.advance(CYCLE_NS)
    assert rig.gw.fault is None and "fault" not in rig.codes()
    silent = [e for e in rig.events() if e.code == "controller_silent"]
    assert len(silent) == 1 and "resumes by itself" in silent[0].text
    # held: every correction after the 3 reused ones is zero, and ALTER off is never asked
    assert all(c.deltas == (0,) * 6 for _, c in rig.corrections[4:])
    assert all(not c.flags & CorrectionFlags.ALTER_OFF for _, c in rig.corrections)
    rig.cycle_with_command(dp_mm=(1.0, 0, 0))
    np.testing.assert_allclose(rig.last_correction().translation_mm, [1.0, 0, 0])
    resumed = rig.events()[-1]
    assert resumed.code == "command_resumed" and "resumed by itself" in resumed.text


def test_a_late_command_is_never_acted_on_and_reported():
    rig = _rig()
    rig.cycle_with_command(dp_mm=(1.0, 0, 0))
    old = rig.cycle
    for _ in range(8):
        rig.status()
        rig.advance(CYCLE_NS)
    n = len(rig.corrections)
    outs = rig.command(cycle=old + 1, dp_mm=(2.0, 0, 0))  # a partition's backlog: 7 cycles late
    assert rig.codes(outs) == ["late_command"]
    rig.status()
    rig.advance(CYCLE_NS)
    assert rig.corrections[n][1].deltas == (0,) * 6  # the late step never reached the robot


def test_a_command_stamped_off_its_cycle_is_dropped():
    """The controller stamps its command with the stamp of the robot_state it answers:
    one stamped a second away (forged, replayed from another run) is no answer to it."""
    rig = _rig()
    rig.cycle_with_command(dp_mm=(1.0, 0, 0))
    rig.status()
    cmd = pb.FlangeCommand(header=header(rig.stamp_for(rig.cycle) + 1_000 * MS, rig.seq, "world"),
                           cycle=rig.cycle, d_translation_m=pb.Vector3(x=0.002), mode=pb.CONTROL_MODE_TRACK)
    rig.seq += 1
    outs = rig.step("controller/command", cmd)
    assert rig.codes(outs) == ["stamp_mismatch"]
    rig.advance(CYCLE_NS)
    assert rig.gw.sent[-1].source == "reused"  # the previous (real) step, never the forged 2 mm
    np.testing.assert_allclose(rig.last_correction().translation_mm, [1.0, 0, 0])


def test_a_second_command_stream_holds_the_robot_until_it_is_quiet():
    """Two controller sessions (or a forger) on the command key: the gateway stays bound to
    the stream it follows and holds the robot while the other speaks; quiet again for
    conflict_hold_ms, the bound stream moves the robot."""
    rig = _rig(conflict_hold_ms=200.0)
    for _ in range(5):
        rig.cycle_with_command(dp_mm=(1.0, 0, 0))
    rig.status()
    forged = pb.FlangeCommand(header=header(rig.stamp_for(rig.cycle), 0, "world"), cycle=rig.cycle,
                              d_translation_m=pb.Vector3(x=0.002), mode=pb.CONTROL_MODE_TRACK)
    outs = rig.step("controller/command", forged)  # seq 0: a second session's first command
    assert rig.codes(outs) == ["controller_conflict"]
    rig.command(dp_mm=(1.0, 0, 0))  # the real one, same cycle
    rig.advance(CYCLE_NS)
    assert rig.gw.sent[-1].source == "conflict" and rig.last_correction().deltas == (0,) * 6
    for _ in range(5):  # both speak: held throughout
        rig.status()
        forged.header.seq += 1
        forged.header.stamp_ns = rig.stamp_for(rig.cycle)
        forged.cycle = rig.cycle
        rig.step("controller/command", forged)
        rig.command(dp_mm=(1.0, 0, 0))
        rig.advance(CYCLE_NS)
        assert rig.last_correction().deltas == (0,) * 6
    for _ in range(8):  # the second stream stopped: 224 ms later the bound one moves the robot
        rig.cycle_with_command(dp_mm=(1.0, 0, 0))
    assert "conflict_cleared" in rig.codes()
    np.testing.assert_allclose(rig.last_correction().translation_mm, [1.0, 0, 0])
    assert rig.gw.counters["foreign_commands"] == 6


def test_a_restarted_controller_whose_old_token_lingers_is_bound_once_the_old_stream_is_silent():
    rig = _rig(conflict_hold_ms=200.0)
    rig.seq = 1000  # the old process had run a while
    for _ in range(3):
        rig.cycle_with_command(dp_mm=(1.0, 0, 0))
    rig.seq = 0  # the old process died (its token lingers); a new one counts from 0
    for _ in range(12):
        rig.cycle_with_command(dp_mm=(0.5, 0, 0))
    assert "controller_conflict" in rig.codes() and "controller_rebound" in rig.codes()
    np.testing.assert_allclose(rig.last_correction().translation_mm, [0.5, 0, 0])

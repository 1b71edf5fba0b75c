"""Issue 29 item 1: a gateway that stops answering must not leave the robot moving on.

With HOLDON on, an RSI robot repeats the last relative correction (RKorr) for every late
answer until its late limit stops RSI: the issue's gateway, killed at 40 mm/s with the
twin's old defaults (HOLDON on, limit 100), let the robot move 50.1 mm in 99 cycles. Now the
twin's default is HOLDON off and a limit of 10 (the configuration components/rsi/README.md
requires of a real robot), and the gateway keeps every step and ``robot_late_limit``
repeats of it inside the envelope in case HOLDON is on anyway.

Hand bounds (12 ms cycle, the controller commands 0.48 mm per cycle = 40 mm/s along +x):
- HOLDON off: after the gateway died the robot applies at most the one answer already on
  its way (RSI answers each <Rob> once; an answer to an earlier <Rob> is late and dropped):
  at most 1 x 0.48 mm. (The old defaults: up to 99 x 0.48 = 47.5 mm.)
- HOLDON on, limit L = 20, gateway robot_late_limit = 20, the envelope's +x face W: each
  step s is at most (W - x) / 21 (x + 21 s <= W), and the robot adds at most the answer on
  its way + L - 1 = 19 repeats of it: 20 s <= 20/21 (W - x) < W - x: inside. Without the
  accounting, killed 5 mm from W at 0.48 mm a step, 20 x 0.48 = 9.6 mm would cross by 4.6 mm.
"""

from __future__ import annotations

import numpy as np
import pytest

from humanpt.robot_gateway.links.rsi.protocol import RsiCorrection, decode_rob, encode_sen
from humanpt.robot_gateway.safety import clip_to_envelope
from humanpt.sim_robot.config import SimRobotConfig
from humanpt.sim_robot.rsi import RsiRobot
from tests.conftest import wait_for
from tests.robot_gateway.rig import Rig
from tests.rsi.live_cell import LiveCell

STEP_MM = 0.48  # 40 mm/s x 12 ms
WIRE_MM = 0.00005  # RKorr is rounded to 4 decimals: half a wire unit per step at most


def test_the_twins_default_rsi_robot_is_holdon_off_with_a_low_late_limit():
    cfg = SimRobotConfig(protocol="rsi", cycle_period_ns=12_000_000)
    assert cfg.rsi_holdon is False and cfg.rsi_late_limit == 10


@pytest.mark.parametrize("holdon, limit", [(False, 10), (True, 10), (True, 100)])
def test_after_the_last_answer_the_robot_moves_by_its_holdon_repeats_only(holdon, limit):
    """Pure, given times: 5 answered cycles of 0.48 mm, then silence until RSI stops."""
    robot = RsiRobot(SimRobotConfig(protocol="rsi", cycle_period_ns=12_000_000, rsi_holdon=holdon, rsi_late_limit=limit))
    t = 0
    for _ in range(5):
        rob = robot.cycle(t)
        robot.receive(encode_sen(RsiCorrection(decode_rob(rob).ipoc, (STEP_MM, 0, 0, 0, 0, 0))), t + 1_000_000)
        t += 12_000_000
    x_last = robot.base_T_flange_mm[0, 3]  # before the boundary that applies the 5th answer
    while robot.cycle(t) is not None:
        t += 12_000_000
    moved = robot.base_T_flange_mm[0, 3] - x_last
    repeats = limit - 1 if holdon else 0  # the limit-th late answer stops RSI before repeating
    assert moved == pytest.approx(STEP_MM * (1 + repeats), abs=1e-6)
    assert robot.stopped is not None and f"{limit} late answers in a row" in robot.stopped


def test_clip_to_envelope_keeps_the_repeats_inside_by_hand():
    lo, hi = np.array([-100.0, -100.0, -100.0]), np.array([10.0, 100.0, 100.0])
    p = np.array([5.0, 0.0, 0.0])
    dp, cut = clip_to_envelope(p, np.array([1.0, 0.5, 0.0]), lo, hi, repeats=9)
    # x: 5 + 10 x 1.0 = 15 > 10: the step is the room left / 10 = 0.5; y: 0 + 10 x 0.5 = 5: kept
    assert cut and dp.tolist() == [0.5, 0.5, 0.0]
    dp, cut = clip_to_envelope(p, np.array([0.4, 0.0, 0.0]), lo, hi, repeats=9)
    assert not cut and dp.tolist() == [0.4, 0.0, 0.0]  # 5 + 10 x 0.4 = 9 < 10
    dp, cut = clip_to_envelope(p, np.array([1.0, 0.0, 0.0]), lo, hi)  # no repeats: as before
    assert not cut and dp.tolist() == [1.0, 0.0, 0.0]
    dp, cut = clip_to_envelope(p, np.array([6.0, 0.0, 0.0]), lo, hi)
    assert cut and dp.tolist() == [5.0, 0.0, 0.0]


def test_the_gateway_cuts_a_step_so_that_its_repeats_stay_inside():
    wall = 790.0  # the +x face; the rig's flange is at x = START_X[0]
    rig = Rig(link="rsi", cycle_period_ms=12.0, robot_late_limit=10, envelope_max_mm=(wall, 1600.0, 1600.0))
    x = rig.robot.rist[0]
    assert wall - x < 11 * STEP_MM  # close enough that 11 full steps would cross
    rig.status()
    rig.command(dp_mm=(STEP_MM, 0, 0))
    c = rig.corrections[-1][1]
    assert c.rkorr[0] == pytest.approx((wall - x) / 11, abs=WIRE_MM)
    assert x + 11 * c.rkorr[0] <= wall + 11 * WIRE_MM
    assert "envelope" in rig.codes() and "10 repeats" in rig.events()[-1].text
    # robot_late_limit 0 (a robot that applies zero when late): the step is cut at the face only
    rig0 = Rig(link="rsi", cycle_period_ms=12.0, robot_late_limit=0, envelope_max_mm=(wall, 1600.0, 1600.0))
    rig0.status()
    rig0.command(dp_mm=(STEP_MM, 0, 0))
    assert rig0.corrections[-1][1].rkorr[0] == pytest.approx(STEP_MM)


def _kill(cell: LiveCell) -> float:
    """SIGKILL the gateway process; once it is dead, the robot's x (mm)."""
    cell.gw.kill()
    cell.gw.wait(10)
    return cell.x_mm


@pytest.mark.timeout(120)
def test_gateway_killed_mid_motion_the_default_robot_moves_at_most_the_answer_on_its_way(router, procs, tmp_path):
    cell = LiveCell(procs, router[0], tmp_path)
    try:
        cell.start_gateway()
        cell.start_controller()
        robot = cell.start_robot()  # the twin's defaults: HOLDON off, late limit 10
        cell.wait_moving(applied=30)
        x_dead = _kill(cell)
        cell.server.join(30.0)  # RSI stops after 10 late answers in a row
        assert robot.stopped is not None and "10 late answers in a row" in robot.stopped, robot.stopped
        moved = cell.x_mm - x_dead
        assert -1e-6 <= moved <= STEP_MM + WIRE_MM, moved
        late = [e for e in robot.events if e.code == "late_reply"]
        assert late and "zero correction (HOLDON=0)" in late[-1].text
    finally:
        cell.close()


@pytest.mark.timeout(120)
def test_gateway_killed_near_the_envelope_with_holdon_on_the_repeats_stay_inside(router, procs, tmp_path):
    limit = 20
    x0 = RsiRobot(SimRobotConfig(protocol="rsi", cycle_period_ns=12_000_000)).base_T_flange_mm[0, 3]
    wall = float(x0) + 15.0
    cell = LiveCell(procs, router[0], tmp_path, robot_late_limit=str(limit),
                    envelope_max_mm=f"[{wall}, 1600.0, 1600.0]")
    try:
        cell.start_gateway()
        cell.start_controller()
        robot = cell.start_robot(rsi_holdon=True, rsi_late_limit=limit)
        # Inside the zone where full steps and their repeats would cross: 20 x 0.48 = 9.6 mm > 5 mm.
        wait_for(lambda: wall - cell.x_mm < 5.0 or robot.stopped is not None, 60.0, "the flange 5 mm from the face")
        assert robot.stopped is None, robot.stopped
        x_dead = _kill(cell)
        cell.server.join(30.0)
        assert robot.stopped is not None and f"{limit} late answers in a row" in robot.stopped, robot.stopped
        x_end = cell.x_mm
        assert x_end <= wall + (limit + 1) * WIRE_MM, (x_end, wall)
        last = robot._last  # the last answer applied in time: HOLDON repeated it
        if last is not None and last.rkorr[0] > 0:  # (not if it was a hold: none on a loaded machine)
            assert x_end > x_dead  # the robot did move on its own: the accounting, not luck, kept it inside
        assert any(e.code == "envelope" for e in cell.events)
    finally:
        cell.close()

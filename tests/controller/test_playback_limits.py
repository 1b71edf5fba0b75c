"""A playback is refused before anything moves when a point lies outside the workspace
envelope (issue 29, item 4), and the controller's work for a playback command is bounded
(item 9): the largest command it takes is handled well inside one ALTER cycle (printed, not
asserted), a larger one is refused with one event before it is parsed or converted."""

from __future__ import annotations

import json
import os
import statistics
import time

import numpy as np
import pytest

from humanpt.controller.config import ControllerConfig
from humanpt.controller.core import ControllerCore
from humanpt.controller.playback import MAX_ARGS_CHARS, MAX_PLAYBACK_POINTS, PlaybackError, thin
from humanpt.robot_gateway.links.alter.config import AlterConfig
from humanpt.robot_gateway.links.rsi.config import RsiConfig
from humanpt.runtime import config as cfgmod
from humanpt.schemas import humanpt_pb2 as pb


def _send(core: ControllerCore, args) -> list[pb.Event]:
    text = args if isinstance(args, str) else json.dumps(args)
    outs = core.step(0, "console/command", pb.Command(component="controller", verb="playback", args_json=text))
    return [m for t, m in outs if t == "controller/events"]


def _line(n: int, x0_mm: float = 400.0, speed_mm_s: float = 20.0, dt_s: float = 0.028):
    """A straight seam at ``speed_mm_s`` sampled every ``dt_s``: tool pointing down (pitch
    90 deg puts the tool's z along world -x... any fixed orientation serves)."""
    t = np.arange(n) * dt_s
    x = np.column_stack([x0_mm + speed_mm_s * t, np.zeros(n), np.full(n, 300.0), np.zeros((n, 3))])
    return {"points": np.round(x, 4).tolist(), "times_s": np.round(t, 6).tolist()}


def test_a_seam_3000_mm_outside_the_envelope_is_refused_naming_the_point_and_the_limit():
    # The attack: a seam 3000 mm beyond the envelope's +x face (1600 mm by default, the
    # gateway's) was accepted and started.  Tool along the flange's z, 200 mm (flange_T_tool_x):
    # with the orientation (0, 0, 0) the flange is 200 mm below the tool, same x.
    core = ControllerCore(ControllerConfig())
    ev = _send(core, {"points": [[4600.0, 0.0, 300.0, 0.0, 0.0, 0.0], [4640.0, 0.0, 300.0, 0.0, 0.0, 0.0]],
                      "speed_mm_s": 20})
    assert [e.code for e in ev] == ["bad_command"] and ev[0].severity == pb.SEVERITY_WARNING
    text = ev[0].text
    assert "point 0 of 2" in text and "x 4600.0 is above" in text and "max 1600 mm" in text, text
    assert "flange at [4600.0, 0.0, 100.0]" in text, text
    assert "\n" not in text
    assert core.playback is None and core.mode != pb.CONTROL_MODE_PLAYBACK


def test_the_first_point_outside_is_named_and_the_flange_not_the_tool_is_checked():
    core = ControllerCore(ControllerConfig(envelope_min_mm=(-800.0, -800.0, 0.0),
                                           envelope_max_mm=(800.0, 800.0, 900.0)))
    ok = [500.0, 0.0, 300.0, 0.0, 0.0, 0.0]
    # The tool at z 150 is inside, its flange (200 mm above along the tool's z, pointing
    # down: yaw 0, pitch 0, roll 180 flips z) at 350... inside; at z 100 with the tool
    # pointing up the flange is at -100: below the box's z min 0.
    low = [500.0, 0.0, 100.0, 0.0, 0.0, 0.0]
    ev = _send(core, {"points": [ok, ok, low, ok], "speed_mm_s": 20})
    assert [e.code for e in ev] == ["bad_command"]
    assert "point 2 of 4" in ev[0].text and "z -100.0 is below" in ev[0].text and "min 0 mm" in ev[0].text
    assert core.playback is None
    down = [500.0, 0.0, 100.0, 0.0, 0.0, 180.0]  # roll 180: the flange 200 mm above the tool
    assert [e.code for e in _send(core, {"points": [ok, down], "speed_mm_s": 20})] == ["playback_started"]


def test_the_controller_takes_the_gateways_envelope_from_the_cells_config():
    # One envelope in the config file, [robot_gateway]'s: the controller checks against it.
    cfg = cfgmod.from_dict({"robot_gateway": {"envelope_min_mm": [-700, -700, -100],
                                              "envelope_max_mm": [700, 700, 800]}}, "cell.toml")
    ctl = cfg.component("controller", ControllerConfig)
    assert ctl.envelope_min_mm == (-700.0, -700.0, -100.0) and ctl.envelope_max_mm == (700.0, 700.0, 800.0)
    # A smaller box of the controller's own stands.
    cfg = cfgmod.from_dict({"robot_gateway": {"envelope_max_mm": [700, 700, 800]},
                            "controller": {"envelope_max_mm": [600, 600, 600]}}, "cell.toml")
    assert cfg.component("controller", ControllerConfig).envelope_max_mm == (600.0, 600.0, 600.0)
    ev = _send(ControllerCore(ctl), {"points": [[750.0, 0.0, 300.0, 0.0, 0.0, 0.0]]})
    assert "x 750.0 is above" in ev[0].text and "max 700 mm" in ev[0].text, ev[0].text
    # Without an envelope in the file both take the gateway's defaults (ALTER's and RSI's).
    assert ControllerConfig().envelope_min_mm == AlterConfig().envelope_min_mm == \
        RsiConfig().envelope_min_mm
    assert ControllerConfig().envelope_max_mm == AlterConfig().envelope_max_mm == \
        RsiConfig().envelope_max_mm
    with pytest.raises(cfgmod.ConfigError, match="envelope_min_mm"):
        cfgmod.from_dict({"controller": {"envelope_min_mm": [0, 0, 0], "envelope_max_mm": [0, 1, 1]}},
                         "cell.toml").component("controller", ControllerConfig)


def test_the_largest_command_is_taken_and_a_larger_one_refused_with_one_event():
    core = ControllerCore(ControllerConfig())
    ev = _send(core, _line(MAX_PLAYBACK_POINTS))
    assert [e.code for e in ev] == ["playback_started"] and f"{MAX_PLAYBACK_POINTS} points timed" in ev[0].text
    assert core.mode == pb.CONTROL_MODE_PLAYBACK
    core = ControllerCore(ControllerConfig())
    ev = _send(core, _line(MAX_PLAYBACK_POINTS + 1))
    assert [e.code for e in ev] == ["bad_command"]
    assert f"{MAX_PLAYBACK_POINTS + 1} points; the controller takes at most {MAX_PLAYBACK_POINTS}" in ev[0].text
    assert core.playback is None
    # The text is bounded before it is parsed: 10^6 points (the old limit) never reach json.
    big = '{"points": [' + ", ".join(["[1, 2, 3, 0, 0, 0]"] * 30_000) + "]}"
    assert len(big) > MAX_ARGS_CHARS
    ev = _send(core, big)
    assert [e.code for e in ev] == ["bad_command"] and f"at most {MAX_ARGS_CHARS}" in ev[0].text


def test_a_recorded_path_longer_than_a_playback_is_refused():
    core = ControllerCore(ControllerConfig())
    core.path = [pb.PathPoint()] * (MAX_PLAYBACK_POINTS + 1)  # what a long recording leaves
    ev = _send(core, {})
    assert [e.code for e in ev] == ["bad_command"] and "recorded path has 2001 points" in ev[0].text


@pytest.mark.parametrize("args, needle", [
    ('{"points": [[true, 0, 0, 0, 0, 0]]}', "points[0]"),
    ('{"points": [[0, 0, 0, 0, 0, 0], [0, 0, 0, 0, 0, "1"]]}', "points[1][5]"),
    ('{"points": [[0, 0, 0, 0, 0, 0], [0, 0, 0, 0, 0, 0]], "times_s": [0, false]}', "times_s[1]"),
    ('{"points": [[0, 0, 0, 0, 0, 0], [0, 0, 0, 0, 0, 0]], "times_s": [0, NaN]}', "times_s[1]"),
    ('{"points": [[0, 0, 0, 0, 0, 0]], "times_s": [-1]}', "times_s[0]"),
    ('{"points": [0, 0, 0, 0, 0, 0]}', "points[0]"),
    ('{"points": {"a": 1}}', "points"),
])
def test_the_vectorised_checks_name_the_first_bad_element(args, needle):
    core = ControllerCore(ControllerConfig())
    ev = _send(core, args)
    assert [e.code for e in ev] == ["bad_command"] and needle in ev[0].text, ev[0].text
    assert core.playback is None


def test_thinning_keeps_every_sample_within_the_tolerance_or_refuses():
    # A straight line at constant speed thins to 2000 points exactly (linear in time).
    big = _line(10_000)
    x, t = thin(np.array(big["points"]), np.array(big["times_s"]))
    assert len(x) <= MAX_PLAYBACK_POINTS and x[0][0] == 400.0 and x[-1][0] == big["points"][-1][0]
    # A circle of radius 50 mm at 20 mm/s, 280 s: every 5th sample is 2.8 mm of arc, a chord
    # 2.8^2 / (8 * 50) = 0.0196 mm from it (inside 0.05 mm); 10 000 samples need every 5th.
    t = np.arange(10_000) * 0.028
    a = 20.0 * t / 50.0
    circle = np.column_stack([50 * np.cos(a), 50 * np.sin(a), np.zeros((len(t), 4))])
    x, _ = thin(circle, t)
    assert len(x) <= MAX_PLAYBACK_POINTS
    # 40 000 samples need every 21st: a chord 11.76 mm long passes 0.346 mm from the arc.
    t = np.arange(40_000) * 0.028
    a = 20.0 * t / 50.0
    with pytest.raises(PlaybackError, match=r"do not fit the controller's 2000 points: every 21th sample passes 0.3"):
        thin(np.column_stack([50 * np.cos(a), 50 * np.sin(a), np.zeros((len(t), 4))]), t)


def test_benchmark_the_largest_command_fits_a_cycle(capsys):
    """Not a timed assertion: prints what the core's handling of the largest playback
    command costs here (parse, check, envelope, prepare), against the 28 ms ALTER cycle."""
    args = json.dumps(_line(MAX_PLAYBACK_POINTS))
    msg = pb.Command(component="controller", verb="playback", args_json=args)
    cpu, wall = [], []
    for _ in range(21):
        core = ControllerCore(ControllerConfig())
        t0, c0 = time.perf_counter(), time.thread_time()
        outs = core.step(0, "console/command", msg)
        cpu.append((time.thread_time() - c0) * 1e3)
        wall.append((time.perf_counter() - t0) * 1e3)
        assert [m.code for t, m in outs if t == "controller/events"] == ["playback_started"]
    with capsys.disabled():
        print(f"\ncontroller core: a playback command of {MAX_PLAYBACK_POINTS} points ({len(args)} characters) "
              f"handled in {statistics.median(cpu):.1f} ms of CPU median ({max(cpu):.1f} max; wall "
              f"{statistics.median(wall):.1f} / {max(wall):.1f} ms at load {os.getloadavg()[0]:.1f}) over "
              f"{len(cpu)} commands; one ALTER cycle is 28 ms")

"""Every console command's arguments are checked before they touch the controller (issue 14,
item 7): the attack's commands each get one ``bad_command`` event and change nothing."""

from __future__ import annotations

import json

import pytest

from humanpt.controller.config import ControllerConfig
from humanpt.controller.core import ControllerCore
from humanpt.schemas import humanpt_pb2 as pb

BAD = [
    ("calibrate", '{"samples": "x"}', "samples"),
    ("calibrate", '{"samples": 5}', "samples"),  # the pivot fit has 6 unknowns
    ("calibrate", '{"pivot_mm": [1, 2]}', "pivot_mm"),
    ("calibrate", '{"pivot_mm": [1, 2, NaN]}', "pivot_mm[2]"),
    ("playback", '{"speed_mm_s": NaN}', "speed_mm_s"),
    ("playback", '{"speed_mm_s": 1e9}', "speed_mm_s"),
    ("playback", '{"speed_mm_s": 150}', "max_speed_mm_s"),  # above the controller's 100 mm/s
    ("playback", '{"speed_mm_s": -5}', "speed_mm_s"),
    ("playback", '{"points": [[0, 0, 0, 0, 0, Infinity]]}', "points[0][5]"),
    ("playback", '{"points": [[0, 0, 0, 0, 0]]}', "points[0]"),
    ("playback", '{"points": [[1e308, 0, 0, 0, 0, 0]]}', "points[0][0]"),
    ("playback", "{}", "no path recorded"),
    ("save", '{"file": "/etc/passwd"}', "plain file name"),
    ("save", '{"file": "../x.csv"}', "plain file name"),
    ("save", '{"file": ".hidden"}', "plain file name"),
    ("save", '{"file": 3}', "file"),
    ("track", '{"now": true}', "unknown argument 'now'"),
    ("fly", "{}", "unknown verb 'fly'"),
    ("hold", "[1, 2]", "JSON object"),
    ("hold", "{", "not JSON"),
    ("hold", "[" * 100_000, "not JSON"),
]


@pytest.mark.parametrize("verb,args,needle", BAD, ids=[f"{v} {a[:30]}" for v, a, _ in BAD])
def test_a_bad_command_is_refused_and_changes_nothing(verb, args, needle):
    core = ControllerCore(ControllerConfig())
    mode, config = core.mode, core.config
    outs = core.step(0, "console/command", pb.Command(component="controller", verb=verb, args_json=args))
    events = [m for t, m in outs if t == "controller/events"]
    assert [e.code for e in events] == ["bad_command"], events
    assert needle in events[0].text and events[0].severity == pb.SEVERITY_WARNING
    assert core.mode == mode and core.config == config and core.playback is None


def test_good_commands_are_taken():
    core = ControllerCore(ControllerConfig())

    def send(verb, **args):
        outs = core.step(0, "console/command", pb.Command(verb=verb, args_json=json.dumps(args)))
        return [m.code for t, m in outs if t == "controller/events"]

    assert send("calibrate", samples=6, pivot_mm=[1, 2, 3]) == ["calibration_started"]
    assert core.mode == pb.CONTROL_MODE_CALIBRATE and core.cal_target == 6
    assert send("playback", points=[[500, 0, 300, 0, 90, 0]], speed_mm_s=20) == ["playback_started"]
    assert core.mode == pb.CONTROL_MODE_PLAYBACK
    assert send("save", file="seam") == ["save"]
    assert json.loads(core.step(0, "console/command", pb.Command(verb="save", args_json='{"file": "a.csv"}'))
                      [0][1].text)["file"] == "a.csv"

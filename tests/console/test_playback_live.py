"""`humanpt path play` and `console playback` against a running cell (a real router, the
robot gateway and the controller as processes), issue 29:

* item 4: a seam 3000 mm outside the workspace envelope is refused before anything is
  sent, by the client (against the gateway's live envelope) and, for a command sent past
  the client, by the controller (against the gateway's envelope from the cell's config);
* item 9: the issue's 1795-point seam plays; a seam too long for one playback and a path
  file with more points than the controller takes are refused before anything is sent,
  without the memory the attack took (3.05 GB);
* item 14: `console set ../x=1` and other names that would be Zenoh key expressions are
  refused with one line, no traceback.
"""

from __future__ import annotations

import queue
import re

import pytest

from humanpt.runtime.recording import read
from humanpt.schemas import humanpt_pb2 as pb
from humanpt.seam import seamfile
from humanpt.seam.fit import FitConfig, Seam, Segment
from tests.conftest import (
    run_cli,
    run_measured,
    wait_for,
    wait_matching,
    write_config,
    zenoh_client,
)
from tests.console import test_console
from tests.console.test_console import _wait_alive, cell_of

# test_console's fixtures: one router for the module, a cell of its own per test; the CLI in-process
shared_router, router = test_console.shared_router, test_console.router

pytestmark = pytest.mark.timeout(240)

# The cell's envelope, in [robot_gateway] only: the controller takes it from there.
ENVELOPE = 'envelope_min_mm = [-800.0, -800.0, -200.0]\nenvelope_max_mm = [800.0, 800.0, 900.0]\n'


def _seam(path, start, end, ypr=(0.0, 0.0, 0.0)):
    """A one-line seam file from ``start`` to ``end`` (mm), the tool at ``ypr`` (deg)."""
    seg = Segment("line", 0, 5, tuple(start), tuple(end), ypr, ypr, 0.0, 0.0, 6)
    return seamfile.write(path, Seam((seg,), (), (), (), 0.0, FitConfig(), 6))


@pytest.fixture
def cell(router, procs, tmp_path):
    """router + robot_gateway (pyserial's loopback: no robot needed) + controller."""
    port, on_cell = router
    cfg = write_config(tmp_path / "cell.toml", port, extra=f'[robot_gateway]\nport = "loop://"\n{ENVELOPE}',
                       cell=cell_of(on_cell))
    run = tmp_path / "run"
    procs.start("robot_gateway", "--config", str(cfg), "--run-dir", str(run))
    ctl = procs.start("controller", "--config", str(cfg), "--run-dir", str(run))
    _wait_alive(port, ("robot_gateway", "controller"), cell=cell_of(cfg))
    return port, cfg, run, ctl


def _commands(procs, ctl, run) -> list[tuple[str, str]]:
    """(verb, the controller's answer) of each console command the controller received."""
    procs.stop(ctl)
    rec = read(run / "controller.mcap")
    verbs = [e.decode().verb for e in rec.inputs if e.topic == "console/command"]
    codes = [e.decode().code for e in rec.outputs if e.topic == "controller/events"
             and e.decode().code in ("bad_command", "playback_started", "command")]
    return list(zip(verbs, codes, strict=True))


def test_a_seam_outside_the_envelope_is_refused_by_the_client_and_by_the_controller(cell, procs, tmp_path, cli):
    port, cfg, run, ctl = cell
    key = f"humanpt/{cell_of(cfg)}"
    # 3000 mm beyond the envelope's +x face (800 mm): tool (0, 0, 0), the flange 200 mm
    # below it (flange_T_tool_x), at the same x.
    far = _seam(tmp_path / "far.seam.json", (3800.0, 0.0, 300.0), (3840.0, 0.0, 300.0))
    r = run_cli("path", "play", str(far), "--config", str(cfg), "--timeout", "20", timeout=120)
    assert r.returncode == 1, r.stdout + r.stderr
    line = r.stderr.strip()
    assert "\n" not in line and "Traceback" not in line, line
    assert "refused, nothing sent" in line and "point 0 of" in line, line
    assert "x 3800.0 is above the robot gateway's envelope's max 800 mm" in line, line
    assert "playback_started" not in r.stdout

    # Past the client: the same points straight onto the bus; the controller refuses them
    # against the gateway's envelope ([robot_gateway] of the cell's config, not its default).
    events: queue.Queue = queue.Queue()
    with zenoh_client(port) as s:
        sub = s.declare_subscriber(f"{key}/controller/events",
                                   lambda smp: events.put(pb.Event.FromString(smp.payload.to_bytes())))
        pub = s.declare_publisher(f"{key}/console/command")
        wait_matching(pub)
        pub.put(pb.Command(header=pb.Header(seq=1), component="controller", verb="playback",
                           args_json='{"points": [[3800, 0, 300, 0, 0, 0], [3840, 0, 300, 0, 0, 0]], '
                                     '"speed_mm_s": 20}').SerializeToString())
        got: list[pb.Event] = []

        def answered() -> bool:
            while not events.empty():
                got.append(events.get())
            return any(e.code in ("bad_command", "playback_started") for e in got)

        wait_for(answered, 30.0, "the controller's answer")
        sub.undeclare()
    ev = next(e for e in got if e.code in ("bad_command", "playback_started"))
    assert ev.code == "bad_command", ev
    assert "point 0 of 2" in ev.text and "x 3800.0 is above" in ev.text and "max 800 mm" in ev.text, ev.text

    # Inside: it plays.  Then the gateway's envelope is made stricter at run time: the
    # client checks the gateway's live value (the authority) and refuses the same seam.
    near = _seam(tmp_path / "near.seam.json", (300.0, 0.0, 300.0), (340.0, 0.0, 300.0))
    code, out, err = cli("path", "play", str(near), "--config", str(cfg), "--timeout", "20")
    assert code == 0 and "playback_started" in out, out + err
    code, out, err = cli("param", "robot_gateway", "envelope_max_mm=[320, 800, 900]", "--config", str(cfg),
                         "--timeout", "20")
    assert code == 0, out + err
    code, out, err = cli("path", "play", str(near), "--config", str(cfg), "--timeout", "20")
    assert code == 1, out + err
    assert re.search(r"x 3[2-4]\d\.\d is above the robot gateway's envelope's max 320 mm", err), err
    # The controller saw two playbacks: the one sent past the client (refused) and the one inside.
    assert _commands(procs, ctl, run) == [("playback", "bad_command"), ("playback", "playback_started")]


def test_the_issues_seam_plays_and_oversized_ones_are_refused_before_sending(cell, procs, tmp_path, cli):
    port, cfg, run, ctl = cell
    # The issue's seam: 1000 mm at 20 mm/s is 50.25 s, 1796 samples of 28 ms (it had 1795).
    seam = _seam(tmp_path / "long.seam.json", (-300.0, 0.0, 300.0), (700.0, 0.0, 300.0))
    code, out, err = cli("path", "play", str(seam), "--config", str(cfg), "--timeout", "20")
    assert code == 0 and "playback_started: 1796 points timed, 50.3 s" in out, out + err

    # 8000 mm at 0.2 mm/s: 40 000 s, 1.4 million samples (the attack's 10^6 points took the
    # CLI 97 s and 3.05 GB): refused before re-timing, before connecting.
    huge = _seam(tmp_path / "huge.seam.json", (-4000.0, 0.0, 300.0), (4000.0, 0.0, 300.0))
    code, out, err, _ = run_measured("path", "play", str(huge), "--speed", "0.2", "--config", str(cfg))
    text = out + err
    assert code == 1 and "too long for one playback" in text and "more than 200000 samples" in text, text
    assert "Traceback" not in text and len(text.strip().splitlines()) == 1, text

    # A path file with more rows than the controller's 2000 points: counted, not parsed.
    big = tmp_path / "big.csv"
    with big.open("w") as f:
        f.write("index,stamp_ns,x_mm,y_mm,z_mm,psi_deg,theta_deg,phi_deg\n")
        for i in range(300_000):
            f.write(f"{i},{i * 28_000_000},{i * 1e-3:.3f},0,300,0,0,0\n")
    code, out, err, peak_kb = run_measured("console", "playback", str(big), "--config", str(cfg))
    text, peak_mb = out + err, peak_kb // 1024
    assert code == 1 and "more than 2000 points" in text and "Traceback" not in text, text
    assert peak_mb < 1000, peak_mb  # the attack's CLI grew to 3.05 GB
    # Nothing of either reached the controller.
    code, out, err = cli("console", "hold", "--config", str(cfg), "--timeout", "20")
    assert code == 0, out + err
    assert _commands(procs, ctl, run) == [("playback", "playback_started"), ("hold", "command")]


# Each name in this process (the same parse and check as the command's); the first of each
# list also as its own process, whose whole output (a traceback, a log line) is checked too.
KEY_NAMES = ["../x=1", "*.x=1", "$x.y=1", ".x=1", "controller.=1", "controller.a/b=1", "controller.**=1",
             "perception..x=1"]
BAD_CELLS = ["$x", "..", "a?b", "a#b", "a b", "@x"]


def _one_line(code: int, text: str) -> str:
    text = text.strip()
    assert code != 0 and "Traceback" not in text and "ZError" not in text and len(text.splitlines()) == 1, text
    return text


def test_console_names_that_would_be_key_expressions_are_refused_in_one_line(router, cli):
    _, cfg = router
    r = run_cli("console", "set", KEY_NAMES[0], "--config", str(cfg), "--timeout", "5", timeout=120)
    assert r.returncode == 1 and KEY_NAMES[0] in _one_line(r.returncode, r.stdout + r.stderr)
    for assignment in KEY_NAMES:
        code, out, err = cli("console", "set", assignment, "--config", str(cfg), "--timeout", "5")
        assert code == 1, (assignment, out + err)
        assert assignment in _one_line(code, out + err), assignment


def test_console_cells_that_would_break_key_expressions_are_refused_in_one_line(router, cli):
    # Each gave a zenoh.ZError traceback ("`$` is only allowed in `$*`", "`#` and `?` are
    # forbidden") or, for '..', a cell of that name.
    _, cfg = router
    r = run_cli("console", "--config", str(cfg), "--cell", BAD_CELLS[0], "status", "--timeout", "5", timeout=120)
    assert f"cell {BAD_CELLS[0]!r} must be a name of letters, digits" in _one_line(r.returncode, r.stdout + r.stderr)
    for cell in BAD_CELLS:
        # (the name is checked with the config, before any verb: every verb for one of them)
        for verb in (["status"], ["set", "dz=600"], ["record", "start"]) if cell == "$x" else (["status"],):
            code, out, err = cli("console", "--config", str(cfg), "--cell", cell, *verb, "--timeout", "5")
            assert f"cell {cell!r} must be a name of letters, digits" in _one_line(code, out + err), (cell, verb)

"""The operator console against a real router and live components: GUI options change
the components' live parameters (and the change is in their recordings), commands reach
the controller, the status shows what is published."""

from __future__ import annotations

import itertools
import json
import threading
import time
import tomllib

import numpy as np
import pytest

from humanpt.console.client import ConsoleError, StatusBoard, gui_values, parse_options
from humanpt.runtime.recording import read
from humanpt.schemas import humanpt_pb2 as pb
from humanpt.schemas.convert import header, pose
from tests.conftest import (
    Procs,
    free_port,
    wait_for,
    wait_port,
    write_config,
    zenoh_client,
)

pytestmark = pytest.mark.timeout(150)

_CELLS = itertools.count(1)


@pytest.fixture(scope="module")
def shared_router(tmp_path_factory):
    """One real router for the module's tests (each test on a cell of its own: see ``router``)."""
    ps = Procs()
    port = free_port()
    cfg = write_config(tmp_path_factory.mktemp("router") / "router.toml", port)
    try:
        wait_port(port, proc=ps.start("router", "--config", str(cfg)))
        yield port
    finally:
        ps.stop_all()


@pytest.fixture
def router(shared_router, tmp_path):
    """(port, config path): the module's router, and a config on a cell no other test uses."""
    return shared_router, write_config(tmp_path / "humanpt.toml", shared_router, cell=f"console{next(_CELLS)}")


def cell_of(cfg) -> str:
    return tomllib.loads(cfg.read_text())["runtime"]["cell"]


def _wait_alive(port: int, names: tuple[str, ...], timeout: float = 60.0, cell: str = "test") -> None:
    """Wait until each component answers its params query: what the console needs."""
    with zenoh_client(port) as s:

        def answering() -> bool:
            return all(any(r.ok is not None for r in s.get(f"humanpt/{cell}/{name}/params", timeout=1.0))
                       for name in names)

        wait_for(answering, timeout, f"{names} to answer their params queries", poll_s=0.3)


def _params(rec, key: str) -> list:
    return [
        json.loads(e.decode().value_json)
        for e in rec.inputs
        if e.topic == "param" and e.decode().key == key
    ]


def test_options_map_to_the_owning_components_live_parameters():
    got = parse_options(
        [
            "threshold=70",
            "Inversion=yes",
            "delay=5",
            "dz=650",
            "stop-on-current-location=false",
            "N=30",
            "perception.track_roi=false",
            "calib_samples=40",
        ]
    )
    assert got == {
        "perception": {"threshold": 70.0, "invert": True, "track_roi": False},
        "controller": {
            "recording_delay_cycles": 5,
            "dz_mm": 650.0,
            "lost_action": "return",
            "calibration_samples": 40,
        },
    }
    assert parse_options(["stop=true"]) == {"controller": {"lost_action": "hold"}}
    for bad in ("threshold", "warp=9", "invert=maybe", "delay=ten"):
        with pytest.raises(ConsoleError):
            parse_options([bad])
    assert gui_values({"controller": {"lost_action": "hold", "dz_mm": 600.0}}) == {
        "dz": 600.0,
        "stop-on-current-location": True,
    }


def test_the_mask_is_a_gui_option_and_goes_through_the_perceptions_own_check():
    # issue 33 item 6: the paper's Mask was reachable only through `param`
    import dataclasses

    from humanpt.perception.config import PerceptionConfig

    assert parse_options(["mask=10,20,100,50; 300,0,40,40"]) == {
        "perception": {"mask": [[10, 20, 100, 50], [300, 0, 40, 40]]}}
    assert parse_options(["mask=none"]) == {"perception": {"mask": []}}
    for bad in ("mask=1,2,3", "mask=a,b,c,d", "mask=1,2,3,4;5"):
        with pytest.raises(ConsoleError, match="mask"):
            parse_options([bad])
    # a rectangle without area is the perception's refusal, the same as through `param`
    with pytest.raises(ValueError, match="no area"):
        dataclasses.replace(PerceptionConfig(), mask=parse_options(["mask=10,10,0,5"])["perception"]["mask"])
    assert gui_values({"perception": {"mask": [[1, 2, 3, 4]]}}) == {"mask": [[1, 2, 3, 4]]}


def test_status_board_line_and_block():
    b = StatusBoard()
    assert b.line() == "(no status yet)"
    st = pb.ControllerStatus(
        mode=pb.CONTROL_MODE_POSITION_ONLY,
        visible=2,
        error_translation_m=0.0012,
        error_rotation_rad=0.01,
        recording=True,
        path_points=7,
    )
    b.update("controller/status", st.SerializeToString())
    b.update(
        "robot_gateway/robot_state", pb.RobotState(cycle=42, missed_cycles=1).SerializeToString()
    )
    line = b.line()
    assert (
        "mode POSITION_ONLY" in line
        and "error 1.20 mm 0.57 deg" in line
        and "misses 1 (cycle 42)" in line
    )
    assert "recording yes, 7 points" in line
    assert "controller  mode POSITION_ONLY" in b.block(["controller"])


def test_console_sets_options_and_commands_live_components(router, procs, tmp_path, cli):
    port, cfg = router
    run_dir = tmp_path / "run"
    ctl = procs.start("controller", "--config", str(cfg), "--run-dir", str(run_dir))
    per = procs.start("perception", "--config", str(cfg), "--run-dir", str(run_dir))
    _wait_alive(port, ("controller", "perception"), cell=cell_of(cfg))

    code, out, err = cli("console", "set", "threshold=70", "invert=true", "delay=5", "dz=650",
                         "stop-on-current-location=false", "calib-samples=30", "--config", str(cfg), "--timeout", "20")
    assert code == 0, out + err
    assert out.count("set: ") == 6 and "threshold = 70.0" in out
    code, out, err = cli("console", "--config", str(cfg), "set", "threshold=300")  # the component refuses it
    assert code == 1 and "REJECTED" in out
    code, out, err = cli("console", "show", "--config", str(cfg))
    assert code == 0, out + err
    assert "threshold" in out and "70.0" in out and "stop-on-current-location   false" in out

    code, out, err = cli("console", "record", "start", "--config", str(cfg), "--timeout", "20")
    assert code == 0 and "record_started" in out, out + err
    code, out, err = cli("console", "playback", "--config", str(cfg), "--timeout", "20")  # nothing recorded yet
    assert code == 1 and "REJECTED" in out, out + err
    # Interactive: verbs from stdin, one session.
    code, out, err = cli("console", "--config", str(cfg), "--timeout", "20", stdin="record stop\nhold\nquit\n")
    assert code == 0 and "record_stopped" in out and "hold (stop on current location)" in out, out + err

    # Save: a plain name in the run's paths/ directory, never over a file unless asked, never
    # anywhere else (the attack wrote any file the controller could write).
    save = ("console", "--config", str(cfg), "--timeout", "20", "save")
    code, out, err = cli(*save, "seam")
    assert code == 0 and "path_saved" in out, out + err
    assert (run_dir / "paths" / "seam.csv").is_file()
    code, out, err = cli(*save, "seam")
    assert code == 1 and "exists" in out, out + err
    code, out, err = cli(*save, "seam", "--overwrite")
    assert code == 0 and "path_saved" in out, out + err
    victim = tmp_path / "victim.txt"
    victim.write_text("precious")
    code, out, err = cli(*save, str(victim))
    assert code == 1 and "plain file name" in out, out + err
    assert victim.read_text() == "precious"

    # A seam (issue 21.4): path play sends it re-timed; the console pauses, slows, resumes it.
    from humanpt.seam import seamfile
    from humanpt.seam.fit import Corner, FitConfig, Seam, Segment

    seg = lambda a, b: Segment("line", 0, 5, a, b, (0.0, 15.0, 180.0), (0.0, 15.0, 180.0), 0.0, 0.0, 6)  # noqa: E731
    seam = seamfile.write(tmp_path / "l.seam.json", Seam(
        (seg((300.0, 1200.0, 0.0), (340.0, 1200.0, 0.0)), seg((340.0, 1200.0, 0.0), (340.0, 1230.0, 0.0))),
        (Corner((340.0, 1200.0, 0.0), 90.0, 0, 1),), (), (), 0.0, FitConfig(), 12))
    code, out, err = cli("path", "play", str(seam), "--speed", "25", "--config", str(cfg), "--timeout", "20")
    assert code == 0 and "playback_started" in out and "timed" in out, out + err
    for verb, answer in (("pause", "playback_paused"), ("rate", "playback_rate"), ("resume", "playback_resumed")):
        code, out, err = cli("console", verb, *(["0.5"] if verb == "rate" else []), "--config", str(cfg),
                             "--timeout", "20")
        assert code == 0 and answer in out, (verb, out + err)

    procs.stop(ctl)
    procs.stop(per)
    prec, crec = read(run_dir / "perception.mcap"), read(run_dir / "controller.mcap")
    assert _params(prec, "threshold") == [70.0, 300.0] and _params(prec, "invert") == [True]
    assert prec.config()["threshold"] == 60.0  # the recorded start config; the change is an input
    assert _params(crec, "dz_mm") == [650.0] and _params(crec, "recording_delay_cycles") == [5]
    assert _params(crec, "lost_action") == ["return"] and _params(crec, "calibration_samples") == [
        30
    ]
    verbs = [e.decode().verb for e in crec.inputs if e.topic == "console/command"]
    assert verbs == ["record_start", "playback", "record_stop", "hold", "save", "save", "save", "save", "playback",
                     "playback_pause", "playback_rate", "playback_resume"]
    codes = [e.decode().code for e in crec.outputs if e.topic == "controller/events"]
    assert "record_started" in codes and "record_stopped" in codes
    assert sum(c == "param_changed" for c in codes) == 4


def test_console_status_shows_what_is_published(router, cli):
    port, cfg = router
    cell = cell_of(cfg)
    stop = threading.Event()

    def publish():
        with zenoh_client(port) as s:
            st = s.declare_publisher(f"humanpt/{cell}/controller/status")
            rs = s.declare_publisher(f"humanpt/{cell}/robot_gateway/robot_state")
            i = 0
            while not stop.is_set():
                st.put(
                    pb.ControllerStatus(
                        header=header(i),
                        mode=pb.CONTROL_MODE_TRACK,
                        visible=3,
                        error_translation_m=0.0004,
                        recording=True,
                        path_points=i,
                        cycle=i,
                    ).SerializeToString()
                )
                rs.put(
                    pb.RobotState(
                        header=header(i), world_T_flange=pose(np.eye(4)), cycle=i, missed_cycles=0
                    ).SerializeToString()
                )
                i += 1
                time.sleep(0.03)

    th = threading.Thread(target=publish, daemon=True)
    th.start()
    try:
        code, out, err = cli("console", "status", "--config", str(cfg), "--timeout", "20")
        assert code == 0, out + err
        assert "controller  mode TRACK, visible sources 3, error |G-D| 0.400 mm" in out
        assert "robot       cycle" in out
        code, out, err = cli("console", "status", "--follow", "--duration", "1.5", "--interval", "0.3",
                             "--config", str(cfg))
        assert code == 0 and "mode TRACK" in out and "misses 0" in out, out + err
    finally:
        stop.set()
        th.join(5)


def test_console_says_when_nobody_answers(router, cli):
    port, cfg = router
    code, out, err = cli("console", "record", "start", "--config", str(cfg), "--timeout", "1")
    assert code == 1 and "is the controller running?" in err
    code, out, err = cli("console", "set", "dz=500", "--config", str(cfg), "--timeout", "1")
    assert code == 1 and "controller did not answer" in out
    code, out, err = cli("console", "status", "--config", str(cfg), "--timeout", "1")
    assert code == 1 and "no status within 1 s" in out


def test_reset_fault_goes_to_the_gateway_with_the_operators_name(router, procs, tmp_path, cli):
    port, cfg = router
    conf = tmp_path / "gw.toml"
    conf.write_text(cfg.read_text() + f'\n[robot_gateway]\nport = "{tmp_path / "no-robot"}"\n')
    procs.start("robot_gateway", "--config", str(conf), "--run-dir", str(tmp_path / "run"))
    _wait_alive(port, ("robot_gateway",), cell=cell_of(cfg))
    code, out, err = cli("console", "--config", str(conf), "--timeout", "20", "reset-fault")
    assert code == 0 and "no_fault" in out, out + err
    assert "reset_fault by " in out and "@" in out  # who asked, as user@host

"""The acceptance test of issue 36: a live cell (a real router on loopback, the twin's
operator, stand-in robot and camera, perception, controller, scene and the bridge, each its
own process) driven from a Foxglove WebSocket client no one in the project wrote:
@foxglove/ws-protocol's FoxgloveClient over the `ws` package (client/client.mjs, installed
by npm from client/package-lock.json).  One cell, every check in one test."""

from __future__ import annotations

import json
import math
import shutil
import subprocess
from pathlib import Path

import pytest

from humanpt.foxglove_bridge.requests import SERVICES
from humanpt.runtime.recording import read
from tests.conftest import free_port, wait_for, zenoh_client

pytestmark = pytest.mark.timeout(400)

CLIENT = Path(__file__).resolve().parent / "client"
CELL = ("operator", "standin_robot", "sim_camera", "perception", "controller", "scene", "foxglove_bridge")


@pytest.fixture(scope="module")
def node_client(tmp_path_factory) -> Path:
    """client.mjs with its locked dependencies installed (npm ci) in a folder of its own."""
    node, npm = shutil.which("node"), shutil.which("npm")
    if not node or not npm:
        pytest.skip("Node.js and npm are needed for the independent Foxglove client")
    d = tmp_path_factory.mktemp("foxglove-client")
    for f in ("package.json", "package-lock.json", "client.mjs"):
        shutil.copy(CLIENT / f, d / f)
    r = subprocess.run([npm, "ci", "--no-audit", "--no-fund", "--ignore-scripts", "--cache", str(d / ".npm")],
                       cwd=d, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, f"npm ci failed:\n{r.stdout}\n{r.stderr}"
    return d


def _wait_alive(port: int, names: tuple[str, ...], timeout: float = 120.0) -> None:
    """Until each component answers its params query (the bridge's: its server is up)."""
    with zenoh_client(port) as s:
        def answering() -> bool:
            return all(any(r.ok is not None for r in s.get(f"humanpt/test/{n}/params", timeout=1.0)) for n in names)

        wait_for(answering, timeout, f"{names} to answer their params queries", poll_s=0.3)


def test_an_independent_foxglove_client_sees_and_drives_the_live_cell(router, procs, tmp_path, node_client, cli):
    port, cfg = router
    ws_port = free_port()
    cfg.write_text(cfg.read_text() + f"\n[foxglove_bridge]\nport = {ws_port}\n")
    run_dir = tmp_path / "run"
    started = {name: procs.start(name, "--config", str(cfg), "--run-dir", str(run_dir)) for name in CELL}
    _wait_alive(port, CELL)

    client = subprocess.Popen(["node", str(node_client / "client.mjs"), f"ws://127.0.0.1:{ws_port}", "test"],
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=node_client)
    try:
        line = client.stdout.readline()  # the client waits for a change made elsewhere
        if line.strip() == "READY":
            code, out, err = cli("console", "set", "threshold=80", "--config", str(cfg), "--timeout", "20")
            assert code == 0, out + err
        rest, err = client.communicate(timeout=300)
    finally:
        if client.poll() is None:
            client.kill()
            client.communicate()
    assert client.returncode == 0, f"the client failed:\n{line}{rest}\n{err}"
    got = json.loads(rest.strip().splitlines()[-1])
    (tmp_path / "client.json").write_text(json.dumps(got, indent=1))  # what it saw, for a failure's reader

    # The server speaks foxglove.sdk.v1 only: ws-protocol's own subprotocol alone is refused.
    assert got["websocket_v1_only"] == "HTTP 400", got["websocket_v1_only"]
    assert got["server"]["protocol"] == "foxglove.sdk.v1" and got["server"]["name"] == "humanpt"
    assert {"clientPublish", "parameters", "services", "time"} <= set(got["server"]["capabilities"])
    # Every bus topic is a channel (each in the topic table), with its schema.
    from humanpt.schemas import topics

    assert got["channels"] == len(topics.TOPICS)
    assert got["schemas"] == {"camera/image": "foxglove.RawImage", "robot_gateway/robot_state": "humanpt.RobotState",
                              "perception/events": "humanpt.Event", "scene/transforms": "foxglove.FrameTransforms"}
    # The image and a pose, decoded by protobufjs from the advertised schemas: the twin's
    # camera is 640 x 480 mono8 (sim_camera's config), a row of bytes per pixel row.
    img = got["image"]
    assert (img["width"], img["height"], img["encoding"], img["step"]) == (640, 480, "mono8", 640)
    assert img["bytes"] == 640 * 480 and img["max"] > 0
    pose = got["robot_state"]
    q = pose["rotation"]
    assert abs(math.sqrt(q["x"] ** 2 + q["y"] ** 2 + q["z"] ** 2 + q["w"] ** 2) - 1.0) < 1e-6
    assert all(math.isfinite(pose["translation"][k]) for k in "xyz") and pose["cycle"] >= 0
    assert "world->base" in got["transforms"] and "base->flange" in got["transforms"]

    # Parameters: set through the component's checks, refused with the reason shown.
    assert got["set_threshold"] == [{"name": "perception.threshold", "value": 70, "type": "float64"}]
    assert got["param_changed"] == "perception: threshold = 70.0"
    assert got["set_threshold_300"] == [{"name": "perception.threshold", "value": 70, "type": "float64"}]
    assert "255" in got["refused_300"], got["refused_300"]  # the range perception's config states
    assert got["set_unknown"] == [] and "parameters: perception.threshold" in got["refused_unknown"]
    assert "may only become stricter" in got["refused_read_only"]
    params = got["all_parameters"]
    assert params["perception.threshold"] == 70 and params["controller.dz_mm"] == 600
    assert params["controller.lost_action"] == "hold" and params["perception.mask"] == []

    # Services: the console's verbs; the operator's need the operator's rights.
    assert sorted(got["services"]) == sorted(SERVICES)
    assert got["record_start"]["ok"] and "record_started" in got["record_start"]["text"]
    assert got["record_stop"]["ok"] and "record_stopped" in got["record_stop"]["text"]
    assert got["save"]["ok"] and "path_saved" in got["save"]["text"]
    assert (run_dir / "paths" / "fox-seam.csv").is_file()
    assert not got["reset_fault"]["ok"] and "needs the operator" in got["reset_fault"]["text"]
    # Malformed, unknown, out of range: an error reply each, the server goes on.
    assert not got["malformed"]["ok"] and "not JSON" in got["malformed"]["text"]
    assert not got["unknown_field"]["ok"] and "unknown field 'evil'" in got["unknown_field"]["text"]
    assert not got["wrong_type"]["ok"] and "whole number" in got["wrong_type"]["text"]
    # a speed outside the range the controller's check states ([0.001, 250] mm/s)
    assert not got["out_of_range"]["ok"] and "outside its range" in got["out_of_range"]["text"]
    assert not got["unknown_service"]["ok"]
    assert got["garbage_connection"] in ("answered",) or got["garbage_connection"].startswith("closed")
    assert got["after_garbage"]["ok"] and "hold" in got["after_garbage"]["text"]
    # humanpt console set threshold=80, pushed to the subscribed client
    assert got["pushed"] == [{"name": "perception.threshold", "value": 80, "type": "float64"}]
    assert got["client_errors"] == []

    bridge = started["foxglove_bridge"]
    assert bridge.poll() is None, "the bridge died"
    log = procs.stop(bridge)
    assert f"Foxglove WebSocket server at ws://127.0.0.1:{ws_port} for this machine only (loopback)" in log, log
    assert "Traceback" not in log, log
    for name in CELL[:-1]:
        procs.stop(started[name])
    # The controller got the commands as the console sends them, the gateway's name and all.
    crec = read(run_dir / "controller.mcap")
    verbs = [e.decode().verb for e in crec.inputs if e.topic == "console/command"]
    assert verbs[:3] == ["record_start", "record_stop", "save"] and "hold" in verbs and "reset_fault" not in verbs
    assert "return" not in verbs  # what the client published never reached the bus
    assert "what it publishes is dropped" in log
    # The bridge's recording: what the browser was given; images at most as many as came.
    brec = read(run_dir / "foxglove_bridge.mcap")
    images_in = sum(e.topic == "camera/image" for e in brec.inputs)
    images_out = sum(e.topic == "show:camera.image" for e in brec.outputs)
    assert 1 <= images_out <= images_in

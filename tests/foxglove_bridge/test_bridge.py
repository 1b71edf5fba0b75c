"""The Foxglove bridge's pure parts: the core's thinning (hand-counted), the checks of
parameters and service requests; and its server: what a taken port does."""

from __future__ import annotations

import json
import logging
import socket

import pytest
from foxglove_schemas_protobuf.RawImage_pb2 import RawImage

from humanpt.foxglove_bridge.config import FoxgloveBridgeConfig
from humanpt.foxglove_bridge.core import BRIDGED_TOPICS, WHOLE, FoxgloveBridgeCore
from humanpt.foxglove_bridge.requests import (
    PARAMETERS,
    SERVICES,
    RequestError,
    service_command,
    typed_value,
)
from humanpt.runtime.config import ConfigError, build
from humanpt.schemas import humanpt_pb2 as pb
from humanpt.schemas import topics
from humanpt.schemas.convert import header

MS = 1_000_000


def _feed(core, topic, msg, times_ns):
    return [out for t in times_ns for out in core.step(t, topic, msg)]


def test_every_bus_topic_is_bridged_and_forwarded_on_a_local_show_topic():
    assert set(BRIDGED_TOPICS) == set(topics.TOPICS)
    core = FoxgloveBridgeCore(FoxgloveBridgeConfig())
    msg = pb.RobotState(header=header(5), cycle=7)
    ((topic, out),) = core.step(0, "robot_gateway/robot_state", msg)
    assert topic == "show:robot_gateway.robot_state" and "/" not in topic  # local: never published
    assert out is msg


def test_images_and_streams_are_thinned_by_arrival_what_counts_is_not():
    core = FoxgloveBridgeCore(FoxgloveBridgeConfig(max_hz=60.0, image_max_hz=10.0))
    # 40 images a second (every 25 ms) at most 10 a second: those at 0, 100, ..., 900 ms.
    images = _feed(core, "camera/image", RawImage(), [k * 25 * MS for k in range(40)])
    assert len(images) == 10
    # A 4 ms robot link (250 states a second) at most 60 a second (16.7 ms apart): every 5th
    # cycle (20 ms), 50 in the second.
    states = _feed(core, "robot_gateway/robot_state", pb.RobotState(), [k * 4 * MS for k in range(250)])
    assert len(states) == 50
    # Events, the path and the scene's transforms are never thinned.
    assert {"controller/events", "controller/path", "scene/transforms", "scene/log"} <= WHOLE
    events = _feed(core, "controller/events", pb.Event(code="x"), [k * MS for k in range(40)])
    assert len(events) == 40
    assert core.thinned == {"camera/image": 30, "robot_gateway/robot_state": 200}


def test_the_rates_are_live_parameters():
    core = FoxgloveBridgeCore(FoxgloveBridgeConfig(image_max_hz=10.0))
    ((_, ev),) = core.step(0, "param", pb.ParamSet(key="image_max_hz", value_json="20"))
    assert ev.code == "param_changed"
    # 20 a second: every other image of 40 a second.
    assert len(_feed(core, "camera/image", RawImage(), [k * 25 * MS for k in range(40)])) == 20
    ((_, ev),) = core.step(0, "param", pb.ParamSet(key="image_max_hz", value_json="0"))
    assert ev.code == "param_rejected"  # its range starts at 0.1 Hz


def test_config_is_loopback_by_default_and_checks_tls_pairs():
    assert FoxgloveBridgeConfig().host == "127.0.0.1" and FoxgloveBridgeConfig().loopback
    assert not FoxgloveBridgeConfig(host="0.0.0.0").loopback
    with pytest.raises(ConfigError, match="tls_cert_file and tls_key_file go together"):
        build(FoxgloveBridgeConfig, {"tls_cert_file": "c.pem"}, source="t.toml", section="foxglove_bridge")
    with pytest.raises(ConfigError, match="port"):
        build(FoxgloveBridgeConfig, {"port": 70000}, source="t.toml", section="foxglove_bridge")


# -- parameters ------------------------------------------------------------------------------------
def test_the_parameters_are_the_paper_gui_options_and_the_gateway_limits_read_only():
    writable = {n for n, p in PARAMETERS.items() if p.writable}
    assert writable == {"perception.threshold", "perception.invert", "perception.mask", "perception.method",
                        "controller.recording_delay_cycles", "controller.dz_mm", "controller.lost_action",
                        "controller.calibration_samples", "controller.playback_speed_mm_s",
                        "controller.return_flange_x"}  # (every console GUI option: the return pose too)
    assert {n for n in PARAMETERS if n not in writable} == {
        f"robot_gateway.{k}" for k in ("max_speed_mm_s", "max_angular_speed_deg_s", "envelope_min_mm",
                                       "envelope_max_mm", "stale_cycles", "fault_after_missed")}


def test_a_parameter_value_is_typed_as_its_component_takes_it_or_refused():
    assert typed_value("perception.threshold", 70)[1] == 70
    assert typed_value("controller.recording_delay_cycles", 10.0)[1] == 10  # a client's float
    assert typed_value("perception.mask", [[1.0, 2.0, 30.0, 40.0]])[1] == [[1, 2, 30, 40]]
    for name, value, why in [
        ("perception.nope", 1, "unknown parameter 'perception.nope'; parameters: perception.threshold"),
        ("robot_gateway.max_speed_mm_s", 50, "read-only"),
        ("perception.threshold", None, "no value given"),
        ("controller.recording_delay_cycles", 10.5, "expected whole numbers, got 10.5"),
        ("controller.dz_mm", {"a": 1}, "got dict"),
    ]:
        with pytest.raises(RequestError, match=why):
            typed_value(name, value)


# -- services --------------------------------------------------------------------------------------
def _call(name, body, token=None):
    payload = body if isinstance(body, bytes) else json.dumps(body).encode()
    return service_command(name, payload, token, "3")


def test_services_are_the_console_verbs():
    assert set(SERVICES) == {"track", "hold", "return", "record_start", "record_stop", "save", "calibrate_tip",
                             "playback", "playback_pause", "playback_resume", "reset_fault", "alter_on", "alter_off"}
    assert _call("track", b"") == ("controller", "track", {})
    assert _call("save", {"file": "seam", "overwrite": True}) == ("controller", "save",
                                                                  {"file": "seam", "overwrite": True})
    assert _call("calibrate_tip", {"samples": 30.0, "pivot_mm": [1, 2, 3]}) == (
        "controller", "calibrate", {"samples": 30, "pivot_mm": [1, 2, 3]})
    assert _call("playback", {"speed_mm_s": 25}) == ("controller", "playback", {"speed_mm_s": 25})
    schema = SERVICES["save"].schema()
    assert schema["required"] == ["file"] and schema["additionalProperties"] is False


@pytest.mark.parametrize("name, body, why", [
    ("teleport", {}, "unknown service 'teleport'; services: track"),
    ("save", b"{not json", "not JSON"),
    ("save", b"\xff\xfe", "not JSON"),
    ("save", [1, 2], "must be a JSON object, got list"),
    ("save", {"file": "x", "evil": 1}, "unknown field 'evil'; fields: file, overwrite"),
    ("save", {}, "'file' missing"),
    ("save", {"file": ""}, "save.file: expected a non-empty printable string"),
    ("save", {"file": "a\nb"}, "printable"),
    ("save", {"file": "x", "overwrite": "yes"}, "true or false"),
    ("calibrate_tip", {"samples": 2.5}, "whole number"),
    ("calibrate_tip", {"pivot_mm": [1, 2]}, "three finite numbers"),
    ("playback", {"speed_mm_s": True}, "finite number"),
    ("playback", b'{"speed_mm_s": NaN}', "finite number"),
    ("track", b"[" * 100_000, "not JSON"),
])
def test_a_bad_request_is_refused_with_its_reason(name, body, why):
    with pytest.raises(RequestError, match=why):
        _call(name, body)


def test_the_operator_services_need_the_operator_and_name_who_asked():
    with pytest.raises(RequestError, match="needs the operator, and this bridge grants no operator rights"):
        _call("reset_fault", {"operator": "alice", "token": "s3cret"}, token=None)
    with pytest.raises(RequestError, match="'token' missing"):
        _call("alter_on", {"operator": "alice"}, token="s3cret")
    with pytest.raises(RequestError, match="token is wrong"):
        _call("alter_off", {"operator": "alice", "token": "guess"}, token="s3cret")
    assert _call("reset_fault", {"operator": "alice", "token": "s3cret"}, token="s3cret") == (
        "robot_gateway", "reset_fault", {"operator": "alice (foxglove client 3)"})


# -- the server ------------------------------------------------------------------------------------
@pytest.mark.live
def test_a_taken_port_leaves_the_bridge_alive(caplog):
    from humanpt.foxglove_bridge.server import FoxgloveAdapter

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen()
        port = s.getsockname()[1]
        adapter = FoxgloveAdapter(FoxgloveBridgeConfig(port=port))
        with caplog.at_level(logging.ERROR, logger="humanpt.foxglove_bridge"):
            adapter.start(lambda *a: None)
        try:
            assert adapter.server is None and f"cannot serve Foxglove on 127.0.0.1:{port}" in caplog.text
            adapter.write("show:camera.image", RawImage())  # nothing to send to: dropped, no error
            with pytest.raises(RequestError, match="no session on the cell"):
                adapter.call("track", b"{}", 1)
        finally:
            adapter.close()

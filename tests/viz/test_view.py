"""viz: the core's choice (pure, replays), a lock-step twin run converted to .rrd by
``humanpt view --save`` and read back with rerun.chunk, the logger's robustness."""

from __future__ import annotations

import collections

import numpy as np
import pytest
import rerun as rr
import rerun.chunk as rrc

from humanpt.cli.main import main
from humanpt.controller.config import ControllerConfig
from humanpt.controller.core import ControllerCore
from humanpt.geometry import transform_from_x
from humanpt.perception.config import PerceptionConfig
from humanpt.perception.core import PerceptionCore
from humanpt.pose_filter.config import PoseFilterConfig
from humanpt.pose_filter.core import PoseFilterCore
from humanpt.runtime.replay import replay
from humanpt.schemas import humanpt_pb2 as pb
from humanpt.schemas import topics
from humanpt.schemas.convert import header, image, pose
from humanpt.twin import build_world
from humanpt.twin.system import path_points
from humanpt.viz.config import VizConfig
from humanpt.viz.convert import convert_run
from humanpt.viz.core import SHOWN_TOPICS, VizCore
from humanpt.viz.logger import ENTITIES, RerunLogger

pytestmark = pytest.mark.timeout(180)


@pytest.fixture(scope="module")
def twin_run(tmp_path_factory):
    """3 s of the closed loop on the arc, recording the path from the start, viz included."""
    run_dir = tmp_path_factory.mktemp("twin")
    cores = [
        PerceptionCore(PerceptionConfig()),
        PoseFilterCore(PoseFilterConfig()),
        ControllerCore(ControllerConfig(record_on_start=True)),
        VizCore(VizConfig(image_every=3)),
    ]
    world = build_world("arc", seed=2, extra_cores=cores, run_dir=run_dir)
    world.run_for(3.0)
    n_path = len(path_points(world)[0])
    n_images = len(world.outputs("camera/image"))
    world.close()
    return run_dir, n_path, n_images


def _entities(path) -> dict[str, int]:
    """Entity path -> rows, read back from an .rrd."""
    rows: dict[str, int] = collections.Counter()
    for chunk in rrc.RrdReader(path).stream().to_chunks():
        rows[chunk.entity_path] += chunk.num_rows
    return dict(rows)


def _column(path, entity: str, component: str) -> list:
    """Every row's value of ``component`` (e.g. "LineStrips3D:strips") of ``entity``, by stamp."""
    out = []
    for chunk in rrc.RrdReader(path).stream().to_chunks():
        if chunk.entity_path != entity:
            continue
        rb = chunk.to_record_batch()
        names = rb.schema.names
        col = next((n for n in names if n.endswith(component)), None)
        if col is None:
            continue
        # Durations (lock-step) or timestamps, as int64 ns (to_pylist would make timedeltas).
        stamps = (
            rb.column(names.index("stamp")).to_numpy().astype("int64").tolist()
            if "stamp" in names
            else [None] * rb.num_rows
        )
        out += list(zip(stamps, rb.column(names.index(col)).to_pylist(), strict=True))
    return [v for _, v in sorted(out, key=lambda x: (x[0] is None, x[0]))]


def test_core_forwards_on_local_show_topics_and_decimates_images():
    core = VizCore(VizConfig(image_every=2))
    img = image(np.zeros((4, 6), np.uint8), 10)
    outs = [core.step(i, "camera/image", img) for i in range(5)]
    assert [len(o) for o in outs] == [1, 0, 1, 0, 1]  # the first image is always shown
    topic, msg = outs[0][0]
    assert topic == "show:camera.image" and "/" not in topic  # local: never published
    assert topics.message_type(topic) is type(img) and topics.shown_short(topic) == "camera/image"
    st = pb.ControllerStatus(header=header(5), mode=pb.CONTROL_MODE_TRACK)
    assert core.step(5, "controller/status", st) == [("show:controller.status", st)]
    assert "viz/events" not in SHOWN_TOPICS and "controller/events" in SHOWN_TOPICS


def test_core_image_every_is_a_live_parameter():
    core = VizCore(VizConfig())
    outs = core.step(0, "param", pb.ParamSet(key="image_every", value_json="4"))
    assert outs[0][1].code == "param_changed" and core.config.image_every == 4
    outs = core.step(0, "param", pb.ParamSet(key="image_every", value_json="0"))
    assert outs[0][1].code == "param_rejected" and core.config.image_every == 4


def test_config_is_validated():
    with pytest.raises(ValueError, match="mode"):
        VizConfig(mode="window")
    with pytest.raises(ValueError, match="grpc_port"):
        VizConfig(grpc_port=0)
    with pytest.raises(ValueError, match="connect_url"):
        VizConfig(connect_url="http://x")


def test_viz_recording_of_a_lockstep_run_replays(twin_run):
    run_dir, _, n_images = twin_run
    res = replay(run_dir / "viz.mcap")
    assert res.match, res.report()
    assert res.recorded_outputs > n_images  # every status, state... and a third of the images


def test_view_save_writes_the_blueprint_and_the_expected_entities(twin_run, tmp_path, capsys, cli_main):
    run_dir, n_path, n_images = twin_run
    out = tmp_path / "run.rrd"
    assert cli_main(["view", str(run_dir), "--save", str(out)]) == 0
    captured = capsys.readouterr()
    assert f"-> the file {out}" in captured.out
    assert "humanpt view:" in captured.err  # the progress line
    reader = rrc.RrdReader(out)
    assert len(reader.recordings()) == 1 and len(reader.blueprints()) == 1
    rows = _entities(out)
    for key in (
        "flange",
        "camera",
        "frustum",
        "desired",
        "measured",
        "points",
        "tob",
        "sources",
        "desired_flange",
        "truth_tob",
        "truth_flange",
        "image",
        "centers",
        "pairs",
        "expected",
        "image_desired",
        "image_truth",
        "error_t",
        "error_r",
        "true_error_t",
        "cmd_v",
        "cmd_w",
        "lat_capture",
        "lat_state",
        "visible",
        "quality",
        "misses",
        "status",
    ):
        assert f"/{ENTITIES[key]}" in rows, f"{ENTITIES[key]} missing from the .rrd: {sorted(rows)}"
    assert any(e.startswith("/events/controller") for e in rows)
    # Every image (the view shows all by default) and one error sample per ALTER cycle.
    assert rows["/image"] == n_images
    assert rows["/plots/error/translation_mm"] >= 100  # 3 s at 28 ms
    # The path as it grows: one strip per path point, the last holding them all.
    strips = _column(out, "/world/path/1/g/0", "LineStrips3D:strips")
    assert n_path >= 5 and len(strips) == n_path
    assert len(strips[-1][0]) == n_path
    # The measured target is close to D (the loop tracks): |G - D| plotted in mm, small.
    errors = [v[0] for v in _column(out, "/plots/error/translation_mm", "Scalars:scalars")]
    assert len(errors) >= 100 and np.median(errors[-30:]) < 5.0
    # Latencies (issue 20: robot state -> command was negative, image -> command nearly
    # empty): never negative, one image -> command sample per image the loop used.
    lat_state = [v[0] for v in _column(out, "/plots/latency/state_to_command_ms", "Scalars:scalars")]
    lat_image = [v[0] for v in _column(out, "/plots/latency/capture_to_command_ms", "Scalars:scalars")]
    assert len(lat_state) >= 100 and min(lat_state) >= 0.0
    assert len(lat_image) >= 0.5 * n_images and min(lat_image) >= 0.0


def test_view_of_the_same_run_with_image_decimation_and_a_progress_callback(twin_run, tmp_path):
    run_dir, _, n_images = twin_run
    rec = rr.RecordingStream("humanpt_test")
    out = tmp_path / "dec.rrd"
    rec.save(out)
    seen = []
    stats = convert_run(
        run_dir, rec, image_every=4, progress=lambda s: seen.append(s.messages), progress_every=100
    )
    rec.flush()
    rec.disconnect()
    assert stats.total == stats.messages and not stats.errors and not stats.notes
    assert seen and seen[-1] == stats.messages
    assert stats.counts["camera/image"] == len(range(0, n_images, 4))
    assert _entities(out)["/image"] == stats.counts["camera/image"]


def test_view_names_a_missing_run(tmp_path, capsys, cli_main):
    assert cli_main(["view", str(tmp_path / "nope"), "--save", str(tmp_path / "x.rrd")]) == 2
    assert "no such run directory" in capsys.readouterr().err
    assert cli_main(["view", str(tmp_path), "--save", str(tmp_path / "x.rrd")]) == 2
    assert "no component recordings" in capsys.readouterr().err


@pytest.mark.parametrize("verb", ["view", "console"])
def test_view_and_console_have_help(verb, capsys):
    with pytest.raises(SystemExit) as e:
        main([verb, "--help"])
    assert e.value.code == 0
    out = capsys.readouterr().out
    assert out.startswith("usage: humanpt " + verb) and len(out.splitlines()) > 4


def test_logger_never_raises_on_bad_messages():
    rec = rr.RecordingStream("humanpt_test")
    rec.memory_recording()
    lg = RerunLogger(rec, VizConfig())
    bad_image = image(np.zeros((4, 6), np.uint8), 1)
    bad_image.data = b"short"
    lg.log("camera/image", bad_image, 1)
    bad_pose = pb.RobotState(header=header(2))
    bad_pose.world_T_flange.translation.x = float("nan")
    lg.log("robot_gateway/robot_state", bad_pose, 2)
    tob = pb.TobMeasurement(header=header(3), status=pb.TOB_STATUS_FULL)
    tob.pairs.add(right=7, left=9)  # indices beyond the centres
    lg.log("perception/tob", tob, 3)
    lg.log(
        "controller/events",
        pb.Event(
            header=header(4),
            source="controller",
            code="param_changed",
            text="controller: dz_mm = 650.0",
        ),
        4,
    )
    assert lg.errors.get("camera/image") == 1
    assert lg.dz_mm == 650.0  # D follows the controller's dz changes
    lg.log("unknown/topic", pb.Event(), 5)  # ignored


def test_logger_overlays_wait_for_their_image():
    rec = rr.RecordingStream("humanpt_test")
    mem = rec.memory_recording()
    lg = RerunLogger(rec, VizConfig())
    tob = pb.TobMeasurement(header=header(1000), status=pb.TOB_STATUS_LOST)
    tob.centers_px.add(u=10, v=20)
    lg.log("perception/tob", tob, 1000)  # before its image: held back
    assert 1000 in lg._pending
    lg.log("camera/image", image(np.zeros((480, 640), np.uint8), 1000), 1000)
    assert 1000 not in lg._pending
    lg.log(
        "robot_gateway/robot_state",
        pb.RobotState(header=header(1001), world_T_flange=pose(np.eye(4))),
        1001,
    )
    rec.flush()
    assert len(mem.drain_as_bytes()) > 0


def test_a_viewer_that_cannot_open_does_not_take_viz_down(caplog):
    import socket

    from humanpt.viz.sink import ViewerAdapter

    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        a = ViewerAdapter(VizConfig(mode="serve", grpc_port=port, bind_ip="127.0.0.1"))
        a.start(lambda *_: None)
        assert a.logger is None and "is in use" in caplog.text
        a.write("show:controller.status", pb.ControllerStatus())  # nothing to draw on: ignored
        a.close()


def test_view_without_a_display_says_to_save_or_serve(twin_run, monkeypatch, capsys, cli_main):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    assert cli_main(["view", str(twin_run[0])]) == 2
    assert "use --save FILE.rrd, or --serve" in capsys.readouterr().err


def test_display_transfer_brightens_the_dark_complex_image():
    """Issue 20: the complex image was nearly black at panel size. shown = 255 (v/255)^gamma."""
    from humanpt.viz.logger import display_lut

    lut = display_lut(0.5)
    assert lut.dtype == np.uint8 and lut.shape == (256,)
    assert (lut[0], lut[255]) == (0, 255)
    assert lut[16] == 64  # 255 * sqrt(16/255) = 63.87: a background of 16 DN shows at a quarter
    assert lut[64] == 128  # 255 * sqrt(64/255) = 127.75
    assert np.all(np.diff(lut.astype(int)) >= 0)  # monotone: the order of brightness is kept
    assert np.array_equal(display_lut(1.0), np.arange(256, dtype=np.uint8))  # 1: the raw image


def test_view_draws_a_fitted_seam_beside_the_path(twin_run, tmp_path, cli_main):
    # Issue 21.5: the seam's segments and corners beside the raw path.  A hand-made seam:
    # an L of two lines with one corner (humanpt.seam's file format).
    from humanpt.seam import seamfile
    from humanpt.seam.fit import Corner, FitConfig, Seam, Segment

    run_dir, _, _ = twin_run
    seg = lambda a, b: Segment("line", 0, 5, a, b, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 0.01, 0.02, 6)  # noqa: E731
    seam = Seam((seg((0.0, 0.0, 0.0), (100.0, 0.0, 0.0)), seg((100.0, 0.0, 0.0), (100.0, 50.0, 0.0))),
                (Corner((100.0, 0.0, 0.0), 90.0, 0, 1),), (), (), 0.0, FitConfig(), 12)
    f = seamfile.write(tmp_path / "l.seam.json", seam)
    out = tmp_path / "seam.rrd"
    assert cli_main(["view", str(run_dir), "--seam", str(f), "--save", str(out), "--no-progress"]) == 0
    rows = _entities(out)
    assert {"/world/seam/l_seam/0", "/world/seam/l_seam/1", "/world/seam/l_seam/corners"} <= set(rows), sorted(rows)
    strips = _column(out, "/world/seam/l_seam/1", "LineStrips3D:strips")
    assert strips, "no strip logged"
    ends = np.array(strips[0][0])
    np.testing.assert_allclose(ends[[0, -1]], [[0.1, 0.0, 0.0], [0.1, 0.05, 0.0]], atol=1e-9)  # mm -> m
    assert cli_main(["view", str(run_dir), "--seam", str(tmp_path / "none.json"), "--save", str(out)]) == 2


def test_logger_sees_the_camera_from_the_robot_state_nearest_the_image():
    """The expected overlay's camera: the robot state nearest the capture stamp (the earlier
    on a tie, the last one after them), times the rig's hand-eye; a robot state stamped
    before the latest (a restarted robot) starts the states again."""
    rec = rr.RecordingStream("humanpt_test")
    rec.memory_recording()
    lg = RerunLogger(rec, VizConfig())
    a, b = np.eye(4), transform_from_x(np.array([0.1, 0.0, 0.0, 90.0, 0.0, 0.0]))
    lg.log("robot_gateway/robot_state", pb.RobotState(header=header(1000), world_T_flange=pose(a)), 1000)
    lg.log("robot_gateway/robot_state", pb.RobotState(header=header(2000), world_T_flange=pose(b)), 2000)
    F = lg.flange_T_camera
    for stamp, flange in ((1400, a), (1500, a), (1600, b), (9000, b), (0, a)):
        np.testing.assert_allclose(lg.frames.lookup("world", "camera", stamp), flange @ F, atol=1e-12)
    lg.log("robot_gateway/robot_state", pb.RobotState(header=header(500), world_T_flange=pose(b)), 2100)
    np.testing.assert_allclose(lg.frames.lookup("world", "camera", 1400), b @ F, atol=1e-12)
    assert len(lg._robot) == 1 and lg._robot.last_ns == 500
    # the entities of the moving frames hang as the frames do
    assert ENTITIES["flange"] == "/".join(lg.frames.path("flange"))
    assert ENTITIES["camera"] == "/".join(lg.frames.path("camera"))

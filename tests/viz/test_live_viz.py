"""The viz component live, headless: a real router, ``humanpt viz`` in save mode (and
serve mode), messages published over Zenoh end up in the .rrd; its recording replays."""

from __future__ import annotations

import collections
import time

import numpy as np
import pytest
import rerun.chunk as rrc

from humanpt.runtime.replay import replay
from humanpt.schemas import humanpt_pb2 as pb
from humanpt.schemas.convert import header, image, pose
from tests.conftest import free_port, write_config, zenoh_client

pytestmark = pytest.mark.timeout(120)


def _wait_alive(session, name: str, timeout: float = 40.0) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if any(
            r.ok is not None for r in session.liveliness().get(f"humanpt/test/{name}", timeout=1.0)
        ):
            return
        time.sleep(0.2)
    raise TimeoutError(f"{name} did not come up")


def _publish_some(session, n: int = 20) -> None:
    pubs = {
        t: session.declare_publisher(f"humanpt/test/{t}")
        for t in (
            "camera/image",
            "alter_gateway/robot_state",
            "controller/status",
            "controller/path",
            "controller/events",
        )
    }
    t0 = time.time_ns()
    for i in range(n):
        t = t0 + i * 28_000_000
        T = np.eye(4)
        T[:3, 3] = [0.2 + i * 1e-3, 1.2, 0.5]
        pubs["alter_gateway/robot_state"].put(
            pb.RobotState(
                header=header(t, i, "world"), world_T_flange=pose(T), cycle=i
            ).SerializeToString()
        )
        pubs["controller/status"].put(
            pb.ControllerStatus(
                header=header(t, i, "world"),
                mode=pb.CONTROL_MODE_TRACK,
                error_translation_m=1e-3,
                cycle=i,
                recording=True,
                path_points=i,
            ).SerializeToString()
        )
        pubs["controller/path"].put(
            pb.PathPoint(
                header=header(t, i, "world"), index=i, world_T_tob=pose(T)
            ).SerializeToString()
        )
        pubs["camera/image"].put(image(np.full((480, 640), i, np.uint8), t).SerializeToString())
        time.sleep(0.01)
    pubs["controller/events"].put(
        pb.Event(
            header=header(t0), source="controller", code="mode", text="mode TRACK"
        ).SerializeToString()
    )
    time.sleep(1.0)
    for p in pubs.values():
        p.undeclare()


def test_live_viz_saves_what_it_receives_and_replays(procs, tmp_path):
    port = free_port()
    rrd = tmp_path / "live.rrd"
    cfg = write_config(
        tmp_path / "humanpt.toml",
        port,
        extra=f'[viz]\nmode = "save"\nrrd_path = "{rrd}"\nimage_every = 2\n',
    )
    procs.start("router", "--config", str(cfg))
    run_dir = tmp_path / "run"
    viz = procs.start("viz", "--config", str(cfg), "--run-dir", str(run_dir))
    with zenoh_client(port) as s:
        _wait_alive(s, "viz")
        time.sleep(0.5)
        _publish_some(s)
    out = procs.stop(viz)
    assert "stopped; consumed" in out, out
    rows: dict[str, int] = collections.Counter()
    for chunk in rrc.RrdReader(rrd).stream().to_chunks():
        rows[chunk.entity_path] += chunk.num_rows
    assert rows["/world/flange"] >= 15, dict(rows)
    assert rows["/plots/error/translation_mm"] >= 15
    assert 5 <= rows["/image"] <= 10  # every second image of 20
    assert any(k.startswith("/world/path/1/g/") for k in rows)
    assert rows["/events/controller"] == 1 and rows["/status"] >= 1
    res = replay(run_dir / "viz.mcap")
    assert res.match and res.recorded_outputs >= 45, res.report()


def test_live_viz_serves_over_grpc_headless(procs, tmp_path):
    port, grpc = free_port(), free_port()
    cfg = write_config(
        tmp_path / "humanpt.toml",
        port,
        extra=f'[viz]\nmode = "serve"\ngrpc_port = {grpc}\nbind_ip = "127.0.0.1"\n',
    )
    procs.start("router", "--config", str(cfg))
    viz = procs.start("viz", "--config", str(cfg), "--run-dir", str(tmp_path / "run"))
    with zenoh_client(port) as s:
        _wait_alive(s, "viz")
        import socket

        with socket.create_connection(("127.0.0.1", grpc), timeout=5):
            pass  # the rerun gRPC server listens for viewers
        _publish_some(s, n=3)
    out = procs.stop(viz)
    assert "stopped; consumed" in out and "Traceback" not in out, out

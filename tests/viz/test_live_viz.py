"""The viz component live, headless: a real router, ``humanpt viz`` in save mode (and
serve mode), messages published over Zenoh end up in the .rrd; its recording replays."""

from __future__ import annotations

import collections
import json
import queue
import time

import numpy as np
import pytest
import rerun.chunk as rrc
import zenoh

from humanpt.runtime.replay import replay
from humanpt.schemas import humanpt_pb2 as pb
from humanpt.schemas.convert import header, image, pose
from tests.conftest import free_port, wait_for, wait_matching, wait_port, write_config, zenoh_client

pytestmark = pytest.mark.timeout(120)


def _wait_alive(session, name: str, timeout: float = 40.0) -> None:
    """Wait for ``name``'s liveliness token (the component's shell is up)."""
    alive: queue.Queue = queue.Queue()
    sub = session.liveliness().declare_subscriber(f"humanpt/test/{name}", lambda smp: alive.put(smp),
                                                  history=True)
    try:
        alive.get(timeout=timeout)
    except queue.Empty:
        raise TimeoutError(f"{name} did not come up") from None
    finally:
        sub.undeclare()


def _consumed(session, name: str, timeout: float = 20.0) -> int:
    """How many inputs the component's shell has consumed (its params queryable; waits for
    the first answer)."""
    got: list[int] = []

    def answered() -> bool:
        for r in session.get(f"humanpt/test/{name}/params", timeout=2.0):
            if r.ok is not None:
                got.append(json.loads(r.ok.payload.to_bytes())["counters"]["consumed"])
        return bool(got)

    wait_for(answered, timeout, f"{name} to answer its params query")
    return got[0]


def _publish_some(session, n: int = 20) -> int:
    """Publish ``n`` cycles of what viz shows (and one event); returns how many messages."""
    # Blocking, not dropping, when a queue is full (Zenoh's default for puts drops): every
    # message reaches viz, so the test can wait for viz to have consumed them all.
    pubs = {
        t: session.declare_publisher(f"humanpt/test/{t}", congestion_control=zenoh.CongestionControl.BLOCK)
        for t in (
            "camera/image",
            "robot_gateway/robot_state",
            "controller/status",
            "controller/path",
            "controller/events",
        )
    }
    for p in pubs.values():  # viz subscribes to each: what is put below reaches it
        wait_matching(p)
    t0 = time.time_ns()
    for i in range(n):
        t = t0 + i * 28_000_000
        T = np.eye(4)
        T[:3, 3] = [0.2 + i * 1e-3, 1.2, 0.5]
        pubs["robot_gateway/robot_state"].put(
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
        time.sleep(0.01)  # paced like a live source (not a wait for anything)
    pubs["controller/events"].put(
        pb.Event(
            header=header(t0), source="controller", code="mode", text="mode TRACK"
        ).SerializeToString()
    )
    for p in pubs.values():
        p.undeclare()
    return 4 * n + 1


def test_live_viz_saves_what_it_receives_and_replays(router, procs, tmp_path):
    port, _ = router
    rrd = tmp_path / "live.rrd"
    cfg = write_config(
        tmp_path / "humanpt.toml",
        port,
        extra=f'[viz]\nmode = "save"\nrrd_path = "{rrd}"\nimage_every = 2\n',
    )
    run_dir = tmp_path / "run"
    viz = procs.start("viz", "--config", str(cfg), "--run-dir", str(run_dir))
    with zenoh_client(port) as s:
        _wait_alive(s, "viz")
        before = _consumed(s, "viz")
        n = _publish_some(s)
        wait_for(lambda: _consumed(s, "viz") >= before + n, 30.0, f"viz to consume {n} messages")
    out = procs.stop(viz)
    assert "stopped; consumed" in out, out
    rows: dict[str, int] = collections.Counter()
    for chunk in rrc.RrdReader(rrd).stream().to_chunks():
        rows[chunk.entity_path] += chunk.num_rows
    # Nothing is dropped on the way (blocking publishers, all consumed): every one of the 20
    # cycles is shown.
    assert rows["/world/flange"] >= 20, dict(rows)
    assert rows["/plots/error/translation_mm"] >= 20
    assert rows["/image"] == 10  # every second image of 20
    assert sum(n for k, n in rows.items() if k.startswith("/world/path/1/g/")) == 20
    assert rows["/events/controller"] == 1 and rows["/status"] == 20
    res = replay(run_dir / "viz.mcap")
    assert res.match and res.recorded_outputs >= 45, res.report()


def test_live_viz_serves_over_grpc_headless(router, procs, tmp_path):
    (port, _), grpc = router, free_port()
    cfg = write_config(
        tmp_path / "humanpt.toml",
        port,
        extra=f'[viz]\nmode = "serve"\ngrpc_port = {grpc}\nbind_ip = "127.0.0.1"\n',
    )
    viz = procs.start("viz", "--config", str(cfg), "--run-dir", str(tmp_path / "run"))
    # The rerun gRPC server listens for viewers: wait for what is needed, the port accepting.
    wait_port(grpc, timeout=40.0)
    with zenoh_client(port) as s:
        _wait_alive(s, "viz")
        before = _consumed(s, "viz")
        n = _publish_some(s, n=3)
        wait_for(lambda: _consumed(s, "viz") >= before + n, 30.0, f"viz to consume {n} messages")
    out = procs.stop(viz)
    assert "stopped; consumed" in out and "Traceback" not in out, out

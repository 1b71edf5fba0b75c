"""A saved path played back by a live cell, and the robot followed it (issue 31 item 5c).

Processes: a router, ``robot_gateway`` and ``sim_robot`` over a pty (the ALTER link),
``pose_filter`` (the controller's cycle: a TobState per robot state) and ``controller``.
A seam file is saved (a 40 mm line from where the tool is, the tool's orientation held)
and played with ``humanpt path play`` (re-timed by the client, checked by the controller,
the gateway's safety rules on every step). The robot's own truth (``sim_robot/truth``, the
simulated arm's flange, independent of what the gateway reports) times the controller's
``flange_T_tool`` must then have followed it, from ``playback_started`` to
``playback_done``:

* every tool position within ``CROSS_MM`` = 0.5 mm of the line (the path is straight and
  starts where the tool is: the only cross-track error is the loop's; ALTER quantises to
  0.01 mm);
* every 1 mm sample of the line within ``COVER_MM`` = 0.5 mm of a tool position (at
  20 mm/s and 28 ms cycles the tool moves 0.56 mm a cycle: half that, plus the cross-track
  error, rounded up);
* the tool's last position within ``END_MM`` = 0.2 mm of the line's end (the controller
  says done within 0.1 mm of it, the robot's reported pose against its truth);
* the orientation held within 0.2 deg.
"""

from __future__ import annotations

import queue

import numpy as np
import pytest

from humanpt.controller.config import ControllerConfig
from humanpt.geometry.transforms import rotation_angle_rad, transform_from_x, x_from_transform
from humanpt.schemas import humanpt_pb2 as pb
from humanpt.schemas.convert import from_pose
from humanpt.seam import seamfile
from humanpt.seam.fit import FitConfig, Seam, Segment
from tests.conftest import run_cli, wait_for, write_config, zenoh_client

LENGTH_MM = 40.0
CROSS_MM, COVER_MM, END_MM, ANGLE_DEG = 0.5, 0.5, 0.2, 0.2
FLANGE_T_TOOL = transform_from_x(np.asarray(ControllerConfig().flange_T_tool_x, dtype=float))


def _distance_to_segment(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(N,) distance (mm) of points (N, 3) to the segment a-b (by hand: the test's own)."""
    ab = b - a
    s = np.clip((p - a) @ ab / (ab @ ab), 0.0, 1.0)
    return np.linalg.norm(p - (a + s[:, None] * ab), axis=1)


@pytest.mark.timeout(240)
def test_a_saved_path_played_by_the_live_cell_is_followed_by_the_robot(router, procs, tmp_path):
    port, _ = router
    link = tmp_path / "alter-pty"
    cfg = write_config(tmp_path / "cell.toml", port,
                       extra=f'[sim_robot]\npty_link = "{link}"\n[robot_gateway]\nport = "{link}"\n')
    run = tmp_path / "run"
    cell = [procs.start(name, "--config", str(cfg), "--run-dir", str(run))
            for name in ("robot_gateway", "sim_robot", "pose_filter", "controller")]
    truth: list[tuple[int, np.ndarray]] = []  # (arrival order, world_T_flange with mm)
    states: list[pb.RobotState] = []
    events: queue.Queue = queue.Queue()
    codes: list[pb.Event] = []

    def seen(code: str) -> bool:
        while not events.empty():
            codes.append(events.get())
        return any(e.code == code for e in codes)

    with zenoh_client(port) as s:
        def on_truth(smp):
            T = from_pose(pb.Truth.FromString(smp.payload.to_bytes()).world_T_flange)
            T[:3, 3] *= 1000.0
            truth.append((len(truth), T))

        subs = [s.declare_subscriber("humanpt/test/sim_robot/truth", on_truth),
                s.declare_subscriber("humanpt/test/robot_gateway/robot_state",
                                     lambda smp: states.append(pb.RobotState.FromString(smp.payload.to_bytes()))),
                s.declare_subscriber("humanpt/test/controller/events",
                                     lambda smp: events.put(pb.Event.FromString(smp.payload.to_bytes())))]
        # The loop runs (the controller commands every cycle: it has seen the filter's states).
        wait_for(lambda: len(states) >= 20 and len(truth) >= 20, 90.0, "the robot's states and truth")
        wait_for(lambda: seen("mode"), 60.0, "the controller's first cycle (its mode event)")
        # The saved path: from where the tool is now, 40 mm along x and 10 along z.
        world_T_tool = truth[-1][1] @ FLANGE_T_TOOL
        x0 = x_from_transform(world_T_tool)
        start = x0[:3]
        end = start + np.array([LENGTH_MM * 0.97, 0.0, LENGTH_MM * 0.25])
        ypr = tuple(float(v) for v in x0[3:])
        seam_file = tmp_path / "saved.seam.json"
        seamfile.write(seam_file, Seam((Segment("line", 0, 5, tuple(start), tuple(end), ypr, ypr, 0.0, 0.0, 6),),
                                       (), (), (), 0.0, FitConfig(), 6))
        t_play = len(truth)  # from here on the tool stands at the start, plays, stands at the end
        # (a process: the console prints through a stream bound when its module was imported)
        r = run_cli("path", "play", str(seam_file), "--config", str(cfg), "--timeout", "30", timeout=90)
        assert r.returncode == 0 and "playback_started" in r.stdout, r.stdout + r.stderr
        wait_for(lambda: seen("playback_done"), 120.0, "the controller's playback_done")
        done_at = len(truth)
        wait_for(lambda: len(truth) >= done_at + 5, 30.0, "five more truths")  # (the last cycles' corrections)
        for sub in subs:
            sub.undeclare()
    played = np.array([T @ FLANGE_T_TOOL for _, T in truth[t_play:]])
    tool = played[:, :3, 3]
    cross = _distance_to_segment(tool, start, end)
    assert cross.max() <= CROSS_MM, f"the tool left the path by {cross.max():.3f} mm"
    samples = start + np.linspace(0.0, 1.0, int(np.ceil(np.linalg.norm(end - start))) + 1)[:, None] * (end - start)
    cover = np.min(np.linalg.norm(samples[:, None, :] - tool[None, :, :], axis=2), axis=1)
    assert cover.max() <= COVER_MM, f"the path's sample {cover.argmax()} mm was missed by {cover.max():.3f} mm"
    assert np.linalg.norm(tool[-1] - end) <= END_MM, np.linalg.norm(tool[-1] - end)
    R0 = world_T_tool[:3, :3]
    angles = np.degrees([rotation_angle_rad(R0.T @ T[:3, :3]) for T in played])
    assert angles.max() <= ANGLE_DEG, angles.max()
    print(f"played {len(tool)} truths: cross-track max {cross.max():.3f} mm, sample missed by at most "
          f"{cover.max():.3f} mm, end {np.linalg.norm(tool[-1] - end):.3f} mm, orientation {angles.max():.3f} deg")
    for p_ in cell:
        out = procs.stop(p_)
        assert p_.returncode == 0 and "core errors 0" in out, out

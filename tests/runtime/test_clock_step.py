"""A step of the wall clock (NTP stepping it by +-2 s) on a running cell restarts no healthy
link and faults no gateway (issue 31 item 5a).

Watchdogs keep monotonic time, stamps follow the shared time base (runtime/clock.py): the
live shell accepts the step before its next input and gives the gateway a ``clock_step``
input, which moves its watchdogs' times (STATUS silence, reply deadline, DDCMP's timers).

* the gateway core alone (ALTER and RSI), its clock ahead of the robot's by a step (the robot controller is
  another machine: NTP does not step it): the step unannounced is the bug (``link_down``
  then ``link_up`` for +2 s), announced it is nothing;
* the camera core: a step back does not make 2 s of frames stale;
* the :class:`~humanpt.runtime.clock.Clock` accepts a step of the wall clock (once), none in a quiet run;
* live: ``humanpt robot_gateway`` and ``humanpt sim_robot`` as processes over a pty and a
  router, this test the controller; the gateway's wall clock is stepped +2 s then -2 s
  mid-run through the clock's hook (``HUMANPT_CLOCK_OFFSET_FILE``: the machine is shared,
  its real clock is not stepped; Debian's libfaketime 0.9.10 breaks Python's ``time.sleep``
  when the monotonic clock is left alone: libfaketime issue 426). The link stays up, no
  fault, and the gateway's recording, steps and all, replays exactly. (Before the fix, the
  same run with the step not announced gave ``link_down``, ``link_up``, ``deadline_missed``
  and ``robot_missed`` at the +2 s step.)
"""

from __future__ import annotations

import os
import queue

import numpy as np
import pytest

from humanpt.camera.config import CameraConfig
from humanpt.camera.core import CameraCore
from humanpt.pose_filter.config import PoseFilterConfig
from humanpt.pose_filter.core import PoseFilterCore
from humanpt.robot_gateway.core import GatewayCore
from humanpt.runtime.clock import Clock
from humanpt.schemas import humanpt_pb2 as pb
from humanpt.schemas.convert import header, image
from humanpt.testing.harness import ScriptedControllerConfig, scripted_command
from tests.conftest import run_cli_here, wait_for, write_config, zenoh_client
from tests.robot_gateway.rig import MS, Rig

STEP_NS = 2_000_000_000
TICK_NS = 2 * MS


class SteppedRig(Rig):
    """The gateway's clock = the robot's + ``offset_ns`` (what the gateway's host reads)."""

    offset_ns = 10_000_000_000  # (so that -2 s stays a time)

    def step(self, topic: str, msg) -> list:
        t = self.t_ns + self.offset_ns
        if topic == self.rx_topic:  # the shell stamps what it reads with its own clock
            msg.header.stamp_ns = t
        outs = self.gw.step(t, topic, msg)
        self.outs += outs
        for topic_out, m in outs:
            if topic_out == self.tx_topic and self.robot_connected:
                back, got = self.robot.take(m.data, self.t_ns)
                self._to_gw += back
                self.corrections += got
        while self._to_gw:
            outs += self.from_robot(self._to_gw.pop(0))
        return outs

    def stamp_for(self, cycle: int) -> int:
        return super().stamp_for(cycle)

    def clock_step(self, step_ns: int, announce: bool) -> list:
        self.offset_ns += step_ns
        if not announce:
            return []
        t = self.t_ns + self.offset_ns
        return self.step("clock_step", pb.Event(header=header(t), code="clock_step", text=str(step_ns)))


def _run_cycles(rig: SteppedRig, n: int) -> list:
    outs = []
    for _ in range(n):
        outs += rig.cycle_with_command(dp_mm=(0.1, 0, 0))
    return outs


def _silent_cycles(rig: SteppedRig, n: int) -> list:
    """``n`` robot cycles the controller does not answer (a late controller): the gateway
    answers each at its reply deadline."""
    outs = []
    for _ in range(n):
        outs += rig.status() + rig.advance(rig.cycle_ns)
    return outs


BAD = {"link_down", "link_up", "fault", "deadline_missed", "controller_silent"}


def _after_step(rig: SteppedRig) -> tuple[list, int]:
    """A tick (the live shell ticks every 2 ms: one comes before the next STATUS), 5 cycles
    the controller misses, 15 it answers; (outputs, corrections the robot got)."""
    before = len(rig.corrections)
    outs = rig.advance(TICK_NS) + _silent_cycles(rig, 5) + _run_cycles(rig, 15)
    return outs, len(rig.corrections) - before


def _silence_found_after(rig: SteppedRig) -> int:
    """The robot goes silent now: how long (ns, robot time) until the gateway says link_down."""
    rig.robot_connected = False
    t0, n = rig.t_ns, len(rig.outs)
    while "link_down" not in rig.codes(rig.outs[n:]):
        assert rig.t_ns - t0 < 10 * STEP_NS, "no link_down in 20 s of silence"
        rig.advance(TICK_NS)
    return rig.t_ns - t0


@pytest.mark.parametrize("link", ["alter", "rsi"])
@pytest.mark.parametrize("step_ns", [STEP_NS, -STEP_NS])
def test_a_step_of_the_gateways_clock_unannounced_breaks_the_link_announced_it_does_not(step_ns, link):
    # The bug first (what the live shell did before it announced steps): +2 s looks like
    # 2 s without STATUS (link_down, then link_up with the next STATUS); -2 s blinds the
    # watchdogs for 2 s (a real silence of the robot right after it is found 2 s late).
    rig = SteppedRig(link=link, status_timeout_cycles=5)
    timeout_ns = 5 * rig.cycle_ns  # status_timeout_cycles x the cycle
    assert not set(rig.codes(_run_cycles(rig, 20))) & BAD
    rig.clock_step(step_ns, announce=False)
    if step_ns > 0:
        outs, _ = _after_step(rig)
        assert rig.codes(outs)[:2] == ["link_down", "link_up"], rig.codes(outs)
    else:
        assert _silence_found_after(rig) > -step_ns

    # Announced (the live shell's clock_step input): nothing happens but one event.
    rig = SteppedRig(link=link, status_timeout_cycles=5)
    _run_cycles(rig, 20)
    counters_before = dict(rig.gw.counters)
    outs = rig.clock_step(step_ns, announce=True)
    assert rig.codes(outs) == ["clock_step"] and f"{step_ns / 1e9:+.3f} s" in rig.events(outs)[0].text
    outs, answered = _after_step(rig)
    assert not set(rig.codes(outs)) & (BAD - {"deadline_missed"}), rig.codes(outs)
    assert rig.gw.link_running and rig.gw.fault is None and rig.gw.missed_cycles == 0
    for key in ("link_down", "robot_missed", "status_lost", "faults", "reps", "stamp_mismatch"):
        assert rig.gw.counters[key] == counters_before[key], key
    # every cycle answered: the 5 missed ones at their deadline (the last command again,
    # then zero), the others with their own command
    assert answered == 20
    assert rig.gw.counters["deadline_missed"] - counters_before["deadline_missed"] == 5
    assert [s.source for s in rig.gw.sent][-15:] == ["fresh"] * 15
    # The robot states carry the new base (the shared time base moved): stamps follow it.
    states = rig.states()
    assert states[-1].header.stamp_ns - states[-21].header.stamp_ns == 20 * rig.cycle_ns + TICK_NS + step_ns
    # and a real silence is found as it would be without a step
    assert _silence_found_after(rig) <= timeout_ns + rig.cycle_ns + TICK_NS


def test_a_step_back_does_not_make_the_cameras_frames_stale():
    # The camera drops a frame stamped not after the previous one (stale_frame): after a
    # -2 s step every frame for 2 s would be, at 30 frames a second, 60 frames.
    frame_ns = 33_000_000
    pixels = np.zeros((4, 4), np.uint8)

    def frames(core: CameraCore, t0: int, n: int) -> list[str]:
        outs = []
        for i in range(n):
            outs += core.step(t0 + i * frame_ns, "capture", image(pixels, t0 + i * frame_ns, "camera", "mono8"))
        return [topic if topic != "camera/events" else m.code for topic, m in outs]

    for announce in (False, True):
        core = CameraCore(CameraConfig())
        t0 = 10_000_000_000
        assert frames(core, t0, 10) == ["camera/image"] * 10
        t1 = t0 + 10 * frame_ns - STEP_NS
        if announce:
            assert core.step(t1, "clock_step", pb.Event(code="clock_step", text=str(-STEP_NS))) == []
        got = frames(core, t1, 10)
        assert got == (["camera/image"] * 10 if announce else ["stale_frame"] * 10), got


def test_a_step_does_not_cut_the_pose_filters_wait_for_the_robot():
    # A measurement newer than the latest robot state waits wait_for_robot_ms (60 ms, input
    # time) for the state that brackets it; a +2 s step unannounced ends the wait at once
    # (the measurement is used on an extrapolated robot pose, or dropped).
    from tests.pose_filter.test_pose_filter import TARGET_X, T_m, World, moving_flange

    for announce in (False, True):
        core = PoseFilterCore(PoseFilterConfig())
        world = World(core, moving_flange, lambda t: T_m(TARGET_X))
        t0 = 10_000_000_000
        for k in range(3):
            world.robot_state(t0 + k * 28_000_000)
        world.measurement(t0 + 60_000_000)  # (given 5 ms after its stamp) newer than the robot's 56 ms
        assert len(core._pending) == 1
        if announce:
            assert core.step(t0 + 70_000_000 + STEP_NS, "clock_step",
                             pb.Event(code="clock_step", text=str(STEP_NS))) == []
        world.measurement(t0 + 65_000_000 + STEP_NS)  # 10 ms later by the monotonic clock
        assert len(core._pending) == (2 if announce else 1), announce


def test_a_clock_step_input_that_is_not_a_number_is_a_warning():
    gw = GatewayCore(Rig().gw.config)
    outs = gw.step(0, "clock_step", pb.Event(code="clock_step", text="soon"))
    assert [(m.code, "not a step in ns" in m.text) for _, m in outs if isinstance(m, pb.Event)] == [("bad_input", True)]


def test_the_clock_accepts_a_step_of_the_wall_clock_and_stamps_follow_it(tmp_path):
    hook = tmp_path / "offset"
    clock = Clock(str(hook))
    assert clock.check() == 0 and clock.steps == []
    t0 = clock.now_ns()
    hook.write_text("+2\n")
    clock._file_read_at = None  # (the file is re-read every 0.1 s: now)
    assert clock.check() == 1
    (step,) = clock.steps
    assert abs(step - STEP_NS) < 1_000_000, step  # within the reading's jitter
    assert clock.now_ns() - t0 >= STEP_NS
    assert clock.check() == 1  # one step, accepted once
    hook.write_text("0")  # back by 2 s
    clock._file_read_at = None
    assert clock.check() == 2 and abs(clock.steps[1] + STEP_NS) < 1_000_000
    assert abs(clock.shift_since(0)) < 2_000_000 and clock.shift_since(1) == clock.steps[1]
    hook.write_text("nonsense")
    clock._file_read_at = None
    assert clock.check() == 2  # a hook that cannot be read is no offset (as it was): no step
    # Without a hook the clock is the machine's: no step in a quiet run.
    plain = Clock()
    assert plain.check() == 0 and abs(plain.now_ns() - plain.realtime_ns()) < 2_000_000


@pytest.mark.timeout(120)
def test_a_step_of_the_gateways_wall_clock_keeps_the_live_link_up(router, procs, tmp_path):
    port, _ = router
    link = tmp_path / "alter-pty"
    cfg = write_config(tmp_path / "alter.toml", port,
                       extra=f'[sim_robot]\npty_link = "{link}"\n[robot_gateway]\nport = "{link}"\n')
    run = tmp_path / "run"
    hook = tmp_path / "gateway-clock-offset"
    hook.write_text("0\n")
    # Only the gateway's host steps: the robot controller keeps its own clock.
    gw = procs.start("robot_gateway", "--config", str(cfg), "--run-dir", str(run),
                     env={**os.environ, "HUMANPT_CLOCK_OFFSET_FILE": str(hook)})
    procs.start("sim_robot", "--config", str(cfg), "--run-dir", str(run))
    script = ScriptedControllerConfig()
    states: list[pb.RobotState] = []
    events: queue.Queue = queue.Queue()
    codes: list[str] = []
    with zenoh_client(port) as s:
        token = s.liveliness().declare_token("humanpt/test/controller")
        pub = s.declare_publisher("humanpt/test/controller/command")

        def on_state(sample):
            st = pb.RobotState.FromString(sample.payload.to_bytes())
            states.append(st)
            pub.put(scripted_command(st, script, len(states)).SerializeToString())

        subs = [s.declare_subscriber("humanpt/test/robot_gateway/robot_state", on_state),
                s.declare_subscriber("humanpt/test/robot_gateway/events",
                                     lambda smp: events.put(pb.Event.FromString(smp.payload.to_bytes())))]

        def seen(code: str, n: int = 1) -> bool:
            while not events.empty():
                codes.append(events.get().code)
            return codes.count(code) >= n

        wait_for(lambda: len(states) >= 25, 60.0, "25 robot states")
        seen("")
        codes.clear()  # (the link's start-up: its link_up)
        for n, offset in enumerate(("+2", "-0"), start=1):  # +2 s, then back by 2 s
            hook.write_text(offset + "\n")
            wait_for(lambda n=n: seen("clock_step", n), 30.0, f"the gateway's clock_step event {n}")
            mark = len(states)
            # 25 cycles (0.7 s) after the step: far beyond the STATUS timeout (3 cycles)
            wait_for(lambda mark=mark: len(states) >= mark + 25, 60.0, "25 more robot states")
        token.undeclare()
        for sub in subs:
            sub.undeclare()
    seen("")
    out = procs.stop(gw)
    assert gw.returncode == 0, out
    assert "core errors 0" in out
    # (what load may bring, a late answer, is not asked about: the link and the fault are)
    assert not set(codes) & {"link_down", "link_up", "fault"}, codes
    assert all(not st.status.fault for st in states)
    # the stamps followed the wall clock: +2 s at the first step, back at the second
    gaps = [b.header.stamp_ns - a.header.stamp_ns for a, b in zip(states, states[1:], strict=False)]
    assert max(gaps) > 1.9e9 and min(gaps) < -1.9e9, (max(gaps), min(gaps))
    res = run_cli_here("replay", str(run), "--component", "robot_gateway")
    assert res.returncode == 0 and "MATCH" in res.stdout, res.stdout + res.stderr

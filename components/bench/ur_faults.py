"""The UR RTDE link's rows of ``humanpt bench faults --link ur`` (issue 34 item 5), against the
live twin over RTDE (the simulated UR's server and the gateway's client on loopback TCP, the
program with its watchdog running):

- ``kill`` (:mod:`humanpt.bench.link_faults`): the gateway killed mid-motion; the program goes
  on to the last target (at most ``max_lead_mm`` ahead) and its watchdog stops the arm.
- ``rtde2`` (a sender that is not the robot's client): a second RTDE client of the robot's
  host sets up humanpt's input registers and writes a target 50 mm away. Over TCP the gateway
  reads only its own connection; the controller refuses the registers (IN_USE, as UR's does)
  and the package for a recipe the client has not set up. Judged: refused, the arm did not
  follow (no step over the gateway's limit), the gateway's session went on.
- ``rtdejunk`` (malformed messages): 3 s of junk on new connections to the robot's RTDE port
  (bytes that are not RTDE packets, a header with a size beyond RTDE's, a bogus packet type):
  the controller drops each such client; judged: the gateway's session went on (robot states
  after it, no ``link_down``) and the program never stopped the arm.
- ``freeze`` (late and lost answers): the gateway frozen (SIGSTOP) for 0.5 s while the robot
  plays a line at 40 mm/s, then let go: no answer for 62 cycles at 8 ms (a loaded PC's stall);
  the program's watchdog stops the arm after ``watchdog_cycles``; judged: the arm moved at most
  the lead + 2 cycles at the limit after the freeze, as after a kill; whether the program
  followed again once the answers came (a newer sequence within the lead) is reported.
- ``lost`` (lost messages): the simulated controller frozen (SIGSTOP) for 0.5 s: 62 data
  packages never sent; judged: robot states again afterwards and no fault latched (the
  gateway's silence watchdog may restart the link: reported).

- ``pstop`` (the robot program stopped): while the robot plays a line at 40 mm/s, Stop
  through the robot's Dashboard server (port 29999 on a UR: what the pendant's Stop does),
  then, after the robot states of :data:`PSTOP_STILL_STATES` cycles, Play. Judged: the
  Dashboard answered as UR documents ("Stopped", "Starting program"); the arm braked within
  the program's stop (v^2 / 2a at the controller's deceleration, + one cycle at v) and then
  did not move while stopped although the gateway went on answering; the gateway read the
  stop from RTDE (``link_down`` naming the stopped program, no fault latched) and, after
  Play, came back up (``link_up``) with no jump: the arm's largest step a cycle over the
  robot states of :data:`PSTOP_AFTER_STATES` cycles after it within the gateway's limit.

Duplicated and reordered data packages cannot happen between the two ends of one TCP
connection, and lost ones only as the robot's silence (``lost``); the link drops a package
whose timestamp does not advance, and a foreign header (tests/ur/test_ur_link.py).
"""

from __future__ import annotations

import math
import os
import signal
import socket
import time

import numpy as np

from humanpt.bench.faults import Ctx, FaultRow, _console, _ms
from humanpt.bench.link_faults import (
    ANSWER_TIMEOUT_S,
    KILL_BOUND_CYCLES,
    LINK_BACK_TIMEOUT_S,
    _events,
    _speed_mm_s,
    _state_after,
    _truth_after,
    _truth_at,
    _truth_now,
    _wait,
    fast_or_along,
    start_line_playback,
)
from humanpt.robot_gateway.links.rsi.config import parse_address
from humanpt.robot_gateway.links.ur import protocol as rtde
from humanpt.robot_gateway.links.ur.link import input_names

FOREIGN_TARGET_MM = 50.0  # rtde2: the second client's target, this far from the arm
JUNK_S = 3.0              # rtdejunk: its length
FREEZE_S = 0.5            # freeze: the gateway stopped this long
UR_FAULTS_CYCLE_MS = 8.0  # the twin's UR at the CB3's 125 Hz (7 processes at 500 Hz: not on a small machine)
PSTOP_STILL_STATES = 50   # pstop: robot states while the program is stopped (0.4 s at 8 ms)
PSTOP_AFTER_STATES = 50   # pstop: robot states after Play judged for a jump


def _rtde_address(ctx: Ctx) -> tuple[str, int]:
    return parse_address(ctx.gw.rtde_address)


def _read_packet(sock: socket.socket, framer: rtde.Framer, pending: list, deadline: float) -> rtde.Packet | None:
    """The next whole packet from ``sock`` (``pending``: those read before, not taken yet);
    None: closed, or nothing by ``deadline``."""
    while not pending:
        left = deadline - time.monotonic()
        if left <= 0:
            return None
        sock.settimeout(left)
        try:
            data = sock.recv(65536)
        except OSError:  # (a timeout too)
            return None
        if not data:
            return None
        pending += framer.feed(data)
    return pending.pop(0)


def attack_second_client(ctx: Ctx, row: FaultRow) -> None:
    """A second RTDE client writes humanpt's target registers (a target 50 mm away)."""
    host, port = _rtde_address(ctx)
    names = input_names(ctx.gw.register_base)
    p0 = _truth_now(ctx)
    t0 = time.monotonic()
    answers: list[str] = []
    with socket.create_connection((host, port), timeout=10.0) as s:
        framer, pending = rtde.Framer(), []
        s.sendall(rtde.encode_version_request())
        v = _read_packet(s, framer, pending, time.monotonic() + ANSWER_TIMEOUT_S)
        answers.append("version " + ("accepted" if v is not None and v.payload[:1] == b"\x01" else "?"))
        s.sendall(rtde.encode_setup_inputs(names))
        setup = _read_packet(s, framer, pending, time.monotonic() + ANSWER_TIMEOUT_S)
        rid, types = rtde.decode_setup_reply(setup.payload, "input setup") if setup is not None else (None, ())
        refused = rid == 0 and "IN_USE" in types
        answers.append(f"input setup: recipe {rid}, {sorted(set(types))}")
        # A data package for the recipe humanpt's gateway has (id 1 on its own session), with a
        # target 50 mm from the arm: not this client's recipe.
        if p0 is not None:
            T = np.eye(4)
            T[:3, 3] = p0 + (FOREIGN_TARGET_MM, 0.0, 0.0)
            pose = rtde.ur_pose_from_transform(T)
            recipe = rtde.Recipe(1, names, ("INT32",) + ("DOUBLE",) * 6)
            s.sendall(recipe.encode({names[0]: 1 << 30, **dict(zip(names[1:], pose, strict=True))}))
            text = _read_packet(s, framer, pending, time.monotonic() + 2.0)
            answers.append("data package: " + (rtde.decode_text(text.payload)[0][:60]
                                               if text is not None and text.type == rtde.TEXT_MESSAGE else "no answer"))
    wall1 = time.time_ns()
    going = _wait(lambda: _state_after(ctx, wall1), LINK_BACK_TIMEOUT_S, ctx)
    p1 = _truth_now(ctx)
    jumped = p0 is not None and p1 is not None and float(np.linalg.norm(p1 - p0)) > FOREIGN_TARGET_MM / 2
    downs = _events(ctx, t0, "robot_gateway", ("link_down",))
    row.expected = refused and going and not jumped and not downs
    row.reaction_ms = None
    row.note = ("refused (IN_USE)" if refused else "NOT refused") + "; " + "; ".join(answers) + \
        ("; the arm did not follow" if not jumped else "; the ARM FOLLOWED the foreign target") + \
        ("; the gateway's session went on" if going and not downs else "; the gateway's session broke")


def attack_rtde_junk(ctx: Ctx, row: FaultRow, seconds: float = JUNK_S) -> None:
    """Junk on new connections to the robot's RTDE port for ``seconds``."""
    host, port = _rtde_address(ctx)
    junk = [b"junk\r\n", b"\xff\xff\xffUUUU", rtde.pack(ord("Z"), b"\x00" * 16), b"\x00\x03U" * 50,
            bytes(range(256))]
    t0 = time.monotonic()
    n = conns = 0
    while time.monotonic() - t0 < seconds:
        try:
            with socket.create_connection((host, port), timeout=2.0) as s:
                conns += 1
                for j in junk:
                    s.sendall(j)
                    n += len(j)
        except OSError:  # the controller dropped us mid-write: what it should do
            pass
    t1 = time.monotonic()
    wall1 = time.time_ns()
    going = _wait(lambda: _state_after(ctx, wall1), LINK_BACK_TIMEOUT_S, ctx)
    stops = _events(ctx, t0, "sim_robot", ("watchdog_stop", "protective_stop"))
    downs = _events(ctx, t0, "robot_gateway", ("link_down",))
    bad = _events(ctx, t0, "sim_robot", ("bad_rtde",))
    row.expected = going and not stops and not downs
    first = ctx.mon.wait_event(t0, ("bad_rtde",), "sim_robot", timeout_s=0.0)
    row.reaction_ms = _ms(first and first[0], t0)
    row.note = (f"{conns} connections, {n / max(t1 - t0, 1e-9) / 1e3:.0f} kB/s for {t1 - t0:.1f} s; "
                + ("the gateway's session went on" if going and not downs else
                   f"the gateway's session BROKE ({len(downs)} link_down)")
                + ("" if not stops else f"; the program STOPPED the arm ({stops[0].code})")
                + f"; the controller: {len(bad)} bad_rtde events")


def _freeze(pid: int) -> None:
    """Stop process ``pid`` (SIGSTOP) for FREEZE_S, then let it go on (the fault itself is a
    duration: the process silent this long)."""
    os.kill(pid, signal.SIGSTOP)
    try:
        time.sleep(FREEZE_S)
    finally:
        os.kill(pid, signal.SIGCONT)


def attack_freeze(ctx: Ctx, row: FaultRow) -> None:
    """The gateway frozen (SIGSTOP) for 0.5 s while the robot plays a line at 40 mm/s."""
    pid = ctx.control.pid("robot_gateway") if ctx.control is not None else None
    if pid is None:
        row.note = "no handle on the gateway's process"
        return
    started, p_start = start_line_playback(ctx, row)
    if not started:
        return
    bound = KILL_BOUND_CYCLES * ctx.gw.max_step_mm + ctx.gw.max_lead_mm
    try:
        if not _wait(lambda: fast_or_along(ctx, p_start), ANSWER_TIMEOUT_S, ctx):
            row.note = f"the robot never moved (at {_speed_mm_s(ctx):.1f} mm/s)"
            return
        speed = _speed_mm_s(ctx)
        t_freeze, wall_freeze = time.monotonic(), time.time_ns()
        _freeze(pid)
        wall_cont = time.time_ns()
        p_freeze = _truth_at(ctx, wall_freeze)
        _wait(lambda: _state_after(ctx, wall_cont), LINK_BACK_TIMEOUT_S, ctx)
        tr = [p for t, p in _truth_after(ctx, wall_freeze) if t <= wall_cont]
        moved = max((float(np.linalg.norm(p - p_freeze)) for p in tr), default=0.0) \
            if p_freeze is not None else math.nan
        stop = next(iter(_events(ctx, t_freeze, "sim_robot", ("watchdog_stop",))), None)
        follows = ctx.mon.wait_event(t_freeze, ("following",), "sim_robot",
                                     timeout_s=5.0 if stop is not None else 0.0)
        row.max_step_mm, row.limit_mm = moved, bound
        row.held = moved <= bound
        row.expected = bool(row.held)
        first = ctx.mon.wait_event(t_freeze, ("watchdog_stop",), "sim_robot", timeout_s=0.0)
        row.reaction_ms = _ms(first and first[0], t_freeze)
        row.note = (f"frozen {FREEZE_S:g} s at {speed:.1f} mm/s; the robot moved {moved:.2f} mm meanwhile (bound "
                    f"{KILL_BOUND_CYCLES} cycles x {ctx.gw.max_step_mm:.2f} mm + the lead {ctx.gw.max_lead_mm:g} mm "
                    f"= {bound:.2f} mm); "
                    + ("the program's watchdog stopped the arm" if stop else "no watchdog stop")
                    + ("; it followed again" if follows else ""))
    finally:
        _console(ctx, "controller", "stop", {}, ("command",), timeout_s=ANSWER_TIMEOUT_S)
        _console(ctx, "controller", "track", {}, ("command",), timeout_s=ANSWER_TIMEOUT_S)


def attack_robot_frozen(ctx: Ctx, row: FaultRow) -> None:
    """The simulated controller frozen (SIGSTOP) for 0.5 s: its data packages lost meanwhile."""
    pid = ctx.control.pid("sim_robot") if ctx.control is not None else None
    if pid is None:
        row.note = "no handle on the robot's process"
        return
    t0 = time.monotonic()
    _freeze(pid)
    wall1 = time.time_ns()
    going = _wait(lambda: _state_after(ctx, wall1), LINK_BACK_TIMEOUT_S, ctx)
    fault = ctx.mon.wait_event(t0, ("fault",), "robot_gateway", timeout_s=0.0)
    flagged = any(m.status.fault for _, m in ctx.mon.since("robot_gateway/robot_state", t0))
    seen = sorted({e.code for e in ctx.mon.events_since(t0) if e.source == "robot_gateway"})
    first = ctx.mon.wait_event(t0, tuple(seen), "robot_gateway", timeout_s=0.0) if seen else None
    row.reaction_ms = _ms(first and first[0], t0)
    row.expected = going and fault is None and not flagged
    row.note = (("robot states again" if going else "NO robot state since")
                + ("; no fault latched" if fault is None and not flagged else "; a FAULT latched")
                + (f"; robot_gateway: {', '.join(seen)}" if seen else ""))


class _Dashboard:
    """A Dashboard client of the robot's (one command line, one reply line)."""

    def __init__(self, address: tuple[str, int]):
        self.sock = socket.create_connection(address, timeout=ANSWER_TIMEOUT_S)
        self._buf = b""
        self.greeting = self.line()

    def line(self) -> str:
        while b"\n" not in self._buf:
            data = self.sock.recv(4096)
            if not data:
                raise OSError("the Dashboard server closed the connection")
            self._buf += data
        line, self._buf = self._buf.split(b"\n", 1)
        return line.decode(errors="replace").strip()

    def __call__(self, command: str) -> str:
        self.sock.sendall(command.encode() + b"\n")
        return self.line()

    def close(self) -> None:
        self.sock.close()


def _states(ctx: Ctx) -> int:
    with ctx.mon.lock:
        return len(ctx.mon.msgs["robot_gateway/robot_state"])


def _max_step_per_cycle(track: list[tuple[int, np.ndarray]], cycle_ns: float) -> float:
    """The largest distance the flange went in one cycle between truth samples (a sample the
    bench missed: the distance over the cycles between, per cycle)."""
    worst = 0.0
    for (t0, p0), (t1, p1) in zip(track, track[1:], strict=False):
        cycles = max(1, round((t1 - t0) / cycle_ns))
        worst = max(worst, float(np.linalg.norm(p1 - p0)) / cycles)
    return worst


def attack_program_stop(ctx: Ctx, row: FaultRow) -> None:
    """Stop and Play through the robot's Dashboard server while the robot plays a line."""
    from humanpt.sim_robot.config import SimRobotConfig
    from humanpt.sim_robot.ur import STOP_DECELERATION_MM_S2

    sim = ctx.file_cfg.component("sim_robot", SimRobotConfig) if ctx.file_cfg is not None else None
    if sim is None:
        row.note = "no run config: the robot's Dashboard address unknown"
        return
    address = parse_address(sim.dashboard_address)
    cycle_ns = ctx.gw.cycle_period_ms * 1e6
    started, p_start = start_line_playback(ctx, row)
    if not started:
        return
    dash: _Dashboard | None = None
    answers: dict[str, str] = {}
    try:
        if not _wait(lambda: fast_or_along(ctx, p_start), ANSWER_TIMEOUT_S, ctx):
            row.note = f"the robot never moved (at {_speed_mm_s(ctx):.1f} mm/s)"
            return
        dash = _Dashboard(address)
        t_stop = time.monotonic()
        answers["stop"] = dash("stop")
        stopped = ctx.mon.wait_event(t_stop, ("program_stopped",), "sim_robot", timeout_s=ANSWER_TIMEOUT_S)
        rest = ctx.mon.wait_event(t_stop, ("arm_at_rest",), "sim_robot", timeout_s=ANSWER_TIMEOUT_S)
        down = ctx.mon.wait_event(t_stop, ("link_down",), "robot_gateway", timeout_s=ANSWER_TIMEOUT_S)
        n = _states(ctx)
        _wait(lambda: _states(ctx) >= n + PSTOP_STILL_STATES, LINK_BACK_TIMEOUT_S, ctx)
        answers["programState"] = dash("programState")
        t_play, wall_play = time.monotonic(), time.time_ns()
        answers["play"] = dash("play")
        up = ctx.mon.wait_event(t_play, ("link_up",), "robot_gateway", timeout_s=ANSWER_TIMEOUT_S)
        n = _states(ctx)
        _wait(lambda: _states(ctx) >= n + PSTOP_AFTER_STATES, LINK_BACK_TIMEOUT_S, ctx)
        answers["after"] = dash("programState")
        if stopped is None or rest is None:
            row.note = "the robot never reported the stop (program_stopped, arm_at_rest)"
            return
        wall_stop, wall_rest = stopped[1].header.stamp_ns, rest[1].header.stamp_ns
        # braking: from the last truth before the stop took effect, at the speed of the cycle before it
        before = [(t, p) for t, p in _truth_after(ctx, wall_stop - 10 * cycle_ns) if t <= wall_stop]
        speed = 1e9 * _max_step_per_cycle(before, cycle_ns) / cycle_ns
        braked = [p for t, p in _truth_after(ctx, wall_stop) if t <= wall_rest]
        p_stop = before[-1][1] if before else None
        brake_mm = max((float(np.linalg.norm(p - p_stop)) for p in braked), default=0.0) if p_stop is not None \
            else math.nan
        brake_bound = speed ** 2 / (2.0 * STOP_DECELERATION_MM_S2) + speed * cycle_ns * 1e-9
        still = [p for t, p in _truth_after(ctx, wall_rest) if t <= wall_play]
        still_mm = max((float(np.linalg.norm(p - still[0])) for p in still), default=0.0)
        after = [(t, p) for t, p in _truth_after(ctx, wall_play)]
        jump = _max_step_per_cycle(after, cycle_ns)
        moved_after = float(np.linalg.norm(after[-1][1] - after[0][1])) if after else 0.0
        faults = _events(ctx, t_stop, "robot_gateway", ("fault", "robot_fault"))
        row.max_step_mm, row.limit_mm = jump, ctx.gw.max_step_mm
        row.held = brake_mm <= brake_bound and still_mm <= 1e-3 and jump <= ctx.gw.max_step_mm + 1e-6
        told = down is not None and "program stopped" in down[1].text
        row.expected = (answers["stop"] == "Stopped" and answers["play"] == "Starting program" and told
                        and up is not None and not faults and answers["programState"].startswith("STOPPED"))
        row.reaction_ms = _ms(down and down[0], t_stop)
        row.recovered = up is not None and answers["after"].startswith("PLAYING")
        row.note = (f"Dashboard: {answers['stop']!r}, {answers['programState']!r}, {answers['play']!r}; braked "
                    f"{brake_mm:.2f} mm from {speed:.1f} mm/s (bound v^2/2a + v dt = {brake_bound:.2f} mm), then "
                    f"{still_mm:.3f} mm in {PSTOP_STILL_STATES} cycles stopped; the gateway: "
                    + ("link_down (program stopped)" if told else "NO link_down naming the stop")
                    + (", link_up after Play" if up is not None else ", NO link_up after Play")
                    + (f", {len(faults)} FAULT(s)" if faults else "")
                    + f"; after Play {moved_after:.1f} mm in {PSTOP_AFTER_STATES} cycles, at most "
                    f"{jump:.2f} mm a cycle (limit {ctx.gw.max_step_mm:.2f})")
    finally:
        if dash is not None:
            try:
                if not dash("programState").startswith("PLAYING"):
                    dash("play")
                dash("quit")
            except OSError:
                pass
            dash.close()
        _console(ctx, "controller", "stop", {}, ("command",), timeout_s=ANSWER_TIMEOUT_S)
        _console(ctx, "controller", "track", {}, ("command",), timeout_s=ANSWER_TIMEOUT_S)


def ur_attacks():
    from humanpt.bench.faults import Attack

    return (
        Attack("rtde2", "second RTDE client writes the target registers", attack_second_client, keeps_loop=False,
               links=("ur",)),
        Attack("rtdejunk", f"junk on the robot's RTDE port ({JUNK_S:g} s)", attack_rtde_junk, keeps_loop=False,
               links=("ur",)),
        Attack("freeze", f"gateway frozen {FREEZE_S:g} s mid-motion (late answers)", attack_freeze,
               keeps_loop=False, links=("ur",)),
        Attack("lost", f"robot frozen {FREEZE_S:g} s (its data packages lost)", attack_robot_frozen,
               keeps_loop=False, links=("ur",)),
        Attack("pstop", "robot program stopped, then played (Dashboard)", attack_program_stop,
               keeps_loop=False, links=("ur",)),
    )

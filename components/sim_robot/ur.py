"""A simulated Universal Robots controller: sim_robot's arm behind an RTDE server running
humanpt's URScript program (``links/ur/robot_files.py``), for the twin and the tests.

:class:`UrRobot` is the controller (pure: times are given). Each RTDE client is a
:class:`RtdeSession` (its own output and input recipes, as on a real controller: the
protocol version 'V', the controller's version 'v', 'O', 'I', 'S', 'P', 'U', 'M'). Every
controller cycle (2 ms e-Series, 8 ms CB3) :meth:`UrRobot.cycle`:

1. runs one cycle of humanpt's program on the input registers the clients wrote: a new
   sequence number resets the watchdog (and, when stopped, resumes only if its target is
   within the lead of the arm: no jump to an old target); ``watchdog_cycles`` cycles without
   one stop the arm (``stopl``: an event; it stays); the heartbeat register +1; a running
   program servoes toward the target: the fraction 1 - exp(-cycle / tau) of the way each
   cycle, through the same kinematics and joint-speed limit as every simulated link
   (:func:`humanpt.sim_robot.core.corrected_joints`); an unreachable target or a joint step
   beyond the limit is a protective stop (safety mode 3, the program stopped);
2. sends every started session its data package (at the session's frequency: every
   ``round(rate / frequency)``-th cycle), ``timestamp`` = cycles x cycle (s).

Outputs and inputs are those of UR's RTDE guide (:data:`OUTPUT_TYPES`, :data:`INPUT_TYPES`);
a name it does not know is NOT_FOUND, an input another session holds is IN_USE (as on a
real controller). What it does not simulate reads as 0. Humanpt's assumptions (no controller
here to check them): the arm follows servoj's target with a first-order lag; the watchdog's
stopl stops at once; a program stopped (the pendant's Stop, the Dashboard server's ``stop``:
:meth:`UrRobot.stop_program`) no longer runs and the arm brakes along its last cycle's motion
at :data:`STOP_DECELERATION_MM_S2` (runtime_state STOPPING, then STOPPED); Play starts the
program from its start (:meth:`UrRobot.play_program`). The Dashboard server's commands:
:mod:`humanpt.sim_robot.ur_dashboard` (its clients come to :class:`UrSimRobotCore` on
``serial_rx`` with frame_id ``dashboard <peer>``).

:class:`RtdeServer` is the live shell: a TCP server on a configurable address (30004 on a
real controller; with ``dashboard``, the Dashboard server too, 29999 on a real one), one
accept loop (:class:`humanpt.sim_robot.tcp.TcpServers`) and a thread running the cycle.
"""

from __future__ import annotations

import math
import re
import socket
import threading
import time
from collections import deque

import numpy as np

from humanpt.geometry.arm import UnreachableError
from humanpt.geometry.transforms import rotation_angle_rad
from humanpt.robot_gateway.links.ur import protocol as rtde
from humanpt.runtime.core import Output, Port
from humanpt.schemas import humanpt_pb2 as pb
from humanpt.schemas.convert import pose
from humanpt.sim_robot.arm import ArmViews, JointStepError, SimArm, lag_gain
from humanpt.sim_robot.config import SimRobotConfig
from humanpt.sim_robot.core import TRUTH
from humanpt.sim_robot.rsi import RsiSimRobotCore, SimEvent
from humanpt.sim_robot.ur_dashboard import DashboardSession

_V6 = "VECTOR6D"
_V3 = "VECTOR3D"
# UR's RTDE guide: the outputs (controller -> client) and their types.
OUTPUT_TYPES: dict[str, str] = {
    "timestamp": "DOUBLE", "target_q": _V6, "target_qd": _V6, "target_qdd": _V6, "target_current": _V6,
    "target_moment": _V6, "actual_q": _V6, "actual_qd": _V6, "actual_current": _V6,
    "actual_current_window": _V6, "joint_control_output": _V6, "actual_TCP_pose": _V6, "actual_TCP_speed": _V6,
    "actual_TCP_force": _V6, "target_TCP_pose": _V6, "target_TCP_speed": _V6,
    "actual_digital_input_bits": "UINT64", "joint_temperatures": _V6, "actual_execution_time": "DOUBLE",
    "robot_mode": "INT32", "joint_mode": "VECTOR6INT32", "safety_mode": "INT32", "safety_status": "INT32",
    "actual_tool_accelerometer": _V3, "speed_scaling": "DOUBLE", "target_speed_fraction": "DOUBLE",
    "actual_momentum": "DOUBLE", "actual_main_voltage": "DOUBLE", "actual_robot_voltage": "DOUBLE",
    "actual_robot_current": "DOUBLE", "actual_joint_voltage": _V6, "actual_digital_output_bits": "UINT64",
    "runtime_state": "UINT32", "elbow_position": _V3, "elbow_velocity": _V3, "robot_status_bits": "UINT32",
    "safety_status_bits": "UINT32", "analog_io_types": "UINT32", "standard_analog_input0": "DOUBLE",
    "standard_analog_input1": "DOUBLE", "standard_analog_output0": "DOUBLE", "standard_analog_output1": "DOUBLE",
    "io_current": "DOUBLE", "euromap67_input_bits": "UINT32", "euromap67_output_bits": "UINT32",
    "euromap67_24V_voltage": "DOUBLE", "euromap67_24V_current": "DOUBLE", "tool_mode": "UINT32",
    "tool_analog_input_types": "UINT32", "tool_analog_input0": "DOUBLE", "tool_analog_input1": "DOUBLE",
    "tool_output_voltage": "INT32", "tool_output_current": "DOUBLE", "tool_temperature": "DOUBLE",
    "tcp_force_scalar": "DOUBLE", "output_bit_registers0_to_31": "UINT32", "output_bit_registers32_to_63": "UINT32",
    "input_bit_registers0_to_31": "UINT32", "input_bit_registers32_to_63": "UINT32",
    "tool_output_mode": "UINT8", "tool_digital_output0_mode": "UINT8", "tool_digital_output1_mode": "UINT8",
    "payload": "DOUBLE", "payload_cog": _V3, "payload_inertia": _V6, "script_control_line": "UINT32",
    "ft_raw_wrench": _V6, "joint_position_deviation_ratio": "DOUBLE", "collision_detection_ratio": "DOUBLE",
    "time_scale_source": "UINT32", "actual_current_as_torque": _V6,
}
# The inputs (client -> controller).
INPUT_TYPES: dict[str, str] = {
    "speed_slider_mask": "UINT32", "speed_slider_fraction": "DOUBLE", "standard_digital_output_mask": "UINT8",
    "standard_digital_output": "UINT8", "configurable_digital_output_mask": "UINT8",
    "configurable_digital_output": "UINT8", "tool_digital_output_mask": "UINT8", "tool_digital_output": "UINT8",
    "standard_analog_output_mask": "UINT8", "standard_analog_output_type": "UINT8",
    "standard_analog_output_0": "DOUBLE", "standard_analog_output_1": "DOUBLE",
    "input_bit_registers0_to_31": "UINT32", "input_bit_registers32_to_63": "UINT32",
    "external_force_torque": _V6,
}
# humanpt's assumption (UR documents no figure for a program stop): the arm brakes along its
# path as ``stopl(1)`` does, 1 m/s^2 (the program's own watchdog stop is stopl(1) too).
STOP_DECELERATION_MM_S2 = 1000.0
PROTECTIVE_UNLOCK_MS = 5000.0  # UR: a protective stop may be unlocked 5 s after it
PROGRAM_URP = "humanpt_ur.urp"  # the program the simulated UR has loaded (humanpt_ur.script in it)
RUNTIME_VERBS = {rtde.RUNTIME_STOPPED: "stopped", rtde.RUNTIME_PAUSED: "paused"}
_REGISTER = re.compile(r"(input|output)_(bit|int|double)_register_(\d+)$")
_REGISTER_TYPES = {"bit": "BOOL", "int": "INT32", "double": "DOUBLE"}
_ZERO = {"BOOL": False, "UINT8": 0, "UINT32": 0, "UINT64": 0, "INT32": 0, "DOUBLE": 0.0, "VECTOR3D": (0.0,) * 3,
         "VECTOR6D": (0.0,) * 6, "VECTOR6INT32": (0,) * 6, "VECTOR6UINT32": (0,) * 6}


def variable_type(name: str, inputs: bool) -> str | None:
    """RTDE's type of an output (``inputs`` False) or input variable; None: NOT_FOUND."""
    m = _REGISTER.match(name)
    if m:
        direction, kind, n = m.group(1), m.group(2), int(m.group(3))
        top = 127 if kind == "bit" else 47
        lo = 64 if kind == "bit" else 0
        if not (lo <= n <= top) or (inputs and direction != "input"):
            return None
        return _REGISTER_TYPES[kind]
    table = INPUT_TYPES if inputs else OUTPUT_TYPES
    return table.get(name)


class RtdeSession:
    """One client's RTDE session (pure): ``feed(bytes)`` -> the bytes to answer."""

    def __init__(self, robot: UrRobot, sid: int):
        self.robot = robot
        self.sid = sid
        self.framer = rtde.Framer()
        self.version_ok = False
        self.outputs: rtde.Recipe | None = None
        self.every = 1  # a data package every this many cycles
        self.inputs: dict[int, rtde.Recipe] = {}
        self.started = False
        self.closed: str | None = None  # why the controller drops the connection

    def feed(self, data: bytes, t_ns: int) -> bytes:
        out = bytearray()
        packets = self.framer.feed(data)
        if self.framer.errors:
            self.closed = str(self.framer.errors[0])  # out of step: the controller drops the client
            self.robot.counters["malformed"] += len(self.framer.errors)
            self.robot.events.append(SimEvent(t_ns, "warning", "bad_rtde", f"client {self.sid}: {self.closed}"))
            self.framer.errors.clear()
            return bytes(out)
        for p in packets:
            try:
                out += self._packet(p, t_ns)
            except (rtde.RtdeProtocolError, ValueError, OverflowError) as e:
                self.robot.counters["malformed"] += 1
                self.robot.events.append(SimEvent(t_ns, "warning", "bad_rtde", f"client {self.sid}: {e}"))
                out += rtde.encode_text(f"humanpt sim: {e}"[:200], "RTDE", 2)
        return bytes(out)

    def _packet(self, p: rtde.Packet, t_ns: int) -> bytes:
        r = self.robot
        if p.type == rtde.REQUEST_PROTOCOL_VERSION:
            self.version_ok = rtde.decode_version_request(p.payload) == rtde.PROTOCOL_VERSION
            return rtde.pack(p.type, rtde.encode_u8(int(self.version_ok)))
        if p.type == rtde.GET_URCONTROL_VERSION:
            return rtde.encode_controller_version(*r.controller_version)
        if p.type == rtde.TEXT_MESSAGE:
            rtde.decode_text(p.payload)
            return b""
        if p.type == rtde.START:
            self.started = self.outputs is not None and self.version_ok
            return rtde.pack(p.type, rtde.encode_u8(int(self.started)))
        if p.type == rtde.PAUSE:
            self.started = False
            return rtde.pack(p.type, rtde.encode_u8(1))
        if p.type == rtde.SETUP_OUTPUTS:
            freq, names = rtde.decode_setup_outputs(p.payload)
            if self.started or freq > r.rate_hz:
                return rtde.encode_setup_reply(p.type, 0, ("NOT_FOUND",) * len(names))
            types = tuple(variable_type(n, False) or "NOT_FOUND" for n in names)
            if "NOT_FOUND" in types:
                return rtde.encode_setup_reply(p.type, 0, types)
            self.outputs = rtde.Recipe(1, names, types)
            self.every = max(1, round(r.rate_hz / freq))
            return rtde.encode_setup_reply(p.type, 1, types)
        if p.type == rtde.SETUP_INPUTS:
            names = rtde.decode_setup_inputs(p.payload)
            types = []
            for n in names:
                t = variable_type(n, True)
                holder = r.input_owner.get(n)
                types.append("NOT_FOUND" if t is None else "IN_USE" if holder not in (None, self.sid) else t)
            if self.started or any(t in ("NOT_FOUND", "IN_USE") for t in types):
                return rtde.encode_setup_reply(p.type, 0, tuple(types))
            rid = len(self.inputs) + 1
            self.inputs[rid] = rtde.Recipe(rid, names, tuple(types))
            for n in names:
                r.input_owner[n] = self.sid
            return rtde.encode_setup_reply(p.type, rid, tuple(types))
        if p.type == rtde.DATA_PACKAGE:
            if not p.payload or p.payload[0] not in self.inputs:
                raise rtde.RtdeProtocolError(f"data package for recipe {p.payload[:1].hex() or '-'}: not set up")
            values = self.inputs[p.payload[0]].decode(p.payload)
            for n, v in values.items():
                if isinstance(v, float) and not math.isfinite(v):
                    raise rtde.RtdeProtocolError(f"{n} = {v}: not a number; package dropped")
            r.inputs.update(values)
            r.counters["input_packages"] += 1
            return b""
        raise rtde.RtdeProtocolError(f"a {p.letter!r} packet is not a client's")

    def close(self) -> None:
        for n, sid in list(self.robot.input_owner.items()):
            if sid == self.sid:
                del self.robot.input_owner[n]


class UrRobot(ArmViews):
    """The simulated UR controller with humanpt's program running (pure). ``events``,
    ``counters``, ``targets`` (the sequences followed, with their targets) for tests."""

    def __init__(self, config: SimRobotConfig, *, cycle_ms: float = 2.0, register_base: int = 24,
                 watchdog_cycles: int = 25, max_lead_mm: float = 5.0, max_lead_deg: float = 2.0,
                 time_constant_s: float = 0.02, controller_version: tuple[int, int, int, int] | None = None,
                 trace_cycles: int = 0, stop_deceleration_mm_s2: float = STOP_DECELERATION_MM_S2):
        if cycle_ms not in (2.0, 8.0):
            raise ValueError(f"a UR controller's cycle is 2 ms (e-Series) or 8 ms (CB3), got {cycle_ms}")
        self.config = config
        self.cycle_ms = cycle_ms
        self.rate_hz = 1000.0 / cycle_ms
        self.controller_version = controller_version or ((5, 11, 0, 0) if cycle_ms == 2.0 else (3, 15, 0, 0))
        self.b = register_base
        self.watchdog_cycles = watchdog_cycles
        self.max_lead_mm = max_lead_mm
        self.max_lead_rad = math.radians(max_lead_deg)
        self.alpha = lag_gain(cycle_ms, time_constant_s * 1000.0)
        self.arm = SimArm(config, cycle_ms)  # the arm (the set-up every simulated controller shares)
        self.cycles = 0
        self.inputs: dict[str, object] = {}
        self.input_owner: dict[str, int] = {}
        self.sessions: dict[int, RtdeSession] = {}
        self._sid = 0
        # the program
        self.runtime_state = rtde.RUNTIME_PLAYING
        self.safety_mode = rtde.SAFETY_MODE_NORMAL
        self.protective_stop_cycle = 0  # the cycle of the last protective stop
        self.stop_deceleration_mm_s2 = stop_deceleration_mm_s2
        self.program_name = PROGRAM_URP  # the program loaded (the Dashboard server's "load")
        self._last_step: tuple[np.ndarray, np.ndarray] | None = None  # the flange's last cycle: (dp mm, dR)
        self._brake: list | None = None  # stopping: [speed mm/s at the stop, the step then (dp, dR), fraction]
        self.start_program()
        self.events: list[SimEvent] = []
        self.targets: list[tuple[int, np.ndarray]] = []
        # (timestamp s, base_T_flange_mm) of the last ``trace_cycles`` cycles: the truth, for tests
        self.trace: deque = deque(maxlen=trace_cycles)
        self.counters = dict.fromkeys(("cycles", "packages", "input_packages", "malformed", "watchdog_stops",
                                       "refused_resumes", "moved", "new_sequence", "program_stops",
                                       "program_starts"), 0)

    @classmethod
    def from_config(cls, config: SimRobotConfig) -> UrRobot:
        """The controller as ``[sim_robot]`` (``protocol = "rtde"``) sets it up: the link's
        cycle (2 ms e-Series, 8 ms CB3), the program's defaults (registers from 24, the
        watchdog 25 cycles: ``[robot_gateway]``'s UR defaults)."""
        return cls(config, cycle_ms=config.cycle_ms)

    @property
    def timestamp_s(self) -> float:
        return self.cycles * self.cycle_ms / 1000.0

    # -- clients ---------------------------------------------------------------------------------
    def connect(self) -> RtdeSession:
        self._sid += 1
        s = self.sessions[self._sid] = RtdeSession(self, self._sid)
        return s

    def disconnect(self, session: RtdeSession) -> None:
        session.close()
        self.sessions.pop(session.sid, None)

    # -- the program's state (the pendant's Play, Pause and Stop; the Dashboard server's) ---------
    @property
    def program_running(self) -> bool:
        """The program runs (runtime_state PLAYING): it reads the registers every cycle."""
        return self.runtime_state == rtde.RUNTIME_PLAYING

    def start_program(self) -> None:
        """humanpt's program from its start (the script's first lines): the heartbeat and the
        followed sequence 0, the sequence already in the register an old session's (never
        followed), stopped until a newer sequence near the arm."""
        self.heartbeat = 0
        self.followed_seq = 0
        self._last_seq = self._seq()
        self._stale = 0
        self.stopped = True  # until a new sequence near the arm
        self.target: np.ndarray | None = None

    def stop_program(self, t_ns: int, why: str = "Stop") -> None:
        """Stop (the pendant's, or the Dashboard server's ``stop``): the program no longer
        runs (it reads no register); a moving arm decelerates along its path at
        ``stop_deceleration_mm_s2`` (runtime_state STOPPING), then STOPPED."""
        self._halt(t_ns, why, rtde.RUNTIME_STOPPING, rtde.RUNTIME_STOPPED)

    def pause_program(self, t_ns: int, why: str = "Pause") -> bool:
        """Pause: as a stop (PAUSING, then PAUSED), but Play resumes the program where it was.
        False: no program playing."""
        if self.runtime_state != rtde.RUNTIME_PLAYING:
            return False
        self._halt(t_ns, why, rtde.RUNTIME_PAUSING, rtde.RUNTIME_PAUSED)
        return True

    def _halt(self, t_ns: int, why: str, halting: int, halted: int) -> None:
        if self.runtime_state in (rtde.RUNTIME_STOPPED, rtde.RUNTIME_STOPPING) or self.runtime_state == halted:
            return
        if halted == rtde.RUNTIME_STOPPED:
            self.counters["program_stops"] += 1
        step = self._last_step if self.runtime_state == rtde.RUNTIME_PLAYING else None
        speed = 0.0 if step is None else float(np.linalg.norm(step[0])) * 1000.0 / self.cycle_ms
        if self._brake is not None:  # (stopped while pausing: goes on braking)
            self.runtime_state = halting
            return
        if speed > 1e-6:
            self._brake = [speed, step, 1.0, halted]
            self.runtime_state = halting
            text = (f"{why}: the program {RUNTIME_VERBS[halted]}; the arm decelerates from {speed:.1f} mm/s at "
                    f"{self.stop_deceleration_mm_s2:g} mm/s^2")
        else:
            self.runtime_state = halted
            text = f"{why}: the program {RUNTIME_VERBS[halted]}; the arm at rest"
        self.events.append(SimEvent(t_ns, "info", "program_" + RUNTIME_VERBS[halted], text))
        if self.runtime_state == halted:
            self._at_rest(t_ns, halted)

    def _at_rest(self, t_ns: int, halted: int) -> None:
        self.events.append(SimEvent(t_ns, "info", "arm_at_rest", f"the arm at rest; runtime_state "
                                    f"{rtde.RUNTIME_NAMES[halted]}"))

    def _decelerate(self, t_ns: int) -> None:
        """One cycle of a stop: the last step before it, scaled down by the deceleration."""
        speed0, (dp, dR), fraction, halted = self._brake
        fraction -= self.stop_deceleration_mm_s2 * self.cycle_ms / 1000.0 / speed0
        if fraction > 1e-9:
            self._brake[2] = fraction
            T = self.arm.forward()
            ahead = np.eye(4)
            ahead[:3, :3] = dR @ T[:3, :3]
            ahead[:3, 3] = T[:3, 3] + dp
            try:
                self.arm.servo(ahead, fraction)
                return
            except (UnreachableError, JointStepError):
                pass  # (cannot go on along it: stops here)
        self._brake = None
        self.runtime_state = halted if self.runtime_state != rtde.RUNTIME_STOPPING else rtde.RUNTIME_STOPPED
        self._at_rest(t_ns, self.runtime_state)

    def play_program(self, t_ns: int, why: str = "Play") -> bool:
        """Play: a stopped program starts from its start (:meth:`start_program`: it follows
        no old target), a paused one goes on. False (not started): a protective stop not
        unlocked, the arm still braking."""
        if self.safety_mode != rtde.SAFETY_MODE_NORMAL or self._brake is not None:
            return False
        if self.runtime_state == rtde.RUNTIME_PLAYING:
            return True
        if self.runtime_state == rtde.RUNTIME_STOPPED:
            self.start_program()
            self.counters["program_starts"] += 1
            text = f"{why}: the program starts from its beginning (no old target followed)"
        else:
            text = f"{why}: the program goes on where it was paused"
        self.runtime_state = rtde.RUNTIME_PLAYING
        self.events.append(SimEvent(t_ns, "info", "program_playing", text))
        return True

    def unlock_protective_stop(self, t_ns: int) -> bool:
        """The protective stop released (as UR allows: 5 s after it); False: too early."""
        if self.safety_mode != rtde.SAFETY_MODE_PROTECTIVE_STOP:
            return True
        if (self.cycles - self.protective_stop_cycle) * self.cycle_ms < PROTECTIVE_UNLOCK_MS:
            return False
        self.safety_mode = rtde.SAFETY_MODE_NORMAL
        self.events.append(SimEvent(t_ns, "info", "protective_stop_unlocked", "the protective stop released"))
        return True

    # -- the program -----------------------------------------------------------------------------
    def _seq(self) -> int:
        return int(self.inputs.get(f"input_int_register_{self.b}", 0))

    def _input_target(self) -> np.ndarray:
        pose = [float(self.inputs.get(f"input_double_register_{self.b + i}", 0.0)) for i in range(6)]
        return rtde.transform_from_ur_pose(pose)

    def _near(self, target: np.ndarray) -> bool:
        T = self.base_T_flange_mm
        return (float(np.linalg.norm(target[:3, 3] - T[:3, 3])) <= self.max_lead_mm
                and float(rotation_angle_rad(T[:3, :3].T @ target[:3, :3])) <= self.max_lead_rad)

    def _program(self, t_ns: int) -> None:
        seq = self._seq()
        if seq != self._last_seq:
            self._last_seq = seq
            self._stale = 0
            self.counters["new_sequence"] += 1  # (cycles answered in time: a new target this cycle)
            target = self._input_target()
            if self.stopped:
                if self._near(target):
                    self.stopped = False
                    self.events.append(SimEvent(t_ns, "info", "following", f"following sequence {seq}"))
                else:
                    self.counters["refused_resumes"] += 1
            if not self.stopped:
                self.target = target
                self.followed_seq = seq
                self.targets.append((seq, target))
        else:
            self._stale += 1
        if not self.stopped and self._stale >= self.watchdog_cycles:
            self.stopped = True
            self.target = None
            self.counters["watchdog_stops"] += 1
            self.events.append(SimEvent(t_ns, "error", "watchdog_stop",
                                        f"no new target for {self.watchdog_cycles} cycles: stopl, the arm stays"))
        self.heartbeat = self.heartbeat % 1_000_000_000 + 1
        if not self.stopped and self.target is not None:
            self._move(t_ns)

    def _move(self, t_ns: int) -> None:
        try:
            moved = self.arm.servo(self.target, self.alpha)
        except (UnreachableError, JointStepError) as e:
            self.safety_mode = rtde.SAFETY_MODE_PROTECTIVE_STOP
            self.protective_stop_cycle = self.cycles
            self.runtime_state = rtde.RUNTIME_STOPPED
            self.stopped = True
            self.events.append(SimEvent(t_ns, "error", "protective_stop", f"protective stop: the target {e}"))
            return
        if moved:
            self.counters["moved"] += 1

    # -- the cycle ---------------------------------------------------------------------------------
    def outputs(self, names=None) -> dict[str, object]:
        """The outputs this controller simulates (the poses only when ``names``, a set, asks
        for them or is None: a rotation vector costs what the rest does)."""
        v: dict[str, object] = {
            "timestamp": self.timestamp_s,
            "actual_q": tuple(float(q) for q in self.q_rad),
            "target_q": tuple(float(q) for q in self.q_rad),
            "robot_mode": rtde.ROBOT_MODE_RUNNING,
            "safety_mode": self.safety_mode,
            "safety_status": self.safety_mode,
            "runtime_state": self.runtime_state,
            "robot_status_bits": rtde.STATUS_BIT_POWER_ON | (rtde.STATUS_BIT_PROGRAM_RUNNING
                                                             if self.program_running else 0),
            "speed_scaling": 1.0,
            "target_speed_fraction": 1.0,
            f"output_int_register_{self.b}": self.heartbeat,
            f"output_int_register_{self.b + 1}": self.followed_seq,
        }
        if names is None or "actual_TCP_pose" in names:
            v["actual_TCP_pose"] = rtde.ur_pose_from_transform(self.arm.forward())
        if names is None or "target_TCP_pose" in names:
            v["target_TCP_pose"] = rtde.ur_pose_from_transform(self.target if self.target is not None
                                                               else self.arm.forward())
        return v

    def cycle(self, t_ns: int) -> dict[int, bytes]:
        """A controller cycle at ``t_ns``: the program's cycle, then each started session's data
        package (session id -> bytes)."""
        self.cycles += 1
        self.counters["cycles"] += 1
        before = self.arm.forward()
        if self.program_running:
            self._program(t_ns)
        elif self._brake is not None:
            self._decelerate(t_ns)
        after = self.arm.forward()
        self._last_step = (after[:3, 3] - before[:3, 3], after[:3, :3] @ before[:3, :3].T)
        if self.trace.maxlen:
            self.trace.append((self.timestamp_s, self.base_T_flange_mm))
        out: dict[int, bytes] = {}
        values = None
        due = [s for s in self.sessions.values()
               if s.started and s.outputs is not None and self.cycles % s.every == 0]
        for s in due:
            sid = s.sid
            if values is None:
                values = self.outputs({n for d in due for n in d.outputs.names})
            vals = {n: values.get(n, _ZERO[t]) for n, t in zip(s.outputs.names, s.outputs.types, strict=True)}
            out[sid] = s.outputs.encode(vals)
            self.counters["packages"] += 1
        return out


CLOSED = " closed"  # a serial_rx chunk's frame_id "<peer> closed" (no data): that client has gone
DASHBOARD = "dashboard "  # a serial_rx chunk's frame_id "dashboard <peer>": a Dashboard server's client


class UrSimRobotCore(RsiSimRobotCore):
    """sim_robot over RTDE (pure): :class:`UrRobot` (:meth:`UrRobot.from_config`) with a
    session per client, on the component's ``tick`` (every cycle of the link, 2 or 8 ms).
    Inputs ``tick``, ``serial_rx`` (the clients' RTDE bytes, a TCP stream as a byte stream;
    the chunk's frame_id names the client, "" the one of the lock-step twin); outputs
    ``serial_tx`` (each session's answers and each cycle's data package, frame_id = its
    client), ``sim_robot/truth`` and ``sim_robot/events``, as over RSI and EGM. Built by
    ``SimRobotCore.create`` for ``protocol = "rtde"``; the lock-step twin wires it to the
    gateway as a fast serial line (:meth:`humanpt.runtime.lockstep.LockStep.connect_serial`);
    live, the shell's TCP server (``humanpt.sim_robot.shell.TcpServerAdapter`` at
    ``rtde_bind``) carries it, serving every client as a UR does: it marks each new connection
    with an empty chunk (that client's session starts afresh) and each closed one with an
    empty chunk from "<peer> closed" (its session ends, its input registers freed); an empty
    ``serial_tx`` chunk to a client is the controller dropping it (bytes that are not RTDE)."""

    ports = (
        Port("tick", pb.Tick, "_on_cycle"),
        Port("serial_rx", pb.SerialChunk, "_on_rtde"),
    )
    # Snapshots: the targets taken and the trace are kept for tests only.
    not_frozen = frozenset({"robot.targets", "robot.trace"})
    state_types = (SimEvent, rtde.Recipe, DashboardSession, RtdeSession)

    def __init__(self, config: SimRobotConfig):
        super().__init__(config)
        self.session = self.robot.connect()  # the lock-step twin's client (frame_id "")
        self.clients: dict[str, RtdeSession] = {"": self.session}  # frame_id -> its session
        self.dashboards: dict[str, DashboardSession] = {}  # frame_id "dashboard <peer>" -> its session

    def make_robot(self, config: SimRobotConfig) -> UrRobot:
        return UrRobot.from_config(config)

    def _send(self, t_ns: int, data: bytes, outs: list[Output], client: str = "", close: bool = False) -> None:
        if data or close:
            outs.append(("serial_tx", pb.SerialChunk(header=self.next_header("serial_tx", t_ns, client), data=data)))

    def _on_rtde(self, t_ns: int, msg: pb.SerialChunk) -> list[Output]:
        outs: list[Output] = []
        client = msg.header.frame_id
        if client.startswith(DASHBOARD):
            self._on_dashboard(t_ns, client, bytes(msg.data), outs)
            self._flush_events(outs)
            return outs
        if not msg.data:  # the live server's mark of a new connection (a fresh session), or of a closed one
            gone = client.endswith(CLOSED)
            client = client.removesuffix(CLOSED)
            old = self.clients.pop(client, None)
            if old is not None:
                self.robot.disconnect(old)
            if not gone:
                self.session = self.clients[client] = self.robot.connect()  # (the latest client's)
            return outs
        session = self.clients.get(client)
        if session is None:  # (bytes from a client never marked: a session of its own)
            session = self.clients[client] = self.robot.connect()
        self._send(t_ns, session.feed(bytes(msg.data), t_ns), outs, client)
        if session.closed is not None:  # out of step: the controller drops the client
            self.robot.disconnect(self.clients.pop(client))
            self._send(t_ns, b"", outs, client, close=True)
        self._flush_events(outs)
        return outs

    def _on_dashboard(self, t_ns: int, client: str, data: bytes, outs: list[Output]) -> None:
        """A Dashboard client's bytes (``dashboard <peer>``; empty: the server's mark of its
        connection, greeted, or of its end)."""
        if not data:
            if client.endswith(CLOSED):
                self.dashboards.pop(client.removesuffix(CLOSED), None)
            else:
                self.dashboards[client] = DashboardSession(self.robot, client.removeprefix(DASHBOARD))
                self._send(t_ns, DashboardSession.greeting(), outs, client)
            return
        session = self.dashboards.get(client)
        if session is None:  # (bytes from a client never marked: greeted now)
            session = self.dashboards[client] = DashboardSession(self.robot, client.removeprefix(DASHBOARD))
        self._send(t_ns, session.feed(data, t_ns), outs, client)
        if session.closed is not None:  # quit, or not a Dashboard client: the server closes it
            del self.dashboards[client]
            self._send(t_ns, b"", outs, client, close=True)

    def _on_cycle(self, t_ns: int, msg: pb.Tick) -> list[Output]:
        outs: list[Output] = []
        packages = self.robot.cycle(t_ns)
        for client, session in self.clients.items():
            self._send(t_ns, packages.get(session.sid, b""), outs, client)
        self._flush_events(outs)
        outs.append((TRUTH, pb.Truth(header=self.next_header(TRUTH, t_ns, "world"),
                                     world_T_flange=pose(self.robot.arm.true_world_T_flange_m()))))
        return outs


class RtdeServer:
    """The simulated controller live: an RTDE server at ``bind`` ("host:port"; port 0: a free
    one, :attr:`address`), with ``dashboard`` ("host:port") its Dashboard server too
    (:mod:`humanpt.sim_robot.ur_dashboard`, :attr:`dashboard_address`), on the shared accept
    loop (:class:`humanpt.sim_robot.tcp.TcpServers`), and its cycle on a thread
    (``time.monotonic`` paced: each cycle at start + k x cycle). Client packets and Dashboard
    commands are handled at once under the robot's lock.

    How a client answers (for ``humanpt bench ur``; the robot's program sees none of it): a
    session's data package is *answered* when the client's next input data package is read
    before the session's next data package goes out (before the program's next cycle reads the
    registers, as the program sees it: a new target for its next cycle). ``answers`` counts,
    over every session, the ``packages`` judged (those whose next one went out) and the
    ``answered`` ones, and ``latency_ns`` keeps each answer's time (package sent -> the first
    input package read after it). ``overruns``: cycles started more than 1 ms after their
    deadline (the simulator itself late)."""

    def __init__(self, robot: UrRobot, bind: str = "127.0.0.1:0", *, dashboard: str | None = None):
        from humanpt.sim_robot.tcp import TcpServers

        self.robot = robot
        binds = {"RTDE": bind} if dashboard is None else {"RTDE": bind, "Dashboard": dashboard}
        self.tcp = TcpServers(binds, self)
        self.address: tuple[str, int] = self.tcp.addresses["RTDE"]
        self.dashboard_address: tuple[str, int] | None = self.tcp.addresses.get("Dashboard")
        self.lock = threading.Lock()
        self._stop = threading.Event()
        self._conns: dict[int, socket.socket] = {}  # RTDE session id -> its connection
        self._sessions: dict[str, RtdeSession | DashboardSession] = {}  # "<service> <peer>" -> its session
        self._thread: threading.Thread | None = None
        self._sent: dict[int, list] = {}  # session -> [send time of its last data package, answered yet]
        self.answers = dict.fromkeys(("packages", "answered"), 0)
        self.latency_ns: deque[int] = deque(maxlen=1_000_000)
        self.overruns = 0
        self.answering = threading.Event()  # set at a client's first answer

    def start(self) -> RtdeServer:
        self.tcp.start()
        self._thread = threading.Thread(target=self._cycle_loop, name="rtde-cycle", daemon=True)
        self._thread.start()
        return self

    # -- the connections (humanpt.sim_robot.tcp.Handler, from the server's threads) --------------
    def opened(self, service: str, peer: str, conn: socket.socket) -> None:
        with self.lock:
            if service == "RTDE":
                session = self._sessions[f"{service} {peer}"] = self.robot.connect()
                self._conns[session.sid] = conn
                return
            self._sessions[f"{service} {peer}"] = DashboardSession(self.robot, peer)
            conn.sendall(DashboardSession.greeting())

    def received(self, service: str, peer: str, conn: socket.socket, data: bytes) -> bool:
        with self.lock:
            session = self._sessions.get(f"{service} {peer}")
            if session is None:
                return False
            now = time.monotonic_ns()
            before = self.robot.counters["input_packages"]
            reply = session.feed(data, now)
            if isinstance(session, RtdeSession) and self.robot.counters["input_packages"] > before:
                self._answered(session.sid, now)
            if reply:
                conn.sendall(reply)
            return session.closed is None

    def closed(self, service: str, peer: str, conn: socket.socket) -> None:
        with self.lock:
            session = self._sessions.pop(f"{service} {peer}", None)
            if isinstance(session, RtdeSession):
                self.robot.disconnect(session)
                self._conns.pop(session.sid, None)
                self._sent.pop(session.sid, None)

    def _answered(self, sid: int, now_ns: int) -> None:
        """An input data package of session ``sid`` read at ``now_ns``: the first since its last
        data package answers it."""
        last = self._sent.get(sid)
        if last is not None and not last[1]:
            last[1] = True
            self.latency_ns.append(now_ns - last[0])
            self.answering.set()

    def _cycle_loop(self) -> None:
        period = self.robot.cycle_ms / 1000.0
        t0 = time.monotonic()
        k = 0
        while not self._stop.is_set():
            k += 1
            delay = t0 + k * period - time.monotonic()
            if delay > 0:
                self._stop.wait(delay)
            elif delay < -1e-3:
                self.overruns += 1
            with self.lock:
                out = self.robot.cycle(time.monotonic_ns())
                for sid, data in out.items():
                    conn = self._conns.get(sid)
                    if conn is None:
                        continue
                    try:
                        conn.sendall(data)
                    except OSError:
                        continue
                    last = self._sent.get(sid)
                    if last is not None:  # the last package's window closes: judged
                        self.answers["packages"] += 1
                        self.answers["answered"] += last[1]
                    self._sent[sid] = [time.monotonic_ns(), False]

    def disconnect_all(self) -> None:
        """Drop every client (a controller reboot's view from the network)."""
        self.tcp.drop_all()

    def close(self) -> None:
        self._stop.set()
        self.tcp.close()
        if self._thread is not None:
            self._thread.join(timeout=2.0)

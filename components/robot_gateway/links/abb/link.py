"""The gateway's Link over ABB EGM position guidance (pure: datagrams and times are given).

Cycle numbers: the robot's ``header.seqno`` (mod 2^32): a lost message is a gap of one, and
the gateway's rules (missed cycles, lost states, command-ahead by cycle number) apply
unchanged. Sequence: the next seqno continues the session; the same again (UDP may
duplicate) is dropped; up to ``MAX_GAP_CYCLES`` ahead is lost messages of the same session;
anything else (back, further ahead) is *out of sequence*: dropped with no answer and kept as
a candidate; if the next message continues the candidate, the robot restarted EGM (a new
session, ``LinkUp``), else it was nothing (as over RSI: one datagram never restarts a session).

Targets: EGM guides the robot to ABSOLUTE poses. The link keeps the target: the first
fed-back pose of a session, then the target plus each cycle's step (in the base frame, or in
the flange's with ``correction_frame = "tool"``), pulled back to within ``max_lead_mm`` /
``max_lead_deg`` of the fed-back pose. A hold repeats the target (the robot converges to it,
at most the lead further); a hold for a fault (the gateway's "corrections off") sets the
target to the fed-back pose: the robot stops where it is.
"""

from __future__ import annotations

import math

import numpy as np

from humanpt.geometry.transforms import (
    apply_step,
    interpolate_transform,
    matrix_from_rotvec,
    rotation_angle_rad,
)
from humanpt.robot_gateway.link import CycleReceived, CycleState, LinkError, LinkUp, Transmit
from humanpt.robot_gateway.links.abb.config import AbbConfig
from humanpt.robot_gateway.links.abb.protocol import (
    EgmProtocolError,
    EgmTarget,
    decode_robot,
    encode_sensor,
    pos_quat,
)

MAX_GAP_CYCLES = 25
_MOD = 1 << 32


class AbbLink:
    name = "EGM"
    rx_topic = "udp_rx"
    tx_topic = "udp_tx"
    up_text = "EGM link up (an EgmRobot message from the robot)"

    def __init__(self, correction_frame: str = "base", max_lead_mm: float = 5.0, max_lead_deg: float = 2.0):
        self.tool_mode = correction_frame == "tool"
        self.max_lead_mm = max_lead_mm
        self.max_lead_rad = math.radians(max_lead_deg)
        self._running = False
        self._last: int | None = None  # the last seqno accepted
        self._candidate: int | None = None
        self.feedback: np.ndarray | None = None  # base_T_flange (mm) last fed back
        self.target: np.ndarray | None = None  # base_T_target (mm) last sent (or to send)
        self._seq = 0  # the sensor's own header.seqno
        self.counters = dict.fromkeys(("datagrams", "malformed", "sessions", "duplicates", "out_of_sequence",
                                       "lead_limited"), 0)

    @classmethod
    def from_config(cls, config: AbbConfig) -> AbbLink:
        return cls(config.correction_frame, config.max_lead_mm, config.max_lead_deg)

    @property
    def is_running(self) -> bool:
        return self._running

    def start(self, t_ns: int) -> list:
        """(Re)start: wait for the robot's next message (EGM has no handshake)."""
        self._running = False
        self._last = self._candidate = None
        self.target = None
        return []

    def poll(self, t_ns: int) -> list:
        return []

    def receive(self, data: bytes, t_ns: int) -> list:
        self.counters["datagrams"] += 1
        try:
            st = decode_robot(data)
        except EgmProtocolError as e:
            self.counters["malformed"] += 1
            return [LinkError(f"EGM link: {e}; datagram dropped, no answer for it "
                              f"({self.counters['malformed']} malformed so far)")]
        if not self._running:
            return self._accept(st, new_session=True)
        last = self._last
        assert last is not None
        ahead = (st.seqno - last) % _MOD
        if ahead == 0:
            self.counters["duplicates"] += 1
            return []
        candidate, self._candidate = self._candidate, None
        if ahead <= MAX_GAP_CYCLES:
            return self._accept(st)
        if candidate is not None and (st.seqno - candidate) % _MOD == 1:
            return self._accept(st, new_session=True)  # the robot restarted EGM
        self._candidate = st.seqno
        self.counters["out_of_sequence"] += 1
        return [LinkError(f"EGM link: seqno {st.seqno} out of sequence (the last {last}): dropped, no answer; "
                          f"it counts only if the next message continues it ({self.counters['out_of_sequence']} "
                          "so far)")]

    def _accept(self, st, new_session: bool = False) -> list:
        events: list = []
        self.feedback = st.base_T_flange_mm()
        if new_session:
            self._running = True
            self.target = self.feedback.copy()
            self.counters["sessions"] += 1
            events.append(LinkUp())
        self._last = st.seqno
        events.append(CycleReceived(CycleState(
            cycle=st.seqno % _MOD,
            base_T_flange_mm=self.feedback,
            corrections_on=st.mci_running and st.rapid_running,
            tool_mode=self.tool_mode,
            cumulative=True,  # each step adds to the target
            arm_power=st.motors_on,
            fault=False,
            correction_missed=False,  # EGM reports no late answers to the sensor
        )))
        return events

    def _within_lead(self, target: np.ndarray) -> np.ndarray:
        """``target`` pulled back to within the lead of the fed-back pose."""
        fb = self.feedback
        assert fb is not None
        out = np.array(target)
        lead = out[:3, 3] - fb[:3, 3]
        n = float(np.linalg.norm(lead))
        limited = False
        if n > self.max_lead_mm:
            out[:3, 3] = fb[:3, 3] + lead * (self.max_lead_mm / n)
            limited = True
        angle = float(rotation_angle_rad(fb[:3, :3].T @ out[:3, :3]))
        if angle > self.max_lead_rad:
            out[:3, :3] = interpolate_transform(fb, out, self.max_lead_rad / angle)[:3, :3]
            limited = True
        if limited:
            self.counters["lead_limited"] += 1
        return out

    def _message(self, cycle: int, t_ns: int) -> EgmTarget:
        assert self.target is not None
        self._seq = (self._seq + 1) % _MOD
        pos, quat = pos_quat(self.target)
        return EgmTarget(self._seq, (t_ns // 1_000_000) % _MOD, pos, quat, echo=cycle)

    def correction(self, cycle: int, dp_mm: np.ndarray, rv_rad: np.ndarray,
                   max_step_mm: float, max_step_deg: float) -> EgmTarget:
        """The target moved by the step (already within the per-cycle limits: the gateway
        clamps before it calls), within the lead of the fed-back pose."""
        assert self.target is not None, "no session"
        dp, rv = np.asarray(dp_mm, float), np.asarray(rv_rad, float)
        if self.tool_mode:  # a step of the flange, in its own frame
            step = np.eye(4)
            step[:3, :3] = matrix_from_rotvec(rv)
            step[:3, 3] = dp
            moved = self.target @ step
        else:
            moved = apply_step(self.target, dp, rv)
        self.target = self._within_lead(moved)
        return self._message(cycle, 0)

    def hold(self, cycle: int, corrections_off: bool) -> EgmTarget:
        assert self.target is not None, "no session"
        if corrections_off and self.feedback is not None:
            self.target = self.feedback.copy()  # a fault: stop where the robot is
        return self._message(cycle, 0)

    def send(self, correction: EgmTarget, t_ns: int) -> list:
        msg = EgmTarget(correction.seqno, (t_ns // 1_000_000) % _MOD, correction.pos_mm, correction.quat_wxyz,
                        correction.echo)
        return [Transmit(encode_sensor(msg))]

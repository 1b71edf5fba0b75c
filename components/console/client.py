"""The operator console's client: the paper's GUI (Fig. 5) as calls from Python.

The GUI's options are the owning components' live parameters, set through their params
queryables (``humanpt/<cell>/<component>/params``), so every change reaches the core as a
``param`` input and is in its recording.  Commands (record, save, calibrate, playback,
hold/track/return) are published on ``console/command`` and confirmed by the controller's
answering event.  The status is read from ``controller/status``,
``robot_gateway/robot_state`` and ``perception/tob``.  Like every component it is a client
of the router.  ``humanpt console`` (:mod:`humanpt.cli.console`) parses and prints::

    from humanpt.console.client import Console, playback_args
    con = Console(load_config("cell.toml"))
    con.set(["threshold=70"]); con.command("record_start")
    con.command("playback", playback_args("path-1.seam.json", speed_mm_s=20))
"""

from __future__ import annotations

import json
import math
import os
import queue
import re
import sys
import threading
import time

import numpy as np

from humanpt.runtime.bus import (
    declare_topic_publisher,
    liveliness_key,
    open_tool_session,
    params_key,
)
from humanpt.schemas import humanpt_pb2 as pb
from humanpt.schemas import topics
from humanpt.schemas.topics import current_name

# GUI option (Fig. 5) -> (component, live parameter, help).
OPTIONS: dict[str, tuple[str, str, str]] = {
    "threshold": (
        "perception",
        "threshold",
        "binarisation threshold T, grey levels (paper §4 step 2)",
    ),
    "invert": (
        "perception",
        "invert",
        "image inversion: the sources are darker than the background (step 3)",
    ),
    "method": ("perception", "method", "perception method: weighted (default) or paper"),
    "mask": (
        "perception",
        "mask",
        "image mask: rectangles u,v,width,height (px) the perception ignores, ';' between them; "
        "'none' clears it (paper Fig. 5: Mask)",
    ),
    "delay": (
        "controller",
        "recording_delay_cycles",
        "recording delay: a path point every N cycles (paper: 10)",
    ),
    "dz": (
        "controller",
        "dz_mm",
        "dz offset: distance of the virtual point D from the camera, mm (paper: 600)",
    ),
    "stop-on-current-location": (
        "controller",
        "lost_action",
        "target lost: true = stop on current location (hold), false = return to start",
    ),
    "return-pose": (
        "controller",
        "return_flange_x",
        "the prespecified pose 'return' goes to: x,y,z,psi,theta,phi of the flange (world, mm, deg); "
        "'start' clears it (the first robot pose)",
    ),
    "calib-samples": (
        "controller",
        "calibration_samples",
        "N calibration samples of the driver tip (§4.1)",
    ),
}
ALIASES = {
    "t": "threshold",
    "inversion": "invert",
    "inverse": "invert",
    "recording-delay": "delay",
    "dz-offset": "dz",
    "dz-mm": "dz",
    "stop": "stop-on-current-location",
    "return": "return-pose",
    "home": "return-pose",
    "n": "calib-samples",
    "samples": "calib-samples",
    "calibration-samples": "calib-samples",
}

# Command verb -> the controller event codes that answer it ("bad_command" answers any).
REPLIES = {
    "track": ("command",),
    "hold": ("command",),
    "return": ("command",),
    "record_start": ("record_started",),
    "record_stop": ("record_stopped",),
    "save": ("path_saved", "save_failed"),  # what the controller's path writer did
    "calibrate": ("calibration_started",),
    "playback": ("playback_started",),
    "playback_pause": ("playback_paused",),
    "playback_resume": ("playback_resumed",),
    "playback_rate": ("playback_rate",),
    "reset_fault": ("fault_cleared", "no_fault"),
    "alter_on": ("alter_on",),
    "alter_off": ("alter_off",),
}
REFUSALS = ("bad_command", "save_failed", "bad_console_command")


def format_event(ev: pb.Event) -> str:
    """One line for an event of any component or of the router (under mTLS the router
    publishes what its access control refused as ``access_denied`` warnings on
    ``router/events``)."""
    sev = pb.Severity.Name(ev.severity).removeprefix("SEVERITY_") if ev.severity in pb.Severity.values() \
        else str(ev.severity)
    return f"event {ev.source or '?'} {sev} {ev.code}: {ev.text}"


class EventFeed:
    """Every component's and the router's events (``humanpt/<cell>/*/events``), queued as
    they arrive; :meth:`lines` gives those at or above ``min_severity`` as text."""

    def __init__(self, session, cell: str, min_severity: int = pb.SEVERITY_WARNING):
        self.queue: queue.Queue = queue.Queue()
        self.min_severity = min_severity
        self._sub = session.declare_subscriber(f"{topics.KEY_PREFIX}/{cell}/*/events",
                                               lambda smp: self.queue.put(smp.payload.to_bytes()))

    def events(self, timeout_s: float = 0.0) -> list[pb.Event]:
        """The events arrived so far (waiting up to ``timeout_s`` for the first one)."""
        out = []
        try:
            while True:
                raw = self.queue.get(timeout=timeout_s) if timeout_s > 0 and not out else self.queue.get_nowait()
                try:
                    ev = pb.Event.FromString(raw)
                except Exception:  # noqa: BLE001 - a bad payload is not the console's business
                    continue
                if ev.severity >= self.min_severity:
                    out.append(ev)
        except queue.Empty:
            return out

    def close(self) -> None:
        self._sub.undeclare()

    undeclare = close  # closed with the status's subscribers


def operator_name() -> str:
    """Who is at this console: user@host (logged by the component that acts on a command)."""
    import getpass
    import socket

    try:
        user = getpass.getuser()
    except (KeyError, OSError):  # no passwd entry (a container)
        user = f"uid{os.getuid()}"
    return f"{user}@{socket.gethostname()}"

STATUS_TOPICS = (
    "controller/status",
    "robot_gateway/robot_state",
    "perception/tob",
    "pose_filter/tob_state",
)


class ConsoleError(ValueError):
    """A console request that cannot be made (bad option, nobody answering); exit status 1."""


def _bool(text) -> bool:
    if isinstance(text, bool):
        return text
    t = str(text).strip().lower()
    if t in ("1", "true", "yes", "on", "y"):
        return True
    if t in ("0", "false", "no", "off", "n"):
        return False
    raise ConsoleError(f"{text!r} is not true or false")


def parse_mask(text: str) -> list[list[int]]:
    """``u,v,w,h;u,v,w,h`` (px) -> [[u, v, w, h], ...]; ``none`` or empty -> [] (no mask).
    ValueError naming the rectangle that is not four integers; the ranges are the
    perception's own check (its config), when the value is set."""
    text = text.strip()
    if text.lower() in ("", "none", "[]"):
        return []
    rects = []
    for part in text.split(";"):
        fields = [f.strip() for f in part.split(",")]
        try:
            if len(fields) != 4:
                raise ValueError
            rects.append([int(f) for f in fields])
        except ValueError:
            raise ValueError(f"{part.strip()!r} is not a rectangle u,v,width,height of integers (px)") from None
    return rects


def parse_pose(text: str) -> list[float] | None:
    """``x,y,z,psi,theta,phi`` (mm, deg) -> six numbers; ``start`` or ``none`` -> None."""
    if text.strip().lower() in ("start", "none", ""):
        return None
    parts = [p for p in re.split(r"[,\s]+", text.strip()) if p]
    if len(parts) != 6:
        raise ValueError(f"{text!r}: give six numbers x,y,z,psi,theta,phi (mm, deg), or 'start'")
    values = [float(p) for p in parts]
    if not all(math.isfinite(v) for v in values):
        raise ValueError(f"{text!r}: the numbers must be finite")
    return values


def parse_options(assignments: list[str]) -> dict[str, dict[str, object]]:
    """``NAME=VALUE`` (GUI names, or ``component.key`` for any live parameter) ->
    {component: {live key: value}}, values typed as the components expect."""
    out: dict[str, dict[str, object]] = {}
    for a in assignments:
        name, eq, value = a.partition("=")
        if not eq or not name:
            raise ConsoleError(f"{a!r} is not NAME=VALUE")
        key = name.strip().lower().replace("_", "-")
        key = ALIASES.get(key, key)
        if key in OPTIONS:
            comp, param, _ = OPTIONS[key]
            try:
                if key == "stop-on-current-location":
                    typed: object = "hold" if _bool(value) else "return"
                elif key == "invert":
                    typed = _bool(value)
                elif key in ("delay", "calib-samples"):
                    typed = int(value)
                elif key == "method":
                    typed = value
                elif key == "mask":
                    typed = parse_mask(value)
                elif key == "return-pose":
                    typed = parse_pose(value)
                else:
                    typed = float(value)
            except ValueError as e:
                raise ConsoleError(f"{name}: {e}") from None
        elif "." in name:  # component.key=JSON, any live parameter
            comp, _, param = name.partition(".")
            comp = _component(comp, a)
            if not _KEY.fullmatch(param):
                raise ConsoleError(f"{a!r}: {param!r} is not a parameter name (letters, digits, '_')")
            try:
                typed = json.loads(value)
            except json.JSONDecodeError:
                typed = value
        else:
            raise ConsoleError(
                f"unknown option {name!r}; options: {', '.join(OPTIONS)} "
                "(or COMPONENT.KEY=VALUE for any live parameter)"
            )
        out.setdefault(comp, {})[param] = typed
    return out


# A live parameter's name (a config field): what a COMPONENT.KEY assignment may name.
_KEY = re.compile(r"[A-Za-z_][A-Za-z0-9_]{0,99}")


def _component(name: str, where: str) -> str:
    """The component a console request names (its current name), or ConsoleError: the name
    goes into a Zenoh key, so only the components of this version ('/', '*', '$', '..' and
    empty names never reach the bus)."""
    from humanpt.runtime.registry import UnknownComponentError, core_class

    try:
        core_class(name)
    except UnknownComponentError as e:
        raise ConsoleError(f"{where!r}: {e}") from None
    return current_name(name)


def gui_values(params: dict[str, dict]) -> dict[str, object]:
    """{component: live params} -> the GUI options' values."""
    values = {}
    for name, (comp, key, _) in OPTIONS.items():
        if comp in params and key in params[comp]:
            v = params[comp][key]
            values[name] = (v == "hold") if name == "stop-on-current-location" else v
    return values


def _mode(m: int) -> str:
    return (
        pb.ControlMode.Name(m).removeprefix("CONTROL_MODE_")
        if m in pb.ControlMode.values()
        else str(m)
    )


def _tob_status(s: int) -> str:
    return (
        pb.TobStatus.Name(s).removeprefix("TOB_STATUS_") if s in pb.TobStatus.values() else str(s)
    )


class StatusBoard:
    """The latest message of each status topic (filled from Zenoh callbacks)."""

    def __init__(self):
        self.lock = threading.Lock()
        self.latest: dict[str, object] = {}
        self.counts: dict[str, int] = {}
        self.changed = threading.Event()

    def update(self, short: str, payload: bytes) -> None:
        msg = topics.message_type(short)()
        try:
            msg.ParseFromString(payload)
        except Exception:  # noqa: BLE001 - a bad payload is not the console's business
            return
        with self.lock:
            self.latest[short] = msg
            self.counts[short] = self.counts.get(short, 0) + 1
        self.changed.set()

    def get(self, short: str):
        with self.lock:
            return self.latest.get(short)

    def line(self) -> str:
        """One line: mode, visible sources, error, cycle misses, recording."""
        st, rs, tob = (
            self.get("controller/status"),
            self.get("robot_gateway/robot_state"),
            self.get("perception/tob"),
        )
        parts = []
        if st is not None:
            parts.append(f"mode {_mode(st.mode)}")
        if tob is not None:
            parts.append(f"visible {tob.visible} ({_tob_status(tob.status)}, q {tob.quality:.2f})")
        elif st is not None:
            parts.append(f"visible {st.visible}")
        if st is not None:
            parts.append(
                f"error {st.error_translation_m * 1e3:.2f} mm {st.error_rotation_rad * 57.29577951308232:.2f} deg"
                f"{' (saturated)' if st.saturated else ''}"
            )
        if rs is not None:
            parts.append(f"misses {rs.missed_cycles} (cycle {rs.cycle})")
        if st is not None:
            parts.append(f"recording {'yes' if st.recording else 'no'}, {st.path_points} points")
            if st.mode == pb.CONTROL_MODE_CALIBRATE or st.calibration_samples:
                parts.append(f"calibration {st.calibration_samples} samples")
        return "  ".join(parts) if parts else "(no status yet)"

    def block(self, alive: list[str]) -> str:
        """Several lines: everything the console knows."""
        st, rs = self.get("controller/status"), self.get("robot_gateway/robot_state")
        tob, state = self.get("perception/tob"), self.get("pose_filter/tob_state")
        lines = [f"components up: {', '.join(alive) or 'none'}"]
        if st is not None:
            lines.append(
                f"controller  mode {_mode(st.mode)}, visible sources {st.visible}, error |G-D| "
                f"{st.error_translation_m * 1e3:.3f} mm, {st.error_rotation_rad * 57.29577951308232:.3f} deg"
                f"{', saturated' if st.saturated else ''}"
            )
            lines.append(
                f"            recording {'yes' if st.recording else 'no'}, path points {st.path_points}, "
                f"calibration samples {st.calibration_samples}, cycle {st.cycle}"
            )
        else:
            lines.append("controller  no status")
        if rs is not None:
            alter = "on" if rs.status.alter_active else "off"
            lines.append(
                f"robot       cycle {rs.cycle}, missed cycles {rs.missed_cycles}, ALTER {alter}"
                f"{', FAULT' if rs.status.fault else ''}"
            )
        if tob is not None:
            lines.append(
                f"perception  {_tob_status(tob.status)}, visible sources {tob.visible}, "
                f"quality {tob.quality:.2f}, blobs {len(tob.centers_px)}"
            )
        if state is not None:
            lines.append(
                f"pose filter {_tob_status(state.status)}, measurements {state.measurements}, "
                f"gated outliers {state.gated_outliers}"
            )
        return "\n".join(lines)


class Console:
    """One Zenoh session (a client of the router) and the console's requests."""

    def __init__(self, cfg, timeout_s: float = 5.0, out=None):
        self.cfg = cfg
        self.cell = cfg.runtime.cell
        self.timeout_s = timeout_s
        self.out = sys.stdout if out is None else out  # (the stdout of the call, not of the import)
        self._seq = 0
        try:  # always a client of the router, never a peer of the running loop
            self.session = open_tool_session(cfg.runtime)
        except ConnectionError as e:
            raise ConsoleError(str(e)) from e
        self._pub = declare_topic_publisher(self.session, self.cell, "console/command")

    def close(self) -> None:
        try:
            self._pub.undeclare()
        finally:
            self.session.close()

    def say(self, text: str) -> None:
        print(text, file=self.out, flush=True)

    # -- components ----------------------------------------------------------------------------
    def alive(self) -> list[str]:
        replies = self.session.liveliness().get(liveliness_key(self.cell, "*"), timeout=2.0)
        return sorted(str(r.ok.key_expr).rsplit("/", 1)[-1] for r in replies if r.ok is not None)

    def params(self, component: str, sets: dict | None = None, timeout_s: float | None = None) -> dict:
        """Ask (and with ``sets``, set) a component's live parameters; its reply."""
        replies = list(
            self.session.get(
                params_key(self.cell, component),
                payload=json.dumps({"set": sets or {}}),
                timeout=(self.timeout_s if timeout_s is None else timeout_s) + 5.0 * len(sets or {}),
            )
        )
        bodies = [json.loads(r.ok.payload.to_bytes()) for r in replies if r.ok is not None]
        if not bodies:
            raise ConsoleError(f"{component} did not answer in cell {self.cell} (is it running?)")
        return bodies[0]

    # -- verbs ------------------------------------------------------------------------------------
    def set(self, assignments: list[str]) -> int:
        if not assignments:
            raise ConsoleError("set what? e.g. set threshold=70 invert=true delay=10 dz=600")
        ok = True
        for comp, sets in parse_options(assignments).items():
            try:
                body = self.params(comp, sets)
            except ConsoleError as e:
                self.say(f"REJECTED: {e}")
                ok = False
                continue
            for r in body.get("results", []):
                self.say(f"{'set' if r['ok'] else 'REJECTED'}: {r['text'] or r['key']}")
                ok &= bool(r["ok"])
        return 0 if ok else 1

    def show(self) -> int:
        params, missing = {}, []
        for comp in sorted({c for c, _, _ in OPTIONS.values()}):
            try:
                params[comp] = self.params(comp)["params"]
            except ConsoleError:
                missing.append(comp)
        for name, value in gui_values(params).items():
            self.say(f"{name:26s} {json.dumps(value):10s} {OPTIONS[name][2]}")
        for comp in missing:
            self.say(f"({comp} did not answer: its options are not shown)")
        return 0 if not missing else 1

    def tell(self, verb: str, component: str) -> int:
        """Publish a Command to a tool that answers on no topic (``humanpt calibrate camera
        --live`` listens for ``capture``): it must be listening, else ConsoleError."""
        deadline = time.monotonic() + self.timeout_s
        while not self._pub.matching_status.matching:
            if time.monotonic() > deadline:
                raise ConsoleError(f"nobody listens to console/command in cell {self.cell} "
                                   f"(is `humanpt calibrate camera --live` running?)")
            time.sleep(0.05)
        self._seq += 1
        self._pub.put(pb.Command(header=pb.Header(stamp_ns=time.time_ns(), seq=self._seq), component=component,
                                 verb=verb, args_json="{}").SerializeToString())
        self.say(f"sent {verb!r} to {component}")
        return 0

    def command(self, verb: str, args: dict | None = None, component: str = "controller") -> int:
        """Publish a Command and wait for the component's answering event (or the router's
        access_denied of the command, under mTLS)."""
        events: queue.Queue = queue.Queue()
        sub = self.session.declare_subscriber(
            topics.TOPICS[f"{component}/events"].key(self.cell),
            lambda s: events.put(s.payload.to_bytes()),
        )
        router_sub = self.session.declare_subscriber(
            topics.TOPICS["router/events"].key(self.cell), lambda s: events.put(s.payload.to_bytes()))
        own_key = topics.TOPICS["console/command"].key(self.cell)
        try:
            deadline = time.monotonic() + self.timeout_s
            while not self._pub.matching_status.matching:  # nobody would hear a command now
                if time.monotonic() > deadline:
                    raise ConsoleError(
                        f"nobody listens to console/command in cell {self.cell} "
                        f"(is the {component} running?)"
                    )
                time.sleep(0.05)
            self._seq += 1
            now = time.time_ns()
            cmd = pb.Command(
                header=pb.Header(stamp_ns=now, seq=self._seq),
                component=component,
                verb=verb,
                args_json=json.dumps(args or {}),
            )
            self._pub.put(cmd.SerializeToString())
            wanted = REPLIES.get(verb, ())
            while True:
                left = deadline - time.monotonic()
                if left <= 0:
                    rt = self.cfg.runtime
                    why = (f"; under mTLS only an operator's certificate may command, this console presents "
                           f"{rt.identity or 'tool'!r} (--as NAME)" if rt.security == "mtls" else "")
                    raise ConsoleError(
                        f"the {component} did not answer {verb!r} within {self.timeout_s:g} s "
                        f"(is it running?{why})"
                    )
                try:
                    ev = pb.Event.FromString(events.get(timeout=left))
                except queue.Empty:
                    continue
                if ev.source == "router":
                    if ev.code == "access_denied" and f" on {own_key} from " in ev.text:
                        self.say(f"REFUSED by the router: {ev.text}")
                        return 1
                    continue
                if ev.code in REFUSALS:
                    self.say(f"REJECTED by the {component}: {ev.text}")
                    return 1
                if ev.code in wanted or not wanted:
                    self.say(f"{component}: {ev.code}: {ev.text}")
                    return 0
        finally:
            sub.undeclare()
            router_sub.undeclare()

    def events(self, duration_s: float | None = None, min_severity: int = pb.SEVERITY_WARNING) -> int:
        """Print every component's and the router's events at or above ``min_severity`` as
        they arrive, until Ctrl-C or ``duration_s``."""
        feed = EventFeed(self.session, self.cell, min_severity)
        end = time.monotonic() + duration_s if duration_s else None
        try:
            while end is None or time.monotonic() < end:
                for ev in feed.events(timeout_s=0.2):
                    self.say(format_event(ev))
        except KeyboardInterrupt:
            pass
        finally:
            feed.close()
        return 0

    def status(
        self, follow: bool = False, interval_s: float = 0.5, duration_s: float | None = None
    ) -> int:
        board = StatusBoard()
        subs = [
            self.session.declare_subscriber(
                topics.TOPICS[s].key(self.cell),
                (lambda short: lambda smp: board.update(short, smp.payload.to_bytes()))(s),
            )
            for s in STATUS_TOPICS
        ]
        try:
            if not follow:
                deadline = time.monotonic() + self.timeout_s
                while board.get("controller/status") is None and time.monotonic() < deadline:
                    board.changed.wait(0.1)
                    board.changed.clear()
                # The other topics come at the same rate: give them a moment to fill in.
                settle = min(deadline, time.monotonic() + 0.5)
                while len(board.latest) < len(STATUS_TOPICS) and time.monotonic() < settle:
                    time.sleep(0.05)
                self.say(board.block(self.alive()))
                if not board.latest:
                    self.say(
                        f"no status within {self.timeout_s:g} s (is the system running in cell {self.cell}?)"
                    )
                    return 1
                return 0
            end = time.monotonic() + duration_s if duration_s else None
            feed = EventFeed(self.session, self.cell)  # warnings and errors, the router's too
            subs.append(feed)
            try:
                while end is None or time.monotonic() < end:
                    time.sleep(interval_s)
                    for ev in feed.events():
                        self.say(format_event(ev))
                    self.say(board.line())
            except KeyboardInterrupt:
                pass
            return 0
        finally:
            for s in subs:
                s.undeclare()


# A seam is re-timed here (every 28 ms) before it is thinned to the controller's points:
# one that would give more samples than this is refused before re-timing (at 20 mm/s,
# 200 000 samples are 112 m of seam, 93 minutes).
MAX_SEAM_SAMPLES = 200_000


def seam_playback(seam_file: str, speed_mm_s: float | None, flange_T_tool_x=None) -> dict:
    """The playback arguments of a seam file: re-timed at ``speed_mm_s`` (default 20) for
    the tool ``flange_T_tool_x`` (default the controller's default tool) and thinned to
    the controller's MAX_PLAYBACK_POINTS (humanpt.controller.playback.seam_command);
    ConsoleError naming the file for a seam too long or too detailed for one playback,
    refused before the work that would grow with it."""
    from humanpt.controller.config import ControllerConfig
    from humanpt.controller.playback import MAX_PLAYBACK_POINTS, seam_command
    from humanpt.seam import seamfile
    from humanpt.seam.retime import RetimeConfig

    seam = seamfile.read(seam_file)
    cfg = RetimeConfig(speed_mm_s=speed_mm_s or 20.0)
    if len(seam.segments) > MAX_PLAYBACK_POINTS:
        raise ConsoleError(f"{seam_file}: {len(seam.segments)} segments; a playback holds at most "
                           f"{MAX_PLAYBACK_POINTS} points: play the seam in parts")
    # At least the length at the feed, plus the dwells: samples every cycle.
    length_mm = math.fsum(s.length_mm for s in seam.segments)
    dwell_s = math.fsum(d.duration_s for d in seam.dwells) if cfg.dwells else 0.0
    least_s = length_mm / min(cfg.speed_mm_s, cfg.max_speed_mm_s) + dwell_s
    if not math.isfinite(least_s) or least_s / (cfg.cycle_ms * 1e-3) > MAX_SEAM_SAMPLES:
        raise ConsoleError(f"{seam_file}: {length_mm:.6g} mm at {cfg.speed_mm_s:g} mm/s is at least {least_s:.6g} s, "
                           f"more than {MAX_SEAM_SAMPLES} samples of {cfg.cycle_ms:g} ms: too long for one "
                           "playback; play the seam in parts")
    try:
        return seam_command(seam, cfg.speed_mm_s, ControllerConfig().flange_T_tool_x if flange_T_tool_x is None
                            else flange_T_tool_x)
    except (OverflowError, FloatingPointError) as e:
        raise ConsoleError(f"{seam_file}: cannot be re-timed ({e})") from None
    except ValueError as e:  # RetimeError, PlaybackError: what does not fit, and why
        raise ConsoleError(f"{seam_file}: {e}") from None


def path_playback(path_file: str, point: str) -> dict:
    """The playback arguments of a recorded path file (CSV): its points, at most the
    controller's MAX_PLAYBACK_POINTS (counted before the file is parsed)."""
    from humanpt.controller import pathfile
    from humanpt.controller.playback import MAX_PLAYBACK_POINTS

    rows = 0
    with open(path_file, "rb") as f:
        while chunk := f.read(1 << 20):
            rows += chunk.count(b"\n")
            if rows > MAX_PLAYBACK_POINTS + 1:
                raise ConsoleError(f"{path_file}: more than {MAX_PLAYBACK_POINTS} points; a playback holds at most "
                                   f"{MAX_PLAYBACK_POINTS}: fit a seam (humanpt path fit) and play that")
    return {"points": pathfile.read(path_file).points(point).tolist()}


def playback_args(file: str | None = None, speed_mm_s: float | None = None, point: str = "auto",
                  flange_T_tool_x=None) -> dict:
    """The ``playback`` command's arguments: a seam file (.json) re-timed at ``speed_mm_s``
    for the tool ``flange_T_tool_x`` (default the controller's default tool) and thinned, a path file's ``point`` (auto, G, tip), or none (the controller's recorded
    path, at ``speed_mm_s``); checked as the controller checks them (a ConsoleError naming
    the first bad point) before anything is sent."""
    from humanpt.controller.playback import check_points, check_times
    from humanpt.runtime.config import ConfigError

    if file and file.endswith(".json"):
        args = seam_playback(file, speed_mm_s, flange_T_tool_x)
    elif file:
        args = path_playback(file, point)
    else:
        args = {}
    if speed_mm_s is not None and "times_s" not in args:
        args["speed_mm_s"] = speed_mm_s
    if "points" in args:
        try:
            pts = check_points(args["points"], "points", booleans=False)
            if "times_s" in args:
                check_times(args["times_s"], len(pts), "times_s")
        except ConfigError as e:
            raise ConsoleError(f"{file}: {e}") from None
    return args


def check_envelope(con: Console, args: dict, source: str) -> None:
    """ConsoleError naming the first point of a playback that would put the flange outside
    the workspace envelope: the robot gateway's as it runs now (its live parameters; the
    authority), else the controller's, else this config file's (ControllerConfig takes
    [robot_gateway]'s); the tool offset is this config file's controller's."""
    from humanpt.controller.config import ControllerConfig
    from humanpt.controller.playback import envelope_refusal
    from humanpt.geometry.transforms import transform_from_x

    if not args.get("points"):
        return
    ctl = con.cfg.component("controller", ControllerConfig)
    box, owner = (ctl.envelope_min_mm, ctl.envelope_max_mm), "the controller config's envelope"
    for comp, whose in (("robot_gateway", "the robot gateway's envelope"), ("controller", "the controller's envelope")):
        try:
            live = con.params(comp, timeout_s=min(con.timeout_s, 2.0)).get("params") or {}
        except ConsoleError:
            continue
        if "envelope_min_mm" in live and "envelope_max_mm" in live:
            box, owner = (live["envelope_min_mm"], live["envelope_max_mm"]), whose
            break
    why = envelope_refusal(np.asarray(args["points"], dtype=float), transform_from_x(np.asarray(ctl.flange_T_tool_x)),
                           *box, owner=owner)
    if why is not None:
        raise ConsoleError(f"{source}: refused, nothing sent: {why}")

"""The simulated UR's Dashboard server (pure): UR's remote control of the program, TCP port
29999 on a real controller.

As UR documents it ("Dashboard Server, port 29999"): on connection the server greets with
``Connected: Universal Robots Dashboard Server``; then every command is one text line (ended
by ``\\n``) and gets one reply line. Commands here (the replies as UR's table and
Universal Robots' own client library, ``ur_client_library``'s dashboard, expect them):

========================== =============================================================
``load <program.urp>``     ``Loading program: <program.urp>`` (humanpt's program, stopped
                           first); any other: ``File not found: <program.urp>``
``play``                   ``Starting program``: a stopped program starts from its start
                           (no jump to an old target), a paused one goes on;
                           ``Failed to execute: play`` in a protective stop or braking
``stop``                   ``Stopped``: the program stops, the arm decelerates
                           (:meth:`UrRobot.stop_program`); answered at once, as UR's
                           servers before 3.3 did
``pause``                  ``Pausing program``; ``Failed to execute: pause`` if not playing
``running``                ``Program running: true`` / ``false`` (``True``/``False`` on a CB3)
``programState``           ``PLAYING <program>``, ``PAUSED <program>``, ``STOPPED <program>``
``robotmode``              ``Robotmode: RUNNING``
``safetymode``             ``Safetymode: NORMAL`` (or ``PROTECTIVE_STOP``)
``safetystatus``           ``Safetystatus: NORMAL`` (or ``PROTECTIVE_STOP``)
``get loaded program``     ``Loaded program: <program>``
``isProgramSaved``         ``true <program>`` (``True <program>`` on a CB3)
``PolyscopeVersion``       ``URSoftware <controller version> (humanpt's simulated UR)``
``unlock protective stop`` ``Protective stop releasing``; within 5 s of the stop:
                           ``Cannot unlock protective stop until 5s after occurrence. ...``
``close safety popup``     ``closing safety popup``; ``close popup``: ``closing popup``;
                           ``popup <text>``: ``showing popup``; ``addToLog <text>``:
                           ``Added log message``
``quit``                   ``Disconnected``, and the server closes the connection
anything else              ``could not understand: '<line>'`` (what UR's servers answer:
                           from memory, UR's table does not list it)
========================== =============================================================

Not simulated: power on/off, brake release, user roles, operational modes, the
installation (they answer as unknown commands). A line longer than
:data:`MAX_LINE` bytes is not a command: the server drops the client.
"""

from __future__ import annotations

from humanpt.robot_gateway.links.ur import protocol as rtde
from humanpt.sim_robot.rsi import SimEvent

GREETING = "Connected: Universal Robots Dashboard Server"
MAX_LINE = 4096  # bytes without a newline: not a Dashboard client
SAFETY_NAMES = {rtde.SAFETY_MODE_NORMAL: "NORMAL", rtde.SAFETY_MODE_REDUCED: "REDUCED",
                rtde.SAFETY_MODE_PROTECTIVE_STOP: "PROTECTIVE_STOP"}
UNLOCK_TOO_EARLY = ("Cannot unlock protective stop until 5s after occurrence. Always inspect cause of protective "
                    "stop before unlocking")


class DashboardSession:
    """One Dashboard client (pure): :meth:`greeting` on connection, then ``feed(bytes)`` ->
    the reply bytes (one line per command line); ``closed`` says why the server ends the
    connection (``quit``, a line too long), else None. ``robot``: the
    :class:`~humanpt.sim_robot.ur.UrRobot` it controls; ``client`` names it in events."""

    def __init__(self, robot, client: str):
        self.robot = robot
        self.client = client
        self._buf = b""  # (bytes: a snapshot's plain data)
        self.closed: str | None = None

    @staticmethod
    def greeting() -> bytes:
        return (GREETING + "\n").encode()

    def feed(self, data: bytes, t_ns: int) -> bytes:
        if self.closed is not None:
            return b""
        self._buf += data
        out = bytearray()
        while self.closed is None:
            end = self._buf.find(b"\n")
            if end < 0:
                if len(self._buf) > MAX_LINE:
                    self.closed = f"a line of more than {MAX_LINE} bytes: not a Dashboard client"
                    self.robot.counters["malformed"] += 1
                    self.robot.events.append(SimEvent(t_ns, "warning", "bad_dashboard", f"client {self.client}: "
                                                      f"{self.closed}; dropped"))
                break
            line = self._buf[:end].decode("utf-8", errors="replace").strip()
            self._buf = self._buf[end + 1:]
            if line:
                out += (reply(self.robot, line, t_ns, self.client) + "\n").encode()
                if line.lower() == "quit":
                    self.closed = "quit"
        return bytes(out)


def reply(robot, line: str, t_ns: int, client: str = "") -> str:
    """The Dashboard server's answer to one command ``line`` (stripped), acting on ``robot``."""
    cmd = line.lower()
    cb3 = robot.controller_version[0] < 5
    why = f"Dashboard ({client})" if client else "Dashboard"
    name = robot.program_name
    if cmd == "play":
        return "Starting program" if robot.play_program(t_ns, f"{why}: play") else "Failed to execute: play"
    if cmd == "stop":
        robot.stop_program(t_ns, f"{why}: stop")
        return "Stopped"
    if cmd == "pause":
        return "Pausing program" if robot.pause_program(t_ns, f"{why}: pause") else "Failed to execute: pause"
    if cmd == "running":
        yes = robot.program_running
        return f"Program running: {('True' if yes else 'False') if cb3 else str(yes).lower()}"
    if cmd == "programstate":
        state = {rtde.RUNTIME_PLAYING: "PLAYING", rtde.RUNTIME_PAUSED: "PAUSED",
                 rtde.RUNTIME_PAUSING: "PAUSED"}.get(robot.runtime_state, "STOPPED")
        return f"{state} {name}"
    if cmd == "robotmode":
        return "Robotmode: RUNNING"
    if cmd in ("safetymode", "safetystatus"):
        return f"{'Safetymode' if cmd == 'safetymode' else 'Safetystatus'}: {SAFETY_NAMES[robot.safety_mode]}"
    if cmd == "get loaded program":
        return f"Loaded program: {name}"
    if cmd == "isprogramsaved":
        return f"{'True' if cb3 else 'true'} {name}"
    if cmd == "polyscopeversion":
        return "URSoftware {}.{}.{}.{} (humanpt's simulated UR)".format(*robot.controller_version)
    if cmd == "unlock protective stop":
        return "Protective stop releasing" if robot.unlock_protective_stop(t_ns) else UNLOCK_TOO_EARLY
    if cmd == "close safety popup":
        return "closing safety popup"
    if cmd == "close popup":
        return "closing popup"
    if cmd.startswith("popup "):
        return "showing popup"
    if cmd.startswith("addtolog "):
        return "Added log message"
    if cmd == "quit":
        return "Disconnected"
    if cmd.startswith("load "):
        program = line[5:].strip()
        if program.rsplit("/", 1)[-1] != robot.program_name.rsplit("/", 1)[-1]:
            return f"File not found: {program}"
        robot.stop_program(t_ns, f"{why}: load")
        return f"Loading program: {program}"
    return f"could not understand: '{line}'"

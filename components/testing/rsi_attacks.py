"""Attacks on the RSI link (issue 29), for tests and ``humanpt bench``: test machinery, never
imported by product code.

- :data:`CRAFTED`: datagrams that are not RSI messages although they look like one (item 8):
  each must be refused by ``humanpt.robot_gateway.links.rsi.protocol.decode_rob`` with one line, before the XML
  parser expands anything.
- :func:`flood` / :func:`start_flood`: junk datagrams at a given rate from a port of their
  own (item 6), in this thread or as a process of its own
  (``python -m humanpt.testing.rsi_attacks flood HOST:PORT --seconds S --rate HZ``).
- :class:`NextIpocSpoofer`: an attacker on another local port that sends the gateway a
  ``<Rob>`` with the robot's next IPOC after each of the robot's (item 5); hook it into
  ``humanpt.sim_robot.rsi.RsiRobotServer(after_send=spoofer)``; it counts the answers it got.
- :func:`rob` / :func:`ipoc_of_cycle`: a ``<Rob>`` datagram for a spoof, replay or jump
  (item 7: ``after_send`` returning ``[rob(ipoc + 500 * cycle_ms)]`` sends it from the
  robot's own address).
"""

from __future__ import annotations

import argparse
import socket
import subprocess
import sys
import threading
import time

from humanpt.robot_gateway.links.rsi.protocol import RobState, encode_rob

# What the simulated robot reports at rest (its default start: flange straight down).
REST_RIST = (786.0, 190.0, -296.0, 0.0, 0.0, 180.0)
REST_AIPOS = (0.0, -35.0, 190.0, 0.0, 25.0, -180.0)
JUNK = b"<Rob TYPE=\"KUKA\"><RIst X=\"junk" + b"x" * 200  # malformed, about the size of a real one


def rob(ipoc: int, rist=REST_RIST, aipos=REST_AIPOS, delay: int = 0) -> bytes:
    """A well-formed ``<Rob>`` datagram with ``ipoc``."""
    return encode_rob(RobState(ipoc, tuple(rist), tuple(aipos), delay))


def ipoc_of_cycle(cycle: int, cycle_ms: int, first_ipoc: int = 1_000_000) -> int:
    """The IPOC of the gateway's cycle number ``cycle`` (IPOC // cycle_ms) for a robot whose
    first IPOC was ``first_ipoc`` (the simulated robot's FIRST_IPOC): what an attacker that
    reads ``robot_gateway/robot_state`` can work out."""
    return cycle * cycle_ms + first_ipoc % cycle_ms


def _rob_text(ipoc_text: str) -> bytes:
    """A <Rob> whose IPOC element holds ``ipoc_text`` (str: encoded by the caller)."""
    return rob(1).decode().replace("<IPOC>1</IPOC>", f"<IPOC>{ipoc_text}</IPOC>").encode("utf-8")


def _entity_rob(encoding: str) -> bytes:
    """A <Rob> declaring an entity that spells its IPOC, encoded in ``encoding``."""
    text = rob(1).decode().replace("<IPOC>1</IPOC>", "<IPOC>&i;</IPOC>")
    head = f'<?xml version="1.0" encoding="{encoding.upper()}"?>' if encoding != "ascii" else ""
    return (head + '<!DOCTYPE Rob [<!ENTITY i "7">]>' + text).encode(encoding)


def _laughs(encoding: str, levels: int = 9) -> bytes:
    """The billion laughs (entities of entities, 10 x each level) inside a <Rob>."""
    ents = '<!ENTITY l0 "lol">' + "".join(f'<!ENTITY l{i} "{f"&l{i - 1};" * 10}">' for i in range(1, levels))
    text = rob(1).decode().replace("<IPOC>1</IPOC>", f"<IPOC>1</IPOC><X>&l{levels - 1};</X>")
    head = f'<?xml version="1.0" encoding="{encoding.upper()}"?>' if encoding != "ascii" else ""
    return (head + f"<!DOCTYPE Rob [{ents}]>" + text).encode(encoding)


# name -> datagram; every one must be refused with one line (RsiProtocolError).
CRAFTED: dict[str, bytes] = {
    "superscript_ipoc": _rob_text("\u00b2"),  # passes str.isdigit(), int() raises
    "arabic_indic_ipoc": _rob_text("\u0663"),  # int() takes it: a digit, not ASCII
    "char_reference_ipoc": _rob_text("&#178;"),
    "entity_rob_ascii": _entity_rob("ascii"),
    "entity_rob_utf16": _entity_rob("utf-16"),  # the byte check for DOCTYPE missed it
    "entity_rob_utf16le": _entity_rob("utf-16-le"),
    "billion_laughs_utf16": _laughs("utf-16"),  # ~150 ms of expat per datagram before
    "encoding_declared_utf16_ascii_bytes": b'<?xml version="1.0" encoding="UTF-16"?>' + rob(1),
    "nul_byte": rob(1) + b"\x00",
    "latin1_byte": rob(1).replace(b'TYPE="KUKA"', b'TYPE="K\xc4KA"'),
    "processing_instruction": rob(1).replace(b"<IPOC>", b"<?evil x?><IPOC>"),
    "comment": rob(1).replace(b"<IPOC>", b"<!-- x --><IPOC>"),
    "underscore_number": rob(1).replace(b'X="786.0000"', b'X="7_86"'),
    "ipoc_too_long": _rob_text("1" * 40),
    "delay_not_a_count": rob(1).replace(b'<Delay D="0"/>', b'<Delay D="1e3"/>'),
    "too_long": rob(1)[:-6] + b" " * 5000 + b"</Rob>",
}


def flood(target: tuple[str, int], seconds: float, rate_hz: float, payload: bytes = JUNK,
          stop: threading.Event | None = None) -> int:
    """Send ``payload`` to ``target`` at about ``rate_hz`` for ``seconds`` from a socket of
    its own (another port than the robot's); the number sent. Paced per millisecond (a
    burst of rate/1000 datagrams, then the rest of the millisecond)."""
    sent = 0
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        t0 = time.monotonic()
        end = t0 + seconds
        while (now := time.monotonic()) < end and not (stop is not None and stop.is_set()):
            due = int((now - t0) * rate_hz) + 1
            while sent < due:
                try:
                    s.sendto(payload, target)
                except OSError:
                    pass  # (a full buffer on a loaded machine: the flood goes on)
                sent += 1
            time.sleep(0.001)  # pacing the flood itself (no event to wait for)
    return sent


def start_flood(target: tuple[str, int], seconds: float, rate_hz: float) -> subprocess.Popen:
    """:func:`flood` as a process of its own (its own interpreter, as an attacker is); its
    last line of output is the number of datagrams sent."""
    return subprocess.Popen([sys.executable, "-m", "humanpt.testing.rsi_attacks", "flood",
                             f"{target[0]}:{target[1]}", "--seconds", str(seconds), "--rate", str(rate_hz)],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)


class NextIpocSpoofer:
    """After each of the robot's <Rob> (``RsiRobotServer(after_send=...)``), once
    :meth:`arm` was called (the loop runs), send the gateway a ``<Rob>`` with the robot's
    *next* IPOC from another local port, ``count`` times: the gateway must neither answer
    it nor let it displace the robot's own datagram. ``answers``: datagrams the gateway sent
    to the attacker; ``sent``: spoofs sent; ``done`` is set after the last."""

    def __init__(self, gateway: tuple[str, int], cycle_ms: int, *, count: int = 80):
        self.gateway = gateway
        self.cycle_ms = cycle_ms
        self.count = count
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.setblocking(False)
        self.sent = 0
        self.answers = 0
        self.armed = threading.Event()
        self.done = threading.Event()

    def arm(self) -> None:
        self.armed.set()

    def __call__(self, n: int, data: bytes) -> list[bytes]:
        self._drain()
        if self.armed.is_set() and self.sent < self.count:
            ipoc = int(data.split(b"<IPOC>")[1].split(b"</IPOC>")[0])
            self.sock.sendto(rob(ipoc + self.cycle_ms), self.gateway)
            self.sent += 1
        elif self.sent >= self.count:
            self.done.set()
        return []

    def _drain(self) -> None:
        while True:
            try:
                self.sock.recvfrom(65536)
            except (BlockingIOError, InterruptedError):
                return
            except OSError:
                return  # (closed)
            self.answers += 1

    def close(self) -> None:
        self._drain()
        self.sock.close()


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m humanpt.testing.rsi_attacks")
    sub = p.add_subparsers(dest="attack", required=True)
    f = sub.add_parser("flood", help="junk datagrams at a rate from a port of their own")
    f.add_argument("target", help="host:port (the gateway's udp_bind)")
    f.add_argument("--seconds", type=float, default=3.0)
    f.add_argument("--rate", type=float, default=20000.0, help="datagrams per second")
    args = p.parse_args(argv)
    host, _, port = args.target.rpartition(":")
    print(flood((host, int(port)), args.seconds, args.rate), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())

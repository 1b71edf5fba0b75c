"""What a KUKA controller needs for humanpt's RSI link, written from the cell's config.

``humanpt robot-files`` (:func:`write`) writes, for the ``[robot_gateway]`` of a
config (link ``rsi``):

* ``humanpt_rsi_ethernet.xml`` — the RSI Ethernet object's configuration file: the sensor's
  address (the gateway's ``udp_bind``, or the address given), ``SENTYPE`` = ``sen_type``, the
  ``<SEND>`` elements the gateway reads (``DEF_RIst``, ``DEF_AIPos``, ``DEF_Delay``; the IPOC
  is always sent) and the ``<RECEIVE>`` elements it writes (``RKorr.X`` ... ``RKorr.C``), each
  with ``HOLDON="0"``: a late answer is a zero correction, never a repeat of the last one
  (the safe setting of issue 29; see README "What the robot must be configured with").
* ``humanpt_rsi.src`` — a KRL program for KR C4 / KR C5 (RSI 3.x / 4.x): it creates the RSI
  context, switches the correction on as *relative* (``RSI_ON(#RELATIVE)``: each ``RKorr`` is
  one cycle's step added to the last, the way the gateway sends them), runs
  ``RSI_MOVECORR()`` until RSI stops (the operator, a limit, the late limit), and switches it off.
* ``humanpt_rsi_context.md`` — the RSI context (signal diagram) to draw in RSI Visual, with
  every parameter value taken from the config: the Ethernet object (its config file and its
  ``Timeout``, the late limit), the position correction (``POSCORR``) in the frame of
  ``correction_frame``, its limits from the envelope and the per-cycle step, and the
  correction monitor. The diagram file itself (``.rsi`` / ``.rsix``) is not written: its
  object and parameter numbering is KUKA's and no public description of it could be checked
  here; RSI Visual writes it from these values.

The files are text; every value in them comes from a validated ``RsiConfig`` (nothing else
reaches a robot program), and the sensor address is checked as an IPv4 address and port.
"""

from __future__ import annotations

import ipaddress
import math
from dataclasses import dataclass
from pathlib import Path

from humanpt.robot_gateway.links.rsi.config import RsiConfig, parse_address

ETHERNET_FILE = "humanpt_rsi_ethernet.xml"
PROGRAM_FILE = "humanpt_rsi.src"
CONTEXT_FILE = "humanpt_rsi_context.md"
CONTEXT_NAME = "humanpt_rsi.rsix"  # what the program opens (RSI 4.x; RSI 3.x: humanpt_rsi.rsi)
# The shipped copies (the robot/ folder beside this module) are these files for this config:
# the gateway PC at 192.168.1.20 on the RSI network, every other value the default.
REFERENCE_BIND = "192.168.1.20:49152"


def reference_config() -> RsiConfig:
    """The config the shipped copies in ``robot/`` are written for."""
    return RsiConfig(udp_bind=REFERENCE_BIND)

# What the gateway reads from each <Rob> (protocol.decode_rob) and writes in each <Sen>
# (protocol.encode_sen): the Ethernet object's elements must declare exactly these.
SEND_ELEMENTS = (("DEF_RIst", "DOUBLE"), ("DEF_AIPos", "DOUBLE"), ("DEF_Delay", "LONG"))
RECEIVE_ELEMENTS = tuple(f"RKorr.{a}" for a in "XYZABC")


class RobotFilesError(ValueError):
    """The config or the address cannot make the robot's files (one line: what and why)."""


@dataclass(frozen=True)
class RobotFiles:
    ethernet_xml: str
    program_src: str
    context_md: str

    def items(self) -> tuple[tuple[str, str], ...]:
        return ((ETHERNET_FILE, self.ethernet_xml), (PROGRAM_FILE, self.program_src), (CONTEXT_FILE, self.context_md))


def sensor_address(config, sensor_ip: str | None = None) -> tuple[str, int]:
    """(IPv4, port) the robot sends to: ``sensor_ip`` (the gateway PC's address on the robot's
    network) or ``udp_bind``'s host (any UDP link's config), with ``udp_bind``'s port. A wildcard or loopback host
    needs ``sensor_ip``: the robot cannot send to 0.0.0.0 or to its own loopback."""
    host, port = parse_address(config.udp_bind)
    ip_text = sensor_ip if sensor_ip is not None else host
    try:
        ip = ipaddress.IPv4Address(ip_text)
    except ipaddress.AddressValueError:
        raise RobotFilesError(f"sensor address {ip_text!r} is not an IPv4 address (the gateway PC's address on "
                              "the RSI network, e.g. 192.168.1.20)") from None
    if ip.is_unspecified or ip.is_loopback or ip.is_multicast:
        raise RobotFilesError(f"sensor address {ip} cannot be the robot's destination: give the gateway PC's address "
                              "on the RSI network (--sensor-ip), or set [robot_gateway] udp_bind to it")
    if port == 0:
        raise RobotFilesError("udp_bind has port 0: the robot needs a fixed port (e.g. 49152)")
    return str(ip), port


def ethernet_xml(config: RsiConfig, sensor_ip: str | None = None) -> str:
    ip, port = sensor_address(config, sensor_ip)
    send = "\n".join(f'         <ELEMENT TAG="{tag}" TYPE="{typ}" INDX="INTERNAL" />' for tag, typ in SEND_ELEMENTS)
    receive = "\n".join(f'         <ELEMENT TAG="{tag}" TYPE="DOUBLE" INDX="{i}" HOLDON="0" />'
                        for i, tag in enumerate(RECEIVE_ELEMENTS, start=1))
    return f"""<ROOT>
   <!-- humanpt's RSI link: written by `humanpt robot-files` from [robot_gateway].
        Copy to C:\\KRC\\ROBOTER\\Config\\User\\Common\\SensorInterface (KR C4/C5). -->
   <CONFIG>
      <IP_NUMBER>{ip}</IP_NUMBER>   <!-- the gateway PC: [robot_gateway] udp_bind -->
      <PORT>{port}</PORT>
      <SENTYPE>{config.sen_type}</SENTYPE>   <!-- [robot_gateway] sen_type -->
      <ONLYSEND>FALSE</ONLYSEND>
   </CONFIG>
   <SEND>
      <ELEMENTS>
{send}
      </ELEMENTS>
   </SEND>
   <!-- HOLDON="0": a late answer is a zero correction, never a repeat of the last (relative) one. -->
   <RECEIVE>
      <ELEMENTS>
{receive}
      </ELEMENTS>
   </RECEIVE>
</ROOT>
"""


def program_src(config: RsiConfig) -> str:
    frame = "#BASE" if config.correction_frame == "base" else "#TCP"
    return f"""&ACCESS RVP
&REL 1
DEF humanpt_rsi( )
; humanpt's RSI link: written by `humanpt robot-files` from [robot_gateway].
; KR C4 / KR C5 (RSI 3.x / 4.x). Start it with the robot where the teaching or the playback
; begins (jog it there, or add your own PTP before RSI_CREATE): humanpt moves it from there.
; Corrections: relative (each RKorr is one {config.cycle_period_ms:g} ms cycle's step) in the
; {config.correction_frame} frame ({frame}; the context's POSCORR must say the same).
DECL INT ret
DECL INT contId

;FOLD INI
  ;FOLD BASISTECH INI
    GLOBAL INTERRUPT DECL 3 WHEN $STOPMESS==TRUE DO IR_STOPM ( )
    INTERRUPT ON 3
    BAS (#INITMOV,0 )
  ;ENDFOLD (BASISTECH INI)
;ENDFOLD (INI)

ret = RSI_CREATE("{CONTEXT_NAME}", contId, TRUE)
IF (ret <> RSIOK) THEN
  HALT
ENDIF

ret = RSI_ON(#RELATIVE)
IF (ret <> RSIOK) THEN
  HALT
ENDIF

; humanpt corrects the path until RSI stops: the operator, a limit of the context, or
; {max(1, config.robot_late_limit)} late answers in a row (the Ethernet object's Timeout).
RSI_MOVECORR()

ret = RSI_OFF()
IF (ret <> RSIOK) THEN
  HALT
ENDIF
END
"""


def context_md(config: RsiConfig, sensor_ip: str | None = None) -> str:
    ip, port = sensor_address(config, sensor_ip)
    late = max(1, config.robot_late_limit)
    lo, hi = config.envelope_min_mm, config.envelope_max_mm
    reach = max(abs(h - lo_) for lo_, h in zip(lo, hi, strict=True))
    step_mm, step_deg = config.max_step_mm, config.max_step_deg
    cycle = config.cycle_period_ms
    frame = "BASE" if config.correction_frame == "base" else "TCP (tool)"
    return f"""# The RSI context for humanpt (draw it in RSI Visual)

Written by `humanpt robot-files` from `[robot_gateway]` (link `rsi`, cycle
{cycle:g} ms). Save it as `{CONTEXT_NAME}` (RSI 4.x; RSI 3.x: `humanpt_rsi.rsi`) in
`C:\\KRC\\ROBOTER\\Config\\User\\Common\\SensorInterface`, beside `{ETHERNET_FILE}`.
The diagram file is not shipped: its object and parameter numbering is KUKA's and could
not be checked here; RSI Visual writes it from these values.

| object | parameter | value | why |
|---|---|---|---|
| ETHERNET | ConfigFile | `{ETHERNET_FILE}` | humanpt's elements: `DEF_RIst`, `DEF_AIPos`, `DEF_Delay` out; `RKorr.X`..`RKorr.C` in, HOLDON 0 |
| ETHERNET | Timeout | {late} | late answers in a row before RSI stops; `[robot_gateway] robot_late_limit` = {config.robot_late_limit} must be >= it |
| ETHERNET | sensor address | {ip}:{port} | `[robot_gateway] udp_bind` |
| POSCORR | inputs 1-6 | ETHERNET outputs 1-6 (`RKorr.X` .. `RKorr.C`) | the relative step of each cycle |
| POSCORR | reference frame | {frame} | `[robot_gateway] correction_frame = "{config.correction_frame}"` |
| POSCORR | LowerLimX/Y/Z, UpperLimX/Y/Z | -{reach:.1f} / +{reach:.1f} mm | the envelope's largest extent: humanpt's envelope (world box {tuple(lo)} .. {tuple(hi)} mm) is the tighter rule; this one stops a runaway |
| POSCORR | MaxRotAngle | 45 deg | the torch's turn from the start (humanpt limits each step to {step_deg:g} deg) |
| POSCORRMON | MaxTrans / MaxRot | {reach:.1f} mm / 45 deg | the whole correction: beyond it RSI stops |

Per cycle humanpt sends at most {step_mm:.3f} mm and {step_deg:.3f} deg (`max_step_mm`,
`max_step_deg` at {cycle:g} ms), and only when the answer is in time; a late answer is zero
on the robot (HOLDON 0). What RSI does when humanpt stops answering: each late cycle
counts, and after {late} in a row RSI stops with the robot holding (KUKA's message on the
pendant); restart `{PROGRAM_FILE}` to go on. humanpt's `<Delay>` handling: the `D` it reads is
the controller's count of late answers; a rise is the gateway's `robot_missed` event.
"""


def robot_files(config: RsiConfig, sensor_ip: str | None = None) -> RobotFiles:
    """The three files for ``config`` (RobotFilesError when the address cannot be the robot's
    destination)."""
    if not isinstance(config, RsiConfig):
        raise RobotFilesError(f"[robot_gateway] link is {getattr(config, 'link', '?')!r}: robot files are written "
                              "for link = \"rsi\"")
    if not (math.isfinite(config.max_step_mm) and math.isfinite(config.max_step_deg)):
        raise RobotFilesError("max_step_mm / max_step_deg are not finite")
    return RobotFiles(ethernet_xml(config, sensor_ip), program_src(config), context_md(config, sensor_ip))


def write_files(items, out_dir: str | Path, overwrite: bool = False) -> list[Path]:
    """Write ``items`` ((name, text), ...) into ``out_dir`` (made if missing); FileExistsError
    naming a file that is there unless ``overwrite``: nothing is written then."""
    d = Path(out_dir)
    items = list(items)
    paths = [d / name for name, _ in items]
    if not overwrite:
        there = [p for p in paths if p.exists()]
        if there:
            raise FileExistsError(f"{there[0]} exists (--overwrite replaces it)")
    d.mkdir(parents=True, exist_ok=True)
    from humanpt.runtime.files import write_atomic

    for p, (_, text) in zip(paths, items, strict=True):
        write_atomic(p, text)
    return paths


def write(config: RsiConfig, out_dir: str | Path, sensor_ip: str | None = None,
          overwrite: bool = False) -> list[Path]:
    """Write the files into ``out_dir`` (made if missing); FileExistsError naming a file that
    is there unless ``overwrite``. Nothing is written when any file would be refused."""
    return write_files(robot_files(config, sensor_ip).items(), out_dir, overwrite)

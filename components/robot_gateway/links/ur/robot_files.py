"""What a Universal Robots controller (e-Series or CB3, PolyScope 5 / 3) needs for humanpt's
``ur`` link, written from the cell's config (``humanpt robot-files``, :func:`write`):

* ``humanpt_ur.script`` — the URScript program: it reads, every cycle, the sequence number
  (``input_int_register_<b>``) and the target pose (``input_double_register_<b>..<b+5>``:
  x, y, z m, rx, ry, rz rotation vector rad, the flange in the base frame) that humanpt's
  gateway writes over RTDE, and servoes to the target (``servoj`` to the target's inverse
  kinematics near the present joints: what ur-rtde's ``servoL`` runs on the robot). Its
  watchdog: the sequence not advancing for ``watchdog_cycles`` cycles stops the arm
  (``stopl``); it then follows again only a NEWER sequence whose target is within
  ``max_lead_mm`` / ``max_lead_deg`` of where the arm is (never a jump to an old target).
  Heartbeat: ``output_int_register_<b>`` +1 every program cycle; ``output_int_register_<b+1>``
  the last sequence it followed.
* ``humanpt_ur_installation.txt`` — the installation settings to make on the teach pendant:
  the robot's IP, the TCP (all zero: humanpt reads ``actual_TCP_pose`` as the flange), the
  registers, and the steps to load and start the program.

Every value comes from a validated ``UrConfig``. The program is humanpt's, written from
URScript's documented functions; it has not been run on a real controller here (none is).
"""

from __future__ import annotations

import ipaddress
import math
from dataclasses import dataclass
from pathlib import Path

from humanpt.robot_gateway.links.rsi.config import parse_address
from humanpt.robot_gateway.links.rsi.robot_files import RobotFilesError, write_files
from humanpt.robot_gateway.links.ur.config import UrConfig

SCRIPT_FILE = "humanpt_ur.script"
INSTALLATION_FILE = "humanpt_ur_installation.txt"
REFERENCE_ADDRESS = "192.168.1.10:30004"  # the shipped copies: a UR on its usual subnet
LOOKAHEAD_S = 0.1  # servoj's lookahead_time (0.03..0.2) and gain (100..2000): ur-rtde's defaults
GAIN = 300
STOP_DECEL_M_S2 = 1.0  # stopl's deceleration when the watchdog stops the arm


def reference_config() -> UrConfig:
    """The config the shipped copies in ``robot/`` are written for."""
    return UrConfig(rtde_address=REFERENCE_ADDRESS)


@dataclass(frozen=True)
class RobotFiles:
    script: str
    installation: str

    def items(self) -> tuple[tuple[str, str], ...]:
        return ((SCRIPT_FILE, self.script), (INSTALLATION_FILE, self.installation))


def robot_address(config: UrConfig) -> str:
    host, _ = parse_address(config.rtde_address)
    try:
        ip = ipaddress.IPv4Address(host)
    except ipaddress.AddressValueError:
        raise RobotFilesError(f"rtde_address host {host!r} is not an IPv4 address (the robot's, e.g. "
                              "192.168.1.10)") from None
    if ip.is_unspecified or ip.is_loopback or ip.is_multicast:
        raise RobotFilesError(f"rtde_address {config.rtde_address!r} is not a robot's address: set [robot_gateway] "
                              "rtde_address to the robot's IP, e.g. \"192.168.1.10:30004\"")
    return str(ip)


def script(config: UrConfig) -> str:
    b = config.register_base
    cycle_s = config.cycle_period_ms / 1000.0
    lead_m = config.max_lead_mm / 1000.0
    lead_rad = math.radians(config.max_lead_deg)
    doubles = ", ".join(f"read_input_float_register({b + i})" for i in range(6))
    return f"""# humanpt's UR link: written by `humanpt robot-files` from [robot_gateway] (link "ur").
# The gateway (RTDE client) writes every {config.cycle_period_ms:g} ms a sequence number to input_int_register_{b}
# and the flange's target pose (base frame; m, rotation vector rad) to input_double_register_{b}..{b + 5}.
# This program servoes to it; the steps are within [robot_gateway]'s limits ({config.max_speed_mm_s:g} mm/s,
# {config.max_angular_speed_deg_s:g} deg/s, the envelope), the target at most {config.max_lead_mm:g} mm /
# {config.max_lead_deg:g} deg ahead of the arm.
# Watchdog: no new sequence for {config.watchdog_cycles} cycles -> stopl; the program then follows again only a
# newer sequence whose target is within that lead of the arm (never a jump to an old target).
# Heartbeat: output_int_register_{b} +1 every cycle; output_int_register_{b + 1}: the last sequence followed.
def humanpt_servo():
  CYCLE_S = {cycle_s:g}
  WATCHDOG_CYCLES = {config.watchdog_cycles}
  MAX_LEAD_M = {lead_m:.6g}
  MAX_LEAD_RAD = {lead_rad:.6g}
  textmsg("humanpt: servo program started")
  heartbeat = 0
  write_output_integer_register({b}, heartbeat)
  write_output_integer_register({b + 1}, 0)
  # The sequence already in the register is an old session's: never followed.
  last_seq = read_input_integer_register({b})
  stale = 0
  stopped = True
  while True:
    seq = read_input_integer_register({b})
    target = p[{doubles}]
    if seq != last_seq:
      last_seq = seq
      stale = 0
      if stopped:
        here = get_actual_tcp_pose()
        d = pose_trans(pose_inv(here), target)
        if pose_dist(here, target) <= MAX_LEAD_M and norm([d[3], d[4], d[5]]) <= MAX_LEAD_RAD:
          stopped = False
          textmsg("humanpt: following the gateway's targets")
        end
      end
    else:
      stale = stale + 1
    end
    if not stopped and stale >= WATCHDOG_CYCLES:
      stopl({STOP_DECEL_M_S2:g})
      stopped = True
      textmsg("humanpt: no new target for ", WATCHDOG_CYCLES, " cycles: stopped")
    end
    heartbeat = heartbeat + 1
    if heartbeat > 1000000000:
      heartbeat = 1
    end
    write_output_integer_register({b}, heartbeat)
    if stopped:
      sync()
    else:
      write_output_integer_register({b + 1}, seq)
      servoj(get_inverse_kin(target, qnear=get_actual_joint_positions()), 0, 0, CYCLE_S, {LOOKAHEAD_S:g}, {GAIN})
    end
  end
end
humanpt_servo()
"""


def installation(config: UrConfig) -> str:
    ip = robot_address(config)
    _, port = parse_address(config.rtde_address)
    b = config.register_base
    hz = 1000.0 / config.cycle_period_ms
    return f"""humanpt's UR link: the robot's installation, written by `humanpt robot-files` from [robot_gateway] (link "ur").

Robot
  IP address          {ip} (Settings > System > Network: static); the gateway connects to {ip}:{port} (RTDE)
  RTDE                {hz:g} Hz ({config.cycle_period_ms:g} ms; 500 Hz at most on an e-Series, 125 Hz on a CB3)
  Remote access       e-Series: Settings > Security > Services: RTDE enabled (Settings > Security > General:
                      no firewall rule closing port {port} to the gateway PC)

Installation (Installation > General)
  TCP                 a TCP "humanpt_flange" with offset X Y Z RX RY RZ = 0 0 0 0 0 0, set as the default TCP:
                      humanpt reads actual_TCP_pose as the flange and sends flange targets
  Payload             the torch's mass and centre of gravity (as for any welding program)

Registers (RTDE, general-purpose range {b}..{b + 5}; registers 0..23 are the fieldbus adapters')
  input_int_register_{b}          written by humanpt: the sequence number (+1 every cycle; the watchdog's count)
  input_double_register_{b}..{b + 5}  written by humanpt: the target x, y, z (m), rx, ry, rz (rotation vector, rad)
  output_int_register_{b}         written by the program: heartbeat (+1 every program cycle)
  output_int_register_{b + 1}         written by the program: the last sequence it followed
  No other RTDE client (a fieldbus adapter, another program) may write these inputs: the controller then
  refuses humanpt's input setup (IN_USE) and the link stays down.

Loading and starting
  1. Copy humanpt_ur.script to a USB stick; on the pendant: Program > Advanced > Script, "File", load it
     (or copy it to /programs over SFTP) into a program "humanpt" with nothing else in it.
  2. Move the arm where the teaching or the playback begins; start humanpt's gateway
     ([robot_gateway] link = "ur", rtde_address = "{ip}:{port}"), then press Play on the pendant.
  3. The program follows the gateway's targets once a newer sequence's target is within {config.max_lead_mm:g} mm /
     {config.max_lead_deg:g} deg of the arm. Watchdog: {config.watchdog_cycles} cycles ({config.watchdog_cycles
     * config.cycle_period_ms:g} ms) without a new sequence -> stopl({STOP_DECEL_M_S2:g}); it resumes on its own only
     as in 3. Stop with the pendant's Stop button.
"""


def robot_files(config: UrConfig, sensor_ip: str | None = None) -> RobotFiles:
    """(``sensor_ip`` is not used: over RTDE the gateway connects to the robot.)"""
    if not isinstance(config, UrConfig):
        raise RobotFilesError(f"[robot_gateway] link is {getattr(config, 'link', '?')!r}, not \"ur\"")
    return RobotFiles(script(config), installation(config))


def write(config: UrConfig, out_dir: str | Path, sensor_ip: str | None = None,
          overwrite: bool = False) -> list[Path]:
    """Write the files into ``out_dir``; nothing written when one would be refused."""
    return write_files(robot_files(config, sensor_ip).items(), out_dir, overwrite)

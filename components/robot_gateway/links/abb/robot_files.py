"""What an ABB controller (IRC5 / OmniCore, RobotWare with the EGM option) needs for humanpt's
``abb`` link, written from the cell's config (``humanpt robot-files``, :func:`write`):

* ``humanpt_egm_sio.cfg`` — the controller's UDP unicast transmission protocol (``COM_TRP``,
  type ``UDPUC``) named ``HUMANPT``: the gateway PC's address and port (``udp_bind``, or the
  address given). Load it with the controller's configuration (Control Panel > Configuration
  > Communication, or RobotStudio), then restart the controller.
* ``humanpt_egm.mod`` — a RAPID module: ``EGMGetId``, ``EGMSetupUC`` on ``HUMANPT`` (pose
  mode), ``EGMActPose`` with ``tool0`` (humanpt guides the flange) and the correction frame
  (the robot base: ``wobj0``'s frame, or the flange's with ``correction_frame = "tool"``),
  the convergence criteria, then ``EGMRunPose`` until the operator stops it or the
  communication timeout (``\\CommTimeout``) ends it, and ``EGMReset``.

Every value comes from a validated ``AbbConfig``; the address is checked as the RSI files'
is. The files are humanpt's, written from the RAPID instruction names of ABB's EGM
application manual as commonly used; they have not been run on a real controller here (none
is): check the instruction arguments against your RobotWare's manual before use.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from humanpt.robot_gateway.links.abb.config import AbbConfig
from humanpt.robot_gateway.links.rsi.robot_files import RobotFilesError, sensor_address, write_files

SIO_FILE = "humanpt_egm_sio.cfg"
RAPID_FILE = "humanpt_egm.mod"
DEVICE = "HUMANPT"  # the transmission protocol's name, as EGMSetupUC names it
COMM_TIMEOUT_S = 1.0  # EGMRunPose \CommTimeout: EGM stops this long after humanpt's last message
REFERENCE_BIND = "192.168.125.10:6510"  # the shipped copies: the gateway PC on the robot's service network


def reference_config() -> AbbConfig:
    """The config the shipped copies in ``robot/`` are written for."""
    return AbbConfig(udp_bind=REFERENCE_BIND)


@dataclass(frozen=True)
class RobotFiles:
    sio_cfg: str
    rapid_mod: str

    def items(self) -> tuple[tuple[str, str], ...]:
        return ((SIO_FILE, self.sio_cfg), (RAPID_FILE, self.rapid_mod))


def sio_cfg(config: AbbConfig, sensor_ip: str | None = None) -> str:
    ip, port = sensor_address(config, sensor_ip)
    return f"""SIO:CFG_1.0:6:1::
# humanpt's EGM link: written by `humanpt robot-files` from [robot_gateway] (link "abb").
# The gateway PC at {ip}:{port} ([robot_gateway] udp_bind): the controller sends EgmRobot there.
#
COM_TRP:

      -Name "{DEVICE}" -Type "UDPUC" -RemoteAddress "{ip}" -RemotePortNumber {port}
"""


def rapid_mod(config: AbbConfig) -> str:
    rate_ms = round(config.cycle_period_ms)
    frame = "EGM_FRAME_TOOL" if config.correction_frame == "tool" else "EGM_FRAME_BASE"
    return f"""MODULE humanpt_egm
    ! humanpt's EGM link: written by `humanpt robot-files` from [robot_gateway] (link "abb").
    ! Run humanpt_egm_run with the robot where the teaching or the playback begins: humanpt
    ! guides tool0 (the flange) in the {config.correction_frame} frame ({frame}) every {rate_ms} ms,
    ! the steps within [robot_gateway]'s limits ({config.max_speed_mm_s:g} mm/s,
    ! {config.max_angular_speed_deg_s:g} deg/s, the envelope), its target at most
    ! {config.max_lead_mm:g} mm / {config.max_lead_deg:g} deg ahead of the robot.
    VAR egmident egm_id;
    VAR egmstate egm_state;
    ! No correction beyond these from where EGM starts (mm, deg): a runaway stops here.
    CONST egm_minmax egm_xyz := [-1000, 1000];
    CONST egm_minmax egm_rot := [-45, 45];
    CONST pose corr_frame := [[0, 0, 0], [1, 0, 0, 0]];
    CONST pose sensor_frame := [[0, 0, 0], [1, 0, 0, 0]];

    PROC humanpt_egm_run()
        EGMReset egm_id;
        EGMGetId egm_id;
        egm_state := EGMGetState(egm_id);
        IF egm_state <= EGM_STATE_CONNECTED THEN
            ! UDP to the transmission protocol "{DEVICE}" (humanpt_egm_sio.cfg), pose mode
            EGMSetupUC ROB_1, egm_id, "default", "{DEVICE}" \\Pose;
        ENDIF
        EGMActPose egm_id \\Tool:=tool0 \\WObj:=wobj0, corr_frame, {frame}, sensor_frame, {frame}
            \\x:=egm_xyz \\y:=egm_xyz \\z:=egm_xyz \\rx:=egm_rot \\ry:=egm_rot \\rz:=egm_rot
            \\LpFilter:=20 \\SampleRate:={rate_ms} \\MaxPosDeviation:=1000 \\MaxSpeedDeviation:=
            {config.max_speed_mm_s:g};
        ! Until the operator stops the program, or {COMM_TIMEOUT_S:g} s without a message from humanpt.
        EGMRunPose egm_id, EGM_STOP_HOLD \\x \\y \\z \\Rx \\Ry \\Rz \\CondTime:=1000000
            \\RampInTime:=0.05 \\RampOutTime:=0.5 \\CommTimeout:={COMM_TIMEOUT_S:g};
        EGMReset egm_id;
    ERROR
        IF ERRNO = ERR_UDPUC_COMM THEN
            ! humanpt went silent (the communication timeout): the robot holds
            TPWrite "humanpt: no message from the gateway; EGM stopped";
            EGMReset egm_id;
            RETURN;
        ENDIF
    ENDPROC
ENDMODULE
"""


def robot_files(config: AbbConfig, sensor_ip: str | None = None) -> RobotFiles:
    if not isinstance(config, AbbConfig):
        raise RobotFilesError(f"[robot_gateway] link is {getattr(config, 'link', '?')!r}, not \"abb\"")
    return RobotFiles(sio_cfg(config, sensor_ip), rapid_mod(config))


def write(config: AbbConfig, out_dir: str | Path, sensor_ip: str | None = None,
          overwrite: bool = False) -> list[Path]:
    """Write the files into ``out_dir``; nothing written when one would be refused."""
    return write_files(robot_files(config, sensor_ip).items(), out_dir, overwrite)

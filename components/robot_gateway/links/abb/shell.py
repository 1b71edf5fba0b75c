"""The ABB EGM link's I/O adapter: RSI's UDP adapter (one socket on a thread of its own,
locked onto the robot's host and port by its first valid message), with EGM's check of what
a robot's message is (a well-formed ``EgmRobot``)."""

from __future__ import annotations

from humanpt.robot_gateway.links.abb.config import AbbConfig
from humanpt.robot_gateway.links.abb.protocol import EgmProtocolError, decode_robot
from humanpt.robot_gateway.links.rsi.shell import UdpAdapter


def is_egm_robot(data: bytes) -> bool:
    try:
        decode_robot(data)
    except EgmProtocolError:
        return False
    return True


def adapters(config: AbbConfig) -> list[UdpAdapter]:
    """One UDP socket at ``udp_bind``, locked onto the robot; another sender may take over
    after the gateway's silence watchdog (``status_timeout_cycles`` x ``cycle_period_ms``)."""
    return [UdpAdapter(config.udp_bind, robot=config.udp_robot, valid=is_egm_robot,
                       relock_after_ms=config.status_timeout_cycles * config.cycle_period_ms)]

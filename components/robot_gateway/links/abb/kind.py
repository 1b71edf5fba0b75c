"""The ABB EGM link as the gateway's registry knows it (``links.LINKS["abb"]``)."""

import math

from humanpt.robot_gateway.links import LinkKind
from humanpt.robot_gateway.links.abb import robot_files
from humanpt.robot_gateway.links.abb.config import AbbConfig
from humanpt.robot_gateway.links.abb.link import AbbLink
from humanpt.robot_gateway.links.abb.shell import adapters


def late_repeats(config: AbbConfig) -> int:
    """When humanpt goes silent EGM goes on to the last target, at most ``max_lead_mm`` ahead
    of the fed-back pose: the envelope keeps pose + (1 + N) x step inside with N x step +
    step > max_lead_mm (N = floor(max_lead_mm / max_step_mm)), the target along the step."""
    return math.floor(config.max_lead_mm / config.max_step_mm)


KIND = LinkKind(name="abb", config_type=AbbConfig, make=AbbLink.from_config, adapters=adapters,
                rx_topic=AbbLink.rx_topic, tx_topic=AbbLink.tx_topic, late_repeats=late_repeats,
                write_robot_files=robot_files.write)

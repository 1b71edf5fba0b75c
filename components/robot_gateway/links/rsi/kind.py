"""The RSI link as the gateway's registry knows it (``links.LINKS["rsi"]``)."""

from humanpt.robot_gateway.links import LinkKind
from humanpt.robot_gateway.links.rsi import robot_files
from humanpt.robot_gateway.links.rsi.config import RsiConfig
from humanpt.robot_gateway.links.rsi.link import RsiLink
from humanpt.robot_gateway.links.rsi.shell import adapters


def late_repeats(config: RsiConfig) -> int:
    """HOLDON on RKorr repeats the last correction for each late answer until the robot's
    late limit stops RSI: the envelope keeps the step and as many repeats inside."""
    return config.robot_late_limit


KIND = LinkKind(name="rsi", config_type=RsiConfig, make=RsiLink.from_config, adapters=adapters,
                rx_topic=RsiLink.rx_topic, tx_topic=RsiLink.tx_topic, late_repeats=late_repeats,
                write_robot_files=robot_files.write)

"""The ALTER link as the gateway's registry knows it (``links.LINKS["alter"]``)."""

from humanpt.robot_gateway.links import LinkKind
from humanpt.robot_gateway.links.alter.config import AlterConfig
from humanpt.robot_gateway.links.alter.link import AlterLink
from humanpt.robot_gateway.links.alter.shell import adapters

KIND = LinkKind(name="alter", config_type=AlterConfig, make=AlterLink.from_config, adapters=adapters,
                rx_topic=AlterLink.rx_topic, tx_topic=AlterLink.tx_topic)

"""The UR RTDE link as the gateway's registry knows it (``links.LINKS["ur"]``)."""

from humanpt.robot_gateway.links import LinkKind
from humanpt.robot_gateway.links.abb.kind import late_repeats
from humanpt.robot_gateway.links.ur import robot_files
from humanpt.robot_gateway.links.ur.config import UrConfig
from humanpt.robot_gateway.links.ur.link import UrLink
from humanpt.robot_gateway.links.ur.shell import adapters

# late_repeats: as over EGM (the same absolute target with a bounded lead: the program
# servoes on to the last target when humanpt goes silent, until its watchdog stops it).
KIND = LinkKind(name="ur", config_type=UrConfig, make=UrLink.from_config, adapters=adapters,
                rx_topic=UrLink.rx_topic, tx_topic=UrLink.tx_topic, late_repeats=late_repeats,
                write_robot_files=robot_files.write)

"""The gateway's robot links: one folder each, one line each in :data:`LINKS`.

A link folder (``links/<name>/``) holds the link's protocol codec, its
:class:`~humanpt.robot_gateway.link.Link` (bytes <-> one ``CycleState`` per robot cycle), its
config table (a :class:`~humanpt.robot_gateway.config.GatewayConfig` with the link's own
fields and its cycle's defaults) and its I/O adapter (the live shell's port or socket), and
names them in one :class:`LinkKind` (``KIND`` in the folder's ``kind.py``).

``[robot_gateway] link = "<name>"`` chooses the link: :func:`link_kind` gives its kind, from
which the config (:func:`config_type`), the :class:`Link` and the adapters are made, the way
lerobot's ``cameras/utils.py`` makes a camera from its config's ``type``. The gateway's safety
rules (``core.GatewayCore``) are the same whatever the link.

Adding a link: a folder ``links/<name>/`` with a ``kind.py`` giving ``KIND``, and one line
here. The kinds are imported when first asked for (this module imports none of them), so
that a link's modules may import the gateway's config and link interface.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

# name -> "module:attribute" of the link's LinkKind.
LINKS: dict[str, str] = {
    "alter": "humanpt.robot_gateway.links.alter.kind:KIND",  # the Puma's ALTER serial line (DDCMP)
    "rsi": "humanpt.robot_gateway.links.rsi.kind:KIND",  # KUKA RSI-style UDP/XML, 4 or 12 ms
    "abb": "humanpt.robot_gateway.links.abb.kind:KIND",  # ABB EGM position guidance, UDP protobuf, 4 ms
    "ur": "humanpt.robot_gateway.links.ur.kind:KIND",  # Universal Robots RTDE (TCP), 2 ms e-Series / 8 ms CB3
}

DEFAULT_LINK = "alter"


@dataclass(frozen=True)
class LinkKind:
    """What the gateway needs to know of a link.

    ``config_type``: the gateway's config over this link (a ``GatewayConfig`` subclass: the
    link's own fields, its defaults for the cycle and timers); ``make``: the :class:`Link`
    from such a config (pure); ``adapters``: the live shell's I/O adapters from it (a serial
    port, a UDP socket); ``rx_topic``/``tx_topic``: the local topics of what the robot sent
    and what goes to it (their messages are ``humanpt.SerialChunk``); ``late_repeats``: how
    many times the robot may repeat a correction on its own when answers are late (the
    envelope keeps them all inside; 0 for a robot that applies nothing then);
    ``write_robot_files``: the robot-side files (``humanpt robot-files``)."""

    name: str
    config_type: type
    make: Callable[[Any], Any]
    adapters: Callable[[Any], list]
    rx_topic: str
    tx_topic: str
    late_repeats: Callable[[Any], int] = lambda config: 0
    # ``humanpt robot-files``: write(config, out_dir, sensor_ip, overwrite) -> paths, the files
    # the robot controller needs for this link (None: nothing to write, e.g. ALTER's VAL II).
    write_robot_files: Callable[..., list] | None = None


class UnknownLinkError(ValueError):
    pass


def link_kind(name: str) -> LinkKind:
    """The kind of link ``name`` (UnknownLinkError naming the known ones)."""
    path = LINKS.get(name) if isinstance(name, str) else None
    if path is None:
        raise UnknownLinkError(f"link {name!r} is not a robot link of this version; known links: "
                               f"{', '.join(sorted(LINKS))}")
    module, _, attr = path.partition(":")
    kind = getattr(importlib.import_module(module), attr)
    if not isinstance(kind, LinkKind) or kind.name != name:
        raise TypeError(f"LINKS[{name!r}] = {path!r} is not the LinkKind of {name!r}")
    return kind


def config_type(link: str) -> type:
    """The gateway's config class over ``link``."""
    return link_kind(link).config_type


def gateway_config(link: str = DEFAULT_LINK, **fields: Any) -> Any:
    """The gateway's config over ``link`` with ``fields`` (each link's defaults otherwise)."""
    return config_type(link)(link=link, **fields)

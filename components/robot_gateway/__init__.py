"""robot_gateway: the host end of the robot link and the last line of safety.

``core.GatewayCore`` (pure) turns what the robot reports every cycle into
``robot_gateway/robot_state`` and answers each cycle with a clamped, enveloped,
fresh-or-zero correction: one implementation of the safety rules (``config.GatewayConfig``)
behind a small ``link.Link`` interface. The links are folders of ``links/`` behind one
registry (``links.LINKS``: ALTER over a serial line, KUKA RSI-style UDP/XML), chosen by
``[robot_gateway] link``; ``shell.adapters`` binds the gateway to its link's port or socket.
Cores on threads without Zenoh (benches, tests) are in ``humanpt.testing.harness``. See
README.md.
"""

"""robot_gateway: the host end of the ALTER serial link and the last line of safety.

``core.GatewayCore`` (pure) turns the controller's per-cycle STATUS into
``robot_gateway/robot_state`` and answers each with a clamped, enveloped, fresh-or-zero
CORRECTION; ``shell.adapters`` binds it to a serial port. The safety rules are
``core.GatewayCore``, one implementation behind a small ``link.Link`` interface (ALTER
in ``alter_link``, KUKA RSI-style UDP/XML in ``humanpt.robot_gateway.links.rsi``). Cores on threads without
Zenoh (benches, tests) are in ``humanpt.testing.harness``. See README.md.
"""

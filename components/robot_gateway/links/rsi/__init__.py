"""rsi: a KUKA RSI-style link (UDP datagrams of XML, 4 or 12 ms) for the gateway.

``protocol`` (messages), ``link.RsiLink`` (the gateway's Link), ``core.GatewayCore``
(the gateway over it), ``shell.UdpAdapter`` (the socket, on a thread of its own). The
simulated RSI controller is ``humanpt.sim_robot.rsi``. See README.md.
"""

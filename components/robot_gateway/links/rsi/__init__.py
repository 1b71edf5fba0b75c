"""rsi: the gateway's KUKA RSI-style link (UDP datagrams of XML, 4 or 12 ms).

``protocol`` (messages), ``link.RsiLink`` (the gateway's Link), ``config.RsiConfig`` (its
``[robot_gateway]`` table), ``shell.UdpAdapter`` (the socket, on a thread of its own),
``kind.KIND`` (its registry entry, ``links.LINKS["rsi"]``). The simulated RSI controller is
``humanpt.sim_robot.rsi``. See README.md.
"""

"""``humanpt bench ...``: speed and accuracy benchmarks; the CLI prints their tables.

- ``measure``: round trips through the router and MCAP write throughput (``bench runtime``),
  the simulated camera (``bench render``), each perception method (``bench perception``);
- ``alter``: robot_gateway <-> sim_robot over a real pty in real time (``bench alter``);
- ``rsi``, ``ur``: the gateway <-> the simulated RSI controller over UDP, the simulated UR over
  RTDE (TCP), in one loop and one table (``bench rsi``, ``bench ur``);
- ``summary``: the figures that matter in one table (``humanpt bench``).
- ``faults``: the attack set of issue 14 against a live twin, one row per attack (reaction
  time, robot held, recovered, data lost) (``bench faults``).
  ``link_faults``, ``ur_faults``: the rows on the robot link (``bench faults --link rsi|abb|ur``).
- ``pose_filter``: the pose filter against the twin's truth on the lock-step twin
  (``python -m humanpt.bench.pose_filter``; until issue 30 ``humanpt.pose_filter.bench``).

Product components never import this package (tests/test_boundaries.py checks it).
"""

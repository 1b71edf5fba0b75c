"""``humanpt bench ...``: speed and accuracy benchmarks; the CLI prints their tables.

- ``measure``: round trips through the router and MCAP write throughput (``bench runtime``),
  the simulated camera (``bench render``), each perception method (``bench perception``);
- ``alter``: robot_gateway <-> sim_robot over a real pty in real time (``bench alter``);
- ``summary``: the figures that matter in one table (``humanpt bench``).
- ``faults``: the attack set of issue 14 against a live twin, one row per attack (reaction
  time, robot held, recovered, data lost) (``bench faults``).
- ``pose_filter``: the pose filter against the twin's truth on the lock-step twin
  (``python -m humanpt.bench.pose_filter``; until issue 30 ``humanpt.pose_filter.bench``).

Product components never import this package (tests/test_boundaries.py checks it).
"""

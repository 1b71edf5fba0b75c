"""sim_robot: a simulated Puma controller at the far end of the ALTER serial link.

The Puma model it moves with (standard DH 761/762 and 560: forward, analytic inverse with
joint limits, Jacobian) is product code, :mod:`humanpt.geometry.puma`.
``core.SimRobotCore`` (pure): its own 28 ms cycle, STATUS out,
corrections in (world or tool mode), faults on unreachable corrections, truth out.
``shell.PtyAdapter``: the master side of a pty pair whose slave the gateway opens.
"""

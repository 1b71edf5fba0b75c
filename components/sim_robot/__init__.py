"""sim_robot: a simulated Puma controller at the far end of the ALTER serial link.

So far only the pure kinematics (``humanpt.sim_robot.kinematics``): standard-DH Puma
761/762 and 560 models, forward and analytic inverse kinematics with joint limits.
The process shell (serial pty, 28 ms cycle, ALTER world/tool mode) comes later.
"""

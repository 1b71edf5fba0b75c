"""Universal Robots (e-Series, CB3) over RTDE: see README.md."""

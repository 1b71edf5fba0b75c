"""Calibration of the cell (issue 17): the camera (Zhang, through OpenCV, and the paper's
appendix corner detector), the PSVS and its mirrors, hand-eye (AX = YB) and the driver tip.
Each tool observes the world through the same components a real cell uses and writes the
rig (:mod:`humanpt.runtime.rigfile`). A product library: it imports runtime, geometry and
schemas, never the twin."""

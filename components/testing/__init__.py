"""Test and evaluation machinery: golden replays, harnesses, ground-truth evaluation.

- ``golden``: the reference runs' replay comparison;
- ``harness``: a scripted controller and ``ThreadShell`` (a core on threads with its
  adapters, no Zenoh) for the ALTER tests and ``humanpt bench alter``;
- ``perception_eval``: both perception methods on twin images with ground truth.

Product components never import this package (tests/test_boundaries.py checks it); the
CLI, the benches and the tests do.
"""

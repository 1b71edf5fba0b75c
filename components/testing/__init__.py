"""Test and evaluation machinery: golden replays, harnesses, ground-truth evaluation.

Product components never import this package (tests/test_boundaries.py checks it); the
CLI, the benches and the tests do.
"""

"""``humanpt bench ...``: speed and accuracy benchmarks that print tables.

Product components never import this package; the CLI calls it.
"""

"""The IMM's mode-probability update uses its own logsumexp (scipy's array-API dispatch cost
more than the filter's update); it must give scipy.special.logsumexp's bits exactly, so a
recorded pose_filter replays bit for bit."""

from __future__ import annotations

import numpy as np
from scipy.special import logsumexp

from humanpt.pose_filter.kalman import _logsumexp


def test_the_filters_logsumexp_is_scipys_bit_for_bit():
    rng = np.random.default_rng(0)
    cases = [rng.normal(0, s, 2) + rng.normal(0, 50) for s in (1e-12, 1e-3, 1.0, 30.0, 800.0) for _ in range(40)]
    cases += [np.array(c) for c in ([3.0, 3.0], [-1e300, 0.0], [0.0, -np.inf], [-np.inf, -np.inf],
                                    [np.inf, 1.0], [np.nan, 1.0], [-745.0, 0.0], [709.0, 709.0])]
    cases += [np.log(np.maximum(rng.dirichlet([1, 1]), 1e-300)) + rng.normal(0, 20, 2) for _ in range(200)]
    for a in cases:
        ours, theirs = _logsumexp(a), logsumexp(a)
        assert type(ours) is type(theirs) and np.array_equal(ours, theirs, equal_nan=True), (a, ours, theirs)
        with np.errstate(invalid="ignore"):  # inf - inf
            assert np.array_equal(np.exp(a - ours), np.exp(a - theirs), equal_nan=True)

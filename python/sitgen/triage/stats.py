"""Exact statistics the comparisons and explanations report, scipy's: a proportion's exact
(Clopper–Pearson) interval and the exact McNemar test of paired outcomes."""

from __future__ import annotations

import numpy as np
from scipy import stats

ALPHA = 0.05
"""The level of the tests and of the intervals (95 %)."""


def exact_interval(k: int, n: int) -> tuple[float, float]:
    """The exact (Clopper–Pearson) 95 % interval of ``k`` successes in ``n`` trials."""
    if n == 0:
        return (0.0, 1.0)
    ci = stats.binomtest(k, n).proportion_ci(confidence_level=1 - ALPHA, method="exact")
    return (float(ci.low), float(ci.high))


def mcnemar_exact(a_only: int, b_only: int) -> float:
    """The exact McNemar p-value of discordant counts ``a_only`` and ``b_only`` (two-sided
    binomial test at 1/2); 1 without discordant pairs."""
    if a_only + b_only == 0:
        return 1.0
    return float(stats.binomtest(a_only, a_only + b_only, 0.5).pvalue)


def fisher_greater(k1: int, n1: int, k2: int, n2: int) -> float:
    """The one-sided Fisher exact p-value that ``k1`` of ``n1`` is a higher rate than ``k2``
    of ``n2`` (scipy's ``fisher_exact``, alternative ``greater``)."""
    table = np.array([[k1, n1 - k1], [k2, n2 - k2]])
    return float(stats.fisher_exact(table, alternative="greater").pvalue)

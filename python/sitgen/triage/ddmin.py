"""Delta debugging's minimising algorithm, ddmin (Zeller and Hildebrandt, "Simplifying and
Isolating Failure-Inducing Input", IEEE TSE 28(2), 2002), batched: shrinking calls it over
peers, peer waypoints and obstacle components, and runs each batch of subsets at once."""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any


def ddmin(items: Sequence[Any], fails: Callable[[list[list[Any]]], list[bool]]) -> list[Any]:
    """Zeller and Hildebrandt's ddmin: a 1-minimal subset of ``items`` (order kept) for which
    ``fails`` holds, given that it holds for all of them. ``fails`` takes a batch of subsets
    and returns, in order, which fail: each round tries the subsets, then the complements, as
    one batch each, and takes the first that fails."""
    current = list(items)
    if current and fails([[]])[0]:
        return []
    n = 2
    while len(current) >= 2:
        size = math.ceil(len(current) / n)
        chunks = [current[i : i + size] for i in range(0, len(current), size)]
        found = first_failing_subset(chunks, fails)
        if found is not None:
            current, n = found, 2
            continue
        dropped = [set(chunk) for chunk in chunks]
        complements = [[x for x in current if x not in d] for d in dropped]
        found = first_failing_subset(complements if len(chunks) > 2 else [], fails)
        if found is not None:
            current, n = found, max(n - 1, 2)
            continue
        if n >= len(current):
            break
        n = min(2 * n, len(current))
    return current


def first_failing_subset(
    subsets: list[list[Any]], fails: Callable[[list[list[Any]]], list[bool]]
) -> Any:
    if not subsets:
        return None
    return next((s for s, f in zip(subsets, fails(subsets), strict=True) if f), None)

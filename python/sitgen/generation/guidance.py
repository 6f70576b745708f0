"""Coverage-guided generation: each later generation's genes drawn level by level, in
proportion to the coverage credit of the runs drawn at each level (cells few runs reached
count most)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from sitgen.execution.jobs import (
    CampaignSpec,
    vary_order,
)
from sitgen.generation.genome import Genome, from_unit, to_unit

if TYPE_CHECKING:
    pass


GUIDE_STRATA = 4


"""Levels of a real or whole gene for the coverage guide (equal parts of its range)."""


GUIDE_EPSILON = 0.25


"""Share of the coverage guide's draw that stays uniform over a gene's levels, so that a level
that found nothing early is still tried."""


GUIDE_PRIOR_RUNS = 2.0


"""Runs' worth of the overall mean credit each level starts with (few runs say little)."""


def levels(kind: str, args: list[Any]) -> int:
    """The coverage guide's levels of a ``[vary]`` entry: a choice's values, else
    :data:`GUIDE_STRATA` equal parts of its range (fewer for a short whole range)."""
    if kind == "choice":
        return len(args)
    if kind == "int":
        return min(GUIDE_STRATA, int(args[1]) - int(args[0]) + 1)
    return GUIDE_STRATA


def level_of(kind: str, args: list[Any], gene: int | float) -> int:
    """The level a gene lies in."""
    if kind == "choice":
        return int(gene)
    n = levels(kind, args)
    return min(n - 1, int(to_unit(kind, args, gene) * n))


def credit(covered: Sequence[tuple[Genome, tuple[str, ...]]]) -> list[float]:
    """Each run's coverage credit: the sum over its cells of 1 / (runs that exercised the
    cell). A cell only this run reached is worth 1, a cell every run reaches almost nothing,
    and a run that met no peer nothing (after the rare-branch credit of coverage-guided
    fuzzers, e.g. FairFuzz)."""
    hits: dict[str, int] = {}
    for _, cells in covered:
        for c in cells:
            hits[c] = hits.get(c, 0) + 1
    return [sum(1.0 / hits[c] for c in cells) for _, cells in covered]


def guide_weights(
    spec: CampaignSpec, covered: Sequence[tuple[Genome, tuple[str, ...]]]
) -> list[np.ndarray]:
    """For each ``[vary]`` entry, the probability of each of its levels: in proportion to the
    mean :func:`credit` of the runs drawn at that level (each level starting with
    :data:`GUIDE_PRIOR_RUNS` runs at the overall mean), mixed with a uniform share
    :data:`GUIDE_EPSILON`."""
    credits = credit(covered)
    mean = float(np.mean(credits)) if credits else 0.0
    out = []
    for j, (_, dist) in enumerate(vary_order(spec)):
        kind, args = next(iter(dist.items()))
        n = levels(kind, args)
        total = np.full(n, GUIDE_PRIOR_RUNS * mean)
        runs = np.full(n, GUIDE_PRIOR_RUNS)
        for (genome, _), c in zip(covered, credits, strict=True):
            level = level_of(kind, args, genome.genes[j])
            total[level] += c
            runs[level] += 1
        w = total / runs
        p = w / w.sum() if w.sum() > 0 else np.full(n, 1.0 / n)
        out.append((1 - GUIDE_EPSILON) * p + GUIDE_EPSILON / n)
    return out


def guided_genes(
    spec: CampaignSpec, weights: list[np.ndarray], rng: np.random.Generator
) -> tuple[int | float, ...]:
    """Genes drawn level by level from :func:`guide_weights`, uniform within a level."""
    genes: list[int | float] = []
    for (_, dist), p in zip(vary_order(spec), weights, strict=True):
        kind, args = next(iter(dist.items()))
        level = int(rng.choice(len(p), p=p))
        if kind == "choice":
            genes.append(level)
        else:
            u = (level + rng.random()) / len(p)
            genes.append(from_unit(kind, args, min(u, 1.0 - 1e-12)))
    return tuple(genes)

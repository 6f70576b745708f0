"""Situation coverage of a store: which cells of the interaction space its runs exercised.

The core's coverage observer (``crates/sitgen-core/src/coverage``) marks, during every run, the
cells (interaction type × closest clearance × terrain context × agent speed) of the agent's
encounters with peers, from the world state; the store keeps them per run. This module reads
them back: covered and total cells, each dimension's marginals, pairwise coverage of the
dimensions (a cell is rare; a pair of values is what a tester can aim for), and which failures
fell in which cells (docs/coverage.md).
"""

from __future__ import annotations

import itertools
import math
from collections import Counter, defaultdict
from dataclasses import dataclass
from typing import Any

from sitgen import _core
from sitgen.store import Store, unpack_json


@dataclass(frozen=True)
class Dimension:
    """One dimension of the interaction space."""

    name: str
    values: tuple[str, ...]


def dimensions() -> list[Dimension]:
    """The interaction space's dimensions, as the core defines them."""
    return [Dimension(name, tuple(values)) for name, values in _core.coverage_dimensions()]


def total_cells(dims: list[Dimension] | None = None) -> int:
    """Cells in the interaction space."""
    return math.prod(len(d.values) for d in dims or dimensions())


def split(cell: str) -> tuple[str, ...]:
    """A cell key's values, one per dimension."""
    return tuple(cell.split("/"))


@dataclass(frozen=True)
class RunCoverage:
    """What one stored run covered."""

    id: int
    cells: tuple[str, ...]
    failure_class: str | None
    failure_cell: str | None
    score: float


def stored(store: Store) -> tuple[list[RunCoverage], int]:
    """Every stored run's coverage, in id order, and how many runs have none (errors, and runs
    stored before coverage was observed)."""
    runs: list[RunCoverage] = []
    unobserved = 0
    rows = store.db.execute(
        "SELECT id, coverage, failure_class, score FROM runs ORDER BY id"
    ).fetchall()
    for run_id, raw, failure_class, score in rows:
        if raw is None:
            unobserved += 1
            continue
        data = unpack_json(raw)
        runs.append(
            RunCoverage(
                run_id,
                tuple(data["cells"]),
                failure_class,
                data.get("failure_cell"),
                float(score),
            )
        )
    return runs, unobserved


def hits(runs: list[RunCoverage]) -> Counter[str]:
    """Runs that exercised each cell."""
    return Counter(c for r in runs for c in r.cells)


def coverage_report(store: Store) -> dict[str, Any]:
    """The store's coverage (:func:`summarise` of its runs)."""
    return summarise(*stored(store))


def summarise(runs: list[RunCoverage], unobserved: int = 0) -> dict[str, Any]:
    """The coverage of ``runs`` (``unobserved``: runs without any) as JSON-ready data
    (schema: ``schema/coverage-report.schema.json``): ``covered``, ``total``, ``ratio``,
    ``runs``, ``runs_without_coverage``, ``dimensions`` (each value's covered cells of its
    total, and runs), ``pairwise`` (each pair of dimensions: value pairs covered of all, and
    runs per pair), ``cells`` (each covered cell: runs, failures that began there by class)
    and ``failures`` (each failure class: the cells its runs' failures began in, and how many
    began outside the space, with no peer in an encounter)."""
    dims = dimensions()
    by_cell = hits(runs)
    covered = [split(c) for c in by_cell]
    run_values = [[split(c) for c in r.cells] for r in runs]
    total = total_cells(dims)
    per_dim = []
    for k, d in enumerate(dims):
        cells_with = Counter(values[k] for values in covered)
        runs_with = Counter(v for cells in run_values for v in {values[k] for values in cells})
        per_dim.append(
            {
                "name": d.name,
                "values": [
                    {
                        "value": v,
                        "covered": cells_with[v],
                        "total": total // len(d.values),
                        "runs": runs_with[v],
                    }
                    for v in d.values
                ],
            }
        )
    pairwise = []
    for (i, a), (j, b) in itertools.combinations(enumerate(dims), 2):
        pair_runs: Counter[tuple[str, str]] = Counter()
        for cells in run_values:
            pair_runs.update({(values[i], values[j]) for values in cells})
        pairwise.append(
            {
                "dimensions": [a.name, b.name],
                "covered": len(pair_runs),
                "total": len(a.values) * len(b.values),
                "pairs": [
                    {"values": [va, vb], "runs": pair_runs.get((va, vb), 0)}
                    for va in a.values
                    for vb in b.values
                ],
            }
        )
    failed_in: dict[str, Counter[str]] = defaultdict(Counter)
    by_class: dict[str, Counter[str]] = defaultdict(Counter)
    outside: Counter[str] = Counter()
    for r in runs:
        if r.failure_class is None:
            continue
        if r.failure_cell is None:
            outside[r.failure_class] += 1
            continue
        failed_in[r.failure_cell][r.failure_class] += 1
        by_class[r.failure_class][r.failure_cell] += 1
    order = {key: n for n, key in enumerate(all_cells(dims))}
    return {
        "covered": len(by_cell),
        "total": total,
        "ratio": len(by_cell) / total,
        "runs": len(runs),
        "runs_without_coverage": unobserved,
        "dimensions": per_dim,
        "pairwise": pairwise,
        "cells": [
            {"cell": c, "runs": by_cell[c], "failures": dict(sorted(failed_in[c].items()))}
            for c in sorted(by_cell, key=order.__getitem__)
        ],
        "failures": [
            {
                "class": cls,
                "runs": sum(by_class[cls].values()) + outside[cls],
                "cells": dict(by_class[cls].most_common()),
                "outside": outside[cls],
            }
            for cls in sorted(set(by_class) | set(outside))
        ],
    }


def all_cells(dims: list[Dimension] | None = None) -> list[str]:
    """Every cell key, in the core's order (interaction-major)."""
    dims = dims or dimensions()
    return ["/".join(values) for values in itertools.product(*(d.values for d in dims))]

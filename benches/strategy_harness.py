"""What ``benches/search.py`` and ``benches/situation_coverage.py`` share: each strategy run on
each seed for the largest budget (a budget only truncates a search), the seeded faults'
kills on its situations in the order they ran (``sitgen faults --strategy stored``), each
budget's figures per seed and their medians, and the table that compares two strategies."""

from __future__ import annotations

import statistics
import sys
import tempfile
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from sitgen.execution.jobs import CampaignSpec
from sitgen.generation.fault_report import FaultReport, report_from
from sitgen.generation.faults import run_faults
from sitgen.generation.search import run_search
from sitgen.generation.search.plan import SearchPlan

Measure = Callable[[Path, int, FaultReport], dict[str, float]]
"""A strategy's figures for the first ``budget`` runs of its store, given its fault kills."""


def mean_runs_to_first_kill(faults: FaultReport, budget: int) -> float:
    """Over the faults, runs to the first kill (a fault not killed within the budget counts as
    budget + 1)."""
    firsts = [f.runs_to_first_kill for f in faults.faults]
    return statistics.fmean(budget + 1 if r is None or r > budget else r for r in firsts)


def compare(
    spec: CampaignSpec,
    strategies: Sequence[str],
    seeds: range,
    budgets: Sequence[int],
    largest: int,
    measure: Measure,
    after_search: Callable[[str, Path], None] | None = None,
) -> dict[str, Any]:
    """Run every strategy on every seed and measure it at every budget; ``after_search`` sees
    each store before it is measured."""
    out: dict[str, Any] = {"budgets": list(budgets), "seeds": list(seeds), "strategies": {}}
    with tempfile.TemporaryDirectory() as tmp:
        for strategy in strategies:
            per_seed: list[dict[str, dict[str, float]]] = []
            wall = 0.0
            for seed in seeds:
                db = Path(tmp) / f"{strategy}-{seed}.db"
                started = time.perf_counter()
                run_search(spec, db, seed=seed, budget=largest, plan=SearchPlan(strategy))
                wall += time.perf_counter() - started
                if after_search is not None:
                    after_search(strategy, db)
                faults_db = Path(tmp) / f"faults-{strategy}-{seed}.db"
                run_faults(spec, faults_db, budget=largest, strategy="stored", situations_db=db)
                faults = report_from(faults_db)
                per_seed.append({str(b): measure(db, b, faults) for b in budgets})
                print(f"{strategy} seed {seed}: {per_seed[-1]}", file=sys.stderr)
            out["strategies"][strategy] = {
                "per_seed": per_seed,
                "median": {
                    str(b): {
                        k: statistics.median(s[str(b)][k] for s in per_seed)
                        for k in per_seed[0][str(b)]
                    }
                    for b in budgets
                },
                "search_wall_s": wall,
            }
    return out


def print_comparison(out: dict[str, Any], strategies: Sequence[str], names: dict[str, str]) -> None:
    """The two strategies' medians side by side at every budget, with their ratio."""
    first, second = strategies
    a, b = (out["strategies"][s]["median"] for s in strategies)
    seeds = out["seeds"]
    print(f"\n{first} against {second}, median over seeds {seeds[0]}-{seeds[-1]}")
    print(f"{'budget':>6}  {'figure':32}{first:>12}{second:>10}{'ratio':>8}")
    for budget in out["budgets"]:
        for key, name in names.items():
            x, y = a[str(budget)][key], b[str(budget)][key]
            ratio = x / y if y else float("nan")
            print(f"{budget:>6}  {name:32}{x:>12.3g}{y:>10.3g}{ratio:>8.2f}")

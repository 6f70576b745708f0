"""Coverage-guided generation against random at equal budget (``make bench-coverage``): for each
of 5 seeds, ``examples/campaigns/coverage.toml`` (the paper's campaign with the peers'
behaviour varied too) searched with ``--strategy coverage`` and generated at random (the
campaign's own jobs), each for the largest budget; a budget only truncates a search, so the
first 100 runs of a 500-run search are the 100-run search. At budgets 100, 250 and 500 it prints
the median over seeds of

- cells of the interaction space covered (of 560), and value pairs covered over all pairs of
  dimensions (``sitgen coverage``),
- distinct failure classes found,
- the kill rate of snd_follow's seeded faults on those situations, in the order they were run
  (``sitgen faults --strategy stored``), and the mean runs to first kill over the faults,

and the ratio guided / random. Writes ``benches/results/coverage.json``.
``SITGEN_BENCH_COVERAGE_SEEDS`` (default 5) and ``SITGEN_BENCH_COVERAGE_BUDGET`` (default 500)
shrink it for a quick look.
"""

from __future__ import annotations

import json
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from sitgen.campaign import parse_campaign
from sitgen.coverage import coverage_curve, dimensions, split, stored
from sitgen.faults import FaultReport, kill_rate_at, report_from, run_faults
from sitgen.search import SearchPlan, run_search
from sitgen.store import Store

ROOT = Path(__file__).resolve().parent.parent
RESULTS = ROOT / "benches" / "results"
SPEC = ROOT / "examples" / "campaigns" / "coverage.toml"
BUDGETS = (100, 250, 500)
STRATEGIES = ("coverage", "random")


def pairs_covered(db: Path, budget: int) -> int:
    """Value pairs covered, summed over every pair of dimensions, by runs below ``budget``."""
    with Store(db) as store:
        runs, _ = stored(store)
    n = len(dimensions())
    seen = {
        (i, j, v[i], v[j])
        for r in runs
        if r.id < budget
        for c in r.cells
        for v in [split(c)]
        for i in range(n)
        for j in range(i + 1, n)
    }
    return len(seen)


def measure(db: Path, budget: int, faults: FaultReport) -> dict[str, float]:
    """The figures of the first ``budget`` runs of the search in ``db``."""
    with Store(db) as store:
        runs, _ = stored(store)
        classes = store.db.execute(
            "SELECT count(DISTINCT failure_class) FROM runs WHERE id < ?", (budget,)
        ).fetchone()[0]
    firsts = [f.runs_to_first_kill for f in faults.faults]
    return {
        "cells": coverage_curve(runs, [budget])[0],
        "pairs": pairs_covered(db, budget),
        "classes": classes,
        "kill_rate": kill_rate_at(faults, budget),
        "mean_runs_to_first_kill": statistics.fmean(
            budget + 1 if r is None or r > budget else r for r in firsts
        ),
    }


def main() -> None:
    seeds = range(1, 1 + int(os.environ.get("SITGEN_BENCH_COVERAGE_SEEDS", "5")))
    largest = int(os.environ.get("SITGEN_BENCH_COVERAGE_BUDGET", str(BUDGETS[-1])))
    budgets = [b for b in BUDGETS if b <= largest] or [largest]
    spec = parse_campaign(SPEC.read_text(), str(SPEC))
    out: dict[str, Any] = {"budgets": budgets, "seeds": list(seeds), "strategies": {}}
    with tempfile.TemporaryDirectory() as tmp:
        for strategy in STRATEGIES:
            per_seed: list[dict[str, dict[str, float]]] = []
            wall = 0.0
            for seed in seeds:
                db = Path(tmp) / f"{strategy}-{seed}.db"
                started = time.perf_counter()
                run_search(spec, db, seed=seed, budget=largest, plan=SearchPlan(strategy))
                wall += time.perf_counter() - started
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
    guided, random = (out["strategies"][s]["median"] for s in STRATEGIES)
    print(f"\ncoverage-guided against random, median over seeds {seeds.start}-{seeds.stop - 1}")
    names = {
        "cells": "cells covered (of 560)",
        "pairs": "value pairs covered",
        "classes": "failure classes found",
        "kill_rate": "kill rate of the seeded faults",
        "mean_runs_to_first_kill": "mean runs to first kill",
    }
    print(f"{'budget':>6}  {'figure':32}{'guided':>10}{'random':>10}{'ratio':>8}")
    for b in budgets:
        for key, name in names.items():
            g, r = guided[str(b)][key], random[str(b)][key]
            ratio = g / r if r else float("nan")
            print(f"{b:>6}  {name:32}{g:>10.3g}{r:>10.3g}{ratio:>8.2f}")
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "coverage.json").write_text(json.dumps(out, indent=2) + "\n")
    print(f"wrote {RESULTS / 'coverage.json'}")


if __name__ == "__main__":
    main()

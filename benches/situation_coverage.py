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

and the ratio guided / random. Writes ``benches/results/coverage.json``. (Not named
``coverage.py``: run as a script, that name would shadow the coverage package numba imports.)
``SITGEN_BENCH_COVERAGE_SEEDS`` (default 5) and ``SITGEN_BENCH_COVERAGE_BUDGET`` (default 500)
shrink it for a quick look.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

from strategy_harness import compare, mean_runs_to_first_kill, print_comparison

from sitgen.execution.jobs import parse_campaign
from sitgen.generation.fault_report import FaultReport, kill_rate_at
from sitgen.store import Store
from sitgen.triage.coverage import stored, summarise

ROOT = Path(__file__).resolve().parent.parent
RESULTS = ROOT / "benches" / "results"
SPEC = ROOT / "examples" / "campaigns" / "coverage.toml"
BUDGETS = (100, 250, 500)
STRATEGIES = ("coverage", "random")


def measure(db: Path, budget: int, faults: FaultReport) -> dict[str, float]:
    """The figures of the first ``budget`` runs of the search in ``db``."""
    with Store(db) as store:
        runs, _ = stored(store)
        classes = store.db.execute(
            "SELECT count(DISTINCT failure_class) FROM runs WHERE id < ?", (budget,)
        ).fetchone()[0]
    report = summarise([r for r in runs if r.id < budget])
    return {
        "cells": report["covered"],
        "pairs": sum(p["covered"] for p in report["pairwise"]),
        "classes": classes,
        "kill_rate": kill_rate_at(faults, budget),
        "mean_runs_to_first_kill": mean_runs_to_first_kill(faults, budget),
    }


def main() -> None:
    seeds = range(1, 1 + int(os.environ.get("SITGEN_BENCH_COVERAGE_SEEDS", "5")))
    largest = int(os.environ.get("SITGEN_BENCH_COVERAGE_BUDGET", str(BUDGETS[-1])))
    budgets = [b for b in BUDGETS if b <= largest] or [largest]
    spec = parse_campaign(SPEC.read_text(), str(SPEC))
    out = compare(spec, STRATEGIES, seeds, budgets, largest, measure)
    print_comparison(
        out,
        STRATEGIES,
        {
            "cells": "cells covered (of 560)",
            "pairs": "value pairs covered",
            "classes": "failure classes found",
            "kill_rate": "kill rate of the seeded faults",
            "mean_runs_to_first_kill": "mean runs to first kill",
        },
    )
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "coverage.json").write_text(json.dumps(out, indent=2) + "\n")
    print(f"wrote {RESULTS / 'coverage.json'}")


if __name__ == "__main__":
    main()

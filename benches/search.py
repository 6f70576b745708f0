"""Search against random generation at equal budget (``make bench-search``): for each of 5
seeds, the paper's campaign spec searched with MAP-Elites and generated at random (the
campaign's own jobs), each for the largest budget; a budget only truncates a search, so the
first 250 runs of a 500-run search are the 250-run search. At budgets 250 and 500 it prints the
median over seeds of

- distinct failure classes found (failure classes with at least one run),
- distinct failures (``sitgen failures``: classes, broad ones split by behaviour),
- the share of runs under 10 points (the paper's low scores),
- the kill rate of snd_follow's seeded faults on those situations, in the order they were run
  (``sitgen faults --strategy stored``), and the mean runs to first kill over the faults,

and the ratio search / random. For the search it also prints the locality of each variation
operator: of the children it made, the share that failed with their first parent's failure
class (or, like it, with none) — how much a child resembles the elite it was varied from.
Writes ``benches/results/search.json``.
``SITGEN_BENCH_SEARCH_SEEDS`` (default 5) and ``SITGEN_BENCH_SEARCH_BUDGET`` (default 500)
shrink it for a quick look.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

from strategy_harness import compare, mean_runs_to_first_kill, print_comparison

from sitgen.execution.jobs import parse_campaign
from sitgen.generation.fault_report import FaultReport, kill_rate_at
from sitgen.generation.search import LOW_SCORE_POINTS
from sitgen.store import Store
from sitgen.triage.failures import distinct_failures

RESULTS = Path(__file__).resolve().parent / "results"
BUDGETS = (250, 500)
STRATEGIES = ("map-elites", "random")


def measure(db: Path, budget: int, faults: FaultReport) -> dict[str, float]:
    """The figures of the first ``budget`` runs of the search in ``db``."""
    with Store(db) as store:
        rows = store.db.execute(
            "SELECT failure_class, score FROM runs WHERE id < ? ORDER BY id", (budget,)
        ).fetchall()
        split = [f for f in distinct_failures(store) if min(f.run_ids) < budget]
    return {
        "classes": len({c for c, _ in rows if c}),
        "distinct_failures": len(split),
        "low_share": sum(s < LOW_SCORE_POINTS for _, s in rows) / len(rows),
        "kill_rate": kill_rate_at(faults, budget),
        "mean_runs_to_first_kill": mean_runs_to_first_kill(faults, budget),
    }


def locality(db: Path) -> dict[str, list[int]]:
    """Per operator: [children, children with their first parent's failure class]."""
    with Store(db) as store:
        rows = store.db.execute("SELECT id, failure_class, parents, genes FROM runs").fetchall()
    classes = {run_id: cls for run_id, cls, _, _ in rows}
    out: dict[str, list[int]] = {}
    for _, cls, parents, genes in rows:
        first = json.loads(parents)[:1]
        if not first:
            continue
        tally = out.setdefault(json.loads(genes)["operator"], [0, 0])
        tally[0] += 1
        tally[1] += cls == classes[first[0]]
    return out


def main() -> None:
    seeds = range(1, 1 + int(os.environ.get("SITGEN_BENCH_SEARCH_SEEDS", "5")))
    largest = int(os.environ.get("SITGEN_BENCH_SEARCH_BUDGET", str(BUDGETS[-1])))
    budgets = [b for b in BUDGETS if b <= largest] or [largest]
    kept: dict[str, list[int]] = {}

    def tally(strategy: str, db: Path) -> None:
        if strategy != "map-elites":
            return
        for operator, (n, same) in locality(db).items():
            counts = kept.setdefault(operator, [0, 0])
            counts[0] += n
            counts[1] += same

    out = compare(parse_campaign(None), STRATEGIES, seeds, budgets, largest, measure, tally)
    out["strategies"]["map-elites"]["children_keeping_parent_class"] = kept
    print_comparison(
        out,
        STRATEGIES,
        {
            "classes": "failure classes found",
            "distinct_failures": "distinct failures",
            "low_share": "share of runs under 10 points",
            "kill_rate": "kill rate of the seeded faults",
            "mean_runs_to_first_kill": "mean runs to first kill",
        },
    )
    print("\nchildren with their first parent's failure class, all seeds, by operator")
    for operator, (n, same) in sorted(kept.items()):
        print(f"  {operator:12} {same:>5} of {n:>5} ({same / n:.0%})")
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "search.json").write_text(json.dumps(out, indent=2) + "\n")
    print(f"wrote {RESULTS / 'search.json'}")


if __name__ == "__main__":
    main()

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
import statistics
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from sitgen.campaign import parse_campaign
from sitgen.failures import distinct_failures
from sitgen.faults import FaultReport, kill_rate_at, report_from, run_faults
from sitgen.search import LOW_SCORE_POINTS, SearchPlan, run_search
from sitgen.store import Store

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
    firsts = [f.runs_to_first_kill for f in faults.faults]
    return {
        "classes": len({c for c, _ in rows if c}),
        "distinct_failures": len(split),
        "low_share": sum(s < LOW_SCORE_POINTS for _, s in rows) / len(rows),
        "kill_rate": kill_rate_at(faults, budget),
        "mean_runs_to_first_kill": statistics.fmean(
            budget + 1 if r is None or r > budget else r for r in firsts
        ),
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
    spec = parse_campaign(None)
    out: dict[str, Any] = {"budgets": budgets, "seeds": list(seeds), "strategies": {}}
    with tempfile.TemporaryDirectory() as tmp:
        for strategy in STRATEGIES:
            per_seed: list[dict[str, dict[str, float]]] = []
            kept: dict[str, list[int]] = {}
            wall = 0.0
            for seed in seeds:
                db = Path(tmp) / f"{strategy}-{seed}.db"
                started = time.perf_counter()
                run_search(spec, db, seed=seed, budget=largest, plan=SearchPlan(strategy))
                wall += time.perf_counter() - started
                for operator, (n, same) in locality(db).items():
                    tally = kept.setdefault(operator, [0, 0])
                    tally[0] += n
                    tally[1] += same
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
                "children_keeping_parent_class": kept,
            }
    search, random = (out["strategies"][s]["median"] for s in STRATEGIES)
    print(f"\nsearch (map-elites) against random, median over seeds {seeds.start}-{seeds.stop - 1}")
    names = {
        "classes": "failure classes found",
        "distinct_failures": "distinct failures",
        "low_share": "share of runs under 10 points",
        "kill_rate": "kill rate of the seeded faults",
        "mean_runs_to_first_kill": "mean runs to first kill",
    }
    print(f"{'budget':>6}  {'figure':32}{'map-elites':>12}{'random':>10}{'ratio':>8}")
    for b in budgets:
        for key, name in names.items():
            s, r = search[str(b)][key], random[str(b)][key]
            ratio = s / r if r else float("nan")
            print(f"{b:>6}  {name:32}{s:>12.3g}{r:>10.3g}{ratio:>8.2f}")
    kept = out["strategies"]["map-elites"]["children_keeping_parent_class"]
    print("\nchildren with their first parent's failure class, all seeds, by operator")
    for operator, (n, same) in sorted(kept.items()):
        print(f"  {operator:12} {same:>5} of {n:>5} ({same / n:.0%})")
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "search.json").write_text(json.dumps(out, indent=2) + "\n")
    print(f"wrote {RESULTS / 'search.json'}")


if __name__ == "__main__":
    main()

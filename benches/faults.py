"""Fault-finding power benchmark: the kill rate of each way of generating situations at budgets
50, 100, 200 and 500 (and 5, 10, 20, where strategies still differ), the median over 5 seeds,
and each fault's median runs to first kill (``make bench-faults``).

Strategies: ``random`` is the paper's campaign (its random generation, 0-5 peers, 600 s runs);
``barn`` is the 300 BARN worlds from ``../shared/data/barn`` with no peers and the BARN
challenge's 100 s limit, shuffled by the seed (at most 300 situations, so its 500 column is
all 300). Both evaluate ``snd_follow`` against every one of its seeded faults with
``sitgen faults`` (``python/sitgen/faults.py``); one evaluation per seed at the largest budget
gives every smaller budget, since a fault's runs to first kill does not depend on the budget.
Search and coverage-guided generation join the table when they land. Writes
``benches/results/faults.json``. ``SITGEN_BENCH_FAULT_SEEDS`` (default 5) and
``SITGEN_BENCH_FAULT_BUDGET`` (default 500) shrink it for a quick look.
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

from sitgen.campaign import campaign_from_data, parse_campaign
from sitgen.faults import FaultReport, kill_rate_at, report_from, run_faults
from sitgen.maps import BARN_WORLDS

RESULTS = Path(__file__).resolve().parent / "results"
SHARED = Path(
    os.environ.get("SITGEN_SHARED_DATA", Path(__file__).resolve().parents[2] / "shared" / "data")
)
BUDGETS = (5, 10, 20, 50, 100, 200, 500)
BARN_TIME_LIMIT_S = 100.0
"""The BARN challenge's time limit."""


def evaluate(strategy: str, seed: int, budget: int, folder: Path) -> FaultReport:
    db = folder / f"{strategy}-{seed}.db"
    if strategy == "random":
        spec = parse_campaign(None)
    else:
        paper = parse_campaign(None)
        run = dict(paper.run, time_limit_s=BARN_TIME_LIMIT_S)
        spec = campaign_from_data({"run": run})
        budget = min(budget, BARN_WORLDS)
    run_faults(spec, db, seed=seed, budget=budget, strategy=strategy, barn_dir=SHARED / "barn")
    report = report_from(db)
    for path in folder.glob(f"{db.name}*"):
        path.unlink()
    return report


def main() -> None:
    seeds = range(1, 1 + int(os.environ.get("SITGEN_BENCH_FAULT_SEEDS", "5")))
    largest = int(os.environ.get("SITGEN_BENCH_FAULT_BUDGET", str(BUDGETS[-1])))
    budgets = [b for b in BUDGETS if b <= largest] or [largest]
    strategies = ["random"]
    if (SHARED / "barn" / "barn_paths.txt").is_file():
        strategies.append("barn")
    else:
        print(f"skipping barn: no BARN data at {SHARED / 'barn'}", file=sys.stderr)
    out: dict[str, Any] = {"budgets": budgets, "seeds": list(seeds), "strategies": {}}
    with tempfile.TemporaryDirectory() as tmp:
        for strategy in strategies:
            reports = []
            started = time.perf_counter()
            for seed in seeds:
                report = evaluate(strategy, seed, budgets[-1], Path(tmp))
                reports.append(report)
                print(
                    f"{strategy} seed {seed}: {report.kill_rate:.0%} of {len(report.faults)} "
                    f"faults in {report.situations} situations",
                    file=sys.stderr,
                )
            medians = {
                str(b): statistics.median(kill_rate_at(r, b) for r in reports) for b in budgets
            }
            faults = [f.id for f in reports[0].faults]
            never = [f for f in faults if not any(_killed(r, f) for r in reports)]
            out["strategies"][strategy] = {
                "median_kill_rate": medians,
                "kill_rates": {str(b): [kill_rate_at(r, b) for r in reports] for b in budgets},
                "faults": len(faults),
                "never_killed": never,
                "runs_to_first_kill": {f: [_first(r, f) for r in reports] for f in faults},
                "wall_s": time.perf_counter() - started,
            }
    print(f"\nkill rate of snd_follow's faults, median over seeds {seeds.start}-{seeds.stop - 1}")
    print(f"{'strategy':10}" + "".join(f"{b:>8}" for b in budgets) + "   never killed")
    for strategy, result in out["strategies"].items():
        cells = "".join(f"{result['median_kill_rate'][str(b)]:>8.0%}" for b in budgets)
        print(f"{strategy:10}{cells}   {', '.join(result['never_killed']) or '-'}")
    print("\nmedian runs to first kill (- : killed in fewer than half the seeds)")
    print(f"{'fault':28}" + "".join(f"{s:>10}" for s in out["strategies"]))
    for fault in out["strategies"]["random"]["runs_to_first_kill"]:
        cells = "".join(
            f"{_median_runs(r['runs_to_first_kill'].get(fault, [])):>10}"
            for r in out["strategies"].values()
        )
        print(f"{fault:28}{cells}")
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "faults.json").write_text(json.dumps(out, indent=2) + "\n")
    print(f"wrote {RESULTS / 'faults.json'}")


def _median_runs(runs: list[int | None]) -> str:
    """The median runs to first kill, a fault never killed counting as infinitely many."""
    if not runs:
        return "n/a"
    median = statistics.median(float("inf") if r is None else r for r in runs)
    return "-" if median == float("inf") else f"{median:g}"


def _first(report: FaultReport, fault: str) -> int | None:
    return next(f.runs_to_first_kill for f in report.faults if f.id == fault)


def _killed(report: FaultReport, fault: str) -> bool:
    return _first(report, fault) is not None


if __name__ == "__main__":
    main()

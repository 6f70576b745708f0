"""Fault-finding power benchmark (``make bench-faults``): for random generation at budgets 50,
100, 250 and 500 situations, the median over 5 seeds of the robust kill rate on the first
catalogue (the faults that can show wherever snd_follow avoids anything), on the harder faults
(those that show only in particular circumstances) and on the whole catalogue; the equivalent
mutants' false-kill rate beside them; and each fault's median runs to first kill, counted in
situations and in runs with every perturbed copy of the kill rule's tests.

``random`` is the paper's campaign (its random generation, 0-5 peers, 600 s runs); ``barn``
(opt-in: ``SITGEN_BENCH_FAULT_STRATEGIES=random,barn``) is the 300 BARN worlds from
``../shared/data/barn`` with no peers and the BARN challenge's 100 s limit, shuffled by the seed
(at most 300 situations, so its 500 column is all 300). Both evaluate ``snd_follow`` against every
one of its seeded faults and the equivalent mutants with ``sitgen faults``
(``python/sitgen/generation/faults.py``); one evaluation per seed at the largest budget gives every
smaller budget, since a fault's runs to first kill does not depend on the budget. Writes
``benches/results/faults.json``. ``SITGEN_BENCH_FAULT_SEEDS`` (default 5) and
``SITGEN_BENCH_FAULT_BUDGET`` (default 500) shrink it for a quick look."""

from __future__ import annotations

import json
import os
import statistics
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from sitgen.execution.jobs import campaign_from_data, parse_campaign
from sitgen.generation.fault_report import FaultReport, FaultRow, report_from, share_killed_within
from sitgen.generation.faults import is_harder, run_faults
from sitgen.world.maps import BARN_WORLDS

RESULTS = Path(__file__).resolve().parent / "results"
SHARED = Path(
    os.environ.get("SITGEN_SHARED_DATA", Path(__file__).resolve().parents[2] / "shared" / "data")
)
BUDGETS = (50, 100, 250, 500)
BARN_TIME_LIMIT_S = 100.0
"""The BARN challenge's time limit."""

Part = Callable[[FaultReport], list[FaultRow]]
PARTS: dict[str, Part] = {
    "first catalogue": lambda r: [f for f in r.faults if not is_harder(f.id)],
    "harder faults": lambda r: [f for f in r.faults if is_harder(f.id)],
    "whole catalogue": lambda r: r.faults,
    "equivalent mutants": lambda r: r.mutants,
}
"""The rows each rate is taken over; a kill among the equivalent mutants is a false kill."""


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
    strategies = os.environ.get("SITGEN_BENCH_FAULT_STRATEGIES", "random").split(",")
    if "barn" in strategies and not (SHARED / "barn" / "barn_paths.txt").is_file():
        print(f"skipping barn: no BARN data at {SHARED / 'barn'}", file=sys.stderr)
        strategies.remove("barn")
    out: dict[str, Any] = {"budgets": budgets, "seeds": list(seeds), "strategies": {}}
    with tempfile.TemporaryDirectory() as tmp:
        for strategy in strategies:
            reports = []
            started = time.perf_counter()
            for seed in seeds:
                report = evaluate(strategy, seed, budgets[-1], Path(tmp))
                reports.append(report)
                print(
                    f"{strategy} seed {seed}: {sum(f.killed for f in report.faults)} of "
                    f"{len(report.faults)} faults and {sum(m.killed for m in report.mutants)} of "
                    f"{len(report.mutants)} equivalent mutants killed in {report.situations} "
                    f"situations, {report.runs} runs with perturbed copies",
                    file=sys.stderr,
                )
            rows = {f.id: [_row(r, f.id) for r in reports] for f in reports[0].faults}
            out["strategies"][strategy] = {
                "median_kill_rate": {
                    part: {
                        str(b): statistics.median(share_killed_within(of(r), b) for r in reports)
                        for b in budgets
                    }
                    for part, of in PARTS.items()
                },
                "kill_rates": {
                    part: {
                        str(b): [share_killed_within(of(r), b) for r in reports] for b in budgets
                    }
                    for part, of in PARTS.items()
                },
                "faults": {part: [f.id for f in of(reports[0])] for part, of in PARTS.items()},
                "never_killed": [f for f, per_seed in rows.items() if not any(per_seed)],
                "runs_to_first_kill": {
                    f: [r.runs_to_first_kill if r else None for r in per_seed]
                    for f, per_seed in rows.items()
                },
                "runs_with_reruns_to_first_kill": {
                    f: [r.runs_with_reruns if r else None for r in per_seed]
                    for f, per_seed in rows.items()
                },
                "runs_at_largest_budget": [r.runs for r in reports],
                "wall_s": time.perf_counter() - started,
            }
    _print(out, seeds)
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "faults.json").write_text(json.dumps(out, indent=2) + "\n")
    print(f"wrote {RESULTS / 'faults.json'}")


def _print(out: dict[str, Any], seeds: range) -> None:
    budgets = out["budgets"]
    for strategy, result in out["strategies"].items():
        print(
            f"\n{strategy}: robust kill rate of snd_follow's faults, median over seeds "
            f"{seeds.start}-{seeds.stop - 1}"
        )
        print(f"{'':34}" + "".join(f"{b:>8}" for b in budgets))
        for part, medians in result["median_kill_rate"].items():
            size = len(result["faults"][part])
            name = f"{part} ({size})" if part != "equivalent mutants" else f"false kills ({size})"
            print(f"{name:34}" + "".join(f"{medians[str(b)]:>8.0%}" for b in budgets))
        runs = statistics.median(result["runs_at_largest_budget"])
        print(f"runs with perturbed copies at {budgets[-1]} situations: {runs:g} (median)")
        print(f"never killed in any seed: {', '.join(result['never_killed']) or '-'}")
        print(
            "\nmedian runs to first kill, in situations and in runs with every perturbed copy "
            "(- : killed in fewer than half the seeds)"
        )
        print(f"{'fault':30}{'situations':>12}{'runs':>10}")
        for fault, firsts in result["runs_to_first_kill"].items():
            harder = " (harder)" if fault in result["faults"]["harder faults"] else ""
            runs_with = result["runs_with_reruns_to_first_kill"][fault]
            print(f"{fault + harder:30}{_median(firsts):>12}{_median(runs_with):>10}")


def _median(runs: list[int | None]) -> str:
    """The median, a fault never killed counting as infinitely many."""
    if not runs:
        return "n/a"
    median = statistics.median(float("inf") if r is None else r for r in runs)
    return "-" if median == float("inf") else f"{median:g}"


def _row(report: FaultReport, fault: str) -> FaultRow | None:
    """The fault's row where it was killed."""
    return next((f for f in report.faults if f.id == fault and f.killed), None)


if __name__ == "__main__":
    main()

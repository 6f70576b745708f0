"""Search strategies against random generation by what survives chaos (``make bench-search``).

For each of 5 seeds, the paper's campaign spec is searched with every strategy — ``mutation``
(situation operators, archive over failure class × variant), ``map-elites`` (spec genes and
seeds), ``coverage`` (coverage-guided) and ``random`` (the campaign's own jobs) — as deep
as the largest budget's yardstick walks (:func:`deep_enough`); then the same yardstick is
applied to every store (:func:`sitgen.triage.variants.robust_variants`): its runs in the
order they were made, and perturbed copies of each failing run whose variant (class ×
interaction × terrain context) is new, every copy counted against the same budget. At
budgets of 250, 500 and 1000 evaluations (runs plus copies) it prints the median over seeds of

- robust distinct failures (variants confirmed robust within the budget), and the ratio of
  each strategy's to random generation's;
- evaluations to the first robust failure of each class that random generation finds in fewer
  than half of the seeds (its rare classes);
- how many of each budget's evaluations were runs (the rest were copies);
- for ``mutation``, over the runs within the largest budget, each situation operator's
  locality (of its children, the share that failed with their parent's failure class), the
  share that failed with their parent's very variant (nothing new), and, for it and fresh runs,
  the share of runs that showed a failure variant new to the store and the share that
  confirmed a new robust variant; and for a targeted operator, of its failing children aimed at
  a target, the share whose failure began in the interaction, context or both aimed at (*aim
  met*); per operator and target, the children aimed there, aim met, and the shares showing a
  new variant and confirming a new robust one; and the yardstick's trials by failure class
  (how many, how many robust, the copies spent on knife-edge ones);

and (``SITGEN_BENCH_SEARCH_FAULTS=1``, about 3 minutes a store) the robust kill rate of the
harder seeded faults on the first 250 situations of the ``mutation`` and ``random`` stores
(``sitgen faults --strategy stored``): per seed, which faults each kills and which way made
the killing situation (a fresh job or an operator), and how many trials spared a fault whose
copies showed the failure because the correct controller's copies showed it too. Writes
``benches/results/search.json``.
Where random generation is among the strategies, each seed's random store is also searched to
``SITGEN_BENCH_SEARCH_REFERENCE`` evaluations (default 5000; 0 skips it), and the bench prints,
per strategy, the share of the robust variants random generation confirms within those that the
strategy confirms within 500 (:func:`share_of_reference`): how close a strategy at 500 comes to
what a ten times larger random campaign finds.
``SITGEN_BENCH_SEARCH_SEEDS`` (default 5), ``SITGEN_BENCH_SEARCH_BUDGET`` (default 1000) and
``SITGEN_BENCH_SEARCH_STRATEGIES`` shrink it for a quick look; ``SITGEN_BENCH_SEARCH_FIRST_SEED``
(default 1) measures other seeds, and ``SITGEN_BENCH_SEARCH_SEED_LIST`` (``8193,60736,…``)
names them one by one (the held-out seeds in ``benches/search-notes.md``).
"""

from __future__ import annotations

import json
import os
import statistics
import sys
import tempfile
import time
from collections import Counter
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from sitgen.execution.jobs import parse_campaign
from sitgen.generation.fault_report import report_from
from sitgen.generation.faults import is_harder, run_faults
from sitgen.generation.mutation import target_of
from sitgen.generation.search import run_search
from sitgen.generation.search.plan import SearchPlan
from sitgen.store import Store, unpack_json
from sitgen.triage.variants import Tally, robust_variants, variant

RESULTS = Path(__file__).resolve().parent / "results"
BUDGETS = (250, 500, 1000)
STRATEGIES = ("mutation", "map-elites", "coverage", "random")
FAULT_SITUATIONS = 250
REFERENCE_AT = 500
"""The budget at which a strategy's robust variants are compared with the reference's."""


def deep_enough(
    spec: Any, db: Path, seed: int, strategy: str, budgets: list[int], least: int
) -> tuple[Tally, int, float, float]:
    """The yardstick on a store searched only as deep as it walks within the largest budget
    (and at least ``least`` runs); how many runs were searched, and the seconds spent searching
    and on the yardstick. A search's runs do not depend on its budget (a budget truncates it,
    and a larger one resumes it), so the figures are those of a search as deep as the budget;
    about half a store's budget goes on copies, so searching to the budget would make about
    twice the runs the yardstick walks. A deeper step applies the yardstick again; the first,
    half the budget, is deep enough for the mutation strategy at 500 evaluations."""
    largest = budgets[-1]
    depth = max(least, largest // 2)
    search_s = yardstick_s = 0.0
    while True:
        started = time.perf_counter()
        run_search(spec, db, seed=seed, budget=depth, plan=SearchPlan(strategy))
        search_s += time.perf_counter() - started
        started = time.perf_counter()
        with Store(db) as store:
            tally = robust_variants(store, largest, budgets, workers=2)
        yardstick_s += time.perf_counter() - started
        if tally.runs < depth or depth >= largest:
            return tally, depth, search_s, yardstick_s
        depth = min(largest, depth + largest // 4)


@dataclass(frozen=True)
class Walked:
    """One run the yardstick walked, as the bench's tables read it."""

    run_id: int
    failure_class: str | None
    parents: list[int]
    genes: dict[str, Any]
    key: str | None
    """Its failure variant (None: it passed)."""
    new: bool
    """Its variant had not been shown by an earlier run of the store."""
    confirmed: bool
    """It is the run that confirmed a new robust variant."""


def walked(db: Path, tally: Tally) -> list[Walked]:
    """The runs ``tally`` walked, in order, read and decoded once for every table."""
    with Store(db) as store:
        rows = store.db.execute(
            "SELECT id, failure_class, parents, genes, coverage FROM runs ORDER BY id LIMIT ?",
            (tally.runs,),
        ).fetchall()
    confirmed = set(tally.robust.values())
    seen: set[str] = set()
    out = []
    for run_id, cls, parents, genes, coverage in rows:
        key = variant(cls, unpack_json(coverage) if coverage else None)
        out.append(
            Walked(
                run_id,
                cls,
                json.loads(parents) if parents else [],
                json.loads(genes),
                key,
                key is not None and key not in seen,
                run_id in confirmed,
            )
        )
        if key is not None:
            seen.add(key)
    return out


def _aim_met(run: Walked) -> bool:
    """A targeted child whose failure began in what it was aimed at (:func:`target_of`)."""
    aim = run.genes.get("aim")
    return (
        run.key is not None and aim is not None and target_of(run.key, run.genes["operator"]) == aim
    )


def locality(runs: list[Walked]) -> dict[str, list[int]]:
    """Per way of making a run (``fresh`` or an operator), over the :func:`walked` runs:
    [runs, children with their parent's failure class, runs showing a failure variant not seen
    before in the store, children failing with their parent's very variant, runs that
    confirmed a new robust variant, failing children aimed at a target, those whose failure
    began where they were aimed]."""
    by_id = {run.run_id: run for run in runs}
    out: dict[str, list[int]] = {}
    for run in runs:
        counts = out.setdefault(run.genes["operator"], [0] * 7)
        parent = by_id.get(run.parents[0]) if run.parents else None
        counts[0] += 1
        counts[1] += parent is not None and run.failure_class == parent.failure_class
        counts[2] += run.new
        counts[3] += run.key is not None and parent is not None and parent.key == run.key
        counts[4] += run.confirmed
        counts[5] += run.key is not None and run.genes.get("aim") is not None
        counts[6] += _aim_met(run)
    return out


def by_aim(runs: list[Walked]) -> dict[str, list[int]]:
    """Per ``OPERATOR:TARGET`` a targeted operator aimed at, over the :func:`walked` runs:
    [children aimed there, those whose failure began where they were aimed (aim met), those
    showing a variant new to the store, those that confirmed a new robust variant]."""
    out: dict[str, list[int]] = {}
    for run in runs:
        if run.genes.get("aim") is not None:
            counts = out.setdefault(f"{run.genes['operator']}:{run.genes['aim']}", [0] * 4)
            counts[0] += 1
            counts[1] += _aim_met(run)
            counts[2] += run.new
            counts[3] += run.confirmed
    return out


def trials_by_class(tally: Tally) -> dict[str, list[int]]:
    """Per failure class, the yardstick's trials: [trials, robust, copies spent on knife-edge
    ones]."""
    out: dict[str, list[int]] = {}
    for trial in tally.trials:
        counts = out.setdefault(trial.key.split("/", 1)[0], [0] * 3)
        counts[0] += 1
        counts[1] += trial.robust
        counts[2] += 0 if trial.robust else len(trial.classes)
    return out


def robust_within(tally: Tally, budget: int) -> set[str]:
    """The robust variants ``tally`` confirmed within ``budget`` evaluations."""
    return {key for key, spent in tally.first_at.items() if spent <= budget}


def share_of_reference(found: set[str], reference: set[str]) -> float | None:
    """The share of ``reference``'s variants among ``found`` (None: the reference is empty)."""
    return len(found & reference) / len(reference) if reference else None


def _add(into: dict[str, list[int]], figures: dict[str, list[int]]) -> None:
    for name, counts in figures.items():
        total = into.setdefault(name, [0] * len(counts))
        for i, figure in enumerate(counts):
            total[i] += figure


def harder_kills(spec: Any, db: Path, folder: Path, seed: int) -> dict[str, Any]:
    """Robust kills of the harder faults on the store's first situations: how many, which,
    the way each killing situation was made, and the trials that spared a fault although its
    copies showed the failure, because the correct controller's copies showed it too."""
    from sitgen import _core

    harder = [f["id"] for f in _core.fault_catalogue() if is_harder(f["id"])]
    faults_db = folder / f"faults-{db.stem}.db"
    run_faults(
        spec, faults_db, seed=seed, budget=FAULT_SITUATIONS, strategy="stored",
        situations_db=db, faults=harder,
    )  # fmt: skip
    report = report_from(faults_db)
    killed = [f for f in report.faults if f.id in harder and f.run is not None]
    with Store(db) as store, Store(faults_db) as evaluation:
        order = sorted(store.done_ids())
        ways = {
            run_id: json.loads(genes)["operator"] if genes else "fresh"
            for run_id, genes in store.db.execute("SELECT id, genes FROM runs")
        }
        trials = evaluation.db.execute(
            "SELECT fault, faulty_recurs, correct_recurs FROM fault_trials WHERE NOT killed"
        ).fetchall()
    spared = [(faulty, correct) for fault, faulty, correct in trials if fault in harder]
    by_way = {f.id: ways[order[f.runs_to_first_kill - 1]] for f in killed if f.runs_to_first_kill}
    return {
        "harder_killed": len(killed),
        "harder": len(harder),
        "killed_by": by_way,
        "spared": len(spared),
        "spared_both_shown": sum(faulty > 0 and correct > 0 for faulty, correct in spared),
    }


def main() -> None:
    first = int(os.environ.get("SITGEN_BENCH_SEARCH_FIRST_SEED", "1"))
    named = os.environ.get("SITGEN_BENCH_SEARCH_SEED_LIST")
    seeds: list[int] = (
        [int(s) for s in named.split(",")]
        if named
        else list(range(first, first + int(os.environ.get("SITGEN_BENCH_SEARCH_SEEDS", "5"))))
    )
    reference = int(os.environ.get("SITGEN_BENCH_SEARCH_REFERENCE", "5000"))
    largest = int(os.environ.get("SITGEN_BENCH_SEARCH_BUDGET", str(BUDGETS[-1])))
    budgets = [b for b in BUDGETS if b <= largest] or [largest]
    strategies = os.environ.get("SITGEN_BENCH_SEARCH_STRATEGIES", ",".join(STRATEGIES)).split(",")
    with_faults = os.environ.get("SITGEN_BENCH_SEARCH_FAULTS") == "1"
    spec = parse_campaign(None)
    out: dict[str, Any] = {"budgets": budgets, "seeds": seeds, "strategies": {}}
    kept: dict[str, list[int]] = {}
    aims: dict[str, list[int]] = {}
    trials: dict[str, list[int]] = {}
    with tempfile.TemporaryDirectory() as tmp:
        for strategy in strategies:
            rows: list[dict[str, Any]] = []
            for seed in seeds:
                db = Path(tmp) / f"{strategy}-{seed}.db"
                least = (
                    FAULT_SITUATIONS if with_faults and strategy in ("mutation", "random") else 0
                )
                tally, searched, search_s, yardstick_s = deep_enough(
                    spec, db, seed, strategy, budgets, least
                )
                row: dict[str, Any] = {
                    "seed": seed,
                    "robust": {str(b): tally.at_budget[b] for b in budgets},
                    "runs": tally.runs,
                    "runs_at": {str(b): tally.runs_at[b] for b in budgets},
                    "copies": tally.copies,
                    "first_by_class": _first_by_class(tally.first_at),
                    "searched": searched,
                    "search_s": search_s,
                    "yardstick_s": yardstick_s,
                    "robust_keys": sorted(robust_within(tally, REFERENCE_AT)),
                }
                if strategy == "mutation":
                    runs = walked(db, tally)
                    _add(kept, locality(runs))
                    _add(aims, by_aim(runs))
                    _add(trials, trials_by_class(tally))
                if with_faults and strategy in ("mutation", "random"):
                    row |= harder_kills(spec, db, Path(tmp), seed)
                rows.append(row)
                print(f"{strategy} seed {seed}: {row}", file=sys.stderr)
            out["strategies"][strategy] = {"per_seed": rows}
        if reference and "random" in strategies:
            out["reference"] = {"evaluations": reference, "per_seed": []}
            for seed in seeds:
                # A random store's runs do not depend on its budget: the one measured above,
                # searched deeper.
                db = Path(tmp) / f"random-{seed}.db"
                tally, searched, _, _ = deep_enough(spec, db, seed, "random", [reference], 0)
                keys = sorted(robust_within(tally, reference))
                row = {"seed": seed, "robust": len(keys), "runs": tally.runs, "keys": keys}
                out["reference"]["per_seed"].append(row)
                print(f"random to {reference}, seed {seed}: {len(keys)} robust", file=sys.stderr)
    out["locality"], out["aims"], out["trials_by_class"] = kept, aims, trials
    report(out, strategies, budgets, seeds)
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "search.json").write_text(json.dumps(out, indent=2) + "\n")
    print(f"wrote {RESULTS / 'search.json'}")


def _first_by_class(first_at: dict[str, int]) -> dict[str, int]:
    """Evaluations to each class's first robust variant."""
    out: dict[str, int] = {}
    for key, spent in first_at.items():
        cls = key.split("/", 1)[0]
        out[cls] = min(out.get(cls, spent), spent)
    return out


def report(
    out: dict[str, Any], strategies: list[str], budgets: list[int], seeds: list[int]
) -> None:
    per = {s: out["strategies"][s]["per_seed"] for s in strategies}
    print(f"\nrobust distinct failures (median over seeds {_seeds(seeds)}, runs + copies)")
    print(f"{'budget':>6}" + "".join(f"{s:>12}" for s in strategies))
    medians: dict[str, dict[int, float]] = {}
    for b in budgets:
        line = f"{b:>6}"
        for s in strategies:
            m = statistics.median(r["robust"][str(b)] for r in per[s])
            medians.setdefault(s, {})[b] = m
            line += f"{m:>12g}"
        print(line)
    print("runs among them (median; the rest are copies)")
    for b in budgets:
        runs = [statistics.median(r["runs_at"][str(b)] for r in per[s]) for s in strategies]
        print(f"{b:>6}" + "".join(f"{m:>12g}" for m in runs))
    if "random" in strategies:
        for s in strategies:
            if s == "random":
                continue
            ratios = ", ".join(
                f"{b}: {medians[s][b] / medians['random'][b]:.2f}x"
                if medians["random"][b]
                else f"{b}: -"
                for b in budgets
            )
            print(f"  {s} / random: {ratios}")
        found = [set(r["first_by_class"]) for r in per["random"]]
        rare = sorted(
            c for c in set().union(*found) if sum(c in f for f in found) < len(found) / 2
        ) + sorted(
            c
            for s in strategies
            for r in per[s]
            for c in r["first_by_class"]
            if not any(c in f for f in found)
        )
        rare = list(dict.fromkeys(rare))
        if rare:
            print(
                "\nevaluations to the first robust failure of random's rare classes (median;"
                " - where under half the seeds found it)"
            )
            print(f"{'class':34}" + "".join(f"{s:>12}" for s in strategies))
            for c in rare:
                line = f"{c:34}"
                for s in strategies:
                    hits = [r["first_by_class"][c] for r in per[s] if c in r["first_by_class"]]
                    enough = len(hits) * 2 >= len(per[s])
                    line += f"{statistics.median(hits):>12g}" if enough else f"{'-':>12}"
                print(line)
    if "reference" in out:
        _report_reference(out["reference"], per, strategies)
    if any("harder_killed" in r for s in strategies for r in per[s]):
        print(f"\nharder faults killed robustly, first {FAULT_SITUATIONS} situations (median)")
        for s in strategies:
            kills = [r["harder_killed"] for r in per[s] if "harder_killed" in r]
            if kills:
                print(
                    f"  {s:12} {statistics.median(kills):g} of {per[s][0]['harder']}"
                    f" (per seed {', '.join(map(str, kills))})"
                )
        faults = sorted({f for s in strategies for r in per[s] for f in r.get("killed_by", {})})
        print(
            "  seeds killing each fault, and the ways that made the killing situations;"
            " trials spared with both sides' copies showing the failure"
        )
        for f in faults:
            line = f"    {f:30}"
            for s in strategies:
                ways = [r["killed_by"][f] for r in per[s] if f in r.get("killed_by", {})]
                made = ", ".join(f"{w} {n}" for w, n in Counter(ways).most_common())
                line += f"  {s} {len(ways)} ({made})" if ways else f"  {s} 0"
            print(line)
        for s in strategies:
            rows = [r for r in per[s] if "spared" in r]
            if rows:
                spared = sum(r["spared"] for r in rows)
                both = sum(r["spared_both_shown"] for r in rows)
                print(f"    {s}: {both} of {spared} spared trials ({both / max(spared, 1):.0%})")
    if out["locality"]:
        print(
            f"\nmutation, by way of making a run, over the runs within {budgets[-1]}"
            " evaluations: runs; children failing with their parent's failure class"
            " (locality); runs showing a variant new to the store; children failing with their"
            " parent's very variant; runs that confirmed a new robust variant; failing children"
            " aimed at a target whose failure began where they were aimed (aim met)"
        )
        rows = sorted(out["locality"].items(), key=lambda kv: -kv[1][0])
        for operator, (n, same, new, repeat, robust, aimed, met) in rows:
            fresh = operator == "fresh"
            local = f"{same:>5} ({same / n:.0%})" if not fresh else f"{'-':>11}"
            again = f"{repeat:>5} ({repeat / n:.0%})" if not fresh else f"{'-':>11}"
            hit = f"{met:>5} of {aimed:<5} ({met / aimed:.0%})" if aimed else ""
            print(
                f"  {operator:20} {n:>5} {local:>11} {new:>5} ({new / n:.0%}) {again:>11}"
                f" {robust:>5} ({robust / n:.0%}) {hit}"
            )
    if out["aims"]:
        print(
            f"\nmutation, by operator and target aimed at, over the runs within {budgets[-1]}"
            " evaluations: children aimed there; aim met; showing a variant new to the store;"
            " confirming a new robust variant"
        )
        for name, (n, met, new, robust) in sorted(out["aims"].items()):
            print(
                f"  {name:40} {n:>5} {met:>5} ({met / n:.0%}) {new:>5} ({new / n:.0%})"
                f" {robust:>5} ({robust / n:.0%})"
            )
    if out["trials_by_class"]:
        print(
            f"\nmutation, the yardstick's trials by failure class within {budgets[-1]}"
            " evaluations: trials; robust; copies spent on knife-edge trials"
        )
        rows = sorted(out["trials_by_class"].items(), key=lambda kv: -kv[1][0])
        for cls, (n, robust, wasted) in rows:
            print(f"  {cls:34} {n:>5} {robust:>5} ({robust / n:.0%}) {wasted:>6}")


def _seeds(seeds: list[int]) -> str:
    consecutive = len(seeds) > 1 and seeds == list(range(seeds[0], seeds[0] + len(seeds)))
    return f"{seeds[0]}-{seeds[-1]}" if consecutive else ", ".join(map(str, seeds))


def _report_reference(
    reference: dict[str, Any], per: dict[str, list[dict[str, Any]]], strategies: list[str]
) -> None:
    rows = reference["per_seed"]
    print(
        f"\nshare of the robust variants random generation confirms within"
        f" {reference['evaluations']} evaluations ({', '.join(str(r['robust']) for r in rows)}"
        f" per seed) that each strategy confirms within {REFERENCE_AT}: median (per seed)"
    )
    for s in strategies:
        shares = [
            share_of_reference(set(mine["robust_keys"]), set(ref["keys"]))
            for mine, ref in zip(per[s], rows, strict=True)
        ]
        known = [x for x in shares if x is not None]
        if known:
            listed = ", ".join(f"{x:.0%}" if x is not None else "-" for x in shares)
            print(f"  {s:12} {statistics.median(known):.0%} ({listed})")


if __name__ == "__main__":
    main()

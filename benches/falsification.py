"""Falsification: ``sitgen search --requirement NAME`` (the mutation strategy driven by the
requirement's robustness) against random generation (the campaign's), on requirements random
generation violates in under 2 % of runs (measured on 500 random runs of paper120.toml, seed
0: ``fast_near_peer`` 7 of 500, ``turn_near_walls`` 4 of 500). For each requirement and seed:
runs to the first violation (the budget, 500, when none), violating runs within the budget,
and the distinct failure classes (sitgen's own, or none) of the violating runs; then the
median over the seeds and the ratio of medians. A search's screen reruns its new variants in
perturbed copies: those are counted and printed beside its runs.

Seeds drawn with Python's random.SystemRandom on 2026-11-29, before any run, written here:
"""

from __future__ import annotations

import json
import os
import sqlite3
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

from sitgen.generation.search.plan import generation_of, generation_runs

SEEDS = [25089, 43852, 104246, 274588, 334391]
BUDGET = int(os.environ.get("SITGEN_BENCH_BUDGET", "500"))
SPEC = Path(__file__).resolve().parent.parent / "examples" / "campaigns" / "paper120.toml"
REQUIREMENTS = {
    "fast_near_peer": "always (peer_clearance < 0.3 implies abs(speed) <= 0.4)",
    "turn_near_walls": "always (obstacle_clearance < 0.15 implies abs(turn_rate) < 1.0)",
}


def sitgen(*args: str) -> str:
    done = subprocess.run(
        [sys.executable, "-m", "sitgen.cli", *args], capture_output=True, text=True, check=False
    )
    if done.returncode != 0:
        raise SystemExit(f"sitgen {' '.join(args)} failed:\n{done.stderr}")
    return done.stdout


def findings(db: Path, name: str) -> dict[str, Any]:
    with sqlite3.connect(db) as c:
        violated = [
            (run_id, cls)
            for run_id, cls in c.execute(
                "SELECT v.run_id, r.failure_class FROM requirement_verdicts v "
                "JOIN runs r ON r.id = v.run_id WHERE v.name = ? AND v.violated ORDER BY v.run_id",
                (name,),
            )
        ]
        # Runs are numbered in the order they were asked for: run i is the (i + 1)th run.
        first = violated[0][0] + 1 if violated else BUDGET
        # The perturbed copies a search's screen ran before the first violation (a
        # generation's runs are screened once it is complete, before the next is asked for:
        # copies of runs of earlier generations than the violating run's), and in all: they
        # are evaluations too (none for random generation).
        before = generation_runs(generation_of(first - 1)).start
        copies_before, copies = c.execute(
            "SELECT coalesce(sum(CASE WHEN run_id < ? THEN reruns END), 0), "
            "coalesce(sum(reruns), 0) FROM robustness",
            (before,),
        ).fetchone()
    return {
        "first": first,
        "evaluations_to_first": first + copies_before,
        "found": bool(violated),
        "violations": len(violated),
        "classes": sorted({cls or "none" for _, cls in violated}),
        "screen_copies": copies,
    }


def main() -> None:
    out: dict[str, Any] = {}
    with tempfile.TemporaryDirectory() as tmp:
        for name, formula in REQUIREMENTS.items():
            req = Path(tmp) / f"{name}.toml"
            req.write_text(f'[[requirement]]\nname = "{name}"\nformula = "{formula}"\n')
            rows: list[dict[str, Any]] = []
            for seed in SEEDS:
                rdb, sdb = Path(tmp) / f"r{name}{seed}.db", Path(tmp) / f"s{name}{seed}.db"
                sitgen("campaign", str(SPEC), "--n", str(BUDGET), "--seed", str(seed),
                       "--db", str(rdb), "--reruns", "0", "--requirements", str(req))  # fmt: skip
                sitgen("search", str(SPEC), "--budget", str(BUDGET), "--seed", str(seed), "--db",
                       str(sdb), "--requirements", str(req), "--requirement", name)  # fmt: skip
                r, s = findings(rdb, name), findings(sdb, name)
                rows.append({"seed": seed, "random": r, "search": s})
                print(
                    f"{name} seed {seed}: first violation at run {r['first']}"
                    f"{'' if r['found'] else ' (none)'} random, {s['first']}"
                    f"{'' if s['found'] else ' (none)'} search ({s['evaluations_to_first']} "
                    f"with its screen's copies); violations {r['violations']} vs "
                    f"{s['violations']} in {BUDGET} runs (+{s['screen_copies']} copies); "
                    f"classes {r['classes']} vs {s['classes']}",
                    flush=True,
                )
            mr = statistics.median(x["random"]["first"] for x in rows)
            ms = statistics.median(x["search"]["first"] for x in rows)
            me = statistics.median(x["search"]["evaluations_to_first"] for x in rows)
            print(
                f"{name}: median runs to the first violation {mr:g} random, {ms:g} search "
                f"({me:g} with its screen's copies): {mr / ms:.1f}x fewer runs, {mr / me:.1f}x "
                f"fewer evaluations (censored at {BUDGET}: a seed without one counts {BUDGET})"
            )
            out[name] = {
                "rows": rows,
                "median_random": mr,
                "median_search": ms,
                "median_search_evaluations": me,
            }
    results = Path(__file__).resolve().parent / "results"
    results.mkdir(exist_ok=True)
    (results / "falsification.json").write_text(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()

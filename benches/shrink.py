"""Shrinking benchmark: the paper's default campaign (500 runs, seed 1), then ``sitgen shrink``
of the representatives of its top 20 distinct failures (``make bench-shrink``).

Prints, per shrink, the class and peers, obstacle cells, agent route length and time to failure
before → after, with the probes and wall time; then the medians: reduction of each measure
(1 − after / before) and probes and wall time per shrink. Writes ``benches/results/shrink.json``.
``SITGEN_BENCH_SHRINK_RUNS`` (default 500) and ``SITGEN_BENCH_SHRINK_TOP`` (default 20) make it
smaller for a quick look. Every shrink checks that its minimal situation fails with the class
it kept, rerun as ``sitgen run`` would.
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

from sitgen.execution.campaign import run_campaign
from sitgen.execution.jobs import parse_campaign
from sitgen.run import run
from sitgen.store import Store
from sitgen.triage.failures import distinct_failures
from sitgen.triage.shrink import shrink_run

RESULTS = Path(__file__).resolve().parent / "results"
MEASURES = ("peers", "obstacle_cells", "route_length_m", "time_to_failure_s")


def reduction(before: float, after: float) -> float:
    return 0.0 if before == 0 else 1.0 - after / before


def main() -> None:
    n = int(os.environ.get("SITGEN_BENCH_SHRINK_RUNS", "500"))
    top = int(os.environ.get("SITGEN_BENCH_SHRINK_TOP", "20"))
    workers = os.cpu_count() or 1
    rows: list[dict[str, Any]] = []
    with tempfile.TemporaryDirectory() as folder:
        db = Path(folder) / "paper.db"
        started = time.perf_counter()
        run_campaign(parse_campaign(None), db, seed=1, n=n)
        campaign_s = time.perf_counter() - started
        with Store(db) as store:
            failures = distinct_failures(store)[:top]
        print(f"campaign: {n} runs in {campaign_s:.1f} s; {len(failures)} distinct failures")
        for f in failures:
            r = shrink_run(db, f.representative, workers=workers)
            again = run(r.minimal, seed=r.run_seed, spec=r.run_spec)
            same = again.failure is not None and again.failure["class"] == r.failure_class
            row = {
                "run": f.representative,
                "distinct_failure": f.key,
                "class": r.failure_class,
                "before": vars(r.before),
                "after": vars(r.after),
                "probes": r.probes,
                "skipped": r.skipped,
                "wall_s": round(r.wall_s, 2),
                "exhausted": r.exhausted,
                "reruns_same_class": same,
            }
            rows.append(row)
            b, a = r.before, r.after
            print(
                f"run {f.representative:>4} {r.failure_class:<28} peers {b.peers}→{a.peers}  "
                f"cells {b.obstacle_cells}→{a.obstacle_cells}  route {b.route_length_m:.0f}→"
                f"{a.route_length_m:.0f} m  failure after {b.time_to_failure_s:.0f}→"
                f"{a.time_to_failure_s:.0f} s  {r.probes} probes  {r.wall_s:.1f} s"
                + ("" if same else "  RERUN DIFFERS")
            )
    medians = {
        f"{m}_reduction": statistics.median(reduction(r["before"][m], r["after"][m]) for r in rows)
        for m in MEASURES
    }
    medians["probes"] = statistics.median(r["probes"] for r in rows)
    medians["wall_s"] = statistics.median(r["wall_s"] for r in rows)
    print(
        "median over {} shrinks: peers −{:.0%}, obstacle cells −{:.0%}, route −{:.0%}, time to "
        "failure −{:.0%}; {:.0f} probes and {:.1f} s per shrink ({} workers)".format(
            len(rows),
            medians["peers_reduction"],
            medians["obstacle_cells_reduction"],
            medians["route_length_m_reduction"],
            medians["time_to_failure_s_reduction"],
            medians["probes"],
            medians["wall_s"],
            workers,
        )
    )
    RESULTS.mkdir(exist_ok=True)
    out = {
        "runs": n,
        "seed": 1,
        "top": top,
        "workers": workers,
        "campaign_s": round(campaign_s, 1),
        "medians": medians,
        "shrinks": rows,
        "all_rerun_same_class": all(r["reruns_same_class"] for r in rows),
    }
    (RESULTS / "shrink.json").write_text(json.dumps(out, indent=2) + "\n")
    if not out["all_rerun_same_class"]:
        sys.exit("a minimal situation did not fail with its class on a rerun")


if __name__ == "__main__":
    main()

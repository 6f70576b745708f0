"""The default campaign under both run profiles, beside the paper (``make bench-profiles``).

Runs the paper's experiment (500 situations, ``python/sitgen/paper_campaign.toml``) under
sitgen's ``default`` profile and under ``paper`` (``examples/campaigns/paper.toml``: SND with
Player 3.0.2's defaults acting every 0.5 s, Stage 4.1's Pioneer limits and 180-beam laser; see
``docs/profiles.md``) for each seed, and prints the score distribution of each beside the
figures Arnold & Alexander report (mean 61.0, 45% of runs under 10 points, top three 3064, 1574
and 988), with the median over seeds, the runs completed, collisions, distinct failure classes,
and wall time. Writes ``benches/results/profiles.json``. ``SITGEN_BENCH_PROFILES_SEEDS``
(default 3) and ``SITGEN_BENCH_PROFILES_N`` (default 500) shrink it for a quick look.
"""

from __future__ import annotations

import json
import os
import statistics
import tempfile
import time
from pathlib import Path
from typing import Any

from sitgen.execution.campaign import run_campaign
from sitgen.execution.jobs import parse_campaign
from sitgen.store import Store

ROOT = Path(__file__).resolve().parent.parent
RESULTS = ROOT / "benches" / "results"
SPECS = {
    "default": ROOT / "python" / "sitgen" / "paper_campaign.toml",
    "paper": ROOT / "examples" / "campaigns" / "paper.toml",
}
PAPER: dict[str, Any] = {"mean": 61.0, "under_10": 0.45, "top": [3064.0, 1574.0, 988.0]}


def distribution(db: Path) -> dict[str, Any]:
    """The score distribution and outcomes of the campaign in ``db``."""
    with Store(db) as store:
        rows = store.db.execute(
            "SELECT score, outcome, collisions, failure_class FROM runs ORDER BY score DESC"
        ).fetchall()
    scores = [r[0] for r in rows]
    return {
        "runs": len(rows),
        "mean": statistics.fmean(scores),
        "median": statistics.median(scores),
        "under_10": sum(s < 10 for s in scores) / len(scores),
        "top": scores[:3],
        "completed": sum(r[1] == "completed" for r in rows) / len(rows),
        "with_collision": sum(r[2] > 0 for r in rows) / len(rows),
        "classes": len({r[3] for r in rows if r[3]}),
    }


def main() -> None:
    seeds = range(1, 1 + int(os.environ.get("SITGEN_BENCH_PROFILES_SEEDS", "3")))
    n = int(os.environ.get("SITGEN_BENCH_PROFILES_N", "500"))
    results: dict[str, list[dict[str, Any]]] = {name: [] for name in SPECS}
    with tempfile.TemporaryDirectory() as tmp:
        for name, path in SPECS.items():
            spec = parse_campaign(path.read_text(), str(path))
            for seed in seeds:
                db = Path(tmp) / f"{name}-{seed}.db"
                began = time.perf_counter()
                run_campaign(spec, db, seed=seed, n=n)
                figures = distribution(db)
                figures["seed"] = seed
                figures["wall_s"] = time.perf_counter() - began
                results[name].append(figures)
                print(f"{name:8} seed {seed}: {fmt(figures)}", flush=True)
    print(f"\nmedian over seeds {list(seeds)}, {n} runs each:")
    print(f"{'':22}{'paper (2013)':>14}" + "".join(f"{name:>14}" for name in SPECS))
    rows = [
        ("mean score", "mean", "{:.1f}"),
        ("median score", "median", "{:.1f}"),
        ("runs under 10 points", "under_10", "{:.0%}"),
        ("completed", "completed", "{:.0%}"),
        ("with a collision", "with_collision", "{:.0%}"),
        ("failure classes", "classes", "{:.0f}"),
        ("wall time, s", "wall_s", "{:.1f}"),
    ]
    for label, key, form in rows:
        paper = form.format(PAPER[key]) if key in PAPER else "-"
        cells = "".join(
            f"{form.format(statistics.median(float(r[key]) for r in results[name])):>14}"
            for name in SPECS
        )
        print(f"{label:22}{paper:>14}{cells}")
    for i in range(3):
        cells = "".join(
            f"{statistics.median(r['top'][i] for r in results[name]):>14.0f}" for name in SPECS
        )
        print(f"{f'top {i + 1}':22}{PAPER['top'][i]:>14.0f}{cells}")
    RESULTS.mkdir(parents=True, exist_ok=True)
    out = {"paper": PAPER, "runs": n, "profiles": results}
    (RESULTS / "profiles.json").write_text(json.dumps(out, indent=2) + "\n")


def fmt(f: dict[str, Any]) -> str:
    top = ", ".join(f"{s:.0f}" for s in f["top"])
    return (
        f"mean {f['mean']:.1f}, median {f['median']:.1f}, {f['under_10']:.0%} under 10, "
        f"top {top}, completed {f['completed']:.0%}, {f['classes']} classes, "
        f"{f['wall_s']:.1f} s"
    )


if __name__ == "__main__":
    main()

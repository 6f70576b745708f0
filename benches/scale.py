"""A campaign of 100,000 runs through Ray on this machine: runs per second, memory over the
campaign (every process of it: the CLI, Ray's own and its workers), and the store's size per
run with no trajectories kept (``--keep-trajectories none``). Prints figures and writes
``benches/results/scale.json``; nothing is asserted.

    python benches/scale.py [--n 100000] [--time-limit 60] [--workers 2] [--backend ray]

The runs are the paper's campaign (``sitgen campaign`` with no spec) with the run's time limit
cut to ``--time-limit`` simulated seconds (600 in the paper), so that 10^5 runs fit in under an
hour on two cores; the per-run store size and memory do not depend on it, and runs per second
at the paper's limit come from ``make bench`` (docs/scale.md projects both to a cluster).
"""

from __future__ import annotations

import argparse
import json
import os
import sqlite3
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import psutil

from sitgen.execution.jobs import paper_campaign_text

RESULTS = Path(__file__).resolve().parent / "results"


def tree_rss_mib(root: psutil.Process) -> float:
    """Resident memory of ``root`` and every process under it (Ray's and its workers')."""
    total = 0
    for p in [root, *root.children(recursive=True)]:
        try:
            total += p.memory_info().rss
        except psutil.NoSuchProcess:
            continue
    return total / 2**20


def rss_by_process_mib(root: psutil.Process) -> dict[str, float]:
    """Resident memory of the campaign's processes, grouped by name (Ray's workers are
    ``ray::…``): where the memory is."""
    groups: dict[str, float] = {}
    for p in [root, *root.children(recursive=True)]:
        try:
            name = "sitgen (the CLI)" if p.pid == root.pid else p.name()
            groups[name] = groups.get(name, 0.0) + p.memory_info().rss / 2**20
        except psutil.NoSuchProcess:
            continue
    return dict(sorted(groups.items(), key=lambda kv: -kv[1]))


def runs_stored(db: Path) -> int:
    if not db.exists():
        return 0
    try:
        with sqlite3.connect(f"file:{db}?mode=ro", uri=True, timeout=1.0) as c:
            count: int = c.execute("SELECT count(*) FROM runs").fetchone()[0]
            return count
    except sqlite3.OperationalError:
        return 0  # the schema is not written yet


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=100_000)
    parser.add_argument("--time-limit", type=float, default=60.0)
    parser.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    parser.add_argument("--backend", default="ray")
    parser.add_argument("--sample-s", type=float, default=5.0)
    args = parser.parse_args()

    text = paper_campaign_text().replace(
        "time_limit_s = 600.0", f"time_limit_s = {args.time_limit}"
    )
    with tempfile.TemporaryDirectory() as tmp:
        spec, db = Path(tmp) / "scale.toml", Path(tmp) / "scale.db"
        spec.write_text(text)
        command = [
            sys.executable, "-m", "sitgen", "campaign", str(spec), "--n", str(args.n),
            "--db", str(db), "--workers", str(args.workers), "--backend", args.backend,
            "--keep-trajectories", "none",
        ]  # fmt: skip
        start = time.perf_counter()
        # Files, not pipes: a progress bar filling a pipe nobody reads would stall the campaign.
        stdout, stderr = Path(tmp) / "stdout", Path(tmp) / "stderr"
        with stdout.open("wb") as o, stderr.open("wb") as e:
            proc = subprocess.Popen(command, stdout=o, stderr=e)
        root = psutil.Process(proc.pid)
        samples: list[dict[str, float]] = []
        by_process: dict[str, float] = {}
        while proc.poll() is None:
            time.sleep(args.sample_s)
            if proc.poll() is not None:
                break
            try:
                cpu = root.cpu_times()
            except psutil.NoSuchProcess:
                break
            sample = {
                "wall_s": time.perf_counter() - start,
                "runs": runs_stored(db),
                "rss_mib": tree_rss_mib(root),
                # The driver alone (the CLI: Ray's scheduling, results, the store's writes),
                # whose cost per run bounds a cluster's rate.
                "driver_cpu_s": cpu.user + cpu.system,
            }
            samples.append(sample)
            if sample["runs"] < args.n:
                by_process = rss_by_process_mib(root)
            print(
                f"{sample['wall_s']:7.0f} s  {sample['runs']:7d} runs  "
                f"{sample['rss_mib']:7.0f} MiB",
                flush=True,
            )
        wall = time.perf_counter() - start
        out = stdout.read_text()
        if proc.returncode != 0:
            raise SystemExit(f"campaign failed ({proc.returncode}): {stderr.read_text()[-2000:]}")
        ran = runs_stored(db)
        size = db.stat().st_size
    # Memory once the campaign is under way (Ray's start-up is done) at each tenth of it.
    busy = [s for s in samples if s["runs"] > 0]
    tenths = [
        next((s for s in busy if s["runs"] >= args.n * k / 10), busy[-1]) for k in range(1, 11)
    ] if busy else []  # fmt: skip
    last = busy[-1] if busy else {"runs": 0, "driver_cpu_s": 0.0}
    driver_ms = 1e3 * last["driver_cpu_s"] / max(last["runs"], 1)
    result: dict[str, Any] = {
        "n": args.n,
        "runs": ran,
        "time_limit_s": args.time_limit,
        "workers": args.workers,
        "backend": args.backend,
        "wall_s": wall,
        "runs_per_s": ran / wall,
        "runs_per_hour_per_core": ran / wall * 3600 / args.workers,
        "store_bytes": size,
        "store_bytes_per_run": size / max(ran, 1),
        "driver_cpu_ms_per_run": driver_ms,
        "peak_rss_mib": max((s["rss_mib"] for s in samples), default=0.0),
        "rss_mib_by_tenth": [round(s["rss_mib"], 1) for s in tenths],
        "rss_mib_by_process": by_process,
        "samples": samples,
        "summary": out.strip().splitlines()[:2],
    }
    print(
        f"{ran:,} runs ({args.time_limit:g} s limit) through {args.backend} with {args.workers} "
        f"workers: {wall:,.0f} s, {ran / wall:.1f} runs/s, "
        f"{result['runs_per_hour_per_core']:,.0f} runs/hour/core"
    )
    print(
        f"memory (all processes): peak {result['peak_rss_mib']:.0f} MiB; at each tenth of the "
        f"campaign {', '.join(f'{m:.0f}' for m in result['rss_mib_by_tenth'])} MiB"
    )
    print(
        "memory by process, last sample under way: "
        + ", ".join(f"{name} {mib:.0f}" for name, mib in by_process.items())
        + " MiB"
    )
    print(f"store: {size / 2**20:.1f} MiB, {size / max(ran, 1):.0f} bytes per run")
    print(
        f"driver: {driver_ms:.2f} ms of CPU per run (scheduling, results, store), so one driver "
        f"takes at most {1e3 / driver_ms:,.0f} runs/s"
    )
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "scale.json").write_text(json.dumps(result, indent=1) + "\n")


if __name__ == "__main__":
    main()

"""What explaining costs: the default campaign (500 runs, seed 0, no robustness copies) made
once, then grown to SITGEN_BENCH_EXPLAIN_RUNS runs (default 10,000) by copying its runs and
their stored descriptors under new ids (the same 500 situations twenty times: what a 10,000-run
store costs to read and learn from, not what it would find), and `sitgen explain --class
collision` timed on both, in its own process. Prints the wall and processor seconds."""

from __future__ import annotations

import os
import resource
import sqlite3
import subprocess
import sys
import tempfile
import time
from pathlib import Path

SITGEN = [sys.executable, "-m", "sitgen"]


def timed(args: list[str]) -> tuple[float, float]:
    """Wall and processor seconds of a sitgen command (its process tree)."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    started = time.perf_counter()
    subprocess.run([*SITGEN, *args], check=True, capture_output=True)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return time.perf_counter() - started, cpu


def grow(db: Path, runs: int) -> None:
    """Copy the store's runs (and their situations' descriptors) until it has ``runs``."""
    con = sqlite3.connect(db)
    with con:
        n = con.execute("SELECT count(*) FROM runs").fetchone()[0]
        cols = [c[1] for c in con.execute("PRAGMA table_info(runs)")]
        scols = [c[1] for c in con.execute("PRAGMA table_info(situations)")]
        for k in range(1, -(-runs // n)):
            shift = k * n
            con.execute(
                f"INSERT INTO situations ({', '.join(scols)}) SELECT "
                + ", ".join(f"id + {shift}" if c == "id" else c for c in scols)
                + f" FROM situations WHERE id < {n}"
            )
            con.execute(
                f"INSERT INTO runs ({', '.join(cols)}) SELECT "
                + ", ".join(f"{c} + {shift}" if c in ("id", "situation_id") else c for c in cols)
                + f" FROM runs WHERE id < {n}"
            )
            con.execute(
                "INSERT INTO situation_descriptors (situation_id, descriptors) SELECT "
                f"situation_id + {shift}, descriptors FROM situation_descriptors "
                f"WHERE situation_id < {n}"
            )
    con.close()


def main() -> None:
    runs = int(os.environ.get("SITGEN_BENCH_EXPLAIN_RUNS", "10000"))
    with tempfile.TemporaryDirectory() as tmp:
        db = Path(tmp) / "c.db"
        subprocess.run(
            [*SITGEN, "campaign", "--seed", "0", "--reruns", "0", "--db", str(db)],
            check=True, capture_output=True,
        )  # fmt: skip
        wall, cpu = timed(["explain", str(db), "--class", "collision"])
        print(f"explain, 500 runs: {wall:.2f} s wall, {cpu:.2f} s cpu")
        grow(db, runs)
        wall, cpu = timed(["explain", str(db), "--class", "collision"])
        print(f"explain, {runs} runs: {wall:.2f} s wall, {cpu:.2f} s cpu")


if __name__ == "__main__":
    main()

"""`make bench-fast-path`: what a ``python:`` class on the fast path costs, as a user's campaign
sees it: the trivial class (benches/user_controllers.py) in its runner
(sitgen.controllers.sandbox), control steps a second as `make bench`'s row counts them (the
median of whole 60 s runs less the median of 0.1 s runs, on the reference scene) and the wall
time of a 200-run campaign of 600 s runs on two workers.

Run it in turn with another tree to compare (a worktree of an earlier commit, its compiled core
copied in, ``PYTHONPATH=TREE/python``): each figure's spread between runs on a 2-core virtual
machine is about ±20 % for the row and ±5 % for the campaign, so compare several pairs.
"""

from __future__ import annotations

import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import sitgen

HERE = Path(__file__).resolve().parent
TRIVIAL = f"python:{HERE / 'user_controllers.py'}:Trivial"
REFERENCE_SCENE = {"terrain": {"preset": "caves"}, "mission": {"peers_min": 5, "peers_max": 5}}
CAMPAIGN = f"""
n = 200
[situation.terrain]
preset = "caves"
[situation.mission]
peers_min = 2
peers_max = 5
[run]
time_limit_s = 600.0
[run.controller]
name = "{TRIVIAL}"
"""


def row(repeats: int = 61) -> tuple[float, float, int]:
    """Control steps a second, and a whole run's median wall time (s), and its steps."""
    situation = sitgen.generate_situation(REFERENCE_SCENE, seed=1)
    spec = {"controller": {"name": TRIVIAL}}

    def median(limit_s: float) -> tuple[float, int]:
        times, steps = [], 0
        for _ in range(repeats):
            start = time.perf_counter()
            record = sitgen.run(situation, spec=spec, time_limit=limit_s, in_process=True)
            times.append(time.perf_counter() - start)
            steps = record.steps
        return statistics.median(times), steps

    median(0.1)  # the runner started, the class imported
    whole, steps = median(60.0)
    start, _ = median(0.1)
    return steps / (whole - start), whole, steps


def campaign() -> float:
    """Wall seconds of the 200-run campaign (`sitgen campaign` in a process of its own)."""
    with tempfile.TemporaryDirectory() as folder:
        spec = Path(folder) / "trivial.toml"
        spec.write_text(CAMPAIGN)
        args = ["campaign", str(spec), "--db", str(Path(folder) / "c.db"), "--workers", "2",
                "--reruns", "0"]  # fmt: skip
        start = time.perf_counter()
        subprocess.run([sys.executable, "-m", "sitgen", *args], check=True,
                       capture_output=True)  # fmt: skip
        return time.perf_counter() - start


def main() -> None:
    per_s, whole_s, steps = row()
    print(f"python trivial, in process: {per_s:8,.0f} control steps/s "
          f"({steps} steps, {whole_s * 1e3:.1f} ms a run)")  # fmt: skip
    print(f"trivial-class campaign, 200 runs of 600 s on 2 workers: {campaign():.2f} s")


if __name__ == "__main__":
    main()

"""`make bench-load`: what a loaded machine does to a slow controller's steps, and what a
campaign's robustness copies cost.

1. A class spending 3 ms of processor time a step (tests/controllers/careless.py:Costs3ms),
   run alone and beside eight spinning loops a core (each in a session of its own): each step's
   wall time, and how many steps a 30 ms wall-clock deadline would have failed (the step
   deadline counts processor time instead: docs/controller-protocol.md, "Deadlines").
2. The default campaign on seeds 0–4 (``SITGEN_BENCH_SEEDS``; empty: none), with
   ``--reruns 0`` and ``--reruns 8`` in turns, ``SITGEN_BENCH_PAIRS`` pairs (default 2): wall
   and processor seconds of the whole process tree, and what the copies add. Run it on an
   idle machine.
"""

from __future__ import annotations

import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any, ClassVar

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from tests.conftest import spinning  # noqa: E402
from tests.controllers.careless import Costs3ms  # noqa: E402

import sitgen  # noqa: E402


class Timed(Costs3ms):
    """Costs3ms, each call's wall time kept."""

    walls: ClassVar[list[float]] = []

    def act(self, obs: Any) -> tuple[float, float]:
        began = time.perf_counter()
        command = super().act(obs)
        Timed.walls.append(time.perf_counter() - began)
        return command


LOOPS_A_CORE = 8
DEADLINE_S = 0.03
"""tests/test_load.py's load and step deadline."""


def step_walls(loaded: bool) -> None:
    Timed.walls = []
    situation = sitgen.generate_situation({"terrain": {"preset": "open_field"}}, seed=1)
    with spinning(LOOPS_A_CORE * (os.cpu_count() or 1) if loaded else 0):
        record = sitgen.run(situation, controller=Timed(), time_limit=8, step_timeout_s=DEADLINE_S)
    walls = sorted(Timed.walls)
    where = f"beside {LOOPS_A_CORE} loops a core" if loaded else "alone"
    print(
        f"3 ms class {where:22}: {record.outcome}, "
        f"{len(walls)} steps, median {1e3 * walls[len(walls) // 2]:.1f} ms, max "
        f"{1e3 * walls[-1]:.1f} ms; over {1e3 * DEADLINE_S:.0f} ms of wall time: "
        f"{sum(w > DEADLINE_S for w in walls)}"
    )


def campaign_cost(seed: int, reruns: int, folder: Path) -> tuple[float, float]:
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    began = time.perf_counter()
    db = folder / f"s{seed}r{reruns}.db"
    db.unlink(missing_ok=True)  # a campaign on a store it finished would run nothing
    subprocess.run(
        [str(Path(sys.executable).parent / "sitgen"), "campaign", "--db", str(db), "--seed",
         str(seed), "--reruns", str(reruns)],
        capture_output=True, check=True,
    )  # fmt: skip
    wall = time.perf_counter() - began
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime
    return wall, cpu


def main() -> None:
    step_walls(False)
    step_walls(True)
    chosen = os.environ.get("SITGEN_BENCH_SEEDS", "0,1,2,3,4")
    seeds = [int(s) for s in chosen.split(",") if s.strip()]
    pairs = int(os.environ.get("SITGEN_BENCH_PAIRS", "2"))
    with tempfile.TemporaryDirectory() as tmp:
        for seed in seeds:
            # In turns, without then with copies, so a drift in the machine's speed falls on
            # both alike; the sums of the pairs are compared.
            cost = {0: [0.0, 0.0], 8: [0.0, 0.0]}
            for _ in range(pairs):
                for k in (0, 8):
                    wall, cpu = campaign_cost(seed, k, Path(tmp))
                    cost[k][0] += wall
                    cost[k][1] += cpu
            (w0, c0), (w8, c8) = ((w / pairs, c / pairs) for w, c in (cost[0], cost[8]))
            print(
                f"default campaign, seed {seed}: {w0:.1f} s wall, {c0:.1f} s cpu without copies; "
                f"copies add {100 * (w8 / w0 - 1):.0f} % wall, {100 * (c8 / c0 - 1):.0f} % cpu "
                f"({pairs} pairs in turns)"
            )


if __name__ == "__main__":
    main()

"""Speed of the Gymnasium environments (``make bench-gym``): environment steps per second of
``sitgen/Navigate-v0`` one world at a time and of its vectorised form with 1, 8 and 32 worlds
per call, on the default situation spec (the paper campaign's: a 50 m rocky desert, 0-5
peers) with random actions, one simulator step (0.1 s) per action. Each figure is the median
of 5 repeats of 4,000 steps per world; resets (a new situation each) are included, as a
learner meets them. Writes ``benches/results/gym.json``. (Not named ``gym.py``: run as a
script, that name would shadow the ``gym`` package for anything importing it.)
"""

from __future__ import annotations

import functools
import json
import os
import statistics
import time
from collections.abc import Callable
from pathlib import Path

from sitgen.controllers.gym import NavigateEnv, NavigateVectorEnv

ROOT = Path(__file__).resolve().parent.parent
RESULTS = ROOT / "benches" / "results"
STEPS = int(os.environ.get("SITGEN_BENCH_GYM_STEPS", "4000"))
REPEATS = 5


def single() -> float:
    env = NavigateEnv(seed=1)
    env.action_space.seed(0)
    env.reset()
    began = time.perf_counter()
    for _ in range(STEPS):
        _, _, terminated, truncated, _ = env.step(env.action_space.sample())
        if terminated or truncated:
            env.reset()
    return STEPS / (time.perf_counter() - began)


def vector(n: int) -> float:
    env = NavigateVectorEnv(n, seed=1)
    env.reset()
    env.action_space.seed(0)
    began = time.perf_counter()
    for _ in range(STEPS):
        env.step(env.action_space.sample())
    return n * STEPS / (time.perf_counter() - began)


def main() -> None:
    cases: dict[str, Callable[[], float]] = {"single env": single}
    for n in (1, 8, 32):
        cases[f"vector, {n} worlds"] = functools.partial(vector, n)
    results = {}
    for name, measure in cases.items():
        runs = [measure() for _ in range(REPEATS)]
        med = statistics.median(runs)
        results[name] = {"steps_per_s": med, "min": min(runs), "max": max(runs)}
        print(
            f"{name:18} {med:>10,.0f} env steps/s  ({min(runs):,.0f}-{max(runs):,.0f}), "
            f"{med * 0.1:>8,.0f}x real time",
            flush=True,
        )
    RESULTS.mkdir(parents=True, exist_ok=True)
    (RESULTS / "gym.json").write_text(
        json.dumps({"steps": STEPS, "cases": results}, indent=2) + "\n"
    )


if __name__ == "__main__":
    main()

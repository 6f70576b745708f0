"""Learned weights: how many judgements a synthetic expert needs, informative pairs against
random ones (``make bench-weights``).

A campaign (the paper's, 500 runs, seed 1, unless ``--db`` names a store) is judged by a
synthetic expert whose weights differ from the defaults (to-and-fro turning far worse than
being pinned) with logistic noise; the fitted weights' Kendall τ against the expert's order of
every run that scores anything is printed for 20, 50 and 200 judgements, with pairs from
``next_pair`` and with random pairs (five seeds), beside the stored scores' τ.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from sitgen.store import Judgement, Store
from sitgen.triage.weights import SimulatedJudge, Weights, fit, next_pair

EXPERT = Weights(
    {
        "collision": (20.0, 0.01),
        "unsafe_proximity": (100.0, 10.0),
        "loitering": (1.0, 0.0),
        "oscillation": (500.0, 50.0),
        "timeout": (0.0, 0.0),
        "waypoint_reached": (0.0, 0.0),
        "route_completed": (0.0, 0.0),
    }
)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--db", type=Path, help="A store to judge (default: a new campaign).")
    parser.add_argument("--n", type=int, default=500, help="Runs of the new campaign.")
    args = parser.parse_args()
    db = args.db
    if db is None:
        db = Path(tempfile.mkdtemp()) / "paper.db"
        subprocess.run(
            [sys.executable, "-m", "sitgen.cli", "campaign", "--n", str(args.n), "--seed", "1",
             "--db", str(db), "--keep-trajectories", "none"],
            check=True, capture_output=True,
        )  # fmt: skip
    with Store(db) as store:
        expert = SimulatedJudge(store, EXPERT, 0)
        rows = expert.rows
        scored = [i for i in rows if expert.truth[i] > 0 or rows[i][2] > 0]

        def judge(a: int, b: int, rng: np.random.Generator) -> Judgement:
            expert.rng = rng
            return expert(a, b)

        def tau(score: dict[int, float]) -> float:
            return expert.tau(scored, score.__getitem__)

        def fitted_tau(judged: list[Judgement]) -> float:
            return expert.tau(scored, expert.weighted(fit(store, judged).weights))

        print(f"{db}: {len(rows)} runs, {len(scored)} that score anything")
        print(f"stored scores: tau {tau({i: rows[i][2] for i in scored}):.3f}")
        print("judgements  informative (tau, s per pair)   random pairs (tau, 5 seeds)")
        ids = sorted(rows)
        for n in (20, 50, 200):
            rng = np.random.default_rng(0)
            judged: list[Judgement] = []
            started = time.perf_counter()
            for _ in range(n):
                pair = next_pair(store, judged)
                if pair is None:
                    break
                judged.append(judge(*pair, rng))
            per_pair = (time.perf_counter() - started) / max(1, len(judged))
            informative = fitted_tau(judged)
            random_taus = []
            for seed in range(5):
                rng = np.random.default_rng(seed)
                pairs = [rng.choice(ids, 2, replace=False) for _ in range(n)]
                random_taus.append(fitted_tau([judge(int(a), int(b), rng) for a, b in pairs]))
            print(
                f"{n:10}  {informative:6.3f}  {per_pair:6.2f} s            "
                + " ".join(f"{t:.3f}" for t in random_taus)
                + f"  (median {np.median(random_taus):.3f})"
            )


if __name__ == "__main__":
    main()

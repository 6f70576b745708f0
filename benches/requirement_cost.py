"""What judging five requirements adds to the default campaign's processor time: the 500
runs (seed 0, one worker, no robustness copies) without and with the five requirements of
docs/requirements.md's examples and one more, in turns (two pairs), each campaign in its own
process, processor time of that process tree. Prints the medians and the difference."""

from __future__ import annotations

import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

FIVE = """
[[requirement]]
name = "slow_near_peers"
formula = "always (peer_clearance < 0.4 implies abs(speed) <= 0.3)"
[[requirement]]
name = "brake_for_peers"
formula = "always (peer_clearance < 1 implies eventually[0:1.5] abs(speed) < 0.1)"
[[requirement]]
name = "reach_goal_in_time"
formula = "eventually[0:120] goal_distance < 0.5"
[[requirement]]
name = "gentle_near_walls"
formula = "always (obstacle_clearance < 0.3 implies abs(turn_rate) < 1.047)"
[[requirement]]
name = "not_unseen"
formula = "always (closing_speed > 0.5 and peer_distance < 2 implies peer_seen > 0.5)"
"""


def campaign_cpu(n: int, folder: Path, requirements: Path | None, k: int) -> float:
    """Processor seconds of one campaign's process tree."""
    db = folder / f"c{k}.db"
    command = [
        sys.executable, "-m", "sitgen.cli", "campaign", "--n", str(n), "--seed", "0",
        "--db", str(db), "--workers", "1", "--reruns", "0",
        *(["--requirements", str(requirements)] if requirements else []),
    ]  # fmt: skip
    proc = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    _, status, usage = os.wait4(proc.pid, 0)
    if status != 0:
        raise SystemExit(f"campaign failed: {proc.stderr.read().decode() if proc.stderr else ''}")
    return usage.ru_utime + usage.ru_stime


def bench_requirements(rows: list[tuple[str, dict[str, float]]]) -> dict[str, Any]:
    n = int(os.environ.get("SITGEN_BENCH_CAMPAIGN_N", "500"))
    with tempfile.TemporaryDirectory() as tmp:
        five = Path(tmp) / "five.toml"
        five.write_text(FIVE)
        without, with_ = [], []
        for k in range(2):
            without.append(campaign_cpu(n, Path(tmp), None, 2 * k))
            with_.append(campaign_cpu(n, Path(tmp), five, 2 * k + 1))
    a, b = statistics.median(without), statistics.median(with_)
    for name, t in (("without requirements", a), ("with five requirements", b)):
        rows.append((f"campaign {n} situations, 1 worker, {name} (cpu)", {
            "median_s": t, "min_s": t, "max_s": t, "repeats": 2,
        }))  # fmt: skip
    print(
        f"requirements: default campaign ({n} runs, 1 worker) {a:.1f} s cpu without, {b:.1f} s "
        f"with five requirements: +{100 * (b / a - 1):.1f} % (pairs {without} / {with_})"
    )
    return {"n": n, "without_cpu_s": without, "with_cpu_s": with_, "added": b / a - 1}


if __name__ == "__main__":
    bench_requirements([])

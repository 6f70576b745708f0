"""`make bench-stage`: the cross-check against the real Stage on every preset's default spec,
seeds 1 and 2, 30 s each; prints per situation what docs/stage.md's table summarises."""

from __future__ import annotations

import sys
import time
from pathlib import Path

from sitgen.controllers.stage import StageError, StageTool, crosscheck
from sitgen.world.situation import generate_situation

ROOT = Path(__file__).resolve().parent.parent
PRESETS = ["caves", "indoor", "maze", "open_field", "rocky_desert", "urban"]


def main() -> None:
    try:
        tool = StageTool.find(ROOT / "target" / "stage" / "prefix" / "bin" / "stage")
    except StageError as e:
        sys.exit(f"{e} (run `make stage` first)")
    print(
        "situation        robots wall_s start_m  both_hit median_cm p95_cm within3cm "
        "stage_only sitgen_only(near_max) same_seen agent_5s_m peers_max_m first_stalls scores"
    )
    for preset in PRESETS:
        for seed in (1, 2):
            s = generate_situation({"terrain": {"preset": preset}}, seed)
            t0 = time.perf_counter()
            r = crosscheck(s, {"time_limit_s": 30}, tool)
            wall = time.perf_counter() - t0
            sc = r["scans"]
            both = sc["beams"] - sc["both_max"] - sc["stage_only_hit"] - sc["sitgen_only_hit"]
            agent_5s = max(e for t, e, _ in r["divergence"][0]["series"] if t <= 5)
            peers = max((d["max_position_m"] for d in r["divergence"][1:]), default=0.0)
            near_max = sc["sitgen_only_hit_near_max"]
            stalls = ",".join(
                f"{a}/{b}"
                for a, b in zip(r["sitgen"]["first_stall"], r["stage"]["first_stall"], strict=True)
                if a is not None or b is not None
            )
            print(
                f"{preset:>12} {seed}  {len(r['divergence']):>6} {wall:>6.1f} "
                f"{r['start_pose_error_m']:>7.0e} {both:>9} {sc['median_abs_m'] * 100:>9.2f} "
                f"{sc['p95_abs_m'] * 100:>6.1f} {sc['within_3cm']:>9.3f} "
                f"{sc['stage_only_hit'] / sc['beams']:>10.2%} "
                f"{sc['sitgen_only_hit'] / sc['beams']:>11.2%}({near_max:>4}) "
                f"{sc['same_robots_seen']:>4}/{sc['scans']:<4} {agent_5s:>10.3f} {peers:>11.3f} "
                f"{stalls or '-':>12} "
                f"{r['sitgen']['score']:g}/{r['stage']['score']:g}",
                flush=True,
            )


if __name__ == "__main__":
    main()

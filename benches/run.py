"""sitgen benchmarks: prints a table of medians with their spread, and writes JSON.

Run with ``make bench`` (or ``python benches/run.py``). Figures are wall-clock times on this
machine; compare runs on the same machine only. Nothing here is asserted: speed is measured,
not tested.
"""

from __future__ import annotations

import json
import os
import platform
import statistics
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import sitgen
from sitgen import _core
from sitgen.config import preset_spec

RESULTS = Path(__file__).resolve().parent / "results"
SHARED = Path(
    os.environ.get("SITGEN_SHARED_DATA", Path(__file__).resolve().parents[2] / "shared" / "data")
)
ASTAR_MAP = "mazes/maze512-1-0.map"
"""The hardest of the largest (512 × 512) MovingAI maps in the shared data."""

# 100 m × 100 m at 0.1 m (10^6 cells), 6 octaves, and every filter that keeps the map's phase.
FULL_CHAIN: dict[str, Any] = {
    "terrain": {
        "width_m": 100.0,
        "height_m": 100.0,
        "resolution_m": 0.1,
        "source": {"kind": "perlin", "octaves": 6, "scale_m": 10.0},
        "filters": [
            {"kind": "pixelise", "block_m": 0.3},
            {"kind": "coverage", "target": 0.3, "tolerance": 0.01},
            {"kind": "dilate", "radius_m": 0.2},
            {"kind": "erode", "radius_m": 0.2},
            {"kind": "remove_islands", "min_area_m2": 0.5},
            {"kind": "border", "width_m": 0.2},
            {"kind": "keep_largest_free_region"},
        ],
    }
}


def measure(run: Callable[[int], object], repeats: int) -> dict[str, float]:
    """Median, min and max seconds of ``run(i)`` over ``repeats`` calls after one warm-up."""
    run(-1)
    times = []
    for i in range(repeats):
        start = time.perf_counter()
        run(i)
        times.append(time.perf_counter() - start)
    return {
        "median_s": statistics.median(times),
        "min_s": min(times),
        "max_s": max(times),
        "repeats": repeats,
    }


def bench_reference_scene(rows: list[tuple[str, dict[str, float]]]) -> dict[str, Any]:
    """Steps per second on the reference scene: 40 × 40 m caves at 0.1 m, the agent scanning
    its 181-beam laser every step, five peers; one core (the simulator is single-threaded)."""
    spec = {"terrain": {"preset": "caves"}, "mission": {"peers_min": 5, "peers_max": 5}}
    situation = sitgen.generate_situation(spec, seed=1)
    steps = 20_000

    def run(_: int) -> None:
        world = sitgen.World(situation)
        world.step({r.id: (0.5, 0.15 * (r.id % 3 - 1)) for r in situation.robots})
        world.advance(steps)

    m = measure(run, repeats=5)
    steps_per_s = steps / m["median_s"]
    rows.append((f"simulator reference scene: {steps} steps", m))
    print(
        f"simulator: {steps_per_s:,.0f} steps/s, {steps_per_s * 0.1:,.0f}x real time "
        f"(spread {steps / m['max_s']:,.0f}-{steps / m['min_s']:,.0f} steps/s)"
    )
    return {"steps": steps, "steps_per_s": steps_per_s, "real_time_factor": steps_per_s * 0.1, **m}


def machine() -> dict[str, Any]:
    return {
        "cpu": platform.processor() or platform.machine(),
        "cores": os.cpu_count(),
        "python": platform.python_version(),
        "sitgen": sitgen.__version__,
        "system": platform.platform(),
    }


def main() -> None:
    results: dict[str, Any] = {"machine": machine(), "terrain": {}}
    rows: list[tuple[str, dict[str, float]]] = []

    full = measure(lambda i: sitgen.generate_terrain(FULL_CHAIN, seed=i + 1), repeats=7)
    rows.append(("terrain 100×100 m @0.1 m, 6 octaves, full chain", full))
    results["terrain"]["full_chain_100m"] = full

    for name in sitgen.preset_names():
        spec = preset_spec(name)

        def generate(i: int, spec: dict[str, Any] = spec) -> object:
            return sitgen.generate_terrain(spec, seed=i + 1)

        m = measure(generate, repeats=9)
        size = sitgen.generate_terrain(spec).size_m
        rows.append((f"preset {name} ({size[0]:g}×{size[1]:g} m)", m))
        results["terrain"][f"preset_{name}"] = m

    for name in sitgen.preset_names():
        spec = preset_spec(name)

        def situation(i: int, spec: dict[str, Any] = spec) -> object:
            return sitgen.generate_situation(spec, seed=i + 1)

        m = measure(situation, repeats=9)
        rows.append((f"situation {name} (terrain + robots + routes)", m))
        results.setdefault("situation", {})[f"preset_{name}"] = m

    results["sim"] = bench_reference_scene(rows)

    scen = SHARED / "movingai" / "scenarios" / (ASTAR_MAP + ".scen")
    if scen.is_file():
        grid = sitgen.load_map(SHARED / "movingai" / "maps" / ASTAR_MAP)
        problems = []
        # Every 10th problem: all path lengths (buckets) at a tenth of the time.
        for line in scen.read_text().splitlines()[1::10]:
            f = line.split("\t")
            problems.append(((int(f[4]), int(f[5])), (int(f[6]), int(f[7]))))
        blocked = grid.occupied
        m = measure(lambda _: _core.shortest_path_lengths(blocked, problems), repeats=5)
        per_second = len(problems) / m["median_s"]
        rows.append((f"A* {ASTAR_MAP}: {len(problems)} problems, one core", m))
        results["astar"] = {
            "map": ASTAR_MAP,
            "problems": len(problems),
            "problems_per_s": per_second,
            **m,
        }
    else:
        print(f"skipped A*: {scen} not found (set SITGEN_SHARED_DATA)")

    print(f"sitgen {sitgen.__version__} on {results['machine']['cpu']}, {os.cpu_count()} cores")
    print(f"{'benchmark':60} {'median':>10} {'min':>10} {'max':>10}")
    for label, m in rows:
        print(
            f"{label:60} {m['median_s'] * 1e3:8.1f}ms {m['min_s'] * 1e3:8.1f}ms "
            f"{m['max_s'] * 1e3:8.1f}ms"
        )
    if "astar" in results:
        print(f"A*: {results['astar']['problems_per_s']:.0f} problems/s")
    RESULTS.mkdir(exist_ok=True)
    out = RESULTS / "latest.json"
    out.write_text(json.dumps(results, indent=2) + "\n")
    print(f"wrote {out}")


if __name__ == "__main__":
    main()

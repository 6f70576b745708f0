"""How long a ROS 2 node takes to start beside busy cores, in sitgen's session and in a session
of its own (``make bench-ros2-start``).

sitgen starts a ``ros2:`` node in sitgen's session, in a process group of its own. Linux's
scheduler shares a core out between sessions (autogroups), and a node alone in a session of its
own was now and then left runnable but unrun for seconds of its start-up beside busy cores —
long enough, now and then, to miss the start timeout. This bench shows it: with every core kept
busy by a process that only spins, it runs the styles test's campaign (20 runs of
``tests/ros2_nodes/usual.py timer``: open field, 0–2 peers, 5 s, seed 3, 2 workers) in turn
with the node as sitgen starts it and with the same node behind ``setsid -w`` (a session of its
own, as sitgen started nodes before), ``SITGEN_BENCH_ROS2_START_ROUNDS`` times (default 6).
Each node writes the seconds from its process's start to its node made (``USUAL_START_LOG``).
Prints per way: nodes, how many took over 2 s, the slowest, and runs that ended as errors
(/proc/sys/kernel/sched_autogroup_enabled says whether autogroups are on). Writes
``benches/results/ros2_start.json``. About 10 minutes on 2 cores.
"""

from __future__ import annotations

import json
import os
import shutil
import sqlite3
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
RESULTS = ROOT / "benches" / "results"
NODE = f"{sys.executable} {ROOT / 'tests' / 'ros2_nodes' / 'usual.py'} timer"
WAYS = {"sitgen's session": f"ros2:{NODE}", "a session of its own": f"ros2:setsid -w {NODE}"}
SLOW_S = 2.0


def campaign(spec: Path, db: Path, log: Path) -> int:
    """The styles test's campaign of ``spec`` on 2 workers, each node's start-up written to
    ``log``; the runs that ended as errors."""
    done = subprocess.run(
        [
            sys.executable, "-m", "sitgen.cli", "campaign", str(spec), "--db", str(db),
            "--workers", "2", "--reruns", "0", "--seed", "3",
        ],
        env={**os.environ, "USUAL_START_LOG": str(log)},
        capture_output=True,
        text=True,
    )  # fmt: skip
    if done.returncode != 0:
        raise SystemExit(f"campaign failed: {done.stderr.strip()}")
    with sqlite3.connect(db) as c:
        (errors,) = c.execute("SELECT count(*) FROM runs WHERE outcome = 'error'").fetchone()
    return int(errors)


def main() -> None:
    if shutil.which("setsid") is None:
        raise SystemExit("setsid (util-linux) is not on PATH")
    rounds = int(os.environ.get("SITGEN_BENCH_ROS2_START_ROUNDS", "6"))
    autogroup = Path("/proc/sys/kernel/sched_autogroup_enabled")
    out: dict[str, Any] = {
        "rounds": rounds,
        "autogroup": autogroup.read_text().strip() if autogroup.exists() else None,
        "ways": {way: {"start_s": [], "errors": 0} for way in WAYS},
    }
    burners = [
        subprocess.Popen([sys.executable, "-c", "while True: pass"])
        for _ in range(os.cpu_count() or 2)
    ]
    try:
        with tempfile.TemporaryDirectory() as tmp:
            for k in range(rounds):
                for way, controller in WAYS.items():
                    spec = Path(tmp) / "usual.toml"
                    spec.write_text(
                        'n = 20\n[situation.terrain]\npreset = "open_field"\n'
                        "[situation.mission]\npeers_min = 0\npeers_max = 2\n"
                        f'[run]\ntime_limit_s = 5.0\n[run.controller]\nname = "{controller}"\n'
                        "params = { answer_timeout_s = 10.0 }\n"
                    )
                    log = Path(tmp) / f"{k}-{len(way)}.log"
                    errors = campaign(spec, Path(tmp) / f"{k}-{len(way)}.db", log)
                    row = out["ways"][way]
                    row["errors"] += errors
                    row["start_s"] += [float(x) for x in log.read_text().split()]
                    print(f"round {k + 1}, {way}: {errors} errors", file=sys.stderr)
    finally:
        for burner in burners:
            burner.kill()
            burner.wait()
    print(f"\nnode start-up beside {len(burners)} busy processes (autogroup {out['autogroup']})")
    for way, row in out["ways"].items():
        starts = row["start_s"]
        slow = sorted(s for s in starts if s > SLOW_S)
        print(
            f"{way:22}: {len(starts)} nodes, {len(slow)} over {SLOW_S:g} s "
            f"({', '.join(f'{s:.1f}' for s in slow) or 'none'}), slowest {max(starts):.1f} s, "
            f"{row['errors']} runs ended as errors"
        )
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "ros2_start.json").write_text(json.dumps(out, indent=2) + "\n")
    print(f"wrote {RESULTS / 'ros2_start.json'}")


if __name__ == "__main__":
    main()

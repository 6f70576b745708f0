"""sitgen benchmarks: prints a table of medians with their spread, and writes JSON.

Run with ``make bench`` (or ``python benches/run.py``; ``SITGEN_BENCH_CAMPAIGN_N=0`` skips the
campaign, which takes a few minutes). Figures are wall-clock times on this machine; compare runs
on the same machine only. Nothing here is asserted: speed is measured, not tested.
``make bench-irsim`` compares the simulator with IR-SIM (benches/irsim_compare.py).
"""

from __future__ import annotations

import contextlib
import functools
import json
import os
import platform
import shutil
import statistics
import subprocess
import sys
import sysconfig
import tempfile
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

from requirement_cost import bench_requirements

import sitgen
from sitgen import _core
from sitgen.world.config import preset_spec

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
    its 181-beam laser every step, five peers on latched commands; one core (the simulator is
    single-threaded). `bench_controllers` adds the controllers and the monitor."""
    situation = sitgen.generate_situation(REFERENCE_SCENE, seed=1)
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


REFERENCE_SCENE = {"terrain": {"preset": "caves"}, "mission": {"peers_min": 5, "peers_max": 5}}
"""40 × 40 m caves at 0.1 m, one agent, five peers."""


def bench_laser(rows: list[tuple[str, dict[str, float]]]) -> dict[str, Any]:
    """Rays per second: the agent's 181-beam scan, repeated from its start on the reference
    scene (walls and the five peers' bodies), one core."""
    situation = sitgen.generate_situation(REFERENCE_SCENE, seed=1)
    world = sitgen.World(situation)
    beams = len(world.observe(0).ranges)
    scans = 20_000
    m = measure(lambda _: world._world.scan_repeatedly(scans), repeats=5)
    rays_per_s = scans * beams / m["median_s"]
    rows.append((f"laser: {scans} scans of {beams} beams", m))
    print(f"laser: {rays_per_s / 1e6:.2f} M rays/s ({beams} beams, reference scene, one core)")
    return {"scans": scans, "beams": beams, "rays_per_s": rays_per_s, **m}


def bench_controllers(rows: list[tuple[str, dict[str, float]]]) -> dict[str, Any]:
    """Whole runs of the reference scene (observe, act, step, monitor, trajectory), one core,
    with each built-in agent controller and `straight` peers; the controller's cost per step
    is its time per step less that of `straight` (no avoidance, a few arithmetic operations)."""
    situation = sitgen.generate_situation(REFERENCE_SCENE, seed=1)
    out: dict[str, Any] = {}
    for name in ("straight", "snd_follow", "follow", "vo", "dwa"):
        spec = json.dumps({"controller": {"name": name}, "time_limit_s": 600.0})
        steps: list[int] = []

        def run(_: int, spec: str = spec, steps: list[int] = steps) -> None:
            r = _core.Run(situation.to_json(), spec, 0)
            r.run_to_end()
            steps.append(json.loads(r.finish()["record"])["steps"])

        # Seven repeats: a run of the reference scene lasts a tenth of a second, and on a shared
        # host a median of three still moves with one disturbed run.
        m = measure(run, repeats=7)
        per_step_us = m["median_s"] / steps[-1] * 1e6
        out[name] = {"steps": steps[-1], "us_per_step": per_step_us, **m}
        rows.append((f"run reference scene, agent {name}: {steps[-1]} steps", m))
    base = out["straight"]["us_per_step"]
    for name, r in out.items():
        r["controller_us_per_step"] = r["us_per_step"] - base
        print(
            f"run with {name:10}: {1e6 / r['us_per_step']:8,.0f} steps/s "
            f"({1e5 / r['us_per_step']:,.0f}x real time), {r['us_per_step']:6.1f} µs/step, "
            f"controller ≈ {r['controller_us_per_step']:+.1f} µs"
        )
    snd = out["snd_follow"]
    print(
        "reference scene as the benchmark issue defines it (snd_follow agent, five straight "
        f"peers, monitor on): {1e5 / snd['us_per_step']:,.0f}x real time (target 5,000x; "
        f"median of {snd['repeats']} runs, which ranged "
        f"{snd['steps'] * 0.1 / snd['max_s']:,.0f}-{snd['steps'] * 0.1 / snd['min_s']:,.0f}x)"
    )
    return out


def own_cost_python(factory: Callable[[], Any], situation: sitgen.Situation) -> float:
    """Seconds a Python controller itself takes a step: its ``act`` called in a loop on one
    observation of the scene, nothing else."""
    from sitgen.world.sim import Observation

    core = _core.Run(situation.to_json(), json.dumps({"controller": {"name": "cmd:x"}}), 0)
    o = core.observe_agent()
    obs = Observation(
        ranges=o["ranges"], angles=o["angles"], pose=o["pose"], velocity=o["velocity"],
        stalled=o["stalled"], time=o["time"], tracks=tuple(o["tracks"]),
    )  # fmt: skip
    from sitgen.run import reset_info

    controller = factory()
    controller.reset(reset_info(situation, {}, situation.agent.id))
    calls = 2000
    start = time.perf_counter()
    for _ in range(calls):
        controller.act(obs)
    return (time.perf_counter() - start) / calls


def own_cost_program(argv: list[str], situation: sitgen.Situation) -> float:
    """Seconds a ``cmd:`` program itself takes a step: observation lines fed to it all at once
    (it never waits for sitgen), less its start-up."""
    core = _core.Run(situation.to_json(), json.dumps({"controller": {"name": "cmd:x"}}), 0)
    o = core.observe_agent()
    line = json.dumps({
        "type": "observation", "time": o["time"], "pose": list(o["pose"]),
        "velocity": list(o["velocity"]), "stalled": o["stalled"], "waypoints_reached": 0,
        "ranges": o["ranges"].tolist(), "tracks": [],
    }) + "\n"  # fmt: skip
    lines = 5000

    def feed(n: int) -> float:
        start = time.perf_counter()
        subprocess.run(argv, input=line * n, capture_output=True, text=True, check=True)
        return time.perf_counter() - start

    feed(0)
    return max(0.0, (feed(lines) - feed(0)) / lines)


def compile_trivial_c_node(folder: Path) -> Path | None:
    """benches/trivial_node.c compiled with gcc against the ROS 2 wheels' headers and rcl;
    None (said why) where it cannot be."""
    if shutil.which("gcc") is None:
        print("skipped the C node: no gcc")
        return None
    include = Path(sys.prefix) / "include"
    lib = Path(sys.prefix) / "lib"
    out = Path(tempfile.mkdtemp(prefix="sitgen-bench-")) / "trivial_node_c"
    libraries = [
        "rcl", "rcutils", "rmw", "rosidl_runtime_c",
        "geometry_msgs__rosidl_generator_c", "geometry_msgs__rosidl_typesupport_c",
        "sensor_msgs__rosidl_generator_c", "sensor_msgs__rosidl_typesupport_c",
    ]  # fmt: skip
    # The wheels' libraries find what they bundle (in site-packages' ros_*.libs) through the
    # program's run path, and some of them (type descriptions' Python support, which rcl
    # links) need libpython: the interpreter's is linked in.
    bundled = sorted(Path(sysconfig.get_paths()["purelib"]).glob("ros_*.libs"))
    python_lib = str(sysconfig.get_config_var("LIBDIR"))
    paths = [lib, *bundled, python_lib]
    command = [
        "gcc", "-O2", str(folder / "trivial_node.c"), "-o", str(out),
        *(f"-I{d}" for d in sorted(include.iterdir()) if d.is_dir()),
        f"-L{lib}", f"-L{python_lib}", "-Wl,--disable-new-dtags",
        *(f"-Wl,-rpath,{p}" for p in paths), "-Wl,--allow-shlib-undefined",
        *(f"-l{name}" for name in libraries),
        "-Wl,--no-as-needed", f"-lpython{sys.version_info.major}.{sys.version_info.minor}",
    ]  # fmt: skip
    done = subprocess.run(command, capture_output=True, text=True, check=False)
    if done.returncode != 0:
        print(f"skipped the C node: gcc failed: {done.stderr.strip().splitlines()[-1:]}")
        return None
    return out


@contextlib.contextmanager
def python_side(wanted: bool) -> Iterator[None]:
    """``ros2:`` periods handed over in Python (``SITGEN_ROS2_NATIVE=0``) where ``wanted``,
    else in C (the default)."""
    from sitgen.controllers.ros2 import native as ros2_native

    before = os.environ.get("SITGEN_ROS2_NATIVE")
    os.environ["SITGEN_ROS2_NATIVE"] = "0" if wanted else "1"
    ros2_native._native.cache_clear()
    try:
        yield
    finally:
        if before is None:
            del os.environ["SITGEN_ROS2_NATIVE"]
        else:
            os.environ["SITGEN_ROS2_NATIVE"] = before
        ros2_native._native.cache_clear()


def bench_user_controllers(rows: list[tuple[str, dict[str, float]]]) -> dict[str, Any]:
    """A user's controller on each path, driving the reference scene's agent: control steps per
    second over a run (less the start-up each run pays, timed on a 0.1 s run), and the ratio of
    the time a step takes to the controller's own cost, measured in the same process.

    - ``python`` in process: a ``python:`` class as a campaign's pool worker calls it (the
      fast path), a trivial one and one that spends 200 µs a step;
    - ``python`` in a host process of its own (the JSON-lines protocol, as ``sitgen run`` and
      a run redone after its worker died use it);
    - ``cmd:`` programs: a trivial reply, and the route follower of examples/ros2;
    - ``ros2:`` the same route follower as a node (DDS in lockstep), where sitgen[ros2] is
      installed, started for each run and kept alive across runs (``keep_alive``: its start
      is then the reset between runs), and a trivial node kept alive (benches/trivial_node.py:
      sitgen's lockstep and an rclpy node's turn, on rclpy's single-threaded executor and on
      its EventsExecutor; benches/trivial_node.c: the lockstep alone),
      each also with sitgen's side of a period in Python rather than C;
    - ``navground:`` HL and ORCA with the sensed perception (on the fast path, as a campaign
      runs them), where sitgen[navground] is installed: their own cost is the adapter and the
      behaviour's compute, called in a loop.

    What limits each: the fast path adds a few µs to the built-in run's own step (the scene's
    simulation, laser and monitor, printed as ``straight``); a program pays a pipe round trip
    and a JSON line each way."""
    from user_controllers import Busy, Trivial

    from sitgen.controllers.navground import NavgroundController
    from sitgen.controllers.ros2.bridge import ros2_available
    from sitgen.controllers.ros2.controller import stop_kept_nodes

    situation = sitgen.generate_situation(REFERENCE_SCENE, seed=1)
    folder = Path(__file__).resolve().parent
    trivial_cmd = [sys.executable, str(folder / "trivial_cmd.py")]
    follower_cmd = [sys.executable, str(folder.parent / "examples" / "ros2" / "follower_cmd.py")]
    kinds: dict[str, tuple[Any, bool, float | None]] = {
        "built-in straight": ("straight", False, None),
        "python trivial, in process": (f"python:{folder / 'user_controllers.py'}:Trivial", True,
                                       own_cost_python(Trivial, situation)),
        "python 200 µs, in process": (f"python:{folder / 'user_controllers.py'}:Busy", True,
                                      own_cost_python(Busy, situation)),
        "python trivial, host process": (f"python:{folder / 'user_controllers.py'}:Trivial", False,
                                         own_cost_python(Trivial, situation)),
        "cmd trivial reply": (f"cmd:{' '.join(trivial_cmd)}", False,
                              own_cost_program(trivial_cmd, situation)),
        "cmd route follower": (f"cmd:{' '.join(follower_cmd)}", False,
                               own_cost_program(follower_cmd, situation)),
        "ros2 route follower": (
            f"ros2:{sys.executable} {folder.parent / 'examples' / 'ros2' / 'follower_node.py'}",
            False, None,
        ),
    }  # fmt: skip
    kinds["ros2 route follower, kept alive"] = kinds["ros2 route follower"]
    kinds["ros2 trivial node, kept alive"] = (
        f"ros2:{sys.executable} {folder / 'trivial_node.py'}",
        False,
        None,
    )
    kinds["ros2 trivial node on EventsExecutor, kept alive"] = (
        f"ros2:{sys.executable} {folder / 'trivial_node.py'} events_executor",
        False,
        None,
    )
    kept_alive = {
        "ros2 route follower, kept alive",
        "ros2 trivial node, kept alive",
        "ros2 trivial node on EventsExecutor, kept alive",
    }
    c_node = compile_trivial_c_node(folder)
    if c_node is not None:
        kinds["ros2 trivial C node, kept alive"] = (f"ros2:{c_node}", False, None)
        kept_alive.add("ros2 trivial C node, kept alive")
    # The trivial nodes again with sitgen's side of each period in Python
    # (controllers/ros2/native.py): what the hand-over in C saves.
    in_python = set()
    for kind in [k for k in kinds if k.startswith("ros2 trivial")]:
        kinds[f"{kind}, Python side"] = kinds[kind]
        kept_alive.add(f"{kind}, Python side")
        in_python.add(f"{kind}, Python side")
    reason = ros2_available()
    if reason is not None:
        print(f"skipped ros2: {reason}")
        for kind in ("ros2 route follower", *kept_alive):
            kinds.pop(kind)
    try:
        for behavior in ("HL", "ORCA"):
            factory = functools.partial(NavgroundController, behavior)
            kinds[f"navground {behavior}, in process"] = (
                f"navground:{behavior}",
                True,
                own_cost_python(factory, situation),
            )
    except ValueError as e:  # navground is not installed
        print(f"skipped navground: {e}")
    out: dict[str, Any] = {}
    for kind, (name, in_process, own_s) in kinds.items():
        steps: list[int] = []
        kept = {"keep_alive": True} if kind in kept_alive else {}
        spec = {"controller": {"name": name, **kept}}

        def whole(
            _: int, spec: Any = spec, fast: bool = in_process, steps: list[int] = steps
        ) -> None:
            record = sitgen.run(situation, spec=spec, time_limit=60.0, in_process=fast)
            assert record.outcome != "error", record.reason
            steps.append(record.steps)

        def start(_: int, spec: Any = spec, fast: bool = in_process) -> None:
            sitgen.run(situation, spec=spec, time_limit=0.1, in_process=fast)

        with python_side(kind in in_python):
            m = measure(whole, repeats=5)
            s = measure(start, repeats=5)
            stop_kept_nodes()
        step_s = max(1e-9, m["median_s"] - s["median_s"]) / steps[-1]
        out[kind] = {
            "steps": steps[-1], "steps_per_s": 1 / step_s, "start_s": s["median_s"],
            "own_us_per_step": None if own_s is None else own_s * 1e6, **m,
        }  # fmt: skip
        rows.append((f"{kind}: {steps[-1]} control steps", m))
        ratio = "" if not own_s else f", {step_s / own_s:7.2f}x its own {own_s * 1e6:6.1f} µs"
        print(
            f"{kind:30}: {1 / step_s:8,.0f} control steps/s, {step_s * 1e6:6.1f} µs a step"
            f"{ratio}; {s['median_s'] * 1e3:5.0f} ms to start and end a run"
        )
    # The floor: a step of the trivial class on the fast path, less its own cost, is the run's
    # own step (simulation, laser, monitor) with what the fast path adds.
    trivial = out["python trivial, in process"]
    floor = 1e6 / trivial["steps_per_s"] - trivial["own_us_per_step"]
    for kind, r in out.items():
        if r["own_us_per_step"] is not None:
            beyond = 1e6 / r["steps_per_s"] - floor - r["own_us_per_step"]
            r["beyond_floor_us_per_step"] = beyond
            print(
                f"{kind:30}: {beyond:+7.1f} µs a step beyond its own cost and the fast "
                f"path's floor ({floor:.1f} µs: the run and the call)"
            )
    return out


PAPER_S = 17 * 3600.0
"""The paper's 500-situation campaign: about 17 hours (§4.2)."""


def bench_campaign(rows: list[tuple[str, dict[str, float]]]) -> dict[str, Any]:
    """The default campaign (the paper's experiment, 500 situations) with 1 and 2 workers, each
    in its own process, timed by wall clock; peak resident memory of that process."""
    n = int(os.environ.get("SITGEN_BENCH_CAMPAIGN_N", "500"))
    out: dict[str, Any] = {"n": n}
    # The default keeps the top 50 runs whole; `none` keeps every run as a summary.
    for workers, keep in ((1, "top:50"), (2, "top:50"), (2, "none")):
        with tempfile.TemporaryDirectory() as tmp:
            db = Path(tmp) / "bench.db"
            command = [
                sys.executable, "-m", "sitgen.cli", "campaign", "--n", str(n), "--seed", "0",
                "--db", str(db), "--workers", str(workers), "--keep-trajectories", keep,
            ]  # fmt: skip
            start = time.perf_counter()
            proc = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
            _, status, usage = os.wait4(proc.pid, 0)
            wall = time.perf_counter() - start
            assert proc.stdout is not None
            summary = proc.stdout.read().decode()
            if status != 0:
                raise SystemExit(
                    f"campaign failed: {proc.stderr.read().decode() if proc.stderr else ''}"
                )
            store_bytes = db.stat().st_size
        peak_mib = usage.ru_maxrss / 1024
        name = f"workers_{workers}" + ("" if keep == "top:50" else f"_keep_{keep}")
        out[name] = {
            "wall_s": wall,
            "runs_per_s": n / wall,
            "runs_per_hour_per_core": n / wall * 3600 / workers,
            "speedup_vs_paper": PAPER_S * n / 500 / wall,
            "peak_rss_mib": peak_mib,
            "store_bytes_per_run": store_bytes / max(n, 1),
        }
        rows.append(
            (f"campaign {n} situations, {workers} worker(s), keep {keep}", {
                "median_s": wall, "min_s": wall, "max_s": wall, "repeats": 1,
            })
        )  # fmt: skip
        print(
            f"campaign {n} runs, {workers} worker(s), keep {keep}: {wall:.1f} s, "
            f"{n / wall:.1f} runs/s, "
            f"{PAPER_S * n / 500 / wall:,.0f}× the paper's ~17 h, peak memory {peak_mib:.0f} MiB, "
            f"store {store_bytes / max(n, 1):,.0f} bytes a run"
        )
        out[name]["summary"] = summary.strip().splitlines()[1:2]
    return out


def bench_robustness(rows: list[tuple[str, dict[str, float]]]) -> dict[str, Any]:
    """What measuring robustness adds to the default campaign, on one worker (so wall time is
    CPU time): the 500 runs, then the copies the campaign makes at its end (each watched to
    its horizon), then the same runs' copies watched to their time limit (as before the
    horizon). Prints each as a share of the runs' cost, and whether the verdicts agree."""
    from sitgen.store import Store
    from sitgen.triage.failures import measure_robustness
    from sitgen.triage.recall import stored_run
    from sitgen.triage.robustness import is_robust, measure

    n = int(os.environ.get("SITGEN_BENCH_CAMPAIGN_N", "500"))
    with tempfile.TemporaryDirectory() as tmp:
        db = Path(tmp) / "bench.db"
        command = [
            sys.executable, "-m", "sitgen.cli", "campaign", "--n", str(n), "--seed", "0",
            "--db", str(db), "--workers", "1", "--reruns", "0",
        ]  # fmt: skip
        start = time.perf_counter()
        subprocess.run(command, check=True, capture_output=True)
        runs_s = time.perf_counter() - start
        with Store(db) as store:
            start = time.perf_counter()
            copies = measure_robustness(store, workers=1)
            horizon_s = time.perf_counter() - start
            measured = store.robustness()
            rows_ = [stored_run(store, i) for i in sorted(measured)]
        start = time.perf_counter()
        whole = measure(rows_, workers=1, horizon=False)
        whole_s = time.perf_counter() - start
    cut = {r: is_robust(m["recurs"], m["reruns"]) for r, m in measured.items()}
    same = sum(cut[w.run_id] == w.robust for w in whole)
    out = {
        "n": n,
        "runs_s": runs_s,
        "copies": copies,
        "copies_to_horizon_s": horizon_s,
        "copies_to_limit_s": whole_s,
        "share_to_horizon": horizon_s / runs_s,
        "share_to_limit": whole_s / runs_s,
        "measured_runs": len(whole),
        "same_verdicts": same,
    }
    for name, t in (("to their horizon", horizon_s), ("to their time limit", whole_s)):
        rows.append(
            (f"robustness copies ({copies}) {name}, 1 worker", {
                "median_s": t, "min_s": t, "max_s": t, "repeats": 1,
            })
        )  # fmt: skip
    print(
        f"robustness of the default campaign ({n} runs, 1 worker): runs {runs_s:.1f} s; "
        f"{copies} copies to their horizon {horizon_s:.1f} s ({horizon_s / runs_s:.0%} of the "
        f"runs), to their time limit {whole_s:.1f} s ({whole_s / runs_s:.0%}); verdicts the "
        f"same on {same} of {len(whole)} measured runs"
    )
    return out


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
    results["laser"] = bench_laser(rows)
    results["controllers"] = bench_controllers(rows)
    results["user_controllers"] = bench_user_controllers(rows)
    if os.environ.get("SITGEN_BENCH_CAMPAIGN_N", "500") != "0":
        results["campaign"] = bench_campaign(rows)
        results["robustness"] = bench_robustness(rows)
        results["requirements"] = bench_requirements(rows)

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

"""sitgen's simulator against IR-SIM, side by side, on sitgen's reference scene.

Measures simulation steps per second of both simulators on the same scene: sitgen's reference
scene (caves preset, 40 × 40 m at 0.1 m, seed 1: the agent and five peers, Pioneer 3-AT
rectangles of 0.626 × 0.505 m). Every robot is driven with constant commands (v = 0.5 m/s,
ω = 0.15·(id mod 3 − 1) rad/s, as ``benches/run.py::bench_reference_scene``), so no controller
is timed: a step is moving the six robots, checking them for collisions, and one 181-beam,
180°, 10 m laser scan of the agent. Rendering is off (IR-SIM ``headless``, matplotlib Agg).

Run with ``make bench-irsim``: it makes a virtual environment of its own,
``benches/.venv-irsim`` (IR-SIM is not a dependency of sitgen), installs ``ir-sim`` and sitgen
from this tree there, and runs this script. Both run in one process, one core each (BLAS is held
to one thread), in alternating rounds; each round times the same window for both, the first
``--irsim-steps`` steps from the situation's start, which IR-SIM runs once and sitgen (far
faster) on ``--sitgen-repeats`` fresh worlds. A long sitgen run (20,000 steps, as ``make bench``
times it) follows in each round, for the real-time factor. Prints medians over rounds with their
spread and writes ``benches/results/irsim.json``. Nothing is asserted: speed is measured.

How IR-SIM gets the same scene: the occupancy grid goes in as its obstacle map (an image, one
pixel a cell; IR-SIM turns the occupied cells into the boundary segments of their union, plus the
grid itself for collision checks), and the script checks that IR-SIM's grid equals sitgen's cell
for cell. Each robot is a differential-drive polygon with sitgen's footprint corners at the
situation's start pose; the agent carries a ``lidar2d`` with sitgen's beam count, field of view
and range. Collision checking is IR-SIM's default (``collision_mode: stop``), and its lidar is
cast on every ``env.step`` (``EnvBase.step`` → ``_objects_sensor_step`` → ``Lidar2D.step``),
not only when drawing.

What cannot be made equal, printed with the results:

- Collisions. sitgen tests a move before making it: a blocked robot stays where it was, stalls,
  and tries again each step. IR-SIM moves first, then finds the overlap and stops the robot for
  good (its later steps skip the kinematics). Touching counts as a collision in IR-SIM, not in
  sitgen. Trajectories part once robots meet walls or each other.
- Motion. sitgen integrates the unicycle exactly (arcs), IR-SIM by Euler steps: millimetres apart
  over the window, before the collisions.
- Laser. Both trace exact distances to the cell edges and to the other robots' bodies; sitgen
  rounds ranges to 1 cm (the SICK LMS200's step), IR-SIM does not, so the first scans agree to
  half a centimetre.
- The map. IR-SIM keeps the grid as line segments (what its lidar casts against) and as a grid
  with a circle of half a cell per occupied cell (its grid collision test, backed by the
  segments); sitgen keeps the grid and a distance transform.
- The interface. IR-SIM is stepped from Python (``env.step`` per step, commands re-sent each time,
  as its API requires); sitgen's ``World.advance`` loops in Rust with latched commands.
"""

from __future__ import annotations

import os

# One core for each simulator: sitgen's loop is single-threaded, and IR-SIM's numpy would
# otherwise spread its small matrix products over a shared machine's cores. Set before numpy
# loads, which reads these once.
for _variable in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_variable, "1")
os.environ.setdefault("MPLBACKEND", "Agg")

import argparse  # noqa: E402
import contextlib  # noqa: E402
import io  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import platform  # noqa: E402
import statistics  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from importlib import metadata  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

import numpy as np  # noqa: E402
import numpy.typing as npt  # noqa: E402
from PIL import Image  # noqa: E402

import sitgen  # noqa: E402
from sitgen.world.situation import Situation  # noqa: E402

RESULTS = Path(__file__).resolve().parent / "results"
REFERENCE_SCENE = {"terrain": {"preset": "caves"}, "mission": {"peers_min": 5, "peers_max": 5}}
"""40 × 40 m caves at 0.1 m, one agent, five peers (as ``benches/run.py``)."""
DT_S = 0.1
LASER_RANGE_M = 10.0
"""sitgen's default laser range (the SICK LMS200); beams and field of view are read from it."""
LONG_RUN_STEPS = 20_000
"""The length of ``make bench``'s simulator run."""
REAL_TIME_TARGET = 5_000.0
RATIO_TARGET = 500.0

EQUALITY_CAVEATS = [
    "collisions: sitgen rejects a blocked move (the robot stays, stalls and retries each step);"
    " IR-SIM makes the move, detects the overlap, then stops the robot for good; touching is a"
    " collision in IR-SIM only",
    "motion: sitgen integrates arcs exactly, IR-SIM by Euler steps",
    "laser: sitgen rounds ranges to 1 cm, IR-SIM does not",
    "map: IR-SIM keeps the grid as segments (lidar) and as cell-centred discs of half a cell plus"
    " segments (collision); sitgen keeps the grid and a distance transform",
    "interface: IR-SIM is stepped from Python with commands passed every step; sitgen advances in"
    " Rust on latched commands",
]


def commands(situation: Situation) -> dict[int, tuple[float, float]]:
    """Constant (v, ω) per robot, as ``benches/run.py::bench_reference_scene`` drives them."""
    return {r.id: (0.5, 0.15 * (r.id % 3 - 1)) for r in situation.robots}


def footprint(body: dict[str, Any]) -> list[list[float]]:
    """The body's rectangle in its own frame (x ahead, y left), as sitgen places it: centred
    ``origin_x_m`` ahead of the rotation centre (behind it for the Pioneer 3-AT). IR-SIM's
    ``rectangle`` is centred on the rotation centre, so the corners are given as a polygon."""
    half_l, half_w = body["length_m"] / 2, body["width_m"] / 2
    ox = body.get("origin_x_m", 0.0)
    return [
        [ox - half_l, -half_w],
        [ox + half_l, -half_w],
        [ox + half_l, half_w],
        [ox - half_l, half_w],
    ]


def irsim_world(situation: Situation, directory: Path) -> Path:
    """Write IR-SIM's world file for ``situation`` (and the map image it names) in
    ``directory``; returns the world file's path."""
    grid = situation.grid
    # IR-SIM reads an image's dark pixels as occupied and its top row as the north edge, the
    # layout of sitgen's grid (row 0 = north); 0 and 255 give occupancies of exactly 100 and 0.
    image = directory / "map.png"
    Image.fromarray(np.where(grid.occupied, 0, 255).astype(np.uint8)).save(image)
    probe = sitgen.World(situation).observe(situation.agent.id)
    beams = len(probe.angles)
    fov_rad = float(probe.angles[-1] - probe.angles[0])
    robots = []
    for r in situation.robots:
        robot: dict[str, Any] = {
            "name": f"robot_{r.id}",
            "kinematics": {"name": "diff"},
            "shape": {"name": "polygon", "vertices": footprint(dict(r.body))},
            "state": [r.start.x_m, r.start.y_m, r.start.heading_rad],
        }
        if r.id == situation.agent.id:
            robot["sensors"] = [
                {
                    "name": "lidar2d",
                    "range_min": 0.0,
                    "range_max": LASER_RANGE_M,
                    "angle_range": fov_rad,
                    "number": beams,
                    "noise": False,
                }
            ]
        robots.append(robot)
    world = {
        "world": {
            "width": grid.size_m[0],
            "height": grid.size_m[1],
            "offset": [grid.origin[0], grid.origin[1]],
            "step_time": DT_S,
            "obstacle_map": str(image),
        },
        "robot": robots,
    }
    # IR-SIM names the world after its file.
    path = directory / "sitgen_reference_scene.yaml"
    # JSON is YAML, and spares a YAML writer.
    path.write_text(json.dumps(world, indent=1))
    return path


def import_irsim_quietly() -> str:
    """Import IR-SIM and make matplotlib's backend Agg; returns IR-SIM's version."""
    # Imported here: IR-SIM lives only in the benchmark's own virtual environment.
    import matplotlib  # type: ignore[import-not-found, unused-ignore]

    # Importing irsim tries the interactive backends first and prints each failure.
    with contextlib.redirect_stdout(io.StringIO()):
        import irsim  # type: ignore[import-not-found, unused-ignore]
    # No figure is open yet, so switching to Agg closes nothing.
    matplotlib.use("Agg")
    return str(irsim.__version__)


def make_irsim_env(world_file: Path) -> Any:
    """IR-SIM's environment for ``world_file``, without any figure, window or input device."""
    import irsim  # type: ignore[import-not-found, unused-ignore]

    # ERROR hides the warning each collision logs; the collision checks still run.
    return irsim.make(str(world_file), headless=True, log_level="ERROR")


def time_irsim(env: Any, actions: list[npt.NDArray[np.float64]], steps: int) -> float:
    """Seconds for ``steps`` IR-SIM steps from the start (after an untimed reset)."""
    env.reset()
    start = time.perf_counter()
    for _ in range(steps):
        env.step(actions)
    return time.perf_counter() - start


def time_sitgen(
    situation: Situation, cmds: dict[int, tuple[float, float]], steps: int, repeats: int
) -> float:
    """Seconds for ``steps`` sitgen steps from the start, summed over ``repeats`` fresh worlds
    (built untimed, as IR-SIM's environment is)."""
    total = 0.0
    for _ in range(repeats):
        world = sitgen.World(situation)
        start = time.perf_counter()
        world.step(cmds)
        world.advance(steps - 1)
        total += time.perf_counter() - start
    return total


def summary(steps_per_s: list[float]) -> dict[str, Any]:
    median = statistics.median(steps_per_s)
    return {
        "steps_per_s_median": median,
        "steps_per_s_min": min(steps_per_s),
        "steps_per_s_max": max(steps_per_s),
        "real_time_factor": median * DT_S,
        "rounds": steps_per_s,
    }


def agreement(
    situation: Situation, env: Any, cmds: dict[int, tuple[float, float]], steps: int
) -> dict[str, Any]:
    """How closely the two scenes match: the map, the agent's first scan, and where the robots
    are after ``steps`` steps (IR-SIM's ``env`` must have just run them from the start)."""
    ids = [r.id for r in situation.robots]
    irsim_end = {i: env.robot_list[i].state[:2, 0].tolist() for i in ids}
    irsim_stopped = sum(bool(env.robot_list[i].stop_flag) for i in ids)
    env.reset()
    agent = situation.agent.id
    irsim_scan = np.asarray(env.get_lidar_scan(agent)["ranges"])
    world = sitgen.World(situation)
    sitgen_scan = np.asarray(world.observe(agent).ranges)
    world.step(cmds)
    world.advance(steps - 1)
    sitgen_end = {s["id"]: s for s in world.state()}
    # IR-SIM indexes its grid [x, y] from the south-west corner; sitgen [row, col] from the north.
    same_grid = np.array_equal(env._world.grid_map > 50, np.fliplr(situation.grid.occupied.T))
    return {
        "same_grid": bool(same_grid),
        "first_scan_max_difference_m": float(np.max(np.abs(sitgen_scan - irsim_scan))),
        "steps": steps,
        "sitgen_stalled": sum(bool(s["stalled"]) for s in sitgen_end.values()),
        "irsim_stopped": irsim_stopped,
        "position_difference_m": [math.dist(sitgen_end[i]["pose"][:2], irsim_end[i]) for i in ids],
    }


def cpu_name() -> str:
    with contextlib.suppress(OSError):
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    return platform.processor() or platform.machine()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--irsim-steps", type=int, default=200)
    parser.add_argument("--sitgen-repeats", type=int, default=50)
    args = parser.parse_args()
    steps: int = args.irsim_steps

    irsim_version = import_irsim_quietly()
    situation = sitgen.generate_situation(REFERENCE_SCENE, seed=1)
    cmds = commands(situation)
    # IR-SIM takes the commands of all robots, in id order, on every step.
    actions = [np.array([[v], [w]]) for _, (v, w) in sorted(cmds.items())]

    with tempfile.TemporaryDirectory() as tmp:
        start = time.perf_counter()
        env = make_irsim_env(irsim_world(situation, Path(tmp)))
        irsim_build_s = time.perf_counter() - start
    n = len(situation.robots)
    n_lidars = sum(len(r.sensors) for r in env.robot_list)

    # Warm-ups, untimed: first calls pay for imports and caches.
    time_irsim(env, actions, 5)
    time_sitgen(situation, cmds, steps, 1)

    sitgen_rates: list[float] = []
    irsim_rates: list[float] = []
    long_rates: list[float] = []
    match: dict[str, Any] = {}
    for i in range(args.rounds):
        s = time_sitgen(situation, cmds, steps, args.sitgen_repeats)
        sitgen_rates.append(steps * args.sitgen_repeats / s)
        t = time_irsim(env, actions, steps)
        irsim_rates.append(steps / t)
        if i == 0:
            match = agreement(situation, env, cmds, steps)
        long_s = time_sitgen(situation, cmds, LONG_RUN_STEPS, 1)
        long_rates.append(LONG_RUN_STEPS / long_s)
        print(
            f"round {i + 1}/{args.rounds}: sitgen {sitgen_rates[-1]:,.0f} steps/s, "
            f"IR-SIM {irsim_rates[-1]:,.1f} steps/s, sitgen long run {long_rates[-1]:,.0f} steps/s",
            flush=True,
        )

    sg, ir, lr = summary(sitgen_rates), summary(irsim_rates), summary(long_rates)
    ratio = sg["steps_per_s_median"] / ir["steps_per_s_median"]
    versions = {
        "python": platform.python_version(),
        "sitgen": sitgen.__version__,
        "ir-sim": irsim_version,
        **{p: metadata.version(p) for p in ("numpy", "shapely", "matplotlib")},
    }
    machine = {
        "cpu": cpu_name(),
        "cores": os.cpu_count(),
        "system": platform.platform(),
        "blas_threads": os.environ.get("OPENBLAS_NUM_THREADS"),
    }

    def spread(m: dict[str, Any], fmt: str) -> str:
        return f"{m['steps_per_s_min']:{fmt}}-{m['steps_per_s_max']:{fmt}}"

    print()
    print(f"machine: {machine['cpu']}, {machine['cores']} cores, {machine['system']}")
    print("versions: " + ", ".join(f"{k} {v}" for k, v in versions.items()))
    width_m, height_m = situation.grid.size_m
    print(
        f"scene: caves {width_m:g} x {height_m:g} m @{situation.grid.resolution:g} m, seed 1, "
        f"{n} robots, {n_lidars} lidar (agent), dt {DT_S} s, one BLAS thread; "
        f"IR-SIM scene built in {irsim_build_s:.1f} s"
    )
    print(
        f"scenes agree: grid identical {match['same_grid']}; agent's first scan within "
        f"{match['first_scan_max_difference_m'] * 100:.2f} cm; after {steps} steps "
        f"{match['sitgen_stalled']}/{n} robots stalled in sitgen, {match['irsim_stopped']}/{n} "
        f"stopped in IR-SIM, positions apart by at most "
        f"{max(match['position_difference_m']):.2f} m"
    )
    print(
        f"window: steps 1-{steps} from the start, {args.rounds} alternating rounds, median (spread)"
    )
    print(
        f"  sitgen: {sg['steps_per_s_median']:>12,.0f} steps/s ({spread(sg, ',.0f')}), "
        f"{sg['real_time_factor']:,.0f}x real time   [{args.sitgen_repeats} worlds a round]"
    )
    print(
        f"  IR-SIM: {ir['steps_per_s_median']:>12,.1f} steps/s ({spread(ir, ',.1f')}), "
        f"{ir['real_time_factor']:,.2f}x real time"
    )
    print(f"  sitgen / IR-SIM: {ratio:,.0f}x   (target >= {RATIO_TARGET:,.0f}x)")
    print(
        f"sitgen long run, {LONG_RUN_STEPS:,} steps (as make bench): "
        f"{lr['steps_per_s_median']:,.0f} steps/s ({spread(lr, ',.0f')}), "
        f"{lr['real_time_factor']:,.0f}x real time   (target >= {REAL_TIME_TARGET:,.0f}x)"
    )
    print("not equal between the two:")
    for caveat in EQUALITY_CAVEATS:
        print(f"  - {caveat}")

    results = {
        "machine": machine,
        "versions": versions,
        "scene": {
            "spec": REFERENCE_SCENE,
            "seed": 1,
            "robots": len(situation.robots),
            "dt_s": DT_S,
            "commands": {str(k): v for k, v in cmds.items()},
            "irsim_build_s": irsim_build_s,
        },
        "agreement": match,
        "window_steps": steps,
        "rounds": args.rounds,
        "sitgen_repeats": args.sitgen_repeats,
        "sitgen": sg,
        "irsim": ir,
        "ratio": ratio,
        "sitgen_long_run": {"steps": LONG_RUN_STEPS, **lr},
        "targets": {"real_time_factor": REAL_TIME_TARGET, "ratio": RATIO_TARGET},
        "not_equal": EQUALITY_CAVEATS,
    }
    RESULTS.mkdir(exist_ok=True)
    out = RESULTS / "irsim.json"
    out.write_text(json.dumps(results, indent=2) + "\n")
    print(f"wrote {out}")


if __name__ == "__main__":
    main()

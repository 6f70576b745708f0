"""Running a situation: ``sitgen.run(situation, controller=..., time_limit=...)``.

A run drives every robot of a situation until the agent completes its route or the time limit
is reached, watched by the monitor and scored (the core's ``run`` module; ARCHITECTURE.md).
Built-in controllers run entirely in Rust with the GIL released; a Python or external
controller (``python:…``, ``cmd:…``, or any object with ``reset`` and ``act``) is stepped from
here, and whatever goes wrong in it ends the run with outcome ``error`` and a reason.
"""

from __future__ import annotations

import contextlib
import json
import resource
import time
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from sitgen import _core
from sitgen.controllers import sandbox
from sitgen.controllers.deadlines import MACHINE_RETRIES, ControllerError, MachineError
from sitgen.controllers.inprocess import InProcessController
from sitgen.controllers.ros2.controller import PREFIX as ROS2_PREFIX
from sitgen.controllers.user import is_user_controller, load_controller, load_peer_controller
from sitgen.world.config import spec_json
from sitgen.world.requirements import verdicts, verdicts_json
from sitgen.world.situation import Situation
from sitgen.world.terrain import wall_segments


@dataclass(frozen=True)
class Sensed:
    """What the agent sensed at the start and after every step (aligned with the
    trajectory's rows)."""

    ranges: npt.NDArray[np.float64]
    """Laser ranges, shape (steps + 1, beams), metres."""
    velocity: npt.NDArray[np.float64]
    """(v m/s, omega rad/s) it moved with, shape (steps + 1, 2)."""
    time_s: npt.NDArray[np.float64]
    """Simulated time, shape (steps + 1,)."""


@dataclass(frozen=True)
class RunRecord:
    """What happened in a run."""

    outcome: str
    """``completed``, ``timeout`` or ``error``."""
    reason: str
    """Why it ended (for ``error``: what the controller did wrong)."""
    score: float
    """Total penalty points."""
    breakdown: dict[str, dict[str, float]]
    """Points by event kind: ``count``, ``seconds``, ``points`` (kinds that earned points)."""
    events: list[dict[str, Any]]
    """The event log: ``kind``, ``start_s``, ``end_s``, ``robot``, ``other``, ``scored``,
    ``details``."""
    trajectory: npt.NDArray[np.float64] = field(repr=False)
    """Poses (x, y, heading) of every robot at the start and after every step:
    shape (steps + 1, robots, 3)."""
    steps: int
    time_s: float
    controller: str
    """The agent's controller."""
    seed: int
    """Sensor-noise seed."""
    events_jsonl: str = field(repr=False)
    """The event log as JSON Lines (byte-identical for the same inputs)."""
    events_text: str = field(repr=False)
    """The event log as text, one line per event."""
    failure: dict[str, Any] | None = None
    """What went wrong: ``class`` (key), ``description`` (sentence), ``events`` (positions in
    the log of the events that decided it), ``features``; None if nothing did
    (docs/failures.md)."""
    coverage: dict[str, Any] | None = None
    """The cells of the interaction space the run exercised: ``cells`` (keys), ``encounters``,
    ``failure_cell`` (docs/coverage.md)."""
    sensed: Sensed | None = field(default=None, repr=False)
    """What the agent sensed at every step, if the run was asked to keep it (``sensed=True``:
    for a rosbag2 of the run)."""
    requirements: list[dict[str, Any]] = field(default_factory=list)
    """Each requirement's verdict, in the run spec's order: ``name``, ``robustness`` (float,
    ±inf possible; None with ``error``), ``violated``, ``first_violation_s``,
    ``interval_s``, ``weight`` (docs/requirements.md)."""
    signals: dict[str, npt.NDArray[np.float64]] = field(default_factory=dict, repr=False)
    """The requirement signals the requirements read, one value a sample (steps + 1)."""
    cost: tuple[float, float] = field(default=(0.0, 0.0), compare=False)
    """What the run cost the machine: (wall seconds, processor seconds of the process that
    made it and of the controller processes it started and ended). Not part of the run: the
    same run costs more on a loaded machine."""

    def to_dict(self) -> dict[str, Any]:
        """Everything but the trajectory, as JSON-ready data."""
        return {
            "outcome": self.outcome,
            "reason": self.reason,
            "score": self.score,
            "breakdown": self.breakdown,
            "controller": self.controller,
            "seed": self.seed,
            "steps": self.steps,
            "time_s": self.time_s,
            "failure": self.failure,
            "coverage": self.coverage,
            "events": self.events,
            **({"requirements": verdicts_json(self.requirements)} if self.requirements else {}),
        }


def _controller_name(controller: Any) -> str:
    if controller is None or isinstance(controller, str):
        return controller or ""
    return f"python:{type(controller).__module__}:{type(controller).__qualname__}"


def reset_info(
    situation: Situation, run: Mapping[str, Any], robot_id: int, with_map: bool = False
) -> dict[str, Any]:
    """What a user controller is told at the start: its robot's id and role, route, body,
    laser and limits, the thresholds the monitor judges it by (the waypoint radius, and the
    whole resolved ``monitor`` section), the params its controller table gives it (the run
    spec's for the agent, if it names one, else the robot's own), and (``with_map``) the
    situation's map."""
    robot = situation.robots[robot_id]
    # The spec as the core resolves it: defaults and the profile's fields filled in.
    resolved = json.loads(_core.check_run_spec(spec_json(dict(run), "run")))
    sim, laser = resolved["sim"], resolved["sim"]["laser"]
    given = resolved.get("controller") if robot.role == "agent" else None
    controller = given or robot.controller
    n, fov = int(laser["beams"]), float(np.radians(laser["fov_deg"]))
    angles = [-fov / 2 + i * fov / (n - 1) for i in range(n)] if n > 1 else [0.0]
    return {
        "robot_id": robot.id,
        "role": robot.role,
        "start": [robot.start.x_m, robot.start.y_m, robot.start.heading_rad],
        "waypoints": [list(w) for w in robot.waypoints],
        "at_end": robot.at_end,
        "body": robot.body,
        "laser": {**laser, "angles": angles},
        "dt_s": float(sim["dt_s"]),
        "max_speed_m_s": float(sim["max_speed_m_s"]),
        "max_turn_rate_deg_s": float(sim["max_turn_rate_deg_s"]),
        "time_limit_s": float(resolved["time_limit_s"]),
        # What the monitor judges the run by, so that a controller can aim at it: a waypoint
        # (and the goal, the route's last) counts as reached within this radius of it.
        "waypoint_radius_m": float(resolved["monitor"]["waypoint_radius_m"]),
        "monitor": dict(resolved["monitor"]),
        "control_period_s": float(controller.get("control_period_s") or sim["dt_s"]),
        "params": dict(controller.get("params") or {}),
        "perception": controller.get("perception") or "sensed",
        **({"map": _map_info(situation)} if with_map else {}),
        **({"walls": _walls(situation)} if controller.get("perception") == "exact" else {}),
    }


def _walls(situation: Situation) -> list[list[float]]:
    """The situation's walls as segments ``[x1, y1, x2, y2]`` (m), for the exact perception."""
    grid = situation.grid
    return wall_segments(grid.occupied, float(grid.resolution)).tolist()  # type: ignore[no-any-return]


def _map_info(situation: Situation) -> dict[str, Any]:
    grid = situation.grid
    return {"occupied": grid.occupied, "resolution_m": float(grid.resolution)}


def run_spec_with(
    spec: Mapping[str, Any] | None,
    time_limit: float | None = None,
    controller: str | None = None,
    params: Mapping[str, float] | None = None,
    base: Mapping[str, Any] | None = None,
    perception: str | None = None,
    keep_alive: bool = False,
    step_timeout_s: float | None = None,
) -> dict[str, Any]:
    """The run spec ``spec`` with a time limit and a built-in or user controller (by name,
    with ``params`` over its own, its ``perception``, ``keep_alive`` and ``step_timeout_s``)
    given on top, as the commands' options give them. The controller table given on top of is
    the spec's, else ``base`` (the situation's agent's): for the same controller its params,
    fault, ``control_period_s``, ``perception``, ``keep_alive`` and ``step_timeout_s`` stay;
    another controller keeps only ``control_period_s`` and ``perception``."""
    run_spec: dict[str, Any] = dict(spec or {})
    if time_limit is not None:
        run_spec["time_limit_s"] = time_limit
    if not controller and not params and not perception and not keep_alive and not step_timeout_s:
        return run_spec
    given = dict(run_spec.get("controller") or base or {})
    if controller and given.get("name") not in (None, controller):
        given = {k: v for k, v in given.items() if k in ("control_period_s", "perception")}
    name = controller or given.get("name")
    if not name:
        option = (
            "--param"
            if params
            else "--perception"
            if perception
            else "--keep-alive"
            if keep_alive
            else "--step-timeout"
        )
        raise _core.SpecError(f"{option}: no controller to give it to; name one with --controller")
    run_spec["controller"] = {
        **given,
        "name": name,
        "params": {**dict(given.get("params") or {}), **dict(params or {})},
        **({"perception": perception} if perception else {}),
        **({"keep_alive": True} if keep_alive else {}),
        **({"step_timeout_s": step_timeout_s} if step_timeout_s else {}),
    }
    return run_spec


def run(
    situation: Situation | str | Path,
    controller: Any = None,
    time_limit: float | None = None,
    seed: int = 0,
    spec: Mapping[str, Any] | None = None,
    params: Mapping[str, float] | None = None,
    step_timeout_s: float | None = None,
    sensed: bool = False,
    in_process: bool = False,
) -> RunRecord:
    """Run ``situation`` (a Situation or a situation file) to its end.

    ``controller``: a built-in name (``snd_follow``, ``follow``, ``vo``, ``dwa``, …),
    ``python:module:Class``, ``cmd:program args``, or an object with ``reset(info)`` and
    ``act(obs)``; default: the situation's own. ``time_limit``: simulated seconds (default 600).
    ``seed``: sensor noise. ``spec``: the run spec (``sim``, ``monitor``, ``scoring``,
    ``time_limit_s``). ``params``: the built-in controller's parameters. A bad spec raises
    SpecError naming the field; a failing user controller gives outcome ``error``.
    ``sensed``: keep what the agent sensed at every step (:class:`Sensed`; the run is the same).
    ``in_process``: call a ``python:`` class in this process, not in a host process of its own
    (for disposable pool workers: :mod:`sitgen.controllers.inprocess`; the run is the same).
    ``step_timeout_s``: the processor seconds a user controller may spend on one step (default:
    the spec controller's ``step_timeout_s``, else 1 s; 10 s for ``navground:``).

    A run the machine fails (a controller starved of a core past its backstop, a runner lost)
    is made again, up to :data:`MACHINE_RETRIES` times; one it still fails is stored with
    outcome ``error`` and a reason that begins "the machine", never as the controller's.
    """
    if not isinstance(situation, Situation):
        situation = Situation.load(situation)
    for _ in range(MACHINE_RETRIES):
        try:
            return _run(situation, controller, time_limit, seed, spec, params, step_timeout_s,
                        sensed, in_process)  # fmt: skip
        except MachineError:
            continue
    try:
        return _run(situation, controller, time_limit, seed, spec, params, step_timeout_s,
                    sensed, in_process)  # fmt: skip
    except MachineError as e:
        name = _controller_name(controller)
        run_spec = run_spec_with(spec, time_limit, name, params, situation.agent.controller)
        return _record(situation, controller, name, run_spec, seed, None, sensed, False,
                       failed=f"{e} (after {MACHINE_RETRIES + 1} tries)")  # fmt: skip


def _run(
    situation: Situation,
    controller: Any,
    time_limit: float | None,
    seed: int,
    spec: Mapping[str, Any] | None,
    params: Mapping[str, float] | None,
    step_timeout_s: float | None,
    sensed: bool,
    in_process: bool,
) -> RunRecord:
    """One try of :func:`run`; MachineError where the machine failed it."""
    name = _controller_name(controller)
    run_spec = run_spec_with(spec, time_limit, name, params, situation.agent.controller)
    forks = _forks(controller, name, situation, run_spec, in_process)
    if not forks:
        return _record(situation, controller, name, run_spec, seed, step_timeout_s, sensed,
                       in_process)  # fmt: skip
    done = sandbox.call(_record, situation, controller, name, run_spec, seed, step_timeout_s,
                        sensed, in_process)  # fmt: skip
    if not isinstance(done, sandbox.Died):
        return done
    if forks == "agent":
        # Made again with the class in a host process of its own, which reports what it did
        # exactly as it always has (and keeps the run up to that step).
        return _run(situation, controller, time_limit, seed, spec, params, step_timeout_s,
                    sensed, in_process=False)  # fmt: skip
    return _record(situation, controller, name, run_spec, seed, step_timeout_s, sensed,
                   in_process, failed=done.reason())  # fmt: skip


def _record(
    situation: Situation,
    controller: Any,
    name: str | None,
    run_spec: Mapping[str, Any],
    seed: int,
    step_timeout_s: float | None,
    sensed: bool,
    in_process: bool,
    failed: str | None = None,
) -> RunRecord:
    """The run made here (``failed``: not made, ended at its start with that reason)."""
    started, cpu = time.perf_counter(), _cpu_s()
    core = _core.Run(situation.to_json(), spec_json(dict(run_spec), "run"), seed)
    senses: list[Mapping[str, Any]] | None = [] if sensed else None
    if failed is None:
        out, senses = _finished(
            core, controller, situation, run_spec, step_timeout_s, senses, in_process
        )
    else:
        core.fail(failed)
        senses = None if senses is None else [core.observe_agent()]
        out = core.finish()
    record = json.loads(out["record"])
    return RunRecord(
        outcome=record["outcome"],
        reason=record["reason"],
        score=record["score"]["total"],
        breakdown=record["score"]["breakdown"],
        events=record["events"],
        trajectory=out["trajectory"],
        steps=record["steps"],
        time_s=record["time_s"],
        controller=name or (run_spec.get("controller") or situation.agent.controller)["name"],
        seed=seed,
        events_jsonl=out["events_jsonl"],
        events_text=out["events_text"],
        failure=record.get("failure"),
        coverage=record.get("coverage"),
        sensed=None if senses is None else _sensed(senses),
        requirements=verdicts(record.get("requirements", [])),
        signals=dict(out["signals"]),
        cost=(time.perf_counter() - started, _cpu_s() - cpu),
    )


def _cpu_s() -> float:
    """Processor seconds this process and its children that have ended used so far (a
    controller's host process or program ends, and is waited for, before its run's record)."""
    own = resource.getrusage(resource.RUSAGE_SELF)
    ended = resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + ended.ru_utime + ended.ru_stime


def _forks(
    controller: Any,
    name: str | None,
    situation: Situation,
    run_spec: Mapping[str, Any],
    in_process: bool,
) -> str | None:
    """Whether the run is made by a runner (:mod:`sitgen.controllers.sandbox`), because it calls
    a user's class loaded by name: ``"agent"`` (the agent's ``python:``/``navground:`` class,
    in a pool worker), ``"peers"`` (a peer's), or None. Not in a runner (it is the runner), for
    an object handed to :func:`run` (the caller's own, whose effects are theirs to keep), nor
    beside a ``ros2:`` node (its middleware lives in this process)."""
    if sandbox.inside() or not isinstance(controller, (str, type(None))):
        return None
    named = run_spec.get("controller") or situation.agent.controller
    agent = name or (named.get("name") if isinstance(named, dict) else None)
    if not isinstance(agent, str):
        return None  # the core refuses the spec, naming the field
    if in_process and agent.startswith(IN_PROCESS_PREFIXES):
        return "agent"
    peers = (r.controller["name"] for r in situation.robots if r.role == "peer")
    if not agent.startswith(ROS2_PREFIX) and any(
        str(p).startswith(IN_PROCESS_PREFIXES) for p in peers
    ):
        return "peers"
    return None


IN_PROCESS_PREFIXES = ("python:", "navground:")
"""Controllers called in sitgen's own process (a peer may run only these)."""


def _finished(
    core: _core.Run,
    controller: Any,
    situation: Situation,
    run_spec: Mapping[str, Any],
    step_timeout_s: float | None,
    senses: list[Mapping[str, Any]] | None,
    in_process: bool,
) -> tuple[dict[str, Any], list[Mapping[str, Any]] | None]:
    """``core`` stepped to its end and finished: its output and what the agent sensed."""
    if core.agent_is_external or core.external_peers:
        _drive(core, controller, situation, run_spec, step_timeout_s, senses, in_process)
    elif senses is not None:
        _step(core, None, senses)
    else:
        core.run_to_end()
    if senses is not None:
        senses.append(core.observe_agent())
    return core.finish(), senses


def _sensed(senses: list[Mapping[str, Any]]) -> Sensed:
    return Sensed(
        ranges=np.array([np.asarray(o["ranges"], dtype=np.float64) for o in senses]),
        velocity=np.array([o["velocity"] for o in senses], dtype=np.float64),
        time_s=np.array([o["time"] for o in senses], dtype=np.float64),
    )


def _step(
    core: _core.Run,
    act: Callable[[Mapping[str, Any]], tuple[float, float]] | None,
    senses: list[Mapping[str, Any]] | None,
) -> None:
    """Step ``core`` to its end, asking ``act`` (an external agent's controller) for a command
    whenever the agent decides, and keeping every step's observation in ``senses`` if given
    (the core keeps a step's scan for the step, so observing changes nothing)."""
    while True:
        acts = act is not None and core.agent_acts
        obs = core.observe_agent() if acts or senses is not None else None
        command = act(obs) if acts and act is not None and obs is not None else None
        # Kept once the step is sure to be taken, so that the rows match the trajectory's
        # even when the controller fails.
        if senses is not None and obs is not None:
            senses.append(obs)
        if core.step(command):
            return


def _drive(
    core: _core.Run,
    controller: Any,
    situation: Situation,
    run_spec: Mapping[str, Any],
    step_timeout_s: float | None,
    senses: list[Mapping[str, Any]] | None = None,
    in_process: bool = False,
) -> None:
    """Step a run whose agent or some peer has a user controller, turning their failures
    into the outcome."""
    try:
        with user_peers(core, situation, run_spec, in_process or sandbox.inside()):
            if core.agent_is_external:
                _drive_agent(
                    core, controller, situation, run_spec, step_timeout_s, senses, in_process
                )
            elif senses is None:
                core.run_to_end()
            else:
                _step(core, None, senses)
    except MachineError:
        raise  # made again by run(), never the controller's failure
    except ControllerError as e:
        core.fail(str(e))


def _drive_agent(
    core: _core.Run,
    controller: Any,
    situation: Situation,
    run_spec: Mapping[str, Any],
    step_timeout_s: float | None,
    senses: list[Mapping[str, Any]] | None,
    in_process: bool,
) -> None:
    named = run_spec.get("controller") or situation.agent.controller
    if controller is None:
        controller = named["name"]
    assert is_user_controller(controller)
    keep_alive = bool(named.get("keep_alive"))
    timeout_s = step_timeout_s or named.get("step_timeout_s")
    user = load_controller(controller, timeout_s, named.get("params"), in_process, keep_alive)
    try:
        user.reset(reset_info(situation, run_spec, core.agent, user.wants_map))
        # Between the controller's decisions (its control period) its last command stays in
        # force and it is not asked.
        if senses is None:
            user.drive(core)
        else:
            _step(core, user.act, senses)
    finally:
        user.close()


@contextlib.contextmanager
def user_peers(
    core: _core.Run, situation: Situation, run_spec: Mapping[str, Any], isolated: bool
) -> Iterator[None]:
    """The run's peers that have ``python:`` or ``navground:`` controllers, loaded and reset in
    this process and handed to the core, which calls each whenever its peer decides; closed
    at the end. ``isolated``: this process is a disposable pool worker."""
    loaded: list[InProcessController] = []
    ids = core.external_peers
    try:
        for i in ids:
            named = situation.robots[i].controller
            name = str(named["name"])
            peer = load_peer_controller(
                name,
                f"`{name}` of peer {i}",
                named.get("params"),
                isolated,
                named.get("step_timeout_s"),
            )
            loaded.append(peer)
            peer.reset(reset_info(situation, run_spec, i))
        core.set_peers({i: p.peer_act() for i, p in zip(ids, loaded, strict=True)})
        yield
    finally:
        for peer in loaded:
            peer.close()


def robots_at(
    situation: Situation, spec: Mapping[str, Any], seed: int, t_s: float
) -> list[dict[str, Any]]:
    """The robots of ``situation`` as they stand ``t_s`` simulated seconds into its run with
    run spec ``spec`` and sensor seed ``seed``: each at its pose with the rest of its route
    (as in a situation file). A user controller is started and driven there (the core
    restarts only its own controllers part-way)."""
    if _forks(None, None, situation, spec, False):
        # A peer's class is called: in a runner, as a run with it is (sitgen.controllers.sandbox).
        done = sandbox.call(robots_at, situation, dict(spec), seed, t_s)
        if isinstance(done, sandbox.Died):
            raise ControllerError(done.reason())
        return done
    spec_text = spec_json(dict(spec), "run")
    core = _core.Run(situation.to_json(), spec_text, seed)
    if not core.agent_is_external and not core.external_peers:
        robots: list[dict[str, Any]] = json.loads(
            _core.robots_at(situation.to_json(), spec_text, seed, t_s)
        )
        return robots
    with user_peers(core, situation, spec, sandbox.inside()):
        if not core.agent_is_external:
            while core.observe_agent()["time"] < t_s - 1e-9 and not core.step(None):
                pass
        else:
            named = spec.get("controller") or situation.agent.controller
            user = load_controller(named["name"], named.get("step_timeout_s"), named.get("params"))
            try:
                user.reset(reset_info(situation, spec, core.agent, user.wants_map))
                while (obs := core.observe_agent())["time"] < t_s - 1e-9:
                    if core.step(user.act(obs) if core.agent_acts else None):
                        break
            finally:
                user.close()
    robots = json.loads(core.robots_now(situation.to_json()))
    return robots

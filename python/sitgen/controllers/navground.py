"""navground's navigation behaviours as sitgen controllers: ``navground:BEHAVIOR``.

What it does: drives a robot with one of navground's behaviours — ``HL`` (human-like),
``ORCA``, ``HRVO``, ``SocialForce``, or any behaviour a navground plugin registers (C++ or
Python, found by navground's plugin mechanism) — towards the next waypoint of its
route. Each decision it sets the behaviour's state from the observation (pose, velocity,
neighbours, obstacles), targets the waypoint the monitor counts as next as a point, and returns
the behaviour's command for two-wheel differential kinematics at the robot's limits (the wheel
axis is the one whose turn in place at full wheel speed is the robot's largest turn rate), or,
with ``ahead = 1``, for navground's ``Ahead`` kinematics, whose speed and turn rate are limited
each on its own, as the simulated robot's are (the wheeled model allows 0.29 m/s at 1 rad/s where
the robot can do 0.8: stricter than the robot).
The robot is a disc: the body's enclosing circle about its pose, and so is every neighbour.

What it sees is the run spec's controller ``perception``:

- ``sensed`` (default), what a deployed robot has: neighbours are the tracks the laser gives
  (position and velocity of each robot the scan sees), static obstacles the laser's end points
  (from the laser's own position, ``sim.laser.offset_x_m`` ahead of the pose) within
  ``horizon`` (those on a neighbour left out), thinned to the first in each square of a grid
  of twice ``obstacle_radius_m``, a disc of ``obstacle_radius_m`` each.
- ``exact``, what navground's own simulator gives: every other robot's true position and
  velocity, and the map's walls as line segments (those within ``horizon`` of the robot).

Why: sitgen exists to find what a navigation behaviour does wrong, and most behaviours that
robots among people run were written elsewhere. navground implements the ones research and
practice use, on one API; this file is the only adapter a user needs, and the two perceptions
separate a behaviour's own failures from its perception's.

Parameters (the controller spec's ``params``, navground's own names and units): any property
of the behaviour (``HL``: ``tau`` s, ``eta`` s, ``aperture`` rad, ``resolution``,
``barrier_angle`` rad, ``epsilon``; ``ORCA``: ``time_horizon`` s, ``static_time_horizon`` s,
``effective_center``, ``treat_obstacles_as_agents``, ``max_neighbors``; ``HRVO``:
``max_neighbors``, ``uncertainty_offset``; ``SocialForce``: ``tau`` s, ``v_a``, ``v_r``,
``u_a``, ``u_r``, ``phi``, ``c``, ``step_duration`` s; integers and switches as numbers); and
of every behaviour ``horizon`` (m, default navground's 5), ``safety_margin`` (m, default 0),
``optimal_speed`` (m/s, default the robot's top speed), ``rotation_tau`` (s, default 0.5).
sitgen's own: ``tolerance_m`` (m, default 0.25) how near a waypoint counts as reached for the
behaviour (under the monitor's 0.5 m, so that the monitor moves the target on first);
``obstacle_radius_m`` (m, default 0.1) the disc of a laser end point; ``ahead`` (0 or 1, default
0) navground's ``Ahead`` kinematics instead of the two-wheel one.

Source: navground (Guzzi et al., IDSIA; PyPI ``navground``, ``sitgen[navground]``),
``navground.core.Behavior``; the behaviours' papers are cited in its documentation.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np
import numpy.typing as npt

from sitgen._core import RouteFollower

PREFIX = "navground:"
"""How a navground controller's name starts: ``navground:BEHAVIOR``."""

STEP_TIMEOUT_S = 10.0
"""Wall-clock seconds a navground controller's decision may take before its run ends as an
error (a user controller's default is 1 s): a behaviour decides in milliseconds (ORCA's
slowest decision in the case study's worst run, 45 ms on a loaded machine), so only a hang
should end a run, not a stall of a loaded machine (one such stall passed 1 s)."""

PERCEPTIONS = ("sensed", "exact")
"""What a controller may perceive (the run spec's ``controller.perception``)."""

OWN_PARAMS = {"tolerance_m": 0.25, "obstacle_radius_m": 0.1, "ahead": 0.0}
"""sitgen's parameters of the adapter, with their defaults."""

PEER_SWITCH_M = 0.3
"""How near its next waypoint a peer switches to the one after (m; at least ``tolerance_m``):
as sitgen's ``straight`` peers do."""

COMMON_PARAMS = ("horizon", "safety_margin", "optimal_speed", "rotation_tau")
"""Parameters every navground behaviour has (attributes of ``navground.core.Behavior``)."""


@functools.cache
def _core() -> Any:
    """navground's core module with its plugins loaded (once a process), or a one-line
    ValueError saying how to install it."""
    try:
        # An optional dependency (sitgen[navground]), loaded when a navground controller is.
        import navground.core as core
    except ImportError as e:
        raise ValueError(f"navground is not installed ({e}); install sitgen[navground]") from None
    core.load_plugins()
    return core


def behaviours() -> list[str]:
    """The behaviours navground has registered (plugins included), by name."""
    return sorted(name for name in _core().Behavior.types if name)


def enclosing_radius_m(body: Mapping[str, Any]) -> float:
    """The radius of the smallest circle about the robot's pose that holds its body (a
    rectangle ``length_m`` × ``width_m`` whose centre is ``origin_x_m`` ahead of the pose)."""
    half_l, half_w = float(body["length_m"]) / 2, float(body["width_m"]) / 2
    return math.hypot(abs(float(body.get("origin_x_m", 0.0))) + half_l, half_w)


def wheel_axis_m(max_speed_m_s: float, max_turn_rate_rad_s: float) -> float:
    """The wheel axis of a two-wheel differential drive whose wheels at ``max_speed_m_s`` in
    opposite directions turn it at ``max_turn_rate_rad_s``."""
    return 2.0 * max_speed_m_s / max_turn_rate_rad_s


def near_segments(
    walls: npt.NDArray[np.float64], x: float, y: float, within_m: float
) -> npt.NDArray[np.float64]:
    """The rows of ``walls`` (x1, y1, x2, y2) that come within ``within_m`` of (x, y)."""
    if not len(walls):
        return walls
    a, b = walls[:, :2], walls[:, 2:]
    ab = b - a
    length2 = np.maximum(np.einsum("ij,ij->i", ab, ab), 1e-12)
    t = np.clip(np.einsum("ij,ij->i", np.array([x, y]) - a, ab) / length2, 0.0, 1.0)
    nearest = a + ab * t[:, None]
    d2 = (nearest[:, 0] - x) ** 2 + (nearest[:, 1] - y) ** 2
    near: npt.NDArray[np.float64] = walls[d2 <= within_m * within_m]
    return near


def thinned(points: npt.NDArray[np.float64], cell_m: float) -> npt.NDArray[np.float64]:
    """The first of ``points`` (in order) in each square of a ``cell_m`` grid. Discs of radius
    ``cell_m / 2`` on what is left still wall off what the points did from a robot wider than
    ``2 cell_m``, with a few dozen obstacles where a scan has a hundred or more: HRVO's cost
    grows with their cube and Social Force's (in Python) with their number (docs/navground.md)."""
    if not len(points):
        return points
    cells = np.floor(points / cell_m).astype(np.int64)
    _, first = np.unique(cells, axis=0, return_index=True)
    kept: npt.NDArray[np.float64] = points[np.sort(first)]
    return kept


class NavgroundController:
    """One navground behaviour driving one robot; a new instance a run."""

    def __init__(self, behavior: str, **params: float) -> None:
        core = _core()
        if behavior not in core.Behavior.types or not behavior:
            known = ", ".join(behaviours())
            raise ValueError(f"no navground behaviour `{behavior}`; registered: {known}")
        self._core = core
        self.behavior_name = behavior
        self.behavior: Any = core.Behavior.make_type(behavior)
        own = {k: float(params.pop(k, v)) for k, v in OWN_PARAMS.items()}
        self.tolerance_m, self.obstacle_radius_m = own["tolerance_m"], own["obstacle_radius_m"]
        if not (self.tolerance_m >= 0 and self.obstacle_radius_m > 0):
            raise ValueError("tolerance_m must be at least 0 and obstacle_radius_m above 0")
        if own["ahead"] not in (0.0, 1.0):
            raise ValueError(f"ahead is a switch (0 or 1), got {own['ahead']:g}")
        self.ahead = own["ahead"] == 1.0
        self.laser_offset_m = 0.0
        self._optimal_speed = params.pop("optimal_speed", None)
        for name, value in params.items():
            self._set(name, value)
        self.radius_m = 0.0
        self.waypoints: list[list[float]] = []
        self.route: Any = None
        self.walls = np.zeros((0, 4))
        self.exact = False
        self.dt_s = 0.1
        self.limits = (0.0, 0.0)

    def _set(self, name: str, value: float) -> None:
        """Set the behaviour's parameter ``name`` (its own property, or one every behaviour
        has), converting the number to the property's type."""
        b = self.behavior
        if name in b.properties:
            default = b.get(name)
            if isinstance(default, bool):
                b.set(name, bool(value))
            elif isinstance(default, int):
                if value != int(value):
                    raise ValueError(f"parameter `{name}` is a whole number, got {value}")
                b.set(name, int(value))
            elif isinstance(default, float):
                b.set(name, float(value))
            else:
                raise ValueError(f"parameter `{name}` is not a number in navground")
        elif name in COMMON_PARAMS:
            setattr(b, name, float(value))
        else:
            known = ", ".join([*sorted(b.properties), *COMMON_PARAMS, *OWN_PARAMS])
            raise ValueError(
                f"unknown parameter `{name}` of {self.behavior_name}; expected {known}"
            )

    def reset(self, info: dict[str, Any]) -> None:
        core, b = self._core, self.behavior
        perception = info.get("perception", "sensed")
        if perception not in PERCEPTIONS:
            raise ValueError(f"perception `{perception}`: expected one of {PERCEPTIONS}")
        self.exact = perception == "exact"
        self.walls = np.asarray(info.get("walls") or np.zeros((0, 4)), dtype=np.float64)
        if self.exact and "walls" not in info:
            raise ValueError("the exact perception needs the map's walls in the reset info")
        max_speed = float(info["max_speed_m_s"])
        max_turn = math.radians(float(info["max_turn_rate_deg_s"]))
        b.kinematics = (
            core.kinematics.AheadKinematics(max_speed, max_turn)
            if self.ahead
            else core.kinematics.TwoWheelsDifferentialDriveKinematics(
                max_speed, wheel_axis_m(max_speed, max_turn)
            )
        )
        # Beams start at the laser, which may sit ahead of the robot's pose.
        self.laser_offset_m = float(info.get("laser", {}).get("offset_x_m", 0.0))
        self.limits = (max_speed, max_turn)
        b.radius = self.radius_m = enclosing_radius_m(info["body"])
        b.optimal_speed = float(self._optimal_speed or max_speed)
        self.waypoints = [list(w) for w in info["waypoints"]]
        # A peer goes on past its route's end as its `at_end` says, which the monitor (one
        # pass, for the agent) does not count: it follows its route as sitgen's peers do.
        start = info["start"]
        self.route = (
            None
            if info.get("role", "agent") == "agent"
            else RouteFollower(
                (start[0], start[1]),
                [(w[0], w[1]) for w in self.waypoints],
                str(info.get("at_end", "stop")),
                max(PEER_SWITCH_M, self.tolerance_m),
            )
        )
        self.dt_s = float(info.get("control_period_s", info.get("dt_s", 0.1)))

    def act(self, obs: Any) -> tuple[float, float]:
        x, y, heading = obs.pose
        if self.route is not None:
            target = self.route.target((x, y))
        elif obs.waypoints_reached < len(self.waypoints):
            target = self.waypoints[obs.waypoints_reached]
        else:
            target = None
        if target is None:
            return 0.0, 0.0
        core, b = self._core, self.behavior
        v, omega = obs.velocity
        b.position = (x, y)
        b.orientation = heading
        b.velocity = (v * math.cos(heading), v * math.sin(heading))
        b.angular_speed = omega
        b.target = core.Target.Point(target, self.tolerance_m)
        self._perceive(obs, x, y, heading)
        cmd = b.compute_cmd(self.dt_s, core.Frame.relative, True)
        # navground computes in single precision: a feasible command can exceed a limit by
        # a rounding error, which the robot would clamp anyway.
        v_max, omega_max = self.limits
        v_cmd = min(max(float(cmd.velocity[0]), -v_max), v_max)
        return v_cmd, min(max(float(cmd.angular_speed), -omega_max), omega_max)

    def _perceive(self, obs: Any, x: float, y: float, heading: float) -> None:
        """Set the behaviour's environment state from what the perception gives (a behaviour
        whose state is not geometric — none, or navground's raw sensing buffers — is given
        nothing: it avoids nothing this adapter could tell it of)."""
        core, state = self._core, self.behavior.environment_state
        if not isinstance(state, core.GeometricState):
            return
        r = self.radius_m
        tracks = obs.tracks
        state.neighbors = [
            core.Neighbor(t["position"], r, t["velocity"], int(t["id"])) for t in tracks
        ]
        if self.exact:
            near = near_segments(self.walls, x, y, float(self.behavior.horizon) + r)
            state.line_obstacles = [core.LineSegment(s[:2], s[2:]) for s in near]
            return
        ranges = np.asarray(obs.ranges)
        # Beyond the behaviour's horizon a return changes nothing it decides; a beam at
        # maximum range hit nothing.
        reach_m = min(float(obs.max_range), float(self.behavior.horizon) + r)
        hit = ranges < reach_m
        bearing = np.asarray(obs.angles)[hit] + heading
        lx = x + self.laser_offset_m * math.cos(heading)
        ly = y + self.laser_offset_m * math.sin(heading)
        points = np.column_stack(
            [lx + ranges[hit] * np.cos(bearing), ly + ranges[hit] * np.sin(bearing)]
        )
        for t in tracks:  # a return on a neighbour is that neighbour, not a wall
            px, py = t["position"]
            points = points[(points[:, 0] - px) ** 2 + (points[:, 1] - py) ** 2 > (r * 1.2) ** 2]
        radius = self.obstacle_radius_m
        state.static_obstacles = [core.Disc(p, radius) for p in thinned(points, 2 * radius)]


def __getattr__(behavior: str) -> Callable[..., NavgroundController]:
    """``sitgen.controllers.navground:ORCA`` (how a ``navground:ORCA`` controller is loaded,
    in a pool worker or a host process): a factory of controllers running that behaviour."""
    if behavior.startswith("__"):
        raise AttributeError(behavior)
    return functools.partial(NavgroundController, behavior)

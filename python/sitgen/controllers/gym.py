"""Gymnasium environments over generated situations: a learner drives sitgen's agent.

``import sitgen.controllers.gym`` registers ``sitgen/Navigate-v0``::

    import gymnasium
    import sitgen.controllers.gym

    env = gymnasium.make("sitgen/Navigate-v0", spec="examples/specs/crossing_peers.toml", seed=1)
    obs, info = env.reset()
    obs, reward, terminated, truncated, info = env.step(env.action_space.sample())

Each episode is a situation generated from ``spec`` (a situation spec: path, TOML text or dict;
default :data:`DEFAULT_SPEC`, the paper campaign's base) with a seed drawn from the
environment's random generator, run under ``run`` (a run spec: time limit, simulator, monitor,
scoring, ``profile``; its ``controller.control_period_s``, if any, is how long each action
holds). The peers drive as the situation says; the learner drives the agent.

- **Observation** (a dict of float32 arrays): ``ranges``, the laser (metres, one per beam,
  ``range_m`` when nothing is hit); ``goal``, the next waypoint of the route in the robot's
  frame (x ahead, y to the left, metres; zeros once the route is complete); ``velocity``, its
  own (v m/s, ω rad/s).
- **Action**: (v m/s, ω rad/s), within the robot's limits; it holds for one control period.
- **Reward**: the metres of route made good over the step, less ``penalty_weight`` (default
  0.05 per point) times the penalty points the run's scoring table gave for the step (with the
  default table a collision costs 5 m of progress at once and 0.5 m per second it lasts).
- **Termination** when the agent completes its route; **truncation** at the run's time limit.
- **info**: at reset, ``situation_seed`` (``generate_situation(spec, seed)`` gives the episode's
  situation again); at each step, ``events`` (the monitor's events, of every robot, that began
  during the step, as dicts) and ``score`` (the agent's penalty points so far); at the end also
  ``outcome``, ``failure`` (the run's failure class, or None) and ``record`` (the run's record:
  outcome, score with its breakdown, events, failure, coverage).

:class:`NavigateVectorEnv` (``gymnasium.make_vec("sitgen/Navigate-v0", num_envs=n)``) steps
``n`` worlds in one call into the core, in parallel, without the GIL, resetting an episode that
ended on the next step (Gymnasium's next-step autoreset).
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from typing import Any

import gymnasium
import numpy as np
import numpy.typing as npt
from gymnasium import spaces
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from sitgen import _core
from sitgen.world.config import SpecLike, spec_json
from sitgen.world.situation import generate_situation

ENV_ID = "sitgen/Navigate-v0"
PENALTY_WEIGHT = 0.05
"""Metres of progress one penalty point is worth, by default."""
DEFAULT_SPEC: dict[str, Any] = {
    "terrain": {"preset": "rocky_desert"},
    "mission": {"peers_min": 0, "peers_max": 5},
}
"""The situation spec episodes are drawn from by default: the paper campaign's base (a 50 m
rocky desert, 0-5 peers that avoid nothing)."""
GENERATION_TRIES = 20
"""Seeds tried for one episode before a spec that keeps failing to generate is an error."""
MAX_ENVS = 4096
"""Most worlds of one vector environment (each holds its map, robots and scans: a few MB)."""

Observation = dict[str, Any]
"""``ranges``, ``goal``, ``velocity``: float32 arrays."""


class _Worlds:
    """The episodes of one or more environments: situations drawn from a spec, run in the
    core's episode batch."""

    def __init__(
        self,
        spec: SpecLike | None,
        run: Mapping[str, Any] | None,
        n: int,
        threads: int = 0,
    ) -> None:
        if isinstance(n, bool) or not isinstance(n, int) or not 1 <= n <= MAX_ENVS:
            raise ValueError(f"num_envs: {n!r} is not a whole number in [1, {MAX_ENVS}]")
        if isinstance(threads, bool) or not isinstance(threads, int) or not 0 <= threads <= 4096:
            raise ValueError(f"threads: {threads!r} is not a whole number in [0, 4096]")
        self.spec = spec if spec is not None else DEFAULT_SPEC
        self.core = _core.Episodes(spec_json(dict(run or {}), "run"), n, threads)
        resolved = json.loads(self.core.spec_json)
        self.run = resolved
        sim = resolved["sim"]
        beams, range_m = int(sim["laser"]["beams"]), float(sim["laser"]["range_m"])
        v, w = float(sim["max_speed_m_s"]), float(np.radians(sim["max_turn_rate_deg_s"]))
        limits = np.array([v, w], dtype=np.float32)
        self.observation_space = spaces.Dict(
            {
                "ranges": spaces.Box(0.0, range_m, (beams,), np.float32),
                "goal": spaces.Box(-np.inf, np.inf, (2,), np.float32),
                "velocity": spaces.Box(-limits, limits, (2,), np.float32),
            }
        )
        self.action_space = spaces.Box(-limits, limits, (2,), np.float32)
        self.n = n
        self.scores = np.zeros(n)
        self.seeds = np.zeros(n, dtype=np.uint64)

    def start(self, i: int, rng: np.random.Generator) -> None:
        """A new episode in slot ``i``: a situation drawn with ``rng``."""
        for _ in range(GENERATION_TRIES):
            seed = int(rng.integers(2**63))
            try:
                situation = generate_situation(self.spec, seed)
            except _core.GenerationFailed:
                continue
            self.core.reset(i, situation.to_json(), seed)
            self.scores[i], self.seeds[i] = 0.0, seed
            return
        raise _core.GenerationFailed(
            f"spec: no situation generated in {GENERATION_TRIES} tries; widen the map or "
            "lower its obstacle density"
        )

    def finish(self, i: int) -> dict[str, Any] | None:
        """End slot ``i``'s run: its record."""
        text = self.core.finish(i)
        return None if text is None else dict(json.loads(text))


def _one(batch: Mapping[str, Any], i: int) -> Observation:
    return {k: np.array(batch[k][i]) for k in ("ranges", "goal", "velocity")}


def _endings(outcome: str | None) -> tuple[bool, bool]:
    """(terminated, truncated) for a run's outcome."""
    return outcome in ("completed", "error"), outcome == "timeout"


class NavigateEnv(gymnasium.Env[Observation, npt.NDArray[np.float32]]):
    """Drive sitgen's agent through generated situations (see the module's documentation)."""

    # An instance attribute in Gymnasium's Env, so not a ClassVar here.
    metadata: dict[str, Any] = {"render_modes": []}  # noqa: RUF012

    def __init__(
        self,
        spec: SpecLike | None = None,
        seed: int | None = None,
        run: Mapping[str, Any] | None = None,
        penalty_weight: float = PENALTY_WEIGHT,
    ) -> None:
        """``spec``: the situation spec episodes are drawn from; ``seed``: the first episode's,
        when ``reset`` is given none; ``run``: the run spec; ``penalty_weight``: metres of
        progress a penalty point is worth."""
        self._worlds = _Worlds(spec, run, 1, threads=1)
        self.observation_space = self._worlds.observation_space
        self.action_space = self._worlds.action_space
        self.penalty_weight = _penalty_weight(penalty_weight)
        self._seed = seed
        self._live = False

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[Observation, dict[str, Any]]:
        if seed is None and self._seed is not None:
            seed, self._seed = self._seed, None
        super().reset(seed=seed)
        self._worlds.finish(0)
        self._worlds.start(0, self.np_random)
        self._live = True
        seed_ = int(self._worlds.seeds[0])
        return _one(self._worlds.core.observe(), 0), {"situation_seed": seed_}

    def step(
        self, action: npt.NDArray[np.float32]
    ) -> tuple[Observation, float, bool, bool, dict[str, Any]]:
        if not self._live:
            raise RuntimeError("the episode has ended: call reset()")
        command = _commands(action, 1)
        out = self._worlds.core.step(command)
        penalty = float(out["penalty"][0])
        self._worlds.scores[0] += penalty
        reward = float(out["progress_m"][0]) - self.penalty_weight * penalty
        terminated, truncated = _endings(out["outcome"][0])
        observation = _one(out, 0)
        info: dict[str, Any] = {
            "events": [json.loads(e) for e in out["events"][0]],
            "score": float(self._worlds.scores[0]),
        }
        if terminated or truncated:
            record = self._worlds.finish(0) or {}
            self._live = False
            info.update(outcome=record["outcome"], failure=record.get("failure"), record=record)
        return observation, reward, terminated, truncated, info


class NavigateVectorEnv(VectorEnv[Observation, npt.NDArray[np.float32], npt.NDArray[Any]]):
    """``num_envs`` worlds stepped together in one call into the core (see the module's
    documentation). An episode that ended is reset on the next step, whose action for it is
    ignored (next-step autoreset)."""

    metadata: dict[str, Any] = {"autoreset_mode": AutoresetMode.NEXT_STEP}  # noqa: RUF012

    def __init__(
        self,
        num_envs: int = 1,
        spec: SpecLike | None = None,
        seed: int | None = None,
        run: Mapping[str, Any] | None = None,
        penalty_weight: float = PENALTY_WEIGHT,
        threads: int = 0,
    ) -> None:
        """As :class:`NavigateEnv`, for ``num_envs`` worlds stepped on ``threads`` threads
        (0: every core)."""
        self._worlds = _Worlds(spec, run, num_envs, threads)
        self.num_envs = num_envs
        self.single_observation_space = self._worlds.observation_space
        self.single_action_space = self._worlds.action_space
        self.observation_space = batch_space(self.single_observation_space, num_envs)
        self.action_space = batch_space(self.single_action_space, num_envs)
        self.penalty_weight = _penalty_weight(penalty_weight)
        self._seed = seed
        self._rngs = [np.random.default_rng() for _ in range(num_envs)]
        self._ended = np.zeros(num_envs, dtype=bool)

    def reset(
        self,
        *,
        seed: int | list[int | None] | None = None,
        options: dict[str, Any] | None = None,
    ) -> tuple[Observation, dict[str, Any]]:
        if seed is None and self._seed is not None:
            seed, self._seed = self._seed, None
        seeds = [seed + i for i in range(self.num_envs)] if isinstance(seed, int) else seed
        for i in range(self.num_envs):
            given = None if seeds is None else seeds[i]
            if given is not None or seeds is None:
                self._rngs[i] = np.random.default_rng(given)
            self._worlds.finish(i)
            self._worlds.start(i, self._rngs[i])
        self._ended[:] = False
        observation = self._worlds.core.observe()
        seeds_ = self._worlds.seeds.copy()
        info = {"situation_seed": seeds_, "_situation_seed": np.ones(self.num_envs, dtype=bool)}
        return {k: observation[k] for k in ("ranges", "goal", "velocity")}, info

    def step(
        self, actions: npt.NDArray[np.float32]
    ) -> tuple[
        Observation,
        npt.NDArray[np.float64],
        npt.NDArray[np.bool_],
        npt.NDArray[np.bool_],
        dict[str, Any],
    ]:
        commands = _commands(actions, self.num_envs)
        restart = np.flatnonzero(self._ended)
        for i in restart:
            self._worlds.finish(int(i))
        out = self._worlds.core.step(commands)
        for i in restart:
            self._worlds.start(int(i), self._rngs[int(i)])
        penalty = np.asarray(out["penalty"], dtype=np.float64)
        self._worlds.scores += penalty
        rewards = np.asarray(out["progress_m"], dtype=np.float64) - self.penalty_weight * penalty
        endings = [_endings(o) for o in out["outcome"]]
        terminated = np.array([t for t, _ in endings], dtype=bool)
        truncated = np.array([t for _, t in endings], dtype=bool)
        events = np.empty(self.num_envs, dtype=object)
        events[:] = [[json.loads(e) for e in started] for started in out["events"]]
        observation = {k: out[k] for k in ("ranges", "goal", "velocity")}
        if len(restart):
            fresh = self._worlds.core.observe()
            for k in observation:
                observation[k][restart] = fresh[k][restart]
            rewards[restart] = 0.0
        self._ended = terminated | truncated
        info = {
            "events": events,
            "_events": np.array([bool(e) for e in events]),
            "score": self._worlds.scores.copy(),
            "_score": np.ones(self.num_envs, dtype=bool),
        }
        return observation, rewards, terminated, truncated, info


def _register() -> None:
    if ENV_ID not in gymnasium.registry:
        gymnasium.register(
            ENV_ID,
            entry_point="sitgen.controllers.gym:NavigateEnv",
            vector_entry_point="sitgen.controllers.gym:NavigateVectorEnv",
            disable_env_checker=False,
        )


_register()


def _penalty_weight(value: float) -> float:
    """``value`` if it is a finite number ≥ 0 (a negative weight would make penalties a bonus,
    NaN every reward NaN), else a ValueError naming it."""
    if isinstance(value, bool) or not isinstance(value, int | float) or not 0 <= value < math.inf:
        raise ValueError(f"penalty_weight: {value!r} is not a finite number ≥ 0")
    return float(value)


def _commands(actions: Any, n: int) -> npt.NDArray[np.float64]:
    """``n`` actions as an (n, 2) array of real numbers (speed, turn rate), or a ValueError
    saying what was given."""
    given = np.asarray(actions)
    if given.dtype.kind not in "iuf":
        raise ValueError(f"action: expected real numbers (v, omega), got dtype {given.dtype}")
    if given.size != 2 * n:
        raise ValueError(f"action: expected {n} × (v, omega), got shape {given.shape}")
    return given.astype(np.float64).reshape(n, 2)

"""The Gymnasium environment: it passes Gymnasium's own checker, its episodes are the
generated situations driven by the learner, it ends as the run ends, and the vectorised form
steps the same worlds as single environments do."""

from __future__ import annotations

import itertools
import math
import warnings
from typing import Any

import gymnasium
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import sitgen
import sitgen.controllers.gym
from sitgen.controllers.gym import NavigateEnv, NavigateVectorEnv

OPEN = {
    "terrain": {"preset": "open_field", "width_m": 25.0, "height_m": 25.0},
    "mission": {"peers_min": 0, "peers_max": 0, "min_route_length_m": 10.0},
}
CROSSING = {
    "terrain": {"preset": "open_field", "width_m": 25.0, "height_m": 25.0},
    "mission": {"peers_min": 2, "peers_max": 2, "peer_mode": "crossing"},
}


def towards_goal(obs: dict[str, Any]) -> np.ndarray:
    """Turn toward the next waypoint, drive when facing it."""
    bearing = math.atan2(float(obs["goal"][1]), float(obs["goal"][0]))
    v = 0.5 if abs(bearing) < 0.3 else 0.0
    return np.array([v, float(np.clip(2.0 * bearing, -1.5, 1.5))], dtype=np.float32)


def test_the_environment_passes_gymnasiums_checker() -> None:
    env = gymnasium.make("sitgen/Navigate-v0", spec=CROSSING, seed=1)
    with warnings.catch_warnings():
        # Physical units are the interface (m, m/s, rad/s), not a normalised box.
        warnings.filterwarnings("ignore", message=".*(normalized|infinity).*")
        check_env(env.unwrapped)
    observations, actions = env.observation_space, env.action_space
    assert isinstance(observations, gymnasium.spaces.Dict)
    assert isinstance(actions, gymnasium.spaces.Box)
    assert observations["ranges"].shape == (181,)
    assert actions.high.tolist() == pytest.approx([0.8, math.pi / 2])


def test_an_episode_is_the_generated_situation_driven_to_its_end() -> None:
    env = NavigateEnv(spec=OPEN, run={"time_limit_s": 120}, penalty_weight=0.0)
    obs, info = env.reset(seed=4)
    situation = sitgen.generate_situation(OPEN, int(info["situation_seed"]))
    agent = situation.agent
    points = [(agent.start.x_m, agent.start.y_m), *agent.waypoints]
    route_m = sum(math.dist(a, b) for a, b in itertools.pairwise(points))
    # The goal is the first waypoint, in the robot's frame.
    (gx, gy), h = agent.waypoints[0], agent.start.heading_rad
    dx, dy = gx - agent.start.x_m, gy - agent.start.y_m
    expected = (math.cos(h) * dx + math.sin(h) * dy, -math.sin(h) * dx + math.cos(h) * dy)
    assert obs["goal"].tolist() == pytest.approx(expected, abs=1e-4)
    total, steps = 0.0, 0
    while True:
        obs, reward, terminated, truncated, info = env.step(towards_goal(obs))
        total, steps = total + reward, steps + 1
        if terminated or truncated:
            break
    assert terminated and not truncated
    assert info["outcome"] == "completed"
    assert info["record"]["steps"] == steps
    # With no penalties the rewards add up to the route: every metre of it made good once.
    assert total == pytest.approx(route_m, abs=0.05)
    with pytest.raises(RuntimeError, match="call reset"):
        env.step(towards_goal(obs))


def test_penalties_and_events_reach_the_learner_and_the_time_limit_truncates() -> None:
    # Standing still among crossing peers until the limit: no progress, the peers' events.
    env = NavigateEnv(spec=CROSSING, run={"time_limit_s": 60}, seed=2)
    env.reset()
    rewards, kinds = [], []
    while True:
        _, reward, terminated, truncated, info = env.step(np.zeros(2, dtype=np.float32))
        rewards.append(reward)
        kinds += [e["kind"] for e in info["events"]]
        if terminated or truncated:
            break
    assert truncated and not terminated and len(rewards) == 600
    assert info["outcome"] == "timeout"
    assert "waypoint_reached" in kinds
    # The reward is the penalty alone, and the score is the run's without the timeout.
    score = sum(
        line["points"] for k, line in info["record"]["score"]["breakdown"].items() if k != "timeout"
    )
    assert -sum(rewards) == pytest.approx(sitgen.controllers.gym.PENALTY_WEIGHT * score)
    assert info["score"] == pytest.approx(score)


def test_an_action_holds_for_the_control_period() -> None:
    env = NavigateEnv(
        spec=OPEN,
        run={"time_limit_s": 2, "controller": {"name": "snd_follow", "control_period_s": 0.5}},
    )
    env.reset(seed=1)
    steps = 0
    while not any(env.step(np.array([0.2, 0.0], dtype=np.float32))[2:4]):
        steps += 1
    assert steps + 1 == 4
    with pytest.raises(sitgen.SpecError, match="control_period_s"):
        NavigateEnv(run={"controller": {"name": "snd_follow", "control_period_s": 0.25}})


def test_the_vector_env_steps_the_worlds_single_envs_step() -> None:
    n, seed = 3, 7
    vector = NavigateVectorEnv(n, spec=CROSSING, run={"time_limit_s": 5}, threads=2)
    singles = [NavigateEnv(spec=CROSSING, run={"time_limit_s": 5}) for _ in range(n)]
    obs, info = vector.reset(seed=seed)
    for i, env in enumerate(singles):
        one, one_info = env.reset(seed=seed + i)
        assert one_info["situation_seed"] == info["situation_seed"][i]
        assert np.array_equal(one["ranges"], obs["ranges"][i])
    for t in range(51):
        actions = np.array([[0.1 * (t % 4), 0.2 * (i - 1)] for i in range(n)], dtype=np.float32)
        obs, rewards, terminated, truncated, info = vector.step(actions)
        for i, env in enumerate(singles):
            if t == 50:  # the episodes ended at step 50 (5 s); the vector env restarts them
                assert rewards[i] == 0.0 and not (terminated[i] or truncated[i])
                continue
            one, reward, done, cut, _ = env.step(actions[i])
            assert np.array_equal(one["ranges"], obs["ranges"][i]), (t, i)
            assert np.array_equal(one["goal"], obs["goal"][i])
            assert reward == pytest.approx(rewards[i])
            assert (done, cut) == (terminated[i], truncated[i])
        if t == 49:
            assert truncated.all()
    vec = gymnasium.make_vec(
        "sitgen/Navigate-v0", num_envs=2, vectorization_mode="vector_entry_point"
    )
    assert isinstance(vec.unwrapped, NavigateVectorEnv)

"""Does a user controller speak the interface? ``sitgen check-controller`` and the checks a
campaign makes before its runs.

:func:`check_controller` drives a controller a few steps of a situation and says, check by
check, what is wrong with it (in the spirit of Gymnasium's ``check_env``); :func:`repeats`
runs it twice and compares; :func:`resets` runs a ``ros2:`` node kept alive after another
situation and compares it with a fresh node's run. Every check makes runs with
:func:`sitgen.run.run` and the same pieces of it a run uses, so a controller that passes runs
as it was checked.
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import time
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from sitgen import _core
from sitgen.controllers.deadlines import ControllerError
from sitgen.controllers.ros2.controller import PREFIX as ROS2_PREFIX
from sitgen.controllers.ros2.controller import stop_kept_nodes
from sitgen.controllers.ros2.native import native_problem
from sitgen.controllers.user import load_controller
from sitgen.run import RunRecord, reset_info, run, user_peers
from sitgen.world.situation import Situation


@dataclass(frozen=True)
class Check:
    """One conformance check of a user controller."""

    name: str
    ok: bool
    detail: str


def check_controller(
    controller: Any,
    situation: Situation,
    steps: int = 50,
    step_timeout_s: float | None = None,
    params: Mapping[str, float] | None = None,
    kept_after: Situation | None = None,
) -> list[Check]:
    """Drive ``controller`` for ``steps`` steps of ``situation`` and say what is wrong with it,
    check by check (in the spirit of Gymnasium's ``check_env``): it loads, it accepts the reset
    message, every reply is a pair of finite numbers in time, commands stay within the robot's
    limits (larger ones are clamped, which is usually a units mistake), and it shuts down.
    ``kept_after``: also whether a ``ros2:`` node kept alive across runs runs ``situation``
    after a run of ``kept_after`` as a fresh node does (:func:`resets`)."""
    checks: list[Check] = []
    # The run first: the core's thread pool starts with it, on every core, before a program's
    # start keeps this thread to one (ProcessController), which threads started then inherit.
    core = _core.Run(situation.to_json(), json.dumps({"controller": {"name": "cmd:check"}}), 0)
    try:
        user = load_controller(controller, step_timeout_s, params)
    except ControllerError as e:
        return [Check("loads", False, str(e))]
    try:
        user.load()
    except ControllerError as e:
        user.close()
        return [Check("loads", False, str(e))]
    checks.append(Check("loads", True, user.name))
    info = reset_info(situation, {}, 0)
    info["params"] = dict(params or {})
    peers = contextlib.ExitStack()
    try:
        try:
            user.reset(info)
        except ControllerError as e:
            checks.append(Check("reset", False, str(e)))
            return checks
        checks.append(Check("reset", True, "accepted the route, body, laser and limits"))
        try:  # the situation's own peers, where they run python: or navground: controllers
            peers.enter_context(user_peers(core, situation, {}, False))
        except ControllerError as e:
            checks.append(Check("peers", False, f"the situation's peers: {e}"))
            return checks
        slowest, beyond, taken, spent = 0.0, 0, 0, 0.0
        for _ in range(steps):
            obs = core.observe_agent()
            began = time.perf_counter()
            try:
                v, omega = user.act(obs)
            except ControllerError as e:
                checks.append(Check("act", False, str(e)))
                return checks
            took = time.perf_counter() - began
            slowest, spent = max(slowest, took), spent + took
            if not (math.isfinite(v) and math.isfinite(omega)):
                checks.append(
                    Check("act", False, f"returned ({v}, {omega}) at {obs['time']:.1f} s")
                )
                return checks
            if abs(v) > info["max_speed_m_s"] or abs(omega) > math.radians(
                info["max_turn_rate_deg_s"]
            ):
                beyond += 1
            taken += 1
            try:
                ended = core.step((v, omega))
            except ControllerError as e:
                checks.append(Check("peers", False, f"the situation's peers: {e}"))
                return checks
            if ended:
                break
        how = ""
        if isinstance(controller, str) and controller.startswith(ROS2_PREFIX):
            problem = native_problem()
            how = (
                "; sitgen's side of each period in C (in Python for a node that reads /tf)"
                if problem is None
                else f"; sitgen's side of each period in Python, slower ({problem})"
            )
        checks.append(
            Check(
                "act", True, f"{taken} finite commands, slowest reply {slowest * 1e3:.1f} ms{how}"
            )
        )
        checks.append(Check("cost", True, campaign_cost(spent / max(taken, 1), dt_s=info["dt_s"])))
        checks.append(
            Check(
                "limits",
                beyond == 0,
                "every command within the velocity limits"
                if beyond == 0
                else f"{beyond} of {taken} commands beyond {info['max_speed_m_s']} m/s or "
                f"{info['max_turn_rate_deg_s']} deg/s (they are clamped; omega is in rad/s)",
            )
        )
    finally:
        peers.close()
        unclean = user.close()
    checks.append(Check("close", unclean is None, unclean or "shut down on `end`"))
    if isinstance(controller, str):
        checks.append(repeats(controller, situation, steps, params))
    if isinstance(controller, str) and kept_after is not None:
        table = {"name": controller, "params": dict(params or {})}
        checks.append(resets(table, situation, kept_after, steps))
    return checks


DEFAULT_RUNS, DEFAULT_LIMIT_S = 500, 600.0
"""The default campaign's size and time limit (the paper's, ``sitgen campaign``)."""
SMALL_RUNS, SMALL_LIMIT_S = 50, 120.0
"""A campaign a slow controller can afford first (docs/your-controller.md)."""
COPIES_SHARE = 0.25
"""What robustness copies add to a campaign's cost, at most (``make bench``)."""


def campaign_cost(step_s: float, dt_s: float = 0.1, workers: int | None = None) -> str:
    """What the default campaign costs on this machine for a controller that takes
    ``step_s`` a decision (every ``dt_s`` simulated), said as a person plans by: an upper
    bound (every run to its time limit, robustness copies included) on ``workers`` (default
    every core), and the smaller campaign to start with."""
    workers = workers or os.cpu_count() or 1

    def hours(runs: int, limit_s: float) -> float:
        return runs * (limit_s / dt_s) * step_s * (1 + COPIES_SHARE) / workers / 3600

    def said(h: float) -> str:
        return f"{h:.1f} h" if h >= 1 else f"{max(1.0, h * 60):.0f} min"

    return (
        f"{step_s * 1e3:.2g} ms a step: the default campaign ({DEFAULT_RUNS} runs of up to "
        f"{DEFAULT_LIMIT_S:g} s) takes up to ~{said(hours(DEFAULT_RUNS, DEFAULT_LIMIT_S))} on "
        f"{workers} workers; `--time-limit {SMALL_LIMIT_S:g} --n {SMALL_RUNS}` ~"
        f"{said(hours(SMALL_RUNS, SMALL_LIMIT_S))}"
    )


def repeats(
    controller: str,
    situation: Situation,
    steps: int = 50,
    params: Mapping[str, float] | None = None,
) -> Check:
    """Whether ``controller`` drives ``situation`` the same way twice (``steps`` control
    periods): a controller whose commands depend on timing (a node that acts on whatever
    message arrived last, a program that reads the clock) cannot show its user a failure
    again. Names the first step where the second run's poses differ from the first's."""
    timing = _Timing.of(situation, {})
    first, second = (
        run(situation, controller=controller, time_limit=steps * timing.period_s, params=params)
        for _ in range(2)
    )
    if errors := _errors(first, second):
        return Check("repeats", False, errors)
    differ = timing.first_difference(first, second)
    if differ is None:
        return Check("repeats", True, f"the same {len(first.trajectory)} poses on a second run")
    return Check(
        "repeats",
        False,
        f"a second run of the same situation differs from the first: {differ}; its commands "
        'depend on timing, not only on what it was given (docs/ros2.md, "Determinism")',
    )


def resets(
    table: Mapping[str, Any],
    situation: Situation,
    before: Situation,
    steps: int = 50,
    spec: Mapping[str, Any] | None = None,
) -> Check:
    """Whether the ``ros2:`` node of the controller table ``table`` (name, params, control
    period, …), kept alive across runs (``keep_alive``), drives ``situation`` after a run of
    ``before`` as a freshly started node does (``steps`` control periods each, under the run
    spec ``spec``, whose controller ``table`` replaces): one that keeps state from run to run
    (a goal read once, a filter's history) would give every run after its first another
    result than the run's own."""
    base = {k: v for k, v in (spec or {}).items() if k != "controller"}
    fresh, kept = ({**base, "controller": {**table, "keep_alive": k}} for k in (False, True))
    timing = _Timing.of(situation, fresh)
    limit = steps * timing.period_s
    first = run(situation, spec=fresh, time_limit=limit)
    try:
        run(before, spec=kept, time_limit=limit)
        again = run(situation, spec=kept, time_limit=limit)
    finally:
        stop_kept_nodes()
    if errors := _errors(first, again):
        return Check("resets", False, errors)
    differ = timing.first_difference(first, again)
    if differ is None:
        return Check("resets", True, "kept alive, a run after another equals a fresh node's")
    return Check(
        "resets",
        False,
        f"kept alive, after a run of another situation, its run differs from a fresh node's: "
        f"{differ}; the node keeps state from run to run (give it a reset service, or drop "
        'keep_alive: docs/ros2.md, "One node across runs")',
    )


def _errors(a: RunRecord, b: RunRecord) -> str | None:
    if "error" in (a.outcome, b.outcome):
        return f"a run of the two ended in error: {a.reason if a.outcome == 'error' else b.reason}"
    return None


@dataclass(frozen=True)
class _Timing:
    """A run's control period and simulator step (seconds), as its run spec resolves them."""

    period_s: float
    dt_s: float

    @staticmethod
    def of(situation: Situation, spec: Mapping[str, Any]) -> _Timing:
        info = reset_info(situation, spec, 0)
        return _Timing(float(info["control_period_s"]), float(info["dt_s"]))

    def first_difference(self, a: RunRecord, b: RunRecord) -> str | None:
        """Where two runs of one situation first differ (the control period whose command
        moved a pose), or None if they are the same."""
        rows = min(len(a.trajectory), len(b.trajectory))
        differ = (i for i in range(rows) if not np.array_equal(a.trajectory[i], b.trajectory[i]))
        first = next(differ, None)
        if first is None and len(a.trajectory) == len(b.trajectory):
            return None
        # A pose row is a simulation step; the command that moved it came one period before.
        at_s = (rows if first is None else first) * self.dt_s - self.period_s
        return f"its command of the control period at {max(0.0, at_s):.1f} s was another"

"""Shrinking: reduce a failing situation to a small valid one that fails the same way.

A failure found in a large map with five peers and a long route is hard to read; the same
failure with one peer, two obstacles and a few seconds of driving takes one look. Shrinking
tries smaller situations — each a *candidate* — and keeps one only if it still fails with the
same failure class for the same controller and run spec. It applies these reductions in turn,
and repeats them while any of them still helps (at most ``PASSES`` times):

1. drop peers (delta debugging, Zeller's ddmin, over the peers);
2. cut the agent's route to the legs up to the failure;
3. start later: every robot placed where it stood a little before the failure, at rest, with
   the rest of its route (``START_EARLIER_S`` before it, the latest that still fails);
4. drop or shorten peer legs (a peer driving to its end and stopping, then ddmin over its
   waypoints);
5. remove obstacle cells far from where things happen (farther than ``KEEP_WITHIN_M`` from
   every point any robot drove through);
6. remove obstacles (ddmin over their 8-connected components);
7. crop the map around the action (every robot's path, start and waypoints, plus
   ``CROP_MARGIN_M``).

Every candidate is checked first (the core's ``shrink`` module: it reads as a situation file
does, robots start clear of obstacles, the edge and each other, peer legs are clear on the
dilated map where the original's are); an invalid candidate is skipped, not run. Every probe is
an ordinary deterministic run, batched in Rust across ``workers`` threads (for a user
controller — ``python:``, ``cmd:``, ``ros2:`` — across ``workers`` processes, each run through
:func:`sitgen.run.run`; a candidate its controller could not finish is skipped), and the
batches do not depend on the worker count, so the same input gives the same minimal situation
whatever ``workers``. The recorded choice sequence of the generator is not shrunk: a shrunk
situation is edited directly, and records in ``provenance.shrunk_from`` the content hash it
came from.

:class:`Shrinker` is one algorithm, the seven reductions above repeated while any helps, read
beside each other; ddmin, which several call, is :mod:`sitgen.triage.ddmin`, what they edit and
give :mod:`sitgen.triage.candidate`. The entry points (:func:`shrink`, :func:`shrink_run`,
:func:`shrink_top`) are a few lines each over it.
"""

from __future__ import annotations

import itertools
import json
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
from scipy import ndimage

from sitgen import _core
from sitgen.controllers.user import is_user_controller
from sitgen.execution.jobs import check_workers
from sitgen.run import robots_at, run
from sitgen.store import Store
from sitgen.triage.candidate import Candidate, Measure, ShrinkResult, Target
from sitgen.triage.ddmin import ddmin
from sitgen.triage.failures import distinct_failures
from sitgen.triage.probes import user_probes
from sitgen.triage.recall import stored_run, whole_run
from sitgen.triage.requirements import PREFIX as REQUIREMENT
from sitgen.triage.robustness import HORIZON_AFTER_S, MOST_HORIZON_S, horizon_of
from sitgen.world.config import spec_json
from sitgen.world.figure import draw_situation
from sitgen.world.situation import Situation

MAX_PROBES = 500
"""Probes (runs) one shrink may make by default; shrinking stops where the budget ends, with
the smallest situation found so far."""

MOST_PROBES = 1_000_000
"""The largest budget one shrink may be given (docs/limits.md)."""

PASSES = 3
"""Rounds of all reductions at most (a round that reduces nothing ends shrinking earlier)."""

START_EARLIER_S = (2.0, 5.0, 10.0, 20.0, 40.0, 80.0)
"""How long before the failure the shrunk situation may start, simulated seconds: the
shortest that still fails is kept."""

KEEP_WITHIN_M = (1.0, 2.0, 4.0, 8.0)
"""Obstacle cells within this distance of some robot's path are kept, metres: the nearest
that still fails is kept."""

CROP_MARGIN_M = (1.0, 2.0, 4.0)
"""Margin around the action when cropping the map, metres beyond every point a robot's
rotation centre passed, started at or is to drive to: the narrowest that still fails is kept
(a margin too narrow for a body is a candidate the start check skips)."""


NOTHING_TO_SHRINK = "the run does not fail (it has no failure class): nothing to shrink"


class ShrinkError(ValueError):
    """A situation that cannot be shrunk (it does not fail, or not the way asked)."""


class Shrinker:
    """One shrink: the original, how it is run, the target class and the probes made."""

    def __init__(
        self,
        original: Situation,
        run_spec: dict[str, Any],
        run_seed: int,
        failure_class: str | None,
        workers: int,
        max_probes: int,
        on_progress: Callable[[int, int], None] | None = None,
        watch: dict[str, Any] | None = None,
    ) -> None:
        """Bind a shrink to ``original`` run with ``run_spec`` and ``run_seed``; runs it once to
        find what must be kept (raises :exc:`ShrinkError` if it does not fail so). ``watch``:
        how far to watch that run (a stored run's failure says: :func:`watch_of`); without it
        that one run goes to its time limit. Every later probe is watched until its failure is
        decided."""
        self.original = original
        self.original_json = original.to_json()
        self.resolution = original.grid.resolution
        self.run_spec = run_spec
        self._watch(watch)
        self.run_seed = run_seed
        self.workers = workers
        self.max_probes = max_probes
        self.on_progress = on_progress
        self.leg_margin = _core.shrink_leg_margin(self.original_json)
        named = (run_spec.get("controller") or original.agent.controller)["name"]
        peers = [r.controller["name"] for r in original.robots if r.role == "peer"]
        self.user = any(is_user_controller(n) for n in [named, *peers])
        """Whether the agent's or a peer's controller is a user's (its probes then run
        through :func:`sitgen.run.run`, each in a process of a pool, rather than in the
        core)."""
        self.cache: dict[str, dict[str, Any]] = {}
        self.paths: dict[str, npt.NDArray[np.float64]] = {}
        self.files: dict[str, str] = {}
        self.start = Candidate(
            np.ascontiguousarray(original.grid.occupied, dtype=bool),
            tuple(json.loads(self.original_json)["robots"]),
        )
        self.probes = 0
        self.skipped = 0
        self.exhausted = False
        self.dt_s = float(run_spec.get("sim", {}).get("dt_s", 0.1))
        self.target = self._target(failure_class)
        self._watch(watch_of(self.target, self.target.time_s(self.probe(self.start))))

    def _watch(self, watch: dict[str, Any] | None) -> None:
        """Probe from now on with the run spec watched as ``watch`` says (None: whole runs)."""
        self.probe_spec = self.run_spec if watch is None else {**self.run_spec, "watch": watch}
        self.run_json = spec_json(self.probe_spec, "run")

    # Building and probing candidates.

    def situation_json(self, c: Candidate) -> str:
        """``c`` as a situation file."""
        return _core.shrunk_situation(
            self.original_json, c.occupied, self.resolution, json.dumps(list(c.robots))
        )

    def kept_json(self, c: Candidate) -> str:
        """A candidate that was kept (restarts and path runs of it, and the result) as a
        situation file, built once; probes of the rest build theirs and let it go."""
        if c.key not in self.files:
            self.files[c.key] = self.situation_json(c)
        return self.files[c.key]

    def outcomes(self, candidates: Sequence[Candidate]) -> list[dict[str, Any]]:
        """Each candidate's probe (from the cache, or run now as one batch); a candidate past
        the probe budget counts as not failing."""
        keys = [c.key for c in candidates]
        todo: dict[str, Candidate] = {}
        for k, c in zip(keys, candidates, strict=True):
            if k not in self.cache and k not in todo:
                todo[k] = c
        if todo:
            room = max(0, self.max_probes - self.probes)
            batch = list(todo.items())[:room]
            if len(batch) < len(todo):
                self.exhausted = True
            situations = [self.situation_json(c) for _, c in batch]
            probes = (
                user_probes(
                    situations, self.probe_spec, self.run_seed, self.leg_margin, self.workers
                )
                if self.user
                else _core.shrink_probes(
                    situations, self.run_json, self.run_seed, self.leg_margin, self.workers
                )
            )
            for (k, _), p in zip(batch, probes, strict=True):
                self.cache[k] = p
                if p["ok"]:
                    self.probes += 1
                else:
                    self.skipped += 1
            if self.on_progress is not None:
                self.on_progress(self.probes, self.max_probes)
        over = {"ok": False, "problem": "over the probe budget"}
        return [self.cache.get(k, over) for k in keys]

    def fails(self, candidates: Sequence[Candidate]) -> list[bool]:
        return [self.target.met(p) for p in self.outcomes(candidates)]

    def probe(self, c: Candidate) -> dict[str, Any]:
        return self.outcomes([c])[0]

    def trajectory(self, c: Candidate) -> npt.NDArray[np.float64]:
        """Every robot's path in ``c``'s run: (steps + 1, robots, 3). One more run."""

        if c.key not in self.paths:
            self.probes += 1
            situation = Situation(self.kept_json(c))
            watched = run(situation, seed=self.run_seed, spec=self.probe_spec)
            self.paths[c.key] = watched.trajectory
        return self.paths[c.key]

    def robots_at(self, c: Candidate, t_s: float) -> list[dict[str, Any]]:
        """``c``'s robots as they stand ``t_s`` into its run. One more (partial) run."""
        self.probes += 1
        return robots_at(Situation(self.kept_json(c)), self.run_spec, self.run_seed, t_s)

    # The reductions: each returns a candidate that still fails (``c`` itself if none does).

    def drop_peers(self, c: Candidate) -> Candidate:
        agent, peers = c.robots[0], list(range(1, len(c.robots)))

        def build(kept: list[int]) -> Candidate:
            return c.with_robots([agent, *(c.robots[i] for i in kept)])

        kept = ddmin(peers, lambda subsets: self.fails([build(s) for s in subsets]))
        return build(kept)

    def cut_agent_route(self, c: Candidate) -> Candidate:
        agent = c.robots[0]
        n = len(agent["waypoints"])
        if n < 2:
            return c
        at_failure = self.robots_at(c, self.target.time_s(self.probe(c)))[0]
        heading_for = n - len(at_failure["waypoints"])
        lengths = sorted({k for k in (heading_for + 1 + 2**i - 1 for i in range(8)) if k < n})
        candidates = [
            c.with_robots([{**agent, "waypoints": agent["waypoints"][:k]}, *c.robots[1:]])
            for k in lengths
        ]
        return _first_failing(candidates, self.fails) or c

    def start_later(self, c: Candidate) -> Candidate:
        t_fail = self.target.time_s(self.probe(c))
        starts = [t_fail - d for d in START_EARLIER_S if t_fail - d >= self.dt_s]
        candidates = [c.with_robots(self.robots_at(c, t)) for t in starts]
        return _first_failing(candidates, self.fails) or c

    def shorten_peer_legs(self, c: Candidate) -> Candidate:
        for i in range(1, len(c.robots)):
            peer = c.robots[i]
            if peer["at_end"] != "stop":
                stop = _with_robot(c, i, {**peer, "at_end": "stop"})
                if self.fails([stop])[0]:
                    c = stop
            waypoints = list(range(len(c.robots[i]["waypoints"])))

            def build(kept: list[int], c: Candidate = c, i: int = i) -> Candidate:
                r = c.robots[i]
                return _with_robot(c, i, {**r, "waypoints": [r["waypoints"][k] for k in kept]})

            kept = ddmin(waypoints, lambda subsets: self.fails([build(s) for s in subsets]))
            c = build(kept)
        return c

    def clear_far_cells(self, c: Candidate) -> Candidate:
        if not c.occupied.any():
            return c
        distance = self._distance_to_paths(c)
        candidates = [
            replace(c, occupied=c.occupied & (distance <= d))
            for d in KEEP_WITHIN_M
            if (c.occupied & (distance > d)).any()
        ]
        return _first_failing(candidates, self.fails) or c

    def remove_obstacles(self, c: Candidate) -> Candidate:
        labels, count = ndimage.label(c.occupied, structure=np.ones((3, 3), dtype=bool))

        def build(kept: list[int]) -> Candidate:
            return replace(c, occupied=np.isin(labels, kept))

        kept = ddmin(
            list(range(1, count + 1)), lambda subsets: self.fails([build(s) for s in subsets])
        )
        return build(kept)

    def crop(self, c: Candidate) -> Candidate:
        rows, cols = c.occupied.shape
        res = self.resolution
        points = self._action_points(c)
        (x_lo, y_lo), (x_hi, y_hi) = points.min(axis=0), points.max(axis=0)
        candidates = []
        for margin in CROP_MARGIN_M:
            m = margin
            c0 = max(0, math.floor((x_lo - m) / res))
            c1 = min(cols, math.ceil((x_hi + m) / res))
            bottom = max(0, math.floor((y_lo - m) / res))
            top = min(rows, math.ceil((y_hi + m) / res))
            if (c0, c1, bottom, top) == (0, cols, 0, rows):
                continue
            occupied = c.occupied[rows - top : rows - bottom, c0:c1]
            shifted = [_shift(r, -c0 * res, -bottom * res) for r in c.robots]
            candidates.append(Candidate(np.ascontiguousarray(occupied), tuple(shifted)))
        return _first_failing(candidates, self.fails) or c

    def _action_points(self, c: Candidate) -> npt.NDArray[np.float64]:
        """Where things happen: every point any robot drove through, started at or is to
        drive to, (x, y) metres."""
        driven = self.trajectory(c)[:, :, :2].reshape(-1, 2)
        planned = [[r["start"]["x_m"], r["start"]["y_m"]] for r in c.robots] + [
            list(w) for r in c.robots for w in r["waypoints"]
        ]
        return np.vstack([driven, np.asarray(planned, dtype=float)])

    def _distance_to_paths(self, c: Candidate) -> npt.NDArray[np.float64]:
        """Each cell's distance (metres) to the nearest cell some robot drove through."""
        rows, cols = c.occupied.shape
        res = self.resolution
        points = self.trajectory(c)[:, :, :2].reshape(-1, 2)
        col = np.clip((points[:, 0] / res).astype(int), 0, cols - 1)
        row = np.clip(rows - 1 - (points[:, 1] / res).astype(int), 0, rows - 1)
        away = np.ones((rows, cols), dtype=bool)
        away[row, col] = False
        return np.asarray(ndimage.distance_transform_edt(away), dtype=float) * res

    # The whole shrink.

    REDUCTIONS = (
        ("peers", "drop_peers"),
        ("agent route", "cut_agent_route"),
        ("start", "start_later"),
        ("peer legs", "shorten_peer_legs"),
        ("far obstacle cells", "clear_far_cells"),
        ("obstacles", "remove_obstacles"),
        ("map", "crop"),
    )

    def shrink(self) -> tuple[Candidate, list[str]]:
        """The smallest failing candidate found, and what helped."""
        c = self.start
        done: list[str] = []
        for _ in range(PASSES):
            changed = False
            for name, method in self.REDUCTIONS:
                # Restarts and path runs count as probes too; stop once they use the budget.
                self.exhausted |= self.probes >= self.max_probes
                if self.exhausted:
                    break
                smaller = getattr(self, method)(c)
                if smaller.key != c.key:
                    done.append(f"{name}: {self._change(name, c, smaller)}")
                    c, changed = smaller, True
            if not changed or self.exhausted:
                break
        return c, done

    def _target(self, failure_class: str | None) -> Target:
        """What candidates must keep, from the original's run: its class, or with
        ``failure_class`` that class among those its events show."""
        probe = self.probe(self.start)
        if not probe["ok"]:
            raise ShrinkError(f"the situation cannot be run: {probe['problem']}")
        requirement = failure_class is not None and failure_class.startswith(REQUIREMENT)
        if probe["class"] is None and not requirement:
            raise ShrinkError(NOTHING_TO_SHRINK)
        if failure_class is None:
            return Target(probe["class"])
        target = Target(failure_class, shown=True)
        if not target.met(probe):
            shown = ", ".join(k for k, _ in probe["first_s"])
            if requirement:
                raise ShrinkError(
                    f"--requirement: the run does not violate {failure_class[len(REQUIREMENT) :]}"
                    f" (it shows {shown or 'nothing'})"
                )
            raise ShrinkError(
                f"--class: the run fails as {probe['class']}, and its events show {shown}, "
                f"not {failure_class}"
            )
        return target

    def measure(self, c: Candidate) -> Measure:
        agent = c.robots[0]
        route = [(agent["start"]["x_m"], agent["start"]["y_m"]), *map(tuple, agent["waypoints"])]
        rows, cols = c.occupied.shape
        return Measure(
            peers=len(c.robots) - 1,
            obstacle_cells=int(c.occupied.sum()),
            route_length_m=round(sum(math.dist(a, b) for a, b in itertools.pairwise(route)), 3),
            time_to_failure_s=round(self.target.time_s(self.probe(c)), 3),
            map_m=(round(cols * self.resolution, 3), round(rows * self.resolution, 3)),
        )

    def _change(self, name: str, before: Candidate, after: Candidate) -> str:
        a, b = self.measure(before), self.measure(after)
        legs = [sum(len(r["waypoints"]) for r in c.robots[1:]) for c in (before, after)]
        return {
            "peers": f"{a.peers} → {b.peers}",
            "agent route": f"{a.route_length_m:g} → {b.route_length_m:g} m",
            "start": f"failure after {a.time_to_failure_s:g} → {b.time_to_failure_s:g} s",
            "peer legs": f"{legs[0]} → {legs[1]} waypoints",
            "map": f"{a.map_m[0]:g} × {a.map_m[1]:g} → {b.map_m[0]:g} × {b.map_m[1]:g} m",
        }.get(name, f"{a.obstacle_cells} → {b.obstacle_cells} cells")


def _first_failing(
    candidates: list[Candidate], fails: Callable[[Sequence[Candidate]], list[bool]]
) -> Candidate | None:
    if not candidates:
        return None
    return next((c for c, f in zip(candidates, fails(candidates), strict=True) if f), None)


def watch_of(target: Target, first_s: float) -> dict[str, Any] | None:
    """How a probe of a shrink toward ``target``, whose original showed it first at
    ``first_s``, is watched: as a robustness copy is (:data:`HORIZON_AFTER_S` past that, and
    on until it has shown the class or a worse one), so that a probe of a run that sat stuck
    until a long time limit costs what its failure took. A class merely shown (``--class``) is
    watched to the horizon; a requirement's violation, to the time limit."""
    if target.failure_class.startswith(REQUIREMENT):
        # A run cut short could violate an `eventually` its whole run satisfies.
        return None
    horizon_s = min(first_s + HORIZON_AFTER_S, MOST_HORIZON_S)
    return {"horizon_s": horizon_s} | ({} if target.shown else {"watch_for": target.failure_class})


def _with_robot(c: Candidate, i: int, robot: dict[str, Any]) -> Candidate:
    return c.with_robots([*c.robots[:i], robot, *c.robots[i + 1 :]])


def _shift(robot: dict[str, Any], dx: float, dy: float) -> dict[str, Any]:
    start = robot["start"]
    return {
        **robot,
        "start": {**start, "x_m": start["x_m"] + dx, "y_m": start["y_m"] + dy},
        "waypoints": [[x + dx, y + dy] for x, y in robot["waypoints"]],
    }


def shrink(
    situation: Situation,
    run_spec: dict[str, Any],
    run_seed: int = 0,
    failure_class: str | None = None,
    workers: int | None = None,
    max_probes: int = MAX_PROBES,
    on_progress: Callable[[int, int], None] | None = None,
    watch: dict[str, Any] | None = None,
) -> ShrinkResult:
    """Shrink ``situation`` run with ``run_spec`` and sensor seed ``run_seed``: the smallest
    situation found that still fails with its failure class (with ``failure_class``: that
    still shows that class). ``watch``: how far its first run is watched (:class:`Shrinker`).
    Raises :exc:`ShrinkError` if it does not fail so, and SpecError for a bad run spec or a
    controller that is not built in."""
    if not 1 <= max_probes <= MOST_PROBES:
        raise ShrinkError(f"--max-probes: {max_probes} is not in [1, {MOST_PROBES}]")
    threads = check_workers(workers, "local")
    started = time.perf_counter()
    shrinker = Shrinker(
        situation, run_spec, run_seed, failure_class, threads, max_probes, on_progress, watch
    )
    minimal, reductions = shrinker.shrink()
    return ShrinkResult(
        original=situation,
        minimal=Situation(shrinker.kept_json(minimal)),
        failure_class=shrinker.target.failure_class,
        run_spec=run_spec,
        run_seed=run_seed,
        before=shrinker.measure(shrinker.start),
        after=shrinker.measure(minimal),
        probes=shrinker.probes,
        skipped=shrinker.skipped,
        wall_s=time.perf_counter() - started,
        reductions=reductions,
        exhausted=shrinker.exhausted,
    )


def shrink_top(
    db: str | Path,
    k: int,
    workers: int | None = None,
    max_probes: int = MAX_PROBES,
) -> list[tuple[int, ShrinkResult | None]]:
    """Shrink the representatives of the campaign's top ``k`` distinct failures (those not
    shrunk already, so that a resumed campaign does not shrink them again). Returns (run,
    result) for each, None where the store already held its shrink."""

    with Store(db) as store:
        runs = [f.representative for f in distinct_failures(store)[: max(0, k)]]
        done = {r for r in runs if store.shrink(r) is not None}
    return [(r, None if r in done else shrink_run(db, r, workers, max_probes)) for r in runs]


def shrink_run(
    db: str | Path,
    run_id: int,
    workers: int | None = None,
    max_probes: int = MAX_PROBES,
    failure_class: str | None = None,
    on_progress: Callable[[int, int], None] | None = None,
    time_limit_s: float | None = None,
) -> ShrinkResult:
    """Shrink stored run ``run_id`` (its situation, run spec and seed; ``time_limit_s`` over
    its time limit) and keep the result in the store's ``shrinks`` table. Its first run is
    watched as its stored failure says (:func:`horizon_of`), every probe until its failure is
    decided."""

    with Store(db) as store:
        row = stored_run(store, run_id)
        if row["failure"] is None and not (failure_class or "").startswith(REQUIREMENT):
            raise ShrinkError(NOTHING_TO_SHRINK)
        whole = whole_run(store, row)
    if whole is None:
        raise ShrinkError("its situation was not generated, so there is nothing to shrink")
    run_spec = dict(row["run_spec"])
    if time_limit_s is not None:
        run_spec["time_limit_s"] = time_limit_s
    result = shrink(
        whole.situation,
        run_spec,
        row["run_seed"],
        failure_class,
        workers,
        max_probes,
        on_progress,
        None if failure_class is not None else horizon_of(row["failure"]),
    )
    with Store(db) as store:
        store.record_shrink(run_id, result.store_row())
    return result


def save_side_by_side(result: ShrinkResult, path: str | Path) -> None:
    """A figure of the original (left) and the minimal situation (right), each with its run
    (paths driven and the agent's scored events), as PNG."""
    from PIL import Image

    panels = []
    for s in (result.original, result.minimal):
        record = run(s, seed=result.run_seed, spec=result.run_spec)
        dt_s = float(result.run_spec.get("sim", {}).get("dt_s", 0.1))
        panels.append(draw_situation(s, record.trajectory, record.events, dt_s))
    gap = 20
    width = sum(p.width for p in panels) + gap
    height = max(p.height for p in panels)
    figure = Image.new("RGB", (width, height), (255, 255, 255))
    figure.paste(panels[0], (0, 0))
    figure.paste(panels[1], (panels[0].width + gap, 0))
    figure.save(Path(path), format="PNG")

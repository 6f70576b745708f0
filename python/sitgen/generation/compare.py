"""Controllers compared on one suite: the same situations under each controller, with honest
uncertainty.

Each controller runs the campaign's first ``n`` jobs (the same spec and seed, so the same
situations: the same terrain, robots and routes; only the agent's controller differs) into a
campaign store of its own, ``DIR/LABEL.db``, which every other command reads as it reads any
campaign (``sitgen failures``, ``sitgen report``). Run ``i`` of each store is situation ``i``,
so runs pair up by situation.

Per controller: its failure rate (runs with a failure class) with an exact 95 % interval
(Clopper–Pearson, scipy's ``binomtest(...).proportion_ci(method="exact")``); its distinct
failures, robust ones marked where ``--reruns`` measured them; the median time to the goal and
path efficiency (the route's length over the path driven, runs that completed). Per pair: the
exact McNemar test on the situations both ran, the two-sided binomial test of the discordant
pairs (``binomtest(b, b + c, 0.5)``): *no difference* unless its p-value is under
:data:`ALPHA`. The distinct failures only one controller shows are listed with it.
"""

from __future__ import annotations

import itertools
import json
import math
import statistics
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from sitgen.store import Store
from sitgen.triage.failures import distinct_failures
from sitgen.triage.stats import ALPHA, exact_interval, mcnemar_exact

NO_DIFFERENCE = "no difference"


@dataclass
class Side:
    """One controller's figures on the suite."""

    label: str
    controller: dict[str, Any]
    runs: int
    """Runs made (errors included)."""
    errors: int
    failed: int
    failure_rate: float
    interval: tuple[float, float]
    """Exact 95 % interval of the failure rate (Clopper–Pearson)."""
    distinct: list[str]
    """Its distinct failures' keys, most dangerous first."""
    robust: list[str]
    """Of those, the ones measured robust."""
    median_time_to_goal_s: float | None
    median_path_efficiency: float | None
    """Route length over path driven, median over completed runs (1 is a route driven as
    planned)."""
    only: list[str] = field(default_factory=list)
    """Distinct failures no other controller showed."""


@dataclass
class Pair:
    """The exact McNemar test of two controllers on the situations both ran."""

    a: str
    b: str
    situations: int
    a_only: int
    """Situations where A failed and B did not."""
    b_only: int
    p_value: float
    verdict: str


def _route_length(situation_json: str | None) -> float | None:
    if not situation_json:
        return None
    agent = json.loads(situation_json)["robots"][0]
    points = [(agent["start"]["x_m"], agent["start"]["y_m"]), *map(tuple, agent["waypoints"])]
    return sum(math.dist(p, q) for p, q in itertools.pairwise(points))


def side_of(label: str, controller: dict[str, Any], db: Path) -> tuple[Side, dict[int, bool]]:
    """Controller ``label``'s figures from its store, and whether it failed on each situation
    it ran without error."""
    with Store(db) as store:
        rows = store.db.execute(
            "SELECT r.id, r.outcome, r.failure_class, r.time_s, r.events_jsonl, s.situation "
            "FROM runs r JOIN situations s ON s.id = r.situation_id ORDER BY r.id"
        ).fetchall()
        found = distinct_failures(store)
    failed: dict[int, bool] = {}
    times, efficiency = [], []
    errors = 0
    for run_id, outcome, failure_class, time_s, events, situation in rows:
        if outcome == "error":
            errors += 1
            continue
        failed[run_id] = failure_class is not None
        if outcome != "completed":
            continue
        times.append(time_s)
        route = _route_length(situation)
        driven = [
            e["details"]["driven_m"]
            for e in map(json.loads, (events or "").splitlines())
            if e["kind"] == "route_completed" and e["robot"] == 0
        ]
        if route and driven and driven[0] > 0:
            efficiency.append(route / driven[0])
    k, n = sum(failed.values()), len(failed)
    side = Side(
        label=label,
        controller=controller,
        runs=len(rows),
        errors=errors,
        failed=k,
        failure_rate=k / n if n else 0.0,
        interval=exact_interval(k, n),
        distinct=[f.key for f in found],
        robust=[f.key for f in found if f.robust],
        median_time_to_goal_s=statistics.median(times) if times else None,
        median_path_efficiency=statistics.median(efficiency) if efficiency else None,
    )
    return side, failed


def pair_of(a: str, b: str, fa: dict[int, bool], fb: dict[int, bool]) -> Pair:
    """The exact McNemar test of ``a`` and ``b`` on the situations both ran."""
    both = sorted(set(fa) & set(fb))
    a_only = sum(fa[i] and not fb[i] for i in both)
    b_only = sum(fb[i] and not fa[i] for i in both)
    p = mcnemar_exact(a_only, b_only)
    if p >= ALPHA:
        said = NO_DIFFERENCE
    else:
        said = f"{a} fails more" if a_only > b_only else f"{b} fails more"
    return Pair(a, b, len(both), a_only, b_only, p, said)


def comparison(
    labels: Sequence[str], controllers: Sequence[dict[str, Any]], folder: Path
) -> dict[str, Any]:
    """The comparison of controllers ``labels`` whose stores are ``folder/LABEL.db``."""
    sides, failed = [], {}
    for label, controller in zip(labels, controllers, strict=True):
        side, failed[label] = side_of(label, controller, folder / f"{label}.db")
        sides.append(side)
    for side in sides:
        others = {k for s in sides if s is not side for k in s.distinct}
        side.only = [k for k in side.distinct if k not in others]
    pairs = [pair_of(a, b, failed[a], failed[b]) for a, b in itertools.combinations(labels, 2)]
    return {
        "controllers": [asdict(s) for s in sides],
        "pairs": [asdict(p) for p in pairs],
        "alpha": ALPHA,
    }


def labels_of(controllers: Sequence[dict[str, Any]]) -> list[str]:
    """A store name a controller: its name made safe for a file name, ``#2``… for repeats."""
    labels: list[str] = []
    for c in controllers:
        base = "".join(ch if ch.isalnum() or ch in "-_." else "_" for ch in str(c["name"]))
        label, k = base, 1
        while label in labels:
            k += 1
            label = f"{base}-{k}"
        labels.append(label)
    return labels

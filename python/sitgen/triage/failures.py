"""Distinct failures: a campaign's runs grouped by failure class, each group with its
representative run (the highest-scoring), most dangerous first.

A run's failure class is computed in the core from its scored events (``docs/failures.md``).
Where one class is broad (at least ``BROAD_RUNS`` runs), it is split by behaviour features of
its deciding events with agglomerative clustering (SciPy's Ward linkage: deterministic, no
random start), and each part is named in words by what sets it apart: the side the other
party came from, whether its failures lasted long or short, were fast or slow, and the terrain
where most of a part happened (terrain describes a part, never makes one) — so a split always
reads as a sentence, never as "cluster 3".
"""

from __future__ import annotations

import json
import math
import statistics
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from typing import Any, TextIO

import numpy as np

from sitgen import _core
from sitgen.store import Store, main_events
from sitgen.triage.avoidability import tier
from sitgen.triage.robustness import (
    CANDIDATES,
    RERUNS,
    check_reruns,
    is_robust,
    measure_runs,
    measured_as_now,
    verdict,
)
from sitgen.triage.rows import write_rows

BROAD_RUNS = 20
"""A class with at least this many runs is split where its runs fall into clear groups."""

MIN_SILHOUETTE = 0.5
"""A split is kept only if its groups are this well separated (silhouette, −1 … 1)."""

MAX_CLUSTERED = 2000
"""Runs of one class clustered at most (evenly spaced by id); the rest join the nearest group."""

SIDES = ("front", "left", "right", "rear")


class FailureFilterError(ValueError):
    """An unknown failure class asked for."""


def classes() -> list[tuple[str, str]]:
    """Every failure class as (key, sentence), most severe first."""
    return _core.failure_classes()


def check_class(key: str) -> str:
    """``key`` if it is a failure class, else an error naming the known ones."""
    known = [k for k, _ in classes()]
    if key not in known:
        raise FailureFilterError(
            f"--class: unknown failure class {key!r}; expected one of {', '.join(known)}"
        )
    return key


@dataclass
class DistinctFailure:
    """One distinct failure of a campaign."""

    key: str
    """The failure class key, with ``/`` and the split's words for part of a broad class."""
    failure_class: str
    description: str
    runs: int
    share: float
    """Of all runs of the campaign."""
    best_score: float
    representative: int
    """Its highest-scoring robust run where one was measured robust, else its highest-scoring
    run (lowest id on ties)."""
    median_duration_s: float
    """Median over its runs of how long the deciding events lasted."""
    run_ids: list[int] = field(default_factory=list)
    recurs: int | None = None
    """In how many perturbed copies of the representative its class recurred (None: not
    measured; ``sitgen robustness``)."""
    reruns: int | None = None
    """How many copies of the representative were run."""
    rerun_classes: list[str | None] = field(default_factory=list)
    """Each copy's failure class (None: no failure; ``error``: it failed to run, and is not
    counted in :attr:`reruns`)."""
    median_cpu_s: float | None = None
    """Median over its runs of the processor seconds each cost (None: no run's cost was
    stored)."""
    avoidability: str | None = None
    """Whether the representative's collision with a robot could have been escaped
    (``avoidable``, ``unavoidable_with_this_sensor``, ``unavoidable``; None: not judged)."""
    avoidable: int | None = None
    """Of its judged runs, how many collisions were avoidable (None: none judged)."""
    judged: int | None = None
    """How many of its runs were judged."""

    @property
    def robust(self) -> bool | None:
        """Whether the representative's failure is robust (None: not measured)."""
        if self.recurs is None or self.reruns is None:
            return None
        return is_robust(self.recurs, self.reruns)

    @property
    def robustness(self) -> str:
        """``robust 7/8``, ``knife-edge 3/8``, or ``unmeasured``."""
        if self.recurs is None or self.reruns is None:
            return "unmeasured"
        erred = len(self.rerun_classes) - self.reruns
        left_out = f" ({erred} erred)" if erred > 0 else ""
        return f"{verdict(self.recurs, self.reruns)} {self.recurs}/{self.reruns}{left_out}"

    def as_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["class"] = d.pop("failure_class")
        d["robust"] = self.robust
        d["robustness"] = self.robustness
        return d


def distinct_failures(store: Store) -> list[DistinctFailure]:
    """The campaign's distinct failures, best score first (then key), those whose
    representative's collision was judged unavoidable with this sensor, then unavoidable,
    after the rest (:func:`sitgen.triage.avoidability.tier`)."""
    total = store.db.execute("SELECT count(*) FROM runs").fetchone()[0]
    by_class: dict[str, list[dict[str, Any]]] = {}
    rows = store.db.execute(
        "SELECT r.id, r.score, r.failure_class, r.failure, s.terrain FROM runs r "
        "JOIN situations s ON s.id = r.situation_id WHERE r.failure_class IS NOT NULL "
        "ORDER BY r.id"
    )
    for run_id, score, key, failure, terrain in rows:
        f = json.loads(failure)
        by_class.setdefault(key, []).append(
            {"id": run_id, "score": score, "terrain": terrain, **f["features"]}
        )
    sentences = dict(classes())
    measured = store.robustness()
    costs = store.costs()
    judged = {i: r["verdict"] for i, r in store.avoidability().items() if r["verdict"]}
    out = []
    for key, runs in by_class.items():
        for marks, part in split(runs):
            words = [w for w, _ in marks]
            description = sentences.get(key, key) + (f", {', '.join(words)}" if words else "")
            sub_key = "/".join([key, *[t for _, t in marks]])
            group = _group(sub_key, key, description, part, total, measured)
            cpu = [costs[i][1] for i in group.run_ids if i in costs]
            group.median_cpu_s = statistics.median(cpu) if cpu else None
            verdicts = [judged[i] for i in group.run_ids if i in judged]
            if verdicts:
                group.avoidable = verdicts.count("avoidable")
                group.judged = len(verdicts)
            group.avoidability = judged.get(group.representative)
            out.append(group)
    # Collisions no controller with this sensor could have escaped rank after the
    # controller's own mistakes (docs/avoidability.md).
    out.sort(key=lambda d: (tier(d.avoidability), -d.best_score, d.key))
    return out


def _group(
    key: str,
    failure_class: str,
    description: str,
    runs: list[dict[str, Any]],
    total: int,
    measured: dict[int, dict[str, Any]],
) -> DistinctFailure:
    by_score = sorted(runs, key=lambda r: (-r["score"], r["id"]))
    best = by_score[0]
    robust = [
        r
        for r in by_score
        if r["id"] in measured
        and is_robust(measured[r["id"]]["recurs"], measured[r["id"]]["reruns"])
    ]
    representative = robust[0] if robust else best
    own = measured.get(representative["id"])
    return DistinctFailure(
        key=key,
        failure_class=failure_class,
        description=description,
        runs=len(runs),
        share=len(runs) / total if total else 0.0,
        best_score=best["score"],
        representative=representative["id"],
        median_duration_s=statistics.median(float(r.get("seconds", 0.0)) for r in runs),
        run_ids=sorted(r["id"] for r in runs),
        recurs=None if own is None else own["recurs"],
        reruns=None if own is None else own["reruns"],
        rerun_classes=[] if own is None else list(own["classes"]),
    )


def candidates(failure: DistinctFailure, scores: dict[int, float], most: int) -> list[int]:
    """A distinct failure's ``most`` highest-scoring runs, best first (lowest id on ties):
    the runs its representative is chosen among."""
    return sorted(failure.run_ids, key=lambda i: (-scores[i], i))[:most]


def measure_robustness(store: Store, reruns: int = RERUNS, workers: int = 1) -> int:
    """Measure the robustness of every distinct failure's candidates for representative: its
    highest-scoring runs, best first, until one is robust (at most ``CANDIDATES``), each
    round of candidates run as one batch, each run's copies only until they decide its
    verdict (6 of 8 recur, or 3 of 8 do not: robustness.decided). A run measured before with
    as many copies is not run again, so a resumed or repeated call costs nothing more.
    Returns the copies judged."""
    reruns = check_reruns(reruns)
    scores = dict(store.db.execute("SELECT id, score FROM runs WHERE failure_class IS NOT NULL"))
    groups = [candidates(f, scores, CANDIDATES) for f in distinct_failures(store)]
    ran = 0
    for depth in range(CANDIDATES):
        stored = store.robustness()
        wanted: list[int] = []
        for runs in groups:
            if depth >= len(runs):
                continue
            earlier = [stored.get(r) for r in runs[:depth]]
            if any(d is None or is_robust(d["recurs"], d["reruns"]) for d in earlier):
                continue
            run_id = runs[depth]
            if not measured_as_now(stored.get(run_id), reruns):
                wanted.append(run_id)
        if wanted:
            measured = measure_runs(store, wanted, reruns, workers, until_decided=True)
            ran += sum(len(m.classes) for m in measured)
    return ran


SPEED_SCALE_M_S = 0.2
"""Agent speeds this far apart count as far apart as two sides, or durations e times apart."""

MIN_SEPARATION = 1.0
"""Groups whose centres are closer than this (in feature units) are not worth a split."""


def _features(runs: Sequence[dict[str, Any]]) -> tuple[np.ndarray, list[str]]:
    """Behaviour features on fixed, meaningful scales (so a spread of a few tenths of a second
    never looks like two groups): side one-hot, log duration, agent speed per 0.2 m/s; and the
    terrain one-hot, which describes a part but never finds one (:func:`split`)."""
    names: list[str] = []
    cols: list[list[float]] = []
    sides = [r.get("bearing") for r in runs]
    if any(sides):
        for side in SIDES:
            names.append(f"side:{side}")
            cols.append([1.0 if s == side else 0.0 for s in sides])
    names.append("seconds")
    cols.append([math.log1p(float(r.get("seconds", 0.0))) for r in runs])
    names.append("speed")
    cols.append([float(r.get("agent_mean_speed_m_s", 0.0)) / SPEED_SCALE_M_S for r in runs])
    terrains = sorted({str(r.get("terrain")) for r in runs})
    if len(terrains) > 1:
        for t in terrains:
            names.append(f"terrain:{t}")
            cols.append([1.0 if str(r.get("terrain")) == t else 0.0 for r in runs])
    return np.array(cols, dtype=float).T, names


Mark = tuple[str, str]
"""Words that tell a part of a class apart (``from the rear``), and its token in keys (``rear``)."""


def split(runs: list[dict[str, Any]]) -> list[tuple[list[Mark], list[dict[str, Any]]]]:
    """A class's runs as (marks, runs) parts: one part with no marks unless the class is broad
    and its runs fall into clearly separated groups that words can tell apart."""
    if len(runs) < BROAD_RUNS:
        return [([], runs)]
    from scipy.spatial.distance import cdist

    features, names = _features(runs)
    # Parts are found by behaviour alone (side, duration, speed): runs that behave alike are
    # one failure wherever they happened (a hundred timeouts are not four failures because
    # they happened on four terrains). Terrain may still describe a part it is found in.
    x = features[:, [i for i, n in enumerate(names) if not n.startswith("terrain:")]]
    step = max(1, math.ceil(len(runs) / MAX_CLUSTERED))
    sample = x[::step]
    if len(np.unique(sample, axis=0)) < 2:
        return [([], runs)]
    distance = cdist(sample, sample)
    best: tuple[float, np.ndarray] | None = None
    for k, labels in ward_parts(sample, (2, 3, 4)).items():
        centres = np.array([sample[labels == c].mean(axis=0) for c in range(k)])
        gaps = np.linalg.norm(centres[:, None, :] - centres[None, :, :], axis=2)
        if gaps[np.triu_indices(k, 1)].min() < MIN_SEPARATION:
            continue
        quality = silhouette(distance, labels)
        if best is None or quality > best[0] + 1e-12:
            best = (quality, labels)
    if best is None or best[0] < MIN_SILHOUETTE:
        return [([], runs)]
    labels = best[1]
    centres = np.array([sample[labels == c].mean(axis=0) for c in range(labels.max() + 1)])
    assigned = np.argmin(((x[:, None, :] - centres[None, :, :]) ** 2).sum(axis=2), axis=1)
    parts: dict[tuple[Mark, ...], list[dict[str, Any]]] = {}
    for c in range(len(centres)):
        members = [r for r, a in zip(runs, assigned, strict=True) if a == c]
        if not members:
            continue
        others = [r for r, a in zip(runs, assigned, strict=True) if a != c]
        words = tuple(describe(members, others, names))
        parts.setdefault(words, []).extend(members)
    if len(parts) < 2:
        return [([], runs)]
    return sorted(
        ((list(w), sorted(p, key=lambda r: r["id"])) for w, p in parts.items()),
        key=lambda wp: wp[1][0]["id"],
    )


def ward_parts(x: np.ndarray, ks: Sequence[int]) -> dict[int, np.ndarray]:
    """The points ``x`` (rows) cut into k parts by one Ward tree, for each k in ``ks`` below
    the number of points: labels 0 … k−1 per point. SciPy's hierarchy, not scikit-learn's
    AgglomerativeClustering (the same Ward tree; a test checks the parts agree): importing
    scikit-learn took about a second at the end of every campaign."""
    from scipy.cluster.hierarchy import cut_tree, linkage

    tree = linkage(x, method="ward")
    return {k: cut_tree(tree, n_clusters=[k]).ravel() for k in ks if k < len(x)}


def silhouette(distance: np.ndarray, labels: np.ndarray) -> float:
    """Mean silhouette of a clustering of points whose pairwise distances are ``distance``
    (labels 0 … k−1, k ≥ 2): for each point, (b − a) / max(a, b), where a is its mean distance
    to the rest of its cluster and b its least mean distance to another cluster; 0 for a point
    alone in its cluster (Rousseeuw 1987). Written out (a dozen lines) because scikit-learn's
    ``silhouette_score`` costs a second to import; a test checks the two agree. The split
    computes the distances once for every k it tries."""
    points = np.arange(len(distance))
    k = int(labels.max()) + 1
    size = np.bincount(labels, minlength=k).astype(float)
    sums = np.stack([distance[:, labels == c].sum(axis=1) for c in range(k)], axis=1)
    own = size[labels]
    a = sums[points, labels] / np.maximum(own - 1.0, 1.0)
    mean_to = sums / size
    mean_to[points, labels] = np.inf
    b = mean_to.min(axis=1)
    spread = np.maximum(a, b)
    s = np.divide(b - a, spread, out=np.zeros(len(distance)), where=(own > 1) & (spread > 0))
    return float(s.mean())


def describe(
    members: list[dict[str, Any]], others: list[dict[str, Any]], names: list[str]
) -> list[Mark]:
    """What tells ``members`` from ``others``: a side or terrain that at least 80% of the
    members share and fewer of the others; lasting more than twice as long (or under half as
    long), or the agent going over 0.1 m/s faster (or slower), than 80% of the others for 80%
    of the members."""
    marks: list[Mark] = []
    categorical = (("side", "bearing", "from the {}"), ("terrain", "terrain", "in {}"))
    for label, feature, phrase in categorical:
        if not any(n.startswith(label + ":") for n in names):
            continue
        values = [str(r.get(feature)) for r in members]
        top = max(sorted(set(values)), key=values.count)
        share = values.count(top) / len(values)
        share_others = sum(str(r.get(feature)) == top for r in others) / max(1, len(others))
        if share >= 0.8 and share_others < share:
            marks.append((phrase.format(top), top))
    numeric: tuple[tuple[str, Callable[[float, float], bool], Mark, Mark], ...] = (
        (
            "seconds",
            lambda more, less: more > 2 * less,
            ("lasting over {} s", "long"),
            ("lasting under {} s", "short"),
        ),
        (
            "agent_mean_speed_m_s",
            lambda more, less: more > less + 0.1,
            ("agent faster than {} m/s", "fast"),
            ("agent slower than {} m/s", "slow"),
        ),
    )
    for feature, beyond, more, less in numeric:
        mine = sorted(float(r.get(feature, 0.0)) for r in members)
        theirs = sorted(float(r.get(feature, 0.0)) for r in others)
        if not theirs:
            continue
        lo, hi = _quantile(mine, 0.2), _quantile(mine, 0.8)
        if beyond(lo, _quantile(theirs, 0.8)):
            marks.append((more[0].format(_round(lo)), more[1]))
        elif beyond(_quantile(theirs, 0.2), hi):
            marks.append((less[0].format(_round(hi)), less[1]))
    return marks


def _quantile(values: list[float], q: float) -> float:
    return float(np.quantile(values, q)) if values else 0.0


def _round(x: float) -> str:
    """Two significant figures, for words."""
    if x == 0:
        return "0"
    digits = max(0, 1 - math.floor(math.log10(abs(x))))
    return f"{x:.{digits}f}"


FAILURE_COLUMNS = (
    "key",
    "class",
    "description",
    "runs",
    "share",
    "best_score",
    "representative",
    "median_duration_s",
    "robustness",
    "robust",
    "recurs",
    "reruns",
    "median_cpu_s",
    "avoidability",
    "avoidable",
    "judged",
)


def write_failures(failures: list[DistinctFailure], format: str, out: TextIO) -> None:
    """Write distinct failures as ``json`` (a list of objects) or ``csv``."""
    write_rows([f.as_dict() for f in failures], FAILURE_COLUMNS, format, out)


def summary(store: Store, top: int = 5) -> dict[str, Any]:
    """The paper's §4.2 figures (runs, mean and median score, share under 10 points, top runs),
    the commonest reasons runs were errors, and the campaign's distinct failures, best first."""
    scores = store.scores()
    ranked = store.ranked(top)
    outcomes: dict[str, int] = {}
    for (outcome,) in store.db.execute("SELECT outcome FROM runs"):
        outcomes[outcome] = outcomes.get(outcome, 0) + 1
    errors = [
        {"reason": reason, "runs": n, "first_run": first}
        for reason, n, first in store.db.execute(
            "SELECT reason, count(*), min(id) FROM runs WHERE outcome = 'error' "
            "GROUP BY reason ORDER BY count(*) DESC, min(id) LIMIT 3"
        )
    ]
    return {
        "runs": len(scores),
        "mean_score": statistics.fmean(scores) if scores else 0.0,
        "median_score": statistics.median(scores) if scores else 0.0,
        "share_under_10": sum(s < 10 for s in scores) / len(scores) if scores else 0.0,
        "outcomes": outcomes,
        "errors": errors,
        "top": [
            {"run": r["run"], "score": r["score"], "main_events": main_events(r["breakdown"])}
            for r in ranked
        ],
        "distinct": [f.as_dict() for f in distinct_failures(store)],
    }

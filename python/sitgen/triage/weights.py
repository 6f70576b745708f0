"""Learned weights: penalty weights fitted to an expert's pairwise judgements of runs.

What it does: an engineer judges pairs of runs (``sitgen judge``: which is more dangerous, or
are they equal); :func:`fit` finds non-negative penalties under which the judged-worse run of
each pair scores higher, and writes them as a run spec's scoring table (``weights.toml``), which
``--weights`` uses to rank stored runs and a run spec's ``scoring`` to score new ones.

Why: the paper tuned its penalties by trial and error, and its most interesting failure ranked
third at a third of the first's score (§6 proposes learning the weights from expert ratings).

The model (Bradley–Terry with a linear strength): a run's score is linear in what every run's
summary keeps, per event kind the number of scored events (``start`` points each) and the
seconds they lasted (``per_s``), plus, where it helps, points for its failure class. So
P(a judged worse than b) = σ(w · (x_a − x_b)): a logistic regression on feature differences
without intercept, "equal" counting as half a win each way. The fit minimises its L2-penalised
log-loss under w ≥ 0 with scipy's L-BFGS-B (scikit-learn's LogisticRegression cannot bound
signs), on features scaled to unit RMS difference. Failure-class points are kept only when
they lower the cross-validated log-loss. The logit-scale weights are then multiplied by one
factor so the judged runs' scores sum to what they sum to as stored (ranks do not depend on it;
it keeps points readable beside the defaults).

Parameters: ``RIDGE`` (1.0, on scaled features), ``FOLDS`` (5, for the held-out figures).
Source: Bradley & Terry 1952; Arnold & Alexander 2013, §6; docs/weights.md.
"""

from __future__ import annotations

import json
import math
import random
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from sitgen import _core
from sitgen.store import WORSE, Judgement, Store
from sitgen.triage.failures import distinct_failures
from sitgen.world.config import read_utf8

RIDGE = 1.0
"""L2 penalty on the scaled weights: keeps a weight no judgement constrains at zero."""

FOLDS = 5
"""Folds of the cross-validation that gives held-out agreement and τ."""

Array = npt.NDArray[np.float64]


class JudgementError(ValueError):
    """Judgements or a weights file that cannot be used; the message names the entry."""


def kinds() -> list[str]:
    """The event kinds a danger penalty applies to: those the core penalises by default (the
    progress kinds earn nothing and stay at zero)."""
    return [k for k, start, per_s in _core.default_penalties() if start or per_s]


# Weights.


@dataclass(frozen=True)
class Weights:
    """A scoring table: ``penalties`` by event kind as (start points, points per second) and
    points per failure class; as a run spec's ``scoring`` section takes it."""

    penalties: dict[str, tuple[float, float]]
    failure_classes: dict[str, float] = field(default_factory=dict)
    score_peers: bool = False

    def __post_init__(self) -> None:  # kinds not named keep the core's penalty, as in a spec
        defaults = {k: (s, p) for k, s, p in _core.default_penalties()}
        object.__setattr__(self, "penalties", {**defaults, **self.penalties})

    @classmethod
    def default(cls) -> Weights:
        return cls({})

    @classmethod
    def from_table(cls, table: Mapping[str, Any], where: str) -> Weights:
        """The weights of a scoring table, checked by the core; ``where`` names it in errors
        (the file, or ``scoring`` of a spec)."""
        try:
            checked = json.loads(_core.check_run_spec(json.dumps({"scoring": dict(table)})))
        except _core.SpecError as e:
            raise JudgementError(f"{where}: {str(e).removeprefix('run.scoring.')}") from None
        scoring = checked["scoring"]
        return cls(
            {
                k: (float(p["start"]), float(p["per_s"]))
                for k, p in scoring.get("penalties", {}).items()
            },
            {k: float(v) for k, v in scoring.get("failure_classes", {}).items()},
            bool(scoring.get("score_peers", False)),
        )

    def table(self) -> dict[str, Any]:
        """The scoring table (every kind, the classes given)."""
        out: dict[str, Any] = {
            "score_peers": self.score_peers,
            "penalties": {k: {"start": s, "per_s": p} for k, (s, p) in self.penalties.items()},
        }
        if self.failure_classes:
            out["failure_classes"] = dict(self.failure_classes)
        return out

    def breakdown(self, stored: Mapping[str, Any]) -> dict[str, dict[str, float]]:
        """A stored breakdown rescored: each kind's points from its count and seconds."""
        out = {}
        for kind, line in stored.items():
            start, per_s = self.penalties.get(kind, (0.0, 0.0))
            points = start * line["count"] + per_s * line["seconds"]
            if points:
                out[kind] = {**line, "points": points}
        return out

    def score(self, stored: Mapping[str, Any], failure_class: str | None) -> float:
        """A run's score from its stored breakdown and failure class."""
        points = sum(line["points"] for line in self.breakdown(stored).values())
        return points + (self.failure_classes.get(failure_class, 0.0) if failure_class else 0.0)


def load_weights(path: Path) -> Weights:
    """The weights file ``path`` (TOML, a scoring table); JudgementError naming the file and
    the field."""
    import tomllib

    try:
        table = tomllib.loads(read_utf8(path, "weights file"))
    except tomllib.TOMLDecodeError as e:
        raise JudgementError(f"{path}: not TOML ({e})") from None
    except _core.SpecError as e:
        raise JudgementError(str(e)) from None
    return Weights.from_table(table, str(path))


def weights_toml(weights: Weights, comment: Sequence[str] = ()) -> str:
    """The weights as TOML, ``comment`` lines first."""
    import tomli_w

    table = weights.table()
    table["penalties"] = {k: table["penalties"][k] for k in kinds()}
    head = "".join(f"# {line}\n" for line in comment)
    return head + tomli_w.dumps(table)


def campaign_weights(store: Store) -> Weights:
    """The scoring the store's runs were scored with (its campaign's ``[run] scoring``)."""
    campaign = store.campaign()
    table = ((campaign or {}).get("spec", {}).get("run") or {}).get("scoring") or {}
    return Weights.from_table(table, f"{store.path}: the campaign's run.scoring")


def check_rescorable(store: Store, weights: Weights, where: str) -> None:
    """Rescoring reads each run's breakdown: it cannot count events the runs did not score
    (peers' events without ``score_peers``, kinds their scoring gave no points)."""
    scored = campaign_weights(store)
    if weights.score_peers and not scored.score_peers:
        raise JudgementError(
            f"{where}: score_peers = true, but {store.path}'s runs were scored without peers' "
            "events; set score_peers = false or run a campaign with it"
        )
    for kind, (start, per_s) in weights.penalties.items():
        if (start or per_s) and scored.penalties.get(kind) == (0.0, 0.0):
            raise JudgementError(
                f"{where}: penalties.{kind} gives points, but {store.path}'s runs gave {kind} "
                "none, so their breakdowns do not count it"
            )


# Judgements.


def read_judgements(path: Path, store: Store) -> list[Judgement]:
    """The judgements of JSON file ``path``, every entry checked against ``store``'s runs:
    JudgementError naming the entry (``[3].worse``) and what was expected."""
    try:
        data = json.loads(read_utf8(path, "judgements file"))
    except json.JSONDecodeError as e:
        raise JudgementError(f"{path}: not JSON ({e.msg}, line {e.lineno})") from None
    except RecursionError:
        raise JudgementError(f"{path}: nested too deeply; expected a flat list") from None
    except _core.SpecError as e:
        raise JudgementError(str(e)) from None
    expected = '{"a": RUN, "b": RUN, "worse": "a" | "b" | "equal"}'
    if not isinstance(data, list):
        raise JudgementError(f"{path}: expected a list of judgements {expected}")
    out = []
    for i, entry in enumerate(data):
        at = f"{path}: [{i}]"
        if not isinstance(entry, dict):
            raise JudgementError(f"{at}: expected an object {expected}")
        unknown = sorted(set(entry) - {"a", "b", "worse", "who", "at"})
        if unknown:
            raise JudgementError(
                f"{at}.{unknown[0]}: unknown field; expected a, b, worse (who, at optional)"
            )
        for key in ("a", "b", "worse"):
            if key not in entry:
                raise JudgementError(f"{at}: no `{key}`; expected {expected}")
        for key in ("a", "b"):
            value = entry[key]
            if not isinstance(value, int) or isinstance(value, bool):
                raise JudgementError(f"{at}.{key}: {value!r} is not a run id (an integer)")
        if entry["a"] == entry["b"]:
            raise JudgementError(f"{at}: a and b are the same run ({entry['a']})")
        if entry["worse"] not in WORSE:
            raise JudgementError(f'{at}.worse: {entry["worse"]!r}; expected "a", "b" or "equal"')
        for key in ("who", "at"):
            if not isinstance(entry.get(key, ""), str):
                raise JudgementError(f"{at}.{key}: {entry[key]!r} is not a string")
        out.append(
            Judgement(
                entry["a"], entry["b"], entry["worse"], entry.get("who", ""), entry.get("at", "")
            )
        )
    present = store.has_runs(r for j in out for r in (j.a, j.b))
    for i, j in enumerate(out):
        for key, run_id in (("a", j.a), ("b", j.b)):
            if run_id not in present:
                raise JudgementError(f"{path}: [{i}].{key}: run {run_id} is not in {store.path}")
    return out


def write_judgements(judgements: Iterable[Judgement], path: Path) -> int:
    """Write judgements as a JSON list (what :func:`read_judgements` reads); returns how many."""
    rows = [j.as_dict() for j in judgements]
    path.write_text(json.dumps(rows, indent=2) + "\n")
    return len(rows)


# Features: what a run's score is linear in.


@dataclass(frozen=True)
class Features:
    """Per run, the features a score is linear in: per kind, scored events and their seconds
    (as stored in its breakdown), and a one-hot of the failure classes in ``classes``."""

    names: list[str]
    rows: dict[int, Array]
    classes: list[str]
    stored: dict[int, float]
    """Each run's score as stored."""

    def matrix(self, ids: Sequence[int]) -> Array:
        return np.array([self.rows[i] for i in ids], dtype=np.float64).reshape(len(ids), -1)


def features(store: Store, ids: Iterable[int]) -> Features:
    """The features of runs ``ids`` (every failure class any of them has gets a column)."""
    wanted = sorted(set(ids))
    rows = {}
    for i in range(0, len(wanted), 500):
        chunk = wanted[i : i + 500]
        rows.update(
            {
                r[0]: (json.loads(r[1]), r[2], r[3])
                for r in store.db.execute(
                    "SELECT id, breakdown, failure_class, score FROM main.runs "
                    f"WHERE id IN ({', '.join('?' for _ in chunk)})",
                    chunk,
                )
            }
        )
    classes = sorted({c for _, c, _ in rows.values() if c})
    names = [f"{k}.{part}" for k in kinds() for part in ("start", "per_s")]
    names += [f"failure_classes.{c}" for c in classes]
    out = {}
    for run_id, (breakdown, failure_class, _) in rows.items():
        x = []
        for k in kinds():
            line = breakdown.get(k, {})
            x += [float(line.get("count", 0)), float(line.get("seconds", 0.0))]
        x += [1.0 if failure_class == c else 0.0 for c in classes]
        out[run_id] = np.array(x)
    return Features(names, out, classes, {i: float(r[2]) for i, r in rows.items()})


def to_weights(coef: Array, f: Features, score_peers: bool) -> Weights:
    """Weights from coefficients in feature order (kinds not fitted stay at zero)."""
    penalties = {k: (0.0, 0.0) for k, _, _ in _core.default_penalties()}
    for j, k in enumerate(kinds()):
        penalties[k] = (float(coef[2 * j]), float(coef[2 * j + 1]))
    offset = 2 * len(kinds())
    classes = {c: float(coef[offset + j]) for j, c in enumerate(f.classes) if coef[offset + j]}
    return Weights(penalties, classes, score_peers)


# The model.


def _sigmoid(z: Array) -> Array:
    out: Array = 0.5 * (1.0 + np.tanh(0.5 * z))
    return out


def labels(judgements: Sequence[Judgement]) -> Array:
    """1 where ``a`` was judged worse, 0 where ``b`` was, ½ where they were judged equal."""
    return np.array([{"a": 1.0, "b": 0.0, "equal": 0.5}[j.worse] for j in judgements])


def train(diffs: Array, y: Array, scale: Array, ridge: float = RIDGE) -> Array:
    """Non-negative weights (per unit of each feature, logit scale) maximising the penalised
    Bradley–Terry likelihood of labels ``y`` given feature differences ``diffs``; features
    with a zero ``scale`` keep weight zero."""
    from scipy.optimize import minimize

    used = scale > 0
    z_diffs = diffs[:, used] / scale[used]

    def loss(beta: Array) -> tuple[float, Array]:
        z = z_diffs @ beta
        value = float(np.sum(y * np.logaddexp(0.0, -z) + (1.0 - y) * np.logaddexp(0.0, z)))
        grad = z_diffs.T @ (_sigmoid(z) - y)
        return value + 0.5 * ridge * float(beta @ beta), grad + ridge * beta

    found = minimize(
        loss,
        np.zeros(int(used.sum())),
        jac=True,
        method="L-BFGS-B",
        bounds=[(0.0, None)] * int(used.sum()),
    )
    coef = np.zeros(diffs.shape[1])
    coef[used] = found.x / scale[used]
    return coef


def feature_scale(x: Array) -> Array:
    """Each feature's RMS difference between two runs (√2 × its standard deviation)."""
    scale: Array = np.sqrt(2.0) * x.std(axis=0) if len(x) else np.zeros(x.shape[1])
    return scale


@dataclass(frozen=True)
class Agreement:
    """How well scores reproduce judgements held out of the fit."""

    agreement: float
    """Share of the judgements saying one run is worse that the scores order the same way
    (a tie in score counts half)."""
    tau: float
    """Kendall's τ-b between the scores' order and the judged one over the judged pairs
    (an "equal" judgement is a tie of the judged order)."""
    log_loss: float
    """Mean held-out log-loss (nats per judgement); NaN for scores with no logit scale."""


def agreement(delta: Array, y: Array, log_loss: float = math.nan) -> Agreement:
    """Agreement of score differences ``delta`` (a − b) with labels ``y``."""
    tol = 1e-9 * max(1.0, float(np.max(np.abs(delta))) if len(delta) else 1.0)
    predicted = np.where(delta > tol, 1.0, np.where(delta < -tol, 0.0, 0.5))
    strict = y != 0.5
    agree = (
        float(np.mean(np.where(predicted[strict] == 0.5, 0.5, predicted[strict] == y[strict])))
        if strict.any()
        else math.nan
    )
    concordant = np.sum(strict & (predicted != 0.5) & (predicted == y))
    discordant = np.sum(strict & (predicted != 0.5) & (predicted != y))
    n = len(y)
    judged_ties = n - int(strict.sum())
    score_ties = int(np.sum(predicted == 0.5))
    denominator = math.sqrt(max(0, n - judged_ties) * max(0, n - score_ties))
    tau = float(concordant - discordant) / denominator if denominator else math.nan
    return Agreement(agree, tau, log_loss)


def _log_loss(z: Array, y: Array) -> float:
    return float(np.mean(y * np.logaddexp(0.0, -z) + (1.0 - y) * np.logaddexp(0.0, z)))


def folds(n: int, k: int = FOLDS) -> list[npt.NDArray[np.int64]]:
    """Held-out index sets of a k-fold split of n judgements (a fixed shuffle: same
    judgements, same figures)."""
    order = np.random.default_rng(0).permutation(n)
    return [order[i::k] for i in range(min(k, n))]


def cross_validate(diffs: Array, y: Array, scale: Array) -> Agreement:
    """Held-out agreement of weights fitted to the other folds, over the folds."""
    z = np.zeros(len(y))
    for held in folds(len(y)):
        train_idx = np.setdiff1d(np.arange(len(y)), held)
        coef = train(diffs[train_idx], y[train_idx], scale)
        z[held] = diffs[held] @ coef
    return agreement(z, y, _log_loss(z, y))


@dataclass(frozen=True)
class Fit:
    """Fitted weights and how well they reproduce the judgements."""

    weights: Weights
    judgements: int
    strict: int
    runs: int
    held_out: Agreement
    stored: Agreement
    """The stored scores' agreement with the same judgements."""
    with_classes: bool
    points_per_logit: float
    folds: int

    def summary(self) -> list[str]:
        def row(name: str, a: Agreement) -> str:
            return f"  {name:15} {a.agreement:9.3f}   {a.tau:+.3f}"

        classes = (
            f"per failure class too ({len(self.weights.failure_classes)} with points)"
            if self.with_classes
            else "per event kind (failure-class points did not help held-out judgements)"
        )
        return [
            f"{self.judgements} judgements ({self.strict} say one run is worse) of "
            f"{self.runs} runs",
            f"fitted {classes}",
            f"held out ({self.folds}-fold):  agreement   Kendall τ",
            row("fitted weights", self.held_out),
            row("stored scores", self.stored),
        ]


def fit(store: Store, judgements: Sequence[Judgement]) -> Fit:
    """Fit weights to ``judgements`` of ``store``'s runs (see the module docstring)."""
    y = labels(judgements)
    if not np.any(y != 0.5):
        raise JudgementError(
            "no judgement says one run is more dangerous than another; nothing to fit"
        )
    ids = sorted({r for j in judgements for r in (j.a, j.b)})
    f = features(store, ids)
    x = f.matrix(ids)
    index = {run_id: i for i, run_id in enumerate(ids)}
    a = np.array([index[j.a] for j in judgements])
    b = np.array([index[j.b] for j in judgements])
    diffs = x[a] - x[b]
    scale = feature_scale(x)
    stored = np.array([f.stored[i] for i in ids])
    stored_delta = stored[a] - stored[b]
    n_kind = 2 * len(kinds())
    kind_only = scale.copy()
    kind_only[n_kind:] = 0.0
    # Failure-class points where they help: kept only if they predict held-out judgements
    # better than the event kinds alone.
    without = cross_validate(diffs, y, kind_only)
    with_classes = cross_validate(diffs, y, scale)
    use_classes = bool(f.classes) and with_classes.log_loss < without.log_loss
    chosen = scale if use_classes else kind_only
    coef = train(diffs, y, chosen)
    fitted = x @ coef
    points_per_logit = float(stored.sum() / fitted.sum()) if fitted.sum() > 0 else 1.0
    weights = to_weights(coef * points_per_logit, f, campaign_weights(store).score_peers)
    return Fit(
        weights=weights,
        judgements=len(judgements),
        strict=int(np.sum(y != 0.5)),
        runs=len(ids),
        held_out=with_classes if use_classes else without,
        stored=agreement(stored_delta, y),
        with_classes=use_classes,
        points_per_logit=points_per_logit,
        folds=len(folds(len(y))),
    )


# Which pair to judge next.


POOL_PER_FAILURE = 5
"""Runs of each distinct failure that may be shown: its representative and runs spread over
its scores."""


def pool(store: Store) -> list[int]:
    """The runs pairs are drawn from: up to ``POOL_PER_FAILURE`` of each distinct failure
    (its representative first, then runs spread over its range of scores) and one run with no
    failure (so "nothing happened" is a judged reference too)."""
    chosen: list[int] = []
    scores = dict(store.db.execute("SELECT id, score FROM main.runs").fetchall())
    for failure in distinct_failures(store):
        runs = sorted(failure.run_ids, key=lambda r: (-scores[r], r))
        picks = [runs[0]]
        for q in np.linspace(0, len(runs) - 1, POOL_PER_FAILURE)[1:]:
            picks.append(runs[round(float(q))])
        chosen += list(dict.fromkeys(picks))
    calm = store.db.execute(
        "SELECT id FROM main.runs WHERE failure_class IS NULL ORDER BY id LIMIT 1"
    ).fetchone()
    if calm:
        chosen.append(calm[0])
    return list(dict.fromkeys(chosen))


def next_pair(
    store: Store, judged: Sequence[Judgement], exclude: Sequence[Judgement] = ()
) -> tuple[int, int] | None:
    """The pair whose judgement tells most about the weights: under the Laplace posterior of
    the model fitted to ``judged`` so far, the largest expected information, log(1 + p(1 − p)
    · dᵀΣd), where p is the current probability that the first is worse and dᵀΣd the
    uncertainty of the pair's score difference; shared out over runs and pairs of failure
    classes already judged, so about 50 judgements cover the distinct failures. Which run
    shows left is drawn (seeded by the count of judgements) so the side says nothing. None if
    every pair has been judged (or is in ``exclude``, pairs skipped)."""
    ids = pool(store)
    if len(ids) < 2:
        return None
    f = features(store, ids + [r for j in judged for r in (j.a, j.b)])
    x = f.matrix(ids)
    scale = feature_scale(x)
    used = scale > 0
    z = np.zeros_like(x)
    z[:, used] = x[:, used] / scale[used]
    k = int(used.sum())
    if judged:
        jx = f.matrix([j.a for j in judged]) - f.matrix([j.b for j in judged])
        coef = train(jx, labels(judged), scale)
        beta = coef[used] * scale[used]
        dz = jx[:, used] / scale[used]
        p = _sigmoid(dz @ beta)
        hessian = (dz * (p * (1 - p))[:, None]).T @ dz + RIDGE * np.eye(k)
    else:
        beta = np.zeros(k)
        hessian = RIDGE * np.eye(k)
    sigma = np.linalg.inv(hessian)
    first, second = np.triu_indices(len(ids), 1)
    d = z[first][:, used] - z[second][:, used]
    p = _sigmoid(d @ beta)
    info = np.log1p(p * (1 - p) * np.einsum("ij,jk,ik->i", d, sigma, d))
    times: dict[int, int] = {}
    class_pairs: dict[tuple[str, str], int] = {}
    seen = set()
    cls = dict(store.db.execute("SELECT id, coalesce(failure_class, '') FROM main.runs"))
    for j in judged:
        times[j.a] = times.get(j.a, 0) + 1
        times[j.b] = times.get(j.b, 0) + 1
        pair = (cls.get(j.a, ""), cls.get(j.b, ""))
        class_pairs[min(pair), max(pair)] = class_pairs.get((min(pair), max(pair)), 0) + 1
        seen.add((min(j.a, j.b), max(j.a, j.b)))
    seen.update((min(j.a, j.b), max(j.a, j.b)) for j in exclude)
    best, best_value = None, -1.0
    for n in np.argsort(-info, kind="stable"):
        if info[n] <= 0 or info[n] <= best_value:
            break
        a, b = ids[first[n]], ids[second[n]]
        if (min(a, b), max(a, b)) in seen:
            continue
        ca, cb = cls.get(a, ""), cls.get(b, "")
        shared = (1 + times.get(a, 0) + times.get(b, 0)) * (
            1 + class_pairs.get((min(ca, cb), max(ca, cb)), 0)
        )
        value = float(info[n]) / shared
        if value > best_value:
            best, best_value = (a, b), value
    if best is None:
        return None
    a, b = best
    return (b, a) if random.Random(len(judged)).random() < 0.5 else (a, b)


class SimulatedJudge:
    """A judge whose weights are known, to measure how fast judgements teach a fit (``make
    bench-weights`` and the tests): of two runs it calls worse the one that scores more under
    ``weights``, with logistic noise of a tenth of the scores' spread, and "equal" within 2 %
    of that spread."""

    def __init__(self, store: Store, weights: Weights, seed: int) -> None:
        self.rows: dict[int, tuple[dict[str, Any], str | None, float]] = {
            r[0]: (json.loads(r[1]), r[2], r[3])
            for r in store.db.execute("SELECT id, breakdown, failure_class, score FROM runs")
        }
        """Run id -> (stored breakdown, failure class, stored score)."""
        self.truth = {i: weights.score(b, c) for i, (b, c, _) in self.rows.items()}
        self.spread = float(np.std(list(self.truth.values())))
        self.rng = np.random.default_rng(seed)

    def __call__(self, a: int, b: int) -> Judgement:
        d = self.truth[a] - self.truth[b]
        if abs(d) < 0.02 * self.spread:
            return Judgement(a, b, "equal")
        p = float(1.0 / (1.0 + np.exp(-d / (0.1 * self.spread))))
        return Judgement(a, b, "a" if self.rng.random() < p else "b")

    def tau(self, ids: Iterable[int], score: Callable[[int], float]) -> float:
        """Kendall's τ-b between ``score(id)`` and the judge's order, over ``ids`` that score
        anything (runs where nothing happened tie everywhere)."""
        from scipy.stats import kendalltau

        kept = [i for i in ids if self.truth[i] > 0 or self.rows[i][2] > 0]
        return float(kendalltau([score(i) for i in kept], [self.truth[i] for i in kept])[0])

    def weighted(self, w: Weights) -> Callable[[int], float]:
        """A run's score under ``w``."""
        return lambda i: w.score(self.rows[i][0], self.rows[i][1])

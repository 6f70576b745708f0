"""Why runs fail, in terms of the situation: which situation descriptors
(:mod:`sitgen.triage.descriptors`) separate the runs that failed a given way from the others,
as a few short rules a person reads, each with its support and an exact binomial interval,
and the model's cross-validated balanced accuracy against the base rate.

The model is scikit-learn's decision tree (CART), shallow (:data:`DEPTH`), its leaves at least
:data:`LEAF_SHARE` of the runs, classes weighted to balance: each leaf where failures are
commoner than elsewhere is a rule, the conjunction of the splits on its path. Balanced
accuracy is scored by stratified 5-fold cross-validation (a rule that only fits the runs it
was learnt from scores 0.5, the base rate's)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from sitgen import _core
from sitgen.store import Store, StoreError
from sitgen.triage.descriptors import NUMERIC, described
from sitgen.triage.stats import exact_interval

DEPTH = 3
"""Splits a rule may have."""
LEAF_SHARE = 0.03
"""Least share of the runs in a leaf (and at least 5 runs): a rule speaks of enough runs to
test."""
FOLDS = 5


@dataclass
class Rule:
    """One leaf of the tree: where its conditions hold, how often runs fail."""

    conditions: list[str]
    runs: int
    failed: int
    rate: float
    interval: tuple[float, float]
    elsewhere: float
    """The failure rate of the runs outside the rule."""

    def text(self) -> str:
        low, high = self.interval
        return (
            f"{' and '.join(self.conditions) or 'every run'}: {self.failed} of {self.runs} runs "
            f"fail, {100 * self.rate:.0f} % ({100 * low:.0f}–{100 * high:.0f} %); elsewhere "
            f"{100 * self.elsewhere:.0f} %"
        )


def target_of(store: Store, failure_class: str | None, outcome: str | None,
              requirement: str | None) -> Callable[[int], bool]:  # fmt: skip
    """Which runs count as failing: of failure class ``failure_class`` (``collision`` for any
    collision class), with ``outcome``, or violating ``requirement``."""
    if requirement is not None:
        bad = {v["run_id"] for v in store.requirement_verdicts(requirement, violated_only=True)}
        return lambda r: r in bad
    rows = dict(store.db.execute("SELECT id, failure_class FROM runs").fetchall())
    outcomes = dict(store.db.execute("SELECT id, outcome FROM runs").fetchall())
    if outcome is not None:
        return lambda r: outcomes.get(r) == outcome
    if failure_class == "collision":
        return lambda r: _is_collision(rows.get(r))
    return lambda r: rows.get(r) == failure_class


def _is_collision(key: str | None) -> bool:
    """Whether class ``key`` is a collision (struck, drove into, collided, turned into)."""
    return key is not None and key.split("/")[0].startswith(
        ("struck_", "drove_into_", "collided_", "turned_into_")
    )


def explain(
    store: Store,
    failure_class: str | None = None,
    outcome: str | None = None,
    requirement: str | None = None,
) -> dict[str, Any]:
    """Rules that separate the failing runs from the others, and how well they do."""
    try:
        from sklearn.model_selection import StratifiedKFold, cross_val_score
        from sklearn.tree import DecisionTreeClassifier
    except ImportError:
        raise _core.SpecError("explain needs scikit-learn; pip install 'sitgen[explain]'") from None
    by_run = described(store)
    fails = target_of(store, failure_class, outcome, requirement)
    ids = sorted(by_run)
    rows = [by_run[i] for i in ids]
    terrains = sorted({d["terrain"] for d in rows})
    names = [*NUMERIC, *(f"terrain is {t}" for t in terrains)]
    x = np.array(
        [[float(d[n]) for n in NUMERIC] + [float(d["terrain"] == t) for t in terrains]
         for d in rows]
    )  # fmt: skip
    y = np.array([fails(i) for i in ids], dtype=int)
    if len(ids) < 2 * FOLDS or y.sum() < FOLDS or (len(y) - y.sum()) < FOLDS:
        raise StoreError(
            f"{store.path}: {int(y.sum())} of {len(ids)} runs fail so: too few of one kind to "
            f"learn from (at least {FOLDS} of each)"
        )
    leaf = max(5, int(LEAF_SHARE * len(ids)))
    model = DecisionTreeClassifier(
        max_depth=DEPTH, min_samples_leaf=leaf, class_weight="balanced", random_state=0
    )
    folds = StratifiedKFold(FOLDS, shuffle=True, random_state=0)
    scores = cross_val_score(model, x, y, cv=folds, scoring="balanced_accuracy")
    model.fit(x, y)
    rules = _rules(model, names, x, y)
    return {
        "runs": len(ids),
        "failed": int(y.sum()),
        "base_rate": float(y.mean()),
        "balanced_accuracy": float(scores.mean()),
        "balanced_accuracy_folds": [float(s) for s in scores],
        "rules": [asdict(r) | {"text": r.text()} for r in rules],
        "descriptors": names,
    }


def _words(conditions: list[tuple[str, str, float]]) -> list[str]:
    """A leaf's path as conditions in words, the bounds on one descriptor in one direction
    kept once (the tightest: ``a > 0.1 and a > 0.4`` is ``a > 0.4``), in path order."""
    tightest: dict[tuple[str, str], float] = {}
    for name, op, cut in conditions:
        if op:
            pick = min if op == "≤" else max
            tightest[name, op] = pick(tightest.get((name, op), cut), cut)
    out, said = [], set()
    for name, op, _ in conditions:
        if not op:
            out.append(name)
        elif (name, op) not in said:
            said.add((name, op))
            out.append(f"{name} {op} {tightest[name, op]:.3g}")
    return out


def _rules(model: Any, names: list[str], x: Any, y: Any) -> list[Rule]:
    """Each leaf whose failure rate is above the rest's, as a rule; highest rate first."""
    tree = model.tree_
    leaves = model.apply(x)
    rules = []

    def walk(node: int, conditions: list[tuple[str, str, float]]) -> None:
        if tree.children_left[node] == -1:
            inside = leaves == node
            k, n = int(y[inside].sum()), int(inside.sum())
            rest_n = len(y) - n
            elsewhere = float(y[~inside].sum() / rest_n) if rest_n else 0.0
            if n and k / n > elsewhere:
                ci = exact_interval(k, n)
                rules.append(Rule(_words(conditions), n, k, k / n, ci, elsewhere))
            return
        name, cut = names[tree.feature[node]], float(tree.threshold[node])
        if name.startswith("terrain is "):
            walk(tree.children_left[node], [*conditions, (name.replace(" is ", " is not "), "", 0)])
            walk(tree.children_right[node], [*conditions, (name, "", 0)])
            return
        walk(tree.children_left[node], [*conditions, (name, "≤", cut)])
        walk(tree.children_right[node], [*conditions, (name, ">", cut)])

    walk(0, [])
    return sorted(rules, key=lambda r: (-r.rate, -r.runs))

"""The kill rule: when a situation shows that a faulty controller is worse than the correct one,
robustly.

A run is chaotic: a controller nudged by a rounding error can fail with another class on a few
situations of a hundred, so one faulty run failing where the correct one did not proves
nothing. A situation kills a fault only when, over the same perturbed copies of the situation
(:mod:`sitgen.triage.robustness`: laser noise and jittered starts), the faulty controller shows the
failure significantly more often than the correct one:

1. **Screen.** The unperturbed pair must differ as :func:`screen` says: the faulty run fails
   with a class the correct run does not show at all, scores worse by the margin, or errs.
   That difference names the *event* the copies are judged by (:class:`Event`).
2. **Test.** Copies 1 … :data:`COPIES` of both runs are compared by a one-sided Fisher exact
   test of "the faulty copies show the event more often" at level :data:`ALPHA`.
3. **Early stopping.** The copies run in stages (:data:`STAGES`); after each, the test stops
   as soon as its verdict can no longer change whatever the remaining copies show
   (curtailment: the p-value with the worst and best outcomes still to come), so the level is
   exactly that of the full test and most candidates cost a few copies, not 2 × COPIES.

Equivalent mutants (:data:`MUTANTS`: the correct controller with one parameter nudged by a
relative 10⁻⁵ or less) are the rule's own check: they must never be killed.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

REQUIREMENT = "requirement:"
"""A violated requirement's class is its name after this (:mod:`sitgen.triage.requirements`)."""

KILL_MARGIN_POINTS = 100.0
"""A faulty run that shows no new failure class passes the screen only if it scores worse than
the correct run by more than this many points (one collision's start penalty)…"""
KILL_MARGIN_SHARE = 0.5
"""…and by more than this share of the correct run's score (a long pinning of the correct run
varies by more than 100 points from a small perturbation alone)."""
ALPHA = 0.001
"""Level of the one-sided test. An evaluation tests a candidate on a few per cent of its
situations for each fault and mutant (hundreds of tests at 500 situations), so the level is
set for a whole evaluation's worth of tests to give about 0.1 false kills in all: with 8
copies it takes 8 of 8 faulty copies against at most 1 correct one, or 7 against none."""
COPIES = 8
"""Perturbed copies of each controller per candidate situation, at most."""
STAGES = (2, 4, 8)
"""Copies done at each look of the sequential test (the last is :data:`COPIES`)."""


@dataclass(frozen=True)
class Outcome:
    """What the kill rule reads of a run."""

    failure_class: str | None
    """The run's failure class (its most severe event's class); None if nothing failed."""
    classes: frozenset[str]
    """Every failure class its events show."""
    score: float
    error: bool = False
    """The run could not be made or its controller failed."""
    violated: frozenset[str] = frozenset()
    """The run spec's requirements it violated, by name (docs/requirements.md)."""

    def shows(self, key: str) -> bool:
        """Whether it fails as ``key``: its failure class, or a violated requirement's class
        (``requirement:NAME``)."""
        if key.startswith(REQUIREMENT):
            return key[len(REQUIREMENT) :] in self.violated
        return self.failure_class == key


@dataclass(frozen=True)
class Kill:
    """Why a faulty run passed the screen, and (once tested) how robustly."""

    by: str
    """``class``: it fails with a failure class the correct run does not show; ``score``: it
    scored worse by more than the margin; ``error``: its controller failed where the correct
    one did not."""
    classes: tuple[str, ...]
    """The faulty run's failure class (none for a run without one)."""
    score_delta: float
    """Faulty score − correct score, unperturbed."""
    faulty_recurs: int | None = None
    """Perturbed faulty copies that showed the event (None: not tested)."""
    correct_recurs: int | None = None
    """Perturbed correct copies that showed it."""
    copies: int | None = None
    """Copies of each controller run before the test stopped."""
    p_value: float | None = None
    """The one-sided Fisher exact test's p-value on those copies."""


def score_margin(correct_score: float) -> float:
    """How much worse than the correct run a faulty run must score to pass the screen by
    score."""
    return max(KILL_MARGIN_POINTS, KILL_MARGIN_SHARE * correct_score)


def screen(correct: Outcome, faulty: Outcome) -> Kill | None:
    """Whether the unperturbed faulty run on a situation differs from the correct run with the
    same run seed enough to test: it fails with a failure class that the correct run does not
    show at all (not even as a lesser event), it scores worse by more than
    :func:`score_margin`, or its controller fails. A situation the correct run could not use
    (an error) is not tested."""
    if correct.error:
        return None
    delta = faulty.score - correct.score
    if faulty.error:
        return Kill("error", (), delta)
    own = () if faulty.failure_class is None else (faulty.failure_class,)
    if faulty.failure_class is not None and faulty.failure_class not in correct.classes:
        return Kill("class", own, delta)
    if delta > score_margin(correct.score):
        return Kill("score", own, delta)
    return None


@dataclass(frozen=True)
class Event:
    """What a perturbed copy must show to count for the faulty side: the screen's difference."""

    by: str
    failure_class: str | None = None
    threshold: float = 0.0
    """For ``score``: the correct run's score plus the margin."""

    def shown(self, o: Outcome) -> bool:
        if self.by == "error":
            return o.error
        if o.error:
            return False
        if self.by == "class":
            return o.failure_class == self.failure_class
        return o.score > self.threshold


def event_of(correct: Outcome, k: Kill) -> Event:
    """The event the copies of a screened pair are judged by."""
    if k.by == "class":
        return Event("class", k.classes[0])
    if k.by == "score":
        return Event("score", threshold=correct.score + score_margin(correct.score))
    return Event("error")


def p_value(faulty: int, correct: int, copies: int) -> float:
    """One-sided Fisher exact test: how likely ``faulty`` or more of ``copies`` faulty copies
    show the event when both controllers show it alike, given ``faulty + correct`` shows in
    all."""
    # scipy.stats takes 1.5 s to import: only a fault evaluation pays it, not every command
    # that reads a store.
    from scipy.stats import fisher_exact

    table = np.array([[faulty, copies - faulty], [correct, copies - correct]])
    return float(fisher_exact(table, alternative="greater").pvalue)


def verdict(faulty: int, correct: int, done: int, copies: int = COPIES) -> bool | None:
    """After ``done`` of ``copies`` copies a side: True (killed) if even the worst remaining
    copies keep the p-value at most :data:`ALPHA`, False (spared) if even the best ones cannot
    bring it there, None (run more) otherwise; at ``done == copies``, the test's verdict."""
    worst, best = p_bounds(faulty, correct, done, copies)
    if worst <= ALPHA:
        return True
    if best > ALPHA:
        return False
    return None


def p_bounds(faulty: int, correct: int, done: int, copies: int = COPIES) -> tuple[float, float]:
    """The full test's p-value at its largest and at its smallest, whatever the ``copies -
    done`` copies not yet run show: they all go the correct side's way, or all the faulty's."""
    left = copies - done
    return p_value(faulty, correct + left, copies), p_value(faulty + left, correct, copies)


def outcome_of_copy(result: Mapping[str, Any]) -> Outcome:
    """The kill rule's view of a perturbed copy's job result: its failure class, score and
    whether it erred (a copy is judged by the screen's event, which needs nothing else, so
    the classes of its other events are not read)."""
    if not result.get("ok"):
        return Outcome(None, frozenset(), 0.0, True)
    record = json.loads(result["record"])
    failure = record.get("failure")
    return Outcome(
        None if failure is None else str(failure["class"]),
        frozenset(),
        float(record["score"]["total"]),
        record.get("outcome") == "error",
        frozenset(v["name"] for v in record.get("requirements", []) if v["violated"]),
    )


@dataclass(frozen=True)
class Mutant:
    """An equivalent mutant: the correct controller with one numeric parameter nudged."""

    id: str
    param: str
    default: float
    """The parameter's value where the controller spec does not set it."""
    factor: float
    """The nudge: the value is multiplied by this (1 ± 10⁻⁵ or closer)."""
    controllers: tuple[str, ...]

    def params(self, given: Mapping[str, float]) -> dict[str, float]:
        """The controller's parameters with this nudge."""
        return {**given, self.param: float(given.get(self.param, self.default)) * self.factor}


_SND = ("snd", "snd_follow")
MUTANTS = (
    Mutant("equivalent_max_speed", "max_speed", 0.5, 1 - 1e-5, _SND),
    Mutant("equivalent_turn_rate", "max_turn_rate_deg_s", 60.0, 1 - 1e-5, _SND),
    Mutant("equivalent_turn_rate_up", "max_turn_rate_deg_s", 60.0, 1 + 1e-6, _SND),
    Mutant("equivalent_goal_angle_tol", "goal_angle_tol_deg", 30.0, 1 + 1e-5, _SND),
    Mutant("equivalent_goal_angle_tol_down", "goal_angle_tol_deg", 30.0, 1 - 1e-6, _SND),
    Mutant("equivalent_switch_m", "switch_m", 0.5, 1 + 1e-5, ("snd_follow",)),
)
"""Equivalent mutants, each a relative nudge of 10⁻⁵ or less of a parameter's default (SND's
Player defaults; the follower's 0.5 m switching distance): far below what the perturbed copies
change, so a kill of one is the rule's false kill."""


def mutants_of(controller: str) -> list[Mutant]:
    """The equivalent mutants ``controller`` has."""
    return [m for m in MUTANTS if controller in m.controllers]

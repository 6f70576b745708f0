"""Reading a stored controller diff (:mod:`sitgen.generation.diff`): each distinct failure's
verdict across the situations, what either side could not run, and the verdict as a summary a
person reads and as JUnit for CI.

What it does: :func:`diff_report` reads a diff store's verdicts (``diff_results``) and runs into
a :class:`DiffReport` (per base failure class: the situations where it is robustly new in B,
fixed, unchanged or not robust either way, each pair with its copies' counts);
:func:`summary_lines` and :func:`write_junit` say it. A diff *fails* (exit 1, failed JUnit
cases) on a robust new failure, on a side that could not run where the other did, on nothing
compared, and when it is partial (fewer situations evaluated than asked).

Why apart from running it: a report, a summary and JUnit read what is stored; they neither run
nor judge anything.

Parameters: none.

Source: the kill rule's verdicts (:mod:`sitgen.triage.kill`), JUnit as :mod:`sitgen.triage.junit`
writes it.
"""

from __future__ import annotations

import json
from collections.abc import Iterable, Iterator
from dataclasses import asdict, dataclass, field
from typing import Any, TextIO

from sitgen import _core
from sitgen.generation.diff import BOTH, FIXED, NEW, NOT_ROBUST, UNCHANGED
from sitgen.store import Store, StoreError
from sitgen.triage.junit import Case
from sitgen.triage.junit import write_junit as write_junit_cases


@dataclass(frozen=True)
class Pair:
    """A situation where A and B differ in one class: A's run and B's run, side by side, and
    how often their perturbed copies showed the class."""

    situation: int
    verdict: str
    a_recurs: int | None
    b_recurs: int | None
    copies: int

    @property
    def a_run(self) -> int:
        return 2 * self.situation

    @property
    def b_run(self) -> int:
        return 2 * self.situation + 1


@dataclass
class ClassDiff:
    """One distinct failure (a base failure class) across the diff's situations."""

    failure_class: str
    description: str
    verdict: str
    new: list[int] = field(default_factory=list)
    """Situations where it is robustly new in B."""
    fixed: list[int] = field(default_factory=list)
    unchanged: list[int] = field(default_factory=list)
    not_robust: list[int] = field(default_factory=list)
    pairs: list[Pair] = field(default_factory=list)
    """Each situation where A and B differ in it, in situation order."""

    def as_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["class"] = d.pop("failure_class")
        return d

    def recurrence(self, verdict: str) -> str:
        """How often B's (for ``new in B``) or A's (``fixed in B``) copies showed it, against
        the other side's, on the situations with that verdict: ``8/8 vs 0/8, 7/8 vs 1/8``."""
        shown = []
        for p in self.pairs:
            if p.verdict != verdict or p.a_recurs is None or p.b_recurs is None:
                continue
            ours, theirs = (p.b_recurs, p.a_recurs) if verdict == NEW else (p.a_recurs, p.b_recurs)
            shown.append(f"{ours}/{p.copies} vs {theirs}/{p.copies}")
        return ", ".join(shown[:3]) + (", …" if len(shown) > 3 else "")


@dataclass
class DiffReport:
    a: dict[str, Any]
    b: dict[str, Any]
    situations: int
    runs: int
    """Runs in all, every perturbed copy counted."""
    classes: list[ClassDiff]
    b_errors: dict[int, str] = field(default_factory=dict)
    """Situations where B could not run (its controller failed) and A could, each with B's
    reason: a regression as much as a new failure."""
    both_ran: int = 0
    """Situations both sides ran: with none, there is no verdict to give."""
    a_errors: dict[int, str] = field(default_factory=dict)
    """Situations where A could not run, each with A's reason: not compared."""
    b_erred: dict[int, str] = field(default_factory=dict)
    """Every situation where B could not run (where A could not either, too): not compared."""
    asked: int = 0
    """Situations the diff was asked to compare (``--n``)."""

    @property
    def robust_new(self) -> list[ClassDiff]:
        return [c for c in self.classes if c.new]

    @property
    def partial(self) -> bool:
        """Fewer situations evaluated than asked (stopped early)."""
        return self.situations < self.asked

    @property
    def failed(self) -> bool:
        """Whether the gate fails: B has robust new failures, fails to run where A ran, a
        situation could not be compared on either side, fewer situations were evaluated than
        asked, or nothing could be compared: a verdict over fewer situations must not pass."""
        return bool(
            self.robust_new
            or self.b_errors
            or self.a_errors
            or self.partial
            or (self.situations and not self.both_ran)
        )

    def uncompared(self) -> Iterator[tuple[str, dict[int, str]]]:
        """Each side that could not run somewhere, with those situations and its reasons (B's
        where A could not run either: :attr:`b_errors` has the rest)."""
        b_also = {i: r for i, r in self.b_erred.items() if i not in self.b_errors}
        for side, erred in (("A", self.a_errors), ("B", b_also)):
            if erred:
                yield side, erred

    def as_dict(self) -> dict[str, Any]:
        return {
            "a": self.a,
            "b": self.b,
            "situations": self.situations,
            "runs": self.runs,
            "robust_new": len(self.robust_new),
            "b_errors": [{"situation": i, "reason": r} for i, r in self.b_errors.items()],
            "not_compared": {
                side.lower(): [{"situation": i, "reason": r} for i, r in erred.items()]
                for side, erred in (("A", self.a_errors), ("B", self.b_erred))
            },
            "asked": self.asked,
            "partial": self.partial,
            "both_ran": self.both_ran,
            "failed": self.failed,
            "classes": [c.as_dict() for c in self.classes],
        }


def diff_report(store: Store) -> DiffReport:
    """The results stored in a diff's store. Raises StoreError if it holds none."""
    plan = store.plan("diff")
    if plan is None:
        raise StoreError(f"{store.path}: holds no controller diff (sitgen diff)")
    sentences = dict(_core.failure_classes())
    by_class: dict[str, ClassDiff] = {}

    def entry(c: str) -> ClassDiff:
        return by_class.setdefault(c, ClassDiff(c, sentences.get(c, c), UNCHANGED))

    for situation, c, a_recurs, b_recurs, copies, verdict_ in store.db.execute(
        "SELECT situation, failure_class, a_recurs, b_recurs, copies, verdict FROM diff_results "
        "ORDER BY situation, failure_class"
    ):
        e = entry(c)
        {NEW: e.new, FIXED: e.fixed, UNCHANGED: e.unchanged}.get(verdict_, e.not_robust).append(
            situation
        )
        if verdict_ != UNCHANGED:
            e.pairs.append(Pair(situation, verdict_, a_recurs, b_recurs, copies))
    for c in by_class.values():
        c.verdict = (
            BOTH
            if c.new and c.fixed
            else NEW
            if c.new
            else FIXED
            if c.fixed
            else NOT_ROBUST
            if c.not_robust
            else UNCHANGED
        )
    order = {k: i for i, (k, _) in enumerate(_core.failure_classes())}
    classes = sorted(
        by_class.values(), key=lambda c: (order.get(c.failure_class, 99), c.failure_class)
    )
    copies = store.db.execute("SELECT coalesce(sum(copies), 0) FROM diff_chunks").fetchone()[0]
    evaluated = store.db.execute("SELECT count(*) FROM runs WHERE id % 2 = 0").fetchone()[0]
    erred: dict[int, dict[int, str]] = {0: {}, 1: {}}
    for run_id, reason in store.db.execute(
        "SELECT id, reason FROM runs WHERE outcome = 'error' ORDER BY id"
    ):
        erred[run_id % 2][run_id // 2] = str(reason)
    both = store.db.execute(
        "SELECT count(*) FROM runs a JOIN runs b ON b.id = a.id + 1 WHERE a.id % 2 = 0 "
        "AND a.outcome != 'error' AND b.outcome != 'error'"
    ).fetchone()[0]
    b_errors = {i: r for i, r in erred[1].items() if i not in erred[0]}
    asked = int((store.campaign() or {}).get("n", evaluated))
    return DiffReport(
        plan["a"],
        plan["b"],
        int(evaluated),
        store.run_count() + int(copies),
        classes,
        b_errors,
        int(both),
        erred[0],
        erred[1],
        asked,
    )


def controller_label(controller: dict[str, Any]) -> str:
    """``snd_follow+safety_distance_halved``, or the name with its parameters."""
    name = str(controller["name"])
    if controller.get("fault"):
        name += f"+{controller['fault']}"
    if controller.get("params"):
        name += " " + json.dumps(controller["params"], sort_keys=True)
    return name


def write_junit(report: DiffReport, out: TextIO) -> None:
    """The verdict as JUnit XML: one test case per distinct failure, failed where it is
    robustly new in B."""
    cases = []
    for c in report.classes:
        if c.new:
            text = (
                f"robustly new in B on situations {', '.join(map(str, c.new))} "
                f"(runs {', '.join(str(2 * s + 1) for s in c.new)}); fixed on "
                f"{len(c.fixed)}, unchanged on {len(c.unchanged)}, not robust on "
                f"{len(c.not_robust)}"
            )
            failure = (c.failure_class, f"{c.description}: robustly new in B", text)
            cases.append(Case(c.failure_class, "sitgen.generation.diff", failure=failure))
        else:
            cases.append(Case(c.failure_class, "sitgen.generation.diff", output=c.verdict))
    if report.b_errors:
        first, reason = next(iter(report.b_errors.items()))
        text = (
            f"B could not run on {len(report.b_errors)} situation(s) where A ran: "
            f"{', '.join(map(str, report.b_errors))}; situation {first} (run {2 * first + 1}): "
            f"{reason}"
        )
        failure = ("controller_error", "B could not run where A ran", text)
        cases.append(Case("controller_error", "sitgen.generation.diff", failure=failure))
    elif report.situations and not report.both_ran:
        failure = ("no_comparison", "no situation ran on both sides", "nothing was compared")
        cases.append(Case("no_comparison", "sitgen.generation.diff", failure=failure))
    for side, erred in report.uncompared():
        key = f"not_compared_{side.lower()}"
        failure = (key, f"{side} could not run: situations not compared", _erred_text(erred))
        cases.append(Case(key, "sitgen.generation.diff", failure=failure))
    if report.partial:
        text = f"{report.situations} of {report.asked} situations evaluated: stopped early"
        cases.append(Case("partial", "sitgen.generation.diff", failure=("partial", text, text)))
    name = f"sitgen diff: {controller_label(report.a)} -> {controller_label(report.b)}"
    write_junit_cases(name, cases, out)


def summary_lines(report: DiffReport) -> Iterable[str]:
    yield (
        f"{controller_label(report.a)} (A) against {controller_label(report.b)} (B) on "
        f"{report.situations} situations, {report.runs} runs with their perturbed copies"
    )
    new = report.robust_new
    yield (
        f"B has {len(new)} robustly new distinct failure{'s' if len(new) != 1 else ''}"
        + (": " + ", ".join(c.failure_class for c in new) if new else "")
    )
    if report.b_errors:
        first, reason = next(iter(report.b_errors.items()))
        yield (
            f"B could not run on {len(report.b_errors)} situation(s) where A ran "
            f"(situation {first}, run {2 * first + 1}: {reason})"
        )
    elif report.situations and not report.both_ran:
        yield "no situation ran on both sides: nothing was compared"
    for side, erred in report.uncompared():
        yield f"not compared: {side} could not run on {_erred_text(erred)}"
    if report.partial:
        yield (
            f"partial: {report.situations} of {report.asked} situations evaluated; the verdict "
            "does not pass until every one is"
        )


def _erred_text(erred: dict[int, str]) -> str:
    """``3 situation(s): 0, 4, 7 (situation 0, run 0: reason)``."""
    first, reason = next(iter(erred.items()))
    return f"{len(erred)} situation(s): {', '.join(map(str, erred))} (situation {first}: {reason})"

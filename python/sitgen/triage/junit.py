"""Results for CI servers as JUnit XML: a campaign's runs (a test case per situation) and
``diff``'s verdict share one writer.

Why JUnit: it is what Jenkins, GitLab, GitHub Actions' test reporters and Azure read. The
document follows the schema those servers accept (Jenkins xunit-plugin's ``junit-10.xsd``,
which pytest also validates its own output against): ``testsuites`` > ``testsuite`` (``name``,
``tests``, ``failures``, ``errors``, ``skipped``) > ``testcase`` (``name``, ``classname``)
with at most one ``failure`` or ``error`` (``type``, ``message``, text) and ``system-out``.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, TextIO
from xml.etree import ElementTree

from sitgen.store import Store, unpack_json
from sitgen.triage.failures import distinct_failures
from sitgen.triage.requirements import PREFIX, requirement_failures
from sitgen.triage.robustness import label, verdict


@dataclass(frozen=True)
class Case:
    """One test case: failed (``failure``: type, message, text), in error (``error``: type,
    message) or passed."""

    name: str
    classname: str
    failure: tuple[str, str, str] | None = None
    error: tuple[str, str] | None = None
    output: str = ""


NOT_XML = re.compile("[\x00-\x08\x0b\x0c\x0e-\x1f\ud800-\udfff\ufffe\uffff]")
"""Characters XML 1.0 cannot hold at all, escaped or not (a controller's name or a program's
last line may hold them: an ANSI colour's ESC, a stray NUL)."""


def xml_text(text: str) -> str:
    """``text`` with each character XML 1.0 cannot hold written as ``\\xNN`` (or
    ``\\uNNNN``), so that the document parses and a reader still sees what was there."""
    return NOT_XML.sub(lambda m: ascii(m.group(0))[1:-1], text)


def write_junit(suite_name: str, cases: Sequence[Case], out: TextIO) -> None:
    """``cases`` as one JUnit test suite named ``suite_name`` (every name and text made
    writable as XML by :func:`xml_text`; ElementTree escapes ``<``, ``&`` and quotes)."""
    cases = [_writable(c) for c in cases]
    suite_name = xml_text(suite_name)
    suite = ElementTree.Element(
        "testsuite",
        name=suite_name,
        tests=str(len(cases)),
        failures=str(sum(c.failure is not None for c in cases)),
        errors=str(sum(c.error is not None and c.failure is None for c in cases)),
        skipped="0",
    )
    for c in cases:
        case = ElementTree.SubElement(suite, "testcase", classname=c.classname, name=c.name)
        if c.failure is not None:
            kind, message, text = c.failure
            ElementTree.SubElement(case, "failure", type=kind, message=message).text = text
        elif c.error is not None:
            kind, message = c.error
            ElementTree.SubElement(case, "error", type=kind, message=message)
        if c.output:
            ElementTree.SubElement(case, "system-out").text = c.output
    root = ElementTree.Element("testsuites")
    root.append(suite)
    ElementTree.indent(root)
    out.write(ElementTree.tostring(root, encoding="unicode", xml_declaration=True))
    out.write("\n")


def _writable(c: Case) -> Case:
    failure = c.failure and (xml_text(c.failure[0]), xml_text(c.failure[1]), xml_text(c.failure[2]))
    error = c.error and (xml_text(c.error[0]), xml_text(c.error[1]))
    return Case(xml_text(c.name), xml_text(c.classname), failure, error, xml_text(c.output))


def campaign_cases(store: Store) -> list[Case]:
    """A test case per run of the campaign in ``store`` (one per situation): failed where the
    run failed, with its failure class (``type``), sentence (``message``) and robustness (the
    run's own if it was measured, else that of its distinct failure's representative); in
    error where it could not run; passed otherwise."""
    failures = distinct_failures(store)
    group_of = {run_id: f for f in failures for run_id in f.run_ids}
    measured = store.robustness()
    cases = []
    rows = store.db.execute(
        "SELECT id, controller, outcome, reason, score, failure_class, failure FROM runs "
        "ORDER BY id"
    )
    for run_id, controller, outcome, reason, score, key, failure_json in rows:
        name = f"situation {run_id}"
        classname = f"sitgen.campaign.{controller}"
        said = f"outcome {outcome} ({reason}), score {score:g}"
        if key is not None:
            failure: dict[str, Any] = unpack_json(failure_json) if failure_json else {}
            description = str(failure.get("description", key))
            text = f"{said}\nrobustness: {_robustness(run_id, group_of.get(run_id), measured)}"
            cases.append(Case(name, classname, failure=(key, description, text)))
        elif outcome == "error":
            cases.append(Case(name, classname, error=("error", reason)))
        else:
            cases.append(Case(name, classname, output=said))
    return cases + requirement_cases(store)


def requirement_cases(store: Store) -> list[Case]:
    """A test case per requirement the campaign's runs were judged by: failed where some run
    violated it (``type`` its class ``requirement:NAME``; the message says in how many runs
    and the worst; the text its formula, the worst runs and its robustness under
    perturbation), passed otherwise with its least robustness."""
    verdicts = store.requirement_verdicts()
    names = sorted({v["name"] for v in verdicts})
    failed = {f.key[len(PREFIX) :]: f for f in requirement_failures(store)}
    cases = []
    for name in names:
        mine = [v for v in verdicts if v["name"] == name]
        judged = [v for v in mine if v["robustness"] is not None]
        formula = mine[0]["formula"]
        classname = "sitgen.requirement"
        if name in failed:
            f = failed[name]
            worst = min(judged, key=lambda v: (v["robustness"], v["run_id"]))
            message = (
                f"violated in {f.runs} of {len(mine)} runs; worst run {worst['run_id']}, "
                f"robustness {worst['robustness']:.4g}"
            )
            text = (
                f"{formula}\nruns, worst first: {', '.join(map(str, f.run_ids[:20]))}\n"
                f"robustness under perturbation: {f.robustness}"
            )
            cases.append(Case(name, classname, failure=(f.key, message, text)))
        elif not judged:
            cases.append(Case(name, classname, error=("no verdict", mine[0]["error"] or "")))
        else:
            least = min(judged, key=lambda v: (v["robustness"], v["run_id"]))
            cases.append(
                Case(name, classname, output=(
                    f"{formula}\nsatisfied in every run judged ({len(judged)} of {len(mine)}); "
                    f"least robustness {least['robustness']:.4g} (run {least['run_id']})"
                ))
            )  # fmt: skip
    return cases


def _robustness(run_id: int, group: Any, measured: dict[int, dict[str, Any]]) -> str:
    if run_id in measured:
        m = measured[run_id]
        return f"{verdict(m['recurs'], m['reruns'])}, {label(m['recurs'], m['reruns'])}"
    if group is not None and group.representative in measured:
        m = measured[group.representative]
        return (
            f"not measured; its distinct failure's representative (run "
            f"{group.representative}) is {verdict(m['recurs'], m['reruns'])}, "
            f"{label(m['recurs'], m['reruns'])}"
        )
    return "not measured"

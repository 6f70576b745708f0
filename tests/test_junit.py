"""Results for CI: ``campaign --junit`` (a test case per situation; a failure carries its class,
sentence and robustness) and ``--summary`` (JSON), and ``diff --junit``, validated against the
JUnit schema CI servers use (Jenkins xunit-plugin's junit-10.xsd, from pytest's source release;
``make install-test`` fetches it into test-artifacts/)."""

from __future__ import annotations

import json
import sqlite3
from pathlib import Path
from xml.etree import ElementTree

import pytest

from sitgen.store import unpack_json
from tests.conftest import ROOT, run_cli

SCHEMA = ROOT / "test-artifacts" / "junit-10.xsd"


def validate(path: Path) -> None:
    if not SCHEMA.is_file():
        pytest.skip(f"no JUnit schema at {SCHEMA} (make install-test fetches it)")
    import xmlschema

    xmlschema.XMLSchema(SCHEMA).validate(path)


@pytest.fixture(scope="module")
def campaign(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("junit")
    done = run_cli(
        "campaign", "--n", "24", "--seed", "2", "--db", str(folder / "c.db"), "--reruns", "4",
        "--junit", str(folder / "junit.xml"), "--summary", str(folder / "summary.json"),
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert f"wrote {folder / 'junit.xml'}" in done.stdout
    return folder


def test_a_campaigns_junit_validates_against_the_schema_ci_servers_use(campaign: Path) -> None:
    validate(campaign / "junit.xml")


def test_a_campaigns_junit_has_a_case_per_situation_failed_with_its_class(campaign: Path) -> None:
    suite = ElementTree.parse(campaign / "junit.xml").getroot().find("testsuite")
    assert suite is not None
    cases = suite.findall("testcase")
    with sqlite3.connect(campaign / "c.db") as c:
        rows = c.execute("SELECT id, failure_class, failure FROM runs ORDER BY id").fetchall()
        robust = {
            run_id: f"{recurs}/{reruns}"
            for run_id, recurs, reruns in c.execute(
                "SELECT run_id, recurs, reruns FROM robustness"
            ).fetchall()
        }
    assert [case.get("name") for case in cases] == [f"situation {r[0]}" for r in rows]
    assert suite.get("tests") == str(len(rows))
    assert suite.get("failures") == str(sum(r[1] is not None for r in rows))
    for case, (run_id, key, failure) in zip(cases, rows, strict=True):
        failed = case.find("failure")
        if key is None:
            assert failed is None
            continue
        assert failed is not None and failed.get("type") == key
        assert failed.get("message") == unpack_json(failure)["description"]
        text = failed.text or ""
        if run_id in robust:
            # --reruns 4, or the first copies that decided the verdict (3 recurred, or 2 not)
            assert f"recurs {robust[run_id]}" in text and robust[run_id][-1] in "234"
        else:
            assert "robustness: not measured" in text
    assert any("robust, recurs" in (c.findtext("failure") or "") for c in cases)


def test_a_campaigns_summary_is_json_with_its_distinct_failures(campaign: Path) -> None:
    summary = json.loads((campaign / "summary.json").read_text())
    assert summary["runs"] == 24
    assert sum(summary["outcomes"].values()) == 24
    assert summary["distinct"] and all("robustness" in d for d in summary["distinct"])
    done = run_cli("failures", str(campaign / "c.db"), "--format", "json")
    assert done.returncode == 0
    assert [d["key"] for d in json.loads(done.stdout)] == [d["key"] for d in summary["distinct"]]


def test_diffs_junit_validates_against_the_same_schema(tmp_path: Path) -> None:
    done = run_cli(
        "diff", "--n", "8", "--seed", "1", "--db", str(tmp_path / "d.db"),
        "--b", "snd_follow+safety_distance_halved", "--junit", str(tmp_path / "d.xml"),
    )  # fmt: skip
    assert done.returncode in (0, 1), done.stderr
    validate(tmp_path / "d.xml")


def test_names_and_messages_with_control_and_markup_characters_still_parse(tmp_path: Path) -> None:
    """A controller's name or a program's last line may hold an ESC, a NUL's neighbours or
    markup: the document must parse, and what was there must still be readable."""
    from sitgen.triage.junit import Case, write_junit

    odd = 'ctl \x01 esc \x1b[31m <&"> é'
    path = tmp_path / "odd.xml"
    with path.open("w") as out:
        write_junit(
            odd, [Case(odd, odd, failure=(odd, odd, odd)), Case(odd, odd, error=(odd, odd))], out
        )
    suite = ElementTree.parse(path).getroot().find("testsuite")
    assert suite is not None
    readable = 'ctl \\x01 esc \\x1b[31m <&"> é'
    assert suite.get("name") == readable
    failure = suite.find("testcase/failure")
    assert failure is not None and failure.text == readable and failure.get("message") == readable
    validate(path)


def test_a_campaign_whose_every_run_errs_still_writes_its_junit_and_summary(tmp_path: Path) -> None:
    junit, summary = tmp_path / "junit.xml", tmp_path / "summary.json"
    done = run_cli(
        "campaign", "--n", "2", "--db", str(tmp_path / "c.db"), "--controller", "cmd:/bin/false",
        "--junit", str(junit), "--summary", str(summary),
    )  # fmt: skip
    assert done.returncode == 1 and "every run is an error" in done.stderr, done.stderr
    suite = ElementTree.parse(junit).getroot().find("testsuite")
    assert suite is not None and suite.get("errors") == "2"
    assert json.loads(summary.read_text())["outcomes"] == {"error": 2}
    validate(junit)

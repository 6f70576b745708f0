"""The HTML report, opened in a real headless Chromium (Debian's, driven by Playwright; nothing
downloads a browser): no console errors, the distinct failures lead the index and link to their
representatives' pages, the table sorts and filters (by event kind and by failure class), run
pages state their failure class and the events that decided it, the replay plays and scrubs;
screenshots of the index and a run page are saved under test-artifacts/. Reports of an empty
campaign, of error outcomes and of 600 s runs are generated without failing."""

from __future__ import annotations

import os
import sys
from pathlib import Path
from typing import Any

import pytest

from sitgen.store import Store
from sitgen.triage.failures import distinct_failures
from tests.conftest import ROOT, open_page, run_cli
from tests.test_campaign import SMALL, write_spec

ARTIFACTS = Path(os.environ.get("SITGEN_TEST_ARTIFACTS", ROOT / "test-artifacts"))


def make_report(tmp_path: Path, text: str, name: str, *extra: str) -> Path:
    db = tmp_path / f"{name}.db"
    done = run_cli("campaign", str(write_spec(tmp_path, text, f"{name}.toml")), "--db", str(db))
    assert done.returncode == 0, done.stderr
    out = tmp_path / f"{name}-report"
    done = run_cli("report", str(db), "-o", str(out), *extra)
    assert done.returncode == 0, done.stderr
    return out


@pytest.fixture(scope="module")
def report(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return make_report(tmp_path_factory.mktemp("report"), SMALL, "small")


def test_the_index_sorts_filters_and_has_no_console_errors(report: Path, browser: Any) -> None:
    page, errors = open_page(browser, report / "index.html")
    rows = page.locator("#runs tbody tr")
    assert rows.count() == 8
    scores = [
        float(s)
        for s in page.eval_on_selector_all("#runs tbody tr", "rs => rs.map(r => r.dataset.score)")
    ]
    assert scores == sorted(scores, reverse=True), "ranked by score"
    page.click("th[data-column=score]")
    ascending = page.eval_on_selector_all("#runs tbody tr", "rs => rs.map(r => +r.dataset.score)")
    assert ascending == sorted(scores)
    page.click("th[data-column=run]")
    runs = page.eval_on_selector_all("#runs tbody tr", "rs => rs.map(r => +r.dataset.run)")
    assert runs == sorted(runs)
    kinds = page.eval_on_selector_all("#filter option", "os => os.map(o => o.value)")[1:]
    assert kinds, "some scored events to filter by"
    kind = kinds[0]
    page.select_option("#filter", kind)
    visible = page.eval_on_selector_all(
        "#runs tbody tr", "rs => rs.filter(r => !r.hidden).map(r => r.dataset.kinds)"
    )
    assert visible and all(kind in k.split() for k in visible)
    assert int(page.inner_text("#shown")) == len(visible)
    hidden = page.eval_on_selector_all("#runs tbody tr", "rs => rs.filter(r => r.hidden).length")
    assert hidden == 8 - len(visible)
    page.select_option("#filter", "")
    ARTIFACTS.mkdir(parents=True, exist_ok=True)
    page.screenshot(path=str(ARTIFACTS / "report-index.png"), full_page=True)
    assert page.locator("#histogram rect").count() >= 1
    assert errors == []


def test_the_distinct_failures_lead_the_index_and_link_to_run_pages(
    report: Path, browser: Any
) -> None:
    with Store(report.parent / "small.db") as store:
        failures = distinct_failures(store)
    assert failures, "the small campaign has failures to show"
    page, errors = open_page(browser, report / "index.html")
    first = page.evaluate("document.querySelector('h1').nextElementSibling.id")
    assert first == "distinct", "the distinct failures come first"
    for later in (".facts", "#histogram", "#kinds", "#runs"):
        before = page.evaluate(
            f"!!(document.getElementById('distinct').compareDocumentPosition("
            f"document.querySelector('{later}')) & Node.DOCUMENT_POSITION_FOLLOWING)"
        )
        assert before, f"the distinct failures come before {later}"
    cards = page.eval_on_selector_all(
        "#distinct .card",
        """cs => cs.map(c => ({key: c.dataset.key, runs: +c.dataset.runs,
            text: c.innerText, href: c.querySelector('a.representative')?.getAttribute('href'),
            figure: c.querySelector('img')?.naturalWidth ?? 0}))""",
    )
    assert [c["key"] for c in cards] == [f.key for f in failures], "one card each, best first"
    for card, f in zip(cards, failures, strict=True):
        assert f.description in card["text"] and f"{f.runs} run" in card["text"]
        assert f"{f.best_score:.1f}" in card["text"] and f"{f.share:.1%}" in card["text"]
        assert card["href"] == f"run-{f.representative}.html"
        assert (report / card["href"]).is_file(), card
        assert card["figure"] > 0, f"run {f.representative}'s figure loads"
    page.click("#distinct .card a.representative")
    assert page.url.endswith(f"run-{failures[0].representative}.html")
    assert errors == []


def test_every_representative_gets_a_page_beyond_the_top(report: Path, browser: Any) -> None:
    out = report.parent / "top1-report"
    done = run_cli("report", str(report.parent / "small.db"), "-o", str(out), "--top", "1")
    assert done.returncode == 0, done.stderr
    with Store(report.parent / "small.db") as store:
        top = store.ranked(1)[0]["run"]
        representatives = {f.representative for f in distinct_failures(store)}
    assert len(representatives - {top}) >= 1, "some representative beyond the top run"
    pages = {int(p.stem.removeprefix("run-")) for p in out.glob("run-*.html")}
    assert pages == representatives | {top}
    assert all((out / f"run-{r}.png").is_file() for r in pages)
    page, errors = open_page(browser, out / "index.html")
    hrefs = page.eval_on_selector_all(
        "#distinct .card a.representative", "as => as.map(a => a.getAttribute('href'))"
    )
    assert sorted(hrefs) == sorted(f"run-{r}.html" for r in representatives)
    linked = page.eval_on_selector_all("#runs tbody tr a", "as => as.map(a => a.textContent)")
    assert {int(r) for r in linked} == pages, "the table links every run page"
    assert errors == []


def test_the_class_filter_shows_only_runs_of_that_class(report: Path, browser: Any) -> None:
    with Store(report.parent / "small.db") as store:
        rows = store.ranked()
    page, errors = open_page(browser, report / "index.html")
    cells = page.eval_on_selector_all(
        "#runs tbody tr",
        "rs => rs.map(r => [+r.dataset.run, r.dataset.class, r.querySelector('td.class').title,"
        " r.querySelector('td.class').innerText])",
    )
    by_run = {r["run"]: r for r in rows}
    for run_id, key, title, text in cells:
        assert key == title == (by_run[run_id]["failure_class"] or "")
        assert text == (by_run[run_id]["failure"] or "none")
    options = page.eval_on_selector_all("#class-filter option", "os => os.map(o => o.value)")
    present = {r["failure_class"] for r in rows}
    assert options[0] == "" and set(options[1:]) == {k or "-" for k in present}
    counts = {k: sum(r["failure_class"] == k for r in rows) for k in present}
    key = max((k for k in present if k), key=lambda k: counts[k])
    page.select_option("#class-filter", key)
    visible = page.eval_on_selector_all(
        "#runs tbody tr", "rs => rs.filter(r => !r.hidden).map(r => r.dataset.class)"
    )
    assert visible == [key] * counts[key], "only the runs of that class"
    assert len(visible) < len(rows), "the filter hides some runs"
    assert int(page.inner_text("#shown")) == counts[key]
    if None in present:
        page.select_option("#class-filter", "-")
        visible = page.eval_on_selector_all(
            "#runs tbody tr", "rs => rs.filter(r => !r.hidden).map(r => r.dataset.class)"
        )
        assert visible == [""] * counts[None]
    # Both filters at once: the runs of the class that also have the event kind.
    page.select_option("#class-filter", key)
    kind = page.eval_on_selector_all("#filter option", "os => os.map(o => o.value)")[1]
    page.select_option("#filter", kind)
    both = page.eval_on_selector_all(
        "#runs tbody tr",
        "rs => rs.filter(r => !r.hidden).map(r => [r.dataset.class, r.dataset.kinds])",
    )
    assert all(c == key and kind in k.split() for c, k in both)
    page.select_option("#filter", "")
    page.select_option("#class-filter", "")
    assert page.locator("#runs tbody tr:not([hidden])").count() == len(rows)
    assert errors == []


def test_a_run_page_states_its_class_and_why(report: Path, browser: Any) -> None:
    with Store(report.parent / "small.db") as store:
        runs = {int(p.stem.removeprefix("run-")) for p in report.glob("run-*.html")}
        failures = {r: store.run_row(r)["failure"] for r in runs}
    assert any(failures.values()), "some run page with a failure class"
    for run_id, failure in failures.items():
        text = (report / f"run-{run_id}.html").read_text()
        if failure is None:
            assert "<p id='failure' data-class=''>Failure: <b>no failure</b>" in text, run_id
            assert "id='failure-events'" not in text
        else:
            assert f"data-class='{failure['class']}'" in text, run_id
            assert text.count("<mark id='event-") == len(failure["events"]), run_id
            assert all(f"<mark id='event-{i}'" in text for i in failure["events"]), run_id
    run_id, failure = min(
        ((r, f) for r, f in failures.items() if f and f["events"]), key=lambda rf: rf[0]
    )
    page, errors = open_page(browser, report / f"run-{run_id}.html")
    stated = page.inner_text("#failure")
    assert failure["description"] in stated and failure["class"] in stated
    listed = page.eval_on_selector_all(
        "#failure-events [data-event]", "ss => ss.map(s => [+s.dataset.event, s.innerText])"
    )
    assert [i for i, _ in listed] == failure["events"], "the deciding events, by position"
    log = page.inner_text("#events").splitlines()
    for i, line in listed:
        assert line.startswith(f"#{i}") and line.split(maxsplit=1)[1] == log[i].strip()
    marked = page.eval_on_selector_all("#events mark", "ms => ms.map(m => m.innerText)")
    assert marked == [log[i] for i in failure["events"]], "the log marks the deciding events"
    outlined = page.eval_on_selector_all(
        "#timeline rect.deciding", "rs => rs.map(r => +r.dataset.event)"
    )
    assert sorted(outlined) == sorted(failure["events"])
    page.click("#failure-events [data-event]")
    frame = int(page.get_attribute("#replay", "data-frame") or 0)
    dt = page.evaluate("window.SITGEN_RUN.dt_s")
    start = page.eval_on_selector("#failure-events [data-event]", "s => +s.dataset.seek")
    assert frame == min(round(start / dt), page.evaluate("window.sitgenReplay.frames") - 1)
    assert errors == []
    no_class = sorted(r for r, f in failures.items() if f is None)
    if no_class:
        page, errors = open_page(browser, report / f"run-{no_class[0]}.html")
        assert page.inner_text("#failure").startswith("Failure: no failure")
        assert errors == []


def test_a_run_page_replays_and_scrubs(report: Path, browser: Any) -> None:
    index, _ = open_page(browser, report / "index.html")
    top = index.eval_on_selector("#runs tbody tr a", "a => a.getAttribute('href')")
    page, errors = open_page(browser, report / top)
    canvas = page.locator("#replay")
    assert canvas.get_attribute("data-frame") == "0"
    start = canvas.get_attribute("data-agent")
    page.select_option("#speed", "10")
    page.click("#play")
    page.wait_for_function("+document.getElementById('replay').dataset.frame > 5", timeout=10_000)
    page.click("#play")  # pause
    paused = int(canvas.get_attribute("data-frame"))
    page.wait_for_timeout(300)
    assert int(canvas.get_attribute("data-frame")) == paused, "paused"
    frames = page.evaluate("window.sitgenReplay.frames")
    page.eval_on_selector(
        "#scrub",
        f"s => {{ s.value = {frames - 1}; s.dispatchEvent(new Event('input')); }}",
    )
    assert canvas.get_attribute("data-frame") == str(frames - 1)
    assert canvas.get_attribute("data-agent") != start, "the scrubber moved the robots"
    assert page.locator("#breakdown tr").count() >= 1
    assert page.locator("#timeline").count() == 1
    assert "sitgen rerun" in page.inner_text("body")
    assert page.evaluate("document.querySelector('img.figure').naturalWidth") > 0
    ARTIFACTS.mkdir(parents=True, exist_ok=True)
    page.screenshot(path=str(ARTIFACTS / "report-run.png"), full_page=True)
    assert errors == []


def test_reports_of_empty_failing_and_long_campaigns(tmp_path: Path, browser: Any) -> None:
    empty = make_report(tmp_path, SMALL.replace("n = 8", "n = 0"), "empty")
    assert (empty / "index.html").exists() and not list(empty.glob("run-*.html"))
    assert "<p id='no-failures'>No failures" in (empty / "index.html").read_text()
    crash = f"{sys.executable} {ROOT / 'tests' / 'controllers' / 'misbehaving.py'} sometimes"
    failing = make_report(tmp_path, SMALL + f'[run.controller]\nname = "cmd:{crash}"\n', "failing")
    long_runs = make_report(
        tmp_path,
        SMALL.replace("n = 8", "n = 2").replace("time_limit_s = 60.0", "time_limit_s = 600.0")
        + '[run.controller]\nname = "straight"\n',
        "long",
        "--top",
        "2",
    )
    for site in (empty, failing, long_runs):
        _, errors = open_page(browser, site / "index.html")
        assert errors == [], (site, errors)
        for run_page in sorted(site.glob("run-*.html")):
            _, errors = open_page(browser, run_page)
            assert errors == [], (run_page, errors)
    assert "error" in (failing / "index.html").read_text()
    assert len(list(long_runs.glob("run-*.html"))) == 2


def test_a_report_never_removes_what_it_did_not_write_where_its_bags_go(tmp_path: Path) -> None:
    """`report --rosbag2` rewrites its own bags, and refuses to touch anything else at
    OUT/rosbag2/run-N (a user's file, a folder of theirs, a link)."""
    db = tmp_path / "c.db"
    spec = write_spec(tmp_path, SMALL)
    assert (
        run_cli("campaign", str(spec), "--n", "3", "--db", str(db), "--reruns", "0").returncode == 0
    )
    out = tmp_path / "site"
    bags = out / "rosbag2"
    bags.mkdir(parents=True)
    mine = tmp_path / "mine.txt"
    mine.write_text("keep")
    for run_id in range(3):
        (bags / f"run-{run_id}").symlink_to(mine)
    done = run_cli("report", str(db), "-o", str(out), "--rosbag2", "1", "--top", "0")
    assert done.returncode == 1 and "is not a rosbag2 a report wrote" in done.stderr, done.stderr
    assert mine.read_text() == "keep"
    for run_id in range(3):
        (bags / f"run-{run_id}").unlink()
    assert (
        run_cli("report", str(db), "-o", str(out), "--rosbag2", "1", "--top", "0").returncode == 0
    )
    written = [p for p in bags.iterdir() if (p / "metadata.yaml").is_file()]
    assert len(written) == 1
    again = run_cli("report", str(db), "-o", str(out), "--rosbag2", "1", "--top", "0")
    assert again.returncode == 0, again.stderr  # its own bag is rewritten

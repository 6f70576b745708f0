"""The HTML report, opened in a real headless Chromium (Debian's, driven by Playwright; nothing
downloads a browser): no console errors, the table sorts and filters, the replay plays and
scrubs; screenshots of the index and a run page are saved under test-artifacts/. Reports of an
empty campaign, of error outcomes and of 600 s runs are generated without failing."""

from __future__ import annotations

import os
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from tests.conftest import ROOT, run_cli
from tests.test_campaign import SMALL, write_spec

CHROMIUM = os.environ.get("SITGEN_CHROMIUM", "/usr/bin/chromium")
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


@pytest.fixture(scope="module")
def browser() -> Iterator[Any]:
    if not Path(CHROMIUM).exists():
        pytest.skip(f"no Chromium at {CHROMIUM} (apt-get install chromium, or set SITGEN_CHROMIUM)")
    sync_api = pytest.importorskip("playwright.sync_api", reason="pip install playwright")
    with sync_api.sync_playwright() as p:
        b = p.chromium.launch(executable_path=CHROMIUM, args=["--no-sandbox"])
        yield b
        b.close()


def open_page(browser: Any, path: Path) -> tuple[Any, list[str]]:
    page = browser.new_page(viewport={"width": 1280, "height": 1000})
    errors: list[str] = []
    page.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
    page.on("pageerror", lambda e: errors.append(str(e)))
    page.goto(path.as_uri())
    return page, errors


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

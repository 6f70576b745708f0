"""`sitgen compare`: controllers on the same situations; its statistics are scipy's exact ones
(checked on fixed tables against values computed by hand), identical controllers come out
"no difference", and the outputs a paper's table needs (JSON, CSV)."""

from __future__ import annotations

import csv
import io
import json
import sqlite3
from pathlib import Path

import pytest

from sitgen.generation.compare import NO_DIFFERENCE, labels_of
from sitgen.triage.stats import exact_interval, fisher_greater, mcnemar_exact
from tests.conftest import ROOT, run_cli

SPEC = str(ROOT / "examples" / "campaigns" / "paper120.toml")


@pytest.mark.parametrize(
    ("k", "n", "low", "high"),
    [(0, 10, 0.0, 0.308497), (5, 10, 0.187086, 0.812914), (10, 10, 0.691503, 1.0),
     (3, 100, 0.006229, 0.085176)],
)  # fmt: skip
def test_the_failure_rates_interval_is_clopper_pearsons(
    k: int, n: int, low: float, high: float
) -> None:
    got = exact_interval(k, n)
    assert got == pytest.approx((low, high), abs=1e-6)


@pytest.mark.parametrize(
    ("a_only", "b_only", "p"),
    [(0, 0, 1.0), (0, 4, 0.125), (4, 0, 0.125), (1, 9, 22 / 1024), (5, 5, 1.0)],
)
def test_the_pairwise_test_is_the_exact_mcnemar(a_only: int, b_only: int, p: float) -> None:
    # Two-sided: twice the smaller binomial tail at 1/2 of the discordant pairs (at most 1).
    assert mcnemar_exact(a_only, b_only) == pytest.approx(p, rel=1e-12)


def test_the_fisher_test_is_scipys_one_sided_exact() -> None:
    # 8 of 10 against 2 of 10: hypergeometric tail P(X >= 8) with 10 failures among 20.
    from math import comb

    tail = sum(comb(10, k) * comb(10, 10 - k) for k in range(8, 11)) / comb(20, 10)
    assert fisher_greater(8, 10, 2, 10) == pytest.approx(tail, rel=1e-12)


def test_repeated_controllers_get_their_own_stores() -> None:
    assert labels_of([{"name": "snd_follow"}, {"name": "snd_follow"}, {"name": "python:m:C"}]) == [
        "snd_follow", "snd_follow-2", "python_m_C",
    ]  # fmt: skip


def test_identical_controllers_show_no_difference_on_the_same_situations(tmp_path: Path) -> None:
    done = run_cli(
        "compare", SPEC, "--controllers", "snd_follow,snd_follow,vo", "--n", "16",
        "--time-limit", "60", "--dir", str(tmp_path), "--format", "json",
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    result = json.loads(done.stdout)
    a, b, vo = result["controllers"]
    assert (a["failed"], a["interval"], a["distinct"]) == (
        b["failed"],
        b["interval"],
        b["distinct"],
    )
    same = next(p for p in result["pairs"] if {p["a"], p["b"]} == {"snd_follow", "snd_follow-2"})
    assert (same["a_only"], same["b_only"], same["p_value"], same["verdict"]) == (
        0, 0, 1.0, NO_DIFFERENCE,
    )  # fmt: skip

    # The same situations: the same map and starts for every controller.
    def starts(db: Path) -> list[str]:
        with sqlite3.connect(db) as c:
            rows = c.execute("SELECT situation FROM situations ORDER BY id").fetchall()
        return [json.dumps([r["start"] for r in json.loads(s)["robots"]]) for (s,) in rows]

    assert starts(tmp_path / "snd_follow.db") == starts(tmp_path / "vo.db")
    assert set(vo["only"]) <= set(vo["distinct"])
    assert not set(vo["only"]) & set(a["distinct"])
    table = list(csv.DictReader(io.StringIO(run_cli(
        "compare", SPEC, "--controllers", "snd_follow,snd_follow,vo", "--n", "16",
        "--time-limit", "60", "--dir", str(tmp_path), "--format", "csv",
    ).stdout)))  # fmt: skip
    assert [r["controller"] for r in table] == ["snd_follow", "snd_follow-2", "vo"]
    assert float(table[2]["failure_rate"]) == pytest.approx(vo["failure_rate"])
    # Beside the stores: the figures as JSON and the comparison page.
    assert json.loads((tmp_path / "comparison.json").read_text()) == result
    page = (tmp_path / "comparison.html").read_text()
    for label in ("snd_follow", "snd_follow-2", "vo"):
        assert f"<tr data-controller='{label}'>" in page
    # The identical pair's cells read 0 / 0 and are not marked as a difference.
    assert page.count("<td class='same' title='no difference, p = 1'>0 / 0</td>") == 2
    assert "sitgen compare" in page and "--controllers snd_follow,snd_follow,vo" in page


def test_compare_needs_two_controllers(tmp_path: Path) -> None:
    done = run_cli("compare", "--controllers", "snd_follow", "--dir", str(tmp_path))
    assert done.returncode == 2
    assert "--controllers: give two or more controllers" in done.stderr

"""Requirements in STL: the core's robustness equals rtamt's offline discrete-time monitor's
(the oracle) on random formulas and traces, and on formulas whose reading depends on rtamt's
precedence; a run's verdicts and signals come back with its record."""

from __future__ import annotations

import json
import math
import shlex
import sqlite3
import subprocess
import sys
import warnings
from pathlib import Path
from typing import Any
from xml.etree import ElementTree

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import sitgen
from sitgen import _core
from tests.conftest import ROOT, open_page, run_cli
from tests.test_guide import guide_commands

rtamt = pytest.importorskip("rtamt", reason="rtamt (the STL oracle) is in the test extra")

DT_S = 0.1
SIGNALS = ["speed", "peer_distance", "goal_distance"]


def oracle(formula: str, trace: dict[str, list[float]]) -> list[float]:
    """rtamt's robustness signal of ``formula`` over ``trace``, samples DT_S apart."""
    spec = rtamt.StlDiscreteTimeOfflineSpecification()
    for name in trace:
        spec.declare_var(name, "float")
    spec.set_sampling_period(int(DT_S * 1000), "ms", 0.1)
    spec.spec = formula
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        spec.parse()
        n = len(next(iter(trace.values())))
        data: dict[str, Any] = {"time": [round(i * DT_S, 9) for i in range(n)]}
        data.update({k: list(v) for k, v in trace.items()})
        return [r for _, r in spec.evaluate(data)]


def same(a: float, b: float) -> bool:
    if math.isnan(a) or math.isnan(b):
        return math.isnan(a) and math.isnan(b)
    if math.isinf(a) or math.isinf(b):
        return a == b
    return abs(a - b) <= 1e-9 * max(1.0, abs(a), abs(b))


def bound(steps: int) -> str:
    return f"{steps * DT_S:.1f}"


def window(draw: st.DrawFn, optional: bool = True) -> str:
    if optional and draw(st.booleans()):
        return ""
    a = draw(st.integers(0, 6))
    b = a + draw(st.integers(0, 8))
    sep = draw(st.sampled_from([":", ","]))
    return f"[{bound(a)}{sep}{bound(b)}]"


@st.composite
def term(draw: st.DrawFn, depth: int = 0) -> str:
    """An arithmetic expression over the signals (no division by a signal, no sqrt or pow of
    a negative number: rtamt raises where IEEE arithmetic gives ±inf or NaN)."""
    choice = draw(st.integers(0, 7 if depth < 2 else 1))
    if choice == 0:
        return draw(st.sampled_from(SIGNALS))
    if choice == 1:
        return repr(draw(st.floats(-3, 3, allow_nan=False).map(lambda x: round(x, 3))))
    left, right = draw(term(depth + 1)), draw(term(depth + 1))
    if choice == 2:
        return f"({left} + {right})"
    if choice == 3:
        return f"({left} - {right})"
    if choice == 4:
        return f"({left} * {right})"
    if choice == 5:
        return f"abs({left})"
    if choice == 6:
        return f"({left} / {draw(st.sampled_from(['2', '0.5', '-4']))})"
    return f"sqrt(abs({left}))"


@st.composite
def formula(draw: st.DrawFn, depth: int = 0) -> str:
    """A random STL formula, fully parenthesised."""
    leaf = depth >= 3 or draw(st.integers(0, 3)) == 0
    if leaf:
        op = draw(st.sampled_from(["<", "<=", ">", ">=", "==", "!=="]))
        return f"({draw(term())} {op} {draw(term())})"
    kind = draw(st.integers(0, 17))

    def sub() -> str:
        return draw(formula(depth + 1))

    match kind:
        case 0:
            return f"(not {sub()})"
        case 1:
            return f"({sub()} and {sub()})"
        case 2:
            return f"({sub()} or {sub()})"
        case 3:
            return f"({sub()} implies {sub()})"
        case 4:
            return f"({sub()} iff {sub()})"
        case 5:
            return f"({sub()} xor {sub()})"
        case 6:
            return f"(always{window(draw)} {sub()})"
        case 7:
            return f"(eventually{window(draw)} {sub()})"
        case 8:
            return f"(historically{window(draw)} {sub()})"
        case 9:
            return f"(once{window(draw)} {sub()})"
        case 10:
            return f"({sub()} until{window(draw)} {sub()})"
        case 11:
            return f"({sub()} since{window(draw)} {sub()})"
        case 12:
            return f"(prev {sub()})"
        case 13:
            return f"(next {sub()})"
        case 14:
            return f"rise({sub()})"
        case 15:
            return f"fall({sub()})"
        case 16:
            return f"({sub()} unless{window(draw, optional=False)} {sub()})"
        case _:
            return f"({draw(st.sampled_from(['G', 'F', 'H', 'O']))}{window(draw)} {sub()})"


@st.composite
def trace(draw: st.DrawFn) -> dict[str, list[float]]:
    n = draw(st.integers(2, 30))  # rtamt cannot evaluate a single sample
    values = st.floats(-5, 5, allow_nan=False).map(lambda x: round(x, 2))
    return {name: draw(st.lists(values, min_size=n, max_size=n)) for name in SIGNALS}


@settings(max_examples=400, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(formula(), trace())
def test_robustness_equals_rtamts_on_random_formulas_and_traces(
    text: str, signals: dict[str, list[float]]
) -> None:
    ours = _core.requirement_robustness(text, signals, DT_S)
    theirs = oracle(text, signals)
    assert len(ours) == len(theirs)
    bad = [(i, a, b) for i, (a, b) in enumerate(zip(ours, theirs, strict=True)) if not same(a, b)]
    assert not bad, f"{text}: sample, sitgen, rtamt: {bad[:3]}"


# Formulas without parentheses, whose value depends on reading them with rtamt's precedence
# and associativity.
UNPARENTHESISED = [
    "not speed > 1 and peer_distance > 0.5",
    "always speed > 0 and peer_distance > 0",
    "always speed > 0 until peer_distance > 1",
    "speed > 0 until peer_distance > 1 until goal_distance > 2",
    "speed > 0 and peer_distance > 1 or goal_distance > 2",
    "speed > 0 or peer_distance > 1 and goal_distance > 2",
    "speed > 0 implies peer_distance > 1 implies goal_distance > 2",
    "speed > 0 iff peer_distance > 1 xor goal_distance > 2",
    "speed > 0 since peer_distance > 1 and goal_distance > 0",
    "eventually[0:0.5] speed > 1 or peer_distance < 0 until[0:0.3] goal_distance > 1",
    "speed * 2 + peer_distance > goal_distance",
    "speed * peer_distance / 2 > 1",
    "speed + peer_distance - goal_distance > 0",
    "abs(speed - 1) * 2 < peer_distance",
    "G[0:0.3] speed >= -1 -> F[0.1:0.4] peer_distance <= 2",
    "prev speed > 0 and next peer_distance > 1",
    "historically[0:0.2] speed > -2 & once peer_distance > 4 | goal_distance < -3",
    "not not speed > 0",
    "speed > 0 unless[0.1:0.4] peer_distance > 2",
]


@pytest.mark.parametrize("text", UNPARENTHESISED)
def test_precedence_and_associativity_are_rtamts(text: str) -> None:
    rng = np.random.default_rng(7)
    for _ in range(20):
        n = int(rng.integers(2, 25))
        signals = {s: [round(float(x), 2) for x in rng.uniform(-5, 5, n)] for s in SIGNALS}
        ours = _core.requirement_robustness(text, signals, DT_S)
        theirs = oracle(text, signals)
        assert all(same(a, b) for a, b in zip(ours, theirs, strict=True)), text


@pytest.mark.parametrize(
    ("text", "message"),
    [
        (
            "always (speed < )",
            "formula: column 17: expected a signal, a number, '(' or an operator",
        ),
        ("always (sped < 1)", "unknown signal 'sped'; the signals are speed, turn_rate,"),
        ("speed/2 > 1", "unknown signal 'speed/2' (rtamt reads '/' and '.' inside a name"),
        ("always[0:0.25] speed < 1", "the bound 0.25 s is not a whole number of steps of 0.1 s"),
        ("always[2:1] speed < 1", "the interval's start is after its end"),
        ("speed / 2 * 3 > 1", "write ( ) around '/ *'"),
        ("speed > 1 unless peer_distance > 1", "'unless' needs an interval"),
        ("speed > true", "'true' is not an expression"),
        ("(" * 300 + "speed > 1" + ")" * 300, "nests deeper than 200 levels"),
    ],
)
def test_a_formula_that_does_not_read_is_one_line_naming_the_column(
    text: str, message: str
) -> None:
    with pytest.raises(_core.SpecError) as e:
        _core.requirement_robustness(text, {"speed": [0.0]}, DT_S)
    assert message in str(e.value)
    assert "\n" not in str(e.value)


def test_a_formula_thousands_of_operators_long_is_evaluated() -> None:
    text = " and ".join(f"speed < {i}" for i in range(1, 5001))
    assert _core.requirement_robustness(text, {"speed": [0.5, 0.2]}, DT_S)[0] == 0.5


# A run's verdicts, its signals, and the commands that take requirements.

FIVE = {
    "keep_away": "always (peer_clearance > 0.3)",
    "slow_near_peer": "always (peer_distance < 1.5 implies speed < 0.3)",
    "reach_goal": "eventually[0:25] goal_distance < 0.5",
    "brake_when_close": "always (peer_distance < 1 implies eventually[0:1.5] speed < 0.1)",
    "gentle_by_walls": "always (obstacle_clearance < 0.3 implies abs(turn_rate) < 1.05)",
}


def _five() -> list[dict[str, str]]:
    return [{"name": k, "formula": f} for k, f in FIVE.items()]


def test_a_runs_verdicts_equal_rtamts_on_its_own_signals(situation: sitgen.Situation) -> None:
    rec = sitgen.run(situation, time_limit=30, spec={"requirement": _five()})
    assert [v["name"] for v in rec.requirements] == list(FIVE)
    n = rec.steps + 1
    for v in rec.requirements:
        used = {s: rec.signals[s].tolist() for s in rec.signals if s in FIVE[v["name"]]}
        assert all(len(x) == n for x in used.values())
        theirs = oracle(FIVE[v["name"]], used)[0]
        assert same(v["robustness"], theirs), v
        assert v["violated"] == (theirs < 0)


def test_signals_recompute_from_the_stored_trajectory(situation: sitgen.Situation) -> None:
    every = " and ".join(f"{s} > -1000000" for s in _core.requirement_signals())
    rec = sitgen.run(
        situation, time_limit=20, spec={"requirement": [{"name": "all", "formula": every}]}
    )
    traj, dt = rec.trajectory, 0.1
    agent, peers = traj[:, 0, :], traj[:, 1:, :]
    step = np.diff(agent[:, :2], axis=0)
    turn = np.angle(np.exp(1j * np.diff(agent[:, 2])))
    mid = agent[:-1, 2] + turn / 2
    sign = np.where(step[:, 0] * np.cos(mid) + step[:, 1] * np.sin(mid) < 0, -1.0, 1.0)
    np.testing.assert_allclose(rec.signals["speed"][1:], sign * np.hypot(*step.T) / dt, atol=1e-9)
    np.testing.assert_allclose(rec.signals["turn_rate"][1:], turn / dt, atol=1e-9)
    d = np.hypot(*(peers[:, :, :2] - agent[:, None, :2]).transpose(2, 0, 1))
    np.testing.assert_allclose(rec.signals["peer_distance"], d.min(axis=1), atol=1e-12)
    goal = situation.agent.waypoints[-1]
    np.testing.assert_allclose(
        rec.signals["goal_distance"], np.hypot(agent[:, 0] - goal[0], agent[:, 1] - goal[1])
    )
    nearest = d.argmin(axis=1)
    closing = (d[:-1, :][np.arange(len(d) - 1), nearest[1:]] - d.min(axis=1)[1:]) / dt
    np.testing.assert_allclose(rec.signals["closing_speed"][1:], closing, atol=1e-9)
    assert set(np.unique(rec.signals["peer_seen"])) <= {0.0, 1.0}
    assert (rec.signals["peer_clearance"] <= rec.signals["peer_distance"]).all()
    assert (rec.signals["obstacle_clearance"] >= 0).all()
    assert (rec.signals["obstacle_clearance"] <= 2.0).all()


def test_an_undefined_value_is_a_verdict_with_its_reason_not_a_crash(
    situation: sitgen.Situation,
) -> None:
    rec = sitgen.run(
        situation, time_limit=5,
        spec={"requirement": [{"name": "nan", "formula": "sqrt(speed - 10) > 0"}]},
    )  # fmt: skip
    (v,) = rec.requirements
    assert v["robustness"] is None and not v["violated"]
    assert "undefined (NaN)" in v["error"]


def test_sitgen_run_prints_each_verdict(situation_file: Path) -> None:
    done = run_cli(
        "run", str(situation_file), "--time-limit", "20",
        "--require", "reach_goal: eventually[0:5] goal_distance < 0.5",
        "--require", "keep_away: always (peer_clearance > 0.3)",
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert "requirement reach_goal: VIOLATED, robustness" in done.stdout
    assert "(from 5.0 s; decided over 0.0-5.0 s)" in done.stdout
    assert "requirement keep_away: " in done.stdout


def test_a_campaign_stores_verdicts_and_failures_lists_violations(tmp_path: Path) -> None:
    spec = tmp_path / "campaign.toml"
    spec.write_text(
        'n = 12\n[situation.terrain]\npreset = "open_field"\n'
        "[situation.mission]\npeers_min = 3\npeers_max = 3\n[run]\ntime_limit_s = 40.0\n"
        + "".join(f'[[requirement]]\nname = "{k}"\nformula = "{f}"\n' for k, f in FIVE.items())
    )
    db = tmp_path / "c.db"
    done = run_cli("campaign", str(spec), "--db", str(db), "--reruns", "2")
    assert done.returncode == 0, done.stderr
    with sqlite3.connect(db) as c:
        rows = c.execute(
            "SELECT name, count(*), sum(violated) FROM requirement_verdicts GROUP BY name"
        ).fetchall()
    assert {r[0] for r in rows} == set(FIVE)
    assert all(r[1] == 12 for r in rows)
    violated = {r[0] for r in rows if r[2]}
    assert "reach_goal" in violated  # 25 s is too short for most routes
    listed = json.loads(run_cli("failures", str(db), "--format", "json").stdout)
    keys = {f["key"]: f for f in listed}
    for name in violated:
        f = keys[f"requirement:{name}"]
        robustness = {r[0]: r[1] for r in sqlite3.connect(db).execute(
            "SELECT run_id, robustness FROM requirement_verdicts WHERE name = ? AND violated",
            (name,),
        )}  # fmt: skip
        # Its runs, worst robustness first; its worst run measured in perturbed copies.
        assert f["run_ids"] == sorted(robustness, key=lambda r: (robustness[r], r))
        assert f["robustness"] != "unmeasured"


@pytest.mark.parametrize(
    ("requirement", "message"),
    [
        ('name = "collision"\nformula = "speed < 1"', "one of sitgen's own classes"),
        ('name = "a"\nformula = "always (speed <)"', "run.requirement[0].formula: column 16"),
        ('name = "a"\nformula = "speed < 1"\ncolour = "red"', "requirement[0].colour: unknown"),
        ('name = "a b"\nformula = "speed < 1"', "is not a requirement name"),
    ],
)
def test_a_bad_requirement_stops_a_campaign_before_any_run(
    tmp_path: Path, requirement: str, message: str
) -> None:
    spec = tmp_path / "campaign.toml"
    spec.write_text(
        f'n = 3\n[situation.terrain]\npreset = "open_field"\n[[requirement]]\n{requirement}\n'
    )
    db = tmp_path / "c.db"
    done = run_cli("campaign", str(spec), "--db", str(db), "--reruns", "0")
    assert done.returncode != 0
    assert message in done.stderr
    assert len(done.stderr.strip().splitlines()) == 1, done.stderr
    assert (
        not db.exists()
        or not sqlite3.connect(db)
        .execute("SELECT count(*) FROM sqlite_master WHERE name = 'runs'")
        .fetchone()[0]
        or not sqlite3.connect(db).execute("SELECT count(*) FROM runs").fetchone()[0]
    )


def test_require_needs_a_name_and_a_formula(situation_file: Path) -> None:
    done = run_cli("run", str(situation_file), "--require", "always speed < 1")
    assert done.returncode != 0
    assert "--require: `always speed < 1` is not NAME: FORMULA" in done.stderr


def test_every_command_of_the_guide_runs_as_written(tmp_path: Path) -> None:
    """docs/requirements.md's ``sh`` blocks, in order, from a folder that sees the examples as
    the repository root does; and what it says the campaign found."""
    (tmp_path / "examples").symlink_to(ROOT / "examples")
    bin_dir = Path(sys.executable).parent
    commands = [argv for argv, _ in guide_commands(ROOT / "docs" / "requirements.md")]
    assert {c[1] for c in commands} >= {"run", "campaign", "failures", "shrink", "search"}
    for argv in commands:
        done = subprocess.run(
            [str(bin_dir / "sitgen"), *argv[1:]],
            cwd=tmp_path, capture_output=True, text=True, timeout=600, check=False,
        )  # fmt: skip
        assert done.returncode == 0, f"{shlex.join(argv)}\n{done.stdout}\n{done.stderr}"
        if argv[1] == "run" and "--requirements" in argv:
            assert "requirement reach_goal_in_time: VIOLATED, robustness -37.04" in done.stdout
    with sqlite3.connect(tmp_path / "pioneer.db") as c:
        worst = c.execute(
            "SELECT run_id, robustness, first_violation_s FROM requirement_verdicts "
            "WHERE name = 'slow_near_peers' AND violated ORDER BY robustness"
        ).fetchone()
        assert worst[0] == 2 and worst[2] == 71.6
        assert round(worst[1], 2) == -0.15
        copies = c.execute(
            "SELECT copies FROM requirement_robustness WHERE name = 'slow_near_peers'"
        ).fetchone()
        assert json.loads(copies[0]) == ["violated", "violated"]


@pytest.fixture(scope="module")
def pioneer_db(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The guide's campaign: 40 runs of paper120.toml judged by the Pioneer's requirements."""
    db = tmp_path_factory.mktemp("pioneer") / "pioneer.db"
    done = run_cli(
        "campaign", str(ROOT / "examples" / "campaigns" / "paper120.toml"), "--n", "40",
        "--reruns", "0", "--db", str(db),
        "--requirements", str(ROOT / "examples" / "requirements" / "pioneer.toml"),
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    return db


def test_shrink_keeps_a_requirement_violated(pioneer_db: Path, tmp_path: Path) -> None:
    out = tmp_path / "min.json"
    done = run_cli(
        "shrink", str(pioneer_db), "2", "--requirement", "slow_near_peers", "-o", str(out)
    )
    assert done.returncode == 0, done.stderr
    seed = done.stdout.split("--seed ")[-1].split()[0]
    again = run_cli("run", str(out), "--spec", str(tmp_path / "min.run.json"), "--seed", seed)
    assert "requirement slow_near_peers: VIOLATED" in again.stdout
    minimal = json.loads(out.read_text())
    assert len(minimal["robots"]) < 5
    # A run that does not violate it is refused in one line.
    done = run_cli("shrink", str(pioneer_db), "0", "--requirement", "slow_near_peers")
    assert done.returncode == 2
    assert "--requirement: the run does not violate slow_near_peers" in done.stderr


def test_search_falsifies_a_requirement_by_its_robustness(tmp_path: Path) -> None:
    req = tmp_path / "r.toml"
    req.write_text(
        '[[requirement]]\nname = "turn_near_walls"\n'
        'formula = "always (obstacle_clearance < 0.15 implies abs(turn_rate) < 1.0)"\n'
    )
    spec = str(ROOT / "examples" / "campaigns" / "paper120.toml")
    db = tmp_path / "s.db"
    done = run_cli(
        "search", spec, "--budget", "40", "--db", str(db), "--requirements", str(req),
        "--requirement", "turn_near_walls", "--reruns", "0",
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    with sqlite3.connect(db) as c:
        plan = json.loads(c.execute("SELECT plan FROM search").fetchone()[0])
        judged = c.execute("SELECT count(*) FROM requirement_verdicts").fetchone()[0]
    assert plan["requirement"] == "turn_near_walls"
    assert judged == 40
    done = run_cli("search", spec, "--budget", "4", "--db", str(tmp_path / "x.db"),
                   "--requirement", "nope")  # fmt: skip
    assert done.returncode == 2
    assert "--requirement: no requirement called 'nope'" in done.stderr


def test_diff_judges_each_requirement_and_fails_on_a_robust_new_violation(
    tmp_path: Path,
) -> None:
    """B drives faster than A may: a requirement A never violates is robustly violated by B,
    a new failure of class requirement:NAME, its own JUnit case, and diff exits 1."""
    junit = tmp_path / "diff.xml"
    done = run_cli(
        "diff", "--n", "3", "--seed", "1", "--db", str(tmp_path / "d.db"), "--format", "json",
        "--a", "snd_follow", "--a-param", "max_speed=0.4", "--b", "snd_follow",
        "--time-limit", "60", "--require", "slow: always (abs(speed) <= 0.45)",
        "--junit", str(junit),
    )  # fmt: skip
    assert done.returncode == 1, done.stderr
    report = json.loads(done.stdout)
    mine = [c for c in report["classes"] if c["class"] == "requirement:slow"]
    assert mine and mine[0]["new"], report["classes"]
    assert report["robust_new"] >= 1
    xml = junit.read_text()
    assert "requirement:slow" in xml


def test_campaign_junit_has_a_case_per_requirement(tmp_path: Path) -> None:
    junit = tmp_path / "c.xml"
    done = run_cli(
        "campaign", str(ROOT / "examples" / "campaigns" / "paper120.toml"), "--n", "12",
        "--reruns", "0", "--db", str(tmp_path / "c.db"), "--junit", str(junit),
        "--require", "keep_away: always (peer_clearance > 0.3)",
        "--require", "never_fast: always (abs(speed) <= 5)",
    )  # fmt: skip
    assert done.returncode in (0, 1), done.stderr
    suite = ElementTree.parse(junit).getroot()[0]
    cases = {c.get("name"): c for c in suite.iter("testcase")}
    assert cases["never_fast"].find("failure") is None
    assert "least robustness" in (cases["never_fast"].findtext("system-out") or "")
    keep = cases["keep_away"].find("failure")
    assert keep is not None and keep.get("type") == "requirement:keep_away"
    assert "violated in" in (keep.get("message") or "")


def test_export_writes_every_judged_runs_signals_and_they_give_the_stored_verdicts(
    pioneer_db: Path, tmp_path: Path
) -> None:
    pq = pytest.importorskip("pyarrow.parquet", reason="pyarrow is in the test extra")
    out = tmp_path / "tables"
    done = run_cli("export", str(pioneer_db), "-o", str(out), "--format", "parquet")
    assert done.returncode == 0, done.stderr
    signals = pq.read_table(out / "signals.parquet").to_pydict()
    verdicts = pq.read_table(out / "requirement_verdicts.parquet").to_pylist()
    with sqlite3.connect(pioneer_db) as c:
        steps = dict(c.execute("SELECT id, steps FROM runs").fetchall())
    assert len(signals["run_id"]) == sum(s + 1 for s in steps.values())
    assert set(signals) >= {"run_id", "step", "time_s", *_core.requirement_signals()}
    runs = np.asarray(signals["run_id"])
    # An outside tool (rtamt) gives each stored verdict from the exported signals alone.
    for v in verdicts[::7]:
        mine = runs == v["run_id"]
        used = {
            s: np.asarray(signals[s])[mine].tolist()
            for s in _core.requirement_signals()
            if s in v["formula"]
        }
        assert same(v["robustness"], oracle(v["formula"], used)[0]), v


def test_a_run_page_plots_each_requirements_signals_and_marks_the_violation(
    pioneer_db: Path, tmp_path: Path, browser: Any
) -> None:
    out = tmp_path / "report"
    done = run_cli("report", str(pioneer_db), "-o", str(out))
    assert done.returncode == 0, done.stderr
    page, errors = open_page(browser, out / "run-2.html")
    plots = page.eval_on_selector_all(
        "svg.requirement", "ss => ss.map(s => [s.dataset.requirement, s.getBBox().width])"
    )
    assert {name for name, _ in plots} == {
        "slow_near_peers",
        "brake_for_peers",
        "reach_goal_in_time",
    }
    assert all(width > 0 for _, width in plots)
    slow = "svg[data-requirement='slow_near_peers']"
    assert page.eval_on_selector_all(f"{slow} polyline.signal", "ls => ls.length") >= 2
    assert page.eval_on_selector_all(f"{slow} line.threshold", "ls => ls.length") == 2
    shaded = page.eval_on_selector(f"{slow} rect.violating", "r => r.getBBox().width")
    assert shaded > 0
    assert "violated" in page.inner_text("#requirement-slow_near_peers + p")
    assert errors == []


def test_a_run_that_ended_early_decides_eventually_over_what_was_recorded(
    situation: sitgen.Situation,
) -> None:
    """The documented value: a run stopped at its 5 s time limit short of its goal violates
    `eventually goal_distance < 0.5`, decided over the whole recorded run."""
    rec = sitgen.run(
        situation, time_limit=5,
        spec={"requirement": [{"name": "goal", "formula": "eventually (goal_distance < 0.5)"}]},
    )  # fmt: skip
    (v,) = rec.requirements
    assert v["violated"] and v["first_violation_s"] == 5.0
    assert v["interval_s"] == [0.0, 5.0]
    assert same(v["robustness"], 0.5 - float(rec.signals["goal_distance"].min()))


def test_a_signal_without_a_subject_reads_infinity_and_its_verdict_says_so() -> None:
    alone = sitgen.generate_situation(
        {"terrain": {"preset": "open_field"}, "mission": {"peers_min": 0, "peers_max": 0}}, seed=2
    )
    spec = {"requirement": [{"name": "apart", "formula": "always (peer_distance > 1)"}]}
    rec = sitgen.run(alone, time_limit=5, spec=spec)
    assert rec.requirements[0]["robustness"] == float("inf")
    assert not rec.requirements[0]["violated"]
    assert rec.to_dict()["requirements"][0]["robustness"] == "inf"  # JSON has no infinity
    assert (rec.signals["peer_distance"] == float("inf")).all()


@pytest.mark.parametrize("cls", ["Costs3ms", "StartsAThread", "StartsAChild"])
def test_a_users_class_is_judged_by_requirements_as_the_built_ins_are(
    cls: str, tmp_path: Path
) -> None:
    """A class run in the campaign's worker processes (costing milliseconds, starting a thread
    or a child) has its verdicts stored and its violation copied, like a built-in's."""
    db = tmp_path / "u.db"
    done = run_cli(
        "campaign", str(ROOT / "examples" / "campaigns" / "paper120.toml"), "--n", "3",
        "--db", str(db), "--reruns", "2", "--time-limit", "8",
        "--controller", f"python:tests.controllers.careless:{cls}",
        "--require", "never_moves: always (abs(speed) <= 0.01)",
        cwd=ROOT,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    with sqlite3.connect(db) as c:
        verdicts = c.execute("SELECT violated FROM requirement_verdicts").fetchall()
        copies = c.execute("SELECT reruns FROM requirement_robustness").fetchall()
    assert len(verdicts) == 3 and all(v for (v,) in verdicts)
    assert copies == [(2,)]

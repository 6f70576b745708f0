"""Requirements in STL: the core's robustness equals rtamt's offline discrete-time monitor's
(the oracle) on random formulas and traces, and on formulas whose reading depends on rtamt's
precedence; a run's verdicts and signals come back with its record."""

from __future__ import annotations

import math
import warnings
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from sitgen import _core

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
    sub = lambda: draw(formula(depth + 1))  # noqa: E731
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
        ("always (speed < )", "formula: column 17: expected a signal, a number, '(' or an operator"),
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

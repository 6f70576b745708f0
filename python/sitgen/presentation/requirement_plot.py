"""A run's requirements on its page: for each requirement the run was judged by, its verdict
and a picture — every signal the formula reads over the run, the thresholds the formula
compares it with as dashed lines, and the interval that decided a violation shaded, from the
first violation on (docs/requirements.md). The signals are not stored: the run is made again
(it is deterministic) with every signal in its record."""

from __future__ import annotations

import html
import math
import re
from typing import Any

import numpy as np
import numpy.typing as npt

from sitgen import _core
from sitgen.presentation.page import time_axis
from sitgen.store import Store
from sitgen.triage.recall import resimulate

WIDTH, LANE, LEFT = 900, 70, 130
"""The plot's width, a signal's lane height and the label margin, pixels."""

COMPARED = re.compile(r"([A-Za-z_]\w*)\s*\)?\s*(<=|>=|<|>|==)\s*(-?\d+(?:\.\d*)?(?:e-?\d+)?)")
"""``signal OP number`` in a formula (also ``abs(signal) OP number``): where to draw a
threshold on the signal's lane."""


def thresholds(formula: str, names: list[str]) -> dict[str, list[float]]:
    """The numbers each signal is compared with in ``formula``, by signal."""
    out: dict[str, list[float]] = {}
    for name, _, number in COMPARED.findall(formula):
        if name in names:
            out.setdefault(name, []).append(float(number))
    return out


def requirements_section(store: Store, row: dict[str, Any]) -> str:
    """The run page's requirements: a heading, then a verdict line and a plot a requirement;
    '' for a run judged by none."""
    verdicts = store.requirement_verdicts(run_id=row["id"])
    if not verdicts:
        return ""
    _, record = resimulate(row, signals=True)
    dt_s = float(row["run_spec"].get("sim", {}).get("dt_s", 0.1))
    names = _core.requirement_signals()
    parts = ["<h2>Requirements</h2>"]
    for v in sorted(verdicts, key=lambda v: v["name"]):
        rho = v["robustness"]
        if rho is None:
            said = f"no verdict: {html.escape(v['error'] or '')}"
        elif v["violated"]:
            said = (
                f"<b class='violated'>violated</b>, robustness {rho:.4g}, from "
                f"{v['first_violation_s']:.1f} s (decided over {v['interval_start_s']:.1f}–"
                f"{v['interval_end_s']:.1f} s)"
            )
        else:
            said = f"satisfied, robustness {rho:.4g}"
        parts.append(
            f"<h3 id='requirement-{html.escape(v['name'])}'>{html.escape(v['name'])}</h3>"
            f"<p><code>{html.escape(v['formula'])}</code>: {said}</p>"
        )
        read = [n for n in names if re.search(rf"\b{n}\b", v["formula"])]
        parts.append(_plot(v, {n: record.signals[n] for n in read}, dt_s))
    return "".join(parts)


def _plot(v: dict[str, Any], signals: dict[str, npt.NDArray[np.float64]], dt_s: float) -> str:
    """One lane a signal: its values over time as a line, its thresholds dashed, the
    deciding interval of a violation shaded red and the first violation a red line."""
    height = LANE * max(1, len(signals)) + 24
    n = max((len(s) for s in signals.values()), default=1)
    span = max((n - 1) * dt_s, 1e-9)
    scale = (WIDTH - LEFT - 10) / span
    name = html.escape(v["name"])
    parts = [
        f"<svg class='requirement' data-requirement='{name}' width='{WIDTH}' height='{height}' "
        f"role='img'><title>{name} over the run</title>"
    ]
    if v["violated"] and v["interval_start_s"] is not None:
        x0 = LEFT + v["interval_start_s"] * scale
        x1 = LEFT + max(v["interval_end_s"], v["interval_start_s"]) * scale
        parts.append(
            f"<rect class='violating' x='{x0:.1f}' y='0' width='{max(2.0, x1 - x0):.1f}' "
            f"height='{height - 24}' fill='#d62728' opacity='0.18'><title>decided the "
            f"violation: {v['interval_start_s']:.1f}–{v['interval_end_s']:.1f} s</title></rect>"
        )
        xf = LEFT + v["first_violation_s"] * scale
        parts.append(
            f"<line class='first-violation' x1='{xf:.1f}' y1='0' x2='{xf:.1f}' "
            f"y2='{height - 24}' stroke='#d62728' stroke-width='1.5'/>"
        )
    limits = thresholds(v["formula"], list(signals))
    for j, (signal, values) in enumerate(signals.items()):
        parts += _lane(j * LANE, signal, values, limits.get(signal, []), scale, dt_s)
    parts += time_axis(LEFT, WIDTH - 10, height - 18, span, scale)
    parts.append("</svg>")
    return "".join(parts)


def _lane(
    top: float,
    signal: str,
    values: npt.NDArray[np.float64],
    limits: list[float],
    scale: float,
    dt_s: float,
) -> list[str]:
    """A signal's lane: label, line (infinite values, a signal without a subject, left out)
    and its thresholds."""
    finite = values[np.isfinite(values)]
    lo = min([*finite.tolist(), *limits], default=0.0)
    hi = max([*finite.tolist(), *limits], default=1.0)
    if hi - lo < 1e-9:
        lo, hi = lo - 0.5, hi + 0.5
    inner = LANE - 16

    def y(value: float) -> float:
        return top + 6 + inner * (hi - value) / (hi - lo)

    parts = [
        f"<text x='0' y='{top + LANE / 2:.0f}' font-size='12'>{signal}</text>",
        f"<text x='{LEFT - 4}' y='{y(hi) + 4:.0f}' font-size='9' text-anchor='end'>{hi:.3g}</text>",
        f"<text x='{LEFT - 4}' y='{y(lo):.0f}' font-size='9' text-anchor='end'>{lo:.3g}</text>",
    ]
    # One point a pixel at most: the slowest page stays light.
    stride = max(1, math.ceil(len(values) / (WIDTH - LEFT)))
    runs: list[list[str]] = [[]]
    for k in range(0, len(values), stride):
        if not math.isfinite(values[k]):
            runs.append([])
            continue
        runs[-1].append(f"{LEFT + k * dt_s * scale:.1f},{y(float(values[k])):.1f}")
    for points in (r for r in runs if len(r) > 1):
        parts.append(
            f"<polyline class='signal' data-signal='{signal}' points='{' '.join(points)}' "
            "fill='none' stroke='#1f77b4' stroke-width='1.2'/>"
        )
    for limit in limits:
        parts.append(
            f"<line class='threshold' x1='{LEFT}' y1='{y(limit):.1f}' x2='{WIDTH - 10}' "
            f"y2='{y(limit):.1f}' stroke='#444' stroke-dasharray='4 3'>"
            f"<title>{signal} compared with {limit:g}</title></line>"
        )
    return parts

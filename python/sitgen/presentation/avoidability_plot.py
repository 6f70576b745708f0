"""A run page's *Avoidability* section: whether its collision with a robot could have been
escaped (docs/avoidability.md), in words, and a plan of the encounter — the walls near it,
the agent's path as driven (red) and the witness's escape (green, dashed) from the moment
the search started, the robot it hit (blue), and the point of contact."""

from __future__ import annotations

import html
from typing import Any

import numpy as np
import numpy.typing as npt

from sitgen.triage.avoidability import WORDS, describe
from sitgen.world.situation import Situation

SIZE_PX = 420
MARGIN_M = 1.0


def avoidability_section(
    judged: dict[str, Any] | None,
    situation: Situation,
    trajectory: npt.NDArray[np.float32],
    dt_s: float,
) -> str:
    """The section for a run's stored judgement (empty if it was never judged)."""
    if judged is None:
        return ""
    head = "<h2>Avoidability</h2>"
    if judged.get("error"):
        return head + f"<p id='avoidability'>{html.escape(describe(judged))}</p>"
    verdict = judged["verdict"]
    # describe() opens with the verdict's words: those are set in bold.
    rest = describe(judged)[len(WORDS[verdict]) :]
    words = (
        f"<p id='avoidability' data-verdict='{verdict}'><b>{WORDS[verdict]}</b>"
        f"{html.escape(rest)}.</p>"
    )
    meaning = {
        "avoidable": "An escape existed from the moment the agent's laser first saw the robot "
        "it hit: the collision is the controller's doing.",
        "unavoidable_with_this_sensor": "No escape existed from the moment the agent's laser "
        "saw the robot (or it never saw it before contact); one did for an agent that knew "
        "every peer's path from the start: a sensor that saw further, wider or round "
        "obstacles might have saved it.",
        "unavoidable": "No manoeuvre tried escapes, even from the start.",
    }[verdict]
    figure = _plan(judged, situation, trajectory, dt_s)
    return head + words + f"<p>{meaning}</p>" + figure


def _plan(
    judged: dict[str, Any],
    situation: Situation,
    trajectory: npt.NDArray[np.float32],
    dt_s: float,
) -> str:
    """An SVG plan of the encounter."""
    n = len(situation.robots)
    poses = np.asarray(trajectory, dtype=float).reshape(-1, n, 3)
    witness = judged.get("witness")
    start_s = witness["from_s"] if witness else max(0.0, judged["collision_s"] - 10.0)
    first = min(len(poses) - 1, round(start_s / dt_s))
    last = min(len(poses) - 1, round(judged["collision_s"] / dt_s))
    agent = poses[first : last + 1, 0, :2]
    hit = poses[first : last + 1, judged["robot"], :2]
    escape = np.asarray([p[:2] for p in witness["path"]]) if witness else np.empty((0, 2))
    points = np.vstack([agent, hit, escape])
    lo, hi = points.min(axis=0) - MARGIN_M, points.max(axis=0) + MARGIN_M
    span = float(max(hi - lo))
    scale = SIZE_PX / span if span > 0 else 1.0

    def xy(p: Any) -> str:
        return f"{(p[0] - lo[0]) * scale:.1f},{(hi[1] - p[1]) * scale:.1f}"

    width, height = (hi - lo) * scale
    parts = [
        f"<svg id='avoidability-plan' width='{width:.0f}' height='{height:.0f}' role='img' "
        "style='border:1px solid #ccc'>"
    ]
    parts += _walls(situation, lo, hi, scale)
    for path, colour, dash, name in (
        (hit, "#1e50c8", "", "robot hit"),
        (agent, "#c81e1e", "", "agent as driven"),
        (escape, "#1a8a2a", " stroke-dasharray='6 4'", "escape"),
    ):
        if len(path) > 1:
            parts.append(
                f"<polyline class='{name.split()[0]}' points='{' '.join(xy(p) for p in path)}' "
                f"fill='none' stroke='{colour}' stroke-width='2'{dash}><title>{name}</title>"
                "</polyline>"
            )
    if len(agent):
        cx, cy = xy(agent[-1]).split(",")
        parts.append(
            f"<circle cx='{cx}' cy='{cy}' r='6' fill='none' stroke='black'>"
            f"<title>contact at {judged['collision_s']:.1f} s</title></circle>"
        )
    parts.append("</svg>")
    return (
        "".join(parts) + "<p>Red: the agent as it drove from "
        f"{start_s:.1f} s to contact (circled); green, dashed: the escape; blue: the robot it hit."
        "</p>"
    )


def _walls(situation: Situation, lo: Any, hi: Any, scale: float) -> list[str]:
    """The occupied cells inside the plan, a rectangle per run of cells along a row."""
    grid = situation.grid
    res = grid.resolution
    rows, cols = grid.occupied.shape
    c0, c1 = max(0, int(lo[0] / res)), min(cols, int(np.ceil(hi[0] / res)))
    r0, r1 = max(0, rows - int(np.ceil(hi[1] / res))), min(rows, rows - int(lo[1] / res))
    out = []
    for r in range(r0, r1):
        line = grid.occupied[r, c0:c1]
        edges = np.flatnonzero(np.diff(np.concatenate([[0], line.astype(np.int8), [0]])))
        y = (hi[1] - (rows - r) * res) * scale
        for a, b in zip(edges[::2], edges[1::2], strict=True):
            x = ((c0 + a) * res - lo[0]) * scale
            out.append(
                f"<rect x='{x:.1f}' y='{y:.1f}' width='{(b - a) * res * scale:.1f}' "
                f"height='{res * scale:.1f}' fill='#555'/>"
            )
    return out

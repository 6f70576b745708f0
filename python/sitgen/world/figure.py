"""Situation figures in the style of Arnold & Alexander (2013), figures 3–5.

The map (obstacles dark), every robot's route as a line, starts as squares and goals (route
ends) as circles, the agent's filled and the peers' hollow, intermediate waypoints as dots, and
a scale bar. With a run, also the path each robot drove and a marker where each of the agent's
scored events began (collision ✕, unsafe proximity ○, loitering ◇, timeout ■). Drawn with
Pillow, so figures are made headless and byte-for-byte reproducible.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
from PIL import Image, ImageDraw, ImageFont

from sitgen.world.situation import Situation

TARGET_PX = 900
"""Length of the longer side of the figure's map area, pixels (before the margin)."""
MARGIN_PX = 40
AGENT = (200, 30, 30)
PEER = (30, 80, 200)
ROUTE = (20, 150, 40)
OBSTACLE = (60, 60, 60)
FREE = (250, 250, 250)
AGENT_PATH = (240, 120, 120)
PEER_PATH = (120, 160, 240)
EVENT_COLOURS = {
    "collision": (220, 0, 0),
    "unsafe_proximity": (240, 140, 0),
    "loitering": (140, 0, 160),
    "timeout": (0, 0, 0),
}


def _scale_bar_length(width_m: float) -> float:
    """A round length near a fifth of the map width: 1, 2 or 5 times a power of ten metres."""
    goal = width_m / 5
    power = 10 ** np.floor(np.log10(goal))
    return float(max(f * power for f in (1, 2, 5) if f * power <= goal))


def draw_situation(
    situation: Situation,
    trajectory: npt.NDArray[Any] | None = None,
    events: Sequence[dict[str, Any]] = (),
    dt_s: float = 0.1,
) -> Image.Image:
    """The figure as a Pillow image; with a run's ``trajectory`` (steps + 1, robots, 3; one row
    per ``dt_s``) and ``events``, also the driven paths and the agent's scored events."""
    grid = situation.grid
    rows, cols = grid.occupied.shape
    scale = max(1, TARGET_PX // max(rows, cols))
    px_per_m = scale / grid.resolution
    height_m = rows * grid.resolution
    pixels = np.where(grid.occupied[..., None], OBSTACLE, FREE).astype(np.uint8)
    base = Image.fromarray(pixels, "RGB").resize(
        (cols * scale, rows * scale), Image.Resampling.NEAREST
    )
    figure = Image.new("RGB", (base.width + 2 * MARGIN_PX, base.height + 2 * MARGIN_PX), "white")
    figure.paste(base, (MARGIN_PX, MARGIN_PX))
    draw = ImageDraw.Draw(figure)

    def to_px(x: float, y: float) -> tuple[float, float]:
        return MARGIN_PX + x * px_per_m, MARGIN_PX + (height_m - y) * px_per_m

    if trajectory is not None:
        for i in reversed(range(trajectory.shape[1])):
            path = [to_px(float(x), float(y)) for x, y in trajectory[:, i, :2]]
            draw.line(path, fill=AGENT_PATH if i == 0 else PEER_PATH, width=2)
        for e in events:
            colour = EVENT_COLOURS.get(e["kind"])
            if colour is None or not e["scored"]:
                continue
            step = min(round(e["start_s"] / dt_s), len(trajectory) - 1)
            x, y = to_px(*(float(v) for v in trajectory[step, e["robot"], :2]))
            _marker(draw, e["kind"], x, y, colour)

    for robot in reversed(situation.robots):  # the agent last, on top
        colour = AGENT if robot.role == "agent" else PEER
        route = [to_px(robot.start.x_m, robot.start.y_m)] + [
            to_px(x, y) for x, y in robot.waypoints
        ]
        draw.line(route, fill=ROUTE, width=3 if robot.role == "agent" else 2)
        for x, y in route[1:-1]:
            draw.ellipse((x - 3, y - 3, x + 3, y + 3), fill=ROUTE)
        fill = colour if robot.role == "agent" else None
        r = max(6.0, robot.body["length_m"] * px_per_m / 2)
        sx, sy = route[0]
        draw.rectangle((sx - r, sy - r, sx + r, sy + r), outline=colour, fill=fill, width=3)
        gx, gy = route[-1]
        draw.ellipse((gx - r, gy - r, gx + r, gy + r), outline=colour, fill=fill, width=3)
        draw.text(
            (sx + r + 3, sy - r - 3), str(robot.id), fill=colour, font=ImageFont.load_default()
        )

    bar_m = _scale_bar_length(cols * grid.resolution)
    x0, y0 = MARGIN_PX, figure.height - MARGIN_PX / 2
    draw.line((x0, y0, x0 + bar_m * px_per_m, y0), fill="black", width=4)
    draw.text((x0 + bar_m * px_per_m + 8, y0 - 7), f"{bar_m:g} m", fill="black")
    draw.text(
        (MARGIN_PX, 10),
        f"seed {situation.seed}  {situation.content_hash[:19]}  agent filled, peers hollow;"
        " squares start, circles goal",
        fill="black",
    )
    return figure


def _marker(draw: ImageDraw.ImageDraw, kind: str, x: float, y: float, colour: Any) -> None:
    r = 7
    if kind == "collision":
        draw.line((x - r, y - r, x + r, y + r), fill=colour, width=3)
        draw.line((x - r, y + r, x + r, y - r), fill=colour, width=3)
    elif kind == "unsafe_proximity":
        draw.ellipse((x - r, y - r, x + r, y + r), outline=colour, width=2)
    elif kind == "loitering":
        draw.polygon([(x, y - r), (x + r, y), (x, y + r), (x - r, y)], outline=colour, width=2)
    else:
        draw.rectangle((x - r / 2, y - r / 2, x + r / 2, y + r / 2), fill=colour)


def save_situation_figure(
    situation: Situation,
    path: str | Path,
    trajectory: npt.NDArray[Any] | None = None,
    events: Sequence[dict[str, Any]] = (),
    dt_s: float = 0.1,
) -> None:
    """Write the figure as PNG (with a run's trajectory and events, if given)."""
    draw_situation(situation, trajectory, events, dt_s).save(Path(path), format="PNG")

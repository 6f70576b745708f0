//! # `rooms` source
//!
//! **What it makes.** An occupancy grid laid out by binary space partitioning: the map is
//! split recursively, across its longer side at a random position, until every part is at
//! most `max_size_m` across (parts between 2 × `min_size_m` and `max_size_m` split with
//! probability ½). Then, by `layout`:
//! - `rooms`: an indoor floor plan. Every split line becomes a wall `wall_m` thick with one
//!   door `door_m` wide at a random place along it, and the map is walled round. Doors join
//!   the two halves of every split, so every room is reachable from every other.
//! - `blocks`: a city. Every part becomes a building (occupied), set back `street_m` / 2 from
//!   its edges, so streets `street_m` wide run between all buildings and round the map.
//!
//! **Why.** The paper's urban and indoor environments: straight walls, right angles, doors and
//! corridors that hide what is round the corner, where robots meet each other at junctions.
//!
//! **Parameters.**
//! - `layout` (`rooms` or `blocks`, default `rooms`).
//! - `min_size_m` (metres, default 3.0, in (0, 1000]): smallest room or block side.
//! - `max_size_m` (metres, default 10.0, in [2 × `min_size_m`, 10000]): largest side.
//! - `wall_m` (metres, default 0.2, in (0, 10]): wall thickness (`rooms`).
//! - `door_m` (metres, default 1.2, in (0, 100]): door width (`rooms`).
//! - `street_m` (metres, default 4.0, in (0, 100]): street width (`blocks`).
//!
//! **Source.** Binary space partitioning for level layout (Shaker, Togelius & Nelson,
//! *Procedural Content Generation in Games*, 2016, ch. 3).

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::error::{join, SpecError};
use crate::grid::OccupancyGrid;
use crate::rng::ChoiceSource;
use crate::terrain::{Extent, Layer, LayerKind, Source};

/// How the partition is drawn.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum RoomsLayout {
    /// Walls with doors between rooms.
    #[default]
    Rooms,
    /// Buildings between streets.
    Blocks,
}

/// Parameters of the `rooms` source.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Rooms {
    /// `rooms` (walls and doors) or `blocks` (buildings and streets). Default `rooms`.
    #[serde(default)]
    pub layout: RoomsLayout,
    /// Smallest room or block side, metres, in (0, 1000]. Default 3.0.
    #[serde(default = "default_min_size_m")]
    pub min_size_m: f64,
    /// Largest room or block side, metres, at least twice `min_size_m`, at most 10000.
    /// Default 10.0.
    #[serde(default = "default_max_size_m")]
    pub max_size_m: f64,
    /// Wall thickness, metres, in (0, 10]. Default 0.2.
    #[serde(default = "default_wall_m")]
    pub wall_m: f64,
    /// Door width, metres, in (0, 100]. Default 1.2.
    #[serde(default = "default_door_m")]
    pub door_m: f64,
    /// Street width, metres, in (0, 100]. Default 4.0.
    #[serde(default = "default_street_m")]
    pub street_m: f64,
}

fn default_min_size_m() -> f64 {
    3.0
}
fn default_max_size_m() -> f64 {
    10.0
}
fn default_wall_m() -> f64 {
    0.2
}
fn default_door_m() -> f64 {
    1.2
}
fn default_street_m() -> f64 {
    4.0
}

/// An axis-aligned rectangle in metres: x from the left edge, y from the top edge.
#[derive(Debug, Clone, Copy)]
struct Rect {
    x0: f64,
    y0: f64,
    x1: f64,
    y1: f64,
}

impl Source for Rooms {
    fn output(&self) -> LayerKind {
        LayerKind::Occupancy
    }

    fn validate(&self, path: &str) -> Result<(), SpecError> {
        SpecError::check_positive(&join(path, "min_size_m"), self.min_size_m, 1000.0)?;
        if !(self.max_size_m >= 2.0 * self.min_size_m && self.max_size_m <= 10_000.0) {
            return Err(SpecError::new(
                join(path, "max_size_m"),
                format!(
                    "{} is not in [{}, 10000] (at least twice min_size_m)",
                    self.max_size_m,
                    2.0 * self.min_size_m
                ),
            ));
        }
        SpecError::check_positive(&join(path, "wall_m"), self.wall_m, 10.0)?;
        SpecError::check_positive(&join(path, "door_m"), self.door_m, 100.0)?;
        SpecError::check_positive(&join(path, "street_m"), self.street_m, 100.0)
    }

    fn generate(&self, extent: Extent, choices: &mut ChoiceSource) -> Result<Layer, String> {
        let res = extent.resolution_m;
        // A wall thinner than a cell could miss every cell centre and leave a gap.
        let this = Rooms {
            wall_m: self.wall_m.max(res),
            ..self.clone()
        };
        let whole = Rect {
            x0: 0.0,
            y0: 0.0,
            x1: extent.cols as f64 * res,
            y1: extent.rows as f64 * res,
        };
        let mut grid = OccupancyGrid::filled(extent.rows, extent.cols, false);
        match self.layout {
            RoomsLayout::Rooms => {
                this.partition(whole, choices, &mut |split, door| {
                    fill_rect(&mut grid, res, split, true);
                    fill_rect(&mut grid, res, door, false);
                });
                let w = this.wall_m;
                for edge in [
                    Rect { x1: w, ..whole },
                    Rect { y1: w, ..whole },
                    Rect {
                        x0: whole.x1 - w,
                        ..whole
                    },
                    Rect {
                        y0: whole.y1 - w,
                        ..whole
                    },
                ] {
                    fill_rect(&mut grid, res, edge, true);
                }
            }
            RoomsLayout::Blocks => {
                let half = this.street_m / 2.0;
                for part in this.leaves(whole, choices) {
                    let building = Rect {
                        x0: part.x0 + half,
                        y0: part.y0 + half,
                        x1: part.x1 - half,
                        y1: part.y1 - half,
                    };
                    fill_rect(&mut grid, res, building, true);
                }
            }
        }
        Ok(Layer::Occupancy(grid))
    }
}

impl Rooms {
    /// Whether a part of side `long` (its longer side) is split, and where along it.
    fn split_at(&self, long: f64, choices: &mut ChoiceSource) -> Option<f64> {
        let min = self.min_size_m;
        let must = long > self.max_size_m;
        let may = long >= 2.0 * min;
        if must || (may && choices.chance(0.5)) {
            Some(choices.uniform(min, long - min))
        } else {
            None
        }
    }

    /// The parts of the partition, depth first.
    fn leaves(&self, whole: Rect, choices: &mut ChoiceSource) -> Vec<Rect> {
        let mut out = Vec::new();
        let mut stack = vec![whole];
        while let Some(part) = stack.pop() {
            match self.split(part, choices) {
                Some((a, b, _)) => {
                    stack.push(b);
                    stack.push(a);
                }
                None => out.push(part),
            }
        }
        out
    }

    /// Split the partition, calling `on_split(wall, door)` for every split line.
    fn partition(
        &self,
        whole: Rect,
        choices: &mut ChoiceSource,
        on_split: &mut dyn FnMut(Rect, Rect),
    ) {
        let mut stack = vec![whole];
        while let Some(part) = stack.pop() {
            if let Some((a, b, wall)) = self.split(part, choices) {
                on_split(wall, self.door_in(wall, choices));
                stack.push(b);
                stack.push(a);
            }
        }
    }

    /// Split `part` across its longer side: the two halves and the wall between them.
    fn split(&self, part: Rect, choices: &mut ChoiceSource) -> Option<(Rect, Rect, Rect)> {
        let (w, h) = (part.x1 - part.x0, part.y1 - part.y0);
        let half_wall = self.wall_m / 2.0;
        if w >= h {
            let x = part.x0 + self.split_at(w, choices)?;
            Some((
                Rect { x1: x, ..part },
                Rect { x0: x, ..part },
                Rect {
                    x0: x - half_wall,
                    x1: x + half_wall,
                    ..part
                },
            ))
        } else {
            let y = part.y0 + self.split_at(h, choices)?;
            Some((
                Rect { y1: y, ..part },
                Rect { y0: y, ..part },
                Rect {
                    y0: y - half_wall,
                    y1: y + half_wall,
                    ..part
                },
            ))
        }
    }

    /// A door of `door_m` at a random place along a wall (a thin rectangle), clear of its ends.
    fn door_in(&self, wall: Rect, choices: &mut ChoiceSource) -> Rect {
        let vertical = wall.y1 - wall.y0 > wall.x1 - wall.x0;
        let (lo, hi) = if vertical {
            (wall.y0, wall.y1)
        } else {
            (wall.x0, wall.x1)
        };
        let margin = self.wall_m;
        let span = (hi - lo - 2.0 * margin - self.door_m).max(0.0);
        let start = lo + margin + choices.uniform(0.0, span);
        let end = (start + self.door_m).min(hi);
        if vertical {
            Rect {
                y0: start,
                y1: end,
                ..wall
            }
        } else {
            Rect {
                x0: start,
                x1: end,
                ..wall
            }
        }
    }
}

/// Set every cell whose centre lies inside `rect` (metres from the top-left corner).
fn fill_rect(grid: &mut OccupancyGrid, res: f64, rect: Rect, occupied: bool) {
    let first = |lo: f64| ((lo / res - 0.5).ceil().max(0.0)) as usize;
    let last = |hi: f64, n: usize| (((hi / res - 0.5).floor()) as isize).min(n as isize - 1);
    let (c0, c1) = (first(rect.x0), last(rect.x1, grid.cols));
    let (r0, r1) = (first(rect.y0), last(rect.y1, grid.rows));
    if c1 < c0 as isize || r1 < r0 as isize {
        return;
    }
    for r in r0..=r1 as usize {
        for c in c0..=c1 as usize {
            grid.set(r, c, occupied);
        }
    }
}

//! # `maze` source
//!
//! **What it makes.** An occupancy grid of a maze: a lattice of square cells of pitch
//! `corridor_m` + `wall_m`, joined into a spanning tree by a randomised depth-first search
//! (the "recursive backtracker"), so that there is exactly one way between any two cells; then
//! a fraction `loop_fraction` of the remaining inner walls is knocked through to make loops.
//! Lattice cells are corridors `corridor_m` wide, separated by walls `wall_m` thick; the maze
//! is walled round, and any margin left at the right and bottom edges is solid.
//!
//! **Why.** Long corridors, dead ends, U-turns and blind corners: the worst case for a purely
//! reactive controller, and the paper's `maze` kind of environment.
//!
//! **Parameters.**
//! - `corridor_m` (metres, default 1.5, in (0, 100]): corridor width.
//! - `wall_m` (metres, default 0.3, in (0, 100]): wall thickness (at least one cell drawn).
//! - `loop_fraction` (fraction, default 0.1, in [0, 1]): share of the inner walls left by the
//!   spanning tree that are removed (0 = a perfect maze).
//!
//! **Source.** The recursive backtracker (J. Buck, *Mazes for Programmers*, 2015, ch. 5);
//! braiding by wall removal, ibid. ch. 9.

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::error::{join, SpecError};
use crate::grid::{cells_for, OccupancyGrid};
use crate::rng::ChoiceSource;
use crate::terrain::{Extent, Layer, LayerKind, Source};

/// Parameters of the `maze` source.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Maze {
    /// Corridor width, metres, in (0, 100]. Default 1.5.
    #[serde(default = "default_corridor_m")]
    pub corridor_m: f64,
    /// Wall thickness, metres, in (0, 100]; at least one cell is drawn. Default 0.3.
    #[serde(default = "default_wall_m")]
    pub wall_m: f64,
    /// Share of the inner walls left by the spanning tree that are removed, in [0, 1].
    /// Default 0.1.
    #[serde(default = "default_loop_fraction")]
    pub loop_fraction: f64,
}

fn default_corridor_m() -> f64 {
    1.5
}
fn default_wall_m() -> f64 {
    0.3
}
fn default_loop_fraction() -> f64 {
    0.1
}

/// Which walls of the lattice are open: `east[i]` between cell i and its east neighbour,
/// `south[i]` between cell i and its south neighbour.
struct Walls {
    rows: usize,
    cols: usize,
    east_open: Vec<bool>,
    south_open: Vec<bool>,
}

impl Source for Maze {
    fn output(&self) -> LayerKind {
        LayerKind::Occupancy
    }

    fn validate(&self, path: &str) -> Result<(), SpecError> {
        SpecError::check_positive(&join(path, "corridor_m"), self.corridor_m, 100.0)?;
        SpecError::check_positive(&join(path, "wall_m"), self.wall_m, 100.0)?;
        SpecError::check_in(&join(path, "loop_fraction"), self.loop_fraction, 0.0, 1.0)
    }

    fn generate(&self, extent: Extent, choices: &mut ChoiceSource) -> Result<Layer, String> {
        let res = extent.resolution_m;
        let wall = cells_for(self.wall_m, res, 1);
        let corridor = cells_for(self.corridor_m, res, 1);
        let pitch = wall + corridor;
        let rows = extent.rows.saturating_sub(wall) / pitch;
        let cols = extent.cols.saturating_sub(wall) / pitch;
        if rows == 0 || cols == 0 {
            return Err(format!(
                "the map is too small for one maze cell of {} m plus walls",
                self.corridor_m
            ));
        }
        let mut walls = carve_spanning_tree(rows, cols, choices);
        braid(&mut walls, self.loop_fraction, choices);
        Ok(Layer::Occupancy(draw(&walls, extent, wall, corridor)))
    }
}

/// A spanning tree of the lattice by randomised depth-first search from the top-left cell.
fn carve_spanning_tree(rows: usize, cols: usize, choices: &mut ChoiceSource) -> Walls {
    let mut walls = Walls {
        rows,
        cols,
        east_open: vec![false; rows * cols],
        south_open: vec![false; rows * cols],
    };
    let mut visited = vec![false; rows * cols];
    let mut stack = vec![0usize];
    visited[0] = true;
    while let Some(&cell) = stack.last() {
        let (r, c) = (cell / cols, cell % cols);
        let mut unvisited = Vec::with_capacity(4);
        if r > 0 && !visited[cell - cols] {
            unvisited.push(cell - cols);
        }
        if r + 1 < rows && !visited[cell + cols] {
            unvisited.push(cell + cols);
        }
        if c > 0 && !visited[cell - 1] {
            unvisited.push(cell - 1);
        }
        if c + 1 < cols && !visited[cell + 1] {
            unvisited.push(cell + 1);
        }
        if unvisited.is_empty() {
            stack.pop();
            continue;
        }
        let next = unvisited[choices.index(unvisited.len())];
        walls.open_between(cell, next);
        visited[next] = true;
        stack.push(next);
    }
    walls
}

/// Knock through each remaining inner wall with probability `fraction`.
fn braid(walls: &mut Walls, fraction: f64, choices: &mut ChoiceSource) {
    if fraction <= 0.0 {
        return;
    }
    for cell in 0..walls.rows * walls.cols {
        let (r, c) = (cell / walls.cols, cell % walls.cols);
        if c + 1 < walls.cols && !walls.east_open[cell] && choices.chance(fraction) {
            walls.east_open[cell] = true;
        }
        if r + 1 < walls.rows && !walls.south_open[cell] && choices.chance(fraction) {
            walls.south_open[cell] = true;
        }
    }
}

impl Walls {
    fn open_between(&mut self, a: usize, b: usize) {
        let (lo, hi) = (a.min(b), a.max(b));
        if hi == lo + 1 {
            self.east_open[lo] = true;
        } else {
            self.south_open[lo] = true;
        }
    }
}

/// Rasterise: solid everywhere, then each lattice cell's corridor square and its openings.
fn draw(walls: &Walls, extent: Extent, wall: usize, corridor: usize) -> OccupancyGrid {
    let mut grid = OccupancyGrid::filled(extent.rows, extent.cols, true);
    let pitch = wall + corridor;
    let mut clear = |r0: usize, c0: usize, h: usize, w: usize| {
        for r in r0..r0 + h {
            for c in c0..c0 + w {
                grid.set(r, c, false);
            }
        }
    };
    for cell in 0..walls.rows * walls.cols {
        let (r, c) = (cell / walls.cols, cell % walls.cols);
        let (top, left) = (wall + r * pitch, wall + c * pitch);
        clear(top, left, corridor, corridor);
        if walls.east_open[cell] {
            clear(top, left + corridor, corridor, wall);
        }
        if walls.south_open[cell] {
            clear(top + corridor, left, wall, corridor);
        }
    }
    grid
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_perfect_maze_is_a_spanning_tree() {
        let mut choices = ChoiceSource::stream(3, "terrain");
        let walls = carve_spanning_tree(7, 9, &mut choices);
        let open = walls
            .east_open
            .iter()
            .chain(&walls.south_open)
            .filter(|&&o| o)
            .count();
        assert_eq!(open, 7 * 9 - 1);
    }
}

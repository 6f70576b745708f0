//! # `caves` source
//!
//! **What it makes.** An occupancy grid of caves by cellular automaton, as BARN makes its
//! worlds: a lattice of `cell_m` cells is filled at random with probability `fill`, then
//! smoothed `smooth_passes` times, each pass updating every cell at once: a cell with at
//! least `wall_at_neighbours` occupied neighbours (of 8) becomes occupied, one with at most
//! `free_at_neighbours` becomes free, others keep their state. Neighbours outside the map
//! count as occupied. The lattice is then drawn onto the map's cells (nearest neighbour).
//!
//! **Why.** Irregular, enclosed, winding free space with dead ends and narrow passages: the
//! cave systems of the paper's range of environments, and the BARN benchmark's style.
//!
//! **Parameters.**
//! - `fill` (fraction, default 0.45, in [0, 1]): initial occupied probability.
//! - `smooth_passes` (count, default 4, in [0, 50]): automaton passes.
//! - `wall_at_neighbours` (count, default 5, in [0, 9]): occupied neighbours that make a wall
//!   (9 never does).
//! - `free_at_neighbours` (count, default 3, in [0, 8]): occupied neighbours at or below which
//!   a cell clears. BARN uses 1; 3 gives the classic "4-5 rule" caves.
//! - `cell_m` (metres, default 0.5, in (0, 100]): automaton cell size; at least the map's
//!   resolution in effect.
//!
//! **Source.** Perille, Truong, Xiao & Stone, "Benchmarking Metric Ground Navigation", SSRR
//! 2020 (BARN), and the cave automaton of J. Johnson et al., "Cellular automata for real-time
//! generation of infinite cave levels", PCG workshop 2010.

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::error::{join, SpecError};
use crate::grid::{cells_for, OccupancyGrid};
use crate::rng::ChoiceSource;
use crate::terrain::{Extent, Layer, LayerKind, Source};

/// Parameters of the `caves` source.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Caves {
    /// Initial occupied probability of each automaton cell, in [0, 1]. Default 0.45.
    #[serde(default = "default_fill")]
    pub fill: f64,
    /// Smoothing passes of the automaton, in [0, 50]. Default 4.
    #[serde(default = "default_smooth_passes")]
    pub smooth_passes: u32,
    /// Occupied neighbours (of 8) at or above which a cell becomes occupied, in [0, 9].
    /// Default 5.
    #[serde(default = "default_wall_at")]
    pub wall_at_neighbours: u32,
    /// Occupied neighbours at or below which a cell becomes free, in [0, 8]. Default 3
    /// (BARN uses 1).
    #[serde(default = "default_free_at")]
    pub free_at_neighbours: u32,
    /// Automaton cell size, metres, in (0, 100]. Default 0.5.
    #[serde(default = "default_cell_m")]
    pub cell_m: f64,
}

fn default_fill() -> f64 {
    0.45
}
fn default_smooth_passes() -> u32 {
    4
}
fn default_wall_at() -> u32 {
    5
}
fn default_free_at() -> u32 {
    3
}
fn default_cell_m() -> f64 {
    0.5
}

impl Source for Caves {
    fn output(&self) -> LayerKind {
        LayerKind::Occupancy
    }

    fn validate(&self, path: &str) -> Result<(), SpecError> {
        SpecError::check_in(&join(path, "fill"), self.fill, 0.0, 1.0)?;
        for (name, value, hi) in [
            ("smooth_passes", self.smooth_passes, 50),
            ("wall_at_neighbours", self.wall_at_neighbours, 9),
            ("free_at_neighbours", self.free_at_neighbours, 8),
        ] {
            if value > hi {
                return Err(SpecError::new(
                    join(path, name),
                    format!("{value} is not in [0, {hi}]"),
                ));
            }
        }
        if self.free_at_neighbours >= self.wall_at_neighbours {
            return Err(SpecError::new(
                join(path, "free_at_neighbours"),
                format!(
                    "{} must be below wall_at_neighbours ({})",
                    self.free_at_neighbours, self.wall_at_neighbours
                ),
            ));
        }
        SpecError::check_positive(&join(path, "cell_m"), self.cell_m, 100.0)
    }

    fn generate(&self, extent: Extent, choices: &mut ChoiceSource) -> Result<Layer, String> {
        let cell_m = self.cell_m.max(extent.resolution_m);
        let width_m = extent.cols as f64 * extent.resolution_m;
        let height_m = extent.rows as f64 * extent.resolution_m;
        let lattice = OccupancyGrid {
            rows: cells_for(height_m, cell_m, 1),
            cols: cells_for(width_m, cell_m, 1),
            cells: Vec::new(),
        };
        let mut lattice = random_fill(lattice, self.fill, choices);
        for _ in 0..self.smooth_passes {
            lattice = self.smooth(&lattice);
        }
        Ok(Layer::Occupancy(
            lattice.resample_nearest(extent.rows, extent.cols),
        ))
    }
}

/// Every cell occupied with probability `fill`, one draw per cell in raster order.
fn random_fill(mut lattice: OccupancyGrid, fill: f64, choices: &mut ChoiceSource) -> OccupancyGrid {
    lattice.cells = (0..lattice.rows * lattice.cols)
        .map(|_| choices.chance(fill))
        .collect();
    lattice
}

impl Caves {
    /// One synchronous automaton pass.
    fn smooth(&self, g: &OccupancyGrid) -> OccupancyGrid {
        let mut next = g.clone();
        for r in 0..g.rows {
            for c in 0..g.cols {
                let n = occupied_neighbours(g, r, c);
                if n >= self.wall_at_neighbours {
                    next.set(r, c, true);
                } else if n <= self.free_at_neighbours {
                    next.set(r, c, false);
                }
            }
        }
        next
    }
}

/// Occupied cells among the 8 neighbours of (r, c); outside the map counts as occupied.
fn occupied_neighbours(g: &OccupancyGrid, r: usize, c: usize) -> u32 {
    let mut n = 0;
    for dr in -1isize..=1 {
        for dc in -1isize..=1 {
            if dr == 0 && dc == 0 {
                continue;
            }
            let (nr, nc) = (r as isize + dr, c as isize + dc);
            let outside = nr < 0 || nc < 0 || nr >= g.rows as isize || nc >= g.cols as isize;
            if outside || g.get(nr as usize, nc as usize) {
                n += 1;
            }
        }
    }
    n
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_isolated_wall_clears_and_a_surrounded_hole_fills() {
        let caves = Caves {
            fill: 0.0,
            smooth_passes: 1,
            wall_at_neighbours: 5,
            free_at_neighbours: 1,
            cell_m: 1.0,
        };
        let mut g = OccupancyGrid::filled(5, 5, false);
        g.set(2, 2, true);
        assert!(!caves.smooth(&g).get(2, 2));
        let mut g = OccupancyGrid::filled(5, 5, true);
        g.set(2, 2, false);
        assert!(caves.smooth(&g).get(2, 2));
        // Corners see 5 outside neighbours: a free corner becomes a wall.
        assert!(caves.smooth(&OccupancyGrid::filled(5, 5, false)).get(0, 0));
    }
}

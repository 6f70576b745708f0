//! # `pixelise` filter
//!
//! **What it does.** Splits the map into square blocks of `block_m` (aligned to the top-left
//! corner; blocks at the right and bottom edges may be smaller) and gives every cell of a
//! block the block's mean value. On an occupancy grid a block becomes occupied when at
//! least half its cells are.
//!
//! **Why.** Smooth noise gives smooth, rounded obstacles; pixelising makes terrain granular
//! and blocky, as rubble, crates or buildings are (the paper's Fig. 1).
//!
//! **Parameters.**
//! - `block_m` (metres, default 0.5, in (0, 1000]): block edge, rounded to whole cells (≥ 1).
//!
//! **Source.** Arnold & Alexander (2013) §3, "a pixelisation filter to make the noise more
//! granular".

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::error::{join, SpecError};
use crate::grid::{cells_for, OccupancyGrid, ScalarField};
use crate::terrain::{Filter, Layer, LayerKind};

/// Parameters of the `pixelise` filter.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Pixelise {
    /// Block edge, metres, in (0, 1000]; rounded to whole cells, at least one. Default 0.5.
    #[serde(default = "default_block_m")]
    pub block_m: f64,
}

fn default_block_m() -> f64 {
    0.5
}

impl Filter for Pixelise {
    fn accepts(&self, _input: LayerKind) -> bool {
        true
    }

    fn validate(&self, path: &str) -> Result<(), SpecError> {
        SpecError::check_positive(&join(path, "block_m"), self.block_m, 1000.0)
    }

    fn apply(&self, layer: Layer, resolution_m: f64) -> Layer {
        let block = cells_for(self.block_m, resolution_m, 1);
        match layer {
            Layer::Field(f) => Layer::Field(pixelise_field(&f, block)),
            Layer::Occupancy(g) => Layer::Occupancy(pixelise_grid(&g, block)),
        }
    }
}

/// The block-mean field.
fn pixelise_field(f: &ScalarField, block: usize) -> ScalarField {
    let mut out = f.clone();
    for (r0, c0, r1, c1) in blocks(f.rows, f.cols, block) {
        let mut sum = 0.0;
        for r in r0..r1 {
            sum += f.values[r * f.cols + c0..r * f.cols + c1]
                .iter()
                .sum::<f64>();
        }
        let mean = sum / ((r1 - r0) * (c1 - c0)) as f64;
        for r in r0..r1 {
            out.values[r * f.cols + c0..r * f.cols + c1].fill(mean);
        }
    }
    out
}

/// The block-majority grid (ties count as occupied).
fn pixelise_grid(g: &OccupancyGrid, block: usize) -> OccupancyGrid {
    let mut out = g.clone();
    for (r0, c0, r1, c1) in blocks(g.rows, g.cols, block) {
        let mut occupied = 0;
        for r in r0..r1 {
            occupied += g.cells[r * g.cols + c0..r * g.cols + c1]
                .iter()
                .filter(|&&c| c)
                .count();
        }
        let majority = 2 * occupied >= (r1 - r0) * (c1 - c0);
        for r in r0..r1 {
            out.cells[r * g.cols + c0..r * g.cols + c1].fill(majority);
        }
    }
    out
}

/// Half-open block bounds (row0, col0, row1, col1), top-left first.
fn blocks(
    rows: usize,
    cols: usize,
    block: usize,
) -> impl Iterator<Item = (usize, usize, usize, usize)> {
    (0..rows).step_by(block).flat_map(move |r0| {
        (0..cols)
            .step_by(block)
            .map(move |c0| (r0, c0, (r0 + block).min(rows), (c0 + block).min(cols)))
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn blocks_take_their_mean_and_edges_are_partial() {
        let f = ScalarField {
            rows: 3,
            cols: 3,
            values: vec![0.0, 1.0, 5.0, 1.0, 2.0, 7.0, 8.0, 8.0, 8.0],
        };
        let out = pixelise_field(&f, 2);
        assert_eq!(
            out.values,
            vec![1.0, 1.0, 6.0, 1.0, 1.0, 6.0, 8.0, 8.0, 8.0]
        );
    }

    #[test]
    fn occupancy_blocks_take_the_majority() {
        let g = OccupancyGrid {
            rows: 2,
            cols: 2,
            cells: vec![true, false, true, false],
        };
        assert!(pixelise_grid(&g, 2).cells.iter().all(|&c| c));
    }
}

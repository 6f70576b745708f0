//! # `remove_islands` filter
//!
//! **What it does.** Clears every obstacle (8-connected region of occupied cells) whose area
//! is below `min_area_m2`.
//!
//! **Why.** Noise and cellular automata leave specks a cell or two across: they are not
//! plausible terrain, a laser barely sees them, and they make stalls that test nothing.
//!
//! **Parameters.**
//! - `min_area_m2` (square metres, default 0.25, in [0, 10⁶]): obstacles smaller than this
//!   are removed; area is cells × resolution².
//!
//! **Source.** Connected-component labelling (Rosenfeld & Pfaltz, 1966).

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::expect_occupancy;
use crate::error::{join, SpecError};
use crate::grid::regions::{label_regions, Connectivity, Regions};
use crate::terrain::{Filter, Layer, LayerKind};

/// Parameters of the `remove_islands` filter.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct RemoveIslands {
    /// Obstacles with a smaller area are cleared, square metres, in [0, 1e6]. Default 0.25.
    #[serde(default = "default_min_area_m2")]
    pub min_area_m2: f64,
}

fn default_min_area_m2() -> f64 {
    0.25
}

impl Filter for RemoveIslands {
    fn accepts(&self, input: LayerKind) -> bool {
        input == LayerKind::Occupancy
    }

    fn validate(&self, path: &str) -> Result<(), SpecError> {
        SpecError::check_in(&join(path, "min_area_m2"), self.min_area_m2, 0.0, 1e6)
    }

    fn apply(&self, layer: Layer, resolution_m: f64) -> Layer {
        let mut g = expect_occupancy(layer, "remove_islands");
        let min_cells = self.min_area_m2 / (resolution_m * resolution_m);
        let regions = label_regions(&g.cells, g.rows, g.cols, Connectivity::Eight);
        for (cell, &id) in g.cells.iter_mut().zip(&regions.label) {
            if id != Regions::NONE && (regions.sizes[id as usize] as f64) < min_cells {
                *cell = false;
            }
        }
        Layer::Occupancy(g)
    }
}

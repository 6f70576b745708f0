//! # `keep_largest_free_region` filter
//!
//! **What it does.** Finds the 8-connected regions of free cells and fills every one but the
//! largest (the first in raster order among equals), leaving a single free region.
//!
//! **Why.** A robot placed in a sealed pocket can never reach its goal; such a situation
//! tests the mission planner, not the controller. With one free region, any two free points
//! are connected (at cell level).
//!
//! **Parameters.** None.
//!
//! **Source.** Connected-component labelling (Rosenfeld & Pfaltz, 1966); BARN keeps the
//! largest connected region of its cellular-automaton worlds the same way (Perille et al., 2020).

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::expect_occupancy;
use crate::error::SpecError;
use crate::grid::regions::{label_regions, Connectivity, Regions};
use crate::terrain::{Filter, Layer, LayerKind};

/// The `keep_largest_free_region` filter (no parameters).
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct KeepLargestFreeRegion {}

impl Filter for KeepLargestFreeRegion {
    fn accepts(&self, input: LayerKind) -> bool {
        input == LayerKind::Occupancy
    }

    fn validate(&self, _path: &str) -> Result<(), SpecError> {
        Ok(())
    }

    fn apply(&self, layer: Layer, _resolution_m: f64) -> Layer {
        let mut g = expect_occupancy(layer, "keep_largest_free_region");
        let free: Vec<bool> = g.cells.iter().map(|&c| !c).collect();
        let regions = label_regions(&free, g.rows, g.cols, Connectivity::Eight);
        // max_by_key keeps the last maximum; iterate reversed so the first region wins ties.
        let Some(largest) = (0..regions.sizes.len())
            .rev()
            .max_by_key(|&i| regions.sizes[i])
        else {
            return Layer::Occupancy(g);
        };
        for (cell, &id) in g.cells.iter_mut().zip(&regions.label) {
            if id != Regions::NONE && id as usize != largest {
                *cell = true;
            }
        }
        Layer::Occupancy(g)
    }
}

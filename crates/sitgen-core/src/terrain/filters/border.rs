//! # `border` filter
//!
//! **What it does.** Makes a band of `width_m` along all four edges of the map occupied.
//!
//! **Why.** Robots must not drive off the map: a wall around it makes the edge an obstacle
//! that the laser sees and the simulator stalls on, as the walls of a Stage world do.
//!
//! **Parameters.**
//! - `width_m` (metres, default 0.2, in (0, 1000]): band width, rounded to whole cells (≥ 1).
//!
//! **Source.** Stage's worlds enclose their floorplans in a wall (Stage `bitmap` models).

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::expect_occupancy;
use crate::error::{join, SpecError};
use crate::grid::cells_for;
use crate::terrain::{Filter, Layer, LayerKind};

/// Parameters of the `border` filter.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Border {
    /// Wall thickness, metres, in (0, 1000]; rounded to whole cells, at least one. Default 0.2.
    #[serde(default = "default_width_m")]
    pub width_m: f64,
}

fn default_width_m() -> f64 {
    0.2
}

impl Filter for Border {
    fn accepts(&self, input: LayerKind) -> bool {
        input == LayerKind::Occupancy
    }

    fn validate(&self, path: &str) -> Result<(), SpecError> {
        SpecError::check_positive(&join(path, "width_m"), self.width_m, 1000.0)
    }

    fn apply(&self, layer: Layer, resolution_m: f64) -> Layer {
        let mut g = expect_occupancy(layer, "border");
        let w = cells_for(self.width_m, resolution_m, 1);
        for r in 0..g.rows {
            for c in 0..g.cols {
                if r < w || c < w || r + w >= g.rows || c + w >= g.cols {
                    g.set(r, c, true);
                }
            }
        }
        Layer::Occupancy(g)
    }
}

//! # `erode` filter
//!
//! **What it does.** Shrinks every obstacle by `radius_m`: an occupied cell stays occupied
//! only if no free cell's centre lies within `radius_m` of its centre. Space outside the map
//! counts as occupied, so obstacles touching the edge are not eaten from outside.
//!
//! **Why.** Opens passages, removes thin walls and specks, and, after a dilate of the same
//! radius (a morphological closing), smooths outlines without changing their size much.
//!
//! **Parameters.**
//! - `radius_m` (metres, default 0.3, in [0, 1000]): how far obstacles shrink.
//!
//! **Source.** Binary erosion by a disc (Serra, 1982), the dual of dilation, computed with
//! Felzenszwalb & Huttenlocher's distance transform (2012).

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::{expect_occupancy, within_radius};
use crate::error::{join, SpecError};
use crate::terrain::{Filter, Layer, LayerKind};

/// Parameters of the `erode` filter.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Erode {
    /// How far obstacles shrink, metres, in [0, 1000]. Default 0.3.
    #[serde(default = "default_radius_m")]
    pub radius_m: f64,
}

fn default_radius_m() -> f64 {
    0.3
}

impl Filter for Erode {
    fn accepts(&self, input: LayerKind) -> bool {
        input == LayerKind::Occupancy
    }

    fn validate(&self, path: &str) -> Result<(), SpecError> {
        SpecError::check_in(&join(path, "radius_m"), self.radius_m, 0.0, 1000.0)
    }

    fn apply(&self, layer: Layer, resolution_m: f64) -> Layer {
        let mut g = expect_occupancy(layer, "erode");
        let free: Vec<bool> = g.cells.iter().map(|&c| !c).collect();
        let near_free = within_radius(&free, g.rows, g.cols, self.radius_m / resolution_m);
        g.cells = near_free.into_iter().map(|near| !near).collect();
        Layer::Occupancy(g)
    }
}

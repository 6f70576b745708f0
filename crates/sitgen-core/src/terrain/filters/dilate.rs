//! # `dilate` filter
//!
//! **What it does.** Grows every obstacle by `radius_m`: a cell becomes occupied when its
//! centre lies within `radius_m` of an occupied cell's centre (a Euclidean disc, from an exact
//! distance transform). Space outside the map counts as free.
//!
//! **Why.** Closes narrow gaps and fattens thin obstacles, so that terrain suits a robot of a
//! given size; the mission stage plans on a dilated map for the same reason.
//!
//! **Parameters.**
//! - `radius_m` (metres, default 0.3, in [0, 1000]): how far obstacles grow.
//!
//! **Source.** Binary dilation by a disc (Serra, *Image Analysis and Mathematical Morphology*,
//! 1982), computed with Felzenszwalb & Huttenlocher's distance transform (2012).

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::{expect_occupancy, within_radius};
use crate::error::{join, SpecError};
use crate::terrain::{Filter, Layer, LayerKind};

/// Parameters of the `dilate` filter.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Dilate {
    /// How far obstacles grow, metres, in [0, 1000]. Default 0.3.
    #[serde(default = "default_radius_m")]
    pub radius_m: f64,
}

fn default_radius_m() -> f64 {
    0.3
}

impl Filter for Dilate {
    fn accepts(&self, input: LayerKind) -> bool {
        input == LayerKind::Occupancy
    }

    fn validate(&self, path: &str) -> Result<(), SpecError> {
        SpecError::check_in(&join(path, "radius_m"), self.radius_m, 0.0, 1000.0)
    }

    fn apply(&self, layer: Layer, resolution_m: f64) -> Layer {
        let mut g = expect_occupancy(layer, "dilate");
        g.cells = within_radius(&g.cells, g.rows, g.cols, self.radius_m / resolution_m);
        Layer::Occupancy(g)
    }
}

//! # `threshold` filter
//!
//! **What it does.** Turns a scalar field into an occupancy grid: a cell is occupied where its
//! value is at or above `value`.
//!
//! **Why.** The paper's terrain is binary (navigable or obstructed); this is the step that
//! makes it so. Use `coverage` instead to ask for an occupied fraction rather than a level.
//!
//! **Parameters.**
//! - `value` (field units, default 0.5, in [0, 1]): the level at and above which a cell is
//!   occupied. Built-in sources give values in [0, 1].
//!
//! **Source.** Arnold & Alexander (2013) §3, "a thresholding filter to convert the noise into
//! binary occupied/unoccupied".

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::binarize;
use crate::error::{join, SpecError};
use crate::terrain::{Filter, Layer, LayerKind};

/// Parameters of the `threshold` filter.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Threshold {
    /// Level at and above which a cell is occupied, in [0, 1]. Default 0.5.
    #[serde(default = "default_value")]
    pub value: f64,
}

fn default_value() -> f64 {
    0.5
}

impl Filter for Threshold {
    fn accepts(&self, input: LayerKind) -> bool {
        input == LayerKind::Field
    }

    fn output(&self, _input: LayerKind) -> LayerKind {
        LayerKind::Occupancy
    }

    fn validate(&self, path: &str) -> Result<(), SpecError> {
        SpecError::check_in(&join(path, "value"), self.value, 0.0, 1.0)
    }

    fn apply(&self, layer: Layer, _resolution_m: f64) -> Layer {
        match layer {
            Layer::Field(f) => Layer::Occupancy(binarize(&f, self.value)),
            Layer::Occupancy(_) => unreachable!("threshold is checked to get a scalar field"),
        }
    }
}

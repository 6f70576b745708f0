//! # `invert` filter
//!
//! **What it does.** Swaps occupied and free cells; on a scalar field, maps v to 1 − v.
//!
//! **Why.** Some sources make the wrong phase for a use: caves carved as rock can be turned
//! into islands in open water, rooms into pillars, and noise ridges into valleys.
//!
//! **Parameters.** None.
//!
//! **Source.** Standard image negation.

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::error::SpecError;
use crate::terrain::{Filter, Layer, LayerKind};

/// The `invert` filter (no parameters).
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Invert {}

impl Filter for Invert {
    fn accepts(&self, _input: LayerKind) -> bool {
        true
    }

    fn validate(&self, _path: &str) -> Result<(), SpecError> {
        Ok(())
    }

    fn apply(&self, layer: Layer, _resolution_m: f64) -> Layer {
        match layer {
            Layer::Field(mut f) => {
                f.values.iter_mut().for_each(|v| *v = 1.0 - *v);
                Layer::Field(f)
            }
            Layer::Occupancy(mut g) => {
                g.cells.iter_mut().for_each(|c| *c = !*c);
                Layer::Occupancy(g)
            }
        }
    }
}

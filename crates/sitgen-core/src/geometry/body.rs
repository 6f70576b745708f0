//! Robot bodies: oriented rectangles about a rotation centre.
//!
//! The default is Stage's Pioneer 3-AT (`pioneer.inc`): `size [0.626 0.505]` (length along the
//! robot's x axis, width along y) and `origin [-0.04465 0 0]`: the body's centre lies 4.465 cm
//! behind the rotation centre, which is the robot's pose.

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::error::{join, SpecError};

/// A robot body: a rectangle, offset along the robot's x axis from its rotation centre.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Body {
    /// Model name, for export and display. Default `pioneer3at`.
    #[serde(default = "default_model")]
    pub model: String,
    /// Length along the robot's heading, metres, in (0, 10]. Default 0.626.
    #[serde(default = "default_length_m")]
    pub length_m: f64,
    /// Width across the heading, metres, in (0, 10]. Default 0.505.
    #[serde(default = "default_width_m")]
    pub width_m: f64,
    /// Body centre ahead of the rotation centre (negative: behind), metres, in [-5, 5].
    /// Default -0.04465.
    #[serde(default = "default_origin_x_m")]
    pub origin_x_m: f64,
}

fn default_model() -> String {
    "pioneer3at".into()
}
fn default_length_m() -> f64 {
    0.626
}
fn default_width_m() -> f64 {
    0.505
}
fn default_origin_x_m() -> f64 {
    -0.04465
}

impl Default for Body {
    fn default() -> Self {
        Self {
            model: default_model(),
            length_m: default_length_m(),
            width_m: default_width_m(),
            origin_x_m: default_origin_x_m(),
        }
    }
}

impl Body {
    /// Radius of the smallest circle about the rotation centre that encloses the body.
    pub fn enclosing_radius(&self) -> f64 {
        let reach = self.length_m / 2.0 + self.origin_x_m.abs();
        reach.hypot(self.width_m / 2.0)
    }

    /// Check the dimensions; `path` names the body in errors.
    pub fn validate(&self, path: &str) -> Result<(), SpecError> {
        SpecError::check_positive(&join(path, "length_m"), self.length_m, 10.0)?;
        SpecError::check_positive(&join(path, "width_m"), self.width_m, 10.0)?;
        SpecError::check_in(&join(path, "origin_x_m"), self.origin_x_m, -5.0, 5.0)
    }

    /// Corners of the footprint in the world for pose (x, y, heading), counter-clockwise.
    pub fn corners(&self, x: f64, y: f64, heading: f64) -> [(f64, f64); 4] {
        let (s, c) = heading.sin_cos();
        let (hl, hw, ox) = (self.length_m / 2.0, self.width_m / 2.0, self.origin_x_m);
        [(hl, -hw), (hl, hw), (-hl, hw), (-hl, -hw)].map(|(bx, by)| {
            let (bx, by) = (bx + ox, by);
            (x + c * bx - s * by, y + s * bx + c * by)
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_pioneer_encloses_its_corners() {
        let body = Body::default();
        let r = body.enclosing_radius();
        assert!((r - 0.43782).abs() < 1e-4, "{r}");
        for (x, y) in body.corners(1.0, 2.0, 0.7) {
            assert!(((x - 1.0).hypot(y - 2.0)) <= r + 1e-12);
        }
    }
}

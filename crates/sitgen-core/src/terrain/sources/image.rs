//! # `image` source
//!
//! **What it makes.** A scalar field from a PNG or PGM file (any bit depth; colour is turned
//! to luma, alpha ignored): each cell's value is its darkness, (max − grey) / max, so black is
//! 1 (occupied) and white is 0 (free), as in ROS map_server and Stage bitmaps; `negate`
//! swaps them. One pixel is one cell unless the spec gives `width_m` and `height_m`, in which
//! case the image is stretched to them (nearest pixel). Follow it with `threshold` (0.5 for a
//! clean black-and-white map) or `coverage`.
//!
//! **Why.** Test against a real floor plan, a map a robot has built, or a hand-drawn case, with
//! the same filters and mission planner as generated terrain.
//!
//! **Parameters.**
//! - `path` (file path, required): the image; relative to the spec file's folder.
//! - `negate` (bool, default false): white is occupied instead of black.
//!
//! **Source.** ROS map_server's image convention (occupancy = (255 − value) / 255).

use std::path::{Path, PathBuf};

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::error::{join, SpecError};
use crate::grid::{nearest_source, ScalarField};
use crate::interchange::image::read_darkness;
use crate::rng::ChoiceSource;
use crate::terrain::{Extent, Layer, LayerKind, Source};

/// Parameters of the `image` source.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ImageSource {
    /// PNG or PGM file; a relative path is relative to the spec file's folder. Required.
    pub path: PathBuf,
    /// Treat white as occupied instead of black. Default false.
    #[serde(default)]
    pub negate: bool,
}

impl ImageSource {
    /// Width and height of the image in pixels.
    pub fn pixel_size(&self) -> Result<(usize, usize), String> {
        let (w, h) = image::image_dimensions(&self.path)
            .map_err(|e| format!("cannot read image {}: {e}", self.path.display()))?;
        Ok((w as usize, h as usize))
    }

    /// Make a relative `path` relative to `dir`.
    pub fn resolve_path(&mut self, dir: &Path) {
        if self.path.is_relative() {
            self.path = dir.join(&self.path);
        }
    }
}

impl Source for ImageSource {
    fn output(&self) -> LayerKind {
        LayerKind::Field
    }

    fn validate(&self, path: &str) -> Result<(), SpecError> {
        if self.path.as_os_str().is_empty() {
            return Err(SpecError::new(
                join(path, "path"),
                "must name a PNG or PGM file",
            ));
        }
        Ok(())
    }

    fn draws(&self) -> bool {
        false
    }

    fn generate(&self, extent: Extent, _choices: &mut ChoiceSource) -> Result<Layer, String> {
        let image = read_darkness(&self.path)?;
        let mut values = vec![0.0; extent.rows * extent.cols];
        for r in 0..extent.rows {
            let sr = nearest_source(r, extent.rows, image.rows);
            for c in 0..extent.cols {
                let sc = nearest_source(c, extent.cols, image.cols);
                let dark = image.values[sr * image.cols + sc];
                values[r * extent.cols + c] = if self.negate { 1.0 - dark } else { dark };
            }
        }
        Ok(Layer::Field(ScalarField {
            cols: extent.cols,
            rows: extent.rows,
            values,
        }))
    }
}

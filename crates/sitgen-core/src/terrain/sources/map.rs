//! # `map` source
//!
//! **What it makes.** An occupancy grid loaded from a map file: a ROS map_server YAML (and the
//! image it names), a PNG or PGM image (ROS's default thresholds), or a MovingAI `.map`. The
//! map keeps its physical size; it is redrawn at the spec's `resolution_m`, a cell being
//! occupied when any file cell under it is (so thin walls survive coarsening). For files that
//! carry no resolution (images, `.map`), `file_resolution_m` gives it.
//!
//! **Why.** Test a controller on the building it will drive in, or on published benchmark maps,
//! with sitgen's robots, routes, monitor and ranking.
//!
//! **Parameters.**
//! - `path` (file path, required): the map; relative to the spec file's folder.
//! - `unknown` (`occupied` or `free`, default `occupied`): how ROS's unknown cells are read.
//! - `file_resolution_m` (metres per file cell, default 0.1, in (0, 100]): for images and
//!   `.map` files; a YAML's own resolution wins.
//!
//! **Source.** ROS map_server (`image_loader.cpp`); Sturtevant (2012) for MovingAI maps.

use std::path::{Path, PathBuf};

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::error::{join, SpecError};
use crate::grid::{cells_for, OccupancyGrid};
use crate::interchange::maps::{load_map, Unknown};
use crate::rng::ChoiceSource;
use crate::terrain::{Extent, Layer, LayerKind, Source};

/// How unknown cells are read.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum UnknownCells {
    /// As obstacles.
    #[default]
    Occupied,
    /// As free space.
    Free,
}

/// Parameters of the `map` source.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct MapSource {
    /// ROS YAML, PNG, PGM or MovingAI `.map` file; relative to the spec file's folder.
    pub path: PathBuf,
    /// `occupied` or `free`: how ROS's unknown cells are read. Default `occupied`.
    #[serde(default)]
    pub unknown: UnknownCells,
    /// Metres per file cell for images and `.map` files, in (0, 100]. Default 0.1.
    #[serde(default = "default_file_resolution_m")]
    pub file_resolution_m: f64,
}

fn default_file_resolution_m() -> f64 {
    0.1
}

impl MapSource {
    /// Make a relative `path` relative to `dir`.
    pub fn resolve_path(&mut self, dir: &Path) {
        if self.path.is_relative() {
            self.path = dir.join(&self.path);
        }
    }
}

impl Source for MapSource {
    fn output(&self) -> LayerKind {
        LayerKind::Occupancy
    }

    fn validate(&self, path: &str) -> Result<(), SpecError> {
        if self.path.as_os_str().is_empty() {
            return Err(SpecError::new(join(path, "path"), "must name a map file"));
        }
        SpecError::check_positive(
            &join(path, "file_resolution_m"),
            self.file_resolution_m,
            100.0,
        )
    }

    fn draws(&self) -> bool {
        false
    }

    fn generate(&self, extent: Extent, _choices: &mut ChoiceSource) -> Result<Layer, String> {
        let unknown = match self.unknown {
            UnknownCells::Occupied => Unknown::Occupied,
            UnknownCells::Free => Unknown::Free,
        };
        let file = load_map(&self.path, self.file_resolution_m, unknown)?;
        let res = extent.resolution_m;
        let rows = cells_for(file.height_m(), res, 1);
        let cols = cells_for(file.width_m(), res, 1);
        crate::grid::check_size(rows, cols)
            .map_err(|e| format!("{} redrawn at {res} m per cell: {e}", self.path.display()))?;
        Ok(Layer::Occupancy(redraw_conservatively(
            &file.grid,
            file.resolution_m,
            rows,
            cols,
            res,
        )))
    }
}

/// `rows × cols` cells of `res` over the same ground as `src` (cells of `src_res`): a cell is
/// occupied when any source cell it overlaps is.
fn redraw_conservatively(
    src: &OccupancyGrid,
    src_res: f64,
    rows: usize,
    cols: usize,
    res: f64,
) -> OccupancyGrid {
    if rows == src.rows && cols == src.cols {
        return src.clone();
    }
    // Source cells overlapped by [lo, hi) metres, half-open, clamped to the grid.
    let span = |lo: f64, hi: f64, n: usize| {
        let first = ((lo / src_res).floor().max(0.0) as usize).min(n - 1);
        let last = (((hi / src_res).ceil() as usize).max(first + 1)).min(n);
        first..last
    };
    let mut out = OccupancyGrid::filled(rows, cols, false);
    for r in 0..rows {
        let rs = span(r as f64 * res, (r + 1) as f64 * res, src.rows);
        for c in 0..cols {
            let cs = span(c as f64 * res, (c + 1) as f64 * res, src.cols);
            let any = rs.clone().any(|sr| cs.clone().any(|sc| src.get(sr, sc)));
            out.set(r, c, any);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn coarsening_keeps_a_thin_wall() {
        let mut g = OccupancyGrid::filled(10, 10, false);
        for r in 0..10 {
            g.set(r, 5, true);
        }
        let coarse = redraw_conservatively(&g, 0.05, 5, 5, 0.1);
        assert!((0..5).all(|r| coarse.get(r, 2)));
        assert_eq!(coarse.occupied_count(), 5);
    }
}

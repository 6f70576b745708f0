//! Terrain filters, one file each, applied in the order the spec lists them.
//!
//! Every file follows the same template: what the filter does, why it is there, its
//! parameters with units and defaults, and its source.

mod border;
pub mod coverage;
mod dilate;
mod erode;
mod invert;
mod keep_largest_free_region;
mod pixelise;
mod remove_islands;
mod threshold;

pub use border::Border;
pub use coverage::Coverage;
pub use dilate::Dilate;
pub use erode::Erode;
pub use invert::Invert;
pub use keep_largest_free_region::KeepLargestFreeRegion;
pub use pixelise::Pixelise;
pub use remove_islands::RemoveIslands;
pub use threshold::Threshold;

use crate::grid::{OccupancyGrid, ScalarField};

use super::Layer;

/// The occupancy grid inside a layer that a validated chain guarantees is one.
pub(crate) fn expect_occupancy(layer: Layer, filter: &str) -> OccupancyGrid {
    match layer {
        Layer::Occupancy(g) => g,
        Layer::Field(_) => unreachable!("{filter} is checked to get an occupancy grid"),
    }
}

/// Occupied where the field is at or above `threshold`.
pub(crate) fn binarize(field: &ScalarField, threshold: f64) -> OccupancyGrid {
    OccupancyGrid {
        rows: field.rows,
        cols: field.cols,
        cells: field.values.iter().map(|&v| v >= threshold).collect(),
    }
}

/// Cells whose centre lies within `radius_cells` of a cell where `feature` is true.
pub(crate) fn within_radius(
    grid_feature: &[bool],
    rows: usize,
    cols: usize,
    radius_cells: f64,
) -> Vec<bool> {
    let r2 = radius_cells * radius_cells;
    crate::grid::distance::squared_distance_to(grid_feature, rows, cols)
        .into_iter()
        .map(|d2| d2 <= r2)
        .collect()
}

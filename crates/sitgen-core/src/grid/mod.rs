//! Scalar fields and occupancy grids: the data that flows through the terrain chain.
//!
//! **Frame.** Cells are stored row-major with row 0 at the top (north), as images are. The
//! world frame is x east, y north, in metres, with its origin at the map's bottom-left corner,
//! so the centre of cell (row r, column c) is at x = (c + ½)·res, y = (rows − r − ½)·res.
//! This is the ROS map_server convention once the image is flipped, and Stage's bitmap
//! convention.

pub mod distance;
pub mod regions;

/// Largest grid sitgen builds, in cells: 10⁸ cells (≈ 100 MB of occupancy, and of the order of a
/// 1 km × 1 km site at 0.1 m). Every grid sized from input — a spec, a map file's header, an
/// image's dimensions, a situation's embedded map — is checked against it before anything of
/// that size is allocated.
pub const MAX_CELLS: usize = 100_000_000;

/// Check that a `rows × cols` grid is non-empty and within [`MAX_CELLS`], before allocating it.
pub fn check_size(rows: usize, cols: usize) -> Result<(), String> {
    match rows.checked_mul(cols) {
        Some(0) => Err(format!("{rows} × {cols} cells is an empty map")),
        Some(n) if n <= MAX_CELLS => Ok(()),
        _ => Err(format!(
            "{rows} × {cols} cells is more than the {MAX_CELLS} a map may have"
        )),
    }
}

/// A rectangular raster of `f64` values, one per cell: what noise sources produce and what
/// pixelise and threshold read. Values from the built-in sources lie in [0, 1], where larger
/// means "more likely an obstacle".
#[derive(Debug, Clone, PartialEq)]
pub struct ScalarField {
    /// Number of columns.
    pub cols: usize,
    /// Number of rows.
    pub rows: usize,
    /// Row-major values, row 0 at the top.
    pub values: Vec<f64>,
}

impl ScalarField {
    /// A field of `rows × cols` cells all equal to `value`.
    pub fn filled(rows: usize, cols: usize, value: f64) -> Self {
        Self {
            cols,
            rows,
            values: vec![value; rows * cols],
        }
    }
}

/// A binary map: each cell is occupied (an obstacle) or free.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct OccupancyGrid {
    /// Number of columns.
    pub cols: usize,
    /// Number of rows.
    pub rows: usize,
    /// Row-major occupancy, row 0 at the top; `true` = occupied.
    pub cells: Vec<bool>,
}

impl OccupancyGrid {
    /// A grid of `rows × cols` cells, all occupied or all free.
    pub fn filled(rows: usize, cols: usize, occupied: bool) -> Self {
        Self {
            cols,
            rows,
            cells: vec![occupied; rows * cols],
        }
    }

    /// Row-major index of cell (row, col).
    #[inline]
    pub fn index(&self, row: usize, col: usize) -> usize {
        row * self.cols + col
    }

    /// Whether cell (row, col) is occupied.
    #[inline]
    pub fn get(&self, row: usize, col: usize) -> bool {
        self.cells[self.index(row, col)]
    }

    /// Set cell (row, col).
    #[inline]
    pub fn set(&mut self, row: usize, col: usize, occupied: bool) {
        let i = self.index(row, col);
        self.cells[i] = occupied;
    }

    /// Number of occupied cells.
    pub fn occupied_count(&self) -> usize {
        self.cells.iter().filter(|&&c| c).count()
    }

    /// Occupied fraction of the map, in [0, 1]; 0 for an empty grid.
    pub fn coverage(&self) -> f64 {
        if self.cells.is_empty() {
            0.0
        } else {
            self.occupied_count() as f64 / self.cells.len() as f64
        }
    }

    /// Resample to `rows × cols` by nearest neighbour (cell centres mapped proportionally).
    pub fn resample_nearest(&self, rows: usize, cols: usize) -> Self {
        let mut out = Self::filled(rows, cols, false);
        for r in 0..rows {
            let sr = nearest_source(r, rows, self.rows);
            for c in 0..cols {
                let sc = nearest_source(c, cols, self.cols);
                out.set(r, c, self.get(sr, sc));
            }
        }
        out
    }
}

/// The source index whose cell centre lies nearest to the centre of destination index `i`
/// when `dst` cells span the same extent as `src` cells.
pub fn nearest_source(i: usize, dst: usize, src: usize) -> usize {
    let centre = (i as f64 + 0.5) * src as f64 / dst as f64;
    (centre.floor() as usize).min(src - 1)
}

/// A grid with its geometry: what a terrain stage hands to the mission stage.
#[derive(Debug, Clone, PartialEq)]
pub struct Map {
    /// The cells.
    pub grid: OccupancyGrid,
    /// Cell edge length, metres per cell.
    pub resolution_m: f64,
}

impl Map {
    /// Width of the map, metres.
    pub fn width_m(&self) -> f64 {
        self.grid.cols as f64 * self.resolution_m
    }

    /// Height of the map, metres.
    pub fn height_m(&self) -> f64 {
        self.grid.rows as f64 * self.resolution_m
    }

    /// World coordinates (x, y) in metres of the centre of cell (row, col).
    pub fn cell_centre(&self, row: usize, col: usize) -> (f64, f64) {
        (
            (col as f64 + 0.5) * self.resolution_m,
            (self.grid.rows as f64 - row as f64 - 0.5) * self.resolution_m,
        )
    }
}

/// Number of cells that a length in metres spans at `resolution_m`, rounded to nearest and at
/// least `min`.
pub fn cells_for(length_m: f64, resolution_m: f64, min: usize) -> usize {
    ((length_m / resolution_m).round() as usize).max(min)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cell_centres_follow_the_documented_frame() {
        let map = Map {
            grid: OccupancyGrid::filled(4, 3, false),
            resolution_m: 0.5,
        };
        assert_eq!(map.cell_centre(0, 0), (0.25, 1.75));
        assert_eq!(map.cell_centre(3, 2), (1.25, 0.25));
        assert_eq!((map.width_m(), map.height_m()), (1.5, 2.0));
    }

    #[test]
    fn nearest_resample_keeps_a_pattern_at_double_size() {
        let mut g = OccupancyGrid::filled(2, 2, false);
        g.set(0, 1, true);
        let big = g.resample_nearest(4, 4);
        assert!(big.get(0, 2) && big.get(1, 3) && !big.get(2, 2) && !big.get(0, 0));
        assert_eq!(big.resample_nearest(2, 2), g);
    }
}

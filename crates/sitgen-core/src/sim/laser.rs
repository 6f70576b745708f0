//! The laser rangefinder: rays against the grid and against other robots' footprints.
//!
//! Beams follow Stage's ranger geometry: n beams, beam t at bearing −fov/2 + t·fov/(n − 1)
//! from the heading (the first and last exactly at the edges of the field of view), from the
//! sensor's mount point. Each ray is traced through the occupancy grid cell by cell (Amanatides
//! & Woo's traversal, so no cell is skipped and the range is the exact distance to where the ray
//! enters the first occupied cell), and intersected with every other robot's rectangle (slab
//! method); the nearest hit wins, and the robot carrying the sensor is never hit. A ray that
//! leaves the map or reaches `range_m` without a hit reads `range_m` exactly. Ranges are rounded
//! to `range_step_m` (1 cm for the SICK LMS200), and optional Gaussian noise is added to hits.
//!
//! Unlike Stage's default models, every robot's full body is visible to the beam (Stage's
//! stock beam height passes over other Pioneers' bodies): sitgen tests avoidance, and a robot
//! the laser cannot see by construction would be a fault of the test, not of the controller.

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::collision::Rect;
use crate::error::{join, SpecError};
use crate::grid::Map;

/// The laser's parameters; defaults are the SICK LMS200 as Arnold & Alexander used it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct LaserSpec {
    /// Field of view, degrees, in (0, 360]. Default 180.
    #[serde(default = "default_fov_deg")]
    pub fov_deg: f64,
    /// Number of beams, in [1, 10000]. Default 181.
    #[serde(default = "default_beams")]
    pub beams: u32,
    /// Maximum range, metres, in (0, 1000]. Default 10.
    #[serde(default = "default_range_m")]
    pub range_m: f64,
    /// Ranges are rounded to multiples of this, metres, in [0, 1]; 0 = no rounding. Default 0.01.
    #[serde(default = "default_range_step_m")]
    pub range_step_m: f64,
    /// Mount point ahead of the rotation centre along the heading, metres, in [-5, 5].
    /// Default 0 (Stage mounts `sicklaser` at the rotation centre).
    #[serde(default)]
    pub offset_x_m: f64,
    /// Standard deviation of Gaussian range noise on hits, metres, in [0, 10]. Default 0.
    #[serde(default)]
    pub noise_sd_m: f64,
}

fn default_fov_deg() -> f64 {
    180.0
}
fn default_beams() -> u32 {
    181
}
fn default_range_m() -> f64 {
    10.0
}
fn default_range_step_m() -> f64 {
    0.01
}

impl Default for LaserSpec {
    fn default() -> Self {
        Self {
            fov_deg: default_fov_deg(),
            beams: default_beams(),
            range_m: default_range_m(),
            range_step_m: default_range_step_m(),
            offset_x_m: 0.0,
            noise_sd_m: 0.0,
        }
    }
}

impl LaserSpec {
    /// Check every range; `path` names the laser in errors.
    pub fn validate(&self, path: &str) -> Result<(), SpecError> {
        SpecError::check_positive(&join(path, "fov_deg"), self.fov_deg, 360.0)?;
        if !(1..=10_000).contains(&self.beams) {
            return Err(SpecError::new(
                join(path, "beams"),
                format!("{} is not in [1, 10000]", self.beams),
            ));
        }
        SpecError::check_positive(&join(path, "range_m"), self.range_m, 1000.0)?;
        SpecError::check_in(&join(path, "range_step_m"), self.range_step_m, 0.0, 1.0)?;
        SpecError::check_in(&join(path, "offset_x_m"), self.offset_x_m, -5.0, 5.0)?;
        SpecError::check_in(&join(path, "noise_sd_m"), self.noise_sd_m, 0.0, 10.0)
    }

    /// Bearing of each beam relative to the heading, radians.
    pub fn bearings(&self) -> Vec<f64> {
        let fov = self.fov_deg.to_radians();
        let n = self.beams as usize;
        if n == 1 {
            return vec![0.0];
        }
        (0..n)
            .map(|t| -fov / 2.0 + t as f64 * fov / (n - 1) as f64)
            .collect()
    }

    /// Round a range to the range step.
    pub fn quantise(&self, r: f64) -> f64 {
        if self.range_step_m > 0.0 {
            ((r / self.range_step_m).round() * self.range_step_m).min(self.range_m)
        } else {
            r
        }
    }
}

/// The grid as a laser ray sees it: per cell, whether it stops rays and, if not, how far a ray
/// may leap from anywhere in it. One table serves both questions, so each cell a ray visits
/// costs one load.
///
/// A cell's leap comes from its centre's clearance `d` (distance to the nearest occupied cell
/// centre): no occupied square is nearer than `d − res·√2` to any point of the cell, so a ray
/// may jump that far (less a micrometre for the f32 rounding of the clearance) and walk on from
/// where it lands. The walk resumes before any occupied cell, so it finds the crossing the
/// plain cell walk finds; open maps with 10 m rays cost a few leaps instead of a hundred cells.
///
/// The map is surrounded by a ring of [`OFF_MAP`] cells, so a walk needs no count of the cells
/// left to each edge: the cell past the edge ends it.
#[derive(Debug, Clone)]
pub struct RayGrid {
    /// Rows from the bottom (row `w` of the map is row `w + 1`), `cols + 2` cells each:
    /// [`OCCUPIED`] or [`OFF_MAP`], the leap in metres, or 0 for a free cell whose leap is
    /// shorter than `leap_min` (so never taken).
    cells: Vec<f64>,
    cols: i64,
    rows: i64,
    res: f64,
    inv_res: f64,
    /// Leaping pays only when it skips a few cells: three.
    leap_min: f64,
}

/// A [`RayGrid`] cell that stops rays: the ray's range is where it enters the cell.
const OCCUPIED: f64 = -1.0;
/// A [`RayGrid`] cell of the ring about the map: a ray that reaches it reads its maximum range.
/// The only other value below zero, so `cell < 0.0` asks whether a walk ends.
const OFF_MAP: f64 = -2.0;

/// Where every ray of a scan from one origin stands after the origin's cell: they all start
/// in it, so its test and its leap are the same for each.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ScanStart {
    /// Every ray reads this range (the origin is off the map or in an occupied cell, or its
    /// leap reaches the maximum range).
    Every(f64),
    /// Every ray walks on from this distance along it.
    From(f64),
}

impl RayGrid {
    /// The map's grid for rays; with `clearance` (metres per cell centre, row-major) rays leap
    /// across open ground, without it they walk every cell.
    pub fn new(map: &Map, clearance: Option<&[f32]>) -> Self {
        let res = map.resolution_m;
        let leap_min = 3.0 * res;
        let cell_reach = res * std::f64::consts::SQRT_2;
        let (cols, rows) = (map.grid.cols, map.grid.rows);
        let mut cells = vec![OFF_MAP; (cols + 2) * (rows + 2)];
        // The map's rows run from the top; the table's from the bottom.
        for (r, map_row) in map.grid.cells.chunks_exact(cols.max(1)).enumerate() {
            let start = (rows - r) * (cols + 2) + 1;
            for (c, (cell, &occupied)) in cells[start..start + cols]
                .iter_mut()
                .zip(map_row)
                .enumerate()
            {
                *cell = if occupied {
                    OCCUPIED
                } else {
                    let leap =
                        clearance.map_or(0.0, |m| f64::from(m[r * cols + c]) - cell_reach - 1e-6);
                    if leap >= leap_min {
                        leap
                    } else {
                        0.0
                    }
                };
            }
        }
        Self {
            cells,
            cols: cols as i64,
            rows: rows as i64,
            res,
            inv_res: 1.0 / res,
            leap_min,
        }
    }

    /// The table's index of the cell holding `(px, py)`, or `None` off the map.
    #[inline]
    fn cell_at(&self, px: f64, py: f64) -> Option<(usize, i64, i64)> {
        // Column index from x, and row-from-the-bottom index from y.
        let scaled = [(px * self.inv_res, 0.0), (py * self.inv_res, 0.0)];
        self.cell_along_ray(0.0, (px, py), (0.0, 0.0), &scaled)
    }

    /// [`RayGrid::cell_at`] for the point `t` along a ray (`origin`, `dir`) whose origin and
    /// direction in cells are `scaled` ([`cell_along`]).
    #[inline]
    fn cell_along_ray(
        &self,
        t: f64,
        origin: (f64, f64),
        dir: (f64, f64),
        scaled: &[(f64, f64); 2],
    ) -> Option<(usize, i64, i64)> {
        let cu = cell_along(t, origin.0, dir.0, scaled[0], self.res)?;
        let cw = cell_along(t, origin.1, dir.1, scaled[1], self.res)?;
        self.index_of(cu, cw)
    }

    /// The table's index of the map's cell in column `cu`, row `cw` from the bottom (both
    /// ≥ 0), or `None` off the map.
    #[inline]
    fn index_of(&self, cu: i64, cw: i64) -> Option<(usize, i64, i64)> {
        if cu >= self.cols || cw >= self.rows {
            return None;
        }
        Some((((cw + 1) * (self.cols + 2) + cu + 1) as usize, cu, cw))
    }

    /// How every ray from `origin` with range `max` starts (see [`ScanStart`]).
    pub fn scan_start(&self, origin: (f64, f64), max: f64) -> ScanStart {
        let Some((index, _, _)) = self.cell_at(origin.0, origin.1) else {
            return ScanStart::Every(max);
        };
        let leap = self.cells[index];
        if leap < 0.0 {
            ScanStart::Every(0.0)
        } else if leap >= self.leap_min {
            if leap >= max {
                ScanStart::Every(max)
            } else {
                ScanStart::From(leap)
            }
        } else {
            ScanStart::From(0.0)
        }
    }

    /// Distance along the ray from `origin` in unit direction `dir` to where it enters the
    /// first occupied cell, or `max` if it meets none within `max` or leaves the map first.
    pub fn ray(&self, origin: (f64, f64), dir: (f64, f64), max: f64) -> f64 {
        match self.scan_start(origin, max) {
            ScanStart::Every(t) => t,
            ScanStart::From(t0) => self.ray_from(t0, origin, dir, max),
        }
    }

    /// [`RayGrid::ray`] for a ray known to be free up to `t0` (its [`ScanStart::From`]): the
    /// cells are walked (Amanatides & Woo's traversal, so none is skipped) and open ground
    /// leapt.
    pub fn ray_from(
        &self,
        mut t0: f64,
        (ox, oy): (f64, f64),
        (dx, dy): (f64, f64),
        max: f64,
    ) -> f64 {
        let (res, stride) = (self.res, self.cols as isize + 2);
        let delta_u = if dx != 0.0 {
            res / dx.abs()
        } else {
            f64::INFINITY
        };
        let delta_w = if dy != 0.0 {
            res / dy.abs()
        } else {
            f64::INFINITY
        };
        // The ray in cells, so that a leap's cell is one multiply-add from its distance.
        let scaled = [
            (ox * self.inv_res, dx * self.inv_res),
            (oy * self.inv_res, dy * self.inv_res),
        ];
        'walk: loop {
            let Some((mut index, cu, cw)) = self.cell_along_ray(t0, (ox, oy), (dx, dy), &scaled)
            else {
                return max;
            };
            let (px, py) = (ox + t0 * dx, oy + t0 * dy);
            // Leap from the start cell before the boundary crossings are computed: a run of
            // leaps across open ground divides by nothing. A free cell holds 0 or a leap
            // ≥ `leap_min`, so one test passes every cell a walk goes on through.
            let leap = self.cells[index];
            if leap != 0.0 {
                if leap < 0.0 {
                    return t0;
                }
                t0 += leap;
                if t0 >= max {
                    return max;
                }
                continue 'walk;
            }
            // Walk the table's index directly: a step in x is ±1, a step in y is ±(cols + 2).
            let step_u: isize = if dx > 0.0 { 1 } else { -1 };
            let step_w = if dy > 0.0 { stride } else { -stride };
            let mut t_u = t0 + first_crossing(px, cu, dx, res);
            let mut t_w = t0 + first_crossing(py, cw, dy, res);
            loop {
                let t;
                if t_u < t_w {
                    index = index.wrapping_add_signed(step_u);
                    t = t_u;
                    t_u += delta_u;
                } else {
                    index = index.wrapping_add_signed(step_w);
                    t = t_w;
                    t_w += delta_w;
                }
                if t >= max {
                    return max;
                }
                let leap = self.cells[index];
                if leap != 0.0 {
                    if leap < 0.0 {
                        return if leap == OFF_MAP { max } else { t };
                    }
                    t0 = t + leap;
                    if t0 >= max {
                        return max;
                    }
                    continue 'walk;
                }
            }
        }
    }
}

/// The cell holding coordinate `o + t·d` along an axis of cells `res` wide from 0 (metres,
/// `o + t*d` rounded as written): its quotient by `res` truncated (the floor, for a coordinate
/// ≥ 0), `None` below zero, given the same in cells, `(os, ds)` = (o·(1/res), d·(1/res)). A
/// point is `t = 0, d = 0`.
///
/// Cells sit on the chain of every leap (the cell a leap lands in gives the next leap), so the
/// cell comes from the scaled terms: one multiply-add from the leap's distance, no division.
/// `os + t·ds` is within 4·ε·(|os| + |t·ds|) of the exact quotient of the rounded coordinate
/// (ε = `f64::EPSILON`), whatever the cancellation; away from a cell boundary by four times
/// that it truncates to the same cell, and that truncation is the cell. Nearer one (or below
/// zero) the coordinate and its quotient are computed: the same cell, bit for bit.
#[inline]
fn cell_along(t: f64, o: f64, d: f64, (os, ds): (f64, f64), res: f64) -> Option<i64> {
    let along = t * ds;
    let fast = os + along;
    let cell = fast as i64;
    let whole = cell as f64;
    let margin = 16.0 * f64::EPSILON * (os.abs() + along.abs());
    if fast - whole > margin && whole + 1.0 - fast > margin {
        // Only for fast > 0: below zero neither difference exceeds the margin (≥ 0).
        Some(cell)
    } else {
        let exact = (o + t * d) / res;
        (exact >= 0.0 || exact.is_nan()).then_some(exact as i64)
    }
}

/// Distance along a ray (coordinate `o`, direction component `d`) from inside cell `cell` to
/// the first cell boundary it crosses on that axis; infinite when it never does.
#[inline]
fn first_crossing(o: f64, cell: i64, d: f64, res: f64) -> f64 {
    if d > 0.0 {
        ((cell + 1) as f64 * res - o) / d
    } else if d < 0.0 {
        (o - cell as f64 * res) / -d
    } else {
        f64::INFINITY
    }
}

/// Distance along the ray to the rectangle `rect`, if it hits within `max` (0 if the origin is
/// inside it).
pub fn ray_to_rect(
    rect: &Rect,
    (ox, oy): (f64, f64),
    (dx, dy): (f64, f64),
    max: f64,
) -> Option<f64> {
    let (ux, uy) = rect.u;
    let (px, py) = (ox - rect.centre.0, oy - rect.centre.1);
    // Origin and direction in the rectangle's frame.
    let (p, d) = (
        (px * ux + py * uy, -px * uy + py * ux),
        (dx * ux + dy * uy, -dx * uy + dy * ux),
    );
    let mut near = f64::NEG_INFINITY;
    let mut far = f64::INFINITY;
    for (p, d, h) in [(p.0, d.0, rect.half_length), (p.1, d.1, rect.half_width)] {
        if d.abs() < 1e-15 {
            if p.abs() > h {
                return None;
            }
        } else {
            let (a, b) = ((-h - p) / d, (h - p) / d);
            near = near.max(a.min(b));
            far = far.min(a.max(b));
        }
    }
    if far < near.max(0.0) {
        return None;
    }
    let t = near.max(0.0);
    (t < max).then_some(t)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::grid::OccupancyGrid;
    use proptest::test_runner::TestCaseError;

    /// Whether [`cell_along`] gives the cell of the exact quotient of `o + t*d` by `res`.
    fn is_the_quotient_s_cell(t: f64, o: f64, d: f64, res: f64) -> Result<(), TestCaseError> {
        let inv = 1.0 / res;
        let quotient = (o + t * d) / res;
        proptest::prop_assert_eq!(
            cell_along(t, o, d, (o * inv, d * inv), res),
            (quotient >= 0.0).then_some(quotient as i64)
        );
        Ok(())
    }

    proptest::proptest! {
        // Near a boundary the scaled terms and the quotient straddle it in a few cases in a
        // hundred at some resolutions (0.7 m), none at others.
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(8192))]

        #[test]
        fn the_cell_is_the_quotient_s_cell(
            p in -10.0f64..1.0e7, res in 0.001f64..2.0
        ) {
            is_the_quotient_s_cell(0.0, p, 0.0, res)?;
        }

        #[test]
        fn the_cell_is_the_quotient_s_cell_on_boundaries(
            k in 0i64..10_000_000, ulps in -4i64..=4, res in proptest::sample::select(
                vec![0.01, 0.02, 0.05, 0.1, 0.2, 0.25, 0.3, 0.5, 0.7, 1.0]
            )
        ) {
            // Points on and a few ulps either side of a cell boundary, where the product and
            // the quotient may truncate differently.
            let p = f64::from_bits(((k as f64) * res).to_bits().wrapping_add_signed(ulps));
            is_the_quotient_s_cell(0.0, p, 0.0, res)?;
        }

        #[test]
        fn the_cell_along_a_ray_is_the_quotient_s_cell(
            o in -5.0f64..1.0e4, angle in -3.2f64..3.2, t in 0.0f64..1000.0,
            res in proptest::sample::select(vec![0.01, 0.05, 0.1, 0.25, 0.7, 1.0])
        ) {
            is_the_quotient_s_cell(t, o, angle.cos(), res)?;
        }

        #[test]
        fn the_cell_along_a_ray_is_the_quotient_s_cell_on_boundaries(
            o in 0.0f64..100.0, angle in -3.2f64..3.2, k in 0i64..2000, ulps in -6i64..=6,
            res in proptest::sample::select(vec![0.01, 0.05, 0.1, 0.25, 0.7, 1.0])
        ) {
            // Distances that put the point on, or a few ulps either side of, a cell boundary,
            // including rays heading back toward the origin's side (cancellation).
            let d = angle.cos();
            proptest::prop_assume!(d.abs() > 1e-3);
            let t = ((k as f64 * res - o) / d).abs();
            let t = f64::from_bits(t.to_bits().wrapping_add_signed(ulps));
            is_the_quotient_s_cell(t, o, d, res)?;
        }
    }

    #[test]
    fn beams_span_the_field_of_view_edge_to_edge() {
        let b = LaserSpec::default().bearings();
        assert_eq!(b.len(), 181);
        assert_eq!(b[0], -std::f64::consts::FRAC_PI_2);
        assert!((b[180] - std::f64::consts::FRAC_PI_2).abs() < 1e-15);
        assert!((b[90]).abs() < 1e-15);
    }

    #[test]
    fn a_rectangle_is_hit_on_its_near_face() {
        let r = Rect {
            centre: (5.0, 0.0),
            u: (1.0, 0.0),
            half_length: 0.5,
            half_width: 0.25,
        };
        assert_eq!(ray_to_rect(&r, (0.0, 0.0), (1.0, 0.0), 10.0), Some(4.5));
        assert_eq!(ray_to_rect(&r, (0.0, 1.0), (1.0, 0.0), 10.0), None);
        assert_eq!(ray_to_rect(&r, (0.0, 0.0), (-1.0, 0.0), 10.0), None);
        assert_eq!(ray_to_rect(&r, (0.0, 0.0), (1.0, 0.0), 4.0), None);
    }

    #[test]
    fn the_grid_ray_stops_at_the_entry_of_the_first_occupied_cell() {
        let mut g = OccupancyGrid::filled(10, 10, false);
        g.set(5, 7, true); // x ∈ [0.7, 0.8], y ∈ [0.4, 0.5]
        let map = Map {
            grid: g,
            resolution_m: 0.1,
        };
        let t = RayGrid::new(&map, None).ray((0.05, 0.45), (1.0, 0.0), 10.0);
        assert!((t - 0.65).abs() < 1e-12, "{t}");
        assert_eq!(
            RayGrid::new(&map, None).ray((0.05, 0.15), (1.0, 0.0), 10.0),
            10.0
        );
    }

    #[test]
    fn a_ray_that_walks_off_any_edge_reads_its_maximum_range() {
        // 12 × 9 cells at 0.1 m, one occupied cell (x ∈ [0.4, 0.5], y ∈ [0.5, 0.6]); a 3 m
        // ray from inside either enters that cell or walks off an edge of the map (through
        // the ring of cells the table puts about it). Real clearances make the leaping table.
        let mut g = OccupancyGrid::filled(9, 12, false);
        g.set(3, 4, true);
        let clearance: Vec<f32> =
            crate::grid::distance::squared_distance_to(&g.cells, g.rows, g.cols)
                .iter()
                .map(|d2| (d2.sqrt() * 0.1) as f32)
                .collect();
        let map = Map {
            grid: g,
            resolution_m: 0.1,
        };
        let cell = Rect {
            centre: (0.45, 0.55),
            u: (1.0, 0.0),
            half_length: 0.05,
            half_width: 0.05,
        };
        let grids = [
            ("walking", RayGrid::new(&map, None)),
            ("leaping", RayGrid::new(&map, Some(&clearance))),
        ];
        let mut edges = 0;
        for origin in [(0.25, 0.15), (1.05, 0.75), (0.15, 0.85)] {
            for k in 0..64 {
                let a = k as f64 * std::f64::consts::PI / 32.0 + 0.01;
                let dir = (a.cos(), a.sin());
                let expected = ray_to_rect(&cell, origin, dir, 3.0).unwrap_or(3.0);
                edges += usize::from(expected == 3.0);
                for (name, grid) in &grids {
                    let t = grid.ray(origin, dir, 3.0);
                    assert!(
                        (t - expected).abs() < 1e-12,
                        "{name} ray from {origin:?} at {a}: {t}, expected {expected}"
                    );
                }
            }
        }
        assert!(edges > 150, "most rays leave the map: {edges}");
    }
}

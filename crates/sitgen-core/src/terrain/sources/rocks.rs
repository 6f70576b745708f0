//! # `rocks` source
//!
//! **What it makes.** An occupancy grid of scattered rocks on open ground: `density_per_100m2`
//! × area / 100 rocks (rounded), each centred uniformly at random on the map, with a size
//! drawn uniformly in [`radius_min_m`, `radius_max_m`], and shaped as a disc or a convex
//! polygon (by `shape`). A polygon has `vertices_min`…`vertices_max` corners at random angles
//! on an ellipse of that radius (axis ratio in [0.5, 1], random orientation), which makes it
//! convex by construction. Rocks may overlap into larger outcrops.
//!
//! **Why.** The paper's rocky desert: isolated obstacles of varied size and outline in open
//! space, where a controller's gap-finding and its speed near obstacles are tested.
//!
//! **Parameters.**
//! - `density_per_100m2` (rocks per 100 m², default 1.5, in [0, 1000]).
//! - `radius_min_m`, `radius_max_m` (metres, defaults 0.3 and 1.5, 0 < min ≤ max ≤ 1000).
//! - `shape` (`disc`, `polygon` or `mixed`, default `mixed`: each rock is either, evenly).
//! - `vertices_min`, `vertices_max` (count, defaults 5 and 9, 3 ≤ min ≤ max ≤ 32).
//!
//! **Source.** Poisson-like scattering of obstacles as in random-forest navigation benchmarks;
//! convexity from points on an ellipse (an affine image of a circle).

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::error::{join, SpecError};
use crate::grid::OccupancyGrid;
use crate::rng::ChoiceSource;
use crate::terrain::{Extent, Layer, LayerKind, Source};

/// The outline of each rock.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum RockShape {
    /// Discs only.
    Disc,
    /// Convex polygons only.
    Polygon,
    /// Each rock a disc or a polygon with equal probability.
    #[default]
    Mixed,
}

/// Parameters of the `rocks` source.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Rocks {
    /// Rocks per 100 square metres, in [0, 1000]. Default 1.5.
    #[serde(default = "default_density")]
    pub density_per_100m2: f64,
    /// Smallest rock radius, metres, in (0, 1000]. Default 0.3.
    #[serde(default = "default_radius_min_m")]
    pub radius_min_m: f64,
    /// Largest rock radius, metres, in [radius_min_m, 1000]. Default 1.5.
    #[serde(default = "default_radius_max_m")]
    pub radius_max_m: f64,
    /// `disc`, `polygon` or `mixed`. Default `mixed`.
    #[serde(default)]
    pub shape: RockShape,
    /// Fewest polygon corners, in [3, 32]. Default 5.
    #[serde(default = "default_vertices_min")]
    pub vertices_min: u32,
    /// Most polygon corners, in [vertices_min, 32]. Default 9.
    #[serde(default = "default_vertices_max")]
    pub vertices_max: u32,
}

fn default_density() -> f64 {
    1.5
}
fn default_radius_min_m() -> f64 {
    0.3
}
fn default_radius_max_m() -> f64 {
    1.5
}
fn default_vertices_min() -> u32 {
    5
}
fn default_vertices_max() -> u32 {
    9
}

impl Source for Rocks {
    fn output(&self) -> LayerKind {
        LayerKind::Occupancy
    }

    fn validate(&self, path: &str) -> Result<(), SpecError> {
        SpecError::check_in(
            &join(path, "density_per_100m2"),
            self.density_per_100m2,
            0.0,
            1000.0,
        )?;
        SpecError::check_positive(&join(path, "radius_min_m"), self.radius_min_m, 1000.0)?;
        SpecError::check_in(
            &join(path, "radius_max_m"),
            self.radius_max_m,
            self.radius_min_m,
            1000.0,
        )?;
        if !(3..=32).contains(&self.vertices_min) {
            return Err(SpecError::new(
                join(path, "vertices_min"),
                format!("{} is not in [3, 32]", self.vertices_min),
            ));
        }
        if !(self.vertices_min..=32).contains(&self.vertices_max) {
            return Err(SpecError::new(
                join(path, "vertices_max"),
                format!(
                    "{} is not in [{}, 32]",
                    self.vertices_max, self.vertices_min
                ),
            ));
        }
        Ok(())
    }

    fn generate(&self, extent: Extent, choices: &mut ChoiceSource) -> Result<Layer, String> {
        let res = extent.resolution_m;
        let (width_m, height_m) = (extent.cols as f64 * res, extent.rows as f64 * res);
        let count = (self.density_per_100m2 * width_m * height_m / 100.0).round() as usize;
        let mut grid = OccupancyGrid::filled(extent.rows, extent.cols, false);
        for _ in 0..count {
            let centre = (
                choices.uniform(0.0, width_m),
                choices.uniform(0.0, height_m),
            );
            let radius = choices.uniform(self.radius_min_m, self.radius_max_m);
            let polygon = match self.shape {
                RockShape::Disc => false,
                RockShape::Polygon => true,
                RockShape::Mixed => choices.chance(0.5),
            };
            if polygon {
                let corners = self.convex_polygon(centre, radius, choices);
                fill_where(&mut grid, res, centre, radius, |p| {
                    inside_convex(&corners, p)
                });
            } else {
                fill_where(&mut grid, res, centre, radius, |(x, y)| {
                    (x - centre.0).powi(2) + (y - centre.1).powi(2) <= radius * radius
                });
            }
        }
        Ok(Layer::Occupancy(grid))
    }
}

impl Rocks {
    /// Corners, counter-clockwise, at sorted random angles on a randomly oriented ellipse.
    fn convex_polygon(
        &self,
        centre: (f64, f64),
        radius: f64,
        choices: &mut ChoiceSource,
    ) -> Vec<(f64, f64)> {
        let n = choices.int_in(i64::from(self.vertices_min), i64::from(self.vertices_max)) as usize;
        let squash = choices.uniform(0.5, 1.0);
        let turn = choices.uniform(0.0, std::f64::consts::TAU);
        let mut angles: Vec<f64> = (0..n)
            .map(|_| choices.uniform(0.0, std::f64::consts::TAU))
            .collect();
        angles.sort_by(f64::total_cmp);
        let (s, c) = turn.sin_cos();
        angles
            .into_iter()
            .map(|a| {
                let (ex, ey) = (radius * a.cos(), radius * squash * a.sin());
                (centre.0 + c * ex - s * ey, centre.1 + s * ex + c * ey)
            })
            .collect()
    }
}

/// Whether `p` is inside (or on) the convex polygon with counter-clockwise `corners`.
fn inside_convex(corners: &[(f64, f64)], p: (f64, f64)) -> bool {
    (0..corners.len()).all(|i| {
        let a = corners[i];
        let b = corners[(i + 1) % corners.len()];
        (b.0 - a.0) * (p.1 - a.1) - (b.1 - a.1) * (p.0 - a.0) >= 0.0
    })
}

/// Occupy the cells within `radius` of `centre` (x from the left, y from the top, metres)
/// whose centre satisfies `inside`.
fn fill_where(
    grid: &mut OccupancyGrid,
    res: f64,
    centre: (f64, f64),
    radius: f64,
    inside: impl Fn((f64, f64)) -> bool,
) {
    let span = |lo: f64, n: usize| ((lo / res).floor().max(0.0) as usize).min(n);
    let (c0, c1) = (
        span(centre.0 - radius, grid.cols),
        span(centre.0 + radius + res, grid.cols),
    );
    let (r0, r1) = (
        span(centre.1 - radius, grid.rows),
        span(centre.1 + radius + res, grid.rows),
    );
    for r in r0..r1 {
        for c in c0..c1 {
            if inside(((c as f64 + 0.5) * res, (r as f64 + 0.5) * res)) {
                grid.set(r, c, true);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn polygons_are_convex() {
        let rocks = Rocks {
            density_per_100m2: 1.0,
            radius_min_m: 1.0,
            radius_max_m: 1.0,
            shape: RockShape::Polygon,
            vertices_min: 5,
            vertices_max: 9,
        };
        let mut choices = ChoiceSource::stream(11, "terrain");
        for _ in 0..200 {
            let corners = rocks.convex_polygon((5.0, 5.0), 1.0, &mut choices);
            // Every corner is on the hull: no corner lies strictly inside the others' polygon.
            for i in 0..corners.len() {
                let mut others = corners.clone();
                let p = others.remove(i);
                assert!(!inside_convex(&others, p) || others.len() < 3);
            }
        }
    }
}

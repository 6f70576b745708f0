//! # `coverage` filter
//!
//! **What it does.** Thresholds a scalar field at the level that makes the *finished* map
//! (after this filter and every filter after it) have an occupied fraction of `target`, and
//! fails if no level brings it within `tolerance`. Given an occupancy grid, it thresholds the
//! grid's signed distance field instead (metres from the nearest obstacle edge, positive
//! inside obstacles), which grows or shrinks every obstacle by the same distance until the
//! target is met: caves get wider or narrower passages, rocks bigger or smaller.
//!
//! **Why.** Obstacle density is the parameter a tester thinks in ("30 % of the ground is
//! blocked"), while the level that gives it depends on the seed. The paper's tool varied the
//! threshold at random until the coverage was acceptable; here it is found directly:
//! 1. *rank the field*: occupying the k highest cells means thresholding at the k-th highest
//!    value (cells with equal values go together, so only the ends of runs of equal values
//!    are reachable); each rank the search asks for is selected, not the whole field sorted;
//! 2. *no filter after it*: the threshold is the ranked value at k = target × cells, or the
//!    next distinct value, whichever count is closer: the closest coverage any threshold can
//!    give, found with at most two thresholdings;
//! 3. *filters after it* (dilate, border, keep_largest_free_region… change coverage): a
//!    bracketing secant search on k, running the rest of the chain at each step, stops when the
//!    finished coverage is within a quarter of the tolerance of the target, or when the bracket
//!    closes on two adjacent reachable thresholds; the closest result seen is kept.
//!
//! **Parameters.**
//! - `target` (fraction, required, in [0, 1]): wanted occupied fraction of the finished map.
//! - `tolerance` (fraction, default 0.01, in [0, 1]): largest accepted |coverage − target|.
//!
//! **Source.** Arnold & Alexander (2013) §3, the coverage constraint wrapped around the
//! thresholding filter.

use std::cell::RefCell;

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::binarize;
use crate::error::{join, SpecError};
use crate::grid::distance::squared_distance_to;
use crate::grid::{OccupancyGrid, ScalarField};
use crate::terrain::{Filter, Layer, LayerKind};

/// Most evaluations of the rest of the chain that the search makes.
const MAX_EVALUATIONS: usize = 24;

/// Parameters of the `coverage` filter.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Coverage {
    /// Wanted occupied fraction of the finished map, in [0, 1]. Required.
    pub target: f64,
    /// Largest accepted difference between achieved and wanted fraction, in [0, 1].
    /// Default 0.01.
    #[serde(default = "default_tolerance")]
    pub tolerance: f64,
}

fn default_tolerance() -> f64 {
    0.01
}

/// The result of the search.
#[derive(Debug, Clone)]
pub struct Found<T> {
    /// The chosen level: cells at or above it are occupied.
    pub threshold: f64,
    /// Occupied fraction right after thresholding.
    pub threshold_coverage: f64,
    /// The finished map.
    pub finished: OccupancyGrid,
    /// What the rest of the chain reported.
    pub rest: T,
    /// How many thresholds were tried (each runs the rest of the chain once).
    pub evaluations: usize,
}

impl Filter for Coverage {
    fn accepts(&self, _input: LayerKind) -> bool {
        true
    }

    fn output(&self, _input: LayerKind) -> LayerKind {
        LayerKind::Occupancy
    }

    fn validate(&self, path: &str) -> Result<(), SpecError> {
        SpecError::check_in(&join(path, "target"), self.target, 0.0, 1.0)?;
        SpecError::check_in(&join(path, "tolerance"), self.tolerance, 0.0, 1.0)
    }

    /// The closest thresholding, tolerance aside; the chain runner calls [`Coverage::search`]
    /// instead, so that later filters are accounted for and a missed tolerance is reported.
    fn apply(&self, layer: Layer, resolution_m: f64) -> Layer {
        let field = level_field(layer, resolution_m);
        let any = Coverage {
            tolerance: 1.0,
            ..self.clone()
        };
        match any.search(&field, false, |g| (g, ())) {
            Ok(found) => Layer::Occupancy(found.finished),
            Err(_) => unreachable!("every coverage is within 1 of the target"),
        }
    }
}

/// The field the threshold is searched on: the layer itself, or an occupancy grid's signed
/// distance field in metres (cell centre to the nearest cell of the other state, less half a
/// cell, so that level 0 gives back the grid unchanged).
pub fn level_field(layer: Layer, resolution_m: f64) -> ScalarField {
    match layer {
        Layer::Field(f) => f,
        Layer::Occupancy(g) => {
            let free: Vec<bool> = g.cells.iter().map(|&c| !c).collect();
            let to_free = squared_distance_to(&free, g.rows, g.cols);
            let to_occupied = squared_distance_to(&g.cells, g.rows, g.cols);
            let values = g
                .cells
                .iter()
                .zip(to_free.iter().zip(&to_occupied))
                .map(|(&occupied, (&df, &dobs))| {
                    let cells = if occupied {
                        df.sqrt() - 0.5
                    } else {
                        0.5 - dobs.sqrt()
                    };
                    cells * resolution_m
                })
                .collect();
            ScalarField {
                cols: g.cols,
                rows: g.rows,
                values,
            }
        }
    }
}

/// The field's values by rank, highest first, and what thresholding at a rank gives.
///
/// A search asks for a handful of ranks, so each is selected (O(cells)) rather than the whole
/// field sorted (O(cells · log cells): 3 % of the default campaign's CPU when it sorted).
struct Ranking<'a> {
    field: &'a ScalarField,
    /// The field's values, reordered by every selection made so far (each leaves the values
    /// partitioned around its rank, which makes the next selection nearby cheaper).
    values: RefCell<Vec<f64>>,
}

impl<'a> Ranking<'a> {
    fn rank_field(field: &'a ScalarField) -> Self {
        Self {
            field,
            values: RefCell::new(field.values.clone()),
        }
    }

    fn cells(&self) -> usize {
        self.field.values.len()
    }

    /// The level that occupies the `k` highest cells (and their equals): +∞ for k = 0.
    fn threshold_at(&self, k: usize) -> f64 {
        if k == 0 {
            f64::INFINITY
        } else {
            let mut values = self.values.borrow_mut();
            *values
                .select_nth_unstable_by(k - 1, |a, b| b.total_cmp(a))
                .1
        }
    }

    /// How many cells thresholding at `level` occupies.
    fn count_at_or_above(&self, level: f64) -> usize {
        self.field.values.iter().filter(|&&v| v >= level).count()
    }

    /// The reachable count nearest below or at `k` (the end of the previous run of equals).
    fn count_above(&self, level: f64) -> usize {
        self.field.values.iter().filter(|&&v| v > level).count()
    }

    fn binarize(&self, level: f64) -> OccupancyGrid {
        binarize(self.field, level)
    }
}

/// One evaluated candidate: reachable count k, its level and the finished coverage.
struct Probe<T> {
    k: usize,
    level: f64,
    error: f64,
    threshold_coverage: f64,
    finished: OccupancyGrid,
    rest: T,
}

impl Coverage {
    /// Find the threshold whose finished map is closest to the target; `finish` runs the rest
    /// of the chain on a thresholded grid.
    pub fn search<T>(
        &self,
        field: &ScalarField,
        has_later_filters: bool,
        finish: impl Fn(OccupancyGrid) -> (OccupancyGrid, T),
    ) -> Result<Found<T>, String> {
        let ranking = Ranking::rank_field(field);
        let n = ranking.cells();
        let evaluate = |k: usize| -> Probe<T> {
            let level = ranking.threshold_at(k);
            let k = if k == 0 {
                0
            } else {
                ranking.count_at_or_above(level)
            };
            let binary = ranking.binarize(level);
            let threshold_coverage = k as f64 / n as f64;
            let (finished, rest) = finish(binary);
            Probe {
                k,
                level,
                error: finished.coverage() - self.target,
                threshold_coverage,
                finished,
                rest,
            }
        };
        let wanted = ((self.target * n as f64).round() as usize).min(n);
        let mut best = evaluate(wanted);
        let mut probes: Vec<(usize, f64)> = vec![(best.k, best.error)];
        let consider = |p: Probe<T>, best: &mut Probe<T>, probes: &mut Vec<(usize, f64)>| {
            probes.push((p.k, p.error));
            if p.error.abs() < best.error.abs() {
                *best = p;
            }
        };
        // The run of equal values containing rank `wanted` splits into "all of it" (best.k)
        // and "none of it": the other reachable count nearest the target. With no later
        // filter the nearer of the two is the answer.
        if !has_later_filters {
            let below = if wanted == 0 {
                0
            } else {
                ranking.count_above(ranking.threshold_at(wanted))
            };
            if below != best.k {
                let p = evaluate(below);
                consider(p, &mut best, &mut probes);
            }
        }
        let good_enough = self.tolerance / 4.0;
        while has_later_filters && best.error.abs() > good_enough && probes.len() < MAX_EVALUATIONS
        {
            let Some(k) = next_rank(&probes, n) else {
                break;
            };
            let p = evaluate(k);
            if probes.iter().any(|&(seen, _)| seen == p.k) {
                break;
            }
            consider(p, &mut best, &mut probes);
        }
        if best.error.abs() > self.tolerance {
            return Err(format!(
                "coverage {} ± {} cannot be reached: the closest is {:.4} (threshold {:.4}); the filters after it change coverage too much, or the field has too few distinct values",
                self.target,
                self.tolerance,
                best.error + self.target,
                best.level
            ));
        }
        Ok(Found {
            threshold: best.level,
            threshold_coverage: best.threshold_coverage,
            finished: best.finished,
            rest: best.rest,
            evaluations: probes.len(),
        })
    }
}

/// The next rank to try: a secant step between the closest probes on either side of the
/// target if they exist (kept strictly inside the bracket), else a secant extrapolation from
/// the two closest probes, else a step of the error's size. `None` when the bracket is closed.
fn next_rank(probes: &[(usize, f64)], n: usize) -> Option<usize> {
    let below = probes
        .iter()
        .filter(|p| p.1 < 0.0)
        .min_by(|a, b| b.1.total_cmp(&a.1));
    let above = probes
        .iter()
        .filter(|p| p.1 > 0.0)
        .min_by(|a, b| a.1.total_cmp(&b.1));
    let secant = |(k0, e0): (usize, f64), (k1, e1): (usize, f64)| -> f64 {
        if e1 == e0 {
            k1 as f64
        } else {
            k1 as f64 - e1 * (k1 as f64 - k0 as f64) / (e1 - e0)
        }
    };
    match (below, above) {
        (Some(&b), Some(&a)) => {
            let (lo, hi) = (b.0.min(a.0), b.0.max(a.0));
            if hi - lo <= 1 {
                return None;
            }
            let guess = secant(b, a).round() as usize;
            let mid = lo + (hi - lo) / 2;
            // Alternate secant and bisection so that a flat side cannot stall the bracket.
            let k = if probes.len().is_multiple_of(2) {
                mid
            } else {
                guess
            };
            Some(k.clamp(lo + 1, hi - 1))
        }
        _ => {
            let last = *probes.last()?;
            let k = if probes.len() >= 2 {
                let prev = probes[probes.len() - 2];
                secant(prev, last)
            } else {
                last.0 as f64 - last.1 * n as f64
            };
            let k = k.round().clamp(0.0, n as f64) as usize;
            // Step at least one rank, in the direction that moves coverage toward the target.
            Some(if k == last.0 {
                if last.1 > 0.0 {
                    last.0.saturating_sub(1)
                } else {
                    (last.0 + 1).min(n)
                }
            } else {
                k
            })
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        /// Ranks selected one after another, on values with many ties, are the fully sorted
        /// field's, and the counts are its partition points.
        #[test]
        fn selected_ranks_are_the_sorted_field_s(
            values in prop::collection::vec((-3i32..4).prop_map(|v| v as f64 * 0.25), 1..300),
            asks in prop::collection::vec(0usize..400, 1..12),
        ) {
            let field = ScalarField { rows: 1, cols: values.len(), values };
            let mut sorted = field.values.clone();
            sorted.sort_unstable_by(|a, b| b.total_cmp(a));
            let ranking = Ranking::rank_field(&field);
            for k in asks.into_iter().map(|k| k % (sorted.len() + 1)) {
                let level = ranking.threshold_at(k);
                prop_assert_eq!(level, if k == 0 { f64::INFINITY } else { sorted[k - 1] });
                prop_assert_eq!(
                    ranking.count_at_or_above(level),
                    sorted.partition_point(|&v| v >= level)
                );
                prop_assert_eq!(ranking.count_above(level), sorted.partition_point(|&v| v > level));
            }
        }
    }

    fn ramp(n: usize) -> ScalarField {
        ScalarField {
            rows: 1,
            cols: n,
            values: (0..n).map(|i| i as f64 / n as f64).collect(),
        }
    }

    #[test]
    fn without_later_filters_the_target_is_met_exactly() {
        let c = Coverage {
            target: 0.37,
            tolerance: 0.0,
        };
        let found = c.search(&ramp(100), false, |g| (g, ())).unwrap();
        assert_eq!(found.finished.occupied_count(), 37);
        assert_eq!(found.threshold, 0.63);
    }

    #[test]
    fn ties_pick_the_nearer_end_of_the_run() {
        let field = ScalarField {
            rows: 1,
            cols: 10,
            values: vec![0.0, 0.0, 0.0, 0.5, 0.5, 0.5, 0.5, 0.5, 0.5, 1.0],
        };
        let c = Coverage {
            target: 0.3,
            tolerance: 0.5,
        };
        // Reachable counts: 0, 1, 7, 10; 0.3 → 3 cells, nearest reachable is 1.
        let found = c.search(&field, false, |g| (g, ())).unwrap();
        assert_eq!(found.finished.occupied_count(), 1);
    }

    #[test]
    fn later_filters_are_accounted_for() {
        // A later filter that always adds 20 occupied cells at the end.
        let add20 = |mut g: OccupancyGrid| {
            let n = g.cells.len();
            g.cells[n - 20..].fill(true);
            (g, ())
        };
        let c = Coverage {
            target: 0.5,
            tolerance: 0.001,
        };
        let field = ScalarField {
            rows: 1,
            cols: 1000,
            values: (0..1000).map(|i| ((i * 7919) % 1000) as f64).collect(),
        };
        let found = c.search(&field, true, add20).unwrap();
        assert!((found.finished.coverage() - 0.5).abs() <= 0.001);
        assert!(found.threshold_coverage < 0.5);
    }

    #[test]
    fn on_an_occupancy_grid_obstacles_grow_to_the_target() {
        let mut g = OccupancyGrid::filled(41, 41, false);
        g.set(20, 20, true);
        let c = Coverage {
            target: 0.1,
            tolerance: 0.01,
        };
        let field = level_field(Layer::Occupancy(g.clone()), 0.1);
        assert_eq!(binarize(&field, 0.0), g);
        let found = c.search(&field, false, |g| (g, ())).unwrap();
        assert!((found.finished.coverage() - 0.1).abs() <= 0.01);
        assert!(found.finished.get(20, 20) && found.threshold < 0.0);
    }

    #[test]
    fn an_unreachable_target_fails_with_the_closest() {
        let c = Coverage {
            target: 0.1,
            tolerance: 0.01,
        };
        let all = |mut g: OccupancyGrid| {
            g.cells.fill(true);
            (g, ())
        };
        let err = c.search(&ramp(50), true, all).unwrap_err();
        assert!(err.contains("closest is 1.0000"), "{err}");
    }
}

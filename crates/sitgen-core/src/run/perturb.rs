//! # Perturbations
//!
//! **What it does.** Makes rerun `k` of a run a copy that a real robot could not tell from the
//! run itself: the laser's ranges carry Gaussian noise at the sensor's datasheet level, and
//! every robot starts a little off its situation's start (a uniform offset in a disc, and a
//! uniform turn). A run spec asks for it with a `perturbation` table; everything else about
//! the run (situation, controllers, peers, time limit) is the run's own. Each copy is drawn
//! from the run's seed and `rerun`, so a figure computed from copies is reproducible.
//!
//! **Why.** A run is deterministic to the bit and still chaotic: a controller nudged by a
//! rounding error can fail with another class. A failure that recurs in most perturbed copies
//! is a weakness of the controller (robust); one that vanishes is knife-edge. The robustness
//! of a failure, the fault yardstick's kill rule and `sitgen diff` all count recurrences over
//! these copies (`docs/failures.md`, `docs/faults.md`). They are defined here, once.
//!
//! **Parameters** (the `perturbation` table of a run spec):
//! - `rerun`: which copy, in [1, 1000]; copy k of a run is always the same copy.
//! - `laser_noise_sd_m`: standard deviation of the range noise, metres, in [0, 0.1]. Default
//!   0.005: the SICK LMS200's statistical error (1σ) in its millimetre mode, up to 8 m. A spec
//!   whose laser already has more noise keeps its own.
//! - `start_position_m`: largest start offset, metres, in [0, 0.1]. Default 0.01: a robot put
//!   down by hand on a mark, or localised by a good AMCL, is a centimetre off.
//! - `start_heading_deg`: largest start turn, degrees, in [0, 5]. Default 0.5: what a
//!   centimetre's offset does to a heading taken from two marks half a metre apart, and about
//!   a Pioneer's odometry after a metre of travel.
//! - `horizon_s`: simulated seconds after which the copy stops, unfinished (outcome
//!   `stopped`, no timeout event), in (0, 86400]. Default none: the run's own time limit. A
//!   robustness copy asks whether a failure shows again near where it showed in the run, so
//!   it is watched only that far (`python/sitgen/triage/robustness.py` says how far); the
//!   controllers are not told, and everything before the horizon is the copy run to its
//!   limit.
//! - `watch_for`: a failure class. With it, a copy past its horizon stops only once it has
//!   shown that class or a more severe one, else runs to its time limit: the absence of a
//!   failure by the horizon is no evidence (it may show late); its presence, or a worse one,
//!   decides the copy. Default none.
//!
//! A robot whose jittered start would overlap an obstacle or another robot starts where the
//! situation puts it (the copy must be a situation the generator could have made).
//!
//! **Source.** SICK LMS200 technical description (statistical error 5 mm, 1σ); Stage 4.3's
//! ranger noise model (`reference/algorithms.md` §2.5), whose constant term is the same
//! Gaussian on hits; the start sizes are set well below anything a robot's own localisation
//! would notice, so a failure that does not survive them is the run's chaos, not the
//! controller's weakness.

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::error::{join, SpecError};
use crate::failure::FailureClass;
use crate::rng::ChoiceSource;
use crate::sim::{wrap_angle, SimSpec, World};
use crate::situation::{Pose, Situation};

/// Default range noise, metres: the LMS200's 1σ statistical error.
pub const LASER_NOISE_SD_M: f64 = 0.005;
/// Default largest start offset, metres.
pub const START_POSITION_M: f64 = 0.01;
/// Default largest start turn, degrees.
pub const START_HEADING_DEG: f64 = 0.5;
/// Most copies of one run.
pub const MAX_RERUN: u32 = 1000;

/// The random stream a copy's start offsets are drawn from.
const STREAM: &str = "perturbation";

/// Which perturbed copy of a run to make, and how large its perturbations are.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Perturbation {
    /// Which copy, in [1, 1000].
    pub rerun: u32,
    /// Range noise (1σ), metres, in [0, 0.1]. Default 0.005 (SICK LMS200).
    #[serde(default = "default_laser_noise_sd_m")]
    pub laser_noise_sd_m: f64,
    /// Largest start offset, metres, in [0, 0.1]. Default 0.01.
    #[serde(default = "default_start_position_m")]
    pub start_position_m: f64,
    /// Largest start turn, degrees, in [0, 5]. Default 0.5.
    #[serde(default = "default_start_heading_deg")]
    pub start_heading_deg: f64,
    /// Simulated seconds after which the copy stops unfinished, in (0, 86400]. Default none:
    /// the run's time limit.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub horizon_s: Option<f64>,
    /// With `horizon_s`: past it, stop once the run has shown this class or a more severe
    /// one. Default none: stop at the horizon.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub watch_for: Option<FailureClass>,
}

fn default_laser_noise_sd_m() -> f64 {
    LASER_NOISE_SD_M
}
fn default_start_position_m() -> f64 {
    START_POSITION_M
}
fn default_start_heading_deg() -> f64 {
    START_HEADING_DEG
}

impl Perturbation {
    /// Copy `rerun` at the default sizes.
    pub fn copy(rerun: u32) -> Self {
        Self {
            rerun,
            laser_noise_sd_m: LASER_NOISE_SD_M,
            start_position_m: START_POSITION_M,
            start_heading_deg: START_HEADING_DEG,
            horizon_s: None,
            watch_for: None,
        }
    }

    /// Check every field; `path` names the table in errors.
    pub fn validate(&self, path: &str) -> Result<(), SpecError> {
        if !(1..=MAX_RERUN).contains(&self.rerun) {
            return Err(SpecError::new(
                join(path, "rerun"),
                format!("{} is not in [1, {MAX_RERUN}]", self.rerun),
            ));
        }
        SpecError::check_in(
            &join(path, "laser_noise_sd_m"),
            self.laser_noise_sd_m,
            0.0,
            0.1,
        )?;
        SpecError::check_in(
            &join(path, "start_position_m"),
            self.start_position_m,
            0.0,
            0.1,
        )?;
        SpecError::check_in(
            &join(path, "start_heading_deg"),
            self.start_heading_deg,
            0.0,
            5.0,
        )?;
        match (self.horizon_s, self.watch_for) {
            (Some(h), _) => SpecError::check_positive(&join(path, "horizon_s"), h, 86_400.0),
            (None, Some(_)) => Err(SpecError::new(
                join(path, "watch_for"),
                "needs a horizon_s to watch past",
            )),
            (None, None) => Ok(()),
        }
    }

    /// The copy's seed: the run's seed and the copy's number mixed (SplitMix64's finaliser),
    /// so copies of one run, and copies of runs with nearby seeds, share no stream.
    pub fn seed(&self, run_seed: u64) -> u64 {
        let mut z = run_seed ^ u64::from(self.rerun).wrapping_mul(0x9E37_79B9_7F4A_7C15);
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// The simulator of the copy: the run's, with at least this much range noise.
    pub fn sim(&self, sim: &SimSpec) -> SimSpec {
        let mut sim = sim.clone();
        sim.laser.noise_sd_m = sim.laser.noise_sd_m.max(self.laser_noise_sd_m);
        sim
    }

    /// Move every robot of `world` (at its start) to its jittered start, drawn from
    /// `copy_seed` ([`Perturbation::seed`]), where it can stand; `situation` with the starts
    /// the robots got.
    pub fn jitter_starts(
        &self,
        situation: &Situation,
        world: &mut World,
        copy_seed: u64,
    ) -> Situation {
        let mut choices = ChoiceSource::stream(copy_seed, STREAM);
        let mut jittered = situation.clone();
        for robot in &mut jittered.robots {
            // Three draws per robot whether or not it moves, so one robot's start never
            // changes another's.
            let radius = self.start_position_m * choices.unit().sqrt();
            let bearing = choices.uniform(-std::f64::consts::PI, std::f64::consts::PI);
            let turn = choices.uniform(-1.0, 1.0) * self.start_heading_deg.to_radians();
            let s = robot.start;
            let pose = Pose {
                x_m: s.x_m + radius * bearing.cos(),
                y_m: s.y_m + radius * bearing.sin(),
                heading_rad: wrap_angle(s.heading_rad + turn),
            };
            if world.place_at_start(robot.id as usize, pose) {
                robot.start = pose;
            }
        }
        jittered
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn copies_have_distinct_seeds() {
        let seeds: std::collections::BTreeSet<u64> = (1..=64)
            .flat_map(|k| (0..16).map(move |s| Perturbation::copy(k).seed(s)))
            .collect();
        assert_eq!(seeds.len(), 64 * 16);
    }

    #[test]
    fn sim_keeps_more_noise_than_the_copy_asks() {
        let mut sim = SimSpec::default();
        assert_eq!(
            Perturbation::copy(1).sim(&sim).laser.noise_sd_m,
            LASER_NOISE_SD_M
        );
        sim.laser.noise_sd_m = 0.03;
        assert_eq!(Perturbation::copy(1).sim(&sim).laser.noise_sd_m, 0.03);
    }

    #[test]
    fn validate_names_the_field() {
        let mut p = Perturbation::copy(0);
        assert!(p
            .validate("run.perturbation")
            .unwrap_err()
            .to_string()
            .contains("run.perturbation.rerun"));
        p.rerun = 3;
        p.start_heading_deg = f64::NAN;
        assert!(p
            .validate("run.perturbation")
            .unwrap_err()
            .to_string()
            .contains("start_heading_deg"));
    }
}

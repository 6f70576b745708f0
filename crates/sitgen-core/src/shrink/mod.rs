//! Shrink probes: whether a candidate situation is one the generator could have made, what it
//! does when run, and where a run's robots stand part-way through.
//!
//! Shrinking (`python/sitgen/shrink.py`, `docs/shrink.md`) reduces a failing situation by delta
//! debugging; each candidate it tries is checked here and, if valid, run once. A candidate is
//! *valid* when it reads as a situation file does (every route point on free ground inside the
//! map), every robot starts clear of obstacles, of the map's edge and of the others (the
//! simulator's own start check), and every peer leg is clear on the map dilated by the
//! mission's `plan_margin_m`, as generated peer legs are. That last rule applies only where the
//! original situation keeps it (a hand-made or benchmark situation may not), so shrinking never
//! refuses a candidate for something the original does too. An invalid candidate is skipped,
//! not run.
//!
//! A probe is an ordinary deterministic run ([`crate::run::run`]); batches run across threads
//! with results in candidate order, so the same input shrinks the same way on any thread count.

use crate::failure::{self, FailureClass};
use crate::mission;
use crate::run::{self, Outcome, RunSpec};
use crate::situation::{Robot, Situation};

/// What a probe's run did.
#[derive(Debug, Clone, PartialEq)]
pub struct Probe {
    /// The run's failure class, `None` if it did not fail.
    pub class: Option<FailureClass>,
    /// Every class its events show, most severe first, with when the first event of each
    /// began (simulated seconds).
    pub first_s: Vec<(FailureClass, f64)>,
    /// How long the run lasted, simulated seconds.
    pub time_s: f64,
    /// How it ended.
    pub outcome: Outcome,
    /// The run spec's requirements it violated, with when each violation began (seconds).
    pub violated: Vec<(String, f64)>,
}

/// The margin peer legs of candidates shrunk from `original` must keep: the mission's
/// `plan_margin_m` if every peer leg of the original keeps it, else `None` (no leg rule).
pub fn leg_margin(original: &Situation) -> Option<f64> {
    let margin = original.provenance.spec.mission.plan_margin_m;
    let map = original.map.decode().ok()?;
    mission::check_peer_legs(&map, margin, &original.robots)
        .is_ok()
        .then_some(margin)
}

/// Check a candidate: the error says why it is not a situation the generator could make.
pub fn check(candidate: &Situation, leg_margin_m: Option<f64>) -> Result<(), String> {
    candidate.validate().map_err(|e| e.to_string())?;
    crate::sim::check_start(candidate).map_err(|e| e.to_string())?;
    if let Some(margin) = leg_margin_m {
        let map = candidate.map.decode().map_err(|e| e.to_string())?;
        mission::check_peer_legs(&map, margin, &candidate.robots)?;
    }
    Ok(())
}

/// Check a candidate and, if it is valid, run it; `Err` says why it was skipped.
pub fn probe(
    candidate: &Situation,
    spec: &RunSpec,
    seed: u64,
    leg_margin_m: Option<f64>,
) -> Result<Probe, String> {
    check(candidate, leg_margin_m)?;
    let record = run::run(candidate, spec, seed).map_err(|e| e.to_string())?;
    // The agent is robot 0 of every valid situation.
    Ok(Probe {
        class: record.failure.map(|f| f.class),
        first_s: failure::first_seen(&record.events, 0),
        time_s: record.time_s,
        outcome: record.outcome,
        violated: record
            .requirements
            .iter()
            .filter(|v| v.violated)
            .map(|v| (v.name.clone(), v.first_violation_s.unwrap_or(0.0)))
            .collect(),
    })
}

/// [`probe`] every candidate on `threads` threads; results in candidate order.
pub fn probe_batch(
    candidates: &[Situation],
    spec: &RunSpec,
    seed: u64,
    leg_margin_m: Option<f64>,
    threads: usize,
) -> Vec<Result<Probe, String>> {
    run::par_map(candidates, threads, |c| probe(c, spec, seed, leg_margin_m))
}

/// The robots of `situation` as they stand `t_s` simulated seconds into its run (each at its
/// pose, at rest, with the rest of its route): the robots of a situation that starts later.
pub fn robots_at(
    situation: &Situation,
    spec: &RunSpec,
    seed: u64,
    t_s: f64,
) -> Result<Vec<Robot>, String> {
    let mut r = run::Run::new(situation, spec, seed).map_err(|e| e.to_string())?;
    if r.any_external() {
        return Err("Python and external controllers cannot be restarted part-way".into());
    }
    let steps = (t_s / spec.sim.dt_s).round().max(0.0) as u64;
    while r.world().steps() < steps && !r.step(None) {}
    Ok(r.robots_now(situation))
}

#[cfg(test)]
mod tests;

//! Episodes: runs whose agent is driven from outside one decision at a time, many side by side
//! (the Gymnasium environment of the Python layer, `sitgen.gym`, is a thin skin over this).
//!
//! Each slot holds one run. A step takes one command per slot and advances each live run by
//! the agent's control period (one simulator step unless its `control_period_s` says more; the
//! command stays in force over it), on a thread pool, each run on its own: the result of a slot
//! never depends on the others or on the thread count. It reports what a learner is rewarded
//! and told with: the metres of route the agent made good (its distance to go along the route
//! before less after), the penalty points it earned ([`Run::penalty_so_far`] after less
//! before), the events that began, and how the run ended, if it did.

use super::{Command, Outcome, Run, RunRecord, RunSpec};
use crate::control::period_steps;
use crate::error::SpecError;
use crate::mission::ControllerSpec;
use crate::monitor::Event;
use crate::sim::Observation;
use crate::situation::Situation;

/// The controller name the agent of an episode runs under: external, so that its commands come
/// from the caller.
pub const AGENT: &str = "python:sitgen.gym:agent";

/// What the agent senses at the start of a decision, with where it is headed.
#[derive(Debug, Clone, PartialEq)]
pub struct EpisodeObservation {
    /// The agent's observation (laser, pose, velocity, ...).
    pub observation: Observation,
    /// The next waypoint to reach in the agent's frame (x ahead, y to the left), metres; (0, 0)
    /// once the route is complete.
    pub goal: (f64, f64),
}

/// What one step of one episode gave.
#[derive(Debug, Clone, PartialEq)]
pub struct EpisodeStep {
    /// Route made good over the step, metres (negative when the agent lost ground).
    pub progress_m: f64,
    /// Penalty points earned over the step (the run's scoring table).
    pub penalty: f64,
    /// Events that began during the step (those still lasting have no end yet).
    pub events: Vec<Event>,
    /// How the run ended, if it ended during this step or before.
    pub ended: Option<Outcome>,
    /// What the agent senses after the step (sensed on the step's thread, beside the run).
    pub observation: EpisodeObservation,
}

struct Episode {
    run: Run,
    to_go_m: f64,
    penalty: f64,
    events_seen: usize,
}

/// A batch of episodes stepped together.
pub struct Episodes {
    spec: RunSpec,
    steps_per_decision: u64,
    slots: Vec<Option<Episode>>,
    pool: Option<rayon::ThreadPool>,
}

impl Episodes {
    /// `n` empty slots for runs under `spec` (whose agent controller, if it names one, gives
    /// only its `control_period_s`: the commands come from the caller), stepped on `threads`
    /// threads.
    pub fn new(spec: &RunSpec, n: usize, threads: usize) -> Result<Self, SpecError> {
        let mut spec = spec.clone();
        let period = spec.controller.as_ref().and_then(|c| c.control_period_s);
        spec.controller = Some(ControllerSpec {
            control_period_s: period,
            ..ControllerSpec::named(AGENT)
        });
        spec.validate("run")?;
        let steps_per_decision = period_steps(
            spec.controller.as_ref().expect("set above"),
            spec.sim.dt_s,
            "run.controller",
        )?;
        let pool = (n > 1 && threads > 1).then(|| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .expect("a thread pool")
        });
        Ok(Self {
            spec,
            steps_per_decision,
            slots: (0..n).map(|_| None).collect(),
            pool,
        })
    }

    /// How many slots.
    pub fn len(&self) -> usize {
        self.slots.len()
    }

    /// Whether there are no slots.
    pub fn is_empty(&self) -> bool {
        self.slots.is_empty()
    }

    /// The run spec every episode runs under.
    pub fn spec(&self) -> &RunSpec {
        &self.spec
    }

    /// Simulator steps per decision (the agent's control period).
    pub fn steps_per_decision(&self) -> u64 {
        self.steps_per_decision
    }

    /// Start slot `i` afresh on `situation`, sensor noise from `seed`.
    pub fn reset(&mut self, i: usize, situation: &Situation, seed: u64) -> Result<(), SpecError> {
        let run = Run::new(situation, &self.spec, seed)?;
        if let Some(&peer) = run.external().iter().find(|&&id| id != run.agent()) {
            return Err(SpecError::new(
                format!("robots[{peer}].controller.name"),
                "an episode's peers run built-in controllers (a peer's python: or navground: \
                 controller is driven by sitgen.run, not by a step of the environment)",
            ));
        }
        self.slots[i] = Some(Episode {
            to_go_m: to_go_m(&run, &run.agent_route_ahead()),
            penalty: 0.0,
            events_seen: 0,
            run,
        });
        Ok(())
    }

    /// What the agent of slot `i` senses now; `None` for an empty slot.
    pub fn observe(&mut self, i: usize) -> Option<EpisodeObservation> {
        self.slots[i].as_mut().map(|e| {
            let ahead = e.run.agent_route_ahead();
            sense(&mut e.run, &ahead)
        })
    }
    /// One decision in every slot: `commands[i]` drives slot `i` for the agent's control
    /// period. An empty slot gives `None`; a run that has ended stays where it ended and
    /// reports its outcome again, with nothing gained.
    pub fn step(&mut self, commands: &[Command]) -> Vec<Option<EpisodeStep>> {
        assert_eq!(commands.len(), self.slots.len(), "one command per slot");
        let k = self.steps_per_decision;
        let one = |(slot, &command): (&mut Option<Episode>, &Command)| {
            slot.as_mut().map(|e| e.decide(command, k))
        };
        match &self.pool {
            Some(pool) => {
                use rayon::prelude::*;
                pool.install(|| {
                    self.slots
                        .par_iter_mut()
                        .zip(commands.par_iter())
                        .map(one)
                        .collect()
                })
            }
            None => self.slots.iter_mut().zip(commands).map(one).collect(),
        }
    }

    /// End slot `i`'s run and empty the slot: its record, as any run's.
    pub fn finish(&mut self, i: usize) -> Option<RunRecord> {
        self.slots[i].take().map(|e| e.run.finish())
    }
}

/// What the agent of `run` senses now, with the next of the waypoints `ahead` (the route it has
/// yet to reach) in its own frame.
fn sense(run: &mut Run, ahead: &[(f64, f64)]) -> EpisodeObservation {
    let observation = run.agent_observation();
    let pose = observation.pose;
    let goal = ahead.first().map_or((0.0, 0.0), |&(x, y)| {
        let (dx, dy) = (x - pose.x_m, y - pose.y_m);
        let (s, c) = pose.heading_rad.sin_cos();
        (c * dx + s * dy, -s * dx + c * dy)
    });
    EpisodeObservation { observation, goal }
}

/// Metres from `from` through every point of `ahead` in turn.
fn distance_along(from: (f64, f64), ahead: &[(f64, f64)]) -> f64 {
    let mut at = from;
    let mut total = 0.0;
    for &next in ahead {
        total += (next.0 - at.0).hypot(next.1 - at.1);
        at = next;
    }
    total
}

/// How far the agent of `run` is from the end of its route along it: straight to the next
/// waypoint it has to reach, then leg by leg (0 once complete).
fn to_go_m(run: &Run, ahead: &[(f64, f64)]) -> f64 {
    let pose = run.world().robots()[run.agent() as usize].pose;
    distance_along((pose.x_m, pose.y_m), ahead)
}

impl Episode {
    fn decide(&mut self, command: Command, steps: u64) -> EpisodeStep {
        for _ in 0..steps {
            if self.run.step(Some(command)) {
                break;
            }
        }
        let ahead = self.run.agent_route_ahead();
        let to_go_m = to_go_m(&self.run, &ahead);
        let penalty = self.run.penalty_so_far();
        let observation = sense(&mut self.run, &ahead);
        let events = self.run.live_monitor().events_so_far();
        let step = EpisodeStep {
            progress_m: self.to_go_m - to_go_m,
            penalty: penalty - self.penalty,
            events: events[self.events_seen..].to_vec(),
            ended: self.run.outcome().cloned(),
            observation,
        };
        (self.to_go_m, self.penalty, self.events_seen) = (to_go_m, penalty, events.len());
        step
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::run::tests::rear_approach;

    fn drive(threads: usize) -> Vec<Vec<Option<EpisodeStep>>> {
        let mut episodes = Episodes::new(&RunSpec::default(), 3, threads).unwrap();
        for i in 0..3 {
            episodes.reset(i, &rear_approach(), i as u64).unwrap();
        }
        (0..80)
            .map(|t| {
                let v = 0.1 * (t % 5) as f64;
                episodes.step(&[(v, 0.0), (0.0, 0.0), (0.5, 0.1)])
            })
            .collect()
    }

    #[test]
    fn episodes_step_alike_on_any_thread_count_and_report_progress_and_penalties() {
        let serial = drive(1);
        assert_eq!(serial, drive(2));
        // The agent standing still while a peer drives into it from behind: no progress,
        // penalties from the unsafe proximity and the collision, and the events as they begin.
        let still: Vec<&EpisodeStep> = serial.iter().map(|s| s[1].as_ref().unwrap()).collect();
        assert!(still.iter().all(|s| s.progress_m.abs() < 1e-12));
        let kinds: Vec<_> = still
            .iter()
            .flat_map(|s| s.events.iter().map(|e| e.kind.name()))
            .collect();
        assert!(kinds.contains(&"collision"), "{kinds:?}");
        let points: f64 = still.iter().map(|s| s.penalty).sum();
        assert!(points > 100.0, "{points}");
        // Driving toward the goal gains ground.
        let moving: f64 = serial
            .iter()
            .map(|s| s[0].as_ref().unwrap().progress_m)
            .sum();
        assert!(moving > 1.0, "{moving}");
    }

    #[test]
    fn a_decision_spans_the_control_period() {
        let spec = RunSpec {
            controller: Some(ControllerSpec {
                control_period_s: Some(0.5),
                ..ControllerSpec::named("snd_follow")
            }),
            ..RunSpec::default()
        };
        let mut episodes = Episodes::new(&spec, 1, 1).unwrap();
        assert_eq!(episodes.steps_per_decision(), 5);
        episodes.reset(0, &rear_approach(), 0).unwrap();
        let step = episodes.step(&[(0.4, 0.0)]).remove(0).unwrap();
        // 0.4 m/s for 0.5 s, straight ahead toward the goal.
        assert!((step.progress_m - 0.2).abs() < 1e-9, "{}", step.progress_m);
        let seen = episodes.observe(0).unwrap();
        assert!((seen.observation.time_s - 0.5).abs() < 1e-9);
        // The goal (15, 10) from (10.2, 10) heading east: 4.8 m ahead.
        assert!((seen.goal.0 - 4.8).abs() < 1e-9 && seen.goal.1.abs() < 1e-9);
        let record = episodes.finish(0).unwrap();
        assert_eq!(record.steps, 5);
        assert!(episodes.observe(0).is_none());
    }
}

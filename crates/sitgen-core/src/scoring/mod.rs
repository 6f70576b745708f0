//! Scoring: a run's event log to one number, so that dangerous runs rank first.
//!
//! Each event kind has a penalty: `start` points when an event of that kind starts, plus
//! `per_s` points per second it lasts (Arnold & Alexander 2013, §3: "a penalty of 10 points is
//! added if two robots enter an unsafe proximity, and a further penalty of 1 point per second
//! is applied for the duration"). The score is the sum over the scored events, kept per kind
//! so a person can see why a run ranks where it does. By default only events that concern the
//! agent count (the paper's §4.1: events concerning only peers did not contribute).
//!
//! Default penalties and why:
//! | kind | start | per s | reason |
//! |---|---|---|---|
//! | `collision` | 100 | 10 | contact is the accident the tool exists to find; pushing on is worse |
//! | `unsafe_proximity` | 10 | 1 | the paper's own example |
//! | `loitering` | 5 | 0.1 | a stuck robot is a mission fault and a hazard to others, milder than a near miss |
//! | `oscillation` | 20 | 1 | to-and-fro turning is unpredictable motion beside whoever it is avoiding and a control fault (the paper's run 219); above a near miss of the same length, below any contact |
//! | `circling` | 10 | 0.2 | orbiting or dithering beside a waypoint it cannot reach: a mission fault with a cause a person can act on, ranked above a plain timeout, below a near miss of the same length |
//! | `timeout` | 20 | — | a failed mission, even without an accident |
//! | `waypoint_reached`, `route_completed` | 0 | 0 | progress, not danger |
//!
//! So one brief collision outranks any near miss shorter than 90 s, and a run whose agent
//! pushed against a robot for a minute ranks far above one that brushed past.
//!
//! A scoring spec may also give points per failure class (`failure_classes`, none by default):
//! added once to a run whose failure class ([`crate::failure::classify`]) is that class, so an
//! expert who judges being driven into unseen worse than being struck while stopped can say so
//! beyond what event durations tell apart. `sitgen weights fit` writes such a spec, fitted to
//! an expert's pairwise judgements (`docs/weights.md`).

use std::collections::BTreeMap;

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::error::{join, SpecError};
use crate::failure::{Failure, FailureClass};
use crate::monitor::{Event, EventKind};

/// Points for one event kind.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Penalty {
    /// Points when an event starts, in [0, 1e6].
    #[serde(default)]
    pub start: f64,
    /// Points per second the event lasts, in [0, 1e6].
    #[serde(default)]
    pub per_s: f64,
}

impl Penalty {
    /// The points of an event that lasted `seconds`.
    pub fn points(&self, seconds: f64) -> f64 {
        self.start + self.per_s * seconds
    }
}

/// How runs are scored.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ScoringSpec {
    /// Penalties by event kind, replacing the defaults for the kinds given.
    #[serde(default)]
    pub penalties: BTreeMap<String, Penalty>,
    /// Whether events that concern only peers count too. Default false (the paper's choice).
    #[serde(default)]
    pub score_peers: bool,
    /// Points added once to a run whose failure class is the key, in [0, 1e6]. Default none.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub failure_classes: BTreeMap<String, f64>,
}

/// The default penalty for `kind` (see the module table).
pub fn default_penalty(kind: EventKind) -> Penalty {
    let (start, per_s) = match kind {
        EventKind::Collision => (100.0, 10.0),
        EventKind::UnsafeProximity => (10.0, 1.0),
        EventKind::Loitering => (5.0, 0.1),
        EventKind::Oscillation => (20.0, 1.0),
        EventKind::Circling => (10.0, 0.2),
        EventKind::Timeout => (20.0, 0.0),
        EventKind::WaypointReached | EventKind::RouteCompleted => (0.0, 0.0),
    };
    Penalty { start, per_s }
}

impl ScoringSpec {
    /// Check kinds and ranges; `path` names the section in errors.
    pub fn validate(&self, path: &str) -> Result<(), SpecError> {
        let table = join(path, "penalties");
        for (kind, p) in &self.penalties {
            let at = join(&table, kind);
            if EventKind::from_name(kind).is_none() {
                let names: Vec<&str> = EventKind::ALL.iter().map(|k| k.name()).collect();
                return Err(SpecError::new(
                    at,
                    format!("unknown event kind; expected one of {}", names.join(", ")),
                ));
            }
            SpecError::check_in(&join(&at, "start"), p.start, 0.0, 1e6)?;
            SpecError::check_in(&join(&at, "per_s"), p.per_s, 0.0, 1e6)?;
        }
        let table = join(path, "failure_classes");
        for (key, points) in &self.failure_classes {
            let at = join(&table, key);
            if FailureClass::from_key(key).is_none() {
                let keys: Vec<&str> = FailureClass::ALL.iter().map(|c| c.key()).collect();
                return Err(SpecError::new(
                    at,
                    format!("unknown failure class; expected one of {}", keys.join(", ")),
                ));
            }
            SpecError::check_in(&at, *points, 0.0, 1e6)?;
        }
        Ok(())
    }

    /// The penalty in force for `kind`.
    pub fn penalty(&self, kind: EventKind) -> Penalty {
        self.penalties
            .get(kind.name())
            .copied()
            .unwrap_or_else(|| default_penalty(kind))
    }
}

/// One kind's share of a score.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct ScoreLine {
    /// Scored events of this kind.
    pub count: u32,
    /// Seconds they lasted in all.
    pub seconds: f64,
    /// Points they earned.
    pub points: f64,
}

/// A run's score with its breakdown by event kind (kinds that earned points only).
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize, JsonSchema)]
pub struct Score {
    /// Total points: the breakdown's and the failure class's.
    pub total: f64,
    /// Points by event kind name.
    pub breakdown: BTreeMap<String, ScoreLine>,
    /// Points the run's failure class earned (`ScoringSpec::failure_classes`); absent if none.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub failure_class_points: f64,
}

fn is_zero(x: &f64) -> bool {
    *x == 0.0
}

/// The points of the events `scored` picks as if the run stopped at `now_s`: one still lasting
/// counts up to then. A running total, for rewards; it needs no copy of the log.
pub fn points_until(
    events: &[Event],
    spec: &ScoringSpec,
    now_s: f64,
    scored: impl Fn(&Event) -> bool,
) -> f64 {
    events
        .iter()
        .filter(|e| scored(e))
        .map(|e| {
            spec.penalty(e.kind)
                .points(e.end_s.unwrap_or(now_s) - e.start_s)
        })
        .sum()
}

/// Score the events marked `scored`, in log order (so the sum is the same wherever it runs),
/// then add the points of the run's failure class, if the spec gives any.
pub fn score(events: &[Event], spec: &ScoringSpec, failure: Option<&Failure>) -> Score {
    let mut out = Score::default();
    for e in events.iter().filter(|e| e.scored) {
        let seconds = e.duration_s();
        let points = spec.penalty(e.kind).points(seconds);
        if points == 0.0 {
            continue;
        }
        let line = out
            .breakdown
            .entry(e.kind.name().to_string())
            .or_insert(ScoreLine {
                count: 0,
                seconds: 0.0,
                points: 0.0,
            });
        line.count += 1;
        line.seconds += seconds;
        line.points += points;
        out.total += points;
    }
    if let Some(&points) = failure.and_then(|f| spec.failure_classes.get(f.class.key())) {
        out.failure_class_points = points;
        out.total += points;
    }
    out
}

//! The monitor: the paper's daemon (Arnold & Alexander 2013, §3). It watches the world after
//! every step and turns what happened into an event log; it never reads a controller's state.
//!
//! Each event kind is one file with the same doc template (what it detects, why it matters,
//! parameters, an example log line): [`collision`], [`unsafe_proximity`], [`loitering`],
//! [`oscillation`], [`circling`], [`waypoint_reached`], [`route_completed`], [`timeout`]. Events between
//! the agent and another party carry [`attribution`]: who moved into whom, from which side,
//! how fast, and whether the agent's laser had seen it. An event has a start, an end (for
//! lasting ones), the robot, the other party and details. Events are kept for every robot; a
//! run's scoring decides which count (by default those that concern the agent, as the paper).
//!
//! Times are step counts inside and seconds (rounded to the nanosecond, so that 0.3 is written
//! as 0.3) in the log, so a log is byte-identical wherever it is produced.

pub mod attribution;
pub mod circling;
pub mod collision;
pub mod loitering;
pub mod oscillation;
pub mod route_completed;
pub mod signals;
pub mod timeout;
pub mod unsafe_proximity;
pub mod waypoint_reached;

use std::collections::BTreeMap;

use schemars::JsonSchema;
use serde::{Deserialize, Serialize, Serializer};

use crate::error::{join, SpecError};
use crate::sim::{RobotState, World};
use crate::situation::{Role, Situation};

/// The monitor's thresholds.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct MonitorSpec {
    /// Footprint clearance between two robots below which they are in unsafe proximity,
    /// metres, in (0, 100]. Default 0.5.
    #[serde(default = "default_unsafe_proximity_m")]
    pub unsafe_proximity_m: f64,
    /// Net progress below which a robot is loitering, metres, in (0, 1000]. Default 1.0.
    #[serde(default = "default_loitering_distance_m")]
    pub loitering_distance_m: f64,
    /// Window over which net progress is measured, seconds, in (0, 3600]. Default 20.
    #[serde(default = "default_loitering_window_s")]
    pub loitering_window_s: f64,
    /// Distance within which a waypoint counts as reached, metres, in (0, 100]. Default 0.5.
    #[serde(default = "default_waypoint_radius_m")]
    pub waypoint_radius_m: f64,
    /// How long before a collision the other party must have been seen by the agent's laser to
    /// count as visible, seconds, in (0, 3600]. Default 1.
    #[serde(default = "default_visibility_window_s")]
    pub visibility_window_s: f64,
    /// A collision, unsafe proximity or oscillation interrupted for less than this and resumed
    /// is one event, seconds, in [0, 3600]. Default 1: a robot that pushes, backs off a
    /// centimetre and pushes again is in one accident, not dozens.
    #[serde(default = "default_merge_gap_s")]
    pub merge_gap_s: f64,
    /// How far back attribution looks to tell who moved into whom and how fast, seconds, in
    /// (0, 60]. Default 1.
    #[serde(default = "default_attribution_window_s")]
    pub attribution_window_s: f64,
    /// Window in which turn reversals are counted for `oscillation`, seconds, in (0, 3600].
    /// Default 10.
    #[serde(default = "default_oscillation_window_s")]
    pub oscillation_window_s: f64,
    /// Turn reversals within the window that make an oscillation, in [2, 1000]. Default 4.
    #[serde(default = "default_oscillation_reversals")]
    pub oscillation_reversals: u32,
    /// Extent of the window's positions below which an oscillating robot is going nowhere,
    /// metres, in (0, 1000]. Default 0.5.
    #[serde(default = "default_oscillation_distance_m")]
    pub oscillation_distance_m: f64,
    /// Turn rate above which a step counts as turning left or right, degrees per second, in
    /// (0, 3600]. Default 5.
    #[serde(default = "default_oscillation_turn_rate_deg_s")]
    pub oscillation_turn_rate_deg_s: f64,
    /// Distance from the agent's next waypoint within which, not reaching it, the agent is
    /// `circling` it (for `loitering_window_s`, or one whole turn), metres, in (0, 100].
    /// Default 2.
    #[serde(default = "default_circling_radius_m")]
    pub circling_radius_m: f64,
}

fn default_circling_radius_m() -> f64 {
    2.0
}

fn default_attribution_window_s() -> f64 {
    1.0
}
fn default_oscillation_window_s() -> f64 {
    10.0
}
fn default_oscillation_reversals() -> u32 {
    4
}
fn default_oscillation_distance_m() -> f64 {
    0.5
}
fn default_oscillation_turn_rate_deg_s() -> f64 {
    5.0
}

fn default_unsafe_proximity_m() -> f64 {
    0.5
}
fn default_loitering_distance_m() -> f64 {
    1.0
}
fn default_loitering_window_s() -> f64 {
    20.0
}
fn default_waypoint_radius_m() -> f64 {
    0.5
}
fn default_visibility_window_s() -> f64 {
    1.0
}
fn default_merge_gap_s() -> f64 {
    1.0
}

impl Default for MonitorSpec {
    fn default() -> Self {
        Self {
            unsafe_proximity_m: default_unsafe_proximity_m(),
            loitering_distance_m: default_loitering_distance_m(),
            loitering_window_s: default_loitering_window_s(),
            waypoint_radius_m: default_waypoint_radius_m(),
            visibility_window_s: default_visibility_window_s(),
            merge_gap_s: default_merge_gap_s(),
            attribution_window_s: default_attribution_window_s(),
            oscillation_window_s: default_oscillation_window_s(),
            oscillation_reversals: default_oscillation_reversals(),
            oscillation_distance_m: default_oscillation_distance_m(),
            oscillation_turn_rate_deg_s: default_oscillation_turn_rate_deg_s(),
            circling_radius_m: default_circling_radius_m(),
        }
    }
}

impl MonitorSpec {
    /// Check every range; `path` names the section in errors.
    pub fn validate(&self, path: &str) -> Result<(), SpecError> {
        let p = |f: &str| join(path, f);
        SpecError::check_positive(&p("unsafe_proximity_m"), self.unsafe_proximity_m, 100.0)?;
        SpecError::check_positive(
            &p("loitering_distance_m"),
            self.loitering_distance_m,
            1000.0,
        )?;
        SpecError::check_positive(&p("loitering_window_s"), self.loitering_window_s, 3600.0)?;
        SpecError::check_positive(&p("waypoint_radius_m"), self.waypoint_radius_m, 100.0)?;
        SpecError::check_positive(&p("visibility_window_s"), self.visibility_window_s, 3600.0)?;
        SpecError::check_in(&p("merge_gap_s"), self.merge_gap_s, 0.0, 3600.0)?;
        SpecError::check_positive(&p("attribution_window_s"), self.attribution_window_s, 60.0)?;
        SpecError::check_positive(
            &p("oscillation_window_s"),
            self.oscillation_window_s,
            3600.0,
        )?;
        SpecError::check_in(
            &p("oscillation_reversals"),
            f64::from(self.oscillation_reversals),
            2.0,
            1000.0,
        )?;
        SpecError::check_positive(
            &p("oscillation_distance_m"),
            self.oscillation_distance_m,
            1000.0,
        )?;
        SpecError::check_positive(
            &p("oscillation_turn_rate_deg_s"),
            self.oscillation_turn_rate_deg_s,
            3600.0,
        )?;
        SpecError::check_positive(&p("circling_radius_m"), self.circling_radius_m, 100.0)
    }
}

/// The kinds of event.
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize, JsonSchema,
)]
#[serde(rename_all = "snake_case")]
pub enum EventKind {
    /// A stall against a wall or another robot, lasting while the contact lasts.
    Collision,
    /// Two robots' footprints closer than the threshold, lasting.
    UnsafeProximity,
    /// Little net progress over a window, lasting.
    Loitering,
    /// Turning to and fro while going nowhere, lasting.
    Oscillation,
    /// Near the next waypoint without reaching it, lasting (the agent only).
    Circling,
    /// A waypoint of the route reached, instant.
    WaypointReached,
    /// The whole route driven, instant.
    RouteCompleted,
    /// The route not completed within the time limit, instant.
    Timeout,
}

impl EventKind {
    /// Every kind, in log order of precedence.
    pub const ALL: [EventKind; 8] = [
        EventKind::Collision,
        EventKind::UnsafeProximity,
        EventKind::Loitering,
        EventKind::Oscillation,
        EventKind::Circling,
        EventKind::WaypointReached,
        EventKind::RouteCompleted,
        EventKind::Timeout,
    ];

    /// The name used in logs and specs.
    pub fn name(self) -> &'static str {
        match self {
            EventKind::Collision => "collision",
            EventKind::UnsafeProximity => "unsafe_proximity",
            EventKind::Loitering => "loitering",
            EventKind::Oscillation => "oscillation",
            EventKind::Circling => "circling",
            EventKind::WaypointReached => "waypoint_reached",
            EventKind::RouteCompleted => "route_completed",
            EventKind::Timeout => "timeout",
        }
    }

    /// The kind called `name`.
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|k| k.name() == name)
    }
}

/// The other party of an event.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum Party {
    /// An occupied cell or the edge of the map.
    Wall,
    /// The robot with this id.
    Robot(u32),
}

/// Written as `"wall"` or the robot's id.
impl Serialize for Party {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        match self {
            Party::Wall => s.serialize_str("wall"),
            Party::Robot(id) => s.serialize_u32(*id),
        }
    }
}

/// Read from `"wall"` or a robot id.
impl<'de> Deserialize<'de> for Party {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        match serde_json::Value::deserialize(d)? {
            serde_json::Value::String(s) if s == "wall" => Ok(Party::Wall),
            v => v
                .as_u64()
                .and_then(|id| u32::try_from(id).ok())
                .map(Party::Robot)
                .ok_or_else(|| serde::de::Error::custom("expected \"wall\" or a robot id")),
        }
    }
}

/// One event of a run. Field names are stable: they are the JSON Lines format.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Event {
    /// What happened.
    pub kind: EventKind,
    /// When it started, seconds of simulated time.
    pub start_s: f64,
    /// When it ended, seconds; `null` for instant events. Lasting events still going on when
    /// the run stops end at the run's end.
    pub end_s: Option<f64>,
    /// The robot it happened to (the lower id of a pair, so the agent's pairs name the agent).
    pub robot: u32,
    /// The other party: `"wall"`, a robot id, or `null`.
    pub other: Option<Party>,
    /// Whether it counts toward the run's score (by default: it concerns the agent).
    pub scored: bool,
    /// Kind-specific facts, by name (documented in each kind's file).
    #[serde(default)]
    pub details: BTreeMap<String, serde_json::Value>,
}

impl Event {
    /// Seconds the event lasted (0 for instant events).
    pub fn duration_s(&self) -> f64 {
        self.end_s.map_or(0.0, |e| e - self.start_s)
    }

    /// Whether the event concerns robot `id` (as the robot or the other party).
    pub fn concerns(&self, id: u32) -> bool {
        self.robot == id || self.other == Some(Party::Robot(id))
    }

    /// One JSON object, on one line.
    pub fn to_json(&self) -> String {
        serde_json::to_string(self).expect("events serialize")
    }

    /// The human-readable line, e.g.
    /// `  12.3 s  agent    collision with peer 2 at 0.40 m/s (drove into it from the front; not
    /// visible 1 s before), 4.1 s`.
    pub fn to_text(&self, agent: u32) -> String {
        let robot = robot_name(self.robot, agent);
        let what = match self.kind {
            EventKind::Collision => collision::describe(self, agent),
            EventKind::UnsafeProximity => unsafe_proximity::describe(self, agent),
            EventKind::Loitering => loitering::describe(self),
            EventKind::Oscillation => oscillation::describe(self, agent),
            EventKind::Circling => circling::describe(self),
            EventKind::WaypointReached => waypoint_reached::describe(self),
            EventKind::RouteCompleted => route_completed::describe(self),
            EventKind::Timeout => timeout::describe(self),
        };
        let lasting = self
            .end_s
            .map(|_| format!(", {:.1} s", self.duration_s()))
            .unwrap_or_default();
        let marked = if self.scored { "" } else { "  (not scored)" };
        format!(
            "{:>7.1} s  {robot:<8} {what}{lasting}{marked}",
            self.start_s
        )
    }

    /// A numeric detail, NaN when absent.
    pub fn detail_f64(&self, name: &str) -> f64 {
        self.details
            .get(name)
            .and_then(serde_json::Value::as_f64)
            .unwrap_or(f64::NAN)
    }
}

/// "agent" or "peer N".
pub fn robot_name(id: u32, agent: u32) -> String {
    if id == agent {
        "agent".into()
    } else {
        format!("peer {id}")
    }
}

/// "wall", "agent" or "peer N".
fn party_name(party: Option<Party>, agent: u32) -> String {
    match party {
        Some(Party::Wall) => "wall".into(),
        Some(Party::Robot(id)) => robot_name(id, agent),
        None => "nothing".into(),
    }
}

/// Seconds for step `step`, rounded to the nanosecond.
fn seconds(step: u64, dt_s: f64) -> f64 {
    (step as f64 * dt_s * 1e9).round() / 1e9
}

/// Whole steps in `seconds` (rounded up).
fn steps(seconds: f64, dt_s: f64) -> u64 {
    (seconds / dt_s - 1e-9).ceil().max(0.0) as u64
}

/// What every detector sees after a step.
pub struct Frame<'a> {
    /// Steps taken so far (the frame's time is `step · dt`).
    pub step: u64,
    /// Ids of the robots the agent's laser saw at the start of this step.
    pub seen_by_agent: &'a [u32],
    /// The world after the step: every robot's state, and the map (for the clearance of a
    /// robot to walls).
    pub world: &'a World,
}

impl Frame<'_> {
    /// Every robot's state.
    pub fn robots(&self) -> &[RobotState] {
        self.world.robots()
    }
}

/// The event log under construction: open lasting events by key, closed in order.
#[derive(Debug, Default)]
struct Log {
    events: Vec<Event>,
    dt_s: f64,
    /// Events opened or closed, or a lasting event's class decided anew ([`Log::decide`]), so
    /// far: a reader of a log still growing re-reads it only when this moved.
    changes: u64,
}

impl Log {
    /// Append an event that starts at `step`; returns its index for closing later.
    fn open(
        &mut self,
        kind: EventKind,
        step: u64,
        robot: u32,
        other: Option<Party>,
        details: BTreeMap<String, serde_json::Value>,
    ) -> usize {
        self.events.push(Event {
            kind,
            start_s: seconds(step, self.dt_s),
            end_s: None,
            robot,
            other,
            scored: false,
            details,
        });
        self.changes += 1;
        self.events.len() - 1
    }

    /// End the lasting event at `index` at `step`.
    fn close(&mut self, index: usize, step: u64) {
        self.events[index].end_s = Some(seconds(step, self.dt_s));
        self.changes += 1;
    }

    fn set(&mut self, index: usize, name: &str, value: serde_json::Value) {
        self.events[index].details.insert(name.into(), value);
    }

    /// [`Log::set`] for a detail that decides the event's failure class while it still
    /// lasts: counted as a change, so a reader of the growing log reads it again.
    fn decide(&mut self, index: usize, name: &str, value: serde_json::Value) {
        self.set(index, name, value);
        self.changes += 1;
    }
}

/// Lasting events of one kind keyed by who is involved: opened when a key becomes active,
/// closed when it has been inactive for `grace_steps` (ending where it became inactive), so a
/// contact broken for a moment and resumed — a robot that pushes, turns a little and pushes
/// again — stays one event.
#[derive(Debug)]
struct Lasting<K: Ord + Copy> {
    open: BTreeMap<K, usize>,
    /// Open keys not active now, with the step since which they are not.
    inactive_since: BTreeMap<K, u64>,
    grace_steps: u64,
}

impl<K: Ord + Copy> Lasting<K> {
    fn new(grace_steps: u64) -> Self {
        Self {
            open: BTreeMap::new(),
            inactive_since: BTreeMap::new(),
            grace_steps,
        }
    }

    /// Note which open keys are active at `step`; close those inactive for the grace period.
    /// Returns the keys closed.
    fn update(&mut self, active: &[K], step: u64, log: &mut Log) -> Vec<K> {
        let mut closed = Vec::new();
        for (&k, &i) in &self.open {
            if active.contains(&k) {
                self.inactive_since.remove(&k);
                continue;
            }
            let since = *self.inactive_since.entry(k).or_insert(step);
            if step - since >= self.grace_steps {
                log.close(i, since);
                closed.push(k);
            }
        }
        for k in &closed {
            self.open.remove(k);
            self.inactive_since.remove(k);
        }
        closed
    }

    /// Close everything still open: at `step`, or where it became inactive.
    fn close_all(&mut self, step: u64, log: &mut Log) {
        for (k, i) in std::mem::take(&mut self.open) {
            log.close(i, self.inactive_since.get(&k).copied().unwrap_or(step));
        }
        self.inactive_since.clear();
    }
}

/// Build a details map from (name, value) pairs.
fn details<const N: usize>(
    pairs: [(&str, serde_json::Value); N],
) -> BTreeMap<String, serde_json::Value> {
    pairs.into_iter().map(|(k, v)| (k.to_string(), v)).collect()
}

/// The monitor of one run.
#[derive(Debug)]
pub struct Monitor {
    agent: u32,
    log: Log,
    collision: collision::Detector,
    unsafe_proximity: unsafe_proximity::Detector,
    loitering: loitering::Detector,
    oscillation: oscillation::Detector,
    circling: circling::Detector,
    waypoints: waypoint_reached::Detector,
    attribution: attribution::Attribution,
}

impl Monitor {
    /// A monitor for a run of `situation` in `world` (at its start).
    pub fn new(situation: &Situation, world: &World, spec: &MonitorSpec) -> Self {
        let dt_s = world.spec().dt_s;
        let agent = situation
            .robots
            .iter()
            .find(|r| r.role == Role::Agent)
            .map_or(0, |r| r.id);
        Self {
            agent,
            log: Log {
                events: Vec::new(),
                dt_s,
                changes: 0,
            },
            collision: collision::Detector::new(
                agent,
                spec.visibility_window_s,
                world.spec().laser.fov_deg,
                dt_s,
                steps(spec.merge_gap_s, dt_s),
            ),
            unsafe_proximity: unsafe_proximity::Detector::new(
                world.robots(),
                agent,
                spec.unsafe_proximity_m,
                steps(spec.merge_gap_s, dt_s),
            ),
            loitering: loitering::Detector::new(
                world.robots(),
                spec.loitering_distance_m,
                spec.loitering_window_s,
                dt_s,
            ),
            oscillation: oscillation::Detector::new(
                world.robots(),
                &oscillation::Thresholds {
                    window_s: spec.oscillation_window_s,
                    reversals: spec.oscillation_reversals,
                    distance_m: spec.oscillation_distance_m,
                    turn_rate_deg_s: spec.oscillation_turn_rate_deg_s,
                    merge_steps: steps(spec.merge_gap_s, dt_s),
                },
                dt_s,
            ),
            circling: circling::Detector::new(
                agent,
                spec.circling_radius_m,
                spec.loitering_window_s,
                dt_s,
            ),
            waypoints: waypoint_reached::Detector::new(situation, spec.waypoint_radius_m),
            attribution: attribution::Attribution::new(
                situation.robots.len(),
                agent,
                steps(spec.attribution_window_s, dt_s),
                dt_s,
            ),
        }
    }

    /// The agent's id.
    pub fn agent(&self) -> u32 {
        self.agent
    }

    /// Watch the world after a step.
    pub fn observe(&mut self, frame: &Frame<'_>) {
        self.attribution.observe(frame);
        self.collision
            .observe(frame, &self.attribution, &mut self.log);
        self.unsafe_proximity
            .observe(frame, &self.attribution, &mut self.log);
        self.waypoints.observe(frame, &mut self.log);
        self.loitering
            .observe(frame, self.waypoints.done(), &mut self.log);
        self.oscillation
            .observe(frame, self.waypoints.done(), &mut self.log);
        let next = self.waypoints.next(self.agent as usize);
        self.circling.observe(frame, next, &mut self.log);
    }

    /// How many waypoints of its route robot `id` has reached, in order.
    pub fn waypoints_reached(&self, id: u32) -> usize {
        self.waypoints.reached(id)
    }

    /// The waypoints robot `id` has yet to reach on one pass of its route, in order, as the
    /// monitor counts them (empty once it is complete).
    pub fn route_ahead(&self, id: u32) -> Vec<(f64, f64)> {
        self.waypoints.ahead(id as usize)
    }

    /// The events so far, those still lasting without an end.
    pub fn events_so_far(&self) -> &[Event] {
        &self.log.events
    }

    /// How many times an event has been opened, closed or had its class decided anew so
    /// far: the events' classes can only have changed when this has (details that decide a
    /// class are written when an event opens, when they change while it lasts, or just
    /// before it closes).
    pub fn log_changes(&self) -> u64 {
        self.log.changes
    }

    /// Whether robot `id` has driven its whole route.
    pub fn route_completed(&self, id: u32) -> bool {
        self.waypoints.completed()[id as usize]
    }

    /// End the run at `step`: close lasting events, add a timeout if the agent's route is not
    /// complete, mark the events `scored` says count, and return the log in start order.
    pub fn finish(
        mut self,
        step: u64,
        timed_out: bool,
        scored: impl Fn(&Event) -> bool,
    ) -> Vec<Event> {
        self.collision.finish(step, &mut self.log);
        self.unsafe_proximity.finish(step, &mut self.log);
        self.loitering.finish(step, &mut self.log);
        self.oscillation.finish(step, &mut self.log);
        self.circling.finish(step, &mut self.log);
        if timed_out {
            timeout::record(
                &mut self.log,
                step,
                self.agent,
                self.waypoints.reached(self.agent),
                self.waypoints.count(self.agent),
            );
        }
        let mut events = self.log.events;
        for e in &mut events {
            e.scored = scored(e);
        }
        // Loitering is detected a window after it began; a stable sort by start keeps the order
        // of detection among events that start together.
        events.sort_by(|a, b| a.start_s.total_cmp(&b.start_s));
        events
    }
}

/// A log as JSON Lines.
pub fn to_jsonl(events: &[Event]) -> String {
    events.iter().map(|e| e.to_json() + "\n").collect()
}

/// A log as text, one line per event.
pub fn to_text(events: &[Event], agent: u32) -> String {
    events.iter().map(|e| e.to_text(agent) + "\n").collect()
}

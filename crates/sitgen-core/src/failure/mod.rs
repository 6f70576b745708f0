//! Failure classes: what went wrong in a run, as a stable key and a sentence a person reads.
//!
//! A deterministic function of the run's scored events and the facts the monitor recorded in
//! them (who moved into whom, whether the agent's laser had seen the other party, how fast the
//! agent was going, whether it was oscillating), never of a controller's state. Each scored
//! event that concerns the agent has a class ([`class_of`]); the run's class is the most severe
//! of them ([`classify`]), in the order of [`FailureClass`] below, and the events of that class
//! are the ones that decided it. A run with no scored failure event has no class.
//!
//! Severity order, and why: contact with a robot (a stand-in for a person) first, the agent's
//! own doing before being struck, unseen before seen (a perception gap is worse than a control
//! one: nothing in the controller even tried); then contact with walls; near misses; to-and-fro
//! turning; circling a waypoint it cannot reach (a cause a person can act on); being stuck;
//! and last a route merely not completed. `docs/failures.md` gives every
//! class with its rule and the run of the paper it stands for.
//!
//! Logs from before attribution (no `initiator`, `agent_mean_speed_m_s`) still classify: who
//! drove is then whose move was refused, and stopped is a commanded speed of zero.

use std::collections::BTreeMap;

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use serde_json::Value;

use crate::monitor::attribution::MOVING_M_S;
use crate::monitor::{Event, EventKind, Party};

/// What went wrong, most severe first.
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize, JsonSchema,
)]
#[serde(rename_all = "snake_case")]
pub enum FailureClass {
    /// The agent drove into a peer its laser had not seen in the window before contact.
    DroveIntoUnseenPeer,
    /// The agent drove into a peer its laser had seen.
    DroveIntoSeenPeer,
    /// The agent collided with a peer while turning to and fro beside it.
    CollidedWhileOscillating,
    /// The agent and a peer both drove toward each other into contact.
    CollidedAsBothClosedIn,
    /// A peer drove into the moving agent, which had not seen it.
    StruckWhileMovingUnseen,
    /// A peer drove into the moving agent, which had seen it coming.
    StruckWhileMovingSeen,
    /// A peer drove into the stopped agent, which had not seen it.
    StruckWhileStoppedUnseen,
    /// A peer drove into the stopped agent, which had seen it coming.
    StruckWhileStoppedSeen,
    /// The agent drove forward into a wall.
    DroveIntoWall,
    /// The agent turned or backed into a wall its laser does not cover.
    TurnedIntoWall,
    /// The agent drove within the safety distance of a peer.
    DroveCloseToPeer,
    /// A peer came within the safety distance of the agent.
    ApproachedByPeer,
    /// The agent turned to and fro beside a peer.
    OscillatedBesidePeer,
    /// The agent turned to and fro beside a wall or doorpost.
    OscillatedBesideWall,
    /// The agent turned to and fro with nothing near it.
    OscillatedInOpen,
    /// The agent circled or dithered near a waypoint (or the goal) without reaching it.
    CircledWaypoint,
    /// The agent made no progress for a long while, without contact.
    StuckWithoutContact,
    /// The agent did not complete its route in the time limit.
    RouteNotCompleted,
}

impl FailureClass {
    /// Every class, most severe first.
    pub const ALL: [FailureClass; 18] = [
        FailureClass::DroveIntoUnseenPeer,
        FailureClass::DroveIntoSeenPeer,
        FailureClass::CollidedWhileOscillating,
        FailureClass::CollidedAsBothClosedIn,
        FailureClass::StruckWhileMovingUnseen,
        FailureClass::StruckWhileMovingSeen,
        FailureClass::StruckWhileStoppedUnseen,
        FailureClass::StruckWhileStoppedSeen,
        FailureClass::DroveIntoWall,
        FailureClass::TurnedIntoWall,
        FailureClass::DroveCloseToPeer,
        FailureClass::ApproachedByPeer,
        FailureClass::OscillatedBesidePeer,
        FailureClass::OscillatedBesideWall,
        FailureClass::OscillatedInOpen,
        FailureClass::CircledWaypoint,
        FailureClass::StuckWithoutContact,
        FailureClass::RouteNotCompleted,
    ];

    /// The stable key (as in JSON and the store).
    pub fn key(self) -> &'static str {
        match self {
            FailureClass::DroveIntoUnseenPeer => "drove_into_unseen_peer",
            FailureClass::DroveIntoSeenPeer => "drove_into_seen_peer",
            FailureClass::CollidedWhileOscillating => "collided_while_oscillating",
            FailureClass::CollidedAsBothClosedIn => "collided_as_both_closed_in",
            FailureClass::StruckWhileMovingUnseen => "struck_while_moving_unseen",
            FailureClass::StruckWhileMovingSeen => "struck_while_moving_seen",
            FailureClass::StruckWhileStoppedUnseen => "struck_while_stopped_unseen",
            FailureClass::StruckWhileStoppedSeen => "struck_while_stopped_seen",
            FailureClass::DroveIntoWall => "drove_into_wall",
            FailureClass::TurnedIntoWall => "turned_into_wall",
            FailureClass::DroveCloseToPeer => "drove_close_to_peer",
            FailureClass::ApproachedByPeer => "approached_by_peer",
            FailureClass::OscillatedBesidePeer => "oscillated_beside_peer",
            FailureClass::OscillatedBesideWall => "oscillated_beside_wall",
            FailureClass::OscillatedInOpen => "oscillated_in_open",
            FailureClass::CircledWaypoint => "circled_waypoint",
            FailureClass::StuckWithoutContact => "stuck_without_contact",
            FailureClass::RouteNotCompleted => "route_not_completed",
        }
    }

    /// The sentence a person reads.
    pub fn description(self) -> &'static str {
        match self {
            FailureClass::DroveIntoUnseenPeer => "drove into a peer it had not seen",
            FailureClass::DroveIntoSeenPeer => "drove into a peer it had seen",
            FailureClass::CollidedWhileOscillating => {
                "collided with a peer while turning to and fro beside it"
            }
            FailureClass::CollidedAsBothClosedIn => {
                "collided with a peer as both drove toward each other"
            }
            FailureClass::StruckWhileMovingUnseen => {
                "struck while moving by a peer it had not seen"
            }
            FailureClass::StruckWhileMovingSeen => "struck while moving by a peer it saw coming",
            FailureClass::StruckWhileStoppedUnseen => {
                "struck while stopped by a peer it had not seen"
            }
            FailureClass::StruckWhileStoppedSeen => "struck while stopped by a peer it saw coming",
            FailureClass::DroveIntoWall => "drove into a wall",
            FailureClass::TurnedIntoWall => "turned or backed into a wall it could not see",
            FailureClass::DroveCloseToPeer => "drove within the safety distance of a peer",
            FailureClass::ApproachedByPeer => "let a peer come within the safety distance",
            FailureClass::OscillatedBesidePeer => "oscillated beside a peer",
            FailureClass::OscillatedBesideWall => "oscillated beside a wall or doorpost",
            FailureClass::OscillatedInOpen => "oscillated with nothing near",
            FailureClass::CircledWaypoint => {
                "circled or dithered near a waypoint without reaching it"
            }
            FailureClass::StuckWithoutContact => "stuck without contact",
            FailureClass::RouteNotCompleted => "route not completed in time",
        }
    }

    /// The class with key `key`.
    pub fn from_key(key: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|c| c.key() == key)
    }
}

/// A run's failure: its class, the events that decided it and the facts of the first of them
/// that a person (or a clustering of a broad class) tells runs apart by.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct Failure {
    /// The class.
    pub class: FailureClass,
    /// Its sentence.
    pub description: String,
    /// Positions in the event log of the events of this class.
    pub events: Vec<usize>,
    /// Behaviour features: `bearing` (front/left/right/rear, contacts and near misses with a
    /// peer), `agent_mean_speed_m_s`, `closing_speed_m_s`, `start_s` (first deciding event),
    /// `seconds` (how long the deciding events lasted in all), `count`.
    pub features: BTreeMap<String, Value>,
}

/// The class of one event of a run whose agent is `agent`, given the whole log (`events`,
/// for whether the agent was oscillating at the time); `None` for events that are not
/// failures (progress, peers among themselves, unscored events).
pub fn class_of(e: &Event, events: &[Event], agent: u32) -> Option<FailureClass> {
    if !e.scored {
        return None;
    }
    agent_class_of(e, events, agent)
}

/// The most severe class among the events of a run still going, whose events are not yet
/// marked scored (every event that concerns the agent will be): what a perturbed copy
/// watching for a class reads each step. An event still lasting reads as the class it would
/// close with if the run stopped now (an oscillation's nearest party so far), which is what
/// a copy stopped now is judged by.
pub fn worst_so_far(events: &[Event], agent: u32) -> Option<FailureClass> {
    events
        .iter()
        .filter_map(|e| agent_class_of(e, events, agent))
        .min()
}

/// [`class_of`] for an event whether or not it is marked scored yet.
fn agent_class_of(e: &Event, events: &[Event], agent: u32) -> Option<FailureClass> {
    if !e.concerns(agent) {
        return None;
    }
    match e.kind {
        EventKind::Collision => Some(match e.other {
            Some(Party::Wall) if e.details.get("visible") == Some(&Value::Bool(true)) => {
                FailureClass::DroveIntoWall
            }
            Some(Party::Wall) => FailureClass::TurnedIntoWall,
            _ if oscillating_at(events, agent, e.start_s) => FailureClass::CollidedWhileOscillating,
            _ => peer_contact(e, agent),
        }),
        EventKind::UnsafeProximity => Some(match initiator(e, agent) {
            "other" => FailureClass::ApproachedByPeer,
            _ => FailureClass::DroveCloseToPeer,
        }),
        EventKind::Oscillation if e.robot == agent => Some(match e.details.get("nearest") {
            Some(Value::String(_)) => FailureClass::OscillatedBesideWall,
            Some(v) if v.is_u64() => FailureClass::OscillatedBesidePeer,
            _ => FailureClass::OscillatedInOpen,
        }),
        EventKind::Circling if e.robot == agent => Some(FailureClass::CircledWaypoint),
        EventKind::Loitering if e.robot == agent => Some(FailureClass::StuckWithoutContact),
        EventKind::Timeout => Some(FailureClass::RouteNotCompleted),
        _ => None,
    }
}

/// A contact between the agent and a peer, by who drove, whether the agent was stopped and
/// whether it had seen the peer.
fn peer_contact(e: &Event, agent: u32) -> FailureClass {
    let seen = e.details.get("visible") == Some(&Value::Bool(true));
    let stopped = match e
        .details
        .get("agent_mean_speed_m_s")
        .and_then(Value::as_f64)
    {
        Some(speed) => speed < MOVING_M_S,
        None => e.detail_f64("speed_m_s") < MOVING_M_S,
    };
    match (initiator(e, agent), seen, stopped) {
        ("agent", false, _) => FailureClass::DroveIntoUnseenPeer,
        ("agent", true, _) => FailureClass::DroveIntoSeenPeer,
        ("both", ..) => FailureClass::CollidedAsBothClosedIn,
        (_, false, false) => FailureClass::StruckWhileMovingUnseen,
        (_, true, false) => FailureClass::StruckWhileMovingSeen,
        (_, false, true) => FailureClass::StruckWhileStoppedUnseen,
        (_, true, true) => FailureClass::StruckWhileStoppedSeen,
    }
}

/// Who moved into whom (`agent`, `other`, `both`): the recorded attribution, else whose move
/// was refused.
fn initiator(e: &Event, agent: u32) -> &str {
    if let Some(who) = e.details.get("initiator").and_then(Value::as_str) {
        return who;
    }
    let blocked = e.details.get("blocked").and_then(Value::as_array);
    match blocked {
        Some(ids) if ids.iter().any(|id| id.as_u64() == Some(u64::from(agent))) => "agent",
        Some(_) => "other",
        None => "agent",
    }
}

/// Whether the agent was oscillating at `t_s` (or had stopped less than a second before).
fn oscillating_at(events: &[Event], agent: u32, t_s: f64) -> bool {
    events.iter().any(|o| {
        o.kind == EventKind::Oscillation
            && o.robot == agent
            && o.start_s <= t_s
            && o.end_s.unwrap_or(f64::INFINITY) + 1.0 >= t_s
    })
}

/// Every class a run's events show, most severe first (what a kill compares: a class of a
/// faulty run that the correct run does not show is a new failure).
pub fn classes(events: &[Event], agent: u32) -> Vec<FailureClass> {
    first_seen(events, agent)
        .into_iter()
        .map(|(c, _)| c)
        .collect()
}

/// Every class a run's events show, most severe first, with when the first event of each
/// began (simulated seconds): what shrinking keeps, and its time to failure.
pub fn first_seen(events: &[Event], agent: u32) -> Vec<(FailureClass, f64)> {
    let mut first: BTreeMap<FailureClass, f64> = BTreeMap::new();
    for e in events {
        if let Some(class) = class_of(e, events, agent) {
            first.entry(class).or_insert(e.start_s);
        }
    }
    first.into_iter().collect()
}

/// The failure of a run: the most severe class among its events, `None` if it has no scored
/// failure.
pub fn classify(events: &[Event], agent: u32) -> Option<Failure> {
    let classes: Vec<Option<FailureClass>> =
        events.iter().map(|e| class_of(e, events, agent)).collect();
    let class = classes.iter().flatten().min().copied()?;
    let deciding: Vec<usize> = (0..events.len())
        .filter(|&i| classes[i] == Some(class))
        .collect();
    let first = &events[deciding[0]];
    let mut features = BTreeMap::new();
    for name in [
        "bearing",
        "agent_mean_speed_m_s",
        "closing_speed_m_s",
        "nearest_m",
        "turns",
        "radius_m",
    ] {
        if let Some(v) = first.details.get(name).filter(|v| !v.is_null()) {
            features.insert(name.to_string(), v.clone());
        }
    }
    let seconds: f64 = deciding.iter().map(|&i| events[i].duration_s()).sum();
    features.insert("start_s".into(), first.start_s.into());
    features.insert("seconds".into(), ((seconds * 1e9).round() / 1e9).into());
    features.insert("count".into(), deciding.len().into());
    Some(Failure {
        class,
        description: class.description().to_string(),
        events: deciding,
        features,
    })
}

#[cfg(test)]
mod situation_tests;
#[cfg(test)]
mod tests;

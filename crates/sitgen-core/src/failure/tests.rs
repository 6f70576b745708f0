//! The class function on constructed event logs: each rule, the fallbacks for logs without
//! attribution, and the severity order that picks a run's class.

use serde_json::json;

use super::*;

fn event(kind: EventKind, start_s: f64, end_s: Option<f64>, other: Option<Party>) -> Event {
    Event {
        kind,
        start_s,
        end_s,
        robot: 0,
        other,
        scored: true,
        details: BTreeMap::new(),
    }
}

fn with(mut e: Event, pairs: &[(&str, Value)]) -> Event {
    for (k, v) in pairs {
        e.details.insert((*k).to_string(), v.clone());
    }
    e
}

fn peer_contact(initiator: &str, visible: bool, agent_speed: f64) -> Event {
    with(
        event(EventKind::Collision, 5.0, Some(9.0), Some(Party::Robot(1))),
        &[
            ("initiator", json!(initiator)),
            ("visible", json!(visible)),
            ("agent_mean_speed_m_s", json!(agent_speed)),
            ("bearing", json!("front")),
        ],
    )
}

fn class(events: &[Event]) -> Option<FailureClass> {
    classify(events, 0).map(|f| f.class)
}

#[test]
fn peer_contacts_are_told_apart_by_who_drove_what_was_seen_and_whether_the_agent_was_stopped() {
    use FailureClass::*;
    let cases = [
        (("agent", false, 0.4), DroveIntoUnseenPeer),
        (("agent", true, 0.4), DroveIntoSeenPeer),
        (("both", true, 0.4), CollidedAsBothClosedIn),
        (("other", false, 0.3), StruckWhileMovingUnseen),
        (("other", true, 0.3), StruckWhileMovingSeen),
        (("other", false, 0.0), StruckWhileStoppedUnseen),
        (("other", true, 0.01), StruckWhileStoppedSeen),
    ];
    for ((who, seen, speed), expected) in cases {
        assert_eq!(
            class(&[peer_contact(who, seen, speed)]),
            Some(expected),
            "{who} {seen} {speed}"
        );
    }
}

#[test]
fn a_contact_during_an_oscillation_is_a_collision_while_oscillating() {
    let osc = with(
        event(EventKind::Oscillation, 2.0, Some(4.5), None),
        &[("nearest", json!(1))],
    );
    let hit = peer_contact("agent", true, 0.1);
    assert_eq!(
        class(&[osc.clone(), hit.clone()]),
        Some(FailureClass::CollidedWhileOscillating),
        "ended 0.5 s before contact"
    );
    let mut late = hit;
    late.start_s = 6.0;
    assert_eq!(
        class(&[osc, late]),
        Some(FailureClass::DroveIntoSeenPeer),
        "ended 1.5 s before contact"
    );
}

#[test]
fn walls_near_misses_oscillation_stuck_and_timeouts_have_their_classes() {
    use FailureClass::*;
    let wall = |visible: bool| {
        with(
            event(EventKind::Collision, 1.0, Some(2.0), Some(Party::Wall)),
            &[("visible", json!(visible))],
        )
    };
    assert_eq!(class(&[wall(true)]), Some(DroveIntoWall));
    assert_eq!(class(&[wall(false)]), Some(TurnedIntoWall));
    let near = |who: &str| {
        with(
            event(
                EventKind::UnsafeProximity,
                1.0,
                Some(2.0),
                Some(Party::Robot(2)),
            ),
            &[("initiator", json!(who))],
        )
    };
    assert_eq!(class(&[near("agent")]), Some(DroveCloseToPeer));
    assert_eq!(class(&[near("both")]), Some(DroveCloseToPeer));
    assert_eq!(class(&[near("other")]), Some(ApproachedByPeer));
    let osc = |nearest: Value| {
        with(
            event(EventKind::Oscillation, 1.0, Some(5.0), None),
            &[("nearest", nearest)],
        )
    };
    assert_eq!(class(&[osc(json!(3))]), Some(OscillatedBesidePeer));
    assert_eq!(class(&[osc(json!("wall"))]), Some(OscillatedBesideWall));
    assert_eq!(class(&[osc(Value::Null)]), Some(OscillatedInOpen));
    assert_eq!(
        class(&[event(EventKind::Loitering, 1.0, Some(30.0), None)]),
        Some(StuckWithoutContact)
    );
    assert_eq!(
        class(&[event(EventKind::Timeout, 600.0, None, None)]),
        Some(RouteNotCompleted)
    );
}

#[test]
fn the_most_severe_class_decides_and_names_its_events() {
    let log = vec![
        event(EventKind::WaypointReached, 0.5, None, None),
        with(
            event(
                EventKind::UnsafeProximity,
                1.0,
                Some(20.0),
                Some(Party::Robot(1)),
            ),
            &[("initiator", json!("other"))],
        ),
        peer_contact("other", true, 0.0),
        event(EventKind::Loitering, 3.0, Some(30.0), None),
        peer_contact("other", true, 0.0),
        event(EventKind::Timeout, 600.0, None, None),
    ];
    let f = classify(&log, 0).unwrap();
    assert_eq!(f.class, FailureClass::StruckWhileStoppedSeen);
    assert_eq!(
        f.description,
        "struck while stopped by a peer it saw coming"
    );
    assert_eq!(f.events, vec![2, 4]);
    assert_eq!(f.features["bearing"], "front");
    assert_eq!(f.features["seconds"], 8.0);
    assert_eq!(f.features["count"], 2);
}

#[test]
fn runs_without_scored_failures_have_no_class() {
    assert!(classify(&[], 0).is_none());
    let mut unscored = peer_contact("agent", false, 0.5);
    unscored.scored = false;
    let progress = event(EventKind::RouteCompleted, 9.0, None, None);
    assert!(classify(&[unscored, progress], 0).is_none());
    let mut peers = peer_contact("agent", false, 0.5);
    (peers.robot, peers.other) = (1, Some(Party::Robot(2)));
    assert!(classify(&[peers], 0).is_none(), "peers among themselves");
}

#[test]
fn logs_without_attribution_fall_back_on_whose_move_was_refused() {
    let old = |blocked: Value, speed: f64| {
        with(
            event(EventKind::Collision, 1.0, Some(3.0), Some(Party::Robot(1))),
            &[
                ("blocked", blocked),
                ("visible", json!(true)),
                ("speed_m_s", json!(speed)),
            ],
        )
    };
    assert_eq!(
        class(&[old(json!([0]), 0.3)]),
        Some(FailureClass::DroveIntoSeenPeer)
    );
    assert_eq!(
        class(&[old(json!([1]), 0.0)]),
        Some(FailureClass::StruckWhileStoppedSeen)
    );
}

#[test]
fn keys_are_unique_and_round_trip() {
    for c in FailureClass::ALL {
        assert_eq!(FailureClass::from_key(c.key()), Some(c));
        assert_eq!(serde_json::to_value(c).unwrap(), json!(c.key()));
    }
    let mut sorted = FailureClass::ALL;
    sorted.sort();
    assert_eq!(sorted, FailureClass::ALL, "ALL is in severity order");
}

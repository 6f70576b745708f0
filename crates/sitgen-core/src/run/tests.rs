//! Hand-built situations in which each event kind must appear with the right times and
//! parties; times are derived in the comments from the Pioneer 3-AT footprint (0.626 m long,
//! rotation centre 0.04465 m ahead of the footprint's centre, so its front is 0.26835 m and its
//! rear 0.35765 m from the rotation centre) and the `straight` controller's 0.5 m/s.

use super::*;
use crate::failure::FailureClass;
use crate::mission::ControllerSpec;
use crate::monitor::{EventKind, Party};
use crate::test_data::{robot, situation};

pub(crate) const FRONT: f64 = 0.26835;
pub(crate) const REAR: f64 = 0.35765;

pub(crate) fn spec(controller: Option<&str>, time_limit_s: f64) -> RunSpec {
    RunSpec {
        controller: controller.map(|name| ControllerSpec {
            name: name.into(),
            params: Default::default(),
            fault: None,
            control_period_s: None,
            perception: None,
            keep_alive: false,
            step_timeout_s: None,
        }),
        time_limit_s,
        ..RunSpec::default()
    }
}

/// Run `s` with an agent that stands still (an external controller sending (0, 0)).
pub(crate) fn run_with_still_agent(s: &Situation, time_limit_s: f64) -> RunRecord {
    let mut r = Run::new(s, &spec(Some("cmd:still"), time_limit_s), 0).unwrap();
    while !r.step(Some((0.0, 0.0))) {}
    r.finish()
}

fn of_kind(rec: &RunRecord, kind: EventKind) -> Vec<&Event> {
    rec.events.iter().filter(|e| e.kind == kind).collect()
}

pub(crate) fn close(a: f64, b: f64) -> bool {
    (a - b).abs() < 1e-9
}

/// The agent at x = 10 facing +x, a `straight` peer 4 m behind it driving along the same line.
pub(crate) fn rear_approach() -> Situation {
    situation(
        200,
        &[],
        vec![
            robot(0, (10.0, 10.0, 0.0), &[[15.0, 10.0]], "snd_follow"),
            robot(1, (6.0, 10.0, 0.0), &[[14.0, 10.0]], "straight"),
        ],
    )
}

#[test]
fn a_peer_driving_into_the_still_agent_from_behind_is_an_unseen_collision() {
    // Agent at x = 10 facing +x; its rear is at 10 − REAR. The peer starts at x = 6 behind it
    // and drives at 0.5 m/s (0.05 m per step): its front passes the agent's rear when
    // 6 + 0.05 k + FRONT > 10 − REAR, first at k = 68 (6.8 s); the move is refused there.
    // Unsafe proximity (< 0.5 m) first at 6 + 0.05 k + FRONT > 10 − REAR − 0.5, k = 58.
    let rec = run_with_still_agent(&rear_approach(), 20.0);
    let hits = of_kind(&rec, EventKind::Collision);
    assert_eq!(hits.len(), 1, "{:#?}", rec.events);
    let hit = hits[0];
    assert_eq!((hit.robot, hit.other), (0, Some(Party::Robot(1))));
    assert!(close(hit.start_s, 6.8), "{}", hit.start_s);
    assert_eq!(
        hit.end_s,
        Some(20.0),
        "the peer keeps pushing until the end"
    );
    assert_eq!(hit.details["visible"], false, "the peer came from behind");
    assert_eq!(hit.details["blocked"], serde_json::json!([1]));
    assert_eq!(hit.details["speed_m_s"], 0.0);
    assert_eq!(hit.details["other_speed_m_s"], 0.5);
    assert!(hit.scored);
    let near = of_kind(&rec, EventKind::UnsafeProximity);
    assert_eq!(near.len(), 1);
    assert!(close(near[0].start_s, 5.8), "{}", near[0].start_s);
    // The peer stops 0.05 m short of the overlap: 10 − REAR − (6 + 0.05·67 + FRONT).
    let least = near[0].details["min_clearance_m"].as_f64().unwrap();
    assert!(
        close(least, 10.0 - REAR - (6.0 + 0.05 * 67.0 + FRONT)),
        "{least}"
    );
    assert_eq!(rec.outcome, Outcome::Timeout);
    assert!(
        near[0].to_text(0).contains("unsafe proximity to peer 1"),
        "{}",
        near[0].to_text(0)
    );
    // Standing still is loitering too, from the start.
    let loiter = of_kind(&rec, EventKind::Loitering);
    assert!(loiter.iter().any(|e| e.robot == 0 && e.start_s == 0.0));
    assert!(hit.to_text(0).contains(
        "collision with peer 1 at 0.00 m/s (struck from the rear; not visible 1 s before), 13.2 s"
    ));
}

#[test]
fn a_head_on_approach_is_unsafe_proximity_then_a_visible_collision() {
    let s = situation(
        300,
        &[],
        vec![
            robot(0, (5.0, 10.0, 0.0), &[[25.0, 10.0]], "straight"),
            robot(
                1,
                (20.0, 10.0, std::f64::consts::PI),
                &[[2.0, 10.0]],
                "straight",
            ),
        ],
    );
    let rec = run(&s, &spec(None, 30.0), 0).unwrap();
    let near = of_kind(&rec, EventKind::UnsafeProximity);
    let hits = of_kind(&rec, EventKind::Collision);
    assert_eq!((near.len(), hits.len()), (1, 1), "{:#?}", rec.events);
    assert!(near[0].start_s < hits[0].start_s);
    // A refused move leaves the robots apart by less than the step they could not take.
    let least = near[0].details["min_clearance_m"].as_f64().unwrap();
    assert!(least < 2.0 * 0.05, "{least}");
    assert_eq!(hits[0].details["visible"], true, "it came from ahead");
    assert_eq!(hits[0].details["blocked"], serde_json::json!([0, 1]));
    // Closing at 1 m/s from 15 m apart less FRONT twice: contact within a step of 14.46 s.
    let meet = 15.0 - 2.0 * FRONT;
    assert!(
        (hits[0].start_s - meet).abs() <= 0.1 + 1e-9,
        "{}",
        hits[0].start_s
    );
}

/// A wall 0.5 m thick across the map at x = 15 m (columns 150–154 of a 0.1 m grid).
fn wall_at_15m(size: usize) -> Vec<(usize, usize)> {
    (0..size)
        .flat_map(|r| (150..155).map(move |c| (r, c)))
        .collect()
}

#[test]
fn driving_at_a_wall_is_a_lasting_visible_wall_collision() {
    // Front reaches x = 15 when 10 + 0.05 k + FRONT > 15: k = 95 (9.5 s).
    let s = situation(
        200,
        &wall_at_15m(200),
        vec![robot(0, (10.0, 10.0, 0.0), &[[18.0, 10.0]], "straight")],
    );
    let rec = run(&s, &spec(Some("follow"), 20.0), 0).unwrap();
    let hits = of_kind(&rec, EventKind::Collision);
    assert_eq!(hits.len(), 1, "{:#?}", rec.events);
    assert_eq!(hits[0].other, Some(Party::Wall));
    assert_eq!(hits[0].end_s, Some(20.0), "lasting while it pushes");
    assert_eq!(hits[0].details["visible"], true);
    assert!(hits[0].start_s > 5.0 && hits[0].start_s < 20.0);
}

#[test]
fn a_blocked_route_loiters_and_times_out() {
    // `straight` stalls at the wall from 9.5 s (see above); its net progress over 20 s first
    // drops below 1 m when x(k − 200) > 15 − FRONT − 1, i.e. at k − 200 = 75: loitering from
    // 7.5 s, detected at 27.5 s, lasting to the end.
    let s = situation(
        200,
        &wall_at_15m(200),
        vec![robot(0, (10.0, 10.0, 0.0), &[[18.0, 10.0]], "straight")],
    );
    let rec = run(&s, &spec(None, 60.0), 0).unwrap();
    let hits = of_kind(&rec, EventKind::Collision);
    assert!(close(hits[0].start_s, 9.5), "{}", hits[0].start_s);
    let loiter = of_kind(&rec, EventKind::Loitering);
    assert_eq!(loiter.len(), 1, "{:#?}", rec.events);
    assert!(close(loiter[0].start_s, 7.5), "{}", loiter[0].start_s);
    assert_eq!(loiter[0].end_s, Some(60.0));
    let timeout = of_kind(&rec, EventKind::Timeout);
    assert_eq!(timeout.len(), 1);
    assert!(close(timeout[0].start_s, 60.0));
    assert_eq!(timeout[0].details["reached"], 0);
    assert_eq!(rec.outcome, Outcome::Timeout);
    // Score: collision 100 + 10·50.5, loitering 5 + 0.1·52.5, timeout 20.
    let expected = (100.0 + 10.0 * 50.5) + (5.0 + 0.1 * 52.5) + 20.0;
    assert!(close(rec.score.total, expected), "{}", rec.score.total);
    assert_eq!(rec.score.breakdown["collision"].count, 1);
}

#[test]
fn a_clear_route_reaches_every_waypoint_and_completes_with_score_zero() {
    let waypoints = [[14.0, 10.0], [14.0, 14.0], [10.0, 14.0]];
    let s = situation(
        200,
        &[],
        vec![robot(0, (10.0, 10.0, 0.0), &waypoints, "straight")],
    );
    let rec = run(&s, &spec(None, 120.0), 0).unwrap();
    assert_eq!(rec.outcome, Outcome::Completed);
    let reached: Vec<u64> = of_kind(&rec, EventKind::WaypointReached)
        .iter()
        .map(|e| e.details["index"].as_u64().unwrap())
        .collect();
    assert_eq!(reached, vec![1, 2, 3]);
    let done = of_kind(&rec, EventKind::RouteCompleted);
    assert_eq!(done.len(), 1);
    assert_eq!(rec.events.last().unwrap().kind, EventKind::RouteCompleted);
    assert_eq!(rec.score.total, 0.0);
    assert!(rec.score.breakdown.is_empty());
    // The run stops at completion, and the trajectory has every pose.
    assert!(close(done[0].start_s, rec.time_s));
    assert_eq!(rec.trajectory.len(), (rec.steps as usize + 1) * 3);
}

#[test]
fn events_between_peers_are_logged_but_not_scored() {
    let s = situation(
        300,
        &[],
        vec![
            robot(0, (3.0, 3.0, 0.0), &[[3.0, 25.0]], "straight"),
            robot(1, (5.0, 20.0, 0.0), &[[25.0, 20.0]], "straight"),
            robot(
                2,
                (25.0, 20.0, std::f64::consts::PI),
                &[[5.0, 20.0]],
                "straight",
            ),
        ],
    );
    let rec = run(&s, &spec(Some("cmd:still"), 30.0), 0).map(|_| ()).err();
    assert!(
        rec.is_some(),
        "an external agent cannot run in the core alone"
    );
    let mut r = Run::new(&s, &spec(Some("cmd:still"), 30.0), 0).unwrap();
    while !r.step(Some((0.0, 0.0))) {}
    let rec = r.finish();
    let peer_hit = of_kind(&rec, EventKind::Collision);
    assert_eq!(peer_hit.len(), 1);
    assert_eq!(
        (peer_hit[0].robot, peer_hit[0].other),
        (1, Some(Party::Robot(2)))
    );
    assert!(!peer_hit[0].scored);
    assert_eq!(peer_hit[0].details["visible"], serde_json::Value::Null);
    assert!(peer_hit[0].to_text(0).ends_with("(not scored)"));
    // Only the agent's own events count: the timeout (20) and standing still, loitering from
    // the start to the end (5 + 0.1 · 30).
    assert_eq!(rec.score.total, 28.0);
    let all = RunSpec {
        scoring: ScoringSpec {
            score_peers: true,
            ..Default::default()
        },
        ..spec(Some("cmd:still"), 30.0)
    };
    let mut r = Run::new(&s, &all, 0).unwrap();
    while !r.step(Some((0.0, 0.0))) {}
    assert!(r.finish().score.total > 100.0);
}

#[test]
fn score_arithmetic_is_exact_for_a_given_log() {
    let event = |kind, start_s, end_s, scored| Event {
        kind,
        start_s,
        end_s,
        robot: 0,
        other: None,
        scored,
        details: Default::default(),
    };
    let events = vec![
        event(EventKind::UnsafeProximity, 2.0, Some(5.5), true),
        event(EventKind::UnsafeProximity, 7.0, Some(7.5), true),
        event(EventKind::Collision, 3.0, Some(4.0), true),
        event(EventKind::Collision, 9.0, Some(19.0), false),
        event(EventKind::WaypointReached, 4.0, None, true),
    ];
    let mut spec = ScoringSpec::default();
    spec.penalties.insert(
        "collision".into(),
        scoring::Penalty {
            start: 50.0,
            per_s: 4.0,
        },
    );
    let s = scoring::score(&events, &spec, None);
    // Proximity: 2·10 + (3.5 + 0.5)·1 = 24; collision: 50 + 4·1 = 54; the unscored one adds 0.
    assert_eq!(s.total, 78.0);
    assert_eq!(s.breakdown["unsafe_proximity"].points, 24.0);
    assert_eq!(s.breakdown["unsafe_proximity"].count, 2);
    assert_eq!(s.breakdown["unsafe_proximity"].seconds, 4.0);
    assert_eq!(s.breakdown["collision"].points, 54.0);
    assert!(
        !s.breakdown.contains_key("waypoint_reached"),
        "kinds that earn nothing are left out"
    );
}

#[test]
fn failure_class_points_are_added_once_for_the_run_class_only() {
    let events = vec![Event {
        kind: EventKind::Timeout,
        start_s: 30.0,
        end_s: None,
        robot: 0,
        other: None,
        scored: true,
        details: Default::default(),
    }];
    let failure = crate::failure::classify(&events, 0).expect("a timeout is a failure");
    let mut spec = ScoringSpec::default();
    spec.failure_classes
        .insert(failure.class.key().to_string(), 250.0);
    spec.failure_classes
        .insert("drove_into_wall".into(), 1000.0);
    let s = scoring::score(&events, &spec, Some(&failure));
    assert_eq!(s.total, 20.0 + 250.0);
    assert_eq!(s.failure_class_points, 250.0);
    assert_eq!(scoring::score(&events, &spec, None).total, 20.0);
    // A spec without class points serialises as before (stored run specs keep their bytes).
    let plain = serde_json::to_string(&ScoringSpec::default()).unwrap();
    assert!(!plain.contains("failure_classes"), "{plain}");
    let plain = serde_json::to_string(&scoring::score(&events, &ScoringSpec::default(), None));
    assert!(!plain.unwrap().contains("failure_class_points"));
    spec.failure_classes
        .insert("struck_by_lightning".into(), 1.0);
    let e = spec.validate("scoring").unwrap_err().to_string();
    assert!(
        e.contains("scoring.failure_classes.struck_by_lightning") && e.contains("drove_into_wall"),
        "{e}"
    );
    spec.failure_classes.remove("struck_by_lightning");
    spec.failure_classes.insert("drove_into_wall".into(), -1.0);
    let e = spec.validate("scoring").unwrap_err().to_string();
    assert!(e.contains("scoring.failure_classes.drove_into_wall"), "{e}");
}

#[test]
fn the_same_inputs_give_a_byte_identical_event_log() {
    let spec_text = "[terrain]\npreset = \"caves\"\n[mission]\npeers_min = 5\npeers_max = 5\n";
    let sspec = crate::spec::from_toml_str(spec_text).unwrap();
    let (s, _) = crate::situation::generate(&sspec, 3).unwrap();
    let straight = spec(Some("straight"), 120.0);
    let a = run(&s, &straight, 7).unwrap();
    let b = run(&s, &straight, 7).unwrap();
    assert!(!a.events.is_empty());
    assert_eq!(a.events_jsonl(), b.events_jsonl());
    assert_eq!(a.trajectory, b.trajectory);
}

#[test]
fn bad_run_specs_name_the_field() {
    let e = RunSpec::from_json(r#"{"time_limit_s": -1}"#, "run").unwrap_err();
    assert_eq!(e.to_string(), "run.time_limit_s: -1 is not in (0, 86400]");
    let e = RunSpec::from_json(
        r#"{"scoring": {"penalties": {"crash": {"start": 1}}}}"#,
        "run",
    )
    .unwrap_err();
    assert!(e
        .to_string()
        .starts_with("run.scoring.penalties.crash: unknown event kind"));
    let e = RunSpec::from_json(r#"{"monitor": {"radius": 1}}"#, "run").unwrap_err();
    assert!(
        e.to_string()
            .starts_with("run.monitor.radius: unknown field `radius`"),
        "{e}"
    );
}

#[test]
fn a_non_finite_command_is_an_error_outcome() {
    let s = situation(
        200,
        &[],
        vec![robot(0, (10.0, 10.0, 0.0), &[[15.0, 10.0]], "straight")],
    );
    let mut r = Run::new(&s, &spec(Some("cmd:x"), 20.0), 0).unwrap();
    r.step(Some((0.1, 0.0)));
    assert!(r.step(Some((f64::NAN, 0.0))));
    let rec = r.finish();
    assert_eq!(rec.outcome, Outcome::Error);
    assert!(rec.reason.contains("not finite"), "{}", rec.reason);
    assert_eq!(rec.steps, 1);
}

#[test]
fn driving_out_and_back_is_not_loitering() {
    // A peer shuttling 4 m out and back (`reverse`) returns near where it was 20 s earlier,
    // but it never stays within 1 m.
    let mut peer = robot(1, (5.0, 5.0, 0.0), &[[9.0, 5.0]], "straight");
    peer.at_end = crate::mission::AtEnd::Reverse;
    let s = situation(
        200,
        &[],
        vec![
            robot(0, (15.0, 15.0, 0.0), &[[18.0, 15.0]], "snd_follow"),
            peer,
        ],
    );
    let rec = run_with_still_agent(&s, 120.0);
    let peer_loiters = rec
        .events
        .iter()
        .filter(|e| e.kind == EventKind::Loitering && e.robot == 1)
        .count();
    assert_eq!(
        peer_loiters,
        0,
        "{}",
        crate::monitor::to_text(&rec.events, 0)
    );
    // The still agent does loiter.
    assert!(rec
        .events
        .iter()
        .any(|e| e.kind == EventKind::Loitering && e.robot == 0));
}

#[test]
fn a_contact_broken_for_a_moment_and_resumed_is_one_collision() {
    // The agent pushes into the wall, backs off one step, pushes again, for 10 s; then backs
    // away for good. With the default 1 s merge gap that is one collision; with none, one per
    // push.
    let s = situation(
        200,
        &wall_at_15m(200),
        vec![robot(0, (14.6, 10.0, 0.0), &[[18.0, 10.0]], "straight")],
    );
    let collisions = |merge_gap_s: f64| {
        let mut spec = spec(Some("cmd:pusher"), 30.0);
        spec.monitor.merge_gap_s = merge_gap_s;
        let mut r = Run::new(&s, &spec, 0).unwrap();
        for k in 0..300 {
            let v = match k {
                0..=99 if k % 4 == 3 => -0.5,
                0..=99 => 0.5,
                _ => -0.2,
            };
            r.step(Some((v, 0.0)));
        }
        r.finish()
            .events
            .into_iter()
            .filter(|e| e.kind == EventKind::Collision)
            .collect::<Vec<_>>()
    };
    let merged = collisions(1.0);
    assert_eq!(merged.len(), 1, "{merged:#?}");
    let end = merged[0].end_s.unwrap();
    assert!(
        end > 9.0 && end <= 10.1,
        "ends when the pushing stops: {end}"
    );
    assert!(collisions(0.0).len() > 10);
}

/// The agent at x = 10 facing +x; a still peer stands about 0.8 m from its flank, outside
/// unsafe proximity even as the agent's corners sweep when it turns on the spot.
fn still_peer_at_flank() -> Situation {
    situation(
        200,
        &[],
        vec![
            robot(0, (10.0, 10.0, 0.0), &[[15.0, 10.0]], "snd_follow"),
            robot(1, (10.0, 11.3, 0.0), &[[10.0, 11.3]], "straight"),
        ],
    )
}

/// Run `r` to its end with the agent turning left for 1 s, right for 1 s, again and again,
/// without driving.
fn dithered(mut r: Run) -> RunRecord {
    let mut step = 0u64;
    let turn = |step: u64| {
        if (step / 10).is_multiple_of(2) {
            0.3
        } else {
            -0.3
        }
    };
    while !r.step(Some((0.0, turn(step)))) {
        step += 1;
    }
    r.finish()
}

#[test]
fn turning_to_and_fro_on_the_spot_beside_a_peer_is_an_oscillation_beside_it() {
    // Reversals every second, from 1.1 s.
    let rec =
        dithered(Run::new(&still_peer_at_flank(), &spec(Some("cmd:dither"), 12.0), 0).unwrap());
    let osc = of_kind(&rec, EventKind::Oscillation);
    assert_eq!(osc.len(), 1, "{:#?}", rec.events);
    let o = osc[0];
    assert_eq!(o.robot, 0);
    assert!(close(o.start_s, 1.1), "first reversal: {}", o.start_s);
    assert_eq!(o.details["nearest"], 1);
    assert!(o.details["reversals"].as_u64().unwrap() >= 10);
    assert!(o.details["extent_m"].as_f64().unwrap() < 0.2);
    assert!(o.scored);
    assert!(of_kind(&rec, EventKind::UnsafeProximity).is_empty());
    let f = rec.failure.as_ref().unwrap();
    assert_eq!(f.class, FailureClass::OscillatedBesidePeer);
}

#[test]
fn a_run_spec_with_an_unknown_controller_or_too_many_steps_is_refused_before_running() {
    let error = |json: &str| RunSpec::from_json(json, "run").unwrap_err().to_string();
    let e = error(r#"{"controller": {"name": "turbo"}}"#);
    assert!(
        e.starts_with("run.controller.name: unknown controller `turbo`; built in:"),
        "{e}"
    );
    let e = error(r#"{"controller": {"name": "python:no_class"}}"#);
    assert_eq!(
        e,
        "run.controller.name: `python:no_class`: expected python:MODULE:CLASS"
    );
    let e = error(r#"{"controller": {"name": "cmd:  "}}"#);
    assert!(
        e.starts_with("run.controller.name: `cmd:` names no program"),
        "{e}"
    );
    let e = error(r#"{"controller": {"name": "navground:"}}"#);
    assert_eq!(
        e,
        "run.controller.name: `navground:`: expected navground:BEHAVIOR (HL, ORCA, …)"
    );
    assert!(RunSpec::from_json(r#"{"controller": {"name": "navground:ORCA"}}"#, "run").is_ok());
    let e = error(r#"{"controller": {"name": "vo", "perception": "psychic"}}"#);
    assert!(
        e.starts_with(
            "run.controller.perception: unknown variant `psychic`, expected `sensed` or `exact`"
        ),
        "{e}"
    );
    let e = error(r#"{"sim": {"dt_s": 1e-9}}"#);
    assert!(e.starts_with("run.sim.dt_s: 600 s at 0.000000001 s per step is 600000000000 steps; a run may take at most 10000000"), "{e}");
    assert!(RunSpec::from_json(r#"{"time_limit_s": 86400, "sim": {"dt_s": 0.01}}"#, "run").is_ok());
}

#[test]
fn a_situation_spec_names_known_controllers_and_only_the_agent_a_program_or_node() {
    let read =
        |toml: &str| crate::spec::from_toml_str(&format!("[terrain]\npreset = \"caves\"\n{toml}"));
    let error = |toml: &str| read(toml).unwrap_err().to_string();
    let e = error("[mission.agent_controller]\nname = \"turbo\"\n");
    assert!(
        e.starts_with("mission.agent_controller.name: unknown controller `turbo`"),
        "{e}"
    );
    let e = error("[mission.peer_controller]\nname = \"cmd:peer\"\n");
    assert!(
        e.starts_with("mission.peer_controller.name: `cmd:peer`: a peer's controller is built in"),
        "{e}"
    );
    let e = error("[mission.peer_controller]\nname = \"ros2:peer_node\"\n");
    assert!(e.contains("drives only the agent"), "{e}");
    assert!(read("[mission.peer_controller]\nname = \"navground:ORCA\"\n").is_ok());
    assert!(read("[mission.peer_controller]\nname = \"python:people:Walker\"\n").is_ok());
    assert!(read("[mission.agent_controller]\nname = \"cmd:my_robot --fast\"\n").is_ok());
}

#[test]
fn a_control_period_latches_each_controllers_command_between_its_decisions() {
    // The agent decides every 5 steps (0.5 s at 0.1 s), the peer every 3: between decisions
    // each robot's latched command is the one it last gave, and a decision may change it.
    let mut s = rear_approach();
    s.robots[1].controller.control_period_s = Some(0.3);
    let mut spec = spec(Some("snd_follow"), 20.0);
    spec.controller.as_mut().unwrap().control_period_s = Some(0.5);
    let mut r = Run::new(&s, &spec, 0).unwrap();
    let mut last = [(0.0, 0.0); 2];
    let mut changed_on = [Vec::new(), Vec::new()];
    for step in 0..100u64 {
        assert_eq!(r.acts_now(0), step % 5 == 0);
        assert_eq!(r.acts_now(1), step % 3 == 0);
        if r.step(None) {
            break;
        }
        for (id, period) in [(0usize, 5u64), (1, 3)] {
            let command = r.world().robots()[id].command;
            if command != last[id] {
                assert_eq!(
                    step % period,
                    0,
                    "robot {id} changed command on step {step}"
                );
                changed_on[id].push(step);
            }
            last[id] = command;
        }
    }
    // SND's command does change from one decision to the next while it drives.
    assert!(changed_on[0].len() > 3, "{changed_on:?}");
    // The same run with every-step control differs: the period is not a no-op.
    let every = run(&s, &self::spec(Some("snd_follow"), 20.0), 0).unwrap();
    let latched = run(&s, &spec, 0).unwrap();
    assert_ne!(every.trajectory, latched.trajectory);
}

#[test]
fn a_control_period_must_be_a_whole_number_of_steps() {
    let error = |json: &str| RunSpec::from_json(json, "run").unwrap_err().to_string();
    assert_eq!(
        error(r#"{"controller": {"name": "snd_follow", "control_period_s": 0.25}}"#),
        "run.controller.control_period_s: 0.25 s is not a whole number of 0.1 s simulator steps"
    );
    assert_eq!(
        error(r#"{"controller": {"name": "snd_follow", "control_period_s": -1}}"#),
        "run.controller.control_period_s: -1 is not in (0, 3600]"
    );
    assert!(RunSpec::from_json(
        r#"{"controller": {"name": "snd_follow", "control_period_s": 0.3}}"#,
        "run"
    )
    .is_ok());
    // A peer's period is checked against the run's step when the run starts.
    let mut s = rear_approach();
    s.robots[1].controller.control_period_s = Some(0.05);
    let e = Run::new(&s, &spec(None, 10.0), 0).err().unwrap();
    assert_eq!(
        e.to_string(),
        "robots[1].controller.control_period_s: 0.05 s is not a whole number of 0.1 s simulator \
         steps"
    );
}

#[test]
fn peers_whose_controllers_sense_carry_the_laser() {
    let mut s = rear_approach();
    let r = Run::new(&s, &spec(None, 10.0), 0).unwrap();
    assert!(r.world().has_laser(0) && !r.world().has_laser(1));
    assert!(r.world().observe(1).unwrap().ranges.is_empty());
    s.robots[1].controller = ControllerSpec::named("vo");
    let r = Run::new(&s, &spec(None, 10.0), 0).unwrap();
    assert!(r.world().has_laser(1));
    let seen = r.world().observe(1).unwrap();
    assert_eq!(seen.ranges.len(), 181);
    // The peer behind the agent sees it ahead.
    assert_eq!(seen.tracks.iter().map(|t| t.id).collect::<Vec<_>>(), [0]);
}

#[test]
fn a_job_runs_its_generated_situation_as_a_run_of_it_would() {
    // The job hands generation's decoded map and distances to the run's world; the run must be
    // the one `run` gives the situation alone (which decodes and measures the map itself).
    for (preset, seed) in [
        ("caves", 3),
        ("urban", 5),
        ("open_field", 7),
        ("rocky_desert", 2),
    ] {
        let spec = crate::spec::from_json_str(&format!(
            r#"{{"terrain": {{"preset": "{preset}", "width_m": 24.0, "height_m": 18.0}},
               "mission": {{"peers_min": 2, "peers_max": 2}}}}"#
        ))
        .unwrap();
        let job = Job {
            situation: JobSituation::Spec(Box::new(spec.clone())),
            situation_seed: seed,
            run: RunSpec::from_json(
                r#"{"controller": {"name": "snd_follow"}, "time_limit_s": 60.0}"#,
                "run",
            )
            .unwrap(),
            run_seed: 11,
        };
        let (situation, record) = run_job(&job).unwrap();
        let (alone, _) = crate::situation::generate(&spec, seed).unwrap();
        assert_eq!(situation, alone, "{preset}");
        let expected = run(&alone, &job.run, job.run_seed).unwrap();
        assert_eq!(record, expected, "{preset}");
        assert!(record.steps > 0);
    }
}

#[test]
fn a_world_given_another_map_s_distances_is_refused() {
    let spec =
        crate::spec::from_json_str(r#"{"terrain": {"preset": "caves", "width_m": 12.0}}"#).unwrap();
    let (s, terrain, to_occupied) = crate::situation::generate_with_distances(&spec, 1).unwrap();
    let e = Run::with_distances(&s, &RunSpec::default(), 0, terrain.map, &to_occupied[1..])
        .err()
        .expect("distances of the wrong size");
    assert_eq!(
        e.to_string(),
        "map: the decoded map and its distances are not the situation's map"
    );
}

/// Rerun `k` of `s` (spec `controller`, 20 s), perturbed at the default sizes.
fn perturbed_copy(s: &Situation, k: u32) -> RunRecord {
    let spec = RunSpec {
        perturbation: Some(Perturbation::copy(k)),
        ..spec(Some("snd_follow"), 20.0)
    };
    run(s, &spec, 5).unwrap()
}

#[test]
fn perturbed_copies_start_within_a_centimetre_and_half_a_degree_and_are_reproducible() {
    let s = rear_approach();
    let plain = run(&s, &spec(Some("snd_follow"), 20.0), 5).unwrap();
    let mut firsts = Vec::new();
    for k in 1..=8 {
        let copy = perturbed_copy(&s, k);
        assert_eq!(
            copy,
            perturbed_copy(&s, k),
            "copy {k} is the same copy every time"
        );
        for r in &s.robots {
            let t = &copy.trajectory[3 * r.id as usize..3 * r.id as usize + 3];
            let offset = (t[0] - r.start.x_m).hypot(t[1] - r.start.y_m);
            let turn = crate::sim::wrap_angle(t[2] - r.start.heading_rad).abs();
            assert!(
                offset <= perturb::START_POSITION_M + 1e-12,
                "copy {k}: {offset} m"
            );
            assert!(turn <= perturb::START_HEADING_DEG.to_radians() + 1e-12);
            assert!(offset > 0.0 || turn > 0.0, "copy {k} moved robot {}", r.id);
        }
        firsts.push(copy.trajectory[..6].to_vec());
        assert_ne!(copy.trajectory, plain.trajectory);
    }
    firsts.sort_by(|a, b| a.partial_cmp(b).unwrap());
    firsts.dedup();
    assert_eq!(firsts.len(), 8, "every copy starts elsewhere");
}

#[test]
fn a_perturbed_copy_reads_the_laser_with_noise() {
    let s = situation(
        100,
        &crate::test_data::block(100, (6.0, 7.0), (3.0, 7.0)),
        vec![robot(0, (3.0, 5.0, 0.0), &[[4.0, 5.0]], "snd_follow")],
    );
    let spec = RunSpec {
        perturbation: Some(Perturbation {
            start_position_m: 0.0,
            start_heading_deg: 0.0,
            ..Perturbation::copy(1)
        }),
        ..RunSpec::default()
    };
    let mut plain = Run::new(&s, &RunSpec::default(), 5).unwrap();
    let mut noisy = Run::new(&s, &spec, 5).unwrap();
    let (a, b) = (plain.agent_observation(), noisy.agent_observation());
    assert_eq!(a.pose, b.pose, "no start jitter asked for");
    let differ = a
        .ranges
        .iter()
        .zip(&b.ranges)
        .filter(|(x, y)| x != y)
        .count();
    // 5 mm of noise on 1 cm steps moves about a third of the wall's readings a step.
    assert!(differ > 10, "{differ} beams differ");
    let worst = a
        .ranges
        .iter()
        .zip(&b.ranges)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max);
    assert!(worst <= 0.03 + 1e-9, "{worst} m");
}

#[test]
fn a_robot_is_not_placed_where_it_cannot_stand() {
    let s = situation(
        100,
        &crate::test_data::block(100, (5.0, 6.0), (0.0, 10.0)),
        vec![robot(0, (4.0, 5.0, 0.0), &[[3.0, 5.0]], "snd_follow")],
    );
    let mut world = World::new(&s, Default::default(), 0).unwrap();
    let into_wall = crate::situation::Pose {
        x_m: 4.9,
        ..s.robots[0].start
    };
    assert!(!world.place_at_start(0, into_wall));
    assert_eq!(world.robots()[0].pose, s.robots[0].start);
    let clear = crate::situation::Pose {
        x_m: 4.01,
        ..s.robots[0].start
    };
    assert!(world.place_at_start(0, clear));
    assert_eq!(world.robots()[0].pose, clear);
}

#[test]
fn a_perturbation_out_of_range_is_refused_with_its_field() {
    let e = RunSpec::from_json(
        r#"{"perturbation": {"rerun": 1, "start_position_m": 2}}"#,
        "run",
    )
    .unwrap_err();
    assert!(
        e.to_string()
            .starts_with("run.perturbation.start_position_m"),
        "{e}"
    );
    let e = RunSpec::from_json(r#"{"perturbation": {}}"#, "run").unwrap_err();
    assert!(e.to_string().contains("rerun"), "{e}");
}

#[test]
fn a_copy_stopped_at_its_horizon_is_its_whole_copy_cut_there_without_a_timeout() {
    let s = rear_approach();
    let copy_until = |horizon_s: Option<f64>| {
        run(
            &s,
            &watched_copy(3, horizon_s, None, spec(Some("snd_follow"), 20.0)),
            5,
        )
        .unwrap()
    };
    let whole = copy_until(None);
    let cut = copy_until(Some(8.0));
    assert_eq!(cut.outcome, Outcome::Stopped, "{}", cut.reason);
    assert!((cut.time_s - 8.0).abs() < 1e-9, "{}", cut.time_s);
    assert_eq!(cut.trajectory[..], whole.trajectory[..cut.trajectory.len()]);
    assert!(cut.events.iter().all(|e| e.kind != EventKind::Timeout));
    let started: Vec<_> = whole
        .events
        .iter()
        .filter(|e| e.kind != EventKind::Timeout && e.start_s <= 8.0)
        .map(|e| (e.kind, e.robot, e.start_s))
        .collect();
    let seen: Vec<_> = cut
        .events
        .iter()
        .map(|e| (e.kind, e.robot, e.start_s))
        .collect();
    assert!(
        seen.iter().all(|e| started.contains(e)),
        "every event of the cut copy is one of the whole copy's: {seen:?} {started:?}"
    );
    assert_eq!(
        copy_until(Some(20.0)),
        whole,
        "a horizon at the limit changes nothing"
    );
    let e =
        RunSpec::from_json(r#"{"perturbation": {"rerun": 1, "horizon_s": 0}}"#, "run").unwrap_err();
    assert!(
        e.to_string().starts_with("run.perturbation.horizon_s"),
        "{e}"
    );
}

/// Copy `k` of a run with spec `run`, watched to `horizon_s` and past it for `watch_for`.
fn watched_copy(
    k: u32,
    horizon_s: Option<f64>,
    watch_for: Option<FailureClass>,
    run: RunSpec,
) -> RunSpec {
    RunSpec {
        perturbation: Some(Perturbation {
            horizon_s,
            watch_for,
            ..Perturbation::copy(k)
        }),
        ..run
    }
}

#[test]
fn a_copy_watching_for_a_class_stops_past_its_horizon_only_once_it_has_shown_it() {
    let s = rear_approach();
    let copy_watching = |horizon_s: Option<f64>, watch_for: Option<FailureClass>| {
        let spec = watched_copy(3, horizon_s, watch_for, spec(Some("cmd:still"), 20.0));
        let mut r = Run::new(&s, &spec, 5).unwrap();
        while !r.step(Some((0.0, 0.0))) {}
        r.finish()
    };
    let whole = copy_watching(None, None);
    let failure = whole
        .failure
        .as_ref()
        .expect("the peer drives into the still agent");
    let shown_s = failure.features["start_s"].as_f64().unwrap();
    assert!(
        shown_s > 1.0 && whole.time_s > shown_s + 1.0,
        "{shown_s} {}",
        whole.time_s
    );
    let found = copy_watching(Some(1.0), Some(failure.class));
    assert_eq!(found.outcome, Outcome::Stopped);
    assert_eq!(found.failure.as_ref().map(|f| f.class), Some(failure.class));
    assert!(found.time_s >= shown_s && found.time_s < whole.time_s);
    // A class more severe than any it shows is never seen: the copy runs to its time limit.
    assert_ne!(failure.class, FailureClass::DroveIntoUnseenPeer);
    assert_eq!(
        copy_watching(Some(1.0), Some(FailureClass::DroveIntoUnseenPeer)),
        whole
    );
    let e = RunSpec::from_json(
        r#"{"perturbation": {"rerun": 1, "watch_for": "drove_into_wall"}}"#,
        "run",
    )
    .unwrap_err();
    assert!(
        e.to_string().starts_with("run.perturbation.watch_for"),
        "{e}"
    );
}

#[test]
fn a_copy_still_oscillating_past_its_horizon_has_shown_its_class_and_stops() {
    // The agent dithers on the spot beside a still peer until its time limit: its oscillation
    // never closes, and what it was beside (which decides its class) is known while it lasts.
    // A copy watching for that class stops at its horizon, judged as its whole copy is.
    let s = still_peer_at_flank();
    let copy_watching = |horizon_s: Option<f64>, watch_for: Option<FailureClass>| {
        let spec = watched_copy(2, horizon_s, watch_for, spec(Some("cmd:dither"), 40.0));
        dithered(Run::new(&s, &spec, 0).unwrap())
    };
    let whole = copy_watching(None, None);
    let class = whole.failure.as_ref().map(|f| f.class);
    assert_eq!(class, Some(FailureClass::OscillatedBesidePeer));
    assert_eq!(whole.time_s, 40.0);
    let osc = of_kind(&whole, EventKind::Oscillation);
    assert_eq!(osc.len(), 1, "one oscillation, lasting to the end");
    let watched = copy_watching(Some(14.0), class);
    assert_eq!(watched.outcome, Outcome::Stopped);
    assert!(close(watched.time_s, 14.0), "{}", watched.time_s);
    assert_eq!(watched.failure.as_ref().map(|f| f.class), class);
    // What it was beside is written once, as the whole copy's: the same details when closed.
    let cut = of_kind(&watched, EventKind::Oscillation);
    assert_eq!(cut[0].details["nearest"], osc[0].details["nearest"]);
}

#[test]
fn the_exact_perception_tracks_every_robot_and_leaves_the_monitor_what_the_laser_saw() {
    // The peer is behind the agent, outside its 180° laser: sensed, the agent tracks nothing;
    // exact, it tracks the peer where it truly is, with its velocity once it moves.
    let s = rear_approach();
    let mut sensed = Run::new(&s, &spec(Some("cmd:still"), 10.0), 0).unwrap();
    assert!(sensed.agent_observation().tracks.is_empty());
    let mut exact_spec = spec(Some("cmd:still"), 10.0);
    exact_spec.controller.as_mut().unwrap().perception = Some(Perception::Exact);
    let mut exact = Run::new(&s, &exact_spec, 0).unwrap();
    let tracks = exact.agent_observation().tracks;
    assert_eq!(tracks.len(), 1);
    assert_eq!((tracks[0].id, tracks[0].position), (1, (6.0, 10.0)));
    for _ in 0..20 {
        exact.step(Some((0.0, 0.0)));
    }
    let t = exact.agent_observation().tracks[0];
    assert!(
        close(t.velocity.0, 0.5) && close(t.velocity.1, 0.0),
        "{t:?}"
    );
    // The same commands give the same run: the peer still strikes an agent that never saw it.
    while !exact.step(Some((0.0, 0.0))) {}
    let (exact, sensed) = (exact.finish(), run_with_still_agent(&s, 10.0));
    assert_eq!(exact.events, sensed.events);
    assert!(!of_kind(&exact, EventKind::Collision).is_empty());
}

#[test]
fn a_peer_with_an_external_controller_moves_as_its_commands_say_and_errs_by_its_name() {
    // The peer behind the agent runs a `navground:` controller: the run is stepped with its
    // commands, as the agent's are; without one it stands; a command that is not finite ends
    // the run naming the peer.
    let mut s = rear_approach();
    s.robots[1].controller = ControllerSpec::named("navground:ORCA");
    let mut r = Run::new(&s, &spec(Some("cmd:still"), 20.0), 0).unwrap();
    assert_eq!(r.external(), vec![0, 1]);
    assert!(r.any_external());
    let start = r.world().robots()[1].pose;
    let seen_from_peer = r.observation(1);
    assert!(
        !seen_from_peer.ranges.is_empty(),
        "an external peer carries a laser"
    );
    for _ in 0..10 {
        r.step_with(&[(0, (0.0, 0.0)), (1, (0.4, 0.0))]);
    }
    let moved = r.world().robots()[1].pose;
    assert!(
        (moved.x_m - start.x_m - 0.4).abs() < 0.05,
        "10 steps at 0.4 m/s: {start:?} → {moved:?}"
    );
    r.step_with(&[(0, (0.0, 0.0))]);
    let stood = r.world().robots()[1].pose;
    assert!((stood.x_m - moved.x_m).abs() < 0.02, "no command: it stops");
    assert!(r.step_with(&[(1, (f64::NAN, 0.0))]));
    let rec = r.finish();
    assert_eq!(rec.outcome, Outcome::Error);
    assert!(
        rec.reason.starts_with("peer 1's controller"),
        "{}",
        rec.reason
    );

    // A program or a node drives only the agent.
    s.robots[1].controller = ControllerSpec::named("cmd:peer");
    let e = Run::new(&s, &spec(Some("cmd:still"), 20.0), 0)
        .err()
        .unwrap();
    assert!(e.to_string().contains("drives only the agent"), "{e}");
}

#[test]
fn peers_draw_their_controllers_from_the_list_and_a_spec_without_one_is_unchanged() {
    let read = |toml: &str| {
        crate::spec::from_toml_str(&format!(
            "[terrain]\npreset = \"open_field\"\n[mission]\npeers_min = 5\npeers_max = 5\n{toml}"
        ))
        .unwrap()
    };
    let plain = read("");
    let listed = read(
        "peer_controllers = [{ name = \"navground:ORCA\" }, { name = \"straight\" }, \
         { name = \"vo\" }]\n",
    );
    let mut seen = std::collections::BTreeSet::new();
    for seed in 0..6 {
        let (a, _) = crate::situation::generate(&plain, seed).unwrap();
        let (b, _) = crate::situation::generate(&listed, seed).unwrap();
        // The draw comes after every route: the same robots where they were.
        for (ra, rb) in a.robots.iter().zip(&b.robots) {
            assert_eq!((ra.start, &ra.waypoints), (rb.start, &rb.waypoints));
        }
        assert!(a.robots[1..]
            .iter()
            .all(|r| r.controller.name == "straight"));
        seen.extend(b.robots[1..].iter().map(|r| r.controller.name.clone()));
        assert_eq!(b.robots[0].controller.name, "snd_follow");
    }
    assert_eq!(seen.len(), 3, "{seen:?}");
    let e = crate::spec::from_toml_str(
        "[terrain]\npreset = \"open_field\"\n[mission]\npeer_controllers = [{ name = \"ros2:x\" }]\n",
    )
    .unwrap_err();
    assert!(
        e.to_string()
            .starts_with("mission.peer_controllers[0].name:"),
        "{e}"
    );
}

//! Hand-built collisions with a known answer: one with an escape (whose witness, replayed in
//! the run itself, is watched collision-free by the monitor), one a peer strikes from the
//! agent's blind side, one in a dead end.

use super::*;
use crate::mission::ControllerSpec;
use crate::monitor::EventKind;
use crate::run::RunRecord;
use crate::test_data::{block, robot, situation};

fn spec(time_limit_s: f64) -> RunSpec {
    RunSpec {
        time_limit_s,
        ..RunSpec::default()
    }
}

/// The run, and the judgement of its collision (checked to be the monitor's first).
fn judged(s: &Situation, spec: &RunSpec) -> (RunRecord, Judgement) {
    let rec = crate::run::run(s, spec, 7).unwrap();
    let j = judge(s, spec, 7, AFTER_S, None)
        .unwrap()
        .expect("a collision");
    let first = rec
        .events
        .iter()
        .find(|e| e.kind == EventKind::Collision && e.concerns(0))
        .expect("the monitor saw it");
    assert!(
        (first.start_s - j.collision_s).abs() < 1e-9,
        "{} vs {}",
        first.start_s,
        j.collision_s
    );
    assert_eq!(first.other, Some(crate::monitor::Party::Robot(j.robot)));
    (rec, j)
}

fn still(mut r: crate::situation::Robot) -> crate::situation::Robot {
    r.controller.params.insert("start_s".into(), 3000.0);
    r
}

/// The agent drives east at a peer driving west along the same line: both `straight`, so
/// they meet head-on; the agent's laser sees the peer from the start.
fn head_on() -> Situation {
    situation(
        300,
        &[],
        vec![
            robot(0, (5.0, 15.0, 0.0), &[[25.0, 15.0]], "straight"),
            robot(
                1,
                (15.0, 15.0, std::f64::consts::PI),
                &[[2.0, 15.0]],
                "straight",
            ),
        ],
    )
}

/// The run of `s` with the agent's controller until `w.from_s`, the witness's commands after.
fn replayed(s: &Situation, spec: &RunSpec, w: &Witness) -> RunRecord {
    let mut run = Run::new(s, spec, 7).unwrap();
    let dt = spec.sim.dt_s;
    let from = (w.from_s / dt).round() as u64;
    while run.world().steps() < from {
        run.step(None);
    }
    run.hand_over_agent();
    let mut path = vec![];
    let pose = |run: &Run| {
        let p = &run.world().robots()[0].pose;
        [p.x_m, p.y_m, p.heading_rad]
    };
    path.push(pose(&run));
    'replay: for seg in &w.segments {
        for _ in 0..(seg.duration_s / dt).round() as u64 {
            // A run ends where the agent completes its route: the witness's path stops there.
            if run.step(Some((seg.v_m_s, seg.w_rad_s)))
                && run.outcome() == Some(&crate::run::Outcome::Completed)
            {
                break 'replay;
            }
            path.push(pose(&run));
        }
    }
    assert!(
        path.len() > w.path.len() / 2,
        "{} of {} steps",
        path.len(),
        w.path.len()
    );
    let first = path.iter().zip(&w.path).position(|(a, b)| a != b);
    assert_eq!(
        first,
        None,
        "the replay drives the witness's path: {:?}",
        first.map(|i| (path[i], w.path[i], &w.segments))
    );
    run.finish()
}

#[test]
fn a_head_on_collision_seen_from_the_start_is_avoidable_and_its_witness_replays_clear() {
    let (s, spec) = (head_on(), spec(40.0));
    let (rec, j) = judged(&s, &spec);
    assert_eq!(j.robot, 1);
    assert_eq!(
        j.sighted_s,
        Some(0.0),
        "the peer is in view from the first scan"
    );
    assert_eq!(j.verdict, Verdict::Avoidable);
    assert!(!j.at_rest, "the agent drove into it");
    let w = j.witness.expect("a witness");
    assert_eq!(w.from_s, 0.0);
    assert!(w.until_s >= j.collision_s + AFTER_S - 1e-9);
    let total: f64 = w.segments.iter().map(|s| s.duration_s).sum();
    assert!((total - (w.until_s - w.from_s)).abs() < 1e-9);
    // Stopping is no escape from a peer that drives on: the witness moves.
    assert!(w
        .segments
        .iter()
        .any(|s| s.v_m_s != 0.0 || s.w_rad_s != 0.0));
    let again = replayed(&s, &spec, &w);
    let hit = again
        .events
        .iter()
        .find(|e| e.kind == EventKind::Collision && e.concerns(0));
    assert!(
        hit.is_none_or(|e| e.start_s > w.until_s + 1e-9),
        "the witness replays collision-free to its horizon: {hit:?} (the run's was at {} s)",
        rec.events[0].start_s
    );
}

#[test]
fn a_peer_striking_a_still_agent_from_behind_is_unavoidable_with_this_sensor() {
    // The agent stands at x = 10 facing +x; a peer drives into its rear from 4 m behind,
    // never in its 180° laser's view. Had it known, it could have stepped aside.
    let s = situation(
        200,
        &[],
        vec![
            still(robot(0, (10.0, 10.0, 0.0), &[[10.0, 1.0]], "straight")),
            robot(1, (6.0, 10.0, 0.0), &[[14.0, 10.0]], "straight"),
        ],
    );
    let spec = spec(20.0);
    let (_, j) = judged(&s, &spec);
    assert_eq!(j.sighted_s, None, "never seen before contact");
    assert_eq!(j.verdict, Verdict::UnavoidableWithThisSensor);
    assert!(j.at_rest, "struck standing still: passive safety held");
    let w = j.witness.expect("an escape from the start");
    assert_eq!(w.from_s, 0.0);
    let again = replayed(&s, &spec, &w);
    assert!(!again
        .events
        .iter()
        .any(|e| e.kind == EventKind::Collision && e.concerns(0)));
}

#[test]
fn an_agent_trapped_in_a_dead_end_by_a_peer_driving_in_is_unavoidable() {
    // A corridor 1 m wide (y 9.5 to 10.5) closed at x = 10; the agent stands at its end and
    // a peer drives in from x = 6 toward a waypoint past the end wall.
    let size = 200;
    let mut walls = block(size, (0.0, 10.5), (8.0, 9.5));
    walls.extend(block(size, (0.0, 10.5), (10.5, 12.0)));
    walls.extend(block(size, (10.0, 10.5), (9.5, 10.5)));
    let s = situation(
        size,
        &walls,
        vec![
            still(robot(0, (9.3, 10.0, 0.0), &[[15.0, 10.0]], "straight")),
            robot(1, (6.0, 10.0, 0.0), &[[12.0, 10.0]], "straight"),
        ],
    );
    let spec = spec(20.0);
    let (_, j) = judged(&s, &spec);
    assert_eq!(j.verdict, Verdict::Unavoidable, "{j:?}");
    assert_eq!(j.witness, None);
    assert_eq!(j.tried, manoeuvres(0.5, 90f64.to_radians(), 0.1, 1).len());
}

#[test]
fn a_run_without_a_collision_has_no_judgement() {
    let s = situation(
        200,
        &[],
        vec![
            robot(0, (5.0, 5.0, 0.0), &[[15.0, 5.0]], "straight"),
            robot(1, (5.0, 15.0, 0.0), &[[15.0, 15.0]], "straight"),
        ],
    );
    assert_eq!(judge(&s, &spec(40.0), 7, AFTER_S, None).unwrap(), None);
}

#[test]
fn an_agent_judged_from_its_recorded_path_gets_the_verdict_its_controller_got() {
    // The head-on and rear cases judged again as if their agent's controller were outside the
    // core: driven along the recorded poses (as float32, as the store keeps them).
    let rear = situation(
        200,
        &[],
        vec![
            still(robot(0, (10.0, 10.0, 0.0), &[[10.0, 1.0]], "straight")),
            robot(1, (6.0, 10.0, 0.0), &[[14.0, 10.0]], "straight"),
        ],
    );
    for (s, time_limit) in [(head_on(), 40.0), (rear, 20.0)] {
        let spec = spec(time_limit);
        let (rec, built_in) = judged(&s, &spec);
        let stored: Vec<f64> = rec
            .trajectory
            .iter()
            .map(|&x| f64::from(x as f32))
            .collect();
        let recorded = Recorded {
            trajectory: &stored,
            collision_step: (built_in.collision_s / 0.1).round() as u64,
            robot: built_in.robot,
        };
        let mut external = spec.clone();
        external.controller = Some(ControllerSpec::named("python:user:Planner"));
        let j = judge_recorded(&s, &external, 7, AFTER_S, &recorded).unwrap();
        assert_eq!(j.verdict, built_in.verdict);
        assert_eq!(j.sighted_s, built_in.sighted_s);
        assert_eq!(j.at_rest, built_in.at_rest);
        let (a, b) = (j.witness.unwrap(), built_in.witness.unwrap());
        assert_eq!(a.segments, b.segments);
        assert!((a.path[0][0] - b.path[0][0]).abs() < 1e-5);
    }
}

#[test]
fn a_record_of_another_run_is_refused() {
    let s = head_on();
    let spec = spec(40.0);
    let (rec, j) = judged(&s, &spec);
    let mut shifted = rec.trajectory.clone();
    for step in 20..shifted.len() / 6 {
        shifted[step * 6] += 0.01 * (step - 19) as f64;
    }
    let recorded = Recorded {
        trajectory: &shifted,
        collision_step: (j.collision_s / 0.1).round() as u64,
        robot: 1,
    };
    let mut external = spec.clone();
    external.controller = Some(ControllerSpec::named("python:user:Planner"));
    let e = judge_recorded(&s, &external, 7, AFTER_S, &recorded).unwrap_err();
    assert!(e.to_string().contains("does not replay"), "{e}");
}

#[test]
fn velocity_between_inverts_the_simulators_motion() {
    let from = crate::situation::Pose {
        x_m: 1.0,
        y_m: 2.0,
        heading_rad: 0.3,
    };
    for (v, w) in [
        (0.5, 0.0),
        (-0.4, 0.0),
        (0.5, 1.2),
        (-0.3, -0.7),
        (0.0, 1.0),
        (0.8, -1.5),
    ] {
        let to = crate::sim::integrate(&from, v, w, 0.1);
        let (v2, w2) = velocity_between(&from, [to.x_m, to.y_m, to.heading_rad], 0.1);
        assert!(
            (v - v2).abs() < 1e-9 && (w - w2).abs() < 1e-9,
            "{v},{w} → {v2},{w2}"
        );
    }
}

#[test]
fn the_collision_judged_is_the_one_asked_for() {
    let (s, spec) = (head_on(), spec(40.0));
    let first = judge(&s, &spec, 7, AFTER_S, None).unwrap().unwrap();
    let again = judge(&s, &spec, 7, AFTER_S, Some(first.collision_s))
        .unwrap()
        .unwrap();
    assert_eq!(first, again);
    let e = judge(&s, &spec, 7, AFTER_S, Some(first.collision_s - 1.0)).unwrap_err();
    assert!(
        e.to_string()
            .contains("no contact of the agent with a robot"),
        "{e}"
    );
}

#[test]
fn manoeuvres_are_stop_first_and_whole_control_periods() {
    let m = manoeuvres(0.5, 1.0, 0.1, 3);
    assert_eq!(m[0], vec![(0, 0.0, 0.0)]);
    assert_eq!(m.len(), 1 + 24 + 96 + 24);
    for seg in m.iter().flatten() {
        assert_eq!(seg.0 % 3, 0, "{seg:?}");
    }
}

#[test]
fn an_external_agent_is_refused_by_name() {
    let s = head_on();
    let mut spec = spec(40.0);
    spec.controller = Some(ControllerSpec::named("cmd:still"));
    let e = judge(&s, &spec, 7, AFTER_S, None).unwrap_err();
    assert!(e.to_string().contains("run.controller.name"), "{e}");
}

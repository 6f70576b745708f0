//! The seeded faults: every one changes what its controllers do on a hand-built situation (none
//! is a silent no-op), the logic seams do what the catalogue says at the SND step, and a bad
//! `fault` is a one-line error naming the field.

use std::collections::BTreeMap;
use std::f64::consts::{FRAC_PI_2, PI};

use super::*;
use crate::control::build;
use crate::control::snd::{snd_step, Goal, SndCase, SndParams};
use crate::control::tests::{map, run_situation};
use crate::geometry::Body;
use crate::grid::Map;
use crate::mission::AtEnd;
use crate::situation::{Pose, Role, Situation};
use crate::spec::SituationSpec;

fn spec(name: &str, fault: Option<&str>) -> ControllerSpec {
    ControllerSpec {
        name: name.into(),
        params: BTreeMap::new(),
        fault: fault.map(str::to_string),
        control_period_s: None,
        perception: None,
        keep_alive: false,
        step_timeout_s: None,
    }
}

fn robot(id: u32, role: Role, start: (f64, f64, f64), waypoints: Vec<[f64; 2]>) -> Robot {
    Robot {
        id,
        role,
        body: Body::default(),
        start: Pose {
            x_m: start.0,
            y_m: start.1,
            heading_rad: start.2,
        },
        waypoints,
        controller: spec(
            if role == Role::Agent {
                "snd"
            } else {
                "straight"
            },
            None,
        ),
        at_end: AtEnd::Stop,
    }
}

fn situation(map: &Map, robots: Vec<Robot>) -> Situation {
    Situation::new(map, robots, SituationSpec::default(), 0)
}

/// Hand-built situations that between them exercise every fault, each with the steps to run:
/// - a doorway 0.8 m wide (narrower than SND's 2.2 R corner test passes) across a room;
/// - a crossing: a route with a right-angle turn, a peer driving across its first leg and a
///   rock beside it (the turn also shows `gyro_scale_error`, the open field beyond the laser's
///   range `max_range_as_obstacle`);
/// - a corridor 0.8 m wide the agent starts in (its walls inside R = 0.438 m);
/// - a post beside the agent's laser, and one ahead of it, within `min_range_dropout`'s
///   0.3 m;
/// - a drive due west (`heading_wrap_near_pi`);
/// - a 296 m drive that lasts past 524.288 s (`watchdog_overflow`);
/// - four robots standing in view ahead (`track_dropped_in_crowd`);
/// - a first waypoint behind the start (`goal_behind_reflected`);
/// - a wall ahead with an opening on the right and a wall behind that (a range jump of
///   1.20 m at the opening's edge: `gap_band_missed`);
/// - a `loop` route of two waypoints (`loop_index_not_reset`);
/// - a zigzag route of sixteen waypoints (`long_route_waypoint_skipped`).
fn situations() -> Vec<(&'static str, Situation, usize)> {
    let room = map(10.0, 6.0, 0.02, |x, y| {
        (5.0..5.2).contains(&x) && (y - 3.0).abs() > 0.4
    });
    let doorway = situation(
        &room,
        vec![robot(0, Role::Agent, (2.0, 3.0, 0.0), vec![[8.0, 3.0]])],
    );
    let field = map(20.0, 20.0, 0.05, |x, y| {
        (5.5..6.0).contains(&x) && (10.35..10.9).contains(&y)
    });
    let crossing = situation(
        &field,
        vec![
            robot(
                0,
                Role::Agent,
                (3.0, 10.0, 0.0),
                vec![[10.0, 10.0], [10.0, 17.0]],
            ),
            robot(1, Role::Peer, (8.0, 4.0, FRAC_PI_2), vec![[8.0, 16.0]]),
        ],
    );
    let hall = map(12.0, 6.0, 0.02, |x, y| {
        (3.0..9.0).contains(&x) && (y - 3.0).abs() > 0.4
    });
    let corridor = situation(
        &hall,
        vec![robot(0, Role::Agent, (4.0, 3.0, 0.0), vec![[11.0, 3.0]])],
    );
    let open = map(20.0, 20.0, 0.05, |_, _| false);
    let west = situation(
        &open,
        vec![robot(0, Role::Agent, (15.0, 10.0, PI), vec![[3.0, 10.0]])],
    );
    let strip = map(300.0, 8.0, 0.1, |_, _| false);
    let long = situation(
        &strip,
        vec![robot(0, Role::Agent, (2.0, 4.0, 0.0), vec![[298.0, 4.0]])],
    );
    let standing = |id, x, y| robot(id, Role::Peer, (x, y, PI), vec![]);
    let crowd = situation(
        &open,
        vec![
            robot(0, Role::Agent, (3.0, 10.0, 0.0), vec![[17.0, 10.0]]),
            standing(1, 7.0, 8.5),
            standing(2, 7.0, 11.5),
            standing(3, 6.0, 13.5),
            standing(4, 8.0, 10.0),
        ],
    );
    let behind = situation(
        &open,
        vec![robot(
            0,
            Role::Agent,
            (10.0, 10.0, 0.0),
            vec![[7.0, 10.0], [7.0, 14.0]],
        )],
    );
    let stepped = map(10.0, 7.0, 0.02, |x, y| {
        let near = (4.0..4.2).contains(&x) && !(1.6..3.0).contains(&y);
        let far = (5.15..5.35).contains(&x) && y < 2.4;
        near || far
    });
    let step = situation(
        &stepped,
        vec![robot(0, Role::Agent, (2.0, 3.5, 0.0), vec![[8.0, 3.5]])],
    );
    let mut looping = robot(
        0,
        Role::Agent,
        (5.0, 5.0, 0.0),
        vec![[9.0, 5.0], [9.0, 9.0]],
    );
    looping.at_end = AtEnd::Loop;
    let lap = situation(&open, vec![looping]);
    let zigzag = situation(
        &open,
        vec![robot(
            0,
            Role::Agent,
            (2.0, 2.0, 0.0),
            vec![
                [4.0, 2.0],
                [5.0, 3.5],
                [7.0, 3.5],
                [8.0, 5.0],
                [10.0, 5.0],
                [11.0, 6.5],
                [13.0, 6.5],
                [14.0, 8.0],
                [16.0, 8.0],
                [17.0, 9.5],
                [17.0, 11.5],
                [16.0, 13.0],
                [14.0, 14.0],
                [12.0, 14.0],
                [10.0, 15.5],
                [8.0, 15.5],
            ],
        )],
    );
    let posted = map(12.0, 6.0, 0.02, |x, y| {
        (3.98..4.02).contains(&x) && (3.28..3.32).contains(&y)
    });
    let post = situation(
        &posted,
        vec![robot(0, Role::Agent, (4.0, 3.0, 0.0), vec![[11.0, 3.0]])],
    );
    let posted_ahead = map(12.0, 6.0, 0.02, |x, y| {
        (4.20..4.24).contains(&x) && (3.27..3.31).contains(&y)
    });
    let post_ahead = situation(
        &posted_ahead,
        vec![robot(0, Role::Agent, (4.0, 3.0, 0.0), vec![[11.0, 3.0]])],
    );
    vec![
        ("doorway", doorway, STEPS),
        ("post", post, STEPS),
        ("post ahead", post_ahead, STEPS),
        ("crossing", crossing, STEPS),
        ("corridor", corridor, STEPS),
        ("west", west, STEPS),
        ("long", long, 5400),
        ("crowd", crowd, STEPS),
        ("behind", behind, STEPS),
        ("step", step, STEPS),
        ("lap", lap, STEPS),
        ("zigzag", zigzag, 2000),
    ]
}

const STEPS: usize = 600;

/// The agent's poses over a run of `s` with `agent`, for at most `steps` steps; with
/// `reference`, it stops at the first pose that differs from it.
fn poses(
    s: &Situation,
    agent: &ControllerSpec,
    steps: usize,
    reference: Option<&[Pose]>,
) -> Vec<Pose> {
    let mut out = Vec::new();
    run_situation(s, agent, steps, |w| {
        let pose = w.robots()[0].pose;
        let differs = reference.is_some_and(|r| r.get(out.len()) != Some(&pose));
        out.push(pose);
        differs
    });
    out
}

#[test]
fn every_fault_changes_what_each_of_its_controllers_does_on_a_hand_built_situation() {
    let situations = situations();
    let mut reference = BTreeMap::new();
    for info in &CATALOGUE {
        for &controller in info.controllers {
            // The first situation it changes is enough: the later ones need not be run.
            let changes_one = situations.iter().any(|(name, s, steps)| {
                let correct = reference
                    .entry((controller, *name))
                    .or_insert_with(|| poses(s, &spec(controller, None), *steps, None));
                let faulty = poses(s, &spec(controller, Some(info.id)), *steps, Some(correct));
                faulty != *correct
            });
            assert!(
                changes_one,
                "`{}` changes nothing `{controller}` does on any hand-built situation",
                info.id
            );
        }
    }
}

/// One SND step with fault `fault` on `ranges` (the SICK geometry, goal 5 m ahead, R = 0.25).
fn step(fault: Option<Fault>, ranges: &[f64]) -> crate::control::snd::SndDecision {
    let p = SndParams::with_radius(0.25).under_fault(fault);
    let goal = Goal {
        x_m: 5.0,
        y_m: 0.0,
        heading_rad: 0.0,
    };
    let origin = Pose {
        x_m: 0.0,
        y_m: 0.0,
        heading_rad: 0.0,
    };
    snd_step(&p, ranges, 1f64.to_radians(), 10.0, &origin, &goal)
}

#[test]
fn the_snd_logic_seams_do_what_the_catalogue_says() {
    // A wall 1 m ahead across the whole view: the goal corridor is blocked.
    let wall: Vec<f64> = (0..181)
        .map(|i| {
            let bearing = (i as f64 - 90.0).to_radians();
            (1.0 / bearing.cos()).min(10.0)
        })
        .collect();
    let correct = step(None, &wall);
    assert_ne!(correct.s_t, correct.goal_sector);
    let skipped = step(Some(Fault::CorridorTestSkipped), &wall);
    assert_eq!(
        skipped.s_t, skipped.goal_sector,
        "heads for the goal through the wall"
    );

    // Something inside R: the correct step stops; without the stop it steers on.
    let touching = vec![0.2; 181];
    assert_eq!(step(None, &touching).case, SndCase::InsideRadius);
    assert_ne!(
        step(Some(Fault::InsideRadiusStopRemoved), &touching).case,
        SndCase::InsideRadius
    );

    // A wall 1 m to the left: the deviation pushes right, flipped it pushes left.
    let left: Vec<f64> = (0..181)
        .map(|i| {
            let bearing = (i as f64 - 90.0).to_radians();
            if bearing > 0.1 {
                (1.0 / bearing.sin()).min(10.0)
            } else {
                10.0
            }
        })
        .collect();
    let pushed = step(None, &left);
    let flipped = step(Some(Fault::DeviationSignFlipped), &left);
    assert!(pushed.s_ao != 0.0);
    assert_eq!(flipped.s_ao, -pushed.s_ao);

    // The speed law: near the left wall the correct step slows; without clearance it does not.
    let slow = pushed.command.0;
    let fast = step(Some(Fault::SpeedIgnoresClearance), &left).command.0;
    assert!(fast > slow, "{fast} > {slow}");

    // Off by one: every range one sector counter-clockwise.
    let shifted = step(Some(Fault::SectorOffByOne), &left);
    assert_eq!(shifted.full[1..], pushed.full[..pushed.full.len() - 1]);
}

#[test]
fn the_parameter_seams_change_the_resolved_parameters() {
    let r = Body::default().enclosing_radius();
    let resolved = |fault| SndParams::with_radius(r).under_fault(fault);
    let correct = resolved(None);
    // 60°/s read as 60 rad/s.
    assert!((resolved(Some(Fault::TurnRateInRadians)).max_turn_rate - 60.0).abs() < 1e-9);
    assert_eq!(
        resolved(Some(Fault::SafetyDistanceHalved)).obstacle_avoid_dist,
        correct.obstacle_avoid_dist / 2.0
    );
    let small = resolved(Some(Fault::PlayerDefaultRadius));
    assert_eq!((small.robot_radius, small.min_gap_width), (0.25, 0.5));
    assert_eq!(switch_m(Some(Fault::SwitchDistanceTooLarge), 0.5), 2.0);
    assert_eq!(switch_m(Some(Fault::MirroredScan), 0.5), 0.5);
}

#[test]
fn the_catalogue_is_complete_and_its_ids_unique() {
    let mut ids: Vec<&str> = CATALOGUE.iter().map(|i| i.id).collect();
    ids.sort_unstable();
    ids.dedup();
    assert_eq!(ids.len(), CATALOGUE.len());
    assert!(CATALOGUE.len() >= 15);
    let on = |name: &str| faults_of(name).len();
    assert!(on("snd_follow") >= 10 && on("snd") >= 10);
    assert!(on("vo") >= 2 && on("dwa") >= 2);
    for info in &CATALOGUE {
        assert_eq!(Fault::from_id(info.id), Some(info.fault));
        assert_eq!(info.fault.id(), info.id);
    }
}

fn error(name: &str, fault: &str) -> String {
    match build(&spec(name, Some(fault)), "run.controller") {
        Err(e) => e.to_string(),
        Ok(_) => panic!("`{fault}` on `{name}` built"),
    }
}

#[test]
fn an_unknown_fault_or_one_the_controller_lacks_is_a_one_line_error_naming_the_field() {
    let e = error("snd_follow", "flipped_everything");
    assert!(
        e.starts_with("run.controller.fault: unknown fault `flipped_everything`; expected one of sector_off_by_one,"),
        "{e}"
    );
    let e = error("snd_follow", "vo_static_peers");
    assert!(
        e.starts_with("run.controller.fault: `vo_static_peers` is not a fault of controller `snd_follow` (its faults: sector_off_by_one,"),
        "{e}"
    );
    let e = error("straight", "mirrored_scan");
    assert!(e.contains("(it has none)"), "{e}");
    for e in [
        error("snd", "switch_distance_too_large"),
        error("follow", "stale_scan"),
    ] {
        assert!(e.starts_with("run.controller.fault: "), "{e}");
        assert!(!e.contains('\n'), "{e}");
    }
    let external =
        crate::control::check(&spec("python:m:C", Some("mirrored_scan")), "run.controller");
    let e = external.unwrap_err().to_string();
    assert!(
        e.starts_with("run.controller.fault: `python:m:C` is not a built-in controller"),
        "{e}"
    );
}

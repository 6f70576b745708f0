use super::*;
use crate::run::tests::spec;
use crate::test_data::{block, robot, situation};

/// A `snd_follow` agent driving east along a corridor 1.2 m wide (y 9.4–10.6 m, x 5–20 m) and a
/// `straight` peer driving west at it along the same line: the agent stops, the peer drives
/// in. A wall block (x 2–3 m, y 17–18 m) plays no part.
fn head_on() -> Situation {
    let mut walls = block(200, (5.0, 20.0), (9.1, 9.4));
    walls.extend(block(200, (5.0, 20.0), (10.6, 10.9)));
    walls.extend(block(200, (2.0, 3.0), (17.0, 18.0)));
    situation(
        200,
        &walls,
        vec![
            robot(0, (8.0, 10.0, 0.0), &[[18.0, 10.0]], "snd_follow"),
            robot(
                1,
                (17.0, 10.0, std::f64::consts::PI),
                &[[6.0, 10.0]],
                "straight",
            ),
        ],
    )
}

#[test]
fn a_generated_situation_keeps_its_peer_legs_clear_and_a_hand_made_one_need_not() {
    let spec = crate::spec::from_toml_str(
        "[terrain]\npreset = \"rocky_desert\"\n[mission]\npeers_min = 3\n",
    )
    .unwrap();
    let (s, _) = crate::situation::generate(&spec, 3).unwrap();
    assert!(s.robots.len() > 1, "the default spec places peers");
    assert_eq!(
        leg_margin(&s),
        Some(s.provenance.spec.mission.plan_margin_m)
    );
    // A peer leg through the block is not clear.
    let mut through = head_on();
    through.robots[1].waypoints = vec![[2.5, 17.5 - 5.0], [2.5, 19.5]];
    through.robots[1].start = crate::situation::Pose {
        x_m: 2.5,
        y_m: 12.5,
        heading_rad: 0.0,
    };
    assert_eq!(leg_margin(&through), None);
    assert!(check(&through, None).is_ok());
    let e = check(&through, Some(0.3)).unwrap_err();
    assert!(e.starts_with("robots[1]: leg 1 from (2.50, 12.50)"), "{e}");
}

#[test]
fn a_candidate_whose_robots_overlap_is_skipped_with_the_reason() {
    let mut s = head_on();
    s.robots[1].start.x_m = 8.3;
    let e = check(&s, None).unwrap_err();
    assert!(e.contains("robot"), "{e}");
    let r = probe(&s, &spec(None, 20.0), 0, None);
    assert_eq!(r, Err(e));
}

#[test]
fn a_probe_reports_the_class_and_when_each_class_first_showed() {
    let p = probe(&head_on(), &spec(None, 30.0), 0, None).unwrap();
    let (class, first) = p.first_s[0];
    assert_eq!(p.class, Some(class), "{p:?}");
    assert!(class <= FailureClass::StruckWhileStoppedSeen, "{p:?}");
    assert!(first > 0.0 && first < 30.0, "{p:?}");
    let sorted: Vec<FailureClass> = p.first_s.iter().map(|(c, _)| *c).collect();
    assert!(sorted.windows(2).all(|w| w[0] < w[1]), "{sorted:?}");
}

#[test]
fn batches_give_the_same_probes_on_any_thread_count() {
    let mut a = head_on();
    let mut b = head_on();
    a.robots.truncate(1);
    b.robots[1].start.x_m = 12.0;
    let candidates = [head_on(), a, b];
    let run = spec(None, 30.0);
    let one = probe_batch(&candidates, &run, 0, None, 1);
    assert_eq!(one, probe_batch(&candidates, &run, 0, None, 2));
    assert_eq!(one[0], probe(&candidates[0], &run, 0, None));
}

#[test]
fn robots_at_the_start_are_the_situation_s_and_later_carry_on_along_their_routes() {
    let s = head_on();
    let run = spec(None, 30.0);
    assert_eq!(robots_at(&s, &run, 0, 0.0).unwrap(), s.robots);
    let later = robots_at(&s, &run, 0, 6.0).unwrap();
    // After 6 s the agent still heads for its only waypoint; the peer (0.5 m/s) is 3 m along
    // its only leg.
    assert_eq!(later[0].waypoints, vec![[18.0, 10.0]]);
    assert_eq!(later[1].waypoints, vec![[6.0, 10.0]]);
    assert!(
        (later[1].start.x_m - 14.0).abs() < 1e-9,
        "{:?}",
        later[1].start
    );
    // The restarted situation's first pose is where the run stood.
    let record = run::run(&s, &run, 0).unwrap();
    let at = 60 * s.robots.len() * 3;
    assert_eq!(record.trajectory[at], later[0].start.x_m);
    assert_eq!(record.trajectory[at + 3], later[1].start.x_m);
}

//! SND's tests. The hand-made scans use the SICK geometry (181 beams, 1° apart, 10 m) and
//! Player's default R = 0.25 m (so 2R = 0.5, Ds_max = 1.0, 2.2R = 0.55), with the robot at
//! the origin facing +x and the goal 5 m straight ahead. Then N = 361, N/2 = 180, N/4 = 90,
//! L/2 = 90, L/3 = 60; beam t is sector t + 90 (first beam sector 90), so sector s looks at
//! bearing (s − 180)°. The goal bearing is 0, so s_g = round(180.5 + 0) = 181 (Player's real
//! N/2.0). Every expected value below is derived by hand from `reference/algorithms.md` §1.4.

use std::f64::consts::PI;

use proptest::prelude::*;

use super::*;
use crate::control::tests::{map, run_situation};
use crate::geometry::Body;
use crate::grid::Map;
use crate::mission::{AtEnd, ControllerSpec};
use crate::sim::laser::LaserSpec;
use crate::sim::World;
use crate::situation::{self, Role, Situation};
use crate::spec::{from_toml_str, SituationSpec};

fn res() -> f64 {
    scan_resolution(&LaserSpec::default().bearings()).unwrap()
}

/// A 181-beam scan with `f(beam)` as each range.
fn scan(f: impl Fn(usize) -> f64) -> Vec<f64> {
    (0..181).map(f).collect()
}

fn origin() -> Pose {
    Pose {
        x_m: 0.0,
        y_m: 0.0,
        heading_rad: 0.0,
    }
}

fn goal_ahead() -> Goal {
    Goal {
        x_m: 5.0,
        y_m: 0.0,
        heading_rad: 0.0,
    }
}

fn step(ranges: &[f64]) -> SndDecision {
    snd_step(
        &SndParams::with_radius(0.25),
        ranges,
        res(),
        10.0,
        &origin(),
        &goal_ahead(),
    )
}

fn gap(sector: i64, dist: f64, side: i64) -> Gap {
    Gap { sector, dist, side }
}

fn valley(rising: Gap, other: Gap, dir: i64) -> Valley {
    Valley { rising, other, dir }
}

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() < 1e-9
}

#[test]
fn the_sick_laser_gives_361_sectors_whichever_way_its_spacing_rounds() {
    assert_eq!(sector_count(res()), 361);
    // One ulp either side of 1° would be 360.4999… or 360.5000…1 unguarded.
    let deg = PI / 180.0;
    let ulp = |k: i64| f64::from_bits((deg.to_bits() as i64 + k) as u64);
    for r in [deg, ulp(1), ulp(-1)] {
        assert_eq!(sector_count(r), 361, "{r}");
    }
    // 361 beams over 180°: 0.5° → 720.5 → 721.
    let fine = LaserSpec {
        beams: 361,
        ..LaserSpec::default()
    };
    assert_eq!(
        sector_count(scan_resolution(&fine.bearings()).unwrap()),
        721
    );
}

#[test]
fn a_half_circle_difference_comes_back_the_long_way() {
    // N = 361, ⌊N/2⌋ = 180: raw ±180 → ∓181; one less is returned as is; one more wraps.
    assert_eq!(sectors_between(0, 180, 361), -181);
    assert_eq!(sectors_between(180, 0, 361), 181);
    assert_eq!(sectors_between(0, 179, 361), 179);
    assert_eq!(sectors_between(0, 181, 361), -180);
    assert_eq!(sectors_between(10, 361, 361), -10, "sector N is sector 0");
    // Even N: both ways are equally long; Player returns the negated sign.
    assert_eq!(sectors_between(0, 180, 360), -180);
    assert_eq!(sectors_between_directed(271, 89, 361, 1), 179);
    assert_eq!(sectors_between_directed(209, 89, 361, -1), 120);
}

#[test]
fn an_empty_scan_has_only_the_forced_edge_gaps_and_the_rear_valley() {
    let d = step(&scan(|_| 10.0));
    assert_eq!((d.sectors, d.goal_sector), (361, 181));
    // No returns: PND all 0, d_min = max_range, Ds = clamp(5·(10 − 0.25), 0, 1) = 1.
    assert!(d.pnd.iter().all(|&p| p == 0.0));
    assert_eq!((d.d_min, d.ds), (10.0, 1.0));
    // Forced gaps: right of beam 0 at sector 89 (side +1, r[0]); left of beam 180 at 271
    // (side −1, r[180]).
    let (right, left) = (gap(89, 10.0, 1), gap(271, 10.0, -1));
    assert_eq!(d.gaps, vec![right, left]);
    // (89+, 271−): no valley. (271−, 89+): both rising; |Δ(271, 181)| = 90 < |Δ(89, 181)| = 92,
    // so 271 rises CCW; its corner test sees only unobserved sectors 272…360 and passes.
    assert_eq!(d.valleys, vec![valley(left, right, 1)]);
    // Pass 1 skips it (it holds sector 0: Δ→(271, 0) = 90 < Δ→(271, 89) = 179); pass 2 takes it.
    assert_eq!(d.best, Some(0));
    // Case C: W = 179 (nothing nearer than 10 m before 89); k = round(asin(1.25/10)/1°) =
    // round(7.18) = 7 ≤ 60, s_srd = 278; s_mid = 271 + (89 − 1) = 359. The goal is in front
    // (|Δ(181, 180)| = 1 < 90) and its corridor clear, so s_t = s_g = 181.
    assert_eq!(d.case, SndCase::Valley);
    assert_eq!(
        (d.valley_width, d.s_srd, d.s_mid, d.s_t),
        (Some(179), Some(278), Some(359), 181)
    );
    // Nothing within R + Ds: S_ao = 0, s_θ = 181, θ = (181 − 180.5)° = 0.5°.
    assert_eq!((d.s_ao, d.s_theta), (0.0, 181));
    assert!(close(d.theta, 0.5f64.to_radians()));
    // ω = (π/3)·(2/π)·θ = π/540; v = 0.5 · 1 · 1 · (30 − 0.5)/30.
    assert!(close(d.command.1, PI / 540.0), "{:?}", d.command);
    assert!(close(d.command.0, 0.5 * 59.0 / 60.0), "{:?}", d.command);
}

#[test]
fn a_wall_to_the_left_leaves_the_goal_corridor_clear() {
    // Beams 120…150 (bearings 30°…60°, sectors 210…240) at 2 m; PND there 10.5 − 2 = 8.5.
    let d = step(&scan(|t| if (120..=150).contains(&t) { 2.0 } else { 10.0 }));
    // Sector 210: δ = +8.5 → gap at 209 (corner D[210] = 2, side +1); sector 241: δ = −8.5 →
    // gap at 241 (corner D[240] = 2, side −1).
    let (edge_r, wall_r, wall_l, edge_l) = (
        gap(89, 10.0, 1),
        gap(209, 2.0, 1),
        gap(241, 2.0, -1),
        gap(271, 10.0, -1),
    );
    assert_eq!(d.gaps, vec![edge_r, wall_r, wall_l, edge_l]);
    // (89+, 209+): 209 rises CW; (209+, 241−): none; (241−, 271−): 241 rises CCW; (271−, 89+):
    // the rear. Every corner test sees only max-range sectors.
    assert_eq!(
        d.valleys,
        vec![
            valley(wall_r, edge_r, -1),
            valley(wall_l, edge_l, 1),
            valley(edge_l, edge_r, 1)
        ]
    );
    // Costs |Δ(·, 181)|: 28, 60, rear skipped → the first.
    assert_eq!(d.best, Some(0));
    // W = Δ→(209, 89, −1) = 120; k = round(asin(1.25/2)/1°) = round(38.68) = 39: s_srd = 170;
    // s_mid = 209 − 59 = 150. The nearest wall point to the corridor of half-width 0.25 is at
    // φ = 29° from the goal sector, where it would need to be nearer than 0.25/sin 29° = 0.52 m:
    // the corridor is clear and s_t = s_g.
    assert_eq!(
        (d.valley_width, d.s_srd, d.s_mid, d.s_t),
        (Some(120), Some(170), Some(150), 181)
    );
    // d_min = 2 > R + Ds = 1.25: no deviation, full clearance speed.
    assert_eq!((d.d_min, d.ds, d.s_ao, d.s_theta), (2.0, 1.0, 0.0, 181));
    assert!(close(d.command.0, 0.5 * 59.0 / 60.0));
}

#[test]
fn a_near_wall_ahead_left_sends_it_right_mid_valley_pushed_further_by_the_deviation() {
    // Beams 90…120 (bearings 0°…30°, sectors 180…210) at 1 m; PND there 9.5.
    let d = step(&scan(|t| if (90..=120).contains(&t) { 1.0 } else { 10.0 }));
    let (edge_r, wall_r, wall_l, edge_l) = (
        gap(89, 10.0, 1),
        gap(179, 1.0, 1),
        gap(211, 1.0, -1),
        gap(271, 10.0, -1),
    );
    assert_eq!(d.gaps, vec![edge_r, wall_r, wall_l, edge_l]);
    assert_eq!(
        d.valleys,
        vec![
            valley(wall_r, edge_r, -1),
            valley(wall_l, edge_l, 1),
            valley(edge_l, edge_r, 1)
        ]
    );
    // Costs: |Δ(179, 181)| = 2, |Δ(211, 181)| = 30, rear skipped.
    assert_eq!(d.best, Some(0));
    // W = 90. The corner at 1 m is nearer than Ds_max + R = 1.25: k = N/4 = 90, capped at
    // L/3 = 60: s_srd = 119. s_mid = 179 − (45 − 1) = 135. The goal corridor is blocked (1 m
    // return at φ = 0 inside length 4.75), and |Δ(179, 135)| = 44 < 60: narrow, s_t = s_mid.
    assert_eq!(
        (d.valley_width, d.s_srd, d.s_mid, d.s_t),
        (Some(90), Some(119), Some(135), 135)
    );
    // d_min = 1, Ds = min(5·0.75, 1) = 1; the 31 wall sectors have m = (1.25 − 1)/1 = 1/4.
    // Escape directions s + 180 mod 361: 360, 0, 1, …, 29; Δ(135, ·): 360 − 135 = 225 → −136,
    // then −135 … −106. Σδ = −136 − 3615 = −3751 = −121·31, so
    // S_ao = (1/4)³·Σδ / (31·(1/4)²) = −121/4 = −30.25, s_θ = round(104.75) = 105.
    assert_eq!((d.d_min, d.ds), (1.0, 1.0));
    assert!(close(d.s_ao, -30.25), "{}", d.s_ao);
    assert_eq!(d.s_theta, 105);
    // θ = −75.5°: ω = (2/3)·θ, and |θ| beyond 30° leaves v = 0 (turn on the spot).
    assert!(close(d.theta, (-75.5f64).to_radians()));
    assert!(close(d.command.1, 2.0 / 3.0 * (-75.5f64).to_radians()));
    assert_eq!(d.command.0, 0.0);
}

#[test]
fn adjacent_gaps_on_the_same_side_merge_as_in_player() {
    // Beam 100 (sector 190) at 5 m, 101…110 (191…200) at 1 m, 111 (201) at 5 m.
    let d = step(&scan(|t| match t {
        100 | 111 => 5.0,
        101..=110 => 1.0,
        _ => 10.0,
    }));
    // Raw gaps: 189 (+1, 5) and 190 (+1, 1) from PND 0 → 5.5 → 9.5; 201 (−1, 1) and
    // 202 (−1, 5) going back down. Side +1 keeps the first (189, corner 5); side −1 keeps one
    // at the second sector, 202, with the first's corner distance, 1.
    assert_eq!(
        d.gaps,
        vec![
            gap(89, 10.0, 1),
            gap(189, 5.0, 1),
            gap(202, 1.0, -1),
            gap(271, 10.0, -1)
        ]
    );
    // One walk: a run of three merges once (the merged gap is not compared again)…
    let mut run = vec![
        gap(10, 1.0, -1),
        gap(11, 2.0, -1),
        gap(12, 3.0, -1),
        gap(50, 4.0, 1),
    ];
    merge_gaps(&mut run, 361);
    assert_eq!(
        run,
        vec![gap(11, 1.0, -1), gap(12, 3.0, -1), gap(50, 4.0, 1)]
    );
    // …and the last gap merges with the first across sector 0, which drops the head.
    let mut wrapped = vec![gap(0, 1.0, 1), gap(100, 2.0, -1), gap(360, 3.0, 1)];
    merge_gaps(&mut wrapped, 361);
    assert_eq!(wrapped, vec![gap(100, 2.0, -1), gap(360, 3.0, 1)]);
}

#[test]
fn an_opening_narrower_than_the_corner_clearance_makes_no_valley() {
    // Walls at 2 m on beams 60…89 (sectors 150…179) and 95…120 (185…210): a 5° slot ahead,
    // 2·2·sin 2.5° = 0.17 m wide.
    let d = step(&scan(|t| match t {
        60..=89 | 95..=120 => 2.0,
        _ => 10.0,
    }));
    let (edge_r, a, b, c, e, edge_l) = (
        gap(89, 10.0, 1),
        gap(149, 2.0, 1),
        gap(180, 2.0, -1),
        gap(184, 2.0, 1),
        gap(211, 2.0, -1),
        gap(271, 10.0, -1),
    );
    assert_eq!(d.gaps, vec![edge_r, a, b, c, e, edge_l]);
    // (180−, 184+) both rise; 180 is nearer s_g = 181, so it is tested going CCW: its corner
    // (2 m at 0°) is 0.17 m < 2.2R = 0.55 m from the return at sector 185: no valley.
    assert_eq!(
        d.valleys,
        vec![
            valley(a, edge_r, -1),
            valley(e, edge_l, 1),
            valley(edge_l, edge_r, 1)
        ]
    );
    // Costs 32 and 30 (rear skipped): the left opening. W = 60 (to 271), s_mid = 211 + 29 = 240,
    // k = 39, s_srd = 250; the corridor is blocked (the 2 m return 2° off the goal sector is
    // inside length 4.75), and 29 < 39: s_t = s_mid = 240.
    assert_eq!(d.best, Some(1));
    assert_eq!(
        (d.valley_width, d.s_srd, d.s_mid, d.s_t),
        (Some(60), Some(250), Some(240), 240)
    );
    assert_eq!((d.s_ao, d.s_theta), (0.0, 240));
    assert!(close(d.command.1, 2.0 / 3.0 * 59.5f64.to_radians()));
    assert_eq!(d.command.0, 0.0);
}

#[test]
fn something_inside_the_radius_stops_it() {
    let d = step(&scan(|t| if t == 100 { 0.2 } else { 10.0 }));
    assert_eq!(d.case, SndCase::InsideRadius);
    // s_θ = ⌊N/2⌋ = 180, θ = −0.5°: the slow clockwise creep of odd N.
    assert_eq!(d.s_theta, 180);
    assert_eq!(d.command.0, 0.0);
    assert!(close(d.command.1, -PI / 540.0));
}

#[test]
fn it_turns_toward_the_open_side() {
    // An obstacle ahead (±20° at 1.5 m), a wall close on one side (1.2 m), open on the other.
    let wall_left = scan(|t| match t {
        0..=69 => 10.0,
        70..=110 => 1.5,
        _ => 1.2,
    });
    let d = step(&wall_left);
    // The only seen gap is the obstacle's right edge (1.5 → 1.2 is a PND step of 0.3 < 2R):
    // right valley from 159, plus the rear.
    assert_eq!(d.gaps[1], gap(159, 1.5, 1));
    assert_eq!(d.valleys[d.best.unwrap()].rising.sector, 159);
    assert!(d.command.1 < 0.0, "turns right: {:?}", d.command);
    let wall_right: Vec<f64> = wall_left.iter().rev().copied().collect();
    let d = step(&wall_right);
    assert!(d.command.1 > 0.0, "turns left: {:?}", d.command);
}

#[test]
fn a_full_circle_laser_has_no_forced_gaps_and_spins_when_boxed_in() {
    // 361 beams over 360°: 1° apart, L = N, first beam sector 0.
    let laser = LaserSpec {
        fov_deg: 360.0,
        beams: 361,
        ..LaserSpec::default()
    };
    let res = scan_resolution(&laser.bearings()).unwrap();
    let p = SndParams::with_radius(0.25);
    let open = snd_step(&p, &[10.0; 361], res, 10.0, &origin(), &goal_ahead());
    assert!(open.gaps.is_empty() && open.valleys.is_empty());
    assert_eq!(open.case, SndCase::NoValleyGoalClear);
    assert_eq!(open.s_theta, 181);
    // Inside a round room of radius 3 m: no gaps, and the goal corridor (length 4.75) is
    // blocked, so s_θ = 0: θ = −180.5° clamps to −90°, ω = −ω_max, v = 0.
    let boxed = snd_step(&p, &[3.0; 361], res, 10.0, &origin(), &goal_ahead());
    assert_eq!(boxed.case, SndCase::NoValleySpin);
    assert_eq!(boxed.s_theta, 0);
    assert_eq!(boxed.command, (0.0, -p.max_turn_rate));
}

#[test]
fn at_the_goal_it_turns_to_the_goal_heading_the_unwrapped_way_then_stops() {
    let p = SndParams::with_radius(0.25);
    let scan = scan(|_| 10.0);
    let at = |heading: f64, goal_heading: f64| {
        let pose = Pose {
            heading_rad: heading,
            ..origin()
        };
        let goal = Goal {
            x_m: 0.1,
            y_m: 0.0,
            heading_rad: goal_heading,
        };
        snd_step(&p, &scan, res(), 10.0, &pose, &goal)
    };
    let d = at(0.2, 0.0);
    assert_eq!((d.case, d.command), (SndCase::Reached, (0.0, 0.0)));
    // 1 rad off: ω = −1/3.
    let d = at(1.0, 0.0);
    assert_eq!(d.case, SndCase::Aligning);
    assert!(close(d.command.1, -1.0 / 3.0) && d.command.0 == 0.0);
    // 2.5 → −2.5 is 1.28 rad the short way (CCW) but Player turns by (−2.5 − 2.5)/3, clamped
    // to −ω_max: clockwise, the long way.
    let d = at(2.5, -2.5);
    assert_eq!(d.command, (0.0, -p.max_turn_rate));
}

proptest! {
    #[test]
    fn the_command_is_finite_with_nonnegative_speed(
        ranges in prop::collection::vec(
            prop_oneof![Just(10.0), Just(0.0), 0.0..10.0f64, 0.2..0.6f64], 181),
        x in -20.0..20.0f64,
        y in -20.0..20.0f64,
        heading in -PI..PI,
        goal_heading in -PI..PI,
        r in prop_oneof![Just(0.25), 0.05..1.5f64],
    ) {
        let p = SndParams::with_radius(r);
        let pose = Pose { x_m: 0.0, y_m: 0.0, heading_rad: heading };
        let goal = Goal { x_m: x, y_m: y, heading_rad: goal_heading };
        let d = snd_step(&p, &ranges, res(), 10.0, &pose, &goal);
        let (v, w) = d.command;
        prop_assert!(v.is_finite() && w.is_finite(), "{:?}", d);
        prop_assert!(v >= 0.0 && v <= p.max_speed);
        prop_assert!(w.abs() <= p.max_turn_rate + 1e-12);
        prop_assert!((0..d.sectors.max(1)).contains(&d.s_theta) || d.s_theta == d.sectors);
    }
}

#[test]
fn a_robot_at_its_goal_does_not_divide_by_zero() {
    let p = SndParams::with_radius(0.25);
    let goal = Goal {
        x_m: 0.0,
        y_m: 0.0,
        heading_rad: 0.0,
    };
    let d = snd_step(&p, &scan(|_| 0.25), res(), 10.0, &origin(), &goal);
    assert_eq!(d.command, (0.0, 0.0));
    // Ds = 0 exactly (d_min = R) on a goal further away: the deviation stays finite.
    let d = step(&scan(|t| if t < 10 { 0.25 } else { 10.0 }));
    assert_eq!(d.ds, 0.0);
    assert!(d.s_ao.is_finite() && d.command.0 == 0.0, "{d:?}");
}

#[test]
fn parameters_are_checked_and_named() {
    let spec = |params: &[(&str, f64)]| ControllerSpec {
        name: "snd".into(),
        params: params.iter().map(|&(k, v)| (k.to_string(), v)).collect(),
        fault: None,
        control_period_s: None,
        perception: None,
        keep_alive: false,
        step_timeout_s: None,
    };
    let err = |p: &[(&str, f64)]| {
        crate::control::build(&spec(p), "agent")
            .err()
            .unwrap()
            .to_string()
    };
    assert!(err(&[("radius", 1.0)]).starts_with("agent.params.radius: unknown parameter"));
    assert_eq!(
        err(&[("robot_radius", 0.0)]),
        "agent.params.robot_radius: 0 is not in (0, 10]"
    );
    assert_eq!(
        err(&[("max_turn_rate_deg_s", -1.0)]),
        "agent.params.max_turn_rate_deg_s: -1 is not in (0, 3600]"
    );
    // Defaults follow R, given or taken from the body.
    let given = SndConfig::read(&spec(&[("robot_radius", 0.3)]).params, "").unwrap();
    let p = given.resolve(0.9);
    assert_eq!(p, SndParams::with_radius(0.3));
    let body = SndConfig::read(&BTreeMap::new(), "").unwrap();
    let r = Body::default().enclosing_radius();
    assert_eq!(body.resolve(r), SndParams::with_radius(r));
    assert_eq!(body.max_range_m(), None);
}

// ---------------------------------------------------------------------------------------------
// Driving in the simulator.

/// A situation with the agent alone at `start` (facing +x) on `map` with `waypoints`.
fn alone(map: &Map, start: (f64, f64), waypoints: Vec<[f64; 2]>) -> Situation {
    let agent = Robot {
        id: 0,
        role: Role::Agent,
        body: Body::default(),
        start: Pose {
            x_m: start.0,
            y_m: start.1,
            heading_rad: 0.0,
        },
        waypoints,
        controller: named("snd"),
        at_end: AtEnd::Stop,
    };
    Situation::new(map, vec![agent], SituationSpec::default(), 0)
}

fn named(name: &str) -> ControllerSpec {
    ControllerSpec {
        name: name.into(),
        params: Default::default(),
        fault: None,
        control_period_s: None,
        perception: None,
        keep_alive: false,
        step_timeout_s: None,
    }
}

/// Drive the agent with `controller` for at most `steps`; returns the world and the number of
/// steps it was stalled.
fn drive(s: &Situation, controller: &str, steps: usize) -> (World, usize) {
    let mut stalls = 0;
    let world = run_situation(s, &named(controller), steps, |w| {
        let agent = &w.robots()[0];
        stalls += usize::from(agent.stalled);
        // Done once it has moved and come to rest.
        w.steps() > 10 && agent.command == (0.0, 0.0) && agent.velocity == (0.0, 0.0)
    });
    (world, stalls)
}

fn distance(world: &World, to: [f64; 2]) -> f64 {
    let p = world.robots()[0].pose;
    (p.x_m - to[0]).hypot(p.y_m - to[1])
}

#[test]
fn snd_reaches_a_goal_in_an_open_field_and_stops_there() {
    let field = map(20.0, 20.0, 0.1, |_, _| false);
    let goal = [16.0, 14.0];
    let s = alone(&field, (3.0, 3.0), vec![[9.0, 3.0], goal]);
    let (world, stalls) = drive(&s, "snd", 1000);
    let tol = Body::default().enclosing_radius() / 2.0;
    assert!(distance(&world, goal) < tol, "{}", distance(&world, goal));
    assert_eq!(world.robots()[0].command, (0.0, 0.0));
    // It stops facing within 30° of the last leg's bearing.
    let leg = (14.0f64 - 3.0).atan2(16.0 - 9.0);
    let off = crate::sim::wrap_angle(world.robots()[0].pose.heading_rad - leg);
    assert!(off.abs() < 30f64.to_radians(), "{off}");
    assert_eq!(stalls, 0);
    // About 19 m at up to 0.5 m/s plus the turn: well under a minute.
    assert!(world.time_s() < 60.0, "{}", world.time_s());
}

/// A 10 × 6 m room split at x = 5 m by a 0.2 m wall with a doorway `width` wide centred on
/// y = 3 m; the robot starts at (2, 3) facing the doorway and its goal is (8, 3). Returns the
/// world after at most 300 s, the steps stalled and the largest x reached.
fn through_door(width: f64) -> (World, usize, f64) {
    let room = map(10.0, 6.0, 0.02, |x, y| {
        (5.0..5.2).contains(&x) && (y - 3.0).abs() > width / 2.0
    });
    let s = alone(&room, (2.0, 3.0), vec![[8.0, 3.0]]);
    let mut furthest = 0.0f64;
    let mut stalls = 0;
    let world = run_situation(&s, &named("snd"), 3000, |w| {
        let agent = &w.robots()[0];
        furthest = furthest.max(agent.pose.x_m);
        stalls += usize::from(agent.stalled);
        w.steps() > 10 && agent.command == (0.0, 0.0) && agent.velocity == (0.0, 0.0)
    });
    (world, stalls, furthest)
}

// The doorway findings, with R = 0.438 m (the Pioneer's enclosing radius; 2R = 0.876 m,
// 2.2R = 0.963 m), in 2 cm steps of width (see `doorway_sweep`):
// - below 1.00 m SND sees no valley through the doorway (the corner test) and its goal corridor
//   (2R wide) is blocked: it turns to and fro in front of it, never entering;
// - from 1.00 m it enters, but as its rotation centre reaches the wall's far face it usually
//   locks into a turn-left/turn-right cycle at v = 0 and stays there: one doorpost drops out
//   of the ±90° edge beams as the robot turns, the other alone then makes S_ao ≈ m·90° (a
//   weighted *mean*, with m ≈ 0.8 for the nearest obstacle), |θ| > 30° stops it, and the next
//   turn (≈ 0.08 rad in 0.1 s) overshoots the narrow band of headings in which both posts are
//   seen. This is Player's algorithm (the oscillation Arnold & Alexander report), not a
//   simulator fault: no step stalls. Whether a width gets through is erratic: 1.76-1.82 m and
//   1.88-1.90 m pass, 1.00-1.74, 1.84-1.86 and 1.92-2.00 m do not.

#[test]
fn snd_does_not_enter_a_doorway_one_and_a_half_body_widths_wide() {
    // 1.5 × 0.505 m ≈ 0.76 m: room for the body, but narrower than 2.2R.
    let (_, stalls, furthest) = through_door(0.76);
    assert!(furthest < 4.0, "reached x = {furthest}");
    assert_eq!(stalls, 0);
}

#[test]
fn snd_enters_a_doorway_once_its_posts_are_2_2_r_apart() {
    let (_, _, furthest) = through_door(0.94);
    assert!(furthest < 4.0, "0.94 m: reached x = {furthest}");
    let (_, stalls, furthest) = through_door(1.04);
    assert!(furthest > 5.1, "1.04 m: reached x = {furthest}");
    assert_eq!(stalls, 0);
}

#[test]
fn snd_passes_a_doorway_it_does_not_lock_up_in() {
    // The smallest width that passes is 1.76 m; 1.78 m is inside the passing run 1.76-1.82.
    let (world, stalls, _) = through_door(1.78);
    let tol = Body::default().enclosing_radius() / 2.0;
    assert!(
        distance(&world, [8.0, 3.0]) < tol,
        "ended at {:?}",
        world.robots()[0].pose
    );
    assert_eq!(stalls, 0);
}

#[test]
fn snd_locks_up_turning_at_the_far_side_of_most_doorways() {
    // 1.5 m: it gets into the doorway and is still turning to and fro there 300 s later.
    let (world, stalls, _) = through_door(1.5);
    let agent = &world.robots()[0];
    assert!((5.0..5.3).contains(&agent.pose.x_m), "{:?}", agent.pose);
    assert_eq!(agent.command.0, 0.0);
    assert!(agent.command.1 != 0.0);
    assert_eq!(stalls, 0);
}

#[test]
#[ignore = "exploration: prints which doorway widths SND gets through"]
fn doorway_sweep() {
    for cm in (76..=200).step_by(2) {
        let (world, stalls, furthest) = through_door(cm as f64 / 100.0);
        println!(
            "door {cm} cm: ended {:.2} m from the goal, furthest x {furthest:.2}, {stalls} stalls",
            distance(&world, [8.0, 3.0]),
        );
    }
}

#[test]
#[ignore = "timing: prints microseconds per SND step on a caves scan, beside one laser scan"]
fn time_per_step() {
    let spec = from_toml_str("[terrain]\npreset = \"caves\"\n[mission]\npeers_min = 5\n").unwrap();
    let (s, _) = situation::generate(&spec, 1).unwrap();
    let world = World::new(&s, crate::sim::SimSpec::default(), 0).unwrap();
    let obs = world.observe(0).unwrap();
    let mut snd = Snd::from_params(&BTreeMap::new(), "").unwrap();
    snd.reset(&s.robots[0]);
    let n = 100_000;
    let start = std::time::Instant::now();
    for _ in 0..n {
        std::hint::black_box(snd.act(std::hint::black_box(&obs)));
    }
    let per_snd = start.elapsed().as_secs_f64() / n as f64;
    let start = std::time::Instant::now();
    for _ in 0..n / 10 {
        std::hint::black_box(world.observe(0).unwrap());
    }
    let per_scan = start.elapsed().as_secs_f64() / (n / 10) as f64;
    let d = snd.decision();
    println!(
        "SND: {:.2} µs per step ({} gaps, {} valleys, {:?}); one observation: {:.2} µs",
        per_snd * 1e6,
        d.gaps.len(),
        d.valleys.len(),
        d.case,
        per_scan * 1e6
    );
}

#[test]
fn snd_takes_its_maximum_range_from_the_laser_unless_told() {
    // Every beam reads 5 m. From a 5 m laser that is no return at all (free space); SND told
    // that the maximum is 10 m takes it for a ring of obstacles at 5 m.
    let robot = crate::test_data::robot(0, (10.0, 10.0, 0.0), &[[15.0, 10.0]], "snd");
    let obs = |max_range_m: f64| Observation {
        ranges: vec![5.0; 181],
        angles: (0..181).map(|i| f64::from(i - 90).to_radians()).collect(),
        max_range_m,
        pose: robot.start,
        velocity: (0.0, 0.0),
        stalled: false,
        time_s: 0.0,
        tracks: Vec::new(),
    };
    let nearness = |params: &[(&str, f64)], max_range_m: f64| {
        let params = params.iter().map(|&(k, v)| (k.to_string(), v)).collect();
        let mut snd = Snd::from_params(&params, "c").unwrap();
        snd.reset(&robot);
        snd.act(&obs(max_range_m));
        snd.decision().pnd.iter().filter(|&&p| p > 0.0).count()
    };
    assert_eq!(nearness(&[], 5.0), 0);
    assert!(nearness(&[], 10.0) > 100);
    assert!(nearness(&[("max_range_m", 10.0)], 5.0) > 100);
}

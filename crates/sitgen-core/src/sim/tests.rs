use proptest::prelude::*;

use super::*;
use crate::grid::OccupancyGrid;
use crate::rng::ChoiceSource;
use crate::situation::Robot;
use crate::spec::SituationSpec;
use crate::test_data;

fn robot(id: u32, x: f64, y: f64, heading: f64) -> Robot {
    test_data::robot(id, (x, y, heading), &[[x, y]], "test")
}

/// A `size` × `size` cell map at 0.1 m with the given occupied cells (row, col).
fn world(size: usize, occupied: &[(usize, usize)], robots: Vec<Robot>) -> World {
    World::new(
        &test_data::situation(size, occupied, robots),
        SimSpec::default(),
        0,
    )
    .unwrap()
}

#[test]
fn a_straight_line_is_exact() {
    let mut w = world(200, &[], vec![robot(0, 2.0, 10.0, 0.0)]);
    for _ in 0..10 {
        w.step(&[(0, 0.5, 0.0)]).unwrap();
    }
    let p = w.robots()[0].pose;
    assert!((p.x_m - 2.5).abs() < 1e-9 && (p.y_m - 10.0).abs() < 1e-12);
    assert!((w.time_s() - 1.0).abs() < 1e-12);
}

#[test]
fn a_constant_turn_drives_a_circle_of_radius_v_over_omega() {
    let (v, om) = (0.4, 0.5);
    let mut w = world(400, &[], vec![robot(0, 20.0, 20.0, 0.0)]);
    // Circle centre: left of the heading at distance v/ω.
    let centre = (20.0, 20.0 + v / om);
    for _ in 0..200 {
        w.step(&[(0, v, om)]).unwrap();
        let p = w.robots()[0].pose;
        let r = (p.x_m - centre.0).hypot(p.y_m - centre.1);
        assert!((r - v / om).abs() < 1e-9, "{r}");
    }
}

#[test]
fn commands_are_clamped_and_latched() {
    let mut w = world(400, &[], vec![robot(0, 20.0, 20.0, 0.0)]);
    w.step(&[(0, 5.0, -10.0)]).unwrap();
    let r = &w.robots()[0];
    assert_eq!(r.command, (0.8, -std::f64::consts::FRAC_PI_2));
    w.step(&[]).unwrap();
    assert_eq!(
        w.robots()[0].velocity,
        (0.8, -std::f64::consts::FRAC_PI_2),
        "latched"
    );
}

#[test]
fn acceleration_limits_ramp_the_speed() {
    let map = Map {
        grid: OccupancyGrid::filled(200, 200, false),
        resolution_m: 0.1,
    };
    let s = Situation::new(
        &map,
        vec![robot(0, 5.0, 5.0, 0.0)],
        SituationSpec::default(),
        0,
    );
    let spec = SimSpec {
        max_accel_m_s2: Some(1.0),
        ..SimSpec::default()
    };
    let mut w = World::new(&s, spec, 0).unwrap();
    w.step(&[(0, 0.8, 0.0)]).unwrap();
    assert!((w.robots()[0].velocity.0 - 0.1).abs() < 1e-12);
}

#[test]
fn a_robot_driven_into_a_wall_stalls_and_stays_stalled_while_pushing() {
    // A wall at x ∈ [5.0, 5.1] m.
    let wall: Vec<(usize, usize)> = (0..100).map(|r| (r, 50)).collect();
    let mut w = world(100, &wall, vec![robot(0, 3.0, 5.0, 0.0)]);
    let mut stalled_at = None;
    for k in 0..100 {
        w.step(&[(0, 0.5, 0.0)]).unwrap();
        let r = &w.robots()[0];
        if r.stalled {
            stalled_at.get_or_insert(k);
            assert_eq!(r.contacts, vec![Contact::Wall]);
        } else {
            assert!(stalled_at.is_none(), "unstalled while still pushing");
        }
    }
    assert!(stalled_at.is_some());
    let front = w.robots()[0].footprint().bounds().2;
    assert!(
        front <= 5.0 && front > 5.0 - 0.05 - 1e-9,
        "stopped within one step: {front}"
    );
}

#[test]
fn two_robots_driven_head_on_both_stop_stalled_and_touching() {
    let mut w = world(
        200,
        &[],
        vec![
            robot(0, 5.0, 10.0, 0.0),
            robot(1, 8.0, 10.0, std::f64::consts::PI),
        ],
    );
    for _ in 0..60 {
        w.step(&[(0, 0.5, 0.0), (1, 0.5, 0.0)]).unwrap();
    }
    let (a, b) = (&w.robots()[0], &w.robots()[1]);
    assert!(a.stalled && b.stalled);
    assert_eq!(a.contacts, vec![Contact::Robot(1)]);
    assert_eq!(b.contacts, vec![Contact::Robot(0)]);
    let gap = b.footprint().bounds().0 - a.footprint().bounds().2;
    assert!((0.0..=0.05 + 1e-9).contains(&gap), "gap {gap}");
}

/// Whether any footprint overlaps an occupied cell, the outside, or another footprint.
fn any_overlap(w: &World) -> bool {
    let g = &w.map().grid;
    let res = w.map().resolution_m;
    let robots = w.robots();
    robots.iter().enumerate().any(|(i, r)| {
        let rect = r.footprint();
        let (x0, y0, x1, y1) = rect.bounds();
        let outside = x0 < 0.0 || y0 < 0.0 || x1 > g.cols as f64 * res || y1 > g.rows as f64 * res;
        let on_cell = (0..g.rows).any(|row| {
            (0..g.cols).any(|c| {
                g.get(row, c)
                    && rect.overlaps_square(c as f64 * res, (g.rows - 1 - row) as f64 * res, res)
            })
        });
        let on_robot = robots
            .iter()
            .skip(i + 1)
            .any(|o| rect.overlaps(&o.footprint()));
        outside || on_cell || on_robot
    })
}

#[test]
fn no_footprint_ever_overlaps_anything_over_thousands_of_random_steps() {
    let mut choices = ChoiceSource::stream(99, "test");
    for trial in 0..20 {
        let occupied: Vec<(usize, usize)> = (0..120)
            .map(|_| (choices.index(60), choices.index(60)))
            .collect();
        let mut robots = Vec::new();
        // Robots on free, separated starts.
        let mut attempts = 0;
        while robots.len() < 4 && attempts < 1000 {
            attempts += 1;
            let r = robot(
                robots.len() as u32,
                choices.uniform(0.6, 5.4),
                choices.uniform(0.6, 5.4),
                choices.uniform(-3.0, 3.0),
            );
            let mut w = world(60, &occupied, {
                let mut all = robots.clone();
                all.push(r.clone());
                all
            });
            w.step(&[]).unwrap();
            if !any_overlap(&w) {
                robots.push(r);
            }
        }
        let mut w = world(60, &occupied, robots.clone());
        assert!(!any_overlap(&w), "trial {trial} starts clear");
        for _ in 0..150 {
            let commands: Vec<(u32, f64, f64)> = (0..robots.len() as u32)
                .map(|id| (id, choices.uniform(-0.8, 0.8), choices.uniform(-1.6, 1.6)))
                .collect();
            w.step(&commands).unwrap();
            assert!(!any_overlap(&w), "trial {trial} at {} s", w.time_s());
        }
    }
}

#[test]
fn the_laser_reads_analytic_ranges() {
    // A wall at x ∈ [5.0, 5.1] m; the robot at x = 2 facing east.
    let wall: Vec<(usize, usize)> = (0..100).map(|r| (r, 50)).collect();
    let w = world(100, &wall, vec![robot(0, 2.0, 5.0, 0.0)]);
    let o = w.observe(0).unwrap();
    assert_eq!(o.ranges.len(), 181);
    assert!(
        (o.ranges[90] - 3.0).abs() < 1e-9,
        "perpendicular: {}",
        o.ranges[90]
    );
    // 30° to the left: 3 / cos 30° = 3.4641 → 3.46.
    assert!(
        (o.ranges[120] - 3.46).abs() < 1e-9,
        "at an angle: {}",
        o.ranges[120]
    );
    // Straight up the wall's side, nothing: max range.
    assert_eq!(o.ranges[180], 10.0);
    // A peer ahead, facing away: the agent sees its rear face, 0.313 + 0.04465 behind its pose.
    let w = world(
        100,
        &[],
        vec![robot(0, 2.0, 5.0, 0.0), robot(1, 4.0, 5.0, 0.0)],
    );
    let o = w.observe(0).unwrap();
    assert!(
        (o.ranges[90] - 1.64).abs() < 1e-9,
        "robot ahead: {}",
        o.ranges[90]
    );
    assert!(
        w.observe(1).unwrap().ranges.is_empty(),
        "peers carry no laser"
    );
}

/// The obviously correct reference: march along the ray in 0.1 mm steps.
fn reference_range(w: &World, i: usize, bearing: f64) -> f64 {
    let r = &w.robots()[i];
    let g = &w.map().grid;
    let res = w.map().resolution_m;
    let a = r.pose.heading_rad + bearing;
    let others: Vec<Rect> = w
        .robots()
        .iter()
        .filter(|o| o.id != r.id)
        .map(|o| o.footprint())
        .collect();
    let mut t = 0.0;
    while t < 10.0 {
        let (x, y) = (r.pose.x_m + t * a.cos(), r.pose.y_m + t * a.sin());
        if x < 0.0 || y < 0.0 || x >= g.cols as f64 * res || y >= g.rows as f64 * res {
            return 10.0;
        }
        let (c, row) = ((x / res) as usize, g.rows - 1 - (y / res) as usize);
        let inside = |q: &Rect| {
            let (dx, dy) = (x - q.centre.0, y - q.centre.1);
            (dx * q.u.0 + dy * q.u.1).abs() <= q.half_length
                && (-dx * q.u.1 + dy * q.u.0).abs() <= q.half_width
        };
        if g.get(row, c) || others.iter().any(inside) {
            return t;
        }
        t += 1e-4;
    }
    10.0
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]
    #[test]
    fn the_fast_ray_caster_agrees_with_the_reference(seed in 0u64..1000) {
        let mut choices = ChoiceSource::stream(seed, "test");
        let occupied: Vec<(usize, usize)> = (0..300).map(|_| (choices.index(120), choices.index(120))).collect();
        let agent = robot(0, choices.uniform(1.0, 11.0), choices.uniform(1.0, 11.0), choices.uniform(-3.0, 3.0));
        let peer = robot(1, choices.uniform(1.0, 11.0), choices.uniform(1.0, 11.0), choices.uniform(-3.0, 3.0));
        let mut w = world(120, &occupied, vec![agent, peer]);
        // Unrounded ranges: compare before quantisation.
        w.spec.laser.range_step_m = 0.0;
        let scan = w.scan(0);
        for (k, b) in w.bearings.clone().iter().enumerate().step_by(9) {
            let reference = reference_range(&w, 0, *b);
            // A ray that clips a cell's corner by less than the reference's 0.1 mm step is a
            // hit the march steps over (seed 922: by 0.015 mm at (3.8, 4.9)).
            let a = w.robots()[0].pose.heading_rad + b;
            let hit = (w.robots()[0].pose.x_m + scan[k] * a.cos(), w.robots()[0].pose.y_m + scan[k] * a.sin());
            let near_corner = |v: f64| (v / 0.1 - (v / 0.1).round()).abs() * 0.1 < 2e-4;
            let grazed = scan[k] < reference && near_corner(hit.0) && near_corner(hit.1);
            prop_assert!(grazed || (scan[k] - reference).abs() <= 2e-4, "beam {}: {} vs {}", k, scan[k], reference);
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(32))]
    #[test]
    fn leaping_across_open_ground_finds_the_same_wall(seed in 0u64..1000, walls in 1usize..400) {
        let mut choices = ChoiceSource::stream(seed, "leap");
        let occupied: Vec<(usize, usize)> =
            (0..walls).map(|_| (choices.index(150), choices.index(150))).collect();
        let w = world(150, &occupied, vec![robot(0, 7.5, 7.5, 0.0)]);
        let walking = laser::RayGrid::new(w.map(), None);
        for _ in 0..200 {
            let origin = (choices.uniform(0.0, 15.0), choices.uniform(0.0, 15.0));
            let a = choices.uniform(-3.2, 3.2);
            let dir = (a.cos(), a.sin());
            let plain = walking.ray(origin, dir, 10.0);
            let leaping = w.rays.ray(origin, dir, 10.0);
            prop_assert!((plain - leaping).abs() < 1e-9, "{:?} {}: {} vs {}", origin, a, plain, leaping);
        }
    }
}

#[test]
fn same_situation_and_commands_give_identical_trajectories() {
    let run = || {
        let spec =
            crate::spec::from_toml_str("[terrain]\npreset = \"caves\"\n[mission]\npeers_min = 3\n")
                .unwrap();
        let (s, _) = crate::situation::generate(&spec, 12).unwrap();
        let sim = SimSpec {
            laser: LaserSpec {
                noise_sd_m: 0.02,
                ..LaserSpec::default()
            },
            ..SimSpec::default()
        };
        let mut w = World::new(&s, sim, 7).unwrap();
        let mut trace = Vec::new();
        for k in 0..300 {
            let commands: Vec<(u32, f64, f64)> = w
                .robots()
                .iter()
                .map(|r| (r.id, 0.6, ((k + r.id as usize) % 7) as f64 * 0.1 - 0.3))
                .collect();
            let scan = w.observe(0).unwrap().ranges;
            w.step(&commands).unwrap();
            for r in w.robots() {
                trace.extend([
                    r.pose.x_m.to_bits(),
                    r.pose.y_m.to_bits(),
                    r.pose.heading_rad.to_bits(),
                ]);
            }
            trace.extend(scan.iter().map(|v| v.to_bits()));
        }
        trace
    };
    assert_eq!(run(), run());
}

#[test]
fn bad_commands_are_errors_that_change_nothing() {
    let mut w = world(100, &[], vec![robot(0, 2.0, 5.0, 0.0)]);
    assert!(w
        .step(&[(3, 0.1, 0.0)])
        .unwrap_err()
        .starts_with("no robot 3"));
    assert!(w
        .step(&[(0, f64::NAN, 0.0)])
        .unwrap_err()
        .contains("not finite"));
    assert_eq!(w.steps(), 0);
}

#[test]
fn tracks_are_the_robots_the_laser_sees_now() {
    // Peer 1 ahead in the open, peer 2 behind the agent (outside the 180° view), peer 3 ahead
    // but behind a wall at x ∈ [5.0, 5.1] m, y ∈ [4, 10] m.
    let wall: Vec<(usize, usize)> = (100..160).map(|r| (r, 50)).collect();
    let mut w = world(
        200,
        &wall,
        vec![
            robot(0, 3.0, 3.0, 0.0),
            robot(1, 6.0, 3.0, 0.0),
            robot(2, 1.0, 3.0, 0.0),
            robot(3, 7.0, 6.0, 0.0),
        ],
    );
    w.step(&[(1, 0.5, 0.0)]).unwrap();
    let o = w.observe(0).unwrap();
    let ids: Vec<u32> = o.tracks.iter().map(|t| t.id).collect();
    assert_eq!(ids, vec![1]);
    let t = o.tracks[0];
    assert!((t.velocity.0 - 0.5).abs() < 1e-12 && t.velocity.1.abs() < 1e-12);
    assert!((t.position.0 - 6.05).abs() < 1e-9);
    assert!(
        w.observe(1).unwrap().tracks.is_empty(),
        "peers carry no laser"
    );
}

#[test]
fn a_robot_standing_still_reuses_its_terrain_scan_but_sees_robots_move() {
    // A wall 3 m ahead of the agent; a peer drives across the beams in between while the
    // agent stands still, then the agent turns.
    let wall: Vec<(usize, usize)> = (50..150).map(|r| (r, 80)).collect();
    let up = std::f64::consts::FRAC_PI_2;
    let mut w = world(
        200,
        &wall,
        vec![robot(0, 5.0, 10.0, 0.0), robot(1, 6.5, 7.0, up)],
    );
    let fresh = |w: &World| {
        w.forget_scans();
        w.scan(0)
    };
    let mut saw_peer = 0;
    for _ in 0..60 {
        let (reused, seen) = w.scan_seeing(0);
        assert_eq!(reused, fresh(&w), "a reused scan reads as a fresh one");
        saw_peer += usize::from(seen.contains(&1));
        w.step(&[(1, 0.8, 0.0)]).unwrap();
    }
    assert!(
        saw_peer > 5,
        "the peer crossed the beams ({saw_peer} scans saw it)"
    );
    let ahead = w.scan(0)[90];
    assert!(
        (ahead - 3.0).abs() < 0.02,
        "the wall again once it passed: {ahead}"
    );
    w.step(&[(0, 0.0, 0.5)]).unwrap();
    assert_eq!(w.scan(0), fresh(&w), "a turned robot traces again");
}

/// Clearance from robot `i`'s footprint to the nearest occupied cell or the map's edge, by
/// brute force: every occupied cell's square measured with `Rect::distance`, and the edges.
fn brute_wall_clearance(w: &World, i: usize) -> f64 {
    let rect = w.robots()[i].footprint();
    let g = &w.map().grid;
    let res = w.map().resolution_m;
    let (x0, y0, x1, y1) = rect.bounds();
    let edges = x0
        .min(y0)
        .min(g.cols as f64 * res - x1)
        .min(g.rows as f64 * res - y1)
        .max(0.0);
    let mut best = edges;
    for row in 0..g.rows {
        for c in 0..g.cols {
            if g.get(row, c) {
                let cell = Rect {
                    centre: (
                        (c as f64 + 0.5) * res,
                        ((g.rows - 1 - row) as f64 + 0.5) * res,
                    ),
                    u: (1.0, 0.0),
                    half_length: res / 2.0,
                    half_width: res / 2.0,
                };
                best = best.min(rect.distance(&cell));
            }
        }
    }
    best
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(32))]
    #[test]
    fn wall_clearance_agrees_with_brute_force(seed in 0u64..1000) {
        // An 8 m map with a few wall segments and scattered cells; robots anywhere on it (in
        // the open, beside walls, overlapping them or the edge), each asked with several reaches.
        let mut choices = ChoiceSource::stream(seed, "wall clearance");
        let n = 80;
        let mut occupied = Vec::new();
        for _ in 0..6 {
            let (r0, c0) = (choices.index(n), choices.index(n));
            let (h, w) = if choices.unit() < 0.5 {
                (1 + choices.index(3), 1 + choices.index(15))
            } else {
                (1 + choices.index(15), 1 + choices.index(3))
            };
            for r in r0..(r0 + h).min(n) {
                for c in c0..(c0 + w).min(n) {
                    occupied.push((r, c));
                }
            }
        }
        for _ in 0..choices.index(25) {
            occupied.push((choices.index(n), choices.index(n)));
        }
        let robots: Vec<Robot> = (0..4)
            .map(|id| {
                robot(
                    id,
                    choices.uniform(0.1, 7.9),
                    choices.uniform(0.1, 7.9),
                    choices.uniform(-3.2, 3.2),
                )
            })
            .collect();
        let w = world(n, &occupied, robots);
        for i in 0..4 {
            let exact = brute_wall_clearance(&w, i);
            for within in [0.0, 0.05, choices.uniform(0.0, 1.0), 2.0, 50.0] {
                if (exact - within).abs() < 1e-9 {
                    continue;
                }
                let got = w.wall_clearance(i, within);
                match got {
                    Some(m) => prop_assert!(
                        exact <= within && (m - exact).abs() < 1e-9,
                        "robot {} within {}: {} vs brute force {}", i, within, m, exact
                    ),
                    None => prop_assert!(
                        exact > within,
                        "robot {} within {}: none vs brute force {}", i, within, exact
                    ),
                }
            }
        }
    }
}

/// Robot `i`'s scan as every beam against every other robot would give it: the per-beam
/// enclosing-circle test and the slab test in robot order, without angular windows.
fn scan_against_every_robot(w: &World, i: usize) -> (Vec<f64>, Vec<u32>) {
    let laser = &w.spec.laser;
    let (origin, dirs) = w.beams_of(i);
    let mut seen = Vec::new();
    let ranges = dirs
        .into_iter()
        .map(|dir| {
            let mut t = w.rays.ray(origin, dir, laser.range_m);
            let mut hit = None;
            for (j, other) in w.robots.iter().enumerate().filter(|(j, _)| *j != i) {
                let rect = other.footprint();
                let to = (rect.centre.0 - origin.0, rect.centre.1 - origin.1);
                let radius = w.half_diagonals[j];
                let along = to.0 * dir.0 + to.1 * dir.1;
                let across = to.0 * dir.1 - to.1 * dir.0;
                if across.abs() > radius || along + radius < 0.0 || along - radius > t {
                    continue;
                }
                if let Some(at) = laser::ray_to_rect(&rect, origin, dir, t) {
                    t = at;
                    hit = Some(other.id);
                }
            }
            if let Some(id) = hit.filter(|id| !seen.contains(id)) {
                seen.push(id);
            }
            laser.quantise(t)
        })
        .collect();
    (ranges, seen)
}

#[test]
fn beams_tested_only_within_each_robot_s_window_see_what_every_beam_would() {
    // Crowds of six robots, some within √2 of each other's radius, under lasers whose beams
    // wrap around (360°, 361 beams) or are few.
    let spec = crate::spec::from_toml_str(
        "[terrain]\npreset = \"open_field\"\n[mission]\npeers_min = 5\npeers_max = 5\n",
    )
    .unwrap();
    let (s, _) = crate::situation::generate(&spec, 3).unwrap();
    let mut choices = ChoiceSource::stream(9, "windows");
    let mut sightings = 0;
    for (fov_deg, beams, offset_x_m) in [
        (180.0, 181, 0.0),
        (360.0, 361, 0.0),
        (360.0, 360, 0.1),
        (240.0, 7, -0.2),
        (90.0, 2, 0.0),
        (180.0, 1, 0.0),
    ] {
        let sim = SimSpec {
            laser: LaserSpec {
                fov_deg,
                beams,
                offset_x_m,
                ..LaserSpec::default()
            },
            ..SimSpec::default()
        };
        let mut w = World::new(&s, sim, 0).unwrap();
        for _ in 0..300 {
            let centre = (choices.uniform(2.0, 38.0), choices.uniform(2.0, 38.0));
            let spread = choices.uniform(0.3, 4.0);
            for r in &mut w.robots {
                r.pose.x_m = centre.0 + choices.uniform(-spread, spread);
                r.pose.y_m = centre.1 + choices.uniform(-spread, spread);
                r.pose.heading_rad = choices.uniform(-3.2, 3.2);
            }
            w.forget_scans();
            let (ranges, seen) = w.scan_seeing(0);
            let (expected, expected_seen) = scan_against_every_robot(&w, 0);
            assert_eq!(seen, expected_seen, "{fov_deg}° {beams} beams");
            let bits = |v: &[f64]| v.iter().map(|r| r.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(&ranges), bits(&expected), "{fov_deg}° {beams} beams");
            sightings += seen.len();
        }
    }
    // The scenes are crowded enough that windows matter.
    assert!(sightings > 1000, "{sightings}");
}

proptest! {
    /// The requirement signal's aided search (edge cells only, bounded by an upper bound on the
    /// clearance) finds exactly the clearance the monitor's full search finds.
    #[test]
    fn an_aided_wall_clearance_is_the_same_value(
        x in 0.5f64..9.5, y in 0.5f64..9.5, heading in -3.2f64..3.2, slack in 0.0f64..0.5,
    ) {
        let mut occupied = test_data::block(100, (3.0, 4.5), (2.0, 7.0));
        occupied.extend(test_data::block(100, (6.0, 6.4), (5.0, 9.0)));
        occupied.extend(test_data::block(100, (0.0, 10.0), (0.0, 0.3)));
        let w = world(100, &occupied, vec![robot(0, 1.0, 1.0, 0.0)]);
        let body = Body::default();
        let pose = Pose { x_m: x, y_m: y, heading_rad: heading };
        let full = w.wall_clearance_at(&body, &pose, 1.0, None);
        let edges = w.edge_cells_before();
        let aided = |at_most_m| {
            w.wall_clearance_at(&body, &pose, 1.0, Some(Aid { edge_cells_before: &edges, at_most_m }))
        };
        prop_assert_eq!(aided(None), full);
        if let Some(d) = full {
            prop_assert_eq!(aided(Some(d)), full);
            prop_assert_eq!(aided(Some(d + slack)), full);
        }
    }
}

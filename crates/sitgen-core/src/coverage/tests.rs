//! Hand-built situations that must mark named cells of the interaction space, the terrain
//! contexts on hand-drawn maps, and cells that come from what happened, not from what the
//! situation's generator asked for. Maps are 20 m square at 0.1 m; the Pioneer 3-AT is 0.505 m
//! wide, so a gap is at most 2 × 0.505 + 0.3 = 1.31 m wide.

use super::*;
use crate::run::tests::{rear_approach, run_with_still_agent, spec};
use crate::run::{run, RunRecord};
use crate::sim::{SimSpec, World};
use crate::situation::Situation;
use crate::test_data::{block, robot, situation};

const SIZE: usize = 200;

fn cells(rec: &RunRecord) -> Vec<&str> {
    rec.coverage.cells.iter().map(String::as_str).collect()
}

/// The cells' values on dimension `d`, without repeats.
fn values(rec: &RunRecord, d: usize) -> BTreeSet<&str> {
    rec.coverage
        .cells
        .iter()
        .map(|c| c.split('/').nth(d).unwrap())
        .collect()
}

/// Both robots driven by `straight` (the agent too: what is marked must not depend on how the
/// agent avoids).
fn run_straight(s: &Situation, time_limit_s: f64) -> RunRecord {
    run(s, &spec(Some("straight"), time_limit_s), 0).unwrap()
}

/// A rectangle of walls: its x range and y range, metres.
type Span = ((f64, f64), (f64, f64));

fn walls(blocks: &[Span]) -> Vec<(usize, usize)> {
    blocks
        .iter()
        .flat_map(|&(x, y)| block(SIZE, x, y))
        .collect()
}

/// The context of the agent (robot 0) standing at `pose` on a map with `occupied` cells.
fn context_at(occupied: &[(usize, usize)], pose: (f64, f64, f64)) -> &'static str {
    let s = situation(
        SIZE,
        occupied,
        vec![robot(0, pose, &[[pose.0, pose.1]], "straight")],
    );
    let world = World::new(&s, SimSpec::default(), 0).unwrap();
    let gap = 2.0 * world.robots()[0].body.width_m + GAP_SLACK_M;
    let pose = Pose {
        x_m: pose.0,
        y_m: pose.1,
        heading_rad: pose.2,
    };
    let asked = agent_context_at(&world, 0, &pose);
    assert_eq!(asked, CONTEXTS[terrain_context(&world, 0, gap) as usize]);
    asked
}

#[test]
fn the_space_has_every_combination_of_its_dimensions() {
    assert_eq!(cell_count(), 7 * 4 * 5 * 4);
    let names: Vec<&str> = DIMENSIONS.iter().map(|d| d.name).collect();
    assert_eq!(names, ["interaction", "clearance", "context", "speed"]);
    let c = Cell {
        interaction: HIDDEN,
        clearance: 1,
        context: BLIND_CORNER,
        speed: 3,
    };
    assert_eq!(c.key(), "hidden/under_0.5m/blind_corner/fast");
}

#[test]
fn a_head_on_pass_in_the_open_marks_head_on_cells_at_every_distance_it_passed() {
    // The peer drives straight at the agent's line 0.8 m to its left: centres 0.8 m apart
    // sideways, footprints 0.8 − 0.505 = 0.295 m at the pass, both at 0.5 m/s.
    let s = situation(
        SIZE,
        &[],
        vec![
            robot(0, (4.0, 10.0, 0.0), &[[16.0, 10.0]], "straight"),
            robot(
                1,
                (16.0, 10.8, std::f64::consts::PI),
                &[[4.0, 10.8]],
                "straight",
            ),
        ],
    );
    let rec = run_straight(&s, 30.0);
    assert_eq!(rec.coverage.encounters, 1);
    assert_eq!(values(&rec, 0), BTreeSet::from(["head_on"]));
    assert_eq!(values(&rec, 2), BTreeSet::from(["open"]));
    assert_eq!(values(&rec, 3), BTreeSet::from(["fast"]));
    for c in ["under_0.5m", "under_1m", "under_2m"] {
        let key = format!("head_on/{c}/open/fast");
        assert!(
            cells(&rec).contains(&key.as_str()),
            "{key} not in {:?}",
            cells(&rec)
        );
    }
    assert!(!values(&rec, 1).contains("contact"), "they never touched");
    assert_eq!(
        rec.coverage.failure_cell.as_deref(),
        Some("head_on/under_0.5m/open/fast")
    );
}

#[test]
fn a_head_on_pass_in_a_corridor_marks_corridor_cells() {
    // Walls above y = 11 and below y = 9 between x = 2 and 18: a corridor 2 m wide (over the
    // 1.31 m of a gap, under the 2.5 m of a corridor). The robots keep 0.9 m apart sideways.
    let map = walls(&[((2.0, 18.0), (8.0, 9.0)), ((2.0, 18.0), (11.0, 12.0))]);
    let s = situation(
        SIZE,
        &map,
        vec![
            robot(0, (4.0, 9.55, 0.0), &[[16.0, 9.55]], "straight"),
            robot(
                1,
                (16.0, 10.45, std::f64::consts::PI),
                &[[4.0, 10.45]],
                "straight",
            ),
        ],
    );
    let rec = run_straight(&s, 30.0);
    assert_eq!(
        values(&rec, 2),
        BTreeSet::from(["corridor"]),
        "{:?}",
        cells(&rec)
    );
    assert!(cells(&rec).contains(&"head_on/under_0.5m/corridor/fast"));
}

#[test]
fn a_peer_appearing_round_a_corner_is_hidden_at_a_blind_corner() {
    // A building fills x in [6, 10], y in [6, 16]. The agent drives east along y = 5.6, its
    // side 0.15 m below the building's wall; the peer drives south down x = 10.6, its side
    // 0.35 m beside the east face. The line from the agent to the peer's nearest corner passes
    // inside the building until both are within a metre of each other (at about 12.6 s, the
    // agent at x = 9.3 and the peer at y = 6.7).
    let map = walls(&[((6.0, 10.0), (6.0, 16.0))]);
    let s = situation(
        SIZE,
        &map,
        vec![
            robot(0, (3.0, 5.6, 0.0), &[[16.0, 5.6]], "straight"),
            robot(
                1,
                (10.6, 13.0, -std::f64::consts::FRAC_PI_2),
                &[[10.6, 1.0]],
                "straight",
            ),
        ],
    );
    let rec = run_straight(&s, 30.0);
    assert_eq!(
        values(&rec, 0),
        BTreeSet::from(["hidden"]),
        "{:?}",
        cells(&rec)
    );
    assert!(
        values(&rec, 2).contains("blind_corner"),
        "{:?}",
        cells(&rec)
    );
}

#[test]
fn a_peer_in_plain_view_crossing_from_the_left_is_not_hidden() {
    // The same crossing with no building: the laser sees the peer from the start.
    let s = situation(
        SIZE,
        &[],
        vec![
            robot(0, (3.0, 5.0, 0.0), &[[16.0, 5.0]], "straight"),
            robot(
                1,
                (11.0, 10.0, -std::f64::consts::FRAC_PI_2),
                &[[11.0, 1.0]],
                "straight",
            ),
        ],
    );
    let rec = run_straight(&s, 30.0);
    assert_eq!(
        values(&rec, 0),
        BTreeSet::from(["crossing_left"]),
        "{:?}",
        cells(&rec)
    );
    assert_eq!(values(&rec, 2), BTreeSet::from(["open"]));
}

#[test]
fn a_peer_driving_into_the_still_agent_from_behind_is_from_behind_in_contact_and_the_failure_is_there(
) {
    // `run::tests::rear_approach`: contact at 6.8 s, the agent never moves.
    let rec = run_with_still_agent(&rear_approach(), 20.0);
    assert_eq!(values(&rec, 0), BTreeSet::from(["from_behind"]));
    assert_eq!(values(&rec, 3), BTreeSet::from(["stopped"]));
    assert!(cells(&rec).contains(&"from_behind/contact/open/stopped"));
    assert_eq!(
        rec.coverage.failure_cell.as_deref(),
        Some("from_behind/contact/open/stopped")
    );
}

#[test]
fn driving_into_a_standing_peer_is_a_stopped_peer_in_the_way() {
    let s = situation(
        SIZE,
        &[],
        vec![
            robot(0, (4.0, 10.0, 0.0), &[[16.0, 10.0]], "straight"),
            robot(1, (10.0, 10.0, 1.0), &[[10.0, 10.0]], "straight"),
        ],
    );
    let rec = run_straight(&s, 30.0);
    assert_eq!(values(&rec, 0), BTreeSet::from(["stopped"]));
    assert!(values(&rec, 1).contains("contact"), "{:?}", cells(&rec));
}

#[test]
fn catching_up_with_a_slower_peer_is_overtaking() {
    let mut slow = robot(1, (8.0, 10.3, 0.0), &[[19.0, 10.3]], "straight");
    slow.controller.params.insert("speed_m_s".into(), 0.1);
    let s = situation(
        SIZE,
        &[],
        vec![robot(0, (4.0, 9.5, 0.0), &[[16.0, 9.5]], "straight"), slow],
    );
    let rec = run_straight(&s, 30.0);
    assert_eq!(
        values(&rec, 0),
        BTreeSet::from(["overtaking"]),
        "{:?}",
        cells(&rec)
    );
}

#[test]
fn cells_come_from_what_happened_not_from_the_generator() {
    // A generated situation whose peers were aimed across the agent's route (`crossing`).
    let crossing = crate::spec::from_toml_str(
        "[terrain]\npreset = \"open_field\"\n[mission]\npeer_mode = \"crossing\"\n\
         peers_min = 2\npeers_max = 2\n",
    )
    .unwrap();
    let (mut s, _) = crate::situation::generate(&crossing, 3).unwrap();
    let met = run(&s, &spec(None, 120.0), 0).unwrap();
    assert!(met.coverage.encounters > 0, "crossing peers met the agent");
    // What the generator was asked for changes nothing ...
    s.provenance.spec = crate::spec::SituationSpec::default();
    s.provenance.spec.mission.peers_max = 0;
    let relabelled = run(&s, &spec(None, 120.0), 0).unwrap();
    assert_eq!(relabelled.coverage, met.coverage);
    // ... and peers that are not there mark nothing, whatever the provenance says.
    let (mut alone, _) = crate::situation::generate(&crossing, 3).unwrap();
    alone.robots.truncate(1);
    let rec = run(&alone, &spec(None, 120.0), 0).unwrap();
    assert_eq!(
        rec.coverage,
        CoverageRecord::default(),
        "{:?}",
        rec.coverage
    );
}

#[test]
fn terrain_contexts_on_hand_drawn_maps() {
    // Open ground.
    assert_eq!(context_at(&[], (10.0, 10.0, 0.0)), "open");
    // A corridor 2 m wide along x.
    let corridor = walls(&[((2.0, 18.0), (8.0, 9.0)), ((2.0, 18.0), (11.0, 12.0))]);
    assert_eq!(context_at(&corridor, (10.0, 10.0, 0.0)), "corridor");
    // A door 1.2 m wide in a wall along y: standing in it, facing through.
    let door = walls(&[((9.0, 10.0), (0.0, 9.4)), ((9.0, 10.0), (10.6, 20.0))]);
    assert_eq!(context_at(&door, (9.5, 10.0, 0.0)), "gap");
    // The corridor closed at x = 12: a metre from its end, facing it.
    let mut pocket = corridor.clone();
    pocket.extend(walls(&[((12.0, 13.0), (9.0, 11.0))]));
    assert_eq!(context_at(&pocket, (11.0, 10.0, 0.0)), "dead_end");
    // A building's corner a metre ahead and to the left, open ground beyond it.
    let corner = walls(&[((6.0, 10.0), (11.0, 16.0))]);
    assert_eq!(context_at(&corner, (9.3, 10.2, 0.0)), "blind_corner");
}

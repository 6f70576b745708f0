//! What a situation file may hold: every robot clear and inside the map, every route usable,
//! the map's size bounded before it is unpacked, and the content hash telling an edited file.

use super::*;
use crate::sim::check_start;
use crate::test_data::{robot, situation};

/// The error of reading `s` back from its JSON, field and message.
fn load_error(s: &Situation) -> String {
    match Situation::from_json(&s.to_json()) {
        Ok(loaded) => check_start(&loaded).unwrap_err().to_string(),
        Err(e) => e.to_string(),
    }
}

fn two_robots(agent: (f64, f64, f64), peer: (f64, f64, f64)) -> Situation {
    situation(
        100,
        &[(50, 50)],
        vec![
            robot(0, agent, &[[8.0, 8.0]], "snd_follow"),
            robot(1, peer, &[[8.0, 2.0]], "straight"),
        ],
    )
}

#[test]
fn a_well_placed_situation_loads_and_its_hash_matches() {
    let s = two_robots((2.0, 2.0, 0.0), (2.0, 8.0, 0.0));
    let loaded = Situation::from_json(&s.to_json()).unwrap();
    check_start(&loaded).unwrap();
    loaded.check_content_hash().unwrap();
}

#[test]
fn robots_outside_the_map_inside_obstacles_or_overlapping_are_refused() {
    // The 10 m map's only obstacle is cell (row 50, column 50): x in [5.0, 5.1], y in [4.9, 5.0].
    let cases = [
        (
            (1e308, 2.0, 0.0),
            (2.0, 8.0, 0.0),
            "robots[0].start: (1e308, 2.0): its footprint leaves the map",
        ),
        (
            (0.1, 2.0, 0.0),
            (2.0, 8.0, 0.0),
            "robots[0].start: (0.1, 2.0): its footprint leaves the map",
        ),
        (
            (2.0, 2.0, 0.0),
            (5.0, 5.0, 0.0),
            "robots[1].start: (5.0, 5.0): its footprint overlaps an obstacle",
        ),
        (
            (2.0, 2.0, 0.0),
            (2.3, 2.2, 1.0),
            "robots[0].start: (2.0, 2.0): its footprint overlaps robot 1's",
        ),
    ];
    for (agent, peer, expected) in cases {
        let e = load_error(&two_robots(agent, peer));
        assert!(e.starts_with(expected), "{e}");
    }
}

#[test]
fn waypoints_outside_the_map_or_in_an_obstacle_and_an_empty_agent_route_are_refused() {
    let mut s = two_robots((2.0, 2.0, 0.0), (2.0, 8.0, 0.0));
    s.robots[1].waypoints = vec![[8.0, 8.0], [12.0, 3.0]];
    assert!(load_error(&s).starts_with("robots[1].waypoints[1]: (12.0, 3.0) is outside the map"));
    s.robots[1].waypoints = vec![[5.05, 4.95]];
    assert!(
        load_error(&s).starts_with("robots[1].waypoints[0]: (5.05, 4.95) is inside an obstacle")
    );
    s.robots[1].waypoints.clear();
    assert!(
        Situation::from_json(&s.to_json()).is_ok(),
        "a peer may stand still"
    );
    s.robots[0].waypoints.clear();
    assert!(
        load_error(&s).starts_with("robots[0].waypoints: the agent needs at least one waypoint")
    );
}

#[test]
fn an_edited_situation_no_longer_matches_its_hash() {
    let mut s = two_robots((2.0, 2.0, 0.0), (2.0, 8.0, 0.0));
    s.robots[1].start.x_m = 3.0;
    let e = s.check_content_hash().unwrap_err().to_string();
    assert!(
        e.starts_with("provenance.content_hash: the map and robots hash to sha256:"),
        "{e}"
    );
    assert!(
        e.ends_with("the file was edited after it was generated"),
        "{e}"
    );
}

#[test]
fn a_map_too_large_or_a_blob_that_inflates_past_its_size_is_refused_unpacked() {
    let mut s = two_robots((2.0, 2.0, 0.0), (2.0, 8.0, 0.0));
    s.map.rows = 1_000_000_000;
    s.map.cols = 1_000_000_000;
    let e = s.map.decode().unwrap_err().to_string();
    assert!(e.contains("more than the 100000000 a map may have"), "{e}");
    // A 10 × 10 map whose blob inflates to a megabyte of zeros: refused after 14 bytes.
    let mut z = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::best());
    z.write_all(&vec![0u8; 1 << 20]).unwrap();
    let bomb = base64::engine::general_purpose::STANDARD.encode(z.finish().unwrap());
    s.map = EmbeddedMap {
        rows: 10,
        cols: 10,
        resolution_m: 0.1,
        encoding: MAP_ENCODING.into(),
        data: bomb,
    };
    let e = s.map.decode().unwrap_err().to_string();
    assert_eq!(
        e,
        "map.data: holds more than 13 bytes; 10 × 10 cells need 13"
    );
}

#[test]
fn too_many_robots_or_waypoints_are_refused() {
    let mut s = two_robots((2.0, 2.0, 0.0), (2.0, 8.0, 0.0));
    s.robots[1].waypoints = vec![[8.0, 2.0]; MAX_WAYPOINTS + 1];
    assert!(load_error(&s).starts_with("robots[1].waypoints: 100001 waypoints; at most 100000"));
    s.robots.truncate(1);
    for id in 1..=MAX_ROBOTS as u32 {
        s.robots.push(robot(id, (2.0, 8.0, 0.0), &[], "straight"));
    }
    assert!(load_error(&s).starts_with("robots: 101 robots; at most 100 allowed"));
}

#[test]
fn a_stage_given_its_own_seed_keeps_its_draws_when_the_master_seed_changes() {
    let spec =
        crate::spec::from_toml_str("[terrain]\npreset = \"caves\"\nwidth_m = 20.0\n").unwrap();
    let mut own = spec.clone();
    own.terrain.seed = Some(7);
    let (a, _) = generate(&own, 1).unwrap();
    let (b, _) = generate(&own, 2).unwrap();
    assert_eq!(a.map, b.map, "the terrain's own seed makes the same map");
    own.mission.seed = Some(11);
    let (c, _) = generate(&own, 3).unwrap();
    let (d, _) = generate(&own, 4).unwrap();
    assert_eq!(
        (c.map, c.robots.len()),
        (d.map.clone(), d.robots.len()),
        "both own seeds: the same situation"
    );
    assert_eq!(c.robots, d.robots);
    // Without them, the master seed decides both stages (what every campaign does).
    let (e, _) = generate(&spec, 1).unwrap();
    let (f, _) = generate(&spec, 2).unwrap();
    assert_ne!(e.map, f.map);
    own.mission.seed = None;
    let (g, _) = generate(&own, 5).unwrap();
    assert_eq!(g.map, d.map);
    assert_ne!(g.robots, d.robots, "a new mission on the same map");
}

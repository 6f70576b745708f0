use std::path::PathBuf;

use rayon::prelude::*;

use super::astar::PathSearch;
use super::rdp::simplify_indices;
use crate::interchange::movingai::{parse_map, parse_scenarios};
use crate::test_data::shared;

#[test]
fn astar_gives_the_movingai_optimal_length_on_every_map_at_every_length() {
    let Some(data) = shared("") else {
        eprintln!(
            "SKIPPED: ../shared/data not found (set SITGEN_SHARED_DATA); MovingAI not checked"
        );
        return;
    };
    let scenarios = data.join("movingai/scenarios");
    let mut files: Vec<PathBuf> = std::fs::read_dir(&scenarios)
        .unwrap()
        .flat_map(|set| std::fs::read_dir(set.unwrap().path()).unwrap())
        .map(|f| f.unwrap().path())
        .collect();
    files.sort();
    let (mut total, mut checked) = (0, 0);
    for scen in &files {
        let set = scen.parent().unwrap().file_name().unwrap();
        let map_name = scen
            .file_name()
            .unwrap()
            .to_string_lossy()
            .replace(".scen", "");
        let map_path = data.join("movingai/maps").join(set).join(&map_name);
        let grid = parse_map(&std::fs::read_to_string(&map_path).unwrap()).unwrap();
        let problems = parse_scenarios(&std::fs::read_to_string(scen).unwrap()).unwrap();
        total += problems.len();
        // A scenario file lists ten problems per length bucket, shortest first: the maze's
        // 11,961 (1,196 buckets of up to 4,800-cell paths) are most of the check's time, and
        // every fourth of them still puts two or three problems of every length in it.
        let stride = problems.len().div_ceil(MOST_PROBLEMS_A_MAP);
        let problems: Vec<_> = problems.into_iter().step_by(stride).collect();
        checked += problems.len();
        let bad: Vec<String> = problems
            .par_iter()
            .map_init(
                || PathSearch::new(&grid.cells, grid.rows, grid.cols),
                |search, p| {
                    (
                        search
                            .shortest_path(p.start, p.goal)
                            .map(|path| path.length),
                        p,
                    )
                },
            )
            .filter_map(|(got, p)| {
                // The files print 6 significant digits (older sets) or 8 decimals: compare
                // within their printed precision plus 1e-6 relative.
                let printed = 5e-6 * p.optimal.max(1.0);
                match got {
                    Some(len) if (len - p.optimal).abs() <= printed + 1e-6 * p.optimal => None,
                    other => Some(format!(
                        "{map_name} {:?}→{:?}: {other:?} vs {}",
                        p.start, p.goal, p.optimal
                    )),
                }
            })
            .collect();
        assert!(bad.is_empty(), "{} wrong, e.g. {}", bad.len(), bad[0]);
    }
    assert_eq!(
        total, 16_980,
        "every problem of the six scenario files read"
    );
    assert_eq!(
        checked, 8_010,
        "all of five maps', every fourth of the maze's"
    );
}

/// Most problems checked on one MovingAI map (its scenario file's, evenly spread).
const MOST_PROBLEMS_A_MAP: usize = 3_000;

#[test]
fn rdp_matches_simplify_js_high_quality_on_every_reference_case() {
    let Some(data) = shared("") else {
        eprintln!("SKIPPED: ../shared/data not found (set SITGEN_SHARED_DATA); RDP not checked");
        return;
    };
    let inputs: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(data.join("rdp/rdp_inputs.json")).unwrap())
            .unwrap();
    let outputs: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(data.join("rdp/rdp_reference_outputs.json")).unwrap(),
    )
    .unwrap();
    let mut checked = 0;
    for result in outputs["results"].as_array().unwrap() {
        let case = result["case"].as_str().unwrap();
        let eps = result["epsilon"].as_f64().unwrap();
        let input = inputs["cases"]
            .as_array()
            .unwrap()
            .iter()
            .find(|c| c["id"] == case)
            .unwrap();
        let points: Vec<(f64, f64)> = input["points"]
            .as_array()
            .unwrap()
            .iter()
            .map(|p| (p[0].as_f64().unwrap(), p[1].as_f64().unwrap()))
            .collect();
        let expected: Vec<usize> =
            serde_json::from_value(result["simplifyjs_1.2.4_highQuality_idx"].clone()).unwrap();
        assert_eq!(
            simplify_indices(&points, eps),
            expected,
            "{case} at ε = {eps}"
        );
        checked += 1;
    }
    assert_eq!(checked, 40);
}

mod situations {
    use crate::grid::distance::squared_distance_to;
    use crate::mission::astar::PathSearch;
    use crate::mission::AtEnd;
    use crate::situation::{self, Role, Situation};
    use crate::spec::from_toml_str;
    use crate::terrain::presets;

    fn generate(preset: &str, seed: u64, extra: &str) -> Situation {
        let spec = from_toml_str(&format!("[terrain]\npreset = \"{preset}\"\n{extra}")).unwrap();
        situation::generate(&spec, seed).unwrap().0
    }

    /// Points spread over the footprint of a robot, its outline included.
    fn footprint_samples(r: &crate::situation::Robot) -> Vec<(f64, f64)> {
        let b = &r.body;
        let (s, c) = r.start.heading_rad.sin_cos();
        let mut out = Vec::new();
        for i in 0..=20 {
            for j in 0..=20 {
                let bx = b.origin_x_m + b.length_m * (i as f64 / 20.0 - 0.5);
                let by = b.width_m * (j as f64 / 20.0 - 0.5);
                out.push((r.start.x_m + c * bx - s * by, r.start.y_m + s * bx + c * by));
            }
        }
        out
    }

    fn dilated(map: &crate::grid::Map, margin: f64) -> Vec<bool> {
        let g = &map.grid;
        squared_distance_to(&g.cells, g.rows, g.cols)
            .into_iter()
            .map(|d| d.sqrt() * map.resolution_m <= margin)
            .collect()
    }

    fn cell(map: &crate::grid::Map, (x, y): (f64, f64)) -> (usize, usize) {
        let res = map.resolution_m;
        (
            (x / res) as usize,
            (map.grid.rows as f64 - y / res) as usize,
        )
    }

    #[test]
    fn situations_keep_their_invariants_over_seeds_and_presets() {
        for name in presets::NAMES {
            for seed in 0..50 {
                let s = generate(name, seed, "");
                let spec = &s.provenance.spec.mission;
                let map = s.map.decode().unwrap();
                let res = map.resolution_m;
                let g = &map.grid;
                // No robot starts touching an obstacle or another robot.
                for r in &s.robots {
                    for (x, y) in footprint_samples(r) {
                        let (c, row) = cell(&map, (x, y));
                        assert!(
                            !g.get(row, c),
                            "{name} {seed}: robot {} on an obstacle",
                            r.id
                        );
                    }
                    for other in s.robots.iter().filter(|o| o.id != r.id) {
                        let d =
                            (r.start.x_m - other.start.x_m).hypot(r.start.y_m - other.start.y_m);
                        assert!(
                            d > 2.0 * r.body.enclosing_radius(),
                            "{name} {seed}: robots {} and {} touch",
                            r.id,
                            other.id
                        );
                    }
                }
                // The simulator agrees that every robot starts clear, and the file reads back.
                crate::sim::check_start(&s).unwrap_or_else(|e| panic!("{name} {seed}: {e}"));
                Situation::from_json(&s.to_json()).unwrap();
                let blocked = dilated(&map, spec.plan_margin_m);
                let agent = &s.robots[0];
                assert_eq!(agent.role, Role::Agent);
                // Every agent leg is plannable, and the planned length reaches the minimum.
                let mut search = PathSearch::new(&blocked, g.rows, g.cols);
                let mut at = (agent.start.x_m, agent.start.y_m);
                let mut planned = 0.0;
                for w in &agent.waypoints {
                    let next = (w[0], w[1]);
                    let path = search.shortest_path(cell(&map, at), cell(&map, next));
                    let path =
                        path.unwrap_or_else(|| panic!("{name} {seed}: agent leg not plannable"));
                    planned += path.length * res;
                    at = next;
                }
                assert!(
                    planned >= spec.min_route_length_m - 1e-9,
                    "{name} {seed}: {planned} m"
                );
                // Every peer leg is a straight line clear of the dilated map (dense sampling),
                // including the leg that closes a loop.
                for p in &s.robots[1..] {
                    assert_eq!(p.role, Role::Peer);
                    let mut at = (p.start.x_m, p.start.y_m);
                    let closing = (p.at_end == AtEnd::Loop).then(|| p.waypoints[0]);
                    for w in p.waypoints.iter().chain(&closing) {
                        // Midpoints of 400 pieces: endpoints are cell centres, and a sample
                        // exactly on a cell corner would count a cell the line only touches.
                        for k in 0..400 {
                            let t = (k as f64 + 0.5) / 400.0;
                            let q = (at.0 + t * (w[0] - at.0), at.1 + t * (w[1] - at.1));
                            let (c, row) = cell(&map, q);
                            assert!(
                                !blocked[row * g.cols + c],
                                "{name} {seed}: peer {} leg blocked",
                                p.id
                            );
                        }
                        at = (w[0], w[1]);
                    }
                }
                assert!(s.robots.len() <= 1 + spec.peers_max as usize);
            }
        }
    }

    #[test]
    fn a_continued_route_goes_on_from_the_goal_as_the_generator_plans_routes() {
        use crate::mission::continue_agent_route;
        use crate::rng::ChoiceSource;
        for name in presets::NAMES {
            for seed in 0..10 {
                let s = generate(name, seed, "");
                let spec = &s.provenance.spec.mission;
                let map = s.map.decode().unwrap();
                let g = &map.grid;
                let goal = s.robots[0].waypoints.last().unwrap();
                let from = (goal[0], goal[1]);
                let go_on = |k| {
                    let mut choices = ChoiceSource::stream(k, "test");
                    continue_agent_route(&map, spec, from, &mut choices)
                        .unwrap_or_else(|e| panic!("{name} {seed}: {}", e.reason))
                };
                let route = go_on(7);
                assert_eq!(route, go_on(7), "{name} {seed}: same seed, same route");
                // Every new leg is plannable from the old goal on, and long enough.
                let blocked = dilated(&map, spec.plan_margin_m);
                let mut search = PathSearch::new(&blocked, g.rows, g.cols);
                let (mut at, mut planned) = (from, 0.0);
                for &next in &route {
                    let path = search.shortest_path(cell(&map, at), cell(&map, next));
                    planned += path.expect("a new leg is plannable").length * map.resolution_m;
                    at = next;
                }
                assert!(planned >= spec.min_route_length_m - 1e-9, "{name} {seed}");
            }
        }
        // No route goes on from inside an obstacle.
        let s = generate("urban", 1, "");
        let map = s.map.decode().unwrap();
        let g = &map.grid;
        let inside = (0..g.rows * g.cols)
            .find(|&i| g.cells[i])
            .map(|i| map.cell_centre(i / g.cols, i % g.cols))
            .unwrap();
        let mut choices = ChoiceSource::stream(1, "test");
        let spec = &s.provenance.spec.mission;
        assert!(continue_agent_route(&map, spec, inside, &mut choices).is_err());
    }

    #[test]
    fn the_same_seed_gives_the_same_situation_and_hash() {
        let a = generate("caves", 4, "");
        let b = generate("caves", 4, "");
        assert_eq!(a.to_json(), b.to_json());
        assert_eq!(a.provenance.content_hash, a.content_hash());
        assert_ne!(
            a.provenance.content_hash,
            generate("caves", 5, "").provenance.content_hash
        );
    }

    #[test]
    fn mission_settings_do_not_change_the_terrain() {
        let a = generate("urban", 9, "");
        let b = generate(
            "urban",
            9,
            "[mission]\npeers_min = 5\npeer_mode = \"crossing\"\n",
        );
        assert_eq!(a.map, b.map);
        assert_eq!(b.robots.len(), 6);
    }

    #[test]
    fn crossing_peers_cross_the_agent_route() {
        let s = generate(
            "open_field",
            2,
            "[mission]\npeers_min = 3\npeers_max = 3\npeer_mode = \"crossing\"\n",
        );
        let agent: Vec<(f64, f64)> =
            std::iter::once((s.robots[0].start.x_m, s.robots[0].start.y_m))
                .chain(s.robots[0].waypoints.iter().map(|w| (w[0], w[1])))
                .collect();
        let crosses = |a: (f64, f64), b: (f64, f64), c: (f64, f64), d: (f64, f64)| {
            let orient = |p: (f64, f64), q: (f64, f64), r: (f64, f64)| {
                (q.0 - p.0) * (r.1 - p.1) - (q.1 - p.1) * (r.0 - p.0)
            };
            orient(a, b, c) * orient(a, b, d) < 0.0 && orient(c, d, a) * orient(c, d, b) < 0.0
        };
        for p in &s.robots[1..] {
            let first = (p.waypoints[0][0], p.waypoints[0][1]);
            let start = (p.start.x_m, p.start.y_m);
            let crossed = agent.windows(2).any(|w| crosses(start, first, w[0], w[1]));
            assert!(
                crossed,
                "peer {} first leg does not cross the agent's route",
                p.id
            );
        }
    }

    #[test]
    fn a_situation_round_trips_through_json_and_bad_fields_are_named() {
        let s = generate("maze", 1, "");
        let back = Situation::from_json(&s.to_json()).unwrap();
        assert_eq!(back, s);
        assert_eq!(
            back.map.decode().unwrap().grid.cells.len(),
            s.map.rows * s.map.cols
        );
        let broken = s
            .to_json()
            .replacen("\"x_m\": ", "\"x_m\": \"far\", \"was\": ", 1);
        let e = Situation::from_json(&broken).unwrap_err().to_string();
        assert!(
            e.starts_with("robots[0].start.x_m: invalid type: string"),
            "{e}"
        );
        let e = Situation::from_json(&s.to_json().replace("\"rows\": ", "\"rows\": 1").to_string())
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("map.data: holds"), "{e}");
    }

    #[test]
    fn no_room_is_a_generation_failure_not_a_crash() {
        let spec = from_toml_str(
            "[terrain]\nwidth_m = 2\nheight_m = 2\n[terrain.source]\nkind = \"rocks\"\ndensity_per_100m2 = 0\n[[terrain.filters]]\nkind = \"border\"\nwidth_m = 0.2\n[mission]\npeers_min = 3\n",
        )
        .unwrap();
        let e = situation::generate(&spec, 1).unwrap_err();
        assert_eq!(e.path, "mission");
        assert!(e.reason.starts_with("no room for robot 1 of"), "{e}");
    }

    #[test]
    fn the_checked_in_situation_schema_matches_the_types() {
        crate::test_data::assert_schema_checked_in(
            "situation.schema.json",
            &situation::json_schema(),
        );
    }

    #[test]
    fn on_a_map_without_a_border_robots_start_inside_it() {
        // An open 6 m × 6 m map: before the map's edge counted as a wall, robots were drawn
        // up to the very edge cells, half their footprint outside.
        for seed in 0..40 {
            let spec = from_toml_str(
                "[terrain]\nwidth_m = 6.0\nheight_m = 6.0\n[terrain.source]\nkind = \"perlin\"\n\
                 [[terrain.filters]]\nkind = \"threshold\"\nvalue = 1.0\n\
                 [mission]\npeers_min = 3\npeers_max = 3\nmin_route_length_m = 5.0\n",
            )
            .unwrap();
            let s = situation::generate(&spec, seed).unwrap().0;
            assert_eq!(s.map.decode().unwrap().grid.occupied_count(), 0);
            crate::sim::check_start(&s).unwrap_or_else(|e| panic!("seed {seed}: {e}"));
        }
    }
}

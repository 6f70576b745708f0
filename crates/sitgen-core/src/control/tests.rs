use super::*;
use crate::grid::{Map, OccupancyGrid};
use crate::sim::{SimSpec, World};
use crate::situation::{self, Role, Situation};
use crate::spec::from_toml_str;

/// Run situation `s`: the agent with `agent`, every peer with its own controller, for at most
/// `max_steps` steps or until `done(world)`; returns the world. Shared by every controller's tests.
pub(crate) fn run_situation(
    s: &Situation,
    agent: &ControllerSpec,
    max_steps: usize,
    mut done: impl FnMut(&World) -> bool,
) -> World {
    let mut world = World::new(s, SimSpec::default(), 0).unwrap();
    let mut controllers: Vec<Box<dyn Controller>> = s
        .robots
        .iter()
        .map(|r| {
            let spec = if r.role == Role::Agent {
                agent
            } else {
                &r.controller
            };
            let mut c = build(spec, "c").unwrap();
            c.reset(r);
            c
        })
        .collect();
    for _ in 0..max_steps {
        if done(&world) {
            break;
        }
        let commands: Vec<(u32, f64, f64)> = controllers
            .iter_mut()
            .enumerate()
            .map(|(i, c)| {
                let (v, w) = c.act(&world.observe(i as u32).unwrap());
                (i as u32, v, w)
            })
            .collect();
        world.step(&commands).unwrap();
    }
    world
}

/// A `w` × `h` m map at `res` m with a one-cell wall round the edge (the laser does not see
/// the map's edge) and the cells whose centres satisfy `wall(x, y)`.
pub(crate) fn map(w: f64, h: f64, res: f64, wall: impl Fn(f64, f64) -> bool) -> Map {
    let (cols, rows) = ((w / res).round() as usize, (h / res).round() as usize);
    let mut grid = OccupancyGrid::filled(rows, cols, false);
    let map_res = res;
    for row in 0..rows {
        for col in 0..cols {
            let (x, y) = ((col as f64 + 0.5) * res, ((rows - row) as f64 - 0.5) * res);
            let edge = row == 0 || col == 0 || row == rows - 1 || col == cols - 1;
            grid.set(row, col, edge || wall(x, y));
        }
    }
    Map {
        grid,
        resolution_m: map_res,
    }
}

/// Generate the situation `spec_text` describes with `seed` and run every robot with `straight`.
fn drive(spec_text: &str, seed: u64, steps: usize) -> World {
    let spec = from_toml_str(spec_text).unwrap();
    let (s, _) = situation::generate(&spec, seed).unwrap();
    let straight = ControllerSpec {
        name: "straight".into(),
        params: Default::default(),
        fault: None,
        control_period_s: None,
        perception: None,
        keep_alive: false,
        step_timeout_s: None,
    };
    run_situation(&s, &straight, steps, |_| false)
}

#[test]
fn straight_peers_drive_their_clear_routes_to_the_end_and_stop() {
    let text = "[terrain]\npreset = \"open_field\"\n[mission]\npeers_min = 3\npeers_max = 3\npeer_at_end = \"stop\"\n";
    let spec = from_toml_str(text).unwrap();
    let (s, _) = situation::generate(&spec, 4).unwrap();
    let world = drive(text, 4, 3000);
    for (r, state) in s
        .robots
        .iter()
        .zip(world.robots())
        .filter(|(r, _)| r.role == Role::Peer)
    {
        let last = r.waypoints.last().unwrap();
        let d = (state.pose.x_m - last[0]).hypot(state.pose.y_m - last[1]);
        assert!(
            d <= 0.3 + 1e-9,
            "peer {} ended {d} m from its last waypoint",
            r.id
        );
        assert_eq!(state.command, (0.0, 0.0), "peer {} stopped", r.id);
    }
}

/// The error building controller `name` with `params` gives, as text.
pub(crate) fn build_error(name: &str, params: &[(&str, f64)], path: &str) -> String {
    let spec = ControllerSpec {
        name: name.into(),
        params: params.iter().map(|&(k, v)| (k.to_string(), v)).collect(),
        fault: None,
        control_period_s: None,
        perception: None,
        keep_alive: false,
        step_timeout_s: None,
    };
    build(&spec, path)
        .err()
        .expect("the spec is bad")
        .to_string()
}

#[test]
fn unknown_controllers_and_parameters_are_named() {
    let e = build_error("teleport", &[], "mission.agent_controller");
    assert!(e.starts_with("mission.agent_controller.name: unknown controller `teleport`"));
    let e = build_error("straight", &[("speed", 1.0)], "c");
    assert!(e.starts_with("c.params.speed: unknown parameter"));
    let e = build_error("straight", &[("speed_m_s", -1.0)], "c");
    assert_eq!(e, "c.params.speed_m_s: -1 is not in (0, 10]");
}

#[test]
fn straight_never_reverses() {
    let world = drive(
        "[terrain]\npreset = \"caves\"\n[mission]\npeers_min = 5\npeers_max = 5\n",
        2,
        400,
    );
    assert!(world.robots().iter().all(|r| r.command.0 >= 0.0));
}

#[test]
fn a_straight_peer_with_start_s_stands_until_then_and_then_drives() {
    let text = "[terrain]\npreset = \"open_field\"\n[mission]\npeers_min = 1\npeers_max = 1\npeer_at_end = \"stop\"\n";
    let spec = from_toml_str(text).unwrap();
    let (mut s, _) = situation::generate(&spec, 4).unwrap();
    s.robots[1].controller.params.insert("start_s".into(), 3.0);
    let agent = ControllerSpec {
        name: "straight".into(),
        params: Default::default(),
        fault: None,
        control_period_s: None,
        perception: None,
        keep_alive: false,
        step_timeout_s: None,
    };
    let start = s.robots[1].start;
    let dt = SimSpec::default().dt_s;
    let moved = |steps: f64| {
        let world = run_situation(&s, &agent, (steps / dt).round() as usize, |_| false);
        let p = world.robots()[1].pose;
        (p.x_m - start.x_m).hypot(p.y_m - start.y_m) + (p.heading_rad - start.heading_rad).abs()
    };
    assert_eq!(moved(2.9), 0.0, "still before start_s");
    assert!(moved(6.0) > 0.1, "on its way after start_s");
    let e = build_error("straight", &[("start_s", -1.0)], "c");
    assert_eq!(e, "c.params.start_s: -1 is not in [0, 3600]");
}

#[test]
fn keep_alive_is_for_a_ros2_node_only() {
    let spec = |name: &str| ControllerSpec {
        keep_alive: true,
        step_timeout_s: None,
        ..ControllerSpec::named(name)
    };
    assert!(super::check(&spec("ros2:python3 node.py"), "run.controller").is_ok());
    for name in ["snd_follow", "cmd:prog", "python:m:C", "navground:HL"] {
        let e = super::check(&spec(name), "run.controller").unwrap_err();
        assert_eq!(e.path, "run.controller.keep_alive", "{name}");
        assert!(e.message.contains("keep_alive is for a ros2: node"), "{e}");
    }
    // Left out where false: a spec without it reads and writes as before.
    let text = serde_json::to_string(&ControllerSpec::named("ros2:x")).unwrap();
    assert!(!text.contains("keep_alive"), "{text}");
}

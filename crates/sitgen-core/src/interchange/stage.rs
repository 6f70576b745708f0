//! Export a situation, with how it is run, to Stage 4.x, so that Stage runs it as sitgen does.
//!
//! Writes into a folder: `situation.world`, `sitgen.inc` (model definitions), `terrain.png`
//! (the map's occupied cells), `edge.png` (the map's edge), `situation.json` and `run.json`
//! (the situation and the resolved run spec, which the controller plugin hands to sitgen).
//! Every robot gets `ctrl "sitgen_stage ID"`: the plugin in `integrations/stage/` drives it with
//! sitgen's own controller over the controller protocol and logs each step
//! (`docs/stage.md`). Facts this follows (Stage's loader, `map.inc`, `model_ranger.cc`):
//! - `size` takes 3 values and `pose`/`origin` 4, or Stage refuses the file at load time (the
//!   stock `pioneer3at` gives 2 and 3, so it is not used: `sitgen_robot` is defined here);
//! - a bitmap pixel is an obstacle when its first channel is ≤ 127, and Stage stretches the
//!   bounding box of the *dark* pixels to the model's `size` and centres it on the model's
//!   pose: so the terrain model's size and pose are those of its occupied cells' bounding box,
//!   and each pixel is exactly one map cell;
//! - sitgen's map edge stops robots but not the laser (a beam leaving the map reads its
//!   maximum), so the edge is a model of its own with `obstacle_return 1` and
//!   `ranger_return -1` (Stage's rangers skip negative returns);
//! - a ranger's beams leave at the height of its model, which Stage stacks on top of its
//!   parent: on top of a 0.277 m Pioneer the beams pass over every other robot. sitgen's laser
//!   sees other robots, so the laser is mounted inside the body (`LASER_DROP_M` below its
//!   top), where beams meet other robots' bodies and the walls;
//! - a robot's `ranger_return` is the intensity a beam reads on hitting it: robot `id` returns
//!   `id + 2` (terrain 1, nothing 0), so the plugin tells which robots a scan sees;
//! - lengths are metres and angles degrees; a child model's pose is relative to its parent's
//!   pose (the rotation centre).
//!
//! Stage's world frame equals sitgen's (origin at the map's bottom-left corner), so poses carry
//! over unchanged. Stage's first update moves nothing (no controller has spoken yet), so Stage
//! time `t + dt` is sitgen time `t`; `quit_time` is the run's time limit plus that step.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use crate::control;
use crate::grid::{Map, OccupancyGrid};
use crate::run::RunSpec;
use crate::situation::{Role, Situation};

use super::image::write_image;

/// File names written into the export folder.
pub const WORLD_FILE: &str = "situation.world";
/// Model definitions included by the world file.
pub const INCLUDE_FILE: &str = "sitgen.inc";
/// The terrain bitmap: the map's cells.
pub const BITMAP_FILE: &str = "terrain.png";
/// The edge bitmap: a one-cell frame just outside the map.
pub const EDGE_BITMAP_FILE: &str = "edge.png";
/// The situation, for the plugin's controllers.
pub const SITUATION_FILE: &str = "situation.json";
/// The resolved run spec, for the plugin's controllers.
pub const RUN_FILE: &str = "run.json";
/// The controller plugin each robot names (`integrations/stage/`).
pub const PLUGIN: &str = "sitgen_stage";

/// Height given to robot bodies, metres (Pioneer 3-AT).
pub const ROBOT_HEIGHT_M: f64 = 0.277;
/// How far below the body's top the laser model sits, metres: its beams then leave at about
/// 0.13 m, within every robot's body and the walls.
pub const LASER_DROP_M: f64 = 0.15;
/// Height of the walls, metres.
const WALL_HEIGHT_M: f64 = 1.0;
/// Intensity of a beam that hits the terrain; robot `id` reads `id + ROBOT_RETURN_BASE`.
pub const TERRAIN_RETURN: u32 = 1;
/// Intensity of a beam that hits robot 0; robot `id` reads `id` more.
pub const ROBOT_RETURN_BASE: u32 = 2;
/// The GUI window's largest side, pixels.
const WINDOW_PX: f64 = 800.0;

/// The model definitions: the terrain, the map's edge, the laser as the run spec has it, and
/// a robot with the run's limits.
pub fn include_text(run: &RunSpec) -> String {
    let laser = &run.sim.laser;
    let mut t = String::from("# Model definitions for worlds exported by sitgen.\n");
    let _ = writeln!(
        t,
        "define sitgen_terrain model\n(\n  color \"gray30\"\n  boundary 0\n  gui_nose 0\n  gui_grid 0\n  gui_move 0\n  gui_outline 0\n  gripper_return 0\n  fiducial_return 0\n  ranger_return {TERRAIN_RETURN}\n  obstacle_return 1\n)\n"
    );
    let _ = writeln!(
        t,
        "# The map's edge: a wall to robots, open to the laser, as in sitgen.\n\
         define sitgen_edge model\n(\n  color \"gray80\"\n  boundary 0\n  gui_nose 0\n  gui_grid 0\n  gui_move 0\n  gui_outline 0\n  gripper_return 0\n  fiducial_return 0\n  ranger_return -1\n  obstacle_return 1\n)\n"
    );
    let _ = writeln!(
        t,
        "# The laser of the run spec ({} degrees, {} beams, {} m), mounted inside the body so\n\
         # that its beams meet other robots; its housing neither blocks nor reflects.\n\
         define sitgen_laser ranger\n(\n  sensor( range [0.0 {}] fov {} samples {} )\n  color \"blue\"\n  size [0.156 0.155 0.19]\n  obstacle_return 0\n  ranger_return -1\n)\n",
        fmt(laser.fov_deg),
        laser.beams,
        fmt(laser.range_m),
        fmt(laser.range_m),
        fmt(laser.fov_deg),
        laser.beams
    );
    let (v, w) = (run.sim.max_speed_m_s, run.sim.max_turn_rate_deg_s);
    let _ = writeln!(
        t,
        "define sitgen_robot position\n(\n  drive \"diff\"\n  gui_nose 1\n  obstacle_return 1\n  localization \"gps\"\n  localization_origin [0 0 0 0]\n  velocity_bounds [{} {} 0 0 0 0 {} {}]\n)",
        fmt(-v),
        fmt(v),
        fmt(-w),
        fmt(w)
    );
    t
}

/// Whether robot `id` carries the laser in a run of `situation` under `run`: the agent
/// always, a peer whose controller senses (as [`crate::run::Run`] fits them).
pub fn has_laser(situation: &Situation, id: u32) -> bool {
    let r = &situation.robots[id as usize];
    r.role == Role::Agent || control::build(&r.controller, "").is_ok_and(|c| c.senses())
}

/// The occupied cells' bounding box as (first row, last row, first col, last col); `None`
/// for a map with none.
fn occupied_box(grid: &OccupancyGrid) -> Option<(usize, usize, usize, usize)> {
    let mut b: Option<(usize, usize, usize, usize)> = None;
    for r in 0..grid.rows {
        for c in 0..grid.cols {
            if grid.get(r, c) {
                b = Some(match b {
                    None => (r, r, c, c),
                    Some((r0, r1, c0, c1)) => (r0.min(r), r1.max(r), c0.min(c), c1.max(c)),
                });
            }
        }
    }
    b
}

/// The world file text for `situation` on `map`, run as `run` says.
pub fn world_text(situation: &Situation, map: &Map, run: &RunSpec) -> String {
    let res = map.resolution_m;
    let (w, h) = (map.width_m(), map.height_m());
    let dt = run.sim.dt_s;
    let mut t = String::new();
    let p = &situation.provenance;
    let _ = writeln!(
        t,
        "# Stage world of a sitgen situation ({}).",
        p.content_hash
    );
    let _ = writeln!(
        t,
        "# Generated by sitgen {} from seed {}.",
        p.sitgen_version, p.seed
    );
    let _ = writeln!(
        t,
        "# Frame: metres, origin at the map's bottom-left corner, as in the situation file.\n\
         # Run headless with `stage -g {WORLD_FILE}`, with the plugin `{PLUGIN}` on STAGEPATH."
    );
    if run.sim.max_accel_m_s2.is_some() || run.sim.max_turn_accel_deg_s2.is_some() {
        let _ = writeln!(
            t,
            "# Not reproduced: the run's acceleration limits (Stage's velocity mode has none)."
        );
    }
    let _ = writeln!(t, "include \"{INCLUDE_FILE}\"\n");
    let _ = writeln!(t, "interval_sim {}", fmt(dt * 1000.0));
    let _ = writeln!(
        t,
        "# The run's time limit, plus Stage's first update, in which nothing moves."
    );
    let _ = writeln!(t, "quit_time {}", fmt(run.time_limit_s + dt));
    let _ = writeln!(t, "resolution {}", fmt(res.min(0.02)));
    let _ = writeln!(t, "speedup -1\n");
    let scale = WINDOW_PX / w.max(h) * 0.95;
    let _ = writeln!(
        t,
        "window\n(\n  size [{} {}]\n  center [{} {}]\n  rotate [0 0]\n  scale {}\n  show_data 1\n)\n",
        (w * scale / 0.95).round(),
        (h * scale / 0.95).round(),
        fmt(w / 2.0),
        fmt(h / 2.0),
        fmt(scale)
    );
    if let Some((r0, r1, c0, c1)) = occupied_box(&map.grid) {
        // Row 0 is the map's top edge.
        let (x0, x1) = (c0 as f64 * res, (c1 + 1) as f64 * res);
        let (y0, y1) = (
            (map.grid.rows - 1 - r1) as f64 * res,
            (map.grid.rows - r0) as f64 * res,
        );
        let _ = writeln!(
            t,
            "sitgen_terrain\n(\n  name \"terrain\"\n  bitmap \"{BITMAP_FILE}\"\n  size [{} {} {}]\n  pose [{} {} 0 0]\n)\n",
            fmt(x1 - x0),
            fmt(y1 - y0),
            fmt(WALL_HEIGHT_M),
            fmt((x0 + x1) / 2.0),
            fmt((y0 + y1) / 2.0)
        );
    }
    let _ = writeln!(
        t,
        "sitgen_edge\n(\n  name \"edge\"\n  bitmap \"{EDGE_BITMAP_FILE}\"\n  size [{} {} {}]\n  pose [{} {} 0 0]\n)\n",
        fmt(w + 2.0 * res),
        fmt(h + 2.0 * res),
        fmt(WALL_HEIGHT_M),
        fmt(w / 2.0),
        fmt(h / 2.0)
    );
    let laser = &run.sim.laser;
    for r in &situation.robots {
        let (name, color) = match r.role {
            Role::Agent => ("agent".to_string(), "red"),
            Role::Peer => (format!("peer{}", r.id), "blue"),
        };
        let mount = if has_laser(situation, r.id) {
            format!(
                "  sitgen_laser( pose [{} 0 {} 0] )\n",
                fmt(laser.offset_x_m),
                fmt(-LASER_DROP_M)
            )
        } else {
            String::new()
        };
        let _ = writeln!(
            t,
            "sitgen_robot\n(\n  name \"{name}\"\n  color \"{color}\"\n  size [{} {} {}]\n  origin [{} 0 0 0]\n  pose [{} {} 0 {}]\n  ranger_return {}\n  ctrl \"{PLUGIN} {}\"\n{mount})\n",
            fmt(r.body.length_m),
            fmt(r.body.width_m),
            fmt(ROBOT_HEIGHT_M),
            fmt(r.body.origin_x_m),
            fmt(r.start.x_m),
            fmt(r.start.y_m),
            fmt(r.start.heading_rad.to_degrees()),
            r.id + ROBOT_RETURN_BASE,
            r.id,
        );
    }
    t
}

/// Shortest decimal that reads back as the same number, with at most 9 decimals.
fn fmt(v: f64) -> String {
    let s = format!("{v:.9}");
    let s = s.trim_end_matches('0').trim_end_matches('.');
    if s == "-0" {
        "0".into()
    } else {
        s.into()
    }
}

/// A one-cell occupied frame around a map of `rows` × `cols` cells, free inside.
pub fn edge_frame(rows: usize, cols: usize) -> OccupancyGrid {
    let mut out = OccupancyGrid::filled(rows + 2, cols + 2, false);
    for c in 0..cols + 2 {
        out.set(0, c, true);
        out.set(rows + 1, c, true);
    }
    for r in 0..rows + 2 {
        out.set(r, 0, true);
        out.set(r, cols + 1, true);
    }
    out
}

/// Write the world, its includes and bitmaps, the situation and the resolved run spec into
/// `dir` (created if needed); returns their paths.
pub fn write_stage(
    situation: &Situation,
    run: &RunSpec,
    dir: &Path,
) -> Result<Vec<PathBuf>, String> {
    run.validate("run").map_err(|e| e.to_string())?;
    let map = situation.map.decode().map_err(|e| e.to_string())?;
    std::fs::create_dir_all(dir).map_err(|e| format!("cannot create {}: {e}", dir.display()))?;
    let path = |name: &str| dir.join(name);
    let write = |path: &Path, text: String| {
        std::fs::write(path, text).map_err(|e| format!("cannot write {}: {e}", path.display()))
    };
    write(&path(WORLD_FILE), world_text(situation, &map, run))?;
    write(&path(INCLUDE_FILE), include_text(run))?;
    write(&path(SITUATION_FILE), situation.to_json())?;
    write(
        &path(RUN_FILE),
        serde_json::to_string_pretty(run).expect("run specs serialise"),
    )?;
    write_image(&map.grid, &path(BITMAP_FILE))?;
    write_image(
        &edge_frame(map.grid.rows, map.grid.cols),
        &path(EDGE_BITMAP_FILE),
    )?;
    Ok([
        WORLD_FILE,
        INCLUDE_FILE,
        BITMAP_FILE,
        EDGE_BITMAP_FILE,
        SITUATION_FILE,
        RUN_FILE,
    ]
    .iter()
    .map(|n| path(n))
    .collect())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::situation;
    use crate::spec::from_toml_str;

    /// Tuples of a property in a world file, e.g. `size [a b c]` → [a, b, c], in file order.
    fn tuples(text: &str, key: &str) -> Vec<Vec<f64>> {
        text.lines()
            .filter_map(|l| l.trim().strip_prefix(&format!("{key} [")))
            .map(|rest| {
                rest.trim_end_matches(']')
                    .split_whitespace()
                    .map(|v| v.parse().unwrap())
                    .collect()
            })
            .collect()
    }

    /// A property's single value, e.g. `quit_time 60.1` → 60.1.
    fn value(text: &str, key: &str) -> f64 {
        text.lines()
            .find_map(|l| l.trim().strip_prefix(&format!("{key} ")))
            .unwrap_or_else(|| panic!("no {key}"))
            .parse()
            .unwrap()
    }

    fn caves(peers: u32, seed: u64) -> (Situation, Map) {
        let spec = from_toml_str(&format!(
            "[terrain]\npreset = \"caves\"\n[mission]\npeers_min = {peers}\npeers_max = {peers}\n"
        ))
        .unwrap();
        let (s, _) = situation::generate(&spec, seed).unwrap();
        let map = s.map.decode().unwrap();
        (s, map)
    }

    #[test]
    fn the_world_file_follows_stages_loader_rules() {
        let (s, map) = caves(2, 3);
        let run = RunSpec::default();
        let world = world_text(&s, &map, &run);
        let sizes = tuples(&world, "size");
        let poses = tuples(&world, "pose");
        let origins = tuples(&world, "origin");
        // The window's size is in pixels (2 values); every model's size has 3.
        assert_eq!(sizes[0].len(), 2);
        assert!(
            sizes[1..].iter().all(|t| t.len() == 3),
            "size takes 3 values"
        );
        assert!(
            poses.iter().chain(&origins).all(|t| t.len() == 4),
            "pose/origin take 4"
        );
        // Terrain: its occupied cells' bounding box, one pixel per cell.
        let (r0, r1, c0, c1) = occupied_box(&map.grid).unwrap();
        let res = map.resolution_m;
        assert!((sizes[1][0] - (c1 - c0 + 1) as f64 * res).abs() < 1e-9);
        assert!((sizes[1][1] - (r1 - r0 + 1) as f64 * res).abs() < 1e-9);
        let left = poses[0][0] - sizes[1][0] / 2.0;
        let top = poses[0][1] + sizes[1][1] / 2.0;
        assert!((left - c0 as f64 * res).abs() < 1e-9);
        assert!((top - (map.grid.rows - r0) as f64 * res).abs() < 1e-9);
        // Edge: a frame one cell outside the map, centred on it.
        assert!((sizes[2][0] - (map.width_m() + 2.0 * res)).abs() < 1e-9);
        assert_eq!(
            poses[1],
            vec![map.width_m() / 2.0, map.height_m() / 2.0, 0.0, 0.0]
        );
        // Robots keep their poses; headings in degrees; the laser mounts come after each body.
        let robot_poses: Vec<_> = poses[2..].iter().filter(|p| p[2] == 0.0).collect();
        for (r, pose) in s.robots.iter().zip(robot_poses) {
            assert!((pose[0] - r.start.x_m).abs() < 1e-9 && (pose[1] - r.start.y_m).abs() < 1e-9);
            assert!((pose[3] - r.start.heading_rad.to_degrees()).abs() < 1e-6);
        }
        assert_eq!(
            world.matches("sitgen_laser(").count(),
            1,
            "only the agent senses among straight peers"
        );
        assert_eq!(
            world.matches("ctrl \"sitgen_stage ").count(),
            s.robots.len()
        );
        assert!((value(&world, "quit_time") - 600.1).abs() < 1e-9);
        let edge = edge_frame(3, 4);
        assert!((0..6).all(|c| edge.get(0, c) && edge.get(4, c)));
        assert!((1..4).all(|r| (1..5).all(|c| !edge.get(r, c))));
    }

    #[test]
    fn the_laser_sits_below_the_top_of_every_body() {
        let (s, map) = caves(2, 5);
        let world = world_text(&s, &map, &RunSpec::default());
        let inc = include_text(&RunSpec::default());
        let line = world.lines().find(|l| l.contains("sitgen_laser(")).unwrap();
        let inside = &line[line.find('[').unwrap() + 1..line.find(']').unwrap()];
        let mount: Vec<f64> = inside
            .split_whitespace()
            .map(|v| v.parse().unwrap())
            .collect();
        let laser_height = tuples(&inc, "size").last().unwrap()[2];
        let beam_z = ROBOT_HEIGHT_M + mount[2] + laser_height / 2.0;
        assert!(
            beam_z > 0.0 && beam_z < ROBOT_HEIGHT_M,
            "beam at {beam_z} m"
        );
    }

    #[test]
    fn peers_that_sense_carry_the_laser_and_the_run_spec_sets_the_world() {
        let spec = from_toml_str(
            "[terrain]\npreset = \"open_field\"\n[mission]\npeers_min = 2\npeers_max = 2\n[mission.peer_controller]\nname = \"vo\"\n",
        )
        .unwrap();
        let (s, _) = situation::generate(&spec, 1).unwrap();
        let map = s.map.decode().unwrap();
        let run: RunSpec = serde_json::from_str(
            r#"{"time_limit_s": 60, "sim": {"max_speed_m_s": 0.5, "laser": {"beams": 90, "fov_deg": 240}}}"#,
        )
        .unwrap();
        let world = world_text(&s, &map, &run);
        let inc = include_text(&run);
        assert_eq!(world.matches("sitgen_laser(").count(), 3);
        assert!((value(&world, "quit_time") - 60.1).abs() < 1e-9);
        assert!(inc.contains("fov 240 samples 90"));
        assert_eq!(
            tuples(&inc, "velocity_bounds")[0],
            vec![-0.5, 0.5, 0.0, 0.0, 0.0, 0.0, -90.0, 90.0]
        );
        // Intensities tell robots apart.
        for r in &s.robots {
            assert!(world.contains(&format!(
                "ranger_return {}\n  ctrl \"sitgen_stage {}\"",
                r.id + 2,
                r.id
            )));
        }
    }
}

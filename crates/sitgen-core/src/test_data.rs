//! Helpers shared by the crate's tests: the reference data beside the repository, the
//! checked-in schema files, and hand-built situations.

use std::path::PathBuf;

use crate::geometry::Body;
use crate::grid::{Map, OccupancyGrid};
use crate::mission::{AtEnd, ControllerSpec};
use crate::situation::{Pose, Robot, Role, Situation};
use crate::spec::SituationSpec;

/// A Pioneer 3-AT with id `id` (0 is the agent) at (x, y, heading) driving to `waypoints` with
/// controller `controller`, stopping at the end.
pub fn robot(id: u32, start: (f64, f64, f64), waypoints: &[[f64; 2]], controller: &str) -> Robot {
    Robot {
        id,
        role: if id == 0 { Role::Agent } else { Role::Peer },
        body: Body::default(),
        start: Pose {
            x_m: start.0,
            y_m: start.1,
            heading_rad: start.2,
        },
        waypoints: waypoints.to_vec(),
        controller: ControllerSpec {
            name: controller.into(),
            params: Default::default(),
            fault: None,
            control_period_s: None,
            perception: None,
            keep_alive: false,
            step_timeout_s: None,
        },
        at_end: AtEnd::Stop,
    }
}

/// A situation on a `size` × `size` cell map at 0.1 m with the given occupied cells (row from
/// the top, column).
pub fn situation(size: usize, occupied: &[(usize, usize)], robots: Vec<Robot>) -> Situation {
    let mut g = OccupancyGrid::filled(size, size, false);
    for &(r, c) in occupied {
        g.set(r, c, true);
    }
    let map = Map {
        grid: g,
        resolution_m: 0.1,
    };
    Situation::new(&map, robots, SituationSpec::default(), 0)
}

/// The occupied cells of a map `size` cells square at 0.1 m whose squares lie inside
/// [x0, x1] × [y0, y1] (metres; give bounds on the 0.1 m grid).
pub fn block(size: usize, (x0, x1): (f64, f64), (y0, y1): (f64, f64)) -> Vec<(usize, usize)> {
    let inside = |lo: f64, hi: f64, k: usize| {
        let a = k as f64 * 0.1;
        a >= lo - 1e-9 && a + 0.1 <= hi + 1e-9
    };
    let mut cells = Vec::new();
    for row in 0..size {
        for col in 0..size {
            if inside(x0, x1, col) && inside(y0, y1, size - 1 - row) {
                cells.push((row, col));
            }
        }
    }
    cells
}

/// `../shared/data` beside the repository (or `$SITGEN_SHARED_DATA`) joined with `rel`, if it
/// exists; tests that need it print why they skip when it does not.
pub fn shared(rel: &str) -> Option<PathBuf> {
    let path = std::env::var_os("SITGEN_SHARED_DATA")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data"))
        .join(rel);
    path.exists().then_some(path)
}

/// Assert that `schema/<file>` equals `generated`; with `SITGEN_BLESS=1` rewrite it first.
pub fn assert_schema_checked_in(file: &str, generated: &str) {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../schema")
        .join(file);
    if std::env::var_os("SITGEN_BLESS").is_some() {
        std::fs::write(&path, generated).unwrap();
    }
    let checked_in = std::fs::read_to_string(&path).unwrap_or_default();
    assert!(
        checked_in == generated,
        "schema/{file} is out of date; run `SITGEN_BLESS=1 cargo test -p sitgen-core schema` and commit it"
    );
}

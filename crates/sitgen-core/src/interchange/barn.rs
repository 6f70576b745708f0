//! BARN worlds as situations: the Benchmark for Autonomous Robot Navigation's 30 × 30 grids
//! (Perille, Truong, Xiao & Stone, SSRR 2020), each set in its challenge's course, with a
//! Clearpath Jackal as the agent and no peers — a fixed, hand-curated benchmark beside
//! generated situations.
//!
//! The course follows the BARN challenge (`../shared/data/barn/README.md`), shifted by 4.5 m in
//! x so that the map starts at the origin: 4.5 m wide (BARN rows 0–29 run along x, cell (r, c)
//! centred at x = 0.075 + 0.15 r) and 15 m long; the obstacle field spans y = 5.1–9.6 m (BARN
//! column c centred at y = 5.175 + 0.15 c); below it the containment pen (a back wall at
//! y = 0.075 m, the field's side walls carried down); above it open ground to the map's edge.
//! The Jackal starts at (2.25, 3) heading +y (the challenge's (−2.25, 3), 1.57 rad) and its
//! route is the world's official path (A* in C-space, `path_files`), simplified by
//! Ramer–Douglas–Peucker to one cell, then the challenge's goal (2.25, 13).

use crate::geometry::Body;
use crate::grid::{Map, OccupancyGrid};
use crate::mission::{rdp, AtEnd, ControllerSpec};
use crate::situation::{Pose, Robot, Role, Situation};
use crate::spec::{SituationSpec, SpecError};

/// BARN's cell size, metres.
pub const CELL_M: f64 = 0.15;
/// Cells of a BARN grid along each side.
pub const SIDE: usize = 30;
/// Rows of the course below the obstacle field (5.1 m).
const FIELD_FIRST_ROW: usize = 34;
/// Rows of the whole course (15 m).
const COURSE_ROWS: usize = 100;
/// The agent's start and the goal, metres (the challenge's, shifted by 4.5 m in x).
const START: (f64, f64) = (2.25, 3.0);
const GOAL: (f64, f64) = (2.25, 13.0);

/// The Clearpath Jackal's footprint: 0.508 × 0.430 m, turning about its centre.
pub fn jackal() -> Body {
    Body {
        model: "jackal".into(),
        length_m: 0.508,
        width_m: 0.430,
        origin_x_m: 0.0,
    }
}

/// The centre of course cell (column `x`, row `y` counted up from the bottom), metres.
fn centre(x: usize, y: usize) -> (f64, f64) {
    ((x as f64 + 0.5) * CELL_M, (y as f64 + 0.5) * CELL_M)
}

/// BARN world `index` as a situation: `grid` is its 30 × 30 grid, row-major with BARN's
/// (row, column) indices (non-zero: obstacle), `path` its official path as (row, column) cells.
pub fn barn_situation(
    grid: &[u8],
    path: &[(usize, usize)],
    index: u64,
) -> Result<Situation, SpecError> {
    if grid.len() != SIDE * SIDE {
        return Err(SpecError::new(
            "grid",
            format!("{} cells; a BARN grid has {SIDE} × {SIDE}", grid.len()),
        ));
    }
    if let Some(&(r, c)) = path.iter().find(|&&(r, c)| r >= SIDE || c >= SIDE) {
        return Err(SpecError::new(
            "path",
            format!("cell ({r}, {c}) is outside the {SIDE} × {SIDE} grid"),
        ));
    }
    // OccupancyGrid row 0 is the top: course row y (from the bottom) is grid row ROWS − 1 − y.
    let mut occupancy = OccupancyGrid::filled(COURSE_ROWS, SIDE, false);
    let mut set = |x: usize, y: usize| occupancy.set(COURSE_ROWS - 1 - y, x, true);
    for r in 0..SIDE {
        for c in 0..SIDE {
            if grid[r * SIDE + c] != 0 {
                set(r, FIELD_FIRST_ROW + c);
            }
        }
    }
    // The pen: a back wall and the field's side walls carried down to it.
    for x in 0..SIDE {
        set(x, 0);
    }
    for y in 0..FIELD_FIRST_ROW {
        set(0, y);
        set(SIDE - 1, y);
    }
    let map = Map {
        grid: occupancy,
        resolution_m: CELL_M,
    };
    let route: Vec<(f64, f64)> = path
        .iter()
        .map(|&(r, c)| centre(r, FIELD_FIRST_ROW + c))
        .collect();
    let mut waypoints: Vec<[f64; 2]> = rdp::simplify(&route, CELL_M)
        .into_iter()
        .map(|(x, y)| [x, y])
        .collect();
    waypoints.dedup();
    waypoints.push([GOAL.0, GOAL.1]);
    let agent = Robot {
        id: 0,
        role: Role::Agent,
        body: jackal(),
        start: Pose {
            x_m: START.0,
            y_m: START.1,
            heading_rad: std::f64::consts::FRAC_PI_2,
        },
        waypoints,
        controller: ControllerSpec::named("snd_follow"),
        at_end: AtEnd::Stop,
    };
    let situation = Situation::new(&map, vec![agent], SituationSpec::default(), index);
    situation.validate()?;
    crate::sim::check_start(&situation)?;
    Ok(situation)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::control::tests::run_situation;

    /// An empty field with a straight path up the middle.
    fn open() -> (Vec<u8>, Vec<(usize, usize)>) {
        let mut grid = vec![0u8; SIDE * SIDE];
        for c in 0..SIDE {
            grid[c] = 1;
            grid[(SIDE - 1) * SIDE + c] = 1;
        }
        (grid, (0..SIDE).map(|c| (15, c)).collect())
    }

    #[test]
    fn an_open_world_is_a_course_the_jackal_drives_through_to_the_goal() {
        let (grid, path) = open();
        let s = barn_situation(&grid, &path, 7).unwrap();
        assert_eq!(s.provenance.seed, 7);
        let agent = &s.robots[0];
        assert_eq!(agent.body.model, "jackal");
        // A straight path simplifies to its two ends, then the goal.
        assert_eq!(agent.waypoints.len(), 3, "{:?}", agent.waypoints);
        assert_eq!(agent.waypoints.last(), Some(&[2.25, 13.0]));
        let map = s.map.decode().unwrap();
        assert_eq!((map.grid.rows, map.grid.cols), (COURSE_ROWS, SIDE));
        let world = run_situation(&s, &agent.controller, 1500, |w| {
            let p = w.robots()[0].pose;
            (p.x_m - GOAL.0).hypot(p.y_m - GOAL.1) < 0.5
        });
        let p = world.robots()[0].pose;
        assert!((p.x_m - GOAL.0).hypot(p.y_m - GOAL.1) < 0.5, "{p:?}");
    }

    #[test]
    fn obstacles_sit_where_the_challenge_puts_them() {
        let (mut grid, path) = open();
        grid[5 * SIDE + 12] = 1; // BARN cell (5, 12): x = 0.825 m, y = 6.975 m
        let s = barn_situation(&grid, &path, 0).unwrap();
        let map = s.map.decode().unwrap();
        let occupied = |x: f64, y: f64| {
            let col = (x / CELL_M) as usize;
            let row = COURSE_ROWS - 1 - (y / CELL_M) as usize;
            map.grid.get(row, col)
        };
        assert!(occupied(0.825, 6.975));
        assert!(!occupied(0.825 + CELL_M, 6.975) && !occupied(0.825, 6.975 + CELL_M));
        assert!(occupied(0.075, 2.0) && occupied(4.425, 2.0) && occupied(2.25, 0.075));
        assert!(!occupied(0.075, 12.0), "open ground beyond the field");
    }

    #[test]
    fn a_grid_of_the_wrong_size_or_a_path_off_it_is_named() {
        let (grid, path) = open();
        let e = barn_situation(&grid[1..], &path, 0)
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("grid: 899 cells"), "{e}");
        let e = barn_situation(&grid, &[(30, 0)], 0)
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("path: cell (30, 0)"), "{e}");
    }
}

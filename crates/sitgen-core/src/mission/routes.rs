//! Placement and routes: the steps listed in the module doc of [`crate::mission`].

use crate::geometry::segment::for_each_cell;
use crate::grid::distance::{squared_distance_with_edge, with_edge};
use crate::grid::regions::{label_regions, Connectivity};
use crate::grid::Map;
use crate::rng::ChoiceSource;
use crate::situation::{Pose, Robot, Role};
use crate::terrain::GenerationFailed;

use super::astar::PathSearch;
use super::rdp::simplify;
use super::{AtEnd, MissionSpec, PeerMode};

/// Most legs an agent route may have before generation gives up (a tiny reachable region
/// can never reach the minimum length).
const MAX_AGENT_LEGS: usize = 1000;

/// Tries at a crossing leg before a peer falls back to a random leg.
const CROSSING_TRIES: u32 = 50;

/// Clear random legs drawn for a peer's leg; the longest is kept, so that peers in cluttered
/// maps do more than shuffle on the spot.
const RANDOM_LEG_CANDIDATES: usize = 8;

fn failed(reason: String) -> GenerationFailed {
    GenerationFailed {
        path: "mission".into(),
        reason,
    }
}

/// The map as planning sees it: which cells can hold a robot, and which are free after
/// dilation.
struct Plan<'a> {
    map: &'a Map,
    /// Cells a robot centre may be placed on.
    placeable: Vec<u32>,
    /// Placeable cells in the largest region of the dilated map that A* can traverse
    /// (4-connected, since A* cuts no corners): the agent starts there, so that most goals are
    /// reachable.
    agent_placeable: Vec<u32>,
    /// Blocked cells of the dilated map.
    blocked: Vec<bool>,
    /// Free cells of the dilated map, for drawing goals.
    free: Vec<u32>,
}

impl<'a> Plan<'a> {
    /// `to_occupied`: the map's squared distances to its occupied cells.
    fn new(map: &'a Map, to_occupied: &[f64], spec: &MissionSpec) -> Self {
        let g = &map.grid;
        let res = map.resolution_m;
        let d2 = with_edge(to_occupied, g.rows, g.cols);
        let place_beyond =
            spec.body.enclosing_radius() + spec.clearance_m + res * std::f64::consts::FRAC_1_SQRT_2;
        let placeable: Vec<u32> = (0..d2.len() as u32)
            .filter(|&i| d2[i as usize].sqrt() * res > place_beyond)
            .collect();
        let blocked = blocked_within(&d2, res, spec.plan_margin_m);
        let free: Vec<u32> = (0..blocked.len() as u32)
            .filter(|&i| !blocked[i as usize])
            .collect();
        let open: Vec<bool> = blocked.iter().map(|&b| !b).collect();
        let regions = label_regions(&open, g.rows, g.cols, Connectivity::Four);
        let largest = (0..regions.sizes.len())
            .rev()
            .max_by_key(|&i| regions.sizes[i])
            .map(|i| i as u32);
        let agent_placeable = placeable
            .iter()
            .copied()
            .filter(|&i| Some(regions.label[i as usize]) == largest)
            .collect();
        Self {
            map,
            placeable,
            agent_placeable,
            blocked,
            free,
        }
    }

    fn cell_of(&self, i: u32) -> (usize, usize) {
        let cols = self.map.grid.cols;
        (i as usize % cols, i as usize / cols)
    }

    /// World coordinates of the centre of cell (column, row).
    fn centre(&self, (c, r): (usize, usize)) -> (f64, f64) {
        self.map.cell_centre(r, c)
    }

    /// Whether the straight segment between two world points crosses no blocked cell.
    fn segment_clear(&self, a: (f64, f64), b: (f64, f64)) -> bool {
        segment_clear(self.map, &self.blocked, a, b)
    }

    /// How far a straight line from `from` in `direction` (radians) stays on free cells of the
    /// dilated map, to half a cell.
    fn clear_reach(&self, from: (f64, f64), direction: f64) -> f64 {
        let step = self.map.resolution_m / 2.0;
        let (dx, dy) = (direction.cos() * step, direction.sin() * step);
        let cols = self.map.grid.cols;
        let mut reach = 0.0;
        let mut at = from;
        loop {
            at = (at.0 + dx, at.1 + dy);
            match self.cell_at(at) {
                Some((c, r)) if !self.blocked[r * cols + c] => reach += step,
                _ => return reach,
            }
        }
    }

    /// The cell (column, row) containing a world point inside the map.
    fn cell_at(&self, (x, y): (f64, f64)) -> Option<(usize, usize)> {
        let g = &self.map.grid;
        let res = self.map.resolution_m;
        let (u, v) = (x / res, g.rows as f64 - y / res);
        (u >= 0.0 && v >= 0.0 && (u as usize) < g.cols && (v as usize) < g.rows)
            .then_some((u as usize, v as usize))
    }
}

/// The cells of the map dilated by `margin_m` (from the squared distances `d2`, in cells, to
/// the nearest obstacle or the edge): those that planning treats as blocked.
fn blocked_within(d2: &[f64], resolution_m: f64, margin_m: f64) -> Vec<bool> {
    d2.iter()
        .map(|&d| d.sqrt() * resolution_m <= margin_m)
        .collect()
}

/// Whether the straight segment between two world points crosses no `blocked` cell of `map`.
fn segment_clear(map: &Map, blocked: &[bool], a: (f64, f64), b: (f64, f64)) -> bool {
    let g = &map.grid;
    let res = map.resolution_m;
    let to_cells = |(x, y): (f64, f64)| (x / res, g.rows as f64 - y / res);
    for_each_cell(to_cells(a), to_cells(b), |u, v| {
        u >= 0
            && v >= 0
            && (u as usize) < g.cols
            && (v as usize) < g.rows
            && !blocked[v as usize * g.cols + u as usize]
    })
}

/// Check that every peer leg (start → waypoints, and a `loop` route's closing leg) is clear on
/// `map` dilated by `margin_m`, as the generator draws them; the error names the first that
/// is not.
pub fn check_peer_legs(map: &Map, margin_m: f64, robots: &[Robot]) -> Result<(), String> {
    let blocked = blocked_within(
        &squared_distance_with_edge(&map.grid),
        map.resolution_m,
        margin_m,
    );
    for r in robots.iter().filter(|r| r.role == Role::Peer) {
        let mut points = vec![(r.start.x_m, r.start.y_m)];
        points.extend(r.waypoints.iter().map(|w| (w[0], w[1])));
        if r.at_end == AtEnd::Loop && points.len() > 2 {
            points.push(points[1]);
        }
        for (k, leg) in points.windows(2).enumerate() {
            if !segment_clear(map, &blocked, leg[0], leg[1]) {
                return Err(format!(
                    "robots[{}]: leg {k} from ({:.2}, {:.2}) to ({:.2}, {:.2}) is not clear of obstacles by {margin_m} m",
                    r.id, leg[0].0, leg[0].1, leg[1].0, leg[1].1
                ));
            }
        }
    }
    Ok(())
}

/// Place the robots and plan their routes on `map`, whose squared distances to its occupied
/// cells are `to_occupied` ([`crate::grid::distance::squared_distance_to`]). The agent
/// (placement and route) draws from `mission`; the peers' routes draw from `peers`.
pub fn generate(
    map: &Map,
    to_occupied: &[f64],
    spec: &MissionSpec,
    mission: &mut ChoiceSource,
    peers: &mut ChoiceSource,
) -> Result<Vec<Robot>, GenerationFailed> {
    let mut plan = Plan::new(map, to_occupied, spec);
    let peer_count = mission.int_in(i64::from(spec.peers_min), i64::from(spec.peers_max)) as usize;
    let starts = place_robots(&mut plan, spec, 1 + peer_count, mission)?;
    let agent_route = plan_agent_route(&plan, spec, starts[0], mission)?;
    let mut robots = vec![robot(
        0,
        Role::Agent,
        spec,
        starts[0],
        agent_route.clone(),
        AtEnd::Stop,
    )];
    let mut agent_polyline = vec![starts[0]];
    agent_polyline.extend(&agent_route);
    for (k, &start) in starts.iter().enumerate().skip(1) {
        let route = plan_peer_route(&plan, spec, start, &agent_polyline, peers)
            .map_err(|reason| failed(format!("peer {k}: {reason}")))?;
        robots.push(robot(
            k as u32,
            Role::Peer,
            spec,
            start,
            route,
            spec.peer_at_end,
        ));
    }
    draw_peer_controllers(spec, &mut robots, peers);
    Ok(robots)
}

/// Each peer's controller drawn from `peer_controllers`, where the spec lists several; drawn
/// after every route, so that a spec without the list draws exactly what it did before.
fn draw_peer_controllers(spec: &MissionSpec, robots: &mut [Robot], choices: &mut ChoiceSource) {
    let listed = &spec.peer_controllers;
    for r in robots.iter_mut().filter(|r| r.role == Role::Peer) {
        r.controller = match listed.len() {
            0 => continue,
            1 => listed[0].clone(),
            n => listed[choices.index(n)].clone(),
        };
    }
}

fn robot(
    id: u32,
    role: Role,
    spec: &MissionSpec,
    start: (f64, f64),
    waypoints: Vec<(f64, f64)>,
    at_end: AtEnd,
) -> Robot {
    let first = waypoints.first().copied().unwrap_or(start);
    Robot {
        id,
        role,
        body: spec.body.clone(),
        start: Pose {
            x_m: start.0,
            y_m: start.1,
            heading_rad: (first.1 - start.1).atan2(first.0 - start.0),
        },
        waypoints: waypoints.into_iter().map(|(x, y)| [x, y]).collect(),
        controller: match role {
            Role::Agent => spec.agent_controller.clone(),
            Role::Peer => spec.peer_controller.clone(),
        },
        at_end,
    }
}

/// Draw `count` robot centres, each clear of obstacles and of the robots before it.
fn place_robots(
    plan: &mut Plan<'_>,
    spec: &MissionSpec,
    count: usize,
    choices: &mut ChoiceSource,
) -> Result<Vec<(f64, f64)>, GenerationFailed> {
    let apart = 2.0 * (spec.body.enclosing_radius() + spec.clearance_m);
    let mut starts = Vec::with_capacity(count);
    for k in 0..count {
        let candidates = if k == 0 {
            &plan.agent_placeable
        } else {
            &plan.placeable
        };
        if candidates.is_empty() {
            return Err(failed(format!(
                "no room for robot {k} of {count}: no free cell is {:.3} m from every obstacle and robot",
                spec.body.enclosing_radius() + spec.clearance_m
            )));
        }
        let cell = candidates[choices.index(candidates.len())];
        let here = plan.centre(plan.cell_of(cell));
        starts.push(here);
        if k + 1 == count {
            break;
        }
        // The next robots keep `hypot(dx, dy) > apart` from this one. Only rows within
        // `apart` of it (and a row's slack) hold a cell that fails it, and the candidates are
        // in row-major order, so those rows are one slice of the 10^5; the cells in it are
        // tested by squares.
        let cols = plan.map.grid.cols;
        let row = plan.cell_of(cell).1;
        let reach = (apart / plan.map.resolution_m).ceil() as usize + 1;
        let first = plan
            .placeable
            .partition_point(|&i| i as usize / cols + reach < row);
        let end = plan
            .placeable
            .partition_point(|&i| i as usize / cols <= row + reach);
        let kept: Vec<u32> = plan.placeable[first..end]
            .iter()
            .copied()
            .filter(|&i| {
                let (x, y) = plan.centre(plan.cell_of(i));
                let (dx, dy) = (x - here.0, y - here.1);
                crate::geometry::beyond_by_squares(dx * dx + dy * dy, apart * apart, || {
                    dx.hypot(dy) > apart
                })
            })
            .collect();
        plan.placeable.splice(first..end, kept);
    }
    Ok(starts)
}

/// Goals planned one after another with A* until the route is long enough, each leg
/// simplified; returns the waypoints after the start.
fn plan_agent_route(
    plan: &Plan<'_>,
    spec: &MissionSpec,
    start: (f64, f64),
    choices: &mut ChoiceSource,
) -> Result<Vec<(f64, f64)>, GenerationFailed> {
    let g = &plan.map.grid;
    let res = plan.map.resolution_m;
    let mut search = PathSearch::new(&plan.blocked, g.rows, g.cols);
    let mut current = plan
        .cell_at(start)
        .expect("robots are placed inside the map");
    let mut length_m = 0.0;
    let mut waypoints = Vec::new();
    let mut legs = 0;
    while legs == 0 || length_m < spec.min_route_length_m {
        if legs == MAX_AGENT_LEGS {
            return Err(failed(format!(
                "agent route reached only {length_m:.1} m of {} m in {MAX_AGENT_LEGS} legs: the free space around the start is too small",
                spec.min_route_length_m
            )));
        }
        let mut leg = None;
        for _ in 0..spec.goal_attempts {
            let goal = plan.cell_of(plan.free[choices.index(plan.free.len())]);
            if goal == current {
                continue;
            }
            if let Some(path) = search.shortest_path(current, goal) {
                leg = Some(path);
                break;
            }
        }
        let Some(path) = leg else {
            let (x, y) = plan.centre(current);
            return Err(failed(format!(
                "no reachable goal from ({x:.2}, {y:.2}) in {} draws (mission.goal_attempts)",
                spec.goal_attempts
            )));
        };
        length_m += path.length * res;
        let points: Vec<(f64, f64)> = path.cells.iter().map(|&c| plan.centre(c)).collect();
        waypoints.extend(simplify(&points, spec.rdp_epsilon_m).into_iter().skip(1));
        current = *path.cells.last().expect("a path has cells");
        legs += 1;
    }
    Ok(waypoints)
}

/// The agent's route continued from `from` as [`generate`] plans one (step 2 of the module
/// doc, on `map` with `spec`): goals drawn from the free cells of the dilated map, each
/// reached by A* from the last and simplified by RDP, until the continuation is
/// `min_route_length_m` long. A mission that goes on past its goal (the search's
/// `extend_route`) is planned as the generator plans one, not by a copy of its rules.
pub fn continue_agent_route(
    map: &Map,
    spec: &MissionSpec,
    from: (f64, f64),
    choices: &mut ChoiceSource,
) -> Result<Vec<(f64, f64)>, GenerationFailed> {
    let g = &map.grid;
    let to_occupied = crate::grid::distance::squared_distance_to(&g.cells, g.rows, g.cols);
    let plan = Plan::new(map, &to_occupied, spec);
    match plan.cell_at(from) {
        Some((c, r)) if !plan.blocked[r * g.cols + c] => {
            plan_agent_route(&plan, spec, from, choices)
        }
        _ => Err(failed(format!(
            "({:.2}, {:.2}) is not free ground of the dilated map: no route goes on from there",
            from.0, from.1
        ))),
    }
}

/// Straight legs, each clear on the dilated map.
fn plan_peer_route(
    plan: &Plan<'_>,
    spec: &MissionSpec,
    start: (f64, f64),
    agent: &[(f64, f64)],
    choices: &mut ChoiceSource,
) -> Result<Vec<(f64, f64)>, String> {
    let mut route = Vec::new();
    let mut here = start;
    for _ in 0..spec.peer_legs {
        let crossing = match spec.peer_mode {
            PeerMode::Crossing => crossing_leg(plan, here, agent, choices),
            PeerMode::Random => None,
        };
        let next = crossing.or_else(|| random_leg(plan, spec, here, choices));
        match next {
            Some(p) => {
                route.push(p);
                here = p;
            }
            None if route.is_empty() => {
                return Err(format!(
                    "no straight clear leg from ({:.2}, {:.2}) in {} draws (mission.goal_attempts)",
                    here.0, here.1, spec.goal_attempts
                ))
            }
            None => break,
        }
    }
    close_loop(plan, spec.peer_at_end, &mut route);
    Ok(route)
}

/// A `loop` route drives from its last waypoint back to its first, a leg no draw checked: if
/// that leg is not clear, the route comes back the way it went (w1 … wn, wn−1 … w2), so that
/// every leg of the loop is one already known to be clear.
fn close_loop(plan: &Plan<'_>, at_end: AtEnd, route: &mut Vec<(f64, f64)>) {
    let n = route.len();
    if at_end != AtEnd::Loop || n < 3 || plan.segment_clear(route[n - 1], route[0]) {
        return;
    }
    let back: Vec<(f64, f64)> = route[1..n - 1].iter().rev().copied().collect();
    route.extend(back);
}

/// A random clear leg: the longest of a few draws, each in a random direction, ending at a
/// random point of the second half of the clear stretch that way.
fn random_leg(
    plan: &Plan<'_>,
    spec: &MissionSpec,
    here: (f64, f64),
    choices: &mut ChoiceSource,
) -> Option<(f64, f64)> {
    let mut best: Option<(f64, (f64, f64))> = None;
    let mut found = 0;
    for _ in 0..spec.goal_attempts {
        let direction = choices.uniform(0.0, std::f64::consts::TAU);
        let reach = plan.clear_reach(here, direction);
        let along = reach * choices.uniform(0.5, 1.0);
        let aim = (
            here.0 + along * direction.cos(),
            here.1 + along * direction.sin(),
        );
        let Some(cell) = plan.cell_at(aim) else {
            continue;
        };
        let target = plan.centre(cell);
        if target != here && plan.segment_clear(here, target) {
            let length = (target.0 - here.0).hypot(target.1 - here.1);
            if best.is_none_or(|(l, _)| length > l) {
                best = Some((length, target));
            }
            found += 1;
            if found == RANDOM_LEG_CANDIDATES {
                break;
            }
        }
    }
    best.map(|(_, target)| target)
}

/// A leg aimed through a random point of the agent's route and up to as far again beyond it.
fn crossing_leg(
    plan: &Plan<'_>,
    here: (f64, f64),
    agent: &[(f64, f64)],
    choices: &mut ChoiceSource,
) -> Option<(f64, f64)> {
    let lengths: Vec<f64> = agent
        .windows(2)
        .map(|w| (w[1].0 - w[0].0).hypot(w[1].1 - w[0].1))
        .collect();
    let total: f64 = lengths.iter().sum();
    if total <= 0.0 {
        return None;
    }
    for _ in 0..CROSSING_TRIES {
        let mut along = choices.uniform(0.0, total);
        let mut through = *agent.last()?;
        for (w, &len) in agent.windows(2).zip(&lengths) {
            if along <= len {
                let t = along / len;
                through = (
                    w[0].0 + t * (w[1].0 - w[0].0),
                    w[0].1 + t * (w[1].1 - w[0].1),
                );
                break;
            }
            along -= len;
        }
        let beyond = choices.uniform(1.2, 2.0);
        let aim = (
            here.0 + beyond * (through.0 - here.0),
            here.1 + beyond * (through.1 - here.1),
        );
        let Some(cell) = plan.cell_at(aim) else {
            continue;
        };
        let target = plan.centre(cell);
        if target != here
            && !plan.blocked[cell.1 * plan.map.grid.cols + cell.0]
            && plan.segment_clear(here, target)
        {
            return Some(target);
        }
    }
    None
}

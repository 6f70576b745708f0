//! The simulator: a 2-D world with Player/Stage semantics (`reference/algorithms.md` §2).
//!
//! One [`World::step`] advances simulated time by `dt_s` (no wall clock anywhere):
//! 1. commands given to the step replace the robots' latched commands (a command stays in force
//!    until replaced, as in Stage's velocity mode), clamped to the velocity limits;
//! 2. each robot's velocity follows its command (at once, or within the acceleration limits if
//!    set);
//! 3. robots move **in id order** (the agent first), each against the others' poses as they
//!    stand at that moment: the new pose is the exact unicycle arc for (v, ω) over `dt_s`; if the
//!    footprint there would overlap an occupied cell, the space outside the map, or another
//!    robot, the move is not made at all and the robot is *stalled* for the step (Stage: whole
//!    step undone, command kept, so a robot pushing against a wall stays stalled step after step);
//!    a robot with zero velocity does not move and keeps its stall flag, as in Stage;
//! 4. time advances.
//!
//! Deviation from Stage, deliberate: Stage integrates with explicit Euler (translation along
//! the heading at the start of the step); sitgen integrates the unicycle exactly, so a constant
//! (v, ω) drives a circle of radius v/ω. The two differ by O(dt²) per step.
//!
//! Sensing is on demand ([`World::observe`]) and reads the poses at the end of the last step,
//! which is what Stage's sensors see at the start of the next one.

pub mod collision;
pub mod laser;

use std::sync::{Arc, Mutex};

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::error::{join, SpecError};
use crate::geometry::Body;
use crate::grid::Map;
use crate::rng::{stream, ChoiceSource};
use crate::situation::{Pose, Role, Situation};

use collision::Rect;
use laser::{ray_to_rect, LaserSpec, RayGrid, ScanStart};

/// Simulator settings.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct SimSpec {
    /// Simulated time per step, seconds, in (0, 10]. Default 0.1 (Stage's `interval_sim`).
    #[serde(default = "default_dt_s")]
    pub dt_s: f64,
    /// Largest speed forward or backward, m/s, in (0, 100]. Default 0.8 (Pioneer 3-AT).
    #[serde(default = "default_max_speed")]
    pub max_speed_m_s: f64,
    /// Largest turn rate, degrees per second, in (0, 3600]. Default 90.
    #[serde(default = "default_max_turn")]
    pub max_turn_rate_deg_s: f64,
    /// Largest change of speed, m/s², in (0, 1000]; none by default (Stage's velocity mode).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_accel_m_s2: Option<f64>,
    /// Largest change of turn rate, degrees/s², in (0, 36000]; none by default.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_turn_accel_deg_s2: Option<f64>,
    /// The laser: the agent's, and that of every peer whose controller senses (`vo`, `dwa`,
    /// `snd`, `snd_follow`).
    #[serde(default)]
    pub laser: LaserSpec,
}

fn default_dt_s() -> f64 {
    0.1
}
fn default_max_speed() -> f64 {
    0.8
}
fn default_max_turn() -> f64 {
    90.0
}

impl Default for SimSpec {
    fn default() -> Self {
        Self {
            dt_s: default_dt_s(),
            max_speed_m_s: default_max_speed(),
            max_turn_rate_deg_s: default_max_turn(),
            max_accel_m_s2: None,
            max_turn_accel_deg_s2: None,
            laser: LaserSpec::default(),
        }
    }
}

impl SimSpec {
    /// Check every range; `path` names the section in errors.
    pub fn validate(&self, path: &str) -> Result<(), SpecError> {
        SpecError::check_positive(&join(path, "dt_s"), self.dt_s, 10.0)?;
        SpecError::check_positive(&join(path, "max_speed_m_s"), self.max_speed_m_s, 100.0)?;
        SpecError::check_positive(
            &join(path, "max_turn_rate_deg_s"),
            self.max_turn_rate_deg_s,
            3600.0,
        )?;
        if let Some(a) = self.max_accel_m_s2 {
            SpecError::check_positive(&join(path, "max_accel_m_s2"), a, 1000.0)?;
        }
        if let Some(a) = self.max_turn_accel_deg_s2 {
            SpecError::check_positive(&join(path, "max_turn_accel_deg_s2"), a, 36_000.0)?;
        }
        self.laser.validate(&join(path, "laser"))
    }
}

/// What a robot is in contact with after a blocked move.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Contact {
    /// An occupied cell or the edge of the map.
    Wall,
    /// Robot with this id.
    Robot(u32),
}

/// The state of one robot, readable after every step.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RobotState {
    /// Id, as in the situation.
    pub id: u32,
    /// Agent or peer.
    pub role: Role,
    /// Footprint.
    pub body: Body,
    /// Pose of the rotation centre.
    pub pose: Pose,
    /// Latched command (v m/s, ω rad/s), after clamping.
    pub command: (f64, f64),
    /// Current velocity (v m/s, ω rad/s).
    pub velocity: (f64, f64),
    /// Whether the last move was blocked.
    pub stalled: bool,
    /// What blocked the last blocked move (empty when not stalled).
    pub contacts: Vec<Contact>,
}

impl RobotState {
    /// This robot as another robot's perception tracks it: position and world-frame velocity.
    pub fn track(&self) -> Track {
        let (s, c) = self.pose.heading_rad.sin_cos();
        Track {
            id: self.id,
            position: (self.pose.x_m, self.pose.y_m),
            velocity: (self.velocity.0 * c, self.velocity.0 * s),
        }
    }

    /// The footprint at `pose`.
    pub fn footprint_at(&self, pose: &Pose) -> Rect {
        footprint(&self.body, pose)
    }

    /// The footprint now.
    pub fn footprint(&self) -> Rect {
        self.footprint_at(&self.pose)
    }
}

/// Another robot as a perception module would report it: what the laser sees right now.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Track {
    /// Its id.
    pub id: u32,
    /// Position of its rotation centre (x, y), metres.
    pub position: (f64, f64),
    /// Its velocity in the world frame (vx, vy), m/s.
    pub velocity: (f64, f64),
}

/// What a robot senses.
#[derive(Debug, Clone, PartialEq)]
pub struct Observation {
    /// Laser ranges, metres, one per beam (empty for robots without a laser).
    pub ranges: Vec<f64>,
    /// Beam bearings relative to the heading, radians.
    pub angles: Vec<f64>,
    /// The laser's maximum range, metres: a reading of this much is no return (Player's laser
    /// data carries it, and SND reads it from there).
    pub max_range_m: f64,
    /// Own pose.
    pub pose: Pose,
    /// Own velocity (v, ω).
    pub velocity: (f64, f64),
    /// Whether the last move was blocked.
    pub stalled: bool,
    /// Simulated time, seconds.
    pub time_s: f64,
    /// The other robots that at least one beam hits first, in id order (empty without a laser).
    pub tracks: Vec<Track>,
}

/// A running world.
#[derive(Debug, Clone)]
pub struct World {
    spec: SimSpec,
    /// The terrain never changes during a run: a copy of the world (a branch,
    /// [`crate::run::Branch`]) shares it.
    map: Arc<Map>,
    /// Distance, metres, from each cell centre to the nearest occupied cell centre: a footprint
    /// whose enclosing circle is nearer than this (less half a cell diagonal) to nothing cannot
    /// touch the grid, which settles most moves without testing cells.
    clearance_m: Arc<Vec<f32>>,
    /// The grid as laser rays see it, with how far they may leap from each cell.
    rays: Arc<RayGrid>,
    robots: Vec<RobotState>,
    /// Which robots carry the laser: the agent always, a peer when its controller senses.
    lasers: Vec<bool>,
    bearings: Vec<f64>,
    /// Half the diagonal of each robot's footprint: the radius of the circle about its centre
    /// that encloses it.
    half_diagonals: Vec<f64>,
    /// (cos, sin) of each bearing: a beam's direction is the heading's rotation of these, which
    /// spares a sine and a cosine per beam per scan.
    bearing_dirs: Vec<(f64, f64)>,
    /// The terrain part of each robot's last scan, by robot index: a robot standing still (a
    /// controller locked up, a robot stalled against a wall) sees the same walls, since the
    /// terrain never changes, so only the robots are traced again.
    wall_scans: WallScans,
    time_s: f64,
    steps: u64,
    seed: u64,
}

/// What a caller of [`World::wall_clearance_at`] that asks it of pose after pose knows: the
/// map's [`World::edge_cells_before`], and an upper bound on the clearance (the last pose's
/// clearance plus how far any point of the footprint has moved since), if it has one.
#[derive(Debug, Clone, Copy)]
pub struct Aid<'a> {
    /// [`World::edge_cells_before`].
    pub edge_cells_before: &'a [u32],
    /// The clearance is at most this, metres.
    pub at_most_m: Option<f64>,
}

/// Each robot's last [`WallScan`], by robot index (a lock, uncontended, so that a world can be
/// shared with threads that only read it).
#[derive(Debug)]
struct WallScans(Mutex<Vec<Option<WallScan>>>);

impl WallScans {
    fn lock(&self) -> std::sync::MutexGuard<'_, Vec<Option<WallScan>>> {
        // A panic elsewhere cannot leave a half-written entry: entries are replaced whole.
        self.0.lock().unwrap_or_else(|e| e.into_inner())
    }
}

impl Clone for WallScans {
    fn clone(&self) -> Self {
        Self(Mutex::new(self.lock().clone()))
    }
}

/// Ranges to the terrain alone, beam by beam, from one exact pose.
#[derive(Debug, Clone)]
struct WallScan {
    pose: (u64, u64, u64),
    ranges: Vec<f64>,
}

impl WallScan {
    /// A pose as a cache key: its exact bits.
    fn key(pose: &Pose) -> (u64, u64, u64) {
        (
            pose.x_m.to_bits(),
            pose.y_m.to_bits(),
            pose.heading_rad.to_bits(),
        )
    }
}

/// Unicycle motion over `dt` from `pose` at constant (v, ω), exactly.
pub fn integrate(pose: &Pose, v: f64, w: f64, dt: f64) -> Pose {
    let a = pose.heading_rad;
    let (x, y, heading) = if w.abs() < 1e-12 {
        (pose.x_m + v * dt * a.cos(), pose.y_m + v * dt * a.sin(), a)
    } else {
        let b = a + w * dt;
        let r = v / w;
        (
            pose.x_m + r * (b.sin() - a.sin()),
            pose.y_m - r * (b.cos() - a.cos()),
            b,
        )
    };
    Pose {
        x_m: x,
        y_m: y,
        heading_rad: wrap_angle(heading),
    }
}

/// The footprint of `body` at `pose`.
pub fn footprint(body: &Body, pose: &Pose) -> Rect {
    let (s, c) = pose.heading_rad.sin_cos();
    Rect {
        centre: (
            pose.x_m + c * body.origin_x_m,
            pose.y_m + s * body.origin_x_m,
        ),
        u: (c, s),
        half_length: body.length_m / 2.0,
        half_width: body.width_m / 2.0,
    }
}

/// An angle in (−π, π].
pub fn wrap_angle(a: f64) -> f64 {
    let wrapped = a.rem_euclid(std::f64::consts::TAU);
    if wrapped > std::f64::consts::PI {
        wrapped - std::f64::consts::TAU
    } else {
        wrapped
    }
}

fn limit(value: f64, previous: f64, max_change: Option<f64>) -> f64 {
    match max_change {
        Some(m) => value.clamp(previous - m, previous + m),
        None => value,
    }
}

/// Check where the robots of `situation` start ([`World::check_start`]).
pub fn check_start(situation: &Situation) -> Result<(), SpecError> {
    World::new(situation, SimSpec::default(), 0)?.check_start()
}

impl World {
    /// A world at the start of `situation`, with sensor noise drawn from `seed`.
    pub fn new(situation: &Situation, spec: SimSpec, seed: u64) -> Result<Self, SpecError> {
        spec.validate("sim")?;
        let map = situation.map.decode()?;
        let g = &map.grid;
        let to_occupied = crate::grid::distance::squared_distance_to(&g.cells, g.rows, g.cols);
        Ok(Self::assemble(situation, map, &to_occupied, spec, seed))
    }

    /// [`World::new`] for a situation whose map is given decoded, with its squared distances
    /// to its occupied cells ([`crate::situation::generate_with_distances`] returns both):
    /// the same world, less a decode and a distance transform.
    pub fn with_distances(
        situation: &Situation,
        map: Map,
        to_occupied: &[f64],
        spec: SimSpec,
        seed: u64,
    ) -> Result<Self, SpecError> {
        spec.validate("sim")?;
        let m = &situation.map;
        if (map.grid.rows, map.grid.cols, map.resolution_m) != (m.rows, m.cols, m.resolution_m)
            || to_occupied.len() != m.rows * m.cols
        {
            return Err(SpecError::new(
                "map",
                "the decoded map and its distances are not the situation's map",
            ));
        }
        Ok(Self::assemble(situation, map, to_occupied, spec, seed))
    }

    /// The world at the start of `situation` on its decoded `map`; `spec` is checked.
    fn assemble(
        situation: &Situation,
        map: Map,
        to_occupied: &[f64],
        spec: SimSpec,
        seed: u64,
    ) -> Self {
        let clearance_m = to_occupied
            .iter()
            .map(|d2| (d2.sqrt() * map.resolution_m) as f32)
            .collect::<Vec<_>>();
        let rays = RayGrid::new(&map, Some(&clearance_m));
        let robots = situation
            .robots
            .iter()
            .map(|r| RobotState {
                id: r.id,
                role: r.role,
                body: r.body.clone(),
                pose: r.start,
                command: (0.0, 0.0),
                velocity: (0.0, 0.0),
                stalled: false,
                contacts: Vec::new(),
            })
            .collect();
        let half_diagonals = situation
            .robots
            .iter()
            .map(|r| (r.body.length_m / 2.0).hypot(r.body.width_m / 2.0))
            .collect();
        let bearings = spec.laser.bearings();
        let bearing_dirs = bearings.iter().map(|b| (b.cos(), b.sin())).collect();
        let lasers = situation
            .robots
            .iter()
            .map(|r| r.role == Role::Agent)
            .collect();
        Self {
            spec,
            map: Arc::new(map),
            clearance_m: Arc::new(clearance_m),
            rays: Arc::new(rays),
            robots,
            lasers,
            bearings,
            half_diagonals,
            bearing_dirs,
            wall_scans: WallScans(Mutex::new(vec![None; situation.robots.len()])),
            time_s: 0.0,
            steps: 0,
            seed,
        }
    }

    /// Simulated time, seconds.
    pub fn time_s(&self) -> f64 {
        self.time_s
    }

    /// The seed sensor noise is drawn from.
    pub fn seed(&self) -> u64 {
        self.seed
    }

    /// Steps taken.
    pub fn steps(&self) -> u64 {
        self.steps
    }

    /// Every robot's state.
    pub fn robots(&self) -> &[RobotState] {
        &self.robots
    }

    /// The map.
    pub fn map(&self) -> &Map {
        &self.map
    }

    /// The settings.
    pub fn spec(&self) -> &SimSpec {
        &self.spec
    }

    /// Advance one step; `commands` are (robot id, v m/s, ω rad/s) and replace the robots'
    /// latched commands. An unknown id is an error and changes nothing.
    pub fn step(&mut self, commands: &[(u32, f64, f64)]) -> Result<(), String> {
        if let Some(&(id, ..)) = commands.iter().find(|c| c.0 as usize >= self.robots.len()) {
            return Err(format!(
                "no robot {id}: the world has {}",
                self.robots.len()
            ));
        }
        if let Some(&(id, v, w)) = commands
            .iter()
            .find(|c| !c.1.is_finite() || !c.2.is_finite())
        {
            return Err(format!("robot {id}: command ({v}, {w}) is not finite"));
        }
        let vmax = self.spec.max_speed_m_s;
        let wmax = self.spec.max_turn_rate_deg_s.to_radians();
        for &(id, v, w) in commands {
            self.robots[id as usize].command = (v.clamp(-vmax, vmax), w.clamp(-wmax, wmax));
        }
        let dt = self.spec.dt_s;
        let dv = self.spec.max_accel_m_s2.map(|a| a * dt);
        let dw = self.spec.max_turn_accel_deg_s2.map(|a| a.to_radians() * dt);
        // Every robot's footprint, kept as robots move in turn: each move is tested against
        // the others where they stand by then.
        let mut footprints: Vec<Rect> = self.robots.iter().map(RobotState::footprint).collect();
        for i in 0..self.robots.len() {
            let r = &mut self.robots[i];
            r.velocity = (
                limit(r.command.0, r.velocity.0, dv),
                limit(r.command.1, r.velocity.1, dw),
            );
            if r.velocity == (0.0, 0.0) {
                continue;
            }
            let next = integrate(&r.pose, r.velocity.0, r.velocity.1, dt);
            let rect = r.footprint_at(&next);
            let contacts = self.contacts_of(i, &rect, &next, &footprints);
            let r = &mut self.robots[i];
            if contacts.is_empty() {
                footprints[i] = rect;
                r.pose = next;
                r.stalled = false;
                r.contacts.clear();
            } else {
                r.stalled = true;
                r.contacts = contacts;
            }
        }
        self.time_s = (self.steps + 1) as f64 * dt;
        self.steps += 1;
        Ok(())
    }

    /// Check that every robot starts where the simulator lets it stand: a finite pose, its
    /// footprint inside the map, clear of every occupied cell and of every other robot. A
    /// robot that starts in contact would "collide" on the first step, a failure that is the
    /// situation's, not the controller's; the error names the robot.
    pub fn check_start(&self) -> Result<(), SpecError> {
        for (i, r) in self.robots.iter().enumerate() {
            let path = format!("robots[{i}].start");
            let p = &r.pose;
            if !(p.x_m.is_finite() && p.y_m.is_finite() && p.heading_rad.is_finite()) {
                return Err(SpecError::new(path, "is not a finite pose"));
            }
            let contacts = self.contacts_at(i, p);
            let what = match contacts.first() {
                None => continue,
                Some(Contact::Wall) => {
                    let (x0, y0, x1, y1) = r.footprint().bounds();
                    let (w, h) = (self.map.width_m(), self.map.height_m());
                    if x0 < 0.0 || y0 < 0.0 || x1 > w || y1 > h {
                        format!("its footprint leaves the map, (0, 0) to ({w}, {h}) m")
                    } else {
                        "its footprint overlaps an obstacle".to_string()
                    }
                }
                Some(Contact::Robot(j)) => format!("its footprint overlaps robot {j}'s"),
            };
            return Err(SpecError::new(
                path,
                format!("({:?}, {:?}): {what}", p.x_m, p.y_m),
            ));
        }
        Ok(())
    }

    /// Put robot `i` at `pose` before the first step, if it can stand there (inside the map,
    /// clear of obstacles and of every other robot where it stands now); whether it moved.
    /// Perturbed copies of a run ([`crate::run::perturb`]) start this way.
    pub fn place_at_start(&mut self, i: usize, pose: Pose) -> bool {
        assert_eq!(self.steps, 0, "a robot is placed before the first step");
        let finite = pose.x_m.is_finite() && pose.y_m.is_finite() && pose.heading_rad.is_finite();
        if !finite || !self.contacts_at(i, &pose).is_empty() {
            return false;
        }
        self.robots[i].pose = pose;
        true
    }

    /// What robot `i` would overlap at `pose`: the grid (or the map's edge) and other robots.
    fn contacts_at(&self, i: usize, pose: &Pose) -> Vec<Contact> {
        let footprints: Vec<Rect> = self.robots.iter().map(RobotState::footprint).collect();
        self.contacts_of(i, &self.robots[i].footprint_at(pose), pose, &footprints)
    }

    /// [`World::contacts_at`] for robot `i`'s footprint `rect` at `pose`, given every robot's
    /// footprint now.
    fn contacts_of(&self, i: usize, rect: &Rect, pose: &Pose, footprints: &[Rect]) -> Vec<Contact> {
        let me = &self.robots[i];
        let mut contacts = Vec::new();
        if self.overlaps_grid(rect, pose, me.body.enclosing_radius()) {
            contacts.push(Contact::Wall);
        }
        for (j, (other, theirs)) in self.robots.iter().zip(footprints).enumerate() {
            // Rectangles whose enclosing circles are clearly apart cannot overlap.
            let apart = (self.half_diagonals[i] + self.half_diagonals[j]) * (1.0 + 1e-9);
            let (dx, dy) = (
                theirs.centre.0 - rect.centre.0,
                theirs.centre.1 - rect.centre.1,
            );
            if j != i && dx * dx + dy * dy <= apart * apart && rect.overlaps(theirs) {
                contacts.push(Contact::Robot(other.id));
            }
        }
        contacts
    }

    /// Whether `rect` overlaps an occupied cell or leaves the map.
    fn overlaps_grid(&self, rect: &Rect, pose: &Pose, enclosing: f64) -> bool {
        let g = &self.map.grid;
        let res = self.map.resolution_m;
        let (x0, y0, x1, y1) = rect.bounds();
        if x0 < 0.0 || y0 < 0.0 || x1 > g.cols as f64 * res || y1 > g.rows as f64 * res {
            return true;
        }
        // Fast path: the enclosing circle is clear of every occupied cell's square.
        let c = (pose.x_m / res) as usize;
        let r_from_bottom = (pose.y_m / res) as usize;
        if c < g.cols && r_from_bottom < g.rows {
            let row = g.rows - 1 - r_from_bottom;
            let clear = f64::from(self.clearance_m[row * g.cols + c]);
            // Pose to its cell centre is at most half a diagonal; a cell's square reaches half a
            // diagonal beyond its centre.
            if clear - res * std::f64::consts::SQRT_2 > enclosing {
                return false;
            }
        }
        let (c0, c1) = (
            (x0 / res).floor() as usize,
            ((x1 / res).ceil() as usize).min(g.cols),
        );
        let (w0, w1) = (
            (y0 / res).floor() as usize,
            ((y1 / res).ceil() as usize).min(g.rows),
        );
        for w in w0..w1 {
            let row = g.rows - 1 - w;
            for c in c0..c1 {
                if g.cells[row * g.cols + c]
                    && rect.overlaps_square(c as f64 * res, w as f64 * res, res)
                {
                    return true;
                }
            }
        }
        false
    }

    /// Clearance from robot `i`'s footprint to the nearest occupied cell or the map's edge,
    /// metres (0 in contact), if there is one within `within_m`; the monitor names the nearest
    /// party of an event with it. Exact: every occupied cell near the footprint is a square
    /// measured against the rectangle; the distance field skips robots in the open.
    pub fn wall_clearance(&self, i: usize, within_m: f64) -> Option<f64> {
        let r = &self.robots[i];
        self.wall_clearance_at(&r.body, &r.pose, within_m, None)
    }

    /// Each row's count of edge cells before each column, `cols + 1` a row, top row first: an
    /// edge cell is an occupied cell with a free cell (or nothing) beside it, the only cells a
    /// footprint outside the walls can be nearest to (one overlapping the walls overlaps an
    /// edge cell: a robot never lies wholly inside them). What lets
    /// [`World::wall_clearance_at`] skip a row's stretch without one, and an inner cell.
    pub fn edge_cells_before(&self) -> Vec<u32> {
        let g = &self.map.grid;
        let occupied = |r: usize, c: usize| g.cells[r * g.cols + c];
        let mut out = Vec::with_capacity(g.rows * (g.cols + 1));
        for r in 0..g.rows {
            let mut n = 0u32;
            out.push(0);
            for c in 0..g.cols {
                let edge = occupied(r, c)
                    && (r == 0
                        || c == 0
                        || r + 1 == g.rows
                        || c + 1 == g.cols
                        || !occupied(r - 1, c)
                        || !occupied(r + 1, c)
                        || !occupied(r, c - 1)
                        || !occupied(r, c + 1));
                n += u32::from(edge);
                out.push(n);
            }
        }
        out
    }

    /// [`World::wall_clearance`] of a robot of `body` at `pose` (the requirement signal
    /// `obstacle_clearance` asks it of every recorded pose, with an [`Aid`]: the same value,
    /// found looking at fewer cells).
    pub fn wall_clearance_at(
        &self,
        body: &Body,
        pose: &Pose,
        within_m: f64,
        aid: Option<Aid<'_>>,
    ) -> Option<f64> {
        let rect = footprint(body, pose);
        let g = &self.map.grid;
        let res = self.map.resolution_m;
        let (w, h) = (g.cols as f64 * res, g.rows as f64 * res);
        let (x0, y0, x1, y1) = rect.bounds();
        let mut best = x0.min(y0).min(w - x1).min(h - y1).max(0.0);
        // No cell beyond the caller's bound can be the nearest (the margin keeps a cell at
        // exactly the bound).
        let bound = aid
            .and_then(|a| a.at_most_m)
            .map_or(f64::INFINITY, |b| b + 1e-6);
        let mut edge_cells_before = aid.map(|a| a.edge_cells_before);
        let mut reach = within_m.min(best).min(bound);
        let c = (pose.x_m / res) as usize;
        let from_bottom = (pose.y_m / res) as usize;
        if c < g.cols && from_bottom < g.rows {
            let clear = f64::from(self.clearance_m[(g.rows - 1 - from_bottom) * g.cols + c]);
            if clear - res * std::f64::consts::SQRT_2 > body.enclosing_radius() + within_m {
                return (best <= within_m).then_some(best);
            }
            // The pose lies inside the footprint, within half a cell diagonal of its cell's
            // centre: no cell nearer the footprint can lie farther out than this.
            reach = reach.min(clear + res);
            if clear == 0.0 {
                // A footprint about an occupied cell may lie wholly inside the walls, beside
                // no edge cell: every occupied cell is looked at.
                edge_cells_before = None;
            }
        }
        let cells = |lo: f64, hi: f64, n: usize| {
            (
                ((lo - reach) / res).floor().max(0.0) as usize,
                (((hi + reach) / res).ceil().max(0.0) as usize).min(n),
            )
        };
        let (c0, c1) = cells(x0, x1, g.cols);
        let (w0, w1) = cells(y0, y1, g.rows);
        for wr in w0..w1 {
            let row = g.rows - 1 - wr;
            let at = row * (g.cols + 1);
            if edge_cells_before.is_some_and(|before| before[at + c1] == before[at + c0]) {
                continue;
            }
            for col in c0..c1 {
                let looked_at = match edge_cells_before {
                    Some(before) => before[at + col + 1] != before[at + col],
                    None => g.cells[row * g.cols + col],
                };
                if !looked_at {
                    continue;
                }
                let centre = ((col as f64 + 0.5) * res, (wr as f64 + 0.5) * res);
                // The cell's centre is at most half a diagonal from its nearest point: skip
                // cells that cannot beat the best without the exact test.
                let half_diagonal = res * std::f64::consts::FRAC_1_SQRT_2;
                let (along, across) = rect.point_offsets(centre);
                let beat = best.min(bound);
                let cannot_beat = crate::geometry::beyond_by_squares(
                    along * along + across * across,
                    (beat + half_diagonal).powi(2),
                    || rect.point_distance(centre) - half_diagonal >= beat,
                );
                if cannot_beat {
                    continue;
                }
                let cell = Rect {
                    centre,
                    u: (1.0, 0.0),
                    half_length: res / 2.0,
                    half_width: res / 2.0,
                };
                best = best.min(rect.distance(&cell));
            }
        }
        (best <= within_m).then_some(best)
    }

    /// Distance from `origin` along the unit direction `dir` to the first occupied cell or the
    /// map's edge, at most `max`, ignoring robots: the terrain as seen from a point (the
    /// coverage observer's terrain context). 0 from outside the map.
    pub fn wall_range(&self, origin: (f64, f64), dir: (f64, f64), max: f64) -> f64 {
        let (w, h) = (self.map.width_m(), self.map.height_m());
        if !(0.0..=w).contains(&origin.0) || !(0.0..=h).contains(&origin.1) {
            return 0.0;
        }
        // Where the ray leaves the map: the edge is a wall to a robot, not open ground.
        let leave = |o: f64, d: f64, size: f64| match d {
            d if d > 0.0 => (size - o) / d,
            d if d < 0.0 => -o / d,
            _ => f64::INFINITY,
        };
        let edge = leave(origin.0, dir.0, w).min(leave(origin.1, dir.1, h));
        self.rays.ray(origin, dir, max.min(edge))
    }

    /// Put the world where another simulator's step `steps` left it (a replay of its log):
    /// each robot's pose, velocity and stall flag, in id order. A stalled robot's contacts are
    /// what its refused move would overlap here, probing up to three steps' travel along it,
    /// since the other simulator's geometry (Stage's 2 cm raster) may refuse a move a little
    /// before sitgen's exact shapes touch; the map's edge or a wall if nothing is found.
    pub fn replay(
        &mut self,
        steps: u64,
        states: &[(Pose, (f64, f64), bool)],
    ) -> Result<(), String> {
        if states.len() != self.robots.len() {
            return Err(format!(
                "{} robots in the step, but the world has {}",
                states.len(),
                self.robots.len()
            ));
        }
        for (r, &(pose, velocity, stalled)) in self.robots.iter_mut().zip(states) {
            r.pose = pose;
            r.velocity = velocity;
            r.command = velocity;
            r.stalled = stalled;
        }
        let dt = self.spec.dt_s;
        for i in 0..self.robots.len() {
            let r = &self.robots[i];
            if !r.stalled {
                self.robots[i].contacts.clear();
                continue;
            }
            let (pose, (v, w)) = (r.pose, r.velocity);
            let contacts = (1..=3)
                .map(|k| self.contacts_at(i, &integrate(&pose, v, w, k as f64 * dt)))
                .find(|c| !c.is_empty())
                .unwrap_or_else(|| vec![Contact::Wall]);
            self.robots[i].contacts = contacts;
        }
        self.steps = steps;
        self.time_s = steps as f64 * dt;
        Ok(())
    }

    /// Mount the laser on robot `id` too (a peer whose controller senses; the agent always
    /// carries one).
    pub fn fit_laser(&mut self, id: u32) -> Result<(), String> {
        let n = self.robots.len();
        let laser = self
            .lasers
            .get_mut(id as usize)
            .ok_or_else(|| format!("no robot {id}: the world has {n}"))?;
        *laser = true;
        Ok(())
    }

    /// Whether robot `id` carries the laser.
    pub fn has_laser(&self, id: u32) -> bool {
        self.lasers.get(id as usize).copied().unwrap_or(false)
    }

    /// What robot `id` senses now: its pose, velocity and stall flag, and, if it carries the
    /// laser, a scan and the robots the scan sees.
    pub fn observe(&self, id: u32) -> Result<Observation, String> {
        let r = self
            .robots
            .get(id as usize)
            .ok_or_else(|| format!("no robot {id}: the world has {}", self.robots.len()))?;
        let (ranges, angles, tracks) = if self.lasers[id as usize] {
            let (ranges, seen) = self.scan_seeing(id as usize);
            let tracks = self
                .robots
                .iter()
                .filter(|o| seen.contains(&o.id))
                .map(RobotState::track)
                .collect();
            (ranges, self.bearings.clone(), tracks)
        } else {
            (Vec::new(), Vec::new(), Vec::new())
        };
        Ok(Observation {
            ranges,
            angles,
            max_range_m: self.spec.laser.range_m,
            pose: r.pose,
            velocity: r.velocity,
            stalled: r.stalled,
            time_s: self.time_s,
            tracks,
        })
    }

    /// Every robot but `id` as it truly is now (the exact perception's tracks, in id order),
    /// whether or not a laser would see it.
    pub fn true_tracks(&self, id: u32) -> Vec<Track> {
        self.robots
            .iter()
            .filter(|o| o.id != id)
            .map(RobotState::track)
            .collect()
    }

    /// One laser scan of robot `i` from its current pose.
    pub fn scan(&self, i: usize) -> Vec<f64> {
        self.scan_seeing(i).0
    }

    /// Forget every robot's last scan of the terrain, so that the next scan traces every beam
    /// (the laser benchmark measures tracing, not the reuse).
    pub fn forget_scans(&self) {
        self.wall_scans.lock().fill(None);
    }

    /// Robot `i`'s laser where it stands: the sensor's position and each beam's unit
    /// direction (the heading's rotation of [`World::bearing_dirs`]).
    fn beams_of(&self, i: usize) -> ((f64, f64), Vec<(f64, f64)>) {
        let offset = self.spec.laser.offset_x_m;
        let pose = &self.robots[i].pose;
        let (s, c) = pose.heading_rad.sin_cos();
        let origin = (pose.x_m + c * offset, pose.y_m + s * offset);
        let dirs = self
            .bearing_dirs
            .iter()
            .map(|&(cb, sb)| (c * cb - s * sb, s * cb + c * sb))
            .collect();
        (origin, dirs)
    }

    /// One laser scan, and the ids of the robots that some beam hits first.
    pub fn scan_seeing(&self, i: usize) -> (Vec<f64>, Vec<u32>) {
        let laser = &self.spec.laser;
        let me = &self.robots[i];
        let (origin, dirs) = self.beams_of(i);
        let mut ranges = self.wall_scan(i, origin, &dirs);
        // The robot each beam hits first, if one is nearer than the terrain.
        let mut hits: Vec<Option<u32>> = vec![None; dirs.len()];
        for (j, other) in self.robots.iter().enumerate() {
            if j == i {
                continue;
            }
            let rect = other.footprint();
            // The robot's enclosing circle relative to the sensor settles most beams before
            // the exact slab test; only beams within its angular window are looked at.
            let to = (rect.centre.0 - origin.0, rect.centre.1 - origin.1);
            let radius = self.half_diagonals[j];
            for k in self.beams_toward(to, radius, me.pose.heading_rad) {
                let (dir, t) = (dirs[k], &mut ranges[k]);
                let along = to.0 * dir.0 + to.1 * dir.1;
                let across = to.0 * dir.1 - to.1 * dir.0;
                if across.abs() > radius || along + radius < 0.0 || along - radius > *t {
                    continue;
                }
                if let Some(hit) = ray_to_rect(&rect, origin, dir, *t) {
                    *t = hit;
                    hits[k] = Some(other.id);
                }
            }
        }
        let mut seen = Vec::new();
        for id in hits.into_iter().flatten() {
            if !seen.contains(&id) {
                seen.push(id);
            }
        }
        // Noise is drawn from a stream keyed by (seed, step, robot), so observing twice gives
        // the same scan and the thread count never matters.
        let mut noise = (laser.noise_sd_m > 0.0).then(|| {
            ChoiceSource::stream(
                self.seed ^ self.steps.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ (i as u64) << 56,
                stream::SENSOR_NOISE,
            )
        });
        for t in &mut ranges {
            if let (Some(noise), true) = (noise.as_mut(), *t < laser.range_m) {
                *t = (*t + laser.noise_sd_m * noise.normal()).clamp(0.0, laser.range_m);
            }
            *t = laser.quantise(*t);
        }
        (ranges, seen)
    }

    /// The beams (indices) that may pass within `radius` of the point `to` (relative to the
    /// sensor) ahead of the sensor, for a sensor heading `heading`: a superset, widened by a
    /// beam either side; every beam when the point is within √2·`radius`, where a beam may
    /// pass that near while heading away.
    fn beams_toward(&self, to: (f64, f64), radius: f64, heading: f64) -> BeamWindow {
        let n = self.bearings.len();
        let distance = to.0.hypot(to.1);
        if n < 2 || distance <= std::f64::consts::SQRT_2 * radius * (1.0 + 1e-9) {
            return BeamWindow::all(n);
        }
        // Beam k's bearing is first + k·step (Stage's geometry, see `LaserSpec::bearings`).
        let first = self.bearings[0];
        let step = (self.bearings[n - 1] - first) / (n - 1) as f64;
        let half = (radius / distance).asin() + 1e-6;
        let centre = wrap_angle(to.1.atan2(to.0) - heading);
        let mut window = BeamWindow::default();
        for turn in [-std::f64::consts::TAU, 0.0, std::f64::consts::TAU] {
            let lo = ((centre + turn - half - first) / step).floor() - 1.0;
            let hi = ((centre + turn + half - first) / step).ceil() + 1.0;
            if hi < 0.0 || lo > (n - 1) as f64 {
                continue;
            }
            window.push(lo.max(0.0) as usize, (hi as usize).min(n - 1));
        }
        window
    }
}

/// Beam indices in up to three inclusive ranges (a window may straddle the wrap of a
/// 360° laser), in increasing order.
#[derive(Debug, Default)]
struct BeamWindow {
    ranges: [(usize, usize); 3],
    len: usize,
}

impl BeamWindow {
    fn all(n: usize) -> Self {
        let mut window = Self::default();
        if n > 0 {
            window.push(0, n - 1);
        }
        window
    }

    fn push(&mut self, lo: usize, hi: usize) {
        // Overlapping ranges (a window wider than the field of view's gap) are merged.
        if self.len > 0 && lo <= self.ranges[self.len - 1].1 + 1 {
            let last = &mut self.ranges[self.len - 1];
            last.1 = last.1.max(hi);
        } else {
            self.ranges[self.len] = (lo, hi);
            self.len += 1;
        }
    }
}

impl IntoIterator for BeamWindow {
    type Item = usize;
    type IntoIter = std::iter::FlatMap<
        std::iter::Take<std::array::IntoIter<(usize, usize), 3>>,
        std::ops::RangeInclusive<usize>,
        fn((usize, usize)) -> std::ops::RangeInclusive<usize>,
    >;

    fn into_iter(self) -> Self::IntoIter {
        self.ranges
            .into_iter()
            .take(self.len)
            .flat_map(|(lo, hi)| lo..=hi)
    }
}

impl World {
    /// Robot `i`'s beams' ranges to the terrain from `origin` in directions `dirs`: the last
    /// ones when it has not moved since (the same bits), else traced afresh.
    fn wall_scan(&self, i: usize, origin: (f64, f64), dirs: &[(f64, f64)]) -> Vec<f64> {
        let key = WallScan::key(&self.robots[i].pose);
        let mut cache = self.wall_scans.lock();
        if let Some(scan) = cache[i].as_ref().filter(|scan| scan.pose == key) {
            return scan.ranges.clone();
        }
        let range = self.spec.laser.range_m;
        let ranges: Vec<f64> = match self.rays.scan_start(origin, range) {
            ScanStart::Every(t) => vec![t; self.bearing_dirs.len()],
            ScanStart::From(t0) => dirs
                .iter()
                .map(|&dir| self.rays.ray_from(t0, origin, dir, range))
                .collect(),
        };
        // The cache's last buffer is reused: a moving robot misses every step.
        match &mut cache[i] {
            Some(scan) => {
                scan.pose = key;
                scan.ranges.clone_from(&ranges);
            }
            slot => {
                *slot = Some(WallScan {
                    pose: key,
                    ranges: ranges.clone(),
                })
            }
        }
        ranges
    }
}

#[cfg(test)]
mod tests;

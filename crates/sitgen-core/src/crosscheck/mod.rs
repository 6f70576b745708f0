//! The cross-check: a situation run by sitgen and by Stage 4.3 (driven by sitgen's own
//! controllers through `integrations/stage/`), compared step by step (`docs/stage.md`).
//!
//! Stage's run comes as the plugin's log, one JSON object per step: every robot's pose,
//! velocity, stall flag, command, and for robots with a laser the scan and the robots it saw.
//! The comparison has four parts:
//! - **divergence**: each robot's position and heading error between the two runs over time;
//! - **stalls**: each robot's first stalled step in each run;
//! - **events**: sitgen's monitor applied to Stage's trajectory ([`Run::replay_step`]), so
//!   both runs' event logs, outcomes, scores and failure classes come from the same monitor;
//! - **scans**: every Stage scan against sitgen's laser cast from the *same* poses (the world
//!   put where Stage's step left it), which isolates the sensor models from the divergence of
//!   the runs, and whether both saw the same robots.

use serde::{Deserialize, Serialize};

use crate::monitor::{Event, EventKind, Party};
use crate::run::{Outcome, Run, RunSpec};
use crate::situation::{Pose, Situation};

/// One robot in one step of the plugin's log (its `command` is for people; the comparison
/// reads what the robot did).
#[derive(Debug, Clone, Deserialize)]
pub struct LogRobot {
    /// Robot id.
    pub id: u32,
    /// x, y (m), heading (rad), after the step.
    pub pose: [f64; 3],
    /// v (m/s), ω (rad/s).
    pub velocity: [f64; 2],
    /// Whether Stage refused the step's move.
    pub stalled: bool,
    /// The scan from the pose after the step (robots with a laser).
    #[serde(default)]
    pub ranges: Option<Vec<f64>>,
    /// Robots that scan saw.
    #[serde(default)]
    pub seen: Vec<u32>,
}

/// One step of the plugin's log; step 0 is the start.
#[derive(Debug, Clone, Deserialize)]
pub struct LogStep {
    /// sitgen's step number.
    pub step: u64,
    /// sitgen's time, seconds.
    pub time: f64,
    /// Every robot, in id order.
    pub robots: Vec<LogRobot>,
}

/// The plugin's log; errors name the line and what was wrong.
pub fn read_log(text: &str, robots: usize) -> Result<Vec<LogStep>, String> {
    let mut steps: Vec<LogStep> = Vec::new();
    for (n, line) in text
        .lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty())
    {
        let at = |why: String| format!("Stage log line {}: {why}", n + 1);
        let s: LogStep = serde_json::from_str(line).map_err(|e| at(e.to_string()))?;
        if s.step != steps.len() as u64 {
            return Err(at(format!("step {}, expected {}", s.step, steps.len())));
        }
        if !s.robots.iter().map(|r| r.id).eq(0..robots as u32) {
            let ids: Vec<u32> = s.robots.iter().map(|r| r.id).collect();
            return Err(at(format!(
                "robots {ids:?}, expected ids 0..{robots} in order"
            )));
        }
        steps.push(s);
    }
    if steps.is_empty() {
        return Err("the Stage log is empty: Stage did not run a step".into());
    }
    Ok(steps)
}

/// One simulator's run as sitgen's monitor sees it.
#[derive(Debug, Clone, Serialize)]
pub struct Side {
    /// `completed` or `timeout`.
    pub outcome: Outcome,
    /// Steps run (to completion or the time limit).
    pub steps: u64,
    /// Score.
    pub score: f64,
    /// Failure class name, if any.
    pub failure: Option<String>,
    /// The event log.
    pub events: Vec<Event>,
    /// Each robot's first stalled step, if any.
    pub first_stall: Vec<Option<u64>>,
}

/// One robot's divergence between the runs.
#[derive(Debug, Clone, Serialize)]
pub struct Divergence {
    /// Robot id.
    pub id: u32,
    /// (time s, position error m, heading error rad) every second while both ran.
    pub series: Vec<(f64, f64, f64)>,
    /// Largest position error, metres.
    pub max_position_m: f64,
    /// First time the position error passed 1 cm, 10 cm and 1 m, seconds.
    pub first_over_s: [Option<f64>; 3],
}

/// Thresholds of [`Divergence::first_over_s`], metres.
pub const DIVERGENCE_THRESHOLDS_M: [f64; 3] = [0.01, 0.1, 1.0];

/// Stage's scans against sitgen's laser from the same poses.
#[derive(Debug, Clone, Default, Serialize)]
pub struct ScanComparison {
    /// Scans compared (the agent's, every step Stage logged).
    pub scans: u64,
    /// Beams compared.
    pub beams: u64,
    /// Beams where both read the maximum range (nothing within range).
    pub both_max: u64,
    /// Beams where Stage hit something and sitgen read the maximum.
    pub stage_only_hit: u64,
    /// Beams where sitgen hit something and Stage read the maximum.
    pub sitgen_only_hit: u64,
    /// Of those, the beams where sitgen's hit is in the last tenth of the range: Stage's ray
    /// walk spends its budget before the true range (`docs/stage.md`).
    pub sitgen_only_hit_near_max: u64,
    /// Of the beams where both hit: the median, 95th percentile and largest |difference|, m.
    pub median_abs_m: f64,
    /// See [`ScanComparison::median_abs_m`].
    pub p95_abs_m: f64,
    /// See [`ScanComparison::median_abs_m`].
    pub max_abs_m: f64,
    /// Of the beams where both hit, the share within 3 cm.
    pub within_3cm: f64,
    /// Scans where both saw the same robots.
    pub same_robots_seen: u64,
    /// (robot, scans) seen only by Stage / only by sitgen.
    pub seen_only_by_stage: Vec<(u32, u64)>,
    /// See [`ScanComparison::seen_only_by_stage`].
    pub seen_only_by_sitgen: Vec<(u32, u64)>,
    /// The first scan: Stage's and sitgen's ranges from the start poses.
    pub first: (Vec<f64>, Vec<f64>),
}

/// Events of one kind for one robot pair that both runs logged, or only one.
#[derive(Debug, Clone, Serialize)]
pub struct EventMatch {
    /// Event kind.
    pub kind: EventKind,
    /// Robot, and the other party as logged.
    pub robot: u32,
    /// Other party (`"wall"`, a robot id, or none).
    pub other: Option<Party>,
    /// Count in sitgen's log.
    pub sitgen: usize,
    /// Count in Stage's log (sitgen's monitor on Stage's trajectory).
    pub stage: usize,
    /// Start of the first in each, seconds.
    pub first_s: (Option<f64>, Option<f64>),
}

/// The whole comparison.
#[derive(Debug, Clone, Serialize)]
pub struct Report {
    /// The situation's content hash.
    pub situation: String,
    /// Largest difference between Stage's logged start poses and the situation's, metres.
    pub start_pose_error_m: f64,
    /// sitgen's run.
    pub sitgen: Side,
    /// Stage's run.
    pub stage: Side,
    /// Per robot.
    pub divergence: Vec<Divergence>,
    /// Per event kind and party.
    pub events: Vec<EventMatch>,
    /// Sensors.
    pub scans: ScanComparison,
}

fn pose_of(p: [f64; 3]) -> Pose {
    Pose {
        x_m: p[0],
        y_m: p[1],
        heading_rad: p[2],
    }
}

fn side(run: Run, first_stall: Vec<Option<u64>>) -> Side {
    let record = run.finish();
    Side {
        outcome: record.outcome,
        steps: record.steps,
        score: record.score.total,
        failure: record.failure.map(|f| f.class.key().to_string()),
        events: record.events,
        first_stall,
    }
}

fn note_stalls(run: &Run, first: &mut [Option<u64>]) {
    let step = run.world().steps();
    for (f, r) in first.iter_mut().zip(run.world().robots()) {
        if r.stalled && f.is_none() {
            *f = Some(step);
        }
    }
}

/// sitgen's own run, with each robot's pose after every step.
fn run_sitgen(situation: &Situation, run: &RunSpec) -> Result<(Side, Vec<Vec<Pose>>), String> {
    let mut r = Run::new(situation, run, 0).map_err(|e| e.to_string())?;
    if r.any_external() {
        return Err("the cross-check runs built-in controllers only".into());
    }
    let mut first = vec![None; situation.robots.len()];
    let mut poses = vec![r.world().robots().iter().map(|s| s.pose).collect()];
    while !r.step(None) {
        note_stalls(&r, &mut first);
        poses.push(r.world().robots().iter().map(|s| s.pose).collect());
    }
    note_stalls(&r, &mut first);
    poses.push(r.world().robots().iter().map(|s| s.pose).collect());
    Ok((side(r, first), poses))
}

fn quantile(sorted: &[f64], q: f64) -> f64 {
    if sorted.is_empty() {
        return 0.0;
    }
    sorted[((sorted.len() - 1) as f64 * q).round() as usize]
}

/// Compare one Stage scan with sitgen's from the same poses.
fn compare_scan(
    cmp: &mut ScanComparison,
    diffs: &mut Vec<f64>,
    stage: (&[f64], &[u32]),
    sitgen: (&[f64], &[u32]),
    max_range: f64,
) {
    cmp.scans += 1;
    // Stage reads its maximum exactly when nothing is hit; sitgen rounds to its range step.
    let open = |r: f64| r >= max_range - 1e-6;
    for (&a, &b) in stage.0.iter().zip(sitgen.0) {
        cmp.beams += 1;
        match (open(a), open(b)) {
            (true, true) => cmp.both_max += 1,
            (false, true) => cmp.stage_only_hit += 1,
            (true, false) => {
                cmp.sitgen_only_hit += 1;
                if b >= 0.9 * max_range {
                    cmp.sitgen_only_hit_near_max += 1;
                }
            }
            (false, false) => diffs.push((a - b).abs()),
        }
    }
    let mut a: Vec<u32> = stage.1.to_vec();
    let mut b: Vec<u32> = sitgen.1.to_vec();
    a.sort_unstable();
    b.sort_unstable();
    if a == b {
        cmp.same_robots_seen += 1;
    }
    let bump = |list: &mut Vec<(u32, u64)>, id: u32| match list.iter_mut().find(|e| e.0 == id) {
        Some(e) => e.1 += 1,
        None => list.push((id, 1)),
    };
    for &id in a.iter().filter(|id| !b.contains(id)) {
        bump(&mut cmp.seen_only_by_stage, id);
    }
    for &id in b.iter().filter(|id| !a.contains(id)) {
        bump(&mut cmp.seen_only_by_sitgen, id);
    }
}

/// Run `situation` under `run` in sitgen and compare it with Stage's log of the same.
pub fn compare(situation: &Situation, run: &RunSpec, log: &[LogStep]) -> Result<Report, String> {
    let n = situation.robots.len();
    let (sitgen, sitgen_poses) = run_sitgen(situation, run)?;
    let mut replay = Run::new(situation, run, 0).map_err(|e| e.to_string())?;
    let agent = replay.agent() as usize;
    let max_range = run.sim.laser.range_m;
    let start_pose_error_m = log[0]
        .robots
        .iter()
        .zip(&situation.robots)
        .map(|(l, r)| (l.pose[0] - r.start.x_m).hypot(l.pose[1] - r.start.y_m))
        .fold(0.0, f64::max);
    let mut scans = ScanComparison::default();
    let mut diffs = Vec::new();
    let mut first_stall = vec![None; n];
    let mut stage_poses: Vec<Vec<Pose>> = Vec::new();
    for (k, entry) in log.iter().enumerate() {
        if k > 0 {
            let states: Vec<_> = entry
                .robots
                .iter()
                .map(|r| (pose_of(r.pose), (r.velocity[0], r.velocity[1]), r.stalled))
                .collect();
            // The monitor's "seen by the agent" for a step is what its scan before it saw.
            let seen = &log[k - 1].robots[agent].seen;
            let ended = replay.replay_step(&states, seen)?;
            note_stalls(&replay, &mut first_stall);
            if ended {
                stage_poses.push(states.iter().map(|s| s.0).collect());
                break;
            }
        }
        stage_poses.push(entry.robots.iter().map(|r| pose_of(r.pose)).collect());
        if let Some(ranges) = &entry.robots[agent].ranges {
            let (ours, seen) = replay.world().scan_seeing(agent);
            if k == 0 {
                scans.first = (ranges.clone(), ours.clone());
            }
            let theirs = &entry.robots[agent].seen;
            compare_scan(
                &mut scans,
                &mut diffs,
                (ranges, theirs),
                (&ours, &seen),
                max_range,
            );
        }
    }
    if !replay.ended() {
        return Err(format!(
            "the Stage log ends at step {} before the run ended (time limit {} s): Stage stopped \
             early",
            log.len() - 1,
            run.time_limit_s
        ));
    }
    diffs.sort_by(f64::total_cmp);
    scans.median_abs_m = quantile(&diffs, 0.5);
    scans.p95_abs_m = quantile(&diffs, 0.95);
    scans.max_abs_m = diffs.last().copied().unwrap_or(0.0);
    scans.within_3cm = if diffs.is_empty() {
        1.0
    } else {
        diffs.iter().filter(|d| **d <= 0.03).count() as f64 / diffs.len() as f64
    };
    let stage = side(replay, first_stall);
    let divergence = (0..n)
        .map(|i| divergence(i as u32, &sitgen_poses, &stage_poses, run.sim.dt_s))
        .collect();
    let events = match_events(&sitgen.events, &stage.events);
    Ok(Report {
        situation: situation.provenance.content_hash.clone(),
        start_pose_error_m,
        sitgen,
        stage,
        divergence,
        events,
        scans,
    })
}

fn divergence(id: u32, a: &[Vec<Pose>], b: &[Vec<Pose>], dt: f64) -> Divergence {
    let i = id as usize;
    let per_second = (1.0 / dt).round().max(1.0) as usize;
    let mut d = Divergence {
        id,
        series: Vec::new(),
        max_position_m: 0.0,
        first_over_s: [None; 3],
    };
    for (k, (p, q)) in a.iter().zip(b).enumerate() {
        let (p, q) = (&p[i], &q[i]);
        let e = (p.x_m - q.x_m).hypot(p.y_m - q.y_m);
        let h = crate::sim::wrap_angle(p.heading_rad - q.heading_rad).abs();
        let t = k as f64 * dt;
        d.max_position_m = d.max_position_m.max(e);
        for (slot, &limit) in d.first_over_s.iter_mut().zip(&DIVERGENCE_THRESHOLDS_M) {
            if slot.is_none() && e > limit {
                *slot = Some(t);
            }
        }
        if k % per_second == 0 {
            d.series.push((t, e, h));
        }
    }
    d
}

fn match_events(sitgen: &[Event], stage: &[Event]) -> Vec<EventMatch> {
    let mut out: Vec<EventMatch> = Vec::new();
    for (which, log) in [(0, sitgen), (1, stage)] {
        for e in log {
            let other = e.other;
            let m = match out
                .iter_mut()
                .find(|m| m.kind == e.kind && m.robot == e.robot && m.other == other)
            {
                Some(m) => m,
                None => {
                    out.push(EventMatch {
                        kind: e.kind,
                        robot: e.robot,
                        other,
                        sitgen: 0,
                        stage: 0,
                        first_s: (None, None),
                    });
                    out.last_mut().expect("just pushed")
                }
            };
            if which == 0 {
                m.sitgen += 1;
                m.first_s.0.get_or_insert(e.start_s);
            } else {
                m.stage += 1;
                m.first_s.1.get_or_insert(e.start_s);
            }
        }
    }
    out
}

#[cfg(test)]
mod tests;

//! Campaign jobs: a situation to generate (or given whole) and how to run it, run one by one
//! or in a batch across threads; a run's trajectory packed for the store.

use super::{run, run_to_end, Run, RunRecord, RunSpec};
use crate::situation::Situation;

/// One run of a campaign: a situation to generate and how to run it.
#[derive(Debug, Clone)]
pub struct Job {
    /// The situation: generated from a spec, or given whole.
    pub situation: JobSituation,
    /// Its master seed (for a spec).
    pub situation_seed: u64,
    /// How to run it.
    pub run: RunSpec,
    /// The run's sensor-noise seed.
    pub run_seed: u64,
}

/// Where a job's situation comes from.
#[derive(Debug, Clone)]
pub enum JobSituation {
    /// Generated from this spec with the job's situation seed.
    Spec(Box<crate::spec::SituationSpec>),
    /// Given whole (a fixed benchmark world, a situation file), already checked.
    Given(Box<Situation>),
}

/// A finished job: the situation generated and the run's record, or why there is none.
pub type JobResult = Result<(Situation, RunRecord), String>;

/// Generate and run one job.
pub fn run_job(job: &Job) -> JobResult {
    // A run checks where the robots start (Run::new), as it does for every situation.
    match &job.situation {
        JobSituation::Spec(spec) => {
            // Generation has the map decoded and its distances to obstacles: the run's world
            // takes them rather than computing them again.
            let (situation, terrain, to_occupied) =
                crate::situation::generate_with_distances(spec, job.situation_seed)
                    .map_err(|e| format!("generation failed: {e}"))?;
            let record = Run::with_distances(
                &situation,
                &job.run,
                job.run_seed,
                terrain.map,
                &to_occupied,
            )
            .and_then(run_to_end)
            .map_err(|e| e.to_string())?;
            Ok((situation, record))
        }
        JobSituation::Given(situation) => {
            let record = run(situation, &job.run, job.run_seed).map_err(|e| e.to_string())?;
            Ok(((**situation).clone(), record))
        }
    }
}

/// Run `jobs` on `threads` threads; results in job order, each independent of the others and
/// of the thread count.
pub fn run_batch(jobs: &[Job], threads: usize) -> Vec<JobResult> {
    par_map(jobs, threads, run_job)
}

/// `f` of every item on a pool of `threads` threads; results in item order, whatever the
/// thread count.
pub fn par_map<T: Sync, R: Send>(
    items: &[T],
    threads: usize,
    f: impl Fn(&T) -> R + Sync + Send,
) -> Vec<R> {
    use rayon::prelude::*;
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads.max(1))
        .build()
        .expect("a thread pool");
    pool.install(|| items.par_iter().map(f).collect())
}

/// A trajectory as zlib-compressed little-endian f32 (x, y, heading per robot per step): a
/// tenth of a millimetre is far below anything a figure or a replay shows, and 600 s of six
/// robots packs into a few hundred kilobytes.
///
/// Deflate's fastest level: raw f32 coordinates hardly compress past half (when the level was
/// chosen, level 6 made blobs 2–16 % smaller than level 1 on three caves runs, at five to eight
/// times the time; docs/scale.md), and a campaign packs every run that may reach its top K.
/// Any level reads back the same way.
pub fn pack_trajectory(trajectory: &[f64]) -> Vec<u8> {
    use std::io::Write;
    // One buffer, compressed in one call: the encoder clears its output buffer on every
    // write, so writing value by value cost more than the compression itself.
    let raw: Vec<u8> = trajectory
        .iter()
        .flat_map(|&v| (v as f32).to_le_bytes())
        .collect();
    let mut enc = flate2::write::ZlibEncoder::new(
        Vec::with_capacity(raw.len() / 2),
        flate2::Compression::fast(),
    );
    enc.write_all(&raw).expect("writing to memory");
    enc.finish().expect("writing to memory")
}

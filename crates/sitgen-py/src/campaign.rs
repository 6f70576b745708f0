//! Bindings for campaigns: many situations generated and run in Rust, across threads, without
//! the GIL.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{channel, Receiver, Sender};
use std::sync::{Arc, Mutex};

use pyo3::exceptions::PyStopIteration;
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyDict};
use rayon::prelude::*;
use sitgen_core::run::{pack_trajectory, par_map, run_job, Job, JobResult, JobSituation, RunSpec};
use sitgen_core::situation::Situation;
use sitgen_core::spec;

/// Parse one job; errors name the job and the field. The situation JSON is a situation spec,
/// or a whole situation (it has a `format`), which is checked as a situation file is.
fn job(
    index: usize,
    (spec_json, situation_seed, run_json, run_seed): &JobTuple,
) -> Result<Job, String> {
    let named = |e: spec::SpecError| format!("job {index}: {e}");
    let is_situation = serde_json::from_str::<serde_json::Value>(spec_json)
        .is_ok_and(|v| v.get("format").is_some());
    let situation = if is_situation {
        JobSituation::Given(Box::new(Situation::from_json(spec_json).map_err(named)?))
    } else {
        JobSituation::Spec(Box::new(spec::from_json_str(spec_json).map_err(named)?))
    };
    let run = RunSpec::from_json(run_json, "run").map_err(|e| format!("job {index}: {e}"))?;
    Ok(Job {
        situation,
        situation_seed: *situation_seed,
        run,
        run_seed: *run_seed,
    })
}

type JobTuple = (String, u64, String, u64);

/// Which finished runs get their trajectory packed: a score of at least the first, or (if
/// the second is true) any failure. A campaign keeping only some trajectories skips the
/// compression of the others; by default every run's is packed.
type PackRule = (f64, bool);

const PACK_ALL: PackRule = (f64::NEG_INFINITY, false);

/// Generate and run `jobs` — (situation spec JSON, situation seed, run spec JSON, run seed) —
/// on `threads` threads. Returns one dict per job, in order: `ok`; then `error`, or
/// `situation` (JSON), `record` (JSON), `events_jsonl`, `trajectory` (zlib f32 bytes; None
/// where the job's entry of `pack` says not to keep it), `robots`.
#[pyfunction]
#[pyo3(signature = (jobs, threads, pack=None))]
fn run_jobs<'py>(
    py: Python<'py>,
    jobs: Vec<JobTuple>,
    threads: usize,
    pack: Option<Vec<PackRule>>,
) -> PyResult<Vec<Bound<'py, PyDict>>> {
    if let Some(rules) = &pack {
        if rules.len() != jobs.len() {
            return Err(pyo3::exceptions::PyValueError::new_err(format!(
                "pack: {} rules for {} jobs",
                rules.len(),
                jobs.len()
            )));
        }
    }
    let parsed: Vec<Result<Job, String>> =
        jobs.iter().enumerate().map(|(i, j)| job(i, j)).collect();
    let rule = |i: usize| pack.as_ref().map_or(PACK_ALL, |rules| rules[i]);
    let good: Vec<Job> = parsed
        .iter()
        .filter_map(|j| j.as_ref().ok().cloned())
        .collect();
    let good_rules: Vec<PackRule> = parsed
        .iter()
        .enumerate()
        .filter(|(_, j)| j.is_ok())
        .map(|(i, _)| rule(i))
        .collect();
    let paired: Vec<(&Job, PackRule)> = good.iter().zip(good_rules).collect();
    let results = py.detach(|| par_map(&paired, threads, |&(j, rule)| timed(j, rule)));
    let mut results = results.into_iter();
    parsed
        .into_iter()
        .map(|p| {
            let result = match p {
                Err(e) => Err(e),
                Ok(_) => results.next().expect("one result per good job"),
            };
            result_dict(py, result)
        })
        .collect()
}

/// A finished job, serialised off the GIL: (situation, record, events, trajectory, robots,
/// (wall seconds, processor seconds) it took, the situation's descriptors).
type Packed = Result<
    (
        String,
        String,
        String,
        Option<Vec<u8>>,
        usize,
        (f64, f64),
        String,
    ),
    String,
>;

/// `describe`: whether the situation's descriptors are wanted (not for a perturbed copy, whose
/// situation is its run's: they would cost every copy a distance transform for nothing).
fn pack_result(
    result: JobResult,
    (min_score, failures): PackRule,
    took: (f64, f64),
    describe: bool,
) -> Packed {
    result.map(|(s, rec)| {
        let keep = rec.score.total >= min_score || (failures && rec.failure.is_some());
        let packed = keep.then(|| pack_trajectory(&rec.trajectory));
        let record = serde_json::to_string(&rec).expect("records serialize");
        // Stored with the situation, so that explaining a campaign generates none again.
        let descriptors = if describe {
            serde_json::to_string(&sitgen_core::situation::descriptors::describe(&s, None))
                .expect("descriptors serialize")
        } else {
            String::new()
        };
        (
            s.to_json(),
            record,
            rec.events_jsonl(),
            packed,
            rec.robots,
            took,
            descriptors,
        )
    })
}

/// This thread's processor time, seconds.
fn thread_cpu_s() -> f64 {
    let mut t = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: clock_gettime writes the timespec it is given.
    unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut t) };
    t.tv_sec as f64 + t.tv_nsec as f64 * 1e-9
}

/// `job` generated and run on this thread, with the wall and processor time it took (what
/// `sitgen failures` and the export show of each run's cost).
fn timed(job: &Job, rule: PackRule) -> Packed {
    let (started, cpu) = (std::time::Instant::now(), thread_cpu_s());
    let result = run_job(job);
    let took = (started.elapsed().as_secs_f64(), thread_cpu_s() - cpu);
    pack_result(result, rule, took, job.run.perturbation.is_none())
}

fn result_dict(py: Python<'_>, result: Packed) -> PyResult<Bound<'_, PyDict>> {
    let d = PyDict::new(py);
    match result {
        Ok((situation, record, events, trajectory, robots, (wall_s, cpu_s), descriptors)) => {
            d.set_item("ok", true)?;
            d.set_item("wall_s", wall_s)?;
            d.set_item("cpu_s", cpu_s)?;
            d.set_item("situation", situation)?;
            d.set_item("record", record)?;
            d.set_item("events_jsonl", events)?;
            d.set_item("trajectory", trajectory.map(|t| PyBytes::new(py, &t)))?;
            d.set_item("robots", robots)?;
            if !descriptors.is_empty() {
                d.set_item("descriptors", descriptors)?;
            }
        }
        Err(e) => {
            d.set_item("ok", false)?;
            d.set_item("error", e)?;
        }
    }
    Ok(d)
}

/// Jobs running on a pool of `threads` threads in the background, fed a few at a time with
/// `submit`, so that a campaign of any size holds only the jobs in flight. Iterating yields
/// (job id, result dict) as each job finishes, so a slow job holds up nobody; exactly one item
/// comes back per job submitted (the caller counts them). `stop()` lets the jobs already
/// started finish and starts no more: those not started come back as (job id, None).
#[pyclass(name = "JobStream", module = "sitgen._core")]
pub struct JobStream {
    jobs: Mutex<Option<Sender<(usize, JobTuple, PackRule)>>>,
    results: Mutex<Receiver<(usize, Option<Packed>)>>,
    stop: Arc<AtomicBool>,
}

#[pymethods]
impl JobStream {
    #[new]
    fn new(threads: usize) -> PyResult<Self> {
        let (job_tx, job_rx) = channel::<(usize, JobTuple, PackRule)>();
        let (tx, rx) = channel();
        let stop = Arc::new(AtomicBool::new(false));
        let stopping = Arc::clone(&stop);
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads.max(1))
            .build()
            .map_err(|e| pyo3::exceptions::PyRuntimeError::new_err(e.to_string()))?;
        std::thread::spawn(move || {
            pool.install(|| {
                // One job per task as it arrives, so idle threads take the next job.
                job_rx
                    .into_iter()
                    .par_bridge()
                    .for_each_with(tx, |tx, (id, tuple, rule)| {
                        let result = (!stopping.load(Ordering::Relaxed))
                            .then(|| job(id, &tuple).and_then(|j| timed(&j, rule)));
                        // The receiver is gone only if Python dropped the stream.
                        let _ = tx.send((id, result));
                    })
            })
        });
        Ok(Self {
            jobs: Mutex::new(Some(job_tx)),
            results: Mutex::new(rx),
            stop,
        })
    }

    /// Queue jobs: (job id, (situation spec JSON, situation seed, run spec JSON, run seed),
    /// pack rule (min score, failures): which finished runs get their trajectory packed).
    fn submit(&self, jobs: Vec<(usize, JobTuple, PackRule)>) -> PyResult<()> {
        let guard = self.jobs.lock().unwrap_or_else(|e| e.into_inner());
        let sender = guard
            .as_ref()
            .ok_or_else(|| pyo3::exceptions::PyRuntimeError::new_err("the stream is closed"))?;
        for j in jobs {
            sender
                .send(j)
                .map_err(|e| pyo3::exceptions::PyRuntimeError::new_err(e.to_string()))?;
        }
        Ok(())
    }

    /// Take no more jobs; the threads end when the queued ones are done.
    fn close(&self) {
        self.jobs.lock().unwrap_or_else(|e| e.into_inner()).take();
    }

    fn __iter__(slf: PyRef<'_, Self>) -> PyRef<'_, Self> {
        slf
    }

    fn __next__<'py>(&self, py: Python<'py>) -> PyResult<(usize, Option<Bound<'py, PyDict>>)> {
        let next = py.detach(|| {
            self.results
                .lock()
                .unwrap_or_else(|e| e.into_inner())
                .recv()
        });
        match next {
            Ok((i, Some(result))) => Ok((i, Some(result_dict(py, result)?))),
            Ok((i, None)) => Ok((i, None)),
            Err(_) => Err(PyStopIteration::new_err(())),
        }
    }

    /// Start no more jobs; those running finish and are still yielded.
    fn stop(&self) {
        self.stop.store(true, Ordering::Relaxed);
    }
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(run_jobs, m)?)?;
    m.add_class::<JobStream>()?;
    Ok(())
}

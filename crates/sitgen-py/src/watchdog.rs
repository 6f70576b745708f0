//! The last resort against an in-process controller call that never returns: a thread of its
//! own (it needs no GIL) kills this process once a call has run past its limit.
//!
//! A Python controller in a pool worker is interrupted by SIGALRM at its step timeout; code
//! that holds the GIL in a C loop (`sum(range(10**12))`) never sees the signal. Killing the
//! worker is then the only way out: the campaign's pool replaces it and reruns the run in a
//! host process of its own, which reports the timeout as it always has.

use std::sync::atomic::{AtomicI32, AtomicU64, Ordering};
use std::sync::{Mutex, OnceLock};
use std::thread;
use std::time::{Duration, Instant};

use pyo3::prelude::*;

/// Nanoseconds since [`epoch`] at which the call in progress is killed; 0 while none is.
static DEADLINE_NS: AtomicU64 = AtomicU64::new(0);
/// The process whose watcher thread runs: a forked child inherits the flag but not the thread.
static WATCHER_PID: Mutex<u32> = Mutex::new(0);
/// A file descriptor the watcher writes one byte (`W`) to before it kills this process, so
/// that whoever waits on the process tells a missed deadline from any other SIGKILL; -1: none.
static REPORT_FD: AtomicI32 = AtomicI32::new(-1);
/// How often an idle watcher looks for a new call.
const IDLE_POLL: Duration = Duration::from_millis(100);

fn epoch() -> Instant {
    static EPOCH: OnceLock<Instant> = OnceLock::new();
    *EPOCH.get_or_init(Instant::now)
}

fn now_ns() -> u64 {
    u64::try_from(epoch().elapsed().as_nanos()).unwrap_or(u64::MAX)
}

fn watch() {
    loop {
        let deadline = DEADLINE_NS.load(Ordering::Acquire);
        let now = now_ns();
        if deadline != 0 && now >= deadline {
            let fd = REPORT_FD.load(Ordering::Acquire);
            // SAFETY: write(2) of one byte from a static buffer, then kill(2) on this process's
            // own id; nothing is borrowed.
            unsafe {
                if fd >= 0 {
                    libc::write(fd, b"W".as_ptr().cast(), 1);
                }
                libc::kill(libc::getpid(), libc::SIGKILL);
            }
        }
        let wait = if deadline == 0 {
            IDLE_POLL
        } else {
            Duration::from_nanos(deadline.saturating_sub(now)).min(IDLE_POLL * 10)
        };
        thread::sleep(wait.max(Duration::from_millis(1)));
    }
}

fn ensure_watcher() {
    let pid = std::process::id();
    let mut running = WATCHER_PID.lock().unwrap_or_else(|e| e.into_inner());
    if *running != pid {
        thread::Builder::new()
            .name("sitgen-watchdog".into())
            .spawn(watch)
            .expect("a watchdog thread starts");
        *running = pid;
    }
}

/// Kills this process if a call runs longer than `limit`.
pub(crate) struct Watchdog {
    limit_ns: u64,
}

/// One call being watched; dropping it (the call returned, or raised) disarms the watchdog.
pub(crate) struct Watched;

impl Watchdog {
    pub(crate) fn new(limit_s: f64) -> Self {
        ensure_watcher();
        let limit_ns = (limit_s.clamp(0.001, 1e6) * 1e9) as u64;
        Self { limit_ns }
    }

    pub(crate) fn watch(&self) -> Watched {
        DEADLINE_NS.store(
            now_ns().saturating_add(self.limit_ns).max(1),
            Ordering::Release,
        );
        Watched
    }
}

impl Drop for Watched {
    fn drop(&mut self) {
        DEADLINE_NS.store(0, Ordering::Release);
    }
}

/// Arm the watchdog for the call that follows (`limit_s`: seconds until this process is
/// killed), or disarm it (`None`): for the work around an in-process controller's steps — its
/// class loading and `reset` — that `Run.drive` does not watch itself.
#[pyfunction]
#[pyo3(signature = (limit_s=None))]
fn kill_after(limit_s: Option<f64>) {
    match limit_s {
        Some(limit_s) => std::mem::forget(Watchdog::new(limit_s).watch()),
        None => drop(Watched),
    }
}

/// Where the watchdog reports a kill (one byte, `W`, written to `fd` just before it kills this
/// process), or nowhere (`None`).
#[pyfunction]
#[pyo3(signature = (fd=None))]
fn watchdog_report(fd: Option<i32>) {
    REPORT_FD.store(fd.unwrap_or(-1), Ordering::Release);
}

/// Start the threads this process's runs use — the step watchdog and the core's data-parallel
/// pool — if they have not started: a process that makes one run after another and checks its
/// threads between runs then sees none appear that a run did not start itself.
#[pyfunction]
fn start_threads() {
    ensure_watcher();
    sitgen_core::parallel::start();
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(start_threads, m)?)?;
    m.add_function(wrap_pyfunction!(kill_after, m)?)?;
    m.add_function(wrap_pyfunction!(watchdog_report, m)?)?;
    Ok(())
}

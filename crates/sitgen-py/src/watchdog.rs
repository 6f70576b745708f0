//! The deadlines of an in-process controller call, kept by a thread of its own (it needs no
//! GIL): a wall-clock backstop that interrupts the call, and a last resort that kills this
//! process once a call has run far past either limit.
//!
//! A Python controller's step deadline counts the processor time it spends (SIGPROF, armed by
//! the caller): a loaded machine slows a call down but does not change its verdict. A call
//! that waits instead — on a sleep, a lock, input — uses no processor time, so this thread
//! sends the calling thread SIGALRM at a generous wall-clock backstop, and keeps what the
//! caller needs to tell a call that waited from one the machine starved of a core
//! ([`watched_call`]: the call's running and run-queue time, from Linux's schedstat). Code that
//! holds the GIL in a C loop (`sum(range(10**12))`) sees neither signal; in a disposable
//! process (a runner) this thread then kills the process a grace period later: the run is made
//! again in a host process of its own, which reports the timeout as it always has.

use std::sync::atomic::{AtomicBool, AtomicI32, AtomicU64, Ordering};
use std::sync::{Mutex, OnceLock};
use std::thread;
use std::time::{Duration, Instant};

use pyo3::prelude::*;

/// Nanoseconds since [`epoch`] at which the call in progress gets SIGALRM; 0 while none is.
static ALARM_NS: AtomicU64 = AtomicU64::new(0);
/// Nanoseconds since [`epoch`] at which the call in progress is killed; 0: never.
static KILL_NS: AtomicU64 = AtomicU64::new(0);
/// Processor nanoseconds the process may use in the call in progress before it is killed; 0:
/// no limit.
static KILL_CPU_NS: AtomicU64 = AtomicU64::new(0);
/// Which call is in progress: a new one each [`Watchdog::watch`].
static GENERATION: AtomicU64 = AtomicU64::new(0);
/// The thread making the call (its `pthread_t`), which the backstop's SIGALRM is sent to: a
/// signal sent to the process could land on another thread and leave a sleeping call asleep.
static CALLER: AtomicU64 = AtomicU64::new(0);
/// Whether the call in progress has had its SIGALRM.
static ALARMED: AtomicBool = AtomicBool::new(false);
/// The process whose watcher thread runs: a forked child inherits the flag but not the thread.
static WATCHER_PID: Mutex<u32> = Mutex::new(0);
/// A file descriptor the watcher writes one byte to before it kills this process (`W` past the
/// wall-clock limit, `C` past the processor-time one), so that whoever waits on the process
/// tells a missed deadline from any other SIGKILL; -1: none.
static REPORT_FD: AtomicI32 = AtomicI32::new(-1);
/// What the watcher saw when it first noticed the call in progress.
static NOTICED: Mutex<Option<Noticed>> = Mutex::new(None);
/// How often an idle watcher looks for a new call.
const IDLE_POLL: Duration = Duration::from_millis(100);
/// How often a watcher looks at a call in progress (for its processor time).
const BUSY_POLL: Duration = Duration::from_millis(50);
/// A watcher that wakes this much later than it asked was paused with its process (SIGSTOP, a
/// suspended machine): the pause is added to the call's wall-clock limits, which measure the
/// call's waiting, not the machine's.
const PAUSED: Duration = Duration::from_millis(250);

#[derive(Clone, Copy)]
struct Noticed {
    generation: u64,
    at: Instant,
    cpu_ns: u64,
    running_ns: u64,
    queued_ns: u64,
}

fn epoch() -> Instant {
    static EPOCH: OnceLock<Instant> = OnceLock::new();
    *EPOCH.get_or_init(Instant::now)
}

fn now_ns() -> u64 {
    u64::try_from(epoch().elapsed().as_nanos()).unwrap_or(u64::MAX)
}

/// This process's processor time (all its threads), nanoseconds.
fn process_cpu_ns() -> u64 {
    let mut t = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: clock_gettime writes the timespec it is given.
    unsafe { libc::clock_gettime(libc::CLOCK_PROCESS_CPUTIME_ID, &mut t) };
    u64::try_from(t.tv_sec).unwrap_or(0) * 1_000_000_000 + u64::try_from(t.tv_nsec).unwrap_or(0)
}

/// The time this process's live threads have spent running and waiting on a run queue for a
/// core (Linux's `/proc/self/task/*/schedstat`, its first two fields), nanoseconds; zeros
/// where the kernel keeps no schedstat.
fn schedstat_ns() -> (u64, u64) {
    let (mut running, mut queued) = (0, 0);
    let Ok(tasks) = std::fs::read_dir("/proc/self/task") else {
        return (0, 0);
    };
    for task in tasks.flatten() {
        let Ok(text) = std::fs::read_to_string(task.path().join("schedstat")) else {
            continue;
        };
        let mut fields = text
            .split_whitespace()
            .map(|f| f.parse::<u64>().unwrap_or(0));
        running += fields.next().unwrap_or(0);
        queued += fields.next().unwrap_or(0);
    }
    (running, queued)
}

fn notice(generation: u64) -> Noticed {
    let mut noticed = NOTICED.lock().unwrap_or_else(|e| e.into_inner());
    match *noticed {
        Some(n) if n.generation == generation => n,
        _ => {
            let (running_ns, queued_ns) = schedstat_ns();
            let n = Noticed {
                generation,
                at: Instant::now(),
                cpu_ns: process_cpu_ns(),
                running_ns,
                queued_ns,
            };
            *noticed = Some(n);
            n
        }
    }
}

fn kill_self(why: &'static [u8; 1]) {
    let fd = REPORT_FD.load(Ordering::Acquire);
    // SAFETY: write(2) of one byte from a static buffer, then kill(2) on this process's own
    // id; nothing is borrowed.
    unsafe {
        if fd >= 0 {
            libc::write(fd, why.as_ptr().cast(), 1);
        }
        libc::kill(libc::getpid(), libc::SIGKILL);
    }
}

fn watch() {
    loop {
        let alarm = ALARM_NS.load(Ordering::Acquire);
        if alarm == 0 {
            thread::sleep(IDLE_POLL);
            continue;
        }
        let generation = GENERATION.load(Ordering::Acquire);
        let noticed = notice(generation);
        let now = now_ns();
        let kill = KILL_NS.load(Ordering::Acquire);
        if kill != 0 && now >= kill {
            kill_self(b"W");
        }
        let kill_cpu = KILL_CPU_NS.load(Ordering::Acquire);
        if kill_cpu != 0 && process_cpu_ns().saturating_sub(noticed.cpu_ns) >= kill_cpu {
            kill_self(b"C");
        }
        if now >= alarm && !ALARMED.swap(true, Ordering::AcqRel) {
            // SAFETY: pthread_kill on the thread that armed this call; a thread that has since
            // exited is not signalled (the call was disarmed when it returned).
            unsafe {
                libc::pthread_kill(
                    CALLER.load(Ordering::Acquire) as libc::pthread_t,
                    libc::SIGALRM,
                )
            };
        }
        let next = [alarm, kill]
            .into_iter()
            .filter(|&t| t > now)
            .min()
            .map_or(BUSY_POLL, |t| Duration::from_nanos(t - now).min(BUSY_POLL))
            .max(Duration::from_millis(1));
        let asked = Instant::now() + next;
        thread::sleep(next);
        let late = Instant::now().saturating_duration_since(asked);
        if late > PAUSED && GENERATION.load(Ordering::Acquire) == generation {
            let late_ns = u64::try_from(late.as_nanos()).unwrap_or(u64::MAX);
            for limit in [&ALARM_NS, &KILL_NS] {
                let _ = limit.fetch_update(Ordering::AcqRel, Ordering::Acquire, |t| {
                    (t != 0).then(|| t.saturating_add(late_ns))
                });
            }
        }
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

/// The limits of one kind of call: SIGALRM to the caller at `wall_s` of wall clock, and, if
/// `kill`, this process killed `grace_s` past that or once the call has used `cpu_s + grace_s`
/// of processor time.
#[derive(Clone, Copy)]
pub(crate) struct Watchdog {
    alarm_ns: u64,
    kill_ns: Option<u64>,
    kill_cpu_ns: u64,
}

/// One call being watched; dropping it (the call returned, or raised) disarms the watchdog.
pub(crate) struct Watched;

fn ns(seconds: f64) -> u64 {
    (seconds.clamp(0.001, 1e6) * 1e9) as u64
}

impl Watchdog {
    pub(crate) fn new(cpu_s: f64, wall_s: f64, kill_grace_s: Option<f64>) -> Self {
        ensure_watcher();
        Self {
            alarm_ns: ns(wall_s),
            kill_ns: kill_grace_s.map(|g| ns(wall_s + g)),
            kill_cpu_ns: kill_grace_s.map_or(0, |g| ns(cpu_s + g)),
        }
    }

    pub(crate) fn watch(&self) -> Watched {
        let now = now_ns();
        // SAFETY: pthread_self has no preconditions.
        CALLER.store(unsafe { libc::pthread_self() } as u64, Ordering::Release);
        GENERATION.fetch_add(1, Ordering::AcqRel);
        ALARMED.store(false, Ordering::Release);
        KILL_CPU_NS.store(self.kill_cpu_ns, Ordering::Release);
        KILL_NS.store(
            self.kill_ns.map_or(0, |k| now.saturating_add(k)),
            Ordering::Release,
        );
        ALARM_NS.store(now.saturating_add(self.alarm_ns).max(1), Ordering::Release);
        Watched
    }
}

impl Drop for Watched {
    fn drop(&mut self) {
        ALARM_NS.store(0, Ordering::Release);
        KILL_NS.store(0, Ordering::Release);
        KILL_CPU_NS.store(0, Ordering::Release);
    }
}

/// Watch the call that follows (`cpu_s`: its processor-time limit; `wall_s`: when the calling
/// thread gets SIGALRM; `kill_grace_s`: how far past either this process is killed, None for
/// never), or stop watching (`None`): for the work around an in-process controller's steps —
/// its class loading, `reset`, a peer's step, `close` — that `Run.drive` does not watch itself.
#[pyfunction]
#[pyo3(signature = (limits=None))]
fn watch_call(limits: Option<(f64, f64, Option<f64>)>) {
    match limits {
        Some((cpu_s, wall_s, grace_s)) => {
            std::mem::forget(Watchdog::new(cpu_s, wall_s, grace_s).watch())
        }
        None => drop(Watched),
    }
}

/// The call in progress as the watcher has seen it since it first noticed it: (wall seconds,
/// seconds its threads ran, seconds they waited on a run queue for a core), or None when no
/// call is watched or the watcher has not yet noticed this one.
#[pyfunction]
fn watched_call() -> Option<(f64, f64, f64)> {
    if ALARM_NS.load(Ordering::Acquire) == 0 {
        return None;
    }
    let generation = GENERATION.load(Ordering::Acquire);
    let n = (*NOTICED.lock().unwrap_or_else(|e| e.into_inner()))?;
    if n.generation != generation {
        return None;
    }
    let (running, queued) = schedstat_ns();
    Some((
        n.at.elapsed().as_secs_f64(),
        running.saturating_sub(n.running_ns) as f64 / 1e9,
        queued.saturating_sub(n.queued_ns) as f64 / 1e9,
    ))
}

/// Where the watchdog reports a kill (one byte, `W` or `C`, written to `fd` just before it
/// kills this process), or nowhere (`None`).
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
    m.add_function(wrap_pyfunction!(watch_call, m)?)?;
    m.add_function(wrap_pyfunction!(watched_call, m)?)?;
    m.add_function(wrap_pyfunction!(watchdog_report, m)?)?;
    Ok(())
}

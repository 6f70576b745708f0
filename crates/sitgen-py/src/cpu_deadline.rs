//! A call's processor-time deadline: SIGPROF once this process has used so many seconds of
//! processor time from now, counted on Linux's scheduler clock (`CLOCK_PROCESS_CPUTIME_ID`).
//!
//! Why not `setitimer(ITIMER_PROF)`: that timer counts user and system time as the scheduler
//! tick samples it, a whole tick (4 or 10 ms) charged to whichever thread is running when the
//! tick comes. Beside other work a step of 3 ms runs in many short slices and can be charged
//! several ticks: a 20 ms deadline it meets alone then fires on a loaded machine, and a verdict
//! depends on load again. The scheduler clock counts what ran, to the nanosecond; a timer on it
//! may fire up to a tick late, never early.
//!
//! One timer a process (a forked child inherits none, so it makes its own), signalling the
//! process: Python's handler runs in its main thread, the only one that arms it.

use std::sync::Mutex;

use pyo3::exceptions::PyOSError;
use pyo3::prelude::*;

/// This process's timer: (the process id it was made in, its `timer_t`).
static TIMER: Mutex<Option<(u32, usize)>> = Mutex::new(None);

fn timer() -> PyResult<libc::timer_t> {
    let pid = std::process::id();
    let mut made = TIMER.lock().unwrap_or_else(|e| e.into_inner());
    if let Some((owner, id)) = *made {
        if owner == pid {
            return Ok(id as libc::timer_t);
        }
    }
    // SAFETY: a zeroed sigevent is a valid one; the fields set below are those SIGEV_SIGNAL
    // reads, and timer_create writes the id it is given.
    let id = unsafe {
        let mut event: libc::sigevent = std::mem::zeroed();
        event.sigev_notify = libc::SIGEV_SIGNAL;
        event.sigev_signo = libc::SIGPROF;
        let mut id: libc::timer_t = std::ptr::null_mut();
        if libc::timer_create(libc::CLOCK_PROCESS_CPUTIME_ID, &mut event, &mut id) != 0 {
            return Err(PyOSError::new_err(format!(
                "a processor-time timer could not be made: {}",
                std::io::Error::last_os_error()
            )));
        }
        id
    };
    *made = Some((pid, id as usize));
    Ok(id)
}

/// Send this process SIGPROF once it has used `seconds` more of processor time (all its
/// threads, on the scheduler's clock); 0 disarms.
#[pyfunction]
fn cpu_deadline(seconds: f64) -> PyResult<()> {
    let id = timer()?;
    let ns = if seconds > 0.0 {
        ((seconds.min(1e9) * 1e9) as i64).max(1)
    } else {
        0
    };
    let spec = libc::itimerspec {
        it_interval: libc::timespec {
            tv_sec: 0,
            tv_nsec: 0,
        },
        it_value: libc::timespec {
            tv_sec: ns / 1_000_000_000,
            tv_nsec: ns % 1_000_000_000,
        },
    };
    // SAFETY: the timer was made by this process; the spec lives across the call.
    if unsafe { libc::timer_settime(id, 0, &spec, std::ptr::null_mut()) } != 0 {
        return Err(PyOSError::new_err(format!(
            "the processor-time timer could not be set: {}",
            std::io::Error::last_os_error()
        )));
    }
    Ok(())
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(cpu_deadline, m)?)?;
    Ok(())
}

//! The thread pool the core's data-parallel loops (Perlin rows, the distance transform's rows)
//! run on when called from outside any pool: rayon's global pool, except in a process forked
//! from one that had started it.
//!
//! A forked child inherits a started pool's bookkeeping but none of its threads, so its first
//! parallel loop would wait for ever. sitgen forks a process to make runs that call a user's
//! Python class (`sitgen.controllers.sandbox`), and that process builds runs: here it gets a
//! pool of its own, started in it. Called from a thread of any pool (a campaign's), a loop runs
//! on that pool as before. Results do not depend on the pool: every loop writes disjoint rows.

use std::sync::Mutex;

use rayon::{ThreadPool, ThreadPoolBuilder};

/// The pool this process started (its id, then the pool, kept for the life of the process).
static POOL: Mutex<Option<(u32, &'static ThreadPool)>> = Mutex::new(None);

/// Run `op` where its parallel loops can run: on the pool of the calling thread, if it is one
/// of a pool's, else on this process's own pool.
pub fn install<R: Send>(op: impl FnOnce() -> R + Send) -> R {
    if rayon::current_thread_index().is_some() {
        return op();
    }
    own_pool().install(op)
}

/// Start this process's pool now, if it has not started (so that a process that checks its
/// threads between runs sees none appear during one).
pub fn start() {
    own_pool();
}

fn own_pool() -> &'static ThreadPool {
    let pid = std::process::id();
    let mut slot = POOL.lock().unwrap_or_else(|e| e.into_inner());
    match *slot {
        Some((owner, pool)) if owner == pid => pool,
        // A pool started by the process this one was forked from has no threads here; it is
        // left as it is (dropping it would wait on threads that do not exist).
        _ => {
            let pool: &'static ThreadPool = Box::leak(Box::new(
                ThreadPoolBuilder::new()
                    .thread_name(|i| format!("sitgen-pool-{i}"))
                    .build()
                    .expect("a thread pool starts"),
            ));
            *slot = Some((pid, pool));
            pool
        }
    }
}

//! The reference scene without Python, for profiling (`make profile` runs it under perf):
//! 40 × 40 m caves at 0.1 m, five `straight` peers, the snd_follow agent with the 181-beam
//! 10 m laser, monitor on. Prints steps per second of whole runs (set-up included, as a
//! campaign pays it) and of the agent's scan alone.
//!
//! `cargo run --release -p sitgen-core --example reference_scene [SECONDS]`

use std::time::Instant;

use sitgen_core::run::{Run, RunSpec};
use sitgen_core::sim::World;

fn main() {
    let seconds: f64 = std::env::args()
        .nth(1)
        .map(|s| s.parse().expect("SECONDS: a number"))
        .unwrap_or(5.0);
    let spec = sitgen_core::spec::from_json_str(
        r#"{"terrain": {"preset": "caves"}, "mission": {"peers_min": 5, "peers_max": 5}}"#,
    )
    .expect("the reference scene's spec");
    let situation = sitgen_core::situation::generate(&spec, 1)
        .expect("the reference scene")
        .0;
    let run_spec = RunSpec::from_json(
        r#"{"controller": {"name": "snd_follow"}, "time_limit_s": 600.0}"#,
        "run",
    )
    .expect("the run spec");

    // Best of several rounds: on a shared machine the best is the least disturbed.
    let rounds = 5;
    let best = |f: &mut dyn FnMut() -> u64| -> f64 {
        (0..rounds)
            .map(|_| {
                let start = Instant::now();
                let mut units = 0u64;
                while start.elapsed().as_secs_f64() < seconds / rounds as f64 {
                    units += f();
                }
                units as f64 / start.elapsed().as_secs_f64()
            })
            .fold(0.0, f64::max)
    };
    let steps_per_s = best(&mut || {
        let mut run = Run::new(&situation, &run_spec, 0).expect("a run");
        run.run_to_end();
        run.finish().steps
    });
    println!(
        "reference scene, snd_follow: {steps_per_s:.0} steps/s ({:.2} µs/step), best of {rounds}",
        1e6 / steps_per_s
    );

    if std::env::args().nth(2).as_deref() == Some("runs") {
        return;
    }
    let world = World::new(&situation, run_spec.sim.clone(), 0).expect("a world");
    let beams = world.scan(0).len() as f64;
    let scans_per_s = best(&mut || {
        for _ in 0..1000 {
            world.forget_scans();
            std::hint::black_box(world.scan(0));
        }
        1000
    });
    println!(
        "agent scan: {:.2} µs/scan, {:.2} M rays/s, best of {rounds}",
        1e6 / scans_per_s,
        scans_per_s * beams / 1e6
    );
}

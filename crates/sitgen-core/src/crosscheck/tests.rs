use super::*;
use crate::spec::from_toml_str;

/// The log the Stage plugin would write for a run that went exactly as sitgen's: after every
/// step, each robot's pose, velocity and stall, and the laser's scan from there.
fn own_log(situation: &Situation, run: &RunSpec) -> String {
    let mut r = Run::new(situation, run, 0).unwrap();
    let mut lines = Vec::new();
    let mut ended = false;
    loop {
        let w = r.world();
        let robots: Vec<_> = w
            .robots()
            .iter()
            .map(|s| {
                let mut o = serde_json::json!({
                    "id": s.id, "pose": [s.pose.x_m, s.pose.y_m, s.pose.heading_rad],
                    "velocity": [s.velocity.0, s.velocity.1], "stalled": s.stalled,
                    "command": [s.command.0, s.command.1],
                });
                if w.has_laser(s.id) {
                    let (ranges, seen) = w.scan_seeing(s.id as usize);
                    o["ranges"] = serde_json::json!(ranges);
                    o["seen"] = serde_json::json!(seen);
                }
                o
            })
            .collect();
        lines.push(
            serde_json::json!({"step": w.steps(), "time": w.time_s(), "robots": robots})
                .to_string(),
        );
        if ended {
            break;
        }
        ended = r.step(None);
    }
    lines.join("\n")
}

fn situation(preset: &str, peers: u32, seed: u64) -> Situation {
    let spec = from_toml_str(&format!(
        "[terrain]\npreset = \"{preset}\"\n[mission]\npeers_min = {peers}\npeers_max = {peers}\n"
    ))
    .unwrap();
    crate::situation::generate(&spec, seed).unwrap().0
}

#[test]
fn a_log_of_sitgens_own_run_compares_identical() {
    let run: RunSpec = serde_json::from_str(r#"{"time_limit_s": 60}"#).unwrap();
    for (preset, seed) in [("caves", 2), ("urban", 3)] {
        let s = situation(preset, 3, seed);
        let log = read_log(&own_log(&s, &run), s.robots.len()).unwrap();
        let report = compare(&s, &run, &log).unwrap();
        assert_eq!(report.start_pose_error_m, 0.0);
        for d in &report.divergence {
            assert_eq!(d.max_position_m, 0.0, "robot {} diverged", d.id);
        }
        assert_eq!(report.sitgen.steps, report.stage.steps);
        assert_eq!(report.sitgen.first_stall, report.stage.first_stall);
        assert_eq!(report.sitgen.score, report.stage.score);
        assert_eq!(
            monitor_lines(&report.sitgen.events),
            monitor_lines(&report.stage.events)
        );
        assert!(report.events.iter().all(|m| m.sitgen == m.stage));
        let sc = &report.scans;
        assert!(sc.scans > 0 && sc.beams == sc.scans * 181);
        assert_eq!(sc.max_abs_m, 0.0);
        assert_eq!(sc.stage_only_hit + sc.sitgen_only_hit, 0);
        assert_eq!(sc.same_robots_seen, sc.scans);
    }
}

fn monitor_lines(events: &[Event]) -> String {
    crate::monitor::to_jsonl(events)
}

#[test]
fn a_displaced_robot_shows_as_divergence_and_scan_differences() {
    let run: RunSpec = serde_json::from_str(r#"{"time_limit_s": 20}"#).unwrap();
    let s = situation("caves", 1, 5);
    let text = own_log(&s, &run);
    // Stage's peer 1 half a metre east of where sitgen has it, from step 50 on.
    let shifted: Vec<String> = text
        .lines()
        .map(|l| {
            let mut v: serde_json::Value = serde_json::from_str(l).unwrap();
            if v["step"].as_u64().unwrap() >= 50 {
                let x = v["robots"][1]["pose"][0].as_f64().unwrap();
                v["robots"][1]["pose"][0] = serde_json::json!(x + 0.5);
            }
            v.to_string()
        })
        .collect();
    let log = read_log(&shifted.join("\n"), 2).unwrap();
    let report = compare(&s, &run, &log).unwrap();
    let d = &report.divergence[1];
    assert!((d.max_position_m - 0.5).abs() < 1e-9);
    assert_eq!(d.first_over_s[0], Some(5.0));
    assert_eq!(report.divergence[0].max_position_m, 0.0);
}

#[test]
fn a_log_that_stops_before_the_run_ends_is_refused() {
    let run: RunSpec = serde_json::from_str(r#"{"time_limit_s": 10}"#).unwrap();
    let s = situation("caves", 1, 5);
    let text = own_log(&s, &run);
    let short: Vec<&str> = text.lines().take(40).collect();
    let log = read_log(&short.join("\n"), 2).unwrap();
    assert_eq!(
        compare(&s, &run, &log).unwrap_err(),
        "the Stage log ends at step 39 before the run ended (time limit 10 s): Stage stopped early"
    );
}

#[test]
fn bad_logs_name_the_line() {
    let s = situation("caves", 1, 5);
    let e = read_log("{\"step\": 0, \"time\": 0, \"robots\": []}", 2).unwrap_err();
    assert_eq!(e, "Stage log line 1: robots [], expected ids 0..2 in order");
    let e = read_log("not json", 2).unwrap_err();
    assert!(e.starts_with("Stage log line 1: "), "{e}");
    assert_eq!(
        read_log("", s.robots.len()).unwrap_err(),
        "the Stage log is empty: Stage did not run a step"
    );
}

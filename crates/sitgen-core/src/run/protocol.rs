//! The controller protocol's observation message (`docs/controller-protocol.md`), written as
//! sitgen sends it to a `cmd:` program: one JSON object on one line.
//!
//! Written here, in one pass over a fixed layout, because it is on every step of a program's
//! run: building it in Python cost more than the rest of the step together. The layout is
//! the one sitgen has always sent (keys in this order, `", "` and `": "` between items, as
//! Python's `json.dumps` writes them), and a number is the shortest text that reads back as
//! the same `f64` (Ryū, as serde_json writes it); a non-finite number is written `NaN`,
//! `Infinity` or `-Infinity`, as Python's `json` writes and reads it.

use std::fmt::Write;

use crate::sim::Observation;

/// `obs` as the protocol's `observation` message, with the waypoints the monitor counts as
/// reached, ending in a newline.
pub fn observation_line(obs: &Observation, waypoints_reached: usize) -> String {
    let mut out = String::with_capacity(160 + 24 * obs.ranges.len() + 96 * obs.tracks.len());
    out.push_str("{\"type\": \"observation\", \"time\": ");
    number(&mut out, obs.time_s);
    out.push_str(", \"pose\": ");
    list(
        &mut out,
        &[obs.pose.x_m, obs.pose.y_m, obs.pose.heading_rad],
    );
    out.push_str(", \"velocity\": ");
    list(&mut out, &[obs.velocity.0, obs.velocity.1]);
    out.push_str(if obs.stalled {
        ", \"stalled\": true"
    } else {
        ", \"stalled\": false"
    });
    let _ = write!(
        out,
        ", \"waypoints_reached\": {waypoints_reached}, \"ranges\": "
    );
    list(&mut out, &obs.ranges);
    out.push_str(", \"tracks\": [");
    for (i, t) in obs.tracks.iter().enumerate() {
        if i > 0 {
            out.push_str(", ");
        }
        let _ = write!(out, "{{\"id\": {}, \"position\": ", t.id);
        list(&mut out, &[t.position.0, t.position.1]);
        out.push_str(", \"velocity\": ");
        list(&mut out, &[t.velocity.0, t.velocity.1]);
        out.push('}');
    }
    out.push_str("]}\n");
    out
}

fn list(out: &mut String, values: &[f64]) {
    out.push('[');
    for (i, &x) in values.iter().enumerate() {
        if i > 0 {
            out.push_str(", ");
        }
        number(out, x);
    }
    out.push(']');
}

fn number(out: &mut String, x: f64) {
    if x.is_finite() {
        out.push_str(ryu::Buffer::new().format_finite(x));
    } else if x.is_nan() {
        out.push_str("NaN");
    } else if x > 0.0 {
        out.push_str("Infinity");
    } else {
        out.push_str("-Infinity");
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::Track;
    use crate::situation::Pose;

    fn observation(ranges: Vec<f64>) -> Observation {
        Observation {
            angles: vec![0.0; ranges.len()],
            ranges,
            max_range_m: 8.0,
            pose: Pose {
                x_m: 1.5,
                y_m: -2.25e-7,
                heading_rad: std::f64::consts::PI,
            },
            velocity: (0.3, -0.1),
            stalled: true,
            time_s: 12.3,
            tracks: vec![Track {
                id: 4,
                position: (3.0, 1e21),
                velocity: (0.0, -0.5),
            }],
        }
    }

    #[test]
    fn the_message_reads_back_as_the_same_numbers() {
        let ranges = vec![0.1, 7.999_999_999_999_999, 1e-9, 8.0, 2.0 / 3.0];
        let line = observation_line(&observation(ranges.clone()), 2);
        assert!(line.ends_with("]}\n") && !line[..line.len() - 1].contains('\n'));
        let v: serde_json::Value = serde_json::from_str(&line).unwrap();
        assert_eq!(v["type"], "observation");
        assert_eq!(v["time"].as_f64(), Some(12.3));
        assert_eq!(v["pose"][1].as_f64(), Some(-2.25e-7));
        assert_eq!(v["pose"][2].as_f64(), Some(std::f64::consts::PI));
        assert_eq!(v["stalled"], true);
        assert_eq!(v["waypoints_reached"], 2);
        let read: Vec<f64> = serde_json::from_value(v["ranges"].clone()).unwrap();
        assert_eq!(read, ranges);
        assert_eq!(v["tracks"][0]["id"], 4);
        assert_eq!(v["tracks"][0]["position"][1].as_f64(), Some(1e21));
    }

    #[test]
    fn the_layout_is_pythons() {
        let line = observation_line(&observation(vec![1.0, 0.5]), 0);
        assert!(line
            .starts_with("{\"type\": \"observation\", \"time\": 12.3, \"pose\": [1.5, -2.25e-7, "));
        assert!(line.contains(
            "\"stalled\": true, \"waypoints_reached\": 0, \"ranges\": [1.0, 0.5], \"tracks\": \
             [{\"id\": 4, \"position\": [3.0, 1e21], \"velocity\": [0.0, -0.5]}]}"
        ));
    }

    #[test]
    fn non_finite_numbers_are_written_as_python_writes_them() {
        let line = observation_line(
            &observation(vec![f64::NAN, f64::INFINITY, -f64::INFINITY]),
            0,
        );
        assert!(line.contains("\"ranges\": [NaN, Infinity, -Infinity]"));
    }
}

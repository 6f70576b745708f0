//! A robot's built-in controller served over the controller protocol
//! (`docs/controller-protocol.md`), with the roles reversed: another simulator sends the
//! observations and sitgen answers with the commands. This is how Stage runs a situation with
//! sitgen's own controllers (`integrations/stage/`, `docs/stage.md`).
//!
//! The controller is the one a run of the situation under the run spec gives the robot
//! ([`super::controller_spec`]), reset with the robot's route, and it decides every
//! `control_period_s` as in [`crate::run::Run`]: between decisions the last command is
//! answered again. The simulator's reset needs only `robot_id`; the reply carries what the
//! simulator must match (`dt_s`, `control_period_s`, the laser's beams).

use serde::Deserialize;

use crate::control::{self, Command, Controller};
use crate::error::SpecError;
use crate::sim::{Observation, Track};
use crate::situation::{Pose, Situation};

use super::{controller_spec, RunSpec};

/// One robot's controller, answering protocol messages.
pub struct Served {
    id: u32,
    controller: Box<dyn Controller>,
    angles: Vec<f64>,
    max_range_m: f64,
    dt_s: f64,
    period: u64,
    command: Command,
}

#[derive(Deserialize)]
#[serde(tag = "type", rename_all = "snake_case")]
enum Message {
    Reset {
        robot_id: u32,
    },
    Observation {
        time: f64,
        pose: [f64; 3],
        velocity: [f64; 2],
        stalled: bool,
        #[serde(default)]
        ranges: Option<Vec<f64>>,
        #[serde(default)]
        tracks: Vec<TrackMessage>,
    },
    End,
}

#[derive(Deserialize)]
struct TrackMessage {
    id: u32,
    position: [f64; 2],
    velocity: [f64; 2],
}

impl Served {
    /// Robot `id`'s controller in a run of `situation` under `run` (checked); errors name the
    /// field.
    pub fn new(situation: &Situation, run: &RunSpec, id: u32) -> Result<Self, SpecError> {
        run.validate("run")?;
        if id as usize >= situation.robots.len() {
            return Err(SpecError::new(
                "robot",
                format!(
                    "no robot {id}: the situation has {}",
                    situation.robots.len()
                ),
            ));
        }
        let (spec, path) = controller_spec(situation, run, id);
        let period = control::period_steps(spec, run.sim.dt_s, &path)?;
        let mut controller = control::build(spec, &path)?;
        controller.reset(&situation.robots[id as usize]);
        Ok(Self {
            id,
            controller,
            angles: run.sim.laser.bearings(),
            max_range_m: run.sim.laser.range_m,
            dt_s: run.sim.dt_s,
            period,
            command: (0.0, 0.0),
        })
    }

    /// The reply to one message line; `None` after `end` (no reply is read). Errors say what
    /// was wrong with the message.
    pub fn answer(&mut self, line: &str) -> Result<Option<String>, String> {
        let message: Message =
            serde_json::from_str(line).map_err(|e| format!("not a protocol message: {e}"))?;
        match message {
            Message::Reset { robot_id } if robot_id != self.id => Err(format!(
                "reset for robot {robot_id}, but this controller serves robot {}",
                self.id
            )),
            Message::Reset { .. } => Ok(Some(
                serde_json::json!({
                    "ready": true,
                    "dt_s": self.dt_s,
                    "control_period_s": self.period as f64 * self.dt_s,
                    "beams": self.angles.len(),
                })
                .to_string(),
            )),
            Message::Observation {
                time,
                pose,
                velocity,
                stalled,
                ranges,
                tracks,
            } => {
                let step = (time / self.dt_s).round() as u64;
                if step.is_multiple_of(self.period) {
                    let (ranges, angles) = match ranges {
                        Some(r) if r.len() != self.angles.len() => {
                            return Err(format!(
                                "ranges: {} values, but the laser has {} beams",
                                r.len(),
                                self.angles.len()
                            ))
                        }
                        Some(r) => (r, self.angles.clone()),
                        None => (Vec::new(), Vec::new()),
                    };
                    let obs = Observation {
                        ranges,
                        angles,
                        max_range_m: self.max_range_m,
                        pose: Pose {
                            x_m: pose[0],
                            y_m: pose[1],
                            heading_rad: pose[2],
                        },
                        velocity: (velocity[0], velocity[1]),
                        stalled,
                        time_s: time,
                        tracks: tracks
                            .into_iter()
                            .map(|t| Track {
                                id: t.id,
                                position: (t.position[0], t.position[1]),
                                velocity: (t.velocity[0], t.velocity[1]),
                            })
                            .collect(),
                    };
                    self.command = self.controller.act(&obs);
                }
                let (v, omega) = self.command;
                Ok(Some(
                    serde_json::json!({"v": v, "omega": omega}).to_string(),
                ))
            }
            Message::End => Ok(None),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::run::Run;

    /// Served controllers fed a run's own observations answer that run's commands: the same
    /// controller, reset the same way, deciding on the same steps.
    #[test]
    fn served_controllers_answer_as_the_run_drives() {
        let spec = crate::spec::from_toml_str(
            "[terrain]\npreset = \"caves\"\n[mission]\npeers_min = 2\npeers_max = 2\n",
        )
        .unwrap();
        let (s, _) = crate::situation::generate(&spec, 4).unwrap();
        let run: RunSpec = serde_json::from_str(
            r#"{"controller": {"name": "snd_follow", "control_period_s": 0.3}}"#,
        )
        .unwrap();
        let mut r = Run::new(&s, &run, 0).unwrap();
        let mut served: Vec<Served> = (0..s.robots.len() as u32)
            .map(|id| Served::new(&s, &run, id).unwrap())
            .collect();
        for (id, sv) in served.iter_mut().enumerate() {
            let reply = sv
                .answer(&format!(r#"{{"type":"reset","robot_id":{id}}}"#))
                .unwrap()
                .unwrap();
            assert!(reply.contains("\"ready\":true"));
        }
        assert_eq!(
            served[0]
                .answer(r#"{"type":"reset","robot_id":1}"#)
                .unwrap_err(),
            "reset for robot 1, but this controller serves robot 0"
        );
        for _ in 0..150 {
            let mut expected = Vec::new();
            for (id, sv) in served.iter_mut().enumerate() {
                let o = r.world().observe(id as u32).unwrap();
                let mut m = serde_json::json!({
                    "type": "observation", "time": o.time_s,
                    "pose": [o.pose.x_m, o.pose.y_m, o.pose.heading_rad],
                    "velocity": [o.velocity.0, o.velocity.1], "stalled": o.stalled,
                });
                if r.world().has_laser(id as u32) {
                    m["ranges"] = serde_json::json!(o.ranges);
                }
                let reply: serde_json::Value =
                    serde_json::from_str(&sv.answer(&m.to_string()).unwrap().unwrap()).unwrap();
                expected.push((
                    reply["v"].as_f64().unwrap(),
                    reply["omega"].as_f64().unwrap(),
                ));
            }
            if r.step(None) {
                break;
            }
            for (state, cmd) in r.world().robots().iter().zip(&expected) {
                let (v, w) = (
                    run.sim.max_speed_m_s,
                    run.sim.max_turn_rate_deg_s.to_radians(),
                );
                assert!((state.command.0 - cmd.0.clamp(-v, v)).abs() < 1e-12);
                assert!((state.command.1 - cmd.1.clamp(-w, w)).abs() < 1e-12);
            }
        }
        assert!(served[0].answer(r#"{"type":"end"}"#).unwrap().is_none());
        assert!(served[0]
            .answer(r#"{"type":"observation","time":0,"pose":[1,1,0],"velocity":[0,0],"stalled":false,"ranges":[1]}"#)
            .unwrap_err()
            .starts_with("ranges: 1 values, but the laser has 181 beams"));
    }
}

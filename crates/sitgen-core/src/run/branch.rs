//! A branch of a run: its world and every peer's controller copied where they stand at one
//! step, stepped on with the agent's commands given from outside and no monitor, coverage or
//! requirements watching. What [`crate::avoidability`] tries the agent's manoeuvres in: a peer
//! in a branch does exactly what it would have done in the run, as long as what it senses is
//! the same (a peer that senses nothing — the built-in `straight`, whatever the agent does —
//! follows the same path until contact).

use super::{perceived, Command, Run};
use crate::control::Controller;
use crate::sim::{Contact, World};

/// A run's world and peers' controllers, copied at one step.
#[derive(Clone)]
pub struct Branch {
    world: World,
    /// The peers' controllers (`None` for the agent).
    controllers: Vec<Option<Box<dyn Controller>>>,
    periods: Vec<u64>,
    exact: Vec<bool>,
    agent: u32,
}

impl Run {
    /// The run as it stands, branched: an error names the peer whose controller is external
    /// (its state lives outside the core and cannot be copied).
    pub fn branch(&self) -> Result<Branch, String> {
        let mut controllers = Vec::with_capacity(self.controllers.len());
        for (id, c) in self.controllers.iter().enumerate() {
            match c {
                _ if id as u32 == self.agent => controllers.push(None),
                Some(c) => controllers.push(Some(c.boxed_clone())),
                None => {
                    return Err(format!(
                        "robot {id}'s controller is external: a branch needs the peers' \
                         controllers built in"
                    ))
                }
            }
        }
        Ok(Branch {
            world: self.world.clone(),
            controllers,
            periods: self.periods.clone(),
            exact: self.exact.clone(),
            agent: self.agent,
        })
    }
}

impl Run {
    /// From this step on, the agent's commands come from outside ([`Run::step`]'s
    /// `agent_command`), its own controller dropped: a manoeuvre replayed in the run itself,
    /// watched by its monitor.
    pub fn hand_over_agent(&mut self) {
        self.controllers[self.agent as usize] = None;
    }

    /// The robots the agent's laser sees now (its scan for the coming step, kept for it, as
    /// [`Run::agent_observation`] keeps it), in id order: what the monitor is told it saw.
    pub fn agent_sees(&mut self) -> Vec<u32> {
        let world = &self.world;
        let agent = self.agent;
        self.agent_scan
            .get_or_insert_with(|| world.observe(agent).expect("the agent is in the world"))
            .tracks
            .iter()
            .map(|t| t.id)
            .collect()
    }

    /// Steps between the agent's decisions (its controller's `control_period_s`).
    pub fn agent_period(&self) -> u64 {
        self.periods[self.agent as usize]
    }
}

impl Branch {
    /// The world as it stands.
    pub fn world(&self) -> &World {
        &self.world
    }

    /// The agent's id.
    pub fn agent(&self) -> u32 {
        self.agent
    }

    /// One step: the agent commands `agent` on its decision steps (between, its last command
    /// stays in force, as in a run), every peer whose controller decides now acts on what it
    /// senses. Returns whether the agent touched anything in the step: a move of its own
    /// refused, or a robot's move refused because of the agent.
    pub fn step(&mut self, agent: Command) -> bool {
        let steps = self.world.steps();
        let mut commands = Vec::with_capacity(self.controllers.len());
        for id in 0..self.controllers.len() as u32 {
            if !steps.is_multiple_of(self.periods[id as usize]) {
                continue;
            }
            if id == self.agent {
                commands.push((id, agent.0, agent.1));
                continue;
            }
            let obs = self.world.observe(id).expect("ids are the world's");
            let obs = perceived(&self.world, self.exact[id as usize], id, obs);
            let c = self.controllers[id as usize]
                .as_mut()
                .expect("a branch's peers are built in")
                .act(&obs);
            // A peer's command that is not finite is refused by the world: it stands still.
            if c.0.is_finite() && c.1.is_finite() {
                commands.push((id, c.0, c.1));
            }
        }
        self.world
            .step(&commands)
            .expect("commands are finite and for known robots");
        self.agent_touched()
    }

    /// Whether the step just taken refused a move of the agent's, or a robot's move because of
    /// the agent. A robot at rest tried no move, so its stall flag is the last move's and is
    /// not read.
    fn agent_touched(&self) -> bool {
        let agent = self.agent;
        self.world.robots().iter().any(|r| {
            r.stalled
                && r.velocity != (0.0, 0.0)
                && (r.id == agent || r.contacts.contains(&Contact::Robot(agent)))
        })
    }
}

//! Mission planning: the second stage of the pipeline, after Arnold & Alexander (2013) §3.

pub mod astar;
pub mod rdp;

#[cfg(test)]
mod tests;

//! Geometry shared by the stages: robot bodies and grid traversal of segments.

pub mod body;
pub mod segment;

pub use body::Body;

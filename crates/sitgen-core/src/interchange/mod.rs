//! Maps in and out of files: images (PNG/PGM), ROS map_server YAML, MovingAI `.map`, BARN
//! worlds as situations, and situations out to Player/Stage world files.

pub mod barn;
pub mod image;
pub mod maps;
pub mod movingai;
pub mod ros;
pub mod stage;

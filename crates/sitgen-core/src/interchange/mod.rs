//! Maps in and out of files: images (PNG/PGM), ROS map_server YAML, MovingAI `.map`.

pub mod image;
pub mod maps;
pub mod movingai;
pub mod ros;

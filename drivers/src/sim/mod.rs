//! The simulated sensor world.

pub mod world;

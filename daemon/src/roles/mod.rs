//! Process shells: each role wires a functional core to its iceoryx2 services.

pub mod demo;
pub mod echo;
pub mod estimator;
pub mod sim_estimate;
